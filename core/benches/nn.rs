//! The int8 segmentation network, op by op: reference vs fast kernels on the real workload.
//!
//! The workload is the Res2Net Fast-SCNN variant at 192×640 (`WORKLOAD` below: every op kind
//! with its shapes, `CxHxW`, and how many times it occurs), run with random int8 tensors,
//! weights and realistic quantisation (activation scales 0.01–0.2, zero points of ReLU outputs
//! near −128, per-channel weight scales, requantisers ≈ 2^-8…2^-12). Before timing, every op's
//! fast output is checked against the reference (bit-equal).
//!
//! Printed first: a table per op kind — reference and fast ms per frame (best of several runs,
//! times the op's count), their ratio, and GMAC/s for the convs — then criterion's figures for
//! the fast kernels per kind. Wall time on a shared machine is noisy: read the ratios.
//!
//! `SEMLOC_SLM=path/to/model.slm` adds the whole graph through `graph::run` (fast and
//! reference, bit-equality checked) on a synthetic input of the model's size.
//! `SEMLOC_NN_REPS=n` sets the repetitions of the table (default 5), `SEMLOC_NN_KINDS=pw,dw`
//! limits it to some kinds, and `SEMLOC_NN_ISA=portable|avx2` caps the x86 fast kernels at the
//! portable (safe, auto-vectorised) or the AVX2 ones (to compare them on a VNNI machine;
//! `portable` also turns the aarch64 NEON kernels off, `neon` only the aarch64 `sdot` GEMM of CPUs
//! with the dot products); `SEMLOC_NN_SEQ_ONLY=1` runs each op
//! once and repeats only the per-kind frames (instruction counts under `qemu-aarch64`: the
//! difference between two repetition counts is whole frames); `SEMLOC_NN_NOREF=1` skips timing the reference
//! kernels (for `perf stat` of the fast ones).

// `criterion_group!` expands to an undocumented `pub fn`.
#![allow(missing_docs)]

use core::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion};
use semloc_core::nn::conv::{
    conv2d_fast, conv2d_reference, depthwise3x3_fast, depthwise3x3_reference, pack_pointwise,
    pointwise_fast, pointwise_packed_len, pointwise_reference, Conv2dParams, ConvQuant,
};
use semloc_core::nn::eltwise::{
    add_fast, add_reference, concat_fast, concat_reference, AddQuant, ConcatInput, Rescale,
};
use semloc_core::nn::graph::{run, Kernels};
use semloc_core::nn::model::Model;
use semloc_core::nn::pool::{avgpool_fast, avgpool_reference, AvgPoolParams, PoolQuant};
use semloc_core::nn::resize::{resize_bilinear_fast, resize_bilinear_reference, ResizeQuant};
use semloc_core::nn::{Requant, Shape};

/// The ops of the Res2Net variant at 192×640 (`kind x count in CxHxW -> out CxHxW ...`), as
/// the ONNX graph lists them (Resize's 4 inputs are X, roi, scales, sizes).
const WORKLOAD: &str = "\
Add          x  1  in 128x24x80 -> out 128x24x80 ninputs 2   (CxHxW)
Add          x  2  in 128x6x20 -> out 128x6x20 ninputs 2   (CxHxW)
Add          x  4  in 148x6x20 -> out 148x6x20 ninputs 2   (CxHxW)
Add          x  6  in 64x12x40 -> out 64x12x40 ninputs 2   (CxHxW)
Add          x  6  in 96x6x20 -> out 96x6x20 ninputs 2   (CxHxW)
AveragePool  x  1  in 128x6x20 -> out 128x1x1 ninputs 1   (CxHxW)
AveragePool  x  1  in 128x6x20 -> out 128x2x2 ninputs 1   (CxHxW)
AveragePool  x  1  in 128x6x20 -> out 128x3x3 ninputs 1   (CxHxW)
AveragePool  x  1  in 128x6x20 -> out 128x6x5 ninputs 1   (CxHxW)
Concat       x  1  in 128x6x20 -> out 256x6x20 ninputs 5   (CxHxW)
Concat       x  3  in 148x6x20 -> out 592x6x20 ninputs 4   (CxHxW)
Concat       x  3  in 64x12x40 -> out 256x12x40 ninputs 4   (CxHxW)
Concat       x  3  in 96x6x20 -> out 384x6x20 ninputs 4   (CxHxW)
Resize       x  1  in 11x24x80 -> out 11x192x640 ninputs 4   (CxHxW)
Resize       x  1  in 128x6x20 -> out 128x24x80 ninputs 4   (CxHxW)
Resize       x  1  in 32x1x1 -> out 32x6x20 ninputs 4   (CxHxW)
Resize       x  1  in 32x2x2 -> out 32x6x20 ninputs 4   (CxHxW)
Resize       x  1  in 32x3x3 -> out 32x6x20 ninputs 4   (CxHxW)
Resize       x  1  in 32x6x5 -> out 32x6x20 ninputs 4   (CxHxW)
conv         x  1  in 1x192x640 -> out 32x96x320 k3 s2   (CxHxW)
dw           x  3  in 128x24x80 -> out 128x24x80 k3 s1   (CxHxW)
dw           x 10  in 148x6x20 -> out 148x6x20 k3 s1   (CxHxW)
dw           x  1  in 32x96x320 -> out 32x48x160 k3 s2   (CxHxW)
dw           x  1  in 48x48x160 -> out 48x24x80 k3 s2   (CxHxW)
dw           x  6  in 64x12x40 -> out 64x12x40 k3 s1   (CxHxW)
dw           x  4  in 64x24x80 -> out 64x12x40 k3 s2   (CxHxW)
dw           x  4  in 96x12x40 -> out 96x6x20 k3 s2   (CxHxW)
dw           x  6  in 96x6x20 -> out 96x6x20 k3 s1   (CxHxW)
pw           x  1  in 128x1x1 -> out 32x1x1 k1 s1   (CxHxW)
pw           x  1  in 128x24x80 -> out 11x24x80 k1 s1   (CxHxW)
pw           x  3  in 128x24x80 -> out 128x24x80 k1 s1   (CxHxW)
pw           x  1  in 128x2x2 -> out 32x2x2 k1 s1   (CxHxW)
pw           x  1  in 128x3x3 -> out 32x3x3 k1 s1   (CxHxW)
pw           x  8  in 128x6x20 -> out 148x6x20 k1 s1   (CxHxW)
pw           x  1  in 128x6x5 -> out 32x6x5 k1 s1   (CxHxW)
pw           x 10  in 148x6x20 -> out 148x6x20 k1 s1   (CxHxW)
pw           x  3  in 256x12x40 -> out 64x12x40 k1 s1   (CxHxW)
pw           x  1  in 256x6x20 -> out 128x6x20 k1 s1   (CxHxW)
pw           x  1  in 32x48x160 -> out 48x48x160 k1 s1   (CxHxW)
pw           x  3  in 384x6x20 -> out 96x6x20 k1 s1   (CxHxW)
pw           x  1  in 48x24x80 -> out 64x24x80 k1 s1   (CxHxW)
pw           x  3  in 592x6x20 -> out 128x6x20 k1 s1   (CxHxW)
pw           x 18  in 64x12x40 -> out 64x12x40 k1 s1   (CxHxW)
pw           x  4  in 64x12x40 -> out 96x12x40 k1 s1   (CxHxW)
pw           x  1  in 64x24x80 -> out 128x24x80 k1 s1   (CxHxW)
pw           x  4  in 64x24x80 -> out 64x24x80 k1 s1   (CxHxW)
pw           x  4  in 96x6x20 -> out 148x6x20 k1 s1   (CxHxW)
pw           x 18  in 96x6x20 -> out 96x6x20 k1 s1   (CxHxW)
";

/// The kinds, in the order the table prints them.
const KINDS: [&str; 7] = ["pw", "dw", "conv", "Resize", "Concat", "Add", "AveragePool"];

/// A tiny xorshift so the bench needs no dependency (same inputs every run).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn int(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.next() % (hi - lo + 1) as u64) as i64
    }
    fn f64(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next() >> 11) as f64 / (1u64 << 53) as f64)
    }
    fn i8s(&mut self, n: usize) -> Vec<i8> {
        (0..n).map(|_| self.int(-128, 127) as i8).collect()
    }
    /// Activations as a ReLU output leaves them: many at the zero point, the rest spread.
    fn acts(&mut self, n: usize, zp: i32) -> Vec<i8> {
        (0..n)
            .map(|_| if self.int(0, 2) == 0 { zp as i8 } else { self.int(zp as i64, 127) as i8 })
            .collect()
    }
    fn weights(&mut self, n: usize) -> Vec<i8> {
        (0..n).map(|_| self.int(-127, 127) as i8).collect()
    }
    /// A ReLU output's zero point.
    fn zp(&mut self) -> i32 {
        self.int(-128, -90) as i32
    }
}

fn parse_shape(s: &str) -> Shape {
    let v: Vec<usize> = s.split('x').map(|t| t.parse().unwrap()).collect();
    Shape::new(v[0], v[1], v[2])
}

/// One line of the workload with its operands.
struct Op {
    kind: &'static str,
    count: usize,
    line: String,
    xs: Shape,
    os: Shape,
    inputs: Vec<(Vec<i8>, Shape, f64, i32)>,
    weights: Vec<i8>,
    bias: Vec<i32>,
    requant: Vec<Requant>,
    stride: usize,
    s_out: f64,
    zp_out: i32,
    relu: bool,
}

impl Op {
    /// Multiply-accumulates of one execution (0 for non-conv ops).
    fn macs(&self) -> u64 {
        let per = match self.kind {
            "pw" => self.xs.c,
            "dw" => 9,
            "conv" => 9 * self.xs.c,
            _ => 0,
        };
        (self.os.len() * per) as u64
    }
}

fn build(rng: &mut Rng) -> Vec<Op> {
    let mut ops = Vec::new();
    for line in WORKLOAD.lines().filter(|l| !l.trim().is_empty()) {
        let t: Vec<&str> = line.split_whitespace().collect();
        let kind = KINDS.iter().find(|&&k| k == t[0]).copied().unwrap();
        let count: usize = t[2].parse().unwrap();
        let xs = parse_shape(t[4]);
        let os = parse_shape(t[7]);
        let ninputs: usize = if t[8] == "ninputs" { t[9].parse().unwrap() } else { 1 };
        let act = |rng: &mut Rng, shape: Shape| {
            let zp = rng.zp();
            (rng.acts(shape.len(), zp), shape, rng.f64(0.01, 0.2), zp)
        };
        let mut inputs = Vec::new();
        match kind {
            "Add" => {
                inputs.push(act(rng, xs));
                inputs.push(act(rng, xs));
            }
            "Concat" => {
                inputs.push(act(rng, xs));
                let rest = (os.c - xs.c) / (ninputs - 1);
                for _ in 1..ninputs {
                    inputs.push(act(rng, Shape::new(rest, xs.h, xs.w)));
                }
            }
            "conv" => {
                // the graph input: luma − 128
                inputs.push((rng.i8s(xs.len()), xs, 1.0 / 255.0, -128));
            }
            _ => inputs.push(act(rng, xs)),
        }
        let (s_in, zp_in) = (inputs[0].2, inputs[0].3);
        let _ = zp_in;
        let (k, c_out) = match kind {
            "pw" => (xs.c, os.c),
            "dw" => (9, os.c),
            "conv" => (9 * xs.c, os.c),
            _ => (0, 0),
        };
        let s_out = rng.f64(0.02, 0.2);
        let weights = rng.weights(c_out * k);
        let s_w: Vec<f64> = (0..c_out).map(|_| rng.f64(0.002, 0.02)).collect();
        let bias = (0..c_out).map(|_| rng.int(-3000, 3000) as i32).collect();
        // output scale sized to the accumulator spread, as calibration does
        let requant = s_w
            .iter()
            .map(|&sw| {
                let spread = 60.0 * 60.0 * (k as f64).sqrt() * s_in * sw;
                Requant::from_scale(s_in * sw / (spread / 40.0).max(1e-6))
            })
            .collect();
        let stride = if line.contains(" s2") { 2 } else { 1 };
        let zp_out = rng.zp();
        let relu = rng.int(0, 1) == 1;
        ops.push(Op {
            kind,
            count,
            line: line.split("   (").next().unwrap().to_string(),
            xs,
            os,
            inputs,
            weights,
            bias,
            requant,
            stride,
            s_out,
            zp_out,
            relu,
        });
    }
    ops
}

/// Packed forms of the weights, prepared once (as a model blob stores them).
fn prepare(ops: &mut [Op]) {
    for op in ops.iter_mut().filter(|o| o.kind == "pw") {
        let mut packed = vec![0i8; pointwise_packed_len(op.os.c, op.xs.c)];
        pack_pointwise(&op.weights, op.os.c, op.xs.c, &mut packed).unwrap();
        op.weights = packed;
    }
}

fn exec(op: &Op, fast: bool, out: &mut [i8]) {
    let (x, xs, s_in, zp_in) = (&op.inputs[0].0, op.inputs[0].1, op.inputs[0].2, op.inputs[0].3);
    let q = ConvQuant {
        input_zero_point: zp_in,
        output_zero_point: op.zp_out,
        requant: &op.requant,
        relu: op.relu,
    };
    match op.kind {
        "pw" => {
            if fast {
                pointwise_fast(x, xs, &op.weights, &op.bias, &q, out).unwrap();
            } else {
                pointwise_reference(x, xs, &op.weights, &op.bias, &q, out).unwrap();
            }
        }
        "dw" => {
            if fast {
                depthwise3x3_fast(x, xs, op.stride, &op.weights, &op.bias, &q, out).unwrap();
            } else {
                depthwise3x3_reference(x, xs, op.stride, &op.weights, &op.bias, &q, out).unwrap();
            }
        }
        "conv" => {
            let p =
                Conv2dParams { c_out: op.os.c, kernel: (3, 3), stride: (2, 2), pads: [1, 1, 1, 1] };
            if fast {
                conv2d_fast(x, xs, &p, &op.weights, &op.bias, &q, out).unwrap();
            } else {
                conv2d_reference(x, xs, &p, &op.weights, &op.bias, &q, out).unwrap();
            }
        }
        "Add" => {
            let (b, _, sb, zb) = &op.inputs[1];
            let q = AddQuant::new(s_in, zp_in, *sb, *zb, op.s_out, op.zp_out, op.relu);
            if fast {
                add_fast(x, b, xs, &q, out).unwrap();
            } else {
                add_reference(x, b, xs, &q, out).unwrap();
            }
        }
        "Concat" => {
            let parts: Vec<ConcatInput<'_>> = op
                .inputs
                .iter()
                .map(|(d, s, sc, zp)| ConcatInput {
                    data: d,
                    shape: *s,
                    rescale: Rescale::new(*sc, *zp, op.s_out, op.zp_out),
                })
                .collect();
            if fast {
                concat_fast(&parts, out).unwrap();
            } else {
                concat_reference(&parts, out).unwrap();
            }
        }
        "Resize" => {
            let q = ResizeQuant::new(s_in, zp_in, op.s_out, op.zp_out);
            if fast {
                resize_bilinear_fast(x, xs, (op.os.h, op.os.w), &q, out).unwrap();
            } else {
                resize_bilinear_reference(x, xs, (op.os.h, op.os.w), &q, out).unwrap();
            }
        }
        "AveragePool" => {
            let bins = xs.h.div_ceil(op.os.h).max(1);
            let mut p = AvgPoolParams::ppm(xs, op.os.h).unwrap();
            if p.output_shape(xs).ok() != Some(op.os) {
                p = AvgPoolParams::ppm(xs, bins).unwrap();
            }
            let q = PoolQuant::new(s_in, zp_in, op.s_out, op.zp_out);
            if fast {
                avgpool_fast(x, xs, &p, &q, out).unwrap();
            } else {
                avgpool_reference(x, xs, &p, &q, out).unwrap();
            }
        }
        _ => unreachable!(),
    }
}

/// Best wall time of `reps` runs, seconds.
fn best(reps: usize, f: &mut dyn FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn table(ops: &[Op]) {
    let reps: usize =
        std::env::var("SEMLOC_NN_REPS").ok().and_then(|v| v.parse().ok()).unwrap_or(5);
    let mut per_kind = vec![(0.0f64, 0.0f64, 0u64, 0usize); KINDS.len()];
    let only = std::env::var("SEMLOC_NN_KINDS").unwrap_or_default();
    let no_ref = std::env::var("SEMLOC_NN_NOREF").is_ok_and(|v| v == "1");
    let seq_only = std::env::var("SEMLOC_NN_SEQ_ONLY").is_ok_and(|v| v == "1");
    println!("\nper op (ms per execution; fast/ref bit-equal checked):");
    for op in ops {
        if !only.is_empty() && !only.split(',').any(|k| k == op.kind) {
            continue;
        }
        let mut r = vec![0i8; op.os.len()];
        let mut f = vec![1i8; op.os.len()];
        exec(op, false, &mut r);
        exec(op, true, &mut f);
        assert!(r == f, "fast != reference: {}", op.line);
        let tr = if no_ref {
            f64::NAN
        } else {
            best(reps.div_ceil(2).max(1), &mut || exec(op, false, black_box(&mut r)))
        };
        // SEMLOC_NN_SEQ_ONLY=1: only the per-kind frames below are repeated (instruction
        // counts under an emulator: the difference of two `SEMLOC_NN_REPS` is whole frames)
        let tf = best(if seq_only { 1 } else { reps }, &mut || exec(op, true, black_box(&mut f)));
        let k = KINDS.iter().position(|&k| k == op.kind).unwrap();
        let e = &mut per_kind[k];
        e.0 += tr * op.count as f64;
        e.1 += tf * op.count as f64;
        e.2 += op.macs() * op.count as u64;
        e.3 += op.os.len() * op.count;
        let gmacs = if op.macs() > 0 { op.macs() as f64 / tf / 1e9 } else { 0.0 };
        println!(
            "  {:<58} ref {:8.3}  fast {:7.3}  x{:5.1}  {:6.1} GMAC/s",
            op.line,
            tr * 1e3,
            tf * 1e3,
            tr / tf,
            gmacs
        );
    }
    println!("\nper kind (ms per frame; `fast seq`: all ops of the kind in graph order, each");
    println!("as often as it occurs, best of {reps} — includes cold caches between ops):");
    println!(
        "  {:<12} {:>8} {:>9} {:>9} {:>8} {:>9} {:>8} {:>8}",
        "kind", "MMAC", "outputs", "ref ms", "fast ms", "fast seq", "ratio", "GMAC/s"
    );
    let (mut tr, mut tf, mut ts) = (0.0, 0.0, 0.0);
    for (k, e) in KINDS.iter().zip(&per_kind) {
        if e.3 == 0 {
            continue;
        }
        let mine: Vec<&Op> = ops.iter().filter(|o| o.kind == *k).collect();
        let mut outs: Vec<Vec<i8>> = mine.iter().map(|o| vec![0i8; o.os.len()]).collect();
        let seq = best(reps, &mut || {
            for (op, out) in mine.iter().zip(outs.iter_mut()) {
                for _ in 0..op.count {
                    exec(op, true, black_box(out));
                }
            }
        });
        tr += e.0;
        tf += e.1;
        ts += seq;
        let g = if e.2 > 0 { format!("{:.1}", e.2 as f64 / e.1 / 1e9) } else { "-".into() };
        println!(
            "  {:<12} {:>8.1} {:>9} {:>9.2} {:>8.3} {:>9.3} {:>7.1}x {:>8}",
            k,
            e.2 as f64 / 1e6,
            e.3,
            e.0 * 1e3,
            e.1 * 1e3,
            seq * 1e3,
            e.0 / e.1,
            g
        );
    }
    println!(
        "  {:<12} {:>8} {:>9} {:>9.2} {:>8.3} {:>9.3} {:>7.1}x",
        "total",
        "",
        "",
        tr * 1e3,
        tf * 1e3,
        ts * 1e3,
        tr / tf
    );
}

fn graph_bench(c: &mut Criterion) {
    let Ok(path) = std::env::var("SEMLOC_SLM") else { return };
    let bytes = match std::fs::read(&path) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("SEMLOC_SLM={path}: {e}");
            return;
        }
    };
    let model_bytes = align_vec(&bytes);
    let m = match Model::parse(model_bytes.as_slice()) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("SEMLOC_SLM: {e}");
            return;
        }
    };
    let parse = best(5, &mut || {
        black_box(Model::parse(black_box(model_bytes.as_slice())).unwrap());
    });
    println!("\nModel::parse (CRC-32 + validation) of {path}: {:.2} ms", parse * 1e3);
    let (h, w) = m.input_size();
    let mut rng = Rng(0x5eed);
    let input: Vec<u8> = (0..h * w).map(|_| rng.int(0, 255) as u8).collect();
    let mut a1 = vec![0i8; m.arena_len()];
    let mut a2 = vec![0i8; m.arena_len()];
    let o1 = run(&m, &input, &mut a1, Kernels::Fast).unwrap().to_vec();
    let o2 = run(&m, &input, &mut a2, Kernels::Reference).unwrap().to_vec();
    assert!(o1 == o2, "whole graph: fast != reference");
    let reps: usize =
        std::env::var("SEMLOC_NN_REPS").ok().and_then(|v| v.parse().ok()).unwrap_or(5);
    let no_ref = std::env::var("SEMLOC_NN_NOREF").is_ok_and(|v| v == "1");
    let tr = if no_ref {
        f64::NAN
    } else {
        best(1, &mut || {
            run(&m, &input, &mut a2, Kernels::Reference).unwrap();
        })
    };
    let tf = best(reps, &mut || {
        run(&m, &input, &mut a1, Kernels::Fast).unwrap();
    });
    println!(
        "\nwhole graph {path} ({} ops, {:.0} MMAC, {h}x{w}): reference {:.1} ms, fast {:.2} ms \
         (best of {reps}), x{:.1}",
        m.n_ops(),
        m.macs() as f64 / 1e6,
        tr * 1e3,
        tf * 1e3,
        tr / tf
    );
    // where the time goes: each op's best time over the runs, summed per kind
    let mut per_op = vec![f64::INFINITY; m.n_ops()];
    for _ in 0..reps {
        let mut last = Instant::now();
        semloc_core::nn::graph::run_observed(&m, &input, &mut a1, Kernels::Fast, &mut |k| {
            let now = Instant::now();
            per_op[k] = per_op[k].min((now - last).as_secs_f64());
            last = now;
        })
        .unwrap();
    }
    let mut kinds: Vec<(String, usize, f64, u64)> = Vec::new();
    for (k, t) in per_op.iter().enumerate() {
        let op = m.op(k);
        let name = format!("{:?}", op.kind());
        let (ins, _) = op.inputs();
        let macs = op.macs(
            m.tensor(ins[0] as usize).unwrap().shape,
            m.tensor(op.output() as usize).unwrap().shape,
        );
        match kinds.iter_mut().find(|e| e.0 == name) {
            Some(e) => {
                e.1 += 1;
                e.2 += t;
                e.3 += macs;
            }
            None => kinds.push((name, 1, *t, macs)),
        }
    }
    println!("  per kind (sum of each op's best):");
    for (name, n, t, macs) in &kinds {
        let g = if *macs > 0 {
            format!("{:6.1} GMAC/s", *macs as f64 / t / 1e9)
        } else {
            String::new()
        };
        println!("  {name:<14} {n:>4} ops {:>8.3} ms {g}", t * 1e3);
    }
    c.bench_function("graph_fast", |b| {
        b.iter(|| {
            run(&m, black_box(&input), &mut a1, Kernels::Fast).unwrap();
        })
    });
}

/// A byte vector whose data starts 4-byte aligned (a `Vec<u8>` from the system allocator is
/// at least 8-byte aligned; checked).
fn align_vec(bytes: &[u8]) -> Vec<u8> {
    let v = bytes.to_vec();
    assert_eq!(v.as_ptr().align_offset(4), 0, "allocator returned an unaligned Vec<u8>");
    v
}

fn kernels(c: &mut Criterion) {
    #[cfg(target_arch = "x86_64")]
    {
        use semloc_core::nn::x86::{isa, set_max_isa, Isa};
        match std::env::var("SEMLOC_NN_ISA").as_deref() {
            Ok("portable") => set_max_isa(Isa::Portable),
            Ok("avx2") => set_max_isa(Isa::Avx2),
            _ => set_max_isa(Isa::Avx512Vnni),
        }
        println!("x86-64 fast kernels: {:?}", isa());
    }
    #[cfg(target_arch = "aarch64")]
    {
        use semloc_core::nn::arm64::{dotprod_enabled, neon_enabled, set_dotprod, set_neon};
        let isa = std::env::var("SEMLOC_NN_ISA");
        set_neon(isa.as_deref() != Ok("portable"));
        set_dotprod(isa.as_deref() != Ok("neon"));
        println!("aarch64 NEON kernels: {}, sdot GEMM: {}", neon_enabled(), dotprod_enabled());
    }
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut ops = build(&mut rng);
    prepare(&mut ops);
    table(&ops);
    let mut g = c.benchmark_group("nn_fast_per_frame");
    for kind in KINDS {
        let mine: Vec<&Op> = ops.iter().filter(|o| o.kind == kind).collect();
        let mut outs: Vec<Vec<i8>> = mine.iter().map(|o| vec![0i8; o.os.len()]).collect();
        g.bench_function(kind, |b| {
            b.iter(|| {
                for (op, out) in mine.iter().zip(outs.iter_mut()) {
                    for _ in 0..op.count {
                        exec(op, true, black_box(out));
                    }
                }
            })
        });
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = kernels, graph_bench
}
criterion_main!(benches);
