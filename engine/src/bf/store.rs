//! How many voxels a ray stores itself in per pass: the paper's store
//! number, fixed or adaptive (Section 2.2), per grid; or the adaptive one
//! with what a pass's rays leave of the memory for registrations given to
//! the walks it cut short ([`StoreNumber::Budget`]).

use super::MAX_GRIDS;
use crate::grid::GridSpec;
use serde::Serialize;

/// How many voxels a ray stores itself in per pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum StoreNumber {
    Fixed(u32),
    /// The paper's adaptive store number (Section 2.2), per ray.
    Adaptive,
    /// The adaptive store number, and then the registrations a pass's
    /// rays leave unused go to the walks it stopped, shared evenly, so
    /// that a ray walks as far in one pass as memory allows: the last
    /// few rays of a round finish in the pass with the others instead of
    /// costing a scan of the objects each. What a ray registers then
    /// depends on the pass it is in: on the budget, and where a pass
    /// cannot register all its rays, on which waited (the threads). The
    /// image and hits do not.
    Budget,
}

/// Store numbers per grid.
#[derive(Clone, Copy, Debug)]
pub struct StorePlan {
    fixed: Option<u32>,
    /// Walks cut short take what the pass leaves ([`StoreNumber::Budget`]).
    extends: bool,
    grids: usize,
    base: [u32; MAX_GRIDS],
    max: [u32; MAX_GRIDS],
    /// Most voxels a walk can cross in the grid (res x + y + z).
    walk: [u32; MAX_GRIDS],
}

impl StorePlan {
    pub fn new(policy: StoreNumber, grids: &[GridSpec]) -> StorePlan {
        let mut base = [1; MAX_GRIDS];
        let mut max = [1; MAX_GRIDS];
        let mut walk = [1; MAX_GRIDS];
        for (g, spec) in grids.iter().enumerate().take(MAX_GRIDS) {
            let res = *spec.res.iter().max().unwrap_or(&1);
            base[g] = ((res as f64 / 10.0).round() as u32).max(1);
            max[g] = res.max(base[g]);
            walk[g] = spec.res.iter().sum();
        }
        StorePlan {
            fixed: match policy {
                StoreNumber::Fixed(n) => Some(n.max(1)),
                StoreNumber::Adaptive | StoreNumber::Budget => None,
            },
            extends: policy == StoreNumber::Budget,
            grids: grids.len().min(MAX_GRIDS),
            base,
            max,
            walk,
        }
    }

    /// Registrations a fresh ray makes at most in its first pass: what a
    /// ray slot plans for (the paper's memory / (ray + store number x
    /// registration)). Survivors of later passes use what finished rays
    /// leave.
    pub fn planned(&self) -> u64 {
        (0..self.grids)
            .map(|g| self.store(g, 0).min(self.walk[g]) as u64)
            .sum()
    }

    /// The most registrations one ray can make in one pass.
    pub fn overrun(&self) -> u64 {
        (0..self.grids)
            .map(|g| self.store(g, 30).min(self.walk[g]) as u64)
            .sum()
    }

    /// Whether walks the store number stopped go on with what the pass
    /// leaves of the registrations.
    pub fn extends(&self) -> bool {
        self.extends
    }

    /// Store number in grid `g` for a ray's pass number `k` there.
    #[inline]
    pub fn store(&self, g: usize, k: u8) -> u32 {
        match self.fixed {
            Some(n) => n,
            None => self.max[g].min(self.base[g].saturating_mul(1 << k.min(20))),
        }
    }
}
