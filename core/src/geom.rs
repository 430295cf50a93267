//! Geometry: SE(3) rigid transforms and the pinhole stereo camera.
//!
//! Poses are `f64`: KITTI trajectories span kilometres and a Gauss-Newton step on an f32 pose
//! loses millimetres at that range; Cortex-M7/A-class ECUs have double-precision FPUs. Pixels
//! and image-space quantities stay `f32` elsewhere in core.
//!
//! Convention: `Se3 { rot, trans }` maps points from the source frame to the target frame,
//! `p_target = rot * p_source + trans`. A camera pose `T_wc` (camera-to-world) is what KITTI
//! pose files hold. Memory: every type here is a fixed-size value; no storage beyond itself.

use nalgebra::{Matrix3, Matrix3x4, Vector3};

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
}
