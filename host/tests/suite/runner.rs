//! The library runner (`semloc::run`) on a short generated drive: every output file exists,
//! parses, and says what the returned result says; a run that cannot label its frames is
//! refused before any tracking.

use std::path::Path;

use semloc::dataset::Sequence;
use semloc::run::{frames_csv_header, Network, RunConfig, RunError, Semantics};
use semloc::synth::{generate, Dynamics, SynthConfig};
use semloc_core::assoc::Association;
use semloc_core::tracker::TrackerParams;

/// A generated high-traffic drive of `frames` frames (with labels and ground truth) in `dir`.
fn drive(dir: &Path, frames: usize) -> Sequence {
    let cfg = SynthConfig { frames, dynamics: Dynamics::High, seed: 3, ..SynthConfig::default() };
    generate(dir, &cfg).unwrap();
    Sequence::open_odometry(dir, &cfg.seq, None).unwrap()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

#[test]
fn outputs_exist_parse_and_agree_with_the_result() {
    let dir = tempfile::tempdir().unwrap();
    let seq = drive(&dir.path().join("seq"), 12);
    let out = dir.path().join("out");
    let cfg = RunConfig {
        max_frames: Some(10),
        semantics: Semantics::Full,
        tracker: TrackerParams { association: Association::Em, ..TrackerParams::default() },
        ..RunConfig::new(&seq, &out)
    };
    assert_eq!(cfg.frame_count(), 10);
    let mut seen = Vec::new();
    let r =
        semloc::run::run_observed(cfg, &mut |f| seen.push(f.output.report.frame_index)).unwrap();
    assert!(r.failure.is_none(), "{:?}", r.failure);
    assert_eq!(seen, (0..10).collect::<Vec<_>>());
    assert_eq!(r.frames.len(), 10);

    // trajectories: KITTI poses bit for bit; TUM timestamps and positions as written
    let poses = r.poses();
    assert_eq!(semloc::traj::read_kitti(out.join("trajectory.txt")).unwrap(), poses);
    let tum = semloc::traj::read_tum(out.join("trajectory_tum.txt")).unwrap();
    assert_eq!(tum.len(), 10);
    for ((t, p), (f, q)) in tum.iter().zip(r.frames.iter().zip(&poses)) {
        assert_eq!(*t, f.timestamp_s);
        assert_eq!(p.trans, q.trans);
    }

    // frames.csv: the header, then one row per record
    let csv = read(&out.join("frames.csv"));
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(frames_csv_header()));
    let columns: Vec<&str> = frames_csv_header().split(',').collect();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), r.frames.len());
    for (row, f) in rows.iter().zip(&r.frames) {
        assert_eq!(row.len(), columns.len(), "{row:?}");
        let col = |name: &str| row[columns.iter().position(|c| *c == name).unwrap()];
        let (o, rep) = (&f.output, &f.output.report);
        assert_eq!(col("frame"), rep.frame_index.to_string());
        assert_eq!(col("timestamp_s"), format!("{:.6}", f.timestamp_s));
        assert_eq!(col("compute_ms"), format!("{:.3}", o.times.compute_ms));
        assert_eq!(col("stereo_matches"), o.stereo.matched.to_string());
        assert_eq!(col("inliers"), rep.inliers.to_string());
        assert_eq!(col("keyframe"), u8::from(rep.keyframe).to_string());
        assert_eq!(col("lost"), u8::from(rep.lost).to_string());
        assert_eq!(col("culled"), o.culled.to_string());
        assert_eq!(col("em_changed"), rep.em_changed.to_string());
    }
    // semantic rows cull and EM rows change associations: the settings reached the pipeline
    assert!(r.frames.iter().any(|f| f.output.culled > 0));
    assert!(r.summary.em_changed_total > 0);

    // summary.json and eval.json are exactly the returned values
    assert_eq!(read(&out.join("summary.json")), serde_json::to_string_pretty(&r.summary).unwrap());
    let summary: serde_json::Value =
        serde_json::from_str(&read(&out.join("summary.json"))).unwrap();
    assert_eq!(summary["frames_processed"], 10);
    assert_eq!(summary["semantics"], "full");
    assert_eq!(summary["association"], "em");
    assert!(summary["timing"]["compute"]["median_ms"].as_f64().unwrap() > 0.0);
    assert!(summary["timing"].get("segment").is_none(), "no network, no segment timing");
    let eval = r.eval.as_ref().expect("the drive has ground truth");
    assert_eq!(read(&out.join("eval.json")), serde_json::to_string_pretty(eval).unwrap());
    assert_eq!(eval.n_poses, 10);
    // serde_json's default float parser may miss the last bit of a written f64.
    let ate = summary["eval"]["ate_rmse_m"].as_f64().unwrap();
    assert!(
        (ate - eval.ate_rmse_m).abs() <= 1e-12 * eval.ate_rmse_m,
        "{ate} vs {}",
        eval.ate_rmse_m
    );
    for plot in ["trajectory.png", "trajectory.svg", "ate.png", "rpe.svg", "orientation.png"] {
        assert!(out.join("plots").join(plot).is_file(), "{plot} missing");
    }
}

#[test]
fn semantics_without_labels_or_network_is_refused_before_tracking() {
    let dir = tempfile::tempdir().unwrap();
    let seq = drive(&dir.path().join("seq"), 3);
    std::fs::remove_dir_all(seq.root.join("semantic")).unwrap();
    let out = dir.path().join("out");
    let cfg = RunConfig { semantics: Semantics::Cull, ..RunConfig::new(&seq, &out) };
    match semloc::run::run(cfg) {
        Err(e @ RunError::NoLabels { .. }) => {
            let msg = e.to_string();
            assert!(msg.contains("--model") && msg.contains("semantic"), "{msg}");
        }
        other => panic!("expected NoLabels, got {:?}", other.map(|r| r.summary)),
    }
    assert!(!out.join("trajectory.txt").exists());
}

/// A network loaded by the caller labels the frames: its time is reported per frame and in
/// `summary.json`, and its memory counted.
#[test]
fn a_loaded_network_labels_the_frames() {
    let slm =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/artefacts/fastscnn_r2_192x640.slm");
    let dir = tempfile::tempdir().unwrap();
    let seq = drive(&dir.path().join("seq"), 3);
    let (w, h) = seq.image_size;
    let net = semloc::run::load_network(&slm, w, h).unwrap();
    let out = dir.path().join("out");
    let cfg = RunConfig {
        semantics: Semantics::Full,
        network: Some(Network::Loaded(Box::new(net))),
        ..RunConfig::new(&seq, &out)
    };
    let r = semloc::run::run(cfg).unwrap();
    assert!(r.failure.is_none(), "{:?}", r.failure);
    assert!(r.frames.iter().all(|f| f.output.times.seg_ms > 0.0));
    assert!(r.summary.timing.contains_key("segment"));
    assert!(r.summary.network_memory_bytes > 0);
}
