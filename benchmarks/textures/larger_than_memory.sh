#!/usr/bin/env bash
# Textures larger than memory: a floor whose 6144 x 6144 texture (144 MiB
# of texels, 192 MiB with its mip chain) is seen from just above it,
# rendered at 512 x 512 by both tracers under several budgets. Prints, per
# budget and tracer, the median wall time of three runs, the peak RSS
# (/usr/bin/time) and the tiles read (--stats).
#
#   benchmarks/textures/larger_than_memory.sh SRAY DIR
#
# Needs python3 with numpy and Pillow to write the texture.
set -euo pipefail
SRAY=$(realpath "$1")
DIR=$2
mkdir -p "$DIR"
cd "$DIR"
python3 - <<'PY'
import json, struct
import numpy as np
from PIL import Image
S = 6144
i = np.arange(S, dtype=np.uint32)[None, :]
j = np.arange(S, dtype=np.uint32)[:, None]
r = np.broadcast_to((i % 256).astype(np.uint8), (S, S))
g = np.broadcast_to((j % 256).astype(np.uint8), (S, S))
b = (((i // 97) * 31 + (j // 89) * 17) % 256).astype(np.uint8)
Image.fromarray(np.dstack([r, g, b, np.full((S, S), 255, np.uint8)]), "RGBA").save("floor.png")
corners = [(-50.0, -50.0), (50.0, -50.0), (50.0, 50.0), (-50.0, 50.0)]
bin_ = b"".join(struct.pack("<3f", x, 0.0, z) for x, z in corners)
bin_ += b"".join(struct.pack("<2f", (x + 50) / 100, (z + 50) / 100) for x, z in corners)
bin_ += struct.pack("<6H", 0, 2, 1, 0, 3, 2)
open("floor.bin", "wb").write(bin_)
doc = {"asset": {"version": "2.0"}, "extensionsUsed": ["KHR_lights_punctual"],
  "extensions": {"KHR_lights_punctual": {"lights": [{"type": "directional", "intensity": 2.0}]}},
  "scene": 0, "scenes": [{"nodes": [0, 1, 2]}],
  "nodes": [{"mesh": 0},
    {"camera": 0, "translation": [0, 0.5, 45], "rotation": [-0.0998, 0, 0, 0.995]},
    {"extensions": {"KHR_lights_punctual": {"light": 0}}, "rotation": [-0.7071, 0, 0, 0.7071]}],
  "cameras": [{"type": "perspective", "perspective": {"yfov": 1.0, "aspectRatio": 1.0, "znear": 0.01}}],
  "buffers": [{"uri": "floor.bin", "byteLength": len(bin_)}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
    {"buffer": 0, "byteOffset": 48, "byteLength": 32}, {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
  "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
      "min": [-50, 0, -50], "max": [50, 0, 50]},
    {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
    {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}],
  "images": [{"uri": "floor.png"}], "samplers": [{"magFilter": 9729}],
  "textures": [{"source": 0, "sampler": 0}],
  "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0},
      "metallicFactor": 0, "roughnessFactor": 1}}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}]}
json.dump(doc, open("floor.gltf", "w"))
PY
/usr/bin/time -f "convert: %e s, peak %M KB" "$SRAY" convert floor.gltf -o floor.sdb --compress zstd --quiet
ls -l floor.sdb
median() { sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
for mem in 16MiB 32MiB 64MiB; do
  for mode in bf df; do
    : > times
    for run in 1 2 3; do
      /usr/bin/time -f "%e %M" -o t "$SRAY" render floor.sdb -o "$mode.png" --mode "$mode" \
        --memory "$mem" --width 512 --height 512 --stats "$mode.json" --quiet
      cat t >> times
    done
    tiles=$(python3 -c "import json; s = json.load(open('$mode.json')); print(s['texture_tiles_read'], s['texture_bytes_read'])")
    echo "$mem $mode: median $(cut -d' ' -f1 times | median) s, peak $(cut -d' ' -f2 times | sort -n | tail -1) KB, tiles read / bytes: $tiles"
  done
  cmp bf.png df.png && echo "$mem: bf and df images identical"
done
