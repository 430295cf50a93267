//! Stereo matching (`stereo::KittiStereoMatcher`) on one synthetic KITTI-sized pair
//! (1241 × 376, ORB-SLAM2's KITTI settings: 2000 features, `bf` 386.1 px·m).
//!
//! The right image is the left one shifted by a disparity that grows down the frame (5 px at
//! the top to 51 px at the bottom, like a road plane), so matches exist at every row. The ORB
//! extraction of both images is done once, outside the timed loop; its time is printed as the
//! reference the matcher's time is a fraction of (measured in the same run).

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

const W: usize = 1241;
const H: usize = 376;

static LEFT: Mutex<KittiOrbExtractor> = Mutex::new(KittiOrbExtractor::new());
static RIGHT: Mutex<KittiOrbExtractor> = Mutex::new(KittiOrbExtractor::new());
static MATCHER: Mutex<KittiStereoMatcher> = Mutex::new(KittiStereoMatcher::new());

fn xorshift(s: &mut u32, n: u32) -> u32 {
    *s ^= *s << 13;
    *s ^= *s >> 17;
    *s ^= *s << 5;
    *s % n
}

/// Value noise on a 6-px grid under random rectangles, 3×3 box blurred.
fn texture(w: usize, h: usize) -> Vec<u8> {
    let mut s = 0x2545_f491u32;
    let (gw, gh, c) = (w / 6 + 2, h / 6 + 2, 6u32);
    let grid: Vec<u32> = (0..gw * gh).map(|_| xorshift(&mut s, 256)).collect();
    let mut img = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let (gx, gy, fx, fy) = (x / 6, y / 6, (x % 6) as u32, (y % 6) as u32);
            let g = |i: usize, j: usize| grid[(gy + j) * gw + gx + i];
            let top = g(0, 0) * (c - fx) + g(1, 0) * fx;
            let bot = g(0, 1) * (c - fx) + g(1, 1) * fx;
            img[y * w + x] = ((top * (c - fy) + bot * fy) / (c * c)) as u8;
        }
    }
    for _ in 0..w * h / 400 {
        let (rw, rh) = (3 + xorshift(&mut s, 30) as usize, 3 + xorshift(&mut s, 30) as usize);
        let (x0, y0) = (xorshift(&mut s, w as u32) as usize, xorshift(&mut s, h as u32) as usize);
        let v = xorshift(&mut s, 256) as u16;
        for y in y0..(y0 + rh).min(h) {
            for p in &mut img[y * w + x0..y * w + (x0 + rw).min(w)] {
                *p = ((u16::from(*p) + 3 * v) / 4) as u8;
            }
        }
    }
    let src = img.clone();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let mut acc = 0u32;
            for dy in 0..3 {
                for dx in 0..3 {
                    acc += u32::from(src[(y + dy - 1) * w + x + dx - 1]);
                }
            }
            img[y * w + x] = (acc / 9) as u8;
        }
    }
    img
}

/// `right(x, y) = left(x + d(y), y)`, `d(y) = 5 + y / 8`.
fn pair() -> (Vec<u8>, Vec<u8>) {
    let tw = W + 64;
    let t = texture(tw, H);
    let (mut l, mut r) = (vec![0u8; W * H], vec![0u8; W * H]);
    for y in 0..H {
        let d = 5 + y / 8;
        l[y * W..(y + 1) * W].copy_from_slice(&t[y * tw..y * tw + W]);
        r[y * W..(y + 1) * W].copy_from_slice(&t[y * tw + d..y * tw + d + W]);
    }
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

    c.bench_function(&format!("stereo_match_{W}x{H}_synthetic"), |b| {
        b.iter(|| {
            black_box(
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
                    .matched,
            )
        })
    });
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
