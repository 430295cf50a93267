//! KITTI calibration files: the `key: numbers` format shared by odometry `calib.txt`
//! (`P0`..`P3`, `Tr`) and the raw `calib_cam_to_cam.txt` / `calib_velo_to_cam.txt` /
//! `calib_imu_to_velo.txt`, and the stereo intrinsics derived from two rectified projection
//! matrices.
//!
//! Values are parsed lazily per key, as pykitti does: lines whose value is not numeric (e.g.
//! `calib_time: 09-Jan-2012 13:57:47`) are only an error if that key is asked for.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix4, Vector3};

use super::text::{numbered_lines, parse_numbers, read_text};
use super::{DatasetError, StereoCalib};

/// A parsed `key: value` calibration file; values are kept as text until asked for.
#[derive(Debug, Clone)]
pub(crate) struct CalibFile {
    path: PathBuf,
    /// (key, 1-based line, value text); a repeated key: the last one wins, as in pykitti.
    entries: Vec<(String, usize, String)>,
}

impl CalibFile {
    /// Reads and splits a calibration file. A non-blank line without `:` is a `Parse` error.
    pub(crate) fn read(path: &Path) -> Result<Self, DatasetError> {
        let text = read_text(path)?;
        Self::parse(path, &text)
    }

    /// Splits calibration text (`path` only names the file in errors).
    pub(crate) fn parse(path: &Path, text: &str) -> Result<Self, DatasetError> {
        let mut entries = Vec::new();
        for (line, l) in numbered_lines(text) {
            let Some((key, value)) = l.split_once(':') else {
                return Err(DatasetError::Parse {
                    path: path.to_path_buf(),
                    line,
                    msg: "expected `key: numbers`".into(),
                });
            };
            entries.push((key.trim().to_string(), line, value.to_string()));
        }
        Ok(Self { path: path.to_path_buf(), entries })
    }

    /// The file this was read from.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// Whether a `key:` line exists.
    pub(crate) fn has(&self, key: &str) -> bool {
        self.entries.iter().any(|(k, _, _)| k == key)
    }

    /// The `n` finite numbers of the `key:` line.
    pub(crate) fn numbers(&self, key: &str, n: usize) -> Result<Vec<f64>, DatasetError> {
        let (_, line, value) =
            self.entries.iter().rev().find(|(k, _, _)| k == key).ok_or_else(|| {
                DatasetError::MissingKey { path: self.path.clone(), key: key.to_string() }
            })?;
        parse_numbers(&self.path, *line, value, Some(n))
    }

    /// A row-major 3x4 projection matrix (12 numbers).
    pub(crate) fn mat3x4(&self, key: &str) -> Result<[f64; 12], DatasetError> {
        let v = self.numbers(key, 12)?;
        let mut m = [0.0; 12];
        m.copy_from_slice(&v);
        Ok(m)
    }

    /// A row-major 3x3 matrix (9 numbers).
    pub(crate) fn mat3(&self, key: &str) -> Result<Matrix3<f64>, DatasetError> {
        let v = self.numbers(key, 9)?;
        Ok(Matrix3::from_row_slice(&v))
    }

    /// A rotation (9 numbers, row-major): orthonormal to 1e-3 with determinant +1, as KITTI's
    /// 7-digit files are to ~1e-6. Anything else (a degenerate or scaled matrix) is a
    /// `BadCalib` error rather than poses that silently blow up when inverted.
    pub(crate) fn rotation(&self, key: &str) -> Result<Matrix3<f64>, DatasetError> {
        let r = self.mat3(key)?;
        let off = (r.transpose() * r - Matrix3::identity()).abs().max();
        let det = r.determinant();
        if !(off <= 1e-3 && (det - 1.0).abs() <= 1e-3) {
            return Err(DatasetError::BadCalib {
                path: self.path.clone(),
                msg: format!("`{key}` is not a rotation (|RᵀR − I| = {off:.3e}, det = {det:.6})"),
            });
        }
        Ok(r)
    }

    /// The rigid transform of a raw `calib_*_to_*.txt` file (`R:` 9 numbers, `T:` 3) as a 4x4
    /// homogeneous matrix, exactly as pykitti's `transform_from_rot_trans`.
    pub(crate) fn rigid(&self) -> Result<Matrix4<f64>, DatasetError> {
        let r = self.rotation("R")?;
        let t = self.numbers("T", 3)?;
        Ok(homogeneous(&r, &Vector3::new(t[0], t[1], t[2])))
    }
}

/// `[R t; 0 1]`.
pub(crate) fn homogeneous(r: &Matrix3<f64>, t: &Vector3<f64>) -> Matrix4<f64> {
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0).copy_from(r);
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(t);
    m
}

/// Stereo intrinsics from the rectified projection matrices of the left and right camera.
///
/// Both KITTI layouts give each camera `P = K [I | t]` in the rectified frame of camera 0, so
/// `P[0][3] = fx · t_x`; the baseline is the x distance between the two camera centres,
/// `-(P_right[0][3] - P_left[0][3]) / fx`. This holds for the grey pair (P0 offset 0) and the
/// colour pair (P2, P3 both offset) alike.
pub(crate) fn stereo_from_projections(
    path: &Path,
    left: &[f64; 12],
    right: &[f64; 12],
) -> Result<StereoCalib, DatasetError> {
    let bad = |msg: String| DatasetError::BadCalib { path: path.to_path_buf(), msg };
    let (fx, fy, cx, cy) = (left[0], left[5], left[2], left[6]);
    if fx <= 0.0 || fy <= 0.0 {
        return Err(bad(format!("focal lengths must be positive, got fx={fx} fy={fy}")));
    }
    if (right[0] - fx).abs() > 1e-6 * fx {
        return Err(bad(format!(
            "left and right focal lengths differ ({fx} vs {}): not a rectified pair",
            right[0]
        )));
    }
    let baseline_m = -(right[3] - left[3]) / fx;
    if baseline_m == 0.0 {
        return Err(bad(
            "baseline is zero: the right projection matrix has the same translation as the \
             left one (the same camera twice?)"
                .to_string(),
        ));
    }
    if baseline_m < 0.0 {
        return Err(bad(format!(
            "baseline must be positive, got {baseline_m} m: the right camera is to the left \
             (left and right swapped?)"
        )));
    }
    Ok(StereoCalib { fx_px: fx, fy_px: fy, cx_px: cx, cy_px: cy, baseline_m })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Odometry sequence 00's calib.txt, verbatim.
    const ODO_00: &str = "\
P0: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 0.000000000000e+00 0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00
P1: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.861448000000e+02 0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00
P2: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 4.538225000000e+01 0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 -1.130887000000e-01 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 3.779761000000e-03
P3: 7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.372877000000e+02 0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 2.369057000000e+00 0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 4.915215000000e-03
Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 -7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01
";

    #[test]
    fn odometry_grey_and_colour_baselines() {
        let p = Path::new("calib.txt");
        let c = CalibFile::parse(p, ODO_00).unwrap();
        let grey =
            stereo_from_projections(p, &c.mat3x4("P0").unwrap(), &c.mat3x4("P1").unwrap()).unwrap();
        assert_eq!(grey.fx_px, 718.856);
        assert_eq!(grey.cx_px, 607.1928);
        assert_eq!(grey.cy_px, 185.2157);
        assert!((grey.baseline_m * grey.fx_px - 386.1448).abs() < 1e-9);
        let col =
            stereo_from_projections(p, &c.mat3x4("P2").unwrap(), &c.mat3x4("P3").unwrap()).unwrap();
        assert!((col.baseline_m * col.fx_px - (45.38225 + 337.2877)).abs() < 1e-9);
        assert_eq!(c.numbers("Tr", 12).unwrap().len(), 12);
    }

    #[test]
    fn non_numeric_values_only_fail_when_asked_for() {
        let p = Path::new("calib_cam_to_cam.txt");
        let c = CalibFile::parse(p, "calib_time: 09-Jan-2012 13:57:47\nT: 1 2 3\n").unwrap();
        assert!(c.has("calib_time"));
        assert_eq!(c.numbers("T", 3).unwrap(), vec![1.0, 2.0, 3.0]);
        let e = c.numbers("calib_time", 1).unwrap_err();
        assert!(matches!(e, DatasetError::BadFieldCount { line: 1, .. }), "{e}");
        let e = c.numbers("R", 9).unwrap_err();
        assert_eq!(e, DatasetError::MissingKey { path: p.into(), key: "R".into() });
        assert!(e.to_string().contains("calib_cam_to_cam.txt"));
    }

    #[test]
    fn rigid_is_r_then_t() {
        let p = Path::new("calib_velo_to_cam.txt");
        let c = CalibFile::parse(p, "R: 0 -1 0 1 0 0 0 0 1\nT: 1 2 3\n").unwrap();
        let m = c.rigid().unwrap();
        assert_eq!(m[(0, 1)], -1.0);
        assert_eq!(m[(1, 0)], 1.0);
        assert_eq!(m[(2, 3)], 3.0);
        assert_eq!(m[(3, 3)], 1.0);
    }

    #[test]
    fn line_without_colon_is_a_parse_error() {
        let e = CalibFile::parse(Path::new("calib.txt"), "P0: 1\ngarbage\n").unwrap_err();
        assert!(matches!(e, DatasetError::Parse { line: 2, .. }), "{e}");
    }

    #[test]
    fn zero_focal_or_negative_baseline_is_bad_calib() {
        let p = Path::new("calib.txt");
        let mut l = [0.0; 12];
        let r = l;
        assert!(matches!(stereo_from_projections(p, &l, &r), Err(DatasetError::BadCalib { .. })));
        l[0] = 700.0;
        l[5] = 700.0;
        let mut r = l;
        r[3] = 10.0; // right camera to the left of the left one
        assert!(matches!(stereo_from_projections(p, &l, &r), Err(DatasetError::BadCalib { .. })));
    }
}
