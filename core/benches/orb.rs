//! ORB extraction on one KITTI-sized frame (1241 × 376, ORB-SLAM2's KITTI settings).
//!
//! `SEMLOC_BENCH_FRAME` may name a real frame: a binary PGM (P5) or raw 8-bit luma of
//! 1241 × 376 bytes (e.g. `python3 -c "from PIL import Image; Image.open('0000000000.png')
//! .convert('L').save('/tmp/f.pgm')"`). Without it a synthetic textured frame is used.
//! Besides the full extraction it times two stages (pyramid build, level-0 blur) so their share
//! of the frame is visible in the same run.

// `criterion_group!` expands to an undocumented `pub fn`.
#![allow(missing_docs)]

use core::hint::black_box;
use std::sync::Mutex;

use criterion::{criterion_group, criterion_main, Criterion};
use semloc_core::image::{gaussian_blur_7x7, BlurScratch, ImageView, ImageViewMut};
use semloc_core::orb::{KittiOrbExtractor, OrbConfig, Pyramid, KITTI_MAX_WIDTH};
use semloc_core::testing;

const W: usize = 1241;
const H: usize = 376;

static EXT: Mutex<KittiOrbExtractor> = Mutex::new(KittiOrbExtractor::new());
static PYR: Mutex<Pyramid<KITTI_MAX_WIDTH, { 1248 * 384 * 4 }>> = Mutex::new(Pyramid::new());

fn read_frame() -> Option<(usize, usize, Vec<u8>)> {
    let path = std::env::var("SEMLOC_BENCH_FRAME").ok()?;
    let bytes = std::fs::read(&path).ok()?;
    if bytes.len() == W * H {
        return Some((W, H, bytes));
    }
    if !bytes.starts_with(b"P5") {
        return None;
    }
    // Header: "P5" w h maxval, whitespace separated, then one whitespace byte.
    let mut fields = Vec::new();
    let mut i = 0;
    while fields.len() < 4 {
        while bytes.get(i)?.is_ascii_whitespace() {
            i += 1;
        }
        let s = i;
        while !bytes.get(i)?.is_ascii_whitespace() {
            i += 1;
        }
        fields.push(String::from_utf8_lossy(&bytes[s..i]).into_owned());
    }
    let (w, h): (usize, usize) = (fields[1].parse().ok()?, fields[2].parse().ok()?);
    Some((w, h, bytes.get(i + 1..i + 1 + w * h)?.to_vec()))
}

/// Random rectangles, lightly blurred: corners at all scales, uniform over the frame.
fn synthetic() -> (usize, usize, Vec<u8>) {
    let mut img = vec![0u8; W * H];
    testing::rect_texture(&mut img, W, H, 0x2545_f491);
    (W, H, img)
}

fn bench(c: &mut Criterion) {
    let (w, h, img) = read_frame().unwrap_or_else(synthetic);
    let source = if std::env::var("SEMLOC_BENCH_FRAME").is_ok() { "file" } else { "synthetic" };
    let frame = ImageView::from_slice(&img, w, h).expect("frame");
    let mut ext = EXT.lock().expect("extractor");
    ext.configure(OrbConfig::KITTI).expect("config");
    let n = ext.extract(&frame).expect("extract").len();
    println!("{source} frame {w}x{h}: {n} features");
    for (l, s) in ext.features().stats().levels().iter().enumerate() {
        println!("  level {l}: corners {} selected {}", s.fast_corners, s.selected);
    }

    // `SEMLOC_BENCH_QUICK=N`: N timed extractions, min and median, then the criterion runs (a
    // quick A/B figure on a loaded machine, where the minimum is the stablest statistic).
    if let Some(n) = std::env::var("SEMLOC_BENCH_QUICK").ok().and_then(|v| v.parse::<usize>().ok())
    {
        let mut ms: Vec<f64> = (0..n.max(1))
            .map(|_| {
                let t = std::time::Instant::now();
                black_box(ext.extract(black_box(&frame)).expect("extract").len());
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        ms.sort_by(f64::total_cmp);
        println!("quick: {n} extractions, min {:.3} ms, median {:.3} ms", ms[0], ms[ms.len() / 2]);
    }

    c.bench_function(&format!("orb_extract_{w}x{h}_{source}"), |b| {
        b.iter(|| black_box(ext.extract(black_box(&frame)).expect("extract").len()))
    });

    let mut pyr = PYR.lock().expect("pyramid");
    c.bench_function("orb_pyramid_8x1.2", |b| {
        b.iter(|| pyr.build(black_box(&frame), 1.2, 8).expect("pyramid"))
    });

    let mut out = vec![0u8; w * h];
    let mut scratch = Box::new(BlurScratch::<KITTI_MAX_WIDTH>::new());
    c.bench_function("gaussian_blur_7x7_level0", |b| {
        b.iter(|| {
            let mut dst = ImageViewMut::from_slice(&mut out, w, h).expect("dst");
            gaussian_blur_7x7(black_box(&frame), &mut dst, &mut scratch).expect("blur")
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
