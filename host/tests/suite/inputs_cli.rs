//! `semloc info`, `gt` and `run` on the two non-KITTI layouts, a generic stereo folder and a
//! EuRoC MAV sequence, built from one synthetic KITTI-layout sequence (`semloc synth`): the
//! same images and camera in each layout must give the same answers.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::common::{s, semloc, synth, text};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion};

/// `ROOT/sequences/00` (8 frames, static street) and `ROOT/poses/00.txt`, written once.
fn synth_root() -> &'static Path {
    static ROOT: OnceLock<tempfile::TempDir> = OnceLock::new();
    ROOT.get_or_init(|| synth("8", "static", "3")).path()
}

fn seq_dir() -> PathBuf {
    synth_root().join("sequences/00")
}

fn rows(p: &Path) -> Vec<Vec<f64>> {
    fs::read_to_string(p)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|v| v.parse().unwrap()).collect())
        .collect()
}

fn images(cam: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> =
        fs::read_dir(seq_dir().join(cam)).unwrap().map(|e| e.unwrap().path()).collect();
    v.sort();
    v
}

fn info_json(args: &[&str]) -> serde_json::Value {
    let o = semloc(&[&["info", "--json"], args].concat());
    assert!(o.status.success(), "{}", text(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The synthetic sequence as a stereo folder: left/, right/, calib.txt, times.txt, gt.txt.
fn folder_fixture(dir: &Path, with_calib: bool) -> PathBuf {
    let root = dir.join("stereo");
    for (cam, side) in [("image_0", "left"), ("image_1", "right")] {
        fs::create_dir_all(root.join(side)).unwrap();
        for p in images(cam) {
            fs::copy(&p, root.join(side).join(p.file_name().unwrap())).unwrap();
        }
    }
    if with_calib {
        fs::copy(seq_dir().join("calib.txt"), root.join("calib.txt")).unwrap();
    }
    fs::copy(seq_dir().join("times.txt"), root.join("times.txt")).unwrap();
    fs::copy(synth_root().join("poses/00.txt"), root.join("gt.txt")).unwrap();
    root
}

const T0_NS: i64 = 1_403_636_579_763_555_584;
const PERIOD_NS: i64 = 100_000_000;

/// The synthetic sequence as EuRoC: an undistorted rig with identity rotations (camera =
/// body), so the rectification leaves the images as they are, and the ground truth is the
/// KITTI poses as body poses with EuRoC timestamps.
fn euroc_fixture(dir: &Path) -> PathBuf {
    let v = info_json(&[s(synth_root()), "--seq", "00"]);
    let c = &v["calib"];
    let f = |k: &str| c[k].as_f64().unwrap();
    let (w, h) = (v["width_px"].as_u64().unwrap(), v["height_px"].as_u64().unwrap());
    let mav = dir.join("MH_synth").join("mav0");
    for (k, cam) in ["image_0", "image_1"].iter().enumerate() {
        let d = mav.join(format!("cam{k}"));
        fs::create_dir_all(d.join("data")).unwrap();
        let mut csv = String::from("#timestamp [ns],filename\n");
        for (i, p) in images(cam).iter().enumerate() {
            let ns = T0_NS + i as i64 * PERIOD_NS;
            fs::copy(p, d.join("data").join(format!("{ns}.png"))).unwrap();
            csv.push_str(&format!("{ns},{ns}.png\n"));
        }
        fs::write(d.join("data.csv"), csv).unwrap();
        let x = if k == 0 { 0.0 } else { f("baseline_m") };
        fs::write(
            d.join("sensor.yaml"),
            format!(
                "sensor_type: camera\ncomment: synthetic\nT_BS:\n  cols: 4\n  rows: 4\n  data: [1.0, 0.0, 0.0, {x},\n         0.0, 1.0, 0.0, 0.0,\n         0.0, 0.0, 1.0, 0.0,\n         0.0, 0.0, 0.0, 1.0]\n\
                 rate_hz: 10\nresolution: [{w}, {h}]\ncamera_model: pinhole\nintrinsics: [{}, {}, {}, {}] #fu, fv, cu, cv\n\
                 distortion_model: radial-tangential\ndistortion_coefficients: [0.0, 0.0, 0.0, 0.0]\n",
                f("fx_px"),
                f("fy_px"),
                f("cx_px"),
                f("cy_px")
            ),
        )
        .unwrap();
    }
    let gt = mav.join("state_groundtruth_estimate0");
    fs::create_dir_all(&gt).unwrap();
    let mut csv = String::from("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n");
    for (i, r) in rows(&synth_root().join("poses/00.txt")).iter().enumerate() {
        let m = Matrix3::new(r[0], r[1], r[2], r[4], r[5], r[6], r[8], r[9], r[10]);
        let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
        let ns = T0_NS + i as i64 * PERIOD_NS;
        csv.push_str(&format!(
            "{ns},{:e},{:e},{:e},{:e},{:e},{:e},{:e}\n",
            r[3], r[7], r[11], q.w, q.i, q.j, q.k
        ));
    }
    fs::write(gt.join("data.csv"), csv).unwrap();
    mav.parent().unwrap().to_path_buf()
}

fn assert_poses_close(a: &[Vec<f64>], b: &[Vec<f64>], tol: f64) {
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        for (u, v) in x.iter().zip(y) {
            assert!((u - v).abs() <= tol, "pose {i}: {x:?} vs {y:?}");
        }
    }
}

#[test]
fn a_stereo_folder_reads_gives_ground_truth_and_runs_like_its_kitti_original() {
    let dir = tempfile::tempdir().unwrap();
    let root = folder_fixture(dir.path(), true);
    let kitti = info_json(&[s(synth_root()), "--seq", "00"]);
    let v = info_json(&[s(&root)]);
    assert_eq!(v["layout"], "folder");
    assert_eq!(v["frames"], 8);
    assert_eq!(v["calib"], kitti["calib"]);
    assert_eq!(v["cameras"], serde_json::json!(["left", "right"]));
    assert_eq!(v["gt_frames"], 8);
    assert_eq!(v["duration_s"], kitti["duration_s"]);

    // Ground truth out: the KITTI poses (they start at the identity, so re-basing keeps them).
    let gt = dir.path().join("gt");
    let o = semloc(&["gt", s(&root), "--out", s(&gt)]);
    assert!(o.status.success(), "{}", text(&o));
    assert_poses_close(&rows(&gt.join("gt.txt")), &rows(&synth_root().join("poses/00.txt")), 1e-12);
    let tum = rows(&gt.join("gt_tum.txt"));
    assert_eq!(tum[3][0], rows(&root.join("times.txt"))[3][0]);

    // The same run as on the KITTI layout, bit for bit.
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let o = semloc(&["run", s(&root), "--out", s(&a)]);
    assert!(o.status.success(), "{}", text(&o));
    let o = semloc(&["run", s(synth_root()), "--seq", "00", "--out", s(&b)]);
    assert!(o.status.success(), "{}", text(&o));
    let traj = |d: &Path| fs::read_to_string(d.join("trajectory.txt")).unwrap();
    assert_eq!(traj(&a), traj(&b));
    assert_eq!(traj(&a).lines().count(), 8);
    let summary: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(a.join("summary.json")).unwrap()).unwrap();
    assert!(summary["eval"].is_object() || summary.to_string().contains("ate"), "{summary}");
}

#[test]
fn a_stereo_folder_without_calibration_asks_for_a_settings_camera() {
    let dir = tempfile::tempdir().unwrap();
    let root = folder_fixture(dir.path(), false);
    let o = semloc(&["info", s(&root)]);
    assert_eq!(o.status.code(), Some(1));
    let t = text(&o);
    assert!(
        t.contains("no calibration") && t.contains("--config FILE") && t.contains("[camera]"),
        "{t}"
    );
    // A settings file with the camera: info, gt and run work; run records the camera's source.
    let k = &info_json(&[s(synth_root()), "--seq", "00"])["calib"];
    let rig = dir.path().join("rig.toml");
    fs::write(
        &rig,
        format!(
            "[camera]\nfx = {}\nfy = {}\ncx = {}\ncy = {}\nbaseline = {}\n",
            k["fx_px"], k["fy_px"], k["cx_px"], k["cy_px"], k["baseline_m"]
        ),
    )
    .unwrap();
    let v = info_json(&[s(&root), "--config", s(&rig)]);
    assert_eq!(&v["calib"], k);
    let o = semloc(&["gt", s(&root), "--config", s(&rig), "--out", s(&dir.path().join("gt"))]);
    assert!(o.status.success(), "{}", text(&o));
    let out = dir.path().join("run");
    let o = semloc(&["run", s(&root), "--config", s(&rig), "--out", s(&out), "--max-frames", "3"]);
    assert!(o.status.success(), "{}", text(&o));
    let summary: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["provenance"]["camera_from"], "settings");
    // Without times.txt: a note says which period is assumed.
    fs::remove_file(root.join("times.txt")).unwrap();
    let o = semloc(&["info", s(&root), "--config", s(&rig)]);
    assert!(o.status.success() && text(&o).contains("note: no "), "{}", text(&o));
}

#[test]
fn a_euroc_sequence_reads_gives_recording_time_ground_truth_and_runs() {
    let dir = tempfile::tempdir().unwrap();
    let root = euroc_fixture(dir.path());
    let kitti = info_json(&[s(synth_root()), "--seq", "00"]);
    for path in [root.clone(), root.join("mav0")] {
        let v = info_json(&[s(&path)]);
        assert_eq!(v["layout"], "euroc");
        assert_eq!(v["name"], "MH_synth");
        assert_eq!(v["frames"], 8);
        assert_eq!(v["rectified_on_load"], true);
        assert_eq!(v["gt_frames"], 8);
        for key in ["fx_px", "fy_px", "cx_px", "cy_px", "baseline_m"] {
            let (a, b) = (v["calib"][key].as_f64().unwrap(), kitti["calib"][key].as_f64().unwrap());
            assert!((a - b).abs() < 1e-9 * b.abs().max(1.0), "{key}: {a} vs {b}");
        }
    }
    let o = semloc(&["info", s(&root)]);
    assert!(text(&o).contains("EuRoC MAV sequence MH_synth"), "{}", text(&o));

    let gt = dir.path().join("gt");
    let o = semloc(&["gt", s(&root), "--out", s(&gt)]);
    assert!(o.status.success(), "{}", text(&o));
    assert_poses_close(&rows(&gt.join("gt.txt")), &rows(&synth_root().join("poses/00.txt")), 1e-9);
    let tum = rows(&gt.join("gt_tum.txt"));
    assert_eq!(tum.len(), 8);
    // Recording times: UNIX seconds of the image timestamps.
    assert!((tum[0][0] - T0_NS as f64 * 1e-9).abs() < 1e-6, "{}", tum[0][0]);
    assert!((tum[5][0] - tum[0][0] - 0.5).abs() < 1e-6);
    let times = rows(&gt.join("times.txt"));
    assert!((times[5][0] - 0.5).abs() < 1e-12);

    // The identity rig's rectification leaves the images unchanged: the run tracks as on
    // the KITTI layout (the rectified camera equals the original to ~1e-13).
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let o = semloc(&["run", s(&root), "--out", s(&a)]);
    assert!(o.status.success(), "{}", text(&o));
    let o = semloc(&["run", s(synth_root()), "--seq", "00", "--out", s(&b)]);
    assert!(o.status.success(), "{}", text(&o));
    assert_poses_close(&rows(&a.join("trajectory.txt")), &rows(&b.join("trajectory.txt")), 1e-6);

    // A cam1 frame without a cam0 partner: the error names the file and line.
    let csv1 = root.join("mav0/cam1/data.csv");
    let text1 = fs::read_to_string(&csv1).unwrap().replacen(
        &format!("{}", T0_NS + PERIOD_NS),
        &format!("{}", T0_NS + PERIOD_NS + 1),
        2,
    );
    fs::write(&csv1, text1).unwrap();
    let o = semloc(&["info", s(&root)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        text(&o).contains("cam0/data.csv:3") || text(&o).contains("cam1/data.csv:3"),
        "{}",
        text(&o)
    );
}

/// `semloc segment` on a distorted EuRoC sequence labels the left images rectified, as `run`
/// tracks them: its labels equal those of the rectified image given as a file, not those of
/// the raw one.
#[test]
fn segment_labels_euroc_images_rectified() {
    let dir = tempfile::tempdir().unwrap();
    let root = euroc_fixture(dir.path());
    for k in 0..2 {
        let p = root.join(format!("mav0/cam{k}/sensor.yaml"));
        let y = fs::read_to_string(&p).unwrap().replace(
            "distortion_coefficients: [0.0, 0.0, 0.0, 0.0]",
            "distortion_coefficients: [-0.25, 0.06, 0.0, 0.0]",
        );
        fs::write(&p, y).unwrap();
    }
    // 48x160: the synthetic 1241x376 frames down-scaled 1/8, the most the letterbox does.
    let onnx = semloc::nn::fixtures::write_tiny(dir.path(), "tiny", 48, 160).unwrap();
    let slm = dir.path().join("tiny.slm");
    let o = semloc(&["convert", "--onnx", s(&onnx), "--out", s(&slm)]);
    assert!(o.status.success(), "{}", text(&o));

    let seq = semloc::dataset::Sequence::open(&root, None).unwrap();
    let name = seq.left[0].file_stem().unwrap().to_str().unwrap().to_string();
    let files = dir.path().join("files");
    fs::create_dir_all(files.join("rect")).unwrap();
    seq.load_luma_side(0, false)
        .unwrap()
        .save(files.join("rect").join(format!("{name}.png")))
        .unwrap();
    let labels = |input: &Path, out: &str| {
        let out = dir.path().join(out);
        let o =
            semloc(&["segment", s(input), "--model", s(&slm), "--out", s(&out), "--limit", "1"]);
        assert!(o.status.success(), "{}", text(&o));
        image::open(out.join(format!("{name}_labels.png"))).unwrap().to_luma8()
    };
    let from_seq = labels(&root, "seq");
    let o = semloc(&[
        "segment",
        s(&root),
        "--model",
        s(&slm),
        "--out",
        s(&dir.path().join("x")),
        "--limit",
        "1",
    ]);
    assert!(text(&o).contains("labelled rectified"), "{}", text(&o));
    assert_eq!(from_seq, labels(&files.join("rect"), "rect"), "labels of the rectified image");
    assert_ne!(from_seq, labels(&seq.left[0], "raw"), "labels of the raw image");
}
