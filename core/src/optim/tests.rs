use super::*;
use crate::testing::{kitti_cam, Rng};

fn world_points(rng: &mut Rng, n: usize) -> Vec<Vector3<f64>> {
    (0..n)
        .map(|_| {
            Vector3::new(rng.signed() * 15.0, rng.signed() * 3.0, 8.0 + (rng.signed() + 1.0) * 20.0)
        })
        .collect()
}

fn measure(cam: &StereoCamera, t_cw: &Se3, p: &Vector3<f64>) -> Measurement {
    let pc = t_cw.transform_point(p);
    let u = cam.fx_px * pc.x / pc.z + cam.cx_px;
    let v = cam.fy_px * pc.y / pc.z + cam.cy_px;
    Measurement { u, v, ur: u - cam.fx_px * cam.baseline_m / pc.z, inv_sigma2: 1.0 }
}

/// Five keyframes driving forward 1 m each, and `n` points ahead of them; every keyframe
/// measures every point `repeat` times, each with weight `1 / repeat`.
fn forward_window(
    rng: &mut Rng,
    cam: &StereoCamera,
    n: usize,
    repeat: usize,
) -> (Vec<Se3>, Vec<Vector3<f64>>, Vec<BaObs>) {
    let truth: Vec<Se3> = (0..5)
        .map(|k| Se3::new(Matrix3::identity(), Vector3::new(0.0, 0.0, -(k as f64))))
        .collect();
    let pts_true = world_points(rng, n);
    let mut obs = Vec::new();
    for (i, p) in pts_true.iter().enumerate() {
        for (k, t) in truth.iter().enumerate() {
            let z = measure(cam, t, p);
            for _ in 0..repeat {
                obs.push(BaObs { kf: k as u8, point: i as u32, z, weight: 1.0 / repeat as f64 });
            }
        }
    }
    (truth, pts_true, obs)
}

fn pose(rng: &mut Rng, rot: f64, trans: f64) -> Se3 {
    let d = Vector6::new(
        rng.signed() * trans,
        rng.signed() * trans,
        rng.signed() * trans,
        rng.signed() * rot,
        rng.signed() * rot,
        rng.signed() * rot,
    );
    Se3::identity().retract(&d)
}

fn pose_err(a: &Se3, b: &Se3) -> (f64, f64) {
    let e = a.inverse().compose(b);
    let c = ((e.rot.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
    (e.trans.norm(), c.acos())
}

#[test]
fn cholesky_solves_spd_system() {
    let m = SMatrix::<f64, 3, 3>::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0);
    let x = Vector3::new(1.0, -2.0, 0.5);
    let mut b = m * x;
    let mut a = m;
    assert!(cholesky_solve_in_place(a.as_mut_slice(), 3, 3, b.as_mut_slice()));
    assert!((b - x).norm() < 1e-12, "{b}");
    let mut neg = -m;
    let mut b2 = x;
    assert!(!cholesky_solve_in_place(neg.as_mut_slice(), 3, 3, b2.as_mut_slice()));
}

#[test]
fn pose_optimisation_recovers_pose_and_rejects_outliers() {
    let mut rng = Rng::new(0x9e3779b97f4a7c15);
    let cam = kitti_cam();
    let truth = pose(&mut rng, 0.05, 0.5);
    let pts = world_points(&mut rng, 300);
    let mut obs: Vec<PoseObs> =
        pts.iter().map(|p| PoseObs { p_w: *p, z: measure(&cam, &truth, p), weight: 1.0 }).collect();
    // Every 5th observation is a gross mismatch (40 px off).
    for o in obs.iter_mut().step_by(5) {
        o.z.u += 40.0;
        o.z.ur += 40.0;
    }
    let mut est = truth.retract(&Vector6::new(0.3, -0.2, 0.5, 0.02, -0.01, 0.03));
    let mut outlier = vec![false; obs.len()];
    let rep = optimize_pose(&cam, &mut est, &obs, &mut outlier, &PoseOptParams::default());
    let (dt, dr) = pose_err(&truth, &est);
    assert!(dt < 1e-6 && dr < 1e-8, "dt {dt} dr {dr}");
    assert_eq!(rep.inliers, 240);
    for (i, out) in outlier.iter().enumerate() {
        assert_eq!(*out, i % 5 == 0, "obs {i}");
    }
}

#[test]
fn zero_weight_observations_do_not_count() {
    let mut rng = Rng::new(7);
    let cam = kitti_cam();
    let truth = Se3::identity();
    let pts = world_points(&mut rng, 50);
    let mut obs: Vec<PoseObs> =
        pts.iter().map(|p| PoseObs { p_w: *p, z: measure(&cam, &truth, p), weight: 1.0 }).collect();
    // Corrupt half of them but give them no weight: the pose must stay exact.
    for o in obs.iter_mut().take(25) {
        o.z.u += 100.0;
        o.weight = 0.0;
    }
    let mut est = truth.retract(&Vector6::new(0.1, 0.0, 0.0, 0.0, 0.01, 0.0));
    let mut outlier = vec![false; obs.len()];
    let rep = optimize_pose(&cam, &mut est, &obs, &mut outlier, &PoseOptParams::default());
    assert_eq!(rep.inliers, 25);
    assert!(pose_err(&truth, &est).0 < 1e-6);
}

#[test]
fn bundle_adjustment_converges_from_perturbed_window() {
    let mut rng = Rng::new(0x1234_5678_9abc_def1);
    let cam = kitti_cam();
    let (truth, pts_true, obs) = forward_window(&mut rng, &cam, 200, 1);
    let mut poses = truth.clone();
    for p in poses.iter_mut().skip(1) {
        *p = p.retract(&Vector6::new(
            rng.signed() * 0.1,
            rng.signed() * 0.1,
            rng.signed() * 0.1,
            rng.signed() * 0.005,
            rng.signed() * 0.005,
            rng.signed() * 0.005,
        ));
    }
    let mut pts: Vec<Vector3<f64>> = pts_true
        .iter()
        .map(|p| p + Vector3::new(rng.signed(), rng.signed(), rng.signed()) * 0.05)
        .collect();
    let mut backup = vec![Vector3::zeros(); pts.len()];
    let mut scratch = Box::new(BaScratch::new());
    let params = BaParams { iterations: 20, robust: true };
    let rep =
        bundle_adjust(&cam, &mut poses, 1, &mut pts, &obs, &mut backup, &mut scratch, &params)
            .unwrap();
    assert!(rep.final_cost < 1e-9 * rep.initial_cost.max(1.0), "{rep:?}");
    for (t, e) in truth.iter().zip(&poses) {
        let (dt, dr) = pose_err(t, e);
        assert!(dt < 1e-5 && dr < 1e-7, "dt {dt} dr {dr}");
    }
    for (t, e) in pts_true.iter().zip(&pts) {
        assert!((t - e).norm() < 1e-4);
    }
}

#[test]
fn bundle_adjustment_is_the_same_bits_at_every_instruction_set_level() {
    // The reduced system and the back-substitution run through `arch::v3`: noisy measurements
    // and perturbed starts, three iterations, and every pose and point must carry the same bits
    // at every level this CPU has (the baseline build's included).
    let mut rng = Rng::new(0x0bad_cafe_f00d_0001);
    let cam = kitti_cam();
    let (truth, pts_true, mut obs) = forward_window(&mut rng, &cam, 150, 1);
    for o in &mut obs {
        o.z.u += rng.signed() * 0.7;
        o.z.v += rng.signed() * 0.7;
        o.z.ur += rng.signed() * 0.7;
    }
    let start: Vec<Se3> =
        truth.iter().map(|t| t.retract(&(pose(&mut rng, 0.004, 0.08).log()))).collect();
    let pts0: Vec<Vector3<f64>> = pts_true
        .iter()
        .map(|p| p + Vector3::new(rng.signed(), rng.signed(), rng.signed()) * 0.1)
        .collect();
    let mut runs = Vec::new();
    crate::nn::dispatch::for_each_level(|level| {
        let (mut poses, mut pts) = (start.clone(), pts0.clone());
        let mut backup = vec![Vector3::zeros(); pts.len()];
        let mut scratch = Box::new(BaScratch::new());
        let params = BaParams { iterations: 3, robust: true };
        let rep =
            bundle_adjust(&cam, &mut poses, 2, &mut pts, &obs, &mut backup, &mut scratch, &params)
                .unwrap();
        let bits: Vec<u64> = poses
            .iter()
            .flat_map(|p| p.rot.iter().chain(p.trans.iter()).copied().collect::<Vec<_>>())
            .chain(pts.iter().flat_map(|p| p.iter().copied().collect::<Vec<_>>()))
            .chain([rep.initial_cost, rep.final_cost])
            .map(f64::to_bits)
            .collect();
        runs.push((level, bits, poses[4].trans != start[4].trans));
    });
    assert!(!runs.is_empty());
    for (level, bits, moved) in &runs {
        assert!(*moved, "{level}: the optimised poses did not move");
        assert_eq!(bits, &runs[0].1, "{level} differs from {}", runs[0].0);
    }
}

#[test]
fn bundle_adjustment_rejects_malformed_problems() {
    let cam = kitti_cam();
    let mut poses = vec![Se3::identity(); 2];
    let mut pts = vec![Vector3::new(0.0, 0.0, 10.0); 2];
    let mut backup = vec![Vector3::zeros(); 2];
    let mut scratch = Box::new(BaScratch::new());
    let z = Measurement { u: 600.0, v: 180.0, ur: 560.0, inv_sigma2: 1.0 };
    let o = |kf: u8, point: u32| BaObs { kf, point, z, weight: 1.0 };
    let p = BaParams::default();
    let bad = [o(0, 0), o(2, 1)];
    assert_eq!(
        bundle_adjust(&cam, &mut poses, 1, &mut pts, &bad, &mut backup, &mut scratch, &p),
        Err(BaError::BadIndex { obs: 1 })
    );
    let ungrouped = [o(0, 1), o(0, 0)];
    assert_eq!(
        bundle_adjust(&cam, &mut poses, 1, &mut pts, &ungrouped, &mut backup, &mut scratch, &p),
        Err(BaError::NotGrouped { obs: 1 })
    );
    let mut many = vec![Se3::identity(); MAX_WINDOW + 1];
    assert_eq!(
        bundle_adjust(&cam, &mut many, 1, &mut pts, &[], &mut backup, &mut scratch, &p),
        Err(BaError::TooManyPoses { got: MAX_WINDOW + 1 })
    );
}

/// Back-substitution reuses each observation's linearisation when a point's observations fit
/// the window, and linearises the rest again when a caller gives more (one pose's measurement
/// repeated): both paths must solve the problem the single observations pose.
#[test]
fn repeated_observations_solve_like_single_ones() {
    let cam = kitti_cam();
    let solve = |repeat: usize| {
        let mut rng = Rng::new(0x0bad_5eed_0000_0042);
        let (truth, pts_true, obs) = forward_window(&mut rng, &cam, 100, repeat);
        let mut poses = truth.clone();
        for p in poses.iter_mut().skip(1) {
            *p = p.retract(&(Vector6::new(1.0, -0.5, 0.3, 2e-3, -1e-3, 4e-3) * rng.signed()));
        }
        let mut pts: Vec<Vector3<f64>> =
            pts_true.iter().map(|p| p + Vector3::new(0.05, -0.03, 0.2) * rng.signed()).collect();
        let mut backup = vec![Vector3::zeros(); pts.len()];
        let mut scratch = Box::new(BaScratch::new());
        let params = BaParams { iterations: 3, robust: true };
        let rep =
            bundle_adjust(&cam, &mut poses, 1, &mut pts, &obs, &mut backup, &mut scratch, &params)
                .unwrap();
        assert!(rep.final_cost < rep.initial_cost, "{rep:?}");
        (poses, pts)
    };
    // 1: groups of 5; 4: 20, within the window; 6: 30, past it.
    let (p1, l1) = solve(1);
    for repeat in [4, 6] {
        let (p, l) = solve(repeat);
        for (a, b) in p1.iter().zip(&p) {
            // Matrix entries, not `pose_err`'s angle: acos resolves nothing under ~2e-8 rad.
            let (dt, dr) = ((a.trans - b.trans).norm(), (a.rot - b.rot).norm());
            assert!(dt < 1e-9 && dr < 1e-11, "x{repeat}: dt {dt} dr {dr}");
        }
        for (a, b) in l1.iter().zip(&l) {
            assert!((a - b).norm() < 1e-8, "x{repeat}: {a} {b}");
        }
    }
}
