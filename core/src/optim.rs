//! Nonlinear least squares for tracking: motion-only pose optimisation and bounded-window
//! bundle adjustment (BA), both with robust (Huber) kernels and per-observation weights.
//!
//! Residuals are stereo reprojection errors `z − π(T_cw · p_w)` with `z = (u_left, v, u_right)`
//! (or `(u, v)` for a key point without a stereo match), weighted by the ORB scale-level
//! information `1/σ²` (σ = 1.2^level, as ORB-SLAM2) and by an association weight in `[0, 1]`:
//! 1 for hard nearest-neighbour association, the E-step weight `w_kj` under EM association
//! (Bowman et al. 2017, paper §3.3) — the M-step *is* this weighted Gauss-Newton.
//!
//! Pose updates are left-multiplicative, `T ← exp(δ)·T` with `δ = [ρ; φ]` (translation first),
//! the convention of [`crate::geom`].
//!
//! BA eliminates points with the Schur complement one point at a time, so memory is the
//! reduced camera system only: a dense `6·MAX_WINDOW` square matrix ([`BaScratch`], 29 KiB for
//! 10 keyframes) plus a caller-provided point backup for rejected Levenberg-Marquardt steps.
//! Nothing is allocated; iteration orders are fixed, so results are bit-identical across runs.

// `!(x > 0.0)` is used on purpose throughout: it is true for NaN as well, so corrupt values
// are rejected by the same test that rejects non-positive ones.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use nalgebra::{Matrix3, Matrix3x6, Matrix6x3, SMatrix, SVector, Vector3, Vector6};

use crate::geom::{times_point_pose_jacobian, Se3, StereoCamera};
use crate::math;

/// Most keyframes a BA problem can hold (the sliding window's capacity).
pub const MAX_WINDOW: usize = 24;
/// Size of the reduced camera system.
const NP: usize = 6 * MAX_WINDOW;

/// χ² threshold at 95 % for 3 degrees of freedom (stereo observation), as ORB-SLAM2.
pub const CHI2_STEREO: f64 = 7.815;
/// χ² threshold at 95 % for 2 degrees of freedom (monocular observation), as ORB-SLAM2.
pub const CHI2_MONO: f64 = 5.991;

/// One measurement of a point in an image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measurement {
    /// Left-image column (px).
    pub u: f64,
    /// Row (px).
    pub v: f64,
    /// Right-image column (px); negative when the key point has no stereo match (monocular).
    pub ur: f64,
    /// Information `1/σ²` of the key point's scale level.
    pub inv_sigma2: f64,
}

impl Measurement {
    /// Whether the measurement has a right-image column.
    #[inline]
    pub fn is_stereo(&self) -> bool {
        self.ur >= 0.0
    }

    /// The χ² threshold that classifies this measurement as an outlier.
    #[inline]
    pub fn chi2_threshold(&self) -> f64 {
        if self.is_stereo() {
            CHI2_STEREO
        } else {
            CHI2_MONO
        }
    }
}

/// Residual, Jacobian with respect to the camera-frame point, and validity for one
/// measurement. Rows: u, v, (ur). A mono measurement has a zero third row.
struct Linearised {
    r: Vector3<f64>,
    /// d(prediction)/d(p_cam).
    j_pc: Matrix3<f64>,
}

/// Smallest depth (m) at which a point still counts as in front of the camera.
const MIN_DEPTH_M: f64 = 1e-3;

#[inline]
fn linearise(cam: &StereoCamera, pc: &Vector3<f64>, z: &Measurement) -> Option<Linearised> {
    if !(pc.z > MIN_DEPTH_M) {
        return None;
    }
    let inv_z = 1.0 / pc.z;
    let inv_z2 = inv_z * inv_z;
    let u = cam.fx_px * pc.x * inv_z + cam.cx_px;
    let v = cam.fy_px * pc.y * inv_z + cam.cy_px;
    let bf = cam.fx_px * cam.baseline_m;
    let mut r = Vector3::new(z.u - u, z.v - v, 0.0);
    let mut j = Matrix3::zeros();
    j[(0, 0)] = cam.fx_px * inv_z;
    j[(0, 2)] = -cam.fx_px * pc.x * inv_z2;
    j[(1, 1)] = cam.fy_px * inv_z;
    j[(1, 2)] = -cam.fy_px * pc.y * inv_z2;
    if z.is_stereo() {
        let ur = u - bf * inv_z;
        r.z = z.ur - ur;
        j[(2, 0)] = cam.fx_px * inv_z;
        j[(2, 2)] = -(cam.fx_px * pc.x - bf) * inv_z2;
    }
    Some(Linearised { r, j_pc: j })
}

/// χ² (information-weighted squared error) of one measurement against a camera-frame point;
/// `None` when the point is behind the camera.
#[inline]
pub fn chi2(cam: &StereoCamera, pc: &Vector3<f64>, z: &Measurement) -> Option<f64> {
    linearise(cam, pc, z).map(|l| l.r.norm_squared() * z.inv_sigma2)
}

/// Huber kernel on a χ² value `s` with threshold `delta2` (= δ²): cost and IRLS weight.
#[inline]
fn huber(s: f64, delta2: f64) -> (f64, f64) {
    if s <= delta2 {
        (s, 1.0)
    } else {
        let e = math::sqrt(s);
        let d = math::sqrt(delta2);
        (2.0 * d * e - delta2, d / e)
    }
}

/// One observation for motion-only pose optimisation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseObs {
    /// The landmark's world position (m); held fixed.
    pub p_w: Vector3<f64>,
    /// Where it was measured.
    pub z: Measurement,
    /// Association weight in `[0, 1]` (1 for hard association).
    pub weight: f64,
}

/// Settings of [`optimize_pose`]; the defaults are ORB-SLAM2's `PoseOptimization`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseOptParams {
    /// Outlier-classification rounds.
    pub rounds: u8,
    /// Gauss-Newton iterations per round.
    pub iterations: u8,
    /// The round from which the robust kernel is switched off (inliers are clean by then).
    pub robust_until_round: u8,
}

impl Default for PoseOptParams {
    fn default() -> Self {
        Self { rounds: 4, iterations: 10, robust_until_round: 2 }
    }
}

/// What [`optimize_pose`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PoseOptReport {
    /// Observations classified as inliers at the end.
    pub inliers: u32,
    /// Gauss-Newton iterations run, over all rounds.
    pub iterations: u32,
    /// Weighted χ² sum over inliers at the end.
    pub chi2: f64,
}

/// Motion-only pose optimisation: refines `t_cw` against fixed landmarks, classifying each
/// observation as inlier/outlier by χ² after each round (`outlier[i]` is read as the initial
/// state and written with the final one; its length must equal `obs.len()`, extra entries on
/// either side are ignored). Observations with zero weight take no part.
pub fn optimize_pose(
    cam: &StereoCamera,
    t_cw: &mut Se3,
    obs: &[PoseObs],
    outlier: &mut [bool],
    params: &PoseOptParams,
) -> PoseOptReport {
    let n = obs.len().min(outlier.len());
    let mut report = PoseOptReport::default();
    for round in 0..params.rounds {
        let robust = round < params.robust_until_round;
        for _ in 0..params.iterations {
            let mut h = SMatrix::<f64, 6, 6>::zeros();
            let mut g = Vector6::zeros();
            let mut used = 0u32;
            for (o, &out) in obs[..n].iter().zip(outlier[..n].iter()) {
                if out || !(o.weight > 0.0) {
                    continue;
                }
                let pc = t_cw.transform_point(&o.p_w);
                let Some(l) = linearise(cam, &pc, &o.z) else { continue };
                let s = l.r.norm_squared() * o.z.inv_sigma2;
                let rw = if robust { huber(s, o.z.chi2_threshold()).1 } else { 1.0 };
                let w = o.weight * o.z.inv_sigma2 * rw;
                let j = times_point_pose_jacobian(&l.j_pc, &pc);
                h += j.transpose() * j * w;
                g += j.transpose() * l.r * w;
                used += 1;
            }
            report.iterations += 1;
            if used < 3 {
                break;
            }
            let Some(delta) = solve6(&h, &g) else { break };
            *t_cw = t_cw.retract(&delta);
            if delta.norm_squared() < 1e-12 {
                break;
            }
        }
        // Re-classify every observation, including earlier outliers (they may come back).
        report.inliers = 0;
        report.chi2 = 0.0;
        for (o, out) in obs[..n].iter().zip(outlier[..n].iter_mut()) {
            if !(o.weight > 0.0) {
                *out = true;
                continue;
            }
            let pc = t_cw.transform_point(&o.p_w);
            match chi2(cam, &pc, &o.z) {
                Some(s) if s <= o.z.chi2_threshold() => {
                    *out = false;
                    report.inliers += 1;
                    report.chi2 += s * o.weight;
                }
                _ => *out = true,
            }
        }
        if report.inliers < 10 {
            break;
        }
    }
    report
}

/// Solves a 6x6 symmetric positive definite system by Cholesky; `None` if it is not.
fn solve6(h: &SMatrix<f64, 6, 6>, g: &Vector6<f64>) -> Option<Vector6<f64>> {
    let mut a = *h;
    let mut b = *g;
    if cholesky_solve_in_place(a.as_mut_slice(), 6, 6, b.as_mut_slice()) {
        Some(b)
    } else {
        None
    }
}

/// In-place Cholesky solve of the leading `n`x`n` block of a column-major `ld`x`ld` matrix.
/// Overwrites `a` with the factor and `b` with the solution; false if not positive definite.
/// Written out (rather than nalgebra's `Cholesky`) so the 60x60 BA system is factored where it
/// lies, with no second copy on the stack. Reads only the lower triangle (row ≥ column):
/// `build_reduced` forms only that half.
fn cholesky_solve_in_place(a: &mut [f64], ld: usize, n: usize, b: &mut [f64]) -> bool {
    let at = |r: usize, c: usize| c * ld + r;
    for j in 0..n {
        let mut d = a[at(j, j)];
        for k in 0..j {
            d -= a[at(j, k)] * a[at(j, k)];
        }
        if !(d > 1e-12) {
            return false;
        }
        let d = math::sqrt(d);
        a[at(j, j)] = d;
        for i in (j + 1)..n {
            let mut s = a[at(i, j)];
            for k in 0..j {
                s -= a[at(i, k)] * a[at(j, k)];
            }
            a[at(i, j)] = s / d;
        }
    }
    // L y = b
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[at(i, k)] * b[k];
        }
        b[i] = s / a[at(i, i)];
    }
    // Lᵀ x = y
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in (i + 1)..n {
            s -= a[at(k, i)] * b[k];
        }
        b[i] = s / a[at(i, i)];
    }
    true
}

/// One observation in a BA problem. Observations of one point must be contiguous in the
/// slice handed to [`bundle_adjust`] (sorted by `point`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaObs {
    /// Index of the observing keyframe in the pose slice.
    pub kf: u8,
    /// Index of the observed point in the point slice.
    pub point: u32,
    /// The measurement.
    pub z: Measurement,
    /// Association weight in `[0, 1]`; 0 excludes the observation (an outlier).
    pub weight: f64,
}

/// Settings of [`bundle_adjust`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaParams {
    /// Levenberg-Marquardt iterations at most.
    pub iterations: u8,
    /// Use the Huber kernel.
    pub robust: bool,
}

impl Default for BaParams {
    fn default() -> Self {
        Self { iterations: 10, robust: true }
    }
}

/// Scratch storage of [`bundle_adjust`]: the reduced camera system. Keep one in the tracker
/// (it is 29 KiB) rather than on an embedded stack.
pub struct BaScratch {
    s: SMatrix<f64, NP, NP>,
    g: SVector<f64, NP>,
}

impl BaScratch {
    /// A zeroed scratch.
    pub fn new() -> Self {
        Self { s: SMatrix::zeros(), g: SVector::zeros() }
    }
}

impl Default for BaScratch {
    fn default() -> Self {
        Self::new()
    }
}

/// Why [`bundle_adjust`] refused a problem (nothing is changed then).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BaError {
    /// More poses than [`MAX_WINDOW`].
    TooManyPoses {
        /// Poses given.
        got: usize,
    },
    /// The point backup slice is shorter than the point slice.
    BackupTooSmall {
        /// Points in the problem.
        need: usize,
        /// Backup length.
        got: usize,
    },
    /// An observation names a pose or point outside the slices.
    BadIndex {
        /// Position of the observation.
        obs: usize,
    },
    /// Observations of one point are not contiguous.
    NotGrouped {
        /// Position of the observation that broke the grouping.
        obs: usize,
    },
}

impl core::fmt::Display for BaError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::TooManyPoses { got } => {
                write!(f, "bundle adjustment given {got} poses, capacity is {MAX_WINDOW}")
            }
            Self::BackupTooSmall { need, got } => {
                write!(f, "point backup holds {got} points, problem has {need}")
            }
            Self::BadIndex { obs } => {
                write!(f, "observation {obs} names a pose or point outside the problem")
            }
            Self::NotGrouped { obs } => {
                write!(f, "observation {obs} breaks the grouping of observations by point")
            }
        }
    }
}

impl core::error::Error for BaError {}

/// What [`bundle_adjust`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BaReport {
    /// Robust cost before.
    pub initial_cost: f64,
    /// Robust cost after.
    pub final_cost: f64,
    /// Iterations run.
    pub iterations: u32,
    /// Accepted steps.
    pub accepted: u32,
}

/// Sliding-window bundle adjustment (Levenberg-Marquardt, Schur complement on points).
///
/// `poses[..fixed]` are held (gauge and the window's anchor); the rest and every point that
/// has an invertible information block are refined. Points observed only in fixed poses move;
/// points with a singular block (e.g. one monocular observation) are held.
#[allow(clippy::too_many_arguments)] // each slice is separate caller-owned fixed storage
pub fn bundle_adjust(
    cam: &StereoCamera,
    poses: &mut [Se3],
    fixed: usize,
    points: &mut [Vector3<f64>],
    obs: &[BaObs],
    backup: &mut [Vector3<f64>],
    scratch: &mut BaScratch,
    params: &BaParams,
) -> Result<BaReport, BaError> {
    if poses.len() > MAX_WINDOW {
        return Err(BaError::TooManyPoses { got: poses.len() });
    }
    if backup.len() < points.len() {
        return Err(BaError::BackupTooSmall { need: points.len(), got: backup.len() });
    }
    // Validate indices and grouping once, so the loops below cannot index out of range.
    let mut prev: Option<u32> = None;
    for (i, o) in obs.iter().enumerate() {
        if usize::from(o.kf) >= poses.len() || o.point as usize >= points.len() {
            return Err(BaError::BadIndex { obs: i });
        }
        if let Some(p) = prev {
            if o.point != p && o.point < p {
                return Err(BaError::NotGrouped { obs: i });
            }
        }
        prev = Some(o.point);
    }
    let fixed = fixed.min(poses.len());
    let nfree = poses.len() - fixed;
    let dim = 6 * nfree;
    let mut pose_backup = [Se3::identity(); MAX_WINDOW];
    let mut report = BaReport {
        initial_cost: total_cost(cam, poses, points, obs, params),
        ..Default::default()
    };
    let mut cost = report.initial_cost;
    let mut lambda = 1e-4;
    for _ in 0..params.iterations {
        report.iterations += 1;
        crate::arch::v3(
            #[inline(always)]
            || build_reduced(cam, poses, fixed, points, obs, scratch, params, lambda),
        );
        let ok = {
            let (s, g) = (scratch.s.as_mut_slice(), scratch.g.as_mut_slice());
            dim == 0 || cholesky_solve_in_place(s, NP, dim, g)
        };
        if !ok {
            lambda *= 10.0;
            continue;
        }
        // Save, apply the pose step, back-substitute the points.
        pose_backup[..poses.len()].copy_from_slice(poses);
        backup[..points.len()].copy_from_slice(points);
        for k in 0..nfree {
            let d = Vector6::from_column_slice(&scratch.g.as_slice()[6 * k..6 * k + 6]);
            poses[fixed + k] = poses[fixed + k].retract(&d);
        }
        let step_norm2 = scratch.g.rows(0, dim).norm_squared();
        // Through `v3` like `build_reduced`: the same bits, wider lanes.
        crate::arch::v3(
            #[inline(always)]
            || back_substitute(cam, &pose_backup, fixed, points, obs, scratch, params, lambda),
        );
        let new_cost = total_cost(cam, poses, points, obs, params);
        if new_cost < cost {
            cost = new_cost;
            report.accepted += 1;
            lambda = (lambda * 0.1).max(1e-9);
            if step_norm2 < 1e-14 {
                break;
            }
        } else {
            poses.copy_from_slice(&pose_backup[..poses.len()]);
            points.copy_from_slice(&backup[..points.len()]);
            lambda *= 10.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    report.final_cost = cost;
    Ok(report)
}

/// Robust, weighted cost of the whole problem.
fn total_cost(
    cam: &StereoCamera,
    poses: &[Se3],
    points: &[Vector3<f64>],
    obs: &[BaObs],
    params: &BaParams,
) -> f64 {
    let mut c = 0.0;
    for o in obs {
        if !(o.weight > 0.0) {
            continue;
        }
        let pc = poses[usize::from(o.kf)].transform_point(&points[o.point as usize]);
        let s = match chi2(cam, &pc, &o.z) {
            Some(s) => s,
            // Behind the camera: charge the threshold so a step that flips a point is not free.
            None => o.z.chi2_threshold() * 4.0,
        };
        let rho = if params.robust { huber(s, o.z.chi2_threshold()).0 } else { s };
        c += o.weight * rho;
    }
    c
}

/// Linear terms of one observation: pose Jacobian (3x6), point Jacobian (3x3), residual, weight.
type ObsTerms = (Matrix3x6<f64>, Matrix3<f64>, Vector3<f64>, f64);

/// Per-observation linear terms, or `None` if the observation is unusable.
#[inline(always)]
fn obs_terms(
    cam: &StereoCamera,
    pose: &Se3,
    p_w: &Vector3<f64>,
    o: &BaObs,
    params: &BaParams,
) -> Option<ObsTerms> {
    if !(o.weight > 0.0) {
        return None;
    }
    let pc = pose.transform_point(p_w);
    let l = linearise(cam, &pc, &o.z)?;
    let s = l.r.norm_squared() * o.z.inv_sigma2;
    let rw = if params.robust { huber(s, o.z.chi2_threshold()).1 } else { 1.0 };
    let w = o.weight * o.z.inv_sigma2 * rw;
    Some((times_point_pose_jacobian(&l.j_pc, &pc), l.j_pc * pose.rot, l.r, w))
}

/// The groups of observations sharing a point, as `(point, start, end)`.
fn groups(obs: &[BaObs]) -> impl Iterator<Item = (u32, usize, usize)> + '_ {
    let mut start = 0;
    core::iter::from_fn(move || {
        if start >= obs.len() {
            return None;
        }
        let p = obs[start].point;
        let mut end = start + 1;
        while end < obs.len() && obs[end].point == p {
            end += 1;
        }
        let g = (p, start, end);
        start = end;
        Some(g)
    })
}

/// The damped point block `H_ll` and gradient `b_l` of one point; `None` if not invertible.
/// `terms[i]`, where `terms` is long enough, receives observation `i`'s linear terms (`None`
/// where it is unusable) for the caller to reuse: linearising is most of the work.
#[inline(always)]
fn point_block(
    cam: &StereoCamera,
    poses: &[Se3],
    p_w: &Vector3<f64>,
    group: &[BaObs],
    params: &BaParams,
    lambda: f64,
    terms: &mut [Option<ObsTerms>],
) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let mut hll = Matrix3::zeros();
    let mut bl = Vector3::zeros();
    for (i, o) in group.iter().enumerate() {
        let t = obs_terms(cam, &poses[usize::from(o.kf)], p_w, o, params);
        if let Some(slot) = terms.get_mut(i) {
            *slot = t;
        }
        if let Some((_, jl, r, w)) = t {
            hll += jl.transpose() * jl * w;
            bl += jl.transpose() * r * w;
        }
    }
    for i in 0..3 {
        hll[(i, i)] += lambda * hll[(i, i)].max(1e-6);
    }
    let inv = hll.try_inverse()?;
    // A block that is numerically singular (a point seen once, monocular) stays fixed.
    if !(hll.determinant() > 1e-18) || !inv.iter().all(|x| x.is_finite()) {
        return None;
    }
    Some((inv, bl))
}

/// Builds the damped reduced camera system `S δp = g` into `scratch`. Called through
/// [`crate::arch::v3`]: the Schur products ([`product_block`]) are its hot loop, and AVX2's four
/// `f64` lanes take them without changing a bit (no FMA, no reassociation).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn build_reduced(
    cam: &StereoCamera,
    poses: &[Se3],
    fixed: usize,
    points: &[Vector3<f64>],
    obs: &[BaObs],
    scratch: &mut BaScratch,
    params: &BaParams,
    lambda: f64,
) {
    let nfree = poses.len() - fixed;
    scratch.s.fill(0.0);
    scratch.g.fill(0.0);
    let free = |kf: u8| usize::from(kf).checked_sub(fixed);
    // Per point: the free poses observing it and their H_lp blocks (one observation per pose
    // and point), so the Schur correction touches only those pose pairs. Each observation is
    // linearised once.
    let mut idx = [0usize; MAX_WINDOW];
    let mut hpl = [Matrix3x6::<f64>::zeros(); MAX_WINDOW];
    for (p, start, end) in groups(obs) {
        let group = &obs[start..end];
        let p_w = points[p as usize];
        let mut hll = Matrix3::<f64>::zeros();
        let mut bl = Vector3::<f64>::zeros();
        let mut n_seen = 0usize;
        for o in group {
            let Some((jp, jl, r, w)) = obs_terms(cam, &poses[usize::from(o.kf)], &p_w, o, params)
            else {
                continue;
            };
            let jlt_w = jl.transpose() * w;
            hll += jlt_w * jl;
            bl += jlt_w * r;
            let Some(a) = free(o.kf) else { continue };
            let jpt_w = jp.transpose() * w;
            product_block::<false>(&mut scratch.s, a, a, &jpt_w, &jp);
            let gp = jpt_w * r;
            for i in 0..6 {
                scratch.g[6 * a + i] += gp[i];
            }
            let h = jlt_w * jp;
            match idx[..n_seen].iter().position(|&x| x == a) {
                Some(k) => hpl[k] += h,
                None if n_seen < MAX_WINDOW => {
                    idx[n_seen] = a;
                    hpl[n_seen] = h;
                    n_seen += 1;
                }
                None => {}
            }
        }
        for i in 0..3 {
            hll[(i, i)] += lambda * hll[(i, i)].max(1e-6);
        }
        // A block that is numerically singular (a point seen once, monocular) stays fixed.
        let Some(hll_inv) = hll.try_inverse() else { continue };
        if !(hll.determinant() > 1e-18) || !hll_inv.iter().all(|x| x.is_finite()) {
            continue;
        }
        // S -= H_pl H_ll⁻¹ H_lp ; g -= H_pl H_ll⁻¹ b_l. S is symmetric and the solver reads
        // only its lower triangle, so only the blocks (a, b) with b ≤ a are formed.
        for ka in 0..n_seen {
            let a = idx[ka];
            let ha = hpl[ka].transpose() * hll_inv; // 6x3
            let ga = ha * bl;
            for i in 0..6 {
                scratch.g[6 * a + i] -= ga[i];
            }
            for kb in 0..n_seen {
                if idx[kb] <= a {
                    product_block::<true>(&mut scratch.s, a, idx[kb], &ha, &hpl[kb]);
                }
            }
        }
    }
    for i in 0..6 * nfree {
        let d = scratch.s[(i, i)];
        scratch.s[(i, i)] = d + lambda * d.max(1e-6);
    }
}

/// `S[a, b] -= ha * h` (`SUB`) or `+=` for one 6×6 block, without forming the product: the
/// Schur complement's inner step, once per pair of poses that see a point. Each entry is summed
/// in the order nalgebra's product sums it (`((ha₀h₀ + ha₁h₁) + ha₂h₂)`), so the result is the
/// same bits.
#[inline(always)]
fn product_block<const SUB: bool>(
    s: &mut SMatrix<f64, NP, NP>,
    a: usize,
    b: usize,
    ha: &Matrix6x3<f64>,
    h: &Matrix3x6<f64>,
) {
    let data = s.as_mut_slice();
    for c in 0..6 {
        let (h0, h1, h2) = (h[(0, c)], h[(1, c)], h[(2, c)]);
        // Column-major: column 6b + c, rows 6a..6a + 6.
        let col = &mut data[(6 * b + c) * NP + 6 * a..][..6];
        for (r, x) in col.iter_mut().enumerate() {
            let m = ha[(r, 0)] * h0 + ha[(r, 1)] * h1 + ha[(r, 2)] * h2;
            if SUB {
                *x -= m;
            } else {
                *x += m;
            }
        }
    }
}

/// Point update after the pose step: `δl = H_ll⁻¹ (b_l − H_lp δp)`, linearised at the old
/// poses (`old_poses`), with the solved pose steps in `scratch.g`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn back_substitute(
    cam: &StereoCamera,
    old_poses: &[Se3],
    fixed: usize,
    points: &mut [Vector3<f64>],
    obs: &[BaObs],
    scratch: &BaScratch,
    params: &BaParams,
    lambda: f64,
) {
    let poses = old_poses;
    // Each group's linear terms, written by `point_block` for its first `MAX_WINDOW`
    // observations. A point has at most one observation per pose, so a group fits; a longer
    // one (a caller's) has the rest linearised again below.
    let mut terms = [None; MAX_WINDOW];
    for (p, start, end) in groups(obs) {
        let group = &obs[start..end];
        let p_w = points[p as usize];
        let Some((hll_inv, mut rhs)) =
            point_block(cam, poses, &p_w, group, params, lambda, &mut terms)
        else {
            continue;
        };
        for (i, o) in group.iter().enumerate() {
            let Some(a) = usize::from(o.kf).checked_sub(fixed) else { continue };
            if a >= MAX_WINDOW {
                continue;
            }
            let t = if i < MAX_WINDOW {
                terms[i]
            } else {
                obs_terms(cam, &poses[usize::from(o.kf)], &p_w, o, params)
            };
            let Some((jp, jl, _, w)) = t else {
                continue;
            };
            let d = Vector6::from_column_slice(&scratch.g.as_slice()[6 * a..6 * a + 6]);
            rhs -= jl.transpose() * jp * d * w;
        }
        points[p as usize] = p_w + hll_inv * rhs;
    }
}

#[cfg(test)]
mod tests;
