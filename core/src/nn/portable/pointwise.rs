//! # portable pointwise: the 1×1 `Conv` as an int8 GEMM, safe Rust
//!
//! ONNX `Conv` with a 1×1 kernel, stride 1, no padding, `group = 1`, over the packed weights
//! of [`crate::nn::conv::pack_pointwise`]: `out[p][co] = clamp(zo + requant[co](bias[co] +
//! Σ_ci (x[p][ci] − zp)·w[co][ci]))`, `i32` accumulation — the integers of
//! [`crate::nn::conv::pointwise_reference`].
//!
//! **ISA:** any (written for the auto-vectoriser: `pmaddwd` on x86, `smlal` on Arm).
//! **Stack:** an unpacked 8-channel weight panel (8 KiB) and a staged `i16` input row (2 KiB);
//! rows wider than [`PW_STAGE`] are read straight from the packed layout instead.

use crate::nn::conv::{pointwise_packed_index, ConvQuant, PW_BLOCK, PW_GROUP};
use crate::nn::quant::{clamp_range, fits_simd_requant, Lanes8};
use crate::nn::Shape;

/// Longest input row the portable pointwise kernel stages as `i16` (2 KiB of stack, beside an
/// 8 KiB unpacked weight panel); wider rows take [`pointwise_wide`].
pub(crate) const PW_STAGE: usize = 1024;

/// The portable GEMM on operands [`crate::nn::conv::pointwise_fast`] has checked. Per 8-channel
/// block the packed panel is unpacked once into 8 plain weight rows (stack, up to 1024 inputs
/// each); per pixel the input row is staged as `i16` minus the zero point and multiplied with
/// four weight rows at a time in one zipped loop (the shape of loop the auto-vectoriser turns
/// into `pmaddwd` / `smlal`), then the block is requantised 8 lanes at a time ([`Lanes8`],
/// branch-free). Rows wider than 1024 take [`pointwise_wide`].
// Out of line: inlined into the dispatcher, its frame (KiBs of staged rows) would add to the
// SIMD kernel's the dispatcher calls first (`nn::dispatch`, **Stack**).
#[inline(never)]
pub(crate) fn pointwise(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) {
    let ci = xs.c;
    if ci > PW_STAGE {
        return pointwise_wide(x, xs, w, b, q, out);
    }
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let co = b.len();
    let zp = q.input_zero_point;
    let zo = q.output_zero_point;
    let lanes = PW_BLOCK * PW_GROUP;
    let panel = ci.div_ceil(PW_GROUP) * lanes;
    let vector = fits_simd_requant(ci as i64 * 255 * 127, b, q.requant);
    let mut wt = [0i8; PW_BLOCK * PW_STAGE];
    let mut st = [0i16; PW_STAGE];
    let x = &x[..xs.len()];
    for (block, wp) in w.chunks_exact(panel).enumerate() {
        let k0 = block * PW_BLOCK;
        let nb = (co - k0).min(PW_BLOCK);
        // unpack: wt[j·ci + k] = w[k0 + j][k] (padding channels stay 0)
        let wt = &mut wt[..PW_BLOCK * ci];
        for (g, chunk) in wp.chunks_exact(lanes).enumerate() {
            for (j, lane) in chunk.chunks_exact(PW_GROUP).enumerate() {
                for (t, &v) in lane.iter().enumerate() {
                    let k = g * PW_GROUP + t;
                    if k < ci {
                        wt[j * ci + k] = v;
                    }
                }
            }
        }
        let lanes8 = Lanes8::new(&q.requant[k0..k0 + nb]);
        let mut bias = [0i32; PW_BLOCK];
        bias[..nb].copy_from_slice(&b[k0..k0 + nb]);
        let (w0, w1) = wt.split_at(4 * ci);
        for (p, xr) in x.chunks_exact(ci).enumerate() {
            let st = &mut st[..ci];
            for (s, &v) in st.iter_mut().zip(xr) {
                *s = v as i16 - zp as i16;
            }
            let a = dot4(st, w0);
            let c = dot4(st, w1);
            let acc = [a[0], a[1], a[2], a[3], c[0], c[1], c[2], c[3]];
            let ob = &mut out[p * co + k0..p * co + k0 + nb];
            if vector {
                let v = lanes8.requant(&core::array::from_fn(|j| acc[j] + bias[j]), zo, lo, hi);
                ob.copy_from_slice(&v[..nb]);
            } else {
                for (t, o) in ob.iter_mut().enumerate() {
                    *o = q.requant[k0 + t].to_i8(acc[t].saturating_add(bias[t]), zo, lo, hi);
                }
            }
        }
    }
}

/// Four dot products of one staged input row with four weight rows, in one zipped loop.
/// `i16 × i8 → i32` with `|x − zp| ≤ 255` is what `pmaddwd` / `smlal` do, and LLVM finds them.
#[inline]
fn dot4(xr: &[i16], w4: &[i8]) -> [i32; 4] {
    let ci = xr.len();
    let (w0, r) = w4.split_at(ci);
    let (w1, r) = r.split_at(ci);
    let (w2, w3) = r.split_at(ci);
    let (mut a0, mut a1, mut a2, mut a3) = (0i32, 0i32, 0i32, 0i32);
    for ((((&xv, &v0), &v1), &v2), &v3) in xr.iter().zip(w0).zip(w1).zip(w2).zip(w3) {
        let xv = xv as i32;
        a0 += xv * v0 as i32;
        a1 += xv * v1 as i32;
        a2 += xv * v2 as i32;
        a3 += xv * v3 as i32;
    }
    [a0, a1, a2, a3]
}

/// The portable GEMM for rows wider than the stage: one dot product per output, straight
/// from the packed layout.
fn pointwise_wide(x: &[i8], xs: Shape, w: &[i8], b: &[i32], q: &ConvQuant<'_>, out: &mut [i8]) {
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let ci = xs.c;
    let co = b.len();
    let zp = q.input_zero_point;
    for (xr, orow) in x[..xs.len()].chunks_exact(ci).zip(out.chunks_exact_mut(co)) {
        for (c, o) in orow.iter_mut().enumerate() {
            let mut acc = 0i32;
            for (k, &xv) in xr.iter().enumerate() {
                acc += (xv as i32 - zp) * w[pointwise_packed_index(c, k, ci)] as i32;
            }
            *o = q.requant[c].to_i8(acc.saturating_add(b[c]), q.output_zero_point, lo, hi);
        }
    }
}
