//! Tasks that hold up their stage: backup attempts for the ones that run
//! far longer than their siblings, and the queued ones that wait too long
//! or that no worker may take.

use super::Shared;
use super::inner::{TaskState, lose};
use super::quarantine::quarantined_now;
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
        let mut late = Vec::new();
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
            // A pinned task can run nowhere else: past the deadline of a
            // backup, its worker is taken to be stuck (it gets no other
            // task until that one ends), and the records it holds are
            // recomputed elsewhere (see `driver/recover.rs`).
            if t.pinned {
                if ran > deadline {
                    stuck.push(*id);
                    for (a, at) in &t.live {
                        late.push((at.worker.clone(), (*id, *a)));
                    }
                }
                continue;
            }
            if ran > deadline {
                t.backup = true;
                let job = t.task.job_id.clone();
                // The workers whose attempts ran past the deadline get no
                // other task until these end.
                for (a, at) in &t.live {
                    if now.duration_since(at.since) > deadline {
                        late.push((at.worker.clone(), (*id, *a)));
                    }
                }
                *g.backups.entry(job).or_default() += 1;
                super::inner::push_queued(&mut g, *id, true);
                backed.push((*id, ran));
            }
        }
        for id in stuck {
            lose(
                &mut g,
                id,
                "it ran past a backup's deadline on the only worker holding its input",
            );
        }
        for (w, a) in &late {
            if let Some(wk) = g.workers.get_mut(&w.session) {
                wk.overdue.insert(*a);
            }
        }
        drop(g);
        for (w, _) in &late {
            tracing::warn!(worker = %w.name, "a task timed out on the worker: it gets no other task until that one ends");
            self.count_fault(w, "task timeouts");
        }
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

    /// Queued tasks among `ids` that no registered worker may take (all
    /// failed them, lack room for them or are quarantined): how long each
    /// has been so, and why, worker by worker. A worker that lacked room
    /// is retried after `room_retry`, but the task counts as blocked until
    /// a worker that never lacked room for it takes it.
    pub fn stranded(&self, ids: &[u64]) -> Vec<(u64, Duration, String)> {
        let mut g = self.lock();
        let now = Instant::now();
        let g = &mut *g;
        let mut out = Vec::new();
        for id in ids {
            let Some(t) = g.tasks.get_mut(id) else {
                continue;
            };
            if t.state != TaskState::Queued {
                continue;
            }
            // Whether the worker `s` may take it now: asked every quarter
            // second of every queued task, so without a string built. A
            // task pinned to its records' holder asks that worker alone.
            let may = |s: &str, w: &super::inner::Worker| {
                !quarantined_now(&g.quarantined, s, &w.name, now)
                    && !t.excludes(s, &w.name)
                    && !t.no_room.contains_key(s)
            };
            let open = match (t.pinned, t.prefer.as_deref()) {
                (true, Some(p)) => g.workers.get(p).is_some_and(|w| may(p, w)),
                _ => g.workers.iter().any(|(s, w)| may(s, w)),
            };
            if open {
                t.blocked_since = None;
                continue;
            }
            // Blocked: why, worker by worker.
            let mut reasons = Vec::new();
            for (s, w) in &g.workers {
                if quarantined_now(&g.quarantined, s, &w.name, now) {
                    let why = [s, &w.name]
                        .iter()
                        .find_map(|k| g.quarantined.get(*k))
                        .map_or("", |q| q.why.as_str());
                    reasons.push(format!("{}: quarantined ({why})", w.name));
                } else if t.excludes(s, &w.name) {
                    let failed = t
                        .failures
                        .iter()
                        .rev()
                        .find(|f| f.strip_prefix(&w.name).is_some_and(|r| r.starts_with(": ")));
                    reasons.push(match failed {
                        Some(f) => f.clone(),
                        None => format!("{}: may not run it", w.name),
                    });
                } else if let Some((_, why)) = t.no_room.get(s) {
                    // Retried after `room_retry`, but blocked still.
                    reasons.push(why.clone());
                }
            }
            let since = *t.blocked_since.get_or_insert(now);
            if reasons.is_empty() {
                reasons.push("no worker is connected".into());
            }
            reasons.sort();
            reasons.dedup();
            out.push((*id, now.duration_since(since), reasons.join("; ")));
        }
        out
    }
}
