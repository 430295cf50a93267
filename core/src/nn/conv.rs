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
//! The depthwise kernel keeps a 64-channel `i32` accumulator block on the stack (256 bytes).

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
/// `kw_valid · c_in` bytes in both input and weights, so each is one dot product.
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

/// Depthwise 3×3, fast: per output pixel and 64-channel block, each valid tap adds a whole
/// channel vector (`x[iy, ix, c..]·w[ky, kx, c..]`) to a stack accumulator, which vectorises.
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
    let c = xs.c;
    let zp = q.input_zero_point;
    let out = &mut out[..os.len()];
    let mut acc = [0i32; DW_BLOCK];
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
                for (((o, &a), &bias), rq) in opix[c0..c0 + n]
                    .iter_mut()
                    .zip(acc.iter())
                    .zip(&b[c0..c0 + n])
                    .zip(&q.requant[c0..c0 + n])
                {
                    *o = rq.to_i8(a.saturating_add(bias), q.output_zero_point, lo, hi);
                }
                c0 += n;
            }
        }
    }
    Ok(os)
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
    check_param(w.len(), c_out.saturating_mul(xs.c))?;
    check_param(q.requant.len(), c_out)?;
    check_tensor(out.len(), os)?;
    Ok(os)
}

/// Pointwise 1×1 conv (stride 1, no padding), reference. The number of output channels is
/// `b.len()`; weights are `[c_out][c_in]`.
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
                    acc += (xv - q.input_zero_point) * w[co * xs.c + ci] as i32;
                }
                let acc = acc.saturating_add(b[co]);
                out[os.index(co, y, xx)] = q.requant[co].to_i8(acc, q.output_zero_point, lo, hi);
            }
        }
    }
    Ok(os)
}

/// Output channels per register block of the fast pointwise kernel.
const PW_CO: usize = 4;
/// Longest input row the fast pointwise kernel stages as `i16` (2 KiB of stack); the network's
/// widest 1×1 input is 768 channels. Wider rows take the direct path (same integers).
const PW_STAGE: usize = 1024;

/// Four dot products of one staged input row with four weight rows, in one zipped loop.
/// `i16 × i8 → i32` with `|x − zp| ≤ 255` is what `pmaddwd` / `smlal` do, and LLVM finds them.
#[inline]
fn dot4<T: Copy + Into<i32>>(xr: &[T], w4: &[i8], zp: i32) -> [i32; 4] {
    let ci = xr.len();
    let (w0, r) = w4.split_at(ci);
    let (w1, r) = r.split_at(ci);
    let (w2, w3) = r.split_at(ci);
    let (mut a0, mut a1, mut a2, mut a3) = (0i32, 0i32, 0i32, 0i32);
    for ((((&xv, &v0), &v1), &v2), &v3) in xr.iter().zip(w0).zip(w1).zip(w2).zip(w3) {
        let xv = xv.into() - zp;
        a0 += xv * v0 as i32;
        a1 += xv * v1 as i32;
        a2 += xv * v2 as i32;
        a3 += xv * v3 as i32;
    }
    [a0, a1, a2, a3]
}

/// Pointwise 1×1 conv, fast: an int8 GEMM `out[p][co] = Σ_ci (x[p][ci] − zp)·w[co][ci]` with
/// `i32` accumulation. Per pixel the input row is staged once as `i16` with the zero point
/// subtracted (so the inner loop is a pure widening multiply-add), then multiplied by blocks
/// of four weight rows (four independent reductions in one zipped loop, no bounds checks);
/// leftover channels use a plain dot product.
pub fn pointwise_fast(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_pointwise(x, xs, w, b, q, out)?;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let ci = xs.c;
    let co = os.c;
    let zp = q.input_zero_point;
    let zo = q.output_zero_point;
    let x = &x[..xs.len()];
    let out = &mut out[..os.len()];
    let full = co / PW_CO * PW_CO;
    let (wblk, wtail) = w.split_at(full * ci);
    let mut stage = [0i16; PW_STAGE];
    for (xr, orow) in x.chunks_exact(ci).zip(out.chunks_exact_mut(co)) {
        let (oblk, otail) = orow.split_at_mut(full);
        let staged = ci <= PW_STAGE;
        if staged {
            for (s, &v) in stage[..ci].iter_mut().zip(xr) {
                *s = v as i16 - zp as i16;
            }
        }
        let xb = &stage[..ci.min(PW_STAGE)];
        for (j, (o4, w4)) in
            oblk.chunks_exact_mut(PW_CO).zip(wblk.chunks_exact(PW_CO * ci)).enumerate()
        {
            let acc = if staged { dot4(xb, w4, 0) } else { dot4(xr, w4, zp) };
            let k = j * PW_CO;
            for (t, (o, a)) in o4.iter_mut().zip(acc).enumerate() {
                *o = q.requant[k + t].to_i8(a.saturating_add(b[k + t]), zo, lo, hi);
            }
        }
        for (t, (o, wr)) in otail.iter_mut().zip(wtail.chunks_exact(ci)).enumerate() {
            let a = dot(xr, wr, zp);
            *o = q.requant[full + t].to_i8(a.saturating_add(b[full + t]), zo, lo, hi);
        }
    }
    Ok(os)
}

#[cfg(test)]
mod tests {
    use super::*;
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
        for _ in 0..300 {
            let xs = Shape::new(rng.usize(1, 5), rng.usize(1, 11), rng.usize(1, 11));
            let kernel = (rng.usize(1, 4), rng.usize(1, 4));
            let p = Conv2dParams {
                c_out: rng.usize(1, 7),
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
            let b: Vec<i32> = (0..p.c_out).map(|_| rng.int(-20_000, 20_000) as i32).collect();
            let q = rand_q(&mut rng, p.c_out, k);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            assert_eq!(conv2d_reference(&x, xs, &p, &w, &b, &q.conv(), &mut r), Ok(os));
            assert_eq!(conv2d_fast(&x, xs, &p, &w, &b, &q.conv(), &mut f), Ok(os));
            assert_eq!(r, f, "{xs:?} {p:?}");
            let e =
                float_conv(&x, xs, os, kernel, p.stride, (p.pads[0], p.pads[1]), false, &w, &b, &q);
            assert!(max_diff(&r, &e) <= 1, "{xs:?} {p:?}");
        }
    }

    #[test]
    fn depthwise_fast_equals_reference_and_float() {
        let mut rng = Rng::new(0xd3);
        for i in 0..300 {
            // channel counts straddle the 64-channel accumulator block
            let c = if i % 5 == 0 { rng.usize(60, 140) } else { rng.usize(1, 9) };
            let xs = Shape::new(c, rng.usize(1, 12), rng.usize(1, 12));
            let stride = rng.usize(1, 2);
            let os = depthwise3x3_output_shape(xs, stride).unwrap();
            let x = rng.i8s(xs.len());
            let w = rng.weights(9 * c);
            let b: Vec<i32> = (0..c).map(|_| rng.int(-5000, 5000) as i32).collect();
            let q = rand_q(&mut rng, c, 9);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            assert_eq!(depthwise3x3_reference(&x, xs, stride, &w, &b, &q.conv(), &mut r), Ok(os));
            assert_eq!(depthwise3x3_fast(&x, xs, stride, &w, &b, &q.conv(), &mut f), Ok(os));
            assert_eq!(r, f, "{xs:?} {stride}");
            let e = float_conv(&x, xs, os, (3, 3), (stride, stride), (1, 1), true, &w, &b, &q);
            assert!(max_diff(&r, &e) <= 1, "{xs:?} {stride}");
        }
    }

    #[test]
    fn pointwise_fast_equals_reference_and_float() {
        let mut rng = Rng::new(0x11);
        for i in 0..300 {
            // a few rows wider than the i16 stage (the direct path)
            let c_in =
                if i % 50 == 0 { rng.usize(PW_STAGE - 2, PW_STAGE + 40) } else { rng.usize(1, 40) };
            let xs = Shape::new(c_in, rng.usize(1, 7), rng.usize(1, 7));
            let c_out = rng.usize(1, 19);
            let x = rng.i8s(xs.len());
            let w = rng.weights(c_out * xs.c);
            let b: Vec<i32> = (0..c_out).map(|_| rng.int(-20_000, 20_000) as i32).collect();
            let q = rand_q(&mut rng, c_out, xs.c);
            let os = Shape::new(c_out, xs.h, xs.w);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            assert_eq!(pointwise_reference(&x, xs, &w, &b, &q.conv(), &mut r), Ok(os));
            assert_eq!(pointwise_fast(&x, xs, &w, &b, &q.conv(), &mut f), Ok(os));
            assert_eq!(r, f, "{xs:?} {c_out}");
            let e = float_conv(&x, xs, os, (1, 1), (1, 1), (0, 0), false, &w, &b, &q);
            assert!(max_diff(&r, &e) <= 1, "{xs:?} {c_out}");
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
        assert_eq!(pointwise_fast(&x, xs, &[0; 4], &b, &bad_zp, &mut out), Err(NnError::BadParam));
        assert_eq!(
            depthwise3x3_reference(&x, xs, 1, &[0; 18], &b, &bad_zp, &mut out),
            Err(NnError::BadParam)
        );
        assert_eq!(
            pointwise_fast(&x, xs, &[0; 3], &b, &q, &mut out),
            Err(NnError::ParamLength { need: 4, got: 3 })
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
        let wp = rng.weights(128 * 128);
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
