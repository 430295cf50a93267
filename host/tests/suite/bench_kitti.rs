//! `semloc bench-kitti ROOT`: every sequence of an odometry root in one table, beside a
//! reference system's trajectories.

use crate::common::{s, semloc, text};

#[test]
fn every_sequence_in_one_table_with_a_reference() {
    let root = tempfile::tempdir().unwrap();
    for (seq, seed) in [("00", "3"), ("01", "4")] {
        let o = semloc(&[
            "synth",
            "--out",
            s(root.path()),
            "--frames",
            "8",
            "--dynamics",
            "static",
            "--seed",
            seed,
            "--seq",
            seq,
        ]);
        assert!(o.status.success(), "synth: {}", text(&o));
    }
    // The reference for 00 is the ground truth itself (ATE 0); 01 has none.
    let reference = tempfile::tempdir().unwrap();
    std::fs::copy(root.path().join("poses/00.txt"), reference.path().join("00.txt")).unwrap();
    let out = tempfile::tempdir().unwrap();
    let out = out.path().join("bench");
    let o = semloc(&[
        "bench-kitti",
        s(root.path()),
        "--out",
        s(&out),
        "--reference",
        s(reference.path()),
        "--reference-name",
        "ORB-SLAM2",
        "--seeds",
        "2",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let table = std::fs::read_to_string(out.join("bench.txt")).unwrap();
    assert!(text(&o).contains(&table), "the table is printed");
    assert!(table.contains("off-hard") && table.contains("ORB-SLAM2"), "{table}");
    let lines: Vec<&str> = table.lines().collect();
    assert!(
        lines.iter().any(|l| l.starts_with("00 ")) && lines.iter().any(|l| l.starts_with("01 "))
    );
    assert!(table.contains("01 ORB-SLAM2:"), "the missing reference is explained: {table}");
    assert!(table.contains("ATE [m] over RANSAC seeds 0-1"), "{table}");

    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("bench.json")).unwrap()).unwrap();
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 2);
    for (row, seq) in rows.iter().zip(["00", "01"]) {
        assert_eq!(row["seq"], seq);
        assert_eq!(row["frames"], 8);
        let cells = row["cells"].as_array().unwrap();
        assert_eq!(cells.len(), 2, "one configuration and the reference");
        // semloc's cell is its run's eval.json.
        let eval: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join(seq).join("off-hard/eval.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(cells[0]["ate_rmse_m"], eval["ate_rmse_m"]);
        // --seeds 2: seed 0's ATE, then seed 1's run beside it.
        let seeded: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(out.join(seq).join("off-hard-seed1/eval.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(cells[0]["ate_seeds_m"][0], eval["ate_rmse_m"]);
        assert_eq!(cells[0]["ate_seeds_m"][1], seeded["ate_rmse_m"]);
        assert_eq!(cells[1]["ate_seeds_m"].as_array().map(Vec::len), Some(0), "reference");
        assert!(cells[0]["ate_rmse_m"].as_f64().unwrap() < 0.05, "{row}");
        // 8 frames are far from 100 m: the devkit figures are n/a, not 0.
        assert!(cells[0]["t_rel_pct"].is_null());
    }
    assert!(rows[0]["cells"][1]["ate_rmse_m"].as_f64().unwrap() < 1e-9);
    assert!(rows[1]["cells"][1]["ate_rmse_m"].is_null());
    assert!(rows[1]["cells"][1]["note"].as_str().unwrap().contains("01.txt"));
}

#[test]
fn a_folder_without_sequences_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let o = semloc(&["bench-kitti", s(d.path()), "--out", s(&d.path().join("o"))]);
    assert!(!o.status.success());
    assert!(text(&o).contains("no sequences/ folder"), "{}", text(&o));
}
