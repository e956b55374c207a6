//! A scene's identity: the BLAKE3 hash of its whole object database, and
//! the hashes of its chunks (the manifest that lets a worker fetch and
//! repair a copy chunk by chunk). The coordinator computes both when it
//! takes a scene; a worker computes both again to check its copy.

use std::io::Read;

/// Chunks read and hashed together: the whole-file hash runs on a second
/// thread while this one hashes the batch's chunks, which halves the wait
/// for a large scene (both hashes are single-threaded and equally costly).
const BATCH_CHUNKS: usize = 8;

/// Below this many bytes a batch is hashed on one thread: starting a
/// thread would cost more than it saves.
const SPLIT_BYTES: usize = 1 << 20;

pub struct SceneHash {
    /// The whole file's hash, in lowercase hex.
    pub hex: String,
    pub size: u64,
    /// The hash of each `chunk`-byte piece, the last one possibly shorter.
    pub chunks: Vec<[u8; 32]>,
}

/// Reads `r` to its end and hashes it whole and by pieces of `chunk` bytes.
pub fn hash_scene(mut r: impl Read, chunk: usize) -> std::io::Result<SceneHash> {
    let chunk = chunk.max(1);
    let mut whole = blake3::Hasher::new();
    let mut chunks = Vec::new();
    let mut buf = vec![0u8; chunk * BATCH_CHUNKS];
    let mut size = 0u64;
    loop {
        let got = read_full(&mut r, &mut buf)?;
        if got == 0 {
            break;
        }
        size += got as u64;
        let data = &buf[..got];
        let hash_chunks = |out: &mut Vec<[u8; 32]>| {
            out.extend(data.chunks(chunk).map(|c| *blake3::hash(c).as_bytes()));
        };
        if got < SPLIT_BYTES {
            whole.update(data);
            hash_chunks(&mut chunks);
        } else {
            std::thread::scope(|s| {
                s.spawn(|| whole.update(data));
                hash_chunks(&mut chunks);
            });
        }
        if got < buf.len() {
            break;
        }
    }
    Ok(SceneHash {
        hex: whole.finalize().to_hex().to_string(),
        size,
        chunks,
    })
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
    fn hashes_match_hashing_the_pieces_one_by_one() {
        // Sizes on both sides of the one-thread bound and of whole batches.
        for len in [0usize, 1, 999, 4096, 3 << 20, (8 << 20) + 17] {
            let data: Vec<u8> = (0..len).map(|i| (i * 7 + i / 251) as u8).collect();
            let chunk = if len > 1 << 20 { 1 << 19 } else { 1000 };
            let h = hash_scene(&data[..], chunk).unwrap();
            assert_eq!(h.size, len as u64);
            assert_eq!(h.hex, blake3::hash(&data).to_hex().to_string());
            let want: Vec<[u8; 32]> = data
                .chunks(chunk)
                .map(|c| *blake3::hash(c).as_bytes())
                .collect();
            assert_eq!(h.chunks, want, "len {len}");
        }
    }
}
