use super::GridSpec;
use crate::math::Vec3;

/// The 3D-DDA walk of a ray through the voxels of a grid (Amanatides and
/// Woo), in order of distance. Plain data, so a breadth-first tracer can
/// keep it with the ray between passes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dda {
    /// The current voxel and its linear index in the grid.
    pub cell: [i32; 3],
    pub index: usize,
    /// Distance at which the ray enters the current voxel.
    pub t_enter: f64,
    /// Distance to the next voxel face on each axis.
    t_next: [f64; 3],
    t_delta: [f64; 3],
    /// Where the walk ends (the grid's far side, or the ray's end).
    pub t_end: f64,
    /// Voxel step per axis (-1, 0, 1), the index change it makes, and the
    /// voxel coordinate that means "left the grid".
    step: [i32; 3],
    stride: [isize; 3],
    out: [i32; 3],
}

impl Dda {
    /// Starts the walk at the ray's entry into the grid, or `None` if the
    /// ray misses the grid within `[t_min, t_max]`. `inv` is 1/d per axis.
    #[inline]
    pub fn start(g: &GridSpec, o: Vec3, d: Vec3, inv: Vec3, t_min: f64, t_max: f64) -> Option<Dda> {
        let (t0, t1) = g.clip(o, d, inv, t_min, t_max)?;
        let c = g.cell_of(o + d * t0);
        let cs = g.cell_size();
        let strides = [
            1isize,
            g.res[0] as isize,
            g.res[0] as isize * g.res[1] as isize,
        ];
        let mut t_next = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        let mut step = [0i32; 3];
        let mut stride = [0isize; 3];
        let mut out = [-1i32; 3];
        for i in 0..3 {
            if d[i] > 0.0 {
                step[i] = 1;
                out[i] = g.res[i] as i32;
                t_next[i] = (g.lo[i] + (c[i] + 1) as f64 * cs[i] - o[i]) * inv[i];
                t_delta[i] = cs[i] * inv[i];
            } else if d[i] < 0.0 {
                step[i] = -1;
                t_next[i] = (g.lo[i] + c[i] as f64 * cs[i] - o[i]) * inv[i];
                t_delta[i] = -cs[i] * inv[i];
            }
            stride[i] = step[i] as isize * strides[i];
        }
        Some(Dda {
            cell: [c[0] as i32, c[1] as i32, c[2] as i32],
            index: g.index(c),
            t_enter: t0,
            t_next,
            t_delta,
            t_end: t1,
            step,
            stride,
            out,
        })
    }

    /// Distance at which the ray leaves the current voxel.
    #[inline(always)]
    pub fn t_exit(&self) -> f64 {
        self.t_next[0]
            .min(self.t_next[1])
            .min(self.t_next[2])
            .min(self.t_end)
    }

    /// Moves to the next voxel; `false` when the walk has left the grid or
    /// passed its end.
    #[inline(always)]
    pub fn advance(&mut self) -> bool {
        self.advance_axis().is_some()
    }

    /// As [`Dda::advance`], returning the axis stepped along.
    #[inline(always)]
    pub fn advance_axis(&mut self) -> Option<usize> {
        // The axis of the nearest face, the lowest axis on a tie: x if
        // t_x <= t_y and t_x <= t_z, else y if t_y <= t_z, else z. Picked
        // by selects rather than branches, which the walk's turns
        // mispredict about every other step.
        let t = &self.t_next;
        let xy = (t[1] < t[0]) as usize;
        let axis = if t[2] < t[xy] { 2 } else { xy };
        let t = self.t_next[axis];
        if t >= self.t_end {
            return None;
        }
        let c = self.cell[axis] + self.step[axis];
        if c == self.out[axis] {
            return None;
        }
        self.cell[axis] = c;
        self.index = (self.index as isize + self.stride[axis]) as usize;
        self.t_enter = t;
        self.t_next[axis] += self.t_delta[axis];
        Some(axis)
    }

    /// Moves to the first voxel of the walk outside the current voxel's
    /// block (the cube of `2^shift` voxels a side, aligned on multiples of
    /// it): bit for bit the state the [`Dda::advance_axis`] calls that get
    /// there leave, and the axis of the last of them; `None` where those
    /// calls end the walk first. For walks through empty space, which
    /// visit nothing in between: a block's crossing costs a few additions
    /// per axis instead of a step (and a voxel's flags) per voxel.
    ///
    /// The walk takes its steps in order of `(t_next, axis)` (each axis's
    /// distances only grow, ties go to the lowest axis), so the step that
    /// leaves the block is the first in that order of each axis's step to
    /// the block's side; the other axes take, before it, exactly their
    /// steps that come before it in that order. Each axis's distances are
    /// the same additions in the same order as step by step.
    #[inline]
    pub fn leave_block(&mut self, shift: u32) -> Option<usize> {
        let mut k = [0i32; 3];
        let mut side = [f64::INFINITY; 3];
        for a in 0..3 {
            if self.step[a] == 0 {
                continue; // its distance stays infinite: it never steps
            }
            let c = self.cell[a];
            let to_side = if self.step[a] > 0 {
                (((c >> shift) + 1) << shift) - c
            } else {
                c - ((c >> shift) << shift) + 1
            };
            k[a] = to_side.min((self.out[a] - c) * self.step[a]);
            let mut t = self.t_next[a];
            for _ in 1..k[a] {
                t += self.t_delta[a];
            }
            side[a] = t;
        }
        let xy = (side[1] < side[0]) as usize;
        let e = if side[2] < side[xy] { 2 } else { xy };
        let t_e = side[e];
        if t_e >= self.t_end || self.cell[e] + k[e] * self.step[e] == self.out[e] {
            return None;
        }
        let mut index = self.index as isize;
        for a in 0..3 {
            let mut n = 0;
            if a == e {
                n = k[e];
                for _ in 0..n {
                    self.t_next[a] += self.t_delta[a];
                }
            } else {
                while self.t_next[a] < t_e || (self.t_next[a] == t_e && a < e) {
                    self.t_next[a] += self.t_delta[a];
                    n += 1;
                }
            }
            self.cell[a] += n * self.step[a];
            index += n as isize * self.stride[a];
        }
        self.index = index as usize;
        self.t_enter = t_e;
        Some(e)
    }

    /// Whether the step just taken along `axis` entered a new block of
    /// `2^shift` voxels a side (see [`Dda::leave_block`]).
    #[inline(always)]
    pub fn entered_block(&self, axis: usize, shift: u32) -> bool {
        let mask = (1 << shift) - 1;
        self.cell[axis] & mask == if self.step[axis] > 0 { 0 } else { mask }
    }

    /// Whether the walk moves up (toward higher voxel coordinates) on `axis`.
    #[inline(always)]
    pub fn steps_up(&self, axis: usize) -> bool {
        self.step[axis] > 0
    }

    /// The walk of [`Dda::start`] (same ray, grid and extent) moved on
    /// to voxel `cell`, which that walk reaches: bit for bit the state
    /// [`Dda::advance`] leaves there, except `t_enter`, which is left at
    /// minus infinity (the next [`Dda::advance`] sets it). `None` where
    /// [`Dda::start`] gives `None`.
    ///
    /// The distance to the next face on an axis changes only when the walk
    /// steps along that axis, by adding `t_delta` to it; the walk has
    /// stepped `|cell - start|` times along each axis, so the same
    /// additions in the same order give the same bits. (A product in place
    /// of the sums would round differently.) This lets a breadth-first ray
    /// keep only the voxel it stopped in between passes, not its walk.
    #[inline]
    pub fn start_at(
        g: &GridSpec,
        o: Vec3,
        d: Vec3,
        inv: Vec3,
        t_min: f64,
        t_max: f64,
        cell: [u32; 3],
    ) -> Option<Dda> {
        let mut w = Dda::start(g, o, d, inv, t_min, t_max)?;
        for (i, &c) in cell.iter().enumerate() {
            let steps = (c as i32 - w.cell[i]) * w.step[i];
            debug_assert!(steps >= 0, "voxel {cell:?} is not on the walk");
            for _ in 0..steps {
                w.t_next[i] += w.t_delta[i];
            }
            w.cell[i] = c as i32;
        }
        w.index = g.index(cell);
        w.t_enter = f64::NEG_INFINITY;
        Some(w)
    }

    /// The current voxel's coordinates.
    #[inline(always)]
    pub fn voxel(&self) -> [u32; 3] {
        [
            self.cell[0] as u32,
            self.cell[1] as u32,
            self.cell[2] as u32,
        ]
    }
}
