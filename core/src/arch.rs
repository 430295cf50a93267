//! # arch: the safe scalar kernels, compiled a second time for x86-64-v3
//!
//! The hot loops of ORB extraction and the image filters (FAST scoring and non-maximum
//! suppression, the pyramid resize, the 7×7 blur, orientation moments, rBRIEF) are plain safe Rust written to auto-vectorise. A baseline
//! x86-64 build (a plain `cargo install`, no `-C target-cpu`) compiles them for SSE2 only:
//! 16-byte vectors and no 32-bit lane multiply. [`v3`] runs a closure compiled with AVX2,
//! POPCNT, BMI1/2 and LZCNT when the CPU has them (probed once with `cpuid`/`xgetbv`, as the
//! network's kernels are: [`crate::nn::x86`]), and the baseline code otherwise. A kernel opts in
//! by passing its body as an `#[inline(always)]` closure, the body and the helpers it calls
//! marked `#[inline(always)]` as well: only code inlined into the `#[target_feature]` function
//! is compiled for it (a closure left out of line is a plain baseline function, and a large one
//! is left out of line).
//!
//! **Same bits on every level.** The code is the same source: integer arithmetic is exact, and
//! floating point is IEEE-754 per operation at any vector width (Rust never fuses a multiply
//! and an add, and FMA is not among the features enabled here), so results are identical to
//! the baseline build's and to every other target's; `tests` compares both levels on real
//! work. The level follows the network's cap ([`crate::nn::x86::set_max_isa`]): capped at
//! `Portable`, these kernels run their baseline code too.
//!
//! `unsafe` is allowed in this module and in `nn::x86` only: calling the `#[target_feature]`
//! function is sound because it is called only after the run-time check.

#![allow(unsafe_code)]

/// Runs `f`, compiled for AVX2 + POPCNT + BMI1/2 + LZCNT when this x86-64 CPU has them (and the
/// instruction-set cap allows AVX2), else as the build's baseline code. `f` and whatever it
/// calls that should be compiled for the faster level must be inlined into it: pass
/// `#[inline(always)] || body(..)` with `body` `#[inline(always)]`. Results are the same either
/// way.
#[inline(always)]
pub(crate) fn v3<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if x86::v3_allowed() {
        // SAFETY: `v3_allowed` is true only when `cpuid`/`xgetbv` report every feature
        // `x86::run_v3` is compiled with, and the OS saves the YMM state.
        return unsafe { x86::run_v3(f) };
    }
    f()
}

/// `v` clamped to `0.0..=max` (NaN as 0) and truncated: Rust's saturating float-to-integer
/// conversion, which does not vectorise, replaced by a plain truncation that cannot overflow
/// once clamped. `max` outside `0.0..=2e9` (or NaN) is taken as 0.
#[inline(always)]
pub(crate) fn trunc_clamped(v: f32, max: f32) -> i32 {
    let max = if (0.0..=2.0e9).contains(&max) { max } else { 0.0 };
    // `f32::max` returns the other argument when one is NaN: `c` is finite, in 0..=max.
    let c = v.max(0.0).min(max);
    // SAFETY: `c` is finite and in `0.0..=2e9`, so its truncation is representable in `i32`.
    unsafe { c.to_int_unchecked::<i32>() }
}

/// The Harris sums `(ΣIx², ΣIy², ΣIxIy)` over a 7 × 7 block from the 9 rows of 10 columns its
/// 3 × 3 Sobel taps touch (`orb::harris`), with SSE2, part of every x86-64 CPU: per row, three
/// 8-byte loads at column offsets 0, 1, 2 give the separable Sobel halves on 8 `i16` lanes (the
/// eighth, outside the block, masked to 0), and `pmaddwd` squares and pair-sums them into `i32`.
/// Exact integers (|Ix|, |Iy| ≤ 1020, so no lane overflows): the same sums as the scalar loop.
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn harris_sums(rows: &[[u8; 10]; 9]) -> (i32, i32, i32) {
    use core::arch::x86_64::*;
    // SAFETY: SSE2 is enabled on every x86-64 target; the intrinsics only read the values
    // passed to them (the loads are of local integers, not pointers).
    unsafe {
        let zero = _mm_setzero_si128();
        let lanes = |r: &[u8; 10], o: usize| -> __m128i {
            let mut b = [0u8; 8];
            b.copy_from_slice(&r[o..o + 8]);
            _mm_unpacklo_epi8(_mm_cvtsi64_si128(i64::from_le_bytes(b)), zero)
        };
        // (horizontal difference, horizontal smoothing) of one row.
        let terms = |r: &[u8; 10]| -> (__m128i, __m128i) {
            let (a0, a1, a2) = (lanes(r, 0), lanes(r, 1), lanes(r, 2));
            (_mm_sub_epi16(a2, a0), _mm_add_epi16(_mm_add_epi16(a0, a2), _mm_add_epi16(a1, a1)))
        };
        let mask = _mm_set_epi16(0, -1, -1, -1, -1, -1, -1, -1);
        let (mut h0, mut s0) = terms(&rows[0]);
        let (mut h1, mut s1) = terms(&rows[1]);
        let (mut a, mut b, mut c) = (zero, zero, zero);
        for r in &rows[2..] {
            let (h2, s2) = terms(r);
            let ix =
                _mm_and_si128(_mm_add_epi16(_mm_add_epi16(h0, h2), _mm_add_epi16(h1, h1)), mask);
            let iy = _mm_and_si128(_mm_sub_epi16(s2, s0), mask);
            a = _mm_add_epi32(a, _mm_madd_epi16(ix, ix));
            b = _mm_add_epi32(b, _mm_madd_epi16(iy, iy));
            c = _mm_add_epi32(c, _mm_madd_epi16(ix, iy));
            (h0, s0, h1, s1) = (h1, s1, h2, s2);
        }
        let sum = |v: __m128i| -> i32 {
            let v = _mm_add_epi32(v, _mm_shuffle_epi32::<0b01_00_11_10>(v));
            let v = _mm_add_epi32(v, _mm_shuffle_epi32::<0b10_11_00_01>(v));
            _mm_cvtsi128_si32(v)
        };
        (sum(a), sum(b), sum(c))
    }
}

/// Whether [`v3`] runs its closure compiled for x86-64-v3 on this thread now.
pub fn v3_active() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        x86::v3_allowed()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Shuffle plan of [`resize_rows_h`] for blocks of 8 destination pixels, made by
/// [`plan_resize_h`]: per block, the first source index and 16 byte indices (`a0 b0 a1 b1 … a7
/// b7`, relative to it) of the two taps of each destination pixel, and its weight pairs
/// `(2048 − w, w)` as `i16`.
// Only the x86-64 vector pass reads it; elsewhere the plan is always empty.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) struct ResizePlan<'a> {
    /// First source index of each block.
    base: &'a [u32],
    /// 16 tap indices per block, relative to its `base`.
    taps: &'a [[u8; 16]],
    /// 16 weights per block (pairs `(2048 − w, w)`).
    weights: &'a [[i16; 16]],
    /// How many leading blocks the plan covers.
    blocks: usize,
}

/// Plans the vector horizontal pass of the bilinear resize for destination columns with
/// source indices `x0` and weights `wx` (11-bit) on source rows of `src_w` pixels, in the
/// caller's storage. The plan covers the leading 8-pixel blocks whose 16 source bytes
/// `base..base + 16` lie in the row and hold both taps of all its pixels (always for
/// down-scaling by up to ~1.9; the scalar pass does the rest); none when [`v3`] would not run
/// the vector code.
pub(crate) fn plan_resize_h<'a>(
    x0: &[u32],
    wx: &[u32],
    src_w: usize,
    base: &'a mut [u32],
    taps: &'a mut [[u8; 16]],
    weights: &'a mut [[i16; 16]],
) -> ResizePlan<'a> {
    let mut blocks = 0;
    if v3_active() && src_w >= 16 {
        let last = src_w - 1;
        let most = (x0.len() / 8).min(base.len()).min(taps.len()).min(weights.len());
        'blocks: while blocks < most {
            let b = blocks;
            let first = x0[8 * b] as usize;
            if first + 16 > src_w {
                break;
            }
            for j in 0..8 {
                let i = x0[8 * b + j] as usize;
                let i1 = if i < last { i + 1 } else { last };
                if i < first || i1 - first > 15 {
                    break 'blocks;
                }
                taps[b][2 * j] = (i - first) as u8;
                taps[b][2 * j + 1] = (i1 - first) as u8;
                let w = wx[8 * b + j] as i16;
                weights[b][2 * j] = 2048 - w;
                weights[b][2 * j + 1] = w;
            }
            base[b] = first as u32;
            blocks += 1;
        }
    }
    ResizePlan { base, taps, weights, blocks }
}

/// The horizontal pass of [`crate::image::resize_bilinear`] for the destination pixels `plan`
/// covers: `out[d] = src[x0]·(2048 − w) + src[x0 + 1]·w`, the same integers as the scalar
/// pass. Returns how many leading pixels of `out` it wrote: 8 per planned block, or 0 where the
/// x86-64-v3 code does not run.
pub(crate) fn resize_rows_h(src: &[u8], plan: &ResizePlan<'_>, out: &mut [u32]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if plan.blocks > 0 && x86::v3_allowed() {
        let ResizePlan { base, taps, weights, blocks } = *plan;
        let blocks = blocks.min(base.len()).min(taps.len()).min(weights.len()).min(out.len() / 8);
        // Every load stays in `src`: checked here once per block (the plan guarantees it).
        if base[..blocks].iter().all(|&b| b as usize + 16 <= src.len()) {
            // SAFETY: AVX2 present (`v3_allowed`); the loads read `src[base..base + 16]`,
            // checked just above, and the stores write `out[8b..8b + 8]` for `b < blocks <=
            // out.len() / 8`.
            unsafe { x86::resize_rows_h_avx2(src, base, taps, weights, blocks, out) };
            return 8 * blocks;
        }
    }
    let _ = (src, plan, out);
    0
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use core::arch::x86_64::{__cpuid, __cpuid_count};
    use core::sync::atomic::{AtomicU8, Ordering};

    use crate::nn::x86::Isa;

    /// 0: not probed; 1: the CPU lacks one of the extra features; 2: it has them all.
    static EXTRAS: AtomicU8 = AtomicU8::new(0);

    /// POPCNT, BMI1, BMI2 and LZCNT, beside the AVX2 (and OS YMM state) that
    /// `nn::x86::cpu_isa` checks.
    fn probe_extras() -> bool {
        let l1 = __cpuid(1);
        let popcnt = l1.ecx & (1 << 23) != 0;
        if __cpuid(0).eax < 7 || __cpuid(0x8000_0000).eax < 0x8000_0001 {
            return false;
        }
        let l7 = __cpuid_count(7, 0);
        let (bmi1, bmi2) = (l7.ebx & (1 << 3) != 0, l7.ebx & (1 << 8) != 0);
        let lzcnt = __cpuid(0x8000_0001).ecx & (1 << 5) != 0;
        popcnt && bmi1 && bmi2 && lzcnt
    }

    /// True when the CPU has every feature of [`run_v3`] and the cap allows AVX2.
    #[inline]
    pub(super) fn v3_allowed() -> bool {
        if crate::nn::dispatch::level() < Isa::Avx2 {
            return false;
        }
        match EXTRAS.load(Ordering::Relaxed) {
            0 => {
                let ok = probe_extras();
                EXTRAS.store(1 + u8::from(ok), Ordering::Relaxed);
                ok
            }
            v => v == 2,
        }
    }

    /// `f()`, compiled with the x86-64-v3 integer and vector features (FMA left out: it would
    /// not change Rust's arithmetic, which never fuses, but nothing here needs it).
    ///
    /// # Safety
    /// The CPU must have AVX2, POPCNT, BMI1, BMI2 and LZCNT, and the OS must save the YMM
    /// state ([`v3_allowed`]).
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    #[inline]
    pub(super) unsafe fn run_v3<R>(f: impl FnOnce() -> R) -> R {
        f()
    }

    /// Per block: one 16-byte load at its base, a byte shuffle into `a0 b0 … a7 b7`, widening
    /// to `i16` and `vpmaddwd` with `(2048 − w, w)`: eight exact `a·(2048 − w) + b·w`.
    ///
    /// # Safety
    /// AVX2 must be present; `base[b] + 16 <= src.len()` and `8·blocks <= out.len()`, with
    /// `blocks` at most the lengths of `base`, `taps` and `weights`.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn resize_rows_h_avx2(
        src: &[u8],
        base: &[u32],
        taps: &[[u8; 16]],
        weights: &[[i16; 16]],
        blocks: usize,
        out: &mut [u32],
    ) {
        use core::arch::x86_64::{
            __m128i, __m256i, _mm256_cvtepu8_epi16, _mm256_loadu_si256, _mm256_madd_epi16,
            _mm256_storeu_si256, _mm_loadu_si128, _mm_shuffle_epi8,
        };
        let (s, o) = (src.as_ptr(), out.as_mut_ptr());
        for b in 0..blocks {
            let v = _mm_loadu_si128(s.add(base[b] as usize).cast::<__m128i>());
            let t = _mm_loadu_si128(taps[b].as_ptr().cast::<__m128i>());
            let pairs = _mm256_cvtepu8_epi16(_mm_shuffle_epi8(v, t));
            let w = _mm256_loadu_si256(weights[b].as_ptr().cast::<__m256i>());
            _mm256_storeu_si256(o.add(8 * b).cast::<__m256i>(), _mm256_madd_epi16(pairs, w));
        }
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    /// The probe finds what std's detection finds, so the tests that compare the levels
    /// (`orb::tests::golden_output_is_unchanged`) really run the x86-64-v3 code where the CPU
    /// has it, and it is off when the cap is below AVX2.
    #[test]
    fn probe_agrees_with_std() {
        use std::arch::is_x86_feature_detected as has;
        let all = has!("avx2") && has!("popcnt") && has!("bmi1") && has!("bmi2") && has!("lzcnt");
        let mut seen = std::vec::Vec::new();
        crate::nn::dispatch::for_each_level(|level| seen.push((level, super::v3_active())));
        for (level, active) in seen {
            assert_eq!(active, all && level != "portable", "level {level}");
        }
    }
}

#[cfg(test)]
mod trunc_tests {
    #[test]
    fn trunc_clamped_is_the_clamped_saturating_conversion() {
        let vals = [
            f32::NAN,
            f32::NEG_INFINITY,
            -1e30,
            -1.5,
            -0.0,
            0.0,
            0.999,
            1.0,
            62.99,
            63.0,
            63.5,
            1e9,
            3e9,
            f32::INFINITY,
        ];
        for max in [0.0f32, 23.0, 63.0, 1.5e9] {
            for &v in &vals {
                let want = (v as i64).clamp(0, max as i64) as i32;
                assert_eq!(super::trunc_clamped(v, max), want, "v {v} max {max}");
            }
        }
        // Out-of-range or NaN bounds are taken as 0, never a conversion that overflows.
        for max in [f32::NAN, -1.0, 3e9, f32::INFINITY] {
            assert_eq!(super::trunc_clamped(1e30, max), 0, "max {max}");
        }
    }
}
