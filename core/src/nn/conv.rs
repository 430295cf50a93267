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
//! The fast kernels compute the same integers: valid tap ranges are hoisted out of the inner
//! loops, which run over contiguous NHWC slices (`kw_valid · c_in` input bytes per kernel row for
//! the general conv, channel vectors for depthwise, one input row per pixel for the 1×1 GEMM).
//! On x86-64 with AVX2 the 1×1 GEMM, the depthwise conv and the one-channel 3×3 conv run as
//! `nn::simd` kernels (see there); elsewhere, and whenever an op's accumulators could
//! saturate the plain vector arithmetic ([`super::quant::fits_simd_requant`], never for a real
//! network), the portable ones. Stack: the portable depthwise kernel a 64-channel `i32`
//! accumulator block and lane-form requantisers (6.3 KiB), the portable GEMM an unpacked
//! 8-channel weight panel and a staged row (10 KiB).
//!
//! **1×1 weights are packed** ([`pack_pointwise`], `[⌈O/8⌉][⌈I/4⌉][8][4]`), the layout the
//! model blob stores; the reference reads them through [`pointwise_packed_index`].

use super::quant::{clamp_range, fits_simd_requant as fits_requant_lanes, Lanes8};
#[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
use super::quant::{fits_simd_requant, simd_allowed};
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

/// `Σ (x − zp)·w` over two equally long slices; the shape of loop LLVM vectorises.
#[inline]
fn dot(x: &[i8], w: &[i8], zp: i32) -> i32 {
    x.iter().zip(w).map(|(&a, &b)| (a as i32 - zp) * b as i32).sum()
}

/// The valid tap range `[k0, k1)` of a window starting at `start − pad` on an axis of `n`.
#[inline]
fn tap_range(o: usize, stride: usize, pad: usize, k: usize, n: usize) -> (usize, usize) {
    let start = o * stride;
    let k0 = pad.saturating_sub(start);
    let k1 = k.min((n + pad).saturating_sub(start));
    (k0, k1.max(k0))
}

/// General conv, fast: per output pixel the valid kernel rows are contiguous NHWC runs of
/// `kw_valid · c_in` bytes in both input and weights, so each is one dot product. On x86-64
/// with AVX2 a 3×3 conv of a one-channel input (the network's first layer) takes
/// `nn::simd`'s kernel: five `vpmaddwd` per 8 output channels and pixel.
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
    let (kh, kw) = p.kernel;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    if simd_allowed()
        && xs.c == 1
        && p.kernel == (3, 3)
        && fits_simd_requant(9 * 255 * 127, b, q.requant)
    {
        let a = super::simd::Conv1 {
            x,
            h: xs.h,
            w: xs.w,
            oh: os.h,
            ow: os.w,
            stride: p.stride,
            pad: (p.pads[0], p.pads[1]),
            wt: w,
            bias: b,
            requant: q.requant,
            zp: q.input_zero_point,
            zo: q.output_zero_point,
            lo,
        };
        super::simd::conv1(&a, out);
        return Ok(os);
    }
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

/// Channels per accumulator block of the fast depthwise kernel.
const DW_BLOCK: usize = 64;
/// Channel groups of 8 whose requantisers the portable depthwise kernel keeps in lane form.
const DW_LANE_GROUPS: usize = 32;

/// Depthwise 3×3, fast. On x86-64 with AVX2: `nn::simd`'s kernel (8 channels per vector;
/// interior pixels sum raw inputs from `bias − zp·Σw`, vectorised requantisation). Portable:
/// per output pixel and 64-channel block, each valid tap adds a whole channel vector
/// (`x[iy, ix, c..]·w[ky, kx, c..]`) to a stack accumulator, which auto-vectorises.
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
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    if simd_allowed() && fits_simd_requant(9 * 255 * 127, b, q.requant) {
        let a = super::simd::Dw {
            x,
            h: xs.h,
            w: xs.w,
            c: xs.c,
            stride,
            wt: w,
            bias: b,
            requant: q.requant,
            zp: q.input_zero_point,
            zo: q.output_zero_point,
            lo,
        };
        super::simd::depthwise(&a, out);
        return Ok(os);
    }
    depthwise3x3_portable(x, xs, stride, w, b, q, out, os, (lo, hi));
    Ok(os)
}

/// The portable depthwise kernel (see [`depthwise3x3_fast`]).
#[allow(clippy::too_many_arguments)]
fn depthwise3x3_portable(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
    (lo, hi): (i32, i32),
) {
    let c = xs.c;
    let zp = q.input_zero_point;
    let out = &mut out[..os.len()];
    let mut acc = [0i32; DW_BLOCK];
    // the requantisers of up to 256 channels in lane form (6 KiB), when the vector form holds
    let mut l8 = [Lanes8::new(&[]); DW_LANE_GROUPS];
    let lanes =
        (c <= 8 * DW_LANE_GROUPS && fits_requant_lanes(9 * 255 * 127, b, q.requant)).then(|| {
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
                if let Some(l8) = &lanes {
                    // 8 channels at a time, branch-free (the biases cannot saturate here)
                    for (j, (o, a)) in opix[c0..c0 + n].chunks_mut(8).zip(acc.chunks(8)).enumerate()
                    {
                        let ch = c0 + 8 * j;
                        let v: [i32; 8] = core::array::from_fn(|t| {
                            a.get(t).copied().unwrap_or(0) + b.get(ch + t).copied().unwrap_or(0)
                        });
                        let r = l8[ch / 8].requant(&v, q.output_zero_point, lo, hi);
                        o.copy_from_slice(&r[..o.len()]);
                    }
                } else {
                    for (((o, &a), &bias), rq) in opix[c0..c0 + n]
                        .iter_mut()
                        .zip(acc.iter())
                        .zip(&b[c0..c0 + n])
                        .zip(&q.requant[c0..c0 + n])
                    {
                        *o = rq.to_i8(a.saturating_add(bias), q.output_zero_point, lo, hi);
                    }
                }
                c0 += n;
            }
        }
    }
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
/// `i32` accumulation over the packed weights. On x86-64 with AVX2 it is `nn::simd`'s
/// register-tiled kernel (AVX-512 VNNI where the CPU has it) with vectorised requantisation;
/// elsewhere (and for accumulators too large for the vector requantisation) the portable
/// kernel below.
pub fn pointwise_fast(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_pointwise(x, xs, w, b, q, out)?;
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    if simd_allowed() && fits_simd_requant(xs.c as i64 * 255 * 127, b, q.requant) {
        let (lo, _) = clamp_range(q.output_zero_point, q.relu);
        let a = super::simd::Pw {
            x,
            p: xs.h * xs.w,
            k: xs.c,
            w,
            bias: b,
            requant: q.requant,
            zp: q.input_zero_point,
            zo: q.output_zero_point,
            lo,
        };
        super::simd::pointwise(&a, out);
        return Ok(os);
    }
    pointwise_portable(x, xs, w, b, q, out);
    Ok(os)
}

/// Longest input row the portable pointwise kernel stages as `i32` (4 KiB of stack); wider
/// rows are staged and summed in pieces.
const PW_STAGE: usize = 1024;

/// The portable GEMM. Per 8-channel block the packed panel is unpacked once into 8 plain
/// weight rows (stack, up to 1024 inputs each); per pixel the input row is staged as `i16`
/// minus the zero point and multiplied with four weight rows at a time in one zipped loop (the
/// shape of loop the auto-vectoriser turns into `pmaddwd` / `smlal`), then the block is
/// requantised 8 lanes at a time ([`Lanes8`], branch-free). Rows wider than 1024 take
/// [`pointwise_portable_wide`].
fn pointwise_portable(x: &[i8], xs: Shape, w: &[i8], b: &[i32], q: &ConvQuant<'_>, out: &mut [i8]) {
    let ci = xs.c;
    if ci > PW_STAGE {
        return pointwise_portable_wide(x, xs, w, b, q, out);
    }
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let co = b.len();
    let zp = q.input_zero_point;
    let zo = q.output_zero_point;
    let lanes = PW_BLOCK * PW_GROUP;
    let panel = ci.div_ceil(PW_GROUP) * lanes;
    let vector = fits_requant_lanes(ci as i64 * 255 * 127, b, q.requant);
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
fn pointwise_portable_wide(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::quant::portable;
    use crate::nn::testutil::{max_diff, quantise, Rng};
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

    #[test]
    fn conv2d_fast_equals_reference_and_float() {
        let mut rng = Rng::new(0xc0);
        for i in 0..400 {
            // every 3rd case a 3x3 conv of a one-channel map (the first layer's SIMD kernel),
            // with up to 40 output channels
            let first = i % 3 == 0;
            let c_in = if first { 1 } else { rng.usize(1, 5) };
            // first-layer maps up to 45 wide: runs of 8 stride-2 pixels take 16-byte loads
            let xs = Shape::new(c_in, rng.usize(1, 11), rng.usize(1, if first { 45 } else { 11 }));
            let kernel = if first { (3, 3) } else { (rng.usize(1, 4), rng.usize(1, 4)) };
            let p = Conv2dParams {
                c_out: if first { rng.usize(1, 40) } else { rng.usize(1, 7) },
                kernel,
                stride: (rng.usize(1, 2), rng.usize(1, 2)),
                pads: [
                    rng.usize(0, kernel.0 - 1),
                    rng.usize(0, kernel.1 - 1),
                    rng.usize(0, kernel.0 - 1),
                    rng.usize(0, kernel.1 - 1),
                ],
            };
            let Ok(os) = p.output_shape(xs) else { continue };
            let k = kernel.0 * kernel.1 * xs.c;
            let x = rng.i8s(xs.len());
            let w = rng.weights(p.c_out * k);
            // every 10th case: huge biases (the scalar requantisation path)
            let bmax = if i % 10 == 9 { 1 << 30 } else { 20_000 };
            let b: Vec<i32> = (0..p.c_out).map(|_| rng.int(-bmax, bmax) as i32).collect();
            let q = rand_q(&mut rng, p.c_out, k);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            assert_eq!(conv2d_reference(&x, xs, &p, &w, &b, &q.conv(), &mut r), Ok(os));
            assert_eq!(conv2d_fast(&x, xs, &p, &w, &b, &q.conv(), &mut f), Ok(os));
            assert_eq!(r, f, "{xs:?} {p:?}");
            let mut g = vec![2i8; os.len()];
            portable(|| conv2d_fast(&x, xs, &p, &w, &b, &q.conv(), &mut g)).unwrap();
            assert_eq!(r, g, "portable {xs:?} {p:?}");
            if bmax > 20_000 {
                continue;
            }
            let e =
                float_conv(&x, xs, os, kernel, p.stride, (p.pads[0], p.pads[1]), false, &w, &b, &q);
            assert!(max_diff(&r, &e) <= 1, "{xs:?} {p:?}");
        }
    }

    #[test]
    fn depthwise_fast_equals_reference_and_float() {
        let mut rng = Rng::new(0xd3);
        for i in 0..300 {
            // channel counts straddle the 64-channel accumulator block and the 8-lane groups
            let c = if i % 5 == 0 { rng.usize(60, 140) } else { rng.usize(1, 19) };
            let xs = Shape::new(c, rng.usize(1, 12), rng.usize(1, 12));
            let stride = rng.usize(1, 2);
            let os = depthwise3x3_output_shape(xs, stride).unwrap();
            let x = rng.i8s(xs.len());
            let w = rng.weights(9 * c);
            // every 10th case: huge biases (the scalar requantisation path)
            let bmax = if i % 10 == 9 { 1 << 30 } else { 5000 };
            let b: Vec<i32> = (0..c).map(|_| rng.int(-bmax, bmax) as i32).collect();
            let q = rand_q(&mut rng, c, 9);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            assert_eq!(depthwise3x3_reference(&x, xs, stride, &w, &b, &q.conv(), &mut r), Ok(os));
            assert_eq!(depthwise3x3_fast(&x, xs, stride, &w, &b, &q.conv(), &mut f), Ok(os));
            assert_eq!(r, f, "{xs:?} {stride}");
            let mut g = vec![2i8; os.len()];
            portable(|| depthwise3x3_fast(&x, xs, stride, &w, &b, &q.conv(), &mut g)).unwrap();
            assert_eq!(r, g, "portable {xs:?} {stride}");
            if bmax > 5000 {
                continue;
            }
            let e = float_conv(&x, xs, os, (3, 3), (stride, stride), (1, 1), true, &w, &b, &q);
            assert!(max_diff(&r, &e) <= 1, "{xs:?} {stride}");
        }
    }

    /// Packs `O·I` weights for the pointwise kernels.
    fn packed(w: &[i8], c_out: usize, c_in: usize) -> Vec<i8> {
        let mut p = vec![0i8; pointwise_packed_len(c_out, c_in)];
        pack_pointwise(w, c_out, c_in, &mut p).unwrap();
        p
    }

    /// Every SIMD path of the pointwise kernel on this machine, bit for bit against `r`.
    #[allow(unused_variables)]
    fn pointwise_simd_paths(x: &[i8], xs: Shape, w: &[i8], b: &[i32], q: &Q, r: &[i8]) {
        #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
        {
            let k = xs.c as i64;
            if !crate::nn::quant::fits_simd_requant(k * 255 * 127, b, &q.rq) {
                return;
            }
            let (lo, _) = clamp_range(q.zp_out, q.relu);
            let a = crate::nn::simd::Pw {
                x,
                p: xs.h * xs.w,
                k: xs.c,
                w,
                bias: b,
                requant: &q.rq,
                zp: q.zp_in,
                zo: q.zp_out,
                lo,
            };
            for vnni in [false, true] {
                let mut f = vec![3i8; r.len()];
                crate::nn::simd::pointwise_isa(&a, &mut f, vnni);
                assert_eq!(f, r, "{xs:?} {} vnni {vnni}", b.len());
            }
        }
    }

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
    fn pointwise_fast_equals_reference_and_float() {
        let mut rng = Rng::new(0x11);
        for i in 0..300 {
            // a few rows wider than the portable kernel's stage
            let c_in =
                if i % 50 == 0 { rng.usize(PW_STAGE - 2, PW_STAGE + 40) } else { rng.usize(1, 40) };
            let xs = Shape::new(c_in, rng.usize(1, 7), rng.usize(1, 7));
            let c_out = rng.usize(1, 40);
            let x = rng.i8s(xs.len());
            let w = rng.weights(c_out * xs.c);
            let wp = packed(&w, c_out, xs.c);
            // every 10th case: huge biases (the scalar requantisation path)
            let bmax = if i % 10 == 9 { 1 << 30 } else { 20_000 };
            let b: Vec<i32> = (0..c_out).map(|_| rng.int(-bmax, bmax) as i32).collect();
            let q = rand_q(&mut rng, c_out, xs.c);
            let os = Shape::new(c_out, xs.h, xs.w);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            assert_eq!(pointwise_reference(&x, xs, &wp, &b, &q.conv(), &mut r), Ok(os));
            assert_eq!(pointwise_fast(&x, xs, &wp, &b, &q.conv(), &mut f), Ok(os));
            assert_eq!(r, f, "{xs:?} {c_out}");
            let mut p = vec![1i8; os.len()];
            pointwise_portable(&x, xs, &wp, &b, &q.conv(), &mut p);
            assert_eq!(r, p, "portable {xs:?} {c_out}");
            pointwise_simd_paths(&x, xs, &wp, &b, &q, &r);
            if bmax < 1 << 30 {
                let e = float_conv(&x, xs, os, (1, 1), (1, 1), (0, 0), false, &w, &b, &q);
                assert!(max_diff(&r, &e) <= 1, "{xs:?} {c_out}");
            }
        }
    }

    /// The depthwise and first-conv shapes of the 192×640 network (`benches/nn.rs`), channels
    /// as there, maps smaller (odd and even sizes, for the stride-2 borders).
    #[test]
    fn depthwise_and_first_conv_workload_shapes_are_bit_equal() {
        let mut rng = Rng::new(0xd4);
        for (c, stride) in
            [(128, 1), (148, 1), (32, 2), (48, 2), (64, 1), (64, 2), (96, 2), (96, 1)]
        {
            for (h, w) in [(6, 20), (7, 13), (12, 40)] {
                let xs = Shape::new(c, h, w);
                let os = depthwise3x3_output_shape(xs, stride).unwrap();
                let x = rng.i8s(xs.len());
                let wt = rng.weights(9 * c);
                let b: Vec<i32> = (0..c).map(|_| rng.int(-5000, 5000) as i32).collect();
                let q = rand_q(&mut rng, c, 9);
                let mut r = vec![0i8; os.len()];
                let mut f = vec![1i8; os.len()];
                let mut g = vec![2i8; os.len()];
                depthwise3x3_reference(&x, xs, stride, &wt, &b, &q.conv(), &mut r).unwrap();
                depthwise3x3_fast(&x, xs, stride, &wt, &b, &q.conv(), &mut f).unwrap();
                portable(|| depthwise3x3_fast(&x, xs, stride, &wt, &b, &q.conv(), &mut g)).unwrap();
                assert_eq!(r, f, "{xs:?} {stride}");
                assert_eq!(r, g, "portable {xs:?} {stride}");
            }
        }
        // the first layer: 1 -> 32, 3x3, stride 2, pad 1 (192x640 in the network)
        for (h, w) in [(12, 40), (13, 41), (24, 17)] {
            let xs = Shape::new(1, h, w);
            let p = Conv2dParams { c_out: 32, kernel: (3, 3), stride: (2, 2), pads: [1; 4] };
            let os = p.output_shape(xs).unwrap();
            let x = rng.i8s(xs.len());
            let wt = rng.weights(32 * 9);
            let b: Vec<i32> = (0..32).map(|_| rng.int(-100_000, 100_000) as i32).collect();
            let q = rand_q(&mut rng, 32, 9);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            conv2d_reference(&x, xs, &p, &wt, &b, &q.conv(), &mut r).unwrap();
            conv2d_fast(&x, xs, &p, &wt, &b, &q.conv(), &mut f).unwrap();
            assert_eq!(r, f, "{xs:?}");
        }
    }

    /// The 1×1 shapes of the 192×640 network (`benches/nn.rs`), on smaller maps.
    #[test]
    fn pointwise_workload_shapes_are_bit_equal() {
        let mut rng = Rng::new(0x12);
        let shapes = [
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
        for (c_in, c_out) in shapes {
            let xs = Shape::new(c_in, rng.usize(1, 6), rng.usize(1, 21));
            let x = rng.i8s(xs.len());
            let wp = packed(&rng.weights(c_out * c_in), c_out, c_in);
            let b: Vec<i32> = (0..c_out).map(|_| rng.int(-20_000, 20_000) as i32).collect();
            let q = rand_q(&mut rng, c_out, c_in);
            let os = Shape::new(c_out, xs.h, xs.w);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            pointwise_reference(&x, xs, &wp, &b, &q.conv(), &mut r).unwrap();
            pointwise_fast(&x, xs, &wp, &b, &q.conv(), &mut f).unwrap();
            assert_eq!(r, f, "{xs:?} {c_out}");
            pointwise_simd_paths(&x, xs, &wp, &b, &q, &r);
        }
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
