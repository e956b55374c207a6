//! Progress reporting for long work (generation, conversion, rendering).
//! The engine only counts; the command line draws the bars.

/// Receives progress of one piece of work. Implementations must be cheap:
/// hot loops call `inc` in batches, not per object.
///
/// One progress may report several counts in turn (a render marks voxels
/// over the objects, then traces each round's rays): each `set_total`
/// starts a new count from zero, so what is done never exceeds the total
/// of the count it belongs to.
pub trait Progress: Send + Sync {
    /// Starts a new count of `total` units (objects, bytes, rays, ...),
    /// none of them done yet.
    fn set_total(&self, total: u64);
    /// Records `n` more units done.
    fn inc(&self, n: u64);
    /// Describes the current stage ("depth 2, pass 3").
    fn set_message(&self, msg: &str);
    /// Names the units counted ("rays", "objects", "bytes") from now on.
    fn set_unit(&self, _unit: &str) {}
    /// Reports something the user should know that does not stop the work
    /// (a missing material library, faces skipped as degenerate). Readers
    /// report each kind of problem once, with a count, not per occurrence.
    fn warn(&self, msg: &str) {
        eprintln!("sray: warning: {msg}");
    }
}

/// Progress that goes nowhere: for tests, and when output is not a terminal.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn set_total(&self, _: u64) {}
    fn inc(&self, _: u64) {}
    fn set_message(&self, _: &str) {}
}

/// Another progress, with every message prefixed: so that work which
/// describes its own stages ("pass 3, ...") says which larger stage it is
/// part of ("round 2: pass 3, ...").
pub struct Prefixed<'a> {
    inner: &'a dyn Progress,
    prefix: String,
}

impl<'a> Prefixed<'a> {
    pub fn new(inner: &'a dyn Progress, prefix: impl Into<String>) -> Self {
        Prefixed {
            inner,
            prefix: prefix.into(),
        }
    }
}

impl Progress for Prefixed<'_> {
    fn set_total(&self, total: u64) {
        self.inner.set_total(total);
    }
    fn inc(&self, n: u64) {
        self.inner.inc(n);
    }
    fn set_message(&self, msg: &str) {
        self.inner.set_message(&format!("{}{msg}", self.prefix));
    }
    fn set_unit(&self, unit: &str) {
        self.inner.set_unit(unit);
    }
    fn warn(&self, msg: &str) {
        self.inner.warn(msg);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::job::{RenderRequest, Stages, render};
    use crate::render::{Mode, RenderOptions};
    use crate::source::SceneSource;
    use std::sync::Mutex;

    /// One count a progress saw: unit, total, done, messages.
    type Count = (String, u64, u64, Vec<String>);

    /// Every count a progress saw.
    #[derive(Default)]
    struct Recorder {
        unit: Mutex<String>,
        counts: Mutex<Vec<Count>>,
    }

    impl Progress for Recorder {
        fn set_total(&self, total: u64) {
            let unit = self.unit.lock().unwrap().clone();
            self.counts
                .lock()
                .unwrap()
                .push((unit, total, 0, Vec::new()));
        }
        fn inc(&self, n: u64) {
            let mut c = self.counts.lock().unwrap();
            let last = c.last_mut().expect("inc before set_total");
            last.2 += n;
        }
        fn set_message(&self, msg: &str) {
            if let Some(last) = self.counts.lock().unwrap().last_mut() {
                last.3.push(msg.to_string());
            }
        }
        fn set_unit(&self, unit: &str) {
            *self.unit.lock().unwrap() = unit.to_string();
        }
    }

    /// Records the rendering stage only.
    struct Rec(Recorder);

    impl Stages for Rec {
        fn stage(&self, name: &str) -> Box<dyn Progress + '_> {
            match name {
                "rendering" => Box::new(Prefixed::new(&self.0, "")),
                _ => Box::new(NoProgress),
            }
        }
    }

    fn counts(mode: Mode) -> Vec<Count> {
        let req = RenderRequest {
            scene: SceneSource::parse("spd:balls:1").unwrap(),
            options: RenderOptions {
                width: 24,
                height: 16,
                threads: 1,
                ..Default::default()
            },
            mode,
            memory: None,
            store: crate::bf::StoreNumber::Adaptive,
            shading: Default::default(),
            models: Default::default(),
            full_scans: false,
            order: crate::job::ObjectOrder::Auto,
            tmp_dir: None,
            setup: Default::default(),
        };
        let stages = Rec(Recorder::default());
        render(&req, &stages).unwrap();
        stages.0.counts.into_inner().unwrap()
    }

    /// Each count of a render ends with all its units done, none more:
    /// the breadth-first tracer's rounds each count their own rays.
    #[test]
    fn a_render_never_counts_past_its_total() {
        for mode in [Mode::Df, Mode::Bf] {
            let c = counts(mode);
            for (unit, total, done, msgs) in &c {
                assert_eq!(done, total, "{mode:?}: {unit} {msgs:?}: {c:?}");
            }
            if mode == Mode::Bf {
                // Marking voxels, then one count per round.
                assert_eq!(c[0].0, "objects");
                let rounds = &c[1..];
                assert!(rounds.len() >= 2, "{c:?}");
                assert_eq!(rounds[0].1, 25 * 17);
                for (i, (unit, _, _, msgs)) in rounds.iter().enumerate() {
                    assert_eq!(unit, "rays");
                    assert!(msgs.iter().any(|m| m.contains("pass 1")), "{msgs:?}");
                    let round = format!("round {}: ", i + 1);
                    assert!(msgs.iter().all(|m| m.starts_with(&round)), "{msgs:?}");
                }
            }
        }
    }
}
