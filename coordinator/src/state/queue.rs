//! The task queue: tasks in (a stage's shards, their samples), the next
//! one out to a worker that asks, and a running task's input.

use super::inner::{Attempt, Inner, TaskEntry, TaskState, live_attempt, lose, push_queued};
use super::quarantine::quarantined_now;
use super::{Refusal, Shared};
use crate::task::{TaskEvent, TaskInput, WorkerTag};
use sray_proto::v1;
use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::{Notify, mpsc};

impl Shared {
    /// Queues tasks; their outcomes go to `events`. Returns their ids.
    /// `avoid`: workers the tasks must not go to (verification).
    pub fn enqueue(
        &self,
        tasks: Vec<(v1::Task, usize, Arc<TaskInput>)>,
        events: &mpsc::UnboundedSender<TaskEvent>,
        avoid: &[WorkerTag],
    ) -> Vec<u64> {
        let mut g = self.lock();
        let mut ids = Vec::with_capacity(tasks.len());
        for (mut task, shard, input) in tasks {
            let mut id = sray_proto::ids::random_u64();
            while id == 0 || g.tasks.contains_key(&id) {
                id = sray_proto::ids::random_u64();
            }
            task.task_id = id;
            task.attempt = 0;
            let prefer = input.held.preferred(task.first_ray, task.ray_count);
            let pinned = input.held.pinned && prefer.is_some();
            // Gone, or quarantined (it would not get the task in time).
            let holder_gone = pinned
                && prefer.as_ref().is_some_and(|s| {
                    !g.workers.contains_key(s)
                        || g.quarantined
                            .get(s)
                            .is_some_and(|q| q.until > Instant::now())
                });
            g.tasks.insert(
                id,
                TaskEntry {
                    task,
                    shard,
                    state: TaskState::Queued,
                    failures: Vec::new(),
                    input,
                    events: events.clone(),
                    live: HashMap::new(),
                    next_attempt: 1,
                    excluded: avoid
                        .iter()
                        .flat_map(|w| [w.session.clone(), w.name.clone()])
                        .collect(),
                    took: None,
                    backup: false,
                    queued_at: Instant::now(),
                    prefer,
                    pinned,
                    no_room: HashMap::new(),
                    not_before: None,
                    local_fault: None,
                    blocked_since: None,
                },
            );
            push_queued(&mut g, id, false);
            ids.push(id);
            if holder_gone {
                lose(&mut g, id, "the worker holding its input is gone");
            }
        }
        // Tasks pinned to the worker holding their input wake that worker
        // alone: no other may take them, and waking a thousand workers to
        // search the queue for nothing costs more than the tasks.
        let holders: Option<Vec<Arc<Notify>>> = ids
            .iter()
            .filter_map(|id| g.tasks.get(id))
            .map(|t| match (t.pinned, &t.prefer) {
                (true, Some(p)) => Some(g.workers.get(p).map(|w| w.wake.clone())),
                _ => None,
            })
            .collect::<Option<Vec<_>>>()
            .map(|v| v.into_iter().flatten().collect());
        drop(g);
        match holders {
            Some(h) => h.iter().for_each(|w| w.notify_one()),
            None => self.task_ready.notify_waiters(),
        }
        ids
    }

    /// Drops tasks (their stage ended, or the job did).
    pub fn forget_tasks(&self, ids: &[u64]) {
        let mut g = self.lock();
        for id in ids {
            if let Some(t) = g.tasks.remove(id) {
                for (a, at) in t.live {
                    if let Some(w) = g.workers.get_mut(&at.worker.session) {
                        w.running.remove(&(*id, a));
                    }
                }
            }
        }
        let tasks = std::mem::take(&mut g.tasks);
        g.queue.retain(|t| tasks.contains_key(t));
        g.pinned_queue.retain(|_, q| {
            q.retain(|t| tasks.contains_key(t));
            !q.is_empty()
        });
        g.tasks = tasks;
    }

    /// Forgets a finished job's counters.
    pub fn end_job(&self, job: &str) {
        let mut g = self.lock();
        g.requeued.remove(job);
        g.backups.remove(job);
        g.last_given.remove(job);
    }

    /// Tasks of job `job` may run under the id `alias` too (a
    /// recomputation's): workers hear it among the jobs running.
    pub fn add_alias(&self, alias: &str, job: &str) {
        self.lock()
            .aliases
            .insert(alias.to_string(), job.to_string());
    }

    /// Drops the alias `alias` and its counters: workers let go of the
    /// records they keep under it (a verification's, once it is done).
    pub fn drop_alias(&self, alias: &str) {
        let mut g = self.lock();
        g.aliases.remove(alias);
        g.requeued.remove(alias);
        g.backups.remove(alias);
        g.last_given.remove(alias);
    }

    /// Drops job `job`'s aliases and their counters.
    pub fn drop_aliases(&self, job: &str) {
        let mut g = self.lock();
        let gone: Vec<String> = g
            .aliases
            .iter()
            .filter(|(_, j)| *j == job)
            .map(|(a, _)| a.clone())
            .collect();
        for a in gone {
            g.aliases.remove(&a);
            g.requeued.remove(&a);
            g.backups.remove(&a);
            g.last_given.remove(&a);
        }
    }

    /// The aliases of the jobs `running`.
    pub fn aliases_of(&self, running: &[String]) -> Vec<String> {
        self.lock()
            .aliases
            .iter()
            .filter(|(_, j)| running.contains(j))
            .map(|(a, _)| a.clone())
            .collect()
    }

    /// Tasks queued again (after a worker loss or failure), and backup
    /// attempts issued, so far for job `job`.
    pub fn requeued(&self, job: &str) -> (u64, u64) {
        let g = self.lock();
        (
            g.requeued.get(job).copied().unwrap_or(0),
            g.backups.get(job).copied().unwrap_or(0),
        )
    }

    /// Tasks queued with no attempt live (waiting for a worker), tasks
    /// running, and tasks queued again so far.
    pub fn task_counts(&self) -> (u64, u64, u64) {
        let g = self.lock();
        let mut queued = 0;
        let mut running = 0;
        for t in g.tasks.values() {
            match t.state {
                TaskState::Queued => queued += 1,
                TaskState::Running => running += 1,
                TaskState::Done => {}
            }
        }
        (queued, running, g.requeued_total)
    }

    /// The next task for the worker `session`, and its input, waiting up
    /// to `wait`.
    pub async fn next_task(
        &self,
        session: &str,
        wait: Duration,
    ) -> Result<Option<(v1::Task, Arc<TaskInput>)>, Refusal> {
        let deadline = tokio::time::Instant::now() + wait;
        loop {
            let notified = self.task_ready.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            if self.is_stopping() {
                return Err(Refusal::Stopping);
            }
            // This worker's own wake-up keeps a permit if it comes before
            // the wait does (`notify_one`): none is lost.
            let mine = {
                let mut g = self.lock();
                let now = Instant::now();
                let Some(w) = g.workers.get_mut(session) else {
                    return Err(Refusal::UnknownWorker);
                };
                w.last_beat = now;
                let mine = w.wake.clone();
                let tag = WorkerTag {
                    session: session.to_string(),
                    name: w.name.clone(),
                };
                if w.free()
                    && !quarantined_now(&g.quarantined, &tag.session, &tag.name, now)
                    && let Some(task) = self.pick(&mut g, &tag, now)
                {
                    return Ok(Some(task));
                }
                mine
            };
            tokio::select! {
                r = tokio::time::timeout_at(deadline, notified) => {
                    if r.is_err() {
                        return Ok(None);
                    }
                }
                _ = mine.notified() => {}
                _ = self.stop.notified() => return Err(Refusal::Stopping),
            }
        }
    }

    /// Gives the worker `tag` a task, if one it may take is queued: from
    /// the job with the fewest attempts running (so that a small job is
    /// not held to the pace of a large one), its first task, unless a
    /// later one's input is held here.
    fn pick(
        &self,
        g: &mut Inner,
        tag: &WorkerTag,
        now: Instant,
    ) -> Option<(v1::Task, Arc<TaskInput>)> {
        let room_retry = self.cfg.room_retry;
        // Per job with a task this worker may take: its first such task,
        // and the first whose input is here (by order of first appearance).
        let mut jobs: Vec<(&str, u64, Option<u64>)> = Vec::new();
        let tasks = &g.tasks;
        // Drops what is done or gone; notes the tasks the worker may take.
        let mut search = |q: &mut VecDeque<u64>| {
            q.retain(|id| {
                let Some(t) = tasks.get(id) else {
                    return false;
                };
                if t.state == TaskState::Done {
                    return false;
                }
                if t.refuses(tag, now, room_retry)
                    || t.live.values().any(|a| a.worker.session == tag.session)
                {
                    return true;
                }
                let mine = t.prefer.as_deref() == Some(tag.session.as_str());
                match jobs.iter_mut().find(|j| j.0 == t.task.job_id) {
                    Some(j) => {
                        if mine && j.2.is_none() {
                            j.2 = Some(*id);
                        }
                    }
                    None => jobs.push((&t.task.job_id, *id, mine.then_some(*id))),
                }
                true
            })
        };
        // Its own pinned tasks first: each is one whose input is here.
        if let Some(q) = g.pinned_queue.get_mut(&tag.session) {
            search(q);
        }
        search(&mut g.queue);
        if jobs.is_empty() {
            return None;
        }
        // Attempts running, by job.
        let mut running: HashMap<&str, usize> = HashMap::new();
        if jobs.len() > 1 {
            for w in g.workers.values() {
                for (id, _) in &w.running {
                    if let Some(t) = tasks.get(id) {
                        *running.entry(&t.task.job_id).or_default() += 1;
                    }
                }
            }
        }
        // Fewest attempts running; of those, the one served longest ago.
        let (job, first, mine) = *jobs
            .iter()
            .min_by_key(|j| {
                (
                    running.get(j.0).copied().unwrap_or(0),
                    g.last_given.get(j.0).copied(),
                )
            })
            .expect("not empty");
        let id = mine.unwrap_or(first);
        let job = job.to_string();
        g.last_given.insert(job, now);
        let pinned = g.pinned_queue.get_mut(&tag.session);
        match pinned.and_then(|q| Some((q.iter().position(|&x| x == id)?, q))) {
            Some((i, q)) => {
                q.remove(i);
            }
            None => {
                if let Some(i) = g.queue.iter().position(|&x| x == id) {
                    g.queue.remove(i);
                }
            }
        }
        let t = g.tasks.get_mut(&id).expect("picked");
        let attempt = t.next_attempt;
        t.next_attempt += 1;
        t.state = TaskState::Running;
        if !t.no_room.contains_key(&tag.session) {
            t.blocked_since = None;
        }
        t.live.insert(
            attempt,
            Attempt {
                worker: tag.clone(),
                since: now,
            },
        );
        let mut task = t.task.clone();
        task.attempt = attempt;
        let input = t.input.clone();
        if let Some(w) = g.workers.get_mut(&tag.session) {
            w.running.insert((id, attempt));
        }
        Some((task, input))
    }

    /// The input of a task the worker is running.
    pub fn task_input(&self, r: &v1::TaskRef) -> Result<(v1::Task, Arc<TaskInput>), Refusal> {
        let g = self.lock();
        let t = live_attempt(&g, r).ok_or(Refusal::NotYours)?;
        let mut task = t.task.clone();
        task.attempt = r.attempt;
        Ok((task, t.input.clone()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::task::Held;

    fn shared(dir: &std::path::Path) -> Arc<Shared> {
        Shared::new(Config {
            data_dir: dir.join("data"),
            tmp_dir: Some(dir.join("tmp")),
            ..Config::default()
        })
        .unwrap()
    }

    /// A shading's input, held by `pinned_to` alone if given.
    fn input(pinned_to: Option<&str>) -> Arc<TaskInput> {
        Arc::new(TaskInput {
            rays: None,
            results: None,
            results_offset: 0,
            objects: 1,
            model_triangles: 0,
            corners: 4,
            held: Held {
                at: pinned_to.map(str::to_string),
                pinned: pinned_to.is_some(),
                ..Held::default()
            },
        })
    }

    fn task(shard: u64) -> v1::Task {
        v1::Task {
            job_id: "job".into(),
            stage: v1::Stage::Shade as i32,
            first_ray: shard * 4,
            ray_count: 4,
            ..Default::default()
        }
    }

    /// Waits for a task for `session` in the background.
    fn wait_for_task(
        s: &Arc<Shared>,
        session: &str,
    ) -> tokio::task::JoinHandle<Option<(v1::Task, Arc<TaskInput>)>> {
        let (s, session) = (s.clone(), session.to_string());
        tokio::spawn(async move {
            s.next_task(&session, Duration::from_secs(30))
                .await
                .ok()
                .flatten()
        })
    }

    /// The first ray of the task `waiting` got within five seconds; panics
    /// with `why` if it got none by then.
    async fn first_ray_given(
        waiting: tokio::task::JoinHandle<Option<(v1::Task, Arc<TaskInput>)>>,
        why: &str,
    ) -> u64 {
        let (t, _) = tokio::time::timeout(Duration::from_secs(5), waiting)
            .await
            .expect(why)
            .unwrap()
            .expect("a task");
        t.first_ray
    }

    /// A task pinned to the worker holding its input wakes that worker
    /// (and no other takes it); a task any worker may take wakes the
    /// others waiting. A wake-up lost would leave a worker waiting out its
    /// poll (30 s here).
    #[tokio::test]
    async fn a_pinned_task_wakes_its_holder_and_others_wake_every_worker() {
        let dir = tempfile::tempdir().unwrap();
        let s = shared(dir.path());
        let (a, _) = s.register("a".into(), "here".into(), 1, 1 << 30);
        let (b, _) = s.register("b".into(), "here".into(), 1, 1 << 30);
        let (got_a, got_b) = (wait_for_task(&s, &a), wait_for_task(&s, &b));
        // Both wait before anything is queued.
        tokio::time::sleep(Duration::from_millis(200)).await;
        let (tx, _rx) = mpsc::unbounded_channel();

        s.enqueue(vec![(task(0), 0, input(Some(&a)))], &tx, &[]);
        assert_eq!(first_ray_given(got_a, "the holder was not woken").await, 0);
        tokio::time::sleep(Duration::from_millis(100)).await;
        assert!(!got_b.is_finished(), "another worker took a pinned task");

        s.enqueue(vec![(task(1), 1, input(None))], &tx, &[]);
        assert_eq!(
            first_ray_given(got_b, "a waiting worker was not woken").await,
            4
        );
    }

    /// Pinned tasks wait in their holder's own queue: the holder gets
    /// them (before a shared task queued earlier, since their input is
    /// there), another worker gets only shared tasks, and tasks forgotten
    /// leave no queue behind.
    #[tokio::test]
    async fn pinned_tasks_wait_in_their_holders_queue() {
        let dir = tempfile::tempdir().unwrap();
        let s = shared(dir.path());
        let (a, _) = s.register("a".into(), "here".into(), 1, 1 << 30);
        let (b, _) = s.register("b".into(), "here".into(), 1, 1 << 30);
        let (tx, _rx) = mpsc::unbounded_channel();
        let ids = s.enqueue(
            vec![
                (task(0), 0, input(None)),
                (task(1), 1, input(Some(&a))),
                (task(2), 2, input(Some(&a))),
            ],
            &tx,
            &[],
        );
        {
            let g = s.lock();
            assert_eq!(g.queue.len(), 1);
            assert_eq!(g.pinned_queue[&a].len(), 2);
        }
        let given = async |who: &str| -> Option<u64> {
            s.next_task(who, Duration::from_millis(50))
                .await
                .ok()
                .expect("the worker is known")
                .map(|(t, _)| t.first_ray)
        };
        assert_eq!(given(&a).await, Some(4), "the holder's pinned task first");
        assert_eq!(
            given(&b).await,
            Some(0),
            "the other worker gets the shared task"
        );
        assert_eq!(given(&b).await, None, "and never a pinned one");
        assert_eq!(s.lock().pinned_queue[&a].len(), 1, "a's other task waits");
        s.forget_tasks(&ids);
        let g = s.lock();
        assert!(g.queue.is_empty() && g.pinned_queue.is_empty());
    }
}
