//! Records on the wire: little-endian, as the engine keeps them in its
//! files, compressed and exact ([`encode`], protocol 4), in chunks of whole
//! records. [`pack`] and [`unpack`] give the plain bytes.

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
    #[error("a compressed chunk is malformed: {0}")]
    Malformed(String),
    #[error("a packed chunk is malformed: {0}")]
    Packed(String),
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

/// zstd level of [`encode`]: the fastest levels already find the
/// redundancy the transform exposes.
const ZSTD_LEVEL: i32 = 1;

/// One thread's zstd contexts and buffers, kept from chunk to chunk:
/// making a compression context clears about a megabyte, and fresh
/// megabyte buffers cost a page fault per 4 KiB each time (profiled with
/// one local worker, the chunks' buffers and contexts were half of all
/// page faults of a render).
struct Codec {
    compressor: zstd::bulk::Compressor<'static>,
    decompressor: zstd::bulk::Decompressor<'static>,
    /// The byte planes of the chunk at hand (only its first bytes count).
    planes: Vec<u8>,
    /// The compressed frame being made.
    frame: Vec<u8>,
}

thread_local! {
    static CODEC: std::cell::RefCell<Option<Codec>> = const { std::cell::RefCell::new(None) };
}

/// Runs `f` with this thread's [`Codec`], made on first use.
fn with_codec<R>(f: impl FnOnce(&mut Codec) -> std::io::Result<R>) -> std::io::Result<R> {
    CODEC.with(|c| {
        let mut c = c.borrow_mut();
        if c.is_none() {
            *c = Some(Codec {
                compressor: zstd::bulk::Compressor::new(ZSTD_LEVEL)?,
                decompressor: zstd::bulk::Decompressor::new()?,
                planes: Vec::new(),
                frame: Vec::new(),
            });
        }
        f(c.as_mut().expect("made above"))
    })
}

/// The first `len` bytes of `buf`, grown if it is shorter; their contents
/// are whatever was there (every caller overwrites them all).
fn scratch(buf: &mut Vec<u8>, len: usize) -> &mut [u8] {
    if buf.len() < len {
        buf.resize(len, 0);
    }
    &mut buf[..len]
}

/// Records packed compactly and exactly (protocol 4): each record is
/// seen as 64-bit words; every word is replaced by its difference to the
/// same word of the previous record (wrapping), the differences are
/// split into byte planes (all first bytes, then all second bytes, ...),
/// and the planes are compressed with zstd. Sorted ids become runs of
/// ones, equal neighbours (the origins of a hit's shadow and reflection
/// rays, padding, a ray's kind and depth) runs of zeros, and the high
/// bytes of nearby floats runs of small numbers; the low bytes of floats
/// stay as they are, so decoding gives back every bit. Records whose size
/// is not a multiple of 8 bytes are split into bytes instead of words.
///
/// Layout: the record count (u32 little-endian), then the zstd frame.
pub fn encode<T: Pod>(recs: &[T]) -> Vec<u8> {
    encode_bytes(bytemuck::cast_slice(recs), std::mem::size_of::<T>())
}

/// [`encode`] of records given as their bytes, `size` bytes each (for a
/// thread that encodes records of any type).
///
/// # Panics
/// If `bytes` does not hold whole records.
pub fn encode_bytes(bytes: &[u8], size: usize) -> Vec<u8> {
    assert!(
        size > 0 && bytes.len().is_multiple_of(size),
        "whole records of {size} bytes"
    );
    let n = bytes.len() / size;
    with_codec(|c| {
        let planes = scratch(&mut c.planes, bytes.len());
        if size == 1 {
            // Bytes: one plane, as they are.
            planes.copy_from_slice(bytes);
        } else if size.is_multiple_of(8) {
            for j in 0..size / 8 {
                let mut prev = 0u64;
                for (i, rec) in bytes.chunks_exact(size).enumerate() {
                    let w = rec[j * 8..j * 8 + 8].try_into().expect("8 bytes");
                    let v = u64::from_le_bytes(w);
                    let d = v.wrapping_sub(prev).to_le_bytes();
                    prev = v;
                    for (b, &x) in d.iter().enumerate() {
                        planes[(j * 8 + b) * n + i] = x;
                    }
                }
            }
        } else {
            for (i, rec) in bytes.chunks_exact(size).enumerate() {
                for (b, &x) in rec.iter().enumerate() {
                    planes[b * n + i] = x;
                }
            }
        }
        c.frame.clear();
        c.frame
            .reserve(zstd::zstd_safe::compress_bound(planes.len()));
        c.compressor.compress_to_buffer(&*planes, &mut c.frame)?;
        let mut out = Vec::with_capacity(4 + c.frame.len());
        out.extend_from_slice(&(n as u32).to_le_bytes());
        out.extend_from_slice(&c.frame);
        Ok(out)
    })
    .expect("compressing into a buffer of the bound's size cannot fail")
}

/// The records of a chunk as it came: `raw` (the records as they lie in
/// memory, see `RecordChunk.raw`) or [`encode`]d; at most `max` of them.
pub fn decode_chunk<T: Pod>(data: &[u8], raw: bool, max: usize) -> Result<Vec<T>, WireError> {
    if !raw {
        return decode(data, max);
    }
    let size = std::mem::size_of::<T>();
    if data.len() / size > max {
        return Err(WireError::Malformed("too many records".into()));
    }
    unpack(data)
}

/// [`decode_chunk`] of one-byte records: the bytes are decompressed
/// straight into the vector returned (no planes to undo, nothing zeroed
/// or copied first).
pub fn decode_bytes(data: &[u8], raw: bool, max: usize) -> Result<Vec<u8>, WireError> {
    if raw {
        if data.len() > max {
            return Err(WireError::Malformed("too many records".into()));
        }
        return Ok(data.to_vec());
    }
    let bad = |m: &str| WireError::Malformed(m.to_string());
    let (head, body) = data
        .split_first_chunk::<4>()
        .ok_or_else(|| bad("no record count"))?;
    let n = u32::from_le_bytes(*head) as usize;
    if n > max {
        return Err(bad("too many records"));
    }
    let mut out = Vec::with_capacity(n);
    with_codec(|c| {
        let got = c.decompressor.decompress_to_buffer(body, &mut out)?;
        if got != n {
            return Err(std::io::Error::other(
                "the record count and the data disagree",
            ));
        }
        Ok(())
    })
    .map_err(|e| bad(&e.to_string()))?;
    Ok(out)
}

/// The records of an [`encode`]d chunk; at most `max` of them (a bound
/// on what a malformed chunk may make the receiver allocate).
pub fn decode<T: Pod>(data: &[u8], max: usize) -> Result<Vec<T>, WireError> {
    let size = std::mem::size_of::<T>();
    let bad = |m: &str| WireError::Malformed(m.to_string());
    let (head, body) = data
        .split_first_chunk::<4>()
        .ok_or_else(|| bad("no record count"))?;
    let n = u32::from_le_bytes(*head) as usize;
    if n > max {
        return Err(bad("too many records"));
    }
    let want = n * size;
    let mut out: Vec<T> = vec![T::zeroed(); n];
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
    with_codec(|c| {
        // Exactly the room the count allows: a frame that holds more
        // does not fit, one that holds less is caught by the length.
        let planes = scratch(&mut c.planes, want);
        let got = c.decompressor.decompress_to_buffer(body, planes)?;
        if got != want {
            return Err(std::io::Error::other(
                "the record count and the data disagree",
            ));
        }
        if size == 1 {
            bytes.copy_from_slice(planes);
        } else if size.is_multiple_of(8) {
            for j in 0..size / 8 {
                let mut prev = 0u64;
                for i in 0..n {
                    let mut d = [0u8; 8];
                    for (b, x) in d.iter_mut().enumerate() {
                        *x = planes[(j * 8 + b) * n + i];
                    }
                    prev = prev.wrapping_add(u64::from_le_bytes(d));
                    bytes[i * size + j * 8..i * size + j * 8 + 8]
                        .copy_from_slice(&prev.to_le_bytes());
                }
            }
        } else {
            for i in 0..n {
                for b in 0..size {
                    bytes[i * size + b] = planes[b * n + i];
                }
            }
        }
        Ok(())
    })
    .map_err(|e| bad(&e.to_string()))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_decode_as_one_byte_records() {
        let v: Vec<u8> = (0..5000u32).map(|i| (i * i % 251) as u8).collect();
        let e = encode(&v);
        assert_eq!(decode_bytes(&e, false, 5000).unwrap(), v);
        assert_eq!(decode::<u8>(&e, 5000).unwrap(), v);
        assert!(decode_bytes(&e, false, 4999).is_err());
        assert_eq!(decode_bytes(&v, true, 5000).unwrap(), v);
        assert!(decode_bytes(&v, true, 4999).is_err());
        // A count that the data do not fill, or overflow: refused.
        let mut more = e.clone();
        more[0] ^= 1;
        assert!(decode_bytes(&more, false, 1 << 20).is_err());
        let mut less = e.clone();
        less[0] = less[0].wrapping_sub(2);
        assert!(decode_bytes(&less, false, 1 << 20).is_err());
    }

    #[test]
    fn raw_chunks_are_the_records_as_they_lie() {
        let v: Vec<[u64; 3]> = (0..100u64).map(|i| [i, i * 7, u64::MAX - i]).collect();
        let raw = pack(&v);
        assert_eq!(decode_chunk::<[u64; 3]>(&raw, true, 100).unwrap(), v);
        // More than the bound, a part of a record, or a raw chunk read as
        // an encoded one: refused.
        assert!(decode_chunk::<[u64; 3]>(&raw, true, 99).is_err());
        assert!(decode_chunk::<[u64; 3]>(&raw[..raw.len() - 1], true, 100).is_err());
        assert!(decode_chunk::<[u64; 3]>(&raw, false, 100).is_err());
        // An encoded chunk still decodes when it says it is one.
        assert_eq!(
            decode_chunk::<[u64; 3]>(&encode(&v), false, 100).unwrap(),
            v
        );
    }

    #[test]
    fn encoded_records_round_trip_exactly() {
        let v: Vec<[u64; 3]> = (0..1000u64)
            .map(|i| [i, (i as f64 * 0.37).sin().to_bits(), !i])
            .collect();
        let e = encode(&v);
        assert!(e.len() < pack(&v).len());
        assert_eq!(decode::<[u64; 3]>(&e, 1000).unwrap(), v);
        assert!(decode::<[u64; 3]>(&e, 999).is_err());
        assert!(decode::<[u64; 3]>(&e[..e.len() - 3], 1000).is_err());
        assert!(decode::<[u8; 3]>(&e, 10_000).is_err());
        let odd: Vec<[u8; 3]> = (0..100u8).map(|i| [i, i ^ 7, 1]).collect();
        assert_eq!(decode::<[u8; 3]>(&encode(&odd), 100).unwrap(), odd);
        let none: Vec<[u64; 2]> = Vec::new();
        assert_eq!(decode::<[u64; 2]>(&encode(&none), 0).unwrap(), none);
    }

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
