//! # portable eltwise: `Add`, `Concat` (channels), `Relu`, safe Rust
//!
//! The integers of [`crate::nn::eltwise`]'s references, walking whole slices (`zip`, no
//! indexing):
//! - ONNX `Add` (same shapes): TFLite's quantised add, element by element.
//! - ONNX `Concat` along channels: per pixel, one input's channel run copied (identity
//!   rescale) or rescaled as one slice.
//! - ONNX `Relu` with a rescale: `max(x, zp)` when the rescale is the identity.
//!
//! **ISA:** any. **Stack:** none.

use crate::nn::eltwise::{AddQuant, ConcatInput, Rescale};
use crate::nn::quant::clamp_range;
use crate::nn::Shape;

/// `Add` on operands [`crate::nn::eltwise::add_fast`] has checked.
pub(crate) fn add(a: &[i8], b: &[i8], shape: Shape, q: &AddQuant, out: &mut [i8]) {
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let n = shape.len();
    for ((o, &x), &y) in out[..n].iter_mut().zip(&a[..n]).zip(&b[..n]) {
        *o = q.add(x, y, lo, hi);
    }
}

/// One input of a channel `Concat` on operands [`crate::nn::eltwise::concat_fast`] has
/// checked, into channels `c0..` of the output of shape `os`.
pub(crate) fn concat_input(i: &ConcatInput<'_>, c0: usize, os: Shape, out: &mut [i8]) {
    let ci = i.shape.c;
    let src = i.data[..i.shape.len()].chunks_exact(ci);
    let dst = out[..os.len()].chunks_exact_mut(os.c);
    if i.rescale.is_identity() {
        for (d, s) in dst.zip(src) {
            d[c0..c0 + ci].copy_from_slice(s);
        }
    } else {
        for (d, s) in dst.zip(src) {
            for (o, &v) in d[c0..c0 + ci].iter_mut().zip(s) {
                *o = i.rescale.apply(v, -128, 127);
            }
        }
    }
}

/// Standalone `Relu` on operands [`crate::nn::eltwise::relu_fast`] has checked.
pub(crate) fn relu(x: &[i8], shape: Shape, r: &Rescale, out: &mut [i8]) {
    let (lo, hi) = clamp_range(r.output_zero_point, true);
    let n = shape.len();
    if r.is_identity() {
        let zp = lo as i8;
        for (o, &v) in out[..n].iter_mut().zip(&x[..n]) {
            *o = v.max(zp);
        }
    } else {
        for (o, &v) in out[..n].iter_mut().zip(&x[..n]) {
            *o = r.apply(v, lo, hi);
        }
    }
}
