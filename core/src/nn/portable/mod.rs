//! # portable: the safe fast kernels, one file per op family
//!
//! The fast kernels of every target, in safe Rust written for the compiler's auto-vectoriser
//! (contiguous row slices, hoisted bounds, `chunks_exact`, zipped loops), as tract's
//! `linalg/src/generic`. On x86-64 with AVX2 the `x86` kernels replace some of them (the
//! `dispatch` module decides); these remain the code of every other target (Cortex-M, aarch64)
//! and are tested on x86 too, bit-equal to the references.
//!
//! | file            | ONNX op                                      | stack            |
//! |-----------------|----------------------------------------------|------------------|
//! | [`conv`]        | `Conv`, `group = 1`, any kernel/stride/pads  | 5.8 KiB          |
//! | [`depthwise`]   | `Conv` depthwise 3×3, pad 1, stride 1/2      | 6.3 KiB          |
//! | [`pointwise`]   | `Conv` 1×1 (int8 GEMM over packed weights)   | 10 KiB           |
//! | [`resize`]      | `Resize` bilinear, `half_pixel`              | none             |
//! | [`eltwise`]     | `Add`, `Concat` (channels), `Relu`           | 2 KiB (`Add`)    |
//! | [`pool`]        | `AveragePool` (the PPM's)                    | 256 B            |
//!
//! **ISA:** none required. Each kernel takes the operands its op has checked
//! (`conv::pointwise_fast` etc.) and does not panic on them.

pub(crate) mod conv;
pub(crate) mod depthwise;
pub(crate) mod eltwise;
pub(crate) mod pointwise;
pub(crate) mod pool;
pub(crate) mod resize;

use crate::nn::quant::{Lanes8, Requant};

/// Requantises one pixel's channel sums `acc` plus `bias` into `out` (all slices from the same
/// channel, as long as `out`): 8 channels at a time through `lanes`, the lane forms of
/// `requant` (branch-free; only where [`crate::nn::quant::fits_simd_requant`] holds, so the
/// bias cannot saturate), else channel by channel ([`Requant::to_i8`]).
#[allow(clippy::too_many_arguments)]
#[inline]
fn requant_channels(
    out: &mut [i8],
    acc: &[i32],
    bias: &[i32],
    requant: &[Requant],
    lanes: Option<&[Lanes8]>,
    zo: i32,
    lo: i32,
    hi: i32,
) {
    match lanes {
        Some(l8) => {
            for (((o, a), bb), l) in
                out.chunks_mut(8).zip(acc.chunks(8)).zip(bias.chunks(8)).zip(l8)
            {
                let v: [i32; 8] = core::array::from_fn(|t| {
                    a.get(t).copied().unwrap_or(0) + bb.get(t).copied().unwrap_or(0)
                });
                let r = l.requant(&v, zo, lo, hi);
                o.copy_from_slice(&r[..o.len()]);
            }
        }
        None => {
            for (((o, &a), &b), rq) in out.iter_mut().zip(acc).zip(bias).zip(requant) {
                *o = rq.to_i8(a.saturating_add(b), zo, lo, hi);
            }
        }
    }
}
