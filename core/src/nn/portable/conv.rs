//! # portable conv: the general `Conv` (`group = 1`), safe Rust
//!
//! ONNX `Conv`, `group = 1`, any kernel, stride and padding, dilation 1, weights OHWI — the
//! integers of [`crate::nn::conv::conv2d_reference`]. Two loop orders:
//! - a short reduction (`kh·kw·c_in ≤ 32`) into at most 64 channels, the network's first conv:
//!   the output channels are the vector ([`conv2d_taps`]);
//! - anything else: per output pixel the valid kernel rows are contiguous NHWC runs of
//!   `kw_valid · c_in` bytes in both input and weights, so each is one dot product.
//!
//! **ISA:** any (auto-vectorised where the target has SIMD). **Stack:** 5.8 KiB (the first
//! form: transposed `i16` weights, lane-form requantisers, a channel accumulator), else none.

use super::requant_channels;
use crate::nn::conv::{Conv2dParams, ConvQuant};
use crate::nn::quant::{clamp_range, fits_simd_requant, Lanes8};
use crate::nn::Shape;

/// `Σ (x − zp)·w` over two equally long slices; the shape of loop LLVM vectorises.
#[inline]
fn dot(x: &[i8], w: &[i8], zp: i32) -> i32 {
    x.iter().zip(w).map(|(&a, &b)| (a as i32 - zp) * b as i32).sum()
}

/// The valid tap range `[k0, k1)` of a window starting at `start − pad` on an axis of `n`.
#[inline]
pub(crate) fn tap_range(o: usize, stride: usize, pad: usize, k: usize, n: usize) -> (usize, usize) {
    let start = o * stride;
    let k0 = pad.saturating_sub(start);
    let k1 = k.min((n + pad).saturating_sub(start));
    (k0, k1.max(k0))
}

/// Largest reduction (`kh·kw·c_in`) of [`conv2d_taps`]: a 3×3 kernel over up to 3 channels.
const TAPS_K: usize = 32;
/// Most output channels of [`conv2d_taps`].
const TAPS_OUT: usize = 64;

/// The general conv on operands [`crate::nn::conv::conv2d_fast`] has checked (`os` the output
/// shape). A short reduction with few output channels (the network's first conv: 3×3 over
/// one grey channel into 32) takes [`conv2d_taps`], anything else the dot-product loop.
#[allow(clippy::too_many_arguments)]
// Out of line: inlined into the dispatcher, its frame (KiBs of staged rows) would add to the
// SIMD kernel's the dispatcher calls first (`nn::dispatch`, **Stack**).
#[inline(never)]
pub(crate) fn conv2d(
    x: &[i8],
    xs: Shape,
    p: &Conv2dParams,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) {
    let k = p.kernel.0 * p.kernel.1 * xs.c;
    if k <= TAPS_K && p.c_out <= TAPS_OUT {
        return conv2d_taps(x, xs, p, w, b, q, out, os);
    }
    let (kh, kw) = p.kernel;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let ci = xs.c;
    let wk = kh * kw * ci;
    let out = &mut out[..os.len()];
    for (oy, orow) in out.chunks_exact_mut(os.w * os.c).enumerate() {
        let (ky0, ky1) = tap_range(oy, p.stride.0, p.pads[0], kh, xs.h);
        for (ox, opix) in orow.chunks_exact_mut(os.c).enumerate() {
            let (kx0, kx1) = tap_range(ox, p.stride.1, p.pads[1], kw, xs.w);
            let run = (kx1 - kx0) * ci;
            let ix0 = ox * p.stride.1 + kx0 - p.pads[1];
            for ((o, wc), (&bias, rq)) in
                opix.iter_mut().zip(w.chunks_exact(wk)).zip(b.iter().zip(q.requant))
            {
                let mut acc = 0i32;
                for ky in ky0..ky1 {
                    let iy = oy * p.stride.0 + ky - p.pads[0];
                    let xo = (iy * xs.w + ix0) * ci;
                    let wo = (ky * kw + kx0) * ci;
                    acc += dot(&x[xo..xo + run], &wc[wo..wo + run], q.input_zero_point);
                }
                *o = rq.to_i8(acc.saturating_add(bias), q.output_zero_point, lo, hi);
            }
        }
    }
}

/// The conv with the output channels as the vector: per output pixel each valid tap's
/// `x − zp` times that tap's weights of every output channel (a transposed `i16` copy of the
/// weights, made once) is added to a channel accumulator, which auto-vectorises as an
/// `i16 × i16` widening multiply-add (`|x − zp| ≤ 255`, `|w| ≤ 128`: the product fits `i16`).
/// The dot-product loop's reductions are as short as the kernel (9 for the first conv) and did
/// not vectorise. Requantised 8 channels at a time ([`Lanes8`]) when [`fits_simd_requant`]
/// holds, else channel by channel. **Stack:** 4 KiB of weights, 1.5 KiB of requantisers.
#[allow(clippy::too_many_arguments)]
fn conv2d_taps(
    x: &[i8],
    xs: Shape,
    p: &Conv2dParams,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) {
    let (kh, kw) = p.kernel;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let (ci, co) = (xs.c, p.c_out);
    let k = kh * kw * ci;
    let zp16 = q.input_zero_point as i16;
    // wt[t·co + o] = w[o][t]
    let mut wt = [0i16; TAPS_K * TAPS_OUT];
    for (o, wo) in w[..co * k].chunks_exact(k).enumerate() {
        for (t, &v) in wo.iter().enumerate() {
            wt[t * co + o] = v as i16;
        }
    }
    let mut l8 = [Lanes8::new(&[]); TAPS_OUT / 8];
    let vector = fits_simd_requant(k as i64 * 255 * 128, b, q.requant);
    for (l, r) in l8.iter_mut().zip(q.requant.chunks(8)) {
        *l = Lanes8::new(r);
    }
    let mut acc = [0i32; TAPS_OUT];
    let acc = &mut acc[..co];
    for (oy, orow) in out[..os.len()].chunks_exact_mut(os.w * co).enumerate() {
        let (ky0, ky1) = tap_range(oy, p.stride.0, p.pads[0], kh, xs.h);
        for (ox, opix) in orow.chunks_exact_mut(co).enumerate() {
            let (kx0, kx1) = tap_range(ox, p.stride.1, p.pads[1], kw, xs.w);
            let ix0 = ox * p.stride.1 + kx0 - p.pads[1];
            acc.fill(0);
            for ky in ky0..ky1 {
                let iy = oy * p.stride.0 + ky - p.pads[0];
                let xo = (iy * xs.w + ix0) * ci;
                let t0 = (ky * kw + kx0) * ci;
                let run = (kx1 - kx0) * ci;
                for (&xv, wt) in x[xo..xo + run].iter().zip(wt[t0 * co..].chunks_exact(co)) {
                    let d = xv as i16 - zp16;
                    for (a, &wv) in acc.iter_mut().zip(wt) {
                        *a += d as i32 * wv as i32;
                    }
                }
            }
            let l8 = vector.then_some(&l8[..]);
            requant_channels(opix, acc, b, q.requant, l8, q.output_zero_point, lo, hi);
        }
    }
}
