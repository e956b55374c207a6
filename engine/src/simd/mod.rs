//! SIMD lanes, chosen at run time from what the CPU has.
//!
//! The intersection kernels ([`crate::kernels`]) test one primitive
//! against many rays at once. They are written once, generic over a
//! vector of lanes ([`Float`]), and compiled for every instruction set
//! this module knows ([`Isa`]): SSE2 (4 `f32` lanes), AVX2 (8), AVX-512
//! (16), NEON (4) and a portable fallback in plain Rust (4). Which one
//! runs is decided when a render starts: the widest the CPU has, unless
//! `--simd` or the `SRAY_SIMD` environment variable forces one.
//!
//! **Every width computes the same bits.** A cluster's workers may run on
//! different CPUs and its verification compares their results bit for
//! bit, so every lane of every width performs exactly the operations of
//! the scalar code, in the same order: additions, subtractions,
//! multiplications, divisions and square roots, each correctly rounded
//! by IEEE 754 on every one of these instruction sets; comparisons that
//! are false for NaN, as Rust's are; `min` and `max` written as a
//! comparison and a select (the instruction sets disagree about NaN and
//! signed zeros in their own min and max); no fused multiply-add (Rust
//! never contracts `a * b + c`, and no kernel asks for one); no
//! approximate reciprocal or square root. Tests render with every width
//! this machine has and compare the images and counts.

mod lanes;
#[cfg(target_arch = "aarch64")]
mod neon;
mod portable;
#[cfg(target_arch = "x86_64")]
mod x86;

pub use lanes::{Elem, Float, Job, Lanes, Mask};

use crate::error::Error;
use serde::Serialize;
use std::sync::OnceLock;

/// An instruction set the kernels are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Isa {
    /// Plain Rust, four lanes: any CPU.
    Portable,
    /// x86-64 SSE2 (every x86-64 CPU): four `f32` lanes.
    Sse,
    /// x86-64 AVX2: eight `f32` lanes.
    Avx2,
    /// x86-64 AVX-512 (F): sixteen `f32` lanes.
    Avx512,
    /// AArch64 NEON (every AArch64 CPU): four `f32` lanes.
    Neon,
}

/// The environment variable that forces an instruction set when no
/// `--simd` is given (as `--simd` spells it).
pub const ENV: &str = "SRAY_SIMD";

impl Isa {
    pub const ALL: [Isa; 5] = [Isa::Portable, Isa::Sse, Isa::Avx2, Isa::Avx512, Isa::Neon];

    pub fn name(self) -> &'static str {
        match self {
            Isa::Portable => "portable",
            Isa::Sse => "sse",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
            Isa::Neon => "neon",
        }
    }

    /// `f32` lanes of one vector.
    pub fn lanes(self) -> usize {
        match self {
            Isa::Portable | Isa::Sse | Isa::Neon => 4,
            Isa::Avx2 => 8,
            Isa::Avx512 => 16,
        }
    }

    /// Whether this CPU can run it.
    pub fn available(self) -> bool {
        match self {
            Isa::Portable => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Sse => true,
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => x86::has_avx2(),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => x86::has_avx2() && std::arch::is_x86_feature_detected!("avx512f"),
            #[cfg(target_arch = "aarch64")]
            Isa::Neon => true,
            #[allow(unreachable_patterns)]
            _ => false,
        }
    }

    /// Every instruction set this CPU can run, narrowest first.
    pub fn available_here() -> Vec<Isa> {
        Isa::ALL.into_iter().filter(|i| i.available()).collect()
    }

    /// The widest this CPU has (detected once).
    pub fn detect() -> Isa {
        static BEST: OnceLock<Isa> = OnceLock::new();
        *BEST.get_or_init(|| {
            [Isa::Avx512, Isa::Avx2, Isa::Neon, Isa::Sse]
                .into_iter()
                .find(|i| i.available())
                .unwrap_or(Isa::Portable)
        })
    }

    /// The instruction set a render uses: `forced` (from `--simd`), else
    /// the one `SRAY_SIMD` names, else the widest this CPU has. An
    /// instruction set this CPU lacks is an error, not a crash.
    pub fn choose(forced: Option<Isa>) -> Result<Isa, Error> {
        let isa = match forced {
            Some(i) => i,
            None => match std::env::var(ENV) {
                Ok(s) if !s.is_empty() && s != "auto" => s
                    .parse::<Isa>()
                    .map_err(|e| Error::Invalid(format!("{ENV}: {e}")))?,
                _ => return Ok(Isa::detect()),
            },
        };
        if !isa.available() {
            return Err(Error::Invalid(format!(
                "this CPU cannot run the {} kernels (it has: {})",
                isa.name(),
                Isa::available_here()
                    .iter()
                    .map(|i| i.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        Ok(isa)
    }

    /// Runs `job` with the lanes of this instruction set.
    ///
    /// Panics if this CPU cannot run it: every `Isa` a render holds came
    /// from [`Isa::choose`], which checks.
    #[inline]
    pub fn run<J: Job>(self, job: J) -> J::Out {
        match self {
            #[cfg(target_arch = "x86_64")]
            Isa::Sse => job.run::<x86::Sse>(),
            #[cfg(target_arch = "x86_64")]
            Isa::Avx2 => {
                assert!(self.available(), "AVX2 kernels on a CPU without AVX2");
                // SAFETY: `run_avx2` needs the features `x86::has_avx2`
                // checks, which the CPU has (checked just above;
                // `is_x86_feature_detected!` caches its answers).
                unsafe { x86::run_avx2(job) }
            }
            #[cfg(target_arch = "x86_64")]
            Isa::Avx512 => {
                assert!(
                    self.available(),
                    "AVX-512 kernels on a CPU without AVX-512F"
                );
                // SAFETY: `run_avx512` needs AVX-512F, which the CPU has
                // (checked just above).
                unsafe { x86::run_avx512(job) }
            }
            #[cfg(target_arch = "aarch64")]
            Isa::Neon => job.run::<neon::Neon>(),
            Isa::Portable => job.run::<portable::Portable>(),
            #[allow(unreachable_patterns)]
            other => panic!("{} kernels on a CPU that cannot run them", other.name()),
        }
    }
}

impl std::str::FromStr for Isa {
    type Err = String;
    fn from_str(s: &str) -> Result<Isa, String> {
        Isa::ALL.into_iter().find(|i| i.name() == s).ok_or_else(|| {
            format!("unknown SIMD width '{s}' (expected auto, portable, sse, avx2, avx512 or neon)")
        })
    }
}

impl std::fmt::Display for Isa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests;

/// Asks the CPU to bring the cache line at `p` into its caches, ahead of
/// a load that would otherwise wait for memory: a hint, which changes no
/// result and never faults, whatever `p` points at. A no-op where there
/// is no such instruction.
#[inline(always)]
pub fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: `_mm_prefetch` needs SSE, which every x86-64 CPU has
        // (it is in the target's baseline); a prefetch neither reads
        // memory the program sees nor faults on any address, so any `p`,
        // dangling or not, is sound.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(p.cast::<i8>()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}
