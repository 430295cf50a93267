//! `semloc run`: the tracker on a KITTI sequence, with trajectory, timings, summary and
//! (when ground truth exists) evaluation and plots.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use semloc::dataset::Sequence;
use semloc::eval::EvalReport;
use semloc::run::{Network, RunConfig, RunResult, Semantics, StopFlag, Summary};
use semloc::settings::Settings;

use super::info::DatasetArgs;

/// Arguments of `semloc run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// The dataset.
    #[command(flatten)]
    pub data: DatasetArgs,
    /// Output folder (created): trajectory.txt (KITTI), trajectory_tum.txt, frames.csv,
    /// summary.json and, with ground truth, eval.json and plots/. The per-frame files are
    /// written as frames are tracked; a folder that is not empty is refused unless --force.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Use a non-empty --out: first remove what semloc wrote there before (the files listed
    /// above; anything else is left in place, with a warning).
    #[arg(long)]
    pub force: bool,
    /// Process only the first N frames (N ≥ 1).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub max_frames: Option<u64>,
    /// Worker threads: with 2 the next frame is labelled and its ORB features extracted while
    /// this one is tracked (the target has two cores); 1 runs everything on one thread. Results
    /// are identical either way.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub threads: u8,
    /// `--config` / `--orbslam2-settings`.
    #[command(flatten)]
    pub settings: SettingsFileArgs,
    /// RANSAC hypotheses per frame before pose optimisation (0 turns RANSAC off: the pose is
    /// then optimised from the constant-velocity prediction only). Default: 100, or the
    /// settings file's.
    #[arg(long, value_name = "N")]
    pub ransac_iterations: Option<u32>,
    /// Varies RANSAC's hypotheses (0: the default stream). Tracking is deterministic, so one
    /// run is one sample; a few seeds show how far a result moves from run to run, as
    /// ORB-SLAM2's results do. Default: 0, or the settings file's `tracker.ransac_seed`.
    #[arg(long, value_name = "SEED")]
    pub ransac_seed: Option<u64>,
    /// Semantic weighting of features: `off` (geometric backbone), `cull` (no features on
    /// dynamic classes), `full` (the paper's semantic ORB: cull dynamic, ×3 construction and
    /// object classes; the settings file's `orb.structure_gain` sets the ×3), `motion` (as full, but features on cars, pedestrians and cyclists are removed
    /// only where the object is tested moving against the ego-motion). Labels come from the int8 network given with --model, else from the
    /// sequence's `semantic/` folder (ground-truth labels, as `semloc synth` writes them); with
    /// neither it is an error. Default: off, or the settings file's.
    #[arg(long, value_enum, ignore_case = true)]
    pub semantics: Option<SemanticsArg>,
    /// The segmentation network (`.slm`, from `semloc convert`; e.g.
    /// models/artefacts/fastscnn_r2_192x640.slm) that labels every left frame, pipelined on the
    /// second thread. Used when --semantics is cull, full or motion.
    #[arg(long, value_name = "SLM")]
    pub model: Option<PathBuf>,
    /// Data association: `hard` (nearest neighbour in descriptor space, ORB-SLAM2) or `em`
    /// (EM over gated candidates with geometry, ORB, class and semantic-descriptor terms and a
    /// null hypothesis; class and semantic terms need --semantics). Default: hard, or the
    /// settings file's.
    #[arg(long, value_enum, ignore_case = true)]
    pub assoc: Option<AssocArg>,
    /// ATE alignment for the evaluation (see `semloc eval --help`).
    #[arg(long, value_enum, ignore_case = true, default_value_t = super::eval::AlignArg::Se3)]
    pub align: super::eval::AlignArg,
    /// Also write the map points as a PLY point cloud (x, y, z in metres in the first left
    /// camera's frame, CamVid class and its colour, observation count, first and last frame):
    /// every point that at some time had two or more keyframe observations. Written when the
    /// run ends (also after an interruption).
    #[arg(long, value_name = "FILE.ply")]
    pub export_map: Option<PathBuf>,
    /// Also record the run for the rerun viewer (`rerun FILE.rrd`): per frame the left image,
    /// its segmentation, the features coloured by class and by inlier/outlier, the map points
    /// by class, the estimated and ground-truth paths. Written as the run goes. Needs the
    /// `rerun` cargo feature (on by default).
    #[arg(long, value_name = "FILE.rrd")]
    pub rerun: Option<PathBuf>,
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
    /// As full, but dynamic-class features are removed only where their object moves
    /// (tested against the ego-motion; parked cars and standing pedestrians are kept).
    Motion,
}

impl From<SemanticsArg> for Semantics {
    fn from(s: SemanticsArg) -> Self {
        match s {
            SemanticsArg::Off => Self::Off,
            SemanticsArg::Cull => Self::Cull,
            SemanticsArg::Full => Self::Full,
            SemanticsArg::Motion => Self::Motion,
        }
    }
}

/// Runs `cfg` behind a progress bar, with SIGINT/SIGTERM routed to its stop flag.
pub fn run_with_progress(mut cfg: RunConfig<'_>) -> Result<RunResult> {
    if cfg.stop.is_none() {
        let stop = StopFlag::new();
        stop.register_signals().context("installing the SIGINT/SIGTERM handlers")?;
        cfg.stop = Some(stop);
    }
    if cfg.command_line.is_empty() {
        cfg.command_line = super::command_line();
    }
    let pb = super::progress(cfg.frame_count() as u64, "tracking");
    let result = semloc::run::run_observed(cfg, &mut |_| pb.inc(1));
    pb.finish_and_clear();
    result.map_err(Into::into)
}

/// The settings file of `semloc run`, `ablate` and `bench-kitti`.
#[derive(Args, Debug, Default, Clone)]
pub struct SettingsFileArgs {
    /// Settings file (TOML): camera, ORB, stereo, tracker, EM, motion and semantic parameters
    /// (`semloc config --print-defaults` prints every key with its unit and default). Flags
    /// given here override it.
    #[arg(long, value_name = "FILE", conflicts_with = "orbslam2_settings")]
    pub config: Option<PathBuf>,
    /// An ORB-SLAM2 stereo settings file (YAML, e.g. KITTI00-02.yaml): its camera (Camera.fx,
    /// fy, cx, cy, bf), ThDepth and ORBextractor.* are used; the images must be rectified.
    #[arg(long, value_name = "FILE")]
    pub orbslam2_settings: Option<PathBuf>,
}

impl SettingsFileArgs {
    /// The settings (defaults without a file) and the file they came from; notes on what an
    /// ORB-SLAM2 file holds that is not used are printed.
    pub fn load(&self) -> Result<(Settings, Option<PathBuf>)> {
        let (settings, file, ignored) =
            load_settings(self.config.as_deref(), self.orbslam2_settings.as_deref())?;
        for n in &ignored {
            eprintln!("note: {}: {n}", file.as_deref().unwrap_or(Path::new("")).display());
        }
        Ok((settings, file))
    }
}

/// `semloc run`'s defaults for `seq`, but for the camera, ORB, stereo and tracker of
/// `settings`, and the file they came from recorded.
pub fn config_from_settings<'a>(
    seq: &'a Sequence,
    out: &Path,
    settings: &Settings,
    settings_file: Option<PathBuf>,
) -> RunConfig<'a> {
    RunConfig {
        tracker: settings.tracker,
        orb: settings.orb,
        stereo: settings.stereo,
        camera: settings.camera,
        settings_file,
        ..RunConfig::new(seq, out)
    }
}

/// The settings of `--config` or `--orbslam2-settings` (with notes on what an ORB-SLAM2 file
/// holds that is not used), or the defaults.
pub fn load_settings(
    config: Option<&Path>,
    orbslam2: Option<&Path>,
) -> Result<(Settings, Option<PathBuf>, Vec<String>)> {
    Ok(match (config, orbslam2) {
        (Some(p), _) => (Settings::from_toml_file(p)?, Some(p.to_path_buf()), Vec::new()),
        (None, Some(p)) => {
            let imp = semloc::settings::import_orbslam2(p)?;
            (imp.settings, Some(p.to_path_buf()), imp.ignored)
        }
        (None, None) => (Settings::default(), None, Vec::new()),
    })
}

/// Runs `semloc run`.
pub fn run(args: &RunArgs) -> Result<()> {
    let (settings, settings_file) = args.settings.load()?;
    for (flag, file) in [("--export-map", &args.export_map), ("--rerun", &args.rerun)] {
        let Some(p) = file else { continue };
        let dir = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if !dir.is_dir() {
            anyhow::bail!("{flag} {}: the folder {} does not exist", p.display(), dir.display());
        }
    }
    let seq = args.data.open_with_camera(settings.camera.as_ref().map(|c| c.calib()))?;
    for n in &seq.notes {
        eprintln!("note: {n}");
    }
    let mut tracker = settings.tracker;
    if let Some(n) = args.ransac_iterations {
        tracker.ransac_iterations = n;
    }
    if let Some(seed) = args.ransac_seed {
        tracker.ransac_seed = seed;
    }
    if let Some(a) = args.assoc {
        tracker.association = a.into();
    }
    let cfg = RunConfig {
        max_frames: args.max_frames.map(|n| usize::try_from(n).unwrap_or(usize::MAX)),
        threads: args.threads,
        tracker,
        semantics: args.semantics.map_or(settings.semantics.mode, Into::into),
        network: args.model.clone().or(settings.semantics.model.clone()).map(Network::File),
        align: args.align.into(),
        force: args.force,
        export_map: args.export_map.clone(),
        rerun: args.rerun.clone(),
        ..config_from_settings(&seq, &args.out, &settings, settings_file)
    };
    let outcome = run_with_progress(cfg)?;
    for n in &outcome.notices {
        eprintln!("note: {n}");
    }
    print_summary(&outcome.summary, outcome.eval.as_ref(), &args.out);
    super::print_warnings(&outcome.warnings);
    finish(&outcome, &args.out)
}

/// The exit of a finished run: success when complete and evaluated where it could be; the
/// stop (signal: 128 + it), or the evaluation failure, as an error otherwise. Outputs are
/// already written either way.
pub fn finish(outcome: &RunResult, out: &Path) -> Result<()> {
    let s = &outcome.summary;
    if let Some(f) = &outcome.failure {
        let summary = if outcome.summary_written {
            "summary.json marked \"complete\": false"
        } else {
            "summary.json could not be written"
        };
        let progress = if s.frames_processed == s.frames_requested {
            format!("all {} frames tracked", s.frames_processed)
        } else {
            format!("stopped after {} of {} frames", s.frames_processed, s.frames_requested)
        };
        let message = format!(
            "{}; {progress} (the per-frame outputs hold every one of them, in {}; {summary})",
            semloc::run::outputs::error_chain(f),
            out.display()
        );
        return Err(super::Exit { code: f.exit_code(), message }.into());
    }
    if let Some(e) = &outcome.eval_error {
        return Err(anyhow::anyhow!(
            "all {} frames tracked and written to {}, but the evaluation failed: {}",
            s.frames_processed,
            out.display(),
            semloc::run::outputs::error_chain(e)
        ));
    }
    Ok(())
}

/// The run's report on stdout. Written with one fallible write: a stdout that cannot take it
/// (a full disk behind `> log`) is a warning, never a panic, and never hides the exit status.
fn print_summary(s: &Summary, eval: Option<&EvalReport>, out: &Path) {
    use core::fmt::Write as _;
    let mut t = String::new();
    let state = if s.complete { String::new() } else { " (incomplete)".to_string() };
    let _ = writeln!(
        t,
        "{} of {} frames of {}{state} ({} thread(s))",
        s.frames_processed, s.frames_requested, s.dataset.name, s.threads
    );
    let _ = writeln!(
        t,
        "keyframes {}, frames not tracked {} ({} losses), median stereo matches {:.0}, median \
         inliers {:.0}",
        s.keyframes, s.lost, s.losses, s.median_stereo_matches, s.median_inliers
    );
    let _ = writeln!(t, "core memory {:.1} MiB", s.core_memory_bytes as f64 / 1048576.0);
    if s.network_memory_bytes > 0 {
        let _ = writeln!(
            t,
            "network memory {:.1} MiB (weights + arena + buffers)",
            s.network_memory_bytes as f64 / 1048576.0
        );
    }
    let _ =
        writeln!(t, "{:<14}{:>10}{:>10}{:>10}{:>10}", "stage [ms]", "median", "p90", "p99", "max");
    for (k, p) in &s.timing {
        let _ = writeln!(
            t,
            "{k:<14}{:>10.2}{:>10.2}{:>10.2}{:>10.2}",
            p.median_ms, p.p90_ms, p.p99_ms, p.max_ms
        );
    }
    let verdict = match eval {
        Some(e) => e.to_string(),
        None if s.eval_error.is_some() => "not evaluated (see the error below)".to_string(),
        None if s.dataset.has_gt => "not evaluated (see the warnings below)".to_string(),
        None => "no ground truth for this sequence: trajectory written, not evaluated".to_string(),
    };
    let _ = writeln!(t, "{verdict}");
    let _ = writeln!(t, "outputs in {}", out.display());
    super::write_stdout(&t);
}
