//! Packed colour (what a worker that keeps its records sends of a
//! shading, `sray_proto::colour`) on arbitrary bytes. The coordinator
//! adds what it reads straight into the frame, so reading must end in
//! entries inside the frame or an error, never a panic; bytes fed in two
//! slices must read as they do whole (chunks arrive in pieces); and
//! packing what was read must keep every slot's sum.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sray_proto::colour::{Reader, SlotColour, pack, unpack};

/// Entries read from `parts` one after another with a frame of `limit`
/// slots, or the error.
fn read(parts: &[&[u8]], limit: u64) -> Result<Vec<SlotColour>, String> {
    let mut r = Reader::new(limit);
    let mut v = Vec::new();
    for p in parts {
        r.feed(p, &mut |c| v.push(c)).map_err(|e| e.to_string())?;
    }
    r.finish().map_err(|e| e.to_string())?;
    Ok(v)
}

/// Each slot's colour, summed exactly.
fn sums(v: &[SlotColour], limit: u64) -> Vec<[i128; 3]> {
    let mut s = vec![[0i128; 3]; limit as usize];
    for c in v {
        for slot in c.slot as u64..c.end() {
            for k in 0..3 {
                s[slot as usize][k] += c.rgb[k] as i128;
            }
        }
    }
    s
}

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    // A frame of up to 4,096 slots, a split point, then the bytes.
    let limit = u16::from_le_bytes([data[0], data[1]]) as u64 % 4097;
    let body = &data[4..];
    let split = u16::from_le_bytes([data[2], data[3]]) as usize % (body.len() + 1);
    let whole = read(&[body], limit);
    let halves = read(&[&body[..split], &body[split..]], limit);
    assert_eq!(whole, halves, "slices read as the whole");
    let Ok(v) = whole else {
        // Without a frame limit, the reader refuses or reads; never panics.
        let _ = unpack(body, 1 << 16);
        return;
    };
    for c in &v {
        assert!(c.end() <= limit, "an entry past the frame");
    }
    let before = sums(&v, limit);
    let mut again = v.clone();
    let packed = pack(&mut again);
    let back = read(&[&packed], limit).expect("packed colour reads back");
    assert_eq!(sums(&back, limit), before, "packing keeps every slot's sum");
});
