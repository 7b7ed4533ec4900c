//! One `f32` per child lane of a wide node, and the two ways of computing on eight of them:
//! two 4-wide SSE instructions per operation (the x86-64 baseline every build can run) or
//! one 8-wide AVX instruction where the CPU has AVX2.
//!
//! Which one runs is chosen once per process by [`crate::simd`]: the walks are compiled
//! twice (as `simd::Kernel`s), and everything below is inlined into the copy compiled with
//! AVX2, where `AVX` is true. The baseline build of the crate stays runnable on any x86-64
//! CPU; no `-C target-cpu` is needed.
//!
//! Both ways take the same decisions bit for bit: `min` and `max` are written as the SSE and
//! AVX instructions compute them (`a < b ? a : b`, the second operand when either is NaN),
//! `le_mask` is an ordered compare (false for NaN), and there is no fused multiply-add.

use super::WIDTH;

/// One value per child lane (32-byte aligned, so a row of node bounds loads as one vector).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub struct Lanes(pub [f32; WIDTH]);

impl Lanes {
    #[inline(always)]
    pub fn splat(v: f32) -> Lanes {
        Lanes([v; WIDTH])
    }

    #[inline(always)]
    fn zip(self, other: Lanes, f: impl Fn(f32, f32) -> f32) -> Lanes {
        let mut out = [0.0; WIDTH];
        for lane in 0..WIDTH {
            out[lane] = f(self.0[lane], other.0[lane]);
        }
        Lanes(out)
    }

    /// `self - other`. With `AVX`, only callable where AVX2 was detected (see the module).
    #[inline(always)]
    pub fn sub<const AVX: bool>(self, other: Lanes) -> Lanes {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is true only in a kernel copy `simd::dispatch` runs where the CPU
            // has AVX2.
            return unsafe { avx::sub(self, other) };
        }
        self.zip(other, |a, b| a - b)
    }

    #[inline(always)]
    pub fn mul<const AVX: bool>(self, other: Lanes) -> Lanes {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::mul(self, other) };
        }
        self.zip(other, |a, b| a * b)
    }

    #[inline(always)]
    pub fn min<const AVX: bool>(self, other: Lanes) -> Lanes {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::min(self, other) };
        }
        #[allow(clippy::manual_min_max)]
        self.zip(other, |a, b| if a < b { a } else { b })
    }

    #[inline(always)]
    pub fn max<const AVX: bool>(self, other: Lanes) -> Lanes {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::max(self, other) };
        }
        #[allow(clippy::manual_min_max)]
        self.zip(other, |a, b| if a > b { a } else { b })
    }

    /// Bit `lane` set where `self <= other` (false for NaN).
    #[inline(always)]
    pub fn le_mask<const AVX: bool>(self, other: Lanes) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::le_mask(self, other) };
        }
        let mut mask = 0;
        for lane in 0..WIDTH {
            mask |= ((self.0[lane] <= other.0[lane]) as u32) << lane;
        }
        mask
    }
}

/// The AVX versions of the operations, inlined only into functions compiled for AVX2.
#[cfg(target_arch = "x86_64")]
mod avx {
    use super::Lanes;
    use std::arch::x86_64::*;

    #[inline]
    #[target_feature(enable = "avx")]
    fn load(a: Lanes) -> __m256 {
        // SAFETY: `Lanes` is 32 bytes, 32-byte aligned.
        unsafe { _mm256_load_ps(a.0.as_ptr()) }
    }

    #[inline]
    #[target_feature(enable = "avx")]
    fn store(v: __m256) -> Lanes {
        let mut out = Lanes::default();
        // SAFETY: as in `load`.
        unsafe { _mm256_store_ps(out.0.as_mut_ptr(), v) };
        out
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn sub(a: Lanes, b: Lanes) -> Lanes {
        store(_mm256_sub_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn mul(a: Lanes, b: Lanes) -> Lanes {
        store(_mm256_mul_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn min(a: Lanes, b: Lanes) -> Lanes {
        store(_mm256_min_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn max(a: Lanes, b: Lanes) -> Lanes {
        store(_mm256_max_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn le_mask(a: Lanes, b: Lanes) -> u32 {
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(load(a), load(b))) as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values that stress the operations: signed zeros, infinities, NaN, tiny and huge.
    const SPECIAL: [f32; 12] = [
        0.0,
        -0.0,
        1.0,
        -1.5,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        f32::MIN_POSITIVE,
        -1e-40,
        3.4e38,
        -2.5e-7,
        1e30,
    ];

    fn lanes(offset: usize) -> Lanes {
        Lanes(std::array::from_fn(|i| {
            SPECIAL[(i * 5 + offset) % SPECIAL.len()]
        }))
    }

    /// Every copy checked on every CPU: the baseline operations against scalar IEEE
    /// arithmetic with the SSE/AVX rules written out (`min`/`max` return the second operand
    /// when either is NaN, `le` is false for NaN), and the AVX operations, where the CPU has
    /// AVX2, against the baseline, bit for bit.
    #[test]
    fn every_copy_of_the_operations_equals_the_scalar_rules() {
        let bits = |l: Lanes| l.0.map(f32::to_bits);
        let scalar = |a: Lanes, b: Lanes, f: fn(f32, f32) -> f32| {
            bits(Lanes(std::array::from_fn(|i| f(a.0[i], b.0[i]))))
        };
        let second_if_nan = |a: f32, b: f32, pick_a: bool| {
            if a.is_nan() || b.is_nan() || !pick_a {
                b
            } else {
                a
            }
        };
        let avx2 = crate::simd::Isa::cpu_has_avx2();
        let mut compared = 0;
        for i in 0..SPECIAL.len() {
            for j in 0..SPECIAL.len() {
                let (a, b) = (lanes(i), lanes(j));
                assert_eq!(bits(a.sub::<false>(b)), scalar(a, b, |x, y| x - y));
                assert_eq!(bits(a.mul::<false>(b)), scalar(a, b, |x, y| x * y));
                let min: Vec<u32> = (0..WIDTH)
                    .map(|l| second_if_nan(a.0[l], b.0[l], a.0[l] < b.0[l]).to_bits())
                    .collect();
                let max: Vec<u32> = (0..WIDTH)
                    .map(|l| second_if_nan(a.0[l], b.0[l], a.0[l] > b.0[l]).to_bits())
                    .collect();
                assert_eq!(bits(a.min::<false>(b)).to_vec(), min);
                assert_eq!(bits(a.max::<false>(b)).to_vec(), max);
                let le = (0..WIDTH).fold(0, |m, l| {
                    let ordered = !a.0[l].is_nan() && !b.0[l].is_nan();
                    m | (((ordered && a.0[l] <= b.0[l]) as u32) << l)
                });
                assert_eq!(a.le_mask::<false>(b), le);
                if avx2 {
                    assert_eq!(bits(a.sub::<true>(b)), bits(a.sub::<false>(b)));
                    assert_eq!(bits(a.mul::<true>(b)), bits(a.mul::<false>(b)));
                    assert_eq!(bits(a.min::<true>(b)), bits(a.min::<false>(b)));
                    assert_eq!(bits(a.max::<true>(b)), bits(a.max::<false>(b)));
                    assert_eq!(a.le_mask::<true>(b), a.le_mask::<false>(b));
                }
                compared += 1;
            }
        }
        assert_eq!(compared, SPECIAL.len() * SPECIAL.len());
        if !avx2 {
            println!(
                "this CPU has no AVX2: the baseline operations were checked against the scalar rules only"
            );
        }
    }

    #[test]
    fn min_and_max_return_the_second_operand_when_either_is_nan() {
        let (a, b) = (Lanes::splat(f32::NAN), Lanes::splat(1.0));
        assert_eq!(a.min::<false>(b).0[0], 1.0);
        assert!(b.max::<false>(a).0[0].is_nan());
        assert_eq!(a.le_mask::<false>(b), 0);
    }
}
