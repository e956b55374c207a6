//! One ray at a time: the 3D-DDA walk (Amanatides and Woo) with mailboxes
//! and early termination, for rays too incoherent to walk as a packet.

use super::DfScene;
use super::packet::Hits;
use super::trace::{NO_OBJECT, Scratch};
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
    let rmin = R::from_f64(t_min);
    // The large objects' grid first: one ground polygon found early prunes
    // the walk through the main grid.
    for g in s.grids.iter().rev() {
        if g.single_cell() {
            // A one-voxel grid (a few large objects): no walk needed.
            for &id in g.cell(0) {
                test_nearest(s, sc, stamp, q, rmin, id, best, lane);
            }
            continue;
        }
        let Some(mut w) = Dda::start(&g.spec, o, d, inv, t_min, best.t[lane].next_up()) else {
            continue;
        };
        loop {
            for &id in g.cell(w.index) {
                test_nearest(s, sc, stamp, q, rmin, id, best, lane);
            }
            if (best.hit(lane).is_some() && best.t[lane] < w.t_exit()) || !w.advance() {
                break;
            }
        }
    }
}

/// Tests one candidate for the nearest hit, unless this ray tested it
/// already (mailbox).
#[inline(always)]
fn test_nearest<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    stamp: u32,
    q: &RayQ<R>,
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
    let shape = &s.shapes[id as usize];
    sc.tests.add(shape.kind());
    if let Some(t) = s.intersect(id, q, rmin, best.upper[lane]) {
        best.offer(lane, t, id);
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
    if cached != NO_OBJECT && blocks(s, sc, stamp, q, rmin, rmax, cached) {
        return true;
    }
    for g in s.grids.iter().rev() {
        if g.single_cell() {
            for &id in g.cell(0) {
                if blocks(s, sc, stamp, q, rmin, rmax, id) {
                    sc.shadow_cache[slot] = id;
                    return true;
                }
            }
            continue;
        }
        let Some(mut w) = Dda::start(&g.spec, o, d, inv, t_min, t_max) else {
            continue;
        };
        loop {
            for &id in g.cell(w.index) {
                if blocks(s, sc, stamp, q, rmin, rmax, id) {
                    sc.shadow_cache[slot] = id;
                    return true;
                }
            }
            if !w.advance() {
                break;
            }
        }
    }
    false
}

/// Whether object `id` blocks the shadow ray, unless tested already.
#[inline(always)]
fn blocks<R: Real>(
    s: &DfScene,
    sc: &mut Scratch<R>,
    stamp: u32,
    q: &RayQ<R>,
    rmin: R,
    rmax: R,
    id: u32,
) -> bool {
    let m = &mut sc.mail[id as usize];
    if *m == stamp {
        return false;
    }
    *m = stamp;
    let shape = &s.shapes[id as usize];
    sc.tests.add(shape.kind());
    s.intersect(id, q, rmin, rmax).is_some()
}
