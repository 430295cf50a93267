//! # portable pool: the PPM's `AveragePool`, safe Rust
//!
//! ONNX `AveragePool` with window = stride, bottom/right padding, `count_include_pad = 0` —
//! the integers of [`crate::nn::pool::avgpool_reference`]. Per window and 64-channel block,
//! each real pixel adds its channel vector to a stack accumulator, which vectorises over
//! channels.
//!
//! **ISA:** any (auto-vectorised where the target has SIMD). **Stack:** a 64-channel `i32`
//! accumulator block (256 B).

use crate::nn::pool::{AvgPoolParams, PoolQuant};
use crate::nn::Shape;

/// Channels per accumulator block.
const BLOCK: usize = 64;

/// The average pool on operands [`crate::nn::pool::avgpool_fast`] has checked (`os` the output
/// shape).
pub(crate) fn avgpool(
    x: &[i8],
    xs: Shape,
    p: &AvgPoolParams,
    q: &PoolQuant,
    out: &mut [i8],
    os: Shape,
) {
    let (kh, kw) = p.kernel;
    let c = xs.c;
    let zp = q.input_zero_point;
    let mut acc = [0i32; BLOCK];
    for oy in 0..os.h {
        let (y0, y1) = (oy * kh, (oy * kh + kh).min(xs.h));
        for ox in 0..os.w {
            let (x0, x1) = (ox * kw, (ox * kw + kw).min(xs.w));
            let n = ((y1 - y0) * (x1 - x0)) as i32;
            let o = os.index(0, oy, ox);
            let opix = &mut out[o..o + c];
            let mut c0 = 0;
            while c0 < c {
                let nb = BLOCK.min(c - c0);
                let acc = &mut acc[..nb];
                acc.fill(0);
                for iy in y0..y1 {
                    for ix in x0..x1 {
                        let i = xs.index(c0, iy, ix);
                        for (a, &v) in acc.iter_mut().zip(&x[i..i + nb]) {
                            *a += v as i32 - zp;
                        }
                    }
                }
                for (o, &a) in opix[c0..c0 + nb].iter_mut().zip(acc.iter()) {
                    *o = q.finish(a, n);
                }
                c0 += nb;
            }
        }
    }
}
