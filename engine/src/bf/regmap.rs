//! One pass's registrations of rays in voxels: for each registered voxel,
//! the rays stored there (in slot order). Sized by the registrations, not
//! by the grid, so a fine grid costs one flag byte per voxel and no more.

/// Open-addressing table from voxel index to a run of `items`.
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

impl Default for RegMap {
    fn default() -> Self {
        RegMap {
            table: Vec::new(),
            mask: 0,
            items: Vec::new(),
        }
    }
}

impl RegMap {
    /// Builds the map from `keys` (voxel << 32 | slot), which it sorts.
    pub fn build(&mut self, keys: &mut [u64]) {
        keys.sort_unstable();
        self.items.clear();
        self.items.extend(keys.iter().map(|k| *k as u32));
        let mut distinct = 0usize;
        let mut last = u64::MAX;
        for k in keys.iter() {
            if k >> 32 != last {
                distinct += 1;
                last = k >> 32;
            }
        }
        let size = (distinct * 2).next_power_of_two().max(16);
        self.table.clear();
        self.table.resize(
            size,
            Entry {
                voxel: EMPTY,
                start: 0,
                len: 0,
            },
        );
        self.mask = size - 1;
        let mut i = 0;
        while i < keys.len() {
            let v = (keys[i] >> 32) as u32;
            let start = i;
            while i < keys.len() && (keys[i] >> 32) as u32 == v {
                i += 1;
            }
            let mut h = hash(v) & self.mask;
            while self.table[h].voxel != EMPTY {
                h = (h + 1) & self.mask;
            }
            self.table[h] = Entry {
                voxel: v,
                start: start as u32,
                len: (i - start) as u32,
            };
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
        let mut keys: Vec<u64> = vec![(7 << 32) | 3, (2 << 32) | 1, (7 << 32) | 1, (9 << 32) | 0];
        let mut m = RegMap::default();
        m.build(&mut keys);
        assert_eq!(m.get(7), &[1, 3]);
        assert_eq!(m.get(2), &[1]);
        assert_eq!(m.get(9), &[0]);
        assert_eq!(m.get(8), &[] as &[u32]);
        let mut v: Vec<u32> = m.voxels().collect();
        v.sort();
        assert_eq!(v, vec![2, 7, 9]);
    }
}
