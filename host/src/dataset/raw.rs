//! KITTI raw layout (synced + rectified):
//! `DATE/{calib_cam_to_cam.txt, calib_imu_to_velo.txt, calib_velo_to_cam.txt}` and
//! `DATE/DATE_drive_NNNN_sync/{image_0X/{data/*.png, timestamps.txt}, oxts/data/*.txt}`.
//!
//! Ground truth follows pykitti's `raw` loader step for step, in 4x4 homogeneous matrices with
//! general inverses (the calibration rotations are only orthonormal to ~1e-7, so a transpose
//! would differ from the reference in the last digits):
//!
//! ```text
//! T_cam0unrect_velo = [R|T] of calib_velo_to_cam       T_velo_imu = [R|T] of calib_imu_to_velo
//! T_L               = I with x = P_rect_0L[0,3] / P_rect_0L[0,0]   (L = 0 grey, 2 colour)
//! T_camL_imu        = T_L · R_rect_00 · T_cam0unrect_velo · T_velo_imu
//! T_w_camL(i)       = T_w_imu(i) · T_camL_imu⁻¹             (T_w_imu from oxts, see `oxts`)
//! G_i               = T_w_camL(0)⁻¹ · T_w_camL(i)           (so G_0 = I)
//! ```

use std::path::{Path, PathBuf};

use nalgebra::{Matrix4, Vector3};
use semloc_core::geom::Se3;

use super::calib::{homogeneous, stereo_from_projections, CalibFile};
use super::text::{list_files, numbered_lines, read_text};
use super::{
    check_times, first_pair_size, list_pair, oxts, CameraPair, DatasetError, Layout, Sequence,
};

/// Whether `name` looks like a KITTI date folder, `YYYY_MM_DD`.
pub fn is_date_name(name: &str) -> bool {
    let b = name.as_bytes();
    b.len() == 10
        && b.iter()
            .enumerate()
            .all(|(i, c)| if i == 4 || i == 7 { *c == b'_' } else { c.is_ascii_digit() })
}

/// Whether `name` is a synced drive folder name, `YYYY_MM_DD_drive_NNNN_sync`.
pub fn is_drive_dir_name(name: &str) -> bool {
    name.ends_with("_sync") && parse_drive(name).is_some()
}

/// Splits a drive name (`2011_09_26_0005`, `2011_09_26_drive_0005`, or
/// `2011_09_26_drive_0005_sync`) into (date, drive number).
pub fn parse_drive(drive: &str) -> Option<(String, String)> {
    let date = drive.get(..10)?;
    if !is_date_name(date) {
        return None;
    }
    let rest = drive.get(10..)?.strip_prefix('_')?;
    let rest = rest.strip_prefix("drive_").unwrap_or(rest);
    let num = rest.strip_suffix("_sync").unwrap_or(rest);
    if num.is_empty() || !num.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    Some((date.to_string(), num.to_string()))
}

/// Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's `days_from_civil`).
fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Parses `2011-09-26 13:02:25.594360375` into (whole seconds since the epoch, nanoseconds).
pub fn parse_timestamp(path: &Path, line: usize, s: &str) -> Result<(i64, u32), DatasetError> {
    let err = |msg: &str| DatasetError::Parse {
        path: path.to_path_buf(),
        line,
        msg: format!("bad timestamp `{s}`: {msg} (expected `YYYY-MM-DD HH:MM:SS.fffffffff`)"),
    };
    let (date, time) = s.trim().split_once(' ').ok_or_else(|| err("no space"))?;
    let int = |t: &str, lo: i64, hi: i64| -> Result<i64, DatasetError> {
        match t.parse::<i64>() {
            Ok(v) if (lo..=hi).contains(&v) && t.bytes().all(|c| c.is_ascii_digit()) => Ok(v),
            _ => Err(err("field out of range")),
        }
    };
    let d: Vec<&str> = date.split('-').collect();
    let t: Vec<&str> = time.trim().split(':').collect();
    let ([y, mo, da], [h, mi, sec]) = (d.as_slice(), t.as_slice()) else {
        return Err(err("wrong number of fields"));
    };
    let (y, mo, da) = (int(y, 1, 9999)?, int(mo, 1, 12)?, int(da, 1, 31)?);
    let (h, mi) = (int(h, 0, 23)?, int(mi, 0, 59)?);
    let (whole, frac) = sec.split_once('.').unwrap_or((sec, ""));
    let sec = int(whole, 0, 60)?;
    if frac.len() > 9 || !frac.bytes().all(|c| c.is_ascii_digit()) {
        return Err(err("bad fraction"));
    }
    let nanos = if frac.is_empty() {
        0
    } else {
        int(frac, 0, 999_999_999)? * 10i64.pow(9 - frac.len() as u32)
    };
    let secs = days_from_civil(y, mo, da) * 86_400 + h * 3600 + mi * 60 + sec;
    Ok((secs, nanos as u32))
}

/// Reads a raw `timestamps.txt`: seconds relative to the first line.
pub fn read_timestamps(path: &Path) -> Result<Vec<f64>, DatasetError> {
    Ok(read_timestamps_with_origin(path)?.1)
}

/// Reads a raw `timestamps.txt`: the first line's time as seconds since 1970-01-01 00:00 (the
/// civil time in the file read as UTC; 0 for an empty file) and every line's seconds relative
/// to it. The relative times keep nanoseconds, which an `f64` of the absolute time would not.
pub fn read_timestamps_with_origin(path: &Path) -> Result<(f64, Vec<f64>), DatasetError> {
    let text = read_text(path)?;
    let stamps = numbered_lines(&text)
        .map(|(line, l)| parse_timestamp(path, line, l))
        .collect::<Result<Vec<_>, _>>()?;
    let Some(&(s0, n0)) = stamps.first() else { return Ok((0.0, Vec::new())) };
    let origin = s0 as f64 + f64::from(n0) * 1e-9;
    Ok((
        origin,
        stamps
            .iter()
            .map(|&(s, n)| (s - s0) as f64 + (f64::from(n) - f64::from(n0)) * 1e-9)
            .collect(),
    ))
}

/// Finds (date folder, drive folder) for `drive` under `root`.
fn locate(root: &Path, drive: &str) -> Result<(PathBuf, PathBuf), DatasetError> {
    let is_drive_dir =
        |p: &Path| ["oxts", "image_00", "image_02"].iter().any(|f| p.join(f).is_dir());
    if let Some((date, num)) = parse_drive(drive) {
        let folder = format!("{date}_drive_{num}_sync");
        let under_root = root.join(&date).join(&folder);
        if under_root.is_dir() {
            return Ok((root.join(&date), under_root));
        }
        let under_date = root.join(&folder);
        if under_date.is_dir() {
            return Ok((root.to_path_buf(), under_date));
        }
        if !is_drive_dir(root) {
            return Err(DatasetError::MissingFile { path: under_root });
        }
        // Handed a drive folder: it must be the drive asked for.
        let found = super::dir_name(root);
        if found != folder {
            return Err(DatasetError::SelectionConflict {
                path: root.to_path_buf(),
                what: "drive",
                asked: drive.to_string(),
                found,
            });
        }
    }
    if is_drive_dir(root) {
        let date_dir = match root.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => root.join(".."),
        };
        return Ok((date_dir, root.to_path_buf()));
    }
    if !root.is_dir() {
        return Err(DatasetError::MissingFile { path: root.to_path_buf() });
    }
    Err(DatasetError::UnknownLayout {
        path: root.to_path_buf(),
        msg: format!(
            "`{drive}` is not a drive name like 2011_09_26_0005 and the folder holds no \
             image_0X or oxts folder"
        ),
    })
}

/// See [`Sequence::open_raw`].
pub(crate) fn open(
    root: &Path,
    drive: &str,
    pair: Option<CameraPair>,
) -> Result<Sequence, DatasetError> {
    let (date_dir, drive_dir) = locate(root, drive)?;
    let pair = match pair {
        Some(p) => p,
        None if drive_dir.join("image_00").is_dir() && drive_dir.join("image_01").is_dir() => {
            CameraPair::Grey
        }
        None if drive_dir.join("image_02").is_dir() => CameraPair::Colour,
        None => return Err(DatasetError::EmptySequence { path: drive_dir }),
    };
    let (l, r) = pair.cameras();
    let cam_dir = |c: usize| drive_dir.join(format!("image_{c:02}"));
    let (left, right) = list_pair(&cam_dir(l).join("data"), &cam_dir(r).join("data"))?;

    let cam_to_cam = CalibFile::read(&date_dir.join("calib_cam_to_cam.txt"))?;
    let pl = cam_to_cam.mat3x4(&format!("P_rect_{l:02}"))?;
    let pr = cam_to_cam.mat3x4(&format!("P_rect_{r:02}"))?;
    let calib = stereo_from_projections(cam_to_cam.path(), &pl, &pr)?;

    let times_path = cam_dir(l).join("timestamps.txt");
    let (time_origin_s, times) = read_timestamps_with_origin(&times_path)?;
    let (times_s, extra) = check_times(&times_path, times, left.len())?;
    let notes: Vec<String> = extra.into_iter().collect();

    let oxts_dir = drive_dir.join("oxts").join("data");
    let mut gt_problem = None;
    let gt = if oxts_dir.is_dir() {
        let files = list_files(&oxts_dir, "txt")?;
        if files.len() != left.len() {
            gt_problem = Some(DatasetError::OxtsCountMismatch {
                dir: oxts_dir.clone(),
                oxts: files.len(),
                images: left.len(),
            });
        }
        // A record short of the images, or a bad one, ends the ground truth there; more
        // records than images mean the folder is not this drive's, and none is used.
        let usable = if files.len() > left.len() { &files[..0] } else { &files[..] };
        let mut packets = Vec::with_capacity(usable.len());
        for f in usable {
            match oxts::read_packet(f) {
                Ok(p) => packets.push(p),
                Err(e) => {
                    gt_problem = Some(e);
                    break;
                }
            }
        }
        if packets.is_empty() {
            None
        } else {
            let t_cam_imu = cam_from_imu(&date_dir, &cam_to_cam, &pl)?;
            Some(camera_poses(&oxts::imu_poses(&packets), &t_cam_imu, cam_to_cam.path())?)
        }
    } else {
        None
    };

    let image_size = first_pair_size(&left, &right)?;
    let s_rect = format!("S_rect_{l:02}");
    if cam_to_cam.has(&s_rect) {
        let s = cam_to_cam.numbers(&s_rect, 2)?;
        let expected = (s[0] as u32, s[1] as u32);
        if (f64::from(expected.0), f64::from(expected.1)) == (s[0], s[1]) && expected != image_size
        {
            return Err(DatasetError::ImageSizeMismatch {
                path: left[0].clone(),
                expected,
                got: image_size,
            });
        }
    }

    let name = drive_dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .filter(|n| n != "." && n != "..")
        .unwrap_or_else(|| drive.to_string());
    Ok(Sequence {
        layout: Layout::Raw,
        name,
        root: drive_dir,
        pair,
        calib,
        left,
        right,
        times_s,
        time_origin_s,
        gt,
        gt_problem,
        image_size,
        notes,
        remap: None,
        first_frame: 0,
    })
}

/// `T_camL_imu = T_L · R_rect_00 · T_cam0unrect_velo · T_velo_imu` (see the module docs).
fn cam_from_imu(
    date_dir: &Path,
    cam_to_cam: &CalibFile,
    p_left: &[f64; 12],
) -> Result<Matrix4<f64>, DatasetError> {
    let velo_to_cam = CalibFile::read(&date_dir.join("calib_velo_to_cam.txt"))?.rigid()?;
    let imu_to_velo = CalibFile::read(&date_dir.join("calib_imu_to_velo.txt"))?.rigid()?;
    let r_rect = homogeneous(&cam_to_cam.rotation("R_rect_00")?, &Vector3::zeros());
    let mut t_l = Matrix4::identity();
    t_l[(0, 3)] = p_left[3] / p_left[0];
    Ok((t_l * (r_rect * velo_to_cam)) * imu_to_velo)
}

/// `G_i = T_w_cam(0)⁻¹ · T_w_imu(i) · T_cam_imu⁻¹`.
fn camera_poses(
    imu: &[Matrix4<f64>],
    t_cam_imu: &Matrix4<f64>,
    calib_path: &Path,
) -> Result<Vec<Se3>, DatasetError> {
    let singular = || DatasetError::BadCalib {
        path: calib_path.to_path_buf(),
        msg: "camera-from-IMU transform is singular".into(),
    };
    let t_imu_cam = t_cam_imu.try_inverse().ok_or_else(singular)?;
    let w_cam: Vec<Matrix4<f64>> = imu.iter().map(|t| t * t_imu_cam).collect();
    let Some(first) = w_cam.first() else { return Ok(Vec::new()) };
    let first_inv = first.try_inverse().ok_or_else(singular)?;
    // G_0 = T⁻¹T is the identity up to rounding (~1e-16); store it exactly, as KITTI's
    // pose files do, so "first pose is the identity" holds bit for bit.
    let poses: Vec<Se3> = core::iter::once(Se3::identity())
        .chain(w_cam.iter().skip(1).map(|t| {
            let g = first_inv * t;
            Se3::new(
                g.fixed_view::<3, 3>(0, 0).into_owned(),
                g.fixed_view::<3, 1>(0, 3).into_owned(),
            )
        }))
        .collect();
    // Finite inputs can still overflow (an extreme altitude or longitude); never hand out
    // non-finite ground truth.
    if let Some(i) =
        poses.iter().position(|p| !p.trans.iter().chain(p.rot.iter()).all(|v| v.is_finite()))
    {
        return Err(DatasetError::BadCalib {
            path: calib_path.to_path_buf(),
            msg: format!(
                "ground-truth pose {i} is not finite (check the oxts records and calibration)"
            ),
        });
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drive_names() {
        let want = Some(("2011_09_26".to_string(), "0005".to_string()));
        assert_eq!(parse_drive("2011_09_26_0005"), want);
        assert_eq!(parse_drive("2011_09_26_drive_0005_sync"), want);
        assert_eq!(parse_drive("2011_09_26_drive_0005"), want);
        assert_eq!(parse_drive("2011_09_26"), None);
        assert_eq!(parse_drive("2011-09-26_0005"), None);
        assert_eq!(parse_drive("2011_09_26_drive_x"), None);
        assert_eq!(parse_drive("ü"), None);
        assert!(is_drive_dir_name("2011_09_26_drive_0005_sync"));
        assert!(!is_drive_dir_name("2011_09_26_drive_0005_extract"));
        assert!(is_date_name("2011_09_26"));
        assert!(!is_date_name("2011_09_2x"));
    }

    #[test]
    fn timestamps_keep_nanoseconds_and_cross_midnight() {
        let p = Path::new("timestamps.txt");
        let (s0, n0) = parse_timestamp(p, 1, "2011-09-26 13:02:25.594360375").unwrap();
        assert_eq!(n0, 594_360_375);
        let (s1, _) = parse_timestamp(p, 1, "2011-09-26 13:02:26.5").unwrap();
        assert_eq!(s1 - s0, 1);
        let (a, _) = parse_timestamp(p, 1, "2011-12-31 23:59:59.0").unwrap();
        let (b, _) = parse_timestamp(p, 1, "2012-01-01 00:00:00.0").unwrap();
        assert_eq!(b - a, 1);
        assert_eq!(parse_timestamp(p, 1, "1970-01-01 00:00:00").unwrap(), (0, 0));
        for bad in ["2011-09-26", "2011-13-26 13:02:25.5", "2011-09-26 13:02:25.1234567890", "x y"]
        {
            let e = parse_timestamp(p, 7, bad).unwrap_err();
            assert!(matches!(e, DatasetError::Parse { line: 7, .. }), "{bad}: {e}");
        }
    }

    #[test]
    fn relative_times() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("timestamps.txt");
        std::fs::write(&p, "2011-09-26 13:04:32.345808896\n2011-09-26 13:04:32.449188864\n\n")
            .unwrap();
        let t = read_timestamps(&p).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t[0], 0.0);
        assert!((t[1] - 0.103379968).abs() < 1e-12);
    }

    #[test]
    fn identity_calibration_gives_imu_motion() {
        let a = Matrix4::identity();
        let mut b = Matrix4::identity();
        b[(0, 3)] = 2.0;
        let g = camera_poses(&[a, b], &Matrix4::identity(), Path::new("c.txt")).unwrap();
        assert_eq!(g[0], Se3::identity());
        assert_eq!(g[1].trans, Vector3::new(2.0, 0.0, 0.0));
        let e = camera_poses(&[a], &Matrix4::zeros(), Path::new("c.txt")).unwrap_err();
        assert!(matches!(e, DatasetError::BadCalib { .. }));
    }
}
