//! Eight `f32` lanes (a wide node's child lanes, eight rays of a packet) and the two ways of
//! computing on them: two 4-wide SSE instructions per operation (the x86-64 baseline every
//! build can run) or one 8-wide AVX instruction where the CPU has AVX2.
//!
//! Which one runs is chosen once per process by [`crate::simd`]: the kernels are compiled
//! twice (as `simd::Kernel`s), and everything below is inlined into the copy compiled with
//! AVX2, where `AVX` is true. The baseline build of the crate stays runnable on any x86-64
//! CPU; no `-C target-cpu` is needed.
//!
//! Both ways take the same decisions bit for bit: every operation is one IEEE operation per
//! lane (no fused multiply-add), `min` and `max` are written as the SSE and AVX instructions
//! compute them (`a < b ? a : b`, the second operand when either is NaN), and the masks are
//! ordered compares (false for NaN) except `ne_mask` (true for NaN, as `!=`).

/// Lanes per vector.
pub const WIDTH: usize = 8;

/// One value per child lane (32-byte aligned, so a row of node bounds loads as one vector).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
pub struct F32x8(pub [f32; WIDTH]);

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::{_CMP_EQ_OQ, _CMP_GT_OQ, _CMP_LT_OQ, _CMP_NEQ_UQ};

impl F32x8 {
    /// Lanes per vector (`WIDTH`), for code that names the type rather than the module.
    pub const LANES: usize = WIDTH;

    #[inline(always)]
    pub fn splat(v: f32) -> F32x8 {
        F32x8([v; WIDTH])
    }

    #[inline(always)]
    fn zip(self, other: F32x8, f: impl Fn(f32, f32) -> f32) -> F32x8 {
        let mut out = [0.0; WIDTH];
        for lane in 0..WIDTH {
            out[lane] = f(self.0[lane], other.0[lane]);
        }
        F32x8(out)
    }

    /// `self - other`. With `AVX`, only callable where AVX2 was detected (see the module).
    #[inline(always)]
    pub fn sub<const AVX: bool>(self, other: F32x8) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: `AVX` is true only in a kernel copy `simd::dispatch` runs where the CPU
            // has AVX2.
            return unsafe { avx::sub(self, other) };
        }
        self.zip(other, |a, b| a - b)
    }

    #[inline(always)]
    pub fn mul<const AVX: bool>(self, other: F32x8) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::mul(self, other) };
        }
        self.zip(other, |a, b| a * b)
    }

    #[inline(always)]
    pub fn min<const AVX: bool>(self, other: F32x8) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::min(self, other) };
        }
        #[allow(clippy::manual_min_max)]
        self.zip(other, |a, b| if a < b { a } else { b })
    }

    #[inline(always)]
    pub fn max<const AVX: bool>(self, other: F32x8) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::max(self, other) };
        }
        #[allow(clippy::manual_min_max)]
        self.zip(other, |a, b| if a > b { a } else { b })
    }

    #[inline(always)]
    pub fn add<const AVX: bool>(self, other: F32x8) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::add(self, other) };
        }
        self.zip(other, |a, b| a + b)
    }

    #[inline(always)]
    pub fn div<const AVX: bool>(self, other: F32x8) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::div(self, other) };
        }
        self.zip(other, |a, b| a / b)
    }

    /// `|self|` (the sign bit cleared; NaN stays NaN).
    #[inline(always)]
    pub fn abs<const AVX: bool>(self) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::abs(self) };
        }
        F32x8(self.0.map(f32::abs))
    }

    /// The correctly rounded square root of each lane (IEEE `sqrt`).
    #[inline(always)]
    pub fn sqrt<const AVX: bool>(self) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::sqrt(self) };
        }
        F32x8(self.0.map(f32::sqrt))
    }

    /// `1 / self`, except where `|self| < 1e-30`: there `1e30` with `self`'s sign, so that a
    /// slab distance stays finite (the lanes of `accel::wide::walk::safe_inverse4`, bit for
    /// bit).
    #[inline(always)]
    pub fn safe_inverse<const AVX: bool>(self) -> F32x8 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::safe_inverse(self) };
        }
        F32x8(self.0.map(|x| {
            if x.abs() < 1e-30 {
                1e30f32.copysign(x)
            } else {
                1.0 / x
            }
        }))
    }

    /// The least lane (`a < b ? a : b` folded from lane 0; meant for lanes without NaN).
    #[inline(always)]
    pub fn min_lane(self) -> f32 {
        self.0
            .into_iter()
            .fold(f32::INFINITY, |a, b| if b < a { b } else { a })
    }

    /// The largest lane (as [`F32x8::min_lane`]).
    #[inline(always)]
    pub fn max_lane(self) -> f32 {
        self.0
            .into_iter()
            .fold(f32::NEG_INFINITY, |a, b| if b > a { b } else { a })
    }

    /// Bit `lane` set where `self < other` (false for NaN).
    #[inline(always)]
    pub fn lt_mask<const AVX: bool>(self, other: F32x8) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::cmp_mask::<_CMP_LT_OQ>(self, other) };
        }
        self.mask_where(other, |a, b| a < b)
    }

    /// Bit `lane` set where `self > other` (false for NaN).
    #[inline(always)]
    pub fn gt_mask<const AVX: bool>(self, other: F32x8) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::cmp_mask::<_CMP_GT_OQ>(self, other) };
        }
        self.mask_where(other, |a, b| a > b)
    }

    /// Bit `lane` set where `self == other` (false for NaN; `-0 == 0`).
    #[inline(always)]
    pub fn eq_mask<const AVX: bool>(self, other: F32x8) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::cmp_mask::<_CMP_EQ_OQ>(self, other) };
        }
        self.mask_where(other, |a, b| a == b)
    }

    /// Bit `lane` set where `self != other` (true for NaN, as `!=`).
    #[inline(always)]
    pub fn ne_mask<const AVX: bool>(self, other: F32x8) -> u32 {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::cmp_mask::<_CMP_NEQ_UQ>(self, other) };
        }
        self.mask_where(other, |a, b| a != b)
    }

    /// `self` where `self <= other` and +infinity in the other lanes (NaN among them), with
    /// the mask of the lanes kept (`le_mask`'s).
    #[inline(always)]
    pub fn kept_where_le<const AVX: bool>(self, other: F32x8) -> (F32x8, u32) {
        #[cfg(target_arch = "x86_64")]
        if AVX {
            // SAFETY: as in `sub`.
            return unsafe { avx::kept_where_le(self, other) };
        }
        let mask = self.le_mask::<false>(other);
        let kept = std::array::from_fn(|lane| {
            if mask & (1 << lane) != 0 {
                self.0[lane]
            } else {
                f32::INFINITY
            }
        });
        (F32x8(kept), mask)
    }

    #[inline(always)]
    fn mask_where(self, other: F32x8, f: impl Fn(f32, f32) -> bool) -> u32 {
        let mut mask = 0;
        for lane in 0..WIDTH {
            mask |= (f(self.0[lane], other.0[lane]) as u32) << lane;
        }
        mask
    }

    /// Bit `lane` set where `self <= other` (false for NaN).
    #[inline(always)]
    pub fn le_mask<const AVX: bool>(self, other: F32x8) -> u32 {
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
    use super::F32x8;
    use std::arch::x86_64::*;

    #[inline]
    #[target_feature(enable = "avx")]
    fn load(a: F32x8) -> __m256 {
        // SAFETY: `F32x8` is 32 bytes, 32-byte aligned.
        unsafe { _mm256_load_ps(a.0.as_ptr()) }
    }

    #[inline]
    #[target_feature(enable = "avx")]
    fn store(v: __m256) -> F32x8 {
        let mut out = F32x8::default();
        // SAFETY: as in `load`.
        unsafe { _mm256_store_ps(out.0.as_mut_ptr(), v) };
        out
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn sub(a: F32x8, b: F32x8) -> F32x8 {
        store(_mm256_sub_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn mul(a: F32x8, b: F32x8) -> F32x8 {
        store(_mm256_mul_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn add(a: F32x8, b: F32x8) -> F32x8 {
        store(_mm256_add_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn div(a: F32x8, b: F32x8) -> F32x8 {
        store(_mm256_div_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn abs(a: F32x8) -> F32x8 {
        store(_mm256_andnot_ps(_mm256_set1_ps(-0.0), load(a)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn sqrt(a: F32x8) -> F32x8 {
        store(_mm256_sqrt_ps(load(a)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn safe_inverse(a: F32x8) -> F32x8 {
        let x = load(a);
        let sign = _mm256_set1_ps(-0.0);
        let tiny = _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_andnot_ps(sign, x), _mm256_set1_ps(1e-30));
        let huge = _mm256_or_ps(_mm256_and_ps(sign, x), _mm256_set1_ps(1e30));
        let inverse = _mm256_div_ps(_mm256_set1_ps(1.0), x);
        store(_mm256_blendv_ps(inverse, huge, tiny))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn cmp_mask<const PREDICATE: i32>(a: F32x8, b: F32x8) -> u32 {
        _mm256_movemask_ps(_mm256_cmp_ps::<PREDICATE>(load(a), load(b))) as u32
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn min(a: F32x8, b: F32x8) -> F32x8 {
        store(_mm256_min_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn max(a: F32x8, b: F32x8) -> F32x8 {
        store(_mm256_max_ps(load(a), load(b)))
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn le_mask(a: F32x8, b: F32x8) -> u32 {
        _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(load(a), load(b))) as u32
    }

    #[inline]
    #[target_feature(enable = "avx")]
    pub fn kept_where_le(a: F32x8, b: F32x8) -> (F32x8, u32) {
        let a = load(a);
        let le = _mm256_cmp_ps::<_CMP_LE_OQ>(a, load(b));
        let kept = _mm256_blendv_ps(_mm256_set1_ps(f32::INFINITY), a, le);
        (store(kept), _mm256_movemask_ps(le) as u32)
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

    fn lanes(offset: usize) -> F32x8 {
        F32x8(std::array::from_fn(|i| {
            SPECIAL[(i * 5 + offset) % SPECIAL.len()]
        }))
    }

    /// Every copy checked on every CPU: the baseline operations against scalar IEEE
    /// arithmetic with the SSE/AVX rules written out (`min`/`max` return the second operand
    /// when either is NaN, `le` is false for NaN), and the AVX operations, where the CPU has
    /// AVX2, against the baseline, bit for bit.
    #[test]
    fn every_copy_of_the_operations_equals_the_scalar_rules() {
        let bits = |l: F32x8| l.0.map(f32::to_bits);
        let scalar = |a: F32x8, b: F32x8, f: fn(f32, f32) -> f32| {
            bits(F32x8(std::array::from_fn(|i| f(a.0[i], b.0[i]))))
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
                assert_eq!(bits(a.add::<false>(b)), scalar(a, b, |x, y| x + y));
                assert_eq!(bits(a.div::<false>(b)), scalar(a, b, |x, y| x / y));
                let rule = |f: &dyn Fn(f32, f32) -> bool| {
                    (0..WIDTH).fold(0, |m, l| m | ((f(a.0[l], b.0[l]) as u32) << l))
                };
                let ordered = |x: f32, y: f32| !x.is_nan() && !y.is_nan();
                assert_eq!(a.lt_mask::<false>(b), rule(&|x, y| ordered(x, y) && x < y));
                assert_eq!(a.gt_mask::<false>(b), rule(&|x, y| ordered(x, y) && x > y));
                assert_eq!(a.eq_mask::<false>(b), rule(&|x, y| ordered(x, y) && x == y));
                assert_eq!(
                    a.ne_mask::<false>(b),
                    rule(&|x, y| !ordered(x, y) || x != y)
                );
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
                let kept: Vec<u32> = (0..WIDTH)
                    .map(|l| {
                        if le & (1 << l) != 0 {
                            a.0[l]
                        } else {
                            f32::INFINITY
                        }
                        .to_bits()
                    })
                    .collect();
                let (kept_lanes, kept_mask) = a.kept_where_le::<false>(b);
                assert_eq!((bits(kept_lanes).to_vec(), kept_mask), (kept, le));
                if j == 0 {
                    assert_eq!(bits(a.abs::<false>()), bits(F32x8(a.0.map(f32::abs))));
                    assert_eq!(bits(a.sqrt::<false>()), bits(F32x8(a.0.map(f32::sqrt))));
                    // The walk's four-lane inverse (`safe_inverse4`), written out in glam.
                    let four = |at: usize| {
                        let x = glam::Vec4::from_slice(&a.0[at..at + 4]);
                        let tiny = x.abs().cmplt(glam::Vec4::splat(1e-30));
                        let huge = glam::Vec4::splat(1e30).copysign(x);
                        glam::Vec4::select(tiny, huge, glam::Vec4::ONE / x).to_array()
                    };
                    let reference = F32x8([four(0), four(4)].concat().try_into().unwrap());
                    assert_eq!(bits(a.safe_inverse::<false>()), bits(reference));
                    if avx2 {
                        assert_eq!(bits(a.abs::<true>()), bits(a.abs::<false>()));
                        assert_eq!(bits(a.sqrt::<true>()), bits(a.sqrt::<false>()));
                        assert_eq!(bits(a.safe_inverse::<true>()), bits(reference));
                    }
                }
                if avx2 {
                    let (avx_lanes, avx_mask) = a.kept_where_le::<true>(b);
                    assert_eq!((bits(avx_lanes), avx_mask), (bits(kept_lanes), kept_mask));
                    assert_eq!(bits(a.add::<true>(b)), bits(a.add::<false>(b)));
                    assert_eq!(bits(a.div::<true>(b)), bits(a.div::<false>(b)));
                    assert_eq!(a.lt_mask::<true>(b), a.lt_mask::<false>(b));
                    assert_eq!(a.gt_mask::<true>(b), a.gt_mask::<false>(b));
                    assert_eq!(a.eq_mask::<true>(b), a.eq_mask::<false>(b));
                    assert_eq!(a.ne_mask::<true>(b), a.ne_mask::<false>(b));
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
        let (a, b) = (F32x8::splat(f32::NAN), F32x8::splat(1.0));
        assert_eq!(a.min::<false>(b).0[0], 1.0);
        assert!(b.max::<false>(a).0[0].is_nan());
        assert_eq!(a.le_mask::<false>(b), 0);
    }
}
