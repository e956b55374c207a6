//! Speed against accuracy: for each default scene, render time against the
//! image's error from a converged reference, over the knobs that trade
//! them: the maximum depth, single against double precision, and corner
//! sampling against jittered supersampling.

use super::chart::{self, Scale, Series};
use super::exec;
use super::report::{Report, num};
use super::{Ctx, Plan};
use anyhow::Context;
use std::path::Path;

/// A render setting: label, knob, arguments.
struct Variant {
    knob: &'static str,
    label: String,
    /// The setting in a few characters, beside its point on the chart.
    short: String,
    args: Vec<String>,
}

fn variants() -> Vec<Variant> {
    let mut v = Vec::new();
    for d in 1..=5 {
        v.push(Variant {
            knob: "depth",
            label: format!("depth {d}"),
            short: format!("depth {d}"),
            args: vec!["--depth".into(), d.to_string()],
        });
    }
    for p in ["single", "double"] {
        v.push(Variant {
            knob: "precision",
            label: format!("{p} precision"),
            short: p.into(),
            args: vec!["--precision".into(), p.into()],
        });
    }
    for s in [1, 4, 16] {
        v.push(Variant {
            knob: "samples",
            label: if s == 1 {
                "pixel corners".into()
            } else {
                format!("{s} jittered samples")
            },
            short: if s == 1 {
                "corners".into()
            } else {
                format!("{s} spp")
            },
            args: vec!["--samples".into(), s.to_string()],
        });
    }
    v
}

/// The converged reference: deep rays, many jittered samples.
const REFERENCE: [&str; 4] = ["--depth", "12", "--samples", "64"];

pub(super) fn plan(ctx: &Ctx) -> Plan {
    let scenes = ctx.scenes().len();
    let steps = scenes * (1 + variants().len());
    Plan {
        steps,
        seconds: if ctx.quick {
            steps as f64 * 0.1
        } else {
            scenes as f64 * 60.0
        },
    }
}

/// 8-bit RGB pixels of a PNG.
fn pixels(path: &Path) -> anyhow::Result<Vec<u8>> {
    let img = image::ImageReader::open(path)
        .with_context(|| path.display().to_string())?
        .with_guessed_format()
        .with_context(|| path.display().to_string())?
        .decode()
        .with_context(|| path.display().to_string())?;
    Ok(img.into_rgb8().into_raw())
}

/// Root mean square difference, in units of full scale (0..1).
fn rmse(a: &[u8], b: &[u8]) -> f64 {
    let s: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| {
            let d = (*x as f64 - *y as f64) / 255.0;
            d * d
        })
        .sum();
    (s / a.len().max(1) as f64).sqrt()
}

pub(super) fn run(ctx: &Ctx, r: &mut Report) -> anyhow::Result<()> {
    let side: u32 = if ctx.quick { 32 } else { 256 };
    r.section("Speed against accuracy");
    r.para(&format!(
        "Each default scene at {side}x{side}, depth-first, both cores; whole-process time (median of {} \
         run(s)) against the root-mean-square error of the 8-bit image from a converged reference \
         (depth 12, 64 jittered samples per pixel, double precision), in units of full scale. Each \
         knob is varied from the default (depth 5, pixel corners, double precision) on its own.",
        ctx.runs
    ));
    let mut rows = Vec::new();
    let mut data = Vec::new();
    let mut verdicts = Vec::new();
    for (scene, size) in ctx.scenes() {
        let name = format!("{}{size}", scene.name());
        let sdb = ctx.scene_file(scene, size, "sdb")?;
        let base = |out: &str| -> Vec<String> {
            vec![
                sdb.display().to_string(),
                "-o".into(),
                ctx.work().join(out).display().to_string(),
                "--mode".into(),
                "df".into(),
                "--width".into(),
                side.to_string(),
                "--height".into(),
                side.to_string(),
            ]
        };
        ctx.step(&format!("accuracy: {name} reference"));
        let mut ref_args = base("ref.png");
        ref_args.extend(REFERENCE.iter().map(|s| s.to_string()));
        exec::sray_render(&ref_args, ctx.work())?;
        let reference = pixels(&ctx.work().join("ref.png"))?;
        // Knob, short setting, seconds, error.
        let mut points: Vec<(&'static str, String, f64, f64)> = Vec::new();
        for v in variants() {
            let mut args = base("var.png");
            args.extend(v.args.iter().cloned());
            let m = ctx.median(&format!("accuracy: {name} {}", v.label), || {
                exec::sray_render(&args, ctx.work())
            })?;
            let err = rmse(&pixels(&ctx.work().join("var.png"))?, &reference);
            rows.push(vec![
                name.clone(),
                v.label.clone(),
                num(m.seconds(), 3),
                format!("{err:.5}"),
            ]);
            data.push(serde_json::json!({
                "scene": name, "knob": v.knob, "setting": v.label, "seconds": m.seconds(), "rmse": err,
            }));
            points.push((v.knob, v.short, m.seconds(), err));
        }
        // One curve per knob, each point labelled with its setting.
        let series: Vec<Series> = [
            ("depth", "maximum depth"),
            ("precision", "precision"),
            ("samples", "samples per pixel"),
        ]
        .iter()
        .map(|&(k, name)| {
            let mine: Vec<_> = points.iter().filter(|p| p.0 == k).collect();
            Series::new(name, mine.iter().map(|p| (p.2, p.3)).collect())
                .with_labels(mine.iter().map(|p| p.1.clone()).collect())
        })
        .collect();
        let file = format!("speed_accuracy_{name}.svg");
        chart::lines(
            &r.path(&file),
            &format!("{name}: time against error"),
            "seconds",
            "RMS error from the reference",
            &series,
            Scale::LogY,
        )?;
        let worths: Vec<(&str, Worth)> = ["depth", "precision", "samples"]
            .iter()
            .map(|&k| {
                let p: Vec<_> = points.iter().filter(|p| p.0 == k).collect();
                let (lo, hi) = (p.first().expect("settings"), p.last().expect("settings"));
                (k, worth((lo.2, lo.3), (hi.2, hi.3)))
            })
            .collect();
        verdicts.push(format!("{name}: {}", verdict(&worths)));
        r.chart(&file, &format!("speed against accuracy, {name}"));
    }
    r.table(
        "speed_accuracy",
        &["scene", "setting", "seconds", "RMS error"],
        &rows,
    )?;
    r.json("speed_accuracy", &serde_json::Value::Array(data))?;
    r.para(&format!(
        "Which knob buys the most accuracy per second, each from its cheapest setting to its \
         dearest (depth 1 to 5, single to double precision, corners to 16 samples). A change of \
         error under 2 % counts as no effect, and a change of time under 5 % (plus 5 ms) as \
         free, since single runs on a shared machine vary that much:\n\n- {}",
        verdicts.join("\n- ")
    ));
    Ok(())
}

/// What moving a knob from its cheapest setting to its dearest buys.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Worth {
    /// The error changes by less than 2 %.
    NoEffect,
    /// The error falls by this much at no measurable cost.
    Free(f64),
    /// Error removed per extra second.
    Rate(f64),
}

/// `lo` and `hi` are (seconds, error) at the cheapest and dearest setting.
fn worth(lo: (f64, f64), hi: (f64, f64)) -> Worth {
    let removed = lo.1 - hi.1;
    if removed <= 0.02 * lo.1 {
        return Worth::NoEffect;
    }
    let extra = hi.0 - lo.0;
    if extra <= 0.05 * lo.0 + 0.005 {
        Worth::Free(removed)
    } else {
        Worth::Rate(removed / extra)
    }
}

/// One sentence: the knob that buys the most accuracy per second, then
/// the others.
fn verdict(knobs: &[(&str, Worth)]) -> String {
    let describe = |(k, w): &(&str, Worth)| match w {
        Worth::NoEffect => format!("{k} has no measurable effect"),
        Worth::Free(e) => format!("{k} removes {e:.4} RMS at no measurable cost"),
        Worth::Rate(r) => format!("{k} removes {r:.4} RMS per extra second"),
    };
    let score = |w: &Worth| match w {
        Worth::NoEffect => f64::NEG_INFINITY,
        Worth::Free(e) => 1e9 + e,
        Worth::Rate(r) => *r,
    };
    let best = knobs
        .iter()
        .max_by(|a, b| score(&a.1).total_cmp(&score(&b.1)))
        .expect("knobs");
    if best.1 == Worth::NoEffect {
        return "no knob changes the error measurably".into();
    }
    let others: Vec<String> = knobs
        .iter()
        .filter(|k| k.0 != best.0)
        .map(describe)
        .collect();
    format!(
        "**{}** buys the most ({}); {}",
        best.0,
        describe(best),
        others.join(", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts_ignore_noise_and_rank_by_rate() {
        assert_eq!(worth((0.10, 0.050), (0.20, 0.0495)), Worth::NoEffect);
        assert_eq!(worth((0.10, 0.05), (0.102, 0.04)), Worth::Free(0.05 - 0.04));
        assert!(
            matches!(worth((0.1, 0.12), (0.2, 0.05)), Worth::Rate(r) if (r - 0.7).abs() < 1e-9)
        );
        let v = verdict(&[
            ("depth", Worth::Rate(1.0)),
            ("precision", Worth::NoEffect),
            ("samples", Worth::Rate(0.03)),
        ]);
        assert!(v.starts_with("**depth** buys the most"), "{v}");
        assert!(v.contains("precision has no measurable effect"), "{v}");
        let v = verdict(&[("depth", Worth::NoEffect), ("samples", Worth::NoEffect)]);
        assert_eq!(v, "no knob changes the error measurably");
    }
}
