//! # arm64 conv1: the 3×3 `Conv` of a one-channel map (the network's first layer) in NEON
//!
//! ONNX `Conv`, `group = 1`, one input channel, a 3×3 kernel, any stride and padding, weights
//! `[c_out][3][3]`: `out[oy][ox][c] = clamp(zo + requant[c](bias[c] + Σ_taps (x − zp)·w[c][t]))`
//! — the integers of [`crate::nn::conv::conv2d_reference`] for that geometry.
//!
//! Per chunk of up to 64 pixels of an output row the 9 taps' `x − zp` of each pixel are staged
//! as one `i16` vector and a lane (a tap outside the map reads 0, which is the reference's
//! skipping it). Then per group of 8 output channels, out of line with the group's weights
//! (widened once per call into a tap-major `i16` table) and requantiser in registers, each
//! pixel's 9 `smlal` pairs by lane add them to sums that start at the biases. Before, the
//! groups ran inside the pixel loop and reloaded their weights and requantiser per pixel
//! (13.5 M guest instructions a frame; the portable kernel's channel loop: 43 M).
//!
//! **Stack:** the widened weights and lane-form requantisers of up to 64 output channels and a
//! chunk's staged taps (1.2 + 1 + 1.1 KiB; more channels: the portable kernel).

use super::mem::{ld1q_s16, ld1q_s32};
use core::arch::aarch64::*;

use super::lanes::{store8, Rq8, Rq8Regs};
use crate::nn::conv::{Conv2dParams, ConvQuant};
use crate::nn::portable::conv::tap_range;
use crate::nn::quant::{clamp_range, fits_simd_requant};
use crate::nn::Shape;

/// Most output channels (8 groups of 8).
const GROUPS: usize = 8;
/// Pixels of a row whose taps are staged at once (1.1 KiB).
const CHUNK: usize = 64;

/// The general conv on operands [`crate::nn::conv::conv2d_fast`] has checked (`os` the output
/// shape), when it is a 3×3 conv of a one-channel map into at most 64 channels; `false`
/// (nothing written) for any other geometry or when the vector requantisation does not hold.
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
    if xs.c != 1
        || p.kernel != (3, 3)
        || p.c_out > 8 * GROUPS
        || !fits_simd_requant(9 * 255 * 128, b, q.requant)
    {
        return false;
    }
    // SAFETY: this module is compiled only where `neon` is a target feature of the build.
    unsafe { run(x, xs, p, w, b, q, out, os) };
    true
}

/// [`conv3x3_c1`] after its checks.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "neon")]
fn run(
    x: &[i8],
    xs: Shape,
    p: &Conv2dParams,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) {
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let co = p.c_out;
    let groups = co.div_ceil(8);
    let zp = q.input_zero_point as i16;
    // wt[t][c] = w[c][t], padding channels 0
    let mut wt = [[0i16; 8 * GROUPS]; 9];
    for (c, wc) in w[..9 * co].chunks_exact(9).enumerate() {
        for (t, &v) in wc.iter().enumerate() {
            wt[t][c] = v as i16;
        }
    }
    let mut rqs = [Rq8::ZERO; GROUPS];
    let mut bias = [0i32; 8 * GROUPS];
    for (r, qq) in rqs.iter_mut().zip(q.requant[..co].chunks(8)) {
        *r = Rq8::new(qq);
    }
    bias[..co].copy_from_slice(&b[..co]);
    let x = &x[..xs.len()];
    // the taps of a chunk of a row's pixels: taps 0-7 as one vector, tap 8 apart
    let mut t8 = [[0i16; 8]; CHUNK];
    let mut t9 = [0i16; CHUNK];
    for (oy, orow) in out[..os.len()].chunks_exact_mut(os.w * co).enumerate() {
        let (ky0, ky1) = tap_range(oy, p.stride.0, p.pads[0], 3, xs.h);
        let mut p0 = 0;
        while p0 < os.w {
            let np = (os.w - p0).min(CHUNK);
            for (i, (v8, v9)) in t8.iter_mut().zip(t9.iter_mut()).take(np).enumerate() {
                let ox = p0 + i;
                let (kx0, kx1) = tap_range(ox, p.stride.1, p.pads[1], 3, xs.w);
                // the 9 taps' x − zp (0 outside the map), tap t = 3·ky + kx
                let mut taps = [0i16; 9];
                if ky1 - ky0 == 3 && kx1 - kx0 == 3 {
                    // interior: three 3-byte row slices, constant indices
                    let base = (oy * p.stride.0 - p.pads[0]) * xs.w + ox * p.stride.1 - p.pads[1];
                    for (ky, tr) in taps.chunks_exact_mut(3).enumerate() {
                        let r = &x[base + ky * xs.w..base + ky * xs.w + 3];
                        tr[0] = r[0] as i16 - zp;
                        tr[1] = r[1] as i16 - zp;
                        tr[2] = r[2] as i16 - zp;
                    }
                } else {
                    for ky in ky0..ky1 {
                        let iy = oy * p.stride.0 + ky - p.pads[0];
                        let ix0 = ox * p.stride.1 + kx0 - p.pads[1];
                        let row = &x[iy * xs.w + ix0..iy * xs.w + ix0 + (kx1 - kx0)];
                        for (t, &v) in taps[3 * ky + kx0..3 * ky + kx1].iter_mut().zip(row) {
                            *t = v as i16 - zp;
                        }
                    }
                }
                v8.copy_from_slice(&taps[..8]);
                *v9 = taps[8];
            }
            let chunk = &mut orow[p0 * co..(p0 + np) * co];
            for (g, r) in rqs.iter().enumerate().take(groups) {
                let c0 = 8 * g;
                // SAFETY: 8 `i32`s of `bias`, 8 `i16`s of each `wt[t]` (c0 + 8 ≤ 64).
                let (b, wv) = unsafe {
                    let b = [ld1q_s32(bias.as_ptr().add(c0)), ld1q_s32(bias.as_ptr().add(c0 + 4))];
                    let wv: [int16x8_t; 9] =
                        core::array::from_fn(|t| ld1q_s16(wt[t].as_ptr().add(c0)));
                    (b, wv)
                };
                let rq = r.regs(q.output_zero_point, lo, hi);
                group_run(&t8[..np], &t9[..np], &wv, b, &rq, chunk, (co, c0));
            }
            p0 += np;
        }
    }
}

/// One group of 8 output channels (from channel `c0` of `co`) over a chunk of pixels (`t8`,
/// `t9`: their taps' `x − zp`): the biases `b` plus 9 `smlal` pairs by lane against the weight
/// vectors `wv`, requantised and stored (the group's channels only). Out of line, so that the
/// weights and the requantiser stay in registers over the chunk.
#[target_feature(enable = "neon")]
#[inline(never)]
fn group_run(
    t8: &[[i16; 8]],
    t9: &[i16],
    wv: &[int16x8_t; 9],
    b: [int32x4_t; 2],
    rq: &Rq8Regs,
    out: &mut [i8],
    (co, c0): (usize, usize),
) {
    let (wv, rq) = (*wv, *rq);
    let nb = (co - c0).min(8);
    for ((v8, &v9), o) in t8.iter().zip(t9).zip(out.chunks_exact_mut(co)) {
        // SAFETY: 8 `i16`s.
        let tv = unsafe { ld1q_s16(v8.as_ptr()) };
        let tl = vdup_n_s16(v9);
        let mut a = b;
        macro_rules! tap {
            ($t:literal) => {
                a[0] = vmlal_laneq_s16::<$t>(a[0], vget_low_s16(wv[$t]), tv);
                a[1] = vmlal_high_laneq_s16::<$t>(a[1], wv[$t], tv);
            };
        }
        tap!(0);
        tap!(1);
        tap!(2);
        tap!(3);
        tap!(4);
        tap!(5);
        tap!(6);
        tap!(7);
        a[0] = vmlal_lane_s16::<0>(a[0], vget_low_s16(wv[8]), tl);
        a[1] = vmlal_high_lane_s16::<0>(a[1], wv[8], tl);
        store8(&mut o[c0..c0 + nb], rq.requant(a));
    }
}
