//! Image files: PNG and OpenEXR, chosen by the output's extension, on one
//! machine and through the cluster path.

use crate::common;

use common::{fails, ok};
use std::path::Path;

const SMALL: [&str; 4] = ["--width", "40", "--height", "30"];

/// Renders `scene` to `out` (in `d`) with `extra` arguments.
fn render(d: &Path, scene: &str, out: &str, extra: &[&str]) {
    let mut args = vec!["render", scene, "-o", out];
    args.extend_from_slice(&SMALL);
    args.extend_from_slice(extra);
    ok(d, &args);
}

fn png_pixels(path: &Path) -> Vec<u8> {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(img.color(), image::ColorType::Rgb8, "{}", path.display());
    assert_eq!((img.width(), img.height()), (40, 30));
    img.into_rgb8().into_raw()
}

/// The pixels of an OpenEXR file, which must be 32-bit float RGB.
fn exr_pixels(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap();
    // The OpenEXR magic number.
    assert_eq!(&bytes[..4], &[0x76, 0x2f, 0x31, 0x01], "{}", path.display());
    let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::OpenExr)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(img.color(), image::ColorType::Rgb32F, "{}", path.display());
    assert_eq!((img.width(), img.height()), (40, 30));
    img.into_rgb32f().into_raw()
}

/// Every EXR value, clamped to [0, 1], scaled to 255 and rounded (half
/// up, as the PNG's were), is the PNG's value; returns the largest EXR
/// value.
fn assert_same_image(what: &str, png: &[u8], exr: &[f32]) -> f32 {
    assert_eq!(png.len(), exr.len(), "{what}");
    for (i, (&p, &e)) in png.iter().zip(exr).enumerate() {
        assert!(e.is_finite(), "{what}: value {i} is {e}");
        let q = ((e as f64).clamp(0.0, 1.0) * 255.0 + 0.5).floor();
        assert_eq!(
            q,
            p as f64,
            "{what}: pixel {}, channel {}: EXR {e}, PNG {p}",
            i / 3,
            i % 3
        );
    }
    exr.iter().copied().fold(f32::MIN, f32::max)
}

#[test]
fn exr_is_the_png_in_linear_float_unclamped() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (scene, mode) in [
        ("spd:balls:1", "df"),
        ("spd:balls:1", "bf"),
        ("spd:gears:1", "auto"),
    ] {
        render(d, scene, "a.png", &["--mode", mode]);
        // The extension is case-insensitive.
        render(d, scene, "a.EXR", &["--mode", mode]);
        let png = png_pixels(&d.join("a.png"));
        let exr = exr_pixels(&d.join("a.EXR"));
        let max = assert_same_image(&format!("{scene} {mode}"), &png, &exr);
        // Some pixels of these scenes are brighter than full scale: the EXR
        // keeps them.
        assert!(max > 1.0, "{scene} {mode}: nothing above 1 (max {max})");
        assert!(png.contains(&255));
    }
    // Jittered samples: the mean of a pixel's samples.
    render(d, "spd:balls:1", "j.png", &["--samples", "4"]);
    render(d, "spd:balls:1", "j.exr", &["--samples", "4"]);
    assert_same_image(
        "4 samples",
        &png_pixels(&d.join("j.png")),
        &exr_pixels(&d.join("j.exr")),
    );
}

#[test]
fn local_workers_write_png_and_exr() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    render(d, "spd:balls:1", "one.png", &["--mode", "bf"]);
    render(d, "spd:balls:1", "one.exr", &["--mode", "bf"]);
    let cluster = ["--local-workers", "1", "--shard-rays", "512"];
    render(d, "spd:balls:1", "c.png", &cluster);
    render(d, "spd:balls:1", "c.exr", &cluster);
    let png = png_pixels(&d.join("c.png"));
    let exr = exr_pixels(&d.join("c.exr"));
    // The cluster's images are those of one machine, value for value.
    assert_eq!(png, png_pixels(&d.join("one.png")));
    assert_eq!(exr, exr_pixels(&d.join("one.exr")));
    let max = assert_same_image("local workers", &png, &exr);
    assert!(max > 1.0, "nothing above 1 (max {max})");
}

#[test]
fn an_unknown_extension_fails_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tmp = d.join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    for (out, extra) in [
        ("x.jpg", &[][..]),
        ("x", &[][..]),
        ("x.png.tmp", &[][..]),
        ("x.jpg", &["--local-workers", "1"][..]),
    ] {
        let mut args = vec![
            "render",
            "spd:balls:4",
            "-o",
            out,
            "--stats",
            "s.json",
            "--tmp-dir",
            "tmp",
        ];
        args.extend_from_slice(extra);
        let err = fails(d, &args);
        assert!(
            err.contains(".png") && err.contains(".exr") && err.contains(out),
            "{out}: {err}"
        );
        // Nothing written, not even the scene's temporary database.
        let left: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(left, ["tmp"], "{out}: files left");
        assert_eq!(
            std::fs::read_dir(&tmp).unwrap().count(),
            0,
            "{out}: work began"
        );
    }
}
