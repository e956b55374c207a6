//! One pass's registrations of rays in voxels: for each registered voxel,
//! the rays stored there (in slot order). Sized by the registrations, not
//! by the grid, so a fine grid costs one flag byte per voxel and no more.

/// Open-addressing table from voxel index to a run of `items`.
#[derive(Default)]
pub struct RegMap {
    table: Vec<Entry>,
    mask: usize,
    items: Vec<u32>,
}

#[derive(Clone, Copy)]
struct Entry {
    voxel: u32,
    start: u32,
    len: u32,
}

const EMPTY: u32 = u32::MAX;

#[inline(always)]
fn hash(v: u32) -> usize {
    (v.wrapping_mul(0x9E37_79B1) ^ (v >> 15)) as usize
}

impl RegMap {
    /// Builds the map from `keys` (voxel << 32 | slot), given in slot
    /// order: a counting sort by voxel through the table, so each voxel's
    /// slots stay in slot order.
    pub fn build(&mut self, keys: &[u64]) {
        self.table.clear();
        self.items.clear();
        if keys.is_empty() {
            self.mask = 0;
            return;
        }
        // Size the table for at most one entry per key.
        let size = (keys.len() * 2).next_power_of_two().max(16);
        self.table.resize(
            size,
            Entry {
                voxel: EMPTY,
                start: 0,
                len: 0,
            },
        );
        self.mask = size - 1;
        // Count per voxel.
        for k in keys {
            let v = (k >> 32) as u32;
            let h = self.slot_of(v);
            let e = &mut self.table[h];
            e.voxel = v;
            e.len += 1;
        }
        // Starts, then fill.
        let mut acc = 0u32;
        for e in self.table.iter_mut() {
            if e.voxel != EMPTY {
                e.start = acc;
                acc += e.len;
                e.len = 0;
            }
        }
        self.items.resize(keys.len(), 0);
        for k in keys {
            let h = self.slot_of((k >> 32) as u32);
            let e = &mut self.table[h];
            self.items[(e.start + e.len) as usize] = *k as u32;
            e.len += 1;
        }
    }

    /// The table position of `voxel`: its entry, or the empty one where it
    /// would go.
    #[inline]
    fn slot_of(&self, voxel: u32) -> usize {
        let mut h = hash(voxel) & self.mask;
        loop {
            let e = self.table[h].voxel;
            if e == voxel || e == EMPTY {
                return h;
            }
            h = (h + 1) & self.mask;
        }
    }

    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// The registered voxels.
    pub fn voxels(&self) -> impl Iterator<Item = u32> + '_ {
        self.table
            .iter()
            .filter(|e| e.voxel != EMPTY)
            .map(|e| e.voxel)
    }

    /// Slots registered in `voxel`.
    #[inline]
    pub fn get(&self, voxel: u32) -> &[u32] {
        if self.table.is_empty() {
            return &[];
        }
        let mut h = hash(voxel) & self.mask;
        loop {
            let e = self.table[h];
            if e.voxel == voxel {
                return &self.items[e.start as usize..(e.start + e.len) as usize];
            }
            if e.voxel == EMPTY {
                return &[];
            }
            h = (h + 1) & self.mask;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lookup() {
        let keys: Vec<u64> = vec![(9 << 32) | 0, (2 << 32) | 1, (7 << 32) | 1, (7 << 32) | 3];
        let mut m = RegMap::default();
        m.build(&keys);
        assert_eq!(m.get(7), &[1, 3]);
        assert_eq!(m.get(2), &[1]);
        assert_eq!(m.get(9), &[0]);
        assert_eq!(m.get(8), &[] as &[u32]);
        let mut v: Vec<u32> = m.voxels().collect();
        v.sort();
        assert_eq!(v, vec![2, 7, 9]);
    }
}
