//! ONNX + `quant.json` → the int8 `.slm` blob (`semloc convert`).
//!
//! Lowers the float graph ([`OnnxGraph`]) with the quantisation parameters `models/quantise.py`
//! wrote to the core's [`TensorSpec`]s and [`OpSpec`]s, reproducing that script's arithmetic
//! exactly (it runs in float32 torch):
//!
//! - weights: `q = clamp(round_half_even(w_f32 / s_w_f32[c]), −127, 127)`, laid out as the
//!   kernels want them (`O·kh·kw·I` general, `3·3·C` depthwise, `O·I` pointwise);
//! - biases: `q = round_half_even(b_f32 / s_b_f32[c])` saturated to `i32` (`s_b` is the JSON
//!   `bias_scales`, the f32 product torch formed);
//! - requantisers: [`Requant::from_scale`]`(s_in · s_w[c] / s_out)` in f64 with the JSON scales;
//! - activations: the JSON per-tensor `scale`/`zero_point`; the input is `1/255`, `−128`;
//! - a `Conv`/`Add` listed in `fused` takes the ReLU that is its only consumer: its output
//!   tensor is that ReLU's output (the quantised one) and the op clamps at the zero point. An
//!   unfused `Relu` becomes [`OpSpec::Relu`].
//!
//! Conv kinds: `group = 1` is [`OpKind::Pointwise`] for a 1×1 / stride 1 / no-pad kernel and
//! [`OpKind::Conv`] otherwise; `group = C_in = C_out` with a 3×3 kernel, pad 1 and equal strides
//! is [`OpKind::Depthwise3x3`]; anything else is an error naming the node. The blob is encoded
//! with the core's [`plan_arena`] and [`write`], then parsed back (so a converted model is one
//! the executor accepts).
//!
//! Memory: the quantised weights (≈ 1.3 MB for the Res2Net net) and the blob.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use semloc_core::nn::model::{
    encoded_len, plan_arena, write, ConvGeometry, Model, ModelError, OpKind, OpSpec, TensorSpec,
    MAX_INPUTS,
};
use semloc_core::nn::{Requant, Shape};
use serde::Deserialize;

use super::onnx::{Node, OnnxGraph};
use super::{NnFileError, SlmBlob};

/// The input quantisation every model has: `q = luma − 128`.
pub const INPUT_SCALE: f64 = 1.0 / 255.0;
/// See [`INPUT_SCALE`].
pub const INPUT_ZERO_POINT: i32 = -128;

/// The parts of `quant.json` the converter reads (see `models/quantise.py`).
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
pub struct QuantParams {
    /// The graph input's quantisation.
    pub input: QuantInput,
    /// Per-tensor activation quantisation, by tensor name.
    pub activations: BTreeMap<String, QuantTensor>,
    /// Conv/Add outputs whose only consumer is a `Relu` (fused).
    pub fused: Vec<String>,
    /// Per-conv weight and bias scales, by node name.
    pub convs: BTreeMap<String, QuantConv>,
}

/// `input` of `quant.json`.
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
pub struct QuantInput {
    /// Graph input name.
    pub name: String,
    /// Its scale (must be 1/255).
    pub scale: f64,
    /// Its zero point (must be −128).
    #[serde(default = "default_input_zp")]
    pub zero_point: i64,
}

fn default_input_zp() -> i64 {
    i64::from(INPUT_ZERO_POINT)
}

/// One entry of `activations`.
#[derive(Clone, Copy, Debug, Deserialize, serde::Serialize)]
pub struct QuantTensor {
    /// `real = scale · (q − zero_point)`.
    pub scale: f64,
    /// Zero point, `−128..=127`.
    pub zero_point: i64,
}

/// One entry of `convs`.
#[derive(Clone, Debug, Deserialize, serde::Serialize)]
pub struct QuantConv {
    /// Input tensor name.
    pub input: String,
    /// Weight initializer name.
    pub weight: String,
    /// Bias initializer name, if any.
    pub bias: Option<String>,
    /// Output tensor name (before ReLU fusion).
    pub output: String,
    /// Per-output-channel weight scales (f32 values).
    pub weight_scales: Vec<f64>,
    /// Per-output-channel bias scales (f32 values).
    pub bias_scales: Vec<f64>,
}

impl QuantParams {
    /// Reads a `quant.json`.
    pub fn load(path: &Path) -> Result<Self, NnFileError> {
        let text = std::fs::read_to_string(path).map_err(|e| NnFileError::io(path, &e))?;
        serde_json::from_str(&text)
            .map_err(|e| NnFileError::QuantJson { path: path.to_path_buf(), msg: e.to_string() })
    }

    /// `X.quant.json` beside `X.onnx` (what `quantise.py` writes).
    pub fn default_path(onnx: &Path) -> PathBuf {
        onnx.with_extension("quant.json")
    }
}

/// One converted op, owning its constant data.
#[derive(Clone, Debug)]
pub enum ConvertedOp {
    /// A conv with its quantised weights, biases and requantisers.
    Conv {
        /// ONNX node name.
        node: String,
        /// Conv kernel kind.
        kind: OpKind,
        /// Input tensor.
        input: u32,
        /// Output tensor.
        output: u32,
        /// Kernel, strides, pads.
        geometry: ConvGeometry,
        /// int8 weights in the kernel's layout.
        weights: Vec<i8>,
        /// int32 biases.
        bias: Vec<i32>,
        /// Per-channel requantisers.
        requant: Vec<Requant>,
        /// Fused ReLU.
        relu: bool,
    },
    /// Any op without constant data.
    Plain {
        /// ONNX node name.
        node: String,
        /// The op.
        op: OpSpec<'static>,
    },
}

impl ConvertedOp {
    /// The ONNX node it came from.
    pub fn node(&self) -> &str {
        match self {
            Self::Conv { node, .. } | Self::Plain { node, .. } => node,
        }
    }

    /// The core op, borrowing the constant data.
    pub fn spec(&self) -> OpSpec<'_> {
        match self {
            Self::Conv { kind, input, output, geometry, weights, bias, requant, relu, .. } => {
                OpSpec::Conv {
                    kind: *kind,
                    input: *input,
                    output: *output,
                    geometry: *geometry,
                    weights,
                    bias,
                    requant,
                    relu: *relu,
                }
            }
            Self::Plain { op, .. } => *op,
        }
    }
}

/// A converted graph: tensors, ops (execution order), input and output.
#[derive(Clone, Debug)]
pub struct Converted {
    /// The ONNX file (named in errors).
    pub onnx: PathBuf,
    /// Tensors; index 0 is the input.
    pub tensors: Vec<TensorSpec>,
    /// ONNX name of each tensor.
    pub tensor_names: Vec<String>,
    /// Ops in execution order.
    pub ops: Vec<ConvertedOp>,
    /// Input tensor index.
    pub input: u32,
    /// Output tensor index.
    pub output: u32,
}

/// Figures of an encoded model, as `semloc convert` prints them.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ModelSummary {
    /// Tensors.
    pub tensors: usize,
    /// Ops.
    pub ops: usize,
    /// Ops per kind (`conv`, `depthwise3x3`, `pointwise`, `add`, ...).
    pub ops_by_kind: BTreeMap<String, usize>,
    /// Multiply-accumulates per inference (convs).
    pub macs: u64,
    /// int8 weight bytes.
    pub weight_bytes: usize,
    /// All constant data (weights, biases, requantisers, with alignment), bytes.
    pub data_bytes: usize,
    /// Activation arena (planned peak), bytes.
    pub arena_bytes: usize,
    /// Blob size, bytes.
    pub blob_bytes: usize,
    /// Input `(h, w)`.
    pub input_hw: (usize, usize),
    /// Output `(classes, h, w)`.
    pub output_chw: (usize, usize, usize),
    /// The CRC-32 in the header.
    pub crc32: u32,
}

impl ModelSummary {
    /// The figures of a parsed model.
    pub fn of(m: &Model<'_>) -> Self {
        let mut ops_by_kind = BTreeMap::new();
        let mut weight_bytes = 0;
        for k in 0..m.n_ops() {
            let op = m.op(k);
            *ops_by_kind.entry(kind_name(op.kind()).to_owned()).or_insert(0) += 1;
            if let OpSpec::Conv { weights, .. } = op {
                weight_bytes += weights.len();
            }
        }
        let o = m.output_shape();
        let b = m.bytes();
        ModelSummary {
            tensors: m.n_tensors(),
            ops: m.n_ops(),
            ops_by_kind,
            macs: m.macs(),
            weight_bytes,
            data_bytes: m.data_len(),
            arena_bytes: m.arena_len(),
            blob_bytes: b.len(),
            input_hw: m.input_size(),
            output_chw: (o.c, o.h, o.w),
            crc32: u32::from_le_bytes([b[16], b[17], b[18], b[19]]),
        }
    }
}

/// Lower-case name of an op kind.
pub fn kind_name(k: OpKind) -> &'static str {
    match k {
        OpKind::Conv => "conv",
        OpKind::Depthwise3x3 => "depthwise3x3",
        OpKind::Pointwise => "pointwise",
        OpKind::Add => "add",
        OpKind::Concat => "concat",
        OpKind::AvgPool => "avgpool",
        OpKind::Resize => "resize",
        OpKind::Relu => "relu",
    }
}

/// Reads an ONNX file and its `quant.json` and converts them.
pub fn convert_files(onnx: &Path, quant: &Path) -> Result<Converted, NnFileError> {
    let g = OnnxGraph::load(onnx)?;
    let q = QuantParams::load(quant)?;
    convert(&g, &q, quant)
}

/// Converts a graph with its quantisation (`quant_path` is named in errors about the JSON).
pub fn convert(
    g: &OnnxGraph,
    q: &QuantParams,
    quant_path: &Path,
) -> Result<Converted, NnFileError> {
    Converter::new(g, q, quant_path).run()
}

struct Converter<'a> {
    g: &'a OnnxGraph,
    q: &'a QuantParams,
    qpath: &'a Path,
    fused: BTreeSet<&'a str>,
    /// Nodes reading each tensor.
    consumers: BTreeMap<&'a str, Vec<usize>>,
    index: BTreeMap<String, u32>,
    out: Converted,
}

impl<'a> Converter<'a> {
    fn new(g: &'a OnnxGraph, q: &'a QuantParams, qpath: &'a Path) -> Self {
        let mut consumers: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
        for (k, n) in g.nodes.iter().enumerate() {
            for i in n.inputs.iter().filter(|i| !i.is_empty()) {
                consumers.entry(i.as_str()).or_default().push(k);
            }
        }
        Converter {
            g,
            q,
            qpath,
            fused: q.fused.iter().map(String::as_str).collect(),
            consumers,
            index: BTreeMap::new(),
            out: Converted {
                onnx: g.path.clone(),
                tensors: Vec::new(),
                tensor_names: Vec::new(),
                ops: Vec::new(),
                input: 0,
                output: 0,
            },
        }
    }

    fn json_error(&self, tensor: &str, msg: impl Into<String>) -> NnFileError {
        NnFileError::Tensor {
            path: self.qpath.to_path_buf(),
            tensor: tensor.into(),
            msg: msg.into(),
        }
    }

    fn run(mut self) -> Result<Converted, NnFileError> {
        let (g, q) = (self.g, self.q);
        let qi = &q.input;
        if qi.name != g.input {
            return Err(self.json_error(&qi.name, format!("input is `{}` in the ONNX", g.input)));
        }
        if (qi.scale - INPUT_SCALE).abs() > 1e-12 || qi.zero_point != i64::from(INPUT_ZERO_POINT) {
            return Err(self.json_error(&qi.name, "input must be scale 1/255, zero point -128"));
        }
        let s = g.shapes[&g.input];
        if s[0] != 1 || s[1] != 1 {
            return Err(NnFileError::Tensor {
                path: g.path.clone(),
                tensor: g.input.clone(),
                msg: format!("input shape {s:?}: expected 1 x 1 x H x W (luma)"),
            });
        }
        let spec = TensorSpec {
            shape: Shape::new(1, s[2], s[3]),
            zero_point: INPUT_ZERO_POINT,
            scale: INPUT_SCALE,
        };
        self.out.input = self.add_tensor(&g.input, spec);
        let mut skip = BTreeSet::new();
        for (k, node) in g.nodes.iter().enumerate() {
            if skip.contains(&k) {
                continue;
            }
            // the tensor this op writes: its own output, or that of the ReLU it absorbs
            let own = &node.outputs[0];
            let relu = match node.op.as_str() {
                "Conv" | "Add" if self.fused.contains(own.as_str()) => {
                    let r = self.fusable_relu(node)?;
                    skip.insert(r);
                    Some(r)
                }
                _ => None,
            };
            let out_name = relu.map_or(own, |r| &g.nodes[r].outputs[0]);
            let out_shape = g.shapes[own];
            let qa = self.q.activations.get(out_name).ok_or_else(|| {
                self.json_error(out_name, "no activation scale/zero point in `activations`")
            })?;
            let in_range =
                qa.scale.is_finite() && qa.scale > 0.0 && (-128..=127).contains(&qa.zero_point);
            if !in_range {
                return Err(self.json_error(out_name, "scale or zero point out of range"));
            }
            if out_shape[0] != 1 {
                return Err(g.node_error(node, "batch must be 1"));
            }
            let spec = TensorSpec {
                shape: Shape::new(out_shape[1], out_shape[2], out_shape[3]),
                zero_point: qa.zero_point as i32,
                scale: qa.scale,
            };
            let input = |i: usize| -> Result<u32, NnFileError> {
                let name = node.input(i).unwrap_or_default();
                self.index.get(name).copied().ok_or_else(|| {
                    g.node_error(node, format!("input `{name}` is not an activation"))
                })
            };
            let op = match node.op.as_str() {
                "Conv" => None,
                "Add" => Some(OpSpec::Add {
                    a: input(0)?,
                    b: input(1)?,
                    output: 0,
                    relu: relu.is_some(),
                }),
                "Relu" => Some(OpSpec::Relu { input: input(0)?, output: 0 }),
                "Concat" => {
                    if node.int("axis", 0).is_none_or(|a| a != 1 && a != -3) {
                        return Err(g.node_error(node, "only channel (axis 1) concat is supported"));
                    }
                    let n = node.inputs.len();
                    if n == 0 || n > MAX_INPUTS {
                        return Err(g.node_error(node, format!("{n} inputs, at most {MAX_INPUTS}")));
                    }
                    let mut inputs = [0u32; MAX_INPUTS];
                    for (j, v) in inputs.iter_mut().enumerate().take(n) {
                        *v = input(j)?;
                    }
                    Some(OpSpec::Concat { inputs, n, output: 0 })
                }
                "AveragePool" => Some(self.avgpool(node, input(0)?)?),
                "Resize" => Some(self.resize(node, input(0)?)?),
                other => {
                    return Err(g.node_error(node, format!("op `{other}` is not supported")));
                }
            };
            let first = input(0)?;
            let output = self.add_tensor(out_name, spec);
            let converted = match op {
                Some(mut op) => {
                    set_output(&mut op, output);
                    ConvertedOp::Plain { node: node.name.clone(), op }
                }
                None => self.conv(node, first, output, relu.is_some())?,
            };
            self.out.ops.push(converted);
        }
        self.out.output = *self.index.get(&g.output).ok_or_else(|| NnFileError::Tensor {
            path: g.path.clone(),
            tensor: g.output.clone(),
            msg: "graph output is not computed".into(),
        })?;
        Ok(self.out)
    }

    fn add_tensor(&mut self, name: &str, spec: TensorSpec) -> u32 {
        let i = self.out.tensors.len() as u32;
        self.out.tensors.push(spec);
        self.out.tensor_names.push(name.to_owned());
        self.index.insert(name.to_owned(), i);
        i
    }

    /// The index of the ReLU node that is the only consumer of `node`'s output.
    fn fusable_relu(&self, node: &Node) -> Result<usize, NnFileError> {
        let own = node.outputs[0].as_str();
        match self.consumers.get(own).map(Vec::as_slice) {
            Some(&[r]) if self.g.nodes[r].op == "Relu" && own != self.g.output => Ok(r),
            _ => Err(self.g.node_error(
                node,
                format!(
                    "{}: `{own}` is listed as fused but its only consumer is not a Relu",
                    self.qpath.display()
                ),
            )),
        }
    }

    fn avgpool(&self, node: &Node, input: u32) -> Result<OpSpec<'static>, NnFileError> {
        let g = self.g;
        let bad = |m: &str| g.node_error(node, m);
        let k = node.ints("kernel_shape", &[]).ok_or_else(|| bad("bad kernel_shape"))?;
        let s = node.ints("strides", &[1, 1]).ok_or_else(|| bad("bad strides"))?;
        let p = node.ints("pads", &[0; 4]).ok_or_else(|| bad("bad pads"))?;
        let cip = node.int("count_include_pad", 0).ok_or_else(|| bad("bad count_include_pad"))?;
        let ceil = node.int("ceil_mode", 0).ok_or_else(|| bad("bad ceil_mode"))?;
        if k != s || p[0] != 0 || p[1] != 0 || cip != 0 || ceil != 0 {
            return Err(bad(
                "only window = stride, bottom/right pads, count_include_pad = 0, ceil_mode = 0",
            ));
        }
        Ok(OpSpec::AvgPool {
            input,
            output: 0,
            kernel: (k[0] as usize, k[1] as usize),
            pad_bottom_right: (p[2] as usize, p[3] as usize),
        })
    }

    fn resize(&self, node: &Node, input: u32) -> Result<OpSpec<'static>, NnFileError> {
        let g = self.g;
        let bad = |m: String| g.node_error(node, m);
        let mode = node.string("mode", "nearest").unwrap_or_default();
        let ctm = node.string("coordinate_transformation_mode", "half_pixel").unwrap_or_default();
        let out = g.shapes[&node.outputs[0]];
        // pytorch_half_pixel differs from half_pixel only for an output of size 1
        let half = ctm == "half_pixel" || (ctm == "pytorch_half_pixel" && out[2] > 1 && out[3] > 1);
        if mode != "linear" || !half {
            return Err(bad(format!(
                "only linear half_pixel resize is supported (got {mode}, {ctm})"
            )));
        }
        if node.int("antialias", 0) != Some(0) || node.attrs.contains_key("axes") {
            return Err(bad("antialias and axes are not supported".into()));
        }
        Ok(OpSpec::Resize { input, output: 0 })
    }

    fn conv(
        &self,
        node: &Node,
        input: u32,
        output: u32,
        relu: bool,
    ) -> Result<ConvertedOp, NnFileError> {
        let g = self.g;
        let bad = |m: String| g.node_error(node, m);
        let qc = self
            .q
            .convs
            .get(&node.name)
            .ok_or_else(|| self.json_error(&node.name, "conv node has no entry in `convs`"))?;
        let x = g.activation(node, 0)?;
        let w = g.constant(node, 1)?;
        let wname = node.input(1).unwrap_or_default();
        if qc.input != node.inputs[0] || qc.weight != wname || qc.output != node.outputs[0] {
            return Err(self.json_error(
                &node.name,
                "`convs` entry names other input/weight/output tensors than the ONNX node",
            ));
        }
        let wf = w.f32s().ok_or_else(|| bad(format!("weight `{wname}` is not float")))?;
        let [co, cig, kh, kw] = w.dims[..] else {
            return Err(bad(format!("weight dims {:?}", w.dims)));
        };
        let ci = x[1];
        let bias: Vec<f32> = match node.input(2) {
            Some(_) => {
                let b = g.constant(node, 2)?;
                let v = b.f32s().ok_or_else(|| bad("bias is not float".into()))?;
                if v.len() != co {
                    return Err(bad(format!("bias has {} values for {co} channels", v.len())));
                }
                v.to_vec()
            }
            None => vec![0.0; co],
        };
        if qc.weight_scales.len() != co || qc.bias_scales.len() != co {
            return Err(self.json_error(
                &node.name,
                format!(
                    "{} weight scales and {} bias scales for {co} output channels",
                    qc.weight_scales.len(),
                    qc.bias_scales.len()
                ),
            ));
        }
        let group = node.int("group", 1).unwrap_or(1) as usize;
        let s = node.ints("strides", &[1, 1]).unwrap_or_default();
        let p = node.ints("pads", &[0; 4]).unwrap_or_default();
        let d = node.ints("dilations", &[1, 1]).unwrap_or_default();
        if d != [1, 1] {
            return Err(bad(format!("dilations {d:?}: only 1 is supported")));
        }
        let geometry = ConvGeometry {
            kernel: (kh, kw),
            stride: (s[0] as usize, s[1] as usize),
            pads: [p[0] as usize, p[1] as usize, p[2] as usize, p[3] as usize],
        };
        let kind = if group == 1 {
            if (kh, kw) == (1, 1) && geometry.stride == (1, 1) && geometry.pads == [0; 4] {
                OpKind::Pointwise
            } else {
                OpKind::Conv
            }
        } else if group == ci && co == ci && cig == 1 {
            let ok = (kh, kw) == (3, 3)
                && geometry.pads == [1; 4]
                && geometry.stride.0 == geometry.stride.1
                && (1..=2).contains(&geometry.stride.0);
            if !ok {
                return Err(bad(format!(
                    "depthwise conv must be 3x3, pad 1, stride 1 or 2 (got {geometry:?})"
                )));
            }
            OpKind::Depthwise3x3
        } else {
            return Err(bad(format!(
                "grouped conv (group {group}, {ci} -> {co} channels) is neither general nor depthwise"
            )));
        };
        // quantise in f32, as torch does (round half to even)
        let taps = cig * kh * kw;
        let mut q = vec![0i8; wf.len()];
        for o in 0..co {
            let sw = qc.weight_scales[o] as f32;
            for (dst, &v) in q[o * taps..(o + 1) * taps].iter_mut().zip(&wf[o * taps..]) {
                *dst = (v / sw).round_ties_even().clamp(-127.0, 127.0) as i8;
            }
        }
        // OIHW → the kernel's layout
        let weights: Vec<i8> = match kind {
            OpKind::Pointwise => q,
            OpKind::Depthwise3x3 => {
                let mut v = vec![0i8; 9 * co];
                for c in 0..co {
                    for t in 0..9 {
                        v[t * co + c] = q[c * 9 + t];
                    }
                }
                v
            }
            _ => {
                let mut v = vec![0i8; q.len()];
                for o in 0..co {
                    for i in 0..cig {
                        for ky in 0..kh {
                            for kx in 0..kw {
                                v[((o * kh + ky) * kw + kx) * cig + i] =
                                    q[((o * cig + i) * kh + ky) * kw + kx];
                            }
                        }
                    }
                }
                v
            }
        };
        let s_in = self.out.tensors[input as usize].scale;
        let s_out = self.out.tensors[output as usize].scale;
        let bias = bias
            .iter()
            .zip(&qc.bias_scales)
            .map(|(&b, &sb)| (b / sb as f32).round_ties_even() as i32)
            .collect();
        let requant =
            qc.weight_scales.iter().map(|&sw| Requant::from_scale(s_in * sw / s_out)).collect();
        Ok(ConvertedOp::Conv {
            node: node.name.clone(),
            kind,
            input,
            output,
            geometry,
            weights,
            bias,
            requant,
            relu,
        })
    }
}

fn set_output(op: &mut OpSpec<'static>, o: u32) {
    match op {
        OpSpec::Conv { output, .. }
        | OpSpec::Add { output, .. }
        | OpSpec::Concat { output, .. }
        | OpSpec::AvgPool { output, .. }
        | OpSpec::Resize { output, .. }
        | OpSpec::Relu { output, .. } => *output = o,
    }
}

impl Converted {
    /// The core ops, borrowing the constant data.
    pub fn specs(&self) -> Vec<OpSpec<'_>> {
        self.ops.iter().map(ConvertedOp::spec).collect()
    }

    /// Plans the arena, encodes the blob and parses it back. Errors name the ONNX file and, where
    /// the core names an op or tensor, its ONNX node or tensor name.
    pub fn encode(&self) -> Result<SlmBlob, NnFileError> {
        let specs = self.specs();
        let mut offsets = vec![0u32; self.tensors.len()];
        let explain = |e: ModelError| -> NnFileError {
            let (what, name) = match e {
                ModelError::BadOp { op } | ModelError::ArenaOverlap { op } => {
                    ("node", self.ops.get(op).map(ConvertedOp::node))
                }
                ModelError::BadTensor { tensor } => {
                    ("tensor", self.tensor_names.get(tensor).map(String::as_str))
                }
                _ => ("", None),
            };
            match name {
                Some(n) => NnFileError::Tensor {
                    path: self.onnx.clone(),
                    tensor: n.to_owned(),
                    msg: format!("{e} ({what} the int8 engine rejects)"),
                },
                None => NnFileError::model(&self.onnx, e),
            }
        };
        let arena = plan_arena(&self.tensors, &specs, self.input, self.output, &mut offsets)
            .map_err(explain)?;
        let mut bytes = vec![0u8; encoded_len(&self.tensors, &specs)];
        let n = write(&self.tensors, &specs, self.input, self.output, &offsets, arena, &mut bytes)
            .map_err(explain)?;
        bytes.truncate(n);
        SlmBlob::from_bytes(&bytes, &self.onnx).map_err(|e| match e {
            NnFileError::Model { source, .. } => explain(source),
            other => other,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{tiny_onnx, tiny_quant};
    use super::*;
    use prost::Message;

    fn tiny() -> (OnnxGraph, QuantParams) {
        let bytes = tiny_onnx(13, 18).encode_to_vec();
        let g = OnnxGraph::from_bytes(&bytes, Path::new("tiny.onnx")).unwrap();
        (g, tiny_quant(&bytes).unwrap())
    }

    #[test]
    fn converts_the_tiny_net_and_parses_back() {
        let (g, q) = tiny();
        let c = convert(&g, &q, Path::new("tiny.quant.json")).unwrap();
        let kinds: Vec<OpKind> = c.specs().iter().map(OpSpec::kind).collect();
        use OpKind::*;
        let want =
            [Conv, Depthwise3x3, Pointwise, Pointwise, Concat, Pointwise, Add, AvgPool, Resize];
        assert_eq!(kinds, want);
        // the fused ReLU outputs are the conv outputs
        assert_eq!(c.tensor_names[1], "r0_out");
        assert!(matches!(c.ops[0].spec(), OpSpec::Conv { relu: true, .. }));
        assert!(matches!(c.ops[2].spec(), OpSpec::Conv { relu: false, .. }));
        let blob = c.encode().unwrap();
        let m = blob.model().unwrap();
        let s = ModelSummary::of(&m);
        assert_eq!((s.tensors, s.ops), (10, 9));
        assert_eq!(s.input_hw, (13, 18));
        assert_eq!(s.output_chw, (3, 13, 18));
        // conv and dw 7x9 x 4 x 9, pointwise 7x9 x (2 + 1 + 3) x 4
        assert_eq!(s.macs, 63 * 4 * 9 * 2 + 63 * 6 * 4);
        let packed = |o, i| semloc_core::nn::conv::pointwise_packed_len(o, i);
        assert_eq!(s.weight_bytes, 36 + 36 + packed(2, 4) + packed(1, 4) + packed(3, 4));
    }

    #[test]
    fn weights_and_biases_are_quantised_like_torch() {
        let (g, q) = tiny();
        let c = convert(&g, &q, Path::new("q.json")).unwrap();
        let ConvertedOp::Conv { weights, bias, requant, .. } = &c.ops[0] else { panic!() };
        let w = g.initializers["w0"].f32s().unwrap();
        let qc = &q.convs["c0"];
        // OHWI with I = 1 is OIHW: element-wise check of round-half-even in f32
        for (k, (&qw, &wf)) in weights.iter().zip(w).enumerate() {
            let s = qc.weight_scales[k / 9] as f32;
            assert_eq!(qw as f32, (wf / s).round_ties_even().clamp(-127.0, 127.0));
        }
        // the channel maximum maps to ±127
        assert!(weights[..9].iter().any(|&v| v.abs() == 127));
        assert_eq!(bias[1], (-0.1f32 / qc.bias_scales[1] as f32).round_ties_even() as i32);
        let want = Requant::from_scale(INPUT_SCALE * qc.weight_scales[2] / c.tensors[1].scale);
        assert_eq!(requant[2], want);
        // depthwise layout: 3·3·C (tap-major)
        let ConvertedOp::Conv { weights, .. } = &c.ops[1] else { panic!() };
        let w1 = g.initializers["w1"].f32s().unwrap();
        let s = q.convs["dw"].weight_scales[2] as f32;
        assert_eq!(weights[5 * 4 + 2] as f32, (w1[2 * 9 + 5] / s).round_ties_even());
    }

    #[test]
    fn unsupported_graphs_are_errors_naming_the_node() {
        let (g, q) = tiny();
        let mut q2 = q.clone();
        q2.activations.remove("pool_out");
        let e = convert(&g, &q2, Path::new("q.json")).unwrap_err();
        assert_eq!(
            e.to_string(),
            "q.json: tensor `pool_out`: no activation scale/zero point in `activations`"
        );

        let mut g2 = g.clone();
        g2.nodes[2].attrs.insert("pads".into(), super::super::onnx::Attr::Ints(vec![0; 4]));
        let e = convert(&g2, &q, Path::new("q.json")).unwrap_err();
        assert!(e.to_string().starts_with("tiny.onnx: node `dw` (Conv): depthwise"), "{e}");

        let mut q3 = q.clone();
        q3.fused.push("pw_out".into()); // consumer is Add, not Relu
        let e = convert(&g, &q3, Path::new("q.json")).unwrap_err();
        assert!(e.to_string().contains("node `pw` (Conv)"), "{e}");

        let mut q4 = q;
        q4.convs.get_mut("pw").unwrap().weight_scales.pop();
        let e = convert(&g, &q4, Path::new("q.json")).unwrap_err();
        assert!(e.to_string().starts_with("q.json: tensor `pw`: 1 weight scales"), "{e}");
    }
}
