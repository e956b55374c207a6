//! The polygon policy: what a face of a mesh becomes.
//!
//! - Consecutive corners at the same position are merged (a quad that
//!   repeats a corner is the triangle it draws).
//! - A face left with fewer than three corners, or with no area (all its
//!   corners on one line), is degenerate: skipped and counted.
//! - A triangle is kept.
//! - A polygon of more corners is kept whole where it is planar (every
//!   corner within 1e-5 of its size of its plane); one with a normal per
//!   corner (smooth shading) must also be convex, since patches are
//!   intersected as a fan. It is started at its best-conditioned corner,
//!   so that the plane sray takes from its first three corners is sound.
//! - Any other polygon is triangulated: by ear clipping in its plane's
//!   projection (up to [`MAX_EAR_CLIPPING`] corners), else as a fan; a
//!   resulting triangle of no area is dropped.

/// Polygons of at most this many corners are triangulated by ear clipping
/// (cubic in the worst case); larger ones as a fan.
pub const MAX_EAR_CLIPPING: usize = 64;

/// Relative distance from its plane that a corner of a planar polygon may
/// have (of the polygon's bounding-box diagonal).
pub const PLANAR_TOLERANCE: f64 = 1e-5;

type P = [f64; 3];

fn p64(v: [f32; 3]) -> P {
    [v[0] as f64, v[1] as f64, v[2] as f64]
}
fn sub(a: P, b: P) -> P {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: P, b: P) -> P {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn dot(a: P, b: P) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn len(a: P) -> f64 {
    dot(a, a).sqrt()
}

/// Newell's normal of a polygon (twice its area vector); zero for a
/// polygon of no area.
pub fn newell(v: &[[f32; 3]]) -> P {
    let mut m = [0.0; 3];
    let c = p64(v[0]);
    for i in 0..v.len() {
        let a = sub(p64(v[i]), c);
        let b = sub(p64(v[(i + 1) % v.len()]), c);
        let x = cross(a, b);
        m[0] += x[0];
        m[1] += x[1];
        m[2] += x[2];
    }
    m
}

/// Whether a triangle has area (its corners are not on one line).
pub fn has_area(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> bool {
    let n = cross(sub(p64(b), p64(a)), sub(p64(c), p64(a)));
    n != [0.0; 3]
}

/// What becomes of a face.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plan {
    Degenerate,
    /// Kept whole (a triangle, or a planar polygon), started at this
    /// corner.
    Keep {
        start: usize,
    },
    Triangulate,
}

/// Merges consecutive corners at the same position (and the last with the
/// first), keeping `normals` in step when given.
pub fn merge_repeats(pos: &mut Vec<[f32; 3]>, normals: Option<&mut Vec<[f32; 3]>>) {
    let same = |a: &[f32; 3], b: &[f32; 3]| a.map(f32::to_bits) == b.map(f32::to_bits);
    let mut keep = Vec::new();
    let n = pos.len();
    let mut any = false;
    for i in 0..n {
        let dup = if i + 1 < n {
            same(&pos[i], &pos[i + 1])
        } else {
            // The last corner against the first kept one.
            n > 1
                && keep
                    .first()
                    .is_some_and(|&f: &usize| same(&pos[i], &pos[f]))
        };
        if dup {
            any = true;
        } else {
            keep.push(i);
        }
    }
    if !any {
        return;
    }
    let p: Vec<[f32; 3]> = keep.iter().map(|&i| pos[i]).collect();
    *pos = p;
    if let Some(nm) = normals {
        let k: Vec<[f32; 3]> = keep.iter().map(|&i| nm[i]).collect();
        *nm = k;
    }
}

/// Decides a face's fate from its corners (after [`merge_repeats`]).
/// `smooth`: it has a normal per corner (a patch).
pub fn plan(v: &[[f32; 3]], smooth: bool) -> Plan {
    if v.len() < 3 {
        return Plan::Degenerate;
    }
    let n = newell(v);
    let nl = len(n);
    if !(nl > 0.0) {
        return Plan::Degenerate;
    }
    if v.len() == 3 {
        return if has_area(v[0], v[1], v[2]) {
            Plan::Keep { start: 0 }
        } else {
            Plan::Degenerate
        };
    }
    let unit = [n[0] / nl, n[1] / nl, n[2] / nl];
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in v {
        for i in 0..3 {
            lo[i] = lo[i].min(p[i] as f64);
            hi[i] = hi[i].max(p[i] as f64);
        }
    }
    let size = len(sub(hi, lo));
    let p0 = p64(v[0]);
    let planar = v
        .iter()
        .all(|p| dot(unit, sub(p64(*p), p0)).abs() <= PLANAR_TOLERANCE * size);
    if !planar || (smooth && !convex(v, unit)) {
        return Plan::Triangulate;
    }
    // The corner whose two edges span the most area, first.
    let mut best = (0usize, -1.0);
    for i in 0..v.len() {
        let a = p64(v[i]);
        let b = p64(v[(i + 1) % v.len()]);
        let c = p64(v[(i + 2) % v.len()]);
        let x = dot(cross(sub(b, a), sub(c, a)), unit).abs();
        if x > best.1 {
            best = (i, x);
        }
    }
    Plan::Keep { start: best.0 }
}

/// The two axes of the projection that drops the normal's largest
/// component.
fn axes(n: P) -> (usize, usize) {
    let a = [n[0].abs(), n[1].abs(), n[2].abs()];
    if a[0] >= a[1] && a[0] >= a[2] {
        (1, 2)
    } else if a[1] >= a[2] {
        (2, 0)
    } else {
        (0, 1)
    }
}

/// Whether a planar polygon of normal `n` is convex: every turn the same
/// way, and once around.
fn convex(v: &[[f32; 3]], n: P) -> bool {
    let k = v.len();
    let mut turn = 0.0f64;
    let mut sign = 0.0f64;
    for i in 0..k {
        let a = p64(v[i]);
        let b = p64(v[(i + 1) % k]);
        let c = p64(v[(i + 2) % k]);
        let e1 = sub(b, a);
        let e2 = sub(c, b);
        let s = dot(cross(e1, e2), n);
        if s != 0.0 {
            if sign == 0.0 {
                sign = s.signum();
            } else if s.signum() != sign {
                return false;
            }
        }
        let (l1, l2) = (len(e1), len(e2));
        if l1 > 0.0 && l2 > 0.0 {
            turn += (dot(e1, e2) / (l1 * l2)).clamp(-1.0, 1.0).acos();
        }
    }
    (turn - std::f64::consts::TAU).abs() < 1e-3
}

/// Triangles (corner index triples) covering a polygon: ear clipping in
/// the projection of its Newell plane, a fan where that fails or the
/// polygon is large.
pub fn triangulate(v: &[[f32; 3]], out: &mut Vec<[usize; 3]>) {
    out.clear();
    let k = v.len();
    if k < 3 {
        return;
    }
    if k > MAX_EAR_CLIPPING {
        fan(0..k, out);
        return;
    }
    let n = newell(v);
    let (iu, iv) = axes(n);
    let flip = n[3 - iu - iv] < 0.0;
    let pt = |i: usize| -> [f64; 2] {
        let (u, w) = (v[i][iu] as f64, v[i][iv] as f64);
        if flip { [w, u] } else { [u, w] }
    };
    let area2 = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let mut idx: Vec<usize> = (0..k).collect();
    let mut guard = 0;
    let mut i = 0;
    while idx.len() > 3 {
        let m = idx.len();
        let (a, b, c) = (idx[(i + m - 1) % m], idx[i % m], idx[(i + 1) % m]);
        let (pa, pb, pc) = (pt(a), pt(b), pt(c));
        let mut ear = area2(pa, pb, pc) > 0.0;
        if ear {
            for &j in &idx {
                if j == a || j == b || j == c {
                    continue;
                }
                let p = pt(j);
                if area2(pa, pb, p) >= 0.0 && area2(pb, pc, p) >= 0.0 && area2(pc, pa, p) >= 0.0 {
                    ear = false;
                    break;
                }
            }
        }
        if ear {
            out.push([a, b, c]);
            idx.remove(i % m);
            guard = 0;
            if i >= idx.len() {
                i = 0;
            }
        } else {
            i = (i + 1) % m;
            guard += 1;
            if guard > m {
                // No ear (a self-intersecting or twisted outline): a fan
                // over what remains.
                fan(idx.iter().copied(), out);
                return;
            }
        }
    }
    out.push([idx[0], idx[1], idx[2]]);
}

fn fan(mut idx: impl Iterator<Item = usize>, out: &mut Vec<[usize; 3]>) {
    let Some(first) = idx.next() else { return };
    let Some(mut prev) = idx.next() else { return };
    for i in idx {
        out.push([first, prev, i]);
        prev = i;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri_area(v: &[[f32; 3]], t: &[[usize; 3]]) -> f64 {
        t.iter()
            .map(|&[a, b, c]| {
                len(cross(sub(p64(v[b]), p64(v[a])), sub(p64(v[c]), p64(v[a])))) / 2.0
            })
            .sum()
    }

    #[test]
    fn triangles_and_degenerate_faces() {
        let a = [0.0, 0.0, 0.0];
        let b = [1.0, 0.0, 0.0];
        let c = [0.0, 1.0, 0.0];
        assert_eq!(plan(&[a, b, c], false), Plan::Keep { start: 0 });
        assert_eq!(plan(&[a, b, [2.0, 0.0, 0.0]], false), Plan::Degenerate);
        assert_eq!(plan(&[a, b], false), Plan::Degenerate);
        let mut v = vec![a, b, b, c, a];
        merge_repeats(&mut v, None);
        assert_eq!(v, vec![a, b, c]);
        let mut v = vec![a, a, a];
        merge_repeats(&mut v, None);
        assert_eq!(plan(&v, false), Plan::Degenerate);
    }

    #[test]
    fn planar_polygons_are_kept_others_triangulated() {
        let square = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        assert!(matches!(plan(&square, true), Plan::Keep { .. }));
        let mut twisted = square;
        twisted[2][2] = 0.2;
        assert_eq!(plan(&twisted, false), Plan::Triangulate);
        // Planar but not convex: a polygon keeps it, a patch may not.
        let ell = [
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [2.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [1.0, 2.0, 0.0],
            [0.0, 2.0, 0.0],
        ];
        assert!(matches!(plan(&ell, false), Plan::Keep { .. }));
        assert_eq!(plan(&ell, true), Plan::Triangulate);
        let mut t = Vec::new();
        triangulate(&ell, &mut t);
        assert_eq!(t.len(), 4);
        assert!((tri_area(&ell, &t) - 3.0).abs() < 1e-12, "{t:?}");
        triangulate(&twisted, &mut t);
        assert_eq!(t.len(), 2);
    }

    #[test]
    fn large_polygons_fan() {
        let v: Vec<[f32; 3]> = (0..100)
            .map(|i| {
                let a = i as f32 / 100.0 * std::f32::consts::TAU;
                [a.cos(), a.sin(), 0.0]
            })
            .collect();
        let mut t = Vec::new();
        triangulate(&v, &mut t);
        assert_eq!(t.len(), 98);
    }
}
