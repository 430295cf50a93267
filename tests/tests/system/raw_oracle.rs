//! Real-data check of the KITTI raw reader against pykitti.
//!
//! Opens `kitti-raw` drive 2011_09_26_0005 with `semloc::dataset`, has
//! `tests/oracle/raw_poses_pykitti.py` compute the camera-2 poses with pykitti, and requires
//! every pose to agree within 1 mm and 1e-6 rad. Skips (with a message) when the data, python3
//! or pykitti is missing, unless `SEMLOC_REQUIRE_DATA` is set.

use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::{Matrix3, Matrix3x4, Vector3};
use semloc::dataset::{CameraPair, Layout, Sequence};

fn required() -> bool {
    std::env::var_os("SEMLOC_REQUIRE_DATA").is_some()
}

/// Skips the test (or fails it when data is required).
fn skip(why: &str) {
    assert!(!required(), "SEMLOC_REQUIRE_DATA is set but {why}");
    eprintln!("skipping raw oracle test: {why}");
}

/// Runs the pykitti oracle; `None` when python3 or pykitti is unavailable.
fn pykitti_poses(date_dir: &Path, drive: &str, out: &Path) -> Option<Vec<Matrix3x4<f64>>> {
    let script =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("oracle").join("raw_poses_pykitti.py");
    // SEMLOC_PYTHON names an interpreter that has the oracle (CI's venv); default python3.
    let python = std::env::var_os("SEMLOC_PYTHON").unwrap_or_else(|| "python3".into());
    let res = Command::new(&python).arg(&script).arg(date_dir).arg(drive).arg(out).output();
    let output = match res {
        Ok(o) => o,
        Err(e) => {
            skip(&format!("cannot run python3: {e}"));
            return None;
        }
    };
    let stderr = String::from_utf8_lossy(&output.stderr);
    if output.status.code() == Some(3) {
        skip(&format!("pykitti unavailable ({})", stderr.trim()));
        return None;
    }
    assert!(output.status.success(), "{} failed: {stderr}", script.display());
    let text = std::fs::read_to_string(out).expect("oracle output");
    let poses = text
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|t| t.parse().expect("number")).collect();
            assert_eq!(v.len(), 12, "oracle line `{l}`");
            Matrix3x4::from_row_slice(&v)
        })
        .collect();
    Some(poses)
}

/// Rotation angle of `a⁻¹ b` (radians), robust near zero.
fn rot_err(a: &Matrix3<f64>, b: &Matrix3<f64>) -> f64 {
    let d = a.transpose() * b;
    let s = Vector3::new(d[(2, 1)] - d[(1, 2)], d[(0, 2)] - d[(2, 0)], d[(1, 0)] - d[(0, 1)]);
    (0.5 * s.norm()).atan2(0.5 * (d.trace() - 1.0))
}

#[test]
#[ignore = "real data in ../shared/data; run with --ignored (CI does)"]
fn raw_drive_0005_matches_pykitti() {
    let Some(data) = semloc_tests::shared_data() else { return };
    let raw_root = data.join("kitti-raw");
    let seq = Sequence::open_raw(&raw_root, "2011_09_26_0005", None).expect("open raw drive");

    assert_eq!(seq.layout, Layout::Raw);
    assert_eq!(seq.pair, CameraPair::Colour);
    assert_eq!(seq.len(), 91);
    assert_eq!(seq.image_size, (1242, 375));
    assert_eq!(seq.times_s.len(), 91);
    assert!((seq.calib.fx_px - 721.5377).abs() < 1e-9);
    assert!((seq.calib.fy_px - 721.5377).abs() < 1e-9);
    assert!((seq.calib.cx_px - 609.5593).abs() < 1e-9);
    assert!((seq.calib.cy_px - 172.854).abs() < 1e-9);
    let bf = seq.calib.baseline_m * seq.calib.fx_px;
    assert!((bf - 384.381).abs() < 1e-3, "baseline·fx = {bf}");
    // ~0.1 s a frame.
    assert!((seq.duration_s() - 9.0).abs() < 0.5, "duration {}", seq.duration_s());

    // Luma of the first and last frames equals Pillow's convert("L") (pixel sums from Pillow).
    let sum = |g: &[u8]| g.iter().map(|&v| u64::from(v)).sum::<u64>();
    let (l0, _) = seq.load_luma(0).expect("frame 0");
    let (l90, r90) = seq.load_luma(90).expect("frame 90");
    assert_eq!(sum(l0.as_raw()), 41_741_370);
    assert_eq!((sum(l90.as_raw()), sum(r90.as_raw())), (41_960_184, 41_241_619));

    let gt = seq.gt.as_ref().expect("oxts ground truth");
    assert_eq!(gt.len(), 91);
    assert_eq!(gt[0], semloc_core::geom::Se3::identity());

    let tmp = tempfile::tempdir().expect("tempdir");
    let out = tmp.path().join("pykitti_cam2.txt");
    let Some(reference) =
        pykitti_poses(&raw_root.join("2011_09_26"), "2011_09_26_drive_0005_sync", &out)
    else {
        return;
    };
    assert_eq!(reference.len(), gt.len());
    let (mut max_t, mut max_r) = (0.0f64, 0.0f64);
    for (i, (ours, theirs)) in gt.iter().zip(&reference).enumerate() {
        let theirs_t: Vector3<f64> = theirs.column(3).into_owned();
        let theirs_r: Matrix3<f64> = theirs.fixed_view::<3, 3>(0, 0).into_owned();
        let dt = (ours.trans - theirs_t).norm();
        let dr = rot_err(&ours.rot, &theirs_r);
        assert!(dt < 1e-3, "frame {i}: translation differs by {dt} m");
        assert!(dr < 1e-6, "frame {i}: rotation differs by {dr} rad");
        max_t = max_t.max(dt);
        max_r = max_r.max(dr);
    }
    let length = seq.gt_length_m().unwrap_or(0.0);
    println!(
        "raw 2011_09_26_0005 vs pykitti: {} poses, max translation error {max_t:.3e} m, \
         max rotation error {max_r:.3e} rad; path length {length:.3} m",
        gt.len()
    );
    eprintln!("max |Δt| = {max_t:.3e} m, max |Δr| = {max_r:.3e} rad");
}
