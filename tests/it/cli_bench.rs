//! `sray bench --quick`: every experiment, small, end to end.

use crate::common;

use common::{json, ok, shared_dir, spd_fixtures};

#[test]
fn quick_bench_writes_report_data_and_charts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The bench reads only the SPD's POV-Ray files (`*.pov`), which are in
    // ../shared/spd and not vendored; without them (or without POV-Ray on
    // PATH) its POV-Ray columns are empty and the rest is the same.
    let spd = shared_dir("spd").unwrap_or_else(spd_fixtures);
    ok(
        d,
        &[
            "bench",
            "--quick",
            "--out",
            "out",
            "--spd-dir",
            spd.to_str().unwrap(),
        ],
    );
    let out = d.join("out");
    let report = std::fs::read_to_string(out.join("REPORT.md")).unwrap();
    for section in ["POV-Ray", "Table 1", "Fig. 3"] {
        assert!(report.contains(section), "no {section} section");
    }
    for file in [
        "povray.csv",
        "table1_df_vs_bf.csv",
        "fig3_remaining_rays.csv",
        "time_df_vs_povray_1thread.svg",
        "time_df_vs_bf_table1.svg",
        "remaining_rays_per_pass_rings.svg",
    ] {
        let text = std::fs::read_to_string(out.join(file)).unwrap();
        assert!(text.len() > 100, "{file} is nearly empty");
        // Every chart is linked from the report.
        if file.ends_with(".svg") {
            assert!(report.contains(file), "{file} not in the report");
            assert!(text.contains("<svg"), "{file} is not SVG");
        }
    }
    // Seven scenes, one and two threads.
    let povray = std::fs::read_to_string(out.join("povray.csv")).unwrap();
    assert_eq!(povray.lines().count(), 1 + 14);
    // The adaptive store number needs fewer passes than store number one,
    // at both resolutions (Fig. 3's point).
    let fig3 = json(&std::fs::read_to_string(out.join("fig3.json")).unwrap());
    let passes = |res: u64, store: &str| {
        fig3.as_array()
            .unwrap()
            .iter()
            .find(|e| e["res"] == res && e["store"] == store)
            .map(|e| e["remaining"].as_array().unwrap().len())
            .unwrap()
    };
    for res in [20, 40] {
        assert!(
            passes(res, "adaptive") < passes(res, "1"),
            "res {res}: adaptive {} passes, fixed {}",
            passes(res, "adaptive"),
            passes(res, "1")
        );
    }
    // No scratch files are left behind.
    let left: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}
