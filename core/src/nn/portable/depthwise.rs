//! # portable depthwise: the depthwise 3×3 `Conv`, safe Rust
//!
//! ONNX `Conv` with `group = C`, a 3×3 kernel, pad 1, stride 1 or 2, weights `[3][3][C]` — the
//! integers of [`crate::nn::conv::depthwise3x3_reference`]. Per output pixel and 64-channel
//! block, each valid tap adds a whole channel vector (`x[iy, ix, c..]·w[ky, kx, c..]`) to a
//! stack accumulator, which auto-vectorises; the block is then requantised 8 lanes at a time
//! ([`Lanes8`], branch-free) when [`fits_simd_requant`] holds, else channel by channel.
//!
//! **ISA:** any (auto-vectorised where the target has SIMD). **Stack:** a 64-channel `i32`
//! accumulator block and the lane-form requantisers of up to 256 channels (6.3 KiB).

use super::conv::tap_range;
use super::requant_channels;
use crate::nn::conv::ConvQuant;
use crate::nn::quant::{clamp_range, fits_simd_requant, Lanes8};
use crate::nn::Shape;

/// Channels per accumulator block of the fast depthwise kernel.
const DW_BLOCK: usize = 64;
/// Channel groups of 8 whose requantisers the portable depthwise kernel keeps in lane form.
const DW_LANE_GROUPS: usize = 32;

/// The depthwise 3×3 conv on operands [`crate::nn::conv::depthwise3x3_fast`] has checked (`os`
/// the output shape).
#[allow(clippy::too_many_arguments)]
// Out of line: inlined into the dispatcher, its frame (KiBs of staged rows) would add to the
// SIMD kernel's the dispatcher calls first (`nn::dispatch`, **Stack**).
#[inline(never)]
pub(crate) fn depthwise3x3(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) {
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let c = xs.c;
    let zp = q.input_zero_point;
    let out = &mut out[..os.len()];
    let mut acc = [0i32; DW_BLOCK];
    // the requantisers of up to 256 channels in lane form (6 KiB), when the vector form holds
    let mut l8 = [Lanes8::new(&[]); DW_LANE_GROUPS];
    let lanes =
        (c <= 8 * DW_LANE_GROUPS && fits_simd_requant(9 * 255 * 127, b, q.requant)).then(|| {
            for (l, r) in l8.iter_mut().zip(q.requant.chunks(8)) {
                *l = Lanes8::new(r);
            }
            &l8
        });
    for (oy, orow) in out.chunks_exact_mut(os.w * c).enumerate() {
        let (ky0, ky1) = tap_range(oy, stride, 1, 3, xs.h);
        for (ox, opix) in orow.chunks_exact_mut(c).enumerate() {
            let (kx0, kx1) = tap_range(ox, stride, 1, 3, xs.w);
            let mut c0 = 0;
            while c0 < c {
                let n = DW_BLOCK.min(c - c0);
                let acc = &mut acc[..n];
                acc.fill(0);
                for ky in ky0..ky1 {
                    let iy = oy * stride + ky - 1;
                    for kx in kx0..kx1 {
                        let ix = ox * stride + kx - 1;
                        let xo = (iy * xs.w + ix) * c + c0;
                        let wo = (ky * 3 + kx) * c + c0;
                        for (a, (&xv, &wv)) in
                            acc.iter_mut().zip(x[xo..xo + n].iter().zip(&w[wo..wo + n]))
                        {
                            *a += (xv as i32 - zp) * wv as i32;
                        }
                    }
                }
                let l8 = lanes.map(|l| &l[c0 / 8..]);
                let (zo, rq) = (q.output_zero_point, &q.requant[c0..c0 + n]);
                requant_channels(&mut opix[c0..c0 + n], acc, &b[c0..c0 + n], rq, l8, zo, lo, hi);
                c0 += n;
            }
        }
    }
}
