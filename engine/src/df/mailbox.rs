//! Which lanes of a walk have tested which objects.
//!
//! A ray walking a grid meets an object in every voxel the object's box
//! overlaps; the mailbox (Amanatides and Woo) makes it test the object
//! once. A group of rays needs one per lane: a lane tests an object when
//! it reaches a voxel listing it, unless it tested it already, so that a
//! lane tests exactly the objects its own walk meets and no others. The
//! objects a walk meets are few (a hundred or so for a packet of eye
//! rays), so they are kept in a small open-addressed table, cleared by a
//! stamp per walk, that stays in the first-level cache, rather than in
//! an array over all the objects.

use crate::kernels::Lanes;

#[derive(Clone, Copy, Default)]
struct Slot {
    /// The walk that filled it; older slots are empty.
    stamp: u32,
    id: u32,
    lanes: Lanes,
}

pub struct Mailbox {
    slots: Vec<Slot>,
    stamp: u32,
    /// Slots filled in this walk.
    used: usize,
}

/// Slots to start with (a power of two).
const START: usize = 256;

impl Default for Mailbox {
    fn default() -> Self {
        Mailbox {
            slots: vec![Slot::default(); START],
            stamp: 0,
            used: 0,
        }
    }
}

impl Mailbox {
    /// Starts a walk: every object untested by every lane.
    #[inline]
    pub fn begin(&mut self) {
        if self.stamp == u32::MAX {
            self.slots.fill(Slot::default());
            self.stamp = 0;
        }
        self.stamp += 1;
        self.used = 0;
    }

    /// The lanes of `lanes` that have not tested object `id` in this
    /// walk; they count as having tested it from now on.
    #[inline]
    pub fn untested(&mut self, id: u32, lanes: Lanes) -> Lanes {
        let mask = self.slots.len() - 1;
        let mut k = hash(id) & mask;
        loop {
            let s = &mut self.slots[k];
            if s.stamp != self.stamp {
                *s = Slot {
                    stamp: self.stamp,
                    id,
                    lanes,
                };
                self.used += 1;
                if 2 * self.used > self.slots.len() {
                    self.grow();
                }
                return lanes;
            }
            if s.id == id {
                let new = lanes & !s.lanes;
                s.lanes |= lanes;
                return new;
            }
            k = (k + 1) & mask;
        }
    }

    /// Twice the slots, holding this walk's entries.
    #[cold]
    fn grow(&mut self) {
        let bigger = vec![Slot::default(); 2 * self.slots.len()];
        let old = std::mem::replace(&mut self.slots, bigger);
        let mask = self.slots.len() - 1;
        for s in old.into_iter().filter(|s| s.stamp == self.stamp) {
            let mut k = hash(s.id) & mask;
            while self.slots[k].stamp == self.stamp {
                k = (k + 1) & mask;
            }
            self.slots[k] = s;
        }
    }
}

#[inline(always)]
fn hash(id: u32) -> usize {
    (id.wrapping_mul(0x9E37_79B1) >> 8) as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_lane_tests_an_object_once_per_walk() {
        let mut m = Mailbox::default();
        m.begin();
        assert_eq!(m.untested(7, 0b0011), 0b0011);
        assert_eq!(m.untested(7, 0b0110), 0b0100);
        assert_eq!(m.untested(7, 0b0111), 0);
        assert_eq!(m.untested(8, 0b0111), 0b0111);
        m.begin();
        assert_eq!(m.untested(7, 0b0001), 0b0001, "a new walk");
    }

    #[test]
    fn many_objects_grow_the_table() {
        let mut m = Mailbox::default();
        for walk in 0..3 {
            m.begin();
            for id in 0..5000u32 {
                assert_eq!(
                    m.untested(id * 31, 1 << (id % 64)),
                    1 << (id % 64),
                    "{walk} {id}"
                );
            }
            for id in 0..5000u32 {
                assert_eq!(
                    m.untested(id * 31, u64::MAX),
                    !(1 << (id % 64)),
                    "{walk} {id}"
                );
            }
        }
        assert!(m.slots.len() >= 10_000);
    }
}
