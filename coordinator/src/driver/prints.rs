//! What verification with records at the workers compares of a task's
//! output (see `held.rs`): its counts, the digest of the records it made,
//! and a fingerprint of the colour it adds to each frame slot.

use crate::task::TaskOutput;
use sray_engine::spill::Records;
use sray_proto::v1;

/// What verification compares of one task's output.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct TaskPrint {
    /// Intersection: results, hits. Shading: eye rays that hit, reflected,
    /// refracted and shadow rays, spawned rays and their first and last
    /// keys.
    counts: [u64; 7],
    /// The digest of the records it made (results, or spawned rays).
    digest: Vec<u8>,
    /// The fingerprint of the colour it adds to each frame slot.
    colour: [u64; 3],
}

/// The print of a task's output, kept at its worker or sent; `key`
/// keys the colour's fingerprint.
pub(super) fn print_of(stage: v1::Stage, o: &TaskOutput, key: u64) -> anyhow::Result<TaskPrint> {
    let s = &o.summary;
    if stage == v1::Stage::Intersect {
        let (n, digest) = match &o.results {
            Some(r) => (r.len(), digest_of(r)?),
            None => (s.kept_records, s.kept_digest.clone()),
        };
        return Ok(TaskPrint {
            counts: [n, o.hits, 0, 0, 0, 0, 0],
            digest,
            colour: [0; 3],
        });
    }
    let (n, first, last, digest) = match &o.rays {
        Some(r) => {
            let first = r.get(0)?.map_or(0, |x| x.key);
            let last = match r.len() {
                0 => 0,
                n => r.get(n - 1)?.map_or(0, |x| x.key),
            };
            (r.len(), first, last, digest_of(r)?)
        }
        None if o.kept_rays == 0 && s.kept_digest.is_empty() => {
            (0, 0, 0, blake3::hash(&[]).as_bytes().to_vec())
        }
        None => (
            o.kept_rays,
            s.kept_first_key,
            s.kept_last_key,
            s.kept_digest.clone(),
        ),
    };
    Ok(TaskPrint {
        counts: [
            s.eye_hit_rays,
            s.reflect_rays,
            s.refract_rays,
            s.shadow_rays,
            n,
            first,
            last,
        ],
        digest,
        colour: colour_print(o, key)?,
    })
}

/// BLAKE3 of records as they travel, in order (what a worker that keeps
/// them reports as `kept_digest`).
pub(super) fn digest_of<T: bytemuck::Pod>(r: &Records<T>) -> anyhow::Result<Vec<u8>> {
    let mut h = blake3::Hasher::new();
    r.for_each_slice(&mut |s| {
        h.update(bytemuck::cast_slice(s));
        Ok(())
    })?;
    Ok(h.finalize().as_bytes().to_vec())
}

/// 2^61 - 1, a prime.
const P: u64 = (1 << 61) - 1;

/// `x` modulo `P` (2^61 ≡ 1: the high bits fold onto the low ones).
fn mod_p(x: u128) -> u64 {
    let p = P as u128;
    let x = (x & p) + (x >> 61);
    let x = ((x & p) + (x >> 61)) as u64;
    if x >= P { x - P } else { x }
}

/// `v` modulo `P`, in `0..P`: that of `v + 8P`, which is never negative
/// (8P > 2^63), with no division.
fn residue(v: i64) -> u64 {
    mod_p((v as i128 + 8 * P as i128) as u128)
}

/// The fingerprint of the colour contributions add to each frame slot:
/// per channel, the sum over slots of the slot's colour sum times a
/// pseudo-random weight of the slot (keyed by `key`), modulo `P`. Linear
/// in the contributions, so contributions to one slot added together
/// first (or sent in runs) give the same fingerprint.
fn colour_print(o: &TaskOutput, key: u64) -> anyhow::Result<[u64; 3]> {
    // Sums of products below 2^122, folded modulo P only when they pass
    // 2^125 (and at the end): the same remainder, fewer folds.
    let mut acc = [0u128; 3];
    o.for_each_contribution(|x| {
        let v = x.rgb.map(|v| residue(v) as u128);
        for slot in x.corner as u64..x.end() {
            let w = mod_p(splitmix(slot ^ key) as u128) as u128;
            for (a, v) in acc.iter_mut().zip(v) {
                *a += v * w;
                if *a >= 1 << 125 {
                    *a = mod_p(*a) as u128;
                }
            }
        }
    })?;
    Ok(acc.map(mod_p))
}

fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::colour_print;
    use crate::task::TaskOutput;
    use sray_engine::bf::Contribution;
    use sray_engine::spill::{MemoryShare, Records};

    fn recs(v: Vec<Contribution>) -> TaskOutput {
        TaskOutput {
            contributions: Some(Records::memory(v, MemoryShare::new(0).lease())),
            ..Default::default()
        }
    }

    /// The same, packed per slot in chunks of `per` (as a worker that
    /// keeps its records sends them).
    fn packed(v: &[Contribution], per: usize) -> TaskOutput {
        let mut bytes = Vec::new();
        for c in v.chunks(per) {
            bytes.extend(sray_worker::exec::pack_colour(c));
        }
        TaskOutput {
            colour: Some(Records::memory(bytes, MemoryShare::new(0).lease())),
            ..Default::default()
        }
    }

    fn c(corner: u32, run: u32, rgb: [i64; 3]) -> Contribution {
        Contribution { corner, run, rgb }
    }

    #[test]
    fn folding_modulo_p_is_the_remainder() {
        use super::{P, mod_p};
        let mut x = 0x1234_5678_9abc_def0_u128;
        for _ in 0..10_000 {
            x = x.wrapping_mul(0x2545_f491_4f6c_dd1d_3c6e_f372_fe94_f82b) >> 5;
            assert_eq!(mod_p(x) as u128, x % P as u128);
            assert_eq!(mod_p(x >> 64) as u128, (x >> 64) % P as u128);
        }
        for x in [
            0,
            P as u128 - 1,
            P as u128,
            (P as u128) << 61,
            u64::MAX as u128,
        ] {
            assert_eq!(mod_p(x) as u128, x % P as u128);
        }
        for v in [
            i64::MIN,
            i64::MIN + 1,
            -(P as i64),
            -1,
            0,
            1,
            P as i64,
            i64::MAX,
        ] {
            assert_eq!(super::residue(v) as i64, v.rem_euclid(P as i64), "{v}");
        }
    }

    #[test]
    fn the_colour_print_is_that_of_the_sums_per_slot() {
        // One at a time, in some order (as a checked output comes) ...
        let apart_v = vec![
            c(7, 0, [-3, 0, 1 << 40]),
            c(5, 0, [1, 2, 3]),
            c(6, 0, [7, 7, 7]),
            c(5, 0, [4, 5, 6]),
            c(8, 0, [7, 7, 7]),
            c(7, 0, [10, 7, 6]),
        ];
        let apart = recs(apart_v.clone());
        // ... summed per slot and in runs (as a worker that keeps its
        // records sends them): the same print.
        let merged = recs(vec![
            c(5, 0, [5, 7, 9]),
            c(6, 0, [7, 7, 7]),
            c(7, 0, [7, 7, 6 + (1 << 40)]),
            c(8, 0, [7, 7, 7]),
        ]);
        let key = 0x5eed;
        let print = colour_print(&apart, key).unwrap();
        assert_eq!(print, colour_print(&merged, key).unwrap());
        // Packed per slot, in one chunk or several: the same print.
        for per in [1, 2, 6] {
            assert_eq!(print, colour_print(&packed(&apart_v, per), key).unwrap());
        }
        // A run is its slots one by one.
        let run = recs(vec![c(5, 0, [5, 7, 9]), c(6, 2, [7, 7, 7])]);
        let slots = recs(vec![
            c(5, 0, [5, 7, 9]),
            c(6, 0, [7, 7, 7]),
            c(7, 0, [7, 7, 7]),
            c(8, 0, [7, 7, 7]),
        ]);
        assert_eq!(
            colour_print(&run, key).unwrap(),
            colour_print(&slots, key).unwrap()
        );
        // Another colour, or the same colour in another slot, differs.
        for other in [
            vec![c(5, 0, [5, 7, 9]), c(6, 2, [7, 7, 8])],
            vec![c(5, 0, [9, 7, 5]), c(6, 2, [7, 7, 7])],
            vec![c(5, 0, [5, 7, 9]), c(6, 3, [7, 7, 7])],
            vec![c(4, 0, [5, 7, 9]), c(6, 2, [7, 7, 7])],
        ] {
            let p = colour_print(&packed(&other, 8), key).unwrap();
            assert_ne!(p, colour_print(&run, key).unwrap());
            assert_eq!(p, colour_print(&recs(other), key).unwrap());
        }
        // Nothing is no colour.
        assert_eq!(colour_print(&TaskOutput::default(), key).unwrap(), [0; 3]);
    }
}
