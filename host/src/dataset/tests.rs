//! Readers against small datasets built in temporary folders: the happy paths of both layouts
//! and one test per kind of bad input (each checks the error variant and that its message names
//! the file at fault).

use std::fs;
use std::path::{Path, PathBuf};

use image::{GrayImage, Luma, Rgb, RgbImage};

use super::*;

const P0: &str = "P0: 7.188560000000e+02 0 6.071928000000e+02 0 0 7.188560000000e+02 1.852157000000e+02 0 0 0 1 0";
const P1: &str = "P1: 7.188560000000e+02 0 6.071928000000e+02 -3.861448000000e+02 0 7.188560000000e+02 1.852157000000e+02 0 0 0 1 0";
const P2: &str = "P2: 7.188560000000e+02 0 6.071928000000e+02 4.538225000000e+01 0 7.188560000000e+02 1.852157000000e+02 -1.130887000000e-01 0 0 1 3.779761000000e-03";
const P3: &str = "P3: 7.188560000000e+02 0 6.071928000000e+02 -3.372877000000e+02 0 7.188560000000e+02 1.852157000000e+02 2.369057000000e+00 0 0 1 4.915215000000e-03";
const TR: &str = "Tr: 4.276802385584e-04 -9.999672484946e-01 -8.084491683471e-03 -1.198459927713e-02 -7.210626507497e-03 8.081198471645e-03 -9.999413164504e-01 -5.403984729748e-02 9.999738645903e-01 4.859485810390e-04 -7.206933692422e-03 -2.921968648686e-01";

const W: u32 = 8;
const H: u32 = 4;

fn write(path: &Path, text: &str) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    fs::write(path, text).unwrap();
}

fn grey_png(path: &Path, w: u32, h: u32, v: u8) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    GrayImage::from_pixel(w, h, Luma([v])).save(path).unwrap();
}

fn rgb_png(path: &Path, w: u32, h: u32, c: [u8; 3]) {
    fs::create_dir_all(path.parent().unwrap()).unwrap();
    RgbImage::from_pixel(w, h, Rgb(c)).save(path).unwrap();
}

fn pose_line(x: f64) -> String {
    format!("1 0 0 {x} 0 1 0 0 0 0 1 0\n")
}

/// `root/sequences/00` with `n` grey frames (8x4), calib, times and `root/poses/00.txt`.
fn odometry_fixture(n: usize) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let seq = tmp.path().join("sequences").join("00");
    for i in 0..n {
        grey_png(&seq.join(format!("image_0/{i:06}.png")), W, H, 10 + i as u8);
        grey_png(&seq.join(format!("image_1/{i:06}.png")), W, H, 20 + i as u8);
    }
    write(&seq.join("calib.txt"), &format!("{P0}\n{P1}\n{P2}\n{P3}\n{TR}\n"));
    let times: String = (0..n).map(|i| format!("{:e}\n", i as f64 * 0.1)).collect();
    write(&seq.join("times.txt"), &times);
    let poses: String = (0..n).map(|i| pose_line(i as f64)).collect();
    write(&tmp.path().join("poses/00.txt"), &poses);
    (tmp, seq)
}

fn open_odo(tmp: &tempfile::TempDir) -> Result<Sequence, DatasetError> {
    Sequence::open_odometry(tmp.path(), "00", None)
}

/// Asserts the message names `file`.
fn names(e: &DatasetError, file: &str) {
    assert!(e.to_string().contains(file), "`{e}` does not name {file}");
}

#[test]
fn odometry_opens_from_root_sequence_folder_and_autodetect() {
    let (tmp, seq) = odometry_fixture(3);
    let a = open_odo(&tmp).unwrap();
    assert_eq!(a.layout, Layout::Odometry);
    assert_eq!(a.name, "00");
    assert_eq!(a.pair, CameraPair::Grey);
    assert_eq!(a.len(), 3);
    assert_eq!(a.image_size, (W, H));
    assert_eq!(a.calib.fx_px, 718.856);
    assert!((a.calib.baseline_m * a.calib.fx_px - 386.1448).abs() < 1e-9);
    let cam = a.calib.to_camera().unwrap();
    assert!((cam.bf() - 386.1448).abs() < 1e-9);
    assert_eq!(a.times_s, vec![0.0, 0.1, 0.2]);
    let gt = a.gt.as_ref().unwrap();
    assert_eq!(gt[2].trans.x, 2.0);
    assert_eq!(a.gt_length_m(), Some(2.0));
    let (l, r) = a.load_luma(1).unwrap();
    assert_eq!((l.get_pixel(0, 0)[0], r.get_pixel(7, 3)[0]), (11, 21));

    // "0" means "00"; the sequence folder itself finds ../../poses/00.txt.
    let b = Sequence::open_odometry(tmp.path(), "0", None).unwrap();
    assert_eq!(b.left, a.left);
    let c = Sequence::open_odometry(&seq, "00", None).unwrap();
    assert_eq!(c.gt, a.gt);
    let d = Sequence::open(&seq, None).unwrap();
    assert_eq!((d.name.as_str(), d.len(), d.gt.is_some()), ("00", 3, true));
    let e = Sequence::open(tmp.path(), None).unwrap();
    assert_eq!(e.root, a.root);

    let s = a.summary();
    assert_eq!((s.frames, s.width_px, s.height_px, s.has_gt), (3, W, H, true));
    assert_eq!(s.cameras, ["image_0".to_string(), "image_1".to_string()]);
    assert!((s.duration_s - 0.2).abs() < 1e-12);
    let json = serde_json::to_value(&s).unwrap();
    assert_eq!(json["layout"], "odometry");
    assert_eq!(json["gt_length_m"], 2.0);
    assert!(s.to_string().contains("frames:     3"), "{s}");
}

#[test]
fn starting_at_cuts_frames_times_and_rebases_the_ground_truth() {
    let (tmp, _) = odometry_fixture(5);
    let a = open_odo(&tmp).unwrap();
    let b = a.starting_at(2).unwrap();
    assert_eq!((b.len(), b.first_frame), (3, 2));
    assert_eq!(b.left[..], a.left[2..]);
    assert_eq!(b.right[..], a.right[2..]);
    // Frame times keep their values (TUM files carry the recording time).
    assert_eq!(b.times_s, a.times_s[2..].to_vec());
    // The ground truth starts at the identity, as the estimate does; the motion is kept.
    let gt = b.gt.as_ref().unwrap();
    assert_eq!(gt.len(), 3);
    assert!(gt[0].trans.norm() < 1e-12 && gt[0].rotation_angle() < 1e-12);
    assert!((gt[2].trans.x - 2.0).abs() < 1e-12);
    let (l, _) = b.load_luma(0).unwrap();
    assert_eq!(l.get_pixel(0, 0)[0], 12);
    // Offsets add up; the summary says which of the dataset's frames these are.
    let c = b.starting_at(1).unwrap();
    assert_eq!((c.len(), c.first_frame), (2, 3));
    let s = c.summary();
    assert_eq!(s.first_frame, 3);
    assert!(s.to_string().contains("the dataset's frames 3 to 4"), "{s}");
    assert_eq!(a.starting_at(0).unwrap().left, a.left);
    // Beyond the last frame: an error in the dataset's numbering, naming the folder.
    let e = b.starting_at(3).unwrap_err();
    assert_eq!(e, DatasetError::FirstFrameBeyondEnd { path: a.root.clone(), first: 5, frames: 5 });
    names(&e, "00");
    assert!(e.to_string().contains("--first-frame 5"), "{e}");
}

#[test]
fn odometry_colour_pair_and_missing_poses() {
    let (tmp, seq) = odometry_fixture(2);
    fs::remove_dir_all(seq.join("image_0")).unwrap();
    fs::remove_dir_all(seq.join("image_1")).unwrap();
    fs::remove_file(tmp.path().join("poses/00.txt")).unwrap();
    for i in 0..2 {
        rgb_png(&seq.join(format!("image_2/{i:06}.png")), W, H, [255, 0, 0]);
        rgb_png(&seq.join(format!("image_3/{i:06}.png")), W, H, [12, 200, 77]);
    }
    let s = open_odo(&tmp).unwrap();
    assert_eq!(s.pair, CameraPair::Colour);
    assert!(s.gt.is_none());
    assert!((s.calib.baseline_m * s.calib.fx_px - (45.38225 + 337.2877)).abs() < 1e-9);
    let (l, r) = s.load_luma(0).unwrap();
    assert_eq!((l.get_pixel(3, 2)[0], r.get_pixel(3, 2)[0]), (76, 130));
    assert_eq!(s.summary().gt_length_m, None);
    let e = s.load_luma(2).unwrap_err();
    assert!(matches!(e, DatasetError::FrameOutOfRange { index: 2, frames: 2, .. }), "{e}");
}

#[test]
fn odometry_colour_gt_is_moved_to_camera_2() {
    let (tmp, seq) = odometry_fixture(2);
    for i in 0..2 {
        rgb_png(&seq.join(format!("image_2/{i:06}.png")), W, H, [1, 2, 3]);
        rgb_png(&seq.join(format!("image_3/{i:06}.png")), W, H, [1, 2, 3]);
    }
    // A pure rotation of camera 0 about its own centre moves camera 2 (offset along x).
    let rot = "0 0 1 0 0 1 0 0 -1 0 0 0\n";
    write(&tmp.path().join("poses/00.txt"), &format!("{}{rot}", pose_line(0.0)));
    let grey = open_odo(&tmp).unwrap();
    let col = Sequence::open_odometry(tmp.path(), "00", Some(CameraPair::Colour)).unwrap();
    let (g, c) = (grey.gt.unwrap(), col.gt.unwrap());
    assert_eq!(c[0], semloc_core::geom::Se3::identity());
    assert_eq!(g[1].rot, c[1].rot);
    let off = 45.38225 / 718.856;
    // G₂ = T₂ G₀ T₂⁻¹: translation = t₂ − R t₂ with t₂ = (off, 0, 0), R maps x to −z.
    assert!((c[1].trans - nalgebra::Vector3::new(off, 0.0, off)).norm() < 1e-12, "{}", c[1].trans);
}

#[test]
fn missing_calib_txt() {
    let (tmp, seq) = odometry_fixture(2);
    fs::remove_file(seq.join("calib.txt")).unwrap();
    let e = open_odo(&tmp).unwrap_err();
    assert_eq!(e, DatasetError::MissingFile { path: seq.join("calib.txt") });
    names(&e, "calib.txt");
}

#[test]
fn calib_line_with_11_numbers() {
    let (tmp, seq) = odometry_fixture(2);
    let short: String = P1.rsplit_once(' ').unwrap().0.to_string();
    write(&seq.join("calib.txt"), &format!("{P0}\n{short}\n{P2}\n{P3}\n"));
    let e = open_odo(&tmp).unwrap_err();
    assert_eq!(
        e,
        DatasetError::BadFieldCount { path: seq.join("calib.txt"), line: 2, expected: 12, got: 11 }
    );
    names(&e, "calib.txt:2");
}

#[test]
fn nan_in_calib() {
    let (tmp, seq) = odometry_fixture(2);
    write(&seq.join("calib.txt"), &format!("{}\n{P1}\n", P0.replace("6.071928000000e+02", "nan")));
    let e = open_odo(&tmp).unwrap_err();
    assert_eq!(e, DatasetError::NonFinite { path: seq.join("calib.txt"), line: 1 });
    names(&e, "calib.txt:1");
}

#[test]
fn calib_without_p1() {
    let (tmp, seq) = odometry_fixture(2);
    write(&seq.join("calib.txt"), &format!("{P0}\n{TR}\n"));
    let e = open_odo(&tmp).unwrap_err();
    assert!(matches!(&e, DatasetError::MissingKey { key, .. } if key == "P1"), "{e}");
    names(&e, "calib.txt");
}

#[test]
fn poses_line_with_13_numbers() {
    let (tmp, _) = odometry_fixture(2);
    let poses = tmp.path().join("poses/00.txt");
    write(&poses, &format!("{}1 0 0 1 0 1 0 0 0 0 1 0 7\n", pose_line(0.0)));
    // The poses before the bad line are kept; the problem is recorded, not fatal.
    let seq = open_odo(&tmp).unwrap();
    assert_eq!(seq.gt.as_ref().map(Vec::len), Some(1));
    let e = seq.gt_problem.clone().expect("problem recorded");
    assert_eq!(e, DatasetError::BadFieldCount { path: poses, line: 2, expected: 12, got: 13 });
    names(&e, "00.txt:2");
    assert_eq!(seq.summary().gt_frames, 1);
}

/// A ground-truth line whose 3x3 part is not a rotation ends the ground truth there, as in
/// `semloc eval`: its rotation errors (RPE, r_rel) would be meaningless.
#[test]
fn poses_line_that_is_not_a_rotation() {
    let (tmp, _) = odometry_fixture(3);
    let poses = tmp.path().join("poses/00.txt");
    for (bad, what) in [
        ("-1 0 0 1 0 1 0 0 0 0 1 0\n", "a reflection"),
        ("1 0 0 1 0 1.1 0 0 0 0 1 0\n", "a stretch"),
        ("0 0 0 1 0 0 0 0 0 0 0 0\n", "all zero"),
    ] {
        write(&poses, &format!("# comment\n{}{bad}{}", pose_line(0.0), pose_line(2.0)));
        let seq = open_odo(&tmp).unwrap();
        assert_eq!(seq.gt.as_ref().map(Vec::len), Some(1), "{what}");
        let e = seq.gt_problem.clone().expect("problem recorded");
        assert!(matches!(&e, DatasetError::Parse { line: 3, .. }), "{what}: {e}");
        names(&e, "00.txt:3");
        assert!(e.to_string().contains("not a rotation matrix"), "{e}");
    }
    // Rotations as KITTI stores them (9 digits) pass.
    let c = 0.6_f64.cos();
    let s = 0.6_f64.sin();
    let turned = format!("{c:.9e} 0 {s:.9e} 2 0 1 0 0 {:.9e} 0 {c:.9e} 0\n", -s);
    write(&poses, &format!("{}{}{turned}", pose_line(0.0), pose_line(1.0)));
    let seq = open_odo(&tmp).unwrap();
    assert_eq!(seq.gt.as_ref().map(Vec::len), Some(3));
    assert!(seq.gt_problem.is_none());
}

#[test]
fn poses_count_differs_from_images() {
    let (tmp, _) = odometry_fixture(3);
    let poses = tmp.path().join("poses/00.txt");
    write(&poses, &pose_line(0.0));
    let seq = open_odo(&tmp).unwrap();
    assert_eq!(seq.gt.as_ref().map(Vec::len), Some(1));
    let e = seq.gt_problem.clone().expect("problem recorded");
    assert_eq!(e, DatasetError::PoseCountMismatch { path: poses.clone(), poses: 1, images: 3 });
    names(&e, "00.txt");
    // More poses than images: another sequence's file; none is used.
    write(&poses, &[pose_line(0.0), pose_line(1.0), pose_line(2.0), pose_line(3.0)].concat());
    let seq = open_odo(&tmp).unwrap();
    assert!(seq.gt.is_none());
    assert!(matches!(seq.gt_problem, Some(DatasetError::PoseCountMismatch { poses: 4, .. })));
    // `#` comment lines are skipped.
    write(&poses, &format!("# x y z\n{}{}{}", pose_line(0.0), pose_line(1.0), pose_line(2.0)));
    let seq = open_odo(&tmp).unwrap();
    assert_eq!(seq.gt.as_ref().map(Vec::len), Some(3));
    assert!(seq.gt_problem.is_none());
}

#[test]
fn times_shorter_than_images() {
    let (tmp, seq) = odometry_fixture(3);
    write(&seq.join("times.txt"), "0\n0.1\n");
    let e = open_odo(&tmp).unwrap_err();
    assert_eq!(e, DatasetError::TimesTooShort { path: seq.join("times.txt"), times: 2, images: 3 });
    names(&e, "times.txt");
}

/// Extra timestamps are used for the frames present, and a note says how many were left out.
#[test]
fn times_longer_than_images_are_noted() {
    let (tmp, seq) = odometry_fixture(3);
    assert!(open_odo(&tmp).unwrap().notes.is_empty());
    write(&seq.join("times.txt"), "0\n0.1\n0.2\n0.3\n0.4\n");
    let s = open_odo(&tmp).unwrap();
    assert_eq!(s.times_s, [0.0, 0.1, 0.2]);
    assert_eq!(s.notes.len(), 1, "{:?}", s.notes);
    assert!(s.notes[0].contains("times.txt: 5 timestamps for 3 images"), "{:?}", s.notes);
    assert!(s.notes[0].contains("last 2 frames"), "{:?}", s.notes);
    // The same for a raw drive's image timestamps.
    let (tmp, drive) = raw_fixture(2);
    assert!(Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap().notes.is_empty());
    let stamps = drive.join("image_02/timestamps.txt");
    let more = fs::read_to_string(&stamps).unwrap() + "2011-09-26 13:00:00.900000000\n";
    write(&stamps, &more);
    let s = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap();
    assert_eq!(s.times_s.len(), 2);
    assert!(
        s.notes.len() == 1 && s.notes[0].contains("3 timestamps for 2 images"),
        "{:?}",
        s.notes
    );
}

#[test]
fn left_right_image_count_mismatch() {
    let (tmp, seq) = odometry_fixture(3);
    fs::remove_file(seq.join("image_1/000002.png")).unwrap();
    let e = open_odo(&tmp).unwrap_err();
    assert_eq!(
        e,
        DatasetError::ImageCountMismatch {
            left_dir: seq.join("image_0"),
            right_dir: seq.join("image_1"),
            left: 3,
            right: 2
        }
    );
    names(&e, "image_0");
    names(&e, "image_1");
}

#[test]
fn left_right_image_size_mismatch() {
    // In the first pair: found when opening.
    let (tmp, seq) = odometry_fixture(2);
    let right0 = seq.join("image_1/000000.png");
    grey_png(&right0, W + 1, H, 0);
    let e = open_odo(&tmp).unwrap_err();
    assert_eq!(
        e,
        DatasetError::ImageSizeMismatch { path: right0, expected: (W, H), got: (W + 1, H) }
    );
    names(&e, "000000.png");
    names(&e, "9x4");

    // In a later pair: found when the frame is loaded.
    let (tmp, seq) = odometry_fixture(2);
    let right1 = seq.join("image_1/000001.png");
    grey_png(&right1, W, H + 2, 0);
    let s = open_odo(&tmp).unwrap();
    let e = s.load_luma(1).unwrap_err();
    assert_eq!(
        e,
        DatasetError::ImageSizeMismatch { path: right1, expected: (W, H), got: (W, H + 2) }
    );
    names(&e, "image_1");
}

#[test]
fn unreadable_png() {
    let (tmp, seq) = odometry_fixture(2);
    let left1 = seq.join("image_0/000001.png");
    fs::write(&left1, b"\x89PNG\r\n\x1a\nthis is not a png at all").unwrap();
    let s = open_odo(&tmp).unwrap();
    let e = s.load_luma(1).unwrap_err();
    assert!(matches!(&e, DatasetError::ImageDecode { path, .. } if *path == left1), "{e}");
    names(&e, "000001.png");

    // Garbage in the first frame is found already when opening (its header is read).
    let left0 = seq.join("image_0/000000.png");
    fs::write(&left0, [0u8, 1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
    let e = open_odo(&tmp).unwrap_err();
    assert!(matches!(&e, DatasetError::ImageDecode { path, .. } if *path == left0), "{e}");
    names(&e, "000000.png");
}

#[test]
fn empty_sequence_folder() {
    let tmp = tempfile::tempdir().unwrap();
    let seq = tmp.path().join("sequences/05");
    fs::create_dir_all(&seq).unwrap();
    let e = Sequence::open_odometry(tmp.path(), "05", None).unwrap_err();
    assert_eq!(e, DatasetError::EmptySequence { path: seq.clone() });
    names(&e, "05");
    let e = Sequence::open(&seq, None).unwrap_err();
    assert!(matches!(e, DatasetError::EmptySequence { .. }), "{e}");

    // Image folders present but empty.
    fs::create_dir_all(seq.join("image_0")).unwrap();
    fs::create_dir_all(seq.join("image_1")).unwrap();
    let e = Sequence::open_odometry(&seq, "05", None).unwrap_err();
    assert_eq!(e, DatasetError::EmptySequence { path: seq.join("image_0") });
    names(&e, "image_0");
}

#[test]
fn missing_sequence_and_unknown_folders() {
    let (tmp, _) = odometry_fixture(1);
    let e = Sequence::open_odometry(tmp.path(), "07", None).unwrap_err();
    assert_eq!(e, DatasetError::MissingFile { path: tmp.path().join("sequences/07") });
    let e = Sequence::open(&tmp.path().join("nope"), None).unwrap_err();
    assert!(matches!(e, DatasetError::MissingFile { .. }), "{e}");
    let other = tempfile::tempdir().unwrap();
    write(&other.path().join("readme.md"), "hi");
    let e = Sequence::open(other.path(), None).unwrap_err();
    assert!(matches!(e, DatasetError::UnknownLayout { .. }), "{e}");
}

// ---------------------------------------------------------------------------------------------
// Raw layout.

const CAM_TO_CAM: &str = "\
calib_time: 09-Jan-2012 13:57:47
corner_dist: 9.950000e-02
S_rect_00: 8.000000e+00 4.000000e+00
R_rect_00: 9.999239e-01 9.837760e-03 -7.445048e-03 -9.869795e-03 9.999421e-01 -4.278459e-03 7.402527e-03 4.351614e-03 9.999631e-01
P_rect_00: 7.215377e+02 0.000000e+00 6.095593e+02 0.000000e+00 0.000000e+00 7.215377e+02 1.728540e+02 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00
P_rect_01: 7.215377e+02 0.000000e+00 6.095593e+02 -3.875744e+02 0.000000e+00 7.215377e+02 1.728540e+02 0.000000e+00 0.000000e+00 0.000000e+00 1.000000e+00 0.000000e+00
S_rect_02: 8.000000e+00 4.000000e+00
P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03
P_rect_03: 7.215377e+02 0.000000e+00 6.095593e+02 -3.395242e+02 0.000000e+00 7.215377e+02 1.728540e+02 2.199936e+00 0.000000e+00 0.000000e+00 1.000000e+00 2.729905e-03
";
const IMU_TO_VELO: &str = "calib_time: 25-May-2012 16:47:16\nR: 9.999976e-01 7.553071e-04 -2.035826e-03 -7.854027e-04 9.998898e-01 -1.482298e-02 2.024406e-03 1.482454e-02 9.998881e-01\nT: -8.086759e-01 3.195559e-01 -7.997231e-01\n";
const VELO_TO_CAM: &str = "calib_time: 15-Mar-2012 11:37:16\nR: 7.533745e-03 -9.999714e-01 -6.166020e-04 1.480249e-02 7.280733e-04 -9.998902e-01 9.998621e-01 7.523790e-03 1.480755e-02\nT: -4.069766e-03 -7.631618e-02 -2.717806e-01\ndelta_f: 0.000000e+00 0.000000e+00\ndelta_c: 0.000000e+00 0.000000e+00\n";

fn oxts_line(lat: f64, lon: f64, yaw: f64) -> String {
    let mut f = vec![lat, lon, 112.8, 0.0, 0.0, yaw];
    f.extend(core::iter::repeat_n(0.5, 19));
    f.extend([4.0, 10.0, 4.0, 4.0, 0.0]);
    f.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" ") + "\n"
}

/// `root/2011_09_26/2011_09_26_drive_0001_sync` with `n` colour frames and oxts records.
fn raw_fixture(n: usize) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let date = tmp.path().join("2011_09_26");
    write(&date.join("calib_cam_to_cam.txt"), CAM_TO_CAM);
    write(&date.join("calib_imu_to_velo.txt"), IMU_TO_VELO);
    write(&date.join("calib_velo_to_cam.txt"), VELO_TO_CAM);
    let drive = date.join("2011_09_26_drive_0001_sync");
    let mut stamps = String::new();
    for i in 0..n {
        rgb_png(&drive.join(format!("image_02/data/{i:010}.png")), W, H, [255, 255, 255]);
        rgb_png(&drive.join(format!("image_03/data/{i:010}.png")), W, H, [0, 0, 255]);
        // Heading east (yaw 0), one metre of easting per frame at the equator-scaled latitude.
        let lat = 49.0f64;
        let lon =
            8.4 + i as f64 / (6_378_137.0 * lat.to_radians().cos()) * 180.0 / core::f64::consts::PI;
        write(&drive.join(format!("oxts/data/{i:010}.txt")), &oxts_line(lat, lon, 0.0));
        stamps += &format!("2011-09-26 13:00:00.{:09}\n", 100_000_000 + i * 50_000_000);
    }
    write(&drive.join("image_02/timestamps.txt"), &stamps);
    (tmp, drive)
}

#[test]
fn raw_opens_every_way_it_can_be_named() {
    let (tmp, drive) = raw_fixture(3);
    let date = drive.parent().unwrap().to_path_buf();
    let a = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap();
    assert_eq!(a.layout, Layout::Raw);
    assert_eq!(a.name, "2011_09_26_drive_0001_sync");
    assert_eq!(a.pair, CameraPair::Colour);
    assert_eq!(a.image_size, (W, H));
    assert!((a.calib.baseline_m * a.calib.fx_px - 384.381).abs() < 1e-3);
    assert!((a.times_s[1] - 0.05).abs() < 1e-9 && (a.times_s[2] - 0.1).abs() < 1e-9);
    let gt = a.gt.as_ref().unwrap();
    assert_eq!(gt[0], semloc_core::geom::Se3::identity());
    // Driving along the IMU's x axis for 2 m: the camera (z forward) moves ~2 m along +z.
    assert!((gt[2].trans.norm() - 2.0).abs() < 1e-3, "{}", gt[2].trans);
    assert!(gt[2].trans.z > 1.99, "{}", gt[2].trans);
    assert!((a.gt_length_m().unwrap() - 2.0).abs() < 1e-3);
    let (l, r) = a.load_luma(2).unwrap();
    assert_eq!((l.get_pixel(0, 0)[0], r.get_pixel(0, 0)[0]), (255, 29));

    for (root, name) in [
        (tmp.path(), "2011_09_26_drive_0001_sync"),
        (date.as_path(), "2011_09_26_0001"),
        (drive.as_path(), "whatever"),
    ] {
        let b = Sequence::open_raw(root, name, None).unwrap();
        assert_eq!((b.left.len(), b.gt.as_ref().map(Vec::len)), (3, Some(3)), "{name}");
    }
    for root in [tmp.path(), date.as_path(), drive.as_path()] {
        let b = Sequence::open(root, None).unwrap();
        assert_eq!(b.name, "2011_09_26_drive_0001_sync");
        assert_eq!(b.gt.as_ref().unwrap()[2], gt[2]);
    }
    let s = a.summary();
    assert_eq!(s.cameras, ["image_02".to_string(), "image_03".to_string()]);
    assert_eq!(serde_json::to_value(&s).unwrap()["layout"], "raw");
}

#[test]
fn raw_without_oxts_has_no_gt_and_missing_drive_is_named() {
    let (tmp, drive) = raw_fixture(2);
    fs::remove_dir_all(drive.join("oxts")).unwrap();
    let s = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap();
    assert!(s.gt.is_none());
    let e = Sequence::open_raw(tmp.path(), "2011_09_26_0002", None).unwrap_err();
    assert!(matches!(e, DatasetError::MissingFile { .. }), "{e}");
    names(&e, "2011_09_26_drive_0002_sync");
}

#[test]
fn oxts_file_with_missing_fields() {
    let (tmp, drive) = raw_fixture(2);
    let rec = drive.join("oxts/data/0000000001.txt");
    let line = oxts_line(49.0, 8.4, 0.0);
    let short: Vec<&str> = line.split_whitespace().take(25).collect();
    write(&rec, &short.join(" "));
    let seq = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap();
    assert_eq!(seq.gt.as_ref().map(Vec::len), Some(1), "the record before the bad one");
    let e = seq.gt_problem.clone().expect("problem recorded");
    assert_eq!(e, DatasetError::OxtsFields { path: rec, got: 25 });
    names(&e, "0000000001.txt");
}

#[test]
fn oxts_count_and_raw_timestamps_checked() {
    let (tmp, drive) = raw_fixture(3);
    fs::remove_file(drive.join("oxts/data/0000000002.txt")).unwrap();
    let seq = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap();
    assert_eq!(seq.gt.as_ref().map(Vec::len), Some(2));
    let e = seq.gt_problem.clone().expect("problem recorded");
    assert!(matches!(e, DatasetError::OxtsCountMismatch { oxts: 2, images: 3, .. }), "{e}");
    names(&e, "data");

    let (tmp, drive) = raw_fixture(3);
    let stamps = drive.join("image_02/timestamps.txt");
    write(&stamps, "2011-09-26 13:04:32.345808896\n");
    let e = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap_err();
    assert_eq!(e, DatasetError::TimesTooShort { path: stamps.clone(), times: 1, images: 3 });
    names(&e, "timestamps.txt");
    write(&stamps, "2011-09-26 13:04:32.3\n2011-09-26 25:04:32.3\n");
    let e = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap_err();
    assert!(matches!(e, DatasetError::Parse { line: 2, .. }), "{e}");
    names(&e, "timestamps.txt:2");
}

#[test]
fn raw_image_size_must_match_s_rect() {
    let (tmp, drive) = raw_fixture(1);
    rgb_png(&drive.join("image_02/data/0000000000.png"), W * 2, H, [0, 0, 0]);
    rgb_png(&drive.join("image_03/data/0000000000.png"), W * 2, H, [0, 0, 0]);
    let e = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap_err();
    assert!(
        matches!(e, DatasetError::ImageSizeMismatch { expected: (8, 4), got: (16, 4), .. }),
        "{e}"
    );
    names(&e, "0000000000.png");
}

#[test]
fn raw_missing_velo_calibration() {
    let (tmp, drive) = raw_fixture(1);
    let f = drive.parent().unwrap().join("calib_velo_to_cam.txt");
    fs::remove_file(&f).unwrap();
    let e = Sequence::open_raw(tmp.path(), "2011_09_26_0001", None).unwrap_err();
    assert_eq!(e, DatasetError::MissingFile { path: f });
    names(&e, "calib_velo_to_cam.txt");
}
