//! Small synthetic networks for tests and examples, built without Python: an ONNX writer
//! over tract-onnx's protobuf types ([`model`], [`node`], ...), [`tiny_onnx`] (a net with
//! every op kind the converter handles) and [`calibrate`], `models/quantise.py`'s min/max
//! post-training quantisation with tract as the float engine, which makes its `quant.json`.
//!
//! Not a general ONNX builder: only the attribute and tensor kinds the network uses.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use prost::Message;
use tract_onnx::pb;
use tract_onnx::prelude::{tvec, Framework, InferenceModelExt, IntoRunnable, Tensor, TractError};

use super::convert::{QuantConv, QuantInput, QuantParams, QuantTensor, INPUT_SCALE};
use super::onnx::OnnxGraph;
use super::NnFileError;

/// A float initializer.
pub fn init_f32(name: &str, dims: &[i64], v: &[f32]) -> pb::TensorProto {
    pb::TensorProto {
        name: name.into(),
        dims: dims.to_vec(),
        data_type: pb::tensor_proto::DataType::Float as i32,
        raw_data: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
        ..Default::default()
    }
}

/// An int64 initializer (inline `int64_data`, to cover both storage forms).
pub fn init_i64(name: &str, v: &[i64]) -> pb::TensorProto {
    pb::TensorProto {
        name: name.into(),
        dims: vec![v.len() as i64],
        data_type: pb::tensor_proto::DataType::Int64 as i32,
        int64_data: v.to_vec(),
        ..Default::default()
    }
}

/// `INTS` attribute.
pub fn ints(name: &str, v: &[i64]) -> pb::AttributeProto {
    pb::AttributeProto {
        name: name.into(),
        r#type: pb::attribute_proto::AttributeType::Ints as i32,
        ints: v.to_vec(),
        ..Default::default()
    }
}

/// `INT` attribute.
pub fn int(name: &str, v: i64) -> pb::AttributeProto {
    pb::AttributeProto {
        name: name.into(),
        r#type: pb::attribute_proto::AttributeType::Int as i32,
        i: v,
        ..Default::default()
    }
}

/// `STRING` attribute.
pub fn string(name: &str, v: &str) -> pb::AttributeProto {
    pb::AttributeProto {
        name: name.into(),
        r#type: pb::attribute_proto::AttributeType::String as i32,
        s: v.as_bytes().to_vec(),
        ..Default::default()
    }
}

/// A node.
pub fn node(
    op: &str,
    name: &str,
    inputs: &[&str],
    output: &str,
    attrs: Vec<pb::AttributeProto>,
) -> pb::NodeProto {
    pb::NodeProto {
        op_type: op.into(),
        name: name.into(),
        input: inputs.iter().map(|s| s.to_string()).collect(),
        output: vec![output.into()],
        attribute: attrs,
        ..Default::default()
    }
}

/// A float tensor value info with a static shape.
pub fn value(name: &str, dims: &[i64]) -> pb::ValueInfoProto {
    use pb::tensor_shape_proto::{dimension::Value, Dimension};
    pb::ValueInfoProto {
        name: name.into(),
        r#type: Some(pb::TypeProto {
            value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                elem_type: pb::tensor_proto::DataType::Float as i32,
                shape: Some(pb::TensorShapeProto {
                    dim: dims
                        .iter()
                        .map(|&d| Dimension {
                            value: Some(Value::DimValue(d)),
                            ..Default::default()
                        })
                        .collect(),
                }),
            })),
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// A whole opset-17 model.
pub fn model(
    nodes: Vec<pb::NodeProto>,
    inits: Vec<pb::TensorProto>,
    input: pb::ValueInfoProto,
    output: pb::ValueInfoProto,
) -> pb::ModelProto {
    pb::ModelProto {
        ir_version: 8,
        opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: 17 }],
        producer_name: "semloc-test".into(),
        graph: Some(pb::GraphProto {
            name: "g".into(),
            node: nodes,
            initializer: inits,
            input: vec![input],
            output: vec![output],
            ..Default::default()
        }),
        ..Default::default()
    }
}

/// A tiny net: conv 3x3 s2 (1→4) + ReLU → depthwise 3x3 + ReLU → pointwise 4→2, concat
/// with a 4→1 pointwise of the first ReLU, add a third pointwise branch → avgpool 2x2
/// (bottom/right pad when odd) → resize back to the input size (3 class logits).
pub fn tiny_onnx(h: i64, w: i64) -> pb::ModelProto {
    let f = |n: usize, seed: f32| -> Vec<f32> {
        (0..n).map(|i| ((i as f32 + 1.0) * seed).sin() * 0.5).collect()
    };
    let (h2, w2) = ((h + 1) / 2, (w + 1) / 2);
    model(
        vec![
            node(
                "Conv",
                "c0",
                &["luma", "w0", "b0"],
                "c0_out",
                vec![
                    ints("strides", &[2, 2]),
                    ints("pads", &[1, 1, 1, 1]),
                    ints("kernel_shape", &[3, 3]),
                ],
            ),
            node("Relu", "r0", &["c0_out"], "r0_out", vec![]),
            node(
                "Conv",
                "dw",
                &["r0_out", "w1", "b1"],
                "dw_out",
                vec![ints("pads", &[1, 1, 1, 1]), int("group", 4)],
            ),
            node("Relu", "r1", &["dw_out"], "r1_out", vec![]),
            node("Conv", "pw", &["r1_out", "w2", "b2"], "pw_out", vec![]),
            node("Conv", "pw2", &["r0_out", "w3"], "pw2_out", vec![]),
            node("Concat", "cat", &["pw_out", "pw2_out"], "cat_out", vec![int("axis", 1)]),
            node("Conv", "pw3", &["r0_out", "w4", "b4"], "pw3_out", vec![]),
            node("Add", "add", &["cat_out", "pw3_out"], "add_out", vec![]),
            node(
                "AveragePool",
                "pool",
                &["add_out"],
                "pool_out",
                vec![
                    ints("kernel_shape", &[2, 2]),
                    ints("strides", &[2, 2]),
                    ints("pads", &[0, 0, h2 % 2, w2 % 2]),
                    int("count_include_pad", 0),
                ],
            ),
            node(
                "Resize",
                "up",
                &["pool_out", "", "", "sizes"],
                "logits",
                vec![
                    string("mode", "linear"),
                    string("coordinate_transformation_mode", "half_pixel"),
                ],
            ),
        ],
        vec![
            init_f32("w0", &[4, 1, 3, 3], &f(36, 0.7)),
            init_f32("b0", &[4], &[0.05, -0.1, 0.2, 0.0]),
            init_f32("w1", &[4, 1, 3, 3], &f(36, 1.3)),
            init_f32("b1", &[4], &[0.1, 0.0, -0.05, 0.02]),
            init_f32("w2", &[2, 4, 1, 1], &f(8, 2.1)),
            init_f32("b2", &[2], &[0.0, 0.1]),
            init_f32("w3", &[1, 4, 1, 1], &f(4, 0.9)),
            init_f32("w4", &[3, 4, 1, 1], &f(12, 1.7)),
            init_f32("b4", &[3], &[0.1, -0.1, 0.0]),
            init_i64("sizes", &[1, 3, h, w]),
        ],
        value("luma", &[1, 1, h, w]),
        value("logits", &[1, 3, h, w]),
    )
}

/// Min/max post-training quantisation of an ONNX graph as `models/quantise.py` does it, with
/// tract running the float graph on `images` (`h x w` luma maps of the model's input size)
/// to observe every node output: activations per-tensor asymmetric
/// (`scale = (max − min)/255` with `min ≤ 0 ≤ max`, `zero_point = round(−128 − min/scale)`),
/// weights per output channel `max|W_c|/127` (f32), biases at `s_in · s_w` (f32), and a
/// Conv/Add whose only consumer is a Relu fused with it.
pub fn calibrate(onnx: &[u8], images: &[Vec<u8>]) -> Result<QuantParams, NnFileError> {
    let path = Path::new("<calibration>");
    let g = OnnxGraph::from_bytes(onnx, path)?;
    let tract_err = |e: TractError| NnFileError::Tract { path: path.into(), msg: format!("{e:#}") };
    let names: Vec<String> = g.nodes.iter().map(|n| n.outputs[0].clone()).collect();
    let mut r = onnx;
    let plan = tract_onnx::onnx()
        .model_for_read(&mut r)
        .and_then(|m| m.with_outputs_by_name(&names))
        .and_then(|m| m.into_optimized())
        .and_then(|m| m.into_runnable())
        .map_err(tract_err)?;
    let (h, w) = g.input_hw();
    let mut range: BTreeMap<String, (f32, f32)> = BTreeMap::new();
    for img in images {
        let x: Vec<f32> = img.iter().map(|&v| f32::from(v) / 255.0).collect();
        let outs = Tensor::from_shape(&[1, 1, h, w], &x)
            .and_then(|t| plan.run(tvec!(t.into())))
            .map_err(tract_err)?;
        for (name, t) in names.iter().zip(&outs) {
            let v = t.to_plain_array_view::<f32>().map_err(tract_err)?;
            let e = range.entry(name.clone()).or_insert((f32::INFINITY, f32::NEG_INFINITY));
            for &y in v.iter() {
                e.0 = e.0.min(y);
                e.1 = e.1.max(y);
            }
        }
    }
    let mut consumers: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for n in &g.nodes {
        for i in &n.inputs {
            consumers.entry(i.as_str()).or_default().push(n.op.as_str());
        }
    }
    let mut fused = Vec::new();
    let mut activations = BTreeMap::new();
    for n in &g.nodes {
        let o = &n.outputs[0];
        let only_relu = consumers.get(o.as_str()).is_some_and(|c| c.as_slice() == ["Relu"]);
        if (n.op == "Conv" || n.op == "Add") && only_relu {
            fused.push(o.clone());
            continue;
        }
        let (lo, hi) = range.get(o).copied().unwrap_or((0.0, 0.0));
        let (lo, mut hi) = (f64::from(lo).min(0.0), f64::from(hi).max(0.0));
        if hi - lo < 1e-8 {
            hi = lo + 1e-8;
        }
        let scale = (hi - lo) / 255.0;
        let zero_point = (-128.0 - lo / scale).round_ties_even().clamp(-128.0, 127.0) as i64;
        activations.insert(o.clone(), QuantTensor { scale, zero_point });
    }
    let mut convs = BTreeMap::new();
    for n in g.nodes.iter().filter(|n| n.op == "Conv") {
        let w = g.constant(n, 1)?;
        let wf = w.f32s().unwrap_or_default();
        let co = w.dims.first().copied().unwrap_or(1).max(1);
        let s_in = if n.inputs[0] == g.input {
            INPUT_SCALE
        } else {
            activations.get(&n.inputs[0]).map_or(1.0, |t: &QuantTensor| t.scale)
        };
        let weight_scales: Vec<f32> = wf
            .chunks(wf.len().div_ceil(co).max(1))
            .map(|row| row.iter().fold(0f32, |a, v| a.max(v.abs())).max(1e-12) / 127.0)
            .collect();
        let bias_scales = weight_scales.iter().map(|&sw| f64::from(s_in as f32 * sw)).collect();
        convs.insert(
            n.name.clone(),
            QuantConv {
                input: n.inputs[0].clone(),
                weight: n.inputs[1].clone(),
                bias: n.input(2).map(str::to_owned),
                output: n.outputs[0].clone(),
                weight_scales: weight_scales.into_iter().map(f64::from).collect(),
                bias_scales,
            },
        );
    }
    Ok(QuantParams {
        input: QuantInput { name: g.input.clone(), scale: INPUT_SCALE, zero_point: -128 },
        activations,
        fused,
        convs,
    })
}

/// Smooth synthetic luma maps (`h x w`) with structure at several scales, for calibration
/// and tests.
pub fn test_images(h: usize, w: usize, n: usize) -> Vec<Vec<u8>> {
    (0..n)
        .map(|k| {
            let k = k as f32;
            (0..h * w)
                .map(|i| {
                    let (y, x) = ((i / w) as f32, (i % w) as f32);
                    let v = 128.0
                        + 70.0 * ((x + 3.0 * k) * 0.21).sin() * ((y + k) * 0.17).cos()
                        + 40.0 * ((x * 0.05 + y * 0.09 + k).sin());
                    v.clamp(0.0, 255.0) as u8
                })
                .collect()
        })
        .collect()
}

/// A `quant.json` for [`tiny_onnx`] bytes: [`calibrate`] on eight [`test_images`].
pub fn tiny_quant(onnx: &[u8]) -> Result<QuantParams, NnFileError> {
    let g = OnnxGraph::from_bytes(onnx, Path::new("<tiny>"))?;
    let (h, w) = g.input_hw();
    calibrate(onnx, &test_images(h, w, 8))
}

/// Writes [`tiny_onnx`]`(h, w)` and its [`tiny_quant`] as `<stem>.onnx` and
/// `<stem>.quant.json` in `dir`; returns the ONNX path.
pub fn write_tiny(dir: &Path, stem: &str, h: i64, w: i64) -> Result<PathBuf, NnFileError> {
    let bytes = tiny_onnx(h, w).encode_to_vec();
    let q = tiny_quant(&bytes)?;
    let onnx = dir.join(format!("{stem}.onnx"));
    std::fs::write(&onnx, &bytes).map_err(|e| NnFileError::io(&onnx, &e))?;
    let json_path = dir.join(format!("{stem}.quant.json"));
    let json = serde_json::to_string_pretty(&q)
        .map_err(|e| NnFileError::QuantJson { path: json_path.clone(), msg: e.to_string() })?;
    std::fs::write(&json_path, json).map_err(|e| NnFileError::io(&json_path, &e))?;
    Ok(onnx)
}
