//! # arm64 eltwise: the quantised `Add` in NEON
//!
//! ONNX `Add` of two same-shaped int8 tensors with TFLite's arithmetic (`nn::eltwise`): each
//! input `requant_k((x − zp_k) << 20)`, their sum requantised to the output — the integers of
//! [`crate::nn::eltwise::add_reference`]. 8 elements at a time: `ssubl`, `sshll`/`shl` by 20, the three
//! requantisations in registers ([`super::lanes::Rq8Regs`], one requantiser broadcast to all
//! lanes); the last `n mod 8` elements through a padded vector.
//!
//! **Stack:** none beyond registers (three requantisers' constants, 8 bytes of tail).

use super::mem::{ld1_s8, st1_s8};
use core::arch::aarch64::*;

use super::lanes::{load8, store8, Rq8};
use crate::nn::eltwise::AddQuant;
use crate::nn::quant::{clamp_range, Lane1, ADD_LEFT_SHIFT};
use crate::nn::Shape;

/// `Add` on operands [`crate::nn::eltwise::add_fast`] has checked; `false` (nothing written)
/// when a requantisation could leave the vector form's range (then the portable kernel runs).
pub(crate) fn add(a: &[i8], b: &[i8], shape: Shape, q: &AddQuant, out: &mut [i8]) -> bool {
    // each input's rescale is monotone in its byte: its extremes are at −128 and 127
    let input = |zp: i32| (((-128 - zp).abs().max((127 - zp).abs())) as i64) << ADD_LEFT_SHIFT;
    let peak = |zp: i32, r: crate::nn::Requant| {
        (r.apply((-128 - zp) << ADD_LEFT_SHIFT) as i64)
            .abs()
            .max((r.apply((127 - zp) << ADD_LEFT_SHIFT) as i64).abs())
    };
    if !Lane1::fits(q.requant1, input(q.zero_point1))
        || !Lane1::fits(q.requant2, input(q.zero_point2))
        || !Lane1::fits(q.output, peak(q.zero_point1, q.requant1) + peak(q.zero_point2, q.requant2))
    {
        return false;
    }
    // SAFETY: this module is compiled only where `neon` is a target feature of the build.
    unsafe { run(a, b, shape, q, out) };
    true
}

/// [`add`] after its checks.
#[target_feature(enable = "neon")]
fn run(a: &[i8], b: &[i8], shape: Shape, q: &AddQuant, out: &mut [i8]) {
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let n = shape.len();
    let r1 = Rq8::new(&[q.requant1; 8]).regs(0, i32::MIN, i32::MAX);
    let r2 = Rq8::new(&[q.requant2; 8]).regs(0, i32::MIN, i32::MAX);
    let ro = Rq8::new(&[q.output; 8]).regs(q.output_zero_point, lo, hi);
    let (z1, z2) = (vdup_n_s8(q.zero_point1 as i8), vdup_n_s8(q.zero_point2 as i8));
    // `(x − zp) << 20` of 8 differences (`sshll` shifts by at most 16: 16, then 4 more)
    let shifted = |d: int16x8_t| {
        [
            vshlq_n_s32::<{ ADD_LEFT_SHIFT - 16 }>(vshll_n_s16::<16>(vget_low_s16(d))),
            vshlq_n_s32::<{ ADD_LEFT_SHIFT - 16 }>(vshll_high_n_s16::<16>(d)),
        ]
    };
    // 8 elements: each input's `(x − zp) << 20` rescaled, summed, requantised
    let add8 = |x: int8x8_t, y: int8x8_t| {
        let sx = r1.requant_i32(shifted(vsubl_s8(x, z1)));
        let sy = r2.requant_i32(shifted(vsubl_s8(y, z2)));
        ro.requant([vaddq_s32(sx[0], sy[0]), vaddq_s32(sx[1], sy[1])])
    };
    let (a, b, out) = (&a[..n], &b[..n], &mut out[..n]);
    let mut oc = out.chunks_exact_mut(8);
    let (mut ac, mut bc) = (a.chunks_exact(8), b.chunks_exact(8));
    for ((o, x), y) in (&mut oc).zip(&mut ac).zip(&mut bc) {
        // SAFETY: 8 bytes each.
        let v = unsafe { add8(ld1_s8(x.as_ptr()), ld1_s8(y.as_ptr())) };
        // SAFETY: 8 bytes of `o`.
        unsafe { st1_s8(o.as_mut_ptr(), v) };
    }
    let (ar, br, or) = (ac.remainder(), bc.remainder(), oc.into_remainder());
    if !or.is_empty() {
        store8(or, add8(load8(ar, 0), load8(br, 0)));
    }
}
