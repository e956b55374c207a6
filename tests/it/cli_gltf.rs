//! glTF 2.0 scenes end to end (fixtures made by trimesh, see
//! tests/fixtures/gltf/make.py): a mesh placed four times renders as the
//! same mesh copied four times, breadth-first under a small budget equals
//! depth-first, a database converted from the file renders the same, and
//! bad files are errors, not panics.

use crate::common;

use common::{fails, json, ok};
use std::path::{Path, PathBuf};

pub(crate) fn fixture(name: &str) -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/gltf")
        .join(name)
        .to_str()
        .unwrap()
        .to_string()
}

/// The PNG and the statistics of `sray render ARGS` at 64 x 64.
pub(crate) fn render(d: &Path, args: &[&str]) -> (Vec<u8>, serde_json::Value) {
    let mut a = args.to_vec();
    a.extend([
        "--width", "64", "--height", "64", "-o", "r.png", "--stats", "r.json", "--quiet",
    ]);
    ok(d, &a);
    (
        std::fs::read(d.join("r.png")).unwrap(),
        json(&std::fs::read_to_string(d.join("r.json")).unwrap()),
    )
}

#[test]
fn a_placed_mesh_renders_as_its_copies_and_bf_equals_df() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let glb = fixture("spot4.glb");
    let (df, sd) = render(d, &["render", &glb, "--mode", "df"]);
    let (copies, _) = render(d, &["render", &fixture("spot4_copies.glb"), "--mode", "df"]);
    assert!(
        df == copies,
        "the placed mesh and its copies render differently"
    );
    let (bf, sb) = render(d, &["render", &glb, "--mode", "bf", "--memory", "16MiB"]);
    assert!(df == bf, "breadth-first and depth-first images differ");
    for k in ["eye_hit_rays", "shadow_rays", "reflect_rays"] {
        assert_eq!(sd[k], sb[k], "{k}");
    }
    // Something of each of the four cows is in view.
    assert!(sd["eye_hit_rays"].as_u64().unwrap() > 200, "{sd}");
    // Converted to a database, the scene renders the same.
    ok(d, &["convert", &glb, "-o", "spot4.sdb", "--quiet"]);
    let (db, _) = render(d, &["render", "spot4.sdb", "--mode", "df"]);
    assert!(
        db == df,
        "the database renders differently from its glTF file"
    );
    // The first camera is the default; there is no second one.
    let (first, _) = render(d, &["render", &glb, "--mode", "df", "--camera-index", "0"]);
    assert!(first == df, "--camera-index 0 is not the default view");
    let e = fails(d, &["render", &glb, "--camera-index", "1", "-o", "x.png"]);
    assert!(
        e.contains("--camera-index 1") && e.contains("1 camera"),
        "{e}"
    );
    // The .gltf with external buffers and a light of its own renders.
    let (lit, _) = render(d, &["render", &fixture("spot4_light.gltf")]);
    assert!(lit != df, "the file's light changed nothing");
}

#[test]
fn a_bad_gltf_file_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let glb = std::fs::read(fixture("spot4.glb")).unwrap();
    std::fs::write(d.join("cut.glb"), &glb[..glb.len() / 2]).unwrap();
    let e = fails(d, &["render", "cut.glb", "-o", "x.png"]);
    assert!(e.contains("cut.glb"), "{e}");
    std::fs::copy(fixture("spot4_light.gltf"), d.join("lonely.gltf")).unwrap();
    let e = fails(d, &["render", "lonely.gltf", "-o", "x.png"]);
    assert!(e.contains("lonely.gltf") && e.contains("buffer"), "{e}");
}

/// The largest and the mean difference of two PNGs' channels.
fn difference(a: &[u8], b: &[u8]) -> (u8, f64) {
    let a = image::load_from_memory(a).unwrap().to_rgb8();
    let b = image::load_from_memory(b).unwrap().to_rgb8();
    assert_eq!(a.dimensions(), b.dimensions());
    let d: Vec<u8> = a
        .iter()
        .zip(b.iter())
        .map(|(x, y)| x.abs_diff(*y))
        .collect();
    let mean = d.iter().map(|&x| f64::from(x)).sum::<f64>() / d.len() as f64;
    (d.iter().copied().max().unwrap_or(0), mean)
}

/// Files written by gltfpack (quantized positions and normals, strided
/// views, GPU instancing required by the file) render as the float
/// original does, to the quantization's rounding; the instanced one is
/// a model placed four times, and breadth-first equals depth-first.
#[test]
fn gltfpack_files_render_as_their_original() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (want, _) = render(d, &["render", &fixture("spot4_smooth.glb"), "--mode", "df"]);
    for f in ["spot4_gltfpack.glb", "spot4_gltfpack_mi.glb"] {
        let (got, stats) = render(d, &["render", &fixture(f), "--mode", "df"]);
        let (most, mean) = difference(&want, &got);
        assert!(
            most <= 2 && mean < 0.05,
            "{f}: channels differ by up to {most}, {mean} on average"
        );
        assert!(stats["eye_hit_rays"].as_u64().unwrap() > 200, "{stats}");
        let (bf, sb) = render(
            d,
            &["render", &fixture(f), "--mode", "bf", "--memory", "16MiB"],
        );
        assert!(
            bf == got,
            "{f}: breadth-first and depth-first images differ"
        );
        assert_eq!(stats["shadow_rays"], sb["shadow_rays"]);
    }
    ok(
        d,
        &[
            "convert",
            &fixture("spot4_gltfpack_mi.glb"),
            "-o",
            "mi.sdb",
            "--quiet",
        ],
    );
    let info = json(&ok(d, &["info", "mi.sdb", "--json"]));
    assert_eq!(info["models"].as_array().map(Vec::len), Some(1), "{info}");
    assert_eq!(info["models"][0]["instances"], 4, "{info}");
}
