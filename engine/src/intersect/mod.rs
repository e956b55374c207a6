//! What every primitive's intersection test shares: the ray prepared for
//! tests ([`RayQ`]), the watertight triangle test (used by polygons and
//! patches alike), and the [`Surface`] a hit hands to shading. The tests
//! of each kind live with the kind, in [`crate::shapes`].

mod ray;
mod surface;
pub mod triangle;

pub use ray::{Ray, RayQ};
pub use surface::{Attrs, Surface};
