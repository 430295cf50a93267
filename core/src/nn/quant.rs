//! Requantisation: an `i32` accumulator times a real scale, in integers only.
//!
//! A real multiplier `m > 0` is stored as a Q0.31 integer `M ∈ [2^30, 2^31)` and a power of two,
//! `m ≈ M · 2^(shift − 31)` (TFLite's `QuantizeMultiplier`; the relative error of `M` is below
//! `2^-31`). [`Requant::apply`] is TFLite's `MultiplyByQuantizedMultiplier`:
//!
//! 1. `x << max(shift, 0)` (saturating),
//! 2. gemmlowp `SaturatingRoundingDoublingHighMul(x, M)`: `x·M / 2^31` rounded to nearest,
//!    ties toward +∞ (gemmlowp's nudge is `2^30` for a positive product and `1 − 2^30` for a
//!    negative one, followed by a truncating division: a negative tie is *not* pushed away from
//!    zero — the code, not its comment, is the spec, and TFLite runs this code),
//! 3. gemmlowp `RoundingDivideByPOT(·, max(−shift, 0))` = `· / 2^e` rounded half away from zero.
//!
//! So the result is the real product `acc · m` rounded **twice** (first to a multiple of
//! `2^-e`, then to an integer). It differs by at most one from the single round-half-away of
//! the exact product, and only when the first rounding lands exactly on a half (or, with no
//! right shift, on a negative exact tie); the tests check this against exact `i128` arithmetic.
//! With the network's scales (`m ≲ 2^-6`, `e ≥ 6`) the first step is fine-grained and such
//! ties are rare. This is the rounding of every TFLite int8 kernel, so results match TFLite
//! bit for bit.
//!
//! **Vector forms.** gemmlowp's step 2 is exactly `floor((x·M + 2^30) / 2^31)` for either sign
//! (its sign-dependent nudge and truncation amount to that), which needs no compare; steps 1 and
//! 3 vectorise as they stand. The x86 kernels (`nn::x86::lanes`) and the portable `Lanes8`
//! compute 8 lanes that way with plain (wrapping) adds and shifts, which equal the saturating
//! ones whenever `|acc + bias| · 2^left ≤ 2^30` — [`fits_simd_requant`], checked once per op
//! from the reduction length and the largest bias (else the scalar [`Requant::to_i8`] runs).

/// A real scale as a Q0.31 multiplier and a power-of-two shift: `scale ≈ multiplier · 2^(shift−31)`.
///
/// `shift > 0` is a left shift of the accumulator before the multiply, `shift < 0` a rounding
/// right shift after it (TFLite's convention). `multiplier == 0` encodes a zero (or
/// unrepresentably small, `< 2^-32`) scale.
///
/// `repr(C)` and `Pod` so a model blob's per-channel requantisers are read in place
/// (`nn::model`: two little-endian `i32`s each).
#[derive(Clone, Copy, Debug, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(C)]
pub struct Requant {
    /// Q0.31 multiplier in `[2^30, 2^31)`, or 0.
    pub multiplier: i32,
    /// Power-of-two exponent, in `-31..=30`.
    pub shift: i32,
}

impl Requant {
    /// The identity (`scale = 1`): `apply(x) == x` for `|x| < 2^30` (the pre-shift saturates
    /// beyond, as in TFLite).
    pub const IDENTITY: Requant = Requant { multiplier: 1 << 30, shift: 1 };

    /// TFLite's `QuantizeMultiplier` for `scale` (`frexp`, then the mantissa rounded half away
    /// from zero to 31 bits, done on the f64's bits so it is exact). Non-positive, NaN or tiny
    /// (`< 2^-32`) scales give the zero requantiser; scales `≥ 2^30` saturate to the largest.
    pub fn from_scale(scale: f64) -> Requant {
        if scale.is_nan() || scale <= 0.0 {
            return Requant { multiplier: 0, shift: 0 };
        }
        if scale >= (1u64 << 30) as f64 {
            return Requant { multiplier: i32::MAX, shift: 30 };
        }
        let bits = scale.to_bits();
        let exp_field = ((bits >> 52) & 0x7ff) as i32;
        if exp_field == 0 {
            // subnormal: far below 2^-32
            return Requant { multiplier: 0, shift: 0 };
        }
        // scale = mant · 2^(exp_field − 1075), mant ∈ [2^52, 2^53): frexp gives q = mant / 2^53
        // ∈ [0.5, 1) and exponent exp_field − 1022.
        let mant = (bits & ((1u64 << 52) - 1)) | (1u64 << 52);
        let mut shift = exp_field - 1022;
        // q · 2^31 = mant / 2^22, rounded half up (= away from zero, it is positive).
        let mut m = (mant + (1 << 21)) >> 22;
        if m == 1u64 << 31 {
            m >>= 1;
            shift += 1;
        }
        if shift < -31 {
            return Requant { multiplier: 0, shift: 0 };
        }
        if shift > 30 {
            return Requant { multiplier: i32::MAX, shift: 30 };
        }
        Requant { multiplier: m as i32, shift }
    }

    /// The real scale this requantiser represents, `multiplier · 2^(shift − 31)`.
    pub fn scale(self) -> f64 {
        let mut s = self.multiplier as f64;
        let mut e = self.shift - 31;
        while e > 0 {
            s *= 2.0;
            e -= 1;
        }
        while e < 0 {
            s *= 0.5;
            e += 1;
        }
        s
    }

    /// `acc · scale`, rounded as TFLite's `MultiplyByQuantizedMultiplier` (see the module docs).
    #[inline]
    pub fn apply(self, acc: i32) -> i32 {
        let left = self.shift.clamp(0, 30);
        let right = (-self.shift).clamp(0, 31);
        let x = acc.saturating_mul(1 << left);
        rounding_divide_by_pot(saturating_rounding_doubling_high_mul(x, self.multiplier), right)
    }

    /// `clamp(zero_point + apply(acc), lo, hi)` as int8, with `(lo, hi)` from [`clamp_range`].
    #[inline]
    pub fn to_i8(self, acc: i32, zero_point: i32, lo: i32, hi: i32) -> i8 {
        self.apply(acc).saturating_add(zero_point).clamp(lo, hi) as i8
    }
}

/// The int8 output range: `[-128, 127]`, or `[max(-128, zero_point), 127]` when a ReLU is fused
/// (real 0 is `zero_point`, so clamping there is exactly `max(0, y)` in the real domain).
#[inline]
pub const fn clamp_range(zero_point: i32, relu: bool) -> (i32, i32) {
    let lo = if relu && zero_point > -128 {
        if zero_point > 127 {
            127
        } else {
            zero_point
        }
    } else {
        -128
    };
    (lo, 127)
}

/// gemmlowp `SaturatingRoundingDoublingHighMul`: `a·b / 2^31` rounded to nearest, ties toward
/// +∞ (see the module docs); the one overflowing case `a = b = i32::MIN` saturates to `i32::MAX`.
#[inline]
pub fn saturating_rounding_doubling_high_mul(a: i32, b: i32) -> i32 {
    if a == i32::MIN && b == i32::MIN {
        return i32::MAX;
    }
    let ab = a as i64 * b as i64;
    let nudge: i64 = if ab >= 0 { 1 << 30 } else { 1 - (1 << 30) };
    // Rust's `/` truncates toward zero, as gemmlowp's C++ does.
    ((ab + nudge) / (1i64 << 31)) as i32
}

/// gemmlowp `RoundingDivideByPOT`: `round_half_away(x / 2^exponent)`, `exponent ∈ 0..=31`.
#[inline]
pub fn rounding_divide_by_pot(x: i32, exponent: i32) -> i32 {
    let e = exponent.clamp(0, 31) as u32;
    let mask = ((1i64 << e) - 1) as i32;
    let remainder = x & mask;
    let threshold = (mask >> 1) + i32::from(x < 0);
    (x >> e) + i32::from(remainder > threshold)
}

/// Largest `|x|` (after the bias and the left shift) the SIMD requantisation takes: below it,
/// `acc + bias` and `x << left` cannot saturate, so plain (wrapping) adds and shifts equal the
/// saturating ones of [`Requant::apply`], and every intermediate of the rounding stays in `i32`.
pub const SIMD_REQUANT_BOUND: i64 = 1 << 30;

/// True when requantising accumulators of magnitude at most `acc_bound` plus any of `bias`
/// with any of `requant` stays below [`SIMD_REQUANT_BOUND`] (see there): the condition under
/// which a kernel may use the vectorised requantisation. It holds for every real network (an
/// accumulator of a 1x1 conv over 592 channels is below `2^25`); when it does not, the kernels
/// take the scalar path, which gives the same integers.
pub fn fits_simd_requant(acc_bound: i64, bias: &[i32], requant: &[Requant]) -> bool {
    let max_bias = bias.iter().map(|&b| (b as i64).abs()).max().unwrap_or(0);
    let max_left = requant.iter().map(|r| r.shift.clamp(0, 30)).max().unwrap_or(0);
    acc_bound.saturating_add(max_bias).saturating_mul(1i64 << max_left) <= SIMD_REQUANT_BOUND
}

/// The requantisers of 8 lanes in a branch-free form (the same integers as
/// [`Requant::apply`]) that the auto-vectoriser maps onto SIMD lanes: `vpmuldq` / `smull` for
/// the 64-bit products, per-lane shifts. For the portable kernels; valid under
/// [`fits_simd_requant`] like the x86 vector code (it is the same arithmetic).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lanes8 {
    m: [i64; 8],
    left: [u32; 8],
    right: [u32; 8],
    mask: [i32; 8],
    half: [i32; 8],
}

impl Lanes8 {
    /// From up to 8 requantisers (missing lanes: zero).
    pub(crate) fn new(r: &[Requant]) -> Self {
        let mut l = Lanes8 { m: [0; 8], left: [0; 8], right: [0; 8], mask: [0; 8], half: [0; 8] };
        for (i, q) in r.iter().take(8).enumerate() {
            let q = Lane1::new(*q);
            (l.m[i], l.left[i], l.right[i], l.mask[i], l.half[i]) =
                (q.m, q.left, q.right, q.mask, q.half);
        }
        l
    }

    /// `clamp(zp + apply(x), lo, hi)` for the 8 lanes (`|x| · 2^left ≤ 2^30`).
    #[inline]
    pub(crate) fn requant(&self, x: &[i32; 8], zp: i32, lo: i32, hi: i32) -> [i8; 8] {
        let mut out = [0i8; 8];
        for l in 0..8 {
            let (m, left, right, mask, half) =
                (self.m[l], self.left[l], self.right[l], self.mask[l], self.half[l]);
            out[l] = requant_lane(x[l], m, left, right, mask, half, zp, lo, hi);
        }
        out
    }
}

/// The branch-free requantisation of one lane (the arithmetic of [`Lanes8`] and [`Lane1`]):
/// `clamp(zp + apply(x), lo, hi)` for `|x| · 2^left ≤ 2^30`, with `mask = 2^right − 1` and
/// `half = mask >> 1`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn requant_lane(
    x: i32,
    m: i64,
    left: u32,
    right: u32,
    mask: i32,
    half: i32,
    zp: i32,
    lo: i32,
    hi: i32,
) -> i8 {
    let v = x << left;
    // SRDHM: floor((v·M + 2^30) / 2^31), whatever the sign (see `nn::x86::lanes`)
    let s = ((v as i64 * m + (1 << 30)) >> 31) as i32;
    // RoundingDivideByPOT, as rounding_divide_by_pot
    let q = (s >> right) + i32::from((s & mask) > half - (s >> 31));
    (q + zp).clamp(lo, hi) as i8
}

/// One requantiser in the branch-free form of [`Lanes8`] (the same integers as
/// [`Requant::to_i8`] for `|x| · 2^left ≤ 2^30`, see [`Lane1::fits`]), for the portable kernels
/// that requantise whole slices with one requantiser (`Add`, `Resize`): there the loop over
/// the slice auto-vectorises, where `to_i8`'s saturating steps and `i64` division do not.
///
/// Its fields are the lane form every vector kernel loads (`Lanes8`, `nn::arm64`'s `Rq8`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lane1 {
    /// The multiplier `M`.
    pub(crate) m: i64,
    /// The left shift `max(shift, 0)`.
    pub(crate) left: u32,
    /// The rounding right shift `e = max(−shift, 0)`.
    pub(crate) right: u32,
    /// `2^e − 1`.
    pub(crate) mask: i32,
    /// `mask >> 1`.
    pub(crate) half: i32,
}

impl Lane1 {
    /// The lane form of `r`.
    pub(crate) fn new(r: Requant) -> Self {
        let right = (-r.shift).clamp(0, 31) as u32;
        let mask = ((1i64 << right) - 1) as i32;
        Lane1 {
            m: r.multiplier as i64,
            left: r.shift.clamp(0, 30) as u32,
            right,
            mask,
            half: mask >> 1,
        }
    }

    /// True when every `|x| ≤ bound` may take [`Lane1::to_i8`] (see [`fits_simd_requant`]).
    pub(crate) fn fits(r: Requant, bound: i64) -> bool {
        fits_simd_requant(bound, &[], &[r])
    }

    /// `clamp(zp + apply(x), lo, hi)`, valid where [`Lane1::fits`] holds for `|x|`.
    #[inline(always)]
    pub(crate) fn to_i8(self, x: i32, zp: i32, lo: i32, hi: i32) -> i8 {
        requant_lane(x, self.m, self.left, self.right, self.mask, self.half, zp, lo, hi)
    }
}

/// The per-input requantisers of TFLite's quantised `Add` (left shift 20): see
/// [`crate::nn::eltwise::AddQuant`].
pub const ADD_LEFT_SHIFT: i32 = 20;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::testutil::Rng;

    /// `n / 2^e` rounded to nearest, ties toward +∞ (gemmlowp's SRDHM), exactly.
    fn rhup_pow2(n: i128, e: u32) -> i128 {
        let d = 1i128 << e;
        (n + d / 2).div_euclid(d)
    }

    /// `round_half_away(n / 2^e)` exactly.
    fn rha_pow2(n: i128, e: u32) -> i128 {
        if e == 0 {
            return n;
        }
        let d = 1i128 << e;
        let q = n.abs() / d;
        let r = n.abs() % d;
        let q = if 2 * r >= d { q + 1 } else { q };
        if n < 0 {
            -q
        } else {
            q
        }
    }

    #[test]
    fn quantize_multiplier_matches_scale() {
        let mut rng = Rng::new(7);
        for _ in 0..10_000 {
            let s = libm::exp(rng.f64(-40.0, 10.0));
            let r = Requant::from_scale(s);
            if s < 1.0 / (1u64 << 32) as f64 {
                continue;
            }
            assert!(r.multiplier >= 1 << 30, "{s} {r:?}");
            assert!((r.scale() - s).abs() <= s * 1e-9, "{s} {r:?}");
        }
        assert_eq!(Requant::from_scale(1.0), Requant::IDENTITY);
        assert_eq!(Requant::from_scale(0.0).multiplier, 0);
        assert_eq!(Requant::from_scale(f64::NAN).multiplier, 0);
        assert_eq!(Requant::from_scale(-1.0).multiplier, 0);
        assert_eq!(Requant::from_scale(1e-300).multiplier, 0);
        assert_eq!(Requant::from_scale(1e300).multiplier, i32::MAX);
        // mantissa rounding up to 2^31 renormalises
        let r = Requant::from_scale(1.0 - 1e-12);
        assert_eq!(r, Requant { multiplier: 1 << 30, shift: 1 });
    }

    #[test]
    fn apply_is_gemmlowp_double_rounding_of_the_exact_product() {
        let mut rng = Rng::new(11);
        let mut single_rounding_mismatches = 0usize;
        let n = 200_000;
        for i in 0..n {
            // every 8th scale a power of two: M = 2^30 makes SRDHM's own ties reachable
            let s = if i % 8 == 7 {
                1.0 / (1u64 << rng.int(0, 24)) as f64
            } else {
                libm::exp(rng.f64(-25.0, 3.0))
            };
            let r = Requant::from_scale(s);
            let acc = match i % 4 {
                0 => rng.int(-300, 300) as i32,
                1 => rng.int(-(1 << 20), 1 << 20) as i32,
                _ => rng.int(i32::MIN as i64, i32::MAX as i64) as i32,
            };
            let got = r.apply(acc);
            let left = r.shift.max(0) as u32;
            let right = (-r.shift).max(0) as u32;
            let x = (acc as i128 * (1i128 << left)).clamp(i32::MIN as i128, i32::MAX as i128);
            let p = x * r.multiplier as i128;
            // the documented two-step rounding, exactly
            let two_step = rha_pow2(rhup_pow2(p, 31), right);
            assert_eq!(got as i128, two_step, "acc {acc} {r:?}");
            // single rounding of the exact product differs by at most one
            let single = rha_pow2(p, 31 + right);
            assert!((got as i128 - single).abs() <= 1);
            if got as i128 != single {
                // only when the first step lands exactly on a half of the second
                let first = rhup_pow2(p, 31);
                let on_half = right > 0 && first.rem_euclid(1 << right) == 1 << (right - 1);
                let negative_tie = right == 0 && p < 0 && p.rem_euclid(1 << 31) == 1 << 30;
                assert!(on_half || negative_tie, "{acc} {r:?}");
                single_rounding_mismatches += 1;
            }
            // and against the float product (only where f64 is exact enough to tell)
            if x == acc as i128 {
                let f = acc as f64 * r.scale();
                let first_step = 0.5 / (1u64 << right) as f64;
                let tol = 0.5 + first_step + 1e-6 * f.abs().max(1.0);
                assert!((got as f64 - f).abs() <= tol, "{acc} {s}");
            }
        }
        // frequent only for right shifts of 1..3 (scales in [1/16, 1/2)), where the first step
        // is coarse; the network's scales are ~2^-8 and smaller
        std::println!("double vs single rounding differ in {single_rounding_mismatches} of {n}");
    }

    #[test]
    fn lanes8_equals_the_scalar_requantisation() {
        let mut rng = Rng::new(0x1a7e);
        for i in 0..20_000 {
            let rq: [Requant; 8] = core::array::from_fn(|_| {
                let s = if i % 4 == 0 {
                    1.0 / (1u64 << rng.int(0, 31)) as f64
                } else {
                    libm::exp(rng.f64(-22.0, 6.0))
                };
                Requant::from_scale(s)
            });
            let x: [i32; 8] = core::array::from_fn(|l| {
                let bound = SIMD_REQUANT_BOUND >> rq[l].shift.clamp(0, 30);
                match rng.int(0, 2) {
                    0 => rng.int(-300, 300) as i32,
                    1 => rng.int(-bound, bound) as i32,
                    _ => [-bound, bound, -1, 0][rng.usize(0, 3)] as i32,
                }
            });
            let (zp, relu) = (rng.zp(), rng.int(0, 1) == 1);
            let (lo, hi) = clamp_range(zp, relu);
            let want: [i8; 8] = core::array::from_fn(|l| rq[l].to_i8(x[l], zp, lo, hi));
            assert_eq!(Lanes8::new(&rq).requant(&x, zp, lo, hi), want, "{rq:?} {x:?}");
            for l in 0..8 {
                // the bound each lane was drawn under is what `Lane1::fits` accepts
                let bound = SIMD_REQUANT_BOUND >> rq[l].shift.clamp(0, 30);
                assert!(Lane1::fits(rq[l], bound) && !Lane1::fits(rq[l], bound + 1));
                assert_eq!(
                    Lane1::new(rq[l]).to_i8(x[l], zp, lo, hi),
                    want[l],
                    "{:?} {}",
                    rq[l],
                    x[l]
                );
            }
        }
    }

    #[test]
    fn identity_and_saturation() {
        for x in [-(1 << 30) + 1, -5, -1, 0, 1, 7, (1 << 30) - 1] {
            assert_eq!(Requant::IDENTITY.apply(x), x);
        }
        assert_eq!(saturating_rounding_doubling_high_mul(i32::MIN, i32::MIN), i32::MAX);
        assert_eq!(rounding_divide_by_pot(5, 1), 3);
        assert_eq!(rounding_divide_by_pot(-5, 1), -3);
        assert_eq!(rounding_divide_by_pot(-4, 1), -2);
        assert_eq!(rounding_divide_by_pot(i32::MIN, 31), -1);
        let half = Requant::from_scale(0.5);
        // SRDHM ties go toward +inf: 1.5 -> 2, -1.5 -> -1, 0.5 -> 1, -0.5 -> 0
        assert_eq!((half.apply(3), half.apply(-3), half.apply(1), half.apply(-1)), (2, -1, 1, 0));
        // RoundingDivideByPOT ties go away from zero: 0.25 · ±6 = ±1.5 -> ±2
        let quarter = Requant::from_scale(0.25);
        assert_eq!((quarter.apply(6), quarter.apply(-6)), (2, -2));
        assert_eq!(Requant::from_scale(1e6).to_i8(1000, 0, -128, 127), 127);
        assert_eq!(clamp_range(-5, true), (-5, 127));
        assert_eq!(clamp_range(-5, false), (-128, 127));
        assert_eq!(half.to_i8(-100, 3, -5, 127), -5);
    }
}
