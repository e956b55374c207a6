//! The primitive kinds, one file each, and the one list that makes them
//! the scene's shapes.
//!
//! A kind owns everything about its primitives: how a record of the object
//! database lays out its geometry, what a well-formed one satisfies, its
//! bounding box, what an intersection test can compute once and reuse
//! (its [`Kind::Prep`]), the intersection test itself, and the surface at a
//! hit. Everything else (the database, both tracers, shading, statistics)
//! goes through [`Shape`], [`Prepared`] and [`ShapeKind`], which the
//! [`kinds!`] list below generates. Adding a kind is one new file and one
//! line in that list.
//!
//! Every routine reads the primitive's `f32` data as stored in the object
//! database and computes in the precision `R` of the ray. Both tracers call
//! exactly these functions on exactly the same data, so they find exactly
//! the same hits. Conventions: a hit counts when `t_min < t < t_max`; a
//! degenerate primitive (zero-area polygon, zero-length cone, zero-radius
//! sphere) is never hit; a ray lying in a polygon's plane does not hit it.

mod counts;
mod owned;

pub use counts::KindCounts;
pub use owned::OwnedShape;

use crate::intersect::{RayQ, Surface};
use crate::math::Aabb;
use crate::math::Real;
use std::fmt::Debug;

/// Largest vertex count accepted for a polygon or patch. Real scenes stay
/// far below it (the gears' faces have 144); it bounds the memory any one
/// object may claim.
pub const MAX_POLYGON_VERTICES: usize = 16_384;

/// One primitive kind, implemented by a marker type. The kind's primitives
/// are values of [`Kind::Shape`], borrowing their geometry from a record
/// (so that reading a database allocates nothing per object).
pub trait Kind {
    /// A primitive of this kind, borrowing its geometry.
    type Shape<'a>: Copy + Debug + PartialEq;
    /// What the intersection test computes once per primitive and may
    /// reuse for every ray (a polygon's plane, a cone's frame); `()` for
    /// kinds where recomputing costs nothing.
    type Prep: Copy + Debug + PartialEq;
    /// The kind's name in statistics and messages.
    const NAME: &'static str;

    /// Words of geometry after the record header of a primitive whose
    /// count field is `count`, or `None` if no primitive of this kind has
    /// that count.
    fn payload_words(count: u32) -> Option<usize>;
    /// The record header's count field (vertices, or 0).
    fn count(s: &Self::Shape<'_>) -> u32;
    /// The primitive whose geometry is `g` (exactly `payload_words` long).
    fn decode(g: &[f32], count: u32) -> Self::Shape<'_>;
    /// Appends the primitive's geometry as record words.
    fn encode(s: &Self::Shape<'_>, out: &mut Vec<u32>);
    /// Checks what a well-formed primitive must satisfy; describes the
    /// first problem.
    fn validate(s: &Self::Shape<'_>) -> Result<(), String>;
    /// A box that contains every point of the primitive, rounded outward
    /// to `f32`.
    fn bounds(s: &Self::Shape<'_>) -> Aabb;
    /// The reusable part of the intersection test, or `None` when there is
    /// nothing worth keeping.
    fn prepare(s: &Self::Shape<'_>) -> Option<Self::Prep>;
    /// Nearest `t` in `(t_min, t_max)` at which `ray` meets the primitive,
    /// whose bounding box is `bbox`; `prep` is `prepare(s)` if the caller
    /// kept it. The result is the same with or without it.
    fn intersect<R: Real>(
        s: &Self::Shape<'_>,
        prep: Option<&Self::Prep>,
        bbox: &Aabb,
        ray: &RayQ<R>,
        t_min: R,
        t_max: R,
    ) -> Option<R>;
    /// The surface where `ray` meets the primitive at `t`, in `f64` so
    /// that shading is the same whatever precision found the hit.
    fn surface(s: &Self::Shape<'_>, ray: &RayQ<f64>, t: f64) -> Surface;
    /// The primitive with its geometry mapped (points, lengths, normals),
    /// as record words: how a scene is scaled or placed.
    fn map(s: &Self::Shape<'_>, m: &GeometryMap<'_>, out: &mut Vec<u32>);
    /// Triangles the primitive makes (`n - 2` for a polygon of `n`
    /// vertices), for statistics.
    fn triangles(s: &Self::Shape<'_>) -> u64;
}

/// How [`Kind::map`] changes geometry: every point, every length (radii)
/// and every normal.
pub struct GeometryMap<'f> {
    pub point: &'f dyn Fn([f32; 3]) -> [f32; 3],
    pub length: &'f dyn Fn(f32) -> f32,
    pub normal: &'f dyn Fn([f32; 3]) -> [f32; 3],
}

/// Declares the kinds: their codes in the object database (0, 1, 2, ...;
/// never renumber one), the file that implements each and its view type
/// (`Kind::Shape<'a>`, spelled out). Generates [`ShapeKind`],
/// [`Shape`], [`Prepared`] and the dispatch between them.
macro_rules! kinds {
    ($( $(#[$doc:meta])* $Variant:ident = $code:literal => $module:ident :: $Marker:ident ($View:ty) ),* $(,)?) => {
        $( mod $module; )*
        $( pub use $module::*; )*

        /// The kinds of primitive.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        #[repr(u8)]
        pub enum ShapeKind {
            $( $(#[$doc])* $Variant = $code, )*
        }

        /// Number of kinds.
        pub const KINDS: usize = [$( ShapeKind::$Variant ),*].len();

        // Codes are 0, 1, 2, ... in list order, so that a kind's code is
        // its index in per-kind arrays.
        const _: () = {
            let mut i = 0;
            while i < KINDS {
                assert!(ShapeKind::ALL[i] as usize == i, "kind codes must be 0, 1, 2, ... in list order");
                i += 1;
            }
        };

        impl ShapeKind {
            pub const ALL: [ShapeKind; KINDS] = [$( ShapeKind::$Variant ),*];

            /// The kind with database code `v`.
            pub fn from_u8(v: u8) -> Option<ShapeKind> {
                match v {
                    $( $code => Some(ShapeKind::$Variant), )*
                    _ => None,
                }
            }

            pub fn name(self) -> &'static str {
                match self {
                    $( ShapeKind::$Variant => <$module::$Marker as Kind>::NAME, )*
                }
            }

            /// Position in [`ShapeKind::ALL`] (the codes are dense; see
            /// the check below).
            #[inline(always)]
            pub fn index(self) -> usize {
                self as usize
            }

            /// See [`Kind::payload_words`].
            #[inline]
            pub fn payload_words(self, count: u32) -> Option<usize> {
                match self {
                    $( ShapeKind::$Variant => <$module::$Marker as Kind>::payload_words(count), )*
                }
            }

            /// The primitive of this kind whose geometry is `g`.
            #[inline(always)]
            pub fn decode(self, g: &[f32], count: u32) -> Shape<'_> {
                match self {
                    $( ShapeKind::$Variant => Shape::$Variant(<$module::$Marker as Kind>::decode(g, count)), )*
                }
            }
        }

        /// One primitive, borrowing its geometry. (The variants name the
        /// view types themselves, not `Kind::Shape<'a>`, which would make
        /// `Shape` invariant in `'a`.)
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub enum Shape<'a> {
            $( $(#[$doc])* $Variant($View), )*
        }

        /// What an intersection test keeps per primitive (see
        /// [`Kind::Prep`]).
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub enum Prepared {
            $( $Variant(<$module::$Marker as Kind>::Prep), )*
        }

        impl Shape<'_> {
            #[inline(always)]
            pub fn kind(&self) -> ShapeKind {
                match self {
                    $( Shape::$Variant(_) => ShapeKind::$Variant, )*
                }
            }

            /// The record header's count field.
            pub fn count(&self) -> u32 {
                match self {
                    $( Shape::$Variant(s) => <$module::$Marker as Kind>::count(s), )*
                }
            }

            /// Appends the geometry as record words.
            pub fn encode(&self, out: &mut Vec<u32>) {
                match self {
                    $( Shape::$Variant(s) => <$module::$Marker as Kind>::encode(s, out), )*
                }
            }

            /// See [`Kind::validate`].
            pub fn validate(&self) -> Result<(), String> {
                match self {
                    $( Shape::$Variant(s) => <$module::$Marker as Kind>::validate(s), )*
                }
            }

            /// See [`Kind::bounds`].
            pub fn bounds(&self) -> Aabb {
                match self {
                    $( Shape::$Variant(s) => <$module::$Marker as Kind>::bounds(s), )*
                }
            }

            /// See [`Kind::prepare`].
            #[inline]
            pub fn prepare(&self) -> Option<Prepared> {
                match self {
                    $( Shape::$Variant(s) => <$module::$Marker as Kind>::prepare(s).map(Prepared::$Variant), )*
                }
            }

            /// See [`Kind::intersect`]; `prep` must be this shape's own.
            #[inline(always)]
            pub fn intersect<R: Real>(
                &self,
                prep: Option<&Prepared>,
                bbox: &Aabb,
                ray: &RayQ<R>,
                t_min: R,
                t_max: R,
            ) -> Option<R> {
                match self {
                    $( Shape::$Variant(s) => {
                        let p = match prep {
                            Some(Prepared::$Variant(p)) => Some(p),
                            _ => None,
                        };
                        <$module::$Marker as Kind>::intersect(s, p, bbox, ray, t_min, t_max)
                    } )*
                }
            }

            /// See [`Kind::surface`].
            pub fn surface(&self, ray: &RayQ<f64>, t: f64) -> Surface {
                match self {
                    $( Shape::$Variant(s) => <$module::$Marker as Kind>::surface(s, ray, t), )*
                }
            }

            /// See [`Kind::map`].
            pub fn map(&self, m: &GeometryMap<'_>, out: &mut Vec<u32>) {
                match self {
                    $( Shape::$Variant(s) => <$module::$Marker as Kind>::map(s, m, out), )*
                }
            }

            /// See [`Kind::triangles`].
            pub fn triangles(&self) -> u64 {
                match self {
                    $( Shape::$Variant(s) => <$module::$Marker as Kind>::triangles(s), )*
                }
            }
        }
    };
}

kinds! {
    /// A sphere (NFF `s`).
    Sphere = 0 => sphere::SphereKind(Sphere),
    /// A planar polygon, possibly non-convex (NFF `p`).
    Polygon = 1 => polygon::PolygonKind(Polygon<'a>),
    /// A polygon with a normal per vertex, shaded smoothly (NFF `pp`).
    Patch = 2 => patch::PatchKind(Patch<'a>),
    /// An open cone or cylinder between two discs (NFF `c`).
    Cone = 3 => cone::ConeKind(Cone),
    /// A model of the database placed by an affine transform.
    Instance = 4 => instance::InstanceKind(Instance<'a>),
    /// A triangle with texture coordinates, colours or normals at its
    /// corners (glTF, OBJ and PLY meshes that carry them).
    Textured = 5 => textured::TexturedKind(Textured<'a>),
}

impl Shape<'_> {
    /// Vertices the primitive lists, if it is made of triangles (a
    /// polygon's or patch's count, a textured triangle's three), else 0:
    /// what statistics call a scene's listed vertices.
    pub fn listed_vertices(&self) -> u64 {
        match self {
            Shape::Polygon(_) | Shape::Patch(_) => self.count() as u64,
            Shape::Textured(_) => 3,
            _ => 0,
        }
    }
}

/// Nearest `t` in `(t_min, t_max)` at which `ray` meets `shape`, whose
/// bounding box is `bbox`, computing any prepared data on the spot.
#[inline]
pub fn intersect<R: Real>(
    shape: &Shape<'_>,
    bbox: &Aabb,
    ray: &RayQ<R>,
    t_min: R,
    t_max: R,
) -> Option<R> {
    shape.intersect(shape.prepare().as_ref(), bbox, ray, t_min, t_max)
}

/// The vertex-count check shared by the polygon kinds.
pub(crate) fn check_vertex_count(n: usize, what: &str) -> Result<(), String> {
    if n < 3 {
        Err(format!("{what} has {n} vertices; at least 3 are needed"))
    } else if n > MAX_POLYGON_VERTICES {
        Err(format!(
            "{what} has {n} vertices, more than the limit of {MAX_POLYGON_VERTICES}"
        ))
    } else {
        Ok(())
    }
}

/// Appends points as record words.
pub(crate) fn push_points(out: &mut Vec<u32>, pts: &[[f32; 3]]) {
    out.extend(pts.iter().flatten().map(|f| f.to_bits()));
}

#[cfg(test)]
mod tests;
