//! How fast the workers trace, measured as tasks complete: what the
//! coordinator weighs when it sizes shards for the cluster
//! (`driver/shards.rs`). With many fast workers and small shards, the
//! coordinator's work per task, not the workers', bounds a round.
//!
//! Kept by scene: the same workers trace a scene in memory at millions of
//! rays a second and one read from disk at a twentieth of that, and a
//! rate measured on one would size the other's shards wrongly.

use std::collections::HashMap;

/// Scenes whose rates are kept (one is forgotten to make room).
const SCENES: usize = 64;

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

/// [`Pace`] by scene hash.
#[derive(Debug, Default)]
pub(super) struct Paces(HashMap<String, Pace>);

impl Paces {
    /// Notes a completed task of the scene `scene` (see [`Pace::record`]).
    pub(super) fn record(&mut self, scene: &str, intersect: bool, rays: u64, seconds: f64) {
        if let Some(p) = self.0.get_mut(scene) {
            return p.record(intersect, rays, seconds);
        }
        if self.0.len() >= SCENES
            && let Some(k) = self.0.keys().next().cloned()
        {
            self.0.remove(&k);
        }
        let mut p = Pace::default();
        p.record(intersect, rays, seconds);
        self.0.insert(scene.to_string(), p);
    }

    /// A worker's rays a second on scene `scene`, if measured.
    pub(super) fn worker_rays_per_second(&self, scene: &str) -> Option<f64> {
        self.0.get(scene)?.worker_rays_per_second()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_kept_by_scene() {
        let mut p = Paces::default();
        p.record("fast", true, 2000, 0.001);
        p.record("slow", true, 100, 0.001);
        assert_eq!(p.worker_rays_per_second("fast"), Some(2e6));
        assert_eq!(p.worker_rays_per_second("slow"), Some(1e5));
        assert_eq!(p.worker_rays_per_second("new"), None);
        for i in 0..2 * SCENES {
            p.record(&i.to_string(), true, 1, 1.0);
        }
        assert_eq!(p.0.len(), SCENES);
    }

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
