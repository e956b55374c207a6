//! How fast the workers trace, measured as tasks complete: what the
//! coordinator weighs when it sizes shards for the cluster
//! (`driver/shards.rs`). With many fast workers and small shards, the
//! coordinator's work per task, not the workers', bounds a round.

/// Weight of what came before, per completed task: the estimate follows
/// the last thousand tasks or so (a new scene, other workers).
const DECAY: f64 = 0.999;

/// Rays and workers' seconds of completed tasks, decayed.
#[derive(Debug, Default)]
pub(super) struct Pace {
    /// Rays of completed intersections.
    rays: f64,
    /// Workers' seconds on completed tasks of either stage.
    seconds: f64,
}

impl Pace {
    /// Notes a completed task: its stage, its rays and the seconds its
    /// worker reports (none: not counted).
    pub(super) fn record(&mut self, intersect: bool, rays: u64, seconds: f64) {
        if seconds > 0.0 && seconds.is_finite() {
            self.rays *= DECAY;
            self.seconds *= DECAY;
            if intersect {
                self.rays += rays as f64;
            }
            self.seconds += seconds;
        }
    }

    /// Rays a worker traces (intersection and shading) per second of its
    /// busy time; `None` until tasks that took time have completed.
    pub(super) fn worker_rays_per_second(&self) -> Option<f64> {
        (self.seconds > 0.0 && self.rays > 0.0).then(|| self.rays / self.seconds)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_workers_rate_from_completed_tasks() {
        let mut p = Pace::default();
        assert_eq!(p.worker_rays_per_second(), None);
        // A shard of 1,000 rays: intersected in 1 ms, shaded in 1 ms.
        p.record(true, 1000, 0.001);
        p.record(false, 1000, 0.001);
        let r = p.worker_rays_per_second().unwrap();
        assert!((r - 500_000.0).abs() < 1000.0, "{r}");
        // Tasks that report no time (a worker of an earlier release) do
        // not count.
        p.record(true, 1_000_000, 0.0);
        assert_eq!(p.worker_rays_per_second(), Some(r));
    }
}
