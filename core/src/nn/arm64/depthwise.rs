//! # arm64 depthwise: the depthwise 3×3 `Conv` in NEON
//!
//! ONNX `Conv` with `group = C`, a 3×3 kernel, pad 1, stride 1 or 2, weights `[3][3][C]` — the
//! integers of [`crate::nn::conv::depthwise3x3_reference`].
//!
//! 8 channels per vector. Per output row and group of 8 channels the 9 taps' weights are
//! widened once and the requantisers loaded into registers; then per pixel each valid tap adds
//! `(x − zp)·w` (`ssubl`, two `smlal`) to sums that start at the biases, and the 8 sums are
//! requantised in registers ([`super::lanes::Rq8Regs`]). Interior pixels run the 9 taps
//! unrolled, their loads unchecked after one range check of the window; border pixels (and a
//! short last group) take only their valid taps through checked loads, a short group's missing
//! lanes reading as the zero point (weight 0), and store only their channels.
//!
//! **Stack:** the lane-form requantisers of up to 256 channels (4 KiB; wider layers make the
//! others per row).

use super::mem::{ld1_s8, ld1q_s32};
use core::arch::aarch64::*;

use super::lanes::{block8, load8, store8, Rq8, Rq8Table, TABLE};
use crate::nn::conv::ConvQuant;
use crate::nn::portable::conv::tap_range;
use crate::nn::quant::{clamp_range, fits_simd_requant};
use crate::nn::Shape;

/// The depthwise 3×3 conv on operands [`crate::nn::conv::depthwise3x3_fast`] has checked (`os`
/// the output shape); `false` (nothing written) when the vector requantisation does not hold.
#[allow(clippy::too_many_arguments)]
pub(crate) fn depthwise3x3(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) -> bool {
    if !fits_simd_requant(9 * 255 * 128, b, q.requant) {
        return false;
    }
    // SAFETY: this module is compiled only where `neon` is a target feature of the build.
    unsafe { run(x, xs, stride, w, b, q, out, os) };
    true
}

/// [`depthwise3x3`] after its check.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "neon")]
fn run(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) {
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let c = xs.c;
    let zp = q.input_zero_point as i8;
    let zp8 = vdup_n_s8(zp);
    let x = &x[..xs.len()];
    let w = &w[..9 * c];
    let row = xs.w * c;
    let mut table = [Rq8::ZERO; TABLE];
    let rqs = Rq8Table::new(&mut table, q.requant);
    for (oy, orow) in out[..os.len()].chunks_exact_mut(os.w * c).enumerate() {
        let (ky0, ky1) = tap_range(oy, stride, 1, 3, xs.h);
        for g in 0..c.div_ceil(8) {
            let c0 = 8 * g;
            let nb = (c - c0).min(8);
            let rq = rqs.block(g).regs(q.output_zero_point, lo, hi);
            let bias = block8(b, c0);
            // SAFETY: 8 `i32`s.
            let b0 = unsafe { [ld1q_s32(bias.as_ptr()), ld1q_s32(bias.as_ptr().add(4))] };
            let mut wv = [vdupq_n_s16(0); 9];
            for (t, v) in wv.iter_mut().enumerate() {
                *v = vmovl_s8(load8(&w[t * c + c0..t * c + c0 + nb], 0));
            }
            // `(x − zp)·wt` of the 8 bytes at `x[xo..]` added to `a`
            macro_rules! mac {
                ($a:expr, $xv:expr, $wt:expr) => {{
                    let xv = vsubl_s8($xv, zp8);
                    $a[0] = vmlal_s16($a[0], vget_low_s16(xv), vget_low_s16($wt));
                    $a[1] = vmlal_high_s16($a[1], xv, $wt);
                }};
            }
            for (ox, opix) in orow.chunks_exact_mut(c).enumerate() {
                let (kx0, kx1) = tap_range(ox, stride, 1, 3, xs.w);
                let mut a = b0;
                // the window's top-left byte of this group, when the window is inside the input
                let base = (ky1 - ky0 == 3 && kx1 - kx0 == 3)
                    .then(|| ((oy * stride - 1) * xs.w + ox * stride - 1) * c + c0);
                match base {
                    // interior, full group: 9 unrolled taps (weights in registers) from one
                    // range check
                    Some(base) if nb == 8 && base + 2 * row + 2 * c + 8 <= x.len() => {
                        let p = x[base..].as_ptr();
                        #[allow(clippy::needless_range_loop)]
                        for t in 0..9 {
                            // SAFETY: `t / 3 · row + t % 3 · c + 8 ≤ 2·row + 2·c + 8`, inside
                            // `x` by the check above.
                            let xv = unsafe { ld1_s8(p.add(t / 3 * row + t % 3 * c)) };
                            mac!(a, xv, wv[t]);
                        }
                    }
                    _ => {
                        for ky in ky0..ky1 {
                            let iy = oy * stride + ky - 1;
                            for kx in kx0..kx1 {
                                let xo = (iy * xs.w + ox * stride + kx - 1) * c + c0;
                                let wo = (ky * 3 + kx) * c + c0;
                                let wt = vmovl_s8(load8(&w[wo..wo + nb], 0));
                                mac!(a, load8(&x[xo..xo + nb], zp), wt);
                            }
                        }
                    }
                }
                store8(&mut opix[c0..c0 + nb], rq.requant(a));
            }
        }
    }
}
