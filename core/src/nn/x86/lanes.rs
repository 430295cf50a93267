//! # x86 lanes: requantisation, loads and stores of 8 `i32` lanes (AVX2)
//!
//! The pieces every x86 family shares. No ONNX op of its own; stack: none beyond registers.
//! ISA: AVX2, [`store8_avx512`] AVX-512 F/VL (VNNI GEMM only), both detected at run time: every
//! function here carries its `#[target_feature]`, so it inlines into the kernels that call it.
//!
//! **Requantisation, 8 lanes at once.** [`Requant::apply`] needs a 32×32→64-bit product; AVX2
//! has it for the even lanes (`vpmuldq`), so odd lanes are shifted down and multiplied
//! separately. gemmlowp's SRDHM `(p + nudge) / 2^31` truncated, with the sign-dependent nudge,
//! is exactly `floor((p + 2^30) / 2^31)` for every `p` (for `p < 0`: `trunc((p + 1 − 2^30) /
//! 2^31) = ceil(…) = floor((p + 2^30) / 2^31)`), i.e. bits 31..62 of `p + 2^30`: one add and one
//! 64-bit shift per half, no compare. `RoundingDivideByPOT` is the reference's own
//! mask/threshold form with `vpsravd`. Bias adds and left shifts are plain (wrapping) ops, valid
//! under [`crate::nn::quant::fits_simd_requant`], which the family entries check once per op
//! (else the portable kernel runs). Output: `+ zero_point`, `max(lo)` for a fused ReLU, and the
//! signed saturating packs (`vpackssdw`/`vpacksswb`) do the clamp to `[-128, 127]`.

use core::arch::x86_64::*;

use crate::nn::Requant;

/// The requantisers of 8 lanes, in the forms the vector code needs.
#[derive(Clone, Copy)]
pub(super) struct Rq8 {
    mult: __m256i,
    /// The odd lanes' multipliers copied to the low half of each 64-bit lane (for `vpmuldq`).
    /// A shuffle, not a 64-bit shift: from `srli_epi64` LLVM proved the high halves zero,
    /// rewrote the `vpmuldq` as a 64-bit multiply and emulated it with three `vpmuludq` (found
    /// in the requantisers built with [`Rq8::splat`]: resize, add, concat).
    mult_odd: __m256i,
    left: __m256i,
    right: __m256i,
    /// `(1 << right) − 1`.
    mask: __m256i,
    /// `mask >> 1`.
    half: __m256i,
    /// Some lane shifts left (never for the network's convs: their scales are `< 1/2`).
    left_any: bool,
}

impl Rq8 {
    /// From up to 8 requantisers (missing lanes: zero multiplier).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn new(r: &[Requant]) -> Self {
        let mut m = [0i32; 8];
        let mut l = [0i32; 8];
        let mut e = [0i32; 8];
        for (i, q) in r.iter().take(8).enumerate() {
            m[i] = q.multiplier;
            l[i] = q.shift.clamp(0, 30);
            e[i] = (-q.shift).clamp(0, 31);
        }
        Self::from_lanes(m, l, e)
    }

    /// The same requantiser in all 8 lanes.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn splat(q: Requant) -> Self {
        Self::from_lanes([q.multiplier; 8], [q.shift.clamp(0, 30); 8], [(-q.shift).clamp(0, 31); 8])
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    fn from_lanes(m: [i32; 8], l: [i32; 8], e: [i32; 8]) -> Self {
        let mask = e.map(|e| ((1i64 << e) - 1) as i32);
        let v = |a: [i32; 8]| _mm256_setr_epi32(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]);
        let mult = v(m);
        Self {
            mult,
            mult_odd: _mm256_shuffle_epi32::<0xf5>(mult),
            left: v(l),
            right: v(e),
            mask: v(mask),
            half: v(mask.map(|m| m >> 1)),
            left_any: l.iter().any(|&l| l != 0),
        }
    }

    /// The same requantisers with the 64-bit lanes 1 and 2 swapped: for values in `vphaddd`
    /// order (`[c0 c1 c4 c5 | c2 c3 c6 c7]`). `mult_odd` stays paired with `mult`, the swap
    /// moving whole 64-bit lanes.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(super) fn in_hadd_order(&self) -> Self {
        let p = |v: __m256i| _mm256_permute4x64_epi64::<0xd8>(v);
        Self {
            mult: p(self.mult),
            mult_odd: p(self.mult_odd),
            left: p(self.left),
            right: p(self.right),
            mask: p(self.mask),
            half: p(self.half),
            left_any: self.left_any,
        }
    }
}

/// [`Requant::apply`] on 8 lanes, for `|x| · 2^left ≤ 2^30` (see the module docs).
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn requant8(x: __m256i, p: &Rq8) -> __m256i {
    let nudge = _mm256_set1_epi64x(1 << 30);
    let x = if p.left_any { _mm256_sllv_epi32(x, p.left) } else { x };
    let pe = _mm256_add_epi64(_mm256_mul_epi32(x, p.mult), nudge);
    // `vpmuldq` reads the low half of each 64-bit lane: the odd lanes, copied down
    let odd = _mm256_shuffle_epi32::<0xf5>(x);
    let po = _mm256_add_epi64(_mm256_mul_epi32(odd, p.mult_odd), nudge);
    // bits 31..62 of each product: the even ones to the low, the odd ones to the high half
    let s =
        _mm256_blend_epi32::<0b1010_1010>(_mm256_srli_epi64::<31>(pe), _mm256_slli_epi64::<1>(po));
    rdbpot8(s, p)
}

/// gemmlowp's `RoundingDivideByPOT` by `p.right` on 8 lanes, in the reference's own form:
/// `(s >> e) + (s & mask > (mask >> 1) + (s < 0))`.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn rdbpot8(s: __m256i, p: &Rq8) -> __m256i {
    let q = _mm256_srav_epi32(s, p.right);
    let rem = _mm256_and_si256(s, p.mask);
    let thr = _mm256_sub_epi32(p.half, _mm256_srai_epi32::<31>(s));
    _mm256_sub_epi32(q, _mm256_cmpgt_epi32(rem, thr))
}

/// 4 × 8 lanes to 32 saturated bytes in lane order (`a` first).
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn pack32(a: __m256i, b: __m256i, c: __m256i, d: __m256i) -> __m256i {
    let abcd = _mm256_packs_epi16(_mm256_packs_epi32(a, b), _mm256_packs_epi32(c, d));
    _mm256_permutevar8x32_epi32(abcd, _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7))
}

/// `max(zero_point + requant(x), lo)`; the packs clamp the top and the bottom at −128.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn finish8(x: __m256i, p: &Rq8, zp: __m256i, lo: __m256i) -> __m256i {
    _mm256_max_epi32(_mm256_add_epi32(requant8(x, p), zp), lo)
}

/// 8 lanes to 8 saturated bytes (little-endian in the `u64`).
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn pack8(v: __m256i) -> u64 {
    let w = _mm256_packs_epi32(v, v);
    let b = _mm256_packs_epi16(w, w);
    let lo = _mm256_castsi256_si128(b);
    let hi = _mm256_extracti128_si256::<1>(b);
    _mm_cvtsi128_si64(_mm_unpacklo_epi32(lo, hi)) as u64
}

/// Stores the first `n ≤ 8` bytes of [`pack8`]`(v)` at `dst`.
///
/// # Safety
/// `dst..dst + n` must be writable.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn store8(dst: *mut i8, v: __m256i, n: usize) {
    let b = pack8(v);
    if n >= 8 {
        // SAFETY: the caller guarantees 8 writable bytes
        unsafe { (dst as *mut u64).write_unaligned(b) };
    } else {
        let bytes = b.to_le_bytes();
        for (t, &v) in bytes.iter().enumerate().take(n) {
            // SAFETY: t < n, writable by the caller's guarantee
            unsafe { *dst.add(t) = v as i8 };
        }
    }
}

/// [`store8`] with AVX-512's saturating narrow (`vpmovsdb`): one instruction for the packs.
///
/// # Safety
/// AVX-512 F/VL available; `dst..dst + n` writable.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
pub(super) unsafe fn store8_avx512(dst: *mut i8, v: __m256i, n: usize) {
    let b = _mm_cvtsi128_si64(_mm256_cvtsepi32_epi8(v)) as u64;
    if n >= 8 {
        // SAFETY: the caller guarantees 8 writable bytes
        unsafe { (dst as *mut u64).write_unaligned(b) };
    } else {
        for (t, &v) in b.to_le_bytes().iter().enumerate().take(n) {
            // SAFETY: t < n
            unsafe { *dst.add(t) = v as i8 };
        }
    }
}

/// 8 bytes at `p` sign-extended to 8 `i32` lanes.
///
/// # Safety
/// `p..p + 8` readable.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn load8(p: *const i8) -> __m256i {
    // SAFETY: by the caller
    _mm256_cvtepi8_epi32(unsafe { _mm_loadl_epi64(p as *const __m128i) })
}

/// The first `n ≤ 8` bytes at `p` sign-extended (the other lanes 0).
///
/// # Safety
/// `p..p + n` readable.
#[inline]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn load_n(p: *const i8, n: usize) -> __m256i {
    if n >= 8 {
        // SAFETY: 8 bytes readable
        return unsafe { load8(p) };
    }
    let mut b = [0i8; 8];
    for (t, v) in b.iter_mut().enumerate().take(n) {
        // SAFETY: t < n
        *v = unsafe { *p.add(t) };
    }
    _mm256_cvtepi8_epi32(_mm_set1_epi64x(i64::from_le_bytes(b.map(|v| v as u8))))
}

/// Up to 8 `i32`s as a vector (missing lanes 0).
#[inline]
#[target_feature(enable = "avx2")]
pub(super) fn from_slice(v: &[i32]) -> __m256i {
    let mut a = [0i32; 8];
    for (d, &s) in a.iter_mut().zip(v) {
        *d = s;
    }
    _mm256_setr_epi32(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::quant::SIMD_REQUANT_BOUND;
    use crate::nn::testutil::Rng;

    #[test]
    fn requant8_equals_the_scalar_requantisation() {
        if super::super::Avx2::get().is_none() {
            return;
        }
        let mut rng = Rng::new(0x51d);
        for i in 0..20_000 {
            // scales from 2^-32 to 2^8: right shifts 0..31, left shifts up to 9, ties reached
            // by powers of two every 4th lane set
            let rq: [Requant; 8] = core::array::from_fn(|_| {
                let s = if i % 4 == 0 {
                    1.0 / (1u64 << rng.int(0, 31)) as f64
                } else {
                    libm::exp(rng.f64(-22.0, 6.0))
                };
                if rng.int(0, 50) == 0 {
                    Requant { multiplier: 0, shift: 0 }
                } else {
                    Requant::from_scale(s)
                }
            });
            let x: [i32; 8] = core::array::from_fn(|l| {
                let bound = SIMD_REQUANT_BOUND >> rq[l].shift.clamp(0, 30);
                match rng.int(0, 3) {
                    0 => rng.int(-300, 300) as i32,
                    1 => rng.int(-bound, bound) as i32,
                    _ => [-bound, bound, -1, 0][rng.usize(0, 3)] as i32,
                }
            });
            let (zp, relu) = (rng.zp(), rng.int(0, 1) == 1);
            let (lo, hi) = crate::nn::quant::clamp_range(zp, relu);
            let want: [i32; 8] = core::array::from_fn(|l| rq[l].apply(x[l]));
            let want8: [i8; 8] = core::array::from_fn(|l| rq[l].to_i8(x[l], zp, lo, hi));
            // SAFETY: AVX2 checked at the top of the test
            let (got, got8) = unsafe { lanes_of(&rq, &x, zp, lo) };
            assert_eq!(got, want, "{rq:?} {x:?}");
            assert_eq!(got8, want8, "{rq:?} {x:?} {zp} {relu}");
        }
    }

    /// `requant8` and `finish8` + `pack8` of one vector, as arrays.
    #[target_feature(enable = "avx2")]
    fn lanes_of(rq: &[Requant; 8], x: &[i32; 8], zp: i32, lo: i32) -> ([i32; 8], [i8; 8]) {
        let p = Rq8::new(rq);
        let v = _mm256_setr_epi32(x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]);
        let mut out = [0i32; 8];
        let r = requant8(v, &p);
        for (l, o) in out.iter_mut().enumerate() {
            let mut a = [0i32; 8];
            // SAFETY: 32 writable bytes
            unsafe { _mm256_storeu_si256(a.as_mut_ptr() as *mut __m256i, r) };
            *o = a[l];
        }
        let b = pack8(finish8(v, &p, _mm256_set1_epi32(zp), _mm256_set1_epi32(lo)));
        (out, b.to_le_bytes().map(|v| v as i8))
    }
}
