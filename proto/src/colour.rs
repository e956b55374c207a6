//! Colour added to frame slots, packed (`RECORD_KIND_COLOUR`, protocol
//! 11): what a worker that keeps its records sends of a shading instead
//! of 32-byte contributions. Within a chunk the entries are sorted by
//! slot and a slot's colours are added together first, and each entry
//! takes only the bytes its numbers need, behind a tag that says how
//! many: the receiver reads an entry with a few independent loads (no
//! 32-byte records to rebuild from byte planes, no chain of varints).
//!
//! A chunk's bytes (encoded as one-byte records by `wire::encode`, or
//! raw): the entry count n (u32, little-endian), then n entries, each
//! - a tag (u16, little-endian): bits 0-1 and 2-3 give the bytes of the
//!   slot's distance and of the run (0, 1, 2 or 4), bits 4-7, 8-11 and
//!   12-15 those of the three channels' differences (0 to 8);
//! - the slot's distance to the slot of the entry before (the first
//!   entry's, from slot 0), little-endian in as many bytes;
//! - the run: how many slots after it get the same colour too;
//! - per channel, the zigzag of the colour's difference (wrapping) to the
//!   same channel of the entry before (the first entry's, from 0).
//!
//! Sums of fixed-point colours are exact in any order while they stay far
//! from saturation, so adding a slot's colours together before they
//! travel changes no pixel; [`pack`] adds only colours below 2^62 (the
//! sum of two fits), as the frame adds saturating.

use crate::wire::WireError;

/// Colour added to `run + 1` frame slots from `slot` on (the fields of
/// the engine's `Contribution`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct SlotColour {
    pub slot: u32,
    pub run: u32,
    pub rgb: [i64; 3],
}

impl SlotColour {
    /// One past the last slot it adds to.
    pub fn end(&self) -> u64 {
        self.slot as u64 + self.run as u64 + 1
    }
}

/// The most bytes of packed colour a chunk may hold (what a receiver
/// allocates at most for one). A sender's chunks of 32,768 entries take
/// at most 40 bytes an entry.
pub const MAX_CHUNK_BYTES: usize = crate::wire::MAX_MESSAGE_BYTES;

/// The longest item: an entry's tag, two 4-byte and three 8-byte numbers.
const MAX_ITEM: usize = 2 + 4 + 4 + 3 * 8;

/// Bytes from an item's start that a reader loads 8 bytes at a time from.
const LOADS: usize = MAX_ITEM + 8;

/// Bytes of a slot distance or a run, by their 2-bit code.
const SHORT: [usize; 4] = [0, 1, 2, 4];

fn small(c: &[i64; 3]) -> bool {
    c.iter().all(|x| x.unsigned_abs() < 1 << 62)
}

/// Sorts `v` by slot, adds the colours of a slot together (those below
/// 2^62), joins a slot of the same colour as the one before into its run,
/// and packs the result as a chunk.
pub fn pack(v: &mut Vec<SlotColour>) -> Vec<u8> {
    v.sort_by_key(|x| x.slot);
    let mut merged: Vec<SlotColour> = Vec::with_capacity(v.len());
    for x in v.drain(..) {
        if let Some(last) = merged.last_mut() {
            if last.run == 0
                && x.run == 0
                && last.slot == x.slot
                && small(&last.rgb)
                && small(&x.rgb)
            {
                for (a, b) in last.rgb.iter_mut().zip(x.rgb) {
                    *a += b;
                }
                continue;
            }
            if last.rgb == x.rgb && last.end() == x.slot as u64 {
                last.run += x.run + 1;
                continue;
            }
        }
        merged.push(x);
    }
    pack_sorted(&merged)
}

/// The 2-bit code of a slot distance or a run.
fn short_code(x: u32) -> u16 {
    match x {
        0 => 0,
        1..=0xff => 1,
        0x100..=0xffff => 2,
        _ => 3,
    }
}

/// Packs entries already sorted by slot, as they are.
///
/// # Panics
/// If they are not sorted by slot.
pub fn pack_sorted(v: &[SlotColour]) -> Vec<u8> {
    let mut out = Vec::with_capacity(4 + v.len() * 16);
    out.extend_from_slice(&(v.len() as u32).to_le_bytes());
    let (mut slot, mut rgb) = (0u32, [0i64; 3]);
    for x in v {
        assert!(x.slot >= slot, "entries sorted by slot");
        let gap = x.slot - slot;
        let z = std::array::from_fn::<u64, 3, _>(|k| {
            let d = x.rgb[k].wrapping_sub(rgb[k]);
            ((d << 1) ^ (d >> 63)) as u64
        });
        let zl = z.map(|z| (64 - z.leading_zeros() as usize).div_ceil(8));
        let (gc, rc) = (short_code(gap), short_code(x.run));
        let tag = gc | rc << 2 | (zl[0] as u16) << 4 | (zl[1] as u16) << 8 | (zl[2] as u16) << 12;
        out.extend_from_slice(&tag.to_le_bytes());
        out.extend_from_slice(&gap.to_le_bytes()[..SHORT[gc as usize]]);
        out.extend_from_slice(&x.run.to_le_bytes()[..SHORT[rc as usize]]);
        for (z, l) in z.iter().zip(zl) {
            out.extend_from_slice(&z.to_le_bytes()[..l]);
        }
        slot = x.slot;
        rgb = x.rgb;
    }
    out
}

/// `l` bytes (at most 8) at `b[at..]`, little-endian; `b` holds 8 bytes
/// from `at`.
#[inline(always)]
fn load(b: &[u8], at: usize, l: usize) -> u64 {
    let w = u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"));
    if l >= 8 {
        w
    } else {
        w & ((1u64 << (8 * l)) - 1)
    }
}

/// Reads packed chunks one after another from bytes that come in slices
/// of any length (a chunk as it arrived, or chunks read back from a spill
/// file in pieces), calling `f` for each entry.
pub struct Reader {
    /// Entries must end at or below this slot.
    limit: u64,
    /// Slots the entries read cover, in all (runs counted whole).
    pub slots: u64,
    /// The start of an item split between slices.
    carry: Vec<u8>,
    /// Entries left in the chunk at hand (none: a count comes next).
    left: u64,
    slot: u32,
    rgb: [i64; 3],
    /// Entries read, in all.
    pub entries: u64,
}

impl Default for Reader {
    fn default() -> Self {
        Reader::new(u64::MAX)
    }
}

impl Reader {
    /// A reader that refuses entries past slot `limit` (the frame's).
    pub fn new(limit: u64) -> Reader {
        Reader {
            limit,
            slots: 0,
            carry: Vec::new(),
            left: 0,
            slot: 0,
            rgb: [0; 3],
            entries: 0,
        }
    }

    /// Reads the next item (a chunk's count, or an entry) from `b[*at..]`:
    /// `Ok(false)` if the bytes end first (nothing consumed).
    #[inline(always)]
    fn item(
        &mut self,
        b: &[u8],
        at: &mut usize,
        f: &mut impl FnMut(SlotColour),
    ) -> Result<bool, WireError> {
        let p = *at;
        let have = b.len() - p;
        if self.left == 0 {
            if have < 4 {
                return Ok(false);
            }
            self.left = u32::from_le_bytes(b[p..p + 4].try_into().expect("4 bytes")) as u64;
            self.slot = 0;
            self.rgb = [0; 3];
            *at = p + 4;
            return Ok(true);
        }
        if have < LOADS {
            // Near the end: read from a copy with room for the loads.
            let mut tmp = [0u8; LOADS];
            tmp[..have].copy_from_slice(&b[p..]);
            return match self.entry(&tmp, 0, have, f)? {
                Some(n) => {
                    *at = p + n;
                    Ok(true)
                }
                None => Ok(false),
            };
        }
        match self.entry(b, p, have, f)? {
            Some(n) => {
                *at = p + n;
                Ok(true)
            }
            None => Ok(false),
        }
    }

    /// Reads an entry at `b[p..]` (which holds [`LOADS`] bytes, of which
    /// `have` count): its length, or `None` if it is longer than `have`.
    #[inline(always)]
    fn entry(
        &mut self,
        b: &[u8],
        p: usize,
        have: usize,
        f: &mut impl FnMut(SlotColour),
    ) -> Result<Option<usize>, WireError> {
        if have < 2 {
            return Ok(None);
        }
        let tag = u16::from_le_bytes([b[p], b[p + 1]]) as usize;
        let (gl, rl) = (SHORT[tag & 3], SHORT[tag >> 2 & 3]);
        let zl = [tag >> 4 & 15, tag >> 8 & 15, tag >> 12];
        if zl.iter().any(|&l| l > 8) {
            return Err(WireError::Packed("a colour longer than 8 bytes".into()));
        }
        let q = p + 2 + gl + rl;
        let len = 2 + gl + rl + zl[0] + zl[1] + zl[2];
        if len > have {
            return Ok(None);
        }
        let gap = load(b, p + 2, gl);
        let run = load(b, p + 2 + gl, rl) as u32;
        let z = [
            load(b, q, zl[0]),
            load(b, q + zl[0], zl[1]),
            load(b, q + zl[0] + zl[1], zl[2]),
        ];
        let mut rgb = self.rgb;
        for (c, z) in rgb.iter_mut().zip(z) {
            *c = c.wrapping_add(((z >> 1) as i64) ^ -((z & 1) as i64));
        }
        let slot = u32::try_from(self.slot as u64 + gap)
            .map_err(|_| WireError::Packed("a slot past 2^32".into()))?;
        let end = slot as u64 + run as u64 + 1;
        if end > self.limit {
            return Err(WireError::Packed(format!(
                "a contribution to pixel corners {slot}..{end} of {}",
                self.limit
            )));
        }
        self.slot = slot;
        self.rgb = rgb;
        self.left -= 1;
        self.entries += 1;
        self.slots += end - slot as u64;
        f(SlotColour { slot, run, rgb });
        Ok(Some(len))
    }

    /// Reads the entries `b` completes (what it leaves unfinished is
    /// kept for the next slice).
    pub fn feed(&mut self, mut b: &[u8], f: &mut impl FnMut(SlotColour)) -> Result<(), WireError> {
        if !self.carry.is_empty() {
            // Finish the split item from the head of `b`.
            let had = self.carry.len();
            let take = b.len().min(MAX_ITEM);
            self.carry.extend_from_slice(&b[..take]);
            let carry = std::mem::take(&mut self.carry);
            let mut at = 0;
            let done = self.item(&carry, &mut at, f)?;
            if !done {
                if take == b.len() {
                    self.carry = carry;
                    return Ok(());
                }
                return Err(WireError::Packed("an entry cut short".into()));
            }
            debug_assert!(at > had);
            b = &b[at - had..];
        }
        let mut at = 0;
        while at < b.len() {
            self.bulk(b, &mut at, f)?;
            if at < b.len() && !self.item(b, &mut at, f)? {
                self.carry.extend_from_slice(&b[at..]);
                break;
            }
        }
        Ok(())
    }

    /// Reads the entries of the chunk at hand from `b[*at..]` while
    /// [`LOADS`] bytes remain after each one's start: the common case,
    /// [`Reader::entry`] with the reader's state in locals and no
    /// copy for the bytes' end (which [`Reader::item`] reads). The same
    /// checks, in the same order, with the same errors.
    #[inline(always)]
    fn bulk(
        &mut self,
        b: &[u8],
        at: &mut usize,
        f: &mut impl FnMut(SlotColour),
    ) -> Result<(), WireError> {
        let Some(stop) = b.len().checked_sub(LOADS) else {
            return Ok(());
        };
        let (mut p, mut left, mut slot, mut rgb) = (*at, self.left, self.slot as u64, self.rgb);
        let mut slots = 0u64;
        let mut result = Ok(());
        while left > 0 && p <= stop {
            let e = &b[p..p + LOADS];
            let tag = u16::from_le_bytes([e[0], e[1]]) as usize;
            // SHORT's bytes, computed: the next entry's start waits on
            // this, and a shift is quicker than a load.
            let (gl, rl) = ((1 << (tag & 3)) >> 1, (1 << (tag >> 2 & 3)) >> 1);
            let zl = [tag >> 4 & 15, tag >> 8 & 15, tag >> 12];
            if zl.iter().any(|&l| l > 8) {
                result = Err(WireError::Packed("a colour longer than 8 bytes".into()));
                break;
            }
            let q = 2 + gl + rl;
            let gap = load(e, 2, gl);
            let run = load(e, 2 + gl, rl) as u32;
            let z = [
                load(e, q, zl[0]),
                load(e, q + zl[0], zl[1]),
                load(e, q + zl[0] + zl[1], zl[2]),
            ];
            for (c, z) in rgb.iter_mut().zip(z) {
                *c = c.wrapping_add(((z >> 1) as i64) ^ -((z & 1) as i64));
            }
            let s = slot + gap;
            if s > u32::MAX as u64 {
                result = Err(WireError::Packed("a slot past 2^32".into()));
                break;
            }
            let end = s + run as u64 + 1;
            if end > self.limit {
                result = Err(WireError::Packed(format!(
                    "a contribution to pixel corners {s}..{end} of {}",
                    self.limit
                )));
                break;
            }
            slot = s;
            slots += end - s;
            left -= 1;
            p += q + zl[0] + zl[1] + zl[2];
            f(SlotColour {
                slot: s as u32,
                run,
                rgb,
            });
        }
        self.entries += self.left - left;
        self.slots += slots;
        (self.left, self.slot, self.rgb) = (left, slot as u32, rgb);
        *at = p;
        result
    }

    /// Whether the bytes fed so far ended where a chunk does.
    pub fn finish(&self) -> Result<(), WireError> {
        if self.left != 0 || !self.carry.is_empty() {
            return Err(WireError::Packed(
                "packed colour cut short of its count".into(),
            ));
        }
        Ok(())
    }
}

/// The entries of one packed chunk (at most `max` of them).
pub fn unpack(data: &[u8], max: usize) -> Result<Vec<SlotColour>, WireError> {
    let mut v = Vec::new();
    let mut r = Reader::default();
    let mut over = false;
    r.feed(data, &mut |x| {
        over |= v.len() >= max;
        if !over {
            v.push(x);
        }
    })?;
    r.finish()?;
    if over {
        return Err(WireError::Packed("too many entries".into()));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn c(slot: u32, run: u32, rgb: [i64; 3]) -> SlotColour {
        SlotColour { slot, run, rgb }
    }

    #[test]
    fn packed_colour_round_trips_in_slices_of_any_length() {
        let v: Vec<SlotColour> = (0..500u32)
            .map(|i| {
                let x = (i as i64 * 7919) % 100_003 - 50_000;
                c(i * 7 + (i % 3), i % 3, [x << 20, -x, i64::MAX - x])
            })
            .chain([c(u32::MAX - 1, 0, [i64::MIN, 0, -1])])
            .collect();
        let one = pack_sorted(&v);
        assert_eq!(unpack(&one, 1000).unwrap(), v);
        assert!(unpack(&one, 10).is_err());
        // Two chunks back to back, fed in pieces of every length.
        let two: Vec<u8> = [one.clone(), pack_sorted(&v[..7])].concat();
        let want: Vec<SlotColour> = v.iter().chain(&v[..7]).copied().collect();
        for step in [1, 2, 3, 5, 39, 40, 41, 1000, two.len()] {
            let mut r = Reader::default();
            let mut got = Vec::new();
            for s in two.chunks(step) {
                r.feed(s, &mut |x| got.push(x)).unwrap();
            }
            r.finish().unwrap();
            assert_eq!(got, want, "slices of {step}");
        }
        // Cut short, or a count that promises more: refused.
        assert!(unpack(&one[..one.len() - 1], 1000).is_err());
        let mut more = one.clone();
        more[0] += 1;
        assert!(unpack(&more, 1000).is_err());
        assert!(unpack(&[0xff; 12], 1000).is_err());
        // Past the frame: refused; the slots covered are counted.
        let mut r = Reader::new(u32::MAX as u64 - 1);
        assert!(r.feed(&one, &mut |_| ()).is_err());
        let mut r = Reader::new(u32::MAX as u64);
        r.feed(&one, &mut |_| ()).unwrap();
        let slots: u64 = v.iter().map(|x| x.end() - x.slot as u64).sum();
        assert_eq!(r.slots, slots);
    }

    #[test]
    fn a_slots_colours_are_added_and_equal_neighbours_joined() {
        let mut v = vec![
            c(5, 0, [1, 2, 3]),
            c(2, 0, [7, 7, 7]),
            c(5, 0, [10, 20, 30]),
            c(3, 0, [7, 7, 7]),
            c(4, 0, [1 << 62, 0, 0]),
            c(4, 0, [1, 0, 0]),
        ];
        let got = unpack(&pack(&mut v), 100).unwrap();
        assert_eq!(
            got,
            vec![
                c(2, 1, [7, 7, 7]),
                c(4, 0, [1 << 62, 0, 0]),
                c(4, 0, [1, 0, 0]),
                c(5, 0, [11, 22, 33]),
            ]
        );
    }

    /// What a reader makes of `b` fed in slices of `step`: the entries
    /// it gives, then its error or whether it ends on a chunk's end.
    fn read_in(b: &[u8], step: usize, limit: u64) -> (Vec<SlotColour>, String) {
        let mut r = Reader::new(limit);
        let mut got = Vec::new();
        for s in b.chunks(step) {
            if let Err(e) = r.feed(s, &mut |x| got.push(x)) {
                return (got, e.to_string());
            }
        }
        let end = match r.finish() {
            Ok(()) => "whole".to_string(),
            Err(e) => e.to_string(),
        };
        (
            got,
            format!("{end}; {} entries, {} slots", r.entries, r.slots),
        )
    }

    /// A whole buffer is read in bulk, its last bytes and slices one
    /// item at a time: both give the same entries and the same error at
    /// the same entry, whatever is wrong where.
    #[test]
    fn bulk_and_item_reads_agree_on_entries_and_errors() {
        let v: Vec<SlotColour> = (0..300u32)
            .map(|i| c(i * 3, i % 2, [(i as i64) << 30, -(i as i64), 7]))
            .collect();
        let good = [pack_sorted(&v), pack_sorted(&v[..20])].concat();
        let mut x: u64 = 0x2545_F491_4F6C_DD1D;
        for case in 0..2000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let mut b = good.clone();
            if case > 0 {
                let i = (x as usize >> 8) % b.len();
                b[i] = x as u8;
            }
            let limit = if case % 2 == 0 { 1 << 20 } else { 800 };
            let whole = read_in(&b, b.len(), limit);
            for step in [1, 7, 41, 42, 43] {
                assert_eq!(
                    read_in(&b, step, limit),
                    whole,
                    "case {case}, slices of {step}"
                );
            }
        }
    }

    /// Bytes from a worker are not trusted: any bytes, cut anywhere and
    /// fed in slices of any length, give entries or an error, never a
    /// panic, and never a slot at or past the reader's limit.
    #[test]
    fn garbage_gives_an_error_not_a_panic() {
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let good = pack_sorted(&[c(3, 0, [1, 2, 3]), c(9, 4, [-5, 6, 1 << 40])]);
        for case in 0..3000 {
            let len = (next() % 200) as usize;
            let mut b: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            if case % 3 == 0 {
                // Mostly well formed, one byte changed.
                b = good.clone();
                let i = (next() as usize) % b.len();
                b[i] = next() as u8;
            }
            let _ = unpack(&b, 1 << 20);
            let mut r = Reader::new(64);
            let mut at = 0;
            let mut failed = false;
            while at < b.len() && !failed {
                let n = 1 + (next() % 40) as usize;
                let end = (at + n).min(b.len());
                failed = r
                    .feed(&b[at..end], &mut |e| assert!(e.end() <= 64, "{e:?}"))
                    .is_err();
                at = end;
            }
            if !failed {
                let _ = r.finish();
            }
        }
    }
}
