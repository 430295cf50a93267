//! The `semloc` binary end to end: exit codes, output and error messages naming the file.

use std::path::Path;

use crate::common::{semloc, streams as text};

/// A straight 200 m drive (KITTI pose lines), optionally with a scale error on x/z.
fn write_drive(path: &Path, n: usize, scale: f64) {
    let mut s = String::new();
    for i in 0..n {
        let z = i as f64 * scale;
        let x = (i as f64 * 0.02).sin() * 3.0 * scale;
        s += &format!("1 0 0 {x} 0 1 0 0 0 0 1 {z}\n");
    }
    std::fs::write(path, s).unwrap();
}

#[test]
fn eval_prints_devkit_and_ate_and_writes_json_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.txt");
    let est = dir.path().join("est.txt");
    write_drive(&gt, 201, 1.0);
    write_drive(&est, 201, 1.01);
    let json = dir.path().join("r.json");
    let plots = dir.path().join("plots");
    let o = semloc(&[
        "eval",
        "--gt",
        gt.to_str().unwrap(),
        "--est",
        est.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--plot",
        plots.to_str().unwrap(),
    ]);
    let (out, err) = text(&o);
    assert!(o.status.success(), "{out}\n{err}");
    assert!(out.contains("t_rel"), "{out}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let t = v["t_rel_pct"].as_f64().expect("t_rel_pct in JSON");
    assert!((t - 1.0).abs() < 0.02, "1 % scale error gives t_rel {t}");
    for name in ["trajectory", "ate", "rpe", "position", "orientation", "per_length"] {
        for ext in ["svg", "png"] {
            assert!(plots.join(format!("{name}.{ext}")).is_file(), "{name}.{ext} missing");
        }
    }
}

#[test]
fn eval_sim3_removes_a_scale_error_that_se3_cannot() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.txt");
    let est = dir.path().join("est.txt");
    write_drive(&gt, 201, 1.0);
    write_drive(&est, 201, 1.05);
    let ate = |align: &str| -> f64 {
        let json = dir.path().join(format!("{align}.json"));
        let o = semloc(&[
            "eval",
            "--gt",
            gt.to_str().unwrap(),
            "--est",
            est.to_str().unwrap(),
            "--align",
            align,
            "--json",
            json.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{:?}", text(&o));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        v["ate_rmse_m"].as_f64().expect("ate_rmse_m in JSON")
    };
    let (se3, sim3) = (ate("se3"), ate("sim3"));
    assert!(se3 > 1.0, "se3 ATE {se3}");
    assert!(sim3 < 1e-6, "sim3 ATE {sim3}");
}

#[test]
fn eval_bad_pose_file_names_file_and_line_and_fails() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.txt");
    let est = dir.path().join("bad_est.txt");
    write_drive(&gt, 20, 1.0);
    write_drive(&est, 20, 1.0);
    let mut s = std::fs::read_to_string(&est).unwrap();
    s = s.replacen("1 0 0 0 0 1 0 0 0 0 1 0\n", "1 0 0 0 0 1 0 0 0 0 1 0 7\n", 1);
    std::fs::write(&est, s).unwrap();
    let o = semloc(&["eval", "--gt", gt.to_str().unwrap(), "--est", est.to_str().unwrap()]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("bad_est.txt") && err.contains(":1"), "{err}");
}

#[test]
fn eval_length_mismatch_is_an_error_not_a_truncation() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.txt");
    let est = dir.path().join("est.txt");
    write_drive(&gt, 30, 1.0);
    write_drive(&est, 29, 1.0);
    let o = semloc(&["eval", "--gt", gt.to_str().unwrap(), "--est", est.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let (_, err) = text(&o);
    assert!(err.contains("30") && err.contains("29"), "{err}");
}

#[test]
fn eval_missing_file_is_named() {
    let o = semloc(&["eval", "--gt", "/nonexistent/gt.txt", "--est", "/nonexistent/est.txt"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).1.contains("/nonexistent/gt.txt"));
}

#[test]
fn info_describes_an_odometry_sequence() {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("sequences").join("07");
    for cam in ["image_0", "image_1"] {
        std::fs::create_dir_all(seq.join(cam)).unwrap();
        for i in 0..3 {
            image::GrayImage::new(64, 32).save(seq.join(cam).join(format!("{i:06}.png"))).unwrap();
        }
    }
    let p = "7.0e+02 0 3.0e+02 0 0 7.0e+02 1.5e+02 0 0 0 1 0";
    let p1 = "7.0e+02 0 3.0e+02 -3.5e+02 0 7.0e+02 1.5e+02 0 0 0 1 0";
    std::fs::write(seq.join("calib.txt"), format!("P0: {p}\nP1: {p1}\nP2: {p}\nP3: {p1}\n"))
        .unwrap();
    std::fs::write(seq.join("times.txt"), "0.0\n0.1\n0.2\n").unwrap();
    let o = semloc(&["info", dir.path().to_str().unwrap(), "--seq", "07", "--json"]);
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["frames"], 3, "{out}");
    assert!((v["calib"]["baseline_m"].as_f64().unwrap() - 0.5).abs() < 1e-9, "{out}");
    assert_eq!(v["has_gt"], false, "{out}");
}

#[test]
fn info_on_a_folder_without_a_dataset_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let o = semloc(&["info", dir.path().to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).1.contains(dir.path().to_str().unwrap()));
}

#[test]
fn help_explains_every_flag() {
    let (out, _) = text(&semloc(&["eval", "--help"]));
    for flag in ["--gt", "--est", "--format", "--align", "--max-time-diff", "--json", "--plot"] {
        assert!(out.contains(flag), "eval --help lacks {flag}");
    }
    let (out, _) = text(&semloc(&["info", "--help"]));
    for flag in ["--seq", "--drive", "--pair", "--json"] {
        assert!(out.contains(flag), "info --help lacks {flag}");
    }
}

/// A tiny textured odometry sequence (`frames` grey stereo pairs, 320x160) under `root`.
fn write_textured_sequence(root: &Path, frames: usize) -> std::path::PathBuf {
    let seq = root.join("sequences").join("00");
    let tex = |x: u32, y: u32| -> u8 {
        let (bx, by) = (x / 5, y / 5);
        let v = (bx.wrapping_mul(2654435761) ^ by.wrapping_mul(40503)).wrapping_mul(2246822519);
        ((v >> 13) & 0xff) as u8
    };
    for (cam, shift) in [("image_0", 0u32), ("image_1", 12)] {
        std::fs::create_dir_all(seq.join(cam)).unwrap();
        for i in 0..frames as u32 {
            let img = image::GrayImage::from_fn(320, 160, |x, y| {
                image::Luma([tex(x + shift + 2 * i, y)])
            });
            img.save(seq.join(cam).join(format!("{i:06}.png"))).unwrap();
        }
    }
    let p0 = "3.0e+02 0 1.6e+02 0 0 3.0e+02 8.0e+01 0 0 0 1 0";
    let p1 = "3.0e+02 0 1.6e+02 -1.5e+02 0 3.0e+02 8.0e+01 0 0 0 1 0";
    std::fs::write(seq.join("calib.txt"), format!("P0: {p0}\nP1: {p1}\nP2: {p0}\nP3: {p1}\n"))
        .unwrap();
    let times: String = (0..frames).map(|i| format!("{:.1}\n", i as f64 * 0.1)).collect();
    std::fs::write(seq.join("times.txt"), times).unwrap();
    seq
}

#[test]
fn run_writes_outputs_and_keeps_them_when_a_later_frame_is_corrupt() {
    let dir = tempfile::tempdir().unwrap();
    let seq = write_textured_sequence(dir.path(), 4);
    let out = dir.path().join("out");
    let o = semloc(&["run", seq.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}\n{err}");
    for f in ["trajectory.txt", "trajectory_tum.txt", "frames.csv", "summary.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert_eq!(std::fs::read_to_string(out.join("trajectory.txt")).unwrap().lines().count(), 4);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["frames_processed"], 4);
    assert!(summary["timing"]["compute"]["median_ms"].as_f64().unwrap() > 0.0);

    // Frame 2's left image becomes garbage: the run fails naming it, frames 0-1 are kept.
    let bad = seq.join("image_0").join("000002.png");
    std::fs::write(&bad, b"not a png").unwrap();
    let out2 = dir.path().join("out2");
    let o = semloc(&["run", seq.to_str().unwrap(), "--out", out2.to_str().unwrap()]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("000002.png"), "{err}");
    assert_eq!(std::fs::read_to_string(out2.join("trajectory.txt")).unwrap().lines().count(), 2);
}

#[test]
fn run_rejects_a_bad_thread_count() {
    let o = semloc(&["run", "/nonexistent", "--out", "/tmp/x", "--threads", "3"]);
    assert_eq!(o.status.code(), Some(2), "clap usage error");
}

#[test]
fn ablate_runs_every_combination_into_one_table() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("synth");
    let o = semloc(&[
        "synth",
        "--out",
        data.to_str().unwrap(),
        "--frames",
        "12",
        "--dynamics",
        "high",
        "--seed",
        "3",
    ]);
    assert!(o.status.success(), "{:?}", text(&o));
    let out = dir.path().join("abl");
    let o = semloc(&[
        "ablate",
        data.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--semantics",
        "off,full,motion",
        "--assoc",
        "hard,em",
    ]);
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}\n{err}");
    for row in
        ["off       hard", "off       em", "full      hard", "full      em", "motion    hard"]
    {
        assert!(stdout.contains(row), "row {row:?} missing:\n{stdout}");
    }
    assert!(stdout.contains("Fig. 4"), "{stdout}");
    let table = std::fs::read_to_string(out.join("ablation.txt")).unwrap();
    assert!(table.lines().count() > 6, "{table}");
    assert!(table.contains("RPE 1f (rmse)") && table.contains("[m / deg]"), "{table}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 6);
    for r in rows {
        assert!(r["ate_rmse_m"].as_f64().is_some_and(|a| a.is_finite()), "{r}");
        assert!(r["rpe_1f_trans_rmse_m"].as_f64().is_some_and(|a| a.is_finite()), "{r}");
        assert!(r["rpe_1f_rot_rmse_deg"].as_f64().is_some_and(|a| a.is_finite()), "{r}");
        let dir = out.join(r["folder"].as_str().unwrap());
        assert!(dir.join("trajectory.txt").is_file(), "{}", dir.display());
    }
    // Only EM rows change associations; only semantic rows cull.
    assert_eq!(rows[0]["em_changed_total"], 0);
    assert!(rows[1]["em_changed_total"].as_u64().unwrap() > 0);
    assert_eq!(rows[0]["median_culled_per_frame"].as_f64(), Some(0.0));
    assert!(rows[2]["median_culled_per_frame"].as_f64().unwrap() > 0.0);
    // Motion rows score the features they remove, and those they call moving, against the
    // street's moving-object mask; the others have nothing to score.
    for (k, r) in rows.iter().enumerate() {
        for key in
            ["moving_precision", "moving_recall", "tested_moving_precision", "tested_moving_recall"]
        {
            if k < 4 {
                assert!(r[key].is_null(), "{key}: {r}");
            } else {
                assert!(r[key].as_f64().is_some_and(|x| (0.0..=1.0).contains(&x)), "{key}: {r}");
            }
        }
    }
    // Fig. 4: semantic ORB moves features off dynamic classes onto static structure.
    let share = &v["feature_share"];
    let pct = |k: &str| share[k].as_f64().unwrap();
    assert!(pct("dynamic_pct_semantic") < pct("dynamic_pct_plain"), "{share}");
    assert!(pct("structure_pct_semantic") > pct("structure_pct_plain"), "{share}");
}

/// `--config` reaches every row of `semloc ablate` and `semloc bench-kitti` as it reaches
/// `semloc run`: each row's summary records the file and its values, each row still sets its
/// own semantics and association, and the rows differ from a run on the defaults.
#[test]
fn ablate_and_bench_kitti_take_a_settings_file() {
    let street = crate::common::synth("10", "high", "3");
    let data = street.path().to_str().unwrap().to_owned();
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("rig.toml");
    std::fs::write(&cfg, "[orb]\nn_features = 700\n\n[tracker.motion]\nmax_frame_llr = 1.4\n")
        .unwrap();
    let summary = |p: std::path::PathBuf| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p.join("summary.json")).unwrap()).unwrap()
    };
    let ablate = |out: &std::path::Path, config: Option<&std::path::Path>| {
        let mut a: Vec<&str> = vec!["ablate", &data, "--out", out.to_str().unwrap()];
        a.extend(["--semantics", "off,motion", "--assoc", "hard,em"]);
        if let Some(c) = config {
            a.extend(["--config", c.to_str().unwrap()]);
        }
        let o = semloc(&a);
        assert!(o.status.success(), "{:?}", text(&o));
    };
    let (with, without) = (dir.path().join("with"), dir.path().join("without"));
    ablate(&with, Some(&cfg));
    ablate(&without, None);
    // The feature share (Fig. 4) is extracted with the file's ORB settings, as the rows are.
    let per_frame = |out: &std::path::Path| -> f64 {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap())
                .unwrap();
        let s = &v["feature_share"];
        let plain: u64 =
            s["plain"].as_object().unwrap().values().map(|n| n.as_u64().unwrap()).sum();
        plain as f64 / s["frames"].as_f64().unwrap()
    };
    let (w, wo) = (per_frame(&with), per_frame(&without));
    assert!(w < 770.0 && wo > 1000.0, "{w} features per frame with the file, {wo} without");
    for (row, assoc) in [("off-hard", "hard"), ("motion-em", "em")] {
        let (v, d) = (summary(with.join(row)), summary(without.join(row)));
        let p = &v["provenance"];
        assert!(p["settings_file"].as_str().is_some_and(|f| f.ends_with("rig.toml")), "{p}");
        assert_eq!(p["orb"]["n_features"], 700, "{p}");
        assert_eq!(p["tracker"]["motion"]["max_frame_llr"], 1.4, "{p}");
        assert_eq!(p["tracker"]["association"], assoc, "{p}");
        assert_eq!(d["provenance"]["orb"]["n_features"], 2000);
        assert!(d["provenance"]["settings_file"].is_null());
        let traj =
            |o: &std::path::Path| std::fs::read_to_string(o.join(row).join("trajectory.txt"));
        assert_ne!(
            traj(&with).unwrap(),
            traj(&without).unwrap(),
            "{row}: 700 features track differently"
        );
    }
    // bench-kitti: the synthetic street is a one-sequence odometry root
    let out = dir.path().join("bench");
    let root = street.path();
    let o = semloc(&[
        "bench-kitti",
        root.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{:?}", text(&o));
    let v = summary(out.join("00").join("off-hard"));
    assert_eq!(v["provenance"]["orb"]["n_features"], 700, "{}", v["provenance"]);
    // a settings file that does not parse is a typed error naming it, before anything runs
    std::fs::write(&cfg, "[orb]\nn_features = \"many\"\n").unwrap();
    let bad = dir.path().join("bad");
    let o = semloc(&[
        "ablate",
        &data,
        "--out",
        bad.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1), "{:?}", text(&o));
    assert!(text(&o).1.contains("rig.toml"), "{:?}", text(&o));
    assert!(!bad.exists(), "nothing written");
}

/// `--seeds N` tracks every row with RANSAC seeds 0..N-1: seed 0 in the row's folder, the
/// others beside it, each recording its seed; the table and JSON give the ATE over seeds.
#[test]
fn ablate_seeds_runs_every_row_per_ransac_seed() {
    let street = crate::common::synth("10", "low", "5");
    let data = street.path();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("abl");
    let args = |seeds: &str| {
        [
            "ablate",
            data.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--force",
            "--semantics",
            "off",
            "--assoc",
            "hard",
            "--seeds",
            seeds,
        ]
        .map(str::to_owned)
    };
    let o = semloc(&args("3").each_ref().map(String::as_str));
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}\n{err}");
    assert!(stdout.contains("ATE, 3 seeds [m]") && stdout.contains("median (min-max)"), "{stdout}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    assert_eq!(v["seeds"], 3);
    let row = &v["rows"][0];
    let ates: Vec<f64> =
        row["ate_rmse_m_seeds"].as_array().unwrap().iter().map(|a| a.as_f64().unwrap()).collect();
    assert_eq!(ates.len(), 3, "{row}");
    assert_eq!(ates[0], row["ate_rmse_m"].as_f64().unwrap(), "seed 0 is the row's own run");
    let mut sorted = ates.clone();
    sorted.sort_by(f64::total_cmp);
    assert_eq!(row["ate_median_m"].as_f64(), Some(sorted[1]), "{row}");
    for (seed, folder) in [(0, "off-hard"), (1, "off-hard-seed1"), (2, "off-hard-seed2")] {
        let d = out.join(folder);
        assert!(d.join("trajectory.txt").is_file(), "{}", d.display());
        let s: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(s["provenance"]["tracker"]["ransac_seed"], seed, "{folder}");
        let eval: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(d.join("eval.json")).unwrap()).unwrap();
        let ate = eval["ate_rmse_m"].as_f64().or_else(|| eval["ate"]["rmse"].as_f64()).unwrap();
        assert_eq!(ate, ates[seed], "{folder}");
    }
    // A later run with fewer seeds removes the extra seed folders it wrote before.
    let o = semloc(&args("1").each_ref().map(String::as_str));
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}\n{err}");
    assert!(!stdout.contains("median (min-max)"), "{stdout}");
    assert!(out.join("off-hard").is_dir() && !out.join("off-hard-seed1").exists());
    // Out of range is refused.
    let o = semloc(&args("17").each_ref().map(String::as_str));
    assert_eq!(o.status.code(), Some(2), "{:?}", text(&o));
}

/// `--first-frames A,B` tracks every row from each start: the main table is A's, B's runs go
/// to `first-frames/<row>-fromB/` and equal `semloc run --first-frame B`; the table and JSON
/// give each row's ratios to the first row over the starts.
#[test]
fn ablate_first_frames_runs_every_row_from_each_start() {
    let street = crate::common::synth("10", "low", "5");
    let data = street.path().to_str().unwrap().to_owned();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("abl");
    let o_s = out.to_str().unwrap();
    let base = ["ablate", &data, "--out", o_s, "--force", "--semantics", "off"];
    // `0-3:3` is frames 0 and 3.
    let o = semloc(&[&base[..], &["--first-frames", "0-3:3"]].concat());
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}\n{err}");
    assert!(stdout.contains("over 2 first frames (0, 3): ratio to off/hard"), "{stdout}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    let over = v["over_first_frames"].as_array().expect("over_first_frames");
    assert_eq!(over.len(), 2, "{v}");
    assert_eq!(over[0]["ate_ratio_geomean"].as_f64(), Some(1.0), "the first row is the reference");
    let em = &over[1];
    assert_eq!((em["semantics"].as_str(), em["association"].as_str()), (Some("off"), Some("em")));
    let ates: Vec<f64> =
        em["ate_rmse_m"].as_array().unwrap().iter().map(|a| a.as_f64().unwrap()).collect();
    assert_eq!(ates.len(), 2);
    assert_eq!(Some(ates[0]), v["rows"][1]["ate_rmse_m"].as_f64(), "start 0 is the main row");
    let base_ates: Vec<f64> =
        over[0]["ate_rmse_m"].as_array().unwrap().iter().map(|a| a.as_f64().unwrap()).collect();
    let geo = ((ates[0] / base_ates[0]).ln() + (ates[1] / base_ates[1]).ln()) / 2.0;
    assert!((em["ate_ratio_geomean"].as_f64().unwrap() - geo.exp()).abs() < 1e-12, "{em}");
    // Two starts: the standard error of the mean log ratio is half their difference.
    let (l0, l1) = ((ates[0] / base_ates[0]).ln(), (ates[1] / base_ates[1]).ln());
    let se = em["ate_ratio_log_se"].as_f64().expect("two starts give a standard error");
    assert!((se - (l0 - l1).abs() / 2.0).abs() < 1e-12, "{em}");
    let better = ates.iter().zip(&base_ates).filter(|(a, b)| a < b).count() as u64;
    assert_eq!(em["ate_better_starts"].as_u64(), Some(better), "{em}");
    assert_eq!(over[0]["ate_better_starts"].as_u64(), Some(0), "a row is not better than itself");
    assert!(stdout.contains(&format!("{better}/2")), "{stdout}");
    // `semloc compare` pairs runs the same way: off/em against off/hard of this run gives
    // ablate's own figures; it reads the alignment the run recorded.
    assert_eq!(v["align"].as_str(), Some("se3"), "{v}");
    let cmp = dir.path().join("cmp.json");
    let c_s = cmp.to_str().unwrap();
    let o = semloc(&["compare", o_s, o_s, "--against", "off/hard", "--json", c_s]);
    let (cout, cerr) = text(&o);
    assert!(o.status.success(), "{cout}\n{cerr}");
    assert!(cout.contains("aligned by se3, paired over 2 first frames (0, 3)"), "{cout}");
    let c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cmp).unwrap()).unwrap();
    let row = &c["rows"][1];
    assert_eq!(
        (row["variant_row"].as_str(), row["reference_row"].as_str()),
        (Some("off/em"), Some("off/hard"))
    );
    assert_eq!(row["ate_ratio_geomean"], em["ate_ratio_geomean"], "{c}");
    assert_eq!(row["ate_ratio_log_se"], em["ate_ratio_log_se"], "{c}");
    assert_eq!(row["better"], em["ate_better_starts"], "{c}");
    assert_eq!(row["rpe_1f_trans_ratio_geomean"], em["rpe_1f_trans_ratio_geomean"], "{c}");
    assert_eq!(row["rpe_1f_rot_ratio_geomean"], em["rpe_1f_rot_ratio_geomean"], "{c}");
    // One of the two starts: that start's ratio, no standard error.
    let o = semloc(&["compare", o_s, o_s, "--against", "off/hard", "--starts", "3", "--json", c_s]);
    assert!(o.status.success(), "{:?}", text(&o));
    let c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cmp).unwrap()).unwrap();
    let r3 = c["rows"][1]["ate_ratio_geomean"].as_f64().unwrap();
    assert!((r3 - ates[1] / base_ates[1]).abs() < 1e-12, "{c}");
    assert!(c["rows"][1]["ate_ratio_log_se"].is_null(), "{c}");
    // A folder without an ablation: an error naming the file it looked for.
    let o = semloc(&["compare", o_s, dir.path().to_str().unwrap()]);
    let (_, cerr) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{cerr}");
    assert!(cerr.contains("ablation.json") && cerr.contains("semloc ablate --out"), "{cerr}");
    // Frame 3's run: its own folder, 7 of the 10 frames, the dataset's numbering recorded,
    // the same trajectory as `semloc run --first-frame 3`.
    let from3 = out.join("first-frames/off-em-from3");
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(from3.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(
        (s["dataset"]["first_frame"].as_u64(), s["dataset"]["frames"].as_u64()),
        (Some(3), Some(7))
    );
    let single = dir.path().join("single");
    let o = semloc(&[
        "run",
        &data,
        "--out",
        single.to_str().unwrap(),
        "--assoc",
        "em",
        "--first-frame",
        "3",
    ]);
    assert!(o.status.success(), "{:?}", text(&o));
    assert_eq!(
        std::fs::read_to_string(single.join("trajectory.txt")).unwrap(),
        std::fs::read_to_string(from3.join("trajectory.txt")).unwrap()
    );
    // The first start is the main table's, its dataset summary and its frame count included.
    let o = semloc(&[&base[..], &["--assoc", "hard", "--first-frames", "3,0"]].concat());
    assert!(o.status.success(), "{:?}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    assert_eq!((v["dataset"]["first_frame"].as_u64(), v["frames"].as_u64()), (Some(3), Some(7)));
    // A start beyond the last frame is an error naming the folder, given before --force
    // removes anything; with --seeds, a usage error.
    let o = semloc(&[&base[..], &["--first-frames", "0,10"]].concat());
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("--first-frame 10") && err.contains("sequences"), "{err}");
    assert!(out.join("ablation.json").is_file(), "the earlier outputs are kept");
    for extra in [["--seeds", "2"], ["--first-frame", "1"]] {
        let o = semloc(&[&base[..], &["--first-frames", "0,3"], &extra[..]].concat());
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {:?}", text(&o));
    }
    // A range that names no frame is a usage error saying so.
    let o = semloc(&[&base[..], &["--first-frames", "0,5-2"]].concat());
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("\"5-2\": the range is empty"), "{err}");
}

#[test]
fn ablate_without_labels_names_the_missing_folder() {
    let dir = tempfile::tempdir().unwrap();
    let seq = write_textured_sequence(dir.path(), 3);
    let out = dir.path().join("abl");
    let o = semloc(&["ablate", seq.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("semantic") && err.contains("--model"), "{err}");
    // Geometry-only rows need no labels.
    let o = semloc(&[
        "ablate",
        seq.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--semantics",
        "off",
    ]);
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}\n{err}");
    assert!(stdout.contains("off       em"), "{stdout}");
}

/// The network named in the settings file labels every row and the feature share (Fig. 4)
/// alike, on a sequence without labels: the share once asked for a semantic/ folder after the
/// rows had run, and failed.
#[test]
fn ablate_takes_the_network_from_the_settings_file() {
    let street = crate::common::synth("4", "high", "3");
    let seq = street.path().join("sequences").join("00");
    std::fs::remove_dir_all(seq.join("semantic")).unwrap();
    let model = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models/artefacts/fastscnn_r2_192x640.slm")
        .canonicalize()
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("rig.toml");
    std::fs::write(&cfg, format!("[semantics]\nmodel = {:?}\n", model.to_str().unwrap())).unwrap();
    let out = dir.path().join("abl");
    let o = semloc(&[
        "ablate",
        street.path().to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--semantics",
        "full",
        "--assoc",
        "hard",
        "--config",
        cfg.to_str().unwrap(),
    ]);
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}\n{err}");
    assert!(stdout.contains("int8 network") && stdout.contains("Fig. 4"), "{stdout}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    assert_eq!(v["model"].as_str(), model.to_str(), "{}", v["model"]);
    assert_eq!(v["feature_share"]["frames"], 4, "{}", v["feature_share"]);
}
