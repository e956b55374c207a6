use crate::error::Error;
use crate::grid::GridSpec;
use crate::scene::Aabb;

/// A uniform grid listing, per voxel, the objects whose bounding box
/// overlaps it: one flat array of object ids and the start of each voxel's
/// run (count, prefix-sum, fill), in object id order within a voxel.
pub struct ObjectGrid {
    pub spec: GridSpec,
    pub start: Vec<u32>,
    pub items: Vec<u32>,
    pub objects: u64,
}

impl ObjectGrid {
    /// Builds the grid over `bounds` for the objects `member` selects.
    pub fn build(
        bboxes: &[Aabb],
        bounds: &Aabb,
        res: [u32; 3],
        member: impl Fn(&Aabb) -> bool,
    ) -> Result<ObjectGrid, Error> {
        let spec = GridSpec::new(bounds, res);
        let cells = spec.cells();
        let mut count = vec![0u32; cells + 1];
        let mut total: u64 = 0;
        let mut n = 0u64;
        let each = |f: &mut dyn FnMut(u32, usize)| {
            for (id, b) in bboxes.iter().enumerate() {
                let id = id as u32;
                if !member(b) {
                    continue;
                }
                if let Some((lo, hi)) = spec.cell_range(b) {
                    for z in lo[2]..=hi[2] {
                        for y in lo[1]..=hi[1] {
                            let row = spec.index([lo[0], y, z]);
                            for x in 0..=(hi[0] - lo[0]) as usize {
                                f(id, row + x);
                            }
                        }
                    }
                }
            }
        };
        each(&mut |_, c| {
            count[c] += 1;
            total += 1;
        });
        if total > u32::MAX as u64 {
            return Err(Error::Invalid(format!(
                "the grid would list {total} object-voxel pairs; choose a coarser --grid-res"
            )));
        }
        // Exclusive prefix sum: count becomes each voxel's start.
        let mut acc = 0u32;
        for c in count.iter_mut() {
            let k = *c;
            *c = acc;
            acc += k;
        }
        let mut fill = count.clone();
        let mut items = vec![0u32; total as usize];
        let mut last = u32::MAX;
        each(&mut |id, c| {
            items[fill[c] as usize] = id;
            fill[c] += 1;
            if id != last {
                last = id;
                n += 1;
            }
        });
        Ok(ObjectGrid {
            spec,
            start: count,
            items,
            objects: n,
        })
    }

    #[inline(always)]
    pub fn single_cell(&self) -> bool {
        self.start.len() == 2
    }

    #[inline(always)]
    pub fn cell(&self, index: usize) -> &[u32] {
        &self.items[self.start[index] as usize..self.start[index + 1] as usize]
    }
}
