#![allow(missing_docs)] // criterion_group! generates an undocumented pub fn
//! Criterion bench of one whole frame (ORB on both images, stereo matching, tracking) on real
//! KITTI raw frames, with one and with two threads, so the figures are read as a ratio in the
//! same run. The tracker first processes 10 frames so the map is in its steady state; each
//! iteration then tracks the next pair of an alternating two-frame loop (frames 10/11), which
//! keeps the map warm without running off the end of the drive.
//!
//! Needs `../shared/data/kitti-raw`; without it the bench says so and measures nothing.

use criterion::{criterion_group, criterion_main, Criterion};
use semloc::dataset::Sequence;
use semloc::pipeline::Pipeline;
use semloc_core::tracker::TrackerParams;

fn frames(c: &mut Criterion) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/kitti-raw");
    let Ok(seq) = Sequence::open_raw(&root, "2011_09_26_0005", None) else {
        eprintln!("frame bench: {} not found, nothing measured", root.display());
        return;
    };
    let imgs: Vec<_> = (0..12).map(|i| seq.load_luma(i).expect("load frame")).collect();
    let (w, h) = seq.image_size;
    let mut group = c.benchmark_group("frame_1242x375");
    group.sample_size(20);
    for threads in [1usize, 2] {
        let mut p =
            Pipeline::new(&seq.calib, w, h, TrackerParams::default(), threads).expect("pipeline");
        for (i, (l, r)) in imgs.iter().take(10).enumerate() {
            p.process_images(l, r, i, i as f64 * 0.1).expect("warm-up frame");
        }
        let mut k = 0usize;
        group.bench_function(format!("{threads}_threads"), |b| {
            b.iter(|| {
                let i = 10 + (k % 2);
                k += 1;
                let (l, r) = &imgs[i];
                p.process_images(l, r, i, i as f64 * 0.1).expect("frame")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
