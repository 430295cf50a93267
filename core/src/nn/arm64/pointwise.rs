//! # arm64 pointwise: the 1×1 `Conv` as an int8 GEMM in NEON
//!
//! The integers of [`crate::nn::conv::pointwise_reference`], over the packed weights of
//! [`crate::nn::conv::pack_pointwise`] (per block of 8 output channels, per group of 4 inputs,
//! 32 bytes: channel-major, 4 inputs each).
//!
//! Per tile of up to 8 pixels the input rows are staged once as `i16` (`x − zp`, zero padded
//! to a multiple of 4; 8 rows of up to 512 inputs, 4 of up to 1024, … 1 of up to 4096). Per
//! block and group, one `ld4` de-interleaves the 32 weight bytes into the 8 channels' weights
//! of each of the 4 inputs, `sxtl` widens them, and each pixel adds `w[·][t] · (x[t] − zp)` for
//! its 4 inputs with 8 `smlal` by lane: 256 multiply-adds in 77 instructions for a full tile
//! (the auto-vectorised portable loop needs about twice as many per multiply-add, widening the
//! weights again for every pixel). The 8 sums start at the biases and are requantised in
//! registers ([`super::lanes::Rq8Regs`]).
//!
//! **Stack:** the 8 KiB stage and the lane-form requantisers of up to 256 output channels
//! ([`super::lanes::Rq8Table`], 4 KiB; wider layers make the others per tile).

use super::mem::{ld1_s16, ld1q_s32};
use core::arch::aarch64::*;

use super::lanes::{block8, store8, Rq8, Rq8Table, TABLE};
use crate::nn::conv::{ConvQuant, PW_BLOCK, PW_GROUP};
use crate::nn::quant::{clamp_range, fits_simd_requant};
use crate::nn::Shape;

/// Most pixels per tile.
pub(super) const TILE: usize = 8;
/// `i16`s of the stage (8 KiB): [`TILE`] rows of up to 512 inputs, fewer rows of wider ones;
/// rows wider than this take the portable kernel.
const STAGE: usize = 4096;

/// The NEON GEMM on operands [`crate::nn::conv::pointwise_fast`] has checked; `false` (nothing
/// written) when a row is wider than [`STAGE`] or the vector requantisation does not hold.
pub(crate) fn pointwise(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> bool {
    let k = xs.c;
    if k > STAGE || !fits_simd_requant(k as i64 * 255 * 128, b, q.requant) {
        return false;
    }
    // SAFETY: this module is compiled only where `neon` is a target feature of the build.
    unsafe { run(x, xs, w, b, q, out) };
    true
}

/// [`pointwise`] after its checks.
#[target_feature(enable = "neon")]
fn run(x: &[i8], xs: Shape, w: &[i8], b: &[i32], q: &ConvQuant<'_>, out: &mut [i8]) {
    let k = xs.c;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let n = b.len();
    let groups = k.div_ceil(PW_GROUP);
    // a staged row: the inputs, zero padded to whole groups
    let kp = groups * PW_GROUP;
    let panel = groups * PW_BLOCK * PW_GROUP;
    let p = xs.h * xs.w;
    let zp = q.input_zero_point as i16;
    let x = &x[..p * k];
    let out = &mut out[..p * n];
    let tp = tile_rows(STAGE / kp);
    let mut st = [0i16; STAGE];
    let mut table = [Rq8::ZERO; TABLE];
    let rqs = Rq8Table::new(&mut table, q.requant);
    for (xt, ot) in x.chunks(tp * k).zip(out.chunks_mut(tp * n)) {
        let np = xt.len() / k;
        for (row, xr) in st.chunks_exact_mut(kp).zip(xt.chunks_exact(k)) {
            for (s, &v) in row[..k].iter_mut().zip(xr) {
                *s = v as i16 - zp;
            }
            // the packed weights of the padding inputs are 0, but keep the products defined
            row[k..].fill(0);
        }
        let st = &st[..tp * kp];
        for (blk, wp) in w.chunks_exact(panel).enumerate() {
            let k0 = blk * PW_BLOCK;
            let nb = (n - k0).min(PW_BLOCK);
            let bias = block8(b, k0);
            // a short last tile takes the next size up within the tile: the extra rows hold
            // an earlier tile's pixels (or zeros), whose sums are not stored
            let acc = match np {
                5.. => tile::<8>(st, kp, wp, &bias),
                3 | 4 => pad(tile::<4>(st, kp, wp, &bias)),
                2 => pad(tile::<2>(st, kp, wp, &bias)),
                _ => pad(tile::<1>(st, kp, wp, &bias)),
            };
            // the requantisers' registers only after the tile, which needs all but a few
            let rq = rqs.block(blk).regs(q.output_zero_point, lo, hi);
            for (i, a) in acc.iter().take(np).enumerate() {
                store8(&mut ot[i * n + k0..i * n + k0 + nb], rq.requant(*a));
            }
        }
    }
}

/// Pixels per tile for a stage that holds `rows` rows: 8, 4, 2 or 1, as many as fit.
pub(super) fn tile_rows(rows: usize) -> usize {
    match rows {
        8.. => 8,
        4..=7 => 4,
        2 | 3 => 2,
        _ => 1,
    }
}

/// A tile's sums widened to [`TILE`] pixels (the missing ones zero, not stored).
#[target_feature(enable = "neon")]
#[inline]
pub(super) fn pad<const P: usize>(a: [[int32x4_t; 2]; P]) -> [[int32x4_t; 2]; TILE] {
    let z = vdupq_n_s32(0);
    core::array::from_fn(|i| if i < P { a[i] } else { [z; 2] })
}

/// The 8 channels' sums (biases included) of the first `P` staged rows (`kp` `i16`s each,
/// `P · kp ≤ st.len()`) over one block's panel (`kp · 8` bytes).
#[target_feature(enable = "neon")]
#[inline]
fn tile<const P: usize>(
    st: &[i16],
    kp: usize,
    wp: &[i8],
    bias: &[i32; PW_BLOCK],
) -> [[int32x4_t; 2]; P] {
    let wp = &wp[..kp * PW_BLOCK];
    let rows: [&[i16]; P] = core::array::from_fn(|i| &st[i * kp..(i + 1) * kp]);
    // SAFETY: 8 `i32`s.
    let b = unsafe { [ld1q_s32(bias.as_ptr()), ld1q_s32(bias.as_ptr().add(4))] };
    let mut acc = [b; P];
    for (g, wg) in wp.chunks_exact(PW_BLOCK * PW_GROUP).enumerate() {
        // SAFETY: `wg` is 32 bytes; `.t` = the 8 channels' weights of input `4g + t`.
        let wv = unsafe { vld4_s8(wg.as_ptr()) };
        let (w0, w1, w2, w3) = (vmovl_s8(wv.0), vmovl_s8(wv.1), vmovl_s8(wv.2), vmovl_s8(wv.3));
        for (a, row) in acc.iter_mut().zip(&rows) {
            // inside the row: `4g + 4 ≤ kp`
            let xr = &row[PW_GROUP * g..PW_GROUP * g + PW_GROUP];
            // SAFETY: 4 `i16`s.
            let xv = unsafe { ld1_s16(xr.as_ptr()) };
            a[0] = vmlal_lane_s16::<0>(a[0], vget_low_s16(w0), xv);
            a[1] = vmlal_high_lane_s16::<0>(a[1], w0, xv);
            a[0] = vmlal_lane_s16::<1>(a[0], vget_low_s16(w1), xv);
            a[1] = vmlal_high_lane_s16::<1>(a[1], w1, xv);
            a[0] = vmlal_lane_s16::<2>(a[0], vget_low_s16(w2), xv);
            a[1] = vmlal_high_lane_s16::<2>(a[1], w2, xv);
            a[0] = vmlal_lane_s16::<3>(a[0], vget_low_s16(w3), xv);
            a[1] = vmlal_high_lane_s16::<3>(a[1], w3, xv);
        }
    }
    acc
}
