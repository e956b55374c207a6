//! Admission: rays given slots between passes (the paper's ray filling),
//! from a stream in id order or by id from any thread, with the rays that
//! meet no grid passed over.

use super::Shard;
use super::slot::{Cold, Hot, MAX_GRIDS, NONE16, empty_cold, od64};
use crate::bf::records::{RayKind, RayRec};
use crate::bf::voxels::VoxelGrids;
use crate::hit::{Hit, PrimId};
use crate::intersect::RayQ;
use crate::math::{Vec3, Vec3Ext};
use crate::simd::Elem;
use rayon::prelude::*;

/// Whether the ray meets no grid's box within its extent: nothing can
/// be found along it.
pub(super) fn misses_every_grid(r: &RayRec, grids: &VoxelGrids, eps: f64) -> bool {
    let o = Vec3::from_array(r.o);
    let d = Vec3::from_array(r.d);
    let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    let t_min = if r.kind == RayKind::Eye as u8 {
        0.0
    } else {
        eps
    };
    grids
        .grids
        .iter()
        .all(|g| g.spec.clip(o, d, inv, t_min, r.t_max).is_none())
}

/// Puts what [`load`] needs of ray `r` into slot `i`: the serial part
/// of giving a ray a slot (see [`Shard::pending`]).
pub(super) fn stage<R: Elem>(sh: &mut Shard<R>, i: usize, id: u64, r: &RayRec, eps: f64) {
    let t_min = if r.kind == RayKind::Eye as u8 {
        0.0
    } else {
        eps
    };
    let (o, d) = (Vec3::from_array(r.o), Vec3::from_array(r.d));
    let shadow = r.is_shadow();
    sh.hot[i] = Hot {
        mailbox: PrimId::NONE,
        best: Hit::NONE,
        upper: if shadow {
            R::from_f64(r.t_max)
        } else {
            R::INFINITY
        },
        t_min: R::from_f64(t_min),
        prev: [[NONE16; 3]; MAX_GRIDS],
        active: true,
        shadow,
        blocked: false,
    };
    let q = &mut sh.q[i];
    q.o = o.cast();
    q.d = d.cast();
    sh.cold[i] = Cold {
        id,
        t_max: r.t_max,
        o: o.to_array().map(R::keep),
        d: d.to_array().map(R::keep),
        t_min: R::keep(t_min),
        ..empty_cold()
    };
}

/// Makes a ray [`stage`] put into slot `i` ready for its walks and tests.
pub(super) fn load<R: Elem>(sh: &mut Shard<R>, i: usize) {
    sh.live += 1;
    let (o, d) = od64(&sh.q[i], &sh.cold[i]);
    let inv = Vec3::new(1.0 / d.x, 1.0 / d.y, 1.0 / d.z);
    sh.q[i] = RayQ::with_inverse(o.cast(), d.cast(), inv.cast());
}

/// Admission of rays that can be had by id (see [`super::intersect_rays`]): the
/// same rays, in the same order, as filling the slots one by one from a
/// stream, but with the rays made, looked at and loaded by all threads.
pub(super) struct ByIdFill<'a> {
    pub(super) ray: &'a (dyn Fn(u64) -> RayRec + Sync),
    pub(super) total: u64,
    /// The first id not yet admitted or passed over.
    pub(super) next: u64,
    /// Whether each ray of the window looked at meets no grid (reused).
    pub(super) sky: Vec<bool>,
    /// The ids admitted this pass, in order.
    pub(super) ids: Vec<u64>,
    /// The same ids dealt to the shards in turn ([`Dealer`]): shard `k`
    /// loads `dealt[k]` into its empty slots, in slot order.
    pub(super) dealt: Vec<Vec<u64>>,
}

impl ByIdFill<'_> {
    /// Admits up to `free[k]` rays for shard `k`, in order: the next rays
    /// that meet some grid, dealt to the shards' empty slots in turn as
    /// a stream's fill deals them. Returns the number
    /// of rays passed over because they meet no grid (misses at once).
    pub(super) fn admit(
        &mut self,
        free: &[usize],
        pool: &rayon::ThreadPool,
        grids: &VoxelGrids,
        eps: f64,
    ) -> u64 {
        let want: usize = free.iter().sum();
        self.ids.clear();
        let mut sky = 0;
        while self.ids.len() < want && self.next < self.total {
            // A window a little larger than what is missing: few rays are
            // looked at twice, and a sky-heavy window is followed by
            // another.
            let need = want - self.ids.len();
            let w = ((need + need / 4 + 64) as u64).min(self.total - self.next) as usize;
            self.sky.resize(w, false);
            let (ray, base) = (self.ray, self.next);
            pool.install(|| {
                self.sky[..w]
                    .par_iter_mut()
                    .enumerate()
                    .with_min_len(1024)
                    .for_each(|(i, s)| *s = misses_every_grid(&ray(base + i as u64), grids, eps))
            });
            let mut used = w;
            for (i, &s) in self.sky[..w].iter().enumerate() {
                if self.ids.len() == want {
                    used = i;
                    break;
                }
                if s {
                    sky += 1;
                } else {
                    self.ids.push(base + i as u64);
                }
            }
            self.next += used as u64;
        }
        deal(&self.ids, free, &mut self.dealt);
        sky
    }
}

/// Deals a pass's admitted rays to the shards in turn, passing over a
/// shard once it holds as many as it has empty slots, so that every
/// shard holds rays from the whole stretch admitted: neighbouring rays
/// meet the same objects, and shards given halves of the stretch (halves
/// of the image) would wait for each other at every batch of blocks. The
/// one rule for both fills: a stream's, ray by ray as it is read (see
/// [`super::intersect_rays`]), and [`ByIdFill`]'s, of ids admitted at once.
pub(super) struct Dealer {
    /// Empty slots left per shard.
    free: Vec<usize>,
    /// Empty slots left in all.
    left: usize,
    /// The shard whose turn it is.
    k: usize,
}

impl Dealer {
    pub(super) fn new(free: Vec<usize>) -> Dealer {
        let left = free.iter().sum();
        Dealer { free, left, k: 0 }
    }

    /// The shard the next ray goes to; `None` once every shard is full.
    pub(super) fn next_shard(&mut self) -> Option<usize> {
        if self.left == 0 {
            return None;
        }
        while self.free[self.k] == 0 {
            self.k = (self.k + 1) % self.free.len();
        }
        let k = self.k;
        self.free[k] -= 1;
        self.left -= 1;
        self.k = (k + 1) % self.free.len();
        Some(k)
    }
}

/// Deals `ids` as [`Dealer`] does: `dealt[k]` gets shard `k`'s, in order.
/// There must be no more ids than empty slots.
fn deal(ids: &[u64], free: &[usize], dealt: &mut Vec<Vec<u64>>) {
    dealt.resize_with(free.len(), Vec::new);
    for d in dealt.iter_mut() {
        d.clear();
    }
    let mut dealer = Dealer::new(free.to_vec());
    for &id in ids {
        let k = dealer.next_shard().expect("no more ids than empty slots");
        dealt[k].push(id);
    }
}

#[cfg(test)]
mod tests {
    use super::{Dealer, deal};

    /// Each shard gets every other ray of the stretch admitted, not a
    /// half of it; a full shard is passed over, the others take the rest.
    #[test]
    fn rays_are_dealt_in_turn_to_the_shards_with_room() {
        let mut dealt = Vec::new();
        deal(&[10, 11, 12, 13, 14], &[3, 3], &mut dealt);
        assert_eq!(dealt, vec![vec![10, 12, 14], vec![11, 13]]);
        deal(&[0, 1, 2, 3, 4], &[1, 4], &mut dealt);
        assert_eq!(dealt, vec![vec![0], vec![1, 2, 3, 4]]);
        deal(&[5, 6, 7], &[0, 2, 1], &mut dealt);
        assert_eq!(dealt, vec![vec![], vec![5, 7], vec![6]]);
        deal(&[], &[2, 2], &mut dealt);
        assert_eq!(dealt, vec![Vec::<u64>::new(), vec![]]);
    }

    /// A stream's fill asks the dealer shard by shard until every shard
    /// is full: the shards with room in turn, then no more.
    #[test]
    fn the_dealer_runs_dry_when_every_shard_is_full() {
        let mut dealer = Dealer::new(vec![1, 3, 0, 2]);
        let turns: Vec<usize> = std::iter::from_fn(|| dealer.next_shard()).collect();
        assert_eq!(turns, vec![0, 1, 3, 1, 3, 1]);
        assert_eq!(dealer.next_shard(), None);
        assert_eq!(Dealer::new(vec![0, 0]).next_shard(), None);
    }
}
