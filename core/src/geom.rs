//! Geometry: SO(3)/SE(3) Lie-group maths, the pinhole stereo camera and the projection
//! Jacobians the Gauss-Newton tracker and local bundle adjustment are built on.
//!
//! Poses are `f64`: KITTI trajectories span kilometres and a Gauss-Newton step on an f32 pose
//! loses millimetres at that range; Cortex-M7/A-class ECUs have double-precision FPUs. Pixels
//! and image-space quantities stay `f32` elsewhere in core and are widened at this boundary.
//!
//! # Conventions (all of them, in one place)
//! - **Transforms.** `Se3 { rot, trans }` maps points from the source frame to the target frame,
//!   `p_target = rot * p_source + trans`; `T_cw` maps world points into the camera frame. KITTI
//!   pose files hold `T_wc` (camera-to-world).
//! - **Tangent vectors.** A twist is `xi = [rho; phi]` (`Vector6`): `xi[0..3]` = `rho`, the
//!   translational part (metres), `xi[3..6]` = `phi`, the rotation vector (axis · angle, rad).
//!   [`Se3::exp`] gives `R = exp(phi)`, `t = J_l(phi) * rho`.
//! - **Perturbation.** Updates are *left-multiplicative*: [`Se3::retract`] returns
//!   `exp(delta) * T`, i.e. `delta` is expressed in the target frame of `T` (the camera frame for
//!   `T_cw`). Every pose Jacobian here is the derivative with respect to that `delta` at
//!   `delta = 0`, so a Gauss-Newton step `delta` solved from these Jacobians is applied with
//!   `retract` and nothing else.
//! - **SO(3) Jacobians.** `exp(phi + d) ≈ exp(J_l(phi) d) exp(phi) ≈ exp(phi) exp(J_r(phi) d)`.
//! - **Camera.** Right-handed camera frame, `x` right, `y` down, `z` forward (depth, metres).
//!   `u = fx x / z + cx`, `v = fy y / z + cy`; the right camera sits at `+baseline_m` along `x`
//!   of the left camera, so `u_right = u_left - fx * baseline / z` (rectified pair, shared
//!   intrinsics). Points with `z <= MIN_DEPTH_M` (or NaN) do not project.
//! - **Maths.** Transcendentals come from [`crate::math`] (libm) and norms are
//!   `math::sqrt(v.dot(v))` rather than nalgebra's `norm()`, so results are bit-identical on the
//!   host and on bare metal whatever features other crates enable in nalgebra/simba.
//!
//! Memory: every type here is a fixed-size value (the largest, [`StereoProjection`], is 264
//! bytes); nothing allocates or keeps storage beyond the value itself.

use core::fmt;

use nalgebra::{
    Matrix2x3, Matrix2x6, Matrix3, Matrix3x4, Matrix3x6, Matrix6, SMatrix, Vector2, Vector3,
    Vector6,
};

use crate::math;

/// Below this rotation angle (rad) the SO(3) coefficient functions use their Taylor series:
/// the closed forms cancel catastrophically near zero, and at 1e-3 the first dropped series
/// term is below 1e-20 relative.
const SMALL_ANGLE_RAD: f64 = 1e-3;

/// Smallest depth (metres) at which a point is considered in front of the camera.
///
/// Only a guard against division blow-up; gating on plausible depths is the caller's business.
pub const MIN_DEPTH_M: f64 = 1e-6;

/// Iteration cap for the polar-decomposition Newton iteration in [`Se3::normalized`];
/// quadratic convergence from drift-sized errors needs 3-4, the cap keeps the loop bounded.
const MAX_POLAR_ITERS: usize = 16;

const _: () = assert!(core::mem::size_of::<Se3>() == 12 * 8);
const _: () = assert!(core::mem::size_of::<StereoProjection>() == 264);

/// Errors from validating geometric inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GeomError {
    /// A camera parameter is NaN or infinite, or (focal lengths, baseline) not strictly
    /// positive. `field` names the offending parameter (`"fx_px"`, `"baseline_m"`, ...).
    InvalidCamera {
        /// Name of the rejected field.
        field: &'static str,
    },
    /// The rotation block is singular, a reflection (det <= 0) or not finite, so it has no
    /// nearest rotation.
    DegenerateRotation,
}

impl fmt::Display for GeomError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GeomError::InvalidCamera { field } => {
                write!(
                    f,
                    "invalid camera parameter `{field}`: must be finite \
                     (and > 0 for focal lengths and baseline)"
                )
            }
            GeomError::DegenerateRotation => {
                f.write_str("rotation block is singular, a reflection or not finite")
            }
        }
    }
}

impl core::error::Error for GeomError {}

#[inline]
fn norm3(v: &Vector3<f64>) -> f64 {
    math::sqrt(v.dot(v))
}

/// The skew-symmetric (cross-product) matrix: `skew(a) * b == a.cross(&b)`.
pub fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Inverse of [`skew`] applied to the antisymmetric part: `vee((m - mᵀ)/2)`, so
/// `vee(skew(v)) == v` and a symmetric matrix maps to zero.
pub fn vee(m: &Matrix3<f64>) -> Vector3<f64> {
    Vector3::new(m[(2, 1)] - m[(1, 2)], m[(0, 2)] - m[(2, 0)], m[(1, 0)] - m[(0, 1)]) * 0.5
}

/// SO(3) exponential (Rodrigues): the rotation by `|w|` radians about `w / |w|`.
///
/// Exact to rounding for every `w`, including `w = 0` (series branch below 1e-3 rad).
pub fn so3_exp(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = w.dot(w);
    let theta = math::sqrt(theta2);
    let (a, b) = if theta < SMALL_ANGLE_RAD {
        (
            1.0 - theta2 / 6.0 + theta2 * theta2 / 120.0,
            0.5 - theta2 / 24.0 + theta2 * theta2 / 720.0,
        )
    } else {
        // (1 - cos θ)/θ² written with the half angle: no cancellation for small θ.
        let s = math::sin(0.5 * theta);
        (math::sin(theta) / theta, 2.0 * s * s / theta2)
    };
    let k = skew(w);
    Matrix3::identity() + k * a + k * k * b
}

/// The rotation angle in `[0, π]` of a rotation matrix, via `atan2(|vee|, (tr - 1)/2)`, which
/// keeps full precision at both ends where `acos` would not.
pub fn so3_angle(r: &Matrix3<f64>) -> f64 {
    let a = vee(r);
    math::atan2(norm3(&a), 0.5 * (r.trace() - 1.0))
}

/// SO(3) logarithm: the rotation vector `w` with `|w| ∈ [0, π]` and `so3_exp(w) == r`.
///
/// Robust over the whole range: near 0 a series for `θ / sin θ`; for `θ > π/2` the axis is
/// taken from the symmetric part `(R + Rᵀ)/2 - cos θ I = (1 - cos θ) n nᵀ` (well conditioned
/// up to and including `θ = π`) and only its sign from the antisymmetric part. At exactly `π`
/// both `±π n` are valid; the one returned is deterministic.
pub fn so3_log(r: &Matrix3<f64>) -> Vector3<f64> {
    // a = sin θ · n
    let a = vee(r);
    let s = norm3(&a);
    let c = 0.5 * (r.trace() - 1.0);
    let theta = math::atan2(s, c);
    if c >= 0.0 {
        // θ ≤ π/2: sin θ ≥ 1 - cos θ, the antisymmetric part is the better conditioned.
        let k = if theta < SMALL_ANGLE_RAD {
            let t2 = theta * theta;
            1.0 + t2 / 6.0 + 7.0 * t2 * t2 / 360.0
        } else {
            theta / s
        };
        a * k
    } else {
        let one_minus_c = 1.0 - c; // in (1, 2]
        let mut k = 0;
        for i in 1..3 {
            if r[(i, i)] > r[(k, k)] {
                k = i;
            }
        }
        // Column k of (S - cI) = (1 - c) n_k n, S the symmetric part.
        let mut col = Vector3::new(
            0.5 * (r[(0, k)] + r[(k, 0)]),
            0.5 * (r[(1, k)] + r[(k, 1)]),
            0.5 * (r[(2, k)] + r[(k, 2)]),
        );
        col[k] -= c;
        col /= one_minus_c;
        let mut n = col / norm3(&col);
        if n.dot(&a) < 0.0 {
            n = -n;
        }
        n * theta
    }
}

/// Left Jacobian of SO(3): `exp(phi + d) ≈ exp(J_l(phi) d) exp(phi)` for small `d`.
///
/// Also the `V` matrix of the SE(3) exponential (`t = J_l(phi) rho`).
pub fn so3_left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.dot(phi);
    let theta = math::sqrt(theta2);
    let (b, c) = if theta < SMALL_ANGLE_RAD {
        (
            0.5 - theta2 / 24.0 + theta2 * theta2 / 720.0,
            1.0 / 6.0 - theta2 / 120.0 + theta2 * theta2 / 5040.0,
        )
    } else {
        let s = math::sin(0.5 * theta);
        (2.0 * s * s / theta2, (theta - math::sin(theta)) / (theta2 * theta))
    };
    let k = skew(phi);
    Matrix3::identity() + k * b + k * k * c
}

/// Inverse of [`so3_left_jacobian`], in closed form; finite for `|phi| < 2π` (so for every
/// output of [`so3_log`]).
pub fn so3_left_jacobian_inv(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.dot(phi);
    let theta = math::sqrt(theta2);
    let d = if theta < SMALL_ANGLE_RAD {
        1.0 / 12.0 + theta2 / 720.0 + theta2 * theta2 / 30240.0
    } else {
        // (1 + cos θ)/(2θ sin θ) = cot(θ/2)/(2θ): stays finite at θ = π.
        let h = 0.5 * theta;
        1.0 / theta2 - math::cos(h) / (2.0 * theta * math::sin(h))
    };
    let k = skew(phi);
    Matrix3::identity() - k * 0.5 + k * k * d
}

/// Right Jacobian of SO(3): `exp(phi + d) ≈ exp(phi) exp(J_r(phi) d)`; equals
/// `J_l(phi)ᵀ = J_l(-phi)`.
pub fn so3_right_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian(phi).transpose()
}

/// Inverse of [`so3_right_jacobian`].
pub fn so3_right_jacobian_inv(phi: &Vector3<f64>) -> Matrix3<f64> {
    so3_left_jacobian_inv(phi).transpose()
}

/// Derivative of `exp(delta) * p` with respect to `delta = [rho; phi]` at `delta = 0`:
/// `[I | -skew(p)]` (3x6).
///
/// With `p = T.transform_point(p_src)` this is the Jacobian of
/// `T.retract(delta).transform_point(p_src)`, the building block of every pose Jacobian here.
pub fn point_pose_jacobian(p: &Vector3<f64>) -> Matrix3x6<f64> {
    let mut j = Matrix3x6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&Matrix3::identity());
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-skew(p)));
    j
}

/// `a * point_pose_jacobian(p)` for an `R`x3 `a` (a projection Jacobian, mono or stereo),
/// without its multiplications by 0 and 1: the same sums in the same order, so the same bits
/// up to the sign of a zero. It is the inner step of every pose linearisation.
#[inline]
pub fn times_point_pose_jacobian<const R: usize>(
    a: &SMatrix<f64, R, 3>,
    p: &Vector3<f64>,
) -> SMatrix<f64, R, 6> {
    let mut j = SMatrix::<f64, R, 6>::zeros();
    for r in 0..R {
        let (a0, a1, a2) = (a[(r, 0)], a[(r, 1)], a[(r, 2)]);
        j[(r, 0)] = a0;
        j[(r, 1)] = a1;
        j[(r, 2)] = a2;
        // -skew(p) = [[0, z, -y], [-z, 0, x], [y, -x, 0]]
        j[(r, 3)] = a1 * -p.z + a2 * p.y;
        j[(r, 4)] = a0 * p.z + a2 * -p.x;
        j[(r, 5)] = a0 * -p.y + a1 * p.x;
    }
    j
}

/// A rigid transform in SE(3): rotation matrix and translation (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Se3 {
    /// Rotation part, orthonormal with determinant +1.
    pub rot: Matrix3<f64>,
    /// Translation part in metres.
    pub trans: Vector3<f64>,
}

impl Default for Se3 {
    fn default() -> Self {
        Self::identity()
    }
}

impl Se3 {
    /// The identity transform, as a constant (for `const` initialisers of fixed storage).
    pub const IDENTITY: Se3 = Se3 {
        rot: Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        trans: Vector3::new(0.0, 0.0, 0.0),
    };

    /// The identity transform.
    pub fn identity() -> Self {
        Self { rot: Matrix3::identity(), trans: Vector3::zeros() }
    }

    /// Builds a transform from its parts (the caller guarantees `rot` is a rotation).
    pub fn new(rot: Matrix3<f64>, trans: Vector3<f64>) -> Self {
        Self { rot, trans }
    }

    /// Builds a transform from a 3x4 `[R | t]` matrix (row-major KITTI layout).
    pub fn from_matrix3x4(m: &Matrix3x4<f64>) -> Self {
        Self { rot: m.fixed_view::<3, 3>(0, 0).into_owned(), trans: m.column(3).into_owned() }
    }

    /// The 3x4 `[R | t]` matrix.
    pub fn to_matrix3x4(&self) -> Matrix3x4<f64> {
        let mut m = Matrix3x4::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rot);
        m.set_column(3, &self.trans);
        m
    }

    /// Composition `self ∘ other`: first `other`, then `self`.
    pub fn compose(&self, other: &Se3) -> Se3 {
        Se3 { rot: self.rot * other.rot, trans: self.rot * other.trans + self.trans }
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Se3 {
        let rt = self.rot.transpose();
        Se3 { rot: rt, trans: -(rt * self.trans) }
    }

    /// Applies the transform to a point.
    pub fn transform_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.rot * p + self.trans
    }

    /// SE(3) exponential of the twist `xi = [rho; phi]` (translation part first, see the
    /// module docs): `R = so3_exp(phi)`, `t = J_l(phi) rho`.
    pub fn exp(xi: &Vector6<f64>) -> Se3 {
        let rho = xi.fixed_rows::<3>(0).into_owned();
        let phi = xi.fixed_rows::<3>(3).into_owned();
        Se3 { rot: so3_exp(&phi), trans: so3_left_jacobian(&phi) * rho }
    }

    /// SE(3) logarithm, the inverse of [`Se3::exp`]: `xi = [rho; phi]` with `|phi| ∈ [0, π]`.
    pub fn log(&self) -> Vector6<f64> {
        let phi = so3_log(&self.rot);
        let rho = so3_left_jacobian_inv(&phi) * self.trans;
        let mut xi = Vector6::zeros();
        xi.fixed_rows_mut::<3>(0).copy_from(&rho);
        xi.fixed_rows_mut::<3>(3).copy_from(&phi);
        xi
    }

    /// Left-multiplicative update `exp(delta) * self` (`delta = [rho; phi]`, expressed in the
    /// target frame of `self`). This is the update every pose Jacobian in this module is the
    /// derivative of. The result is not re-orthonormalised; see [`Se3::normalized`].
    pub fn retract(&self, delta: &Vector6<f64>) -> Se3 {
        Se3::exp(delta).compose(self)
    }

    /// Adjoint (6x6) for the `[rho; phi]` ordering: `self * exp(xi) * self⁻¹ == exp(Ad * xi)`,
    /// `Ad = [[R, skew(t) R], [0, R]]`. Moves a perturbation from the source frame of `self`
    /// to its target frame.
    pub fn adjoint(&self) -> Matrix6<f64> {
        let mut ad = Matrix6::zeros();
        ad.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.rot);
        ad.fixed_view_mut::<3, 3>(0, 3).copy_from(&(skew(&self.trans) * self.rot));
        ad.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.rot);
        ad
    }

    /// Rotation angle in radians, in `[0, π]` (see [`so3_angle`]).
    pub fn rotation_angle(&self) -> f64 {
        so3_angle(&self.rot)
    }

    /// Euclidean norm of the translation, in metres.
    pub fn translation_norm(&self) -> f64 {
        norm3(&self.trans)
    }

    /// The same transform with its rotation block replaced by the nearest rotation (Frobenius
    /// norm): the orthogonal polar factor, by the Newton iteration `R ← (R + R⁻ᵀ)/2` (fixed
    /// order and bounded count, so deterministic). Repairs the drift that accumulates over
    /// many [`Se3::retract`]/[`Se3::compose`] calls; the translation is kept as is.
    ///
    /// # Errors
    /// [`GeomError::DegenerateRotation`] if the rotation block is not finite, singular or a
    /// reflection (det <= 0).
    pub fn normalized(&self) -> Result<Se3, GeomError> {
        let mut r = self.rot;
        for _ in 0..MAX_POLAR_ITERS {
            let c0 = r.column(0).into_owned();
            let c1 = r.column(1).into_owned();
            let c2 = r.column(2).into_owned();
            let x12 = c1.cross(&c2);
            let det = c0.dot(&x12);
            if !det.is_finite() || det <= 0.0 {
                return Err(GeomError::DegenerateRotation);
            }
            // Columns of R⁻ᵀ are the cofactor columns over det.
            let inv_t = Matrix3::from_columns(&[x12, c2.cross(&c0), c0.cross(&c1)]) / det;
            let next = (r + inv_t) * 0.5;
            let mut change = 0.0f64;
            for (x, y) in next.iter().zip(r.iter()) {
                change = change.max(math::abs(x - y));
            }
            r = next;
            if change <= 4.0 * f64::EPSILON {
                break;
            }
        }
        if r.iter().all(|x| x.is_finite()) {
            Ok(Se3 { rot: r, trans: self.trans })
        } else {
            Err(GeomError::DegenerateRotation)
        }
    }
}

/// Projection of a world point with its Jacobians (monocular, left camera).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonoProjection {
    /// Pixel coordinates `(u, v)`.
    pub uv: Vector2<f64>,
    /// The point in the camera frame, `T_cw * p_world` (metres).
    pub p_cam: Vector3<f64>,
    /// `d(u, v) / d delta` for `T_cw.retract(delta)` (2x6, `delta = [rho; phi]`).
    pub d_pose: Matrix2x6<f64>,
    /// `d(u, v) / d p_world` (2x3).
    pub d_point: Matrix2x3<f64>,
}

/// Projection of a world point into the stereo pair with its Jacobians.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StereoProjection {
    /// `(u_left, v, u_right)` in pixels.
    pub uvr: Vector3<f64>,
    /// The point in the (left) camera frame, `T_cw * p_world` (metres).
    pub p_cam: Vector3<f64>,
    /// `d(u_left, v, u_right) / d delta` for `T_cw.retract(delta)` (3x6).
    pub d_pose: Matrix3x6<f64>,
    /// `d(u_left, v, u_right) / d p_world` (3x3).
    pub d_point: Matrix3<f64>,
}

/// A rectified pinhole stereo pair with shared intrinsics (the left camera is the reference).
///
/// Fields are public so calibration code can fill them directly; [`StereoCamera::new`] is the
/// validating constructor and the only one that guarantees positive, finite parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StereoCamera {
    /// Horizontal focal length in pixels.
    pub fx_px: f64,
    /// Vertical focal length in pixels.
    pub fy_px: f64,
    /// Principal point, column, in pixels.
    pub cx_px: f64,
    /// Principal point, row, in pixels.
    pub cy_px: f64,
    /// Distance between the optical centres, metres; the right camera is at `+x`.
    pub baseline_m: f64,
}

impl StereoCamera {
    /// Validated constructor.
    ///
    /// # Errors
    /// [`GeomError::InvalidCamera`] if any value is NaN or infinite, or `fx_px`, `fy_px` or
    /// `baseline_m` is not strictly positive.
    pub fn new(
        fx_px: f64,
        fy_px: f64,
        cx_px: f64,
        cy_px: f64,
        baseline_m: f64,
    ) -> Result<Self, GeomError> {
        let positive = [("fx_px", fx_px), ("fy_px", fy_px), ("baseline_m", baseline_m)];
        for (field, x) in positive {
            if !x.is_finite() || x <= 0.0 {
                return Err(GeomError::InvalidCamera { field });
            }
        }
        for (field, x) in [("cx_px", cx_px), ("cy_px", cy_px)] {
            if !x.is_finite() {
                return Err(GeomError::InvalidCamera { field });
            }
        }
        Ok(Self { fx_px, fy_px, cx_px, cy_px, baseline_m })
    }

    /// `fx * baseline` in pixel·metres: `depth = bf / disparity`.
    pub fn bf(&self) -> f64 {
        self.fx_px * self.baseline_m
    }

    /// Projects a camera-frame point to left-image pixels `(u, v)`; `None` if
    /// `z <= MIN_DEPTH_M` or `z` is NaN.
    pub fn project(&self, p_cam: &Vector3<f64>) -> Option<Vector2<f64>> {
        if p_cam.z > MIN_DEPTH_M {
            let iz = 1.0 / p_cam.z;
            Some(Vector2::new(
                self.fx_px * p_cam.x * iz + self.cx_px,
                self.fy_px * p_cam.y * iz + self.cy_px,
            ))
        } else {
            None
        }
    }

    /// Projects a camera-frame point into both images: `(u_left, v, u_right)` with
    /// `u_right = u_left - bf / z`; `None` where [`StereoCamera::project`] is `None`.
    pub fn project_stereo(&self, p_cam: &Vector3<f64>) -> Option<Vector3<f64>> {
        let uv = self.project(p_cam)?;
        Some(Vector3::new(uv.x, uv.y, uv.x - self.bf() / p_cam.z))
    }

    /// The camera-frame point at pixel `(u, v)` of the left image and depth `depth_m` (its
    /// `z`); the inverse of [`StereoCamera::project`] for that depth.
    pub fn backproject(&self, u: f64, v: f64, depth_m: f64) -> Vector3<f64> {
        Vector3::new(
            (u - self.cx_px) * depth_m / self.fx_px,
            (v - self.cy_px) * depth_m / self.fy_px,
            depth_m,
        )
    }

    /// Depth in metres for a disparity `u_left - u_right` in pixels; `None` unless the
    /// disparity is finite and strictly positive.
    pub fn depth_from_disparity(&self, disparity_px: f64) -> Option<f64> {
        if disparity_px.is_finite() && disparity_px > 0.0 {
            Some(self.bf() / disparity_px)
        } else {
            None
        }
    }

    /// `d(u, v) / d p_cam` (2x3) at a camera-frame point; `None` where
    /// [`StereoCamera::project`] is `None`.
    pub fn project_jacobian(&self, p_cam: &Vector3<f64>) -> Option<Matrix2x3<f64>> {
        if p_cam.z > MIN_DEPTH_M {
            let iz = 1.0 / p_cam.z;
            let (fx, fy) = (self.fx_px * iz, self.fy_px * iz);
            Some(Matrix2x3::new(fx, 0.0, -fx * p_cam.x * iz, 0.0, fy, -fy * p_cam.y * iz))
        } else {
            None
        }
    }

    /// `d(u_left, v, u_right) / d p_cam` (3x3); `None` where [`StereoCamera::project`] is
    /// `None`.
    pub fn project_stereo_jacobian(&self, p_cam: &Vector3<f64>) -> Option<Matrix3<f64>> {
        let j = self.project_jacobian(p_cam)?;
        let iz = 1.0 / p_cam.z;
        let fx = self.fx_px * iz;
        let mut m = Matrix3::zeros();
        m.fixed_view_mut::<2, 3>(0, 0).copy_from(&j);
        m[(2, 0)] = fx;
        m[(2, 2)] = -fx * (p_cam.x - self.baseline_m) * iz;
        Some(m)
    }

    /// Projects `p_world` through `t_cw` into the left image, with the Jacobians with respect
    /// to the left-multiplicative pose perturbation (`t_cw.retract(delta)`) and to the point.
    /// `None` if the point is not in front of the camera.
    ///
    /// For a residual `r = predicted - observed` these are the residual Jacobians as they are;
    /// for `observed - predicted` negate them.
    pub fn project_world(&self, t_cw: &Se3, p_world: &Vector3<f64>) -> Option<MonoProjection> {
        let p_cam = t_cw.transform_point(p_world);
        let uv = self.project(&p_cam)?;
        let j = self.project_jacobian(&p_cam)?;
        Some(MonoProjection {
            uv,
            p_cam,
            d_pose: times_point_pose_jacobian(&j, &p_cam),
            d_point: j * t_cw.rot,
        })
    }

    /// Stereo version of [`StereoCamera::project_world`]: `(u_left, v, u_right)` and its 3x6
    /// pose and 3x3 point Jacobians.
    pub fn project_world_stereo(
        &self,
        t_cw: &Se3,
        p_world: &Vector3<f64>,
    ) -> Option<StereoProjection> {
        let p_cam = t_cw.transform_point(p_world);
        let uvr = self.project_stereo(&p_cam)?;
        let j = self.project_stereo_jacobian(&p_cam)?;
        Some(StereoProjection {
            uvr,
            p_cam,
            d_pose: times_point_pose_jacobian(&j, &p_cam),
            d_point: j * t_cw.rot,
        })
    }

    /// `d(u, v) / d delta` (2x6) of projecting `p_world` through `t_cw.retract(delta)`.
    pub fn pose_jacobian(&self, t_cw: &Se3, p_world: &Vector3<f64>) -> Option<Matrix2x6<f64>> {
        self.project_world(t_cw, p_world).map(|p| p.d_pose)
    }

    /// `d(u, v) / d p_world` (2x3) of projecting `p_world` through `t_cw`.
    pub fn point_jacobian(&self, t_cw: &Se3, p_world: &Vector3<f64>) -> Option<Matrix2x3<f64>> {
        self.project_world(t_cw, p_world).map(|p| p.d_point)
    }

    /// `d(u_left, v, u_right) / d delta` (3x6) of projecting through `t_cw.retract(delta)`.
    pub fn stereo_pose_jacobian(
        &self,
        t_cw: &Se3,
        p_world: &Vector3<f64>,
    ) -> Option<Matrix3x6<f64>> {
        self.project_world_stereo(t_cw, p_world).map(|p| p.d_pose)
    }

    /// `d(u_left, v, u_right) / d p_world` (3x3) of projecting `p_world` through `t_cw`.
    pub fn stereo_point_jacobian(
        &self,
        t_cw: &Se3,
        p_world: &Vector3<f64>,
    ) -> Option<Matrix3<f64>> {
        self.project_world_stereo(t_cw, p_world).map(|p| p.d_point)
    }
}

#[cfg(test)]
mod tests;
