//! `semloc run`: the tracker on a KITTI sequence, with trajectory, timings, summary and
//! (when ground truth exists) evaluation and plots.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use semloc::eval::{evaluate, EvalReport};
use semloc::pipeline::{FrameOutput, Pipeline};
use semloc_core::geom::Se3;
use semloc_core::tracker::TrackerParams;

use super::info::DatasetArgs;
use semloc::dataset::Sequence;

/// Arguments of `semloc run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// The dataset.
    #[command(flatten)]
    pub data: DatasetArgs,
    /// Output folder (created): trajectory.txt (KITTI), trajectory_tum.txt, frames.csv,
    /// summary.json and, with ground truth, eval.json and plots/.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Process only the first N frames.
    #[arg(long, value_name = "N")]
    pub max_frames: Option<usize>,
    /// Worker threads: 2 extracts the left and right images in parallel (the target has two
    /// cores); 1 runs everything on one thread. Results are identical either way.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub threads: u8,
    /// RANSAC hypotheses per frame before pose optimisation (0 turns RANSAC off: the pose is
    /// then optimised from the constant-velocity prediction only).
    #[arg(long, default_value_t = TrackerParams::default().ransac_iterations, value_name = "N")]
    pub ransac_iterations: u32,
    /// Semantic weighting of features: `off` (geometric backbone), `cull` (no features on
    /// dynamic classes), `full` (the paper's semantic ORB: cull dynamic, ×3 construction and
    /// object classes). Labels come from the int8 network given with --model, else from the
    /// sequence's `semantic/` folder (ground-truth labels, as `semloc synth` writes them); with
    /// neither it is an error.
    #[arg(long, value_enum, default_value_t = SemanticsArg::Off)]
    pub semantics: SemanticsArg,
    /// The segmentation network (`.slm`, from `semloc convert`; e.g.
    /// models/artefacts/fastscnn_r2_192x640.slm) that labels every left frame, pipelined on the
    /// second thread. Used when --semantics is cull or full.
    #[arg(long, value_name = "SLM")]
    pub model: Option<PathBuf>,
    /// Data association: `hard` (nearest neighbour in descriptor space, ORB-SLAM2) or `em`
    /// (EM over gated candidates with geometry, ORB, class and semantic-descriptor terms and a
    /// null hypothesis; class and semantic terms need --semantics).
    #[arg(long, value_enum, default_value_t = AssocArg::Hard)]
    pub assoc: AssocArg,
    /// ATE alignment for the evaluation (see `semloc eval --help`).
    #[arg(long, value_enum, default_value_t = super::eval::AlignArg::Se3)]
    pub align: super::eval::AlignArg,
}

/// `--assoc` values.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum AssocArg {
    /// Nearest neighbour.
    Hard,
    /// EM probabilistic association.
    Em,
}

impl From<AssocArg> for semloc_core::assoc::Association {
    fn from(a: AssocArg) -> Self {
        match a {
            AssocArg::Hard => Self::Hard,
            AssocArg::Em => Self::Em,
        }
    }
}

/// `--semantics` values.
#[derive(Copy, Clone, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SemanticsArg {
    /// No semantics.
    Off,
    /// Cull features on dynamic classes.
    Cull,
    /// Cull dynamic classes and weight construction/object classes ×3.
    Full,
}

impl SemanticsArg {
    /// The core weight scheme, if any.
    pub fn scheme(self) -> Option<semloc_core::seg::WeightScheme> {
        match self {
            Self::Off => None,
            Self::Cull => Some(semloc_core::seg::WeightScheme::Cull),
            Self::Full => Some(semloc_core::seg::WeightScheme::Full),
        }
    }
}

/// Median, p90, p99 and max of one timing column.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Percentiles {
    /// Median (ms).
    pub median_ms: f64,
    /// 90th percentile (ms).
    pub p90_ms: f64,
    /// 99th percentile (ms).
    pub p99_ms: f64,
    /// Maximum (ms).
    pub max_ms: f64,
}

/// Nearest-rank percentiles of `v`.
pub fn percentiles(v: &[f64]) -> Percentiles {
    if v.is_empty() {
        return Percentiles::default();
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let at = |q: f64| s[((q * s.len() as f64).ceil() as usize).clamp(1, s.len()) - 1];
    Percentiles { median_ms: at(0.5), p90_ms: at(0.9), p99_ms: at(0.99), max_ms: at(1.0) }
}

/// What `summary.json` holds.
#[derive(Debug, serde::Serialize)]
#[allow(missing_docs)] // field names are the JSON keys; see the README
pub struct Summary {
    pub dataset: semloc::dataset::DatasetSummary,
    pub frames_processed: usize,
    pub threads: u8,
    pub keyframes: u32,
    pub lost: u32,
    pub landmark_overflow: u32,
    pub core_memory_bytes: usize,
    pub network_memory_bytes: usize,
    pub median_stereo_matches: f64,
    pub median_inliers: f64,
    pub semantics: String,
    pub association: String,
    pub median_culled: f64,
    pub em_changed_total: u64,
    pub timing: std::collections::BTreeMap<&'static str, Percentiles>,
    pub eval: Option<EvalSummary>,
}

/// The evaluation figures inside `summary.json`.
#[derive(Debug, serde::Serialize)]
#[allow(missing_docs)]
pub struct EvalSummary {
    pub align: String,
    pub ate_rmse_m: f64,
    pub t_rel_pct: Option<f64>,
    pub r_rel_deg_per_100m: Option<f64>,
    pub path_length_m: f64,
}

/// Everything the run produced so far, so it can be written even when a later frame fails.
struct Run {
    poses: Vec<Se3>,
    stamps: Vec<f64>,
    outputs: Vec<FrameOutput>,
}

/// How one tracking run is configured (the parts of `semloc run`'s arguments that `semloc
/// demo` varies).
#[derive(Clone, Debug)]
pub struct RunConfig {
    /// Worker threads (1 or 2).
    pub threads: u8,
    /// RANSAC hypotheses per frame.
    pub ransac_iterations: u32,
    /// Semantic weighting.
    pub semantics: SemanticsArg,
    /// Data association.
    pub assoc: AssocArg,
    /// ATE alignment.
    pub align: super::eval::AlignArg,
    /// Frames to process at most.
    pub max_frames: Option<usize>,
    /// The segmentation network that labels frames (else the dataset's labels are used).
    pub model: Option<PathBuf>,
}

/// What one run produced.
pub struct RunOutcome {
    /// The summary written to `summary.json`.
    pub summary: Summary,
    /// The evaluation, when the sequence has ground truth.
    pub eval: Option<EvalReport>,
    /// The frame that stopped the run early, if one did.
    pub failure: Option<semloc::pipeline::PipelineError>,
}

/// Runs the tracker on `seq` with `cfg` and writes every output into `out`; a frame that fails
/// ends the run but everything computed before it is still written and evaluated.
pub fn execute(seq: &Sequence, cfg: &RunConfig, out: &Path) -> Result<RunOutcome> {
    let n = cfg.max_frames.map_or(seq.len(), |m| m.min(seq.len()));
    std::fs::create_dir_all(out)
        .with_context(|| format!("creating output folder {}", out.display()))?;
    let (w, h) = seq.image_size;
    let params = TrackerParams {
        ransac_iterations: cfg.ransac_iterations,
        association: cfg.assoc.into(),
        ..TrackerParams::default()
    };
    let mut pipe = Pipeline::new(&seq.calib, w, h, params, usize::from(cfg.threads))?;
    if let Some(p) = &cfg.model {
        let seg = semloc::nn::segment::Segmenter::new(semloc::nn::SlmBlob::load(p)?)?;
        seg.letterbox(w as usize, h as usize)
            .with_context(|| format!("{} on {w}x{h} frames", p.display()))?;
        pipe.set_segmenter(seg);
    } else if cfg.semantics != SemanticsArg::Off && !seq.has_labels() {
        anyhow::bail!(
            "--semantics {:?} needs labels: give the network with --model FILE.slm, or a \
             sequence with a {} folder (synthetic sequences from `semloc synth` have one)",
            cfg.semantics,
            seq.root.join("semantic").display()
        );
    }
    pipe.set_semantics(cfg.semantics.scheme());
    let pb = super::progress(n as u64, "tracking");
    let mut run = Run { poses: Vec::new(), stamps: Vec::new(), outputs: Vec::new() };
    let mut failure = None;
    for i in 0..n {
        match pipe.process_sequence_frame(seq, i) {
            Ok(o) => {
                run.poses.push(o.report.t_wc);
                run.stamps.push(seq.times_s.get(i).copied().unwrap_or(i as f64 * 0.1));
                run.outputs.push(o);
            }
            Err(e) => {
                failure = Some(e);
                break;
            }
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    // Write what exists before reporting a failure: never lose output already computed.
    let stats = pipe.tracker().stats();
    write_outputs(out, &run)?;
    let gt = seq.gt.as_ref().map(|g| &g[..run.poses.len()]);
    let eval = match gt {
        Some(gt) if run.poses.len() >= 3 => {
            let report = evaluate(gt, &run.poses, cfg.align.into())
                .context("evaluating the estimated trajectory")?;
            let json = out.join("eval.json");
            std::fs::write(&json, serde_json::to_string_pretty(&report)?)
                .with_context(|| format!("writing {}", json.display()))?;
            let plots = out.join("plots");
            std::fs::create_dir_all(&plots)
                .with_context(|| format!("creating {}", plots.display()))?;
            semloc::plot::write_eval_plots(&plots, gt, &report)?;
            Some(report)
        }
        _ => None,
    };
    let net_bytes = pipe.segmenter().map_or(0, |s| s.memory_bytes());
    let summary = summarise(seq, &run, cfg, &stats, eval.as_ref(), net_bytes);
    let path = out.join("summary.json");
    std::fs::write(&path, serde_json::to_string_pretty(&summary)?)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(RunOutcome { summary, eval, failure })
}

/// Runs `semloc run`.
pub fn run(args: &RunArgs) -> Result<()> {
    let seq = args.data.open()?;
    let cfg = RunConfig {
        threads: args.threads,
        ransac_iterations: args.ransac_iterations,
        semantics: args.semantics,
        assoc: args.assoc,
        align: args.align,
        max_frames: args.max_frames,
        model: args.model.clone(),
    };
    let outcome = execute(&seq, &cfg, &args.out)?;
    print_summary(&outcome.summary, outcome.eval.as_ref(), &args.out);
    match outcome.failure {
        Some(e) => Err(anyhow::Error::new(e).context(format!(
            "stopped after {} frames (outputs so far are in {})",
            outcome.summary.frames_processed,
            args.out.display()
        ))),
        None => Ok(()),
    }
}

fn write_outputs(out: &Path, run: &Run) -> Result<()> {
    let p = out.join("trajectory.txt");
    semloc::traj::write_kitti(&p, &run.poses)?;
    let p = out.join("trajectory_tum.txt");
    let tum: Vec<(f64, Se3)> = run.stamps.iter().copied().zip(run.poses.iter().copied()).collect();
    semloc::traj::write_tum(&p, &tum)?;
    let p = out.join("frames.csv");
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(&p).with_context(|| format!("creating {}", p.display()))?,
    );
    writeln!(
        f,
        "frame,timestamp_s,load_ms,orb_left_ms,orb_right_ms,extract_wall_ms,stereo_ms,track_ms,\
         seg_ms,compute_ms,total_ms,stereo_matches,matched,inliers,keyframe,lost,initialised,landmarks,\
         keyframes,ba_iterations,culled,em_changed"
    )?;
    for (o, t) in run.outputs.iter().zip(&run.stamps) {
        let (s, r) = (o.times, o.report);
        writeln!(
            f,
            "{},{t:.6},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{},{},{},{}",
            r.frame_index,
            s.load_ms,
            s.orb_left_ms,
            s.orb_right_ms,
            s.extract_wall_ms,
            s.stereo_ms,
            s.track_ms,
            s.seg_ms,
            s.compute_ms,
            s.total_ms,
            o.stereo.matched,
            r.matched,
            r.inliers,
            u8::from(r.keyframe),
            u8::from(r.lost),
            u8::from(r.initialised),
            r.landmarks,
            r.keyframes,
            r.ba_iterations,
            o.culled,
            r.em_changed
        )?;
    }
    f.flush().with_context(|| format!("writing {}", p.display()))?;
    Ok(())
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn summarise(
    seq: &semloc::dataset::Sequence,
    run: &Run,
    cfg: &RunConfig,
    stats: &semloc_core::tracker::TrackerStats,
    eval: Option<&EvalReport>,
    network_memory_bytes: usize,
) -> Summary {
    let col = |f: fn(&FrameOutput) -> f64| -> Vec<f64> { run.outputs.iter().map(f).collect() };
    let mut timing = std::collections::BTreeMap::new();
    timing.insert("load", percentiles(&col(|o| o.times.load_ms)));
    timing.insert("orb_left", percentiles(&col(|o| o.times.orb_left_ms)));
    timing.insert("orb_right", percentiles(&col(|o| o.times.orb_right_ms)));
    timing.insert("extract_wall", percentiles(&col(|o| o.times.extract_wall_ms)));
    timing.insert("stereo", percentiles(&col(|o| o.times.stereo_ms)));
    timing.insert("track", percentiles(&col(|o| o.times.track_ms)));
    if cfg.model.is_some() && cfg.semantics != SemanticsArg::Off {
        timing.insert("segment", percentiles(&col(|o| o.times.seg_ms)));
    }
    timing.insert("compute", percentiles(&col(|o| o.times.compute_ms)));
    timing.insert("total", percentiles(&col(|o| o.times.total_ms)));
    Summary {
        dataset: seq.summary(),
        frames_processed: run.poses.len(),
        threads: cfg.threads,
        keyframes: stats.keyframes,
        lost: stats.lost,
        landmark_overflow: stats.landmark_overflow,
        core_memory_bytes: Pipeline::memory_bytes(),
        network_memory_bytes,
        median_stereo_matches: median(col(|o| f64::from(o.stereo.matched))),
        median_inliers: median(col(|o| f64::from(o.report.inliers))),
        semantics: format!("{:?}", cfg.semantics).to_lowercase(),
        association: format!("{:?}", cfg.assoc).to_lowercase(),
        em_changed_total: run.outputs.iter().map(|o| u64::from(o.report.em_changed)).sum(),
        median_culled: median(col(|o| f64::from(o.culled))),
        timing,
        eval: eval.map(|e| EvalSummary {
            align: e.align.to_string(),
            ate_rmse_m: e.ate_rmse_m,
            t_rel_pct: e.t_rel_pct,
            r_rel_deg_per_100m: e.r_rel_deg_per_100m,
            path_length_m: e.path_length_m,
        }),
    }
}

fn print_summary(s: &Summary, eval: Option<&EvalReport>, out: &Path) {
    println!("{} frames of {} ({} thread(s))", s.frames_processed, s.dataset.name, s.threads);
    println!(
        "keyframes {}, lost {}, median stereo matches {:.0}, median inliers {:.0}",
        s.keyframes, s.lost, s.median_stereo_matches, s.median_inliers
    );
    println!("core memory {:.1} MiB", s.core_memory_bytes as f64 / 1048576.0);
    if s.network_memory_bytes > 0 {
        println!(
            "network memory {:.1} MiB (weights + arena + buffers)",
            s.network_memory_bytes as f64 / 1048576.0
        );
    }
    println!("{:<14}{:>10}{:>10}{:>10}{:>10}", "stage [ms]", "median", "p90", "p99", "max");
    for (k, p) in &s.timing {
        println!(
            "{k:<14}{:>10.2}{:>10.2}{:>10.2}{:>10.2}",
            p.median_ms, p.p90_ms, p.p99_ms, p.max_ms
        );
    }
    if let Some(e) = eval {
        println!("{e}");
    } else {
        println!("no ground truth: trajectory written, not evaluated");
    }
    println!("outputs in {}", out.display());
}
