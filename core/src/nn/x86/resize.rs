//! # x86 resize: bilinear `Resize` (`half_pixel`), AVX2
//!
//! ONNX `Resize`, `mode = linear`, `coordinate_transformation_mode = half_pixel`, static
//! sizes: the fixed-point blend of [`crate::nn::resize`] (11-bit weights, one requantisation),
//! the integers of [`crate::nn::resize::resize_bilinear_reference`].
//!
//! Separable: each source row blended in `x` once per chunk of output columns, each output row
//! one flat run of `s + wy·d` over the chunk (no lanes lost to 11 channels).
//!
//! **ISA:** AVX2 (detected at run time: [`super::Avx2`]). **Stack:** 16 KiB of staged row chunks
//! and 24 KiB of column taps; outputs wider than [`RESIZE_MAX_OW`] or with more than
//! [`RESIZE_MAX_C`] channels are left to the portable kernel.

use core::arch::x86_64::*;

use super::lanes::{finish8, load8, load_n, pack32, store8, Rq8};
use super::Avx2;
use crate::nn::quant::fits_simd_requant;
use crate::nn::resize::{half_pixel_taps, ResizeQuant, RESIZE_FRAC_BITS};
use crate::nn::{Requant, Shape};

/// The resize on operands [`crate::nn::resize::resize_bilinear_fast`] has checked (`os` the output
/// shape). `false`, with nothing written, on a CPU without AVX2, when the output is wider than
/// [`RESIZE_MAX_OW`], has more than [`RESIZE_MAX_C`] channels, or the requantiser leaves the range
/// of the vector requantisation ([`fits_simd_requant`]).
pub(crate) fn resize_bilinear(
    x: &[i8],
    xs: Shape,
    q: &ResizeQuant,
    out: &mut [i8],
    os: Shape,
) -> bool {
    let Some(avx2) = Avx2::get() else {
        return false;
    };
    if xs.c > RESIZE_MAX_C
        || os.w > RESIZE_MAX_OW
        || !fits_simd_requant(255 << (2 * RESIZE_FRAC_BITS), &[], &[q.requant])
    {
        return false;
    }
    let a = Rs {
        x,
        h: xs.h,
        w: xs.w,
        c: xs.c,
        oh: os.h,
        ow: os.w,
        zp: q.input_zero_point,
        zo: q.output_zero_point,
        requant: q.requant,
    };
    run(&a, out, avx2);
    true
}

/// `i32`s per chunk of an output row in the resize kernel (two stacked chunks: 16 KiB).
const RESIZE_CHUNK: usize = 2048;
/// Widest output of the SIMD resize (its x taps are tabulated once per call, 24 KiB).
pub(crate) const RESIZE_MAX_OW: usize = 2048;
/// Most channels of the SIMD resize (a chunk holds at least one output pixel).
pub(crate) const RESIZE_MAX_C: usize = RESIZE_CHUNK - 16;

/// One resize call (operands checked by the caller; `c ≤ RESIZE_MAX_C`, `ow ≤ RESIZE_MAX_OW`).
struct Rs<'a> {
    /// Input `h × w × c`.
    x: &'a [i8],
    /// Input height.
    h: usize,
    /// Input width.
    w: usize,
    /// Channels.
    c: usize,
    /// Output height.
    oh: usize,
    /// Output width.
    ow: usize,
    /// Input zero point.
    zp: i32,
    /// Output zero point.
    zo: i32,
    /// `s_in / (s_out · 2^22)`.
    requant: Requant,
}

/// Bilinear resize, AVX2, separable and flat. The output row is cut into chunks of whole
/// pixels (≤ 2048 values). Per chunk and pair of source rows `(y0, y1)`, each source row is
/// blended in x once, `h = (a − zp)·2^11 + wx·(b − a)` (= the reference's `(2^11 − wx)·a +
/// wx·b`), staged as `s = h0·2^11` and `d = h1 − h0`; every output row of that pair is then
/// `s + wy·d` (= `(2^11 − wy)·h0 + wy·h1`, the reference's integer) over the chunk as one flat
/// run of values — no lanes wasted on channel counts like 11 — requantised 8 at a time and
/// stored 32 bytes at a time. `|s|, |d·wy| < 2^31`: nothing overflows.
fn run(a: &Rs<'_>, out: &mut [i8], _avx2: Avx2) {
    assert!(
        a.x.len() >= a.h * a.w * a.c
            && a.c <= RESIZE_MAX_C
            && a.ow <= RESIZE_MAX_OW
            && out.len() >= a.oh * a.ow * a.c,
        "resize operands checked by the caller"
    );
    // SAFETY: AVX2 detected at run time (the `Avx2` token); ranges asserted above
    unsafe { resize_avx2(a, out) }
}

/// # Safety
/// Ranges as asserted by [`run`].
#[target_feature(enable = "avx2")]
unsafe fn resize_avx2(a: &Rs<'_>, out: &mut [i8]) {
    let c = a.c;
    let in_row = a.w * c;
    let x_len = a.h * in_row;
    let out_row = a.ow * c;
    let rq = Rq8::splat(a.requant);
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(-128);
    let zpv = _mm256_set1_epi32(a.zp);
    let x = a.x.as_ptr();
    let o = out.as_mut_ptr();
    // (x0·c, x1·c, wx) per output column
    let mut xt = [(0u32, 0u32, 0i32); RESIZE_MAX_OW];
    for (ox, t) in xt.iter_mut().enumerate().take(a.ow) {
        let (x0, x1, wx) = half_pixel_taps(ox, a.w, a.ow);
        *t = ((x0 * c) as u32, (x1 * c) as u32, wx);
    }
    // chunk: + 16 values of slack for the last pixel's vectors
    let mut s = [0i32; RESIZE_CHUNK];
    let mut d = [0i32; RESIZE_CHUNK];
    let px_per_chunk = (RESIZE_CHUNK - 16) / c;
    // the source value `x[r + off .. + 8] − zp` (8-byte loads inside the input, else fewer)
    let src = |off: usize| {
        if off + 8 <= x_len {
            // SAFETY: 8 bytes inside the input
            _mm256_sub_epi32(unsafe { load8(x.add(off)) }, zpv)
        } else {
            // SAFETY: the bytes up to the input's end
            _mm256_sub_epi32(unsafe { load_n(x.add(off), x_len - off) }, zpv)
        }
    };
    let mut p0 = 0;
    while p0 < a.ow {
        let np = (a.ow - p0).min(px_per_chunk);
        let len = np * c;
        let mut pair = (usize::MAX, usize::MAX);
        for oy in 0..a.oh {
            let (y0, y1, wy) = half_pixel_taps(oy, a.h, a.oh);
            if (y0, y1) != pair {
                pair = (y0, y1);
                // x-blend both source rows over the chunk's pixels (lanes past the pixel's
                // channels are overwritten by the next pixel or lie in the slack)
                for (i, &(x0, x1, wx)) in xt[p0..p0 + np].iter().enumerate() {
                    let wxv = _mm256_set1_epi32(wx);
                    let mut ch = 0;
                    while ch < c {
                        let (o0, o1) = (x0 as usize + ch, x1 as usize + ch);
                        let (r0, r1) = (y0 * in_row, y1 * in_row);
                        let (a0, b0) = (src(r0 + o0), src(r0 + o1));
                        let (a1, b1) = (src(r1 + o0), src(r1 + o1));
                        let h0 = _mm256_add_epi32(
                            _mm256_slli_epi32::<11>(a0),
                            _mm256_mullo_epi32(wxv, _mm256_sub_epi32(b0, a0)),
                        );
                        let h1 = _mm256_add_epi32(
                            _mm256_slli_epi32::<11>(a1),
                            _mm256_mullo_epi32(wxv, _mm256_sub_epi32(b1, a1)),
                        );
                        let at = i * c + ch;
                        // SAFETY: at + 8 ≤ len + 8 ≤ RESIZE_CHUNK
                        unsafe {
                            _mm256_storeu_si256(
                                s.as_mut_ptr().add(at) as *mut __m256i,
                                _mm256_slli_epi32::<11>(h0),
                            );
                            _mm256_storeu_si256(
                                d.as_mut_ptr().add(at) as *mut __m256i,
                                _mm256_sub_epi32(h1, h0),
                            );
                        }
                        ch += 8;
                    }
                }
            }
            let wyv = _mm256_set1_epi32(wy);
            // SAFETY: the chunk's values of output row oy
            let dst = unsafe { o.add(oy * out_row + p0 * c) };
            let value = |i: usize| {
                // SAFETY: i + 8 ≤ len + 8 ≤ RESIZE_CHUNK
                let (sv, dv) = unsafe {
                    (
                        _mm256_loadu_si256(s.as_ptr().add(i) as *const __m256i),
                        _mm256_loadu_si256(d.as_ptr().add(i) as *const __m256i),
                    )
                };
                finish8(_mm256_add_epi32(sv, _mm256_mullo_epi32(wyv, dv)), &rq, zo, lo)
            };
            let mut i = 0;
            while i + 32 <= len {
                let v = pack32(value(i), value(i + 8), value(i + 16), value(i + 24));
                // SAFETY: 32 bytes of the chunk
                unsafe { _mm256_storeu_si256(dst.add(i) as *mut __m256i, v) };
                i += 32;
            }
            while i < len {
                // SAFETY: min(8, len − i) bytes of the chunk
                unsafe { store8(dst.add(i), value(i), (len - i).min(8)) };
                i += 8;
            }
        }
        p0 += np;
    }
}
