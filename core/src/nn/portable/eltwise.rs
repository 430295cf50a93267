//! # portable eltwise: `Add`, `Concat` (channels), `Relu`, safe Rust
//!
//! The integers of [`crate::nn::eltwise`]'s references, walking whole slices (`zip`, no
//! indexing):
//! - ONNX `Add` (same shapes): TFLite's quantised add, element by element, each input's
//!   rescale read from a 256-entry table.
//! - ONNX `Concat` along channels: per pixel, one input's channel run copied (identity
//!   rescale) or looked up in the rescale's 256-byte table.
//! - ONNX `Relu` with a rescale: `max(x, zp)` when the rescale is the identity, else a table.
//!
//! **ISA:** any. **Stack:** two 1 KiB tables (`Add`), a 256-byte one (`Concat`, `Relu`).

use crate::nn::eltwise::{AddQuant, ConcatInput, Rescale};
use crate::nn::quant::{clamp_range, Lane1, Requant, ADD_LEFT_SHIFT};
use crate::nn::Shape;

/// `Add` on operands [`crate::nn::eltwise::add_fast`] has checked. Each input's rescaled
/// value depends on its byte alone, so it is read from a 256-entry table made once per call
/// (`requant_k((v − zp_k) << 20)`, the reference's own step); the sum is then requantised
/// branch-free ([`Lane1`]) when the tables' largest sum fits it, else as the reference does.
pub(crate) fn add(a: &[i8], b: &[i8], shape: Shape, q: &AddQuant, out: &mut [i8]) {
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let n = shape.len();
    let table = |zp: i32, r: Requant| -> [i32; 256] {
        core::array::from_fn(|i| r.apply((i as i32 - 128 - zp) << ADD_LEFT_SHIFT))
    };
    let (t1, t2) = (table(q.zero_point1, q.requant1), table(q.zero_point2, q.requant2));
    let peak = |t: &[i32; 256]| t.iter().map(|&v| (v as i64).abs()).max().unwrap_or(0);
    let (a, b, out) = (&a[..n], &b[..n], &mut out[..n]);
    let zo = q.output_zero_point;
    if Lane1::fits(q.output, peak(&t1) + peak(&t2)) {
        let l = Lane1::new(q.output);
        for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
            *o = l.to_i8(t1[(x as i32 + 128) as usize] + t2[(y as i32 + 128) as usize], zo, lo, hi);
        }
    } else {
        for ((o, &x), &y) in out.iter_mut().zip(a).zip(b) {
            let s = t1[(x as i32 + 128) as usize].saturating_add(t2[(y as i32 + 128) as usize]);
            *o = q.output.to_i8(s, zo, lo, hi);
        }
    }
}

/// The 256-entry table of a rescale clamped to `[lo, hi]`: `table[v + 128] = r.apply(v, lo, hi)`.
fn rescale_table(r: &Rescale, lo: i32, hi: i32) -> [i8; 256] {
    core::array::from_fn(|i| r.apply((i as i32 - 128) as i8, lo, hi))
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
        let t = rescale_table(&i.rescale, -128, 127);
        for (d, s) in dst.zip(src) {
            for (o, &v) in d[c0..c0 + ci].iter_mut().zip(s) {
                *o = t[(v as i32 + 128) as usize];
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
        let t = rescale_table(r, lo, hi);
        for (o, &v) in out[..n].iter_mut().zip(&x[..n]) {
            *o = t[(v as i32 + 128) as usize];
        }
    }
}
