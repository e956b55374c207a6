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

/// Rays per shard in a round of `n` rays on `workers` workers: the job's
/// size, except when the job left it to the coordinator and one worker
/// does the work. No shard then waits for another worker, and fewer,
/// larger shards make fewer passes over the database (one local worker,
/// balls4 512x512: 1.34 s in shards of 65,536 rays, 1.18 s in two shards
/// per round). Where records travel, two per round keep the
/// coordinator's handling of one beside the worker's tracing of the
/// other; where the worker keeps them (`keep`), there is nothing to
/// overlap and the round is one shard (one local worker, balls4: 0.75 s
/// against 0.81 s in two shards per round, medians of 5; each shard's
/// passes end with a few that hold few rays).
pub(super) fn shard_size(job: &Job, n: u64, workers: usize, keep: bool) -> u64 {
    if job.auto_shard && workers == 1 {
        auto_shard_size(job.shard_rays, n, keep)
    } else {
        job.shard_rays
    }
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
    use super::{AUTO_SHARD_MAX, Segment, auto_shard_size, held_shards};

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
