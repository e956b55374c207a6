//! Textures larger than memory, end to end through the command line: a
//! floor whose texture takes 4.5 times `--memory` (144 MiB of texels, 192
//! MiB with its mip chain), seen from just above it so that the near
//! floor reads the finest level and the far floor coarse ones. Both
//! tracers, two local workers and two worker processes give the same
//! image; each render (and each worker) stays within its budget plus 64
//! MiB, and reports the tiles it read.

use crate::common;

use common::{json, ok, run};
use serde_json::json;
use std::f64::consts::FRAC_1_SQRT_2;
use std::path::Path;

/// Texels a side: 6144^2 x 4 bytes = 144 MiB.
const SIDE: u32 = 6144;

/// A PNG of `SIDE`^2 texels, each its own colour along both axes, that
/// compresses (a few MiB) so that writing it stays quick.
fn floor_png(d: &Path) {
    let img = image::RgbaImage::from_fn(SIDE, SIDE, |i, j| {
        let block = ((i / 97) * 31 + (j / 89) * 17) as u8;
        image::Rgba([i as u8, j as u8, block, 255])
    });
    img.save(d.join("floor.png")).unwrap();
}

/// The floor y = 0 over [-50, 50]^2, its texture once across it, a
/// camera half a unit above it looking along it, and a light above.
fn floor_gltf(d: &Path) {
    let mut bin: Vec<u8> = Vec::new();
    let corners = [
        [-50.0f32, -50.0],
        [50.0, -50.0],
        [50.0, 50.0],
        [-50.0, 50.0],
    ];
    for c in corners {
        for x in [c[0], 0.0, c[1]] {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    for c in corners {
        for x in [(c[0] + 50.0) / 100.0, (c[1] + 50.0) / 100.0] {
            bin.extend_from_slice(&x.to_le_bytes());
        }
    }
    for i in [0u16, 2, 1, 0, 3, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(d.join("floor.bin"), &bin).unwrap();
    let doc = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "directional", "intensity": 2.0}]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2]}],
        "nodes": [
            {"mesh": 0},
            {"camera": 0, "translation": [0.0, 0.5, 45.0], "rotation": [-0.0998, 0.0, 0.0, 0.995]},
            {"extensions": {"KHR_lights_punctual": {"light": 0}},
             "rotation": [-FRAC_1_SQRT_2, 0.0, 0.0, FRAC_1_SQRT_2]}
        ],
        "cameras": [{"type": "perspective", "perspective": {
            "yfov": 1.0, "aspectRatio": 1.0, "znear": 0.01}}],
        "buffers": [{"uri": "floor.bin", "byteLength": bin.len()}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 32},
            {"buffer": 0, "byteOffset": 80, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [-50.0, 0.0, -50.0], "max": [50.0, 0.0, 50.0]},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ],
        "images": [{"uri": "floor.png"}],
        "samplers": [{"magFilter": 9729}],
        "textures": [{"source": 0, "sampler": 0}],
        "materials": [{"pbrMetallicRoughness": {
            "baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 1.0}}],
        "meshes": [{"primitives": [
            {"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}]
    });
    std::fs::write(
        d.join("floor.gltf"),
        serde_json::to_string_pretty(&doc).unwrap(),
    )
    .unwrap();
}

fn stats(d: &Path, file: &str) -> serde_json::Value {
    json(&std::fs::read_to_string(d.join(file)).unwrap())
}

#[test]
fn textures_four_times_the_memory_render_within_it_in_both_tracers_and_on_two_workers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    floor_png(d);
    floor_gltf(d);
    ok(
        d,
        &[
            "convert",
            "floor.gltf",
            "-o",
            "floor.sdb",
            "--compress",
            "zstd",
        ],
    );
    let info = json(&ok(d, &["info", "floor.sdb", "--json"]));
    assert_eq!(info["textures"], 1, "{info}");
    let size = ["--width", "160", "--height", "160"];
    let mut renders = Vec::new();
    for mode in ["bf", "df"] {
        let out = format!("{mode}.png");
        let st = format!("{mode}.json");
        let mut a = vec!["render", "floor.sdb", "-o", &out, "--mode", mode];
        a.extend(["--memory", "32MiB", "--stats", &st, "--quiet"]);
        a.extend(size);
        ok(d, &a);
        let s = stats(d, &st);
        let peak = s["peak_rss_bytes"].as_f64().unwrap() / (1 << 20) as f64;
        assert!(
            peak <= 32.0 + 64.0,
            "{mode}: peak RSS {peak:.1} MiB is over the 32 MiB budget plus 64 MiB"
        );
        // Each level is read where its texels match the pixels: about as
        // many tiles as the image has pixels per tile (4,096 texels) at
        // each level seen, a few dozen of the chain's 12,000.
        let tiles = s["texture_tiles_read"].as_u64().unwrap();
        assert!((20..2000).contains(&tiles), "{mode}: {tiles} tiles read");
        assert!(s["texture_bytes_read"].as_u64().unwrap() > 0);
        renders.push((std::fs::read(d.join(&out)).unwrap(), s));
    }
    assert!(
        renders[0].0 == renders[1].0,
        "breadth-first and depth-first differ"
    );
    assert_eq!(renders[0].1["eye_hit_rays"], renders[1].1["eye_hit_rays"]);
    // The floor shows its texture: many colours, not one.
    let img = image::load_from_memory(&renders[0].0).unwrap().to_rgb8();
    let colours: std::collections::BTreeSet<[u8; 3]> = img.pixels().map(|p| p.0).collect();
    assert!(colours.len() > 1000, "{} colours", colours.len());

    let tmp = d.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let mut a = vec![
        "render",
        "floor.sdb",
        "-o",
        "local.png",
        "--local-workers",
        "2",
    ];
    a.extend([
        "--memory",
        "64MiB",
        "--shard-rays",
        "4096",
        "--stats",
        "local.json",
    ]);
    a.extend(["--tmp-dir", tmp.to_str().unwrap()]);
    a.extend(size);
    let o = run(d, &a);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        std::fs::read(d.join("local.png")).unwrap() == renders[0].0,
        "two local workers differ from the embedded render"
    );
    assert_eq!(
        stats(d, "local.json")["eye_hit_rays"],
        renders[0].1["eye_hit_rays"]
    );

    // Two worker processes of 32 MiB each (their caches hold the scene as
    // the coordinator serves it): the same image, and each worker's peak
    // within its budget plus 64 MiB.
    std::fs::write(d.join("token"), "texture-secret\n").unwrap();
    let (coord, url) = common::cluster::coordinator(d, &["--token-file", "token"]);
    let workers: Vec<common::Proc> = ["t0", "t1"]
        .iter()
        .map(|n| common::cluster::worker(d, &url, n, Some("token"), &["--memory", "32MiB"]))
        .collect();
    for n in ["t0", "t1"] {
        common::cluster::registered(&coord, n);
    }
    let mut a =
        common::cluster::render_args("floor.sdb", &url, "token", "workers.png", "160", "4096");
    a.push("--quiet");
    ok(d, &a);
    assert!(
        std::fs::read(d.join("workers.png")).unwrap() == renders[0].0,
        "two worker processes differ from the embedded render"
    );
    for w in &workers {
        let status =
            std::fs::read_to_string(format!("/proc/{}/status", w.child.id())).unwrap_or_default();
        let Some(kb) = status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<f64>().ok())
        else {
            common::cannot_run("a worker's peak needs /proc/PID/status");
            return;
        };
        let peak = kb / 1024.0;
        assert!(
            peak <= 32.0 + 64.0,
            "a worker's peak RSS {peak:.1} MiB is over its 32 MiB budget plus 64 MiB"
        );
        eprintln!("worker peak RSS {peak:.1} MiB");
        assert!(peak > 1.0, "{peak} MiB: not the worker's figure");
    }
}
