//! # The `.slm` model blob: format, writer, arena planner and zero-copy parser
//!
//! One file holds a whole quantised network: the tensors (shape, int8 quantisation, place in
//! the activation arena), the operators in execution order, and the constant data (int8
//! weights, `i32` biases, per-channel [`Requant`]s). [`Model::parse`] checks everything once —
//! magic, version, length, CRC-32, every range, shape, parameter and the arena plan — and then
//! hands out views into the caller's `&[u8]` without copying or allocating: weights are
//! `&[i8]`, biases `&[i32]`, requantisers `&[Requant]` straight from the blob. A blob that
//! parses cannot make the executor fail.
//!
//! The host's converter (`semloc convert`) lowers the ONNX graph + `quant.json` to
//! [`TensorSpec`]s and [`OpSpec`]s; [`plan_arena`] places the activations and [`write()`] encodes
//! them. Writer and parser live here together so there is one definition of the format.
//!
//! ## Layout (version 2, little-endian, offsets from the blob start)
//!
//! ```text
//! 0   magic  "SEMLOCNN"            8 bytes
//! 8   version u32 = 2
//! 12  total_len u32                whole blob, bytes
//! 16  crc32 u32                    CRC-32 (IEEE, as zlib) of bytes [20, total_len)
//! 20  n_tensors u32, 24 n_ops u32
//! 28  input tensor u32, 32 output tensor u32
//! 36  arena_len u32                bytes of activation arena the plan needs (the peak)
//! 40  tensors_off u32, 44 ops_off u32, 48 data_off u32, 52 data_len u32
//! 56  reserved (8 bytes, zero)
//! 64  tensor records, 32 bytes each: c, h, w u32; zero_point i32; scale f64; arena_off u32; 0
//! ..  op records, 80 bytes each (see `OP_RECORD`): kind u8, relu u8, n_inputs u8, 0;
//!     output u32; inputs [u32; 8]; kernel h, w, stride h, w, pads t, l, b, r (u16 each);
//!     weights off/len, bias off, requant off (u32, relative to data_off); 8 bytes zero
//! ..  data, 16-byte aligned: weights (i8), biases (i32), requantisers (i32 multiplier, i32 shift)
//! ```
//!
//! Weight layouts are those of the kernels: general conv `O·kh·kw·I`, depthwise `3·3·C`,
//! pointwise **packed** (version 2; version 1 stored `O·I`): [`write()`] takes `O·I` in the
//! [`OpSpec`] and stores [`pack_pointwise`]'s `[⌈O/8⌉][⌈I/4⌉][8][4]` blocks (8 output channels
//! × 4 input channels per 32 bytes, zero padding, `pointwise_packed_len(O, I)` bytes), the
//! layout the 1×1 GEMM reads without copying; the parser hands that layout out (and rejects
//! non-zero padding). The blob must sit at a 4-byte-aligned address (`include_bytes!` does not
//! promise that: wrap it in an aligned struct) — [`ModelError::Misaligned`] says so otherwise.
//!
//! **Memory:** parsing keeps only the `&[u8]`; [`Model`] is a few words. The activation arena
//! is the caller's `&mut [i8]` of [`Model::arena_len`] bytes.

use core::fmt;

use super::conv::{
    depthwise3x3_output_shape, pack_pointwise, pointwise_packed_len, pointwise_padding_is_zero,
    Conv2dParams,
};
use super::pool::AvgPoolParams;
use super::{NnError, Requant, Shape, MAX_REDUCTION};

#[cfg(target_endian = "big")]
compile_error!("the .slm blob is read in place as little-endian data");

/// The magic bytes that open every blob.
pub const MAGIC: [u8; 8] = *b"SEMLOCNN";
/// The format version this code reads and writes.
pub const VERSION: u32 = 2;
/// Header size in bytes.
pub const HEADER_LEN: usize = 64;
/// Bytes per tensor record.
pub const TENSOR_RECORD: usize = 32;
/// Bytes per op record.
pub const OP_RECORD: usize = 80;
/// Most inputs of one op (a `Concat`).
pub const MAX_INPUTS: usize = 8;
/// Most tensors in a graph (the Res2Net variant has 163).
pub const MAX_TENSORS: usize = 1024;
/// Most ops in a graph (the Res2Net variant has 162 after ReLU fusion).
pub const MAX_OPS: usize = 1024;
/// Largest tensor, elements (a 2048 x 1024 map of 16 channels).
pub const MAX_TENSOR_LEN: usize = 1 << 25;

/// The operator kinds of the format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum OpKind {
    /// General conv (`group = 1`), any kernel, stride and pads.
    Conv = 1,
    /// Depthwise 3x3 conv (`group = C`), stride 1 or 2, pad 1.
    Depthwise3x3 = 2,
    /// 1x1 conv, stride 1, no pads.
    Pointwise = 3,
    /// Element-wise `Add` of two same-shaped tensors.
    Add = 4,
    /// `Concat` along channels.
    Concat = 5,
    /// `AveragePool`, window = stride, bottom/right pads, `count_include_pad = 0`.
    AvgPool = 6,
    /// Bilinear `Resize`, `half_pixel`, to the output tensor's size.
    Resize = 7,
    /// Standalone `Relu` (one not fused into a conv or add).
    Relu = 8,
}

impl OpKind {
    fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            1 => Self::Conv,
            2 => Self::Depthwise3x3,
            3 => Self::Pointwise,
            4 => Self::Add,
            5 => Self::Concat,
            6 => Self::AvgPool,
            7 => Self::Resize,
            8 => Self::Relu,
            _ => return None,
        })
    }
}

/// Errors of parsing, planning and writing a blob. Numbers say where.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ModelError {
    /// The first 8 bytes are not [`MAGIC`].
    BadMagic,
    /// A version this code does not read.
    UnsupportedVersion {
        /// The version in the blob.
        got: u32,
    },
    /// The blob (or a buffer) is shorter than it must be.
    Truncated {
        /// Bytes needed.
        need: usize,
        /// Bytes there.
        got: usize,
    },
    /// The CRC-32 over the blob does not match the header: the file is corrupt.
    BadChecksum {
        /// The stored CRC.
        stored: u32,
        /// The CRC of the bytes.
        computed: u32,
    },
    /// The blob does not start at a 4-byte-aligned address.
    Misaligned,
    /// A count is over its limit ([`MAX_TENSORS`], [`MAX_OPS`]) or zero.
    TooMany {
        /// The count in the blob.
        got: usize,
        /// The limit.
        max: usize,
    },
    /// A header section or data range lies outside the blob or overlaps another.
    BadSection,
    /// A tensor record is invalid (empty or oversized shape, zero point outside int8, scale not
    /// finite and positive, arena range outside the arena).
    BadTensor {
        /// Tensor index.
        tensor: usize,
    },
    /// An op record is invalid: unknown kind, a tensor index out of range or not yet computed,
    /// parameters that do not fit the shapes, constant data out of range.
    BadOp {
        /// Op index.
        op: usize,
    },
    /// The arena plan lets an op's output overwrite a tensor still needed.
    ArenaOverlap {
        /// Op index.
        op: usize,
    },
    /// The arena given to the executor (or the plan) is smaller than the blob needs.
    ArenaTooSmall {
        /// Bytes needed.
        need: usize,
        /// Bytes given.
        got: usize,
    },
    /// The input or output tensor is not what the executor can use (input: 1 channel with
    /// scale 1/255 and zero point −128; output: produced by an op).
    BadIo,
    /// [`Model::attach`] was given other memory than the layout was parsed from.
    NotParsed,
    /// A kernel refused an op's operands (cannot happen for a blob that parsed).
    Kernel {
        /// Op index.
        op: usize,
        /// The kernel's error.
        error: NnError,
    },
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BadMagic => write!(f, "not a semloc model blob (bad magic)"),
            Self::UnsupportedVersion { got } => {
                write!(f, "model blob version {got} is not supported (this build reads {VERSION})")
            }
            Self::Truncated { need, got } => {
                write!(f, "model blob truncated: need {need} bytes, got {got}")
            }
            Self::BadChecksum { stored, computed } => write!(
                f,
                "model blob corrupt: CRC-32 {computed:#010x} does not match stored {stored:#010x}"
            ),
            Self::Misaligned => write!(f, "model blob is not 4-byte aligned in memory"),
            Self::TooMany { got, max } => write!(f, "model blob count {got} outside 1..={max}"),
            Self::BadSection => write!(f, "model blob section out of range"),
            Self::BadTensor { tensor } => write!(f, "model blob tensor {tensor} is invalid"),
            Self::BadOp { op } => write!(f, "model blob op {op} is invalid"),
            Self::ArenaOverlap { op } => {
                write!(f, "model blob arena plan: op {op} overwrites a live tensor")
            }
            Self::ArenaTooSmall { need, got } => {
                write!(f, "activation arena too small: need {need} bytes, got {got}")
            }
            Self::BadIo => write!(f, "model blob input/output tensors are not usable"),
            Self::NotParsed => write!(f, "model bytes are not the ones that were parsed"),
            Self::Kernel { op, error } => write!(f, "model op {op}: {error}"),
        }
    }
}

impl core::error::Error for ModelError {}

/// A tensor of the graph: shape and int8 quantisation (`real = scale · (q − zero_point)`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TensorSpec {
    /// Shape (batch 1, NHWC in memory).
    pub shape: Shape,
    /// Zero point, `-128..=127`.
    pub zero_point: i32,
    /// Scale, finite and positive.
    pub scale: f64,
}

/// Geometry of a conv op in the format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvGeometry {
    /// Kernel height and width.
    pub kernel: (usize, usize),
    /// Vertical and horizontal stride.
    pub stride: (usize, usize),
    /// Pads `[top, left, bottom, right]`.
    pub pads: [usize; 4],
}

/// One operator, as the writer takes it and the parser returns it (with the constant data
/// borrowed from the blob).
#[derive(Clone, Copy, Debug)]
pub enum OpSpec<'a> {
    /// A conv of any of the three conv kinds ([`OpKind::Conv`], [`OpKind::Depthwise3x3`],
    /// [`OpKind::Pointwise`]).
    Conv {
        /// Which conv kernel.
        kind: OpKind,
        /// Input tensor.
        input: u32,
        /// Output tensor.
        output: u32,
        /// Geometry (depthwise: 3x3, pad 1; pointwise: 1x1, stride 1, no pads).
        geometry: ConvGeometry,
        /// Weights. General conv `O·kh·kw·I`, depthwise `3·3·C`; pointwise: `O·I` when given
        /// to [`write()`], packed ([`pack_pointwise`]) when returned by the parser.
        weights: &'a [i8],
        /// One `i32` bias per output channel (scale `s_in · s_w[c]`).
        bias: &'a [i32],
        /// One requantiser per output channel (`s_in · s_w[c] / s_out`).
        requant: &'a [Requant],
        /// A fused `Relu`.
        relu: bool,
    },
    /// `Add(a, b)`, optionally with a fused `Relu`.
    Add {
        /// First input.
        a: u32,
        /// Second input.
        b: u32,
        /// Output tensor.
        output: u32,
        /// A fused `Relu`.
        relu: bool,
    },
    /// `Concat` along channels of `inputs[..n]`.
    Concat {
        /// Input tensors (the first `n`).
        inputs: [u32; MAX_INPUTS],
        /// How many inputs.
        n: usize,
        /// Output tensor.
        output: u32,
    },
    /// PPM `AveragePool`.
    AvgPool {
        /// Input tensor.
        input: u32,
        /// Output tensor.
        output: u32,
        /// Window = stride.
        kernel: (usize, usize),
        /// Bottom and right zero pads.
        pad_bottom_right: (usize, usize),
    },
    /// Bilinear `half_pixel` resize to the output tensor's `h x w`.
    Resize {
        /// Input tensor.
        input: u32,
        /// Output tensor.
        output: u32,
    },
    /// Standalone `Relu`.
    Relu {
        /// Input tensor.
        input: u32,
        /// Output tensor.
        output: u32,
    },
}

impl<'a> OpSpec<'a> {
    /// The op's kind.
    pub fn kind(&self) -> OpKind {
        match self {
            Self::Conv { kind, .. } => *kind,
            Self::Add { .. } => OpKind::Add,
            Self::Concat { .. } => OpKind::Concat,
            Self::AvgPool { .. } => OpKind::AvgPool,
            Self::Resize { .. } => OpKind::Resize,
            Self::Relu { .. } => OpKind::Relu,
        }
    }

    /// The output tensor.
    pub fn output(&self) -> u32 {
        match self {
            Self::Conv { output, .. }
            | Self::Add { output, .. }
            | Self::Concat { output, .. }
            | Self::AvgPool { output, .. }
            | Self::Resize { output, .. }
            | Self::Relu { output, .. } => *output,
        }
    }

    /// The input tensors, in order, and how many there are.
    pub fn inputs(&self) -> ([u32; MAX_INPUTS], usize) {
        let mut v = [0u32; MAX_INPUTS];
        let n = match self {
            Self::Conv { input, .. }
            | Self::AvgPool { input, .. }
            | Self::Resize { input, .. }
            | Self::Relu { input, .. } => {
                v[0] = *input;
                1
            }
            Self::Add { a, b, .. } => {
                v[0] = *a;
                v[1] = *b;
                2
            }
            Self::Concat { inputs, n, .. } => {
                v = *inputs;
                *n
            }
        };
        (v, n)
    }

    /// Multiply-accumulates of a conv op for an output of `out` (0 for the other ops).
    pub fn macs(&self, input: Shape, out: Shape) -> u64 {
        match self {
            Self::Conv { kind, geometry, .. } => {
                let per = match kind {
                    OpKind::Depthwise3x3 => 9,
                    _ => geometry.kernel.0 * geometry.kernel.1 * input.c,
                };
                (out.len() as u64) * per as u64
            }
            _ => 0,
        }
    }
}

/// Checks an op against the tensor shapes: that its parameters are ones the kernels accept and
/// its output shape is the one the parameters give. `Ok` means the executor cannot fail on it.
fn check_op(op: &OpSpec<'_>, tensors: &dyn Fn(u32) -> Option<TensorSpec>) -> bool {
    let (ins, n) = op.inputs();
    if n == 0 || n > MAX_INPUTS {
        return false;
    }
    let Some(out) = tensors(op.output()) else { return false };
    let mut shapes = [Shape::new(0, 0, 0); MAX_INPUTS];
    for (s, &i) in shapes.iter_mut().zip(&ins[..n]) {
        match tensors(i) {
            Some(t) => *s = t.shape,
            None => return false,
        }
    }
    let x = shapes[0];
    match *op {
        OpSpec::Conv { kind, geometry: g, weights, bias, requant, .. } => {
            let co = out.shape.c;
            let (wlen, expect) = match kind {
                OpKind::Conv => {
                    let p = Conv2dParams {
                        c_out: co,
                        kernel: g.kernel,
                        stride: g.stride,
                        pads: g.pads,
                    };
                    let red = g.kernel.0.saturating_mul(g.kernel.1).saturating_mul(x.c);
                    if red > MAX_REDUCTION {
                        return false;
                    }
                    (co.saturating_mul(red), p.output_shape(x).ok())
                }
                OpKind::Depthwise3x3 => {
                    let ok = g.kernel == (3, 3)
                        && g.stride.0 == g.stride.1
                        && g.pads == [1; 4]
                        && co == x.c;
                    if !ok {
                        return false;
                    }
                    (9 * x.c, depthwise3x3_output_shape(x, g.stride.0).ok())
                }
                OpKind::Pointwise => {
                    let ok = g.kernel == (1, 1) && g.stride == (1, 1) && g.pads == [0; 4];
                    if !ok || x.c > MAX_REDUCTION || !pointwise_padding_is_zero(weights, co, x.c) {
                        return false;
                    }
                    (pointwise_packed_len(co, x.c), Some(Shape::new(co, x.h, x.w)))
                }
                _ => return false,
            };
            expect == Some(out.shape)
                && weights.len() == wlen
                && bias.len() == co
                && requant.len() == co
                && requant.iter().all(|r| (-31..=30).contains(&r.shift) && r.multiplier >= 0)
        }
        OpSpec::Add { .. } => shapes[1] == x && out.shape == x,
        OpSpec::Concat { n, .. } => {
            let mut c = 0usize;
            for s in &shapes[..n] {
                if s.h != out.shape.h || s.w != out.shape.w {
                    return false;
                }
                c += s.c;
            }
            c == out.shape.c
        }
        OpSpec::AvgPool { kernel, pad_bottom_right, .. } => {
            let p = AvgPoolParams { kernel, pad_bottom_right };
            p.output_shape(x).ok() == Some(out.shape)
        }
        OpSpec::Resize { .. } => out.shape.c == x.c,
        OpSpec::Relu { .. } => out.shape == x,
    }
}

/// For each tensor, the index of the last op that reads it (`None`: never read), into `last`.
fn last_uses(ops: &[OpSpec<'_>], n_tensors: usize, last: &mut [Option<usize>]) {
    for l in last.iter_mut().take(n_tensors) {
        *l = None;
    }
    for (k, op) in ops.iter().enumerate() {
        let (ins, n) = op.inputs();
        for &i in &ins[..n] {
            if let Some(l) = last.get_mut(i as usize) {
                *l = Some(k);
            }
        }
    }
}

/// Places every tensor in the arena, greedy in execution order: an op's output goes to the
/// lowest 16-byte-aligned offset that overlaps no tensor still live (computed earlier and read
/// by this op or a later one; the graph input and output stay live throughout). Writes the
/// offsets into `offsets` (one per tensor) and returns the arena length, the peak.
///
/// Fixed memory: the only scratch is a stack array of [`MAX_TENSORS`] last-use indices.
pub fn plan_arena(
    tensors: &[TensorSpec],
    ops: &[OpSpec<'_>],
    input: u32,
    output: u32,
    offsets: &mut [u32],
) -> Result<usize, ModelError> {
    let nt = tensors.len();
    if nt == 0 || nt > MAX_TENSORS {
        return Err(ModelError::TooMany { got: nt, max: MAX_TENSORS });
    }
    if ops.is_empty() || ops.len() > MAX_OPS {
        return Err(ModelError::TooMany { got: ops.len(), max: MAX_OPS });
    }
    if offsets.len() < nt {
        return Err(ModelError::Truncated { need: nt, got: offsets.len() });
    }
    let mut last = [None; MAX_TENSORS];
    last_uses(ops, nt, &mut last);
    let keep = |t: usize, k: usize| {
        t == input as usize || t == output as usize || last[t].is_some_and(|l| l >= k)
    };
    let mut placed = [false; MAX_TENSORS];
    let input = input as usize;
    if input >= nt {
        return Err(ModelError::BadIo);
    }
    offsets[input] = 0;
    placed[input] = true;
    let mut peak = align16(tensors[input].shape.len());
    for (k, op) in ops.iter().enumerate() {
        let o = op.output() as usize;
        if o >= nt || placed[o] {
            return Err(ModelError::BadOp { op: k });
        }
        let len = tensors[o].shape.len();
        // candidate offsets: 0 and the end of every live tensor, lowest that fits
        let mut best: Option<usize> = None;
        let fits = |start: usize| {
            (0..nt).all(|t| {
                !placed[t]
                    || !keep(t, k)
                    || overlap(start, len, offsets[t] as usize, tensors[t].shape.len()) == 0
            })
        };
        if fits(0) {
            best = Some(0);
        }
        for t in 0..nt {
            if placed[t] && keep(t, k) {
                let start = align16(offsets[t] as usize + tensors[t].shape.len());
                if best.is_none_or(|b| start < b) && fits(start) {
                    best = Some(start);
                }
            }
        }
        let start = best.unwrap_or(peak);
        offsets[o] = u32::try_from(start).map_err(|_| ModelError::BadOp { op: k })?;
        placed[o] = true;
        peak = peak.max(align16(start + len));
    }
    Ok(peak)
}

fn align16(n: usize) -> usize {
    n.div_ceil(16) * 16
}

fn overlap(a: usize, alen: usize, b: usize, blen: usize) -> usize {
    let lo = a.max(b);
    let hi = (a + alen).min(b + blen);
    hi.saturating_sub(lo)
}

/// Bytes a conv op's weights take in the blob: packed for pointwise (from `O·I`, the input
/// tensor's channels being `I`), as given otherwise.
fn stored_weights_len(tensors: &[TensorSpec], op: &OpSpec<'_>) -> usize {
    match *op {
        OpSpec::Conv { kind: OpKind::Pointwise, input, bias, .. } => {
            tensors.get(input as usize).map_or(0, |t| pointwise_packed_len(bias.len(), t.shape.c))
        }
        OpSpec::Conv { weights, .. } => weights.len(),
        _ => 0,
    }
}

/// Bytes [`write()`] needs for this graph.
pub fn encoded_len(tensors: &[TensorSpec], ops: &[OpSpec<'_>]) -> usize {
    let mut data = 0usize;
    for op in ops {
        if let OpSpec::Conv { bias, requant, .. } = op {
            data = align16(data + stored_weights_len(tensors, op));
            data = align16(data + 4 * bias.len());
            data = align16(data + 8 * requant.len());
        }
    }
    align16(HEADER_LEN + TENSOR_RECORD * tensors.len() + OP_RECORD * ops.len()) + data
}

/// Encodes a graph into `out` (at least [`encoded_len`] bytes) and returns the length written.
/// `offsets` and `arena_len` come from [`plan_arena`]. The result is checked by parsing it.
pub fn write(
    tensors: &[TensorSpec],
    ops: &[OpSpec<'_>],
    input: u32,
    output: u32,
    offsets: &[u32],
    arena_len: usize,
    out: &mut [u8],
) -> Result<usize, ModelError> {
    let total = encoded_len(tensors, ops);
    if out.len() < total {
        return Err(ModelError::Truncated { need: total, got: out.len() });
    }
    if offsets.len() < tensors.len() {
        return Err(ModelError::Truncated { need: tensors.len(), got: offsets.len() });
    }
    let out = &mut out[..total];
    out.fill(0);
    let tensors_off = HEADER_LEN;
    let ops_off = tensors_off + TENSOR_RECORD * tensors.len();
    let data_off = align16(ops_off + OP_RECORD * ops.len());
    let to32 = |v: usize| u32::try_from(v).map_err(|_| ModelError::BadSection);
    out[..8].copy_from_slice(&MAGIC);
    put32(out, 8, VERSION);
    put32(out, 12, to32(total)?);
    put32(out, 20, to32(tensors.len())?);
    put32(out, 24, to32(ops.len())?);
    put32(out, 28, input);
    put32(out, 32, output);
    put32(out, 36, to32(arena_len)?);
    put32(out, 40, to32(tensors_off)?);
    put32(out, 44, to32(ops_off)?);
    put32(out, 48, to32(data_off)?);
    put32(out, 52, to32(total - data_off)?);
    for (i, t) in tensors.iter().enumerate() {
        let r = tensors_off + i * TENSOR_RECORD;
        put32(out, r, to32(t.shape.c)?);
        put32(out, r + 4, to32(t.shape.h)?);
        put32(out, r + 8, to32(t.shape.w)?);
        put32(out, r + 12, t.zero_point as u32);
        out[r + 16..r + 24].copy_from_slice(&t.scale.to_le_bytes());
        put32(out, r + 24, offsets[i]);
    }
    let mut data = 0usize;
    for (k, op) in ops.iter().enumerate() {
        let r = ops_off + k * OP_RECORD;
        let (ins, n) = op.inputs();
        out[r] = op.kind() as u8;
        out[r + 2] = n as u8;
        put32(out, r + 4, op.output());
        for (j, &i) in ins.iter().enumerate() {
            put32(out, r + 8 + 4 * j, i);
        }
        let mut geo = [0usize; 8];
        match *op {
            OpSpec::Conv { kind, input, geometry: g, weights, bias, requant, relu, .. } => {
                out[r + 1] = relu as u8;
                geo = [
                    g.kernel.0, g.kernel.1, g.stride.0, g.stride.1, g.pads[0], g.pads[1],
                    g.pads[2], g.pads[3],
                ];
                let base = data_off;
                let wlen = stored_weights_len(tensors, op);
                put32(out, r + 56, to32(data)?);
                put32(out, r + 60, to32(wlen)?);
                let dst = &mut out[base + data..base + data + wlen];
                if kind == OpKind::Pointwise {
                    let c_in = tensors.get(input as usize).map_or(0, |t| t.shape.c);
                    pack_pointwise(weights, bias.len(), c_in, bytemuck::cast_slice_mut(dst))
                        .map_err(|_| ModelError::BadOp { op: k })?;
                } else {
                    for (d, &w) in dst.iter_mut().zip(weights) {
                        *d = w as u8;
                    }
                }
                data = align16(data + wlen);
                put32(out, r + 64, to32(data)?);
                for (j, &b) in bias.iter().enumerate() {
                    put32(out, base + data + 4 * j, b as u32);
                }
                data = align16(data + 4 * bias.len());
                put32(out, r + 68, to32(data)?);
                for (j, q) in requant.iter().enumerate() {
                    put32(out, base + data + 8 * j, q.multiplier as u32);
                    put32(out, base + data + 8 * j + 4, q.shift as u32);
                }
                data = align16(data + 8 * requant.len());
            }
            OpSpec::Add { relu, .. } => out[r + 1] = relu as u8,
            OpSpec::AvgPool { kernel, pad_bottom_right, .. } => {
                geo = [
                    kernel.0,
                    kernel.1,
                    kernel.0,
                    kernel.1,
                    0,
                    0,
                    pad_bottom_right.0,
                    pad_bottom_right.1,
                ];
            }
            OpSpec::Concat { .. } | OpSpec::Resize { .. } | OpSpec::Relu { .. } => {}
        }
        for (j, &g) in geo.iter().enumerate() {
            let g = u16::try_from(g).map_err(|_| ModelError::BadOp { op: k })?;
            out[r + 40 + 2 * j..r + 42 + 2 * j].copy_from_slice(&g.to_le_bytes());
        }
    }
    let crc = crc32(&out[20..]);
    put32(out, 16, crc);
    Ok(total)
}

fn put32(out: &mut [u8], at: usize, v: u32) {
    out[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn get32(b: &[u8], at: usize) -> u32 {
    let mut v = [0u8; 4];
    v.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(v)
}

fn get16(b: &[u8], at: usize) -> usize {
    u16::from_le_bytes([b[at], b[at + 1]]) as usize
}

const CRC_TABLE: [u32; 256] = {
    let mut t = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            k += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

/// CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`).
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut c = !0u32;
    for &b in bytes {
        c = CRC_TABLE[((c ^ b as u32) & 0xff) as usize] ^ (c >> 8);
    }
    !c
}

/// A parsed, validated model: views into the blob, nothing copied.
#[derive(Clone, Copy, Debug)]
pub struct Model<'a> {
    blob: &'a [u8],
    n_tensors: usize,
    n_ops: usize,
    input: u32,
    output: u32,
    arena_len: usize,
    tensors_off: usize,
    ops_off: usize,
    data: &'a [u8],
}

/// A parsed model's layout without the borrow of its bytes: an owner of a blob keeps it and
/// calls [`Model::attach`] per use instead of parsing (CRC and validation, ~2–3 ms for the
/// 1.4 MB network) again. It remembers which memory was parsed (address and length); the owner
/// must not modify that memory afterwards (the host's `SlmBlob` never hands out `&mut`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ModelLayout {
    addr: usize,
    len: usize,
    n_tensors: usize,
    n_ops: usize,
    input: u32,
    output: u32,
    arena_len: usize,
    tensors_off: usize,
    ops_off: usize,
    data_off: usize,
}

impl<'a> Model<'a> {
    /// Parses and validates a blob (see the module docs for what is checked).
    pub fn parse(blob: &'a [u8]) -> Result<Self, ModelError> {
        if blob.len() < HEADER_LEN {
            return Err(ModelError::Truncated { need: HEADER_LEN, got: blob.len() });
        }
        if blob[..8] != MAGIC {
            return Err(ModelError::BadMagic);
        }
        let version = get32(blob, 8);
        if version != VERSION {
            return Err(ModelError::UnsupportedVersion { got: version });
        }
        let total = get32(blob, 12) as usize;
        if blob.len() < total || total < HEADER_LEN {
            return Err(ModelError::Truncated { need: total.max(HEADER_LEN), got: blob.len() });
        }
        let blob = &blob[..total];
        let stored = get32(blob, 16);
        let computed = crc32(&blob[20..]);
        if stored != computed {
            return Err(ModelError::BadChecksum { stored, computed });
        }
        if blob.as_ptr().align_offset(4) != 0 {
            return Err(ModelError::Misaligned);
        }
        let n_tensors = get32(blob, 20) as usize;
        let n_ops = get32(blob, 24) as usize;
        if n_tensors == 0 || n_tensors > MAX_TENSORS {
            return Err(ModelError::TooMany { got: n_tensors, max: MAX_TENSORS });
        }
        if n_ops == 0 || n_ops > MAX_OPS {
            return Err(ModelError::TooMany { got: n_ops, max: MAX_OPS });
        }
        let tensors_off = get32(blob, 40) as usize;
        let ops_off = get32(blob, 44) as usize;
        let data_off = get32(blob, 48) as usize;
        let data_len = get32(blob, 52) as usize;
        // Checked: on 32-bit targets (thumbv7em) an offset near u32::MAX plus the record
        // bytes would wrap and pass the ordering checks.
        let t_end = tensors_off.checked_add(TENSOR_RECORD * n_tensors);
        let o_end = ops_off.checked_add(OP_RECORD * n_ops);
        let (Some(t_end), Some(o_end)) = (t_end, o_end) else {
            return Err(ModelError::BadSection);
        };
        let sections_ok = tensors_off >= HEADER_LEN
            && ops_off >= t_end
            && data_off >= o_end
            && data_off.is_multiple_of(16)
            && data_off.checked_add(data_len) == Some(total);
        if !sections_ok {
            return Err(ModelError::BadSection);
        }
        let m = Model {
            blob,
            n_tensors,
            n_ops,
            input: get32(blob, 28),
            output: get32(blob, 32),
            arena_len: get32(blob, 36) as usize,
            tensors_off,
            ops_off,
            data: &blob[data_off..],
        };
        m.validate()?;
        Ok(m)
    }

    /// This model's layout, for [`Model::attach`].
    pub fn layout(&self) -> ModelLayout {
        ModelLayout {
            addr: self.blob.as_ptr() as usize,
            len: self.blob.len(),
            n_tensors: self.n_tensors,
            n_ops: self.n_ops,
            input: self.input,
            output: self.output,
            arena_len: self.arena_len,
            tensors_off: self.tensors_off,
            ops_off: self.ops_off,
            data_off: self.blob.len() - self.data.len(),
        }
    }

    /// The model [`Model::parse`] returned for exactly these bytes (same address and length:
    /// else [`ModelError::NotParsed`]), without parsing again.
    pub fn attach(layout: &ModelLayout, blob: &'a [u8]) -> Result<Self, ModelError> {
        let blob = blob.get(..layout.len).ok_or(ModelError::NotParsed)?;
        if blob.as_ptr() as usize != layout.addr || layout.data_off > blob.len() {
            return Err(ModelError::NotParsed);
        }
        Ok(Model {
            blob,
            n_tensors: layout.n_tensors,
            n_ops: layout.n_ops,
            input: layout.input,
            output: layout.output,
            arena_len: layout.arena_len,
            tensors_off: layout.tensors_off,
            ops_off: layout.ops_off,
            data: &blob[layout.data_off..],
        })
    }

    fn validate(&self) -> Result<(), ModelError> {
        for t in 0..self.n_tensors {
            let s = self.tensor_raw(t);
            let len = s.shape.len();
            let off = get32(self.blob, self.tensors_off + t * TENSOR_RECORD + 24) as usize;
            let ok = !s.shape.is_empty()
                && s.shape.c <= MAX_TENSOR_LEN
                && s.shape.h <= MAX_TENSOR_LEN
                && s.shape.w <= MAX_TENSOR_LEN
                && len <= MAX_TENSOR_LEN
                && (-128..=127).contains(&s.zero_point)
                && s.scale.is_finite()
                && s.scale > 0.0
                && off.checked_add(len).is_some_and(|e| e <= self.arena_len);
            if !ok {
                return Err(ModelError::BadTensor { tensor: t });
            }
        }
        let (input, output) = (self.input as usize, self.output as usize);
        if input >= self.n_tensors || output >= self.n_tensors || input == output {
            return Err(ModelError::BadIo);
        }
        let it = self.tensor_raw(input);
        if it.shape.c != 1 || it.zero_point != -128 {
            return Err(ModelError::BadIo);
        }
        // every op: record decodes, tensors computed before use, parameters fit the shapes
        let mut computed = [false; MAX_TENSORS];
        computed[input] = true;
        for k in 0..self.n_ops {
            let op = self.op_checked(k)?;
            let (ins, n) = op.inputs();
            let o = op.output() as usize;
            let inputs_ready = ins[..n].iter().all(|&i| computed.get(i as usize) == Some(&true));
            if !inputs_ready || o >= self.n_tensors || computed[o] {
                return Err(ModelError::BadOp { op: k });
            }
            let tensor =
                |i: u32| ((i as usize) < self.n_tensors).then(|| self.tensor_raw(i as usize));
            if !check_op(&op, &tensor) {
                return Err(ModelError::BadOp { op: k });
            }
            computed[o] = true;
        }
        if !computed[output] {
            return Err(ModelError::BadIo);
        }
        // the arena plan: no op's output overlaps a tensor that is live at that op
        let mut last = [None; MAX_TENSORS];
        for k in 0..self.n_ops {
            let (ins, n) = self.op(k).inputs();
            for &i in &ins[..n] {
                last[i as usize] = Some(k);
            }
        }
        let mut placed = [false; MAX_TENSORS];
        placed[input] = true;
        for k in 0..self.n_ops {
            let o = self.op(k).output() as usize;
            let (oo, ol) = (self.arena_offset(o), self.tensor_raw(o).shape.len());
            for t in 0..self.n_tensors {
                let live = t == input || t == output || last[t].is_some_and(|l| l >= k);
                if placed[t]
                    && live
                    && overlap(oo, ol, self.arena_offset(t), self.tensor_raw(t).shape.len()) > 0
                {
                    return Err(ModelError::ArenaOverlap { op: k });
                }
            }
            placed[o] = true;
        }
        Ok(())
    }

    fn tensor_raw(&self, t: usize) -> TensorSpec {
        let r = self.tensors_off + t * TENSOR_RECORD;
        let b = self.blob;
        let mut f = [0u8; 8];
        f.copy_from_slice(&b[r + 16..r + 24]);
        TensorSpec {
            shape: Shape::new(
                get32(b, r) as usize,
                get32(b, r + 4) as usize,
                get32(b, r + 8) as usize,
            ),
            zero_point: get32(b, r + 12) as i32,
            scale: f64::from_le_bytes(f),
        }
    }

    fn data_range<T: bytemuck::Pod>(&self, off: usize, n: usize) -> Option<&'a [T]> {
        let size = core::mem::size_of::<T>();
        let end = off.checked_add(n.checked_mul(size)?)?;
        let bytes = self.data.get(off..end)?;
        bytemuck::try_cast_slice(bytes).ok()
    }

    fn op_checked(&self, k: usize) -> Result<OpSpec<'a>, ModelError> {
        let bad = ModelError::BadOp { op: k };
        let r = self.ops_off + k * OP_RECORD;
        let b = self.blob;
        let kind = OpKind::from_u8(b[r]).ok_or(bad)?;
        let relu = match b[r + 1] {
            0 => false,
            1 => true,
            _ => return Err(bad),
        };
        let n = b[r + 2] as usize;
        if n == 0 || n > MAX_INPUTS {
            return Err(bad);
        }
        let output = get32(b, r + 4);
        let mut inputs = [0u32; MAX_INPUTS];
        for (j, i) in inputs.iter_mut().enumerate() {
            *i = get32(b, r + 8 + 4 * j);
        }
        let g = |j: usize| get16(b, r + 40 + 2 * j);
        let arity = match kind {
            OpKind::Add => 2,
            OpKind::Concat => n,
            _ => 1,
        };
        if n != arity
            || (relu
                && !matches!(
                    kind,
                    OpKind::Conv | OpKind::Depthwise3x3 | OpKind::Pointwise | OpKind::Add
                ))
        {
            return Err(bad);
        }
        Ok(match kind {
            OpKind::Conv | OpKind::Depthwise3x3 | OpKind::Pointwise => {
                let geometry = ConvGeometry {
                    kernel: (g(0), g(1)),
                    stride: (g(2), g(3)),
                    pads: [g(4), g(5), g(6), g(7)],
                };
                let co = self.tensor_raw_checked(output).ok_or(bad)?.shape.c;
                let wlen = get32(b, r + 60) as usize;
                OpSpec::Conv {
                    kind,
                    input: inputs[0],
                    output,
                    geometry,
                    weights: self.data_range::<i8>(get32(b, r + 56) as usize, wlen).ok_or(bad)?,
                    bias: self.data_range::<i32>(get32(b, r + 64) as usize, co).ok_or(bad)?,
                    requant: self
                        .data_range::<Requant>(get32(b, r + 68) as usize, co)
                        .ok_or(bad)?,
                    relu,
                }
            }
            OpKind::Add => OpSpec::Add { a: inputs[0], b: inputs[1], output, relu },
            OpKind::Concat => OpSpec::Concat { inputs, n, output },
            OpKind::AvgPool => {
                if (g(2), g(3)) != (g(0), g(1)) || g(4) != 0 || g(5) != 0 {
                    return Err(bad);
                }
                OpSpec::AvgPool {
                    input: inputs[0],
                    output,
                    kernel: (g(0), g(1)),
                    pad_bottom_right: (g(6), g(7)),
                }
            }
            OpKind::Resize => OpSpec::Resize { input: inputs[0], output },
            OpKind::Relu => OpSpec::Relu { input: inputs[0], output },
        })
    }

    fn tensor_raw_checked(&self, t: u32) -> Option<TensorSpec> {
        ((t as usize) < self.n_tensors).then(|| self.tensor_raw(t as usize))
    }

    /// Number of tensors.
    pub fn n_tensors(&self) -> usize {
        self.n_tensors
    }

    /// Number of ops.
    pub fn n_ops(&self) -> usize {
        self.n_ops
    }

    /// Tensor `t` (`t < n_tensors()`, else `None`).
    pub fn tensor(&self, t: usize) -> Option<TensorSpec> {
        (t < self.n_tensors).then(|| self.tensor_raw(t))
    }

    /// Byte offset of tensor `t` in the arena (validated at parse).
    pub fn arena_offset(&self, t: usize) -> usize {
        get32(self.blob, self.tensors_off + t * TENSOR_RECORD + 24) as usize
    }

    /// Op `k` (`k < n_ops()`; validated at parse, so decoding cannot fail).
    pub fn op(&self, k: usize) -> OpSpec<'a> {
        // validated in `parse`; the fallback is unreachable for a parsed model
        self.op_checked(k).unwrap_or(OpSpec::Relu { input: self.input, output: self.output })
    }

    /// The graph input tensor (1 channel, `q = luma − 128`).
    pub fn input(&self) -> u32 {
        self.input
    }

    /// The graph output tensor (the class logits).
    pub fn output(&self) -> u32 {
        self.output
    }

    /// The input map `(h, w)`.
    pub fn input_size(&self) -> (usize, usize) {
        let s = self.tensor_raw(self.input as usize).shape;
        (s.h, s.w)
    }

    /// The output shape (classes x h x w).
    pub fn output_shape(&self) -> Shape {
        self.tensor_raw(self.output as usize).shape
    }

    /// Bytes of activation arena the executor needs (the planned peak).
    pub fn arena_len(&self) -> usize {
        self.arena_len
    }

    /// Bytes of constant data (weights, biases, requantisers).
    pub fn data_len(&self) -> usize {
        self.data.len()
    }

    /// The whole blob.
    pub fn bytes(&self) -> &'a [u8] {
        self.blob
    }

    /// Total multiply-accumulates of one inference (convs only).
    pub fn macs(&self) -> u64 {
        (0..self.n_ops)
            .map(|k| {
                let op = self.op(k);
                let (ins, _) = op.inputs();
                op.macs(
                    self.tensor_raw(ins[0] as usize).shape,
                    self.tensor_raw(op.output() as usize).shape,
                )
            })
            .sum()
    }
}
