//! Tasks that hold up their stage: backup attempts for the ones that run
//! far longer than their siblings, and the queued ones that wait too long
//! or that no worker may take.

use super::Shared;
use super::inner::{TaskState, lose};
use super::quarantine::quarantined_now;
use crate::task::WorkerTag;
use std::time::{Duration, Instant};

impl Shared {
    /// Backup attempts for the tasks among `ids` that run far longer than
    /// their finished siblings (or than `task_timeout` while none has
    /// finished). Returns the ids given a backup, with how long they ran.
    pub fn issue_backups(&self, ids: &[u64]) -> Vec<(u64, Duration)> {
        let mut g = self.lock();
        let mut took: Vec<Duration> = ids
            .iter()
            .filter_map(|id| g.tasks.get(id).and_then(|t| t.took))
            .collect();
        took.sort();
        let deadline = match took.get(took.len() / 2) {
            Some(median) => median
                .mul_f64(self.cfg.deadline_factor)
                .max(self.cfg.deadline_min),
            None => self.cfg.task_timeout,
        };
        let now = Instant::now();
        let mut backed = Vec::new();
        let mut stuck = Vec::new();
        for id in ids {
            let Some(t) = g.tasks.get_mut(id) else {
                continue;
            };
            if t.state != TaskState::Running || t.backup {
                continue;
            }
            let Some(oldest) = t.live.values().map(|a| a.since).min() else {
                continue;
            };
            let ran = now.duration_since(oldest);
            // A pinned task can run nowhere else: past the task timeout,
            // its worker is taken to be stuck and the job starts again.
            if t.pinned {
                if ran > self.cfg.task_timeout {
                    stuck.push(*id);
                }
                continue;
            }
            if ran > deadline {
                t.backup = true;
                let job = t.task.job_id.clone();
                *g.backups.entry(job).or_default() += 1;
                g.queue.push_front(*id);
                backed.push((*id, ran));
            }
        }
        for id in stuck {
            lose(&mut g, id, "it ran past --task-timeout where its input is");
        }
        drop(g);
        if !backed.is_empty() {
            self.task_ready.notify_waiters();
        }
        backed
    }

    /// Tasks among `ids` queued, with no attempt live, for longer than
    /// `wait` (every worker that may take them is busy or stuck).
    pub fn waiting(&self, ids: &[u64], wait: Duration) -> Vec<u64> {
        let g = self.lock();
        ids.iter()
            .copied()
            .filter(|id| {
                g.tasks
                    .get(id)
                    .is_some_and(|t| t.state == TaskState::Queued && t.queued_at.elapsed() > wait)
            })
            .collect()
    }

    /// Queued tasks among `ids` that no registered worker may take.
    pub fn stranded(&self, ids: &[u64]) -> Vec<(u64, String)> {
        let g = self.lock();
        let now = Instant::now();
        ids.iter()
            .filter_map(|id| {
                let t = g.tasks.get(id)?;
                if t.state != TaskState::Queued {
                    return None;
                }
                let any = g.workers.iter().any(|(s, w)| {
                    let tag = WorkerTag {
                        session: s.clone(),
                        name: w.name.clone(),
                    };
                    !t.excludes(&tag) && !quarantined_now(&g, &tag, now)
                });
                (!any).then(|| (*id, t.failures.join("; ")))
            })
            .collect()
    }
}
