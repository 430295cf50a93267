//! `semloc gt`: a dataset's ground truth written out, so that a run can be checked with evo or
//! the KITTI devkit as well as with `semloc eval`.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;
use semloc::dataset::Sequence;
use semloc::run::{prepare_output_dir, write_atomic};

use super::info::{settings_camera, DatasetArgs};

/// The files `semloc gt` writes (and, with `--force`, replaces).
pub const GT_OUTPUTS: &[&str] = &["gt.txt", "gt_tum.txt", "times.txt"];

/// Arguments of `semloc gt`.
#[derive(Args, Debug)]
pub struct GtArgs {
    /// The dataset.
    #[command(flatten)]
    pub data: DatasetArgs,
    /// Output folder for `gt.txt` (KITTI poses), `gt_tum.txt` (TUM, recording times) and
    /// `times.txt` (seconds from the first frame). Created if missing; must be empty unless
    /// --force.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Replace the files a previous `semloc gt` wrote in --out (other files are kept).
    #[arg(long)]
    pub force: bool,
    /// Settings file (TOML) whose [camera] section calibrates a stereo folder without
    /// calib.txt (the other sections are not used here).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
}

/// What `semloc gt` wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct GtWritten {
    /// Poses written (frames from the first).
    pub poses: usize,
    /// Frames of the sequence.
    pub frames: usize,
    /// Why fewer poses than frames were written, if so.
    pub problem: Option<String>,
}

/// Writes `seq`'s ground truth into `out` (see [`GtArgs::out`]): the left camera of the pair,
/// camera-to-world, one line per frame, as `semloc run` writes its estimate, so the two files
/// compare line by line (KITTI) or by recording time (TUM).
pub fn write_gt(
    seq: &Sequence,
    out: &std::path::Path,
    force: bool,
) -> Result<(GtWritten, Vec<String>)> {
    let Some(gt) = seq.gt.as_deref().filter(|g| !g.is_empty()) else {
        match &seq.gt_problem {
            Some(p) => bail!("{} has no usable ground truth: {p}", seq.root.display()),
            None => bail!(
                "{} has no ground truth (odometry: poses/XX.txt beside sequences/; raw: \
                 oxts/data; stereo folder: gt.txt or gt_tum.txt; EuRoC: \
                 mav0/state_groundtruth_estimate0/data.csv)",
                seq.root.display()
            ),
        }
    };
    let mut warnings = Vec::new();
    warnings.extend(prepare_output_dir(out, force, GT_OUTPUTS)?);
    let kitti = semloc::traj::format_kitti(gt);
    let mut tum = String::from(semloc::traj::TUM_HEADER);
    let mut times = String::new();
    for (pose, t) in gt.iter().zip(&seq.times_s) {
        tum.push_str(&semloc::traj::format_tum_line(seq.time_origin_s + t, pose));
    }
    for t in &seq.times_s {
        times.push_str(&format!("{t:e}\n"));
    }
    write_atomic(&out.join("gt.txt"), kitti.as_bytes())?;
    write_atomic(&out.join("gt_tum.txt"), tum.as_bytes())?;
    write_atomic(&out.join("times.txt"), times.as_bytes())?;
    let problem = seq.gt_problem.as_ref().map(ToString::to_string);
    if let Some(p) = &problem {
        warnings.push(format!(
            "ground truth covers frames 0..{} of {} only: {p}",
            gt.len(),
            seq.len()
        ));
    }
    Ok((GtWritten { poses: gt.len(), frames: seq.len(), problem }, warnings))
}

/// Runs `semloc gt`.
pub fn run(args: &GtArgs) -> Result<()> {
    let seq = args.data.open_with_camera(settings_camera(args.config.as_deref())?)?;
    for n in &seq.notes {
        eprintln!("note: {n}");
    }
    let (w, warnings) = write_gt(&seq, &args.out, args.force)?;
    super::print_warnings(&warnings);
    super::write_stdout(&format!(
        "wrote {} ground-truth poses of {} ({} frames) to {}: gt.txt (KITTI), gt_tum.txt (TUM, \
         recording time origin {} s), times.txt\n",
        w.poses,
        seq.name,
        w.frames,
        args.out.display(),
        seq.time_origin_s
    ));
    Ok(())
}
