//! # Graph executor: one int8 inference of a parsed [`Model`] in a caller-provided arena
//!
//! [`run`] writes the input map (`q = luma − 128`, i.e. scale 1/255, zero point −128) into the
//! arena at the input tensor's planned offset and executes the ops in blob order, each reading
//! its inputs and writing its output at the offsets [`super::model::plan_arena`] chose — so the
//! activation memory is exactly [`Model::arena_len`] bytes, known before the first frame. The
//! per-op quantisation structs are rebuilt from the tensors' scales on the fly (f64, IEEE, so
//! the same integers on every target). [`Kernels`] selects the reference or the fast kernel of
//! every op; the two are bit-equal (tested per op and on whole graphs).
//!
//! [`Letterbox`] maps camera frames to the network's static input (integer box down-scaling
//! and edge padding) and the labels back (nearest), and [`argmax`] turns logits into class ids.
//!
//! **Memory:** no allocation; the stack holds one `[ConcatInput; 8]`.

use super::conv::{
    conv2d_fast, conv2d_reference, depthwise3x3_fast, depthwise3x3_reference, pointwise_fast,
    pointwise_reference, Conv2dParams, ConvQuant,
};
use super::eltwise::{
    add_fast, add_reference, concat_fast, concat_reference, relu_fast, relu_reference, AddQuant,
    ConcatInput, Rescale,
};
use super::model::{Model, ModelError, OpKind, OpSpec, MAX_INPUTS};
use super::pool::{avgpool_fast, avgpool_reference, AvgPoolParams, PoolQuant};
use super::resize::{resize_bilinear_fast, resize_bilinear_reference, ResizeQuant};
use super::{NnError, Shape};

/// Which implementation of each operator to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kernels {
    /// The plain loops that read like the ONNX definitions.
    Reference,
    /// The optimised kernels (bit-equal to the reference).
    Fast,
}

/// One inference: `input` is the model's `h × w` input map (luma bytes, row-major); returns the
/// output tensor (NHWC int8 logits of [`Model::output_shape`]) inside `arena`.
pub fn run<'x>(
    model: &Model<'_>,
    input: &[u8],
    arena: &'x mut [i8],
    kernels: Kernels,
) -> Result<&'x [i8], ModelError> {
    run_observed(model, input, arena, kernels, &mut |_| {})
}

/// [`run`], calling `after_op(k)` when op `k` has finished (for per-op profiling on the host).
pub fn run_observed<'x>(
    model: &Model<'_>,
    input: &[u8],
    arena: &'x mut [i8],
    kernels: Kernels,
    after_op: &mut dyn FnMut(usize),
) -> Result<&'x [i8], ModelError> {
    let need = model.arena_len();
    if arena.len() < need {
        return Err(ModelError::ArenaTooSmall { need, got: arena.len() });
    }
    let (ih, iw) = model.input_size();
    if input.len() != ih * iw {
        return Err(ModelError::Truncated { need: ih * iw, got: input.len() });
    }
    let inp = model.input() as usize;
    let off = model.arena_offset(inp);
    for (a, &l) in arena[off..off + ih * iw].iter_mut().zip(input) {
        *a = (l as i16 - 128) as i8;
    }
    for k in 0..model.n_ops() {
        exec(model, k, arena, kernels).map_err(|error| ModelError::Kernel { op: k, error })?;
        after_op(k);
    }
    let out = model.output() as usize;
    let off = model.arena_offset(out);
    Ok(&arena[off..off + model.output_shape().len()])
}

/// The read-only parts of the arena around an op's output: everything below and above it.
#[derive(Clone, Copy)]
struct Around<'x> {
    lo: &'x [i8],
    hi: &'x [i8],
    hi_start: usize,
}

/// Splits the arena into the output range (mutable) and the rest (read-only).
fn split(arena: &mut [i8], start: usize, len: usize) -> (Around<'_>, &mut [i8]) {
    let (lo, rest) = arena.split_at_mut(start);
    let (out, hi) = rest.split_at_mut(len);
    (Around { lo, hi, hi_start: start + len }, out)
}

impl<'x> Around<'x> {
    /// A tensor that does not overlap the output (guaranteed by the validated plan).
    fn get(self, off: usize, len: usize) -> Result<&'x [i8], NnError> {
        if off + len <= self.lo.len() {
            Ok(&self.lo[off..off + len])
        } else if off >= self.hi_start && off - self.hi_start + len <= self.hi.len() {
            Ok(&self.hi[off - self.hi_start..off - self.hi_start + len])
        } else {
            Err(NnError::BadParam)
        }
    }
}

fn exec(model: &Model<'_>, k: usize, arena: &mut [i8], kernels: Kernels) -> Result<(), NnError> {
    let op = model.op(k);
    let tensor = |t: u32| model.tensor(t as usize).ok_or(NnError::BadParam);
    let to = tensor(op.output())?;
    let os = to.shape;
    let (rest, out) = split(arena, model.arena_offset(op.output() as usize), os.len());
    let view = |t: u32| -> Result<(&[i8], Shape, f64, i32), NnError> {
        let ts = tensor(t)?;
        let data = rest.get(model.arena_offset(t as usize), ts.shape.len())?;
        Ok((data, ts.shape, ts.scale, ts.zero_point))
    };
    let fast = kernels == Kernels::Fast;
    match op {
        OpSpec::Conv { kind, input, geometry: g, weights, bias, requant, relu, .. } => {
            let (x, xs, _, zp) = view(input)?;
            let q =
                ConvQuant { input_zero_point: zp, output_zero_point: to.zero_point, requant, relu };
            match kind {
                OpKind::Conv => {
                    let p = Conv2dParams {
                        c_out: os.c,
                        kernel: g.kernel,
                        stride: g.stride,
                        pads: g.pads,
                    };
                    if fast {
                        conv2d_fast(x, xs, &p, weights, bias, &q, out)?;
                    } else {
                        conv2d_reference(x, xs, &p, weights, bias, &q, out)?;
                    }
                }
                OpKind::Depthwise3x3 => {
                    if fast {
                        depthwise3x3_fast(x, xs, g.stride.0, weights, bias, &q, out)?;
                    } else {
                        depthwise3x3_reference(x, xs, g.stride.0, weights, bias, &q, out)?;
                    }
                }
                _ => {
                    if fast {
                        pointwise_fast(x, xs, weights, bias, &q, out)?;
                    } else {
                        pointwise_reference(x, xs, weights, bias, &q, out)?;
                    }
                }
            }
        }
        OpSpec::Add { a, b, relu, .. } => {
            let (xa, shape, sa, za) = view(a)?;
            let (xb, _, sb, zb) = view(b)?;
            let q = AddQuant::new(sa, za, sb, zb, to.scale, to.zero_point, relu);
            if fast {
                add_fast(xa, xb, shape, &q, out)?;
            } else {
                add_reference(xa, xb, shape, &q, out)?;
            }
        }
        OpSpec::Concat { inputs, n, .. } => {
            let empty = ConcatInput {
                data: &[],
                shape: Shape::new(0, 0, 0),
                rescale: Rescale::new(1.0, 0, 1.0, 0),
            };
            let mut parts = [empty; MAX_INPUTS];
            for (p, &t) in parts.iter_mut().zip(&inputs[..n]) {
                let (data, shape, sc, zp) = view(t)?;
                *p = ConcatInput {
                    data,
                    shape,
                    rescale: Rescale::new(sc, zp, to.scale, to.zero_point),
                };
            }
            if fast {
                concat_fast(&parts[..n], out)?;
            } else {
                concat_reference(&parts[..n], out)?;
            }
        }
        OpSpec::AvgPool { input, kernel, pad_bottom_right, .. } => {
            let (x, xs, sc, zp) = view(input)?;
            let p = AvgPoolParams { kernel, pad_bottom_right };
            let q = PoolQuant::new(sc, zp, to.scale, to.zero_point);
            if fast {
                avgpool_fast(x, xs, &p, &q, out)?;
            } else {
                avgpool_reference(x, xs, &p, &q, out)?;
            }
        }
        OpSpec::Resize { input, .. } => {
            let (x, xs, sc, zp) = view(input)?;
            let q = ResizeQuant::new(sc, zp, to.scale, to.zero_point);
            if fast {
                resize_bilinear_fast(x, xs, (os.h, os.w), &q, out)?;
            } else {
                resize_bilinear_reference(x, xs, (os.h, os.w), &q, out)?;
            }
        }
        OpSpec::Relu { input, .. } => {
            let (x, xs, sc, zp) = view(input)?;
            let r = Rescale::new(sc, zp, to.scale, to.zero_point);
            if fast {
                relu_fast(x, xs, &r, out)?;
            } else {
                relu_reference(x, xs, &r, out)?;
            }
        }
    }
    Ok(())
}

/// Caller-provided working memory of [`segment_frame`]: the input map, the activation arena
/// and the labels at the network's resolution.
pub struct SegBuffers<'b> {
    /// `model_h × model_w` bytes.
    pub input: &'b mut [u8],
    /// [`Model::arena_len`] bytes.
    pub arena: &'b mut [i8],
    /// `model_h × model_w` bytes.
    pub labels: &'b mut [u8],
}

/// Labels one camera frame: letterbox the `lb.src_w × lb.src_h` luma frame into the input map,
/// run the network, take the arg-max class per pixel and map it back onto the frame
/// (`out`: `src_w × src_h` class ids).
pub fn segment_frame(
    model: &Model<'_>,
    lb: &Letterbox,
    luma: &[u8],
    bufs: SegBuffers<'_>,
    kernels: Kernels,
    out: &mut [u8],
) -> Result<(), ModelError> {
    let (mh, mw) = model.input_size();
    if (lb.model_h, lb.model_w) != (mh, mw) {
        return Err(ModelError::BadIo);
    }
    let n = mh * mw;
    if bufs.input.len() < n || bufs.labels.len() < n {
        return Err(ModelError::Truncated {
            need: n,
            got: bufs.input.len().min(bufs.labels.len()),
        });
    }
    prepare_input(luma, lb, bufs.input)?;
    let logits = run(model, &bufs.input[..n], bufs.arena, kernels)?;
    let os = model.output_shape();
    if (os.h, os.w) != (mh, mw) {
        return Err(ModelError::BadIo);
    }
    argmax(logits, os, bufs.labels)?;
    labels_to_frame(bufs.labels, lb, out)
}

/// Class ids from NHWC logits: per pixel the channel with the largest value (ties: the lowest
/// channel). `labels` gets `h·w` entries.
pub fn argmax(logits: &[i8], shape: Shape, labels: &mut [u8]) -> Result<(), ModelError> {
    let n = shape.h * shape.w;
    if shape.is_empty() || shape.c > 256 {
        return Err(ModelError::BadIo);
    }
    if logits.len() < shape.len() {
        return Err(ModelError::Truncated { need: shape.len(), got: logits.len() });
    }
    if labels.len() < n {
        return Err(ModelError::Truncated { need: n, got: labels.len() });
    }
    match shape.c {
        // The deployed networks' class count: the channel loop unrolls.
        crate::seg::NUM_CLASSES => argmax_pixels::<{ crate::seg::NUM_CLASSES }>(logits, labels),
        c => {
            for (l, px) in labels.iter_mut().zip(logits.chunks_exact(c)) {
                *l = argmax_of(px);
            }
        }
    }
    Ok(())
}

/// [`argmax`] over pixels of `C` channels.
fn argmax_pixels<const C: usize>(logits: &[i8], labels: &mut [u8]) {
    let (px, _) = logits.as_chunks::<C>();
    for (l, px) in labels.iter_mut().zip(px) {
        *l = argmax_of(px);
    }
}

/// The first channel holding the largest value (a running maximum, no branches).
#[inline(always)]
fn argmax_of(px: &[i8]) -> u8 {
    let (mut best, mut best_v) = (0u8, px[0]);
    for (c, &v) in px.iter().enumerate().skip(1) {
        let gt = v > best_v;
        best = if gt { c as u8 } else { best };
        best_v = if gt { v } else { best_v };
    }
    best
}

/// How a camera frame maps onto the network's static input: a down-scaling by `num / den`
/// frame pixels per input pixel (an area mean; `den = 1` is an integer `f × f` box mean) and
/// edge-replicated padding on the right and bottom.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Letterbox {
    /// Numerator of the down-scaling (`num / den` frame pixels per input pixel).
    pub num: usize,
    /// Denominator of the down-scaling (1 ..= [`Letterbox::MAX_DEN`]).
    pub den: usize,
    /// Frame width.
    pub src_w: usize,
    /// Frame height.
    pub src_h: usize,
    /// Network input width.
    pub model_w: usize,
    /// Network input height.
    pub model_h: usize,
}

impl Letterbox {
    /// Largest denominator of a fractional down-scaling.
    pub const MAX_DEN: usize = 4;
    /// Largest down-scaling (frame pixels per input pixel).
    pub const MAX_SCALE: usize = 8;

    /// The smallest down-scaling `num / den ≥ 1` (`den ≤ 4`, at most 8) with
    /// `ceil(src · den / num)` fitting the model input (KITTI 1241x376 → 192x640: 2;
    /// → 256x832: 3/2; CamVid 480x360 → 384x480: 1).
    pub fn fit(
        src_w: usize,
        src_h: usize,
        model_h: usize,
        model_w: usize,
    ) -> Result<Self, ModelError> {
        if src_w == 0 || src_h == 0 || model_w == 0 || model_h == 0 {
            return Err(ModelError::BadIo);
        }
        let mut best: Option<(usize, usize)> = None;
        for den in 1..=Self::MAX_DEN {
            // the smallest numerator that fits with this denominator
            let fits = |num: usize| {
                (src_w * den).div_ceil(num) <= model_w && (src_h * den).div_ceil(num) <= model_h
            };
            if let Some(num) = (den..=Self::MAX_SCALE * den).find(|&n| fits(n)) {
                // strictly smaller only: equal values keep the smaller denominator
                if best.is_none_or(|(bn, bd)| num * bd < bn * den) {
                    best = Some((num, den));
                }
            }
        }
        best.map(|(num, den)| Self { num, den, src_w, src_h, model_w, model_h })
            .ok_or(ModelError::BadIo)
    }

    /// The down-scaling as a number (frame pixels per input pixel).
    pub fn scale(&self) -> f64 {
        self.num as f64 / self.den.max(1) as f64
    }

    /// Width of the scaled frame inside the input map.
    pub fn scaled_w(&self) -> usize {
        (self.src_w * self.den).div_ceil(self.num.max(1))
    }

    /// Height of the scaled frame inside the input map.
    pub fn scaled_h(&self) -> usize {
        (self.src_h * self.den).div_ceil(self.num.max(1))
    }

    fn valid(&self) -> bool {
        self.num >= self.den
            && (1..=Self::MAX_DEN).contains(&self.den)
            && self.num <= Self::MAX_SCALE * self.den
            && self.scaled_w() <= self.model_w
            && self.scaled_h() <= self.model_h
    }
}

/// The frame pixels under input pixel `i` of one axis, in units of `1 / den` frame pixel: input
/// pixel `i` spans `[i·num, (i+1)·num)`, frame pixel `s` spans `[s·den, (s+1)·den)`, clipped to
/// the frame's `len` pixels. Returns the first frame pixel, the number of frame pixels and the
/// total overlap; `weight(k)` is the overlap of the `k`-th of them.
#[derive(Clone, Copy)]
struct Span {
    lo: usize,
    hi: usize,
    den: usize,
    first: usize,
    count: usize,
    total: u32,
}

impl Span {
    fn new(i: usize, num: usize, den: usize, len: usize) -> Self {
        let lo = i * num;
        let hi = ((i + 1) * num).min(len * den);
        let first = lo / den;
        let count = hi.div_ceil(den) - first;
        Self { lo, hi, den, first, count, total: (hi - lo) as u32 }
    }

    fn weight(&self, k: usize) -> u32 {
        let s = self.first + k;
        let a = (s * self.den).max(self.lo);
        let b = ((s + 1) * self.den).min(self.hi);
        (b - a) as u32
    }
}

/// Fills the `model_h × model_w` input map from a `src_w × src_h` luma frame: each input pixel
/// is the area mean of the frame pixels it covers (integer overlap weights, so the result is
/// the same on every target; a clipped edge pixel averages the real pixels only; rounded half
/// up), and the padding repeats the last scaled column / row. With an integer scale `f` this is
/// the mean of the `f × f` block.
pub fn prepare_input(src: &[u8], lb: &Letterbox, out: &mut [u8]) -> Result<(), ModelError> {
    let (sw, sh, num, den) = (lb.src_w, lb.src_h, lb.num, lb.den);
    if src.len() < sw * sh {
        return Err(ModelError::Truncated { need: sw * sh, got: src.len() });
    }
    if out.len() < lb.model_w * lb.model_h {
        return Err(ModelError::Truncated { need: lb.model_w * lb.model_h, got: out.len() });
    }
    if !lb.valid() || sw == 0 || sh == 0 {
        return Err(ModelError::BadIo);
    }
    let (w, h) = (lb.scaled_w(), lb.scaled_h());
    for y in 0..h {
        let row = &mut out[y * lb.model_w..(y + 1) * lb.model_w];
        let sy = Span::new(y, num, den, sh);
        // Halving (the deployed KITTI letterbox): whole 2 × 2 blocks as one vector loop, the
        // same rounded mean `(sum + 2) / 4` as the general loop below, which does the rest.
        let mut x_start = 0;
        if num == 2 && den == 1 && sy.count == 2 {
            let full = w.min(sw / 2);
            let (a, b) = (&src[2 * y * sw..][..2 * full], &src[(2 * y + 1) * sw..][..2 * full]);
            for ((o, a), b) in row[..full].iter_mut().zip(a.chunks_exact(2)).zip(b.chunks_exact(2))
            {
                let sum = u16::from(a[0]) + u16::from(a[1]) + u16::from(b[0]) + u16::from(b[1]);
                *o = ((sum + 2) >> 2) as u8;
            }
            x_start = full;
        }
        for (x, o) in row[..w].iter_mut().enumerate().skip(x_start) {
            let sx = Span::new(x, num, den, sw);
            let mut sum = 0u32;
            for ky in 0..sy.count {
                let line = &src[(sy.first + ky) * sw + sx.first..][..sx.count];
                let row_sum: u32 = if den == 1 {
                    line.iter().map(|&v| v as u32).sum()
                } else {
                    line.iter().enumerate().map(|(kx, &v)| sx.weight(kx) * v as u32).sum()
                };
                sum += sy.weight(ky) * row_sum;
            }
            let n = sx.total * sy.total;
            *o = ((sum + n / 2) / n) as u8;
        }
        let edge = row[w - 1];
        row[w..].fill(edge);
    }
    let (filled, pad) = out[..lb.model_w * lb.model_h].split_at_mut(h * lb.model_w);
    let last = &filled[(h - 1) * lb.model_w..];
    for r in pad.chunks_exact_mut(lb.model_w) {
        r.copy_from_slice(last);
    }
    Ok(())
}

/// Labels of the input map back on the frame: each frame pixel takes the label of the input
/// pixel under its centre, `out[y][x] = labels[⌊(2y+1)·den / 2num⌋][⌊(2x+1)·den / 2num⌋]`
/// (`labels[y / f][x / f]` for an integer scale `f`).
pub fn labels_to_frame(labels: &[u8], lb: &Letterbox, out: &mut [u8]) -> Result<(), ModelError> {
    let (sw, sh, num, den) = (lb.src_w, lb.src_h, lb.num, lb.den);
    if labels.len() < lb.model_w * lb.model_h {
        return Err(ModelError::Truncated { need: lb.model_w * lb.model_h, got: labels.len() });
    }
    if out.len() < sw * sh {
        return Err(ModelError::Truncated { need: sw * sh, got: out.len() });
    }
    if !lb.valid() {
        return Err(ModelError::BadIo);
    }
    let at = |s: usize| ((2 * s + 1) * den) / (2 * num);
    // The last frame row filled from the label map, and its label row.
    let mut prev: Option<(usize, usize)> = None;
    for y in 0..sh {
        let ly = at(y);
        if let Some((p, _)) = prev.filter(|&(_, lp)| lp == ly) {
            // The same label row as the row above: copy it.
            out.copy_within(p * sw..(p + 1) * sw, y * sw);
            continue;
        }
        prev = Some((y, ly));
        let lrow = &labels[ly * lb.model_w..];
        // `at(x)` stepped without a division: the numerator grows by `2·den` per column.
        let (step, div) = (2 * den, 2 * num);
        let (mut q, mut r) = (den / div, den % div);
        for o in out[y * sw..(y + 1) * sw].iter_mut() {
            *o = lrow[q];
            r += step;
            while r >= div {
                r -= div;
                q += 1;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::dispatch::for_each_level;
    use super::super::model::{encoded_len, plan_arena, write, ConvGeometry, TensorSpec};
    use super::super::testutil::Rng;
    use super::super::Requant;
    use super::*;
    use std::vec;
    use std::vec::Vec;

    /// A small random network with every op kind: conv s2 → dw s2 → pw → (pool → resize) ‖ add
    /// → concat → relu, in the order and layout the converter produces.
    struct Net {
        tensors: Vec<TensorSpec>,
        w: Vec<Vec<i8>>,
        b: Vec<Vec<i32>>,
        rq: Vec<Vec<Requant>>,
    }

    fn net(rng: &mut Rng, h: usize, w: usize) -> (Net, Vec<u8>) {
        let t = |c: usize, hh: usize, ww: usize, rng: &mut Rng| TensorSpec {
            shape: Shape::new(c, hh, ww),
            zero_point: rng.int(-128, -60) as i32,
            scale: rng.f64(0.01, 0.2),
        };
        let (h2, w2) = (h.div_ceil(2), w.div_ceil(2));
        let (h4, w4) = (h2.div_ceil(2), w2.div_ceil(2));
        let mut tensors =
            vec![TensorSpec { shape: Shape::new(1, h, w), zero_point: -128, scale: 1.0 / 255.0 }];
        for (c, hh, ww) in [
            (8, h2, w2),  // 1 conv 3x3 s2
            (8, h4, w4),  // 2 dw s2
            (12, h4, w4), // 3 pw
            (12, 2, 2),   // 4 pool
            (12, h4, w4), // 5 resize
            (12, h4, w4), // 6 add
            (24, h4, w4), // 7 concat
            (24, h4, w4), // 8 relu
            (5, h4, w4),  // 9 pw classifier
            (5, h, w),    // 10 resize to input size
        ] {
            tensors.push(t(c, hh, ww, rng));
        }
        let mut n = Net { tensors, w: vec![], b: vec![], rq: vec![] };
        for (co, len) in [(8usize, 8 * 9), (8, 9 * 8), (12, 12 * 8), (5, 5 * 24)] {
            n.w.push(rng.weights(len));
            n.b.push((0..co).map(|_| rng.int(-2000, 2000) as i32).collect());
            n.rq.push((0..co).map(|_| Requant::from_scale(rng.f64(0.0005, 0.01))).collect());
        }
        let blob = encode(&n, h4, w4);
        (n, blob)
    }

    fn encode(n: &Net, h4: usize, w4: usize) -> Vec<u8> {
        let conv = |k: usize, kind, input, output, g: ConvGeometry, relu| OpSpec::Conv {
            kind,
            input,
            output,
            geometry: g,
            weights: &n.w[k],
            bias: &n.b[k],
            requant: &n.rq[k],
            relu,
        };
        let g3s2 = ConvGeometry { kernel: (3, 3), stride: (2, 2), pads: [1; 4] };
        let g1 = ConvGeometry { kernel: (1, 1), stride: (1, 1), pads: [0; 4] };
        let mut cat = [0u32; MAX_INPUTS];
        cat[0] = 5;
        cat[1] = 6;
        let pool = AvgPoolParams::ppm(Shape::new(12, h4, w4), 2).unwrap();
        let ops = [
            conv(0, OpKind::Conv, 0, 1, g3s2, true),
            conv(1, OpKind::Depthwise3x3, 1, 2, g3s2, true),
            conv(2, OpKind::Pointwise, 2, 3, g1, false),
            OpSpec::AvgPool {
                input: 3,
                output: 4,
                kernel: pool.kernel,
                pad_bottom_right: pool.pad_bottom_right,
            },
            OpSpec::Resize { input: 4, output: 5 },
            OpSpec::Add { a: 3, b: 5, output: 6, relu: true },
            OpSpec::Concat { inputs: cat, n: 2, output: 7 },
            OpSpec::Relu { input: 7, output: 8 },
            conv(3, OpKind::Pointwise, 8, 9, g1, false),
            OpSpec::Resize { input: 9, output: 10 },
        ];
        let mut offsets = vec![0u32; n.tensors.len()];
        let arena = plan_arena(&n.tensors, &ops, 0, 10, &mut offsets).unwrap();
        let mut blob = vec![0u8; encoded_len(&n.tensors, &ops)];
        write(&n.tensors, &ops, 0, 10, &offsets, arena, &mut blob).unwrap();
        blob
    }

    /// The blob in a 4-byte aligned buffer.
    fn aligned(blob: &[u8]) -> Vec<u32> {
        let mut v = vec![0u32; blob.len().div_ceil(4)];
        bytemuck::cast_slice_mut::<u32, u8>(&mut v)[..blob.len()].copy_from_slice(blob);
        v
    }

    #[test]
    fn fast_and_reference_graphs_are_bit_equal() {
        let mut rng = Rng::new(7);
        for case in 0..12 {
            let (h, w) = (rng.usize(9, 40), rng.usize(9, 40));
            let (_n, blob) = net(&mut rng, h, w);
            let words = aligned(&blob);
            let bytes = &bytemuck::cast_slice::<u32, u8>(&words)[..blob.len()];
            let m = Model::parse(bytes).unwrap();
            assert_eq!(m.n_ops(), 10);
            let input: Vec<u8> = (0..h * w).map(|_| rng.int(0, 255) as u8).collect();
            let mut a2 = vec![0i8; m.arena_len()];
            let o2 = run(&m, &input, &mut a2, Kernels::Reference).unwrap().to_vec();
            // the fast kernels at every instruction-set level of this CPU
            let mut o1 = Vec::new();
            for_each_level(|level| {
                let mut a1 = vec![0i8; m.arena_len()];
                o1 = run(&m, &input, &mut a1, Kernels::Fast).unwrap().to_vec();
                assert_eq!(o1, o2, "{level}, case {case} {h}x{w}");
            });
            assert_eq!(o1.len(), 5 * h * w);
            // not a constant output
            assert!(o1.iter().any(|&v| v != o1[0]), "case {case}");
            let mut labels = vec![0u8; h * w];
            argmax(&o1, m.output_shape(), &mut labels).unwrap();
            assert!(labels.iter().all(|&l| l < 5));
        }
    }

    #[test]
    fn arena_plan_reuses_memory_and_is_checked() {
        let mut rng = Rng::new(3);
        let (n, blob) = net(&mut rng, 64, 64);
        let words = aligned(&blob);
        let bytes = &bytemuck::cast_slice::<u32, u8>(&words)[..blob.len()];
        let m = Model::parse(bytes).unwrap();
        let total: usize = n.tensors.iter().map(|t| t.shape.len()).sum();
        assert!(m.arena_len() < total, "plan {} vs sum {}", m.arena_len(), total);
        // too small an arena is an error, not a panic
        let mut small = vec![0i8; m.arena_len() - 1];
        let input = vec![0u8; 64 * 64];
        assert!(matches!(
            run(&m, &input, &mut small, Kernels::Fast),
            Err(ModelError::ArenaTooSmall { .. })
        ));
        assert!(matches!(
            run(&m, &input[1..], &mut vec![0i8; m.arena_len()], Kernels::Fast),
            Err(ModelError::Truncated { .. })
        ));
    }

    #[test]
    fn corrupt_blobs_are_rejected_with_their_error() {
        let mut rng = Rng::new(5);
        let (_n, blob) = net(&mut rng, 20, 24);
        let parse = |b: &[u8]| {
            let words = aligned(b);
            Model::parse(&bytemuck::cast_slice::<u32, u8>(&words)[..b.len()]).map(|_| ())
        };
        assert_eq!(parse(&blob), Ok(()));
        let mut bad = blob.clone();
        bad[0] = b'X';
        assert_eq!(parse(&bad), Err(ModelError::BadMagic));
        let mut bad = blob.clone();
        bad[8] = 9;
        assert_eq!(parse(&bad), Err(ModelError::UnsupportedVersion { got: 9 }));
        assert!(matches!(parse(&blob[..blob.len() - 1]), Err(ModelError::Truncated { .. })));
        assert!(matches!(parse(&blob[..10]), Err(ModelError::Truncated { .. })));
        // every single bit flip after the CRC field is caught
        for i in (20..blob.len()).step_by(97) {
            let mut bad = blob.clone();
            bad[i] ^= 1 << (i % 8);
            assert!(matches!(parse(&bad), Err(ModelError::BadChecksum { .. })), "byte {i}");
        }
        // a structurally bad blob with a valid CRC: op 0 reading tensor 9 (not yet computed)
        let m_ops = u32::from_le_bytes(blob[44..48].try_into().unwrap()) as usize;
        let mut bad = blob.clone();
        bad[m_ops + 8..m_ops + 12].copy_from_slice(&9u32.to_le_bytes());
        let crc = super::super::model::crc32(&bad[20..]);
        bad[16..20].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(parse(&bad), Err(ModelError::BadOp { op: 0 }));
        // misaligned
        let words = aligned(&[&[0u8][..], &blob].concat());
        let b = &bytemuck::cast_slice::<u32, u8>(&words)[1..1 + blob.len()];
        assert_eq!(Model::parse(b).map(|_| ()), Err(ModelError::Misaligned));
    }

    #[test]
    fn segment_frame_labels_a_frame() {
        let mut rng = Rng::new(11);
        let (_n, blob) = net(&mut rng, 16, 24);
        let words = aligned(&blob);
        let m = Model::parse(&bytemuck::cast_slice::<u32, u8>(&words)[..blob.len()]).unwrap();
        let (sw, sh) = (45, 31);
        let luma: Vec<u8> = (0..sw * sh).map(|_| rng.int(0, 255) as u8).collect();
        let lb = Letterbox::fit(sw, sh, 16, 24).unwrap();
        assert_eq!((lb.num, lb.den), (2, 1));
        let (mut input, mut arena, mut labels) =
            (vec![0u8; 16 * 24], vec![0i8; m.arena_len()], vec![0u8; 16 * 24]);
        let mut out = vec![0u8; sw * sh];
        let bufs = SegBuffers { input: &mut input, arena: &mut arena, labels: &mut labels };
        segment_frame(&m, &lb, &luma, bufs, Kernels::Fast, &mut out).unwrap();
        // the same as doing the steps by hand
        let mut inp2 = vec![0u8; 16 * 24];
        prepare_input(&luma, &lb, &mut inp2).unwrap();
        let mut a2 = vec![0i8; m.arena_len()];
        let logits = run(&m, &inp2, &mut a2, Kernels::Reference).unwrap().to_vec();
        let mut l2 = vec![0u8; 16 * 24];
        argmax(&logits, m.output_shape(), &mut l2).unwrap();
        assert_eq!(labels, l2);
        assert_eq!(out[(2 * sw) + 2], l2[24 + 1]);
        // a letterbox for another input size is refused
        let other = Letterbox::fit(sw, sh, 32, 48).unwrap();
        let bufs = SegBuffers { input: &mut input, arena: &mut arena, labels: &mut labels };
        assert_eq!(
            segment_frame(&m, &other, &luma, bufs, Kernels::Fast, &mut out),
            Err(ModelError::BadIo)
        );
    }

    #[test]
    fn crc_matches_zlib() {
        // zlib.crc32(b"123456789") == 0xCBF43926
        assert_eq!(super::super::model::crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn letterbox_maps_frames_both_ways() {
        let lb = Letterbox::fit(1241, 376, 192, 640).unwrap();
        assert_eq!((lb.num, lb.den, lb.scaled_w(), lb.scaled_h()), (2, 1, 621, 188));
        let lb1 = Letterbox::fit(480, 360, 384, 480).unwrap();
        assert_eq!((lb1.num, lb1.den), (1, 1));
        assert!(Letterbox::fit(10000, 376, 192, 640).is_err());
        let (sw, sh) = (7, 5);
        let src: Vec<u8> = (0..sw * sh).map(|i| (i * 7 % 256) as u8).collect();
        // an integer scale of 2 (`fit` would take 5/4 here, see below)
        let lb = Letterbox { num: 2, den: 1, src_w: sw, src_h: sh, model_w: 6, model_h: 4 };
        let mut inp = vec![0u8; 24];
        prepare_input(&src, &lb, &mut inp).unwrap();
        // block (0,0): pixels 0,1,7,8 → values 0,7,49,56 → mean 28
        assert_eq!(inp[0], 28);
        // last column block is 1 pixel wide (x = 6): rows 0,1 → 42, 91 → 66.5 → 67
        assert_eq!(inp[3], 67);
        assert_eq!(inp[4], inp[3]);
        assert_eq!(inp[5], inp[3]);
        // last row block is 1 row (y = 4); row 3 of the map repeats row 2
        assert_eq!(&inp[18..24], &inp[12..18]);
        let labels: Vec<u8> = (0..24).map(|i| i as u8).collect();
        let mut out = vec![0u8; sw * sh];
        labels_to_frame(&labels, &lb, &mut out).unwrap();
        assert_eq!(out[0], 0);
        assert_eq!(out[6], 3);
        assert_eq!(out[4 * sw + 6], 2 * 6 + 3);
        assert!(prepare_input(&src[1..], &lb, &mut inp).is_err());
        // a scale `fit` cannot produce is refused, not read out of bounds
        let bad = Letterbox { num: 1, den: 1, ..lb };
        assert_eq!(prepare_input(&src, &bad, &mut inp), Err(ModelError::BadIo));
        assert_eq!(labels_to_frame(&labels, &bad, &mut out), Err(ModelError::BadIo));
    }

    /// The halving and unrolled fast paths of `prepare_input`, `labels_to_frame` and `argmax`
    /// give the bytes of their definitions (the general loops they replaced) on every scale
    /// `fit` picks for a range of frame sizes, odd edges included.
    #[test]
    fn letterbox_and_argmax_fast_paths_match_the_definitions() {
        fn input_reference(src: &[u8], lb: &Letterbox, out: &mut [u8]) {
            let (sw, sh, num, den) = (lb.src_w, lb.src_h, lb.num, lb.den);
            let (w, h) = (lb.scaled_w(), lb.scaled_h());
            for y in 0..lb.model_h {
                for x in 0..lb.model_w {
                    let (sx, sy) = (
                        Span::new(x.min(w - 1), num, den, sw),
                        Span::new(y.min(h - 1), num, den, sh),
                    );
                    let mut sum = 0u32;
                    for ky in 0..sy.count {
                        for kx in 0..sx.count {
                            let v = u32::from(src[(sy.first + ky) * sw + sx.first + kx]);
                            sum += sy.weight(ky) * sx.weight(kx) * v;
                        }
                    }
                    let n = sx.total * sy.total;
                    out[y * lb.model_w + x] = ((sum + n / 2) / n) as u8;
                }
            }
        }
        let mut rng = Rng::new(0x5eed_1e77);
        for &(sw, sh, mh, mw) in &[
            (1241usize, 376usize, 192usize, 640usize),
            (1226, 370, 192, 640),
            (1242, 375, 192, 640),
            (1241, 376, 256, 832),
            (1241, 376, 384, 1248),
            (480, 360, 384, 480),
            (7, 5, 4, 6),
            (9, 7, 4, 5),
            (20, 10, 5, 10),
        ] {
            let lb = Letterbox::fit(sw, sh, mh, mw).unwrap();
            let src: Vec<u8> = (0..sw * sh).map(|_| rng.usize(0, 256) as u8).collect();
            let (mut got, mut want) = (vec![0u8; mw * mh], vec![1u8; mw * mh]);
            prepare_input(&src, &lb, &mut got).unwrap();
            input_reference(&src, &lb, &mut want);
            assert!(got == want, "prepare_input {sw}x{sh} -> {mw}x{mh} ({}/{})", lb.num, lb.den);
            let labels: Vec<u8> = (0..mw * mh).map(|_| rng.usize(0, 256) as u8).collect();
            let mut out = vec![0u8; sw * sh];
            labels_to_frame(&labels, &lb, &mut out).unwrap();
            let at = |s: usize| ((2 * s + 1) * lb.den) / (2 * lb.num);
            for y in 0..sh {
                for x in 0..sw {
                    assert_eq!(
                        out[y * sw + x],
                        labels[at(y) * mw + at(x)],
                        "labels {sw}x{sh} ({x}, {y})"
                    );
                }
            }
        }
        for c in [1usize, 2, 5, crate::seg::NUM_CLASSES, 12, 19] {
            let shape = Shape { c, h: 7, w: 9 };
            // few distinct values, so ties are common: the first largest channel wins
            let logits: Vec<i8> = (0..shape.len()).map(|_| rng.int(-2, 2) as i8).collect();
            let mut labels = vec![0u8; 63];
            argmax(&logits, shape, &mut labels).unwrap();
            for (p, px) in logits.chunks_exact(c).enumerate() {
                let max = *px.iter().max().unwrap();
                let first = px.iter().position(|&v| v == max).unwrap();
                assert_eq!(usize::from(labels[p]), first, "argmax c = {c}, pixel {p}");
            }
        }
    }

    #[test]
    fn letterbox_takes_the_smallest_fractional_scale() {
        // KITTI into the 256x832 input: 3/2 (828x251), where whole factors give 2 (621x188)
        let lb = Letterbox::fit(1241, 376, 256, 832).unwrap();
        assert_eq!((lb.num, lb.den, lb.scaled_w(), lb.scaled_h()), (3, 2, 828, 251));
        // a 7x5 frame into 4x6: 5/4 (6x4), not 2 (4x3)
        let lb = Letterbox::fit(7, 5, 4, 6).unwrap();
        assert_eq!((lb.num, lb.den, lb.scaled_w(), lb.scaled_h()), (5, 4, 6, 4));
        // equal scales keep the smaller denominator: 4/2 and 8/4 are 2/1
        let lb = Letterbox::fit(20, 10, 5, 10).unwrap();
        assert_eq!((lb.num, lb.den), (2, 1));
        // every frame width from 1 to 200 into every input width from 1 to 40: the scale
        // found is the smallest of all num/den (den ≤ 4, ≤ 8) that fit
        for sw in 1..200 {
            for mw in 1..40 {
                let fits = |n: usize, d: usize| (sw * d).div_ceil(n) <= mw;
                let brute = (1..=4)
                    .flat_map(|d| (d..=8 * d).map(move |n| (n, d)))
                    .filter(|&(n, d)| fits(n, d))
                    .min_by(|a, b| (a.0 * b.1).cmp(&(b.0 * a.1)).then(a.1.cmp(&b.1)));
                let got = Letterbox::fit(sw, 1, 1, mw).ok().map(|l| (l.num, l.den));
                assert_eq!(got, brute, "{sw} into {mw}");
            }
        }
    }

    #[test]
    fn fractional_letterbox_is_the_area_mean() {
        // 3/2: input pixel 0 covers frame pixels 0 and half of 1, input pixel 1 the other
        // half of 1 and pixel 2 (per axis)
        let (sw, sh) = (5, 3);
        let src: Vec<u8> = (0..sw * sh).map(|i| (i * 17 % 256) as u8).collect();
        let lb = Letterbox { num: 3, den: 2, src_w: sw, src_h: sh, model_w: 4, model_h: 2 };
        assert_eq!((lb.scaled_w(), lb.scaled_h()), (4, 2));
        let mut inp = vec![0u8; 8];
        prepare_input(&src, &lb, &mut inp).unwrap();
        let px = |x: usize, y: usize| src[y * sw + x] as f64;
        // weights per axis in halves: pixel 0 → (0: 2, 1: 1); pixel 1 → (1: 1, 2: 2);
        // pixel 2 → (3: 2, 4: 1); pixel 3 → (4: 1) only (the frame ends at 5)
        let axis = |i: usize, len: usize| -> Vec<(usize, f64)> {
            let (lo, hi) = (i * 3, ((i + 1) * 3).min(len * 2));
            (lo / 2..hi.div_ceil(2))
                .map(|s| (s, ((s * 2 + 2).min(hi) - (s * 2).max(lo)) as f64))
                .collect()
        };
        for y in 0..2 {
            for x in 0..4 {
                let (ax, ay) = (axis(x, sw), axis(y, sh));
                let (mut s, mut n) = (0.0, 0.0);
                for &(fy, wy) in &ay {
                    for &(fx, wx) in &ax {
                        s += wx * wy * px(fx, fy);
                        n += wx * wy;
                    }
                }
                assert_eq!(inp[y * 4 + x], (s / n + 0.5).floor() as u8, "({x}, {y})");
            }
        }
        // labels back: frame pixel centres 0.5, 1.5, 2.5, 3.5, 4.5 → input 0.33, 1, 1.67,
        // 2.33, 3 → columns 0, 1, 1, 2, 3; rows 0.33, 1, 1.67 → 0, 1, 1
        let labels: Vec<u8> = (0..8).map(|i| i as u8).collect();
        let mut out = vec![0u8; sw * sh];
        labels_to_frame(&labels, &lb, &mut out).unwrap();
        assert_eq!(&out[..5], &[0, 1, 1, 2, 3]);
        assert_eq!(&out[5..10], &[4, 5, 5, 6, 7]);
        assert_eq!(&out[10..15], &[4, 5, 5, 6, 7]);
    }
}
