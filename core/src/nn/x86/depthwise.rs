//! # x86 depthwise: the depthwise 3×3 `Conv`, AVX2
//!
//! ONNX `Conv` with `group = C`, a 3×3 kernel, pad 1, stride 1 or 2, weights `[3][3][C]`:
//! `out[oy][ox][c] = clamp(zo + requant[c](bias[c] + Σ_taps (x − zp)·w[ky][kx][c]))` — the
//! integers of [`crate::nn::conv::depthwise3x3_reference`].
//!
//! 8 channels per vector. Interior pixels sum raw bytes from `bias − zp·Σw`, taps interleaved
//! in pairs into `vpmaddwd`; border pixels `(x − zp)·w` over their valid taps.
//!
//! **ISA:** AVX2 (detected at run time: [`super::Avx2`]). **Stack:** 21 KiB of per-group constants
//! (32 groups of 8 channels; wider layers take several passes over the pixels).

use core::arch::x86_64::*;

use super::lanes::{finish8, from_slice, load8, load_n, pack32, store8, Rq8};
use super::Avx2;
use crate::nn::conv::ConvQuant;
use crate::nn::quant::{clamp_range, fits_simd_requant};
use crate::nn::{Requant, Shape};

/// The depthwise 3×3 conv on operands [`crate::nn::conv::depthwise3x3_fast`] has checked. `false`,
/// with nothing written, on a CPU without AVX2 or when the accumulators could leave the range of
/// the vector requantisation ([`fits_simd_requant`]).
pub(crate) fn depthwise3x3(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> bool {
    let Some(avx2) = Avx2::get() else {
        return false;
    };
    if !fits_simd_requant(9 * 255 * 127, b, q.requant) {
        return false;
    }
    let (lo, _) = clamp_range(q.output_zero_point, q.relu);
    let a = Dw {
        x,
        h: xs.h,
        w: xs.w,
        c: xs.c,
        stride,
        wt: w,
        bias: b,
        requant: q.requant,
        zp: q.input_zero_point,
        zo: q.output_zero_point,
        lo,
    };
    run(&a, out, avx2);
    true
}

/// One depthwise call (operands checked by the caller).
struct Dw<'a> {
    /// Input `h × w × c`.
    x: &'a [i8],
    /// Input height, width, channels.
    h: usize,
    /// Input width.
    w: usize,
    /// Channels.
    c: usize,
    /// 1 or 2.
    stride: usize,
    /// `[3][3][c]` weights.
    wt: &'a [i8],
    /// Per-channel bias.
    bias: &'a [i32],
    /// Per-channel requantisers.
    requant: &'a [Requant],
    /// Input zero point.
    zp: i32,
    /// Output zero point.
    zo: i32,
    /// Lower clamp.
    lo: i32,
}

/// The constants of one 8-channel group of the depthwise kernel.
#[derive(Clone, Copy)]
struct DwGroup {
    /// The 9 taps' weights, `i32`.
    w: [__m256i; 9],
    /// Taps `(2i, 2i + 1)`'s weights as `i16` pairs per channel, for `vpmaddwd`.
    wp: [__m256i; 4],
    /// `bias − zp·Σw`: the start of an interior pixel's sum over raw inputs.
    c_int: __m256i,
    bias: __m256i,
    rq: Rq8,
    /// Real channels (8, or fewer in the last group).
    nb: usize,
}

/// Groups whose constants the depthwise kernel keeps at once (21 KiB of stack): 256 channels,
/// more than any layer of the network has, so one pass over the pixels.
const DW_GROUPS: usize = 32;

/// Depthwise 3×3, pad 1, AVX2: per output pixel and 8-channel group, interior pixels sum the
/// raw inputs of all 9 taps on top of `bias − zp·Σw`; border pixels sum `(x − zp)·w` over
/// their valid taps from `bias`. Groups of four full groups are packed and stored as 32 bytes.
/// `out` is `oh × ow × c`.
fn run(a: &Dw<'_>, out: &mut [i8], _avx2: Avx2) {
    let oh = (a.h - 1) / a.stride + 1;
    let ow = (a.w - 1) / a.stride + 1;
    assert!(
        a.x.len() >= a.h * a.w * a.c
            && a.wt.len() == 9 * a.c
            && a.bias.len() == a.c
            && a.requant.len() == a.c
            && out.len() >= oh * ow * a.c,
        "depthwise operands checked by the caller"
    );
    // SAFETY: AVX2 detected at run time (the `Avx2` token); ranges asserted above
    unsafe { dw_avx2(a, out, oh, ow) }
}

/// # Safety
/// Ranges as asserted by [`run`].
#[target_feature(enable = "avx2")]
unsafe fn dw_avx2(a: &Dw<'_>, out: &mut [i8], oh: usize, ow: usize) {
    let c = a.c;
    let s = a.stride;
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(a.lo);
    let zpv = _mm256_set1_epi32(a.zp);
    let groups = c.div_ceil(8);
    let empty = DwGroup {
        w: [_mm256_setzero_si256(); 9],
        wp: [_mm256_setzero_si256(); 4],
        c_int: _mm256_setzero_si256(),
        bias: _mm256_setzero_si256(),
        rq: Rq8::splat(Requant { multiplier: 0, shift: 0 }),
        nb: 0,
    };
    let mut g = [empty; DW_GROUPS];
    let x = a.x.as_ptr();
    let x_len = a.h * a.w * c;
    let o = out.as_mut_ptr();
    let out_len = oh * ow * c;
    let mut g0 = 0;
    while g0 < groups {
        let ng = (groups - g0).min(DW_GROUPS);
        // a short last group may store 8 bytes (spilling into the next pixel, written later)
        // only when all groups are done in this one pass
        let single_pass = g0 == 0 && ng == groups;
        for (j, gr) in g.iter_mut().enumerate().take(ng) {
            let c0 = (g0 + j) * 8;
            let nb = (c - c0).min(8);
            let mut sum = _mm256_setzero_si256();
            for (t, wv) in gr.w.iter_mut().enumerate() {
                // SAFETY: tap t's channels c0..c0+nb exist
                *wv = unsafe { load_n(a.wt.as_ptr().add(t * c + c0), nb) };
                sum = _mm256_add_epi32(sum, *wv);
            }
            for (i, wp) in gr.wp.iter_mut().enumerate() {
                let mut l = [0i16; 16];
                for ch in 0..nb {
                    l[2 * ch] = a.wt[2 * i * c + c0 + ch] as i16;
                    l[2 * ch + 1] = a.wt[(2 * i + 1) * c + c0 + ch] as i16;
                }
                *wp = _mm256_setr_epi16(
                    l[0], l[1], l[2], l[3], l[4], l[5], l[6], l[7], l[8], l[9], l[10], l[11],
                    l[12], l[13], l[14], l[15],
                );
            }
            gr.bias = from_slice(&a.bias[c0..c0 + nb]);
            gr.c_int = _mm256_sub_epi32(gr.bias, _mm256_mullo_epi32(sum, zpv));
            gr.rq = Rq8::new(&a.requant[c0..c0 + nb]);
            gr.nb = nb;
        }
        for oy in 0..oh {
            let iy = (oy * s) as isize - 1;
            let (ky0, ky1) = (usize::from(iy < 0), 3.min((a.h as isize - iy) as usize));
            for ox in 0..ow {
                let ix = (ox * s) as isize - 1;
                let (kx0, kx1) = (usize::from(ix < 0), 3.min((a.w as isize - ix) as usize));
                let inside = ky0 == 0 && ky1 == 3 && kx0 == 0 && kx1 == 3;
                // the pixel's first tap (may be virtual: outside taps are never read)
                let base = ((iy * a.w as isize + ix) * c as isize + (g0 * 8) as isize) as usize;
                let obase = (oy * ow + ox) * c + g0 * 8;
                // the last tap's end: 8-byte loads of a short group stay inside the input
                let last = base.wrapping_add((2 * a.w + 2) * c + 8);
                // one group's accumulator (lanes past the group's channels meet zero weights)
                let group = |j: usize| -> __m256i {
                    let gr = &g[j];
                    let p0 = base.wrapping_add(j * 8);
                    if inside && (gr.nb == 8 || last + j * 8 <= x_len) {
                        // SAFETY: an interior pixel's taps are inside the input
                        unsafe { dw_taps9(x.add(p0), a.w * c, c, gr) }
                    } else {
                        let mut acc = gr.bias;
                        for ky in ky0..ky1 {
                            for kx in kx0..kx1 {
                                let p = p0.wrapping_add(ky * a.w * c + kx * c);
                                // SAFETY: a valid tap
                                let v = if p + 8 <= x_len {
                                    unsafe { load8(x.add(p)) }
                                } else {
                                    unsafe { load_n(x.add(p), gr.nb) }
                                };
                                let d = _mm256_sub_epi32(v, zpv);
                                acc =
                                    _mm256_add_epi32(acc, _mm256_mullo_epi32(d, gr.w[ky * 3 + kx]));
                            }
                        }
                        acc
                    }
                };
                let mut j = 0;
                while j + 4 <= ng && g[j + 3].nb == 8 {
                    let v = pack32(
                        finish8(group(j), &g[j].rq, zo, lo),
                        finish8(group(j + 1), &g[j + 1].rq, zo, lo),
                        finish8(group(j + 2), &g[j + 2].rq, zo, lo),
                        finish8(group(j + 3), &g[j + 3].rq, zo, lo),
                    );
                    // SAFETY: 32 bytes of this pixel's groups j..j+4
                    unsafe { _mm256_storeu_si256(o.add(obase + j * 8) as *mut __m256i, v) };
                    j += 4;
                }
                while j < ng {
                    let at = obase + j * 8;
                    let nb = g[j].nb;
                    let m = if nb == 8 || (single_pass && at + 8 <= out_len) { 8 } else { nb };
                    // SAFETY: m bytes inside `out`
                    unsafe { store8(o.add(at), finish8(group(j), &g[j].rq, zo, lo), m) };
                    j += 1;
                }
            }
        }
        g0 += ng;
    }
}

/// `c_int + Σ x·w` over the 9 taps of an interior pixel (raw inputs, the zero point being in
/// `c_int`): taps `(2i, 2i + 1)` interleaved byte by byte and sign-extended to `i16` pairs,
/// one `vpmaddwd` per pair (`|x·w| ≤ 128·127`, a pair's sum fits its `i32` lane), tap 8 alone.
///
/// # Safety
/// 8 readable bytes at `p + ky·row + kx·c` for `ky, kx < 3`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn dw_taps9(p: *const i8, row: usize, c: usize, g: &DwGroup) -> __m256i {
    // SAFETY: by the caller
    let tap =
        |t: usize| unsafe { _mm_loadl_epi64(p.add(t / 3 * row + t % 3 * c) as *const __m128i) };
    let (mut a0, mut a1) = (g.c_int, _mm256_setzero_si256());
    for i in 0..4 {
        let v = _mm256_cvtepi8_epi16(_mm_unpacklo_epi8(tap(2 * i), tap(2 * i + 1)));
        let m = _mm256_madd_epi16(v, g.wp[i]);
        if i % 2 == 0 {
            a0 = _mm256_add_epi32(a0, m);
        } else {
            a1 = _mm256_add_epi32(a1, m);
        }
    }
    let m8 = _mm256_mullo_epi32(_mm256_cvtepi8_epi32(tap(8)), g.w[8]);
    _mm256_add_epi32(_mm256_add_epi32(a0, m8), a1)
}
