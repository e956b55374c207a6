//! One ray at a time: the 3D-DDA walk (Amanatides and Woo) with mailboxes
//! and early termination, for rays too incoherent to walk as a packet.

use super::nested::{Entry, high_first, ray_meets};
use super::packet::Hits;
use super::trace::{NO_OBJECT, Scratch};
use super::{DfScene, ObjectGrid};
use crate::grid::Dda;
use crate::intersect::RayQ;
use crate::math::{Real, Vec3};

/// The nearest hit beyond `t_min` of the ray `q` (`o`, `d`, `inv` = 1/d),
/// offered to lane `lane` of `best`: smallest distance, ties to the smaller object id.
/// Grids are walked voxel by voxel and left as soon as the best hit lies
/// before the current voxel's far side.
#[inline]
pub fn nearest<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    q: &RayQ<R>,
    o: Vec3,
    d: Vec3,
    inv: Vec3,
    t_min: f64,
    best: &mut Hits<R>,
    lane: usize,
) {
    let stamp = sc.next_stamp();
    // The large objects' grid first: one ground polygon found early prunes
    // the walk through the main grid.
    for g in s.grids.iter().rev() {
        nearest_in(s, sc, g, stamp, q, o, d, inv, t_min, best, lane);
    }
}

/// [`nearest`] within grid `g` alone, with mailbox stamp `stamp`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn nearest_in<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    g: &ObjectGrid,
    stamp: u32,
    q: &RayQ<R>,
    o: Vec3,
    d: Vec3,
    inv: Vec3,
    t_min: f64,
    best: &mut Hits<R>,
    lane: usize,
) {
    let rmin = R::from_f64(t_min);
    let (hf, pad) = (high_first(d), s.slack);
    // Each voxel's objects; in a crowded voxel's hierarchy, only the boxes
    // the ray may meet before its best hit so far.
    let visit = |sc: &mut Scratch<R>, best: &mut Hits<R>, cell: usize| {
        g.visit(cell, hf, (), &mut |e| match e {
            Entry::Box(b, ()) => {
                ray_meets(o, inv, t_min, best.upper[lane].to_f64(), b, pad).then_some(())
            }
            Entry::Object(id, ()) => {
                test_nearest(s, sc, stamp, q, o, d, rmin, id, best, lane);
                Some(())
            }
        });
    };
    if g.single_cell() {
        // A one-voxel grid (a few large objects): no walk needed.
        visit(sc, best, 0);
        return;
    }
    let Some(mut w) = Dda::start(&g.spec, o, d, inv, t_min, best.t[lane].next_up()) else {
        return;
    };
    loop {
        visit(sc, best, w.index);
        if (best.hit(lane).is_some() && best.t[lane] < w.t_exit()) || !w.advance() {
            break;
        }
    }
}

/// Tests one candidate for the nearest hit, unless this ray tested it
/// already (mailbox).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn test_nearest<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    stamp: u32,
    q: &RayQ<R>,
    o: Vec3,
    d: Vec3,
    rmin: R,
    id: u32,
    best: &mut Hits<R>,
    lane: usize,
) {
    let m = &mut sc.mail[id as usize];
    if *m == stamp {
        return;
    }
    *m = stamp;
    if let Some((t, prim)) = s.test(id, q, o, d, rmin, best.upper[lane], &mut sc.tests) {
        best.offer(lane, t, prim, s.objects.ranks());
    }
}

/// Whether anything lies between `t_min` and `t_max` along the ray; tries
/// the cached blocker of `slot` first and stops at the first blocker.
/// `tested` (or `NO_OBJECT`) is an object already tried for this ray.
#[inline]
pub fn occluded<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    slot: usize,
    q: &RayQ<R>,
    o: Vec3,
    d: Vec3,
    inv: Vec3,
    t_min: f64,
    t_max: f64,
    tested: u32,
) -> bool {
    let stamp = sc.next_stamp();
    if tested != NO_OBJECT {
        sc.mail[tested as usize] = stamp;
    }
    let (rmin, rmax) = (R::from_f64(t_min), R::from_f64(t_max));
    let cached = sc.shadow_cache[slot];
    if cached != NO_OBJECT && blocks(s, sc, stamp, q, o, d, rmin, rmax, cached) {
        return true;
    }
    for g in s.grids.iter().rev() {
        let id = blocker_in(s, sc, g, stamp, q, o, d, inv, t_min, t_max);
        if id != NO_OBJECT {
            sc.shadow_cache[slot] = id;
            return true;
        }
    }
    false
}

/// The first object of grid `g` found between `t_min` and `t_max` along
/// the ray (not one stamped `stamp` already), or `NO_OBJECT`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub fn blocker_in<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    g: &ObjectGrid,
    stamp: u32,
    q: &RayQ<R>,
    o: Vec3,
    d: Vec3,
    inv: Vec3,
    t_min: f64,
    t_max: f64,
) -> u32 {
    let (rmin, rmax) = (R::from_f64(t_min), R::from_f64(t_max));
    let (hf, pad) = (high_first(d), s.slack);
    // The first blocker among a voxel's objects (in a crowded voxel's
    // hierarchy, among the boxes the segment meets).
    let blocker = |sc: &mut Scratch<R>, cell: usize| {
        let mut found = NO_OBJECT;
        g.visit(cell, hf, (), &mut |e| match e {
            Entry::Box(b, ()) => ray_meets(o, inv, t_min, t_max, b, pad).then_some(()),
            Entry::Object(id, ()) => {
                if blocks(s, sc, stamp, q, o, d, rmin, rmax, id) {
                    found = id;
                }
                (found == NO_OBJECT).then_some(())
            }
        });
        found
    };
    if g.single_cell() {
        return blocker(sc, 0);
    }
    let Some(mut w) = Dda::start(&g.spec, o, d, inv, t_min, t_max) else {
        return NO_OBJECT;
    };
    loop {
        let id = blocker(sc, w.index);
        if id != NO_OBJECT || !w.advance() {
            return id;
        }
    }
}

/// Whether object `id` blocks the shadow ray, unless tested already.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn blocks<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    stamp: u32,
    q: &RayQ<R>,
    o: Vec3,
    d: Vec3,
    rmin: R,
    rmax: R,
    id: u32,
) -> bool {
    let m = &mut sc.mail[id as usize];
    if *m == stamp {
        return false;
    }
    *m = stamp;
    s.test_blocks(id, q, o, d, rmin, rmax, &mut sc.tests)
}
