//! The settings file (`semloc config`, `run --config`, `run --orbslam2-settings`) and
//! `semloc gt`, through the binary, on a small synthetic sequence.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use crate::common::{s, semloc, synth, text};

/// `ROOT/sequences/00` (8 frames, static street) and `ROOT/poses/00.txt`, written once.
fn synth_root() -> &'static Path {
    static ROOT: OnceLock<tempfile::TempDir> = OnceLock::new();
    ROOT.get_or_init(|| synth("8", "static", "5")).path()
}

fn summary(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap()
}

/// The synthetic camera as `semloc info --json` reports it: (fx, fy, cx, cy, baseline, w, h).
fn synth_camera() -> (f64, f64, f64, f64, f64, u64, u64) {
    let o = semloc(&["info", s(synth_root()), "--seq", "00", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let c = &v["calib"];
    let f = |k: &str| c[k].as_f64().unwrap();
    (
        f("fx_px"),
        f("fy_px"),
        f("cx_px"),
        f("cy_px"),
        f("baseline_m"),
        v["width_px"].as_u64().unwrap(),
        v["height_px"].as_u64().unwrap(),
    )
}

#[test]
fn print_defaults_is_a_valid_settings_file_and_check_reads_it_back() {
    let o = semloc(&["config", "--print-defaults"]);
    assert!(o.status.success(), "{}", text(&o));
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("rig.toml");
    std::fs::write(&f, &o.stdout).unwrap();
    let checked = semloc(&["config", "--check", s(&f)]);
    assert!(checked.status.success(), "{}", text(&checked));
    let printed = String::from_utf8_lossy(&checked.stdout);
    assert!(printed.contains("n_features = 2000") && printed.contains("[tracker.em]"), "{printed}");
    // Nothing asked: a usage error that says what to ask.
    let o = semloc(&["config"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("--print-defaults"), "{}", text(&o));
    // A misspelt key names the file and the key.
    std::fs::write(&f, "[tracker]\nransac_iteration = 5\n").unwrap();
    let o = semloc(&["config", "--check", s(&f)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("rig.toml") && text(&o).contains("ransac_iteration"), "{}", text(&o));
}

#[test]
fn run_takes_its_parameters_from_the_settings_file_and_flags_override_it() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("rig.toml");
    std::fs::write(
        &f,
        "[orb]\nn_features = 1000\n[stereo]\nsad_half_window = 4\n[tracker]\nassociation = \"em\"\n\
         ransac_iterations = 50\nransac_seed = 7\n[tracker.em]\niterations = 2\n",
    )
    .unwrap();
    let out = dir.path().join("a");
    let o = semloc(&["run", s(synth_root()), "--seq", "00", "--out", s(&out), "--config", s(&f)]);
    assert!(o.status.success(), "{}", text(&o));
    let p = &summary(&out)["provenance"];
    assert_eq!(p["orb"]["n_features"], 1000);
    assert_eq!(p["stereo"]["sad_half_window"], 4);
    assert_eq!(p["tracker"]["association"], "em");
    assert_eq!(p["tracker"]["ransac_iterations"], 50);
    assert_eq!(p["tracker"]["ransac_seed"], 7);
    assert_eq!(p["tracker"]["em"]["iterations"], 2);
    assert_eq!(p["settings_file"], s(&f));
    assert_eq!(p["camera_from"], "dataset");
    // Flags given on the command line win over the file.
    let out = dir.path().join("b");
    let o = semloc(&[
        "run",
        s(synth_root()),
        "--seq",
        "00",
        "--out",
        s(&out),
        "--config",
        s(&f),
        "--assoc",
        "hard",
        "--ransac-iterations",
        "20",
        "--ransac-seed",
        "3",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let p = &summary(&out)["provenance"];
    assert_eq!(
        (&p["tracker"]["association"], &p["tracker"]["ransac_iterations"]),
        (&"hard".into(), &20.into())
    );
    assert_eq!(p["tracker"]["ransac_seed"], 3);
    assert_eq!(p["orb"]["n_features"], 1000);
    // Fewer features really reach the extractor: the run differs from the defaults'.
    let out_d = dir.path().join("d");
    let o = semloc(&["run", s(synth_root()), "--seq", "00", "--out", s(&out_d)]);
    assert!(o.status.success(), "{}", text(&o));
    let csv = |d: &Path| std::fs::read_to_string(d.join("frames.csv")).unwrap();
    assert_ne!(csv(&out), csv(&out_d));
}

#[test]
fn a_settings_camera_replaces_the_calibration_and_must_fit_the_images() {
    let (fx, fy, cx, cy, b, w, h) = synth_camera();
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("cam.toml");
    let cam = format!(
        "[camera]\nfx = {fx:?}\nfy = {fy:?}\ncx = {cx:?}\ncy = {cy:?}\nbf = {:?}\n",
        fx * b
    );
    std::fs::write(&f, format!("{cam}width = {w}\nheight = {h}\n")).unwrap();
    let (same, theirs) = (dir.path().join("same"), dir.path().join("theirs"));
    let o = semloc(&["run", s(synth_root()), "--seq", "00", "--out", s(&same), "--config", s(&f)]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(summary(&same)["provenance"]["camera_from"], "settings");
    let o = semloc(&["run", s(synth_root()), "--seq", "00", "--out", s(&theirs)]);
    assert!(o.status.success(), "{}", text(&o));
    let traj = |d: &Path| std::fs::read_to_string(d.join("trajectory.txt")).unwrap();
    // The same camera in a file gives the same poses (bf/fx round-trips to the baseline).
    let (a, b2) = (traj(&same), traj(&theirs));
    for (la, lb) in a.lines().zip(b2.lines()) {
        let pa: Vec<f64> = la.split(' ').map(|v| v.parse().unwrap()).collect();
        let pb: Vec<f64> = lb.split(' ').map(|v| v.parse().unwrap()).collect();
        assert!(pa.iter().zip(&pb).all(|(x, y)| (x - y).abs() < 1e-6), "{la}\n{lb}");
    }
    // A camera for another image size is refused before any output.
    std::fs::write(&f, format!("{cam}width = {}\nheight = {h}\n", w + 2)).unwrap();
    let bad = dir.path().join("bad");
    let o = semloc(&["run", s(synth_root()), "--seq", "00", "--out", s(&bad), "--config", s(&f)]);
    assert_eq!(o.status.code(), Some(1));
    let t = text(&o);
    assert!(t.contains("cam.toml") && t.contains(&format!("{}x{h}", w + 2)), "{t}");
    assert!(!bad.join("summary.json").exists());
}

#[test]
fn run_reads_an_orbslam2_settings_file() {
    let (fx, fy, cx, cy, b, _, _) = synth_camera();
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("Synth.yaml");
    std::fs::write(
        &f,
        format!(
            "%YAML:1.0\n# camera\nCamera.fx: {fx}\nCamera.fy: {fy}\nCamera.cx: {cx}\nCamera.cy: {cy}\n\
             Camera.k1: 0.0\nCamera.fps: 10.0\nCamera.bf: {}\nCamera.RGB: 1\nThDepth: 40\n\
             ORBextractor.nFeatures: 1500\nORBextractor.scaleFactor: 1.2\nORBextractor.nLevels: 8\n\
             ORBextractor.iniThFAST: 20\nORBextractor.minThFAST: 7\nViewer.PointSize:2\n",
            fx * b
        ),
    )
    .unwrap();
    let out = dir.path().join("o");
    let o = semloc(&[
        "run",
        s(synth_root()),
        "--seq",
        "00",
        "--out",
        s(&out),
        "--orbslam2-settings",
        s(&f),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("note:") && t.contains("Camera.fps") && t.contains("Viewer.PointSize"),
        "{t}"
    );
    let p = &summary(&out)["provenance"];
    assert_eq!((&p["orb"]["n_features"], &p["camera_from"]), (&1500.into(), &"settings".into()));
    assert_eq!(p["tracker"]["close_depth_baselines"], 40.0);
    // The converter prints the equivalent TOML, which `--config` takes.
    let o = semloc(&["config", "--orbslam2-settings", s(&f)]);
    assert!(o.status.success(), "{}", text(&o));
    let toml_file = dir.path().join("synth.toml");
    std::fs::write(&toml_file, &o.stdout).unwrap();
    let o = semloc(&["config", "--check", s(&toml_file)]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(String::from_utf8_lossy(&o.stdout).contains("n_features = 1500"));
    // Both at once is a usage error.
    let o = semloc(&[
        "run",
        s(synth_root()),
        "--seq",
        "00",
        "--out",
        s(&out),
        "--config",
        s(&toml_file),
        "--orbslam2-settings",
        s(&f),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
}

fn read_poses(p: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|v| v.parse().unwrap()).collect())
        .collect()
}

#[test]
fn gt_writes_kitti_and_tum_ground_truth_that_eval_accepts() {
    let dir = tempfile::tempdir().unwrap();
    let gt_dir = dir.path().join("gt");
    let o = semloc(&["gt", s(synth_root()), "--seq", "00", "--out", s(&gt_dir)]);
    assert!(o.status.success(), "{}", text(&o));
    let kitti = read_poses(&gt_dir.join("gt.txt"));
    assert_eq!(kitti, read_poses(&synth_root().join("poses/00.txt")));
    let tum = read_poses(&gt_dir.join("gt_tum.txt"));
    let times = read_poses(&synth_root().join("sequences/00/times.txt"));
    assert_eq!(tum.len(), kitti.len());
    for ((t, k), time) in tum.iter().zip(&kitti).zip(&times) {
        assert_eq!(t[0], time[0], "odometry TUM time is times.txt");
        assert_eq!(&t[1..4], &[k[3], k[7], k[11]]);
    }
    assert_eq!(read_poses(&gt_dir.join("times.txt")), times);
    // A second time: refused, then replaced with --force.
    let o = semloc(&["gt", s(synth_root()), "--seq", "00", "--out", s(&gt_dir)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("--force"), "{}", text(&o));
    let o = semloc(&["gt", s(synth_root()), "--seq", "00", "--out", s(&gt_dir), "--force"]);
    assert!(o.status.success(), "{}", text(&o));
    // A run's TUM file and the ground truth's share their time base: evo-style association.
    let run_dir = dir.path().join("run");
    let o = semloc(&["run", s(synth_root()), "--seq", "00", "--out", s(&run_dir)]);
    assert!(o.status.success(), "{}", text(&o));
    let o = semloc(&[
        "eval",
        "--gt",
        s(&gt_dir.join("gt_tum.txt")),
        "--est",
        s(&run_dir.join("trajectory_tum.txt")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("8 poses") || text(&o).contains("ATE"), "{}", text(&o));
}

#[test]
fn gt_without_ground_truth_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let root: PathBuf = dir.path().join("data");
    let seq = root.join("sequences/00");
    std::fs::create_dir_all(&root).unwrap();
    // Copy the sequence without its poses.
    let src = synth_root().join("sequences/00");
    for cam in ["image_0", "image_1"] {
        std::fs::create_dir_all(seq.join(cam)).unwrap();
        for e in std::fs::read_dir(src.join(cam)).unwrap() {
            let e = e.unwrap();
            std::fs::copy(e.path(), seq.join(cam).join(e.file_name())).unwrap();
        }
    }
    for f in ["calib.txt", "times.txt"] {
        std::fs::copy(src.join(f), seq.join(f)).unwrap();
    }
    let out = dir.path().join("gt");
    let o = semloc(&["gt", s(&seq), "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("no ground truth"), "{}", text(&o));
    assert!(!out.join("gt.txt").exists());
}
