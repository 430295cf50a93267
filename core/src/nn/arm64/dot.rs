//! # arm64 dot: the 1×1 `Conv` with the ARMv8.2 dot products (`sdot`)
//!
//! The integers of [`crate::nn::conv::pointwise_reference`], over the packed weights of
//! [`crate::nn::conv::pack_pointwise`], on CPUs with FEAT_DotProd (Cortex-A55, A65, A75, A76,
//! A78AE, Neoverse; [`super::dotprod_enabled`]). A group's 32 packed bytes are two `sdot`
//! operands as they stand: channels 0–3's four weights each, then channels 4–7's. A pixel's
//! 4 inputs of the group are one 32-bit lane of its input row, so `sdot acc.4s, w.16b,
//! x.4b[t]` adds 16 products (4 channels × 4 inputs) in one instruction; per group and
//! pixel two of them do what [`super::pointwise`] does with 8 `smlal` and a widening of the
//! inputs to `i16`.
//!
//! The inputs are therefore staged as they are (`i8`, each row zero padded to a multiple of 16),
//! and the products are `w · x`, not `w · (x − zp)`: each block's 8 sums start at
//! `b − zp · Σw` instead of `b` (`Σw` by `sdot` against a vector of ones, once per block and
//! call), in wrapping `i32` arithmetic. The sum differs from the reference's integer by a
//! multiple of 2^32 at most, so it is that integer whenever it fits an `i32`, which
//! [`fits_simd_requant`] guarantees (its bound, `|acc| · 2^left ≤ 2^30`, is checked here as in
//! the other GEMMs). The requantisation is [`super::lanes::Rq8Regs`]'s.
//!
//! Per tile of 8 pixels and block of 8 channels, each 16 inputs cost one 16-byte load per
//! pixel, then per group of 4 one 32-byte weight load and 16 `sdot`: 256 multiply-adds in
//! about 19 instructions, against 77 for [`super::pointwise`].
//!
//! `sdot` is written in `asm!`: its intrinsics (`vdotq_laneq_s32`) are not stable Rust.
//!
//! **Stack:** the 8 KiB stage and the corrected biases of up to 256 output channels (1 KiB);
//! the requantisers as in [`super::pointwise`] (4 KiB).

use super::mem::{ld1q_s32, ld1q_s8};
use core::arch::aarch64::*;
use core::arch::asm;

use super::lanes::{block8, store8, Rq8, Rq8Table, TABLE};
use super::pointwise::{pad, tile_rows};
use crate::nn::conv::{ConvQuant, PW_BLOCK, PW_GROUP};
use crate::nn::quant::{clamp_range, fits_simd_requant};
use crate::nn::Shape;

/// Bytes of the stage (8 KiB): 8 rows of up to 1024 inputs, fewer rows of wider ones.
const STAGE: usize = 8192;
/// Inputs per staged load: 4 groups, one `sdot` lane each.
const CHUNK: usize = 4 * PW_GROUP;
/// Widest input row taken (the other GEMMs' limit: rows of up to 4096 inputs).
const MAX_K: usize = 4096;
/// Packed weight bytes of one group of one block.
const GROUP_BYTES: usize = PW_BLOCK * PW_GROUP;

/// The `sdot` GEMM on operands [`crate::nn::conv::pointwise_fast`] has checked; `false`
/// (nothing written) when the CPU has no dot products ([`super::dotprod_enabled`]: the
/// dispatcher asks first, but the `unsafe` call below relies on this check alone), a row is
/// wider than [`MAX_K`] or the vector requantisation does not hold.
pub(crate) fn pointwise(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> bool {
    let k = xs.c;
    if !super::dotprod_enabled()
        || k > MAX_K
        || !fits_simd_requant(k as i64 * 255 * 128, b, q.requant)
    {
        return false;
    }
    // SAFETY: this module is compiled only where `neon` is a target feature of the build, and
    // the CPU has FEAT_DotProd (`super::dotprod_enabled`, checked above).
    unsafe { run(x, xs, w, b, q, out) };
    true
}

/// `acc + (Σ_t w[4i + t] · x[4L + t])_i`: `sdot acc.4s, w.16b, x.4b[L]`.
#[target_feature(enable = "neon,dotprod")]
#[inline]
fn sdot<const L: i32>(acc: int32x4_t, w: int8x16_t, x: int8x16_t) -> int32x4_t {
    let mut acc = acc;
    // SAFETY: a register-only instruction of FEAT_DotProd, which this function's target
    // features require of the CPU.
    unsafe {
        asm!(
            "sdot {a:v}.4s, {w:v}.16b, {x:v}.4b[{l}]",
            a = inout(vreg) acc,
            w = in(vreg) w,
            x = in(vreg) x,
            l = const L,
            options(pure, nomem, nostack, preserves_flags),
        );
    }
    acc
}

/// A group's 32 packed weight bytes as the two `sdot` operands (channels 0–3, 4–7).
#[target_feature(enable = "neon")]
#[inline]
fn weights(wg: &[i8; GROUP_BYTES]) -> (int8x16_t, int8x16_t) {
    // SAFETY: 32 bytes.
    unsafe { (ld1q_s8(wg.as_ptr()), ld1q_s8(wg.as_ptr().add(16))) }
}

/// A block's 8 sums before any input: `b − zp · Σw` per channel (wrapping), over its panel.
#[target_feature(enable = "neon,dotprod")]
#[inline]
fn block_bias(bias: &[i32; PW_BLOCK], panel: &[i8], zp: i32) -> [int32x4_t; 2] {
    let ones = vdupq_n_s8(1);
    let mut s = [vdupq_n_s32(0); 2];
    for wg in panel.chunks_exact(GROUP_BYTES) {
        let Ok(wg) = <&[i8; GROUP_BYTES]>::try_from(wg) else { continue };
        let (w0, w1) = weights(wg);
        s = [sdot::<0>(s[0], w0, ones), sdot::<0>(s[1], w1, ones)];
    }
    // SAFETY: 8 `i32`s.
    let b = unsafe { [ld1q_s32(bias.as_ptr()), ld1q_s32(bias.as_ptr().add(4))] };
    [vmlsq_n_s32(b[0], s[0], zp), vmlsq_n_s32(b[1], s[1], zp)]
}

/// [`pointwise`] after its checks.
#[target_feature(enable = "neon,dotprod")]
fn run(x: &[i8], xs: Shape, w: &[i8], b: &[i32], q: &ConvQuant<'_>, out: &mut [i8]) {
    let k = xs.c;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let zp = q.input_zero_point;
    let n = b.len();
    let groups = k.div_ceil(PW_GROUP);
    // a staged row: the inputs, zero padded to whole chunks
    let kp = k.div_ceil(CHUNK) * CHUNK;
    let panel = groups * GROUP_BYTES;
    let p = xs.h * xs.w;
    let x = &x[..p * k];
    let out = &mut out[..p * n];
    let tp = tile_rows(STAGE / kp);
    let mut st = [0i8; STAGE];
    let mut table = [Rq8::ZERO; TABLE];
    let rqs = Rq8Table::new(&mut table, q.requant);
    // the blocks' starting sums, made once for up to TABLE blocks (1 KiB)
    let z = vdupq_n_s32(0);
    let mut sums = [[z; 2]; TABLE];
    let block_sums = |blk: usize, wp: &[i8]| block_bias(&block8(b, blk * PW_BLOCK), wp, zp);
    for ((blk, wp), s) in w.chunks_exact(panel).enumerate().zip(sums.iter_mut()) {
        *s = block_sums(blk, wp);
    }
    for (xt, ot) in x.chunks(tp * k).zip(out.chunks_mut(tp * n)) {
        let np = xt.len() / k;
        for (row, xr) in st.chunks_exact_mut(kp).zip(xt.chunks_exact(k)) {
            row[..k].copy_from_slice(xr);
            // the packed weights of the padding inputs are 0, but keep the products defined
            row[k..].fill(0);
        }
        let st = &st[..tp * kp];
        for (blk, wp) in w.chunks_exact(panel).enumerate() {
            let k0 = blk * PW_BLOCK;
            let nb = (n - k0).min(PW_BLOCK);
            let bias = match sums.get(blk) {
                Some(s) => *s,
                None => block_sums(blk, wp),
            };
            // a short last tile takes the next size up within the tile: the extra rows hold
            // an earlier tile's pixels (or zeros), whose sums are not stored
            let acc = match np {
                5.. => tile::<8>(st, kp, wp, bias),
                3 | 4 => pad(tile::<4>(st, kp, wp, bias)),
                2 => pad(tile::<2>(st, kp, wp, bias)),
                _ => pad(tile::<1>(st, kp, wp, bias)),
            };
            // the requantisers' registers only after the tile, which needs all but a few
            let rq = rqs.block(blk).regs(q.output_zero_point, lo, hi);
            for (i, a) in acc.iter().take(np).enumerate() {
                store8(&mut ot[i * n + k0..i * n + k0 + nb], rq.requant(*a));
            }
        }
    }
}

/// The 8 channels' sums (starting at `bias`) of the first `P` staged rows (`kp` bytes each, a
/// multiple of [`CHUNK`], `P · kp ≤ st.len()`) over one block's panel (`GROUP_BYTES` per
/// group, `kp / 4` groups at most).
#[target_feature(enable = "neon,dotprod")]
#[inline]
fn tile<const P: usize>(
    st: &[i8],
    kp: usize,
    wp: &[i8],
    bias: [int32x4_t; 2],
) -> [[int32x4_t; 2]; P] {
    let rows: [&[i8]; P] = core::array::from_fn(|i| &st[i * kp..(i + 1) * kp]);
    let mut acc = [bias; P];
    // one group `t` of the loaded chunk: 2 `sdot` per row
    macro_rules! group {
        ($t:literal, $wg:expr, $xv:expr) => {{
            let (w0, w1) = weights($wg);
            for (a, xv) in acc.iter_mut().zip($xv.iter()) {
                a[0] = sdot::<$t>(a[0], w0, *xv);
                a[1] = sdot::<$t>(a[1], w1, *xv);
            }
        }};
    }
    for (c, wc) in wp.chunks(CHUNK / PW_GROUP * GROUP_BYTES).enumerate() {
        // each row's 16 inputs of the chunk (inside the row: `16c + 16 ≤ kp`)
        let xv: [int8x16_t; P] = core::array::from_fn(|i| {
            let r = &rows[i][CHUNK * c..CHUNK * c + CHUNK];
            // SAFETY: 16 bytes.
            unsafe { ld1q_s8(r.as_ptr()) }
        });
        let mut gs =
            wc.chunks_exact(GROUP_BYTES).filter_map(|g| <&[i8; GROUP_BYTES]>::try_from(g).ok());
        match (gs.next(), gs.next(), gs.next(), gs.next()) {
            (Some(g0), Some(g1), Some(g2), Some(g3)) => {
                group!(0, g0, xv);
                group!(1, g1, xv);
                group!(2, g2, xv);
                group!(3, g3, xv);
            }
            // the last chunk of a row whose groups are not a multiple of 4
            (g0, g1, g2, _) => {
                if let Some(g0) = g0 {
                    group!(0, g0, xv);
                }
                if let Some(g1) = g1 {
                    group!(1, g1, xv);
                }
                if let Some(g2) = g2 {
                    group!(2, g2, xv);
                }
            }
        }
    }
    acc
}
