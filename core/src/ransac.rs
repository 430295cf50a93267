//! Deterministic RANSAC for the camera pose from 3D–3D correspondences.
//!
//! With stereo, a matched feature gives a point in the camera frame and its landmark a point in
//! the world: three such pairs fix the pose (Kabsch/Umeyama, no scale). Hypotheses are scored by
//! the reprojection χ² of *all* matches (mono ones too), so the consensus set is what the pose
//! optimisation will accept. In traffic the largest consistent set is the static scene; a van
//! or cyclist moving with the camera is a smaller, self-consistent set that a least-squares
//! start from the constant-velocity prediction can otherwise be drawn towards.
//!
//! Randomness is a seeded xorshift (same input → same hypotheses on every target). Memory: the
//! caller's slices only.

use nalgebra::{Matrix3, Vector3};

use crate::geom::{Se3, StereoCamera};
use crate::optim::{chi2, Measurement};

/// xorshift64: tiny, seedable, identical on every target.
#[derive(Clone, Copy, Debug)]
pub struct XorShift64(u64);

impl XorShift64 {
    /// A generator; a zero seed is replaced (xorshift would stay at zero).
    pub const fn new(seed: u64) -> Self {
        Self(if seed == 0 { 0x9e37_79b9_7f4a_7c15 } else { seed })
    }

    /// Next value.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// Uniform index in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// The rigid transform `T` with `q ≈ T p` for three (or more) pairs, by Kabsch's SVD with the
/// reflection fix; `None` for degenerate (collinear or coincident) points.
pub fn rigid_from_points(p: &[Vector3<f64>], q: &[Vector3<f64>]) -> Option<Se3> {
    let n = p.len().min(q.len());
    if n < 3 {
        return None;
    }
    let inv = 1.0 / n as f64;
    let pc = p[..n].iter().fold(Vector3::zeros(), |a, x| a + x) * inv;
    let qc = q[..n].iter().fold(Vector3::zeros(), |a, x| a + x) * inv;
    let mut h = Matrix3::zeros();
    for (a, b) in p[..n].iter().zip(&q[..n]) {
        h += (a - pc) * (b - qc).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    // Rank check: the second singular value vanishes for collinear points.
    let mut s = svd.singular_values;
    s.as_mut_slice().sort_unstable_by(|a, b| b.total_cmp(a));
    // `partial_cmp` so a NaN singular value also counts as degenerate.
    if s[1].partial_cmp(&(1e-9 * s[0].max(1e-300))) != Some(core::cmp::Ordering::Greater) {
        return None;
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant();
    let mut fix = Matrix3::identity();
    fix[(2, 2)] = if d < 0.0 { -1.0 } else { 1.0 };
    let r = v * fix * u.transpose();
    let t = qc - r * pc;
    Some(Se3::new(r, t))
}

/// One correspondence for [`ransac_pose`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Correspondence {
    /// Landmark position in the world (m).
    pub p_w: Vector3<f64>,
    /// The feature's point in the camera frame from stereo, when it has depth.
    pub p_c: Option<Vector3<f64>>,
    /// The feature's measurement.
    pub z: Measurement,
}

/// Result of [`ransac_pose`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RansacResult {
    /// Best world-to-camera pose.
    pub t_cw: Se3,
    /// Its consensus count.
    pub inliers: u32,
    /// Hypotheses evaluated.
    pub hypotheses: u32,
}

/// Counts the correspondences whose reprojection χ² under `t_cw` is within their threshold.
pub fn count_inliers(cam: &StereoCamera, t_cw: &Se3, corr: &[Correspondence]) -> u32 {
    corr.iter()
        .filter(|c| {
            chi2(cam, &t_cw.transform_point(&c.p_w), &c.z)
                .is_some_and(|s| s <= c.z.chi2_threshold())
        })
        .count() as u32
}

/// RANSAC over `iterations` three-point hypotheses drawn from the stereo correspondences,
/// seeded with `seed`. `None` when fewer than three stereo correspondences exist or no
/// hypothesis was valid.
pub fn ransac_pose(
    cam: &StereoCamera,
    corr: &[Correspondence],
    iterations: u32,
    seed: u64,
) -> Option<RansacResult> {
    let stereo = corr.iter().filter(|c| c.p_c.is_some()).count();
    if stereo < 3 {
        return None;
    }
    let mut rng = XorShift64::new(seed);
    let mut best: Option<RansacResult> = None;
    let mut hypotheses = 0;
    for _ in 0..iterations {
        // Draw three distinct stereo correspondences.
        let mut idx = [usize::MAX; 3];
        let mut k = 0;
        let mut guard = 0;
        while k < 3 && guard < 64 {
            guard += 1;
            let i = rng.below(corr.len());
            if corr[i].p_c.is_none() || idx[..k].contains(&i) {
                continue;
            }
            idx[k] = i;
            k += 1;
        }
        if k < 3 {
            continue;
        }
        let p = [corr[idx[0]].p_w, corr[idx[1]].p_w, corr[idx[2]].p_w];
        let q = [
            corr[idx[0]].p_c.unwrap_or_default(),
            corr[idx[1]].p_c.unwrap_or_default(),
            corr[idx[2]].p_c.unwrap_or_default(),
        ];
        let Some(t) = rigid_from_points(&p, &q) else { continue };
        hypotheses += 1;
        let n = count_inliers(cam, &t, corr);
        if best.is_none_or(|b| n > b.inliers) {
            best = Some(RansacResult { t_cw: t, inliers: n, hypotheses: 0 });
        }
    }
    best.map(|b| RansacResult { hypotheses, ..b })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::kitti_cam;
    use nalgebra::Vector6;

    #[test]
    fn kabsch_recovers_a_rigid_transform() {
        let t = Se3::exp(&Vector6::new(0.3, -1.0, 2.0, 0.1, -0.2, 0.3));
        let p = [
            Vector3::new(1.0, 2.0, 3.0),
            Vector3::new(-2.0, 0.5, 7.0),
            Vector3::new(0.0, -1.0, 4.0),
        ];
        let q: std::vec::Vec<_> = p.iter().map(|x| t.transform_point(x)).collect();
        let e = rigid_from_points(&p, &q).unwrap();
        assert!((e.rot - t.rot).norm() < 1e-12 && (e.trans - t.trans).norm() < 1e-12);
        let collinear =
            [Vector3::new(0.0, 0.0, 1.0), Vector3::new(0.0, 0.0, 2.0), Vector3::new(0.0, 0.0, 3.0)];
        assert!(rigid_from_points(&collinear, &collinear).is_none());
    }

    #[test]
    fn ransac_prefers_the_larger_consistent_set() {
        let cam = kitti_cam();
        let truth = Se3::exp(&Vector6::new(0.1, 0.0, -1.0, 0.0, 0.02, 0.0));
        // A "moving object": 40 % of the points obey a different motion (static w.r.t. camera).
        let object = Se3::identity();
        let mut rng = XorShift64::new(3);
        let mut corr = std::vec::Vec::new();
        for i in 0..200 {
            let u = |r: &mut XorShift64| (r.next_u64() % 10_000) as f64 / 10_000.0;
            let p_w = Vector3::new(
                u(&mut rng) * 20.0 - 10.0,
                u(&mut rng) * 4.0 - 2.0,
                6.0 + u(&mut rng) * 30.0,
            );
            let t = if i % 5 < 2 { object } else { truth };
            let p_c = t.transform_point(&p_w);
            let uu = cam.fx_px * p_c.x / p_c.z + cam.cx_px;
            let vv = cam.fy_px * p_c.y / p_c.z + cam.cy_px;
            let z = Measurement { u: uu, v: vv, ur: uu - cam.bf() / p_c.z, inv_sigma2: 1.0 };
            corr.push(Correspondence { p_w, p_c: Some(p_c), z });
        }
        let r = ransac_pose(&cam, &corr, 100, 42).unwrap();
        // All 120 static points agree; a far object point may agree by coincidence too.
        assert!((120..=124).contains(&r.inliers), "{}", r.inliers);
        assert!((r.t_cw.trans - truth.trans).norm() < 1e-9);
        // Same seed, same answer.
        assert_eq!(ransac_pose(&cam, &corr, 100, 42), Some(r));
    }
}
