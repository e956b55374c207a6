//! One pass's registrations of rays in voxels: for each registered voxel,
//! the rays stored there. Sized by the registrations, not by the grid, so a
//! fine grid costs one flag byte per voxel and no more.
//!
//! Each registration is one probe of an open-addressing table (voxel to its
//! list) and one entry in a flat array linking the voxel's rays. The order
//! of rays within a voxel does not matter: each ray's state is its own, and
//! it meets the objects in file order whatever order it sits in.

#[derive(Default)]
pub struct RegMap {
    /// Dense mode: the head of each voxel's list, indexed by voxel (used
    /// when the grid is small enough to afford four bytes per voxel; nearby
    /// voxels then sit nearby in memory).
    dense: Vec<u32>,
    /// Otherwise an open-addressing table: index into `voxels`, or `EMPTY`.
    table: Vec<u32>,
    mask: usize,
    /// Registered voxels in order of first registration, and the head of
    /// each one's list in `links`.
    voxels: Vec<u32>,
    heads: Vec<u32>,
    /// Per registration: the ray's slot and the next registration of the
    /// same voxel.
    links: Vec<(u32, u32)>,
}

const EMPTY: u32 = u32::MAX;

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
            + self.heads.capacity())
            + 8 * self.links.capacity()
    }

    /// Empties the map, sized for about `expected` registrations; with
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
            self.voxels.clear();
            self.heads.clear();
            self.links.clear();
            return;
        }
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
        self.voxels.clear();
        self.heads.clear();
        self.links.clear();
    }

    /// Stores `slot` in `voxel`.
    #[inline]
    pub fn insert(&mut self, voxel: u32, slot: u32) {
        if !self.dense.is_empty() {
            let h = &mut self.dense[voxel as usize];
            if *h == EMPTY {
                self.voxels.push(voxel);
            }
            self.links.push((slot, *h));
            *h = (self.links.len() - 1) as u32;
            return;
        }
        if self.voxels.len() * 2 >= self.table.len() {
            self.grow();
        }
        let mut h = hash(voxel) & self.mask;
        let at = loop {
            let e = self.table[h];
            if e == EMPTY {
                self.table[h] = self.voxels.len() as u32;
                self.voxels.push(voxel);
                self.heads.push(EMPTY);
                break self.voxels.len() - 1;
            }
            if self.voxels[e as usize] == voxel {
                break e as usize;
            }
            h = (h + 1) & self.mask;
        };
        self.links.push((slot, self.heads[at]));
        self.heads[at] = (self.links.len() - 1) as u32;
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

    pub fn is_empty(&self) -> bool {
        self.links.is_empty()
    }

    /// Registrations in the map.
    pub fn len(&self) -> usize {
        self.links.len()
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

    /// The first registration in `voxel`, if any (follow with `link`).
    #[inline]
    pub fn first(&self, voxel: u32) -> Option<u32> {
        if !self.dense.is_empty() {
            let h = self.dense[voxel as usize];
            return (h != EMPTY).then_some(h);
        }
        let mut h = hash(voxel) & self.mask;
        loop {
            let e = self.table[h];
            if e == EMPTY {
                return None;
            }
            if self.voxels[e as usize] == voxel {
                return Some(self.heads[e as usize]);
            }
            h = (h + 1) & self.mask;
        }
    }

    /// The slot of registration `r`, and the next registration of its voxel.
    #[inline(always)]
    pub fn link(&self, r: u32) -> (u32, u32) {
        self.links[r as usize]
    }

    /// Iterates the slots registered in `voxel`.
    #[cfg(test)]
    pub fn slots(&self, voxel: u32) -> impl Iterator<Item = u32> + '_ {
        let mut r = self.first(voxel).unwrap_or(EMPTY);
        std::iter::from_fn(move || {
            if r == EMPTY {
                return None;
            }
            let (s, n) = self.links[r as usize];
            r = n;
            Some(s)
        })
    }
}

/// End of a voxel's list.
pub const END: u32 = EMPTY;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup_and_reuse() {
        let mut m = RegMap::default();
        for round in 0..6 {
            m.clear(4, if round % 2 == 0 { 0 } else { 64 });
            for (v, s) in [(9u32, 0u32), (2, 1), (7, 1), (7, 3)] {
                m.insert(v + round, s);
            }
            let mut got: Vec<u32> = m.slots(7 + round).collect();
            got.sort();
            assert_eq!(got, vec![1, 3]);
            assert_eq!(m.slots(2 + round).collect::<Vec<_>>(), vec![1]);
            assert_eq!(m.slots(8 + round).count(), 0);
            assert_eq!(m.voxels(), &[9 + round, 2 + round, 7 + round]);
            assert_eq!(m.is_dense(), round % 2 == 1);
            assert_eq!(m.len(), 4);
        }
        // Growing keeps everything.
        m.clear(1, 0);
        for v in 0..1000 {
            m.insert(v, v);
        }
        assert!((0..1000).all(|v| m.slots(v).collect::<Vec<_>>() == vec![v]));
    }
}
