//! Local bundle adjustment (`optim::bundle_adjust`) on a KITTI-like window: 24 keyframes 1 m
//! apart along a straight road, 3000 points 8–48 m ahead, each seen by a run of 4–16
//! consecutive keyframes (at most `MAX_OBS` = 16, as a landmark keeps), 5 Levenberg-Marquardt
//! iterations (`tracker.ba_iterations`), from poses and points perturbed as tracking leaves
//! them.
//!
//! Two rows in the same run: 15 keyframes optimised and 9 fixed (the default,
//! `tracker.ba_keyframes = 15`) and 20 optimised and 4 fixed (`ba_keyframes = 20`); the second's
//! time is read as a ratio to the first. On x86-64 a third row runs the default window with the
//! instruction set capped at the baseline (`set_max_isa(Portable)`: SSE2 only), the reference
//! for the reduced system and back-substitution that run through `arch::v3` (AVX2 lanes, the
//! same bits).

// `criterion_group!` expands to an undocumented `pub fn`.
#![allow(missing_docs)]

use core::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Matrix3, Vector3, Vector6};
use semloc_core::geom::{Se3, StereoCamera};
use semloc_core::optim::{bundle_adjust, BaObs, BaParams, BaScratch, Measurement};
use semloc_core::testing::{kitti_cam, Rng};

const KEYFRAMES: usize = 24;
const POINTS: usize = 3000;

struct Window {
    poses: Vec<Se3>,
    points: Vec<Vector3<f64>>,
    obs: Vec<BaObs>,
}

fn measure(cam: &StereoCamera, t_cw: &Se3, p: &Vector3<f64>) -> Option<Measurement> {
    let pc = t_cw.transform_point(p);
    if pc.z < 1.0 {
        return None;
    }
    let u = cam.fx_px * pc.x / pc.z + cam.cx_px;
    let v = cam.fy_px * pc.y / pc.z + cam.cy_px;
    if !(0.0..1241.0).contains(&u) || !(0.0..376.0).contains(&v) {
        return None;
    }
    Some(Measurement { u, v, ur: u - cam.fx_px * cam.baseline_m / pc.z, inv_sigma2: 1.0 })
}

/// The window in BA order: keyframe 0 is the oldest; `bundle_adjust` holds the first `fixed`.
fn window(cam: &StereoCamera) -> Window {
    let mut rng = Rng::new(0x0ba0_5eed);
    let truth: Vec<Se3> = (0..KEYFRAMES)
        .map(|k| Se3::new(Matrix3::identity(), Vector3::new(0.0, 0.0, -(k as f64))))
        .collect();
    let mut points = Vec::with_capacity(POINTS);
    let mut obs = Vec::new();
    while points.len() < POINTS {
        let first = rng.below(KEYFRAMES);
        let len = rng.int(4, 16) as usize;
        let z = first as f64 + rng.range(8.0, 48.0);
        let p = Vector3::new(rng.signed() * 15.0, rng.range(-3.0, 1.6), z);
        let i = points.len() as u32;
        let seen: Vec<BaObs> = (first..(first + len).min(KEYFRAMES))
            .filter_map(|k| {
                let mut z = measure(cam, &truth[k], &p)?;
                z.u += rng.signed() * 0.5;
                z.v += rng.signed() * 0.5;
                z.ur += rng.signed() * 0.5;
                Some(BaObs { kf: k as u8, point: i, z, weight: 1.0 })
            })
            .collect();
        if seen.len() >= 2 {
            obs.extend(seen);
            points.push(p + Vector3::new(rng.signed(), rng.signed(), rng.signed()) * 0.05);
        }
    }
    let poses = truth
        .iter()
        .map(|t| {
            t.retract(&Vector6::new(
                rng.signed() * 0.02,
                rng.signed() * 0.02,
                rng.signed() * 0.02,
                rng.signed() * 0.001,
                rng.signed() * 0.001,
                rng.signed() * 0.001,
            ))
        })
        .collect();
    Window { poses, points, obs }
}

fn bench(c: &mut Criterion) {
    let cam = kitti_cam();
    let w = window(&cam);
    println!(
        "local BA window: {} keyframes, {} points, {} observations",
        w.poses.len(),
        w.points.len(),
        w.obs.len()
    );
    let params = BaParams { iterations: 5, robust: true };
    let mut scratch = Box::new(BaScratch::new());
    let mut backup = vec![Vector3::zeros(); w.points.len()];
    let mut group = c.benchmark_group("local_ba");
    group.sample_size(20);
    #[cfg(target_arch = "x86_64")]
    let rows = [(15usize, ""), (20, ""), (15, "_baseline_isa")];
    #[cfg(not(target_arch = "x86_64"))]
    let rows = [(15usize, ""), (20, "")];
    for (optimised, tag) in rows {
        let fixed = KEYFRAMES - optimised;
        #[cfg(target_arch = "x86_64")]
        {
            use semloc_core::nn::x86::{set_max_isa, Isa};
            set_max_isa(if tag.is_empty() { Isa::Avx512Vnni } else { Isa::Portable });
        }
        group.bench_function(format!("{optimised}_optimised_{fixed}_fixed{tag}"), |b| {
            b.iter(|| {
                let mut poses = w.poses.clone();
                let mut points = w.points.clone();
                let rep = bundle_adjust(
                    &cam,
                    &mut poses,
                    fixed,
                    &mut points,
                    &w.obs,
                    &mut backup,
                    &mut scratch,
                    &params,
                )
                .expect("valid window");
                black_box((rep, poses, points))
            });
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default();
    targets = bench
}
criterion_main!(benches);
