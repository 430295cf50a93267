//! ONNX reader: a float ONNX file → a small graph IR with static shapes.
//!
//! Decodes the protobuf with tract-onnx's generated types (`tract_onnx::pb`, prost) and keeps
//! only what the int8 converter needs: nodes in file order (ONNX requires topological order,
//! checked here) with their attributes, initializers as `f32`/`i64` arrays with dims (inline
//! `float_data`/`int64_data` or little-endian `raw_data`; external data is refused), and the
//! static NCHW shape of every activation tensor, computed from the op semantics of the six ops
//! the network uses (`Conv`, `Relu`, `Add`, `Concat`, `AveragePool`, `Resize` — ONNX opset 17
//! definitions). Any other op is a [`NnFileError::Node`] naming it.
//!
//! Memory: the initializers as `f32` (≈ 5 MB for the Res2Net net) plus the names.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use prost::Message;
use tract_onnx::pb;

use super::NnFileError;

/// An attribute value (the kinds the network's ops use; others are kept as `Other`).
#[derive(Clone, Debug, PartialEq)]
pub enum Attr {
    /// `INT`.
    Int(i64),
    /// `INTS`.
    Ints(Vec<i64>),
    /// `FLOAT`.
    Float(f32),
    /// `FLOATS`.
    Floats(Vec<f32>),
    /// `STRING` (UTF-8, lossy).
    Str(String),
    /// Any other kind (tensor, graph, ...), unused by the converter.
    Other,
}

/// One graph node.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// Node name (its first output's name when the file leaves it empty).
    pub name: String,
    /// ONNX op type (`Conv`, ...).
    pub op: String,
    /// Input tensor names (`""` for an omitted optional input).
    pub inputs: Vec<String>,
    /// Output tensor names.
    pub outputs: Vec<String>,
    /// Attributes by name.
    pub attrs: BTreeMap<String, Attr>,
}

impl Node {
    /// An `INT` attribute, or `default` when absent.
    pub fn int(&self, name: &str, default: i64) -> Option<i64> {
        match self.attrs.get(name) {
            None => Some(default),
            Some(Attr::Int(v)) => Some(*v),
            Some(_) => None,
        }
    }

    /// An `INTS` attribute, or `default` when absent.
    pub fn ints(&self, name: &str, default: &[i64]) -> Option<Vec<i64>> {
        match self.attrs.get(name) {
            None => Some(default.to_vec()),
            Some(Attr::Ints(v)) => Some(v.clone()),
            Some(_) => None,
        }
    }

    /// A `STRING` attribute, or `default` when absent.
    pub fn string(&self, name: &str, default: &str) -> Option<String> {
        match self.attrs.get(name) {
            None => Some(default.to_owned()),
            Some(Attr::Str(v)) => Some(v.clone()),
            Some(_) => None,
        }
    }

    /// The `i`-th input name, `None` when absent or empty.
    pub fn input(&self, i: usize) -> Option<&str> {
        self.inputs.get(i).map(String::as_str).filter(|s| !s.is_empty())
    }
}

/// Initializer values.
#[derive(Clone, Debug, PartialEq)]
pub enum InitData {
    /// `FLOAT` tensors.
    F32(Vec<f32>),
    /// `INT64` tensors (e.g. `Resize` sizes).
    I64(Vec<i64>),
}

/// A constant tensor of the graph.
#[derive(Clone, Debug, PartialEq)]
pub struct Initializer {
    /// Dimensions (row-major).
    pub dims: Vec<usize>,
    /// Values, `dims.iter().product()` of them.
    pub data: InitData,
}

impl Initializer {
    /// The values as `f32`, if it is a float tensor.
    pub fn f32s(&self) -> Option<&[f32]> {
        match &self.data {
            InitData::F32(v) => Some(v),
            InitData::I64(_) => None,
        }
    }

    /// The values as `i64`, if it is an int64 tensor.
    pub fn i64s(&self) -> Option<&[i64]> {
        match &self.data {
            InitData::I64(v) => Some(v),
            InitData::F32(_) => None,
        }
    }
}

/// A static NCHW shape.
pub type Nchw = [usize; 4];

/// The graph IR: one input, one output, nodes in execution order, static shapes.
#[derive(Clone, Debug)]
pub struct OnnxGraph {
    /// The file it came from (named in errors).
    pub path: PathBuf,
    /// Graph input name (the one that is not an initializer).
    pub input: String,
    /// Graph output name.
    pub output: String,
    /// Nodes in file (= execution) order.
    pub nodes: Vec<Node>,
    /// Constant tensors by name.
    pub initializers: BTreeMap<String, Initializer>,
    /// Static NCHW shape of the input and of every node output.
    pub shapes: BTreeMap<String, Nchw>,
}

impl OnnxGraph {
    /// Reads and decodes an ONNX file and infers its shapes.
    pub fn load(path: &Path) -> Result<Self, NnFileError> {
        let bytes = std::fs::read(path).map_err(|e| NnFileError::io(path, &e))?;
        Self::from_bytes(&bytes, path)
    }

    /// Decodes ONNX protobuf bytes (`path` is only named in errors).
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, NnFileError> {
        let proto = pb::ModelProto::decode(bytes)
            .map_err(|e| NnFileError::Decode { path: path.to_path_buf(), msg: e.to_string() })?;
        Self::from_proto(&proto, path)
    }

    /// Builds the IR from a decoded model.
    pub fn from_proto(proto: &pb::ModelProto, path: &Path) -> Result<Self, NnFileError> {
        let decode = |msg: &str| NnFileError::Decode { path: path.to_path_buf(), msg: msg.into() };
        let g = proto.graph.as_ref().ok_or_else(|| decode("no graph"))?;
        let mut initializers = BTreeMap::new();
        for t in &g.initializer {
            initializers.insert(t.name.clone(), read_initializer(t, path)?);
        }
        let inputs: Vec<&pb::ValueInfoProto> =
            g.input.iter().filter(|v| !initializers.contains_key(&v.name)).collect();
        let [input] = inputs.as_slice() else {
            return Err(decode(&format!("{} graph inputs, expected one", inputs.len())));
        };
        let [output] = g.output.as_slice() else {
            return Err(decode(&format!("{} graph outputs, expected one", g.output.len())));
        };
        let input_shape = value_shape(input).ok_or_else(|| NnFileError::Tensor {
            path: path.to_path_buf(),
            tensor: input.name.clone(),
            msg: "graph input needs a static 4-D shape (N x C x H x W)".into(),
        })?;
        let nodes = g.node.iter().map(read_node).collect();
        let mut graph = OnnxGraph {
            path: path.to_path_buf(),
            input: input.name.clone(),
            output: output.name.clone(),
            nodes,
            initializers,
            shapes: BTreeMap::new(),
        };
        graph.shapes.insert(graph.input.clone(), input_shape);
        graph.infer_shapes()?;
        if !graph.shapes.contains_key(&graph.output) {
            return Err(NnFileError::Tensor {
                path: path.to_path_buf(),
                tensor: graph.output.clone(),
                msg: "graph output is produced by no node".into(),
            });
        }
        Ok(graph)
    }

    /// The input's `(h, w)`.
    pub fn input_hw(&self) -> (usize, usize) {
        let s = self.shapes[&self.input];
        (s[2], s[3])
    }

    /// A [`NnFileError::Node`] about `node`.
    pub fn node_error(&self, node: &Node, msg: impl Into<String>) -> NnFileError {
        NnFileError::Node {
            path: self.path.clone(),
            node: node.name.clone(),
            op: node.op.clone(),
            msg: msg.into(),
        }
    }

    /// The shape of activation `name` as input `i` of `node` (error naming the node if it is not
    /// computed before the node: a graph out of topological order or a dangling input).
    pub fn activation(&self, node: &Node, i: usize) -> Result<Nchw, NnFileError> {
        let name =
            node.input(i).ok_or_else(|| self.node_error(node, format!("input {i} missing")))?;
        self.shapes.get(name).copied().ok_or_else(|| {
            self.node_error(node, format!("input `{name}` is not computed before this node"))
        })
    }

    /// The initializer that is input `i` of `node`.
    pub fn constant(&self, node: &Node, i: usize) -> Result<&Initializer, NnFileError> {
        let name =
            node.input(i).ok_or_else(|| self.node_error(node, format!("input {i} missing")))?;
        self.initializers
            .get(name)
            .ok_or_else(|| self.node_error(node, format!("input `{name}` is not a constant")))
    }

    fn infer_shapes(&mut self) -> Result<(), NnFileError> {
        for k in 0..self.nodes.len() {
            let node = &self.nodes[k];
            let out = self.output_shape(node)?;
            let [o] = node.outputs.as_slice() else {
                return Err(self.node_error(node, "expected exactly one output"));
            };
            if self.shapes.contains_key(o) || self.initializers.contains_key(o) {
                return Err(self.node_error(node, format!("output `{o}` is defined twice")));
            }
            if out.contains(&0) {
                return Err(self.node_error(node, format!("empty output shape {out:?}")));
            }
            self.shapes.insert(o.clone(), out);
        }
        Ok(())
    }

    /// The output shape of one node (ONNX opset-17 semantics of the supported ops).
    fn output_shape(&self, node: &Node) -> Result<Nchw, NnFileError> {
        let bad = |msg: String| self.node_error(node, msg);
        let attr = |name: &str| bad(format!("attribute `{name}` has the wrong type"));
        match node.op.as_str() {
            "Relu" => self.activation(node, 0),
            "Add" => {
                let (a, b) = (self.activation(node, 0)?, self.activation(node, 1)?);
                if a != b {
                    return Err(bad(format!("broadcasting {a:?} + {b:?} is not supported")));
                }
                Ok(a)
            }
            "Concat" => {
                let axis = node.int("axis", i64::MIN).ok_or_else(|| attr("axis"))?;
                if axis == i64::MIN {
                    return Err(bad("attribute `axis` missing".into()));
                }
                let axis = if axis < 0 { axis + 4 } else { axis };
                if !(0..4).contains(&axis) {
                    return Err(bad(format!("axis {axis} outside a 4-D tensor")));
                }
                let axis = axis as usize;
                let mut out = self.activation(node, 0)?;
                for i in 1..node.inputs.len() {
                    let s = self.activation(node, i)?;
                    for d in (0..4).filter(|&d| d != axis) {
                        if s[d] != out[d] {
                            return Err(bad(format!("input {i} shape {s:?} does not fit {out:?}")));
                        }
                    }
                    out[axis] += s[axis];
                }
                Ok(out)
            }
            "Conv" => {
                let x = self.activation(node, 0)?;
                let w = self.constant(node, 1)?;
                let [o, ci, kh, kw] = w.dims[..] else {
                    return Err(bad(format!("weight dims {:?}, expected 4", w.dims)));
                };
                let group = node.int("group", 1).ok_or_else(|| attr("group"))?;
                if group < 1 || ci * group as usize != x[1] || o % group as usize != 0 {
                    return Err(bad(format!(
                        "group {group} with {} input channels and weights {:?}",
                        x[1], w.dims
                    )));
                }
                let g = self.window(node, x, (kh, kw), false)?;
                Ok([x[0], o, g.0, g.1])
            }
            "AveragePool" => {
                let x = self.activation(node, 0)?;
                let k = node.ints("kernel_shape", &[]).ok_or_else(|| attr("kernel_shape"))?;
                let [kh, kw] = k[..] else {
                    return Err(bad(format!("kernel_shape {k:?}, expected 2 values")));
                };
                let kernel = (to_usize(kh), to_usize(kw));
                let ceil = node.int("ceil_mode", 0).ok_or_else(|| attr("ceil_mode"))? != 0;
                let g = self.window(node, x, kernel, ceil)?;
                Ok([x[0], x[1], g.0, g.1])
            }
            "Resize" => {
                let x = self.activation(node, 0)?;
                if let Some(name) = node.input(3) {
                    let s = self.initializers.get(name).and_then(Initializer::i64s);
                    let Some(&[n, c, h, w]) = s else {
                        return Err(bad(format!("sizes `{name}` is not a constant 4-vector")));
                    };
                    let out = [n, c, h, w].map(to_usize);
                    if out[0] != x[0] || out[1] != x[1] {
                        return Err(bad(format!("resizes batch or channels: {x:?} -> {out:?}")));
                    }
                    return Ok(out);
                }
                let Some(name) = node.input(2) else {
                    return Err(bad("neither `scales` nor `sizes` given".into()));
                };
                let s = self.initializers.get(name).and_then(Initializer::f32s);
                let Some(&[sn, sc, sh, sw]) = s else {
                    return Err(bad(format!("scales `{name}` is not a constant 4-vector")));
                };
                if sn != 1.0 || sc != 1.0 || !(sh > 0.0 && sw > 0.0) {
                    return Err(bad(format!("scales {:?} not supported", [sn, sc, sh, sw])));
                }
                // ONNX: output = floor(input · scale)
                let d = |v: usize, s: f32| (v as f64 * f64::from(s)).floor() as usize;
                Ok([x[0], x[1], d(x[2], sh), d(x[3], sw)])
            }
            other => Err(bad(format!("op `{other}` is not supported by the int8 engine"))),
        }
    }

    /// Output `(h, w)` of a sliding window (Conv / AveragePool): `strides` (default 1), `pads`
    /// (`[top, left, bottom, right]`), `dilations`; `auto_pad` must be `NOTSET`.
    fn window(
        &self,
        node: &Node,
        x: Nchw,
        kernel: (usize, usize),
        ceil: bool,
    ) -> Result<(usize, usize), NnFileError> {
        let bad = |msg: String| self.node_error(node, msg);
        let auto = node.string("auto_pad", "NOTSET").ok_or_else(|| bad("bad auto_pad".into()))?;
        if auto != "NOTSET" {
            return Err(bad(format!("auto_pad {auto} not supported (export with explicit pads)")));
        }
        let s = node.ints("strides", &[1, 1]).ok_or_else(|| bad("bad strides".into()))?;
        let p = node.ints("pads", &[0; 4]).ok_or_else(|| bad("bad pads".into()))?;
        let d = node.ints("dilations", &[1, 1]).ok_or_else(|| bad("bad dilations".into()))?;
        if let Some(k) = node.ints("kernel_shape", &[kernel.0 as i64, kernel.1 as i64]) {
            if k != [kernel.0 as i64, kernel.1 as i64] {
                return Err(bad(format!("kernel_shape {k:?} does not match {kernel:?}")));
            }
        }
        let ok = s.len() == 2 && p.len() == 4 && d.len() == 2;
        if !ok || s.iter().any(|&v| v < 1) || p.iter().any(|&v| v < 0) || d.iter().any(|&v| v < 1) {
            return Err(bad(format!("strides {s:?}, pads {p:?}, dilations {d:?} invalid")));
        }
        let dim = |n: usize, k: usize, s: i64, d: i64, p0: i64, p1: i64| -> Option<usize> {
            let span = (d as usize).checked_mul(k.checked_sub(1)?)?.checked_add(1)?;
            let padded = n + p0 as usize + p1 as usize;
            let room = padded.checked_sub(span)?;
            let s = s as usize;
            Some(if ceil { room.div_ceil(s) + 1 } else { room / s + 1 })
        };
        let h = dim(x[2], kernel.0, s[0], d[0], p[0], p[2]);
        let w = dim(x[3], kernel.1, s[1], d[1], p[1], p[3]);
        match (h, w) {
            (Some(h), Some(w)) => Ok((h, w)),
            _ => Err(bad(format!("kernel {kernel:?} larger than the padded input {x:?}"))),
        }
    }
}

fn to_usize(v: i64) -> usize {
    usize::try_from(v).unwrap_or(0)
}

fn value_shape(v: &pb::ValueInfoProto) -> Option<Nchw> {
    let Some(pb::type_proto::Value::TensorType(t)) = v.r#type.as_ref()?.value.as_ref() else {
        return None;
    };
    let dims = &t.shape.as_ref()?.dim;
    let mut out = [0usize; 4];
    if dims.len() != 4 {
        return None;
    }
    for (o, d) in out.iter_mut().zip(dims) {
        match d.value {
            Some(pb::tensor_shape_proto::dimension::Value::DimValue(v)) if v > 0 => *o = v as usize,
            _ => return None,
        }
    }
    Some(out)
}

fn read_node(n: &pb::NodeProto) -> Node {
    use pb::attribute_proto::AttributeType as T;
    let attrs = n
        .attribute
        .iter()
        .map(|a| {
            let v = match T::try_from(a.r#type) {
                Ok(T::Int) => Attr::Int(a.i),
                Ok(T::Ints) => Attr::Ints(a.ints.clone()),
                Ok(T::Float) => Attr::Float(a.f),
                Ok(T::Floats) => Attr::Floats(a.floats.clone()),
                Ok(T::String) => Attr::Str(String::from_utf8_lossy(&a.s).into_owned()),
                _ => Attr::Other,
            };
            (a.name.clone(), v)
        })
        .collect();
    let name = if n.name.is_empty() {
        n.output.first().cloned().unwrap_or_default()
    } else {
        n.name.clone()
    };
    Node { name, op: n.op_type.clone(), inputs: n.input.clone(), outputs: n.output.clone(), attrs }
}

fn read_initializer(t: &pb::TensorProto, path: &Path) -> Result<Initializer, NnFileError> {
    use pb::tensor_proto::DataType;
    let bad =
        |msg: String| NnFileError::Tensor { path: path.to_path_buf(), tensor: t.name.clone(), msg };
    if !t.external_data.is_empty() || t.data_location == Some(1) {
        return Err(bad("external data is not supported (save the model in one file)".into()));
    }
    let dims: Vec<usize> = t
        .dims
        .iter()
        .map(|&d| usize::try_from(d).map_err(|_| bad(format!("negative dimension {d}"))))
        .collect::<Result<_, _>>()?;
    let n: usize = dims.iter().product();
    let data = match DataType::try_from(t.data_type) {
        Ok(DataType::Float) => InitData::F32(if t.raw_data.is_empty() {
            t.float_data.clone()
        } else {
            t.raw_data
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect()
        }),
        Ok(DataType::Int64) => InitData::I64(if t.raw_data.is_empty() {
            t.int64_data.clone()
        } else {
            t.raw_data
                .chunks_exact(8)
                .map(|c| {
                    let mut b = [0u8; 8];
                    b.copy_from_slice(c);
                    i64::from_le_bytes(b)
                })
                .collect()
        }),
        _ => return Err(bad(format!("data type {} is not FLOAT or INT64", t.data_type))),
    };
    let got = match &data {
        InitData::F32(v) => v.len(),
        InitData::I64(v) => v.len(),
    };
    if got != n {
        return Err(bad(format!("{got} values for dims {dims:?}")));
    }
    Ok(Initializer { dims, data })
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::*;
    use super::*;
    use prost::Message;

    fn conv_pool_resize() -> pb::ModelProto {
        let w: Vec<f32> = (0..4 * 9).map(|i| (i as f32 * 0.37).sin()).collect();
        model(
            vec![
                node(
                    "Conv",
                    "c",
                    &["x", "w", "b"],
                    "y",
                    vec![ints("strides", &[2, 2]), ints("pads", &[1, 1, 1, 1])],
                ),
                node("Relu", "r", &["y"], "z", vec![]),
                node(
                    "AveragePool",
                    "p",
                    &["z"],
                    "q",
                    vec![
                        ints("kernel_shape", &[2, 3]),
                        ints("strides", &[2, 3]),
                        ints("pads", &[0, 0, 1, 1]),
                    ],
                ),
                node("Resize", "u", &["q", "", "", "s"], "out", vec![string("mode", "linear")]),
            ],
            vec![
                init_f32("w", &[4, 1, 3, 3], &w),
                init_f32("b", &[4], &[0.1, -0.2, 0.3, 0.0]),
                init_i64("s", &[1, 4, 8, 10]),
            ],
            value("x", &[1, 1, 9, 10]),
            value("out", &[1, 4, 8, 10]),
        )
    }

    #[test]
    fn shapes_follow_the_op_definitions() {
        let bytes = conv_pool_resize().encode_to_vec();
        let g = OnnxGraph::from_bytes(&bytes, Path::new("t.onnx")).unwrap();
        assert_eq!(g.shapes["y"], [1, 4, 5, 5]);
        assert_eq!(g.shapes["q"], [1, 4, 3, 2]);
        assert_eq!(g.shapes["out"], [1, 4, 8, 10]);
        assert_eq!(g.input_hw(), (9, 10));
        assert_eq!(g.nodes[0].ints("strides", &[]), Some(vec![2, 2]));
        assert_eq!(g.initializers["s"].i64s(), Some(&[1, 4, 8, 10][..]));
        assert_eq!(g.initializers["w"].f32s().map(<[f32]>::len), Some(36));
    }

    #[test]
    fn errors_name_the_file_and_node() {
        let e = OnnxGraph::from_bytes(b"\xff\xff\xff", Path::new("bad.onnx")).unwrap_err();
        assert!(e.to_string().starts_with("bad.onnx: not a valid ONNX model"), "{e}");

        let mut m = conv_pool_resize();
        let g = m.graph.as_mut().unwrap();
        g.node[1].op_type = "Sigmoid".into();
        let e = OnnxGraph::from_proto(&m, Path::new("m.onnx")).unwrap_err();
        assert!(e.to_string().contains("m.onnx: node `r` (Sigmoid)"), "{e}");

        let mut m = conv_pool_resize();
        m.graph.as_mut().unwrap().node.swap(0, 1);
        let e = OnnxGraph::from_proto(&m, Path::new("m.onnx")).unwrap_err();
        assert!(e.to_string().contains("not computed before"), "{e}");

        let mut m = conv_pool_resize();
        m.graph.as_mut().unwrap().initializer[0].raw_data.pop();
        let e = OnnxGraph::from_proto(&m, Path::new("m.onnx")).unwrap_err();
        assert!(e.to_string().contains("tensor `w`"), "{e}");

        let e = OnnxGraph::load(Path::new("/nonexistent/x.onnx")).unwrap_err();
        assert_eq!(e.to_string(), "/nonexistent/x.onnx: missing file");
    }
}
