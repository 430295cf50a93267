//! Quantised `Conv` (ONNX, `group = 1` general, `group = C` depthwise 3×3, 1×1 pointwise).
//!
//! ONNX semantics with zero padding in the *real* domain: a padded tap contributes
//! `(zero_point_in − zero_point_in)·w = 0`. For output channel `co`:
//!
//! ```text
//! acc = bias[co] + Σ_{ky,kx,ci} (x[iy,ix,ci] − zp_in) · w[co,ky,kx,ci]
//! iy = oy·stride_h + ky − pad_top,  ix = ox·stride_w + kx − pad_left   (taps outside: skipped)
//! y  = clamp(zp_out + requant[co](acc), lo, hi)      (lo = zp_out with a fused ReLU, else −128)
//! ```
//!
//! `requant[co]` is [`Requant::from_scale`]`(s_in · s_w[co] / s_out)`. The sum of products is
//! formed first and the bias added with saturation, so no input can overflow (reductions are
//! bounded by [`MAX_REDUCTION`]). Dilation is 1 (the only value the network uses).
//!
//! This file holds the ONNX definition: parameters, the checks at entry, the `*_reference`
//! kernels (plain loops, no scratch) and the packed 1×1 weight layout. The `*_fast` entries
//! check their operands the same way and hand them to `nn::dispatch`, which runs the x86
//! kernel (`nn::x86::{conv1, depthwise, pointwise}`) where one applies, else the portable one
//! (`nn::portable::{conv, depthwise, pointwise}`); all compute the same integers. Stack: the
//! references none; the fast kernels as documented in their files (at most 19 KiB).
//!
//! **1×1 weights are packed** ([`pack_pointwise`], `[⌈O/8⌉][⌈I/4⌉][8][4]`), the layout the
//! model blob stores; the reference reads them through [`pointwise_packed_index`].

use super::dispatch;
use super::quant::clamp_range;
use super::{check_param, check_tensor, check_zero_point, NnError, Requant, Shape, MAX_REDUCTION};

/// Quantisation of a conv: zero points, per-output-channel requantisers, fused ReLU.
#[derive(Clone, Copy, Debug)]
pub struct ConvQuant<'a> {
    /// Zero point of the input tensor, an int8 value (`-128..=127`, checked).
    pub input_zero_point: i32,
    /// Zero point of the output tensor.
    pub output_zero_point: i32,
    /// One requantiser per output channel (`s_in · s_w[co] / s_out`).
    pub requant: &'a [Requant],
    /// Clamp at the output zero point (a fused `Relu`).
    pub relu: bool,
}

/// Geometry of a general conv (`group = 1`, dilation 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Conv2dParams {
    /// Output channels.
    pub c_out: usize,
    /// Kernel height and width.
    pub kernel: (usize, usize),
    /// Vertical and horizontal stride.
    pub stride: (usize, usize),
    /// Zero padding `[top, left, bottom, right]` (ONNX `pads` order).
    pub pads: [usize; 4],
}

impl Conv2dParams {
    /// The output shape for `input` (ONNX: `floor((h + pt + pb − kh) / sh) + 1`).
    pub fn output_shape(&self, input: Shape) -> Result<Shape, NnError> {
        let (kh, kw) = self.kernel;
        let (sh, sw) = self.stride;
        let [pt, pl, pb, pr] = self.pads;
        let hp = input.h.saturating_add(pt).saturating_add(pb);
        let wp = input.w.saturating_add(pl).saturating_add(pr);
        if kh == 0 || kw == 0 || sh == 0 || sw == 0 || self.c_out == 0 || hp < kh || wp < kw {
            return Err(NnError::BadParam);
        }
        // a window made only of padding would still be defined, but no network produces one
        if pt >= kh || pb >= kh || pl >= kw || pr >= kw {
            return Err(NnError::BadParam);
        }
        Ok(Shape::new(self.c_out, (hp - kh) / sh + 1, (wp - kw) / sw + 1))
    }
}

#[allow(clippy::too_many_arguments)]
fn check_conv2d(
    x: &[i8],
    xs: Shape,
    p: &Conv2dParams,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &[i8],
) -> Result<Shape, NnError> {
    check_tensor(x.len(), xs)?;
    check_zero_point(q.input_zero_point)?;
    let os = p.output_shape(xs)?;
    let k = p.kernel.0.saturating_mul(p.kernel.1).saturating_mul(xs.c);
    if k > MAX_REDUCTION {
        return Err(NnError::BadParam);
    }
    check_param(w.len(), p.c_out.saturating_mul(k))?;
    check_param(b.len(), p.c_out)?;
    check_param(q.requant.len(), p.c_out)?;
    check_tensor(out.len(), os)?;
    Ok(os)
}

/// General conv, reference: the ONNX definition as nested loops. Returns the output shape.
#[allow(clippy::too_many_arguments)]
pub fn conv2d_reference(
    x: &[i8],
    xs: Shape,
    p: &Conv2dParams,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_conv2d(x, xs, p, w, b, q, out)?;
    let (kh, kw) = p.kernel;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    for oy in 0..os.h {
        for ox in 0..os.w {
            for co in 0..os.c {
                let mut acc = 0i32;
                for ky in 0..kh {
                    for kx in 0..kw {
                        let iy = (oy * p.stride.0 + ky) as isize - p.pads[0] as isize;
                        let ix = (ox * p.stride.1 + kx) as isize - p.pads[1] as isize;
                        if iy < 0 || ix < 0 || iy >= xs.h as isize || ix >= xs.w as isize {
                            continue;
                        }
                        for ci in 0..xs.c {
                            let xv = x[xs.index(ci, iy as usize, ix as usize)] as i32;
                            let wv = w[((co * kh + ky) * kw + kx) * xs.c + ci] as i32;
                            acc += (xv - q.input_zero_point) * wv;
                        }
                    }
                }
                let acc = acc.saturating_add(b[co]);
                out[os.index(co, oy, ox)] = q.requant[co].to_i8(acc, q.output_zero_point, lo, hi);
            }
        }
    }
    Ok(os)
}

/// General conv, fast: the same integers as [`conv2d_reference`], from the kernel
/// `nn::dispatch` picks — on x86-64 with AVX2 for a 3×3 conv of a one-channel input (the
/// network's first layer) `nn::x86::conv1` (five `vpmaddwd` per 8 output channels and pixel),
/// else `nn::portable::conv` (one dot product per valid kernel row, contiguous in NHWC).
#[allow(clippy::too_many_arguments)]
pub fn conv2d_fast(
    x: &[i8],
    xs: Shape,
    p: &Conv2dParams,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_conv2d(x, xs, p, w, b, q, out)?;
    dispatch::conv2d(x, xs, p, w, b, q, out, os);
    Ok(os)
}

/// Output shape of the depthwise 3×3 conv, pad 1: `floor((h − 1) / stride) + 1`.
pub fn depthwise3x3_output_shape(input: Shape, stride: usize) -> Result<Shape, NnError> {
    if !(stride == 1 || stride == 2) || input.is_empty() {
        return Err(NnError::BadParam);
    }
    Ok(Shape::new(input.c, (input.h - 1) / stride + 1, (input.w - 1) / stride + 1))
}

#[allow(clippy::too_many_arguments)]
fn check_depthwise(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &[i8],
) -> Result<Shape, NnError> {
    check_tensor(x.len(), xs)?;
    check_zero_point(q.input_zero_point)?;
    let os = depthwise3x3_output_shape(xs, stride)?;
    check_param(w.len(), xs.c.saturating_mul(9))?;
    check_param(b.len(), xs.c)?;
    check_param(q.requant.len(), xs.c)?;
    check_tensor(out.len(), os)?;
    Ok(os)
}

/// Depthwise 3×3 conv (`group = C`, pad 1, stride 1 or 2), reference. Weights `[3][3][C]`.
#[allow(clippy::too_many_arguments)]
pub fn depthwise3x3_reference(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_depthwise(x, xs, stride, w, b, q, out)?;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    for oy in 0..os.h {
        for ox in 0..os.w {
            for c in 0..os.c {
                let mut acc = 0i32;
                for ky in 0..3 {
                    for kx in 0..3 {
                        let iy = (oy * stride + ky) as isize - 1;
                        let ix = (ox * stride + kx) as isize - 1;
                        if iy < 0 || ix < 0 || iy >= xs.h as isize || ix >= xs.w as isize {
                            continue;
                        }
                        let xv = x[xs.index(c, iy as usize, ix as usize)] as i32;
                        acc += (xv - q.input_zero_point) * w[(ky * 3 + kx) * xs.c + c] as i32;
                    }
                }
                let acc = acc.saturating_add(b[c]);
                out[os.index(c, oy, ox)] = q.requant[c].to_i8(acc, q.output_zero_point, lo, hi);
            }
        }
    }
    Ok(os)
}

/// Depthwise 3×3, fast: the same integers as [`depthwise3x3_reference`], from the kernel
/// `nn::dispatch` picks — on x86-64 with AVX2 `nn::x86::depthwise` (8 channels per vector;
/// interior pixels sum raw inputs from `bias − zp·Σw`, vectorised requantisation), on aarch64
/// `nn::arm64::depthwise` (NEON, 8 channels per vector), else `nn::portable::depthwise` (per
/// output pixel and 64-channel block, each valid tap adds a whole channel vector to a stack
/// accumulator, which auto-vectorises).
#[allow(clippy::too_many_arguments)]
pub fn depthwise3x3_fast(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_depthwise(x, xs, stride, w, b, q, out)?;
    dispatch::depthwise3x3(x, xs, stride, w, b, q, out, os);
    Ok(os)
}

/// Output channels per block of the packed 1×1 weights.
pub const PW_BLOCK: usize = 8;
/// Input channels per group of the packed 1×1 weights.
pub const PW_GROUP: usize = 4;

/// Bytes of packed 1×1 weights for `c_out × c_in`: both padded, `c_out` to a multiple of
/// [`PW_BLOCK`], `c_in` to a multiple of [`PW_GROUP`] (saturating, so absurd sizes fail the
/// length checks).
pub const fn pointwise_packed_len(c_out: usize, c_in: usize) -> usize {
    let co = c_out.div_ceil(PW_BLOCK).saturating_mul(PW_BLOCK);
    let ci = c_in.div_ceil(PW_GROUP).saturating_mul(PW_GROUP);
    co.saturating_mul(ci)
}

/// Position of weight `(co, ci)` in the packed 1×1 layout (see [`pack_pointwise`]).
#[inline]
pub const fn pointwise_packed_index(co: usize, ci: usize, c_in: usize) -> usize {
    let groups = c_in.div_ceil(PW_GROUP);
    (co / PW_BLOCK) * groups * (PW_BLOCK * PW_GROUP)
        + (ci / PW_GROUP) * (PW_BLOCK * PW_GROUP)
        + (co % PW_BLOCK) * PW_GROUP
        + ci % PW_GROUP
}

/// Packs `O·I` 1×1 weights (`w[co·c_in + ci]`) into the layout the pointwise kernels read:
/// `[c_out/8][c_in/4][8][4]` — blocks of 8 output channels; within a block, per group of 4
/// input channels, 32 bytes: channel 0's four weights, channel 1's, … (the 32 bytes of one
/// 256-bit register: the four `k` of a group sit in one 32-bit lane per channel, as
/// `vpdpbusd` / `sdot` / pairs for `vpmaddwd` want them). Padding (channels `≥ c_out`, inputs
/// `≥ c_in`) is zero; the model parser rejects blobs where it is not.
pub fn pack_pointwise(w: &[i8], c_out: usize, c_in: usize, out: &mut [i8]) -> Result<(), NnError> {
    check_param(w.len(), c_out.saturating_mul(c_in))?;
    check_param(out.len(), pointwise_packed_len(c_out, c_in))?;
    out.fill(0);
    for (co, row) in w.chunks_exact(c_in.max(1)).enumerate().take(c_out) {
        for (ci, &v) in row.iter().enumerate() {
            out[pointwise_packed_index(co, ci, c_in)] = v;
        }
    }
    Ok(())
}

/// True when the padding of packed 1×1 weights is zero (what [`pack_pointwise`] writes; the
/// fast kernels rely on it).
pub fn pointwise_padding_is_zero(w: &[i8], c_out: usize, c_in: usize) -> bool {
    if w.len() != pointwise_packed_len(c_out, c_in) {
        return false;
    }
    let groups = c_in.div_ceil(PW_GROUP);
    let chunk = PW_BLOCK * PW_GROUP;
    for (block, panel) in w.chunks_exact((groups * chunk).max(1)).enumerate() {
        let valid_co = (c_out - block * PW_BLOCK).min(PW_BLOCK);
        for (g, lanes) in panel.chunks_exact(chunk).enumerate() {
            let valid_k = if g + 1 == groups { c_in - g * PW_GROUP } else { PW_GROUP };
            if valid_co == PW_BLOCK && valid_k == PW_GROUP {
                continue;
            }
            for (j, lane) in lanes.chunks_exact(PW_GROUP).enumerate() {
                let from = if j < valid_co { valid_k } else { 0 };
                if lane[from..].iter().any(|&v| v != 0) {
                    return false;
                }
            }
        }
    }
    true
}

fn check_pointwise(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &[i8],
) -> Result<Shape, NnError> {
    check_tensor(x.len(), xs)?;
    check_zero_point(q.input_zero_point)?;
    let c_out = b.len();
    if c_out == 0 || xs.c > MAX_REDUCTION {
        return Err(NnError::BadParam);
    }
    let os = Shape::new(c_out, xs.h, xs.w);
    check_param(w.len(), pointwise_packed_len(c_out, xs.c))?;
    check_param(q.requant.len(), c_out)?;
    check_tensor(out.len(), os)?;
    Ok(os)
}

/// Pointwise 1×1 conv (stride 1, no padding), reference. The number of output channels is
/// `b.len()`; weights are packed ([`pack_pointwise`]), read through
/// [`pointwise_packed_index`].
pub fn pointwise_reference(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_pointwise(x, xs, w, b, q, out)?;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    for y in 0..os.h {
        for xx in 0..os.w {
            for co in 0..os.c {
                let mut acc = 0i32;
                for ci in 0..xs.c {
                    let xv = x[xs.index(ci, y, xx)] as i32;
                    let wv = w[pointwise_packed_index(co, ci, xs.c)] as i32;
                    acc += (xv - q.input_zero_point) * wv;
                }
                let acc = acc.saturating_add(b[co]);
                out[os.index(co, y, xx)] = q.requant[co].to_i8(acc, q.output_zero_point, lo, hi);
            }
        }
    }
    Ok(os)
}

/// Pointwise 1×1 conv, fast: an int8 GEMM `out[p][co] = Σ_ci (x[p][ci] − zp)·w[co][ci]` with
/// `i32` accumulation over the packed weights, the same integers as [`pointwise_reference`],
/// from the kernel `nn::dispatch` picks — on x86-64 with AVX2 `nn::x86::pointwise`'s
/// register-tiled GEMM (AVX-512 VNNI where the CPU has it) with vectorised requantisation,
/// on aarch64 `nn::arm64::pointwise` (NEON, 8-pixel tiles), else `nn::portable::pointwise`.
pub fn pointwise_fast(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_pointwise(x, xs, w, b, q, out)?;
    dispatch::pointwise(x, xs, w, b, q, out);
    Ok(os)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::portable::pointwise::PW_STAGE;
    use crate::nn::testutil::{kernel_equivalence, max_diff, quantise, KernelCase, Rng};
    use std::format;
    use std::string::String;
    use std::vec;
    use std::vec::Vec;

    /// Random per-channel quantisation for a reduction of length `k`: returns
    /// (s_in, zp_in, s_w, s_out, zp_out, relu, requant).
    struct Q {
        s_in: f64,
        zp_in: i32,
        s_w: Vec<f64>,
        s_out: f64,
        zp_out: i32,
        relu: bool,
        rq: Vec<Requant>,
    }

    fn rand_q(rng: &mut Rng, c_out: usize, k: usize) -> Q {
        let s_in = rng.f64(0.005, 0.05);
        let s_w: Vec<f64> = (0..c_out).map(|_| rng.f64(0.001, 0.02)).collect();
        // typical |acc| ~ 70·127/2·sqrt(k); aim the output range near it, sometimes saturating
        let s_out = s_in * 0.01 * 4000.0 * (k as f64).sqrt() / 127.0 * rng.f64(0.3, 3.0);
        let rq = s_w.iter().map(|&sw| Requant::from_scale(s_in * sw / s_out)).collect();
        Q { s_in, zp_in: rng.zp(), s_w, s_out, zp_out: rng.zp(), relu: rng.int(0, 1) == 1, rq }
    }

    impl Q {
        fn conv(&self) -> ConvQuant<'_> {
            ConvQuant {
                input_zero_point: self.zp_in,
                output_zero_point: self.zp_out,
                requant: &self.rq,
                relu: self.relu,
            }
        }
        /// The float engine's int8 output for a real accumulator of channel `co`.
        fn expect(&self, real: f64) -> i32 {
            let (lo, hi) = clamp_range(self.zp_out, self.relu);
            let real = if self.relu { real.max(0.0) } else { real };
            quantise(real, self.s_out, self.zp_out, lo, hi)
        }
    }

    /// Float conv on dequantised tensors (NHWC, OHWI), any groups-1 geometry.
    #[allow(clippy::too_many_arguments)]
    fn float_conv(
        x: &[i8],
        xs: Shape,
        os: Shape,
        (kh, kw): (usize, usize),
        (sh, sw): (usize, usize),
        (pt, pl): (usize, usize),
        depthwise: bool,
        w: &[i8],
        b: &[i32],
        q: &Q,
    ) -> Vec<i32> {
        let mut out = vec![0; os.len()];
        for oy in 0..os.h {
            for ox in 0..os.w {
                for co in 0..os.c {
                    let sw_c = q.s_w[co];
                    let mut y = b[co] as f64 * q.s_in * sw_c;
                    for ky in 0..kh {
                        for kx in 0..kw {
                            let iy = (oy * sh + ky) as isize - pt as isize;
                            let ix = (ox * sw + kx) as isize - pl as isize;
                            if iy < 0 || ix < 0 || iy >= xs.h as isize || ix >= xs.w as isize {
                                continue;
                            }
                            let cis: Vec<usize> =
                                if depthwise { vec![co] } else { (0..xs.c).collect() };
                            for ci in cis {
                                let xr = (x[xs.index(ci, iy as usize, ix as usize)] as i32
                                    - q.zp_in) as f64
                                    * q.s_in;
                                let wi = if depthwise {
                                    (ky * kw + kx) * xs.c + co
                                } else {
                                    ((co * kh + ky) * kw + kx) * xs.c + ci
                                };
                                y += xr * w[wi] as f64 * sw_c;
                            }
                        }
                    }
                    out[os.index(co, oy, ox)] = q.expect(y);
                }
            }
        }
        out
    }

    /// Packs `O·I` weights for the pointwise kernels.
    fn packed(w: &[i8], c_out: usize, c_in: usize) -> Vec<i8> {
        let mut p = vec![0i8; pointwise_packed_len(c_out, c_in)];
        pack_pointwise(w, c_out, c_in, &mut p).unwrap();
        p
    }

    /// Random biases in `±bmax`.
    fn biases(rng: &mut Rng, n: usize, bmax: i64) -> Vec<i32> {
        (0..n).map(|_| rng.int(-bmax, bmax) as i32).collect()
    }

    /// A general conv case (OHWI weights); `float`: also check the reference against floats.
    struct ConvCase {
        x: Vec<i8>,
        xs: Shape,
        p: Conv2dParams,
        os: Shape,
        w: Vec<i8>,
        b: Vec<i32>,
        q: Q,
        float: bool,
    }

    impl ConvCase {
        /// Input, weights, biases in `±bmax` and quantisation drawn in that order.
        fn new(rng: &mut Rng, xs: Shape, p: Conv2dParams, bmax: i64, float: bool) -> Option<Self> {
            let os = p.output_shape(xs).ok()?;
            let k = p.kernel.0 * p.kernel.1 * xs.c;
            let x = rng.i8s(xs.len());
            let w = rng.weights(p.c_out * k);
            let b = biases(rng, p.c_out, bmax);
            let q = rand_q(rng, p.c_out, k);
            Some(Self { x, xs, p, os, w, b, q, float })
        }
    }

    impl KernelCase for ConvCase {
        fn out_shape(&self) -> Shape {
            self.os
        }
        fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            conv2d_reference(&self.x, self.xs, &self.p, &self.w, &self.b, &self.q.conv(), out)
        }
        fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            conv2d_fast(&self.x, self.xs, &self.p, &self.w, &self.b, &self.q.conv(), out)
        }
        fn describe(&self) -> String {
            format!("{:?} {:?}", self.xs, self.p)
        }
        fn check(&self, r: &[i8]) {
            if self.float {
                let (p, pads) = (&self.p, (self.p.pads[0], self.p.pads[1]));
                let (x, w, b, q) = (&self.x, &self.w, &self.b, &self.q);
                let e = float_conv(x, self.xs, self.os, p.kernel, p.stride, pads, false, w, b, q);
                assert!(max_diff(r, &e) <= 1, "{}", self.describe());
            }
        }
    }

    /// Random general-conv geometry for `kernel`: strides 1–2, each pad below the kernel.
    fn rand_conv(rng: &mut Rng, c_out: usize, kernel: (usize, usize)) -> Conv2dParams {
        Conv2dParams {
            c_out,
            kernel,
            stride: (rng.usize(1, 2), rng.usize(1, 2)),
            pads: [
                rng.usize(0, kernel.0 - 1),
                rng.usize(0, kernel.1 - 1),
                rng.usize(0, kernel.0 - 1),
                rng.usize(0, kernel.1 - 1),
            ],
        }
    }

    /// A depthwise 3×3 case; `float`: also check the reference against floats.
    struct DwCase {
        x: Vec<i8>,
        xs: Shape,
        stride: usize,
        os: Shape,
        w: Vec<i8>,
        b: Vec<i32>,
        q: Q,
        float: bool,
    }

    impl DwCase {
        /// Input, weights, biases in `±bmax` and quantisation drawn in that order.
        fn new(rng: &mut Rng, xs: Shape, stride: usize, bmax: i64, float: bool) -> Self {
            let os = depthwise3x3_output_shape(xs, stride).unwrap();
            let x = rng.i8s(xs.len());
            let w = rng.weights(9 * xs.c);
            let b = biases(rng, xs.c, bmax);
            let q = rand_q(rng, xs.c, 9);
            Self { x, xs, stride, os, w, b, q, float }
        }
    }

    impl KernelCase for DwCase {
        fn out_shape(&self) -> Shape {
            self.os
        }
        fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            let (x, w, b, q) = (&self.x, &self.w, &self.b, self.q.conv());
            depthwise3x3_reference(x, self.xs, self.stride, w, b, &q, out)
        }
        fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            let (x, w, b, q) = (&self.x, &self.w, &self.b, self.q.conv());
            depthwise3x3_fast(x, self.xs, self.stride, w, b, &q, out)
        }
        fn describe(&self) -> String {
            format!("{:?} stride {}", self.xs, self.stride)
        }
        fn check(&self, r: &[i8]) {
            if self.float {
                let s = (self.stride, self.stride);
                let (x, w, b, q) = (&self.x, &self.w, &self.b, &self.q);
                let e = float_conv(x, self.xs, self.os, (3, 3), s, (1, 1), true, w, b, q);
                assert!(max_diff(r, &e) <= 1, "{}", self.describe());
            }
        }
    }

    /// A pointwise case: `O·I` weights (for the float check) and their packed form.
    struct PwCase {
        x: Vec<i8>,
        xs: Shape,
        w: Vec<i8>,
        wp: Vec<i8>,
        b: Vec<i32>,
        q: Q,
        float: bool,
    }

    impl PwCase {
        /// Input, weights, biases in `±bmax` and quantisation drawn in that order.
        fn new(rng: &mut Rng, xs: Shape, c_out: usize, bmax: i64, float: bool) -> Self {
            let x = rng.i8s(xs.len());
            let w = rng.weights(c_out * xs.c);
            let wp = packed(&w, c_out, xs.c);
            let b = biases(rng, c_out, bmax);
            let q = rand_q(rng, c_out, xs.c);
            Self { x, xs, w, wp, b, q, float }
        }
    }

    impl KernelCase for PwCase {
        fn out_shape(&self) -> Shape {
            Shape::new(self.b.len(), self.xs.h, self.xs.w)
        }
        fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            pointwise_reference(&self.x, self.xs, &self.wp, &self.b, &self.q.conv(), out)
        }
        fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            pointwise_fast(&self.x, self.xs, &self.wp, &self.b, &self.q.conv(), out)
        }
        fn describe(&self) -> String {
            format!("{:?} -> {} channels", self.xs, self.b.len())
        }
        fn check(&self, r: &[i8]) {
            if self.float {
                let (x, w, b, q) = (&self.x, &self.w, &self.b, &self.q);
                let os = self.out_shape();
                let e = float_conv(x, self.xs, os, (1, 1), (1, 1), (0, 0), false, w, b, q);
                assert!(max_diff(r, &e) <= 1, "{}", self.describe());
            }
        }
    }

    kernel_equivalence!(conv2d_fast_equals_reference_and_float, 0xc0, 400, |rng, i| {
        // every 3rd case a 3x3 conv of a one-channel map (the first layer's x86 kernel), with
        // up to 40 output channels
        let first = i % 3 == 0;
        let c_in = if first { 1 } else { rng.usize(1, 5) };
        // first-layer maps up to 45 wide: runs of 8 stride-2 pixels take 16-byte loads
        let xs = Shape::new(c_in, rng.usize(1, 11), rng.usize(1, if first { 45 } else { 11 }));
        let kernel = if first { (3, 3) } else { (rng.usize(1, 4), rng.usize(1, 4)) };
        // every 7th other case more output channels than the portable kernel's channel-vector
        // form takes (64)
        let c_out = if first {
            rng.usize(1, 40)
        } else if i % 7 == 1 {
            rng.usize(60, 70)
        } else {
            rng.usize(1, 7)
        };
        let p = rand_conv(rng, c_out, kernel);
        // every 10th case: huge biases (the scalar requantisation path)
        let bmax = if i % 10 == 9 { 1 << 30 } else { 20_000 };
        ConvCase::new(rng, xs, p, bmax, bmax <= 20_000)
    });

    kernel_equivalence!(depthwise_fast_equals_reference_and_float, 0xd3, 300, |rng, i| {
        // channel counts straddle the 64-channel accumulator block and the 8-lane groups
        let c = if i % 5 == 0 { rng.usize(60, 140) } else { rng.usize(1, 19) };
        let xs = Shape::new(c, rng.usize(1, 12), rng.usize(1, 12));
        let stride = rng.usize(1, 2);
        // every 10th case: huge biases (the scalar requantisation path)
        let bmax = if i % 10 == 9 { 1 << 30 } else { 5000 };
        Some(DwCase::new(rng, xs, stride, bmax, bmax <= 5000))
    });

    kernel_equivalence!(pointwise_fast_equals_reference_and_float, 0x11, 300, |rng, i| {
        // a few rows wider than the portable kernel's stage (and the x86 kernels' staged tiles)
        let c_in =
            if i % 50 == 0 { rng.usize(PW_STAGE - 2, PW_STAGE + 40) } else { rng.usize(1, 40) };
        let xs = Shape::new(c_in, rng.usize(1, 7), rng.usize(1, 7));
        let c_out = rng.usize(1, 40);
        // every 10th case: huge biases (the scalar requantisation path)
        let bmax = if i % 10 == 9 { 1 << 30 } else { 20_000 };
        Some(PwCase::new(rng, xs, c_out, bmax, bmax < 1 << 30))
    });

    /// The depthwise shapes of the 192×640 network (`benches/nn.rs`), channels as there, maps
    /// smaller (odd and even sizes, for the stride-2 borders).
    const DW_WORKLOAD: [(usize, usize); 8] =
        [(128, 1), (148, 1), (32, 2), (48, 2), (64, 1), (64, 2), (96, 2), (96, 1)];
    /// The maps of the workload-shape tests.
    const WORKLOAD_MAPS: [(usize, usize); 3] = [(6, 20), (7, 13), (12, 40)];

    kernel_equivalence!(depthwise_workload_shapes_are_bit_equal, 0xd4, 24, |rng, i| {
        let (c, stride) = DW_WORKLOAD[i / 3];
        let (h, w) = WORKLOAD_MAPS[i % 3];
        Some(DwCase::new(rng, Shape::new(c, h, w), stride, 5000, false))
    });

    kernel_equivalence!(first_conv_workload_shapes_are_bit_equal, 0xd5, 3, |rng, i| {
        // the first layer: 1 -> 32, 3x3, stride 2, pad 1 (192x640 in the network)
        let (h, w) = [(12, 40), (13, 41), (24, 17)][i];
        let p = Conv2dParams { c_out: 32, kernel: (3, 3), stride: (2, 2), pads: [1; 4] };
        ConvCase::new(rng, Shape::new(1, h, w), p, 100_000, false)
    });

    /// The 1×1 shapes `(c_in, c_out)` of the 192×640 network (`benches/nn.rs`).
    const PW_WORKLOAD: [(usize, usize); 16] = [
        (128, 32),
        (128, 11),
        (128, 128),
        (128, 148),
        (148, 148),
        (256, 64),
        (256, 128),
        (32, 48),
        (384, 96),
        (48, 64),
        (592, 128),
        (64, 64),
        (64, 96),
        (64, 128),
        (96, 148),
        (96, 96),
    ];

    kernel_equivalence!(pointwise_workload_shapes_are_bit_equal, 0x12, 16, |rng, i| {
        // on smaller maps
        let (c_in, c_out) = PW_WORKLOAD[i];
        let xs = Shape::new(c_in, rng.usize(1, 6), rng.usize(1, 21));
        Some(PwCase::new(rng, xs, c_out, 20_000, false))
    });

    kernel_equivalence!(depthwise_extreme_operands_are_bit_equal, 0xd7, 40, |rng, i| {
        // inputs at −128 / 127 and weights at ±127 (even cases; the largest pairs of products
        // `arm64::depthwise` adds in `i16`) or with −128 among them (odd cases: its `i32` path)
        let xs = Shape::new(rng.usize(8, 40), rng.usize(3, 9), rng.usize(3, 9));
        let stride = rng.usize(1, 2);
        let mut case = DwCase::new(rng, xs, stride, 5000, false);
        for v in &mut case.x {
            *v = if rng.usize(0, 3) == 0 { 127 } else { -128 };
        }
        let choices: &[i8] = if i % 2 == 0 { &[-127, 127] } else { &[-128, -127, 127] };
        for v in &mut case.w {
            *v = choices[rng.usize(0, choices.len() - 1)];
        }
        Some(case)
    });

    kernel_equivalence!(depthwise_wide_layers_are_bit_equal, 0xd6, 12, |rng, _| {
        // more than 256 channels: several passes of the x86 kernel's group constants, and the
        // portable kernel's scalar requantisation (its lane-form table holds 256 channels)
        let xs = Shape::new(rng.usize(257, 300), rng.usize(1, 7), rng.usize(1, 9));
        let stride = rng.usize(1, 2);
        Some(DwCase::new(rng, xs, stride, 5000, true))
    });

    kernel_equivalence!(first_conv_many_channels_are_bit_equal, 0xc1, 30, |rng, _| {
        // more than 64 output channels: several passes of the x86 kernel's 8 groups; rows up
        // to 60 wide for several runs of 8 stride-2 pixels
        let xs = Shape::new(1, rng.usize(1, 12), rng.usize(1, 60));
        let c_out = rng.usize(41, 80);
        let p = rand_conv(rng, c_out, (3, 3));
        ConvCase::new(rng, xs, p, 20_000, true)
    });

    kernel_equivalence!(first_conv_wide_rows_are_bit_equal, 0xc2, 8, |rng, i| {
        // output rows wider than `arm64::conv1`'s 64-pixel chunk (several chunks and a short
        // last one), stride 1 and 2, up to 64 channels
        let xs = Shape::new(1, rng.usize(2, 6), rng.usize(65, 200));
        let s = 1 + i % 2;
        let p =
            Conv2dParams { c_out: rng.usize(1, 64), kernel: (3, 3), stride: (s, s), pads: [1; 4] };
        ConvCase::new(rng, xs, p, 20_000, true)
    });

    kernel_equivalence!(pointwise_wide_layers_are_bit_equal, 0x13, 12, |rng, i| {
        // more than 256 output channels (several passes of the AVX2 kernel's 32 blocks), or
        // rows wider than every staged tile (the unstaged x86 paths, the portable wide path)
        let (c_in, c_out) = if i % 2 == 0 {
            (rng.usize(1, 40), rng.usize(257, 300))
        } else {
            (rng.usize(PW_STAGE + 1, PW_STAGE + 80), rng.usize(1, 30))
        };
        let xs = Shape::new(c_in, rng.usize(1, 4), rng.usize(1, 9));
        Some(PwCase::new(rng, xs, c_out, 20_000, true))
    });

    #[test]
    fn pointwise_packing_round_trips() {
        let mut rng = Rng::new(0x9a);
        for _ in 0..50 {
            let (co, ci) = (rng.usize(1, 30), rng.usize(1, 30));
            let w = rng.weights(co * ci);
            let p = packed(&w, co, ci);
            assert!(pointwise_padding_is_zero(&p, co, ci));
            for o in 0..co {
                for i in 0..ci {
                    assert_eq!(p[pointwise_packed_index(o, i, ci)], w[o * ci + i]);
                }
            }
            if p.len() > co * ci {
                // some byte is padding: a non-zero there is caught
                let pad = (0..p.len())
                    .find(|&j| {
                        (0..co).all(|o| (0..ci).all(|i| pointwise_packed_index(o, i, ci) != j))
                    })
                    .unwrap();
                let mut bad = p.clone();
                bad[pad] = 1;
                assert!(!pointwise_padding_is_zero(&bad, co, ci));
            }
        }
        assert_eq!(
            pack_pointwise(&[0; 5], 2, 3, &mut [0; 32]),
            Err(NnError::ParamLength { need: 6, got: 5 })
        );
    }

    #[test]
    fn bad_shapes_are_errors_not_panics() {
        let q = ConvQuant {
            input_zero_point: 0,
            output_zero_point: 0,
            requant: &[Requant::IDENTITY; 2],
            relu: false,
        };
        let xs = Shape::new(2, 4, 4);
        let x = [0i8; 32];
        let mut out = [0i8; 32];
        let b = [0i32; 2];
        assert_eq!(
            pointwise_fast(&x[..31], xs, &[0; 4], &b, &q, &mut out),
            Err(NnError::BufferTooSmall { need: 32, got: 31 })
        );
        let bad_zp = ConvQuant { input_zero_point: 128, ..q };
        assert_eq!(pointwise_fast(&x, xs, &[0; 32], &b, &bad_zp, &mut out), Err(NnError::BadParam));
        assert_eq!(
            depthwise3x3_reference(&x, xs, 1, &[0; 18], &b, &bad_zp, &mut out),
            Err(NnError::BadParam)
        );
        assert_eq!(
            pointwise_fast(&x, xs, &[0; 3], &b, &q, &mut out),
            Err(NnError::ParamLength { need: 32, got: 3 })
        );
        assert_eq!(
            depthwise3x3_fast(&x, xs, 3, &[0; 18], &b, &q, &mut out),
            Err(NnError::BadParam)
        );
        assert_eq!(
            depthwise3x3_fast(&x, xs, 1, &[0; 18], &b, &q, &mut out[..10]),
            Err(NnError::BufferTooSmall { need: 32, got: 10 })
        );
        // absurd geometry: an error, not an overflow
        let huge = Conv2dParams {
            c_out: usize::MAX,
            kernel: (4, 4),
            stride: (1, 1),
            pads: [3, 3, usize::MAX, 3],
        };
        assert!(conv2d_reference(&x, xs, &huge, &[0; 4], &b, &q, &mut out).is_err());
        let huge = Conv2dParams { c_out: 2, kernel: (usize::MAX, 3), stride: (1, 1), pads: [0; 4] };
        assert!(conv2d_fast(&x, xs, &huge, &[0; 4], &b, &q, &mut out).is_err());
        let p = Conv2dParams { c_out: 2, kernel: (5, 5), stride: (1, 1), pads: [0; 4] };
        assert_eq!(conv2d_fast(&x, xs, &p, &[0; 100], &b, &q, &mut out), Err(NnError::BadParam));
        assert_eq!(
            conv2d_reference(&x, Shape::new(0, 4, 4), &p, &[], &b, &q, &mut out),
            Err(NnError::BadParam)
        );
    }

    /// Wall time of the fast kernels vs the reference in the same run (not asserted; the
    /// figure that counts is the ratio, cores here are shared).
    #[test]
    fn timing_pointwise_and_depthwise_96x48x128() {
        use std::time::Instant;
        let mut rng = Rng::new(5);
        let xs = Shape::new(128, 48, 96);
        let x = rng.i8s(xs.len());
        let q = rand_q(&mut rng, 128, 128);
        let b: Vec<i32> = (0..128).map(|_| rng.int(-2000, 2000) as i32).collect();
        let wp = packed(&rng.weights(128 * 128), 128, 128);
        let wd = rng.weights(9 * 128);
        let mut r = vec![0i8; xs.len()];
        let mut f = vec![0i8; xs.len()];
        // best of three: the cores are shared, the minimum is the least disturbed run
        let time = |g: &mut dyn FnMut()| {
            (0..3)
                .map(|_| {
                    let t = Instant::now();
                    g();
                    t.elapsed().as_secs_f64()
                })
                .fold(f64::INFINITY, f64::min)
        };
        let tr = time(&mut || {
            pointwise_reference(&x, xs, &wp, &b, &q.conv(), &mut r).unwrap();
        });
        let tf = time(&mut || {
            pointwise_fast(&x, xs, &wp, &b, &q.conv(), &mut f).unwrap();
        });
        assert!(r == f, "pointwise fast != reference");
        std::println!(
            "pointwise 128->128 on 96x48: reference {:.2} ms, fast {:.2} ms, ratio {:.1}x",
            tr * 1e3,
            tf * 1e3,
            tr / tf
        );
        let tr = time(&mut || {
            depthwise3x3_reference(&x, xs, 1, &wd, &b, &q.conv(), &mut r).unwrap();
        });
        let tf = time(&mut || {
            depthwise3x3_fast(&x, xs, 1, &wd, &b, &q.conv(), &mut f).unwrap();
        });
        assert!(r == f, "depthwise fast != reference");
        std::println!(
            "depthwise 3x3 s1 128ch on 96x48: reference {:.2} ms, fast {:.2} ms, ratio {:.1}x",
            tr * 1e3,
            tf * 1e3,
            tr / tf
        );
    }
}
