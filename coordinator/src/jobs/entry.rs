//! A job as the coordinator holds it: who may see it (its secret), what
//! its watchers, `sray status` and the dashboard are told (its log,
//! progress, state and a preview), and the table of all jobs.

use super::files::{latest_frame, unix_now};
use anyhow::Context;
use sray_proto::v1;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Where a job stands.
#[derive(Clone, Debug, PartialEq)]
pub enum JobState {
    Running,
    Done,
    Failed(String),
}

/// What watchers see of a job.
pub struct JobView {
    pub progress: Option<v1::JobProgress>,
    pub log: Vec<String>,
    pub state: JobState,
    pub finished: Option<Instant>,
    /// Its render settings (known once checked; for status and previews).
    pub params: Option<v1::RenderParams>,
    /// Unix seconds (0: not yet).
    pub submitted_unix: u64,
    pub started_unix: u64,
    pub finished_unix: u64,
    /// When its driver started (in this run), for the ETA.
    pub started: Option<Instant>,
    /// Shards done per round, for status.
    pub rounds: Vec<v1::RoundStatus>,
}

pub struct JobEntry {
    pub id: String,
    pub(super) secret_hash: [u8; 32],
    pub dir: PathBuf,
    pub scene: String,
    pub view: Mutex<JobView>,
    changed: tokio::sync::watch::Sender<u64>,
    pub cancelled: AtomicBool,
    pub driver: Mutex<Option<tokio::task::AbortHandle>>,
    /// The last preview encoded: the checkpoint round it shows, and the PNG.
    preview: Mutex<Option<(u32, Arc<Vec<u8>>)>>,
}

impl JobEntry {
    pub fn view(&self) -> std::sync::MutexGuard<'_, JobView> {
        self.view.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn touch(&self) {
        self.changed.send_modify(|v| *v += 1);
    }

    pub fn subscribe(&self) -> tokio::sync::watch::Receiver<u64> {
        self.changed.subscribe()
    }

    pub fn set_progress(&self, p: v1::JobProgress) {
        let mut v = self.view();
        v.progress = Some(p);
        let at = match v.rounds.iter().position(|r| r.round == p.round) {
            Some(i) => i,
            None => {
                v.rounds.push(v1::RoundStatus {
                    round: p.round,
                    rays: p.rays,
                    shards: p.shards_total,
                    ..Default::default()
                });
                v.rounds.len() - 1
            }
        };
        let r = &mut v.rounds[at];
        if p.stage == v1::Stage::Shade as i32 {
            r.intersect_done = r.shards;
            r.shade_done = p.shards_done;
        } else {
            r.intersect_done = p.shards_done;
        }
        drop(v);
        self.touch();
    }

    /// The job's settings, once checked.
    pub fn set_params(&self, p: v1::RenderParams) {
        self.view().params = Some(p);
    }

    /// Its driver starts (or resumes).
    pub fn set_started(&self) {
        let mut v = self.view();
        v.started = Some(Instant::now());
        v.started_unix = unix_now();
    }

    /// What `sray status` and the dashboard show of the job.
    pub fn status(&self) -> v1::JobStatus {
        let v = self.view();
        let p = v.params.unwrap_or_default();
        let (state, error) = match &v.state {
            JobState::Running => ("running", String::new()),
            JobState::Done => ("done", String::new()),
            JobState::Failed(e) => ("failed", e.clone()),
        };
        let (round, stage) = v.progress.map_or((0, 0), |p| (p.round, p.stage));
        let percent = match &v.state {
            JobState::Done => 100.0,
            _ => match v.progress {
                // Rounds are at most max_depth (the eye ray is depth 1);
                // each round is half intersection, half shading.
                Some(pr) if pr.shards_total > 0 => {
                    let f = pr.shards_done as f64 / pr.shards_total as f64;
                    let stage_f = if pr.stage == v1::Stage::Shade as i32 {
                        0.5 + 0.5 * f
                    } else {
                        0.5 * f
                    };
                    let rounds = p.max_depth.max(pr.round).max(1) as f64;
                    (100.0 * ((pr.round.max(1) - 1) as f64 + stage_f) / rounds).clamp(0.0, 99.9)
                }
                _ => 0.0,
            },
        };
        let eta = match (&v.state, v.started) {
            (JobState::Running, Some(t)) if percent > 0.0 => {
                t.elapsed().as_secs_f64() * (100.0 - percent) / percent
            }
            (JobState::Running, _) => -1.0,
            _ => 0.0,
        };
        v1::JobStatus {
            id: self.id.clone(),
            scene: self.scene.clone(),
            width: p.width,
            height: p.height,
            samples: p.samples,
            max_depth: p.max_depth,
            state: state.into(),
            error,
            round,
            stage,
            progress_percent: percent,
            eta_seconds: eta,
            submitted_unix: v.submitted_unix,
            started_unix: v.started_unix,
            finished_unix: v.finished_unix,
            rounds: v.rounds.clone(),
            log: v.log.iter().rev().take(20).rev().cloned().collect(),
        }
    }

    /// A PNG of the image as far as the coordinator has it: the finished
    /// image, or the frame of the last checkpoint (black before the first
    /// round ends). Encoded again only when a round has ended since.
    pub fn preview_png(&self) -> anyhow::Result<Arc<Vec<u8>>> {
        let (params, state) = {
            let v = self.view();
            (v.params, v.state.clone())
        };
        let params = params.context("the job's settings are not known yet")?;
        if state == JobState::Done {
            for name in ["preview.png", "image.bin"] {
                if let Ok(b) = std::fs::read(self.dir.join(name))
                    && b.starts_with(b"\x89PNG")
                {
                    return Ok(Arc::new(b));
                }
            }
        }
        let round = latest_frame(&self.dir).unwrap_or(0);
        if let Some((r, png)) = &*self.preview.lock().unwrap_or_else(|p| p.into_inner())
            && *r == round
            && state == JobState::Running
        {
            return Ok(png.clone());
        }
        let (opts, _) = sray_worker::params::from_proto(&params, 0).map_err(anyhow::Error::msg)?;
        let mut frame =
            sray_engine::render::Frame::with_sampling(opts.width, opts.height, opts.sampling());
        if round > 0 {
            // Removed by the next checkpoint meanwhile: the black frame
            // this once.
            if let Ok(b) = std::fs::read(self.dir.join(format!("frame-{round}.bin")))
                && b.len() == frame.slots.len() * 24
            {
                frame.slots = bytemuck::pod_collect_to_vec(&b);
            }
        }
        let png = Arc::new(frame.encode(sray_engine::render::ImageFormat::Png)?);
        *self.preview.lock().unwrap_or_else(|p| p.into_inner()) = Some((round, png.clone()));
        Ok(png)
    }

    /// A line of the job's log: to its watchers, the coordinator's log,
    /// and (at the next checkpoint) the journal.
    pub fn log(&self, line: String) {
        tracing::info!(job = %self.id, "{line}");
        let mut v = self.view();
        if v.log.len() < 1000 {
            v.log.push(line);
        }
        drop(v);
        self.touch();
    }

    pub fn set_state(&self, s: JobState) {
        let mut v = self.view();
        if s != JobState::Running {
            v.finished = Some(Instant::now());
            v.finished_unix = unix_now();
        }
        v.state = s;
        drop(v);
        self.touch();
    }

    pub fn is_running(&self) -> bool {
        self.view().state == JobState::Running
    }
}

/// All jobs, running and finished.
pub struct Jobs {
    pub dir: PathBuf,
    map: Mutex<HashMap<String, Arc<JobEntry>>>,
}

/// Why a job could not be had.
pub enum JobRefusal {
    NoSuchJob,
    WrongSecret,
}

fn secret_hash(secret: &str) -> [u8; 32] {
    *blake3::hash(secret.as_bytes()).as_bytes()
}

impl Jobs {
    pub fn new(data_dir: &Path) -> anyhow::Result<Jobs> {
        let dir = data_dir.join("jobs");
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create {}", dir.display()))?;
        Ok(Jobs {
            dir,
            map: Mutex::new(HashMap::new()),
        })
    }

    fn map(&self) -> std::sync::MutexGuard<'_, HashMap<String, Arc<JobEntry>>> {
        self.map.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A new job: a random id and secret (returned; only its hash is kept).
    pub fn create(&self, scene: &str) -> anyhow::Result<(Arc<JobEntry>, String)> {
        let id = sray_proto::ids::new_job_id();
        let secret = sray_proto::ids::new_secret();
        let dir = self.dir.join(&id);
        std::fs::create_dir_all(&dir).with_context(|| dir.display().to_string())?;
        let e = self.insert(
            id,
            secret_hash(&secret),
            dir,
            scene.to_string(),
            JobState::Running,
        );
        Ok((e, secret))
    }

    pub(super) fn insert(
        &self,
        id: String,
        secret_hash: [u8; 32],
        dir: PathBuf,
        scene: String,
        state: JobState,
    ) -> Arc<JobEntry> {
        let e = Arc::new(JobEntry {
            id: id.clone(),
            secret_hash,
            dir,
            scene,
            view: Mutex::new(JobView {
                progress: None,
                log: Vec::new(),
                finished: (state != JobState::Running).then(Instant::now),
                state,
                params: None,
                submitted_unix: unix_now(),
                started_unix: 0,
                finished_unix: 0,
                started: None,
                rounds: Vec::new(),
            }),
            changed: tokio::sync::watch::channel(0).0,
            cancelled: AtomicBool::new(false),
            driver: Mutex::new(None),
            preview: Mutex::new(None),
        });
        self.map().insert(id, e.clone());
        e
    }

    /// The job `id`, if `secret` is its secret.
    pub fn get(&self, id: &str, secret: &str) -> Result<Arc<JobEntry>, JobRefusal> {
        let e = self.map().get(id).cloned().ok_or(JobRefusal::NoSuchJob)?;
        if !sray_proto::ids::same(&secret_hash(secret), &e.secret_hash) {
            return Err(JobRefusal::WrongSecret);
        }
        Ok(e)
    }

    /// The job `id`, without its secret: for the operator's views
    /// (status, the dashboard), never for its image or to act on it.
    pub fn find(&self, id: &str) -> Option<Arc<JobEntry>> {
        self.map().get(id).cloned()
    }

    pub fn running(&self) -> Vec<Arc<JobEntry>> {
        self.map()
            .values()
            .filter(|e| e.is_running())
            .cloned()
            .collect()
    }

    pub fn all(&self) -> Vec<Arc<JobEntry>> {
        self.map().values().cloned().collect()
    }

    pub(crate) fn remove(&self, id: &str) {
        self.map().remove(id);
    }

    pub fn wake_all(&self) {
        for e in self.all() {
            e.touch();
        }
    }
}
