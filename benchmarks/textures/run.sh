#!/bin/sh
# sray against Blender on textured files other tools wrote; see README.md.
# Needs: target/release/sray (CARGO_BUILD_JOBS=1 cargo build --release -p sray),
# Debian's blender and python3-numpy (apt-get install -y blender python3-numpy),
# and trimesh, pillow, numpy for python3 (pip install trimesh pillow numpy).
set -eu
cd "$(dirname "$0")"
MESHES=${MESHES:-../../../shared/meshes}
python3 make_texture_files.py "$MESHES/spot.obj" out/inputs
# Blender's own glTF export (its Python needs no pyenv on PATH: see compare.py)
PATH=$(printf %s "$PATH" | tr ':' '\n' | grep -v pyenv | paste -sd:) \
    blender -b --factory-startup --python-exit-code 1 --python make_blender_gltf.py -- out/inputs
python3 compare.py "$@"
# the committed copies
mkdir -p images
for f in out/side/*.png; do cp "$f" images/; done
cp out/inputs/uvgrid.png images/uvgrid_texture.png
cp out/results.json results.json
