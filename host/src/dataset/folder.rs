//! Generic stereo folder: `ROOT/left/` and `ROOT/right/` holding the same image names
//! (PNG, JPEG, PGM/PPM/PNM; colour is read as BT.601 luma), **already rectified** (semloc does
//! not undistort or rectify them).
//!
//! * Frames: the names present in `left/`, sorted by their number when every name is a number
//!   (`1.png`, `2.png`, `10.png`), else by name; every name must be in `right/` too (and the
//!   other way round): one on one side only is an error naming it. Other files are ignored.
//! * Calibration: the `[camera]` of the settings file when one is given (`--config FILE`);
//!   else `ROOT/calib.txt` in KITTI format (`P0:` and `P1:`, the rectified 3x4 projections of
//!   left and right); with neither, opening fails with [`DatasetError::NoCalibration`].
//! * Times: `ROOT/times.txt`, one time in seconds per line, one line per frame, strictly
//!   increasing; taken as recording times (`time_origin_s = 0`). Without it, frame `i` is at
//!   `i ×` [`FOLDER_DEFAULT_PERIOD_S`] and [`Sequence::notes`] says so.
//! * Ground truth (optional): `ROOT/gt.txt`, KITTI poses (12 numbers a line, left camera to
//!   world, one line per frame), or `ROOT/gt_tum.txt`, TUM lines `t x y z qx qy qz qw` in the
//!   clock of `times.txt` (required then), interpolated at each frame time (linear position,
//!   slerp rotation; samples more than [`FOLDER_MAX_GT_GAP_S`] apart are not bridged). Either
//!   is re-based so the first frame's pose is the identity, as for KITTI raw and EuRoC. A bad
//!   line, a short file, or a frame outside the TUM file's time span ends the ground truth
//!   there ([`Sequence::gt_problem`]). With both files, `gt.txt` is used and a note says so.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3x4, Quaternion, UnitQuaternion, Vector3};
use semloc_core::geom::Se3;

use super::calib::{stereo_from_projections, CalibFile};
use super::euroc::{interpolate, rebase, PoseSample};
use super::text::{read_rows, read_rows_prefix};
use super::{check_times, first_pair_size, DatasetError, Layout, Sequence, StereoCalib};

/// Frame period assumed when a stereo folder has no `times.txt`, s (10 Hz, KITTI's rate).
pub const FOLDER_DEFAULT_PERIOD_S: f64 = 0.1;

/// Largest time between two TUM ground-truth samples a frame time may be interpolated
/// between, s.
pub const FOLDER_MAX_GT_GAP_S: f64 = 1.0;

/// Image file extensions a stereo folder's images may have (case-insensitive).
pub const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "pgm", "ppm", "pnm"];

/// Whether `path` holds `left/` and `right/` folders.
pub(crate) fn is_folder(path: &Path) -> bool {
    path.join("left").is_dir() && path.join("right").is_dir()
}

/// The image files of `dir`, by file name.
fn images(dir: &Path) -> Result<Vec<String>, DatasetError> {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| DatasetError::io(dir, &e))? {
        let entry = entry.map_err(|e| DatasetError::io(dir, &e))?;
        let path = entry.path();
        let is_image = path
            .extension()
            .and_then(|x| x.to_str())
            .is_some_and(|x| IMAGE_EXTENSIONS.iter().any(|e| x.eq_ignore_ascii_case(e)));
        if is_image && path.is_file() {
            names.push(entry.file_name().to_string_lossy().into_owned());
        }
    }
    Ok(names)
}

/// Frame order: by number when every stem is all digits, else by name.
fn sort_frames(names: &mut [String]) {
    let number = |n: &String| -> Option<u128> {
        let stem = Path::new(n).file_stem()?.to_str()?;
        (!stem.is_empty() && stem.bytes().all(|b| b.is_ascii_digit())).then(|| stem.parse().ok())?
    };
    if names.iter().all(|n| number(n).is_some()) {
        names.sort_by_key(|n| (number(n), n.clone()));
    } else {
        names.sort();
    }
}

/// See [`Sequence::open_folder`].
pub(crate) fn open(root: &Path, camera: Option<StereoCalib>) -> Result<Sequence, DatasetError> {
    if !root.is_dir() {
        return Err(DatasetError::MissingFile { path: root.to_path_buf() });
    }
    let (left_dir, right_dir) = (root.join("left"), root.join("right"));
    let mut names = images(&left_dir)?;
    let right_names = images(&right_dir)?;
    sort_frames(&mut names);
    let mut right_sorted = right_names.clone();
    right_sorted.sort();
    let mut left_sorted = names.clone();
    left_sorted.sort();
    if let Some(n) = names.iter().find(|n| right_sorted.binary_search(n).is_err()) {
        return Err(DatasetError::UnpairedImage { path: left_dir.join(n), other_dir: right_dir });
    }
    if let Some(n) = right_names.iter().find(|n| left_sorted.binary_search(n).is_err()) {
        return Err(DatasetError::UnpairedImage { path: right_dir.join(n), other_dir: left_dir });
    }
    if names.is_empty() {
        return Err(DatasetError::EmptySequence { path: left_dir });
    }
    let left: Vec<PathBuf> = names.iter().map(|n| left_dir.join(n)).collect();
    let right: Vec<PathBuf> = names.iter().map(|n| right_dir.join(n)).collect();
    let mut notes = Vec::new();

    let calib_path = root.join("calib.txt");
    let calib = match camera {
        Some(c) => {
            if calib_path.is_file() {
                notes.push(format!(
                    "the settings file's [camera] is used; {} is not read",
                    calib_path.display()
                ));
            }
            c
        }
        None if calib_path.is_file() => {
            let file = CalibFile::read(&calib_path)?;
            stereo_from_projections(file.path(), &file.mat3x4("P0")?, &file.mat3x4("P1")?)?
        }
        None => return Err(DatasetError::NoCalibration { path: root.to_path_buf() }),
    };

    let times_path = root.join("times.txt");
    let has_times = times_path.is_file();
    let times_s = if has_times {
        let times: Vec<f64> = read_rows(&times_path, 1)?.into_iter().map(|r| r[0]).collect();
        if times.len() != left.len() {
            return Err(DatasetError::TimesCountMismatch {
                path: times_path,
                times: times.len(),
                images: left.len(),
            });
        }
        // the counts are equal: no note for extra times
        check_times(&times_path, times, left.len())?.0
    } else {
        notes.push(format!(
            "no {}: frame i is taken to be at i × {FOLDER_DEFAULT_PERIOD_S} s",
            times_path.display()
        ));
        (0..left.len()).map(|i| i as f64 * FOLDER_DEFAULT_PERIOD_S).collect()
    };

    let (kitti_gt, tum_gt) = (root.join("gt.txt"), root.join("gt_tum.txt"));
    let (poses, gt_problem) = if kitti_gt.is_file() {
        if tum_gt.is_file() {
            notes.push(format!(
                "ground truth from {}; {} is not read",
                kitti_gt.display(),
                tum_gt.display()
            ));
        }
        kitti_poses(&kitti_gt, left.len())?
    } else if tum_gt.is_file() {
        if has_times {
            tum_poses(&tum_gt, &times_s)?
        } else {
            let problem = DatasetError::GtNotCovered {
                path: tum_gt.clone(),
                frame: 0,
                time_s: 0.0,
                msg: format!(
                    "TUM ground truth is matched to frame times, and {} is missing",
                    times_path.display()
                ),
            };
            (Vec::new(), Some(problem))
        }
    } else {
        (Vec::new(), None)
    };
    let gt = (!poses.is_empty()).then(|| rebase(&poses));

    let image_size = first_pair_size(&left, &right)?;
    Ok(Sequence {
        layout: Layout::Folder,
        name: super::dir_name(root),
        root: root.to_path_buf(),
        pair: super::CameraPair::Grey,
        calib,
        left,
        right,
        times_s,
        time_origin_s: 0.0,
        gt,
        gt_problem,
        image_size,
        notes,
        remap: None,
        first_frame: 0,
    })
}

/// KITTI poses, one per frame: the poses before a bad line or past the end, and the problem.
/// A line whose 3x3 part is not a rotation ([`crate::traj::rotation_defect`], the rule
/// `semloc eval` applies to the same files) is a bad line: its rotation error would be
/// meaningless.
pub(super) fn kitti_poses(
    path: &Path,
    frames: usize,
) -> Result<(Vec<Se3>, Option<DatasetError>), DatasetError> {
    let (rows, mut problem) = read_rows_prefix(path, 12)?;
    // Each row becomes a pose once; the first whose 3x3 part is not a rotation ends them.
    let mut poses = Vec::with_capacity(rows.len());
    for (k, r) in rows.iter().enumerate() {
        let pose = Se3::from_matrix3x4(&Matrix3x4::from_row_slice(r));
        if let Some((deviation, det)) = crate::traj::rotation_defect(&pose.rot) {
            problem = Some(DatasetError::Parse {
                path: path.to_path_buf(),
                line: data_line(path, k),
                msg: crate::traj::not_rotation_msg(deviation, det),
            });
            break;
        }
        poses.push(pose);
    }
    if problem.is_none() && poses.len() != frames {
        problem = Some(DatasetError::PoseCountMismatch {
            path: path.to_path_buf(),
            poses: poses.len(),
            images: frames,
        });
    }
    if poses.len() > frames {
        // More poses than frames: not this sequence's file; no pose can be trusted.
        poses.clear();
    }
    Ok((poses, problem))
}

/// TUM samples interpolated at each frame time, up to the first frame they do not cover.
fn tum_poses(
    path: &Path,
    times_s: &[f64],
) -> Result<(Vec<Se3>, Option<DatasetError>), DatasetError> {
    let (rows, bad) = read_rows_prefix(path, 8)?;
    let mut samples: Vec<PoseSample> = Vec::with_capacity(rows.len());
    let mut bad = bad;
    for (k, r) in rows.iter().enumerate() {
        let q = Quaternion::new(r[7], r[4], r[5], r[6]);
        let problem = if q.norm() <= 1e-6 {
            Some("the quaternion has zero length")
        } else if samples.last().is_some_and(|s| r[0] <= s.0) {
            Some("the time is not after the previous line's")
        } else {
            None
        };
        if let Some(msg) = problem {
            // `read_rows_prefix` skips blank and comment lines; name the data line by number.
            bad = Some(DatasetError::Parse {
                path: path.to_path_buf(),
                line: data_line(path, k),
                msg: msg.into(),
            });
            break;
        }
        samples.push((r[0], Vector3::new(r[1], r[2], r[3]), UnitQuaternion::from_quaternion(q)));
    }
    let mut poses = Vec::with_capacity(times_s.len());
    let mut problem = None;
    for (i, &t) in times_s.iter().enumerate() {
        match interpolate(&samples, t, FOLDER_MAX_GT_GAP_S) {
            Ok(p) => poses.push(p),
            Err(msg) => {
                problem = Some(bad.clone().unwrap_or(DatasetError::GtNotCovered {
                    path: path.to_path_buf(),
                    frame: i,
                    time_s: t,
                    msg,
                }));
                break;
            }
        }
    }
    Ok((poses, problem))
}

/// The 1-based file line of the `k`-th (0-based) data line of a text file.
fn data_line(path: &Path, k: usize) -> usize {
    super::text::read_text(path)
        .ok()
        .and_then(|t| super::text::numbered_lines(&t).nth(k).map(|(line, _)| line))
        .unwrap_or(k + 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, Luma, Rgb, RgbImage};
    use std::fs;

    const P0: &str = "P0: 700 0 600 0 0 700 180 0 0 0 1 0";
    const P1: &str = "P1: 700 0 600 -350 0 700 180 0 0 0 1 0";

    fn grey(path: &Path, v: u8) {
        fs::create_dir_all(path.parent().unwrap()).unwrap();
        GrayImage::from_pixel(8, 4, Luma([v])).save(path).unwrap();
    }

    /// `n` frames named `1.png, 2.png, ...` (not zero-padded), calib.txt, times.txt, gt.txt
    /// with the camera at x = 5 + i (so re-basing shows).
    fn fixture(n: usize) -> tempfile::TempDir {
        let tmp = tempfile::tempdir().unwrap();
        for i in 0..n {
            grey(&tmp.path().join(format!("left/{}.png", i + 1)), 10 + i as u8);
            grey(&tmp.path().join(format!("right/{}.png", i + 1)), 100 + i as u8);
        }
        fs::write(tmp.path().join("calib.txt"), format!("{P0}\n{P1}\n")).unwrap();
        let times: String = (0..n).map(|i| format!("{}\n", 3.0 + 0.05 * i as f64)).collect();
        fs::write(tmp.path().join("times.txt"), times).unwrap();
        let gt: String = (0..n).map(|i| format!("1 0 0 {} 0 1 0 0 0 0 1 2\n", 5 + i)).collect();
        fs::write(tmp.path().join("gt.txt"), gt).unwrap();
        tmp
    }

    #[test]
    fn a_stereo_folder_opens_in_numeric_order_with_rebased_ground_truth() {
        let tmp = fixture(11);
        let s = Sequence::open(tmp.path(), None).unwrap();
        assert_eq!(s.layout, Layout::Folder);
        assert_eq!(s.len(), 11);
        assert_eq!(s.left[1].file_name().unwrap(), "2.png");
        assert_eq!(s.left[10].file_name().unwrap(), "11.png");
        assert_eq!(s.calib.fx_px, 700.0);
        assert!((s.calib.baseline_m - 0.5).abs() < 1e-15);
        assert_eq!(s.times_s[0], 3.0);
        assert_eq!(s.time_origin_s, 0.0);
        assert!(s.notes.is_empty(), "{:?}", s.notes);
        let gt = s.gt.as_ref().unwrap();
        assert_eq!(gt[0], Se3::identity());
        assert_eq!(gt[3].trans, Vector3::new(3.0, 0.0, 0.0));
        let (l, r) = s.load_luma(1).unwrap();
        assert_eq!((l.get_pixel(0, 0)[0], r.get_pixel(0, 0)[0]), (11, 101));
        assert_eq!(s.camera_names(), ["left".to_string(), "right".to_string()]);
    }

    #[test]
    fn colour_jpeg_and_pgm_images_are_read_as_luma() {
        let tmp = tempfile::tempdir().unwrap();
        for side in ["left", "right"] {
            fs::create_dir_all(tmp.path().join(side)).unwrap();
            RgbImage::from_pixel(8, 4, Rgb([12, 200, 77]))
                .save(tmp.path().join(side).join("a.png"))
                .unwrap();
            GrayImage::from_pixel(8, 4, Luma([77]))
                .save(tmp.path().join(side).join("b.pgm"))
                .unwrap();
            RgbImage::from_pixel(8, 4, Rgb([128, 128, 128]))
                .save(tmp.path().join(side).join("c.jpg"))
                .unwrap();
            fs::write(tmp.path().join(side).join("notes.txt"), "ignored").unwrap();
        }
        fs::write(tmp.path().join("calib.txt"), format!("{P0}\n{P1}\n")).unwrap();
        let s = Sequence::open(tmp.path(), None).unwrap();
        assert_eq!(s.len(), 3);
        assert_eq!(s.load_luma(0).unwrap().0.get_pixel(0, 0)[0], 130); // BT.601 (Pillow)
        assert_eq!(s.load_luma(1).unwrap().0.get_pixel(0, 0)[0], 77);
        let jpg = s.load_luma(2).unwrap().0.get_pixel(3, 2)[0];
        assert!(jpg.abs_diff(128) <= 2, "{jpg}");
    }

    #[test]
    fn calibration_comes_from_the_settings_camera_or_calib_txt_or_the_error_says_how() {
        let tmp = fixture(2);
        let cam =
            StereoCalib { fx_px: 500.0, fy_px: 501.0, cx_px: 4.0, cy_px: 2.0, baseline_m: 0.3 };
        let s = Sequence::open_with_camera(tmp.path(), None, Some(cam)).unwrap();
        assert_eq!(s.calib, cam);
        assert!(s.notes[0].contains("calib.txt is not read"), "{:?}", s.notes);
        fs::remove_file(tmp.path().join("calib.txt")).unwrap();
        assert_eq!(Sequence::open_folder(tmp.path(), Some(cam)).unwrap().calib, cam);
        let e = Sequence::open(tmp.path(), None).unwrap_err();
        assert_eq!(e, DatasetError::NoCalibration { path: tmp.path().to_path_buf() });
        let msg = e.to_string();
        assert!(msg.contains("--config FILE") && msg.contains("[camera]"), "{msg}");
        fs::write(tmp.path().join("calib.txt"), format!("{P0}\n")).unwrap();
        let e = Sequence::open(tmp.path(), None).unwrap_err();
        assert!(matches!(&e, DatasetError::MissingKey { key, .. } if key == "P1"), "{e}");
    }

    #[test]
    fn without_times_the_default_period_is_used_and_noted() {
        let tmp = fixture(3);
        fs::remove_file(tmp.path().join("times.txt")).unwrap();
        let s = Sequence::open(tmp.path(), None).unwrap();
        assert_eq!(s.times_s, vec![0.0, FOLDER_DEFAULT_PERIOD_S, 2.0 * FOLDER_DEFAULT_PERIOD_S]);
        assert!(
            s.notes.iter().any(|n| n.contains("times.txt") && n.contains("0.1 s")),
            "{:?}",
            s.notes
        );
        assert!(s.summary().to_string().contains("note: no "), "{}", s.summary());
    }

    #[test]
    fn tum_ground_truth_is_interpolated_at_frame_times() {
        let tmp = fixture(4); // frames at 3.00, 3.05, 3.10, 3.15 s
        fs::remove_file(tmp.path().join("gt.txt")).unwrap();
        let half = (0.2_f64 / 2.0).sin(); // 0.2 rad about z at t = 3.2
        fs::write(
            tmp.path().join("gt_tum.txt"),
            format!(
                "# t x y z qx qy qz qw\n3.0 1 0 0 0 0 0 1\n3.2 5 0 0 0 0 {half} {}\n",
                (0.1_f64).cos()
            ),
        )
        .unwrap();
        let s = Sequence::open(tmp.path(), None).unwrap();
        assert!(s.gt_problem.is_none(), "{:?}", s.gt_problem);
        let gt = s.gt.as_ref().unwrap();
        assert_eq!(gt.len(), 4);
        assert_eq!(gt[0], Se3::identity());
        assert!((gt[2].trans - Vector3::new(2.0, 0.0, 0.0)).norm() < 1e-12, "{}", gt[2].trans);
        assert!((gt[2].rotation_angle() - 0.1).abs() < 1e-12);
        // Frame 3 (3.15 s) inside, a frame past 3.2 s outside: the ground truth stops there.
        fs::write(tmp.path().join("gt_tum.txt"), "3.0 1 0 0 0 0 0 1\n3.1 2 0 0 0 0 0 1\n").unwrap();
        let s = Sequence::open(tmp.path(), None).unwrap();
        assert_eq!(s.gt.as_ref().map(Vec::len), Some(3));
        assert!(
            matches!(s.gt_problem, Some(DatasetError::GtNotCovered { frame: 3, .. })),
            "{:?}",
            s.gt_problem
        );
        // A bad line: the samples before it are used and the line is the problem.
        fs::write(tmp.path().join("gt_tum.txt"), "3.0 1 0 0 0 0 0 1\n\n3.05 1 0 0 0 0 0 0\n")
            .unwrap();
        let s = Sequence::open(tmp.path(), None).unwrap();
        assert!(
            matches!(s.gt_problem, Some(DatasetError::Parse { line: 3, .. })),
            "{:?}",
            s.gt_problem
        );
        assert_eq!(s.gt.as_ref().map(Vec::len), Some(1));
        // Without times.txt there is nothing to match the times to.
        fs::remove_file(tmp.path().join("times.txt")).unwrap();
        let s = Sequence::open(tmp.path(), None).unwrap();
        assert!(s.gt.is_none());
        assert!(s.gt_problem.unwrap().to_string().contains("times.txt"));
    }

    #[test]
    fn malformed_folders_are_typed_errors_naming_the_file() {
        let tmp = fixture(3);
        let root = tmp.path();
        grey(&root.join("left/9.png"), 0);
        let e = Sequence::open(root, None).unwrap_err();
        assert_eq!(
            e,
            DatasetError::UnpairedImage {
                path: root.join("left/9.png"),
                other_dir: root.join("right")
            }
        );
        fs::rename(root.join("left/9.png"), root.join("right/9.png")).unwrap();
        let e = Sequence::open(root, None).unwrap_err();
        assert_eq!(
            e,
            DatasetError::UnpairedImage {
                path: root.join("right/9.png"),
                other_dir: root.join("left")
            }
        );
        fs::remove_file(root.join("right/9.png")).unwrap();
        fs::write(root.join("times.txt"), "0\n0.1\n").unwrap();
        let e = Sequence::open(root, None).unwrap_err();
        assert!(matches!(e, DatasetError::TimesCountMismatch { times: 2, images: 3, .. }), "{e}");
        fs::write(root.join("times.txt"), "0\n0.1\n0.1\n").unwrap();
        assert!(matches!(
            Sequence::open(root, None).unwrap_err(),
            DatasetError::TimesNotIncreasing { frame: 2, .. }
        ));
        fs::write(root.join("times.txt"), "0\n0.1\nx\n").unwrap();
        assert!(matches!(
            Sequence::open(root, None).unwrap_err(),
            DatasetError::Parse { line: 3, .. }
        ));
        fs::write(root.join("times.txt"), "0\n0.1\n0.2\n").unwrap();
        // A short or bad gt.txt is a ground-truth problem, not an error.
        fs::write(root.join("gt.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0\n").unwrap();
        let s = Sequence::open(root, None).unwrap();
        assert_eq!(s.gt.as_ref().map(Vec::len), Some(1));
        assert!(matches!(s.gt_problem, Some(DatasetError::BadFieldCount { line: 2, .. })));
        // So is a line that is not a rotation (here a reflection).
        fs::write(root.join("gt.txt"), "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 -1 0 0 0 0 1 0\n")
            .unwrap();
        let s = Sequence::open(root, None).unwrap();
        assert_eq!(s.gt.as_ref().map(Vec::len), Some(1));
        assert!(matches!(s.gt_problem, Some(DatasetError::Parse { line: 2, .. })));
        // A different image size on the right.
        GrayImage::from_pixel(9, 4, Luma([0])).save(root.join("right/1.png")).unwrap();
        assert!(matches!(
            Sequence::open(root, None).unwrap_err(),
            DatasetError::ImageSizeMismatch { .. }
        ));
        // --pair has no meaning here; an empty pair of folders is empty.
        let e = Sequence::open(root, Some(super::super::CameraPair::Grey)).unwrap_err();
        assert!(matches!(e, DatasetError::PairNotAvailable { .. }));
        let empty = tempfile::tempdir().unwrap();
        fs::create_dir_all(empty.path().join("left")).unwrap();
        fs::create_dir_all(empty.path().join("right")).unwrap();
        assert!(matches!(
            Sequence::open(empty.path(), None).unwrap_err(),
            DatasetError::EmptySequence { .. }
        ));
    }

    #[test]
    fn an_unknown_folder_lists_the_layouts_looked_for() {
        let tmp = tempfile::tempdir().unwrap();
        fs::write(tmp.path().join("readme.md"), "x").unwrap();
        let msg = Sequence::open(tmp.path(), None).unwrap_err().to_string();
        for layout in ["EuRoC", "left/ and right/", "KITTI odometry", "KITTI raw"] {
            assert!(msg.contains(layout), "{msg}");
        }
    }
}
