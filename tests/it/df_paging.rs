//! The file-backed allocator (`engine/src/paging.rs`), which only the
//! paging experiment's binary, `sray-paged`, installs: there, a depth-first
//! render of a scene larger than its `--memory` budget puts its big arrays
//! in a temporary file, and must give the same image as the render in
//! ordinary memory and leave nothing behind. `sray` itself renders such a
//! scene in ordinary memory, and says so.

use crate::common;

use common::json;
use std::process::Command;

/// Counts that must not change with where the arrays live.
const COUNTS: [&str; 6] = [
    "eye_rays",
    "eye_hit_rays",
    "reflect_rays",
    "refract_rays",
    "shadow_rays",
    "intersection_tests",
];

/// `sray render --mode df` (or `sray-paged` with `paged`) of a scene whose
/// arrays are far above the allocator's 1 MiB threshold; `budget` adds
/// `--memory`. Returns stderr.
fn render(
    d: &std::path::Path,
    tmp: &std::path::Path,
    out: &str,
    budget: Option<&str>,
    paged: bool,
) -> String {
    let png = format!("{out}.png");
    let stats = format!("{out}.json");
    let mut args = vec![
        "render",
        "spd:tetra:8",
        "-o",
        &png,
        "--stats",
        &stats,
        "--mode",
        "df",
        "--width",
        "64",
        "--height",
        "64",
        "--tmp-dir",
        tmp.to_str().unwrap(),
    ];
    if let Some(b) = budget {
        args.extend(["--memory", b]);
    }
    let mut cmd = if paged {
        Command::new(env!("CARGO_BIN_EXE_sray-paged"))
    } else {
        common::sray()
    };
    let o = cmd
        .current_dir(d)
        .args(&args)
        .env("SRAY_SUMMARY", "0")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "render {args:?} failed: {err}");
    err
}

fn entries(dir: &std::path::Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

#[test]
fn depth_first_past_the_budget_pages_to_a_file_and_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tmp = d.join("tmp");
    std::fs::create_dir(&tmp).unwrap();

    // tetra 8: 65,536 triangles, several MiB of decoded shapes and grid.
    render(d, &tmp, "paged", Some("1MiB"), true);
    let paged = json(&std::fs::read_to_string(d.join("paged.json")).unwrap());
    assert_eq!(paged["mode"], "df", "{paged}");
    assert_eq!(paged["df_paged"], true, "not paged: {paged}");
    // Every file-backed region is at least the 1 MiB threshold, so a peak
    // of at least that much means allocations really went to the file
    // (not back to the system allocator after a failed mapping).
    let peak = paged["df_paged_peak_bytes"].as_u64().unwrap();
    assert!(peak >= 1 << 20, "nothing was file-backed: {paged}");
    assert!(
        entries(&tmp).is_empty(),
        "left in the tmp dir: {:?}",
        entries(&tmp)
    );

    // The same render in ordinary memory: no paging, same image and counts.
    render(d, &tmp, "plain", None, true);
    let plain = json(&std::fs::read_to_string(d.join("plain.json")).unwrap());
    assert!(plain["df_paged"].is_null(), "paged without need: {plain}");

    // `sray` has no file-backed allocator: past the budget, it renders in
    // ordinary memory, says so, and gives the same image.
    let err = render(d, &tmp, "sray", Some("1MiB"), false);
    let unpaged = json(&std::fs::read_to_string(d.join("sray.json")).unwrap());
    assert!(unpaged["df_paged"].is_null(), "sray paged: {unpaged}");
    assert!(
        err.contains("more than the budget of 1.0 MiB") && err.contains("sray-paged"),
        "{err}"
    );
    assert!(
        std::fs::read(d.join("sray.png")).unwrap() == std::fs::read(d.join("plain.png")).unwrap()
    );
    assert!(
        std::fs::read(d.join("paged.png")).unwrap() == std::fs::read(d.join("plain.png")).unwrap(),
        "the paged render's image differs"
    );
    for k in COUNTS {
        assert_eq!(paged[k], plain[k], "{k}");
    }
    assert!(paged["eye_hit_rays"].as_u64().unwrap() > 0, "nothing hit");
}
