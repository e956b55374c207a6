//! The checks of a block's records, made once per file, so that decoding
//! them afterwards cannot fail: kinds, counts, material and model indices,
//! lengths, and no number that is not finite.

use super::block::decode_record;
use super::format::*;
use crate::shapes::{Shape, ShapeKind};

/// Checks every record of a decoded block so that iteration cannot fail.
pub(super) fn validate_records(
    words: &[u32],
    count: u32,
    materials: usize,
    models: usize,
) -> Result<(), String> {
    let mut pos = 0usize;
    let mut instances = false;
    for i in 0..count {
        let head = words
            .get(pos..pos + RECORD_HEADER_WORDS)
            .ok_or_else(|| format!("record {i} is cut off"))?;
        let kind = ShapeKind::from_u8((head[0] & 0xff) as u8)
            .ok_or_else(|| format!("record {i} has unknown kind {}", head[0] & 0xff))?;
        let count = head[0] >> 8;
        let payload = kind.payload_words(count).ok_or_else(|| {
            format!(
                "record {i} is a {} with an invalid count {count}",
                kind.name()
            )
        })?;
        if head[1] as usize >= materials {
            return Err(format!(
                "record {i} refers to material {} of {materials}",
                head[1]
            ));
        }
        instances |= matches!(kind, ShapeKind::Instance | ShapeKind::Textured);
        pos += RECORD_HEADER_WORDS + payload;
        if pos > words.len() {
            return Err(format!("record {i} is cut off"));
        }
    }
    if pos != words.len() {
        return Err("block has bytes after its last record".into());
    }
    if instances {
        // An instance's transform is stored as `f64` words, whose low
        // halves are any bit pattern, and a textured triangle's colours
        // as 16-bit integers: their records are checked as shapes.
        return validate_with_instances(words, count, models);
    }
    // No number may be NaN or infinite. The integer words (kind and vertex
    // count, material index) are far below the pattern once checked above,
    // so one pass over every word (which vectorizes) covers all the floats.
    const _: () = assert!(MAX_MATERIALS <= 1 << 23);
    const _: () = assert!(crate::shapes::MAX_POLYGON_VERTICES < 1 << 15);
    let bad = words.iter().fold(0u32, |acc, w| {
        acc | ((w & 0x7f80_0000) == 0x7f80_0000) as u32
    });
    if bad != 0 {
        return Err("a record has a non-finite number".into());
    }
    Ok(())
}

/// The finiteness check of [`validate_records`], record by record, for a
/// block holding instances (checked whole, and their model's index) or
/// textured triangles (checked whole, their colours aside).
fn validate_with_instances(words: &[u32], count: u32, models: usize) -> Result<(), String> {
    let finite = |w: &[u32]| w.iter().all(|w| (w & 0x7f80_0000) != 0x7f80_0000);
    let mut pos = 0usize;
    for i in 0..count {
        let (o, len) =
            decode_record(&words[pos..], i).ok_or_else(|| format!("record {i} is cut off"))?;
        let rec = &words[pos..pos + len];
        match o.shape {
            Shape::Instance(inst) => {
                if !finite(&rec[..RECORD_HEADER_WORDS]) {
                    return Err(format!("record {i} has a non-finite number"));
                }
                o.shape.validate().map_err(|e| format!("record {i}: {e}"))?;
                if inst.model() as usize >= models {
                    return Err(format!(
                        "record {i} places model {} of {models}",
                        inst.model()
                    ));
                }
            }
            Shape::Textured(t) => {
                let colors = 2 * t.colors.len();
                if !finite(&rec[..len - colors]) {
                    return Err(format!("record {i} has a non-finite number"));
                }
                o.shape.validate().map_err(|e| format!("record {i}: {e}"))?;
            }
            _ if !finite(rec) => return Err(format!("record {i} has a non-finite number")),
            _ => {}
        }
        pos += len;
    }
    Ok(())
}

/// What [`super::packed::expand`] hands out, checked on its way to `to`
/// when `check` holds the scene's materials and models: what
/// [`validate_records`] checks of the records it expands to.
pub(super) struct Checked<'a, E> {
    to: &'a mut E,
    check: Option<(usize, usize)>,
    /// Objects handed out so far.
    seen: u32,
    /// Textured triangles' records, checked as such.
    scratch: Vec<u32>,
}

impl<'a, E> Checked<'a, E> {
    pub(super) fn new(to: &'a mut E, check: Option<(usize, usize)>) -> Checked<'a, E> {
        Checked {
            to,
            check,
            seen: 0,
            scratch: Vec::new(),
        }
    }
}

impl<E: super::packed::Expand> super::packed::Expand for Checked<'_, E> {
    fn records(&mut self, words: &[u32], count: u32) -> Result<(), String> {
        if let Some((materials, models)) = self.check {
            validate_records(words, count, materials, models)?;
        }
        self.seen += count;
        self.to.records(words, count)
    }

    fn run(&mut self, run: &super::packed::StoredRun<'_>) -> Result<(), String> {
        if let Some((materials, models)) = self.check {
            if run.textured() {
                // Colours are integers: checked as records, as shapes.
                let words = run.record_words();
                self.scratch.clear();
                self.scratch.resize(run.faces() * words, 0);
                for (t, rec) in self.scratch.chunks_exact_mut(words).enumerate() {
                    run.write_record(t, rec);
                }
                validate_records(&self.scratch, run.faces() as u32, materials, models)?;
            } else {
                // The records' other words are their kind and count, and
                // a box of these corners: finite when they are.
                if run.material() as usize >= materials {
                    return Err(format!(
                        "record {} refers to material {} of {materials}",
                        self.seen,
                        run.material()
                    ));
                }
                if !run.finite() {
                    return Err("a record has a non-finite number".into());
                }
            }
        }
        self.seen += run.faces() as u32;
        self.to.run(run)
    }
}
