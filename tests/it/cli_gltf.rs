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
