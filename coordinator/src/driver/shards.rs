//! How a round's rays are cut into shards: of the job's size, or of the
//! coordinator's choosing for one worker; within one worker's records
//! where the records stay at the workers.

use super::job::Job;
use crate::task::Segment;

/// A round of `n` rays in shards (first ray, count) of at most `per`
/// rays; `held_only`: the rays are only at the workers that spawned them
/// (`segments`), and each shard keeps to one worker's.
pub(super) fn cut(
    job: &Job,
    n: u64,
    per: u64,
    segments: &[Segment],
    held_only: bool,
) -> anyhow::Result<Vec<(u64, u64)>> {
    if held_only {
        // A shard size of the coordinator's choosing stretches to
        // the longest segment (within its cap): cutting a segment
        // only a little too long makes a small shard, and a pass
        // more.
        let longest = segments.iter().map(|g| g.len).max().unwrap_or(0);
        let per = if job.auto_shard {
            per.max(longest.min(AUTO_SHARD_MAX))
        } else {
            per
        };
        let shards = held_shards(segments, per);
        anyhow::ensure!(
            shards.iter().map(|s| s.1).sum::<u64>() == n,
            "internal: the held segments do not make the round's {n} rays"
        );
        Ok(shards)
    } else {
        Ok((0..n.div_ceil(per))
            .map(|i| {
                let first = i * per;
                (first, per.min(n - first))
            })
            .collect())
    }
}

/// What the coordinator knows of its workers when it cuts a round.
#[derive(Clone, Copy, Debug)]
pub(super) struct Fleet {
    pub(super) workers: usize,
    /// The smallest `--memory` among them.
    pub(super) min_memory: u64,
    /// Rays a worker traces per second of its busy time (both stages),
    /// measured from completed tasks; `None` until then.
    pub(super) worker_rate: Option<f64>,
}

/// Rays per shard in a round of `n` rays: the job's size, or (the job left
/// it to the coordinator) one for the cluster there is (see
/// [`cluster_shard_size`]). One worker alone gets the round in one or two
/// shards: no shard then waits for another worker, and fewer, larger
/// shards make fewer passes over the database (one local worker, balls4
/// 512x512: 1.34 s in shards of 65,536 rays, 1.18 s in two shards per
/// round). Where records travel, two per round keep the coordinator's
/// handling of one beside the worker's tracing of the other; where the
/// worker keeps them (`keep`), there is nothing to overlap and the round
/// is one shard (one local worker, balls4: 0.75 s against 0.81 s in two
/// shards per round, medians of 5; each shard's passes end with a few
/// that hold few rays).
pub(super) fn shard_size(job: &Job, n: u64, fleet: Fleet, keep: bool) -> u64 {
    if !job.auto_shard {
        job.shard_rays
    } else if fleet.workers <= 1 {
        auto_shard_size(ONE_WORKER_LEAST, n, keep)
    } else {
        cluster_shard_size(n, fleet, job.scene.size)
    }
}

/// The fewest rays of a shard of the coordinator's sizing for one worker.
const ONE_WORKER_LEAST: u64 = 1 << 16;

/// The fewest rays of any shard of the coordinator's sizing.
const CLUSTER_LEAST: u64 = 4096;

/// Database bytes a shard's rays pay for: a shard of `s` rays costs about
/// `p·D/B` seconds of scans (p ≈ 5 passes, B ≈ 2 GB/s) and `s·c` of
/// tracing (c ≈ 1.3 µs a ray on one core), so below D/400 rays its scans
/// cost more than its tracing (the model in docs/cluster.md).
const DB_BYTES_PER_SHARD_RAY: u64 = 400;

/// Bytes of a worker's `--memory` a ray of its shard takes in its
/// passes (the ray, its registrations and result): beyond its memory /
/// this, a shard's rays wait on disk and make more passes.
const WORKER_BYTES_PER_RAY: u64 = 256;

/// [`shard_size`] for several workers: about two shards per worker (every
/// worker busy, and room to even out stragglers), but no smaller than the
/// database makes worth a scan (so that more workers never multiply the
/// scans beyond need), nor than keeps the coordinator from being what a
/// round waits for (see [`coordinator_bound`]), and no larger than the
/// smallest worker holds in a pass (three quarters of its memory are its
/// tracer's).
pub(super) fn cluster_shard_size(n: u64, fleet: Fleet, db_bytes: u64) -> u64 {
    let target = n.div_ceil(2 * fleet.workers.max(1) as u64);
    let floor = CLUSTER_LEAST
        .max(db_bytes / DB_BYTES_PER_SHARD_RAY)
        .max(coordinator_bound(n, fleet.worker_rate));
    let cap = AUTO_SHARD_MAX
        .min(fleet.min_memory / 4 * 3 / WORKER_BYTES_PER_RAY)
        .max(CLUSTER_LEAST);
    target.max(floor).min(cap)
}

/// The coordinator's CPU seconds a task costs it beyond the task's rays:
/// two RPCs' worth and their bookkeeping. `sray bench load` (release
/// builds, one call a task, 100 simulated workers) measures 48-113 µs
/// a task, by machine load and by whether colour is sent; this is near
/// the top, as sizing shards a little too large costs less than a
/// coordinator that holds up every round.
const TASK_SECONDS: f64 = 100e-6;

/// The shard size below which the coordinator's work on a round's tasks
/// outlasts the workers' tracing of them: a round of `n` rays in shards
/// of `s` (each worker with a shard at most) takes the workers about
/// `s / r` seconds (r: a worker's rays a second, both stages) and the
/// coordinator `2 (n / s) t` (t: [`TASK_SECONDS`], two tasks a shard, one
/// core), the two equal at `s = sqrt(2 n r t)`. Below it more, smaller
/// shards put more workers to work but make the round longer: with 1,000
/// workers of 2 M rays a second and a round of a million rays, 4,096-ray
/// shards keep 244 workers busy for 2 ms and the coordinator for 49 ms;
/// 20,000-ray shards keep 50 busy for 10 ms and the coordinator for
/// 10 ms. (The coordinator's work per ray, on colour and on records that
/// travel, is the same whatever the shards.) 0 until `r` is measured.
fn coordinator_bound(n: u64, worker_rate: Option<f64>) -> u64 {
    worker_rate.map_or(0, |r| {
        (2.0 * n as f64 * r * TASK_SECONDS)
            .sqrt()
            .min(u64::MAX as f64) as u64
    })
}

/// [`shard_size`] for one worker: at least `least` rays, and the round in
/// one shard (`keep`) or two, within [`AUTO_SHARD_MAX`].
fn auto_shard_size(least: u64, n: u64, keep: bool) -> u64 {
    let parts = if keep { 1 } else { 2 };
    least.max(n.div_ceil(parts).min(AUTO_SHARD_MAX))
}

/// Shards of at most `per` rays, each within the records of one worker
/// (records at the workers): a worker's consecutive segments joined, a
/// segment longer than `per` cut into equal parts.
fn held_shards(segments: &[Segment], per: u64) -> Vec<(u64, u64)> {
    let mut shards: Vec<(u64, u64)> = Vec::new();
    let mut open: Option<(&str, u64, u64)> = None;
    for g in segments {
        match &mut open {
            Some((s, _, len)) if *s == g.session && *len + g.len <= per => *len += g.len,
            _ => {
                if let Some((_, first, len)) = open.take() {
                    shards.push((first, len));
                }
                if g.len <= per {
                    open = Some((&g.session, g.start, g.len));
                } else {
                    let k = g.len.div_ceil(per);
                    let mut at = g.start;
                    for i in 0..k {
                        let len = g.len / k + u64::from(i < g.len % k);
                        shards.push((at, len));
                        at += len;
                    }
                }
            }
        }
    }
    if let Some((_, first, len)) = open {
        shards.push((first, len));
    }
    shards
}

/// The largest shard [`shard_size`] makes by itself.
const AUTO_SHARD_MAX: u64 = 1 << 20;

#[cfg(test)]
mod tests {
    use super::{AUTO_SHARD_MAX, Fleet, Segment, auto_shard_size, cluster_shard_size, held_shards};

    #[test]
    fn one_worker_keeping_its_records_takes_a_round_in_one_shard() {
        // Records travel: two shards, so that the coordinator handles one
        // while the worker traces the other.
        assert_eq!(auto_shard_size(65_536, 797_659, false), 398_830);
        // Kept at the worker: the whole round, within the cap.
        assert_eq!(auto_shard_size(65_536, 797_659, true), 797_659);
        assert_eq!(auto_shard_size(65_536, 5 << 20, true), AUTO_SHARD_MAX);
        // Never below the job's size.
        assert_eq!(auto_shard_size(65_536, 1_000, true), 65_536);
    }

    #[test]
    fn shards_are_sized_for_the_cluster() {
        let fleet = |workers| Fleet {
            workers,
            min_memory: 1 << 30,
            worker_rate: None,
        };
        // A small database: two shards per worker.
        assert_eq!(cluster_shard_size(263_169, fleet(2), 1 << 20), 65_793);
        assert_eq!(cluster_shard_size(263_169, fleet(16), 1 << 20), 8_225);
        // Never below what a scan of the database is worth ...
        assert_eq!(cluster_shard_size(263_169, fleet(100), 1 << 20), 4_096);
        assert_eq!(cluster_shard_size(263_169, fleet(16), 100 << 20), 262_144);
        // ... nor above what the smallest worker holds in a pass.
        let small = Fleet {
            workers: 16,
            min_memory: 64 << 20,
            worker_rate: None,
        };
        assert_eq!(cluster_shard_size(263_169, small, 100 << 20), 196_608);
        assert_eq!(cluster_shard_size(16 << 20, fleet(4), 0), AUTO_SHARD_MAX);
    }

    #[test]
    fn shards_are_no_smaller_than_keeps_the_coordinator_ahead() {
        let paced = |workers, worker_rate| Fleet {
            workers,
            min_memory: 1 << 30,
            worker_rate,
        };
        // 1,000 workers of 2 M rays a second: the coordinator would hold
        // up rounds of shards below sqrt(2 n r t).
        assert_eq!(
            cluster_shard_size(1_000_000, paced(1000, Some(2e6)), 0),
            20_000
        );
        // Slow workers (20,000 rays a second): every worker busy, as
        // before.
        assert_eq!(
            cluster_shard_size(1_000_000, paced(16, Some(2e4)), 0),
            31_250
        );
        // Nothing measured yet (the first tasks): as before.
        assert_eq!(cluster_shard_size(1_000_000, paced(1000, None), 0), 4_096);
        // Within the cap, however fast the workers.
        assert_eq!(
            cluster_shard_size(1_000_000, paced(1000, Some(1e12)), 0),
            AUTO_SHARD_MAX
        );
    }

    #[test]
    fn held_shards_keep_to_one_worker_and_cover_every_ray() {
        let seg = |start, len, w: &str| Segment {
            start,
            len,
            task: 0,
            session: w.to_string(),
        };
        let segs = [
            seg(0, 30, "a"),
            seg(30, 40, "a"),
            seg(70, 50, "b"),
            seg(120, 250, "a"),
            seg(370, 10, "a"),
        ];
        assert_eq!(
            held_shards(&segs, 100),
            vec![
                (0, 70),
                (70, 50),
                (120, 84),
                (204, 83),
                (287, 83),
                (370, 10)
            ]
        );
    }
}
