//! Stereo matching (`stereo::KittiStereoMatcher`) on one synthetic KITTI-sized pair
//! (1241 × 376, ORB-SLAM2's KITTI settings: 2000 features, `bf` 386.1 px·m).
//!
//! The right image is the left one shifted by a disparity that grows down the frame (5 px at
//! the top to 51 px at the bottom, like a road plane), so matches exist at every row. The ORB
//! extraction of both images is done once, outside the timed loop; its time is printed as the
//! reference the matcher's time is a fraction of (measured in the same run). On x86-64 a
//! second matcher row runs with the instruction set capped at the baseline (SSE2 only,
//! `set_max_isa(Portable)`): the reference for the SAD refinement that runs through `arch::v3`.

// `criterion_group!` expands to an undocumented `pub fn`.
#![allow(missing_docs)]

use core::hint::black_box;
use std::sync::Mutex;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion};
use semloc_core::frame::Frame;
use semloc_core::image::ImageView;
use semloc_core::orb::{KittiOrbExtractor, OrbConfig};
use semloc_core::stereo::{KittiStereoMatcher, StereoParams};
use semloc_core::testing;

const W: usize = 1241;
const H: usize = 376;

static LEFT: Mutex<KittiOrbExtractor> = Mutex::new(KittiOrbExtractor::new());
static RIGHT: Mutex<KittiOrbExtractor> = Mutex::new(KittiOrbExtractor::new());
static MATCHER: Mutex<KittiStereoMatcher> = Mutex::new(KittiStereoMatcher::new());

/// Value noise on a 6-px grid under random rectangles, blurred; `right(x, y) = left(x + d(y),
/// y)`, `d(y) = 5 + y / 8`.
fn pair() -> (Vec<u8>, Vec<u8>) {
    let tw = W + 64;
    let mut t = vec![0u8; tw * H];
    testing::value_noise_texture(&mut t, tw, H, 0x2545_f491, &[6]);
    let (mut l, mut r) = (vec![0u8; W * H], vec![0u8; W * H]);
    testing::stereo_pair(&t, tw, &mut l, &mut r, W, |y| 5 + y / 8);
    (l, r)
}

fn bench(c: &mut Criterion) {
    let (l, r) = pair();
    let (lv, rv) = (
        ImageView::from_slice(&l, W, H).expect("left"),
        ImageView::from_slice(&r, W, H).expect("right"),
    );
    let mut el = LEFT.lock().expect("left extractor");
    let mut er = RIGHT.lock().expect("right extractor");
    el.configure(OrbConfig::KITTI).expect("config");
    er.configure(OrbConfig::KITTI).expect("config");
    let t0 = Instant::now();
    el.extract(&lv).expect("extract left");
    let t_orb = t0.elapsed();
    er.extract(&rv).expect("extract right");

    let params = StereoParams::KITTI_00_02;
    let mut matcher = MATCHER.lock().expect("matcher");
    let mut out = Box::new(Frame::new());
    let t0 = Instant::now();
    let stats = matcher
        .match_frame(
            el.features(),
            el.pyramid(),
            er.features(),
            er.pyramid(),
            &params,
            0.0,
            &mut out,
        )
        .expect("match");
    let t_match = t0.elapsed();
    println!("synthetic pair {W}x{H}: {stats:?}");
    println!(
        "one-shot: ORB extract (one image) {:.2} ms, stereo match {:.3} ms ({:.1} % of one extraction)",
        t_orb.as_secs_f64() * 1e3,
        t_match.as_secs_f64() * 1e3,
        100.0 * t_match.as_secs_f64() / t_orb.as_secs_f64()
    );

    let mut match_once = || {
        matcher
            .match_frame(
                el.features(),
                el.pyramid(),
                er.features(),
                er.pyramid(),
                black_box(&params),
                0.0,
                &mut out,
            )
            .expect("match")
            .matched
    };
    c.bench_function(&format!("stereo_match_{W}x{H}_synthetic"), |b| {
        b.iter(|| black_box(match_once()))
    });
    #[cfg(target_arch = "x86_64")]
    {
        use semloc_core::nn::x86::{set_max_isa, Isa};
        set_max_isa(Isa::Portable);
        c.bench_function(&format!("stereo_match_{W}x{H}_synthetic_baseline_isa"), |b| {
            b.iter(|| black_box(match_once()))
        });
        set_max_isa(Isa::Avx512Vnni);
    }
    c.bench_function(&format!("orb_extract_{W}x{H}_reference"), |b| {
        b.iter(|| black_box(el.extract(black_box(&lv)).expect("extract").len()))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
