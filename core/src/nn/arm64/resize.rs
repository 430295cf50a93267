//! # arm64 resize: bilinear `Resize` (`half_pixel`) in NEON
//!
//! ONNX `Resize`, `mode = linear`, `coordinate_transformation_mode = half_pixel`, static sizes:
//! the fixed-point blend of [`crate::nn::resize`], the integers of
//! [`crate::nn::resize::resize_bilinear_reference`]:
//! `(2^11 − wy)·((2^11 − wx)·a + wx·b) + wy·((2^11 − wx)·c + wx·d)` over `x − zp`, exact in
//! `i32`, then one requantisation.
//!
//! 8 channels per vector: the four source pixels' bytes minus the zero point (`ssubl`), the
//! horizontal blends as `smull`/`smlal` by the `i16` weights, the vertical one as `i32`
//! `mul`/`mla`, the requantisation in registers. A short last group (11 classes: 8 + 3) loads
//! and stores 8 bytes where the row has them — the extra lanes are the next pixel's, which is
//! written after this one — and only its own bytes at the row's end. The x taps are computed
//! once per column for a band of 64 columns (they are the same on every row; each costs two
//! divisions).
//!
//! **Stack:** the x taps of 64 columns (1.5 KiB).

use super::mem::{ld1_s8, st1_s8};
use core::arch::aarch64::*;

use super::lanes::{load8, store8, Rq8};
use crate::nn::quant::Lane1;
use crate::nn::resize::{half_pixel_taps, ResizeQuant, RESIZE_FRAC_BITS};
use crate::nn::Shape;

/// Output columns whose x taps are made at once.
const BAND: usize = 64;

/// The resize on operands [`crate::nn::resize::resize_bilinear_fast`] has checked (`os` the
/// output shape); `false` (nothing written) when the vector requantisation does not hold.
pub(crate) fn resize_bilinear(
    x: &[i8],
    xs: Shape,
    q: &ResizeQuant,
    out: &mut [i8],
    os: Shape,
) -> bool {
    // a blend is at most 2^22 · 255 in magnitude
    if !Lane1::fits(q.requant, 255 << (2 * RESIZE_FRAC_BITS)) {
        return false;
    }
    // SAFETY: this module is compiled only where `neon` is a target feature of the build.
    unsafe { run(x, xs, q, out, os) };
    true
}

/// [`resize_bilinear`] after its check.
#[target_feature(enable = "neon")]
fn run(x: &[i8], xs: Shape, q: &ResizeQuant, out: &mut [i8], os: Shape) {
    const ONE: i32 = 1 << RESIZE_FRAC_BITS;
    let c = xs.c;
    let zp = q.input_zero_point as i8;
    let zp8 = vdup_n_s8(zp);
    let rq = Rq8::new(&[q.requant; 8]).regs(q.output_zero_point, -128, 127);
    let x = &x[..xs.len()];
    let out = &mut out[..os.len()];
    let mut taps = [(0usize, 0usize, 0i16); BAND];
    let mut cx0 = 0;
    while cx0 < os.w {
        let nx = BAND.min(os.w - cx0);
        for (i, t) in taps[..nx].iter_mut().enumerate() {
            let (x0, x1, wx) = half_pixel_taps(cx0 + i, xs.w, os.w);
            // wx ≤ 2^11: an `i16`
            *t = (x0 * c, x1 * c, wx as i16);
        }
        for (oy, orow) in out.chunks_exact_mut(os.w * c).enumerate() {
            let (y0, y1, wy) = half_pixel_taps(oy, xs.h, os.h);
            let (r0, r1) =
                (&x[y0 * xs.w * c..(y0 + 1) * xs.w * c], &x[y1 * xs.w * c..(y1 + 1) * xs.w * c]);
            let (wy0, wy1) = (ONE - wy, wy);
            let row = xs.w * c;
            for (i, &(p0, p1, wx)) in taps[..nx].iter().enumerate() {
                let ox = cx0 + i;
                let (wx0, wx1) = (ONE as i16 - wx, wx);
                let mut c0 = 0;
                while c0 < c {
                    let nb = (c - c0).min(8);
                    // 8 bytes from each source pixel: beyond a short group they belong to the
                    // next pixel (ignored lanes) while the row has them, else the zero point
                    let [a, b, cc, d] = if p1 + c0 + 8 <= row {
                        // SAFETY: `p0 ≤ p1` and `p1 + c0 + 8 ≤ row`: inside both rows.
                        unsafe {
                            [
                                ld1_s8(r0.as_ptr().add(p0 + c0)),
                                ld1_s8(r0.as_ptr().add(p1 + c0)),
                                ld1_s8(r1.as_ptr().add(p0 + c0)),
                                ld1_s8(r1.as_ptr().add(p1 + c0)),
                            ]
                        }
                    } else {
                        [
                            load8(&r0[p0 + c0..p0 + c0 + nb], zp),
                            load8(&r0[p1 + c0..p1 + c0 + nb], zp),
                            load8(&r1[p0 + c0..p0 + c0 + nb], zp),
                            load8(&r1[p1 + c0..p1 + c0 + nb], zp),
                        ]
                    };
                    let [a, b, cc, d] = [a, b, cc, d].map(|v| vsubl_s8(v, zp8));
                    // the horizontal blends of both rows, low and high 4 lanes, then the
                    // vertical one
                    let lo = |u: int16x8_t, v: int16x8_t| {
                        vmlal_n_s16(vmull_n_s16(vget_low_s16(u), wx0), vget_low_s16(v), wx1)
                    };
                    let hi = |u: int16x8_t, v: int16x8_t| {
                        vmlal_high_n_s16(vmull_high_n_s16(u, wx0), v, wx1)
                    };
                    let s0 = vmlaq_n_s32(vmulq_n_s32(lo(a, b), wy0), lo(cc, d), wy1);
                    let s1 = vmlaq_n_s32(vmulq_n_s32(hi(a, b), wy0), hi(cc, d), wy1);
                    let v = rq.requant([s0, s1]);
                    let o = (ox * c) + c0;
                    match orow.get_mut(o..o + 8) {
                        // a short group's extra bytes land on later pixels of this row, each
                        // written after this one (bands and pixels run left to right)
                        // SAFETY: 8 bytes of `orow`.
                        Some(dst) => unsafe { st1_s8(dst.as_mut_ptr(), v) },
                        None => store8(&mut orow[o..o + nb], v),
                    }
                    c0 += nb;
                }
            }
        }
        cx0 += nx;
    }
}
