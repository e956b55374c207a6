//! A scene's identity. An object database is cut into chunks of a fixed
//! size, each hashed with BLAKE3 (the manifest that lets a worker fetch
//! and repair a copy chunk by chunk); the scene hash is the BLAKE3 hash of
//! the database's size, the chunk size and that list of chunk hashes. So
//! every byte is hashed once, chunks on as many threads as there are cores,
//! and a worker checks a manifest against the scene hash before it trusts
//! a single chunk hash of it.

use std::io::Read;

/// Chunks read and hashed together, spread over the threads.
const BATCH_CHUNKS: usize = 8;

/// Below this many bytes a batch is hashed on one thread: starting threads
/// would cost more than it saves.
const SPLIT_BYTES: usize = 1 << 20;

/// Most threads one hash takes.
const MAX_THREADS: usize = 8;

/// BLAKE3's key derivation context for scene hashes: they can never equal
/// the plain hash of any file or of any other list.
const CONTEXT: &str = "sray 2026-12 scene hash: size, chunk size, chunk hashes";

pub struct SceneHash {
    /// The scene hash, in lowercase hex.
    pub hex: String,
    pub size: u64,
    /// The hash of each `chunk`-byte piece, the last one possibly shorter.
    pub chunks: Vec<[u8; 32]>,
}

/// The scene hash (lowercase hex) of a database of `size` bytes whose
/// `chunk`-byte pieces hash to `chunks`.
pub fn scene_hash(size: u64, chunk: u64, chunks: &[[u8; 32]]) -> String {
    let mut h = blake3::Hasher::new_derive_key(CONTEXT);
    h.update(&size.to_le_bytes());
    h.update(&chunk.to_le_bytes());
    for c in chunks {
        h.update(c);
    }
    h.finalize().to_hex().to_string()
}

/// Reads `r` to its end and hashes it by pieces of `chunk` bytes.
pub fn hash_scene(mut r: impl Read, chunk: usize) -> std::io::Result<SceneHash> {
    let chunk = chunk.max(1);
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .clamp(1, MAX_THREADS);
    let mut chunks = Vec::new();
    let mut buf = vec![0u8; chunk * BATCH_CHUNKS];
    let mut size = 0u64;
    loop {
        let got = read_full(&mut r, &mut buf)?;
        if got == 0 {
            break;
        }
        size += got as u64;
        let pieces: Vec<&[u8]> = buf[..got].chunks(chunk).collect();
        let first = chunks.len();
        chunks.resize(first + pieces.len(), [0u8; 32]);
        let out = &mut chunks[first..];
        if got < SPLIT_BYTES || threads == 1 || pieces.len() == 1 {
            hash_pieces(&pieces, out);
        } else {
            // Contiguous runs of pieces, one per thread (this one included).
            let per = pieces.len().div_ceil(threads);
            std::thread::scope(|s| {
                let mut groups = pieces.chunks(per).zip(out.chunks_mut(per));
                let mine = groups.next();
                for (p, o) in groups {
                    s.spawn(move || hash_pieces(p, o));
                }
                if let Some((p, o)) = mine {
                    hash_pieces(p, o);
                }
            });
        }
        if got < buf.len() {
            break;
        }
    }
    Ok(SceneHash {
        hex: scene_hash(size, chunk as u64, &chunks),
        size,
        chunks,
    })
}

fn hash_pieces(pieces: &[&[u8]], out: &mut [[u8; 32]]) {
    for (p, o) in pieces.iter().zip(out) {
        *o = *blake3::hash(p).as_bytes();
    }
}

/// Fills `buf` from `r` as far as the input goes.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_hash_as_the_pieces_one_by_one_and_the_list_names_the_scene() {
        // Sizes on both sides of the one-thread bound and of whole batches.
        for len in [0usize, 1, 999, 4096, 3 << 20, (8 << 20) + 17] {
            let data: Vec<u8> = (0..len).map(|i| (i * 7 + i / 251) as u8).collect();
            let chunk = if len > 1 << 20 { 1 << 19 } else { 1000 };
            let h = hash_scene(&data[..], chunk).unwrap();
            assert_eq!(h.size, len as u64);
            let want: Vec<[u8; 32]> = data
                .chunks(chunk)
                .map(|c| *blake3::hash(c).as_bytes())
                .collect();
            assert_eq!(h.chunks, want, "len {len}");
            assert_eq!(h.hex, scene_hash(len as u64, chunk as u64, &want));
        }
    }

    #[test]
    fn the_scene_hash_covers_size_chunking_and_every_chunk() {
        let a = [[1u8; 32], [2u8; 32]];
        let base = scene_hash(1500, 1000, &a);
        assert_ne!(base, scene_hash(1501, 1000, &a));
        assert_ne!(base, scene_hash(1500, 1024, &a));
        assert_ne!(base, scene_hash(1500, 1000, &[[1u8; 32], [3u8; 32]]));
        assert_ne!(base, scene_hash(1500, 1000, &a[..1]));
        // Not the plain hash of the list.
        assert_ne!(
            base,
            blake3::hash(&[[1u8; 32], [2u8; 32]].concat())
                .to_hex()
                .to_string()
        );
    }
}
