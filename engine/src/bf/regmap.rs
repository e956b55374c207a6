//! One pass's registrations of rays in voxels: for each registered voxel,
//! the rays stored there, as one flat array (count, prefix sum, fill).
//! Sized by the registrations, not by the grid, so a fine grid costs one
//! flag byte per voxel and no more.
//!
//! Registration appends (voxel, slot) pairs; [`RegMap::finish`] groups the
//! slots by voxel, keeping registration order within a voxel (so rays in a
//! voxel lie in slot order, close together in memory when neighbouring
//! rays are neighbouring slots). The scan then reads each voxel's rays as
//! one contiguous run instead of chasing a linked list.

#[derive(Default)]
pub struct RegMap {
    /// Dense mode: the index into `voxels` of each voxel, or `EMPTY` (used
    /// when the grid is small enough to afford four bytes per voxel).
    dense: Vec<u32>,
    /// Otherwise an open-addressing table: index into `voxels`, or `EMPTY`.
    table: Vec<u32>,
    mask: usize,
    /// Registered voxels in order of first registration.
    voxels: Vec<u32>,
    /// Registrations per voxel while filling; after `finish`, the start of
    /// each voxel's run in `slots` (one more entry than `voxels`).
    starts: Vec<u32>,
    /// Registrations in the order they came: voxel index and ray slot.
    pending: Vec<(u32, u32)>,
    /// After `finish`: the slots, grouped by voxel.
    slots: Vec<u32>,
}

const EMPTY: u32 = u32::MAX;

/// Memory per registration: its (voxel, slot) pair while rays register,
/// and its slot in its voxel's run once they are grouped.
pub const REGISTRATION_BYTES: usize = 8 + 4;
/// Memory per voxel a map holds rays in: its place in the list of
/// voxels, its run's start, and its share of the hash table (a power of
/// two, at most half full: up to four entries of four bytes).
pub const VOXEL_BYTES: usize = 4 + 4 + 16;
/// The most a registration takes: one in a voxel of its own. A pass's
/// rays share most of their voxels (rings80's first round: 18 to 32
/// registrations a voxel), so planning every registration for this left
/// two thirds of the registrations' memory unused.
pub const WORST_REGISTRATION_BYTES: usize = REGISTRATION_BYTES + VOXEL_BYTES;

#[inline(always)]
fn hash(v: u32) -> usize {
    (v.wrapping_mul(0x9E37_79B1) ^ (v >> 15)) as usize
}

impl RegMap {
    /// Bytes allocated.
    pub fn bytes(&self) -> usize {
        4 * (self.dense.capacity()
            + self.table.capacity()
            + self.voxels.capacity()
            + self.starts.capacity()
            + self.slots.capacity())
            + 8 * self.pending.capacity()
    }

    /// The memory its registrations take by [`REGISTRATION_BYTES`] and
    /// [`VOXEL_BYTES`]: what a shard's share of the budget is spent on.
    pub fn used_bytes(&self) -> usize {
        REGISTRATION_BYTES * self.len() + VOXEL_BYTES * self.voxels.len()
    }

    /// Empties the map, its table sized for about `expected` voxels; with
    /// `dense_cells > 0`, indexes voxels directly.
    pub fn clear(&mut self, expected: usize, dense_cells: usize) {
        if dense_cells > 0 {
            if self.dense.len() != dense_cells {
                self.dense = vec![EMPTY; dense_cells];
            } else {
                for &v in &self.voxels {
                    self.dense[v as usize] = EMPTY;
                }
            }
            self.table = Vec::new();
        } else {
            self.dense = Vec::new();
            let size = (expected * 2).next_power_of_two().max(64);
            if self.table.len() < size {
                self.table = vec![EMPTY; size];
                self.mask = size - 1;
            } else {
                // Only the used entries need resetting.
                for &v in &self.voxels {
                    let mut h = hash(v) & self.mask;
                    while self.table[h] != EMPTY {
                        self.table[h] = EMPTY;
                        h = (h + 1) & self.mask;
                    }
                }
            }
        }
        self.voxels.clear();
        self.starts.clear();
        self.pending.clear();
        self.slots.clear();
    }

    /// The index of `voxel` in `voxels`, adding it if new.
    #[inline]
    fn index_of(&mut self, voxel: u32) -> u32 {
        if !self.dense.is_empty() {
            let e = &mut self.dense[voxel as usize];
            if *e == EMPTY {
                *e = self.voxels.len() as u32;
                self.voxels.push(voxel);
                self.starts.push(0);
            }
            return *e;
        }
        if self.voxels.len() * 2 >= self.table.len() {
            self.grow();
        }
        let mut h = hash(voxel) & self.mask;
        loop {
            let e = self.table[h];
            if e == EMPTY {
                let i = self.voxels.len() as u32;
                self.table[h] = i;
                self.voxels.push(voxel);
                self.starts.push(0);
                return i;
            }
            if self.voxels[e as usize] == voxel {
                return e;
            }
            h = (h + 1) & self.mask;
        }
    }

    /// Stores `slot` in `voxel`.
    #[inline]
    pub fn insert(&mut self, voxel: u32, slot: u32) {
        let i = self.index_of(voxel);
        self.starts[i as usize] += 1;
        self.pending.push((i, slot));
    }

    fn grow(&mut self) {
        let size = self.table.len() * 2;
        self.table = vec![EMPTY; size];
        self.mask = size - 1;
        for (i, &v) in self.voxels.iter().enumerate() {
            let mut h = hash(v) & self.mask;
            while self.table[h] != EMPTY {
                h = (h + 1) & self.mask;
            }
            self.table[h] = i as u32;
        }
    }

    /// Groups the registrations by voxel; call once, after the last
    /// `insert` and before the first `slots_in`.
    pub fn finish(&mut self) {
        // Exclusive prefix sum of the counts, then one more entry.
        let mut acc = 0u32;
        for c in self.starts.iter_mut() {
            let k = *c;
            *c = acc;
            acc += k;
        }
        self.starts.push(acc);
        self.slots.clear();
        self.slots.reserve_exact(acc as usize);
        self.slots.resize(acc as usize, 0);
        // Fill in registration order, each voxel's start serving as its
        // cursor, so each run keeps that order.
        for &(i, slot) in &self.pending {
            let at = &mut self.starts[i as usize];
            self.slots[*at as usize] = slot;
            *at += 1;
        }
        // The fill advanced every start to the next voxel's start: shift
        // back by one.
        for i in (1..self.starts.len() - 1).rev() {
            self.starts[i] = self.starts[i - 1];
        }
        if self.starts.len() > 1 {
            self.starts[0] = 0;
        }
        self.pending.clear();
    }

    pub fn is_empty(&self) -> bool {
        self.slots.is_empty() && self.pending.is_empty()
    }

    /// Registrations in the map.
    pub fn len(&self) -> usize {
        self.slots.len() + self.pending.len()
    }

    /// The registered voxels.
    pub fn voxels(&self) -> &[u32] {
        &self.voxels
    }

    /// Whether the map indexes voxels directly.
    #[inline(always)]
    pub fn is_dense(&self) -> bool {
        !self.dense.is_empty()
    }

    /// The slots registered in `voxel` (after `finish`), in registration
    /// order.
    #[inline]
    pub fn slots_in(&self, voxel: u32) -> &[u32] {
        let i = if !self.dense.is_empty() {
            self.dense[voxel as usize]
        } else {
            let mut h = hash(voxel) & self.mask;
            loop {
                let e = self.table[h];
                if e == EMPTY || self.voxels[e as usize] == voxel {
                    break e;
                }
                h = (h + 1) & self.mask;
            }
        };
        if i == EMPTY {
            return &[];
        }
        let i = i as usize;
        &self.slots[self.starts[i] as usize..self.starts[i + 1] as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup_and_reuse() {
        let mut m = RegMap::default();
        for round in 0..6 {
            m.clear(4, if round % 2 == 0 { 0 } else { 64 });
            for (v, s) in [(9u32, 0u32), (2, 1), (7, 1), (7, 3), (9, 5)] {
                m.insert(v + round, s);
            }
            m.finish();
            assert_eq!(m.slots_in(7 + round), &[1, 3]);
            assert_eq!(m.slots_in(9 + round), &[0, 5]);
            assert_eq!(m.slots_in(2 + round), &[1]);
            assert!(m.slots_in(8 + round).is_empty());
            assert_eq!(m.voxels(), &[9 + round, 2 + round, 7 + round]);
            assert_eq!(m.is_dense(), round % 2 == 1);
            assert_eq!(m.len(), 5);
        }
        // Growing keeps everything; runs keep registration order.
        m.clear(1, 0);
        for v in 0..1000 {
            m.insert(v % 300, v);
        }
        m.finish();
        for v in 0..300 {
            let want: Vec<u32> = (0..1000).filter(|s| s % 300 == v).collect();
            assert_eq!(m.slots_in(v), &want[..]);
        }
        m.clear(1, 0);
        m.finish();
        assert!(m.is_empty() && m.slots_in(3).is_empty());
    }
}
