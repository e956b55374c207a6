//! The worker's scene cache: object databases fetched from the coordinator
//! in chunks, stored under their content hash, verified chunk by chunk
//! (BLAKE3) whenever a job starts, and repaired by fetching again only the
//! chunks that do not match.
//!
//! A worker may also be given directories it shares with others (a
//! mount of the coordinator's data directory, or any directory holding
//! databases as `HASH.sdb`): each chunk is read from there first, checked
//! against its hash, and fetched from the coordinator only when missing
//! or damaged there, so that a hundred workers cost the coordinator no
//! scene bytes at all.

use anyhow::{Context, bail};
use sray_proto::net::Client;
use sray_proto::scene_hash::{hash_scene, scene_hash};
use sray_proto::v1;
use std::fs::{File, OpenOptions};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Tries per chunk before a fetch is given up.
const FETCH_TRIES: u32 = 3;
/// Largest chunk a manifest may announce.
const MAX_CHUNK: u32 = 16 << 20;

pub struct SceneCache {
    dir: PathBuf,
    /// Shared directories read before the coordinator is asked.
    shared: Vec<PathBuf>,
    /// Bytes of scenes kept; least recently used are removed past it.
    max: u64,
    /// Chunks fetched since start, and how many of those replaced a
    /// corrupt or missing chunk of an existing copy.
    pub chunks_fetched: AtomicU64,
    pub chunks_repaired: AtomicU64,
    /// Chunks read (and verified) from a shared directory instead.
    pub chunks_shared: AtomicU64,
}

/// A scene hash is 64 lowercase hex digits: it names a file in the cache
/// directory and must never name anything else.
pub fn check_hash(hash: &str) -> anyhow::Result<()> {
    if hash.len() == 64
        && hash
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
    {
        Ok(())
    } else {
        bail!("'{hash}' is not a scene hash")
    }
}

struct Manifest {
    size: u64,
    chunk: u64,
    hashes: Vec<[u8; 32]>,
}

impl SceneCache {
    pub fn new(dir: &Path, max: u64) -> anyhow::Result<SceneCache> {
        SceneCache::with_shared(dir, max, Vec::new())
    }

    /// A cache that reads chunks from `shared` directories (databases
    /// named `HASH.sdb`) before it asks the coordinator.
    pub fn with_shared(dir: &Path, max: u64, shared: Vec<PathBuf>) -> anyhow::Result<SceneCache> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the cache directory {}", dir.display()))?;
        Ok(SceneCache {
            dir: dir.to_path_buf(),
            shared,
            max,
            chunks_fetched: AtomicU64::new(0),
            chunks_repaired: AtomicU64::new(0),
            chunks_shared: AtomicU64::new(0),
        })
    }

    /// A verified local copy of scene `hash`.
    pub async fn ensure(&self, client: &mut Client, hash: &str) -> anyhow::Result<PathBuf> {
        Ok(self.check(client, hash, true).await?.0)
    }

    /// Checks (and repairs) the local copy of scene `hash`: its path, and
    /// whether it was fetched or repaired (written). `touch`: mark it used
    /// (for eviction), which a database open on it takes for a change.
    pub async fn check(
        &self,
        client: &mut Client,
        hash: &str,
        touch: bool,
    ) -> anyhow::Result<(PathBuf, bool)> {
        check_hash(hash)?;
        let m = client
            .scene_manifest(v1::SceneRef { hash: hash.into() })
            .await
            .with_context(|| format!("scene {hash}: manifest"))?
            .into_inner();
        let manifest = check_manifest(&m)?;
        // The scene hash is the hash of the manifest: one that does not
        // match it is refused before any chunk is trusted or fetched.
        if scene_hash(manifest.size, manifest.chunk, &manifest.hashes) != hash {
            bail!("scene {hash}: the coordinator's manifest does not match the scene's hash");
        }
        let path = self.dir.join(format!("{hash}.sdb"));
        let existing = std::fs::metadata(&path)
            .map(|md| md.len() == manifest.size)
            .unwrap_or(false);
        // A fresh copy is assembled in a file of its own (several workers
        // may share a cache directory) and renamed into place when whole.
        let part = if existing {
            None
        } else {
            let t = tempfile::Builder::new()
                .prefix(&format!("{hash}."))
                .suffix(".part")
                .tempfile_in(&self.dir)
                .with_context(|| format!("cannot create a file in {}", self.dir.display()))?;
            t.as_file()
                .set_len(manifest.size)
                .with_context(|| t.path().display().to_string())?;
            Some(t)
        };
        let work = part
            .as_ref()
            .map_or(path.clone(), |t| t.path().to_path_buf());
        let bad = if existing {
            let bad = verify(&work, &manifest).await?;
            if !bad.is_empty() {
                tracing::warn!(scene = hash, chunks = ?bad, "cached scene is corrupt: fetching those chunks again");
            }
            bad
        } else {
            (0..manifest.hashes.len()).collect()
        };
        let shared0 = self.chunks_shared.load(Ordering::Relaxed);
        for &i in &bad {
            self.fetch_chunk(client, hash, &manifest, i, &work).await?;
            if existing {
                self.chunks_repaired.fetch_add(1, Ordering::Relaxed);
            }
        }
        if !bad.is_empty() {
            let shared = self.chunks_shared.load(Ordering::Relaxed) - shared0;
            tracing::info!(
                scene = hash,
                chunks = bad.len(),
                from_shared = shared,
                from_coordinator = bad.len() as u64 - shared,
                "scene fetched"
            );
            let still = verify(&work, &manifest).await?;
            if !still.is_empty() {
                bail!(
                    "scene {hash}: chunks {still:?} still do not match after fetching them again"
                );
            }
        }
        if let Some(t) = part {
            t.persist(&path)
                .with_context(|| path.display().to_string())?;
        }
        // Last use is the file's access time, set here. Not its
        // modification time: that is part of the database's stamp, and a
        // worker with the file open (another worker sharing the cache)
        // would take a new one for a changed database and fail its task.
        // A symlink (a local render links the user's own database) is
        // left alone: the user's file is not ours to touch.
        let written = !bad.is_empty();
        if !(touch || written) {
            return Ok((path, false));
        }
        let linked = std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_symlink());
        if !linked && let Ok(f) = OpenOptions::new().write(true).open(&path) {
            let now = std::time::SystemTime::now();
            let _ = f.set_times(std::fs::FileTimes::new().set_accessed(now));
        }
        self.evict(hash);
        Ok((path, written))
    }

    /// Removes cached scenes, least recently used first, until the cache
    /// holds at most `max` bytes; never `keep` (the scene in use).
    fn evict(&self, keep: &str) {
        let Ok(rd) = std::fs::read_dir(&self.dir) else {
            return;
        };
        let mut files: Vec<(std::time::SystemTime, u64, PathBuf)> = rd
            .flatten()
            .filter_map(|f| {
                let name = f.file_name().to_string_lossy().to_string();
                let hash = name.strip_suffix(".sdb")?;
                if check_hash(hash).is_err() || hash == keep {
                    return None;
                }
                let md = std::fs::symlink_metadata(f.path()).ok()?;
                if !md.is_file() {
                    return None;
                }
                Some((md.accessed().ok()?, md.len(), f.path()))
            })
            .collect();
        let keep_size =
            std::fs::metadata(self.dir.join(format!("{keep}.sdb"))).map_or(0, |m| m.len());
        let mut total: u64 = keep_size + files.iter().map(|f| f.1).sum::<u64>();
        files.sort();
        for (_, size, path) in files {
            if total <= self.max {
                break;
            }
            if std::fs::remove_file(&path).is_ok() {
                tracing::info!(path = %path.display(), bytes = size, "cached scene evicted (--cache-max)");
                total -= size;
            }
        }
    }

    async fn fetch_chunk(
        &self,
        client: &mut Client,
        hash: &str,
        m: &Manifest,
        i: usize,
        path: &Path,
    ) -> anyhow::Result<()> {
        let want_len = (m.size - i as u64 * m.chunk).min(m.chunk) as usize;
        let write = |data: &[u8]| -> anyhow::Result<()> {
            let f = OpenOptions::new()
                .write(true)
                .open(path)
                .with_context(|| path.display().to_string())?;
            f.write_all_at(data, i as u64 * m.chunk)
                .with_context(|| path.display().to_string())
        };
        for dir in &self.shared {
            if let Some(data) = shared_chunk(&dir.join(format!("{hash}.sdb")), m, i, want_len) {
                write(&data)?;
                self.chunks_shared.fetch_add(1, Ordering::Relaxed);
                return Ok(());
            }
        }
        for attempt in 1..=FETCH_TRIES {
            let data = client
                .scene_chunk(v1::SceneChunkRequest {
                    hash: hash.into(),
                    index: i as u64,
                })
                .await
                .with_context(|| format!("scene {hash}: chunk {i}"))?
                .into_inner()
                .data;
            self.chunks_fetched.fetch_add(1, Ordering::Relaxed);
            if data.len() == want_len && *blake3::hash(&data).as_bytes() == m.hashes[i] {
                write(&data)?;
                return Ok(());
            }
            tracing::warn!(
                scene = hash,
                chunk = i,
                attempt,
                "chunk failed its checksum: fetching it again"
            );
        }
        bail!("scene {hash}: chunk {i} failed its checksum {FETCH_TRIES} times")
    }
}

/// Chunk `i` of the database at `path` (a shared directory's), if it is
/// there whole and matches its hash.
fn shared_chunk(path: &Path, m: &Manifest, i: usize, len: usize) -> Option<Vec<u8>> {
    let f = File::open(path).ok()?;
    let mut buf = vec![0u8; len];
    f.read_exact_at(&mut buf, i as u64 * m.chunk).ok()?;
    (*blake3::hash(&buf).as_bytes() == m.hashes[i]).then_some(buf)
}

fn check_manifest(m: &v1::SceneManifestReply) -> anyhow::Result<Manifest> {
    if m.chunk_size == 0 || m.chunk_size > MAX_CHUNK {
        bail!(
            "scene manifest: chunk size {} is out of range",
            m.chunk_size
        );
    }
    let chunk = m.chunk_size as u64;
    let n = m.size.div_ceil(chunk);
    if m.chunk_hashes.len() as u64 != n {
        bail!(
            "scene manifest: {} chunk hashes for {} chunks",
            m.chunk_hashes.len(),
            n
        );
    }
    let mut hashes = Vec::with_capacity(n as usize);
    for h in &m.chunk_hashes {
        hashes.push(
            <[u8; 32]>::try_from(h.as_slice())
                .map_err(|_| anyhow::anyhow!("scene manifest: a chunk hash is not 32 bytes"))?,
        );
    }
    Ok(Manifest {
        size: m.size,
        chunk,
        hashes,
    })
}

/// Reads the file once: the chunks that do not match the manifest.
async fn verify(path: &Path, m: &Manifest) -> anyhow::Result<Vec<usize>> {
    let path = path.to_path_buf();
    let (chunk, size) = (m.chunk as usize, m.size);
    let hashes = m.hashes.clone();
    tokio::task::spawn_blocking(move || -> anyhow::Result<Vec<usize>> {
        let f = File::open(&path).with_context(|| path.display().to_string())?;
        let got = hash_scene(f, chunk).with_context(|| path.display().to_string())?;
        if got.size != size {
            // It changed since its size was checked (a local render's link
            // to a database being rewritten): no chunk can be trusted.
            bail!(
                "{}: {} bytes where the scene has {size}: the file changed while it was checked",
                path.display(),
                got.size
            );
        }
        Ok((0..hashes.len())
            .filter(|&i| got.chunks.get(i) != Some(&hashes[i]))
            .collect())
    })
    .await?
}
