//! KITTI odometry layout: `sequences/XX/{image_0,image_1,image_2,image_3}/NNNNNN.png`,
//! `calib.txt` (`P0`..`P3`, 12 numbers each; other keys such as `Tr` are ignored),
//! `times.txt` (one number a line), and optional `poses/XX.txt` (12 numbers a line, the 3x4
//! camera-to-world pose of camera 0).

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use semloc_core::geom::Se3;

use super::calib::{stereo_from_projections, CalibFile};
use super::text::read_rows;
use super::{check_times, first_pair_size, list_pair, CameraPair, DatasetError, Layout, Sequence};

/// Finds the sequence folder and the pose file for `seq` under `root`.
fn locate(root: &Path, seq: &str) -> Result<(PathBuf, String, PathBuf), DatasetError> {
    let padded = match seq.parse::<u32>() {
        Ok(n) if seq.len() < 2 => format!("{n:02}"),
        _ => seq.to_string(),
    };
    for name in [seq, padded.as_str()] {
        let dir = root.join("sequences").join(name);
        if dir.is_dir() {
            return Ok((dir, name.to_string(), root.join("poses").join(format!("{name}.txt"))));
        }
    }
    let looks_like_sequence =
        ["calib.txt", "times.txt", "image_0", "image_2"].iter().any(|f| root.join(f).exists());
    if looks_like_sequence || (root.is_dir() && !root.join("sequences").is_dir()) {
        // Handed the sequence folder itself: poses live at ../../poses/XX.txt. It must be the
        // sequence asked for (`--seq 06` on `sequences/01` is a mistake, not a request).
        let name = super::dir_name(root);
        if !name.is_empty() && name != seq && name != padded {
            return Err(DatasetError::SelectionConflict {
                path: root.to_path_buf(),
                what: "sequence",
                asked: seq.to_string(),
                found: name,
            });
        }
        let name = if name.is_empty() { padded } else { name };
        let poses = root.join("..").join("..").join("poses").join(format!("{name}.txt"));
        return Ok((root.to_path_buf(), name, poses));
    }
    Err(DatasetError::MissingFile { path: root.join("sequences").join(padded) })
}

/// See [`Sequence::open_odometry`].
pub(crate) fn open(
    root: &Path,
    seq: &str,
    pair: Option<CameraPair>,
) -> Result<Sequence, DatasetError> {
    if !root.is_dir() {
        return Err(DatasetError::MissingFile { path: root.to_path_buf() });
    }
    let (dir, name, poses_path) = locate(root, seq)?;
    let pair = match pair {
        Some(p) => p,
        None if dir.join("image_0").is_dir() && dir.join("image_1").is_dir() => CameraPair::Grey,
        None if dir.join("image_2").is_dir() => CameraPair::Colour,
        None => return Err(DatasetError::EmptySequence { path: dir }),
    };
    let (l, r) = pair.cameras();
    let left_dir = dir.join(format!("image_{l}"));
    let right_dir = dir.join(format!("image_{r}"));
    let (left, right) = list_pair(&left_dir, &right_dir)?;

    let calib_file = CalibFile::read(&dir.join("calib.txt"))?;
    let pl = calib_file.mat3x4(&format!("P{l}"))?;
    let pr = calib_file.mat3x4(&format!("P{r}"))?;
    let calib = stereo_from_projections(calib_file.path(), &pl, &pr)?;

    let times_path = dir.join("times.txt");
    let times: Vec<f64> = read_rows(&times_path, 1)?.into_iter().map(|r| r[0]).collect();
    let (times_s, extra) = check_times(&times_path, times, left.len())?;
    let notes: Vec<String> = extra.into_iter().collect();

    let mut gt_problem = None;
    let gt = if poses_path.is_file() {
        let (poses, bad) = super::folder::kitti_poses(&poses_path, left.len())?;
        gt_problem = bad;
        // Poses are of camera 0; the colour pair's left camera sits P2[0][3]/fx to its side
        // in the rectified frame (pykitti's T2), so G₂ = T₂ G₀ T₂⁻¹ keeps pose 0 the identity.
        let t2 = Se3::new(nalgebra::Matrix3::identity(), Vector3::new(pl[3] / pl[0], 0.0, 0.0));
        let t2_inv = t2.inverse();
        let poses = poses
            .into_iter()
            .map(|g| match pair {
                CameraPair::Grey => g,
                CameraPair::Colour => t2.compose(&g).compose(&t2_inv),
            })
            .collect::<Vec<_>>();
        (!poses.is_empty()).then_some(poses)
    } else {
        None
    };

    let image_size = first_pair_size(&left, &right)?;
    Ok(Sequence {
        layout: Layout::Odometry,
        name,
        root: dir,
        pair,
        calib,
        left,
        right,
        times_s,
        time_origin_s: 0.0,
        gt,
        gt_problem,
        image_size,
        notes,
        remap: None,
        first_frame: 0,
    })
}
