//! Tiles read from a database file on demand, through a cache of a fixed
//! number of bytes: the textures of a scene may be many times the memory
//! a render has, and it holds only the tiles it used last.
//!
//! What a texel is does not depend on the cache: a tile is the same bytes
//! whenever it is read, so the image is the same whatever the cache's size
//! or the order of the reads. How many tiles are read does depend on them
//! (as the bytes a scan reads depend on the memory): it is reported, not
//! compared.
//!
//! Sampling cannot return an error (it runs inside shading and the
//! intersection tests): a tile that cannot be read or is corrupt gives
//! zero texels, and its error is kept for the tracer, which fails the
//! render with it ([`TileStore::error`]) instead of writing a wrong image.

use super::mip::{TILE_BYTES, TILE_TEXELS, TileTexels};
use crate::error::Error;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Where one tile lies in the file: its offset from the database's start,
/// its stored size (zstd-compressed when the database is) and the CRC-32
/// of the stored bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileRef {
    pub offset: u64,
    pub stored: u32,
    pub crc: u32,
}

/// Tiles kept, by (texture, tile) key, with the stamp of their last use,
/// and the keys by stamp: the least recently used goes first.
#[derive(Default)]
struct Lru {
    tiles: HashMap<u64, (Arc<TileTexels>, u64)>,
    by_use: BTreeMap<u64, u64>,
    clock: u64,
}

impl Lru {
    fn get(&mut self, key: u64) -> Option<Arc<TileTexels>> {
        let (tile, stamp) = self.tiles.get_mut(&key)?;
        self.by_use.remove(stamp);
        self.clock += 1;
        *stamp = self.clock;
        self.by_use.insert(self.clock, key);
        Some(tile.clone())
    }

    fn put(&mut self, key: u64, tile: Arc<TileTexels>, capacity: usize) {
        if self.tiles.contains_key(&key) {
            return;
        }
        while self.tiles.len() >= capacity {
            let Some((_, old)) = self.by_use.pop_first() else {
                break;
            };
            self.tiles.remove(&old);
        }
        self.clock += 1;
        self.tiles.insert(key, (tile, self.clock));
        self.by_use.insert(self.clock, key);
    }
}

/// What a render read of its textures.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct TileReads {
    pub texture_tiles_read: u64,
    /// Bytes of tiles read, as stored (compressed or not).
    pub texture_bytes_read: u64,
}

/// The tiles of one database file, cached.
pub struct TileStore {
    path: PathBuf,
    file: File,
    compressed: bool,
    /// Tiles the cache keeps.
    capacity: usize,
    lru: Mutex<Lru>,
    tiles_read: AtomicU64,
    bytes_read: AtomicU64,
    /// The first failed read: where, and why.
    error: Mutex<Option<(String, String)>>,
}

impl std::fmt::Debug for TileStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TileStore")
            .field("path", &self.path)
            .field("capacity", &self.capacity)
            .finish()
    }
}

impl TileStore {
    /// The tiles of `path`, compressed or not, cached in at most
    /// `cache_bytes` (at least 16 tiles: a bilinear sample needs four).
    pub fn open(path: &Path, compressed: bool, cache_bytes: u64) -> Result<TileStore, Error> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        Ok(TileStore {
            path: path.to_path_buf(),
            file,
            compressed,
            capacity: ((cache_bytes / TILE_BYTES as u64) as usize).max(16),
            lru: Mutex::new(Lru::default()),
            tiles_read: AtomicU64::new(0),
            bytes_read: AtomicU64::new(0),
            error: Mutex::new(None),
        })
    }

    /// Bytes the cache may hold.
    pub fn cache_bytes(&self) -> u64 {
        (self.capacity * TILE_BYTES) as u64
    }

    /// Tile `tile` of texture `texture`, stored at `at`, `extent()`
    /// columns and rows inside its level; zero texels (and the error kept)
    /// when it cannot be read.
    pub fn tile(
        &self,
        texture: u32,
        tile: u32,
        at: &TileRef,
        extent: impl FnOnce() -> (u32, u32),
    ) -> Arc<TileTexels> {
        let key = (texture as u64) << 32 | tile as u64;
        if let Some(t) = self.lru.lock().expect("tile cache").get(key) {
            return t;
        }
        // Read outside the lock: other threads go on sampling cached
        // tiles meanwhile (two threads may read the same tile once each).
        let (cols, rows) = extent();
        let t = match self.read(at, cols, rows) {
            Ok(t) => Arc::new(t),
            Err(e) => {
                let mut err = self.error.lock().expect("tile error");
                if err.is_none() {
                    *err = Some((format!("texture {texture}, tile {tile}"), e));
                }
                return Arc::new([[0; 4]; TILE_TEXELS]);
            }
        };
        self.lru
            .lock()
            .expect("tile cache")
            .put(key, t.clone(), self.capacity);
        t
    }

    fn read(&self, at: &TileRef, cols: u32, rows: u32) -> Result<TileTexels, String> {
        let mut stored = vec![0u8; at.stored as usize];
        read_at(&self.file, &mut stored, at.offset).map_err(|e| format!("cannot read: {e}"))?;
        self.tiles_read.fetch_add(1, Ordering::Relaxed);
        self.bytes_read
            .fetch_add(at.stored as u64, Ordering::Relaxed);
        if !cfg!(fuzzing) && crc32fast::hash(&stored) != at.crc {
            return Err("checksum mismatch: the tile is corrupt".into());
        }
        let want = (4 * cols * rows) as usize;
        let packed = if self.compressed {
            zstd::bulk::decompress(&stored, want)
                .map_err(|e| format!("the tile does not decompress: {e}"))?
        } else {
            stored
        };
        super::mip::unpack(&packed, cols, rows).ok_or_else(|| {
            format!(
                "the tile holds {} bytes, not the {want} of {cols} x {rows} texels",
                packed.len()
            )
        })
    }

    /// What has been read so far.
    pub fn reads(&self) -> TileReads {
        TileReads {
            texture_tiles_read: self.tiles_read.load(Ordering::Relaxed),
            texture_bytes_read: self.bytes_read.load(Ordering::Relaxed),
        }
    }

    /// The first tile that could not be read, if any: the render that
    /// sampled it must fail.
    pub fn error(&self) -> Option<Error> {
        let err = self.error.lock().expect("tile error");
        err.as_ref().map(|(location, message)| Error::Database {
            file: self.path.clone(),
            location: location.clone(),
            message: message.clone(),
        })
    }
}

#[cfg(unix)]
fn read_at(f: &File, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(f, buf, offset)
}

#[cfg(windows)]
fn read_at(f: &File, mut buf: &mut [u8], mut offset: u64) -> std::io::Result<()> {
    while !buf.is_empty() {
        let n = std::os::windows::fs::FileExt::seek_read(f, buf, offset)?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        buf = &mut buf[n..];
        offset += n as u64;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cache_keeps_its_capacity_and_the_last_used() {
        let mut lru = Lru::default();
        let tile = |v: u8| Arc::new([[v; 4]; TILE_TEXELS]);
        for k in 0..3 {
            lru.put(k, tile(k as u8), 3);
        }
        // Using 0 makes 1 the oldest.
        assert!(lru.get(0).is_some());
        lru.put(3, tile(3), 3);
        assert_eq!(lru.tiles.len(), 3);
        assert!(lru.get(1).is_none());
        assert_eq!(lru.get(0).unwrap()[0], [0; 4]);
        assert_eq!(lru.get(3).unwrap()[0], [3; 4]);
        assert_eq!(lru.by_use.len(), 3);
    }
}
