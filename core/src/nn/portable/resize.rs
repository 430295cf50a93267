//! # portable resize: bilinear `Resize` (`half_pixel`), safe Rust
//!
//! ONNX `Resize`, `mode = linear`, `coordinate_transformation_mode = half_pixel`, static sizes:
//! the fixed-point blend of [`crate::nn::resize`], the integers of
//! [`crate::nn::resize::resize_bilinear_reference`]. The y taps are computed once per output
//! row and the x taps once per output pixel; whole channel vectors (NHWC) are blended in one
//! zipped loop.
//!
//! **ISA:** any (auto-vectorised where the target has SIMD). **Stack:** none.

use crate::nn::quant::Lane1;
use crate::nn::resize::{blend, half_pixel_taps, ResizeQuant, RESIZE_FRAC_BITS};
use crate::nn::Shape;

/// The resize on operands [`crate::nn::resize::resize_bilinear_fast`] has checked (`os` the
/// output shape).
pub(crate) fn resize_bilinear(x: &[i8], xs: Shape, q: &ResizeQuant, out: &mut [i8], os: Shape) {
    let c = xs.c;
    let zp = q.input_zero_point;
    let zo = q.output_zero_point;
    let rq = q.requant;
    // a blend is at most 2^22 · 255 in magnitude: the branch-free requantisation takes it
    // whenever the requantiser does not shift left far
    let lane = Lane1::fits(rq, 255 << (2 * RESIZE_FRAC_BITS)).then(|| Lane1::new(rq));
    let out = &mut out[..os.len()];
    for (oy, orow) in out.chunks_exact_mut(os.w * c).enumerate() {
        let (y0, y1, wy) = half_pixel_taps(oy, xs.h, os.h);
        let (r0, r1) = (y0 * xs.w * c, y1 * xs.w * c);
        for (ox, opix) in orow.chunks_exact_mut(c).enumerate() {
            let (x0, x1, wx) = half_pixel_taps(ox, xs.w, os.w);
            let (p0, p1) = (x0 * c, x1 * c);
            let a = &x[r0 + p0..r0 + p0 + c];
            let b = &x[r0 + p1..r0 + p1 + c];
            let cc = &x[r1 + p0..r1 + p0 + c];
            let d = &x[r1 + p1..r1 + p1 + c];
            let px = opix.iter_mut().zip(a).zip(b).zip(cc).zip(d);
            let tap = |va: i8, vb: i8, vc: i8, vd: i8| {
                blend(va as i32 - zp, vb as i32 - zp, vc as i32 - zp, vd as i32 - zp, wx, wy)
            };
            match &lane {
                Some(l) => {
                    for ((((o, &va), &vb), &vc), &vd) in px {
                        *o = l.to_i8(tap(va, vb, vc, vd), zo, -128, 127);
                    }
                }
                None => {
                    for ((((o, &va), &vb), &vc), &vd) in px {
                        *o = rq.to_i8(tap(va, vb, vc, vd), zo, -128, 127);
                    }
                }
            }
        }
    }
}
