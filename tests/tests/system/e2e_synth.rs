//! End to end on generated sequences: `semloc::synth` writes a KITTI-layout drive with ground
//! truth, the full pipeline tracks it, the evaluator scores it. No outside data needed.
//!
//! Bounds (80-frame drives; seed 1 unless said; the bounds leave room for the 2-3x spread
//! between seeds). Remeasured 2026-11-26, after the first frame after initialisation is
//! matched by appearance (it used to be projected at the last pose, which let the truck ahead
//! drag the backbone from the start): a single street is one sample, so the comparisons
//! between semantic settings are made over two streets (seeds 1 and 2).
//! - static traffic: ATE ≤ 0.5 % of the path length (the backbone target);
//! - high traffic without semantics: a truck leads the camera and drags the estimate along on
//!   at least one of the two streets (ATE > 5 % of the path: seed 2 21.8 m; seed 1 0.29 m,
//!   where it was 24.1 m before the start-up fix; seeds 3 and 4 12.3 and 22.6 m);
//! - high traffic culling dynamic classes (ground-truth labels): ATE over both streets at most
//!   a third of the no-semantics ATE (0.091 + 0.153 m against 0.29 + 21.8 m);
//! - the paper's full method (semantic ORB + EM association) against the backbone (no
//!   semantics, hard association), issue 6's targets: high traffic ≤ 0.5 × the backbone's ATE.
//!   Without traffic EM alone costs nothing (0.0729 m against 0.0770 m), but the full method
//!   does not always: full + EM over the backbone is 1.21, 0.91, 1.39 and 2.03 on seeds 1-4
//!   (the same on seeds 2-4 before the start-up fix; seed 1 was 1.08), so it is held only to
//!   the static backbone target;
//! - motion-aware semantics + EM (issue 15) in streets lined with parked cars (`parked`) beat
//!   Table-1 culling with the same association over seeds 1 and 2 (0.077 + 0.096 m against
//!   0.074 + 0.146 m; seeds 3 and 4: 0.060 / 0.045 against 0.070 / 0.068 m), because the parked
//!   cars stay usable; in high traffic they stay ≤ 0.5 × the backbone and the features they
//!   remove cover the moving objects (precision and recall against the generator's `dynamic/`
//!   mask).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use semloc::dataset::Sequence;
use semloc::run::{RunConfig, Semantics};
use semloc::synth::{generate, Dynamics, SynthConfig};
use semloc_core::assoc::Association;
use semloc_core::tracker::TrackerParams;

const FRAMES: usize = 80;

/// A drive several tests use, generated once per test process, with its backbone result
/// (no semantics, hard association) computed once: seed 1's `static` and `high` streets are
/// each tracked by two or three tests: generating one (~6 s) and its backbone run (~7 s) once
/// instead of two or three times took this file's tests from 152 to 121 s (2 threads). The
/// runs are deterministic, so sharing changes no figure (the printed ATEs are the same).
struct SharedDrive {
    seq: Sequence,
    backbone: OnceLock<(f64, f64, u32)>,
}

impl SharedDrive {
    /// The backbone's (ATE in m, path length in m, frames lost), run on first use.
    fn backbone(&self) -> (f64, f64, u32) {
        *self.backbone.get_or_init(|| track(&self.seq, Semantics::Off))
    }
}

/// The 80-frame drive of seed 1 with `dynamics`, shared between the tests of this process.
/// Its files are under `CARGO_TARGET_TMPDIR/e2e_synth/<pid>/` (a static is never dropped, so
/// a process cannot remove its own); each process removes those of processes that have
/// exited, where `/proc` says which are alive.
fn shared(dynamics: Dynamics) -> &'static SharedDrive {
    static DRIVES: OnceLock<Mutex<HashMap<String, &'static OnceLock<SharedDrive>>>> =
        OnceLock::new();
    let key = format!("{dynamics:?}").to_lowercase();
    let cell = *DRIVES
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .entry(key.clone())
        .or_insert_with(|| Box::leak(Box::new(OnceLock::new())));
    // Outside the map's lock: other drives generate meanwhile; a second user of this one waits.
    // `shared_root` is this process's own fresh folder, so the drive's folder cannot exist yet.
    cell.get_or_init(|| SharedDrive {
        seq: generated_street(&shared_root().join(key), dynamics, 1),
        backbone: OnceLock::new(),
    })
}

fn shared_root() -> &'static Path {
    static ROOT: OnceLock<PathBuf> = OnceLock::new();
    ROOT.get_or_init(|| {
        let base = Path::new(env!("CARGO_TARGET_TMPDIR")).join("e2e_synth");
        std::fs::create_dir_all(&base).unwrap();
        let me = std::process::id();
        if Path::new("/proc/self").is_dir() {
            for e in std::fs::read_dir(&base).unwrap().flatten() {
                let pid = e.file_name().to_str().and_then(|n| n.parse::<u32>().ok());
                if pid.is_some_and(|p| p != me && !Path::new(&format!("/proc/{p}")).exists()) {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
        }
        let dir = base.join(me.to_string());
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    })
}

/// The drive of generator seed `seed` (another street with other traffic).
fn generated_street(dir: &Path, dynamics: Dynamics, seed: u64) -> Sequence {
    generated_frames(dir, dynamics, seed, FRAMES)
}

/// The first `frames` frames of the drive of generator seed `seed`.
fn generated_frames(dir: &Path, dynamics: Dynamics, seed: u64, frames: usize) -> Sequence {
    let cfg = SynthConfig { frames, dynamics, seed, ..SynthConfig::default() };
    generate(dir, &cfg).expect("generate");
    Sequence::open_odometry(dir, &cfg.seq, None).expect("open generated sequence")
}

/// (ATE in m, path length in m, frames lost) with hard association.
fn track(seq: &Sequence, semantics: Semantics) -> (f64, f64, u32) {
    track_with(seq, semantics, Association::Hard)
}

/// (ATE in m, path length in m, frames lost): the library runner on every frame, two threads,
/// SE(3)-aligned ATE against the generator's ground truth.
fn track_with(seq: &Sequence, semantics: Semantics, association: Association) -> (f64, f64, u32) {
    let (ate, len, lost, _) = track_full(seq, semantics, association);
    (ate, len, lost)
}

/// As [`track_with`], plus the summary's motion-aware totals.
fn track_full(
    seq: &Sequence,
    semantics: Semantics,
    association: Association,
) -> (f64, f64, u32, Option<semloc::run::MotionSummary>) {
    let out = tempfile::tempdir().unwrap();
    let cfg = RunConfig {
        semantics,
        tracker: TrackerParams { association, ..TrackerParams::default() },
        ..RunConfig::new(seq, out.path())
    };
    let r = semloc::run::run(cfg).unwrap();
    assert!(r.failure.is_none(), "{:?}", r.failure);
    assert_eq!(r.frames.len(), seq.len());
    let e = r.eval.expect("the generated sequence has ground truth");
    (e.ate_rmse_m, e.path_length_m, r.summary.lost, r.summary.motion)
}

#[test]
fn static_traffic_tracks_within_half_a_percent() {
    let (ate, len, lost) = shared(Dynamics::Static).backbone();
    eprintln!("static: ATE {ate:.3} m over {len:.1} m ({:.3} %), lost {lost}", 100.0 * ate / len);
    assert!(ate <= 0.005 * len, "ATE {ate:.3} m > 0.5 % of {len:.1} m");
    assert_eq!(lost, 0);
}

#[test]
fn high_traffic_breaks_the_backbone_and_culling_repairs_it() {
    let (mut off_sum, mut cull_sum, mut off_max_share) = (0.0f64, 0.0f64, 0.0f64);
    for seed in [1, 2] {
        // seed 1 is the shared drive; seed 2's folder lives to the end of the iteration
        let mut dir = None;
        let (seq, (off, len, _)) = if seed == 1 {
            let d = shared(Dynamics::High);
            (d.seq.clone(), d.backbone())
        } else {
            let dir = dir.insert(tempfile::tempdir().unwrap());
            let seq = generated_street(dir.path(), Dynamics::High, seed);
            let off = track(&seq, Semantics::Off);
            (seq, off)
        };
        let (cull, _, lost) = track(&seq, Semantics::Cull);
        eprintln!("high, seed {seed}: ATE off {off:.3} m, cull {cull:.3} m over {len:.1} m (cull lost {lost})");
        off_sum += off;
        cull_sum += cull;
        off_max_share = off_max_share.max(off / len);
    }
    assert!(
        off_max_share > 0.05,
        "no-semantics ATE at most {:.2} % of the path on both streets: the scenes are not dynamic enough",
        100.0 * off_max_share
    );
    assert!(
        cull_sum <= off_sum / 3.0,
        "culling ATE {cull_sum:.3} m vs {off_sum:.3} m without (sums)"
    );
}

#[test]
fn full_method_halves_the_backbone_error_in_high_traffic() {
    let d = shared(Dynamics::High);
    let (backbone, len, _) = d.backbone();
    let (full, _, lost) = track_with(&d.seq, Semantics::Full, Association::Em);
    eprintln!("high: ATE backbone {backbone:.3} m, full + EM {full:.3} m over {len:.1} m");
    assert!(full <= 0.5 * backbone, "full + EM {full:.3} m vs backbone {backbone:.3} m");
    assert_eq!(lost, 0);
}

#[test]
fn em_costs_nothing_without_traffic_and_the_full_method_meets_the_backbone_target() {
    let d = shared(Dynamics::Static);
    let (backbone, len, _) = d.backbone();
    let (full, _, lost) = track_with(&d.seq, Semantics::Full, Association::Em);
    let (em, _, _) = track_with(&d.seq, Semantics::Off, Association::Em);
    eprintln!(
        "static: ATE backbone {backbone:.4} m, EM alone {em:.4} m, full + EM {full:.4} m over \
         {len:.1} m"
    );
    // 0.0729 against 0.0770 m measured.
    assert!(em <= 1.05 * backbone, "EM alone {em:.4} m vs backbone {backbone:.4} m");
    // The paper's semantic weights do cost accuracy on some static streets (full + EM over the
    // backbone: 1.21, 0.91, 1.39, 2.03 on seeds 1-4; see the module docs), so the full method
    // is held to the backbone's own static target; 0.0935 m over 82.8 m (0.11 %) measured.
    assert!(full <= 0.005 * len, "full + EM {full:.4} m > 0.5 % of {len:.1} m");
    assert_eq!(lost, 0);
}

#[test]
fn motion_aware_semantics_keep_parked_cars_and_beat_table_one_culling() {
    let (mut cull_sum, mut motion_sum) = (0.0f64, 0.0f64);
    for seed in [1, 2] {
        let dir = tempfile::tempdir().unwrap();
        let seq = generated_street(dir.path(), Dynamics::Parked, seed);
        let (cull, len, _) = track_with(&seq, Semantics::Cull, Association::Em);
        let (motion, _, lost, m) = track_full(&seq, Semantics::Motion, Association::Em);
        let m = m.expect("motion totals");
        eprintln!(
            "parked, seed {seed}: ATE cull + EM {cull:.3} m, motion + EM {motion:.3} m over \
             {len:.1} m; {m:?}"
        );
        assert!(m.parked_features > 1000, "seed {seed}: parked cars were not used: {m:?}");
        assert_eq!(lost, 0);
        cull_sum += cull;
        motion_sum += motion;
    }
    assert!(
        motion_sum < cull_sum,
        "motion-aware {motion_sum:.3} m vs Table-1 culling {cull_sum:.3} m (sums over two streets)"
    );
}

#[test]
fn motion_aware_semantics_find_the_moving_traffic() {
    let d = shared(Dynamics::High);
    let (backbone, len, _) = d.backbone();
    let (motion, _, lost, m) = track_full(&d.seq, Semantics::Motion, Association::Em);
    let m = m.expect("motion totals");
    let (p, r) = (m.moving_precision.unwrap(), m.moving_recall.unwrap());
    eprintln!(
        "high: ATE backbone {backbone:.3} m, motion + EM {motion:.3} m over {len:.1} m; \
         moving features: precision {p:.3}, recall {r:.3}"
    );
    assert!(motion <= 0.5 * backbone, "motion + EM {motion:.3} m vs backbone {backbone:.3} m");
    // 0.863 / 0.986 measured (2026-11-29); 0.849 / 0.985 before the epipolar and later
    // tests; 0.833 / 0.980 before objects without landmarks were tested frame to frame
    // (motion.rs, `match_previous`), 0.815 / 0.977 before depthless features stopped chaining
    // the passing cars into the parked ones (`segment`).
    assert!(p >= 0.84 && r >= 0.98, "moving-feature precision {p:.3}, recall {r:.3}");
    // Features on moving objects that were tested moving, not merely left unproven: 0.858
    // measured (0.800 before the epipolar and later tests); 0.45 (seed 1, 100 frames) before
    // the frame-to-frame test, when a moving object's features had no landmarks to be
    // measured against.
    let c = m.moving_check.expect("moving check");
    let tested = m.tested_moving_recall.unwrap();
    assert_eq!(tested, f64::from(c.tested_moving_true) / f64::from(c.true_pos + c.false_neg));
    let tested_p = m.tested_moving_precision.unwrap();
    eprintln!("high: features on moving objects tested moving {tested:.3}, of those called moving on moving objects {tested_p:.3}");
    assert!(tested >= 0.7, "only {tested:.3} of the moving features were tested moving");
    // Features called moving (tested, unproven ones left out) are on moving objects: 0.925-0.983
    // on `high` seeds 1-4 (100 frames, hard and EM alike), where the removed features'
    // precision is 0.83-0.92.
    assert!(tested_p >= 0.9, "of the features tested moving only {tested_p:.3} move");
    // Withheld from the pose or the map: the removed features less the deferred ones
    // (unproven, free to make a landmark), which are treated as a parked car's are.
    let (wp, wr) = (m.withheld_precision.unwrap(), m.withheld_recall.unwrap());
    assert_eq!(wr, f64::from(c.true_pos - c.deferred_true) / f64::from(c.true_pos + c.false_neg));
    eprintln!("high: withheld from pose or map: precision {wp:.3}, recall {wr:.3}; deferred {} ({} on moving objects: {} of objects measured, evidence pending, {} unmeasured, {} depthless)", c.deferred, c.deferred_true, c.deferred_true_pending, c.deferred_true_unseen, c.deferred_true_depthless);
    assert_eq!(c.deferred_true_pending + c.deferred_true_unseen, c.deferred_true);
    assert!(c.deferred_true_depthless <= c.deferred_true);
    // 0.926 / 0.953 measured (4077 deferred, 1202 of them on moving objects): what is withheld
    // is on moving objects more often than what is removed, and one moving feature in 30
    // is deferred, like a parked car's: 404 of those 1202 on objects measured whose evidence
    // is not yet enough to call them moving, 798 on objects nothing of which was measured
    // (first sight, or nothing re-found). 0.931 / 0.786 (7048 deferred on moving objects)
    // before the epipolar test and its chains, bounded by the road and the class's height;
    // 0.931 / 0.849 before untested people stopped making landmarks; 0.934 / 0.883 (3680)
    // before untested objects without any stereo depth did; 0.927 / 0.927 (2092) before a
    // pass of the depthless test stopped counting where a match with no image motion would
    // have passed too (`uninformative` in motion.rs); 4598 / 1669 / 867 deferred before
    // that rule applied to features with an unmeasured landmark candidate too, 0.927 / 0.939
    // (4582 / 1667 / 865) before it applied to the chain test's passes, 0.927 / 0.940
    // (4554 / 1644 / 848) before it applied to landmark matches, and 0.926 / 0.940 (4561 /
    // 1662 / 863) before a pass a walker at 1 m/s would also make stopped counting, and
    // 0.926 / 0.943 (4463 / 1565 / 760) before that rule applied to the depthless test.
    assert!(wp >= 0.92 && wp > p, "withheld precision {wp:.3} (removed: {p:.3})");
    assert!(wr >= 0.9 && wr < r, "withheld recall {wr:.3} (removed: {r:.3})");
    // Every wrongly removed feature has exactly one cause.
    let causes = [c.false_pos_joined, c.false_pos_tested, c.false_pos_pending, c.false_pos_unseen];
    eprintln!(
        "high: wrongly removed features joined / tested / pending / unseen: {causes:?} of {}",
        c.false_pos
    );
    assert_eq!(causes.iter().sum::<u32>(), c.false_pos);
    assert!(causes.iter().all(|&k| k > 0), "{causes:?}");
    assert_eq!(lost, 0);
}

/// Motion-aware semantics from frame 40 of the `high` street of seed 1: the truck ahead fills
/// the frame after initialisation, and between 20 and 29 static matches remain beside it. The
/// tracker used to solve with the truck whenever fewer than 30 static matches remained; the
/// pose was dragged and the truck then tested static, and the run broke as the backbone does
/// (16.2 m of ATE, hard and EM). Now it holds the truck whenever the static matches can track
/// the frame on their own (`min_inliers`): 0.057 m, as Table-1 culling (0.10 m) does.
#[test]
fn motion_aware_semantics_start_beside_a_truck_that_fills_the_frame() {
    let dir = tempfile::tempdir().unwrap();
    let seq = generated_frames(dir.path(), Dynamics::High, 1, 100).starting_at(40).unwrap();
    let (motion, len, lost) = track(&seq, Semantics::Motion);
    eprintln!("high, seed 1, from frame 40: motion-aware {motion:.3} m over {len:.1} m");
    assert!(motion < 0.2, "motion-aware from frame 40: {motion:.3} m over {len:.1} m");
    assert_eq!(lost, 0);
}

/// Motion-aware semantics with EM from frame 40 of the `high` street of seed 4. Without a motion
/// estimate the first frame after initialisation is matched by appearance; with ORB-SLAM2's
/// ratio 0.7 over the whole image the facades' repeated windows failed it, the frame was solved
/// from lane markings and tree crowns alone, 0.9 m and 1.5° off, and at that pose the truck
/// ahead passed the motion test, was called parked and dragged every later frame: 16.2 m of
/// ATE (motion + hard, whose pose let the truck fail, 0.17 m). With ratio 0.9: 0.037 m.
#[test]
fn motion_aware_em_starts_where_the_facades_repeat() {
    let dir = tempfile::tempdir().unwrap();
    let seq = generated_frames(dir.path(), Dynamics::High, 4, 100).starting_at(40).unwrap();
    let (motion, len, lost, _) = track_full(&seq, Semantics::Motion, Association::Em);
    eprintln!("high, seed 4, from frame 40: motion + EM {motion:.3} m over {len:.1} m");
    assert!(motion < 0.2, "motion + EM from frame 40: {motion:.3} m over {len:.1} m");
    assert_eq!(lost, 0);
}
