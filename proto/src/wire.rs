//! Records on the wire: packed little-endian bytes, exactly as the engine
//! keeps them in its files, in chunks of whole records.

use bytemuck::Pod;

// Records are sent as they lie in memory; every supported target is
// little-endian, and a big-endian build would silently disagree.
#[cfg(not(target_endian = "little"))]
compile_error!("sray's wire format assumes a little-endian target");

/// Bytes of records per message: large enough to amortise the per-message
/// cost, small enough to stay far below [`MAX_MESSAGE_BYTES`].
pub const RECORD_CHUNK_BYTES: usize = 1 << 20;
/// Bytes of an object database per scene chunk.
pub const SCENE_CHUNK_BYTES: usize = 1 << 20;
/// The largest message any side accepts.
pub const MAX_MESSAGE_BYTES: usize = 4 << 20;

#[derive(Debug, thiserror::Error)]
pub enum WireError {
    #[error("a chunk of {len} bytes does not hold whole {size}-byte records")]
    Ragged { len: usize, size: usize },
}

/// Records per chunk for records of type `T`.
pub fn records_per_chunk<T: Pod>() -> usize {
    (RECORD_CHUNK_BYTES / std::mem::size_of::<T>()).max(1)
}

/// The bytes of `recs`.
pub fn pack<T: Pod>(recs: &[T]) -> Vec<u8> {
    bytemuck::cast_slice(recs).to_vec()
}

/// Records from bytes (copied, so the bytes need no alignment).
pub fn unpack<T: Pod>(data: &[u8]) -> Result<Vec<T>, WireError> {
    let size = std::mem::size_of::<T>();
    if !data.len().is_multiple_of(size) {
        return Err(WireError::Ragged {
            len: data.len(),
            size,
        });
    }
    Ok(bytemuck::pod_collect_to_vec(data))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_round_trip_and_ragged_chunks_are_refused() {
        let v: Vec<[u64; 3]> = (0..1000).map(|i| [i, i * 2, !i]).collect();
        let b = pack(&v);
        assert_eq!(unpack::<[u64; 3]>(&b).unwrap(), v);
        // Unaligned input is fine.
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&b);
        assert_eq!(unpack::<[u64; 3]>(&shifted[1..]).unwrap(), v);
        assert!(unpack::<[u64; 3]>(&b[..b.len() - 1]).is_err());
    }
}
