//! The geometric backbone end to end on real KITTI odometry: the 51-frame clips of sequences
//! 01 (highway on-ramp, little near texture, far structure) and 06 (suburban loop) in
//! `../shared/data/kitti-odometry`, judged as issue 14 asks: Sim(3) ATE (the clips' ground truth
//! and any estimate differ by a few per cent of scale) and per-frame RPE as evo_rpe computes
//! it, against ORB-SLAM2 stereo on the same frames (`../shared/data/README.md`).
//!
//! Bounds are ORB-SLAM2's figures: 01 Sim(3) ATE ≤ 0.094 m (its worst of 6 runs; measured
//! 0.051 m on 2026-11-24) and RPE rotation ≤ 0.055° (it: 0.048°; measured 0.045°); 06 Sim(3)
//! ATE ≤ 0.030 m (it: 0.022–0.027 m; measured 0.025 m) and RPE rotation ≤ 0.075° (it: 0.065°;
//! measured 0.067°). No frame may be lost, and one worker thread and two agree byte for byte.

use semloc_core::assoc::Association;
use std::path::Path;

use semloc::dataset::Sequence;
use semloc::eval::Align;
use semloc::run::{RunConfig, RunResult, Semantics};

fn run(cfg: RunConfig<'_>) -> RunResult {
    let r = semloc::run::run(cfg).unwrap();
    assert!(r.failure.is_none(), "{:?}", r.failure);
    r
}

fn check_clip(seq_id: &str, max_ate_m: f64, max_rpe_rot_deg: f64) {
    let Some(data) = semloc_tests::shared_data() else { return };
    let seq = Sequence::open_odometry(&data.join("kitti-odometry"), seq_id, None).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (out2, out1) = (dir.path().join("two"), dir.path().join("one"));
    let r = run(RunConfig { threads: 2, align: Align::Sim3, ..RunConfig::new(&seq, &out2) });
    assert_eq!(r.frames.len(), seq.len());
    let report = r.eval.unwrap();
    let rpe = report.rpe_1f.unwrap();
    eprintln!(
        "KITTI {seq_id} clip: Sim(3) ATE {:.3} m, RPE 1 frame {:.4} m / {:.4} deg, lost {}, \
         keyframes {}",
        report.ate_rmse_m, rpe.trans_m.rmse, rpe.rot_deg.rmse, r.summary.lost, r.summary.keyframes
    );
    assert_eq!(r.summary.lost, 0, "tracking was lost");
    assert!(report.ate_rmse_m <= max_ate_m, "ATE {:.3} m > {max_ate_m} m", report.ate_rmse_m);
    assert!(
        rpe.rot_deg.rmse <= max_rpe_rot_deg,
        "RPE rotation {:.4} deg > {max_rpe_rot_deg} deg",
        rpe.rot_deg.rmse
    );
    run(RunConfig { threads: 1, align: Align::Sim3, ..RunConfig::new(&seq, &out1) });
    let read = |d: &Path| std::fs::read(d.join("trajectory.txt")).unwrap();
    assert_eq!(read(&out2), read(&out1), "1 vs 2 threads differ");
}

#[test]
#[ignore = "real data in ../shared/data; run with --ignored (CI does)"]
fn kitti_01_clip_at_orb_slam2_accuracy() {
    check_clip("01", 0.094, 0.055);
}

#[test]
#[ignore = "real data in ../shared/data; run with --ignored (CI does)"]
fn kitti_06_clip_at_orb_slam2_accuracy() {
    check_clip("06", 0.030, 0.075);
}

/// One run of a clip, Sim(3)-aligned: its ATE (m); the run must not lose a frame.
fn clip_ate(
    seq_id: &str,
    semantics: Semantics,
    association: Association,
    ransac_seed: u64,
) -> Option<f64> {
    let data = semloc_tests::shared_data()?;
    let seq = Sequence::open_odometry(&data.join("kitti-odometry"), seq_id, None).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let model =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/artefacts/fastscnn_r2_192x640.slm");
    let r = run(RunConfig {
        align: Align::Sim3,
        semantics,
        network: (semantics != Semantics::Off).then_some(semloc::run::Network::File(model)),
        tracker: semloc_core::tracker::TrackerParams {
            association,
            ransac_seed,
            ..Default::default()
        },
        ..RunConfig::new(&seq, dir.path().join("r"))
    });
    assert_eq!(r.summary.lost, 0, "{seq_id}: frames lost");
    Some(r.eval.unwrap().ate_rmse_m)
}

/// Issue 15: semantics must not make real traffic worse. Table-1 culling with this network
/// broke the 01 clip (0.76 m against 0.032 m). Motion-aware semantics are compared with the
/// geometric rows of the same association, and the paper's full method with EM with the
/// backbone (off, hard), from frame 0 (2026-12-02, Sim(3), EM without the class term on the
/// network's labels): 01 motion hard 0.0316 against 0.0316 m, motion EM 0.0356 against
/// 0.0345 m, full EM 0.0338 against 0.0316 m; 06 0.0234 / 0.0234, 0.0217 / 0.0209,
/// 0.0218 / 0.0234 m. One start of a 51-frame clip is one sample of a spread of tens of per
/// cent (over 13 starts, `semloc ablate --first-frames`, full EM is 0.911 of the backbone on 01
/// and 0.891 on 06, motion EM 0.914 and 0.720: README, "Where tracking starts"), so the bound
/// here is 10 %, what a single start can hold.
#[test]
#[ignore = "real data in ../shared/data; run with --ignored (CI does)"]
fn semantic_rows_keep_real_clips_at_backbone_accuracy() {
    for seq_id in ["01", "06"] {
        let Some(backbone) = clip_ate(seq_id, Semantics::Off, Association::Hard, 0) else { return };
        for association in [Association::Hard, Association::Em] {
            let b = match association {
                Association::Hard => backbone,
                Association::Em => clip_ate(seq_id, Semantics::Off, association, 0).unwrap(),
            };
            let m = clip_ate(seq_id, Semantics::Motion, association, 0).unwrap();
            eprintln!("KITTI {seq_id} clip, {association:?}: Sim(3) ATE off {b:.4} m, motion-aware {m:.4} m");
            assert!(
                m <= 1.10 * b,
                "{seq_id} {association:?}: motion-aware {m:.4} m vs off {b:.4} m"
            );
        }
        let full = clip_ate(seq_id, Semantics::Full, Association::Em, 0).unwrap();
        eprintln!("KITTI {seq_id} clip: full EM {full:.4} m, backbone {backbone:.4} m");
        assert!(
            full <= 1.10 * backbone,
            "{seq_id}: full EM {full:.4} m vs backbone {backbone:.4} m"
        );
    }
}

/// The first frame after initialisation has no motion estimate. Projected at the last pose,
/// only far points matched on the 01 clip (the car moves ~1 m per frame), and the pose hung
/// on RANSAC's draws: with seeds 1, 4 and 5 the backbone's Sim(3) ATE was 0.55, 0.56 and
/// 0.14 m (seed 0: 0.032 m). Matched by appearance, every seed gives 0.032-0.033 m.
#[test]
#[ignore = "real data in ../shared/data; run with --ignored (CI does)"]
fn kitti_01_does_not_depend_on_ransac_draws() {
    for seed in [1, 4, 5] {
        let Some(ate) = clip_ate("01", Semantics::Off, Association::Hard, seed) else { return };
        eprintln!("KITTI 01 clip, RANSAC seed {seed}: Sim(3) ATE {ate:.4} m");
        assert!(ate < 0.04, "RANSAC seed {seed}: Sim(3) ATE {ate:.4} m");
    }
}
