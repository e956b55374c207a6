//! The coordinator's jobs: who may see them, what their clients are told,
//! and their journal on disk, so that a coordinator that stops (SIGTERM)
//! or dies (SIGKILL, power loss) resumes every unfinished job from its
//! last finished round, and keeps finished images fetchable for
//! `job_retention`.
//!
//! Journal: `DATA_DIR/jobs/ID/`, written at the end of every round:
//!
//! - `rays-R.bin`: the rays of round R (the next one to run), packed
//!   records as on the wire; `frame-R.bin`: the fixed-point frame after
//!   round R - 1 (the sums of every finished round);
//! - `job.json`: the request (the protobuf `JobSpec`, hex), the hash of the
//!   job's secret (never the secret), the round to resume at, the totals
//!   so far and the job's log; written last, so it only ever names files
//!   that are whole;
//! - when the job ends, `image.bin` and `stats.json` (or the error).
//!
//! Every file is written to a temporary name, fsynced and renamed, and the
//! directory fsynced, so a crash at any point leaves the previous round's
//! checkpoint or the new one, never a mix. The scene itself is in the
//! scene store (`DATA_DIR/HASH.sdb`), by content hash.

use crate::state::{Config, Shared};
use anyhow::{Context, bail};
use prost::Message;
use sray_engine::bf::RayRec;
use sray_engine::spill::{RecordFile, RecordWriter, Records, SpillDir};
use sray_proto::v1;
use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

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
    secret_hash: [u8; 32],
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

    fn insert(
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

    fn remove(&self, id: &str) {
        self.map().remove(id);
    }

    pub fn wake_all(&self) {
        for e in self.all() {
            e.touch();
        }
    }
}

// ---- the journal ----

/// `job.json`.
#[derive(Clone, serde::Serialize, serde::Deserialize, Default)]
pub struct Record {
    pub version: u32,
    pub id: String,
    pub secret_blake3: String,
    /// The request, protobuf-encoded, hex.
    pub spec: String,
    pub scene: String,
    /// "running", "done" or "failed".
    pub state: String,
    pub error: String,
    /// The round to run next (its rays are `rays-ROUND.bin`); 0: no
    /// round finished yet.
    pub round: u32,
    /// Rays in `rays-ROUND.bin`.
    pub rays: u64,
    pub totals: serde_json::Value,
    pub log: Vec<String>,
    pub finished_unix: u64,
    #[serde(default)]
    pub submitted_unix: u64,
}

fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// Writes `name` in `dir` crash-safely: a temporary file, fsync, rename,
/// fsync of the directory.
pub fn write_atomic(
    dir: &Path,
    name: &str,
    fill: impl FnOnce(&mut BufWriter<&File>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let tmp = dir.join(format!("{name}.tmp"));
    let f = File::create(&tmp).with_context(|| tmp.display().to_string())?;
    {
        let mut w = BufWriter::with_capacity(1 << 20, &f);
        fill(&mut w)?;
        w.flush().with_context(|| tmp.display().to_string())?;
    }
    f.sync_all().with_context(|| tmp.display().to_string())?;
    drop(f);
    let path = dir.join(name);
    std::fs::rename(&tmp, &path).with_context(|| path.display().to_string())?;
    File::open(dir)
        .and_then(|d| d.sync_all())
        .with_context(|| dir.display().to_string())?;
    Ok(())
}

impl Record {
    pub fn new(e: &JobEntry, spec: &v1::JobSpec) -> Record {
        Record {
            version: 1,
            id: e.id.clone(),
            secret_blake3: sray_proto::ids::hex(&e.secret_hash),
            spec: sray_proto::ids::hex(&spec.encode_to_vec()),
            scene: e.scene.clone(),
            state: "running".into(),
            submitted_unix: e.view().submitted_unix,
            ..Default::default()
        }
    }

    pub fn spec(&self) -> anyhow::Result<v1::JobSpec> {
        let bytes = unhex(&self.spec).context("job.json: spec is not hex")?;
        Ok(v1::JobSpec::decode(bytes.as_slice())?)
    }

    fn save(&self, dir: &Path) -> anyhow::Result<()> {
        let json = serde_json::to_vec_pretty(self)?;
        write_atomic(dir, "job.json", |w| Ok(w.write_all(&json)?))
    }
}

fn unhex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

/// The checkpoint at the end of a round: the next round's rays, the frame
/// so far, then the record naming them; older rounds' files go.
pub fn checkpoint(
    e: &JobEntry,
    rec: &mut Record,
    next_round: u32,
    frame: &[[i64; 3]],
    rays: Option<&Records<RayRec>>,
    totals: serde_json::Value,
) -> anyhow::Result<()> {
    let dir = &e.dir;
    let rays_name = format!("rays-{next_round}.bin");
    write_atomic(dir, &rays_name, |w| {
        // In memory: written a part at a time, as the parts lie.
        if let Some(rays) = rays {
            rays.for_each_slice(&mut |s| {
                w.write_all(bytemuck::cast_slice(s))
                    .map_err(|e| sray_engine::Error::io(&rays_name, e))
            })?;
        }
        Ok(())
    })?;
    write_atomic(dir, &format!("frame-{next_round}.bin"), |w| {
        Ok(w.write_all(bytemuck::cast_slice(frame))?)
    })?;
    rec.round = next_round;
    rec.rays = rays.map_or(0, |r| r.len());
    rec.totals = totals;
    rec.log = e.view().log.clone();
    rec.save(dir)?;
    remove_stale(dir, Some(next_round));
    Ok(())
}

/// The round of the newest checkpoint frame in `dir`.
fn latest_frame(dir: &Path) -> Option<u32> {
    std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .filter_map(|f| {
            f.file_name()
                .to_str()?
                .strip_prefix("frame-")?
                .strip_suffix(".bin")?
                .parse::<u32>()
                .ok()
        })
        .max()
}

/// Removes temporary files and the files of rounds other than `keep`.
fn remove_stale(dir: &Path, keep: Option<u32>) {
    let Ok(rd) = std::fs::read_dir(dir) else {
        return;
    };
    for f in rd.flatten() {
        let name = f.file_name().to_string_lossy().to_string();
        let round_file = name
            .strip_suffix(".bin")
            .and_then(|s| s.strip_prefix("rays-").or_else(|| s.strip_prefix("frame-")))
            .and_then(|n| n.parse::<u32>().ok());
        let stale = name.ends_with(".tmp") || round_file.is_some_and(|r| Some(r) != keep);
        if stale {
            let _ = std::fs::remove_file(f.path());
        }
    }
}

/// The job ended well: the image and statistics, then the record.
pub fn finish(e: &JobEntry, rec: &mut Record, image: &[u8], stats: &str) -> anyhow::Result<()> {
    write_atomic(&e.dir, "image.bin", |w| Ok(w.write_all(image)?))?;
    write_atomic(&e.dir, "stats.json", |w| Ok(w.write_all(stats.as_bytes())?))?;
    rec.state = "done".into();
    rec.finished_unix = unix_now();
    rec.log = e.view().log.clone();
    rec.save(&e.dir)?;
    remove_stale(&e.dir, None);
    Ok(())
}

/// The job failed (or was cancelled): the error is kept for its client.
pub fn fail(e: &JobEntry, rec: &mut Record, error: &str) -> anyhow::Result<()> {
    rec.state = "failed".into();
    rec.error = error.to_string();
    rec.finished_unix = unix_now();
    rec.log = e.view().log.clone();
    rec.save(&e.dir)?;
    remove_stale(&e.dir, None);
    Ok(())
}

/// A finished job's image and statistics.
pub fn result(e: &JobEntry) -> anyhow::Result<(Vec<u8>, String)> {
    let image = std::fs::read(e.dir.join("image.bin")).context("the job's image")?;
    let stats = std::fs::read_to_string(e.dir.join("stats.json")).context("the job's stats")?;
    Ok((image, stats))
}

/// A checkpoint read back: the frame and the rays of the round to run.
pub struct Resume {
    pub round: u32,
    pub frame: Vec<[i64; 3]>,
    pub rays: Option<RecordFile<RayRec>>,
    pub totals: serde_json::Value,
}

/// Reads a running job's checkpoint into the spill directory.
pub fn load_checkpoint(
    dir: &Path,
    rec: &Record,
    slots: u64,
    spill: &SpillDir,
) -> anyhow::Result<Option<Resume>> {
    if rec.round == 0 {
        return Ok(None);
    }
    let frame_bytes = std::fs::read(dir.join(format!("frame-{}.bin", rec.round)))?;
    if frame_bytes.len() as u64 != slots * 24 {
        bail!(
            "the checkpoint's frame has {} bytes, not {}",
            frame_bytes.len(),
            slots * 24
        );
    }
    let frame: Vec<[i64; 3]> = bytemuck::pod_collect_to_vec(&frame_bytes);
    let path = dir.join(format!("rays-{}.bin", rec.round));
    let size = std::fs::metadata(&path)?.len();
    let rec_size = std::mem::size_of::<RayRec>() as u64;
    if size != rec.rays * rec_size {
        bail!(
            "the checkpoint's rays file has {size} bytes, not {}",
            rec.rays * rec_size
        );
    }
    let rays = if rec.rays == 0 {
        None
    } else {
        let mut rd = BufReader::with_capacity(1 << 20, File::open(&path)?);
        let mut w = RecordWriter::<RayRec>::create(spill, "resumed")?;
        let mut buf = vec![0u8; rec_size as usize * 4096];
        let mut left = rec.rays;
        while left > 0 {
            let n = left.min(4096);
            let b = &mut buf[..(n * rec_size) as usize];
            rd.read_exact(b)?;
            w.extend(&bytemuck::pod_collect_to_vec::<u8, RayRec>(b))?;
            left -= n;
        }
        Some(w.finish()?)
    };
    Ok(Some(Resume {
        round: rec.round,
        frame,
        rays,
        totals: rec.totals.clone(),
    }))
}

/// Reads every job's record at start: finished ones become fetchable
/// again (until their retention ends), running ones are returned to be
/// resumed. Unreadable directories are logged and left alone.
pub fn load_all(jobs: &Jobs, retention: Duration) -> Vec<(Arc<JobEntry>, Record)> {
    let mut resume = Vec::new();
    let Ok(rd) = std::fs::read_dir(&jobs.dir) else {
        return resume;
    };
    for d in rd.flatten() {
        let dir = d.path();
        let name = d.file_name().to_string_lossy().to_string();
        if !sray_proto::ids::is_hex_id(&name, 32) {
            continue;
        }
        let rec: Record = match std::fs::read(dir.join("job.json"))
            .map_err(anyhow::Error::from)
            .and_then(|b| Ok(serde_json::from_slice(&b)?))
        {
            Ok(r) => r,
            Err(e) => {
                // Submitted but never checkpointed, or damaged.
                tracing::warn!(dir = %dir.display(), error = %e, "job without a readable record: removed");
                let _ = std::fs::remove_dir_all(&dir);
                continue;
            }
        };
        let Some(hash) = unhex(&rec.secret_blake3).and_then(|h| <[u8; 32]>::try_from(h).ok())
        else {
            continue;
        };
        let state = match rec.state.as_str() {
            "done" => JobState::Done,
            "failed" => JobState::Failed(rec.error.clone()),
            _ => JobState::Running,
        };
        if state != JobState::Running {
            let age = Duration::from_secs(unix_now().saturating_sub(rec.finished_unix));
            if age >= retention {
                let _ = std::fs::remove_dir_all(&dir);
                continue;
            }
        }
        remove_stale(&dir, (state == JobState::Running).then_some(rec.round));
        let e = jobs.insert(name, hash, dir, rec.scene.clone(), state.clone());
        {
            let mut v = e.view();
            v.log = rec.log.clone();
            v.params = rec.spec().ok().and_then(|s| s.params);
            v.submitted_unix = rec.submitted_unix;
            if state != JobState::Running {
                v.finished_unix = rec.finished_unix;
            }
            if state != JobState::Running {
                let age = Duration::from_secs(unix_now().saturating_sub(rec.finished_unix));
                v.finished = Instant::now().checked_sub(age).or(Some(Instant::now()));
            }
        }
        if state == JobState::Running {
            resume.push((e, rec));
        }
    }
    resume
}

/// The coordinator's spill directory: a fixed place per data directory,
/// emptied at start, so that the files of a coordinator that was killed
/// are removed by the next one.
pub fn spill_dir(cfg: &Config) -> anyhow::Result<(SpillDir, PathBuf)> {
    std::fs::create_dir_all(&cfg.data_dir).with_context(|| {
        format!(
            "cannot create the data directory {}",
            cfg.data_dir.display()
        )
    })?;
    let canon = std::fs::canonicalize(&cfg.data_dir)?;
    let tag = &blake3::hash(canon.as_os_str().as_encoded_bytes()).to_hex()[..16];
    let base = cfg.tmp_dir.clone().unwrap_or_else(|| cfg.data_dir.clone());
    let dir = base.join(format!("sray-coordinator-{tag}"));
    if dir.exists() {
        let n = std::fs::read_dir(&dir).map_or(0, |r| r.count());
        if n > 0 {
            tracing::info!(dir = %dir.display(), "removing the spill files of an earlier run");
        }
        std::fs::remove_dir_all(&dir).with_context(|| dir.display().to_string())?;
    }
    Ok((SpillDir::new(Some(&dir))?, dir))
}

/// Expires finished jobs past their retention and evicts scenes over the
/// store's cap (least recently used first, never one a running job uses).
pub fn housekeeping(shared: &Shared) {
    let now = Instant::now();
    for e in shared.jobs.all() {
        let expired = {
            let v = e.view();
            v.state != JobState::Running
                && v.finished
                    .is_some_and(|f| now.duration_since(f) >= shared.cfg.job_retention)
        };
        if expired {
            shared.jobs.remove(&e.id);
            match std::fs::remove_dir_all(&e.dir) {
                Ok(()) => tracing::info!(job = %e.id, "finished job expired: removed"),
                Err(err) => {
                    tracing::warn!(job = %e.id, error = %err, "finished job expired, but its journal could not be removed")
                }
            }
        }
    }
    let in_use: Vec<String> = shared
        .jobs
        .running()
        .iter()
        .map(|e| e.scene.clone())
        .collect();
    shared.scenes.evict(shared.cfg.scene_store_max, &in_use);
}
