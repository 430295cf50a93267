//! `semloc run --rerun FILE.rrd`: the recording is read back with rerun's own decoder and
//! checked against the run's `frames.csv`.
#![cfg(feature = "rerun")]

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use crate::common::{run_parked, s, semloc, text};
use rerun::components::{ClassId, Color, Position2D, Position3D};
use rerun::log::{Chunk, LogMsg};

/// Every chunk of the recording at `path`, decoded by rerun.
fn read_chunks(path: &Path) -> Vec<Chunk> {
    let file = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let decoder = re_log_encoding::decoder::Decoder::new(file).expect("an rrd header");
    let mut chunks = Vec::new();
    let mut store_infos = 0;
    for msg in decoder {
        match msg.expect("a decodable message") {
            LogMsg::SetStoreInfo(info) => {
                assert_eq!(info.info.application_id.as_str(), "semloc");
                store_infos += 1;
            }
            LogMsg::ArrowMsg(_, arrow) => chunks.push(Chunk::from_arrow_msg(&arrow).unwrap()),
            LogMsg::BlueprintActivationCommand(_) => {}
        }
    }
    assert!(store_infos >= 1, "no store info");
    chunks
}

/// The `frame` timeline value of each row of `chunk` (None for static chunks).
fn frames_of(chunk: &Chunk) -> Option<Vec<i64>> {
    chunk
        .timelines()
        .iter()
        .find(|(name, _)| name.as_str() == "frame")
        .map(|(_, col)| col.times_raw().to_vec())
}

/// Per frame, the rows of `entity` in `chunks`, each row as `f(chunk, row)`.
fn per_frame<T>(chunks: &[Chunk], entity: &str, f: impl Fn(&Chunk) -> Vec<T>) -> BTreeMap<i64, T> {
    let mut out = BTreeMap::new();
    for c in chunks.iter().filter(|c| c.entity_path().to_string() == entity) {
        let Some(frames) = frames_of(c) else { continue };
        let rows = f(c);
        if rows.is_empty() {
            continue; // the archetype's indicator chunk
        }
        assert_eq!(rows.len(), frames.len(), "{entity}: rows and frame times");
        for (k, row) in frames.into_iter().zip(rows) {
            assert!(out.insert(k, row).is_none(), "{entity}: frame {k} twice");
        }
    }
    out
}

/// `frames.csv` column `name`, per row.
fn csv_column(out: &Path, name: &str) -> Vec<u32> {
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let i = header.iter().position(|h| *h == name).unwrap();
    lines.map(|l| l.split(',').nth(i).unwrap().parse().unwrap()).collect()
}

#[test]
fn run_records_images_features_map_and_paths() {
    let dir = tempfile::tempdir().unwrap();
    let (out, rrd) = (dir.path().join("out"), dir.path().join("run.rrd"));
    let o = run_parked(&out, &["--semantics", "motion", "--rerun", s(&rrd)]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("10 frames recorded to"), "{}", text(&o));
    let chunks = read_chunks(&rrd);
    let entities: BTreeSet<String> = chunks.iter().map(|c| c.entity_path().to_string()).collect();
    for e in [
        "/world",
        "/world/camera",
        "/world/camera/image",
        "/world/camera/image/segmentation",
        "/world/camera/image/features/class",
        "/world/camera/image/features/tracking",
        "/world/camera/image/features/moving",
        "/world/map",
        "/world/path/estimated",
        "/world/path/ground_truth",
        "/stats/inliers",
    ] {
        assert!(entities.contains(e), "{e} missing from {entities:?}");
    }

    // Per frame: the tracking colours say how many features were inliers, and that is the
    // run's own inlier count; the class points are the same features with a class each.
    let inliers = csv_column(&out, "inliers");
    let landmarks = csv_column(&out, "landmarks");
    assert_eq!(inliers.len(), 10);
    let green = Color::from_rgb(40, 220, 60);
    let tracking = per_frame(&chunks, "/world/camera/image/features/tracking", |c| {
        c.iter_component::<Color>().map(|row| row.iter().filter(|&&k| k == green).count()).collect()
    });
    let positions = per_frame(&chunks, "/world/camera/image/features/tracking", |c| {
        c.iter_component::<Position2D>().map(|row| row.len()).collect()
    });
    let classes = per_frame(&chunks, "/world/camera/image/features/class", |c| {
        c.iter_component::<ClassId>().map(|row| row.len()).collect()
    });
    assert_eq!(tracking.keys().copied().collect::<Vec<_>>(), (0..10).collect::<Vec<i64>>());
    for (k, &n_green) in &tracking {
        assert_eq!(n_green as u32, inliers[*k as usize], "frame {k}: green features vs inliers");
        assert_eq!(classes[k], positions[k], "frame {k}: class and tracking points");
        assert!(positions[k] > 100, "frame {k}: {} features", positions[k]);
    }
    assert!(tracking.values().skip(1).all(|&g| g > 50), "inliers after the first frame");

    // The map points are the live landmarks of frames.csv, with classes from the labels.
    let map = per_frame(&chunks, "/world/map", |c| {
        c.iter_component::<Position3D>().map(|row| row.len()).collect()
    });
    let map_classes = per_frame(&chunks, "/world/map", |c| {
        c.iter_component::<ClassId>()
            .map(|row| row.iter().filter(|id| u16::from(***id) < 11).count())
            .collect()
    });
    for (k, &n) in &map {
        assert_eq!(n as u32, landmarks[*k as usize], "frame {k}: map points vs landmarks");
        assert!(map_classes[k] * 10 >= n * 9, "frame {k}: {} of {n} with a class", map_classes[k]);
    }

    // Images and segmentations on every frame; the estimated path grows by one point a frame;
    // the ground truth is static, one point per frame run.
    let images = per_frame(&chunks, "/world/camera/image", |c| {
        c.iter_component::<rerun::components::Blob>().map(|row| row.len()).collect()
    });
    assert_eq!(images.len(), 10, "images");
    let seg = per_frame(&chunks, "/world/camera/image/segmentation", |c| {
        c.iter_component::<rerun::components::ImageBuffer>().map(|row| row.len()).collect()
    });
    assert_eq!(seg.len(), 10, "segmentations");
    let strips = per_frame(&chunks, "/world/path/estimated", |c| {
        c.iter_component::<rerun::components::LineStrip3D>()
            .map(|row| row.first().map_or(0, |s| s.0.len()))
            .collect()
    });
    assert_eq!(strips.values().copied().collect::<Vec<_>>(), (1..=10).collect::<Vec<usize>>());
    let gt: Vec<usize> = chunks
        .iter()
        .filter(|c| c.entity_path().to_string() == "/world/path/ground_truth" && c.is_static())
        .flat_map(|c| {
            c.iter_component::<rerun::components::LineStrip3D>()
                .map(|row| row.first().map_or(0, |s| s.0.len()))
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(gt, [10], "ground-truth strip");
}

#[test]
fn a_missing_folder_is_refused_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("nope").join("run.rrd");
    let o = run_parked(&dir.path().join("out"), &["--rerun", s(&rrd)]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--rerun") && text(&o).contains("does not exist"), "{}", text(&o));
    assert!(!dir.path().join("out").exists(), "the run started");
}

/// A run stopped by SIGINT still ends its recording: the file decodes to its end and holds
/// exactly the frames `trajectory.txt` holds.
#[test]
fn an_interrupted_run_leaves_a_whole_recording_of_its_frames() {
    use std::process::{Command, Stdio};
    let data = crate::common::synth("40", "static", "5");
    let dir = tempfile::tempdir().unwrap();
    let (out, rrd) = (dir.path().join("out"), dir.path().join("run.rrd"));
    let mut child = Command::new(env!("CARGO_BIN_EXE_semloc"))
        .args(["run", s(data.path()), "--seq", "00", "--out", s(&out), "--threads", "1"])
        .args(["--rerun", s(&rrd)])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let lines =
        || std::fs::read_to_string(out.join("trajectory.txt")).map_or(0, |t| t.lines().count());
    let start = std::time::Instant::now();
    while lines() < 3 {
        assert!(child.try_wait().unwrap().is_none(), "the run ended before frame 3");
        assert!(start.elapsed().as_secs() < 300, "no frame 3 after 300 s");
        std::thread::sleep(core::time::Duration::from_millis(20));
    }
    let pid = child.id().to_string();
    assert!(Command::new("kill").args(["-2", &pid]).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let frames = lines();
    eprintln!("interrupted after {frames} of 40 frames");
    assert!(frames >= 3, "{frames} frames");
    if frames < 40 {
        assert!(err.contains("stopped by SIGINT"), "{err}");
    }
    assert!(err.contains(&format!("rerun: {frames} frames recorded")), "{err}");
    let chunks = read_chunks(&rrd);
    let recorded = per_frame(&chunks, "/world/camera/image/features/tracking", |c| {
        c.iter_component::<Position2D>().map(|row| row.len()).collect()
    });
    assert_eq!(recorded.len(), frames, "recorded frames vs trajectory.txt");
}

/// The `rerun` command-line tool (`pip install rerun-sdk`): `SEMLOC_RERUN`, else `rerun` beside
/// `SEMLOC_PYTHON` (CI's oracle venv), else `rerun` on the PATH.
fn rerun_cli() -> std::path::PathBuf {
    if let Some(p) = std::env::var_os("SEMLOC_RERUN") {
        return p.into();
    }
    std::env::var_os("SEMLOC_PYTHON")
        .map(std::path::PathBuf::from)
        .and_then(|py| py.parent().map(|d| d.join("rerun")))
        .filter(|p| p.is_file())
        .unwrap_or_else(|| "rerun".into())
}

/// A recording of real KITTI frames (with the committed network's segmentation) is loaded and
/// interpreted without error by rerun's own `rerun rrd verify`, the viewer's loader.
#[test]
#[ignore = "real data in ../shared/data and the rerun CLI; run with --ignored (CI does)"]
fn a_kitti_recording_verifies_with_the_rerun_tool() {
    use std::process::Command;
    let required = std::env::var_os("SEMLOC_REQUIRE_DATA").is_some();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/kitti-odometry");
    if !root.is_dir() {
        assert!(!required, "SEMLOC_REQUIRE_DATA is set but {} does not exist", root.display());
        eprintln!("skipping: {} not found", root.display());
        return;
    }
    let cli = rerun_cli();
    let version = match Command::new(&cli).arg("--version").output() {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
        other => {
            assert!(
                !required,
                "SEMLOC_REQUIRE_DATA is set but {} does not run: {other:?}",
                cli.display()
            );
            eprintln!("skipping: no rerun CLI ({})", cli.display());
            return;
        }
    };
    assert!(version.contains(" 0.23."), "the rerun CLI is {version}; the recording is 0.23");
    let model =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/artefacts/fastscnn_r2_192x640.slm");
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("kitti.rrd");
    let o = semloc(&[
        "run",
        s(&root),
        "--seq",
        "06",
        "--max-frames",
        "8",
        "--semantics",
        "motion",
        "--model",
        s(&model),
        "--out",
        s(&dir.path().join("out")),
        "--rerun",
        s(&rrd),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let v = Command::new(&cli).args(["rrd", "verify"]).arg(&rrd).output().unwrap();
    let said =
        format!("{}{}", String::from_utf8_lossy(&v.stdout), String::from_utf8_lossy(&v.stderr));
    assert!(
        v.status.success() && said.contains("verified without error"),
        "rerun rrd verify: {said}"
    );
    let entities = per_frame(&read_chunks(&rrd), "/world/camera/image/segmentation", |c| {
        c.iter_component::<rerun::components::ImageBuffer>().map(|row| row.len()).collect()
    });
    assert_eq!(entities.len(), 8, "segmentations of the 8 frames");
}
