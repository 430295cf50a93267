//! # portable conv: the general `Conv` (`group = 1`), safe Rust
//!
//! ONNX `Conv`, `group = 1`, any kernel, stride and padding, dilation 1, weights OHWI — the
//! integers of [`crate::nn::conv::conv2d_reference`]. Per output pixel the valid kernel rows
//! are contiguous NHWC runs of `kw_valid · c_in` bytes in both input and weights, so each is
//! one dot product, the shape of loop the auto-vectoriser handles.
//!
//! **ISA:** any (auto-vectorised where the target has SIMD). **Stack:** none.

use crate::nn::conv::{Conv2dParams, ConvQuant};
use crate::nn::quant::clamp_range;
use crate::nn::Shape;

/// `Σ (x − zp)·w` over two equally long slices; the shape of loop LLVM vectorises.
#[inline]
fn dot(x: &[i8], w: &[i8], zp: i32) -> i32 {
    x.iter().zip(w).map(|(&a, &b)| (a as i32 - zp) * b as i32).sum()
}

/// The valid tap range `[k0, k1)` of a window starting at `start − pad` on an axis of `n`.
#[inline]
pub(super) fn tap_range(o: usize, stride: usize, pad: usize, k: usize, n: usize) -> (usize, usize) {
    let start = o * stride;
    let k0 = pad.saturating_sub(start);
    let k1 = k.min((n + pad).saturating_sub(start));
    (k0, k1.max(k0))
}

/// The general conv on operands [`crate::nn::conv::conv2d_fast`] has checked (`os` the output
/// shape).
#[allow(clippy::too_many_arguments)]
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
