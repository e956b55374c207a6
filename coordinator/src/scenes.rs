//! The coordinator's scenes: object databases it serves to workers by
//! scene hash (the hash of their chunks' BLAKE3 hashes, see
//! `sray_proto::scene_hash`), in chunks each with its own hash, so that a
//! worker can check every chunk and fetch again only what is damaged.
//!
//! Uploaded scenes live in the data directory as `HASH.sdb`; a local
//! render registers its database where it lies. No request names a path:
//! a hash is 64 hex digits and nothing else.

use anyhow::{Context, bail};
use sray_proto::scene_hash::hash_scene;
use sray_proto::wire::SCENE_CHUNK_BYTES;
use std::collections::HashMap;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

pub struct Scene {
    pub path: PathBuf,
    pub size: u64,
    pub chunk_hashes: Vec<[u8; 32]>,
}

impl Scene {
    pub fn chunk(&self, index: u64) -> anyhow::Result<Vec<u8>> {
        let chunk = SCENE_CHUNK_BYTES as u64;
        if index >= self.chunk_hashes.len() as u64 {
            bail!(
                "chunk {index} is beyond the scene's {} chunks",
                self.chunk_hashes.len()
            );
        }
        let len = (self.size - index * chunk).min(chunk) as usize;
        let mut buf = vec![0u8; len];
        let f = File::open(&self.path).with_context(|| self.path.display().to_string())?;
        f.read_exact_at(&mut buf, index * chunk)
            .with_context(|| self.path.display().to_string())?;
        Ok(buf)
    }
}

pub struct SceneStore {
    dir: PathBuf,
    scenes: Mutex<HashMap<String, Arc<Scene>>>,
    /// When each scene was last asked for (uploaded ones are evicted least
    /// recently used first when the store is over its cap).
    used: Mutex<HashMap<String, std::time::SystemTime>>,
}

pub fn valid_hash(hash: &str) -> bool {
    hash.len() == 64
        && hash
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// Hashes a file: its scene hash, size and chunk hashes.
pub fn hash_file(path: &Path) -> anyhow::Result<(String, u64, Vec<[u8; 32]>)> {
    let f = File::open(path).with_context(|| path.display().to_string())?;
    let h = hash_scene(f, SCENE_CHUNK_BYTES).with_context(|| path.display().to_string())?;
    Ok((h.hex, h.size, h.chunks))
}

impl SceneStore {
    pub fn new(dir: &Path) -> anyhow::Result<SceneStore> {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the data directory {}", dir.display()))?;
        // Uploads cut short by a killed coordinator.
        if let Ok(rd) = std::fs::read_dir(dir) {
            for f in rd.flatten() {
                let n = f.file_name().to_string_lossy().to_string();
                if n.starts_with("upload-") && n.ends_with(".part") {
                    let _ = std::fs::remove_file(f.path());
                }
            }
        }
        Ok(SceneStore {
            dir: dir.to_path_buf(),
            scenes: Mutex::new(HashMap::new()),
            used: Mutex::new(HashMap::new()),
        })
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// A scene by hash: known already, or found in the data directory
    /// (and checked against its name) after a restart.
    pub fn get(&self, hash: &str) -> anyhow::Result<Option<Arc<Scene>>> {
        if !valid_hash(hash) {
            bail!("'{hash}' is not a scene hash");
        }
        self.used
            .lock()
            .unwrap()
            .insert(hash.to_string(), std::time::SystemTime::now());
        if let Some(s) = self.scenes.lock().unwrap().get(hash) {
            return Ok(Some(s.clone()));
        }
        let path = self.dir.join(format!("{hash}.sdb"));
        if !path.is_file() {
            return Ok(None);
        }
        let (h, size, chunk_hashes) = hash_file(&path)?;
        if h != hash {
            tracing::warn!(path = %path.display(), "stored scene does not match its name; ignored");
            return Ok(None);
        }
        Ok(Some(self.insert(hash, path, size, chunk_hashes)))
    }

    fn insert(
        &self,
        hash: &str,
        path: PathBuf,
        size: u64,
        chunk_hashes: Vec<[u8; 32]>,
    ) -> Arc<Scene> {
        let s = Arc::new(Scene {
            path,
            size,
            chunk_hashes,
        });
        self.scenes
            .lock()
            .unwrap()
            .insert(hash.to_string(), s.clone());
        s
    }

    /// Registers a database where it lies (a local render); returns its hash.
    pub fn add_file(&self, path: &Path) -> anyhow::Result<String> {
        sray_engine::sdb::Database::open(path)?;
        let (hash, size, chunks) = hash_file(path)?;
        self.insert(&hash, path.to_path_buf(), size, chunks);
        Ok(hash)
    }

    /// Takes an uploaded file (written in the data directory), checks it
    /// is the database it claims to be and files it under its hash.
    pub fn add_upload(
        &self,
        tmp: tempfile::NamedTempFile,
        claimed: &str,
    ) -> anyhow::Result<String> {
        let (hash, size, chunks) = hash_file(tmp.path())?;
        if hash != claimed {
            bail!("the uploaded scene's hash is {hash}, not {claimed} as announced");
        }
        sray_engine::sdb::Database::open(tmp.path())
            .context("the uploaded scene is not a valid object database")?;
        let path = self.dir.join(format!("{hash}.sdb"));
        tmp.persist(&path)
            .with_context(|| path.display().to_string())?;
        self.insert(&hash, path, size, chunks);
        Ok(hash)
    }

    /// Removes uploaded scenes, least recently used first, until those in
    /// the data directory take at most `cap` bytes; never one in `keep`.
    pub fn evict(&self, cap: u64, keep: &[String]) {
        let Ok(rd) = std::fs::read_dir(&self.dir) else {
            return;
        };
        let used = self.used.lock().unwrap().clone();
        let mut files: Vec<(std::time::SystemTime, String, u64, PathBuf)> = rd
            .flatten()
            .filter_map(|f| {
                let name = f.file_name().to_string_lossy().to_string();
                let hash = name.strip_suffix(".sdb")?.to_string();
                if !valid_hash(&hash) {
                    return None;
                }
                let md = f.metadata().ok()?;
                let t = used
                    .get(&hash)
                    .copied()
                    .or_else(|| md.modified().ok())
                    .unwrap_or(std::time::UNIX_EPOCH);
                Some((t, hash, md.len(), f.path()))
            })
            .collect();
        let mut total: u64 = files.iter().map(|f| f.2).sum();
        if total <= cap {
            return;
        }
        files.sort();
        for (_, hash, size, path) in files {
            if total <= cap {
                break;
            }
            if keep.contains(&hash) {
                continue;
            }
            if std::fs::remove_file(&path).is_ok() {
                tracing::info!(scene = %hash, bytes = size, "scene evicted (the store is over --scene-store-max)");
                total -= size;
                self.scenes.lock().unwrap().remove(&hash);
                self.used.lock().unwrap().remove(&hash);
            }
        }
    }

    /// A temporary file in the data directory for an upload.
    pub fn upload_file(&self) -> anyhow::Result<tempfile::NamedTempFile> {
        tempfile::Builder::new()
            .prefix("upload-")
            .suffix(".part")
            .tempfile_in(&self.dir)
            .with_context(|| format!("cannot create a file in {}", self.dir.display()))
    }
}
