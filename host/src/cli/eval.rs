//! `semloc eval`: KITTI devkit t_rel/r_rel, Umeyama-aligned ATE, per-length table, JSON, plots.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use semloc::eval::{evaluate, Align};
use semloc::traj::{self, TrajFormat};
use semloc_core::geom::Se3;

/// Arguments of `semloc eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Ground-truth trajectory (KITTI pose file: 12 numbers a line; or TUM: `t x y z qx qy qz qw`).
    #[arg(long, value_name = "FILE")]
    pub gt: PathBuf,
    /// Estimated trajectory, same kinds of file as --gt.
    #[arg(long, value_name = "FILE")]
    pub est: PathBuf,
    /// File format of both trajectories; `auto` looks at the first data line (12 fields: KITTI,
    /// 8 fields: TUM).
    #[arg(long, value_enum, ignore_case = true, default_value_t = FormatArg::Auto)]
    pub format: FormatArg,
    /// Alignment of the estimate to ground truth before ATE: `se3` rotation+translation (as
    /// `evo_ape kitti -a`), `sim3` adds scale (`-as`), `none` compares raw positions.
    /// t_rel/r_rel are relative measures and do not depend on it.
    #[arg(long, value_enum, ignore_case = true, default_value_t = AlignArg::Se3)]
    pub align: AlignArg,
    /// TUM files only: the largest timestamp difference (seconds) at which an estimated pose is
    /// associated with a ground-truth pose (evo's default is 0.01).
    #[arg(long, default_value_t = 0.01, value_name = "SECONDS")]
    pub max_time_diff: f64,
    /// KITTI files only: evaluate an estimate with fewer poses than the ground truth (a run
    /// that stopped early) against the ground truth's first poses. Without it a length
    /// mismatch is an error.
    #[arg(long)]
    pub prefix: bool,
    /// Also write the full report (summary, per-length table, per-segment errors) as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write plots into this folder (created if missing), each as SVG and PNG: `trajectory`
    /// (top view of ground truth and aligned estimate), `ate` (ATE over distance travelled),
    /// `rpe` (RPE over time), `position` and `orientation` (over time), `per_length` (devkit
    /// errors per segment length). See docs/outputs.md.
    #[arg(long, value_name = "DIR")]
    pub plot: Option<PathBuf>,
}

/// `--format` values.
#[derive(Copy, Clone, Debug, ValueEnum)]
pub enum FormatArg {
    /// Decide per file from its first data line.
    Auto,
    /// KITTI odometry pose file.
    Kitti,
    /// TUM RGB-D trajectory file.
    Tum,
}

/// `--align` values.
#[derive(Copy, Clone, Debug, ValueEnum)]
pub enum AlignArg {
    /// Rotation and translation (no scale).
    Se3,
    /// Rotation, translation and scale.
    Sim3,
    /// No alignment.
    None,
}

impl From<AlignArg> for Align {
    fn from(a: AlignArg) -> Self {
        match a {
            AlignArg::Se3 => Align::Se3,
            AlignArg::Sim3 => Align::Sim3,
            AlignArg::None => Align::None,
        }
    }
}

/// A trajectory as read: poses, with timestamps when the file had them.
struct Loaded {
    times: Option<Vec<f64>>,
    poses: Vec<Se3>,
}

fn load(path: &std::path::Path, format: FormatArg) -> Result<Loaded> {
    let fmt = match format {
        FormatArg::Kitti => TrajFormat::Kitti,
        FormatArg::Tum => TrajFormat::Tum,
        FormatArg::Auto => traj::detect_format(path)?,
    };
    Ok(match fmt {
        TrajFormat::Kitti => Loaded { times: None, poses: traj::read_kitti(path)? },
        TrajFormat::Tum => {
            let (times, poses) = traj::read_tum(path)?.into_iter().unzip();
            Loaded { times: Some(times), poses }
        }
    })
}

/// The associated ground-truth and estimated poses, and for TUM files the ground-truth time
/// of each pair (s).
type Associated = (Vec<Se3>, Vec<Se3>, Option<Vec<f64>>);

/// Pairs up poses: index by index for KITTI files (with `prefix`, an estimate shorter than
/// the ground truth takes its first poses), by nearest timestamp, one to one, for TUM files.
fn associate(gt: Loaded, est: Loaded, max_dt: f64, prefix: bool) -> Result<Associated> {
    match (gt.times, est.times) {
        (Some(tg), Some(te)) => {
            let pairs = traj::associate_by_time(&tg, &te, max_dt);
            if pairs.is_empty() {
                bail!("no estimated timestamp lies within {max_dt} s of a ground-truth timestamp");
            }
            let (g, e) = pairs.iter().map(|&(i, j)| (gt.poses[i], est.poses[j])).unzip();
            Ok((g, e, Some(pairs.iter().map(|&(i, _)| tg[i]).collect())))
        }
        (None, None) => {
            let (g, e) = (gt.poses.len(), est.poses.len());
            if e < g && !prefix {
                bail!(
                    "the estimate has {e} poses and the ground truth {g}; if the run stopped \
                     early, pass --prefix to evaluate against the first {e} ground-truth poses"
                );
            }
            let mut gt_poses = gt.poses;
            if prefix {
                gt_poses.truncate(e);
            }
            Ok((gt_poses, est.poses, None))
        }
        _ => bail!(
            "one trajectory has timestamps (TUM) and the other has none (KITTI); \
             convert one of them or pass both in the same format"
        ),
    }
}

/// Runs `semloc eval`.
pub fn run(args: &EvalArgs) -> Result<()> {
    let gt = load(&args.gt, args.format)?;
    let est = load(&args.est, args.format)?;
    let (gt, est, times) = associate(gt, est, args.max_time_diff, args.prefix)?;
    let report = evaluate(&gt, &est, args.align.into()).with_context(|| {
        format!("evaluating {} against {}", args.est.display(), args.gt.display())
    })?;
    super::write_stdout(&format!("{report}\n"));
    super::print_warnings(&report.warnings);
    if let Some(json) = &args.json {
        semloc::run::outputs::write_json(json, &report)?;
        println!("wrote {}", json.display());
    }
    if let Some(dir) = &args.plot {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let written = semloc::plot::write_eval_plots(dir, &gt, &report, times.as_deref())?;
        for p in written {
            println!("wrote {}", p.display());
        }
    }
    Ok(())
}
