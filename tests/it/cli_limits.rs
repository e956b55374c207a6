//! Renders at the edges of what the options allow: grids as fine as a grid
//! may be, and images far larger than the memory budget.

use crate::common;

use common::{fails, json, ok};
use std::path::Path;

/// Two spheres side by side in front of the camera, lit, on a black
/// background (misses contribute nothing).
const TWO_SPHERES: &str = "v
from 0 0 -10
at 0 0 0
up 0 1 0
angle 40
hither 1
resolution 64 64
b 0 0 0
l 5 5 -10
f 1 0 0 1 0 0 0 1
s -1.5 0 0 1
s 1.5 0 0 1
";

fn stats(d: &Path, file: &str) -> serde_json::Value {
    json(&std::fs::read_to_string(d.join(file)).unwrap())
}

/// A grid finer than any default gives the same image as the default grid
/// in both tracers; one past the cell cap is refused with a message naming
/// the option, before any work (it once gave breadth-first half the hits,
/// silently, after a minute and 6 GB).
#[test]
fn fine_grids_give_the_exact_image_or_a_clear_refusal() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("two.nff"), TWO_SPHERES).unwrap();
    let size = ["--width", "40", "--height", "40"];
    let render = |mode: &str, res: Option<&str>, out: &str| {
        let mut a = vec!["render", "two.nff", "-o", out, "--mode", mode];
        a.extend(size);
        a.extend(["--stats", "s.json"]);
        if let Some(r) = res {
            a.extend(["--grid-res", r]);
        }
        ok(d, &a);
        let s = stats(d, "s.json");
        (std::fs::read(d.join(out)).unwrap(), s)
    };
    let (reference, s) = render("df", None, "ref.png");
    let hits = s["eye_hit_rays"].as_u64().unwrap();
    assert!(hits > 0);
    for mode in ["df", "bf"] {
        let (img, s) = render(mode, Some("160"), &format!("{mode}-fine.png"));
        assert_eq!(s["grid_res"], serde_json::json!([160, 160, 160]));
        assert_eq!(s["eye_hit_rays"].as_u64().unwrap(), hits, "{mode}");
        assert!(img == reference, "{mode}: a 160^3 grid changed the image");

        for res in ["2048", "513", "100000"] {
            let mut a = vec!["render", "two.nff", "-o", "no.png", "--mode", mode];
            a.extend(size);
            a.extend(["--grid-res", res]);
            let err = fails(d, &a);
            assert!(err.contains("--grid-res"), "{mode} {res}: {err}");
            assert!(!d.join("no.png").exists());
        }
    }
}

/// An 8192x8192 breadth-first render in a 64 MiB budget: the frame (1.6 GB
/// of pixel corners in memory) goes to disk as contributions and the image
/// streams out row by row, so the process stays within the budget plus
/// the documented 8 MiB of fixed overhead.
#[test]
fn an_image_far_larger_than_the_budget_renders_within_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // One small sphere: most eye rays miss every grid and leave at once,
    // which keeps the test quick; the sphere's rays are traced and shaded.
    let scene = TWO_SPHERES
        .replace("s -1.5 0 0 1\ns 1.5 0 0 1\n", "s 0 0 0 0.3\n")
        .replace("angle 40", "angle 20");
    std::fs::write(d.join("one.nff"), scene).unwrap();
    ok(
        d,
        &[
            "render", "one.nff", "-o", "big.png", "--mode", "bf", "--memory", "64MiB", "--width",
            "8192", "--height", "8192", "--stats", "s.json", "--quiet",
        ],
    );
    let s = stats(d, "s.json");
    let peak = s["peak_rss_bytes"].as_f64().unwrap() / (1 << 20) as f64;
    assert!(
        peak <= 64.0 + 8.0,
        "peak RSS {peak:.1} MiB is over the 64 MiB budget plus 8 MiB"
    );
    assert!(s["eye_hit_rays"].as_u64().unwrap() > 100_000, "{s}");
    let img = image::open(d.join("big.png")).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (8192, 8192));
    assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0], "background");
    assert_ne!(img.get_pixel(4096, 4096).0, [0, 0, 0], "the sphere");
}

/// The frame's spill path with a contribution from every pixel (a lit
/// background): the image equals the one rendered with the frame in
/// memory, byte for byte.
#[test]
fn a_spilled_frame_gives_the_image_of_a_frame_in_memory() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = TWO_SPHERES.replace("b 0 0 0", "b 0.2 0.3 0.4");
    std::fs::write(d.join("two.nff"), scene).unwrap();
    let mut images = Vec::new();
    for memory in ["8MiB", "1GiB"] {
        let out = format!("{memory}.png");
        ok(
            d,
            &[
                "render", "two.nff", "-o", &out, "--mode", "bf", "--memory", memory, "--width",
                "1024", "--height", "1024", "--stats", "s.json", "--quiet",
            ],
        );
        let s = stats(d, "s.json");
        if memory == "8MiB" {
            // 1025^2 corners of 24 bytes are 24 MiB: three times the budget.
            assert!(s["spill_bytes_written"].as_u64().unwrap() > 24 << 20, "{s}");
        }
        images.push(std::fs::read(d.join(&out)).unwrap());
    }
    assert!(
        images[0] == images[1],
        "the spilled frame changed the image"
    );
}
