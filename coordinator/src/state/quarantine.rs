//! Quarantine: a worker that fails too often, or is caught returning
//! wrong output, gets no task for a while, by session and by name.

use super::Shared;
use super::inner::{Quarantine, drop_attempt, lose_pinned_to, requeue_if_idle};
use crate::task::WorkerTag;
use std::collections::HashMap;
use std::time::Instant;

impl Shared {
    /// Gives `worker` no task for `cfg.quarantine`; its live attempts are
    /// dropped and their tasks queued again elsewhere.
    pub fn quarantine(&self, worker: &WorkerTag, why: &str) {
        let mut g = self.lock();
        let until = Instant::now() + self.cfg.quarantine;
        tracing::warn!(worker = %worker.name, why, seconds = self.cfg.quarantine.as_secs(), "worker quarantined");
        for k in [&worker.session, &worker.name] {
            g.quarantined.insert(
                k.clone(),
                Quarantine {
                    until,
                    why: why.to_string(),
                },
            );
        }
        let mine: Vec<(u64, u32)> = g
            .tasks
            .iter()
            .flat_map(|(id, t)| {
                t.live
                    .iter()
                    .filter(|(_, a)| a.worker.session == worker.session)
                    .map(move |(a, _)| (*id, *a))
            })
            .collect();
        for (id, a) in mine {
            drop_attempt(&mut g, id, a);
            if let Some(t) = g.tasks.get_mut(&id) {
                t.excluded.insert(worker.session.clone());
                t.excluded.insert(worker.name.clone());
            }
            requeue_if_idle(&mut g, id);
        }
        lose_pinned_to(
            &mut g,
            &worker.session,
            "the worker holding its input is quarantined",
        );
        drop(g);
        self.task_ready.notify_waiters();
    }

    /// Whether the worker is quarantined now.
    pub fn is_quarantined(&self, worker: &WorkerTag) -> bool {
        quarantined_now(
            &self.lock().quarantined,
            &worker.session,
            &worker.name,
            Instant::now(),
        )
    }
}

/// Whether `tag` (by session or by name) is quarantined at `now`.
pub(super) fn quarantined_now(
    quarantined: &HashMap<String, Quarantine>,
    session: &str,
    name: &str,
    now: Instant,
) -> bool {
    [session, name]
        .iter()
        .any(|k| quarantined.get(*k).is_some_and(|q| q.until > now))
}
