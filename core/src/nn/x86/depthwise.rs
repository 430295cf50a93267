//! # x86 depthwise: the depthwise 3×3 `Conv`, AVX2
//!
//! ONNX `Conv` with `group = C`, a 3×3 kernel, pad 1, stride 1 or 2, weights `[3][3][C]`:
//! `out[oy][ox][c] = clamp(zo + requant[c](bias[c] + Σ_taps (x − zp)·w[ky][kx][c]))` — the
//! integers of [`crate::nn::conv::depthwise3x3_reference`].
//!
//! 8 channels per vector. Every pixel sums raw bytes from `bias − zp·Σw`, taps interleaved in
//! pairs into `vpmaddwd`; a border pixel's taps outside the input read as the zero point, which
//! makes the same sum exactly `bias + Σ_inside (x − zp)·w`. Each output row is cut into runs
//! (border pixels one by one, the interior in one run with unchecked loads), each pixel's
//! groups stored 32 bytes at a time.
//!
//! **ISA:** AVX2 (detected at run time: [`super::Avx2`]). **Stack:** 14 KiB of per-group constants
//! (32 groups of 8 channels; wider layers take several passes over the pixels) and a 256-byte
//! row of zero points.

use core::arch::x86_64::*;

use super::lanes::{finish8, from_slice, load_n, pack32, store8, Rq8};
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
    /// Tap 8's weights, `i32` (the one tap without a pair).
    w8: __m256i,
    /// Taps `(2i, 2i + 1)`'s weights as `i16` pairs per channel, for `vpmaddwd`.
    wp: [__m256i; 4],
    /// `bias − zp·Σw`: the start of a pixel's sum over raw inputs.
    c_int: __m256i,
    rq: Rq8,
    /// Real channels (8, or fewer in the last group).
    nb: usize,
}

/// Groups whose constants the depthwise kernel keeps at once (14 KiB of stack): 256 channels,
/// more than any layer of the network has, so one pass over the pixels.
const DW_GROUPS: usize = 32;

/// Bytes of zero points a border pixel's outside taps read, one pass's groups' worth.
const ZP_ROW: usize = DW_GROUPS * 8;

/// Depthwise 3×3, pad 1, AVX2: per output pixel and 8-channel group, the raw inputs of all 9
/// taps on top of `bias − zp·Σw`, a border pixel's outside taps reading the zero point
/// ([`dw_span`]). Groups of four full groups are packed and stored as 32 bytes. `out` is
/// `oh × ow × c`.
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
    // a border pixel's taps outside the input, read as the zero point (it fits i8: checked)
    let zp8 = _mm_set1_epi8(a.zp as i8);
    let zp_row = [a.zp as i8; ZP_ROW];
    let groups = c.div_ceil(8);
    let empty = DwGroup {
        w8: _mm256_setzero_si256(),
        wp: [_mm256_setzero_si256(); 4],
        c_int: _mm256_setzero_si256(),
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
            for t in 0..9 {
                // SAFETY: tap t's channels c0..c0+nb exist
                let wv = unsafe { load_n(a.wt.as_ptr().add(t * c + c0), nb) };
                sum = _mm256_add_epi32(sum, wv);
                gr.w8 = wv;
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
            let bias = from_slice(&a.bias[c0..c0 + nb]);
            gr.c_int = _mm256_sub_epi32(bias, _mm256_mullo_epi32(sum, zpv));
            gr.rq = Rq8::new(&a.requant[c0..c0 + nb]);
            gr.nb = nb;
        }
        let last_short = g[ng - 1].nb < 8;
        let row = a.w * c;
        for oy in 0..oh {
            let iy = (oy * s) as isize - 1;
            let (ky0, ky1) = (usize::from(iy < 0), 3.min((a.h as isize - iy) as usize));
            // the taps inside the input, bit ky·3 + kx: the row's and a column's
            let row_mask = (ky0..ky1).fold(0u16, |m, ky| m | 0b111 << (3 * ky));
            let col_mask = |ox: usize| {
                let ix = (ox * s) as isize - 1;
                let (kx0, kx1) = (usize::from(ix < 0), 3.min((a.w as isize - ix) as usize));
                let cols = (kx0..kx1).fold(0u16, |m, kx| m | 1 << kx);
                cols | cols << 3 | cols << 6
            };
            // the offset of pixel ox's first tap (top left; wraps for a border pixel, whose
            // outside taps are never formed into pointers)
            let first_tap = |ox: usize| {
                ((iy * a.w as isize + (ox * s) as isize - 1) * c as isize + (g0 * 8) as isize)
                    as usize
            };
            // the columns whose 3 taps are all inside: ox ≥ 1, ox·s + 1 < w
            let ox_a = 1.min(ow);
            let mut ox_b = if a.w >= 3 { ((a.w - 2) / s + 1).min(ow) } else { 0 }.max(ox_a);
            let full = ky0 == 0 && ky1 == 3;
            if full && last_short {
                // unchecked 8-byte loads of the short group must stay inside the input
                let end = |ox: usize| first_tap(ox) + (2 * a.w + 2) * c + (ng - 1) * 8 + 8;
                while ox_b > ox_a && end(ox_b - 1) > x_len {
                    ox_b -= 1;
                }
            }
            let run = |ox: usize, n: usize, mask: u16, full: bool| {
                let obase = (oy * ow + ox) * c + g0 * 8;
                let sp = Span {
                    x,
                    x_len,
                    p0: first_tap(ox),
                    step: s * c,
                    row,
                    c,
                    mask,
                    // SAFETY: pixel ox's outputs are inside `out`
                    o: unsafe { o.add(obase) },
                    n,
                    // a short last group may store 8 bytes (spilling into the next pixel,
                    // written later) only when all groups are done in this one pass
                    spill_end: if single_pass { out_len - obase } else { 0 },
                };
                // SAFETY: `full` only for interior pixels whose loads stay inside the input
                // (`ox_b` above); the others check theirs
                unsafe {
                    if full {
                        dw_span::<true>(&sp, &g[..ng], zo, lo, zp8, &zp_row)
                    } else {
                        dw_span::<false>(&sp, &g[..ng], zo, lo, zp8, &zp_row)
                    }
                }
            };
            for ox in 0..ox_a {
                run(ox, 1, row_mask & col_mask(ox), false);
            }
            if ox_b > ox_a {
                run(ox_a, ox_b - ox_a, row_mask, full);
            }
            for ox in ox_b..ow {
                run(ox, 1, row_mask & col_mask(ox), false);
            }
        }
        g0 += ng;
    }
}

/// A run of output pixels of one row whose taps lie alike inside or outside the input.
struct Span {
    /// The input.
    x: *const i8,
    /// Its length.
    x_len: usize,
    /// Offset of the first pixel's first tap (top left) at the pass's first channel; wraps
    /// below zero for a pixel on the top or left border.
    p0: usize,
    /// Input bytes between the taps of neighbouring output pixels (`stride · c`).
    step: usize,
    /// Input row bytes.
    row: usize,
    /// Channels (bytes per pixel).
    c: usize,
    /// The taps inside the input, bit `ky·3 + kx`.
    mask: u16,
    /// The first pixel's output, at the pass's first channel.
    o: *mut i8,
    /// Pixels.
    n: usize,
    /// Bytes from `o` a short last group may write 8 at a time up to (0: exactly its own).
    spill_end: usize,
}

impl Span {
    /// Offset of tap `t = ky·3 + kx` from a pixel's first tap.
    #[inline]
    fn tap(&self, t: usize) -> usize {
        t / 3 * self.row + t % 3 * self.c
    }
}

/// The pixels of a [`Span`], each pixel's groups in turn (so a short last group's 8-byte
/// store only spills onto a pixel written after it). `FULL`: all 9 taps inside and read 8
/// bytes at a time unchecked; else the taps outside `mask` read as the zero point and a short
/// last group's loads are checked against the input's end.
///
/// # Safety
/// The taps in `mask` inside the input; with `FULL`, 8 readable bytes at every group's taps;
/// `n` pixels of `c` bytes from `o` writable (`spill_end` bytes where it is larger).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn dw_span<const FULL: bool>(
    sp: &Span,
    g: &[DwGroup],
    zo: __m256i,
    lo: __m256i,
    zp8: __m128i,
    zp_row: &[i8; ZP_ROW],
) {
    let ng = g.len();
    let mut full4 = 0;
    while full4 + 4 <= ng && g[full4 + 3].nb == 8 {
        full4 += 4;
    }
    for px in 0..sp.n {
        let p = sp.p0.wrapping_add(px * sp.step);
        // SAFETY: by the caller
        let q = unsafe { sp.o.add(px * sp.c) };
        // each tap's first group: in the input, or (outside it) the row of zero points
        let mut tp = [zp_row.as_ptr(); 9];
        if !FULL {
            for (t, tp) in tp.iter_mut().enumerate() {
                if sp.mask & (1 << t) != 0 {
                    // SAFETY: a tap inside the input
                    *tp = unsafe { sp.x.add(p.wrapping_add(sp.tap(t))) };
                }
            }
        }
        let ctx = PxCtx { sp, tp: &tp, p, zo, lo, zp8 };
        // SAFETY: by the caller
        let acc = |j: usize| unsafe { group_acc::<FULL>(&ctx, j, &g[j]) };
        let mut j = 0;
        while j < full4 {
            let v = pack32(acc(j), acc(j + 1), acc(j + 2), acc(j + 3));
            // SAFETY: 32 bytes of this pixel's groups j..j+4
            unsafe { _mm256_storeu_si256(q.add(j * 8) as *mut __m256i, v) };
            j += 4;
        }
        while j < ng {
            let at = px * sp.c + j * 8;
            let nb = g[j].nb;
            let m = if nb == 8 || at + 8 <= sp.spill_end { 8 } else { nb };
            // SAFETY: m bytes inside `out`
            unsafe { store8(q.add(j * 8), acc(j), m) };
            j += 1;
        }
    }
}

/// One pixel of a [`Span`] as [`group_acc`] reads it.
struct PxCtx<'a> {
    sp: &'a Span,
    /// Each tap's first group, or the row of zero points (not `FULL`).
    tp: &'a [*const i8; 9],
    /// Offset of the pixel's first tap.
    p: usize,
    zo: __m256i,
    lo: __m256i,
    zp8: __m128i,
}

/// Group `j` of a [`PxCtx`]'s pixel, requantised (`i32` lanes).
///
/// # Safety
/// As [`dw_span`].
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn group_acc<const FULL: bool>(cx: &PxCtx<'_>, j: usize, gr: &DwGroup) -> __m256i {
    let sp = cx.sp;
    let pj = cx.p.wrapping_add(j * 8);
    let v = if FULL {
        // SAFETY: by the caller (FULL)
        taps9(|t| unsafe { _mm_loadl_epi64(sp.x.add(pj + sp.tap(t)) as *const __m128i) }, gr)
    } else if gr.nb == 8 {
        // SAFETY: a tap inside the input and a full group's 8 bytes, or the zero row
        taps9(|t| unsafe { _mm_loadl_epi64(cx.tp[t].add(j * 8) as *const __m128i) }, gr)
    } else {
        // SAFETY: the taps in `mask` are inside the input
        unsafe { dw_taps9_border(sp, pj, gr, cx.zp8) }
    };
    finish8(v, &gr.rq, cx.zo, cx.lo)
}

/// [`taps9`] of a short group at offset `p0` (its pixel's first tap): the taps outside the input
/// (not in the span's mask) read as the zero point, so the sum is exactly
/// `bias + Σ_inside (x − zp)·w`. Taps whose 8 bytes would pass the input's end read the bytes
/// there are; the lanes past the group's channels meet zero weights.
///
/// # Safety
/// Each tap of the mask starts inside the input at `p0 + sp.tap(t)` (the others are never
/// formed into pointers).
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn dw_taps9_border(sp: &Span, p0: usize, g: &DwGroup, zp8: __m128i) -> __m256i {
    let tap = |t: usize| {
        if sp.mask & (1 << t) == 0 {
            return zp8;
        }
        let p = p0.wrapping_add(sp.tap(t));
        if p + 8 <= sp.x_len {
            // SAFETY: 8 bytes inside the input
            unsafe { _mm_loadl_epi64(sp.x.add(p) as *const __m128i) }
        } else {
            let mut b = [0u8; 8];
            for (k, v) in b.iter_mut().enumerate().take(sp.x_len - p) {
                // SAFETY: p + k < x_len
                *v = unsafe { *sp.x.add(p + k) } as u8;
            }
            _mm_set_epi64x(0, i64::from_le_bytes(b))
        }
    };
    taps9(tap, g)
}

/// `c_int + Σ_t x_t·w_t` over the 9 taps `tap(t)` (8 bytes each, `t = ky·3 + kx`): taps
/// `(2i, 2i + 1)` interleaved byte by byte and sign-extended to `i16` pairs, one `vpmaddwd` per
/// pair (`|x·w| ≤ 128·127`, a pair's sum fits its `i32` lane), tap 8 alone.
#[inline]
#[target_feature(enable = "avx2")]
fn taps9(tap: impl Fn(usize) -> __m128i, g: &DwGroup) -> __m256i {
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
    let m8 = _mm256_mullo_epi32(_mm256_cvtepi8_epi32(tap(8)), g.w8);
    _mm256_add_epi32(_mm256_add_epi32(a0, m8), a1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stack the module documentation claims: the per-group constants and the zero row.
    #[test]
    fn stack_is_as_documented() {
        assert_eq!(core::mem::size_of::<[DwGroup; DW_GROUPS]>(), 14 * 1024);
        assert_eq!(ZP_ROW, 256);
    }
}
