//! Writes the committed seed corpus of the fuzz targets into `tests/fuzz/seeds/`: small valid
//! model blobs (every op kind) and a few frames. `cargo run --bin make_seeds` from
//! `tests/fuzz`; deterministic, so re-running reproduces the committed files.

use std::path::Path;

use semloc_core::nn::model::MAX_INPUTS;
use semloc_core::nn::model::{
    encoded_len, plan_arena, write, ConvGeometry, OpKind, OpSpec, TensorSpec,
};
use semloc_core::nn::pool::AvgPoolParams;
use semloc_core::nn::{Requant, Shape};

fn t(c: usize, h: usize, w: usize, zp: i32) -> TensorSpec {
    TensorSpec { shape: Shape::new(c, h, w), zero_point: zp, scale: 0.05 }
}

/// A blob as the model_blob target reads it: flag byte 3 (fix length, re-seal CRC) + blob.
fn blob(tensors: &[TensorSpec], ops: &[OpSpec<'_>], output: u32) -> Vec<u8> {
    let mut offsets = vec![0u32; tensors.len()];
    let arena = plan_arena(tensors, ops, 0, output, &mut offsets).expect("plan");
    let mut b = vec![0u8; encoded_len(tensors, ops)];
    write(tensors, ops, 0, output, &offsets, arena, &mut b).expect("write");
    let mut v = vec![3u8];
    v.extend_from_slice(&b);
    v
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("seeds");
    let (h, w) = (12, 16);
    let input = TensorSpec { shape: Shape::new(1, h, w), zero_point: -128, scale: 1.0 / 255.0 };
    let rq = |n: usize| vec![Requant::from_scale(0.004); n];
    let wts = |n: usize| (0..n).map(|i| ((i * 37) % 255) as i8).collect::<Vec<i8>>();
    let g1 = ConvGeometry { kernel: (1, 1), stride: (1, 1), pads: [0; 4] };
    let g3s2 = ConvGeometry { kernel: (3, 3), stride: (2, 2), pads: [1; 4] };
    let (w0, w1, w2) = (wts(4 * 9), wts(4 * 9), wts(6 * 4));
    let (b4, b6, rq4, rq6) = (vec![10i32; 4], vec![-5i32; 6], rq(4), rq(6));

    // 1. one pointwise conv
    let pw = [OpSpec::Conv {
        kind: OpKind::Pointwise,
        input: 0,
        output: 1,
        geometry: g1,
        weights: &w2[..4],
        bias: &b4,
        requant: &rq4,
        relu: true,
    }];
    let seeds_model = vec![
        ("pointwise", blob(&[input, t(4, h, w, -20)], &pw, 1)),
        ("conv_dw_pool_resize_add_concat", {
            let (h2, w2s) = (h / 2, w / 2);
            let (h4, w4) = (h2 / 2, w2s / 2);
            let tensors = [
                input,
                t(4, h2, w2s, -10),
                t(4, h4, w4, -12),
                t(4, 2, 2, -11),
                t(4, h4, w4, -13),
                t(4, h4, w4, -9),
                t(8, h4, w4, -14),
                t(8, h4, w4, -128),
                t(6, h4, w4, 0),
                t(6, h, w, 1),
            ];
            let pool = AvgPoolParams::ppm(Shape::new(4, h4, w4), 2).expect("ppm");
            let mut cat = [0u32; MAX_INPUTS];
            cat[0] = 4;
            cat[1] = 5;
            let ops = [
                OpSpec::Conv {
                    kind: OpKind::Conv,
                    input: 0,
                    output: 1,
                    geometry: g3s2,
                    weights: &w0,
                    bias: &b4,
                    requant: &rq4,
                    relu: true,
                },
                OpSpec::Conv {
                    kind: OpKind::Depthwise3x3,
                    input: 1,
                    output: 2,
                    geometry: g3s2,
                    weights: &w1,
                    bias: &b4,
                    requant: &rq4,
                    relu: false,
                },
                OpSpec::AvgPool {
                    input: 2,
                    output: 3,
                    kernel: pool.kernel,
                    pad_bottom_right: pool.pad_bottom_right,
                },
                OpSpec::Resize { input: 3, output: 4 },
                OpSpec::Add { a: 2, b: 4, output: 5, relu: true },
                OpSpec::Concat { inputs: cat, n: 2, output: 6 },
                OpSpec::Relu { input: 6, output: 7 },
                OpSpec::Conv {
                    kind: OpKind::Pointwise,
                    input: 7,
                    output: 8,
                    geometry: g1,
                    weights: &wts(6 * 8),
                    bias: &b6,
                    requant: &rq6,
                    relu: false,
                },
                OpSpec::Resize { input: 8, output: 9 },
            ];
            blob(&tensors, &ops, 9)
        }),
    ];
    let dir = root.join("model_blob");
    std::fs::create_dir_all(&dir).expect("seed folder");
    for (name, b) in seeds_model {
        std::fs::write(dir.join(name), b).expect("write seed");
    }
    // Frames: width, height (LE u16), flags, then tiled bytes.
    let dir = root.join("image_frontend");
    std::fs::create_dir_all(&dir).expect("seed folder");
    let frame = |w: u16, h: u16, flags: u8, body: &[u8]| {
        let mut v = w.to_le_bytes().to_vec();
        v.extend_from_slice(&h.to_le_bytes());
        v.push(flags);
        v.extend_from_slice(body);
        v
    };
    let texture: Vec<u8> = (0..997u32).map(|i| (i.wrapping_mul(2654435761) >> 24) as u8).collect();
    for (name, f) in [
        ("kitti_size_texture", frame(1242, 375, 232, &texture)),
        ("small_texture", frame(96, 64, 7, &texture)),
        ("blank", frame(320, 120, 0, &[])),
        ("one_pixel", frame(1, 1, 0, &[9])),
        ("too_wide", frame(1280, 100, 96, &texture)),
    ] {
        std::fs::write(dir.join(name), f).expect("write seed");
    }
}
