//! Trajectory files: KITTI pose files and TUM files.
//!
//! * **KITTI** (odometry `poses/XX.txt`, also what ORB-SLAM2 writes): one pose a line, 12
//!   numbers, the 3x4 `[R | t]` camera-to-world matrix in row-major order. No timestamps.
//! * **TUM** (RGB-D benchmark): `timestamp tx ty tz qx qy qz qw` a line; `#` starts a comment
//!   (whole line or the rest of a line). The quaternion is normalised on reading.
//!
//! Fields are separated by whitespace; blank lines are skipped. Every error names the file and,
//! where there is one, the line (1-based). Non-finite numbers (`nan`, `inf`) are rejected.
//!
//! Writers print each number in its shortest form that parses back to the same `f64`, so
//! `read_kitti(write_kitti(poses)) == poses` bit for bit (TUM: the numbers written round-trip
//! exactly; the rotation goes through a quaternion, so it round-trips to ~1e-16).

use core::fmt::Write as _;
use std::fs;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix3x4, Quaternion, Rotation3, UnitQuaternion, Vector3};
use semloc_core::geom::Se3;

/// An error reading or writing a trajectory file. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum TrajError {
    /// The file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A line holds the wrong number of fields.
    #[error("{}:{line}: expected {expected} numbers, found {found}", path.display())]
    FieldCount {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// How many fields the format needs.
        expected: usize,
        /// How many the line holds.
        found: usize,
    },
    /// A field is not a number.
    #[error("{}:{line}: field {field} is not a number: {text:?}", path.display())]
    NotANumber {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// 1-based field index on the line.
        field: usize,
        /// The offending text.
        text: String,
    },
    /// A field is NaN or infinite.
    #[error("{}:{line}: field {field} is not finite: {text:?}", path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// 1-based field index on the line.
        field: usize,
        /// The offending text.
        text: String,
    },
    /// A TUM line's quaternion has zero length.
    #[error("{}:{line}: quaternion has zero norm", path.display())]
    ZeroQuaternion {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
    },
    /// The first data line has a field count of neither format (12: KITTI, 8: TUM).
    #[error("{}:{line}: {found} fields: neither a KITTI (12) nor a TUM (8) trajectory", path.display())]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Fields on that line.
        found: usize,
    },
    /// A KITTI line's 3x3 block is not a rotation (not orthonormal, or a reflection).
    #[error("{}:{line}: {}", path.display(), not_rotation_msg(*deviation, *det))]
    NotRotation {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// Largest entry of |RᵀR − I|.
        deviation: f64,
        /// Determinant of R.
        det: f64,
    },
    /// A TUM timestamp is not after the one before it.
    #[error(
        "{}:{line}: timestamp {time} is not after the previous one ({previous}); TUM times \
         must increase strictly",
        path.display()
    )]
    TimeNotIncreasing {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The timestamp.
        time: f64,
        /// The previous line's.
        previous: f64,
    },
    /// The file holds no poses.
    #[error("{}: no poses in file", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
}

/// Parses the data lines of `text`: strips `#` comments when `comments`, skips blank lines,
/// checks the field count and returns `(line number, numbers)` for each data line.
fn parse_lines(
    text: &str,
    path: &Path,
    expected: usize,
    comments: bool,
) -> Result<Vec<(usize, Vec<f64>)>, TrajError> {
    let mut rows = Vec::new();
    for (idx, raw) in text.lines().enumerate() {
        let line = idx + 1;
        let content = if comments { raw.split('#').next().unwrap_or("") } else { raw };
        let fields: Vec<&str> = content.split_whitespace().collect();
        if fields.is_empty() {
            continue;
        }
        if fields.len() != expected {
            return Err(TrajError::FieldCount {
                path: path.to_path_buf(),
                line,
                expected,
                found: fields.len(),
            });
        }
        let mut nums = Vec::with_capacity(expected);
        for (f, s) in fields.iter().enumerate() {
            let v: f64 = s.parse().map_err(|_| TrajError::NotANumber {
                path: path.to_path_buf(),
                line,
                field: f + 1,
                text: (*s).to_string(),
            })?;
            if !v.is_finite() {
                return Err(TrajError::NonFinite {
                    path: path.to_path_buf(),
                    line,
                    field: f + 1,
                    text: (*s).to_string(),
                });
            }
            nums.push(v);
        }
        rows.push((line, nums));
    }
    if rows.is_empty() {
        return Err(TrajError::Empty { path: path.to_path_buf() });
    }
    Ok(rows)
}

fn read_text(path: &Path) -> Result<String, TrajError> {
    fs::read_to_string(path).map_err(|source| TrajError::Io { path: path.to_path_buf(), source })
}

fn write_text(path: &Path, text: &str) -> Result<(), TrajError> {
    let io = |source| TrajError::Io { path: path.to_path_buf(), source };
    let mut f = fs::File::create(path).map_err(io)?;
    f.write_all(text.as_bytes()).map_err(io)?;
    f.flush().map_err(io)
}

/// A trajectory file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrajFormat {
    /// KITTI pose file: 12 numbers a line.
    Kitti,
    /// TUM file: `timestamp tx ty tz qx qy qz qw` a line.
    Tum,
}

/// Tells the format of trajectory text from its first data line (after blank and `#` lines):
/// 12 fields → KITTI, 8 → TUM. `path` is only used in error messages.
pub fn detect_format_of(text: &str, path: &Path) -> Result<TrajFormat, TrajError> {
    for (idx, raw) in text.lines().enumerate() {
        let content = raw.split('#').next().unwrap_or("");
        let found = content.split_whitespace().count();
        match found {
            0 => continue,
            12 => return Ok(TrajFormat::Kitti),
            8 => return Ok(TrajFormat::Tum),
            _ => {
                return Err(TrajError::UnknownFormat {
                    path: path.to_path_buf(),
                    line: idx + 1,
                    found,
                })
            }
        }
    }
    Err(TrajError::Empty { path: path.to_path_buf() })
}

/// Tells the format of a trajectory file from its first data line (see [`detect_format_of`]).
pub fn detect_format(path: impl AsRef<Path>) -> Result<TrajFormat, TrajError> {
    let path = path.as_ref();
    detect_format_of(&read_text(path)?, path)
}

/// Pairs poses of two timestamped trajectories one to one: every stamp of the shorter list is
/// matched to the nearest stamp of the longer one (the first such on ties), as evo's
/// `associate_trajectories` does, and kept when they differ by at most `max_dt` seconds; when
/// two stamps pick the same partner only the closer pair is kept (evo would use that pose
/// twice and weight it double in the ATE). Returns `(index into gt, index into est)` pairs in
/// the order of the shorter list.
pub fn associate_by_time(gt: &[f64], est: &[f64], max_dt: f64) -> Vec<(usize, usize)> {
    let pairs = nearest_pairs(gt, est, max_dt);
    let est_longer = est.len() > gt.len();
    let partner = |p: &(usize, usize)| if est_longer { p.1 } else { p.0 };
    let gap = |p: &(usize, usize)| (gt[p.0] - est[p.1]).abs();
    let mut best: std::collections::HashMap<usize, (usize, usize)> = Default::default();
    for p in &pairs {
        best.entry(partner(p))
            .and_modify(|b| {
                if gap(p) < gap(b) {
                    *b = *p;
                }
            })
            .or_insert(*p);
    }
    pairs.into_iter().filter(|p| best.get(&partner(p)) == Some(p)).collect()
}

/// evo's nearest-stamp matching (see [`associate_by_time`]), which may use a pose twice.
fn nearest_pairs(gt: &[f64], est: &[f64], max_dt: f64) -> Vec<(usize, usize)> {
    let est_longer = est.len() > gt.len();
    let (short, long) = if est_longer { (gt, est) } else { (est, gt) };
    let sorted = long.windows(2).all(|w| w[0] <= w[1]);
    let nearest = |t: f64| -> Option<usize> {
        if long.is_empty() || !t.is_finite() {
            return None;
        }
        if sorted {
            let k = long.partition_point(|&x| x < t);
            // Candidates k-1 and k; prefer the earlier on a tie, as numpy's argmin does.
            let mut best = k.min(long.len() - 1);
            if k > 0 && (t - long[k - 1]).abs() <= (long[best] - t).abs() {
                best = k - 1;
            }
            Some(best)
        } else {
            (0..long.len()).min_by(|&a, &b| (long[a] - t).abs().total_cmp(&(long[b] - t).abs()))
        }
    };
    short
        .iter()
        .enumerate()
        .filter_map(|(i, &t)| {
            let j = nearest(t)?;
            ((long[j] - t).abs() <= max_dt).then_some(if est_longer { (i, j) } else { (j, i) })
        })
        .collect()
}

/// How far from orthonormal a stored rotation may be (largest entry of |RᵀR − I|): files
/// keep 6 to 9 digits, which leaves ~1e-7; anything near this is not a rotation.
pub const ROTATION_TOLERANCE: f64 = 1e-3;

/// `Some((largest entry of |RᵀR − I|, det R))` when `rot` is not a rotation: farther from
/// orthonormal than [`ROTATION_TOLERANCE`], or a reflection (NaN fails too). The rule every
/// reader of KITTI pose files applies, estimates and ground truth alike.
pub fn rotation_defect(rot: &Matrix3<f64>) -> Option<(f64, f64)> {
    let deviation = (rot.transpose() * rot - Matrix3::identity()).amax();
    let det = rot.determinant();
    // Written so that NaN is a defect.
    let ok = deviation <= ROTATION_TOLERANCE && det > 0.0;
    (!ok).then_some((deviation, det))
}

/// What is wrong with a pose line that [`rotation_defect`] refuses.
pub fn not_rotation_msg(deviation: f64, det: f64) -> String {
    format!(
        "the 3x3 part is not a rotation matrix (|RᵀR − I| = {deviation:.2e}, det {det:.4}); poses \
         must be rigid camera-to-world transforms"
    )
}

/// Parses KITTI pose text; `path` is only used in error messages. `#` starts a comment. A
/// 3x3 block that is not a rotation ([`ROTATION_TOLERANCE`], or a reflection) is an error.
pub fn parse_kitti(text: &str, path: &Path) -> Result<Vec<Se3>, TrajError> {
    let rows = parse_lines(text, path, 12, true)?;
    rows.into_iter()
        .map(|(line, n)| {
            let pose = Se3::from_matrix3x4(&Matrix3x4::from_row_slice(&n));
            if let Some((deviation, det)) = rotation_defect(&pose.rot) {
                return Err(TrajError::NotRotation {
                    path: path.to_path_buf(),
                    line,
                    deviation,
                    det,
                });
            }
            Ok(pose)
        })
        .collect()
}

/// Reads a KITTI pose file (12 numbers a line, 3x4 row-major camera-to-world).
pub fn read_kitti(path: impl AsRef<Path>) -> Result<Vec<Se3>, TrajError> {
    let path = path.as_ref();
    parse_kitti(&read_text(path)?, path)
}

/// Parses TUM trajectory text; `path` is only used in error messages.
pub fn parse_tum(text: &str, path: &Path) -> Result<Vec<(f64, Se3)>, TrajError> {
    let rows = parse_lines(text, path, 8, true)?;
    for w in rows.windows(2) {
        if w[1].1[0] <= w[0].1[0] {
            return Err(TrajError::TimeNotIncreasing {
                path: path.to_path_buf(),
                line: w[1].0,
                time: w[1].1[0],
                previous: w[0].1[0],
            });
        }
    }
    rows.into_iter()
        .map(|(line, n)| {
            // nalgebra's Quaternion::new takes (w, i, j, k).
            let q = Quaternion::new(n[7], n[4], n[5], n[6]);
            if q.norm() == 0.0 {
                return Err(TrajError::ZeroQuaternion { path: path.to_path_buf(), line });
            }
            let rot = UnitQuaternion::from_quaternion(q).to_rotation_matrix().into_inner();
            Ok((n[0], Se3::new(rot, Vector3::new(n[1], n[2], n[3]))))
        })
        .collect()
}

/// Reads a TUM trajectory file (`timestamp tx ty tz qx qy qz qw`, `#` comments).
pub fn read_tum(path: impl AsRef<Path>) -> Result<Vec<(f64, Se3)>, TrajError> {
    let path = path.as_ref();
    parse_tum(&read_text(path)?, path)
}

/// Appends `v` in the shortest decimal form that parses back to exactly `v`
/// (plain notation for ordinary magnitudes, scientific otherwise).
fn push_num(out: &mut String, v: f64) {
    let a = v.abs();
    // Both `{}` and `{:e}` print the shortest round-tripping digits.
    let _ = if a == 0.0 || (1e-5..1e16).contains(&a) {
        write!(out, "{v}")
    } else {
        write!(out, "{v:e}")
    };
}

/// Formats poses as KITTI pose text (one line each, shortest exact numbers).
pub fn format_kitti(poses: &[Se3]) -> String {
    let mut out = String::with_capacity(poses.len() * 12 * 12);
    for p in poses {
        let m = p.to_matrix3x4();
        for r in 0..3 {
            for c in 0..4 {
                if r + c > 0 {
                    out.push(' ');
                }
                push_num(&mut out, m[(r, c)]);
            }
        }
        out.push('\n');
    }
    out
}

/// Writes a KITTI pose file; reading it back gives the same poses bit for bit.
pub fn write_kitti(path: impl AsRef<Path>, poses: &[Se3]) -> Result<(), TrajError> {
    write_text(path.as_ref(), &format_kitti(poses))
}

/// The unit quaternion of a pose's rotation, re-orthonormalising it first if needed.
fn rot_to_quat(rot: &Matrix3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*rot))
}

/// The `#` header line of TUM files semloc writes.
pub const TUM_HEADER: &str = "# timestamp tx ty tz qx qy qz qw\n";

/// Formats timestamped poses as TUM text, with a `#` header line.
pub fn format_tum(poses: &[(f64, Se3)]) -> String {
    let mut out = String::from(TUM_HEADER);
    for (t, p) in poses {
        out.push_str(&format_tum_line(*t, p));
    }
    out
}

/// One TUM line (`timestamp tx ty tz qx qy qz qw` and a newline).
pub fn format_tum_line(t: f64, p: &Se3) -> String {
    let mut out = String::with_capacity(8 * 24);
    let q = rot_to_quat(&p.rot);
    let nums = [t, p.trans.x, p.trans.y, p.trans.z, q.i, q.j, q.k, q.w];
    for (i, v) in nums.iter().enumerate() {
        if i > 0 {
            out.push(' ');
        }
        push_num(&mut out, *v);
    }
    out.push('\n');
    out
}

/// Writes a TUM trajectory file (`timestamp tx ty tz qx qy qz qw`).
pub fn write_tum(path: impl AsRef<Path>, poses: &[(f64, Se3)]) -> Result<(), TrajError> {
    write_text(path.as_ref(), &format_tum(poses))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn p() -> &'static Path {
        Path::new("t.txt")
    }

    fn rot_from(ax: f64, ay: f64, az: f64) -> Matrix3<f64> {
        Rotation3::from_euler_angles(ax, ay, az).into_inner()
    }

    proptest! {
        #[test]
        fn kitti_round_trip_is_exact(
            vals in proptest::collection::vec(
                (-3.2f64..3.2, -3.2f64..3.2, -3.2f64..3.2, -1e6f64..1e6, -1e-7f64..1e-7, -1e3f64..1e3),
                1..20)
        ) {
            let poses: Vec<Se3> = vals.iter()
                .map(|&(a, b, c, x, y, z)| Se3::new(rot_from(a, b, c), Vector3::new(x, y, z)))
                .collect();
            let back = parse_kitti(&format_kitti(&poses), p()).unwrap();
            prop_assert_eq!(back, poses);
        }

        #[test]
        fn tum_round_trip(
            vals in proptest::collection::vec(
                (0.0f64..1e9, -3.2f64..3.2, -3.2f64..3.2, -3.2f64..3.2, -1e4f64..1e4),
                1..20)
        ) {
            // Strictly increasing times, as the reader requires: a running sum of the draws.
            let mut clock = 0.0;
            let poses: Vec<(f64, Se3)> = vals.iter()
                .map(|&(t, a, b, c, x)| {
                    clock += 1e-3 + t;
                    (clock, Se3::new(rot_from(a, b, c), Vector3::new(x, -x, 0.5 * x)))
                })
                .collect();
            let back = parse_tum(&format_tum(&poses), p()).unwrap();
            prop_assert_eq!(back.len(), poses.len());
            for ((t0, p0), (t1, p1)) in poses.iter().zip(&back) {
                prop_assert_eq!(t0, t1);
                prop_assert_eq!(p0.trans, p1.trans);
                prop_assert!((p0.rot - p1.rot).abs().max() < 1e-14);
            }
        }
    }

    #[test]
    fn kitti_reads_identity_and_blank_lines() {
        let text = "1 0 0 0 0 1 0 0 0 0 1 0\n\n  1 0 0 1.5 0 1 0 -2 0 0 1 3e2  \n";
        let poses = parse_kitti(text, p()).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0], Se3::identity());
        assert_eq!(poses[1].trans, Vector3::new(1.5, -2.0, 300.0));
    }

    #[test]
    fn kitti_bad_inputs_name_file_and_line() {
        let good = "1 0 0 0 0 1 0 0 0 0 1 0\n";
        let e = parse_kitti(&format!("{good}1 0 0 0 0 1 0 0 0 0 1 0 7\n"), p()).unwrap_err();
        assert!(matches!(e, TrajError::FieldCount { line: 2, expected: 12, found: 13, .. }));
        assert_eq!(e.to_string(), "t.txt:2: expected 12 numbers, found 13");
        let e = parse_kitti("1 0 0 0 0 1 0 0 0 0 1\n", p()).unwrap_err();
        assert!(matches!(e, TrajError::FieldCount { line: 1, found: 11, .. }));
        let e = parse_kitti(&format!("{good}{good}1 0 0 x 0 1 0 0 0 0 1 0\n"), p()).unwrap_err();
        assert!(matches!(e, TrajError::NotANumber { line: 3, field: 4, .. }), "{e}");
        assert!(e.to_string().starts_with("t.txt:3:"));
        let e = parse_kitti("1 0 0 NaN 0 1 0 0 0 0 1 0\n", p()).unwrap_err();
        assert!(matches!(e, TrajError::NonFinite { line: 1, field: 4, .. }));
        let e = parse_kitti("1 0 0 0 0 1 0 -inf 0 0 1 0\n", p()).unwrap_err();
        assert!(matches!(e, TrajError::NonFinite { line: 1, field: 8, .. }));
        let e = parse_kitti("", p()).unwrap_err();
        assert!(matches!(e, TrajError::Empty { .. }));
        assert_eq!(e.to_string(), "t.txt: no poses in file");
        assert!(matches!(parse_kitti(" \n\n", p()), Err(TrajError::Empty { .. })));
    }

    #[test]
    fn tum_comments_and_bad_inputs() {
        let text = "# header\n1.5 1 2 3 0 0 0 1 # trailing\n\n2.5 1 2 3 0 0 1 0\n";
        let poses = parse_tum(text, p()).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].0, 1.5);
        assert_eq!(poses[0].1.rot, Matrix3::identity());
        assert_eq!(poses[1].1.trans, Vector3::new(1.0, 2.0, 3.0));
        // 180 degrees about z.
        assert!((poses[1].1.rot - rot_from(0.0, 0.0, core::f64::consts::PI)).abs().max() < 1e-12);
        // Non-unit quaternions are normalised.
        let q = parse_tum("0 0 0 0 0 0 0 2\n", p()).unwrap();
        assert!((q[0].1.rot - Matrix3::identity()).abs().max() < 1e-15);
        let e = parse_tum("0 0 0 0 0 0 0 0\n", p()).unwrap_err();
        assert!(matches!(e, TrajError::ZeroQuaternion { line: 1, .. }));
        let e = parse_tum("#only comments\n0 1 2 3 0 0 0\n", p()).unwrap_err();
        assert!(matches!(e, TrajError::FieldCount { line: 2, expected: 8, found: 7, .. }));
        let e = parse_tum("0 1 2 3 0 0 0 inf\n", p()).unwrap_err();
        assert!(matches!(e, TrajError::NonFinite { field: 8, .. }));
        assert!(matches!(parse_tum("# nothing\n", p()), Err(TrajError::Empty { .. })));
    }

    #[test]
    fn format_detection() {
        let k = "# c\n\n1 0 0 0 0 1 0 0 0 0 1 0\n";
        assert_eq!(detect_format_of(k, p()).unwrap(), TrajFormat::Kitti);
        assert_eq!(detect_format_of("0 1 2 3 0 0 0 1\n", p()).unwrap(), TrajFormat::Tum);
        let e = detect_format_of("\n1 2 3\n", p()).unwrap_err();
        assert!(matches!(e, TrajError::UnknownFormat { line: 2, found: 3, .. }));
        assert!(matches!(detect_format_of("# x\n", p()), Err(TrajError::Empty { .. })));
    }

    #[test]
    fn association_follows_evo() {
        let gt = [0.0, 0.1, 0.2, 0.3, 0.4];
        let est = [0.004, 0.2, 0.305, 0.5];
        // est is shorter: each est stamp gets its nearest gt stamp.
        assert_eq!(associate_by_time(&gt, &est, 0.01), vec![(0, 0), (2, 1), (3, 2)]);
        assert_eq!(associate_by_time(&gt, &est, 0.2), vec![(0, 0), (2, 1), (3, 2), (4, 3)]);
        // gt shorter: each gt stamp gets its nearest est stamp; a tie takes the earlier.
        assert_eq!(
            associate_by_time(&[0.0, 0.25], &[0.0, 0.125, 0.375], 0.2),
            vec![(0, 0), (1, 1)]
        );
        // Unsorted stamps fall back to a full search.
        assert_eq!(associate_by_time(&[0.3, 0.1], &[0.1, 0.3, 0.2], 0.01), vec![(0, 1), (1, 0)]);
        assert!(associate_by_time(&[], &est, 1.0).is_empty());
        assert!(associate_by_time(&gt, &[], 1.0).is_empty());
    }

    #[test]
    fn association_is_one_to_one() {
        // A sparse estimate around one ground-truth stamp: evo pairs gt 1.0 with est 0.98
        // and 1.03 both, counting that ground-truth pose twice in the ATE; only the closer
        // pair is kept.
        let gt = [0.0, 1.0, 2.0, 3.0];
        let est = [0.98, 1.03, 2.0];
        assert_eq!(nearest_pairs(&gt, &est, 0.1), vec![(1, 0), (1, 1), (2, 2)]);
        assert_eq!(associate_by_time(&gt, &est, 0.1), vec![(1, 0), (2, 2)]);
        let mut used: Vec<usize> = associate_by_time(&gt, &est, 0.1).iter().map(|p| p.0).collect();
        used.dedup();
        assert_eq!(used.len(), 2);
    }

    #[test]
    fn files_round_trip_and_missing_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("poses.txt");
        let poses =
            vec![Se3::identity(), Se3::new(rot_from(0.1, 0.2, 0.3), Vector3::new(1e-9, 2.0, -3e7))];
        write_kitti(&f, &poses).unwrap();
        assert_eq!(read_kitti(&f).unwrap(), poses);
        let tf = dir.path().join("poses.tum");
        let stamped: Vec<(f64, Se3)> =
            poses.iter().enumerate().map(|(i, p)| (i as f64 * 0.1, *p)).collect();
        write_tum(&tf, &stamped).unwrap();
        assert_eq!(read_tum(&tf).unwrap().len(), 2);
        let missing = dir.path().join("nope.txt");
        let e = read_kitti(&missing).unwrap_err();
        assert!(matches!(e, TrajError::Io { .. }));
        assert!(e.to_string().contains("nope.txt"), "{e}");
        let e = write_kitti(dir.path().join("no/such/dir.txt"), &poses).unwrap_err();
        assert!(e.to_string().contains("dir.txt"), "{e}");
    }
}
