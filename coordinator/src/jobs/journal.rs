//! A job's journal: its record (`job.json`), the checkpoint at the end
//! of every round, its outcome, and reading them all back when the
//! coordinator starts.

use super::entry::{JobEntry, JobState, Jobs};
use super::files::{remove_stale, unhex, unix_now, write_atomic};
use anyhow::{Context, bail};
use prost::Message;
use sray_engine::bf::RayRec;
use sray_engine::spill::{RecordFile, RecordWriter, Records, SpillDir};
use sray_proto::v1;
use std::fs::File;
use std::io::{BufReader, Read, Write};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

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
