//! # x86 conv1: the 3×3 `Conv` of a one-channel map (the network's first layer), AVX2
//!
//! ONNX `Conv`, `group = 1`, one input channel, a 3×3 kernel, any stride and padding, weights
//! `[c_out][3][3]`: `out[oy][ox][c] = clamp(zo + requant[c](bias[c] + Σ_taps (x − zp)·w[c][t]))`
//! — the integers of [`crate::nn::conv::conv2d_reference`] for that geometry.
//!
//! The 9 taps as five `i16` pairs broadcast into `vpmaddwd` per 8 output channels; with
//! stride 2, eight pixels' pairs come from 16-byte row loads.
//!
//! **ISA:** AVX2 (detected at run time: [`super::Avx2`]). **Stack:** 3 KiB of per-group constants
//! (8 groups of 8 output channels; more channels take several passes).

use core::arch::x86_64::*;

use super::lanes::{finish8, from_slice, pack32, store8, Rq8};
use super::Avx2;
use crate::nn::conv::{Conv2dParams, ConvQuant};
use crate::nn::quant::{clamp_range, fits_simd_requant};
use crate::nn::{Requant, Shape};

/// The general conv on operands [`crate::nn::conv::conv2d_fast`] has checked (`os` the output
/// shape), when it is a 3×3 conv of a one-channel map. `false`, with nothing written, on a CPU
/// without AVX2, for any other geometry or when the accumulators could leave the range of the
/// vector requantisation ([`fits_simd_requant`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv3x3_c1(
    x: &[i8],
    xs: Shape,
    p: &Conv2dParams,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) -> bool {
    let Some(avx2) = Avx2::get() else {
        return false;
    };
    if xs.c != 1 || p.kernel != (3, 3) || !fits_simd_requant(9 * 255 * 127, b, q.requant) {
        return false;
    }
    let (lo, _) = clamp_range(q.output_zero_point, q.relu);
    let a = Conv1 {
        x,
        h: xs.h,
        w: xs.w,
        oh: os.h,
        ow: os.w,
        stride: p.stride,
        pad: (p.pads[0], p.pads[1]),
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

/// A 3×3 conv of a one-channel input (operands checked by the caller).
struct Conv1<'a> {
    /// Input `h × w`.
    x: &'a [i8],
    /// Input height.
    h: usize,
    /// Input width.
    w: usize,
    /// Output height.
    oh: usize,
    /// Output width.
    ow: usize,
    /// Vertical and horizontal stride.
    stride: (usize, usize),
    /// Top and left padding.
    pad: (usize, usize),
    /// `[c_out][9]` weights.
    wt: &'a [i8],
    /// Per-channel bias (`c_out`).
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

/// 8-channel groups of the one-channel conv kept at once.
const C1_GROUPS: usize = 8;
/// The one-channel conv's taps (`ky·3 + kx`) in `i16` pairs: the three rows' `(kx 0, kx 1)`,
/// then `kx = 2` of rows 0 and 1, then row 2's alone — pairs a 16-byte row load gives directly
/// for 8 stride-2 pixels.
const TAP_PAIRS: [(usize, usize); 5] = [(0, 1), (3, 4), (6, 7), (2, 5), (8, 9)];

/// 3×3 conv of a one-channel map, AVX2: per output pixel the 9 taps `x − zp` (0 outside) as
/// five `i16` pairs ([`TAP_PAIRS`]), each broadcast and multiplied into every 8-channel group
/// with `vpmaddwd` against the matching weight pairs. With stride 2, runs of 8 interior pixels
/// get their pairs from six 16-byte row loads (bytes `2i, 2i + 1` are pixel `i`'s `kx = 0, 1`).
fn run(a: &Conv1<'_>, out: &mut [i8], _avx2: Avx2) {
    let n = a.bias.len();
    assert!(
        a.x.len() >= a.h * a.w
            && a.wt.len() == 9 * n
            && a.requant.len() == n
            && out.len() >= a.oh * a.ow * n,
        "conv operands checked by the caller"
    );
    // SAFETY: AVX2 detected at run time (the `Avx2` token); ranges asserted above
    unsafe { conv1_avx2(a, out) }
}

/// # Safety
/// Ranges as asserted by [`run`].
#[target_feature(enable = "avx2")]
unsafe fn conv1_avx2(a: &Conv1<'_>, out: &mut [i8]) {
    let n = a.bias.len();
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(a.lo);
    let groups = n.div_ceil(8);
    let mut wp = [[_mm256_setzero_si256(); 5]; C1_GROUPS];
    let mut bias = [_mm256_setzero_si256(); C1_GROUPS];
    let mut rq = [Rq8::splat(Requant { multiplier: 0, shift: 0 }); C1_GROUPS];
    let mut nbs = [0usize; C1_GROUPS];
    let (sy, sx) = a.stride;
    let (pt, pl) = a.pad;
    let mut g0 = 0;
    while g0 < groups {
        let ng = (groups - g0).min(C1_GROUPS);
        for j in 0..ng {
            let c0 = (g0 + j) * 8;
            let nb = (n - c0).min(8);
            for (&(ta, tb), v) in TAP_PAIRS.iter().zip(wp[j].iter_mut()) {
                let mut l = [0i16; 16];
                for ch in 0..nb {
                    let w = &a.wt[(c0 + ch) * 9..(c0 + ch) * 9 + 9];
                    l[2 * ch] = w[ta] as i16;
                    l[2 * ch + 1] = if tb < 9 { w[tb] as i16 } else { 0 };
                }
                *v = _mm256_setr_epi16(
                    l[0], l[1], l[2], l[3], l[4], l[5], l[6], l[7], l[8], l[9], l[10], l[11],
                    l[12], l[13], l[14], l[15],
                );
            }
            bias[j] = from_slice(&a.bias[c0..c0 + nb]);
            rq[j] = Rq8::new(&a.requant[c0..c0 + nb]);
            nbs[j] = nb;
        }
        let op = out.as_mut_ptr();
        // one output pixel from its five tap pairs (broadcast), every group of this pass
        let emit = |pairs: &[__m256i; 5], o: usize| {
            let group = |j: usize| {
                let mut acc = bias[j];
                for (p, w) in pairs.iter().zip(&wp[j]) {
                    acc = _mm256_add_epi32(acc, _mm256_madd_epi16(*p, *w));
                }
                finish8(acc, &rq[j], zo, lo)
            };
            let mut j = 0;
            while j + 4 <= ng && nbs[j + 3] == 8 {
                let v = pack32(group(j), group(j + 1), group(j + 2), group(j + 3));
                // SAFETY: 32 bytes of this pixel's groups j..j+4 inside `out`
                unsafe { _mm256_storeu_si256(op.add(o + j * 8) as *mut __m256i, v) };
                j += 4;
            }
            while j < ng {
                // SAFETY: nb bytes of this pixel's group inside `out`
                unsafe { store8(op.add(o + j * 8), group(j), nbs[j]) };
                j += 1;
            }
        };
        let zp16 = _mm256_set1_epi16(a.zp as i16);
        let x = a.x.as_ptr();
        for oy in 0..a.oh {
            let iy0 = (oy * sy) as isize - pt as isize;
            let rows_inside = iy0 >= 0 && iy0 + 2 < a.h as isize;
            let mut ox = 0;
            while ox < a.ow {
                let ix0 = (ox * sx) as isize - pl as isize;
                let o = (oy * a.ow + ox) * n + g0 * 8;
                // stride 2, 8 interior pixels: the tap pairs of all 8 from 16-byte row loads
                // (pixel i's taps kx = 0, 1 are bytes 2i, 2i + 1 from ix0: one i16 pair each)
                if sx == 2 && rows_inside && ix0 >= 0 && ox + 8 <= a.ow && ix0 as usize + 18 <= a.w
                {
                    let r = iy0 as usize * a.w + ix0 as usize;
                    // SAFETY: rows iy0..iy0+3, bytes ix0..ix0+18 are inside the input
                    let row = |ky: usize, off: usize| unsafe {
                        _mm256_sub_epi16(
                            _mm256_cvtepi8_epi16(_mm_loadu_si128(
                                x.add(r + ky * a.w + off) as *const __m128i
                            )),
                            zp16,
                        )
                    };
                    let lo16 = _mm256_set1_epi32(0xffff);
                    let p3 = _mm256_blend_epi16::<0b1010_1010>(
                        row(0, 2),
                        _mm256_slli_epi32::<16>(row(1, 2)),
                    );
                    let p4 = _mm256_and_si256(row(2, 2), lo16);
                    let mut tab = [[0i32; 8]; 5];
                    for (t, v) in tab.iter_mut().zip([row(0, 0), row(1, 0), row(2, 0), p3, p4]) {
                        // SAFETY: 32 writable bytes
                        unsafe { _mm256_storeu_si256(t.as_mut_ptr() as *mut __m256i, v) };
                    }
                    #[allow(clippy::needless_range_loop)]
                    for i in 0..8 {
                        let pairs = [
                            _mm256_set1_epi32(tab[0][i]),
                            _mm256_set1_epi32(tab[1][i]),
                            _mm256_set1_epi32(tab[2][i]),
                            _mm256_set1_epi32(tab[3][i]),
                            _mm256_set1_epi32(tab[4][i]),
                        ];
                        emit(&pairs, o + i * n);
                    }
                    ox += 8;
                    continue;
                }
                // one pixel, taps gathered one by one (0 outside the input)
                let mut t = [0i32; 10];
                for ky in 0..3 {
                    let yy = iy0 + ky as isize;
                    for kx in 0..3 {
                        let xx = ix0 + kx as isize;
                        if yy >= 0 && xx >= 0 && yy < a.h as isize && xx < a.w as isize {
                            t[ky * 3 + kx] = a.x[yy as usize * a.w + xx as usize] as i32 - a.zp;
                        }
                    }
                }
                // pairs (0,1) (3,4) (6,7) (2,5) (8,-): the same sums as the 16-byte path
                let pair = |a: i32, b: i32| _mm256_set1_epi32((a & 0xffff) | (b << 16));
                let pairs = [
                    pair(t[0], t[1]),
                    pair(t[3], t[4]),
                    pair(t[6], t[7]),
                    pair(t[2], t[5]),
                    pair(t[8], 0),
                ];
                emit(&pairs, o);
                ox += 1;
            }
        }
        g0 += ng;
    }
}
