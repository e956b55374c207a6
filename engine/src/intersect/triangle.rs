use super::RayQ;
use crate::math::Real;

/// A point relative to the ray origin, as an array padded to four so that
/// indexing it by an axis masked with `& 3` needs no bounds check.
#[inline(always)]
fn rel<R: Real>(v: [f32; 3], o: &[R; 4]) -> [R; 4] {
    [
        R::from_f32(v[0]) - o[0],
        R::from_f32(v[1]) - o[1],
        R::from_f32(v[2]) - o[2],
        R::ZERO,
    ]
}

/// Edge functions of the watertight test: the ray's view of the triangle
/// after shearing the ray direction onto +z.
#[inline(always)]
fn edges<R: Real>(v0: [f32; 3], v1: [f32; 3], v2: [f32; 3], ray: &RayQ<R>) -> ([R; 3], [R; 3]) {
    let (kx, ky, kz) = (
        ray.kx as usize & 3,
        ray.ky as usize & 3,
        ray.kz as usize & 3,
    );
    let o = [ray.o.x, ray.o.y, ray.o.z, R::ZERO];
    let a = rel(v0, &o);
    let b = rel(v1, &o);
    let c = rel(v2, &o);
    let ax = a[kx] - ray.sx * a[kz];
    let ay = a[ky] - ray.sy * a[kz];
    let bx = b[kx] - ray.sx * b[kz];
    let by = b[ky] - ray.sy * b[kz];
    let cx = c[kx] - ray.sx * c[kz];
    let cy = c[ky] - ray.sy * c[kz];
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let sz = ray.sz();
    ([u, v, w], [sz * a[kz], sz * b[kz], sz * c[kz]])
}

/// Watertight ray/triangle test: a ray through a shared edge or vertex hits
/// at least one of the triangles sharing it, so meshes have no cracks.
#[inline(always)]
pub fn intersect<R: Real>(
    v0: [f32; 3],
    v1: [f32; 3],
    v2: [f32; 3],
    ray: &RayQ<R>,
    t_min: R,
    t_max: R,
) -> Option<R> {
    let ([u, v, w], [az, bz, cz]) = edges(v0, v1, v2, ray);
    let z = R::ZERO;
    if (u < z || v < z || w < z) && (u > z || v > z || w > z) {
        return None;
    }
    let det = u + v + w;
    if det == z {
        return None; // the ray lies in the triangle's plane, or it is degenerate
    }
    let t = (u * az + v * bz + w * cz) / det;
    (t > t_min && t < t_max).then_some(t)
}

/// Barycentric weights of the point where `ray` meets the triangle's plane,
/// without the inside test (used to shade a hit already found).
pub fn weights<R: Real>(v0: [f32; 3], v1: [f32; 3], v2: [f32; 3], ray: &RayQ<R>) -> [R; 3] {
    let ([u, v, w], _) = edges(v0, v1, v2, ray);
    let det = u + v + w;
    if det == R::ZERO {
        let third = R::ONE / (R::ONE + R::TWO);
        return [third; 3];
    }
    let inv = R::ONE / det;
    [u * inv, v * inv, w * inv]
}
