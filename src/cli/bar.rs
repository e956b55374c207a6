//! Terminal progress bars (indicatif) behind the engine's `Progress`.
//!
//! A counting bar reads, e.g.,
//! `rendering [00:00:12] =====>     47% 123,456/263,169 rays (10,288 rays/s, eta 13s) round 2: pass 3, ...`:
//! the percentage and the ETA are of the current count (each
//! `set_total` starts a new one; a breadth-first render's rays are one
//! count over all its rounds, whose estimated total `grow_total` raises),
//! the rate a whole number with its unit, the stage beside it.

use indicatif::{HumanCount, ProgressBar, ProgressState, ProgressStyle};
use sray_engine::progress::Progress;
use std::fmt::Write;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// `--quiet`: no bars at all in this process.
static QUIET: AtomicBool = AtomicBool::new(false);

/// Hides every bar made after this (`--quiet`).
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

pub fn quiet() -> bool {
    QUIET.load(Ordering::Relaxed)
}

/// A progress bar on stderr; invisible when stderr is not a terminal or
/// with `--quiet`.
pub struct Bar(pub ProgressBar);

impl Bar {
    /// A bar counting `unit`s ("objects"; "" for a count whose unit the
    /// engine names, or leaves unnamed).
    pub fn new(prefix: &str, unit: &str) -> Bar {
        let bar = Bar(Bar::make(prefix));
        bar.0.set_style(count_style(unit));
        bar
    }

    pub fn bytes(prefix: &str) -> Bar {
        let bar = Bar(Bar::make(prefix));
        bar.0.set_style(bytes_style());
        bar
    }

    fn make(prefix: &str) -> ProgressBar {
        if quiet() {
            return ProgressBar::hidden();
        }
        let pb = ProgressBar::new(0);
        pb.set_prefix(prefix.to_string());
        pb.enable_steady_tick(Duration::from_millis(200));
        pb
    }

    pub fn finish(&self) {
        self.0.finish_and_clear();
    }
}

/// The style of a bar counting bytes.
fn bytes_style() -> ProgressStyle {
    ProgressStyle::with_template(
        "{prefix} [{elapsed_precise}] {wide_bar} {pct} {bytes}/{total_bytes} ({bytes_per_sec}, eta {eta}) {msg}",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .with_key("pct", pct_key)
    .progress_chars("=> ")
}

/// The style of a counting bar of `unit`s.
fn count_style(unit: &str) -> ProgressStyle {
    let shown = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    let unit = unit.to_string();
    ProgressStyle::with_template(&format!(
        "{{prefix}} [{{elapsed_precise}}] {{wide_bar}} {{pct}} {{human_pos}}/{{human_len}}{shown} ({{rate}}, eta {{eta}}) {{msg}}"
    ))
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .with_key("pct", pct_key)
    .with_key("rate", move |s: &ProgressState, w: &mut dyn Write| {
        let _ = w.write_str(&rate_text(s.per_sec(), &unit));
    })
    .progress_chars("=> ")
}

fn pct_key(s: &ProgressState, w: &mut dyn Write) {
    let _ = w.write_str(&pct_text(s.pos(), s.len()));
}

/// The share of the count done, in whole percent (never past 100); "-"
/// before there is a total.
fn pct_text(pos: u64, len: Option<u64>) -> String {
    match len {
        Some(len) if len > 0 => format!("{:>3}%", (pos.min(len) as u128 * 100 / len as u128)),
        _ => "  -%".into(),
    }
}

/// A rate as a whole number with its unit: "1,234,567 rays/s".
fn rate_text(per_sec: f64, unit: &str) -> String {
    let n = if per_sec.is_finite() && per_sec > 0.0 {
        per_sec.round() as u64
    } else {
        0
    };
    if unit.is_empty() {
        format!("{}/s", HumanCount(n))
    } else {
        format!("{} {unit}/s", HumanCount(n))
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}

impl Progress for Bar {
    /// A new count: the position, the rate and the ETA start again. The
    /// position goes back first, so that a frame drawn in between shows
    /// nothing done of the old total, not the old count against the new.
    fn set_total(&self, total: u64) {
        self.0.set_position(0);
        self.0.reset_eta();
        self.0.set_length(total);
    }
    /// The same count with a larger total: position, rate and ETA go on.
    fn grow_total(&self, total: u64) {
        if self.0.length().is_none_or(|l| l < total) {
            self.0.set_length(total);
        }
    }
    fn inc(&self, n: u64) {
        self.0.inc(n);
    }
    fn set_message(&self, msg: &str) {
        self.0.set_message(msg.to_string());
    }
    /// `bytes` switches to the bytes style (a scene file being read);
    /// other units to a count of them.
    fn set_unit(&self, unit: &str) {
        if unit == "bytes" {
            self.0.set_style(bytes_style());
        } else {
            self.0.set_style(count_style(unit));
        }
    }
    /// A warning on its own line above the bar (printed with `--quiet`
    /// too: only progress and the summary are quiet).
    fn warn(&self, msg: &str) {
        self.0.suspend(|| eprintln!("sray: warning: {msg}"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_total_starts_a_new_count() {
        let b = Bar(ProgressBar::hidden());
        b.set_total(10);
        b.inc(10);
        assert_eq!((b.0.position(), b.0.length()), (10, Some(10)));
        b.set_total(4);
        assert_eq!((b.0.position(), b.0.length()), (0, Some(4)));
        b.inc(3);
        assert_eq!(b.0.position(), 3);
    }

    #[test]
    fn a_growing_total_keeps_the_count() {
        let b = Bar(ProgressBar::hidden());
        b.set_total(10);
        b.inc(7);
        b.grow_total(25);
        assert_eq!((b.0.position(), b.0.length()), (7, Some(25)));
        // Never lowered.
        b.grow_total(12);
        assert_eq!(b.0.length(), Some(25));
    }

    #[test]
    fn percentages_and_rates_read_well() {
        assert_eq!(pct_text(0, Some(263_169)), "  0%");
        assert_eq!(pct_text(131_585, Some(263_169)), " 50%");
        assert_eq!(pct_text(263_169, Some(263_169)), "100%");
        assert_eq!(pct_text(274_909, Some(263_169)), "100%");
        assert_eq!(pct_text(5, Some(0)), "  -%");
        assert_eq!(pct_text(5, None), "  -%");
        assert_eq!(rate_text(1_234_567.4, "rays"), "1,234,567 rays/s");
        assert_eq!(rate_text(0.6, "objects"), "1 objects/s");
        assert_eq!(rate_text(f64::NAN, "rays"), "0 rays/s");
        assert_eq!(rate_text(42.0, ""), "42/s");
    }
}
