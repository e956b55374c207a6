//! Progress reporting for long work (generation, conversion, rendering).
//! The engine only counts; the command line draws the bars.

/// Receives progress of one piece of work. Implementations must be cheap:
/// hot loops call `inc` in batches, not per object.
///
/// One progress may report several counts in turn (a render marks voxels
/// over the objects, then traces its rays): each `set_total` starts a new
/// count from zero, so what is done never exceeds the total of the count
/// it belongs to. A count whose total is an estimate (the rays of a
/// breadth-first render, all rounds together) raises it with
/// `grow_total` as the estimate improves: the total never goes down, and
/// what is done only goes up.
pub trait Progress: Send + Sync {
    /// Starts a new count of `total` units (objects, bytes, rays, ...),
    /// none of them done yet.
    fn set_total(&self, total: u64);
    /// Raises the total of the current count to `total` (nothing if it is
    /// already that much), keeping what is done.
    fn grow_total(&self, _total: u64) {}
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
    fn grow_total(&self, total: u64) {
        self.inner.grow_total(total);
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

/// The total of work done in rounds, each round's size known only when
/// it starts: a breadth-first render, whose round 1 holds the eye rays
/// and each later round the rays that the one before spawned (shadow
/// rays to the lights, and reflected and refracted rays, which spawn the
/// round after). The total is the rounds known so far plus an estimate of
/// the later ones, corrected as each round starts.
///
/// Round 2 is taken to be `first_ratio` times round 1 (every eye ray
/// hitting, with a shadow ray per light and some reflected or refracted
/// rays); each round after that `later_ratio` times the one before, until
/// rounds 2 and 3 are known, and from then on the ratio of the last two
/// rounds (from round 2 on, each round holds the same mix: the rays that
/// the reflected and refracted rays of the round before spawned).
///
/// The total given out never goes down: when the estimate of what is
/// left drops, the difference is counted as done at once (the position
/// jumps forward, never back), so that what is left to do is always the
/// estimate's.
#[derive(Clone, Debug)]
pub struct RoundsEstimate {
    /// Sizes of the rounds known so far (the last one may be running).
    rounds: Vec<u64>,
    /// Most rounds there can be.
    max_rounds: usize,
    /// Round 2 per unit of round 1, until round 2 is known.
    first_ratio: f64,
    /// A later round per unit of the round before, until round 3 is known.
    later_ratio: f64,
    /// The largest total given out so far.
    total: u64,
    /// Units counted as done that were never work: estimated, then not
    /// needed.
    credited: u64,
}

impl RoundsEstimate {
    /// Work whose first round has `first` units, in `max_rounds` rounds at
    /// most, with the ratios assumed between rounds until they are seen.
    pub fn new(first: u64, max_rounds: usize, first_ratio: f64, later_ratio: f64) -> Self {
        let mut e = RoundsEstimate {
            rounds: vec![first],
            max_rounds: max_rounds.max(1),
            first_ratio: first_ratio.max(0.0),
            later_ratio: later_ratio.max(0.0),
            total: 0,
            credited: 0,
        };
        e.total = e.estimate();
        e
    }

    /// The total, as estimated so far.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The next round starts with `next` units (0: the work is over).
    /// Returns the total now (never less than before) and the units to
    /// count as done now, which the estimate had and the work will not
    /// need.
    pub fn next_round(&mut self, next: u64) -> (u64, u64) {
        self.rounds.push(next);
        let est = self.estimate();
        let counted = self.total - self.credited;
        let credit = if est > counted {
            self.total = est + self.credited;
            0
        } else {
            counted - est
        };
        self.credited += credit;
        (self.total, credit)
    }

    /// Units in the rounds known so far, and the estimate of the rounds
    /// to come.
    fn estimate(&self) -> u64 {
        let known: u64 = self.rounds.iter().sum();
        let k = self.rounds.len();
        let last = self.rounds[k - 1] as f64;
        let later = self.max_rounds.saturating_sub(k);
        let (next_ratio, ratio) = match k {
            1 => (self.first_ratio, self.later_ratio),
            2 => (self.later_ratio, self.later_ratio),
            _ => {
                let before = self.rounds[k - 2];
                let r = if before == 0 {
                    0.0
                } else {
                    last / before as f64
                };
                (r, r)
            }
        };
        let mut round = last;
        let mut rest = 0.0;
        for i in 0..later {
            round *= if i == 0 { next_ratio } else { ratio };
            rest += round;
        }
        known.saturating_add(rest.min(u64::MAX as f64 / 2.0) as u64)
    }
}

/// A breadth-first render's progress as one count of rays over all its
/// rounds. The tracer counts each round's rays as a count of their own
/// (`set_unit("rays")` and `set_total` at each round's start, every ray
/// counted once); this turns them into one count for the whole render,
/// whose total is a [`RoundsEstimate`] and grows (`grow_total`) as the
/// rounds start, so that the percentage and the time left are the
/// render's, not a round's. The rounds and passes stay in the messages.
/// Other counts (the objects when marking voxels) pass through.
///
/// [`RenderRounds::finish`] ends the count when the render is over,
/// counting the estimate of rounds that never came as done.
pub struct RenderRounds<'a> {
    inner: &'a dyn Progress,
    max_rounds: usize,
    first_ratio: f64,
    later_ratio: f64,
    state: std::sync::Mutex<RoundsState>,
}

#[derive(Default)]
struct RoundsState {
    /// The unit last named.
    unit: String,
    /// The count of rays, once its first round has started.
    rays: Option<RoundsEstimate>,
}

impl<'a> RenderRounds<'a> {
    /// A render of rays up to depth `max_depth` (the eye rays are depth 1)
    /// of a scene with `lights` lights. Such a render has `max_depth + 1`
    /// rounds at most: the eye rays; then in each round the shadow rays of
    /// the round before's hits with the reflected and refracted rays of the
    /// next depth; last, the shadow rays of the deepest hits.
    pub fn new(inner: &'a dyn Progress, max_depth: u8, lights: usize) -> Self {
        RenderRounds {
            inner,
            max_rounds: max_depth as usize + 1,
            // Until they are seen: every eye ray hits and sends a shadow
            // ray to each light, and a quarter of the hits spawn a
            // reflected or refracted ray; so on in each round after.
            first_ratio: lights.max(1) as f64 + 0.25,
            later_ratio: 0.25,
            state: Default::default(),
        }
    }

    /// The render is over: the rays estimated for rounds that never came
    /// are counted as done, so that the count ends at its total.
    pub fn finish(&self) {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(e) = st.rays.as_mut() {
            let (total, credit) = e.next_round(0);
            self.inner.grow_total(total);
            self.inner.inc(credit);
        }
    }
}

impl Progress for RenderRounds<'_> {
    fn set_total(&self, total: u64) {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if st.unit != "rays" {
            self.inner.set_total(total);
            return;
        }
        match st.rays.as_mut() {
            None => {
                let e =
                    RoundsEstimate::new(total, self.max_rounds, self.first_ratio, self.later_ratio);
                self.inner.set_total(e.total());
                st.rays = Some(e);
            }
            Some(e) => {
                let (total, credit) = e.next_round(total);
                self.inner.grow_total(total);
                self.inner.inc(credit);
            }
        }
    }
    fn grow_total(&self, total: u64) {
        self.inner.grow_total(total);
    }
    fn inc(&self, n: u64) {
        self.inner.inc(n);
    }
    fn set_message(&self, msg: &str) {
        self.inner.set_message(msg);
    }
    /// A new unit starts a new count; "rays" again, at the next round,
    /// goes on with the same one.
    fn set_unit(&self, unit: &str) {
        let mut st = self.state.lock().unwrap_or_else(|e| e.into_inner());
        if unit == "rays" && st.unit == "rays" {
            return;
        }
        st.unit = unit.to_string();
        st.rays = None;
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

    /// One count a progress saw: unit, every total it was given (the
    /// first by `set_total`, then by `grow_total`), done, messages.
    type Count = (String, Vec<u64>, u64, Vec<String>);

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
                .push((unit, vec![total], 0, Vec::new()));
        }
        fn grow_total(&self, total: u64) {
            let mut c = self.counts.lock().unwrap();
            c.last_mut()
                .expect("grow_total before set_total")
                .1
                .push(total);
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

    /// Each count of a render ends with all its units done, none more,
    /// and its total never goes down: the breadth-first tracer's rays are
    /// one count over all its rounds, whose total grows as the rounds
    /// end, and whose messages name each round and its passes.
    #[test]
    fn a_render_never_counts_past_its_total() {
        for mode in [Mode::Df, Mode::Bf] {
            let c = counts(mode);
            for (unit, totals, done, msgs) in &c {
                assert!(totals.is_sorted(), "{mode:?}: {unit}: {totals:?}");
                assert_eq!(
                    done,
                    totals.last().unwrap(),
                    "{mode:?}: {unit} {msgs:?}: {c:?}"
                );
            }
            if mode == Mode::Bf {
                // Marking voxels, then the rays of every round.
                assert_eq!(c.len(), 2, "{c:?}");
                assert_eq!(c[0].0, "objects");
                let (unit, totals, _, msgs) = &c[1];
                assert_eq!(unit, "rays");
                // The eye rays, and an estimate of the rounds after.
                assert!(totals[0] > 25 * 17, "{totals:?}");
                for round in 1..=2 {
                    let p = format!("round {round}: pass 1");
                    assert!(msgs.iter().any(|m| m.starts_with(&p)), "{p}: {msgs:?}");
                }
                assert!(msgs.iter().all(|m| m.starts_with("round ")), "{msgs:?}");
            }
        }
    }

    #[test]
    fn an_estimate_of_rounds_never_goes_down() {
        // 1000 eye rays; round 2 three times as many (the prior), each
        // round after a third of the one before: 1000, 3000, 1000, 333.
        let mut e = RoundsEstimate::new(1000, 4, 3.0, 1.0 / 3.0);
        assert_eq!(e.total(), 1000 + 3000 + 1000 + 333);
        assert_eq!(e.next_round(3000), (5333, 0));
        assert_eq!(e.next_round(1000), (5333, 0));
        assert_eq!(e.next_round(333), (5333, 0));
        assert_eq!(e.next_round(0), (5333, 0));

        // Fewer than estimated: what the estimate had is counted done at
        // once, and what is left is the new estimate's.
        let mut e = RoundsEstimate::new(1000, 4, 3.0, 1.0);
        assert_eq!(e.total(), 10_000);
        let mut done = 1000;
        // Round 2: 1500 rays; rounds 3 and 4 taken as as many.
        let (total, credit) = e.next_round(1500);
        done += credit;
        assert_eq!(total, 10_000);
        assert_eq!(total - done, 1500 + 1500 + 1500);
        done += 1500;
        // Round 3: 150, so round 4 a tenth of that.
        let (total, credit) = e.next_round(150);
        done += credit;
        assert_eq!(total - done, 150 + 15);
        done += 150;
        // No round 4: the rest counted done.
        let (total, credit) = e.next_round(0);
        done += credit;
        assert_eq!((total, done), (10_000, 10_000));

        // More than estimated: the total grows, nothing is credited.
        let mut e = RoundsEstimate::new(100, 4, 1.0, 0.5);
        let t0 = e.total();
        assert_eq!(t0, 100 + 100 + 50 + 25);
        let (t1, c1) = e.next_round(400);
        assert_eq!(c1, 0);
        assert!(t1 > t0, "{t0} {t1}");
        // Nothing more: all of the estimate of the later rounds credited.
        let (t2, c2) = e.next_round(0);
        assert_eq!((t2, c2), (t1, t1 - 500));

        // One round at most.
        let mut e = RoundsEstimate::new(100, 1, 5.0, 1.0);
        assert_eq!(e.total(), 100);
        assert_eq!(e.next_round(0), (100, 0));
    }

    /// Rounds counted one after another through [`RenderRounds`] make one
    /// count that ends at its total; other counts pass through.
    #[test]
    fn rounds_become_one_count() {
        let rec = Recorder::default();
        let r = RenderRounds::new(&rec, 3, 1);
        r.set_unit("objects");
        r.set_total(10);
        r.inc(10);
        for n in [100, 60, 20, 5] {
            r.set_unit("rays");
            r.set_total(n);
            r.set_message("pass 1");
            r.inc(n);
        }
        r.finish();
        let c = rec.counts.into_inner().unwrap();
        assert_eq!(c.len(), 2, "{c:?}");
        assert_eq!((c[0].0.as_str(), c[0].2), ("objects", 10));
        let (unit, totals, done, _) = &c[1];
        assert_eq!(unit, "rays");
        assert!(totals.is_sorted(), "{totals:?}");
        // 100 eye rays, then 125, 31.25 and 7.8 estimated.
        assert_eq!(totals[0], 264);
        assert_eq!(done, totals.last().unwrap());
    }
}
