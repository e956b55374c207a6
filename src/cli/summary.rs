//! The line `sray render` ends with on a terminal: which tracer and why,
//! the size, the time, the rate, the peak memory and where the image went.

use sray_engine::units::fmt_bytes;
use std::io::IsTerminal;
use std::path::Path;

/// Set to 1, prints the summary even when stderr is not a terminal (for
/// logs and tests); `--quiet` still silences it.
pub const FORCE_ENV: &str = "SRAY_SUMMARY";

/// Prints the summary of a finished render to stderr, unless `quiet` or
/// stderr is not a terminal (and [`FORCE_ENV`] does not force it).
pub fn print(stats: &serde_json::Value, output: &Path, quiet: bool) {
    let forced = std::env::var_os(FORCE_ENV).is_some_and(|v| v == "1");
    if !quiet && (forced || std::io::stderr().is_terminal()) {
        eprintln!("{}", line(stats, output));
    }
}

/// The summary of a render from its statistics (those `--stats` writes,
/// from one machine or a cluster), e.g.
/// `sray: df (auto: ...), 512x512, 0.84 s, 1.23 M rays/s, peak 14.2 MiB -> balls.png`.
///
/// The time is the whole render as the user waited for it (a cluster
/// client's own clock when there is one); the rate is every ray traced
/// (eye, reflected, refracted, shadow) over the tracing time, the
/// tracer's speed without scene preparation.
pub fn line(stats: &serde_json::Value, output: &Path) -> String {
    let f = |k: &str| stats[k].as_f64().unwrap_or(0.0);
    let u = |k: &str| stats[k].as_u64().unwrap_or(0);
    let mode = stats["mode"].as_str().unwrap_or("?");
    let reason = stats["mode_reason"].as_str().unwrap_or("");
    let tracer = if reason.is_empty() {
        mode.to_string()
    } else {
        format!("{mode} ({reason})")
    };
    let seconds = stats["client_seconds"]
        .as_f64()
        .unwrap_or_else(|| f("total_seconds"));
    let rays = u("eye_rays") + u("reflect_rays") + u("refract_rays") + u("shadow_rays");
    let trace = match f("trace_seconds") {
        t if t > 0.0 => t,
        _ => seconds,
    };
    let rate = if trace > 0.0 {
        fmt_si(rays as f64 / trace)
    } else {
        "-".into()
    };
    // A cluster's statistics are the coordinator's, in this process; the
    // workers' memory is not in them.
    let peak = match mode {
        "cluster" => format!("peak {} in this process", fmt_bytes(u("peak_rss_bytes"))),
        _ => format!("peak {}", fmt_bytes(u("peak_rss_bytes"))),
    };
    format!(
        "sray: {tracer}, {}x{}, {}, {rate} rays/s, {peak} -> {}",
        u("width"),
        u("height"),
        fmt_seconds(seconds),
        output.display()
    )
}

/// A rate with three significant digits and an SI prefix: 950, 12.3 k,
/// 1.23 M.
fn fmt_si(v: f64) -> String {
    const P: [&str; 5] = ["", " k", " M", " G", " T"];
    let mut v = v.max(0.0);
    let mut i = 0;
    while v >= 999.5 && i < P.len() - 1 {
        v /= 1000.0;
        i += 1;
    }
    if i == 0 {
        return format!("{v:.0}");
    }
    let digits = if v >= 99.95 {
        0
    } else if v >= 9.995 {
        1
    } else {
        2
    };
    format!("{v:.digits$}{}", P[i])
}

/// A duration: 0.84 s, 12.3 s, 4 min 05 s, 2 h 03 min.
fn fmt_seconds(s: f64) -> String {
    let s = s.max(0.0);
    if s < 9.995 {
        format!("{s:.2} s")
    } else if s < 59.95 {
        format!("{s:.1} s")
    } else if s < 3599.5 {
        let t = s.round() as u64;
        format!("{} min {:02} s", t / 60, t % 60)
    } else {
        let m = (s / 60.0).round() as u64;
        format!("{} h {:02} min", m / 60, m % 60)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn one_line_with_everything() {
        let s = json!({
            "mode": "df",
            "mode_reason": "auto: the scene needs about 3.1 MiB in memory, within the budget of 12.0 GiB",
            "width": 512,
            "height": 384,
            "eye_rays": 263_169,
            "reflect_rays": 400_000,
            "refract_rays": 0,
            "shadow_rays": 566_831,
            "trace_seconds": 1.0,
            "total_seconds": 1.25,
            "peak_rss_bytes": 14_889_779,
        });
        assert_eq!(
            line(&s, Path::new("out/balls.png")),
            "sray: df (auto: the scene needs about 3.1 MiB in memory, within the budget of \
             12.0 GiB), 512x384, 1.25 s, 1.23 M rays/s, peak 14.2 MiB -> out/balls.png"
        );
    }

    #[test]
    fn a_cluster_counts_the_clients_time() {
        let s = json!({
            "mode": "cluster",
            "mode_reason": "breadth-first on the cluster's workers",
            "width": 40,
            "height": 30,
            "eye_rays": 1271,
            "trace_seconds": 0.5,
            "total_seconds": 0.75,
            "client_seconds": 2.5,
            "peak_rss_bytes": 3 << 20,
        });
        assert_eq!(
            line(&s, Path::new("c.exr")),
            "sray: cluster (breadth-first on the cluster's workers), 40x30, 2.50 s, 2.54 k rays/s, \
             peak 3.0 MiB in this process -> c.exr"
        );
    }

    #[test]
    fn numbers_read_well() {
        assert_eq!(fmt_si(0.0), "0");
        assert_eq!(fmt_si(950.2), "950");
        assert_eq!(fmt_si(999.6), "1.00 k");
        assert_eq!(fmt_si(12_345.0), "12.3 k");
        assert_eq!(fmt_si(123_456.0), "123 k");
        assert_eq!(fmt_si(1_234_567.0), "1.23 M");
        assert_eq!(fmt_si(3.2e9), "3.20 G");
        assert_eq!(fmt_seconds(0.842), "0.84 s");
        assert_eq!(fmt_seconds(12.34), "12.3 s");
        assert_eq!(fmt_seconds(245.0), "4 min 05 s");
        assert_eq!(fmt_seconds(7380.0), "2 h 03 min");
    }
}
