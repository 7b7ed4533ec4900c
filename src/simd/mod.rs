//! Which SIMD copy of a hot loop runs: the one place that decides.
//!
//! The release binary is built for the x86-64 baseline (SSE2), so it runs on any x86-64
//! CPU; the hot loops (a film tile's whole loop of rays, surfaces, shading and texture
//! lookups, the BVH walks and packets, the batched `log2`, and the frame update's skinning,
//! slot-order write and `log2 P_b` walk) are compiled a second time with AVX2 and the
//! integer instructions that come with it (POPCNT, LZCNT, BMI1, BMI2; not FMA) enabled, and
//! the copy is chosen at run time, once per process ([`Isa::current`]). A loop takes part
//! by implementing [`Kernel`]: its `run` is generic over `AVX2` and `#[inline(always)]`, so
//! [`dispatch`] inlines it whole into a function compiled with AVX2 (where `AVX2` is true)
//! or into the baseline caller; what a kernel calls out of line is compiled for the
//! baseline, so the tile loop's helpers are `#[inline(always)]`. A kernel called often from
//! inside another (a tile's texture lookups) runs as `run::<AVX2>` with the caller's `AVX2`:
//! a `dispatch` there would leave the caller's copy for an out-of-line call to the callee's,
//! arguments and result through memory. Code inside may branch on
//! `AVX2` to use AVX intrinsics ([`F32x8`]); it must compute the same bits either way (no
//! fused multiply-add is formed in either copy), which the tests of every such kernel check
//! against the baseline copy or a scalar reference, and the identity frames check for the
//! tile loop.
//!
//! `MIPRAY_SIMD=baseline` forces the baseline copy on any CPU, for comparisons and for
//! testing the baseline path on a machine that has AVX2; `MIPRAY_SIMD=avx2` keeps the AVX2
//! copies from calling the AVX-512 routines ([`avx512`]).

use std::sync::OnceLock;

mod f32x8;
mod prefetch;

pub use f32x8::F32x8;
pub use prefetch::{prefetch, prefetch_ptr};

/// Four rays' `Vec3A`s (one a row, as glam keeps them) as rows of their x, y, z and w
/// components (one a row, a ray a lane): how a packet's rays, kept ray by ray, become
/// structure of arrays four at a time. Moves bits only.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub fn transpose4([a, b, c, d]: [std::arch::x86_64::__m128; 4]) -> [std::arch::x86_64::__m128; 4] {
    use std::arch::x86_64::*;
    // SAFETY: SSE2 is part of x86_64; these shuffles only read and write registers.
    unsafe {
        let (ab_low, cd_low) = (_mm_unpacklo_ps(a, b), _mm_unpacklo_ps(c, d));
        let (ab_high, cd_high) = (_mm_unpackhi_ps(a, b), _mm_unpackhi_ps(c, d));
        [
            _mm_movelh_ps(ab_low, cd_low),
            _mm_movehl_ps(cd_low, ab_low),
            _mm_movelh_ps(ab_high, cd_high),
            _mm_movehl_ps(cd_high, ab_high),
        ]
    }
}

/// What the `MIPRAY_SIMD` environment variable asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimdOverride {
    /// Unset, empty or `auto`: the best copy the CPU runs.
    None,
    /// `baseline`: the baseline copy on any CPU.
    Baseline,
    /// `avx2`: the AVX2 copy without the AVX-512 routines.
    Avx2,
}

/// Reads `MIPRAY_SIMD`; `Err` holds a value it does not know. The kernels treat such a value
/// as unset; the command line refuses it before any work (a typo must not silently measure
/// the copy it meant to leave out).
pub fn simd_override() -> Result<SimdOverride, String> {
    match std::env::var("MIPRAY_SIMD") {
        Err(std::env::VarError::NotPresent) => Ok(SimdOverride::None),
        Err(std::env::VarError::NotUnicode(value)) => Err(value.to_string_lossy().into_owned()),
        Ok(value) => match value.as_str() {
            "" | "auto" => Ok(SimdOverride::None),
            "baseline" => Ok(SimdOverride::Baseline),
            "avx2" => Ok(SimdOverride::Avx2),
            _ => Err(value),
        },
    }
}

/// The instruction sets a kernel is compiled for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isa {
    /// x86-64 baseline (SSE2): runs everywhere; on other architectures, portable code.
    Baseline,
    /// AVX2 (Intel Haswell, 2013, and AMD Excavator, 2015, onward).
    Avx2,
}

impl Isa {
    /// The copy this process runs: AVX2 where the CPU has it, unless `MIPRAY_SIMD=baseline`.
    /// Decided once.
    #[inline]
    pub fn current() -> Isa {
        static CHOICE: OnceLock<Isa> = OnceLock::new();
        *CHOICE.get_or_init(|| {
            let forced_baseline = simd_override() == Ok(SimdOverride::Baseline);
            if Isa::cpu_has_avx2() && !forced_baseline {
                Isa::Avx2
            } else {
                Isa::Baseline
            }
        })
    }

    /// Whether the CPU can run the AVX2 copy (whatever `MIPRAY_SIMD` says): AVX2 and the
    /// integer instructions that came with it (the features `run_avx2` is compiled for).
    pub fn cpu_has_avx2() -> bool {
        #[cfg(target_arch = "x86_64")]
        return std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("lzcnt")
            && std::arch::is_x86_feature_detected!("popcnt");
        #[cfg(not(target_arch = "x86_64"))]
        return false;
    }

    /// Whether the CPU has AVX-512F, for the routines [`avx512`] lets the AVX2 copies call
    /// (whatever `MIPRAY_SIMD` says).
    pub fn cpu_has_avx512() -> bool {
        #[cfg(target_arch = "x86_64")]
        return std::arch::is_x86_feature_detected!("avx512f");
        #[cfg(not(target_arch = "x86_64"))]
        return false;
    }
}

/// Whether [`dispatch`] runs AVX2 copies in this process.
#[inline]
pub fn avx2() -> bool {
    Isa::current() == Isa::Avx2
}

/// Whether the AVX2 copies may also call the few AVX-512 routines written for 16 lanes (the
/// masked walk's node test, a packet's leaf box test and the closest-hit triangle test, each
/// across sixteen rays): the process runs the AVX2 copies and the CPU has
/// AVX-512F, unless `MIPRAY_SIMD=avx2` (or `baseline`) says otherwise. Those routines
/// compute the same bits as the 8-lane code they stand in for. Decided once.
#[inline]
pub fn avx512() -> bool {
    static CHOICE: OnceLock<bool> = OnceLock::new();
    *CHOICE.get_or_init(|| {
        let forced_off = simd_override() == Ok(SimdOverride::Avx2);
        avx2() && Isa::cpu_has_avx512() && !forced_off
    })
}

/// A computation compiled twice, once per [`Isa`].
pub trait Kernel {
    type Output;

    /// Runs the computation. `AVX2` is true only in the copy compiled for AVX2; implement it
    /// `#[inline(always)]` so that the whole computation is compiled into that copy.
    fn run<const AVX2: bool>(self) -> Self::Output;
}

/// Runs `kernel`'s copy for [`Isa::current`].
#[inline(always)]
pub fn dispatch<K: Kernel>(kernel: K) -> K::Output {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: `avx2()` is true only where the CPU has what the AVX2 copy needs
        // (`Isa::current`, `Isa::cpu_has_avx2`).
        return unsafe { run_avx2(kernel) };
    }
    kernel.run::<false>()
}

/// Runs `kernel`'s baseline copy whatever the CPU (tests compare the copies with it).
#[inline(always)]
pub fn run_baseline<K: Kernel>(kernel: K) -> K::Output {
    kernel.run::<false>()
}

/// Runs `kernel`'s AVX2 copy, or `None` where the CPU has no AVX2 (tests).
#[inline(always)]
pub fn run_avx2_if_available<K: Kernel>(kernel: K) -> Option<K::Output> {
    #[cfg(target_arch = "x86_64")]
    if Isa::cpu_has_avx2() {
        // SAFETY: the CPU has what the AVX2 copy needs (detected just above).
        return Some(unsafe { run_avx2(kernel) });
    }
    let _ = kernel;
    None
}

/// `kernel`'s AVX2 copy: `run::<true>` and everything it inlines compiled with AVX2 and
/// the integer instructions every CPU with AVX2 also has (of x86-64-v3, all but FMA, which
/// would change floating-point bits, F16C and MOVBE): a mask's `count_ones` is one `popcnt` instead of a
/// dozen shifts and adds, `trailing_zeros` one `tzcnt` instead of a `bsf` and a zero test,
/// and the hot loops count and scan ray masks at every node and leaf. Integer results are
/// the same whichever instructions compute them.
///
/// # Safety
/// The CPU must have every feature enabled here, as [`Isa::cpu_has_avx2`] checks them.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,bmi1,bmi2,lzcnt,popcnt")]
unsafe fn run_avx2<K: Kernel>(kernel: K) -> K::Output {
    kernel.run::<true>()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reports which copy ran.
    struct WhichCopy;

    impl Kernel for WhichCopy {
        type Output = bool;
        #[inline(always)]
        fn run<const AVX2: bool>(self) -> bool {
            AVX2
        }
    }

    #[test]
    fn dispatch_runs_the_copy_the_process_chose() {
        assert_eq!(dispatch(WhichCopy), Isa::current() == Isa::Avx2);
        assert!(!run_baseline(WhichCopy));
        assert_eq!(
            run_avx2_if_available(WhichCopy),
            Isa::cpu_has_avx2().then_some(true)
        );
    }

    #[test]
    fn the_avx2_copy_is_chosen_only_where_the_cpu_has_it() {
        if Isa::current() == Isa::Avx2 {
            assert!(Isa::cpu_has_avx2());
        }
        if simd_override() == Ok(SimdOverride::Baseline) {
            assert_eq!(Isa::current(), Isa::Baseline);
        }
    }
}
