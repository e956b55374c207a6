//! Coarser copies of a grid's occupancy, for walks that skip empty space.
//!
//! A uniform grid sized for a scanned mesh is mostly empty voxels: the
//! dragon's grid has 3.5 million, of which 100,000 list anything. A group
//! of rays walking it voxel by voxel pays for every empty one it crosses.
//! Level `l` of the pyramid has a block per `2^l x 2^l x 2^l` voxels of
//! the grid (level 0: the voxels), and holds for each block of level 1
//! and up a byte whose bit `x + 2y + 4z` is set when its child
//! `(x, y, z)` (a block of the level below, or a voxel) holds a voxel
//! that lists something. A walk descends from the one block of the top
//! level into the set children its rays meet, and reaches only voxels
//! that list something. It is the grid itself, summarised: the voxels
//! and their lists are those of the paper's uniform subdivision.

/// The levels above the grid's voxels.
#[derive(Default)]
pub struct Pyramid {
    /// Level `l + 1` at index `l`.
    levels: Vec<Level>,
}

struct Level {
    res: [u32; 3],
    /// Each block's children that hold something, one bit each.
    kids: Vec<u8>,
}

impl Level {
    #[inline(always)]
    fn index(&self, c: [u32; 3]) -> usize {
        c[0] as usize
            + self.res[0] as usize * (c[1] as usize + self.res[1] as usize * c[2] as usize)
    }
}

impl Pyramid {
    /// The levels over a grid of resolution `res` whose voxel `i` lists
    /// something when bit `i` of `occupied` is set, up to one block.
    pub fn build(res: [u32; 3], occupied: &[u64]) -> Pyramid {
        let mut levels: Vec<Level> = Vec::new();
        let mut below_res = res;
        while below_res.iter().any(|&r| r > 1) {
            let up = below_res.map(|r| r.div_ceil(2));
            let cells = up.iter().map(|&r| r as usize).product::<usize>();
            let mut level = Level {
                res: up,
                kids: vec![0; cells],
            };
            let (rx, ry) = (below_res[0] as usize, below_res[1] as usize);
            let mut mark = |i: usize| {
                let c = [i % rx, i / rx % ry, i / (rx * ry)];
                let child = (c[0] & 1) | (c[1] & 1) << 1 | (c[2] & 1) << 2;
                let j = level.index(c.map(|x| (x / 2) as u32));
                level.kids[j] |= 1 << child;
            };
            match levels.last() {
                None => {
                    for (w, &word) in occupied.iter().enumerate() {
                        let mut bits = word;
                        while bits != 0 {
                            mark(w * 64 + bits.trailing_zeros() as usize);
                            bits &= bits - 1;
                        }
                    }
                }
                Some(below) => {
                    for (i, &k) in below.kids.iter().enumerate() {
                        if k != 0 {
                            mark(i);
                        }
                    }
                }
            }
            levels.push(level);
            below_res = up;
        }
        Pyramid { levels }
    }

    /// Levels above the grid's voxels.
    pub fn height(&self) -> usize {
        self.levels.len()
    }

    /// The children of block `c` of level `l` (1 and up) that hold a voxel
    /// that lists something: bit `x + 2y + 4z` for child `(x, y, z)`.
    #[inline(always)]
    pub fn kids(&self, l: usize, c: [u32; 3]) -> u8 {
        let level = &self.levels[l - 1];
        level.kids[level.index(c)]
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.kids.len()).sum()
    }
}

/// The boxes of every block of every level of a grid's pyramid (level 0:
/// its voxels), grown by a pad and rounded outward to `f32` (so that the
/// same numbers serve a walk in either precision), per axis: block `i`
/// of level `l` spans `lo[l][a][i]..hi[l][a][i]` along axis `a`.
pub struct BlockBounds {
    lo: Vec<[Vec<f64>; 3]>,
    hi: Vec<[Vec<f64>; 3]>,
}

impl BlockBounds {
    /// The bounds for `grid` (whose pyramid has `levels` levels above it),
    /// grown by `pad`.
    pub fn new(spec: &crate::grid::GridSpec, levels: usize, pad: f64) -> BlockBounds {
        let cell = spec.cell_size();
        let down = |x: f64| {
            let f = x as f32;
            if f as f64 > x {
                f.next_down() as f64
            } else {
                f as f64
            }
        };
        let up = |x: f64| {
            let f = x as f32;
            if (f as f64) < x {
                f.next_up() as f64
            } else {
                f as f64
            }
        };
        let mut lo = Vec::with_capacity(levels + 1);
        let mut hi = Vec::with_capacity(levels + 1);
        for l in 0..=levels {
            let per_axis = |a: usize| {
                let res = spec.res[a] as u64;
                let blocks = res.div_ceil(1 << l);
                let edge = |v: u64| {
                    if v >= res {
                        spec.hi[a]
                    } else {
                        spec.lo[a] + v as f64 * cell[a]
                    }
                };
                let los: Vec<f64> = (0..blocks).map(|i| down(edge(i << l) - pad)).collect();
                let his: Vec<f64> = (0..blocks).map(|i| up(edge((i + 1) << l) + pad)).collect();
                (los, his)
            };
            let (x, y, z) = (per_axis(0), per_axis(1), per_axis(2));
            lo.push([x.0, y.0, z.0]);
            hi.push([x.1, y.1, z.1]);
        }
        BlockBounds { lo, hi }
    }

    /// Block `c` of level `l`: its lower and upper corners.
    #[inline(always)]
    pub fn of<R: crate::math::Real>(&self, l: usize, c: [u32; 3]) -> ([R; 3], [R; 3]) {
        let (lo, hi) = (&self.lo[l], &self.hi[l]);
        (
            [
                R::from_f64(lo[0][c[0] as usize]),
                R::from_f64(lo[1][c[1] as usize]),
                R::from_f64(lo[2][c[2] as usize]),
            ],
            [
                R::from_f64(hi[0][c[0] as usize]),
                R::from_f64(hi[1][c[1] as usize]),
                R::from_f64(hi[2][c[2] as usize]),
            ],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_child_is_set_exactly_when_a_voxel_below_it_is() {
        let res = [13u32, 7, 5];
        let cells = 13 * 7 * 5;
        let mut occupied = vec![0u64; (cells as usize).div_ceil(64)];
        let set = [0usize, 12, 13 * 6, 13 * 7 * 4 + 12, 200, 201];
        for &i in &set {
            occupied[i >> 6] |= 1 << (i & 63);
        }
        let p = Pyramid::build(res, &occupied);
        assert_eq!(p.height(), 4, "13 -> 7 -> 4 -> 2 -> 1");
        let holds = |l: usize, c: [usize; 3]| {
            set.iter().any(|&i| {
                let v = [i % 13, i / 13 % 7, i / 91];
                (0..3).all(|a| v[a] >> l == c[a])
            })
        };
        let mut r = res;
        for l in 1..=p.height() {
            let below = r;
            r = r.map(|x| x.div_ceil(2));
            for z in 0..r[2] {
                for y in 0..r[1] {
                    for x in 0..r[0] {
                        let k = p.kids(l, [x, y, z]);
                        for child in 0..8usize {
                            let c = [
                                2 * x as usize + (child & 1),
                                2 * y as usize + (child >> 1 & 1),
                                2 * z as usize + (child >> 2 & 1),
                            ];
                            let inside = (0..3).all(|a| c[a] < below[a] as usize);
                            let want = inside && holds(l - 1, c);
                            assert_eq!(
                                k >> child & 1 != 0,
                                want,
                                "level {l} {x} {y} {z} child {child}"
                            );
                        }
                    }
                }
            }
        }
        assert_eq!(r, [1, 1, 1]);
    }

    #[test]
    fn a_grid_of_one_voxel_has_no_levels() {
        assert_eq!(Pyramid::build([1, 1, 1], &[1]).height(), 0);
    }
}
