use super::*;
use core::f64::consts::PI;
use nalgebra::{SMatrix, SVector};
use proptest::prelude::*;

use crate::testing::asymmetric_cam;

/// Per-entry check `|a - b| <= tol * max(1, max|b|)`.
fn assert_close<const R: usize, const C: usize>(
    a: &SMatrix<f64, R, C>,
    b: &SMatrix<f64, R, C>,
    tol: f64,
    what: &str,
) {
    let scale = b.iter().fold(1.0f64, |m, x| m.max(x.abs()));
    let err = a.iter().zip(b.iter()).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    assert!(err <= tol * scale, "{what}: err {err:e} > {tol:e}·{scale}\n a = {a}\n b = {b}");
}

/// Central finite-difference Jacobian of `f` at `x`.
fn fd_jacobian<const N: usize, const M: usize>(
    f: impl Fn(&SVector<f64, N>) -> SVector<f64, M>,
    x: &SVector<f64, N>,
    h: f64,
) -> SMatrix<f64, M, N> {
    let mut j = SMatrix::<f64, M, N>::zeros();
    for i in 0..N {
        let mut xp = *x;
        let mut xm = *x;
        xp[i] += h;
        xm[i] -= h;
        j.set_column(i, &((f(&xp) - f(&xm)) / (2.0 * h)));
    }
    j
}

fn is_rotation(r: &Matrix3<f64>, tol: f64) -> bool {
    (r.transpose() * r - Matrix3::identity()).amax() <= tol && (r.determinant() - 1.0).abs() <= tol
}

fn vec3(r: f64) -> impl Strategy<Value = Vector3<f64>> {
    (-r..r, -r..r, -r..r).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

fn unit3() -> impl Strategy<Value = Vector3<f64>> {
    vec3(1.0).prop_filter("direction", |v| v.norm() > 0.1).prop_map(|v| v / v.norm())
}

/// Rotation vectors with angle uniform in `[0, max_angle)`.
fn rotvec(max_angle: f64) -> impl Strategy<Value = Vector3<f64>> {
    (unit3(), 0.0..max_angle).prop_map(|(n, a)| n * a)
}

/// Rotation vectors with angle `π - 10^-k`, k in [1, 12].
fn rotvec_near_pi() -> impl Strategy<Value = Vector3<f64>> {
    (unit3(), 1.0..12.0f64).prop_map(|(n, k)| n * (PI - 10f64.powf(-k)))
}

/// Rotation vectors with angle `10^-k`, k in [0, 15].
fn rotvec_near_zero() -> impl Strategy<Value = Vector3<f64>> {
    (unit3(), 0.0..15.0f64).prop_map(|(n, k)| n * 10f64.powf(-k))
}

fn pose() -> impl Strategy<Value = Se3> {
    (rotvec(PI), vec3(20.0)).prop_map(|(w, t)| Se3::new(so3_exp(&w), t))
}

fn twist(rot: impl Strategy<Value = Vector3<f64>>) -> impl Strategy<Value = Vector6<f64>> {
    (vec3(10.0), rot).prop_map(|(rho, phi)| Vector6::new(rho.x, rho.y, rho.z, phi.x, phi.y, phi.z))
}

/// A camera-frame point comfortably in front of the camera.
fn p_cam() -> impl Strategy<Value = Vector3<f64>> {
    (-20.0..20.0f64, -5.0..5.0f64, 1.0..60.0f64).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

#[test]
fn skew_and_vee() {
    let a = Vector3::new(0.3, -1.2, 2.0);
    let b = Vector3::new(-0.7, 0.1, 0.4);
    assert_close(&(skew(&a) * b), &a.cross(&b), 1e-15, "skew is cross");
    assert_eq!(vee(&skew(&a)), a);
}

#[test]
fn so3_exp_known_values() {
    assert_eq!(so3_exp(&Vector3::zeros()), Matrix3::identity());
    let rz = so3_exp(&Vector3::new(0.0, 0.0, PI / 2.0));
    assert_close(&(rz * Vector3::x()), &Vector3::y(), 1e-15, "Rz(90°) x = y");
    assert_close(&(rz * Vector3::y()), &-Vector3::x(), 1e-15, "Rz(90°) y = -x");
    let rx = so3_exp(&Vector3::new(PI, 0.0, 0.0));
    assert_close(&rx, &Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0)), 1e-15, "Rx(π)");
}

#[test]
fn so3_log_exactly_pi() {
    for axis in [
        Vector3::x(),
        Vector3::y(),
        Vector3::z(),
        Vector3::new(1.0, 1.0, 0.0) / 2f64.sqrt(),
        Vector3::new(-1.0, 2.0, 3.0) / 14f64.sqrt(),
    ] {
        let r = so3_exp(&(axis * PI));
        let w = so3_log(&r);
        assert!((w.norm() - PI).abs() < 1e-14, "|w| = {}", w.norm());
        // Both ±π n are valid at π; the axis must match up to sign.
        assert!((w.normalize().dot(&axis).abs() - 1.0).abs() < 1e-14, "axis {w} vs {axis}");
        assert_close(&so3_exp(&w), &r, 1e-14, "exp(log(R)) at π");
    }
    // The exact matrix diag(1, -1, -1), not produced by exp.
    let w = so3_log(&Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0)));
    assert_close(&w.abs(), &Vector3::new(PI, 0.0, 0.0), 1e-15, "log diag(1,-1,-1)");
}

#[test]
fn so3_log_identity_is_zero() {
    assert_eq!(so3_log(&Matrix3::identity()), Vector3::zeros());
    assert_eq!(Se3::identity().log(), Vector6::zeros());
}

#[test]
fn se3_exp_known_values() {
    let t = Se3::exp(&Vector6::new(1.0, 2.0, 3.0, 0.0, 0.0, 0.0));
    assert_eq!(t.rot, Matrix3::identity());
    assert_eq!(t.trans, Vector3::new(1.0, 2.0, 3.0));
    // Screw motion: rho = x, quarter turn about z. t = ∫ Rz(sθ) x ds = (2/π, 2/π, 0).
    let t = Se3::exp(&Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, PI / 2.0));
    assert_close(&t.trans, &Vector3::new(2.0 / PI, 2.0 / PI, 0.0), 1e-15, "screw");
    assert!((t.rotation_angle() - PI / 2.0).abs() < 1e-15);
    assert!((t.translation_norm() - 8f64.sqrt() / PI).abs() < 1e-15);
}

#[test]
fn retract_is_left_multiplicative() {
    let t = Se3::new(so3_exp(&Vector3::new(0.1, -0.4, 0.3)), Vector3::new(1.0, 2.0, -3.0));
    let d = Vector6::new(0.2, 0.0, -0.1, 0.0, 0.3, 0.0);
    let p = Vector3::new(0.5, -0.5, 4.0);
    let want = Se3::exp(&d).transform_point(&t.transform_point(&p));
    assert_close(&t.retract(&d).transform_point(&p), &want, 1e-14, "retract");
    // And not right-multiplicative: the two differ for this non-trivial pose.
    let right = t.compose(&Se3::exp(&d)).transform_point(&p);
    assert!((right - want).norm() > 1e-2);
    assert_eq!(t.retract(&Vector6::zeros()), t.compose(&Se3::identity()));
}

#[test]
fn normalized_repairs_drift_and_rejects_degenerate() {
    let r = so3_exp(&Vector3::new(0.3, 1.1, -0.7));
    let t = Vector3::new(1.0, 2.0, 3.0);
    // Symmetric stretch: the nearest rotation of R(I + εS), S symmetric, is exactly R, which
    // Gram-Schmidt would not give.
    let s = Matrix3::new(1.0, 0.3, -0.2, 0.3, -0.5, 0.7, -0.2, 0.7, 0.9);
    let drifted = Se3::new(r * (Matrix3::identity() + s * 1e-4), t);
    assert!(!is_rotation(&drifted.rot, 1e-6));
    let fixed = drifted.normalized().unwrap();
    assert!(is_rotation(&fixed.rot, 1e-15));
    assert_close(&fixed.rot, &r, 1e-14, "nearest rotation");
    assert_eq!(fixed.trans, t);
    // Far from orthonormal still converges.
    let far = Se3::new(r * (Matrix3::identity() + s * 0.3) * 2.5, t).normalized().unwrap();
    assert_close(&far.rot, &r, 1e-14, "nearest rotation, large stretch");
    // Exact rotations are fixed points.
    let exact = Se3::new(r, t);
    assert_close(&exact.normalized().unwrap().rot, &r, 1e-15, "fixed point");
    for bad in [
        Matrix3::zeros(),
        Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0)),
        Matrix3::from_element(f64::NAN),
        Matrix3::identity() * f64::INFINITY,
    ] {
        assert_eq!(Se3::new(bad, t).normalized(), Err(GeomError::DegenerateRotation));
    }
}

#[test]
fn camera_new_validates() {
    assert!(StereoCamera::new(718.856, 718.856, 607.19, 185.22, 0.537).is_ok());
    let cases = [
        ((f64::NAN, 1.0, 0.0, 0.0, 0.5), "fx_px"),
        ((1.0, 0.0, 0.0, 0.0, 0.5), "fy_px"),
        ((1.0, -1.0, 0.0, 0.0, 0.5), "fy_px"),
        ((1.0, 1.0, f64::INFINITY, 0.0, 0.5), "cx_px"),
        ((1.0, 1.0, 0.0, f64::NAN, 0.5), "cy_px"),
        ((1.0, 1.0, 0.0, 0.0, 0.0), "baseline_m"),
        ((1.0, 1.0, 0.0, 0.0, f64::INFINITY), "baseline_m"),
    ];
    for ((fx, fy, cx, cy, b), field) in cases {
        let e = StereoCamera::new(fx, fy, cx, cy, b).unwrap_err();
        assert_eq!(e, GeomError::InvalidCamera { field });
        assert!(e.to_string().contains(field));
    }
    fn is_error<E: core::error::Error + Copy>(_: E) {}
    is_error(GeomError::DegenerateRotation);
}

#[test]
fn projection_known_values_and_rejects_behind() {
    let c = asymmetric_cam();
    let uv = c.project(&Vector3::new(1.0, -2.0, 10.0)).unwrap();
    assert_close(&uv, &Vector2::new(718.0 * 0.1 + 607.2, 702.0 * -0.2 + 185.2), 1e-12, "uv");
    let uvr = c.project_stereo(&Vector3::new(1.0, -2.0, 10.0)).unwrap();
    assert!((uvr.z - (uv.x - 718.0 * 0.537 / 10.0)).abs() < 1e-12);
    assert_eq!(c.bf(), 718.0 * 0.537);
    for z in [0.0, -1.0, MIN_DEPTH_M, f64::NAN] {
        let p = Vector3::new(0.1, 0.2, z);
        assert!(c.project(&p).is_none(), "z = {z}");
        assert!(c.project_stereo(&p).is_none());
        assert!(c.project_jacobian(&p).is_none());
        assert!(c.project_stereo_jacobian(&p).is_none());
    }
    // Behind the camera after the pose is applied.
    let t_cw = Se3::new(Matrix3::identity(), Vector3::new(0.0, 0.0, -20.0));
    assert!(c.project_world(&t_cw, &Vector3::new(0.0, 0.0, 10.0)).is_none());
    assert!(c.pose_jacobian(&t_cw, &Vector3::new(0.0, 0.0, 10.0)).is_none());
    assert_eq!(c.depth_from_disparity(0.0), None);
    assert_eq!(c.depth_from_disparity(-3.0), None);
    assert_eq!(c.depth_from_disparity(f64::NAN), None);
    assert_eq!(c.depth_from_disparity(c.bf() / 7.0), Some(7.0));
}

proptest! {
    #[test]
    fn so3_round_trip(w in rotvec(PI - 1e-6)) {
        let r = so3_exp(&w);
        prop_assert!(is_rotation(&r, 1e-14));
        assert_close(&so3_log(&r), &w, 1e-12, "log(exp(w))");
        prop_assert!((so3_angle(&r) - w.norm()).abs() < 1e-12);
    }

    #[test]
    fn so3_round_trip_near_pi(w in rotvec_near_pi()) {
        let r = so3_exp(&w);
        assert_close(&so3_log(&r), &w, 1e-12, "log(exp(w)) near π");
        assert_close(&so3_exp(&so3_log(&r)), &r, 1e-14, "exp(log(R)) near π");
    }

    #[test]
    fn so3_round_trip_near_zero(w in rotvec_near_zero()) {
        let back = so3_log(&so3_exp(&w));
        // Relative to |w| itself: the small-angle branches must not lose digits.
        prop_assert!((back - w).norm() <= 1e-14 * w.norm(), "{back} vs {w}");
        prop_assert!((so3_angle(&so3_exp(&w)) - w.norm()).abs() <= 1e-14 * w.norm());
    }

    #[test]
    fn so3_jacobians_match_finite_differences(
        phi in prop_oneof![rotvec(3.0), rotvec(2e-3)],
    ) {
        let r = so3_exp(&phi);
        let rt = r.transpose();
        let jl_fd = fd_jacobian(|p: &Vector3<f64>| so3_log(&(so3_exp(p) * rt)), &phi, 1e-6);
        let jr_fd = fd_jacobian(|p: &Vector3<f64>| so3_log(&(rt * so3_exp(p))), &phi, 1e-6);
        assert_close(&so3_left_jacobian(&phi), &jl_fd, 1e-6, "J_l");
        assert_close(&so3_right_jacobian(&phi), &jr_fd, 1e-6, "J_r");
        let id = Matrix3::identity();
        let jl = so3_left_jacobian_inv(&phi) * so3_left_jacobian(&phi);
        assert_close(&jl, &id, 1e-12, "J_l⁻¹ J_l");
        let jr = so3_right_jacobian_inv(&phi) * so3_right_jacobian(&phi);
        assert_close(&jr, &id, 1e-12, "J_r⁻¹ J_r");
    }

    #[test]
    fn se3_round_trip(
        xi in prop_oneof![
            twist(rotvec(PI - 1e-6)),
            twist(rotvec_near_pi()),
            twist(rotvec_near_zero()),
        ],
    ) {
        let t = Se3::exp(&xi);
        prop_assert!(is_rotation(&t.rot, 1e-14));
        assert_close(&t.log(), &xi, 1e-11, "log(exp(xi))");
        let back = Se3::exp(&t.log()).to_matrix3x4();
        assert_close(&back, &t.to_matrix3x4(), 1e-12, "exp(log(T))");
        prop_assert!((t.rotation_angle() - xi.fixed_rows::<3>(3).norm()).abs() < 1e-12);
    }

    #[test]
    fn times_point_pose_jacobian_is_the_product(
        a in prop::array::uniform9(-1e3f64..1e3), p in vec3(50.0), zero in 0usize..9,
    ) {
        // Every entry, and with one entry of `a` zero (the projection Jacobian's zeros): the
        // same values as the product, bit for bit.
        for z in [None, Some(zero)] {
            let mut m = Matrix3::from_row_slice(&a);
            if let Some(k) = z {
                m[(k / 3, k % 3)] = 0.0;
            }
            prop_assert_eq!(times_point_pose_jacobian(&m, &p), m * point_pose_jacobian(&p));
            // Two rows, as a mono projection Jacobian has.
            let m2 = m.fixed_rows::<2>(0).into_owned();
            prop_assert_eq!(times_point_pose_jacobian(&m2, &p), m2 * point_pose_jacobian(&p));
        }
    }

    #[test]
    fn compose_inverse_identities(a in pose(), b in pose(), p in vec3(50.0)) {
        let id = Se3::identity().to_matrix3x4();
        assert_close(&a.compose(&a.inverse()).to_matrix3x4(), &id, 1e-13, "A A⁻¹");
        assert_close(&a.inverse().compose(&a).to_matrix3x4(), &id, 1e-13, "A⁻¹ A");
        assert_close(
            &a.compose(&b).inverse().to_matrix3x4(),
            &b.inverse().compose(&a.inverse()).to_matrix3x4(),
            1e-13,
            "(AB)⁻¹",
        );
        let abp = a.transform_point(&b.transform_point(&p));
        assert_close(&a.compose(&b).transform_point(&p), &abp, 1e-13, "(AB)p");
        assert_close(&a.inverse().transform_point(&a.transform_point(&p)), &p, 1e-13, "A⁻¹Ap");
        prop_assert_eq!(Se3::from_matrix3x4(&a.to_matrix3x4()), a);
        prop_assert!((a.translation_norm() - a.trans.norm()).abs() <= 1e-15 * a.trans.norm());
    }

    #[test]
    fn adjoint_moves_perturbations(t in pose(), xi in twist(rotvec(1.0))) {
        let lhs = t.compose(&Se3::exp(&xi)).compose(&t.inverse());
        let rhs = Se3::exp(&(t.adjoint() * xi));
        assert_close(&lhs.to_matrix3x4(), &rhs.to_matrix3x4(), 1e-12, "T exp(xi) T⁻¹");
    }

    #[test]
    fn retract_log_recovers_delta(t in pose(), d in twist(rotvec(1.0))) {
        let back = t.retract(&d).compose(&t.inverse()).log();
        assert_close(&back, &d, 1e-11, "log(retract(d) T⁻¹)");
    }

    #[test]
    fn stereo_backproject_round_trip(p in p_cam()) {
        let c = asymmetric_cam();
        let uvr = c.project_stereo(&p).unwrap();
        prop_assert!((uvr.x - uvr.z - c.bf() / p.z).abs() < 1e-9);
        let depth = c.depth_from_disparity(uvr.x - uvr.z).unwrap();
        prop_assert!((depth - p.z).abs() <= 1e-9 * p.z);
        assert_close(&c.backproject(uvr.x, uvr.y, depth), &p, 1e-9, "backproject(project)");
        let uv = c.project(&c.backproject(uvr.x, uvr.y, p.z)).unwrap();
        assert_close(&uv, &uvr.xy(), 1e-9, "project(backproject)");
    }

    #[test]
    fn projection_jacobians_match_finite_differences(p in p_cam()) {
        let c = asymmetric_cam();
        let fd = fd_jacobian(|q: &Vector3<f64>| c.project(q).unwrap(), &p, 1e-6);
        assert_close(&c.project_jacobian(&p).unwrap(), &fd, 1e-6, "d uv / d p_cam");
        let fd = fd_jacobian(|q: &Vector3<f64>| c.project_stereo(q).unwrap(), &p, 1e-6);
        assert_close(&c.project_stereo_jacobian(&p).unwrap(), &fd, 1e-6, "d uvr / d p_cam");
    }

    #[test]
    fn pose_and_point_jacobians_match_finite_differences(t_cw in pose(), pc in p_cam()) {
        let c = asymmetric_cam();
        let pw = t_cw.inverse().transform_point(&pc);
        let mono = c.project_world(&t_cw, &pw).unwrap();
        let stereo = c.project_world_stereo(&t_cw, &pw).unwrap();
        assert_close(&mono.uv, &c.project(&pc).unwrap(), 1e-9, "project_world uv");
        assert_close(&stereo.uvr, &c.project_stereo(&pc).unwrap(), 1e-9, "stereo uvr");
        assert_close(&mono.p_cam, &pc, 1e-12, "p_cam");

        let zero = Vector6::zeros();
        let moved = |d: &Vector6<f64>| t_cw.retract(d).transform_point(&pw);
        let fd = fd_jacobian(|d: &Vector6<f64>| c.project(&moved(d)).unwrap(), &zero, 1e-6);
        assert_close(&mono.d_pose, &fd, 1e-6, "d uv / d xi");
        assert_eq!(c.pose_jacobian(&t_cw, &pw), Some(mono.d_pose));
        let fd =
            fd_jacobian(|d: &Vector6<f64>| c.project_stereo(&moved(d)).unwrap(), &zero, 1e-6);
        assert_close(&stereo.d_pose, &fd, 1e-6, "d uvr / d xi");
        assert_eq!(c.stereo_pose_jacobian(&t_cw, &pw), Some(stereo.d_pose));

        let cam_pt = |q: &Vector3<f64>| t_cw.transform_point(q);
        let fd = fd_jacobian(|q: &Vector3<f64>| c.project(&cam_pt(q)).unwrap(), &pw, 1e-6);
        assert_close(&mono.d_point, &fd, 1e-6, "d uv / d p_world");
        assert_eq!(c.point_jacobian(&t_cw, &pw), Some(mono.d_point));
        let fd =
            fd_jacobian(|q: &Vector3<f64>| c.project_stereo(&cam_pt(q)).unwrap(), &pw, 1e-6);
        assert_close(&stereo.d_point, &fd, 1e-6, "d uvr / d p_world");
        assert_eq!(c.stereo_point_jacobian(&t_cw, &pw), Some(stereo.d_point));

        let fd = fd_jacobian(moved, &zero, 1e-6);
        assert_close(&point_pose_jacobian(&pc), &fd, 1e-6, "d p_cam / d xi");
    }
}
