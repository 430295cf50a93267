//! EuRoC MAV (ASL folder layout): `ROOT/mav0/cam0/{data.csv, sensor.yaml, data/*.png}`, the
//! same for `cam1`, and optionally `ROOT/mav0/state_groundtruth_estimate0/data.csv`. `ROOT` may
//! be the sequence folder (holding `mav0`) or `mav0` itself.
//!
//! * `camN/data.csv`: `#timestamp [ns],filename` then one `NS,FILE` line per image, times
//!   increasing. Camera 0 and camera 1 images pair by equal timestamp; one without a partner
//!   is an error naming its file and line.
//! * `camN/sensor.yaml`: `T_BS` (camera to body, 4x4 row-major under `T_BS:` with `rows`,
//!   `cols`, `data`), `resolution: [w, h]`, `camera_model: pinhole`,
//!   `intrinsics: [fu, fv, cu, cv]`, `distortion_model: radial-tangential` and
//!   `distortion_coefficients: [k1, k2, p1, p2]`; read with the settings' OpenCV-YAML reader.
//! * The images are distorted and not rectified: the pair is rectified as OpenCV's
//!   `stereoRectify` with `alpha = 0` does (see [`super::rectify`]); the rectified camera is
//!   the sequence's calibration and [`Sequence::load_luma`] returns rectified images.
//! * Times: `time_origin_s` is the first image's timestamp in seconds (UNIX time), `times_s`
//!   the offsets from it (computed from integer nanoseconds, so nothing is lost).
//! * Ground truth: `#timestamp, p_RS_R_x [m], p_RS_R_y, p_RS_R_z, q_RS_w [], q_RS_x, q_RS_y,
//!   q_RS_z, ...` (further columns ignored) is the body (IMU) in the world. At each image time
//!   the pose is interpolated between the two samples around it (position linearly, rotation
//!   by slerp; samples more than [`EUROC_MAX_GT_GAP_S`] apart are not bridged), moved to the
//!   rectified left camera, `T_w_c = T_w_b · T_BS(cam0) · [R_rect0ᵀ | 0]`, and re-based so the
//!   first pose is the identity (`G_i = T_w_c(0)⁻¹ T_w_c(i)`), as raw KITTI drives are. A
//!   frame outside the ground truth's time span ends the ground truth there, with
//!   [`Sequence::gt_problem`] saying so (a sequence whose ground truth starts after its first
//!   image has none).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::{Matrix3, Matrix4, Quaternion, UnitQuaternion, Vector3};
use semloc_core::geom::Se3;

use super::rectify::{stereo_rectify, PinholeRadtan, StereoRemap};
use super::text::{numbered_lines, parse_f64, read_text};
use super::{first_pair_size, DatasetError, Layout, Sequence};
use crate::settings::{number_list, parse_opencv_yaml, YamlValue};

/// Largest time between two ground-truth samples that a frame time may be interpolated
/// between, s (EuRoC's ground truth is sampled at 200 Hz).
pub const EUROC_MAX_GT_GAP_S: f64 = 0.1;

/// The `mav0` folder of `root` (the sequence folder or `mav0` itself), if it looks like one.
pub(crate) fn mav_dir(root: &Path) -> Option<PathBuf> {
    [root.join("mav0"), root.to_path_buf()].into_iter().find(|m| {
        m.join("cam0").join("data.csv").is_file() || m.join("cam0").join("sensor.yaml").is_file()
    })
}

/// One `data.csv` entry: timestamp (ns), image file, 1-based line.
type Stamp = (i64, PathBuf, usize);

/// Reads a camera's `data.csv`: `NS,FILE` lines, timestamps strictly increasing.
fn read_camera_csv(cam_dir: &Path) -> Result<Vec<Stamp>, DatasetError> {
    let path = cam_dir.join("data.csv");
    let text = read_text(&path)?;
    let mut out: Vec<Stamp> = Vec::new();
    for (line, l) in numbered_lines(&text) {
        let fields: Vec<&str> = l.split(',').map(str::trim).collect();
        let [ns, file] = fields.as_slice() else {
            return Err(DatasetError::Parse {
                path: path.clone(),
                line,
                msg: format!("expected `timestamp_ns,filename`, found {} fields", fields.len()),
            });
        };
        let ns: i64 = ns.parse().map_err(|_| DatasetError::Parse {
            path: path.clone(),
            line,
            msg: format!("`{ns}` is not a timestamp in whole nanoseconds"),
        })?;
        if file.is_empty() {
            return Err(DatasetError::Parse {
                path: path.clone(),
                line,
                msg: "no file name".into(),
            });
        }
        if let Some((prev, _, _)) = out.last() {
            if ns <= *prev {
                return Err(DatasetError::TimesNotIncreasing {
                    path: path.clone(),
                    frame: out.len(),
                    time_s: ns as f64 * 1e-9,
                    previous_s: *prev as f64 * 1e-9,
                });
            }
        }
        out.push((ns, cam_dir.join("data").join(file), line));
    }
    Ok(out)
}

/// Pairs camera 0 and camera 1 entries by equal timestamp; any entry without a partner is an
/// error naming its list and line.
fn pair_by_time(
    c0: &[Stamp],
    c1: &[Stamp],
    csv0: &Path,
    csv1: &Path,
) -> Result<Vec<(i64, PathBuf, PathBuf)>, DatasetError> {
    let mut out = Vec::with_capacity(c0.len());
    let (mut i, mut j) = (0, 0);
    let unpaired = |s: &Stamp, path: &Path, other: &Path| DatasetError::UnpairedTimestamp {
        path: path.to_path_buf(),
        line: s.2,
        timestamp_ns: s.0,
        other: other.to_path_buf(),
    };
    while i < c0.len() || j < c1.len() {
        match (c0.get(i), c1.get(j)) {
            (Some(a), Some(b)) if a.0 == b.0 => {
                out.push((a.0, a.1.clone(), b.1.clone()));
                i += 1;
                j += 1;
            }
            (Some(a), Some(b)) if a.0 < b.0 => return Err(unpaired(a, csv0, csv1)),
            (Some(_), Some(b)) | (None, Some(b)) => return Err(unpaired(b, csv1, csv0)),
            (Some(a), None) => return Err(unpaired(a, csv0, csv1)),
            (None, None) => break,
        }
    }
    Ok(out)
}

/// What a camera's `sensor.yaml` gives.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SensorYaml {
    /// Camera to body.
    pub t_bs: Matrix4<f64>,
    /// Intrinsics and distortion.
    pub camera: PinholeRadtan,
    /// `resolution`, px.
    pub resolution: (u32, u32),
}

/// Reads and checks a `sensor.yaml` (see the module docs).
pub(crate) fn read_sensor_yaml(path: &Path) -> Result<SensorYaml, DatasetError> {
    let text = read_text(path)?;
    let entries = parse_opencv_yaml(&text, path).map_err(|e| DatasetError::from_yaml(path, e))?;
    let missing =
        |key: &str| DatasetError::MissingKey { path: path.to_path_buf(), key: key.into() };
    let bad = |msg: String| DatasetError::BadCalib { path: path.to_path_buf(), msg };
    let get = |key: &str| entries.iter().find(|e| e.key == key).ok_or_else(|| missing(key));
    let scalar = |key: &str| -> Result<(String, usize), DatasetError> {
        let e = get(key)?;
        match &e.value {
            YamlValue::Scalar(s) => Ok((s.clone(), e.line)),
            YamlValue::Matrix { .. } => Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line: e.line,
                msg: format!("{key}: expected a value, found a matrix"),
            }),
        }
    };
    let list = |key: &str, n: usize| -> Result<Vec<f64>, DatasetError> {
        let (s, line) = scalar(key)?;
        let v = number_list(&s).map_err(|msg| DatasetError::Parse {
            path: path.to_path_buf(),
            line,
            msg: format!("{key}: {msg}"),
        })?;
        if v.len() != n {
            return Err(DatasetError::BadFieldCount {
                path: path.to_path_buf(),
                line,
                expected: n,
                got: v.len(),
            });
        }
        Ok(v)
    };
    let (model, _) = scalar("camera_model")?;
    if model != "pinhole" {
        return Err(bad(format!("camera_model `{model}`: only `pinhole` is supported")));
    }
    let (dist, _) = scalar("distortion_model")?;
    if dist != "radial-tangential" && dist != "radtan" {
        return Err(bad(format!(
            "distortion_model `{dist}`: only `radial-tangential` (k1, k2, p1, p2) is supported"
        )));
    }
    let k = list("intrinsics", 4)?;
    if !(k[0] > 0.0 && k[1] > 0.0) {
        return Err(bad(format!(
            "intrinsics: focal lengths must be positive, got {} {}",
            k[0], k[1]
        )));
    }
    let d = list("distortion_coefficients", 4)?;
    let res = list("resolution", 2)?;
    let whole =
        |v: f64| (v >= 1.0 && v <= f64::from(u32::MAX) && v.fract() == 0.0).then_some(v as u32);
    let (Some(w), Some(h)) = (whole(res[0]), whole(res[1])) else {
        return Err(bad(format!("resolution {res:?} is not two positive whole numbers")));
    };
    let e = get("T_BS")?;
    let YamlValue::Matrix { rows: 4, cols: 4, data } = &e.value else {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line: e.line,
            msg: "T_BS: expected a 4x4 matrix (rows: 4, cols: 4, data: [16 numbers])".into(),
        });
    };
    let t_bs = Matrix4::from_row_slice(data);
    let r = t_bs.fixed_view::<3, 3>(0, 0).into_owned();
    let off = (r.transpose() * r - Matrix3::identity()).abs().max();
    let det = r.determinant();
    let last_row_ok = t_bs.row(3).iter().zip([0.0, 0.0, 0.0, 1.0]).all(|(a, b)| *a == b);
    if !(off <= 1e-6
        && (det - 1.0).abs() <= 1e-6
        && last_row_ok
        && data.iter().all(|v| v.is_finite()))
    {
        return Err(bad(format!(
            "T_BS is not a rigid transform (|RᵀR − I| = {off:.3e}, det = {det:.6}, last row {:?})",
            t_bs.row(3).iter().collect::<Vec<_>>()
        )));
    }
    Ok(SensorYaml {
        t_bs,
        camera: PinholeRadtan {
            fx_px: k[0],
            fy_px: k[1],
            cx_px: k[2],
            cy_px: k[3],
            k: [d[0], d[1]],
            p: [d[2], d[3]],
        },
        resolution: (w, h),
    })
}

/// A timestamped pose sample: time (s), position, rotation.
pub(crate) type PoseSample = (f64, Vector3<f64>, UnitQuaternion<f64>);

/// The pose at time `t` (s) from samples sorted by time: linear in position, slerp in rotation
/// between the two samples around `t` (an exact sample time gives that sample). `Err` says why
/// there is none: `t` outside the samples' span, or the samples around it more than `max_gap_s`
/// apart.
pub(crate) fn interpolate(samples: &[PoseSample], t: f64, max_gap_s: f64) -> Result<Se3, String> {
    let (Some(first), Some(last)) = (samples.first(), samples.last()) else {
        return Err("the ground truth is empty".into());
    };
    if t < first.0 || t > last.0 {
        return Err(format!("outside the ground truth's time span {} .. {} s", first.0, last.0));
    }
    let k = samples.partition_point(|s| s.0 < t); // first sample at or after t
    let b = &samples[k];
    if b.0 == t {
        return Ok(Se3::new(b.2.to_rotation_matrix().into_inner(), b.1));
    }
    let a = &samples[k - 1]; // k ≥ 1: t > first.0
    let gap = b.0 - a.0;
    if gap > max_gap_s {
        return Err(format!(
            "the ground truth has no samples between {} and {} s ({gap:.3} s, more than {max_gap_s} s)",
            a.0, b.0
        ));
    }
    let s = (t - a.0) / gap;
    let qb = if a.2.coords.dot(&b.2.coords) < 0.0 {
        UnitQuaternion::new_unchecked(-b.2.into_inner())
    } else {
        b.2
    };
    let q = a.2.try_slerp(&qb, s, 1e-9).unwrap_or(if s < 0.5 { a.2 } else { qb });
    Ok(Se3::new(q.to_rotation_matrix().into_inner(), a.1 + (b.1 - a.1) * s))
}

/// Re-bases poses so the first is the identity, exactly: `G_i = P_0⁻¹ P_i`.
pub(crate) fn rebase(poses: &[Se3]) -> Vec<Se3> {
    let Some(first) = poses.first() else { return Vec::new() };
    let inv = first.inverse();
    core::iter::once(Se3::identity()).chain(poses[1..].iter().map(|p| inv.compose(p))).collect()
}

/// Reads the ground-truth CSV: samples up to the first bad line, and that line's error.
/// Times are seconds from `origin_ns`.
fn read_gt_csv(
    path: &Path,
    origin_ns: i64,
) -> Result<(Vec<PoseSample>, Option<DatasetError>), DatasetError> {
    let text = read_text(path)?;
    let mut out: Vec<PoseSample> = Vec::new();
    for (line, l) in numbered_lines(&text) {
        match gt_line(path, line, l, origin_ns, out.last().map(|s| s.0)) {
            Ok(s) => out.push(s),
            Err(e) => return Ok((out, Some(e))),
        }
    }
    Ok((out, None))
}

fn gt_line(
    path: &Path,
    line: usize,
    l: &str,
    origin_ns: i64,
    prev: Option<f64>,
) -> Result<PoseSample, DatasetError> {
    let fields: Vec<&str> = l.split(',').map(str::trim).collect();
    if fields.len() < 8 {
        return Err(DatasetError::BadFieldCount {
            path: path.to_path_buf(),
            line,
            expected: 8,
            got: fields.len(),
        });
    }
    let ns: i64 = fields[0].parse().map_err(|_| DatasetError::Parse {
        path: path.to_path_buf(),
        line,
        msg: format!("`{}` is not a timestamp in whole nanoseconds", fields[0]),
    })?;
    let v = fields[1..8].iter().map(|f| parse_f64(path, line, f)).collect::<Result<Vec<_>, _>>()?;
    let t = (ns - origin_ns) as f64 * 1e-9;
    if let Some(p) = prev {
        if t <= p {
            return Err(DatasetError::Parse {
                path: path.to_path_buf(),
                line,
                msg: format!("timestamp {ns} ns is not after the previous line's"),
            });
        }
    }
    let q = Quaternion::new(v[3], v[4], v[5], v[6]);
    if q.norm() <= 1e-6 {
        return Err(DatasetError::Parse {
            path: path.to_path_buf(),
            line,
            msg: "the quaternion q_RS has zero length".into(),
        });
    }
    Ok((t, Vector3::new(v[0], v[1], v[2]), UnitQuaternion::from_quaternion(q)))
}

/// See [`Sequence::open_euroc`].
pub(crate) fn open(root: &Path) -> Result<Sequence, DatasetError> {
    if !root.is_dir() {
        return Err(DatasetError::MissingFile { path: root.to_path_buf() });
    }
    let Some(mav) = mav_dir(root) else {
        return Err(DatasetError::MissingFile {
            path: root.join("mav0").join("cam0").join("data.csv"),
        });
    };
    let (cam0, cam1) = (mav.join("cam0"), mav.join("cam1"));
    let (csv0, csv1) = (cam0.join("data.csv"), cam1.join("data.csv"));
    let pairs = pair_by_time(&read_camera_csv(&cam0)?, &read_camera_csv(&cam1)?, &csv0, &csv1)?;
    let Some(&(ns0, _, _)) = pairs.first() else {
        return Err(DatasetError::EmptySequence { path: csv0 });
    };
    let mut left = Vec::with_capacity(pairs.len());
    let mut right = Vec::with_capacity(pairs.len());
    for (_, l, r) in &pairs {
        for p in [l, r] {
            if !p.is_file() {
                return Err(DatasetError::MissingFile { path: p.clone() });
            }
        }
        left.push(l.clone());
        right.push(r.clone());
    }
    let times_s: Vec<f64> = pairs.iter().map(|(ns, _, _)| (ns - ns0) as f64 * 1e-9).collect();
    let time_origin_s = ns0 as f64 * 1e-9;

    let (yaml0, yaml1) = (cam0.join("sensor.yaml"), cam1.join("sensor.yaml"));
    let s0 = read_sensor_yaml(&yaml0)?;
    let s1 = read_sensor_yaml(&yaml1)?;
    let image_size = first_pair_size(&left, &right)?;
    for (s, img) in [(&s0, &left[0]), (&s1, &right[0])] {
        if s.resolution != image_size {
            return Err(DatasetError::ImageSizeMismatch {
                path: img.clone(),
                expected: s.resolution,
                got: image_size,
            });
        }
    }
    // X_c1 = T_BS1⁻¹ T_BS0 X_c0 (both rigid: the inverse exists).
    let t_b_c1_inv = s1.t_bs.try_inverse().ok_or_else(|| DatasetError::BadCalib {
        path: yaml1.clone(),
        msg: "T_BS is singular".into(),
    })?;
    let t10 = t_b_c1_inv * s0.t_bs;
    let rect = stereo_rectify(
        &s0.camera,
        &s1.camera,
        &t10.fixed_view::<3, 3>(0, 0).into_owned(),
        &t10.fixed_view::<3, 1>(0, 3).into_owned(),
        image_size,
        Some(0.0),
    )
    .map_err(|msg| DatasetError::BadCalib {
        path: yaml1.clone(),
        msg: format!("{msg} (cam0 {} and cam1 as one stereo pair)", yaml0.display()),
    })?;
    let remap = StereoRemap::new(&s0.camera, &s1.camera, &rect, image_size);

    let gt_path = mav.join("state_groundtruth_estimate0").join("data.csv");
    let (gt, gt_problem) = if gt_path.is_file() {
        let (samples, bad) = read_gt_csv(&gt_path, ns0)?;
        // Body → rectified left camera: T_BS(cam0) · [R_rect0ᵀ | 0].
        let t_bs0 = Se3::new(
            s0.t_bs.fixed_view::<3, 3>(0, 0).into_owned(),
            s0.t_bs.fixed_view::<3, 1>(0, 3).into_owned(),
        );
        let b_c = t_bs0.compose(&Se3::new(rect.r_left.transpose(), Vector3::zeros()));
        let mut poses = Vec::with_capacity(times_s.len());
        let mut problem = None;
        for (i, &t) in times_s.iter().enumerate() {
            match interpolate(&samples, t, EUROC_MAX_GT_GAP_S) {
                Ok(w_b) => poses.push(w_b.compose(&b_c)),
                Err(msg) => {
                    problem = Some(bad.clone().unwrap_or(DatasetError::GtNotCovered {
                        path: gt_path.clone(),
                        frame: i,
                        time_s: t,
                        msg,
                    }));
                    break;
                }
            }
        }
        let poses = rebase(&poses);
        ((!poses.is_empty()).then_some(poses), problem)
    } else {
        (None, None)
    };

    let name = super::dir_name(&if mav.file_name().is_some_and(|n| n == "mav0") {
        mav.join("..")
    } else {
        mav.clone()
    });
    Ok(Sequence {
        layout: Layout::Euroc,
        name,
        root: mav,
        pair: super::CameraPair::Grey,
        calib: rect.calib,
        left,
        right,
        times_s,
        time_origin_s,
        gt,
        gt_problem,
        image_size,
        notes: Vec::new(),
        remap: Some(Arc::new(remap)),
        first_frame: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::luma;
    use crate::dataset::rectify::RemapTable;
    use image::{GrayImage, Luma};
    use std::fs;

    /// EuRoC's own cam0 `sensor.yaml`, verbatim (comments, a multi-line `data`).
    const EUROC_CAM0_YAML: &str = "\
# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
         0.0, 0.0, 0.0, 1.0]

# Camera specific definitions.
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
";

    fn yaml(t_bs: &Matrix4<f64>, cam: &PinholeRadtan, size: (u32, u32)) -> String {
        let data: Vec<String> = t_bs.transpose().iter().map(|v| format!("{v:e}")).collect();
        format!(
            "sensor_type: camera\nT_BS:\n  cols: 4\n  rows: 4\n  data: [{}]\nrate_hz: 20\n\
             resolution: [{}, {}]\ncamera_model: pinhole\nintrinsics: [{:e}, {:e}, {:e}, {:e}]\n\
             distortion_model: radial-tangential\ndistortion_coefficients: [{:e}, {:e}, {:e}, {:e}]\n",
            data.join(", "),
            size.0,
            size.1,
            cam.fx_px,
            cam.fy_px,
            cam.cx_px,
            cam.cy_px,
            cam.k[0],
            cam.k[1],
            cam.p[0],
            cam.p[1]
        )
    }

    /// EuRoC's camera-to-body rotation: camera z along body x, camera x along body −y.
    fn r_bs() -> Matrix3<f64> {
        Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0)
    }

    fn rigid(r: &Matrix3<f64>, t: &Vector3<f64>) -> Matrix4<f64> {
        super::super::calib::homogeneous(r, t)
    }

    const T0_NS: i64 = 1_403_636_579_763_555_584;
    const PERIOD_NS: i64 = 50_000_000;

    /// The test rig: `cam`, cam1 `b` m to the right of cam0 (rotated by `r10` about its
    /// centre), cam0 at the body origin.
    struct Rig {
        cam0: PinholeRadtan,
        cam1: PinholeRadtan,
        t_bs0: Matrix4<f64>,
        t_bs1: Matrix4<f64>,
        size: (u32, u32),
    }

    fn simple_rig(distorted: bool, r10: Matrix3<f64>) -> Rig {
        let (k, p) = if distorted { ([-0.28, 0.07], [2e-4, 1e-5]) } else { ([0.0; 2], [0.0; 2]) };
        let cam0 = PinholeRadtan { fx_px: 230.0, fy_px: 229.0, cx_px: 183.0, cy_px: 121.0, k, p };
        let cam1 = PinholeRadtan { fx_px: 229.5, fy_px: 228.5, cx_px: 190.0, cy_px: 127.0, k, p };
        let b = 0.11;
        let t_bs0 = rigid(&r_bs(), &Vector3::zeros());
        // cam1 centre at cam0's (b, 0, 0); its axes turned by r10ᵀ: X_c1 = r10 (X_c0 − b x̂).
        let t_bs1 = rigid(&(r_bs() * r10.transpose()), &(r_bs() * Vector3::new(b, 0.0, 0.0)));
        Rig { cam0, cam1, t_bs0, t_bs1, size: (376, 240) }
    }

    /// Texture on the plane Z = 3 m in front of cam0: smooth (bilinear sampling is nearly
    /// exact), varied enough that a wrong remap shows.
    fn texture(p: &Vector3<f64>) -> f64 {
        let (x, y) = (p.x / p.z * 3.0, p.y / p.z * 3.0);
        128.0 + 60.0 * (x * 9.0).sin() * (y * 7.0).cos() + 40.0 * (x * 3.0 + y * 5.0).sin()
    }

    /// The point of the plane Z₀ = 3 m on the ray `d` (cam0 coordinates) from `origin`.
    fn on_plane(origin: &Vector3<f64>, d: &Vector3<f64>) -> Vector3<f64> {
        origin + d * ((3.0 - origin.z) / d.z)
    }

    /// Renders what camera `k` of `rig` sees of the plane.
    fn render(rig: &Rig, right: bool) -> GrayImage {
        let cam = if right { &rig.cam1 } else { &rig.cam0 };
        // cam k → cam0: T_BS0⁻¹ T_BSk.
        let t = rig.t_bs0.try_inverse().unwrap() * if right { rig.t_bs1 } else { rig.t_bs0 };
        let (r, o) =
            (t.fixed_view::<3, 3>(0, 0).into_owned(), t.fixed_view::<3, 1>(0, 3).into_owned());
        GrayImage::from_fn(rig.size.0, rig.size.1, |u, v| {
            let ray = cam.undistort_pixel(f64::from(u), f64::from(v)).unwrap();
            Luma([texture(&on_plane(&o, &(r * ray))).round().clamp(0.0, 255.0) as u8])
        })
    }

    /// Writes a EuRoC sequence of `n` frames into `dir/mav0` (images rendered with `rig`,
    /// ground truth of the body moving along world x at 1 m/s and turning about world z at
    /// 0.5 rad/s, sampled at 200 Hz from 10 ms before the first image).
    fn write_sequence(dir: &Path, rig: &Rig, n: usize) {
        let mav = dir.join("mav0");
        let (l, r) = (render(rig, false), render(rig, true));
        for (cam, img, t_bs, c) in
            [("cam0", &l, &rig.t_bs0, &rig.cam0), ("cam1", &r, &rig.t_bs1, &rig.cam1)]
        {
            let d = mav.join(cam);
            fs::create_dir_all(d.join("data")).unwrap();
            let mut csv = String::from("#timestamp [ns],filename\n");
            for i in 0..n as i64 {
                let ns = T0_NS + i * PERIOD_NS;
                img.save(d.join("data").join(format!("{ns}.png"))).unwrap();
                csv.push_str(&format!("{ns},{ns}.png\n"));
            }
            fs::write(d.join("data.csv"), csv).unwrap();
            fs::write(d.join("sensor.yaml"), yaml(t_bs, c, rig.size)).unwrap();
        }
        let gt = mav.join("state_groundtruth_estimate0");
        fs::create_dir_all(&gt).unwrap();
        let mut csv = String::from(
            "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1]\n",
        );
        let samples = (n as i64 - 1) * PERIOD_NS / 5_000_000 + 4;
        for k in 0..samples {
            let ns = T0_NS - 10_000_000 + k * 5_000_000;
            let t = (ns - T0_NS) as f64 * 1e-9;
            let half = 0.25 * t; // half of 0.5 rad/s · t
            csv.push_str(&format!(
                "{ns},{},{},{},{},{},{},{},1.0\n",
                t + 4.0,
                -2.0,
                1.5,
                half.cos(),
                0.0,
                0.0,
                half.sin()
            ));
        }
        fs::write(gt.join("data.csv"), csv).unwrap();
    }

    fn mean_abs_diff(a: &GrayImage, b: &GrayImage, margin: u32) -> f64 {
        let (w, h) = a.dimensions();
        let mut sum = 0.0;
        let mut n = 0.0;
        for v in margin..h - margin {
            for u in margin..w - margin {
                sum += (f64::from(a.get_pixel(u, v)[0]) - f64::from(b.get_pixel(u, v)[0])).abs();
                n += 1.0;
            }
        }
        sum / n
    }

    #[test]
    fn sensor_yaml_of_euroc_reads() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sensor.yaml");
        fs::write(&p, EUROC_CAM0_YAML).unwrap();
        let s = read_sensor_yaml(&p).unwrap();
        assert_eq!(s.resolution, (752, 480));
        assert_eq!(s.camera.fx_px, 458.654);
        assert_eq!(s.camera.cy_px, 248.375);
        assert_eq!(s.camera.k, [-0.28340811, 0.07395907]);
        assert_eq!(s.camera.p, [0.00019359, 1.76187114e-05]);
        assert_eq!(s.t_bs[(0, 1)], -0.999880929698);
        assert_eq!(s.t_bs[(1, 3)], -0.064676986768);
        assert_eq!(s.t_bs[(3, 3)], 1.0);
    }

    #[test]
    fn malformed_sensor_yaml_is_a_typed_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sensor.yaml");
        let cases: &[(&str, &str, &str)] = &[
            ("camera_model: pinhole", "camera_model: omni", "omni"),
            ("radial-tangential", "equidistant", "equidistant"),
            (
                "intrinsics: [458.654, 457.296, 367.215, 248.375]",
                "intrinsics: [458.654, 457.296]",
                "expected 4",
            ),
            ("intrinsics: [458.654,", "intrinsics: [-458.654,", "positive"),
            ("resolution: [752, 480]", "resolution: [752.5, 480]", "whole"),
            ("resolution: [752, 480]", "", "resolution"),
            ("0.0, 0.0, 0.0, 1.0]", "0.0, 0.0, 0.0, 2.0]", "rigid"),
            ("0.0148655429818, -0.999880929698", "1.5, -0.999880929698", "rigid"),
            ("  rows: 4\n", "  rows: 3\n", "matrix"),
            (
                "distortion_coefficients: [-0.28340811,",
                "distortion_coefficients: [x,",
                "not a finite number",
            ),
        ];
        for (from, to, says) in cases {
            assert!(EUROC_CAM0_YAML.contains(from), "{from}");
            fs::write(&p, EUROC_CAM0_YAML.replacen(from, to, 1)).unwrap();
            let e = read_sensor_yaml(&p).unwrap_err();
            let msg = e.to_string();
            assert!(msg.contains("sensor.yaml") && msg.contains(says), "{from} → {to}: {msg}");
        }
        fs::write(&p, "T_BS:\n  cols: 4\n  rows: 4\n  data: [1, 2]\n").unwrap();
        let e = read_sensor_yaml(&p).unwrap_err();
        assert!(matches!(e, DatasetError::Parse { line: 1, .. }), "{e}");
    }

    /// A distorted rig with a rotation between the cameras: the images `load_luma` returns are
    /// the rectified cameras' views of the scene (checked against a direct rendering of each
    /// rectified camera), and the rectified left/right rows agree.
    #[test]
    fn distorted_sequence_is_rectified_on_loading() {
        let r10 = so3_exp_small(0.01, -0.02, 0.015);
        let rig = simple_rig(true, r10);
        let dir = tempfile::tempdir().unwrap();
        write_sequence(dir.path(), &rig, 3);
        let seq = Sequence::open(dir.path(), None).unwrap();
        assert_eq!(seq.layout, Layout::Euroc);
        assert_eq!(seq.len(), 3);
        assert_eq!(seq.image_size, rig.size);
        assert_eq!(seq.time_origin_s, T0_NS as f64 * 1e-9);
        assert!((seq.times_s[2] - 0.1).abs() < 1e-12);
        let m = seq.remap.as_ref().unwrap();
        let rect = m.rectification;
        assert_eq!(seq.calib, rect.calib);
        assert!((rect.calib.baseline_m - 0.11).abs() < 1e-12);
        let (l, r) = seq.load_luma(1).unwrap();
        // The rectified views drawn directly: rectified pixel → ray → cam0 frame → plane.
        let k = rect.calib;
        let t01 = rig.t_bs0.try_inverse().unwrap() * rig.t_bs1;
        let view = |right: bool| {
            let (rot, o) = if right {
                (
                    t01.fixed_view::<3, 3>(0, 0) * rect.r_right.transpose(),
                    t01.fixed_view::<3, 1>(0, 3).into_owned(),
                )
            } else {
                (rect.r_left.transpose(), Vector3::zeros())
            };
            GrayImage::from_fn(rig.size.0, rig.size.1, |u, v| {
                let ray = Vector3::new(
                    (f64::from(u) - k.cx_px) / k.fx_px,
                    (f64::from(v) - k.cy_px) / k.fy_px,
                    1.0,
                );
                Luma([texture(&on_plane(&o, &(rot * ray))).round().clamp(0.0, 255.0) as u8])
            })
        };
        let (dl, dr) = (mean_abs_diff(&l, &view(false), 2), mean_abs_diff(&r, &view(true), 2));
        assert!(dl < 1.5 && dr < 1.5, "left {dl}, right {dr} grey levels");
        // The unrectified images differ from the rectified views far more.
        let raw = luma::load_luma_file(&seq.left[1]).unwrap();
        assert!(mean_abs_diff(&raw, &view(false), 2) > 5.0 * dl.max(0.5));
        // The EuRoC remap of the first image is what `RemapTable` gives.
        let again = RemapTable::new(&rig.cam0, &rect.r_left, &k, rig.size).apply(&raw);
        assert_eq!(again, l);
    }

    fn so3_exp_small(x: f64, y: f64, z: f64) -> Matrix3<f64> {
        semloc_core::geom::so3_exp(&Vector3::new(x, y, z))
    }

    /// Body along world x at 1 m/s turning about world z at 0.5 rad/s, camera z along body x:
    /// the left camera moves forward along its z and turns about its −y, exactly.
    #[test]
    fn ground_truth_is_the_rectified_left_camera_rebased() {
        let rig = simple_rig(false, Matrix3::identity());
        let dir = tempfile::tempdir().unwrap();
        write_sequence(dir.path(), &rig, 4);
        let seq = Sequence::open(&dir.path().join("mav0"), None).unwrap();
        assert_eq!(
            seq.name,
            dir.path().canonicalize().unwrap().file_name().unwrap().to_string_lossy()
        );
        assert!(seq.gt_problem.is_none(), "{:?}", seq.gt_problem);
        let gt = seq.gt.as_ref().unwrap();
        assert_eq!(gt.len(), 4);
        assert_eq!(gt[0], Se3::identity());
        for (i, g) in gt.iter().enumerate() {
            let t = seq.times_s[i];
            // World motion: (t + 4, ...) and yaw 0.5 t. In the camera (rebased): forward t along
            // z rotated by the yaw: x_cam = −y_body, z_cam = x_body.
            let yaw = 0.5 * t;
            let want_rot =
                Matrix3::new(yaw.cos(), 0.0, -yaw.sin(), 0.0, 1.0, 0.0, yaw.sin(), 0.0, yaw.cos());
            assert!((g.rot - want_rot).amax() < 1e-9, "frame {i}: {}", g.rot);
            assert!((g.trans - Vector3::new(0.0, 0.0, t)).amax() < 1e-9, "frame {i}: {}", g.trans);
        }
    }

    #[test]
    fn frames_outside_the_ground_truth_end_it_with_the_problem() {
        let rig = simple_rig(false, Matrix3::identity());
        let dir = tempfile::tempdir().unwrap();
        write_sequence(dir.path(), &rig, 4);
        let gt = dir.path().join("mav0/state_groundtruth_estimate0/data.csv");
        let text = fs::read_to_string(&gt).unwrap();
        // Cut the samples after frame 1's time (t = 0.05 s: 12 samples from −10 ms).
        let short: String = text.lines().take(1 + 14).map(|l| format!("{l}\n")).collect();
        fs::write(&gt, short).unwrap();
        let seq = Sequence::open(dir.path(), None).unwrap();
        assert_eq!(seq.gt.as_ref().map(Vec::len), Some(2));
        let e = seq.gt_problem.clone().unwrap();
        assert!(matches!(e, DatasetError::GtNotCovered { frame: 2, .. }), "{e}");
        assert!(e.to_string().contains("data.csv"), "{e}");
        // A bad line is the problem reported (it is why the samples stop).
        let bad: String = text
            .lines()
            .enumerate()
            .map(|(i, l)| {
                if i == 20 {
                    "1403636579,nan,0,0,1,0,0,0\n".to_string()
                } else {
                    format!("{l}\n")
                }
            })
            .collect();
        fs::write(&gt, bad).unwrap();
        let seq = Sequence::open(dir.path(), None).unwrap();
        assert!(
            matches!(seq.gt_problem, Some(DatasetError::NonFinite { line: 21, .. })),
            "{:?}",
            seq.gt_problem
        );
        // Starting after the first image: no ground truth at all, and why.
        let late: String =
            text.lines().take(1).chain(text.lines().skip(5)).map(|l| format!("{l}\n")).collect();
        fs::write(&gt, late).unwrap();
        let seq = Sequence::open(dir.path(), None).unwrap();
        assert!(seq.gt.is_none());
        assert!(matches!(seq.gt_problem, Some(DatasetError::GtNotCovered { frame: 0, .. })));
    }

    #[test]
    fn malformed_sequences_are_typed_errors_naming_the_file() {
        let rig = simple_rig(false, Matrix3::identity());
        let dir = tempfile::tempdir().unwrap();
        write_sequence(dir.path(), &rig, 3);
        let mav = dir.path().join("mav0");
        let csv1 = mav.join("cam1/data.csv");
        let good1 = fs::read_to_string(&csv1).unwrap();
        let open = || Sequence::open(dir.path(), None).unwrap_err();

        // cam1 lacks frame 1: its timestamp in cam0 has no partner.
        let lines: Vec<&str> = good1.lines().collect();
        fs::write(&csv1, format!("{}\n{}\n{}\n", lines[0], lines[1], lines[3])).unwrap();
        let e = open();
        assert!(
            matches!(&e, DatasetError::UnpairedTimestamp { line: 3, timestamp_ns, .. } if *timestamp_ns == T0_NS + PERIOD_NS),
            "{e}"
        );
        assert!(e.to_string().contains("cam0/data.csv"), "{e}");
        // A timestamp in cam1 only.
        fs::write(&csv1, format!("{good1}{},x.png\n", T0_NS + 7 * PERIOD_NS)).unwrap();
        let e = open();
        assert!(matches!(&e, DatasetError::UnpairedTimestamp { line: 5, .. }), "{e}");
        assert!(e.to_string().contains("cam1/data.csv"), "{e}");
        // Bad lines and order.
        fs::write(&csv1, format!("{good1}garbage\n")).unwrap();
        assert!(matches!(open(), DatasetError::Parse { line: 5, .. }));
        fs::write(&csv1, format!("{good1}12x,a.png\n")).unwrap();
        assert!(matches!(open(), DatasetError::Parse { line: 5, .. }));
        fs::write(&csv1, format!("{}\n{}\n{}\n", lines[0], lines[2], lines[1])).unwrap();
        assert!(matches!(open(), DatasetError::TimesNotIncreasing { frame: 1, .. }));
        fs::write(&csv1, &good1).unwrap();
        // A listed image that is missing.
        let img = mav.join("cam1/data").join(format!("{}.png", T0_NS + PERIOD_NS));
        fs::rename(&img, dir.path().join("x.png")).unwrap();
        assert_eq!(open(), DatasetError::MissingFile { path: img.clone() });
        fs::rename(dir.path().join("x.png"), &img).unwrap();
        // The resolution does not match the images.
        let yaml1 = mav.join("cam1/sensor.yaml");
        let y = fs::read_to_string(&yaml1).unwrap();
        fs::write(&yaml1, y.replace("resolution: [376, 240]", "resolution: [752, 480]")).unwrap();
        assert!(matches!(open(), DatasetError::ImageSizeMismatch { expected: (752, 480), .. }));
        // cam1 to the left of cam0.
        let swapped = rigid(&r_bs(), &(r_bs() * Vector3::new(-0.11, 0.0, 0.0)));
        fs::write(&yaml1, yaml(&swapped, &rig.cam1, rig.size)).unwrap();
        let e = open();
        assert!(
            matches!(&e, DatasetError::BadCalib { .. })
                && e.to_string().contains("left of camera 0"),
            "{e}"
        );
        fs::write(&yaml1, &y).unwrap();
        // A missing sensor.yaml, an empty list.
        fs::remove_file(&yaml1).unwrap();
        assert_eq!(open(), DatasetError::MissingFile { path: yaml1.clone() });
        fs::write(&yaml1, &y).unwrap();
        fs::write(&csv1, "#timestamp [ns],filename\n").unwrap();
        fs::write(mav.join("cam0/data.csv"), "#timestamp [ns],filename\n").unwrap();
        assert!(matches!(open(), DatasetError::EmptySequence { .. }));
        // --pair has no meaning here.
        let e = Sequence::open(dir.path(), Some(super::super::CameraPair::Colour)).unwrap_err();
        assert!(matches!(e, DatasetError::PairNotAvailable { .. }), "{e}");
    }

    #[test]
    fn interpolation_is_linear_and_slerp() {
        let q0 = UnitQuaternion::identity();
        let q1 = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.4);
        let s = [(0.0, Vector3::zeros(), q0), (1.0, Vector3::new(2.0, 0.0, 0.0), q1)];
        let p = interpolate(&s, 0.25, 2.0).unwrap();
        assert!((p.trans - Vector3::new(0.5, 0.0, 0.0)).norm() < 1e-15);
        assert!((p.rotation_angle() - 0.1).abs() < 1e-12);
        // The same rotation with the opposite quaternion sign interpolates the short way.
        let s2 = [s[0], (1.0, s[1].1, UnitQuaternion::new_unchecked(-q1.into_inner()))];
        assert!((interpolate(&s2, 0.25, 2.0).unwrap().rotation_angle() - 0.1).abs() < 1e-12);
        assert!(interpolate(&s, 1.5, 2.0).unwrap_err().contains("outside"));
        assert!(interpolate(&s, 0.5, 0.5).unwrap_err().contains("no samples between"));
        assert_eq!(interpolate(&s, 1.0, 0.1).unwrap().trans, Vector3::new(2.0, 0.0, 0.0));
    }
}
