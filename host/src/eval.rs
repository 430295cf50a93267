//! Trajectory evaluation: KITTI devkit t_rel/r_rel, Umeyama-aligned ATE and evo's RPE.
//!
//! # KITTI relative error (t_rel, r_rel)
//! A re-implementation of `calcSequenceErrors` in the KITTI odometry devkit's
//! `evaluate_odometry.cpp`:
//! * cumulative distance along the **ground truth** (`trajectoryDistances`), kept in `f32` and
//!   accumulated with the same roundings as the devkit so segment ends are chosen identically;
//! * segment lengths 100, 200, …, 800 m, first frames every 10 frames (`step_size = 10`);
//! * last frame = first `i >= first` with `dist[i] > dist[first] + len`
//!   (`lastFrameFromSegmentLength`); segments with no such frame are skipped;
//! * `E = (P_first⁻¹ P_last)⁻¹ (G_first⁻¹ G_last)` with general 4x4 inverses like the devkit's
//!   `Matrix::inv`; `r = acos(clamp(0.5 (tr R_E − 1), −1, 1)) / len`, `t = ‖t_E‖ / len`;
//! * the sequence figures are the means over all segments: t_rel in %, r_rel in deg/100 m.
//!
//! The errors themselves are computed in `f64` (the devkit rounds them to `f32`), which changes
//! results only far below the 3 significant digits that are reported.
//!
//! # RPE
//! The relative pose error of `evo_rpe` without alignment (evo v1.38.1, `core/metrics.py` `RPE`):
//! pairs `(i, j)` chosen on the **estimate** ([`rpe_pairs`]: every Δ frames, or each time the
//! estimate has travelled Δ metres since the last chosen frame), the error
//! `E = (Q_i⁻¹Q_j)⁻¹(P_i⁻¹P_j)` of the ground truth `Q` and estimate `P`, its translation
//! `‖t(E)‖` (m) and the angle of `R(E)` (deg, [`rotation_angle`] as scipy gets it), plus the
//! translation as a share of the ground-truth path between `i` and `j` (%). Relative errors
//! need no alignment, and the pairs do not depend on the ground truth's scale. [`evaluate`]
//! reports Δ = 1 frame and Δ = 10 m.
//!
//! # ATE
//! Estimated positions are aligned to ground-truth positions with Umeyama's method
//! ([`Align::Se3`]: rotation + translation like `evo_ape kitti -a`; [`Align::Sim3`]: also scale,
//! like `-as`; [`Align::None`]), then the translation error of every pose is summarised as
//! RMSE, mean, median and max (evo's APE on the translation part).
//!
//! Both trajectories must have the same number of poses (frame `i` of one is frame `i` of the
//! other), as the devkit requires; otherwise [`EvalError::LengthMismatch`]. Callers that want to
//! evaluate a prefix can slice both inputs to the shorter length themselves.

use core::fmt;
use core::str::FromStr;

use nalgebra::{Matrix3, Matrix4, Vector3};
use semloc_core::geom::Se3;
use serde::Serialize;

/// Segment lengths of the KITTI devkit in metres.
pub const KITTI_LENGTHS: [f64; 8] = [100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0];
/// The devkit's spacing of first frames (every 10 frames, one second at 10 Hz).
pub const KITTI_STEP: usize = 10;

/// An evaluation error.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum EvalError {
    /// The two trajectories have different numbers of poses.
    #[error(
        "ground truth has {gt} poses but the estimate has {est}; they must match frame for frame"
    )]
    LengthMismatch {
        /// Ground-truth pose count.
        gt: usize,
        /// Estimated pose count.
        est: usize,
    },
    /// There are no poses.
    #[error("empty trajectory")]
    Empty,
    /// The estimated positions do not span a plane, so Umeyama alignment is undefined
    /// (the same condition on which evo refuses to align).
    #[error("degenerate point set: Umeyama alignment needs positions spanning at least a plane")]
    DegenerateAlignment,
    /// The positions are so large that their spread overflows `f64` (a diverged estimate), so
    /// no alignment can be computed.
    #[error(
        "positions too large to align: their spread overflows f64 (|x| near 1e150 m or more; a \
         diverged estimate?)"
    )]
    Overflow,
    /// An RPE delta of 0 frames, or a negative or non-finite distance.
    #[error("RPE delta must be at least 1 frame or a finite, non-negative distance")]
    InvalidDelta,
}

/// How the estimate is aligned to the ground truth before the ATE.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Align {
    /// No alignment: both trajectories are taken in their own (shared) world frame.
    None,
    /// Rotation and translation (Umeyama without scale), like `evo_ape -a`.
    #[default]
    Se3,
    /// Rotation, translation and scale (Umeyama with scale), like `evo_ape -as`.
    Sim3,
}

impl fmt::Display for Align {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Align::None => "none",
            Align::Se3 => "se3",
            Align::Sim3 => "sim3",
        })
    }
}

impl FromStr for Align {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "none" => Ok(Align::None),
            "se3" => Ok(Align::Se3),
            "sim3" => Ok(Align::Sim3),
            _ => Err(format!("unknown alignment {s:?} (expected se3, sim3 or none)")),
        }
    }
}

/// A similarity transform `p ↦ scale · rot · p + trans` (the result of an alignment).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Sim3 {
    /// Rotation matrix, row-major when serialised.
    #[serde(serialize_with = "ser_mat3")]
    pub rot: Matrix3<f64>,
    /// Translation in metres.
    #[serde(serialize_with = "ser_vec3")]
    pub trans: Vector3<f64>,
    /// Scale factor (1 unless aligned with [`Align::Sim3`]).
    pub scale: f64,
}

fn ser_mat3<S: serde::Serializer>(m: &Matrix3<f64>, s: S) -> Result<S::Ok, S::Error> {
    let rows: [[f64; 3]; 3] = core::array::from_fn(|r| core::array::from_fn(|c| m[(r, c)]));
    rows.serialize(s)
}

fn ser_vec3<S: serde::Serializer>(v: &Vector3<f64>, s: S) -> Result<S::Ok, S::Error> {
    [v.x, v.y, v.z].serialize(s)
}

impl Sim3 {
    /// The identity.
    pub fn identity() -> Self {
        Sim3 { rot: Matrix3::identity(), trans: Vector3::zeros(), scale: 1.0 }
    }

    /// Maps a point.
    pub fn apply_point(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.scale * (self.rot * p) + self.trans
    }

    /// Maps a pose (camera-to-world): rotates its orientation, maps its position.
    pub fn apply_pose(&self, pose: &Se3) -> Se3 {
        Se3::new(self.rot * pose.rot, self.apply_point(&pose.trans))
    }
}

/// Umeyama's least-squares similarity: the `Sim3` minimising `Σ ‖dst_i − (s R src_i + t)‖²`
/// (scale fixed to 1 unless `with_scale`). Uses a 3x3 SVD with the reflection fix, in `f64`.
///
/// Fails with [`EvalError::DegenerateAlignment`] when the cross-covariance has rank < 2
/// (fewer than three non-collinear points), [`EvalError::Overflow`] when the positions' spread
/// overflows `f64`, and [`EvalError::LengthMismatch`] / [`EvalError::Empty`].
pub fn umeyama(
    src: &[Vector3<f64>],
    dst: &[Vector3<f64>],
    with_scale: bool,
) -> Result<Sim3, EvalError> {
    if src.len() != dst.len() {
        return Err(EvalError::LengthMismatch { gt: dst.len(), est: src.len() });
    }
    if src.is_empty() {
        return Err(EvalError::Empty);
    }
    let n = src.len() as f64;
    let mean_s = src.iter().sum::<Vector3<f64>>() / n;
    let mean_d = dst.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    let mut var_s = 0.0;
    for (s, d) in src.iter().zip(dst) {
        let (cs, cd) = (s - mean_s, d - mean_d);
        cov += cd * cs.transpose();
        var_s += cs.norm_squared();
    }
    cov /= n;
    var_s /= n;
    if !(var_s.is_finite() && cov.iter().all(|x| x.is_finite())) {
        return Err(EvalError::Overflow);
    }
    let svd = cov.svd(true, true);
    let (u, v_t) = match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => (u, v_t),
        _ => return Err(EvalError::DegenerateAlignment),
    };
    let d = svd.singular_values;
    if d.iter().filter(|&&x| x > f64::EPSILON).count() < 2 {
        return Err(EvalError::DegenerateAlignment);
    }
    let mut sign = Vector3::new(1.0, 1.0, 1.0);
    if u.determinant() * v_t.determinant() < 0.0 {
        // Flip the direction of the smallest singular value.
        sign[d.imin()] = -1.0;
    }
    let rot = u * Matrix3::from_diagonal(&sign) * v_t;
    let scale = if with_scale { d.dot(&sign) / var_s } else { 1.0 };
    let trans = mean_d - scale * (rot * mean_s);
    Ok(Sim3 { rot, trans, scale })
}

/// The KITTI devkit's error record for one segment (`errors` in `evaluate_odometry.cpp`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SegmentError {
    /// First frame of the segment.
    pub first_frame: usize,
    /// Last frame of the segment.
    pub last_frame: usize,
    /// Rotation error per metre (rad/m).
    pub r_err: f64,
    /// Translation error per metre (m/m).
    pub t_err: f64,
    /// Segment length (m).
    pub len: f64,
    /// Speed (m/s) as the devkit computes it: `len / (0.1 · (last − first + 1))`.
    pub speed: f64,
}

/// Cumulative distance along a trajectory as the devkit computes it (`trajectoryDistances`):
/// `f32` storage, each step added in `f64` then rounded.
pub fn trajectory_distances_f32(poses: &[Se3]) -> Vec<f32> {
    let mut dist = Vec::with_capacity(poses.len());
    if poses.is_empty() {
        return dist;
    }
    dist.push(0.0f32);
    for w in poses.windows(2) {
        let step = (w[0].trans - w[1].trans).norm();
        let prev = *dist.last().unwrap_or(&0.0) as f64;
        dist.push((prev + step) as f32);
    }
    dist
}

/// Cumulative distance along a trajectory in `f64` (for reporting and plots).
pub fn trajectory_distances(poses: &[Se3]) -> Vec<f64> {
    let mut acc = 0.0;
    let mut out = Vec::with_capacity(poses.len());
    for (i, p) in poses.iter().enumerate() {
        if i > 0 {
            acc += (p.trans - poses[i - 1].trans).norm();
        }
        out.push(acc);
    }
    out
}

/// The devkit's `lastFrameFromSegmentLength`: the first frame `i >= first` whose distance
/// exceeds `dist[first] + len` (compared in `f32`), or `None`.
pub fn last_frame_from_segment_length(dist: &[f32], first: usize, len: f32) -> Option<usize> {
    let target = dist.get(first)? + len;
    (first..dist.len()).find(|&i| dist[i] > target)
}

fn to_mat4(p: &Se3) -> Matrix4<f64> {
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 4>(0, 0).copy_from(&p.to_matrix3x4());
    m
}

/// General 4x4 inverse like the devkit's `Matrix::inv` (falls back to the rigid inverse for a
/// singular matrix, which a pose never is).
fn inv4(m: &Matrix4<f64>) -> Matrix4<f64> {
    m.try_inverse().unwrap_or_else(|| {
        let r = m.fixed_view::<3, 3>(0, 0).transpose();
        let t = -(r * m.fixed_view::<3, 1>(0, 3));
        let mut out = Matrix4::identity();
        out.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
        out.fixed_view_mut::<3, 1>(0, 3).copy_from(&t);
        out
    })
}

/// All devkit segment errors of one sequence (`calcSequenceErrors`).
pub fn segment_errors(gt: &[Se3], est: &[Se3]) -> Result<Vec<SegmentError>, EvalError> {
    check_lengths(gt, est)?;
    let dist = trajectory_distances_f32(gt);
    let gt4: Vec<Matrix4<f64>> = gt.iter().map(to_mat4).collect();
    let est4: Vec<Matrix4<f64>> = est.iter().map(to_mat4).collect();
    let mut out = Vec::new();
    for first in (0..gt.len()).step_by(KITTI_STEP) {
        let (gi, ei) = (inv4(&gt4[first]), inv4(&est4[first]));
        for &len in &KITTI_LENGTHS {
            let Some(last) = last_frame_from_segment_length(&dist, first, len as f32) else {
                continue;
            };
            let delta_gt = gi * gt4[last];
            let delta_est = ei * est4[last];
            let e = inv4(&delta_est) * delta_gt;
            let d = 0.5 * (e[(0, 0)] + e[(1, 1)] + e[(2, 2)] - 1.0);
            let r_err = d.clamp(-1.0, 1.0).acos();
            let t_err = e.fixed_view::<3, 1>(0, 3).norm();
            let num_frames = (last - first + 1) as f64;
            out.push(SegmentError {
                first_frame: first,
                last_frame: last,
                r_err: r_err / len,
                t_err: t_err / len,
                len,
                speed: len / (0.1 * num_frames),
            });
        }
    }
    Ok(out)
}

fn check_lengths(gt: &[Se3], est: &[Se3]) -> Result<(), EvalError> {
    if gt.len() != est.len() {
        return Err(EvalError::LengthMismatch { gt: gt.len(), est: est.len() });
    }
    if gt.is_empty() {
        return Err(EvalError::Empty);
    }
    Ok(())
}

/// rad/m → deg/100 m.
const RAD_PER_M_TO_DEG_PER_100M: f64 = 180.0 / core::f64::consts::PI * 100.0;

/// Mean t_rel (%) and r_rel (deg/100 m) over segments; `None` when there are none.
pub fn kitti_means(segments: &[SegmentError]) -> Option<(f64, f64)> {
    if segments.is_empty() {
        return None;
    }
    let n = segments.len() as f64;
    let t = segments.iter().map(|s| s.t_err).sum::<f64>() / n;
    let r = segments.iter().map(|s| s.r_err).sum::<f64>() / n;
    Some((t * 100.0, r * RAD_PER_M_TO_DEG_PER_100M))
}

/// Devkit errors averaged over the segments of one length.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LengthStats {
    /// Segment length (m).
    pub length_m: f64,
    /// Number of segments of this length.
    pub n_segments: usize,
    /// Mean translation error (%).
    pub t_rel_pct: f64,
    /// Mean rotation error (deg/100 m).
    pub r_rel_deg_per_100m: f64,
}

/// Per-length averages (only lengths that have at least one segment), in increasing length.
pub fn per_length(segments: &[SegmentError]) -> Vec<LengthStats> {
    KITTI_LENGTHS
        .iter()
        .filter_map(|&len| {
            let segs: Vec<SegmentError> =
                segments.iter().copied().filter(|s| s.len == len).collect();
            kitti_means(&segs).map(|(t, r)| LengthStats {
                length_m: len,
                n_segments: segs.len(),
                t_rel_pct: t,
                r_rel_deg_per_100m: r,
            })
        })
        .collect()
}

/// Absolute trajectory error after alignment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Ate {
    /// The alignment used.
    pub align: Align,
    /// The similarity that maps the estimate onto the ground truth.
    pub alignment: Sim3,
    /// Root mean square translation error (m).
    pub rmse_m: f64,
    /// Mean translation error (m).
    pub mean_m: f64,
    /// Median translation error (m) (mean of the two middle values for an even count).
    pub median_m: f64,
    /// Largest translation error (m).
    pub max_m: f64,
    /// Per-pose translation errors (m), frame order.
    #[serde(skip)]
    pub errors_m: Vec<f64>,
    /// The estimate after alignment, frame order.
    #[serde(skip)]
    pub aligned_est: Vec<Se3>,
}

/// Aligns `est` to `gt` as `align` says and measures the translation error of every pose.
pub fn ate(gt: &[Se3], est: &[Se3], align: Align) -> Result<Ate, EvalError> {
    check_lengths(gt, est)?;
    let src: Vec<Vector3<f64>> = est.iter().map(|p| p.trans).collect();
    let dst: Vec<Vector3<f64>> = gt.iter().map(|p| p.trans).collect();
    let alignment = match align {
        Align::None => Sim3::identity(),
        Align::Se3 => umeyama(&src, &dst, false)?,
        Align::Sim3 => umeyama(&src, &dst, true)?,
    };
    let aligned_est: Vec<Se3> = est.iter().map(|p| alignment.apply_pose(p)).collect();
    let errors_m: Vec<f64> =
        aligned_est.iter().zip(gt).map(|(e, g)| (e.trans - g.trans).norm()).collect();
    let s = ErrorStats::of(&errors_m).ok_or(EvalError::Empty)?;
    Ok(Ate {
        align,
        alignment,
        rmse_m: s.rmse,
        mean_m: s.mean,
        median_m: s.median,
        max_m: s.max,
        errors_m,
        aligned_est,
    })
}

/// Summary statistics of a set of non-negative errors, as evo computes them (`numpy`'s
/// `sqrt(mean(e²))`, `mean`, `median`, `max`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorStats {
    /// Root mean square.
    pub rmse: f64,
    /// Mean.
    pub mean: f64,
    /// Median (mean of the two middle values for an even count, like `numpy.median`).
    pub median: f64,
    /// Largest value.
    pub max: f64,
}

impl ErrorStats {
    /// The statistics of `errors`; `None` when there are none.
    pub fn of(errors: &[f64]) -> Option<Self> {
        if errors.is_empty() {
            return None;
        }
        let n = errors.len() as f64;
        let rmse = (errors.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
        let mean = errors.iter().sum::<f64>() / n;
        let max = errors.iter().copied().fold(0.0, f64::max);
        let mut sorted = errors.to_vec();
        sorted.sort_by(f64::total_cmp);
        let mid = sorted.len() / 2;
        let median =
            if sorted.len() % 2 == 1 { sorted[mid] } else { 0.5 * (sorted[mid - 1] + sorted[mid]) };
        Some(ErrorStats { rmse, mean, median, max })
    }
}

/// How far apart the two poses of an RPE pair are.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RpeDelta {
    /// This many frames: pairs `(0, Δ), (Δ, 2Δ), …` (`evo_rpe --delta Δ --delta_unit f`).
    Frames(usize),
    /// This many metres travelled along the **estimate** (`evo_rpe --delta Δ --delta_unit m`,
    /// whose pairs come from the estimate unless `--pairs_from_reference`).
    Metres(f64),
}

/// The RPE over one frame that `semloc eval` reports.
pub const RPE_1_FRAME: RpeDelta = RpeDelta::Frames(1);
/// The RPE over 10 m that `semloc eval` reports.
pub const RPE_10_M: RpeDelta = RpeDelta::Metres(10.0);

impl fmt::Display for RpeDelta {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            RpeDelta::Frames(1) => f.write_str("1 frame"),
            RpeDelta::Frames(n) => write!(f, "{n} frames"),
            RpeDelta::Metres(m) => write!(f, "{m} m"),
        }
    }
}

/// The pairs `(i, j)` of evo's RPE with consecutive (not all) pairs, chosen on `est`:
/// `filter_pairs_by_index` for frames; `filter_pairs_by_path` for metres, which walks the
/// estimate, sums the steps since the last chosen frame and chooses frame `i` once that sum
/// reaches `Δ` (the overshoot is dropped: the sum restarts at 0).
///
/// Fails with [`EvalError::InvalidDelta`] for 0 frames or a negative / non-finite distance.
pub fn rpe_pairs(est: &[Se3], delta: RpeDelta) -> Result<Vec<(usize, usize)>, EvalError> {
    let ids: Vec<usize> = match delta {
        RpeDelta::Frames(0) => return Err(EvalError::InvalidDelta),
        RpeDelta::Frames(d) => (0..est.len()).step_by(d).collect(),
        RpeDelta::Metres(m) if !(m.is_finite() && m >= 0.0) => return Err(EvalError::InvalidDelta),
        RpeDelta::Metres(m) => {
            let mut ids = Vec::new();
            if !est.is_empty() {
                ids.push(0);
            }
            let mut path = 0.0;
            for (i, w) in est.windows(2).enumerate() {
                path += (w[1].trans - w[0].trans).norm();
                if path >= m {
                    ids.push(i + 1);
                    path = 0.0;
                }
            }
            ids
        }
    };
    Ok(ids.windows(2).map(|w| (w[0], w[1])).collect())
}

/// The rotation angle (rad, in `[0, π]`) of `m` as evo's `so3_log_angle` gets it from scipy's
/// `Rotation.from_matrix(m).as_rotvec()`: a matrix that is not orthogonal to numpy's
/// `isclose(m mᵀ, I, atol=1e-12)` is replaced by its nearest rotation (`U Vᵀ` of its SVD),
/// then Markley's quaternion, then `2 atan2(‖q_xyz‖, |q_w|)`.
///
/// The rounding of stored poses (KITTI files keep 7 digits) leaves their products non-orthogonal
/// by ~1e-7, as large as a one-frame rotation error; `acos((tr R − 1) / 2)` on the raw matrix
/// is then off by up to 20 % in the median on evo's KITTI 00 test pair.
pub fn rotation_angle(m: &Matrix3<f64>) -> f64 {
    let gram = m * m.transpose();
    // numpy.isclose(a, b) is |a − b| <= atol + rtol·|b| with the default rtol 1e-5.
    let orthogonal = (0..3).all(|r| {
        (0..3).all(|c| {
            let want = if r == c { 1.0 } else { 0.0 };
            (gram[(r, c)] - want).abs() <= 1e-12 + 1e-5 * want
        })
    });
    let r = if orthogonal {
        *m
    } else {
        let svd = m.svd(true, true);
        match (svd.u, svd.v_t) {
            (Some(u), Some(v_t)) => u * v_t,
            _ => *m,
        }
    };
    let tr = r[(0, 0)] + r[(1, 1)] + r[(2, 2)];
    let decision = [r[(0, 0)], r[(1, 1)], r[(2, 2)], tr];
    // numpy.argmax: the first of equal maxima.
    let choice = (1..4).fold(0, |best, k| if decision[k] > decision[best] { k } else { best });
    let q = match choice {
        0 => [
            1.0 - tr + 2.0 * r[(0, 0)],
            r[(1, 0)] + r[(0, 1)],
            r[(2, 0)] + r[(0, 2)],
            r[(2, 1)] - r[(1, 2)],
        ],
        1 => [
            r[(1, 0)] + r[(0, 1)],
            1.0 - tr + 2.0 * r[(1, 1)],
            r[(2, 1)] + r[(1, 2)],
            r[(0, 2)] - r[(2, 0)],
        ],
        2 => [
            r[(2, 0)] + r[(0, 2)],
            r[(2, 1)] + r[(1, 2)],
            1.0 - tr + 2.0 * r[(2, 2)],
            r[(1, 0)] - r[(0, 1)],
        ],
        _ => [r[(2, 1)] - r[(1, 2)], r[(0, 2)] - r[(2, 0)], r[(1, 0)] - r[(0, 1)], 1.0 + tr],
    };
    // The common scale of the quaternion cancels in atan2, so it needs no normalisation.
    let xyz = Vector3::new(q[0], q[1], q[2]).norm();
    2.0 * xyz.atan2(q[3].abs())
}

/// Relative pose error over one [`RpeDelta`], as `evo_rpe` without alignment computes it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Rpe {
    /// The distance between the two poses of a pair.
    pub delta: RpeDelta,
    /// Number of pairs.
    pub n_pairs: usize,
    /// Translation error `‖t(E)‖` (m), evo's `trans_part`.
    pub trans_m: ErrorStats,
    /// Translation error as a share of the ground-truth path between the two poses (%), over
    /// the pairs whose ground-truth path is not zero; `None` when none is (a standing vehicle).
    pub trans_pct: Option<ErrorStats>,
    /// Rotation error: the angle of `R(E)` (deg), evo's `angle_deg`.
    pub rot_deg: ErrorStats,
    /// The pairs `(i, j)`.
    #[serde(skip)]
    pub pairs: Vec<(usize, usize)>,
    /// Translation error per pair (m).
    #[serde(skip)]
    pub trans_errors_m: Vec<f64>,
    /// Rotation error per pair (deg).
    #[serde(skip)]
    pub rot_errors_deg: Vec<f64>,
}

/// The RPE of `est` against `gt` over `delta`: for every pair `(i, j)` of [`rpe_pairs`] the
/// error `E = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j)` (`Q` ground truth, `P` estimate, rigid inverses as
/// evo's `se3_inverse`), its translation `‖t(E)‖` and its [`rotation_angle`].
///
/// `Ok(None)` when the trajectory has no pair (shorter than `delta`); the usual
/// [`EvalError::LengthMismatch`] / [`EvalError::Empty`] and [`EvalError::InvalidDelta`].
pub fn rpe(gt: &[Se3], est: &[Se3], delta: RpeDelta) -> Result<Option<Rpe>, EvalError> {
    check_lengths(gt, est)?;
    let pairs = rpe_pairs(est, delta)?;
    let dist = trajectory_distances(gt);
    let (mut trans_errors_m, mut rot_errors_deg, mut pct) = (Vec::new(), Vec::new(), Vec::new());
    for &(i, j) in &pairs {
        let q = gt[i].inverse().compose(&gt[j]);
        let p = est[i].inverse().compose(&est[j]);
        let e = q.inverse().compose(&p);
        let t = e.trans.norm();
        let path_m = dist[j] - dist[i];
        if path_m > 0.0 {
            pct.push(100.0 * t / path_m);
        }
        trans_errors_m.push(t);
        rot_errors_deg.push(rotation_angle(&e.rot).to_degrees());
    }
    let (Some(trans_m), Some(rot_deg)) =
        (ErrorStats::of(&trans_errors_m), ErrorStats::of(&rot_errors_deg))
    else {
        return Ok(None);
    };
    Ok(Some(Rpe {
        delta,
        n_pairs: pairs.len(),
        trans_m,
        trans_pct: ErrorStats::of(&pct),
        rot_deg,
        pairs,
        trans_errors_m,
        rot_errors_deg,
    }))
}

/// Above this rotation (degrees) an alignment is suspicious and the evaluation warns: a
/// tracker's estimate and the ground truth both start at the first camera pose, so a good
/// estimate needs a few degrees at most; frames fed in reverse order, or a wrong world frame,
/// score a good ATE only through a large turn (about 180° for reversed frames).
pub const ALIGNMENT_WARN_DEG: f64 = 15.0;

/// The angle (degrees) by which `rot` turns the direction from `est`'s first to its last
/// position; the whole rotation's angle when that displacement is under 1 mm.
fn heading_turn_deg(est: &[Se3], rot: &Matrix3<f64>) -> f64 {
    let d = match (est.first(), est.last()) {
        (Some(a), Some(b)) => b.trans - a.trans,
        _ => Vector3::zeros(),
    };
    let n = d.norm();
    if n < 1e-3 {
        return rotation_angle(rot).to_degrees();
    }
    let u = d / n;
    (rot * u).dot(&u).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Everything `semloc eval` reports about one estimated trajectory.
///
/// Serialises to JSON with the summary, the per-length table, the ATE alignment and every
/// devkit segment; the per-frame distances and errors and the aligned trajectory are kept for
/// plots but skipped in JSON.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EvalReport {
    /// Number of poses in each trajectory.
    pub n_poses: usize,
    /// Ground-truth path length (m).
    pub path_length_m: f64,
    /// Number of devkit segments (0 when the path is shorter than 100 m).
    pub n_segments: usize,
    /// Devkit translation error (%), `None` without segments.
    pub t_rel_pct: Option<f64>,
    /// Devkit rotation error (deg/100 m), `None` without segments.
    pub r_rel_deg_per_100m: Option<f64>,
    /// Alignment mode of the ATE.
    pub align: Align,
    /// ATE RMSE (m).
    pub ate_rmse_m: f64,
    /// ATE mean (m).
    pub ate_mean_m: f64,
    /// ATE median (m).
    pub ate_median_m: f64,
    /// ATE max (m).
    pub ate_max_m: f64,
    /// The alignment that maps the estimate onto the ground truth.
    pub alignment: Sim3,
    /// The rotation angle of `alignment` (degrees). On a straight path the turn about the
    /// direction of travel is undetermined, so this can be large for a good estimate.
    pub alignment_rotation_deg: f64,
    /// How far `alignment` turns the estimate's direction of travel (first to last position;
    /// degrees; the full rotation when the estimate does not move): the figure the warning
    /// looks at, since it is determined even on a straight path.
    pub alignment_heading_deg: f64,
    /// What makes this evaluation suspect (e.g. an alignment rotation above
    /// [`ALIGNMENT_WARN_DEG`]); empty when nothing does.
    pub warnings: Vec<String>,
    /// Devkit errors per segment length.
    pub per_length: Vec<LengthStats>,
    /// Every devkit segment.
    pub segments: Vec<SegmentError>,
    /// RPE over one frame; `None` for a single pose.
    pub rpe_1f: Option<Rpe>,
    /// RPE over 10 m of the estimate's path; `None` when the estimate travels less than 10 m.
    pub rpe_10m: Option<Rpe>,
    /// Cumulative ground-truth distance at every frame (m), for plots.
    #[serde(skip)]
    pub gt_distances_m: Vec<f64>,
    /// ATE translation error at every frame (m).
    #[serde(skip)]
    pub ate_errors_m: Vec<f64>,
    /// The estimate after alignment (same frame as the ground truth).
    #[serde(skip)]
    pub aligned_est: Vec<Se3>,
}

/// Evaluates `est` against `gt` (same length, frame for frame): devkit t_rel/r_rel, the ATE
/// after `align` and the RPE over [`RPE_1_FRAME`] and [`RPE_10_M`] (never aligned).
pub fn evaluate(gt: &[Se3], est: &[Se3], align: Align) -> Result<EvalReport, EvalError> {
    let segments = segment_errors(gt, est)?;
    let a = ate(gt, est, align)?;
    let rpe_1f = rpe(gt, est, RPE_1_FRAME)?;
    let rpe_10m = rpe(gt, est, RPE_10_M)?;
    let gt_distances_m = trajectory_distances(gt);
    let means = kitti_means(&segments);
    let alignment_rotation_deg = rotation_angle(&a.alignment.rot).to_degrees();
    let alignment_heading_deg = heading_turn_deg(est, &a.alignment.rot);
    let mut warnings = Vec::new();
    if alignment_heading_deg > ALIGNMENT_WARN_DEG {
        warnings.push(format!(
            "the {align} alignment turns the estimate's direction of travel by \
             {alignment_heading_deg:.1}° to fit the ground truth (more than \
             {ALIGNMENT_WARN_DEG}°): the ATE is only this good after that turn. Frames in \
             reverse order, another sequence's ground truth or another world frame would do \
             this; check before trusting the ATE"
        ));
    }
    Ok(EvalReport {
        n_poses: gt.len(),
        path_length_m: gt_distances_m.last().copied().unwrap_or(0.0),
        n_segments: segments.len(),
        t_rel_pct: means.map(|m| m.0),
        r_rel_deg_per_100m: means.map(|m| m.1),
        align,
        ate_rmse_m: a.rmse_m,
        ate_mean_m: a.mean_m,
        ate_median_m: a.median_m,
        ate_max_m: a.max_m,
        alignment: a.alignment,
        alignment_rotation_deg,
        alignment_heading_deg,
        warnings,
        per_length: per_length(&segments),
        segments,
        rpe_1f,
        rpe_10m,
        gt_distances_m,
        ate_errors_m: a.errors_m,
        aligned_est: a.aligned_est,
    })
}

impl fmt::Display for EvalReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "poses          {}", self.n_poses)?;
        writeln!(f, "path length    {:.1} m", self.path_length_m)?;
        writeln!(
            f,
            "segments       {} (100..800 m, first frame every {KITTI_STEP})",
            self.n_segments
        )?;
        match (self.t_rel_pct, self.r_rel_deg_per_100m) {
            (Some(t), Some(r)) => {
                writeln!(f, "t_rel          {t:.3} %")?;
                writeln!(f, "r_rel          {r:.3} deg/100 m")?;
            }
            _ => {
                writeln!(f, "t_rel          n/a (ground-truth path shorter than 100 m)")?;
                writeln!(f, "r_rel          n/a")?;
            }
        }
        writeln!(
            f,
            "ATE ({})     rmse {:.3} m, mean {:.3} m, median {:.3} m, max {:.3} m",
            match self.align {
                Align::None => "none",
                Align::Se3 => "se3 ",
                Align::Sim3 => "sim3",
            },
            self.ate_rmse_m,
            self.ate_mean_m,
            self.ate_median_m,
            self.ate_max_m
        )?;
        if self.align == Align::Sim3 {
            writeln!(f, "scale          {:.4}", self.alignment.scale)?;
        }
        if self.align != Align::None {
            writeln!(
                f,
                "alignment      rotation {:.2} deg, turns the direction of travel {:.2} deg",
                self.alignment_rotation_deg, self.alignment_heading_deg
            )?;
        }
        writeln!(f)?;
        writeln!(
            f,
            "RPE (as evo_rpe: no alignment, pairs on the estimate)\n\
             delta     error             pairs       rmse       mean     median        max"
        )?;
        write_rpe_rows(f, RPE_1_FRAME, self.rpe_1f.as_ref())?;
        write_rpe_rows(f, RPE_10_M, self.rpe_10m.as_ref())?;
        if !self.per_length.is_empty() {
            writeln!(f)?;
            writeln!(f, "length [m]  segments  t_rel [%]  r_rel [deg/100 m]")?;
            for row in &self.per_length {
                writeln!(
                    f,
                    "{:>10.0}  {:>8}  {:>9.3}  {:>17.3}",
                    row.length_m, row.n_segments, row.t_rel_pct, row.r_rel_deg_per_100m
                )?;
            }
        }
        Ok(())
    }
}

/// The three rows of one RPE delta in [`EvalReport`]'s text, or one line saying why there is
/// none.
fn write_rpe_rows(f: &mut fmt::Formatter<'_>, delta: RpeDelta, rpe: Option<&Rpe>) -> fmt::Result {
    let Some(r) = rpe else {
        let why = match delta {
            RpeDelta::Frames(_) => "fewer poses than that",
            RpeDelta::Metres(_) => "the estimate travels less than that",
        };
        return writeln!(f, "{:<10}none ({why})", delta.to_string());
    };
    let rows = [
        ("translation [m]", Some(r.trans_m)),
        ("translation [%]", r.trans_pct),
        ("rotation [deg]", Some(r.rot_deg)),
    ];
    for (k, (what, stats)) in rows.into_iter().enumerate() {
        let (head, pairs) =
            if k == 0 { (delta.to_string(), r.n_pairs.to_string()) } else { Default::default() };
        match stats {
            Some(s) => writeln!(
                f,
                "{head:<10}{what:<16}{pairs:>7}{:>11.4}{:>11.4}{:>11.4}{:>11.4}",
                s.rmse, s.mean, s.median, s.max
            )?,
            None => {
                writeln!(f, "{head:<10}{what:<16}{pairs:>7}  n/a (ground truth does not move)")?
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    /// A smooth synthetic drive: ~1 m per frame along a wide arc (radius 5 km), slightly hilly.
    fn drive(n: usize) -> Vec<Se3> {
        (0..n)
            .map(|i| {
                let s = i as f64;
                let yaw = s / 5000.0;
                let rot = Rotation3::from_euler_angles(0.0, yaw, 0.0).into_inner();
                let trans = Vector3::new(
                    5000.0 * (1.0 - yaw.cos()),
                    0.5 * (0.01 * s).sin(),
                    5000.0 * yaw.sin(),
                );
                Se3::new(rot, trans)
            })
            .collect()
    }

    #[test]
    fn perfect_estimate_has_zero_error() {
        let gt = drive(1200);
        let r = evaluate(&gt, &gt, Align::Se3).unwrap();
        assert!(r.n_segments > 0);
        assert!(r.t_rel_pct.unwrap() < 1e-9);
        assert!(r.r_rel_deg_per_100m.unwrap() < 1e-5);
        assert!(r.ate_rmse_m < 1e-6);
        assert_eq!(r.per_length.len(), 8);
    }

    #[test]
    fn constant_scale_error_gives_t_rel_of_the_scale() {
        let gt = drive(1200);
        let est: Vec<Se3> = gt.iter().map(|p| Se3::new(p.rot, p.trans * 1.01)).collect();
        let r = evaluate(&gt, &est, Align::Se3).unwrap();
        // E = (P_i⁻¹P_j)⁻¹ G_i⁻¹G_j has translation −0.01 · R_Δᵀ t_Δ, so ‖t_E‖/len = 0.01 · chord/len;
        // on this wide arc the chord is within 0.2 % of the arc, and segments overshoot len by < 1 m.
        let t = r.t_rel_pct.unwrap();
        assert!((t - 1.0).abs() < 0.01, "t_rel {t}");
        assert!(r.r_rel_deg_per_100m.unwrap() < 1e-5);
        // Sim(3) alignment recovers the scale exactly and leaves no error.
        let s = evaluate(&gt, &est, Align::Sim3).unwrap();
        assert!((s.alignment.scale - 1.0 / 1.01).abs() < 1e-12);
        assert!(s.ate_rmse_m < 1e-6);
        assert!(r.ate_rmse_m > 1.0);
    }

    #[test]
    fn rigidly_moved_estimate_ate_se3_zero_none_not() {
        let gt = drive(500);
        let t = Se3::new(
            Rotation3::from_euler_angles(0.3, -1.0, 2.0).into_inner(),
            Vector3::new(10.0, -5.0, 100.0),
        );
        let est: Vec<Se3> = gt.iter().map(|p| t.compose(p)).collect();
        let se3 = evaluate(&gt, &est, Align::Se3).unwrap();
        assert!(se3.ate_rmse_m < 1e-6, "{}", se3.ate_rmse_m);
        let rot_err = (se3.alignment.rot - t.rot.transpose()).abs().max();
        assert!(rot_err < 1e-7, "{rot_err}");
        let none = evaluate(&gt, &est, Align::None).unwrap();
        assert!(none.ate_rmse_m > 10.0);
        // Relative errors do not depend on the world frame.
        assert!(se3.t_rel_pct.unwrap() < 1e-9 && none.t_rel_pct.unwrap() < 1e-9);
        for p in &se3.aligned_est {
            assert!((p.rot.determinant() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn umeyama_recovers_similarity_and_avoids_reflection() {
        let src: Vec<Vector3<f64>> = (0..20)
            .map(|i| {
                let s = i as f64;
                Vector3::new(s.sin() * 3.0, (0.7 * s).cos(), 0.1 * s * s)
            })
            .collect();
        let rot = Rotation3::from_euler_angles(1.0, 0.5, -2.0).into_inner();
        let t = Vector3::new(1.0, 2.0, 3.0);
        let dst: Vec<Vector3<f64>> = src.iter().map(|p| 2.5 * (rot * p) + t).collect();
        let sim = umeyama(&src, &dst, true).unwrap();
        assert!((sim.scale - 2.5).abs() < 1e-12);
        assert!((sim.rot - rot).abs().max() < 1e-12);
        assert!((sim.trans - t).norm() < 1e-10);
        // A mirrored target: the best proper rotation, never a reflection.
        let mirrored: Vec<Vector3<f64>> =
            src.iter().map(|p| Vector3::new(p.x, p.y, -p.z)).collect();
        let r = umeyama(&src, &mirrored, false).unwrap();
        assert!((r.rot.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn degenerate_inputs_are_errors_not_panics() {
        let p = vec![Vector3::new(1.0, 2.0, 3.0); 5];
        assert_eq!(umeyama(&p, &p, false), Err(EvalError::DegenerateAlignment));
        let line: Vec<Vector3<f64>> = (0..5).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        assert_eq!(umeyama(&line, &line, true), Err(EvalError::DegenerateAlignment));
        // Finite positions whose spread overflows are not called degenerate.
        let mut far = p.clone();
        far[1].x = 1e300;
        assert_eq!(umeyama(&far, &p, false), Err(EvalError::Overflow));
        assert_eq!(umeyama(&far, &far, true), Err(EvalError::Overflow));
        assert_eq!(umeyama(&[], &[], true), Err(EvalError::Empty));
        let gt = drive(10);
        assert_eq!(
            evaluate(&gt, &gt[..9], Align::Se3).unwrap_err(),
            EvalError::LengthMismatch { gt: 10, est: 9 }
        );
        assert_eq!(evaluate(&[], &[], Align::None).unwrap_err(), EvalError::Empty);
        // Short path: no devkit segments, but an ATE.
        let r = evaluate(&gt, &gt, Align::None).unwrap();
        assert_eq!((r.n_segments, r.t_rel_pct), (0, None));
        assert!(r.to_string().contains("n/a"));
        let one = evaluate(&gt[..1], &gt[..1], Align::None).unwrap();
        assert_eq!(one.ate_rmse_m, 0.0);
    }

    /// A ground truth with a pure scale bias `s` against a perfect estimate: every pair's error
    /// is `(1 − s)·t` of the estimate's step `t`, over a ground-truth path of `s·|path|`, so the
    /// RPE translation reads `100·(1 − 1/s)` % (the estimate's scale error against that ground
    /// truth, exactly for one frame, where the path is the chord) and the rotation reads 0.
    #[test]
    fn rpe_of_a_scale_biased_ground_truth_is_the_bias() {
        let est = drive(600);
        let s = 1.03;
        let gt: Vec<Se3> = est.iter().map(|p| Se3::new(p.rot, p.trans * s)).collect();
        let bias_pct = 100.0 * (1.0 - 1.0 / s);
        let r = evaluate(&gt, &est, Align::Se3).unwrap();
        let one = r.rpe_1f.as_ref().unwrap();
        assert_eq!((one.n_pairs, one.delta), (599, RpeDelta::Frames(1)));
        let pct = one.trans_pct.unwrap();
        for x in [pct.rmse, pct.mean, pct.median, pct.max] {
            assert!((x - bias_pct).abs() < 1e-9, "{pct:?} vs {bias_pct}");
        }
        assert!(one.rot_deg.max < 1e-9, "{:?}", one.rot_deg);
        assert!((one.trans_m.mean - 0.03 * 1.0).abs() < 1e-3, "{:?}", one.trans_m);
        // Pairs over 10 m follow the estimate's path (so the biased ground truth does not move
        // them): 10 frames of ~1 m; on this wide arc the chord is the path to 2e-7.
        let ten = r.rpe_10m.as_ref().unwrap();
        assert!(ten.pairs.iter().all(|&(i, j)| j - i == 10 || j - i == 11), "{:?}", ten.pairs);
        let pct = ten.trans_pct.unwrap();
        assert!((pct.max - bias_pct).abs() < 1e-5 && (pct.median - bias_pct).abs() < 1e-5);
        assert!(ten.rot_deg.max < 1e-9);
        // Scaling the estimate the other way round gives exactly the bias.
        let longer: Vec<Se3> = est.iter().map(|p| Se3::new(p.rot, p.trans * 1.02)).collect();
        let r = rpe(&est, &longer, RPE_1_FRAME).unwrap().unwrap();
        assert!((r.trans_pct.unwrap().mean - 2.0).abs() < 1e-9);
    }

    #[test]
    fn short_trajectories_have_no_10m_rpe() {
        // About 1 m per frame: 5 poses travel about 4 m.
        let gt = drive(5);
        let r = evaluate(&gt, &gt, Align::None).unwrap();
        assert_eq!(r.rpe_1f.as_ref().map(|r| r.n_pairs), Some(4));
        assert_eq!(r.rpe_10m, None);
        let text = r.to_string();
        assert!(text.contains("10 m      none (the estimate travels less than that)"), "{text}");
        let json = serde_json::to_value(&r).unwrap();
        assert!(json["rpe_10m"].is_null());
        assert_eq!(json["rpe_1f"]["n_pairs"], 4);
        assert_eq!(json["rpe_1f"]["delta"]["frames"], 1);
        // One pose: no pair at all, and still no NaN anywhere.
        let one = evaluate(&gt[..1], &gt[..1], Align::None).unwrap();
        assert_eq!((one.rpe_1f.as_ref(), one.rpe_10m.as_ref()), (None, None));
        assert!(!one.to_string().contains("NaN"));
        // A standing vehicle: translation % has no path to divide by.
        let still = vec![Se3::identity(); 4];
        let r = rpe(&still, &still, RPE_1_FRAME).unwrap().unwrap();
        assert_eq!((r.n_pairs, r.trans_pct, r.trans_m.max), (3, None, 0.0));
        assert_eq!(rpe(&still, &still, RpeDelta::Frames(0)), Err(EvalError::InvalidDelta));
        assert_eq!(rpe(&still, &still, RpeDelta::Metres(-1.0)), Err(EvalError::InvalidDelta));
        assert_eq!(rpe(&still, &still, RpeDelta::Metres(f64::NAN)), Err(EvalError::InvalidDelta));
    }

    #[test]
    fn rpe_pairs_follow_evo_filters() {
        let at = |xs: &[f64]| -> Vec<Se3> {
            xs.iter().map(|&x| Se3::new(Matrix3::identity(), Vector3::new(x, 0.0, 0.0))).collect()
        };
        // filter_pairs_by_index: (0, Δ), (Δ, 2Δ), … while both exist.
        let eight = at(&[0.0; 8]);
        assert_eq!(rpe_pairs(&eight, RpeDelta::Frames(3)).unwrap(), [(0, 3), (3, 6)]);
        assert_eq!(rpe_pairs(&eight, RpeDelta::Frames(8)).unwrap(), []);
        // filter_pairs_by_path: steps 4, 4, 3 | 10 | 1, 9.5 — each sum >= 10 ends a pair and the
        // overshoot is dropped.
        let path = at(&[0.0, 4.0, 8.0, 11.0, 21.0, 22.0, 31.5, 32.0]);
        assert_eq!(rpe_pairs(&path, RPE_10_M).unwrap(), [(0, 3), (3, 4), (4, 6)]);
        assert_eq!(rpe_pairs(&path, RpeDelta::Metres(0.0)).unwrap().len(), 7);
        assert_eq!(rpe_pairs(&[], RPE_10_M).unwrap(), []);
    }

    #[test]
    fn rotation_angle_is_that_of_the_nearest_rotation() {
        for angle in [0.0, 1e-6, 1e-4, 0.3, 2.0, 3.1, core::f64::consts::PI] {
            let axis = nalgebra::Unit::new_normalize(Vector3::new(0.3, -1.0, 0.2));
            let r = Rotation3::from_axis_angle(&axis, angle).into_inner();
            assert!((rotation_angle(&r) - angle).abs() < 1e-12, "{angle}");
            // A rotation times a symmetric positive-definite matrix has that rotation as its
            // nearest one: rounding a pose file's entries to 7 digits is such an error.
            let sym = Matrix3::new(1.0, 3e-8, -2e-8, 3e-8, 1.0 - 4e-8, 5e-8, -2e-8, 5e-8, 1.0);
            let got = rotation_angle(&(r * sym));
            assert!((got - angle).abs() < 1e-12, "{angle}: {got}");
        }
        // acos of the trace on the raw matrix is far off for a small angle.
        let axis = Vector3::z_axis();
        let r = Rotation3::from_axis_angle(&axis, 1e-4).into_inner();
        let sym = Matrix3::<f64>::new(1.0 + 1e-7, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
        let naive = (0.5 * ((r * sym).trace() - 1.0)).clamp(-1.0, 1.0).acos();
        assert!((naive - 1e-4).abs() > 1e-5, "{naive}");
        assert!((rotation_angle(&(r * sym)) - 1e-4).abs() < 1e-12);
    }

    #[test]
    fn last_frame_matches_devkit_rule() {
        let dist = [0.0f32, 50.0, 100.0, 100.5, 250.0];
        // Strictly greater than dist[first] + len.
        assert_eq!(last_frame_from_segment_length(&dist, 0, 100.0), Some(3));
        assert_eq!(last_frame_from_segment_length(&dist, 1, 100.0), Some(4));
        assert_eq!(last_frame_from_segment_length(&dist, 2, 200.0), None);
        assert_eq!(last_frame_from_segment_length(&dist, 9, 100.0), None);
    }

    #[test]
    fn report_serialises_and_displays() {
        let gt = drive(900);
        let r = evaluate(&gt, &gt, Align::Sim3).unwrap();
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["align"], "sim3");
        assert_eq!(json["n_poses"], 900);
        assert!(json["per_length"].as_array().unwrap().len() >= 7);
        assert!(json.get("aligned_est").is_none());
        assert_eq!(json["segments"].as_array().unwrap().len(), r.n_segments);
        let text = r.to_string();
        assert!(text.contains("t_rel") && text.contains("length [m]"), "{text}");
        assert_eq!("SIM3".parse::<Align>().unwrap(), Align::Sim3);
        assert!("x".parse::<Align>().is_err());
    }
}
