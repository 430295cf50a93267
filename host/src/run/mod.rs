//! One tracking run over a sequence, as `semloc run`, `ablate` and `demo` do it, and as tests
//! and benches drive it: a typed [`RunConfig`] in, a [`RunResult`] (per-frame records,
//! summary, optional evaluation) out, with every output file written on the way
//! ([`outputs`]: `trajectory.txt`, `trajectory_tum.txt`, `frames.csv`, `summary.json`, and with
//! ground truth `eval.json` and `plots/`).
//!
//! The frames go through [`Pipeline`] in order; a frame that fails ends the run, and what was
//! computed before it is still written and evaluated (the failure is returned, not raised), so
//! a corrupt image late in a drive never costs the trajectory up to it. Evaluation follows the
//! paper's protocol (§4: KITTI devkit t_rel/r_rel, Umeyama-aligned ATE; see [`crate::eval`]).
//!
//! Memory: the pipeline's fixed core state ([`Pipeline::memory_bytes`], ≈ 11 MiB), the
//! network's when one is set, and one [`FrameRecord`] per frame (a few hundred bytes) kept for
//! the outputs and the caller.

pub mod map_export;
pub mod outputs;
pub mod provenance;
pub mod stats;
pub mod stream;
#[cfg(feature = "rerun")]
pub mod viewer;

use std::path::{Path, PathBuf};

use semloc_core::assoc::Association;
use semloc_core::frame::Feature;
use semloc_core::geom::Se3;
use semloc_core::motion::{FeatureMotion, MotionSegment};
use semloc_core::nn::graph::Letterbox;
use semloc_core::orb::OrbConfig;
use semloc_core::seg::WeightScheme;
use semloc_core::stereo::StereoMatching;
use semloc_core::tracker::TrackerParams;

use image::GrayImage;

use crate::dataset::Sequence;
use crate::eval::{Align, EvalError, EvalReport};
use crate::nn::segment::Segmenter;
use crate::nn::{NnFileError, SlmBlob};
use crate::pipeline::{FrameOutput, FrameSource, Pipeline, PipelineError};
use crate::settings::CameraSettings;

pub use outputs::{frames_csv_header, EvalSummary, FrameRow, MotionSummary, Summary};
pub use provenance::{ModelInfo, Provenance};
pub use stats::{percentiles, Percentiles};
pub use stream::{prepare_output_dir, signal_name, write_atomic, StopFlag, RUN_OUTPUTS};

/// Semantic weighting of left-image features (the paper's §3.1).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Semantics {
    /// No semantics: the geometric backbone.
    #[default]
    Off,
    /// Cull features on dynamic classes.
    Cull,
    /// Cull dynamic classes and weight construction/object classes ×3 (semantic ORB, Eq. 2).
    Full,
    /// Motion-aware semantics (beyond the paper): semantic ORB's ×3 on construction/object,
    /// and features on dynamic classes removed only where their object is tested moving.
    Motion,
}

impl Semantics {
    /// The core weight scheme, if any.
    pub fn scheme(self) -> Option<WeightScheme> {
        match self {
            Self::Off => None,
            Self::Cull => Some(WeightScheme::Cull),
            Self::Full => Some(WeightScheme::Full),
            Self::Motion => Some(WeightScheme::Motion),
        }
    }

    /// The setting's name in `summary.json` and tables: `off`, `cull`, `full`, `motion`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Cull => "cull",
            Self::Full => "full",
            Self::Motion => "motion",
        }
    }
}

/// The association's name in `summary.json` and tables: `hard`, `em`.
pub fn association_name(a: Association) -> String {
    format!("{a:?}").to_lowercase()
}

/// The int8 segmentation network that labels the left frames.
pub enum Network {
    /// Loaded from this `.slm` file (`semloc convert`) when the run starts.
    File(PathBuf),
    /// Already loaded.
    Loaded(Box<Segmenter>),
}

/// How one run is configured.
pub struct RunConfig<'a> {
    /// The sequence, already opened.
    pub seq: &'a Sequence,
    /// Output folder (created with its parents).
    pub out: PathBuf,
    /// Frames to process at most (from the first).
    pub max_frames: Option<usize>,
    /// Worker threads: 1, or 2 to extract left and right in parallel; results are identical.
    pub threads: u8,
    /// Tracker parameters, the association among them.
    pub tracker: TrackerParams,
    /// ORB extraction settings.
    pub orb: OrbConfig,
    /// Stereo matching settings.
    pub stereo: StereoMatching,
    /// The rectified camera, replacing the dataset's calibration (from a settings file).
    pub camera: Option<CameraSettings>,
    /// The settings file the configuration came from, for provenance and messages.
    pub settings_file: Option<PathBuf>,
    /// Semantic weighting.
    pub semantics: Semantics,
    /// The network that labels frames; without one, semantics use the sequence's `semantic/`
    /// labels (as `semloc synth` writes them).
    pub network: Option<Network>,
    /// ATE alignment of the evaluation.
    pub align: Align,
    /// A non-empty output folder is refused unless this is set; then what semloc wrote there
    /// before is removed first ([`prepare_output_dir`]).
    pub force: bool,
    /// Checked between frames: once set, the run stops after the current frame and writes
    /// its outputs marked incomplete.
    pub stop: Option<StopFlag>,
    /// The command line, recorded in `summary.json`'s provenance.
    pub command_line: Vec<String>,
    /// Where to write the map points as PLY (`--export-map`), if anywhere.
    pub export_map: Option<PathBuf>,
    /// Where to write the rerun viewer recording (`--rerun`), if anywhere; needs the `rerun`
    /// cargo feature ([`RunError::ViewerUnavailable`] without it).
    pub rerun: Option<PathBuf>,
}

impl<'a> RunConfig<'a> {
    /// `semloc run`'s defaults: two threads, default tracker (hard association), no semantics,
    /// no network, SE(3) alignment, every frame.
    pub fn new(seq: &'a Sequence, out: impl Into<PathBuf>) -> Self {
        Self {
            seq,
            out: out.into(),
            max_frames: None,
            threads: 2,
            tracker: TrackerParams::default(),
            orb: OrbConfig::KITTI,
            stereo: StereoMatching::ORB_SLAM2,
            camera: None,
            settings_file: None,
            semantics: Semantics::Off,
            network: None,
            align: Align::Se3,
            force: false,
            stop: None,
            command_line: Vec::new(),
            export_map: None,
            rerun: None,
        }
    }

    /// How many frames the run will process.
    pub fn frame_count(&self) -> usize {
        self.max_frames.map_or(self.seq.len(), |m| m.min(self.seq.len()))
    }
}

/// One processed frame.
#[derive(Clone, Copy, Debug)]
pub struct FrameRecord {
    /// The frame's timestamp (s), as written to `trajectory_tum.txt` and `frames.csv`.
    pub timestamp_s: f64,
    /// What the pipeline returned for it.
    pub output: FrameOutput,
    /// With motion-aware semantics on a source that has a moving-object mask: the features
    /// the motion test removed, scored against the mask.
    pub moving_check: Option<MovingCheck>,
}

/// One frame's features scored against the ground-truth moving-object mask: "called moving"
/// is a feature the motion test removed (moving or unproven, [`FeatureMotion::removed`]); a
/// feature is truly moving when the mask is set at its key point.
///
/// Of the removed features, the *deferred* ones (unproven and free to make a landmark: matched
/// to no landmark, on an object more likely parked than moving and, until it is measured, with
/// some stereo depth) are treated as a parked car's features are: they had no match to hold
/// out of the pose and may make a landmark, which is tested before it is used. Counting them as kept gives the
/// precision and recall of what the motion test actually withholds from the pose and the
/// map ([`MovingCheck::withheld_precision`]).
///
/// The wrongly removed features (`false_pos`) are split by why they were removed, from the
/// object the motion test grouped them into ([`semloc_core::tracker::Tracker::feature_segment`]):
/// `false_pos_joined` + `false_pos_tested` + `false_pos_pending` + `false_pos_unseen` =
/// `false_pos`. The deferred features on moving objects, the recall that "withheld" loses, are
/// split the same way: `deferred_true_pending` + `deferred_true_unseen` = `deferred_true`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct MovingCheck {
    /// Removed and on a moving object.
    pub true_pos: u32,
    /// Removed but static.
    pub false_pos: u32,
    /// Kept but on a moving object.
    pub false_neg: u32,
    /// Removed as moving (tested), of `true_pos + false_pos`.
    pub tested_moving: u32,
    /// Of `tested_moving`, on a moving object.
    pub tested_moving_true: u32,
    /// Used as parked (tested static) but on a moving object.
    pub tested_parked_moving: u32,
    /// Of `false_pos`: grouped into one object with features on a moving object (a parked car
    /// joined to the one passing it), which decided for all of them.
    pub false_pos_joined: u32,
    /// Of `false_pos`: on an object none of whose features moves, tested moving.
    pub false_pos_tested: u32,
    /// Of `false_pos`: on such an object, measured but without enough evidence yet to be
    /// called parked (unproven).
    pub false_pos_pending: u32,
    /// Of `false_pos`: on such an object, none of whose features could be measured on this
    /// frame (seen for the first time, or nothing re-found): unproven.
    pub false_pos_unseen: u32,
    /// Of `true_pos + false_pos`: unproven and free to make a landmark, so neither held out of
    /// the pose nor kept from making a landmark ([`semloc_core::tracker::Tracker::feature_blocked`]).
    pub deferred: u32,
    /// Of `deferred`, on a moving object.
    pub deferred_true: u32,
    /// Of `deferred_true`: its object measured on this frame, without the evidence yet to be
    /// called moving.
    pub deferred_true_pending: u32,
    /// Of `deferred_true`: nothing of its object measured on this frame (seen for the first
    /// time, or nothing re-found).
    pub deferred_true_unseen: u32,
    /// Of `deferred_true`: the feature has no stereo depth (whichever of the two above).
    pub deferred_true_depthless: u32,
}

impl MovingCheck {
    /// Sums two checks.
    pub fn add(&mut self, o: &MovingCheck) {
        self.true_pos += o.true_pos;
        self.false_pos += o.false_pos;
        self.false_neg += o.false_neg;
        self.tested_moving += o.tested_moving;
        self.tested_moving_true += o.tested_moving_true;
        self.tested_parked_moving += o.tested_parked_moving;
        self.false_pos_joined += o.false_pos_joined;
        self.false_pos_tested += o.false_pos_tested;
        self.false_pos_pending += o.false_pos_pending;
        self.false_pos_unseen += o.false_pos_unseen;
        self.deferred += o.deferred;
        self.deferred_true += o.deferred_true;
        self.deferred_true_pending += o.deferred_true_pending;
        self.deferred_true_unseen += o.deferred_true_unseen;
        self.deferred_true_depthless += o.deferred_true_depthless;
    }
    /// Precision of "called moving" (NaN when nothing was called moving).
    pub fn precision(&self) -> f64 {
        f64::from(self.true_pos) / f64::from(self.true_pos + self.false_pos)
    }
    /// Recall of the moving features (NaN when none moved).
    pub fn recall(&self) -> f64 {
        f64::from(self.true_pos) / f64::from(self.true_pos + self.false_neg)
    }
    /// Precision of "withheld": of the features kept out of the pose or the map (removed, not
    /// deferred), the share on moving objects (NaN when none was).
    pub fn withheld_precision(&self) -> f64 {
        f64::from(self.true_pos - self.deferred_true)
            / f64::from(self.true_pos + self.false_pos - self.deferred)
    }
    /// Recall of "withheld": of the features on moving objects, the share kept out of the pose
    /// or the map (NaN when none moved).
    pub fn withheld_recall(&self) -> f64 {
        f64::from(self.true_pos - self.deferred_true) / f64::from(self.true_pos + self.false_neg)
    }
    /// Precision of the "moving" verdict alone: of the features tested moving, the share on
    /// moving objects (NaN when none was); unproven features are not counted.
    pub fn tested_precision(&self) -> f64 {
        f64::from(self.tested_moving_true) / f64::from(self.tested_moving)
    }
    /// Recall of the "moving" verdict alone: of the features on moving objects, the share
    /// tested moving rather than left unproven or kept (NaN when none moved).
    pub fn tested_recall(&self) -> f64 {
        f64::from(self.tested_moving_true) / f64::from(self.true_pos + self.false_neg)
    }
}

/// Scores the last tracked frame's features against `mask` (see [`MovingCheck`]).
pub fn moving_check(pipe: &Pipeline, mask: &GrayImage) -> MovingCheck {
    let tracker = pipe.tracker();
    score_moving(
        &pipe.localiser().frame().features,
        tracker.feature_motion(),
        tracker.feature_blocked(),
        |i| tracker.feature_segment(i),
        mask,
    )
}

/// [`moving_check`] on its parts: each feature, what the motion test made of it and the object
/// it grouped it into.
fn score_moving(
    feats: &[Feature],
    states: &[FeatureMotion],
    blocked: &[bool],
    segment: impl Fn(usize) -> Option<MotionSegment>,
    mask: &GrayImage,
) -> MovingCheck {
    let n = feats.len().min(states.len()).min(blocked.len());
    let truth: Vec<bool> = feats[..n]
        .iter()
        .map(|f| {
            let x = (f.x.round().max(0.0) as u32).min(mask.width() - 1);
            let y = (f.y.round().max(0.0) as u32).min(mask.height() - 1);
            mask.get_pixel(x, y).0[0] != 0
        })
        .collect();
    // Objects with at least one feature on a moving object.
    let mut has_moving = vec![false; n];
    for (i, _) in truth.iter().enumerate().filter(|(_, &t)| t) {
        if let Some(s) = segment(i) {
            if let Some(m) = has_moving.get_mut(usize::from(s.id)) {
                *m = true;
            }
        }
    }
    let mut c = MovingCheck::default();
    for i in 0..n {
        let (st, truth) = (states[i], truth[i]);
        // Its object, and whether anything of it was measured on this frame.
        let seg = segment(i);
        let measured = seg.is_some_and(|s| s.measured > 0);
        match (st.removed(), truth) {
            (true, true) => c.true_pos += 1,
            (true, false) => {
                c.false_pos += 1;
                let joined = seg
                    .is_some_and(|s| has_moving.get(usize::from(s.id)).copied().unwrap_or(false));
                if joined {
                    c.false_pos_joined += 1;
                } else if st == FeatureMotion::Moving {
                    c.false_pos_tested += 1;
                } else if measured {
                    c.false_pos_pending += 1;
                } else {
                    c.false_pos_unseen += 1;
                }
            }
            (false, true) => c.false_neg += 1,
            _ => {}
        }
        if st == FeatureMotion::Unproven && !blocked[i] {
            c.deferred += 1;
            if truth {
                c.deferred_true += 1;
                if measured {
                    c.deferred_true_pending += 1;
                } else {
                    c.deferred_true_unseen += 1;
                }
                c.deferred_true_depthless += u32::from(!feats[i].is_stereo());
            }
        }
        if st == FeatureMotion::Moving {
            c.tested_moving += 1;
            c.tested_moving_true += u32::from(truth);
        }
        if st == FeatureMotion::Parked {
            c.tested_parked_moving += u32::from(truth);
        }
    }
    c
}

/// What one run produced (everything in it is also in the output folder).
#[derive(Debug)]
pub struct RunResult {
    /// One record per processed frame, in order.
    pub frames: Vec<FrameRecord>,
    /// The content of `summary.json`.
    pub summary: Summary,
    /// The content of `eval.json`, when the sequence has ground truth (and ≥ 3 frames ran).
    pub eval: Option<EvalReport>,
    /// What ended the run before its last frame, if anything did (a frame's error, a failed
    /// output write, a signal). Everything processed before it is in the outputs.
    pub failure: Option<RunFailure>,
    /// Why the trajectory was not evaluated although the sequence has ground truth, or why
    /// writing the evaluation failed (`summary.json` says so too).
    pub eval_error: Option<RunError>,
    /// Things the user should know (also in `summary.json`'s `warnings`).
    pub warnings: Vec<String>,
    /// Information worth printing (e.g. how frames are fitted to the network input).
    pub notices: Vec<String>,
    /// Whether `summary.json` was written (not on a full disk, for instance).
    pub summary_written: bool,
}

/// What ended a run early.
#[derive(Debug, thiserror::Error)]
pub enum RunFailure {
    /// A signal (SIGINT, SIGTERM) asked the run to stop; it stopped after the current frame.
    #[error("stopped by {}", signal_name(*.0))]
    Signal(i32),
    /// A frame could not be processed.
    #[error(transparent)]
    Frame(#[from] PipelineError),
    /// An output file could not be written (disk full, file size limit, permissions).
    #[error(transparent)]
    Output(RunError),
}

impl RunFailure {
    /// `summary.json`'s `stopped_by`: `signal`, `frame_error` or `output_error`.
    pub fn stopped_by(&self) -> &'static str {
        match self {
            Self::Signal(_) => "signal",
            Self::Frame(_) => "frame_error",
            Self::Output(_) => "output_error",
        }
    }

    /// The exit status a CLI should end with: 128 + the signal, else 1.
    pub fn exit_code(&self) -> u8 {
        match self {
            Self::Signal(s) => (128 + s).clamp(1, 255) as u8,
            _ => 1,
        }
    }
}

impl RunResult {
    /// The estimated camera-to-world poses, one per processed frame.
    pub fn poses(&self) -> Vec<Se3> {
        self.frames.iter().map(|r| r.output.report.t_wc).collect()
    }
}

/// Why a run could not start or its outputs could not be written. A frame that fails is not
/// one of these: see [`RunResult::failure`].
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// The settings file's camera is for another image size than the sequence's.
    #[error(
        "{}: the camera is {}x{} px but the images are {}x{} ({})",
        settings.display(), camera.0, camera.1, images.0, images.1, first_image.display()
    )]
    CameraSize {
        /// The settings file.
        settings: PathBuf,
        /// `camera.width`, `camera.height`.
        camera: (u32, u32),
        /// The images' size.
        images: (u32, u32),
        /// The first left image.
        first_image: PathBuf,
    },
    /// The output folder could not be created.
    #[error("creating output folder {}", path.display())]
    OutputFolder {
        /// The folder.
        path: PathBuf,
        /// The operating system's reason.
        #[source]
        source: std::io::Error,
    },
    /// An output file or folder could not be created.
    #[error("creating {}", path.display())]
    Create {
        /// The file or folder.
        path: PathBuf,
        /// The operating system's reason.
        #[source]
        source: std::io::Error,
    },
    /// An output file could not be written.
    #[error("writing {}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        #[source]
        source: std::io::Error,
    },
    /// The pipeline could not be built.
    #[error(transparent)]
    Pipeline(#[from] PipelineError),
    /// The network file could not be loaded.
    #[error(transparent)]
    Network(#[from] NnFileError),
    /// `--rerun` was asked of a build without the `rerun` cargo feature.
    #[error(
        "--rerun {}: this semloc was built without the `rerun` feature; install it with its \
         default features (cargo install semloc) or with --features rerun",
        path.display()
    )]
    ViewerUnavailable {
        /// The recording asked for.
        path: PathBuf,
    },
    /// The output folder holds files and `--force` was not given.
    #[error(
        "output folder {} is not empty ({}); choose another folder, or pass --force to replace \
         the outputs of an earlier run there",
        path.display(),
        list_names(entries)
    )]
    OutputNotEmpty {
        /// The folder.
        path: PathBuf,
        /// What it holds.
        entries: Vec<String>,
    },
    /// The network's input is a different shape from the frames: most of it would be padding
    /// and its labels garbage.
    #[error(
        "{}: the network's input is {}x{} but the frames are {width}x{height}; fitted by a \
         down-scaling of {factor}, they cover only {:.0} % of the input (at least {:.0} \
         % needed). Use a network exported for this image shape (models/export.py --size HxW)",
        path.display(),
        input.0,
        input.1,
        coverage * 100.0,
        MIN_INPUT_COVERAGE * 100.0
    )]
    NetworkShape {
        /// The network file.
        path: PathBuf,
        /// Network input (width, height).
        input: (usize, usize),
        /// Frame width (px).
        width: u32,
        /// Frame height (px).
        height: u32,
        /// The letterbox's down-scaling (`2`, `3/2`).
        factor: String,
        /// Share of the input the frame covers.
        coverage: f64,
    },
    /// The network's input cannot take the sequence's frames.
    #[error("{} on {width}x{height} frames", path.display())]
    NetworkInput {
        /// The network file.
        path: PathBuf,
        /// Frame width (px).
        width: u32,
        /// Frame height (px).
        height: u32,
        /// Why the letterbox does not fit.
        #[source]
        source: Box<NnFileError>,
    },
    /// Semantics are on but nothing labels the frames.
    #[error(
        "--semantics {semantics:?} needs labels: give the network with --model FILE.slm, or a \
         sequence with a {} folder (synthetic sequences from `semloc synth` have one)",
        folder.display()
    )]
    NoLabels {
        /// The semantic setting asked for.
        semantics: Semantics,
        /// The label folder the sequence lacks.
        folder: PathBuf,
    },
    /// A trajectory file could not be written.
    #[error(transparent)]
    Trajectory(#[from] crate::traj::TrajError),
    /// The trajectory could not be evaluated.
    #[error("evaluating the estimated trajectory")]
    Eval(#[source] EvalError),
    /// A plot could not be written.
    #[error(transparent)]
    Plot(#[from] crate::plot::PlotError),
    /// A JSON output could not be serialised.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
}

/// The smallest share of the network input a frame must cover: below it the network sees
/// mostly padding, at a scale it was not trained for (CamVid's 384x480 network on KITTI
/// frames covers 28 % and labels nearly everything one class).
pub const MIN_INPUT_COVERAGE: f64 = 0.8;

/// Up to four names, then how many more.
pub(crate) fn list_names(names: &[String]) -> String {
    let shown: Vec<&str> = names.iter().take(4).map(String::as_str).collect();
    match names.len() {
        n if n > 4 => format!("{}, and {} more", shown.join(", "), n - 4),
        _ => shown.join(", "),
    }
}

/// Loads the network in `path` and checks that it takes `width`x`height` frames.
pub fn load_network(path: &Path, width: u32, height: u32) -> Result<Segmenter, RunError> {
    let seg = Segmenter::new(SlmBlob::load(path)?)?;
    check_network_input(&seg, width, height)?;
    Ok(seg)
}

/// Checks that `seg` can label `width`x`height` frames: the letterbox fits, and the frame
/// covers at least [`MIN_INPUT_COVERAGE`] of the input.
pub fn check_network_input(seg: &Segmenter, width: u32, height: u32) -> Result<(), RunError> {
    let lb = seg.letterbox(width as usize, height as usize).map_err(|source| {
        RunError::NetworkInput {
            path: seg.blob().path().to_path_buf(),
            width,
            height,
            source: Box::new(source),
        }
    })?;
    let (h, w) = seg.input_size();
    let coverage = provenance::input_coverage(&lb);
    if coverage < MIN_INPUT_COVERAGE {
        return Err(RunError::NetworkShape {
            path: seg.blob().path().to_path_buf(),
            input: (w, h),
            width,
            height,
            factor: provenance::scale_text(&lb),
            coverage,
        });
    }
    Ok(())
}

/// The notice printed when a network's input does not match the frames exactly.
fn letterbox_notice(m: &ModelInfo, width: u32, height: u32) -> Option<String> {
    let lb = Letterbox::fit(width as usize, height as usize, m.input_height, m.input_width).ok()?;
    (m.coverage < 0.999).then(|| {
        format!(
            "network {}: {width}x{height} frames are down-scaled by {} to {}x{} and padded to its \
             {}x{} input ({:.1} % padding)",
            m.name,
            provenance::scale_text(&lb),
            lb.scaled_w(),
            lb.scaled_h(),
            m.input_width,
            m.input_height,
            (1.0 - m.coverage) * 100.0
        )
    })
}

/// Frames tracked by [`track_frames`].
#[derive(Debug)]
pub struct Tracked {
    /// One record per frame processed, in order.
    pub frames: Vec<FrameRecord>,
    /// What stopped the loop before the last frame, if anything did.
    pub failure: Option<RunFailure>,
}

/// Feeds frames `0..n` of `src` through `pipe` in order, calling `on_frame` after each; stops
/// at the first frame that fails, at the first `on_frame` error, or when `stop` is set
/// (checked before each frame), and returns why with the frames before it. `on_frame` sees the
/// pipeline as the frame left it (its map, features and labels).
pub fn track_frames(
    pipe: &mut Pipeline,
    src: &(impl FrameSource + ?Sized),
    n: usize,
    stop: Option<&StopFlag>,
    on_frame: &mut dyn FnMut(&Pipeline, &FrameRecord) -> Result<(), RunError>,
) -> Tracked {
    let mut frames = Vec::with_capacity(n);
    pipe.set_end(Some(n));
    for i in 0..n {
        if let Some(sig) = stop.and_then(StopFlag::requested) {
            return Tracked { frames, failure: Some(RunFailure::Signal(sig)) };
        }
        match pipe.process_frame(src, i) {
            Ok(output) => {
                let moving_check = if pipe.tracker().motion_aware() {
                    src.moving_mask(i).map(|m| moving_check(pipe, &m))
                } else {
                    None
                };
                let record = FrameRecord { timestamp_s: src.timestamp_s(i), output, moving_check };
                // A frame whose lines could not be written is not counted: the records and
                // the per-frame files always hold the same frames.
                if let Err(e) = on_frame(pipe, &record) {
                    return Tracked { frames, failure: Some(RunFailure::Output(e)) };
                }
                frames.push(record);
            }
            Err(e) => return Tracked { frames, failure: Some(RunFailure::Frame(e)) },
        }
    }
    Tracked { frames, failure: None }
}

/// Runs `cfg` and writes its outputs; see [`run_observed`].
pub fn run(cfg: RunConfig<'_>) -> Result<RunResult, RunError> {
    run_observed(cfg, &mut |_| {})
}

/// Tracks `cfg.seq` as configured, calling `on_frame` after each frame (for progress), and
/// writes every output into `cfg.out` (see the module docs) as it goes.
///
/// `Err` only when the run cannot start (output folder, network, labels). Once frames are
/// tracked, whatever happens is reported in the [`RunResult`] instead and every output that
/// can be written is: the per-frame files hold every processed frame, and `summary.json`
/// says whether the run is complete, what stopped it, and why the evaluation is missing.
pub fn run_observed(
    cfg: RunConfig<'_>,
    on_frame: &mut dyn FnMut(&FrameRecord),
) -> Result<RunResult, RunError> {
    let n = cfg.frame_count();
    let RunConfig {
        seq,
        out,
        max_frames: _,
        threads,
        tracker,
        orb,
        stereo,
        camera,
        settings_file,
        semantics,
        network,
        align,
        force,
        stop,
        command_line,
        export_map,
        rerun,
    } = cfg;
    #[cfg(not(feature = "rerun"))]
    if let Some(path) = rerun {
        return Err(RunError::ViewerUnavailable { path });
    }
    let (w, h) = seq.image_size;
    if let Some(c) = &camera {
        let (cw, ch) = (c.width.unwrap_or(w), c.height.unwrap_or(h));
        if (cw, ch) != (w, h) {
            return Err(RunError::CameraSize {
                settings: settings_file.clone().unwrap_or_default(),
                camera: (cw, ch),
                images: (w, h),
                first_image: seq.left.first().cloned().unwrap_or_default(),
            });
        }
    }
    let calib = camera.as_ref().map_or(seq.calib, CameraSettings::calib);
    let mut pipe =
        Pipeline::with_settings(&calib, w, h, orb, stereo, tracker, usize::from(threads))?;
    let mut warnings = Vec::new();
    let mut notices = Vec::new();
    let network = match network {
        Some(_) if semantics == Semantics::Off => {
            warnings.push(
                "--model is not used with --semantics off (the geometric backbone); the network \
                 was not loaded"
                    .to_string(),
            );
            None
        }
        other => other,
    };
    let segment_timed = network.is_some();
    match network {
        Some(Network::File(p)) => pipe.set_segmenter(load_network(&p, w, h)?),
        Some(Network::Loaded(seg)) => {
            check_network_input(&seg, w, h)?;
            pipe.set_segmenter(*seg);
        }
        None if semantics != Semantics::Off && !seq.has_labels() => {
            return Err(RunError::NoLabels { semantics, folder: seq.root.join("semantic") });
        }
        None => {}
    }
    let model = pipe.segmenter().map(|s| ModelInfo::of(s, w, h));
    notices.extend(model.as_ref().and_then(|m| letterbox_notice(m, w, h)));
    pipe.set_semantics(semantics.scheme());
    warnings.extend(prepare_output_dir(&out, force, RUN_OUTPUTS)?);
    let provenance = Provenance {
        semloc_version: provenance::VERSION,
        git_hash: provenance::GIT_HASH,
        command_line,
        dataset_path: seq.root.clone(),
        first_frame: seq.first_frame,
        frames_requested: n,
        semantics: semantics.name(),
        labels: match (semantics, &model) {
            (Semantics::Off, _) => "none",
            (_, Some(_)) => "network",
            (_, None) => "dataset",
        },
        threads,
        align: align.to_string(),
        settings_file,
        camera: calib,
        camera_from: if camera.is_some() { "settings" } else { "dataset" },
        orb,
        stereo,
        tracker,
        model,
    };

    let mut map = export_map.as_ref().map(|_| map_export::MapCollector::new());
    #[cfg(feature = "rerun")]
    let mut viewer = match &rerun {
        Some(path) => {
            let gt = seq.gt.as_deref().map(|g| &g[..n.min(g.len())]);
            Some(viewer::Recorder::create(path, &calib, w, h, gt)?)
        }
        None => None,
    };
    let mut stream = stream::StreamWriter::create(&out, seq.time_origin_s)?;
    let Tracked { frames, failure } =
        track_frames(&mut pipe, seq, n, stop.as_ref(), &mut |p: &Pipeline, r: &FrameRecord| {
            stream.append(r)?;
            if let Some(m) = map.as_mut() {
                m.observe(p.tracker().map(), r.output.report.frame_index);
            }
            #[cfg(feature = "rerun")]
            if let Some(v) = viewer.as_mut() {
                v.record(p, r)?;
            }
            on_frame(r);
            Ok(())
        });
    drop(stream);
    // The map file is an output like the others: failing to write it fails the run (after
    // the summary is written), unless the run already failed.
    let mut failure = failure;
    if let (Some(m), Some(path)) = (&map, &export_map) {
        match m.write_ply(path) {
            Ok(n) => notices.push(format!(
                "map: {n} confirmed points (of {} seen) written to {}",
                m.seen(),
                path.display()
            )),
            Err(e) if failure.is_none() => failure = Some(RunFailure::Output(e)),
            Err(e) => warnings.push(format!("--export-map: {}", outputs::error_chain(&e))),
        }
    }

    #[cfg(feature = "rerun")]
    if let (Some(v), Some(path)) = (viewer, &rerun) {
        match v.finish() {
            Ok(()) => notices.push(format!(
                "rerun: {} frames recorded to {} (open it with `rerun {}`)",
                frames.len(),
                path.display(),
                path.display()
            )),
            Err(e) if failure.is_none() => failure = Some(RunFailure::Output(e)),
            Err(e) => warnings.push(format!("--rerun: {}", outputs::error_chain(&e))),
        }
    }

    // Evaluation: skipped with a reason rather than failing the run.
    let poses: Vec<Se3> = frames.iter().map(|r| r.output.report.t_wc).collect();
    let mut eval_error = None;
    let gt = match (&seq.gt, &seq.gt_problem) {
        (Some(gt), _) if gt.len() >= poses.len() => Some(&gt[..poses.len()]),
        (_, Some(problem)) => {
            warnings.push(format!(
                "ground truth covers {} of the {} frames processed ({problem}); the trajectory \
                 was not evaluated",
                seq.gt.as_ref().map_or(0, Vec::len),
                poses.len()
            ));
            None
        }
        _ => None,
    };
    let eval = match gt {
        Some(gt) if poses.len() >= 3 => {
            let times: Vec<f64> = frames.iter().map(|r| r.timestamp_s).collect();
            let (report, error) =
                outputs::write_eval(&out, gt, &poses, align, &times, &mut warnings);
            eval_error = error;
            report
        }
        Some(_) => {
            warnings.push(format!(
                "{} frame(s) processed: the evaluation needs at least 3; not evaluated",
                poses.len()
            ));
            None
        }
        None => None,
    };
    let inputs = outputs::SummaryInputs {
        seq,
        threads,
        semantics: semantics.name(),
        association: tracker.association,
        segment_timed,
        stats: pipe.tracker().stats(),
        core_memory_bytes: Pipeline::memory_bytes(),
        network_memory_bytes: pipe.segmenter().map_or(0, Segmenter::memory_bytes),
        frames_requested: n,
        failure: failure.as_ref(),
        eval_error: eval_error.as_ref(),
        warnings: &warnings,
        provenance,
    };
    let summary = outputs::summarise(&frames, &inputs, eval.as_ref());
    let written = outputs::write_json(&out.join("summary.json"), &summary);
    // A summary that cannot be written is an output failure unless the run already failed
    // for a reason that explains it (the same disk, usually).
    let summary_written = written.is_ok();
    let failure = match (failure, written) {
        (None, Err(e)) => Some(RunFailure::Output(e)),
        (Some(f), Err(e)) => {
            warnings.push(format!("summary.json not written: {}", outputs::error_chain(&e)));
            Some(f)
        }
        (f, Ok(())) => f,
    };
    Ok(RunResult { frames, summary, eval, failure, eval_error, warnings, notices, summary_written })
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;

    fn feat(x: f32, y: f32) -> Feature {
        Feature { x, y, level: 0, angle: 0.0, desc: [0; 32], ur: -1.0, depth_m: 0.0, class: 8 }
    }

    /// Each wrongly removed feature lands in exactly one cause, from its object: joined to a
    /// moving one, tested moving, pending (measured, unproven) or unseen (unmeasured); each
    /// deferred feature on a moving object in pending or unseen.
    #[test]
    fn wrongly_removed_features_are_split_by_cause() {
        use FeatureMotion::*;
        // The mask marks x < 10 as moving.
        let mask = GrayImage::from_fn(40, 10, |x, _| Luma([if x < 10 { 255 } else { 0 }]));
        // (x, state, object, blocked: kept from making a landmark)
        type Case = (f32, FeatureMotion, Option<(u16, u32)>, bool);
        let cases: [Case; 11] = [
            (2.0, Moving, Some((0, 5)), true),     // true positive of object 0
            (12.0, Moving, Some((0, 5)), true),    // static, joined to object 0: joined
            (14.0, Moving, Some((2, 4)), true),    // static object 2 tested moving
            (16.0, Unproven, Some((3, 2)), true),  // static object 3, measured, unproven: pending
            (18.0, Unproven, Some((4, 0)), false), // static object 4, nothing measured: unseen, deferred
            (20.0, Parked, Some((5, 6)), false),   // kept, static: not counted
            (4.0, Parked, Some((6, 6)), false),    // kept, moving: false negative
            (6.0, Unproven, Some((7, 0)), false), // removed, moving: true positive, deferred, unseen
            (7.0, Unproven, Some((8, 3)), false), // the same, its object measured: pending (stereo)
            (30.0, Static, None, false),          // static class: not counted
            (8.0, Static, None, false),           // static class on the mask: false negative
        ];
        let mut feats: Vec<Feature> = cases.iter().map(|c| feat(c.0, 5.0)).collect();
        (feats[7].ur, feats[7].depth_m) = (1.0, 20.0);
        let states: Vec<FeatureMotion> = cases.iter().map(|c| c.1).collect();
        let blocked: Vec<bool> = cases.iter().map(|c| c.3).collect();
        let seg = |i: usize| cases[i].2.map(|(id, measured)| MotionSegment { id, measured });
        let c = score_moving(&feats, &states, &blocked, seg, &mask);
        assert_eq!((c.true_pos, c.false_pos, c.false_neg), (3, 4, 2));
        assert_eq!(
            (c.false_pos_joined, c.false_pos_tested, c.false_pos_pending, c.false_pos_unseen),
            (1, 1, 1, 1)
        );
        assert_eq!((c.tested_moving, c.tested_moving_true, c.tested_parked_moving), (3, 1, 1));
        // Withheld: the three deferred features (two on the mask) count as kept.
        assert_eq!((c.deferred, c.deferred_true), (3, 2));
        assert_eq!(
            (c.deferred_true_pending, c.deferred_true_unseen, c.deferred_true_depthless),
            (1, 1, 1)
        );
        assert_eq!((c.precision(), c.recall()), (3.0 / 7.0, 3.0 / 5.0));
        assert_eq!((c.withheld_precision(), c.withheld_recall()), (1.0 / 4.0, 1.0 / 5.0));
        let mut sum = c;
        sum.add(&c);
        assert_eq!((sum.false_pos, sum.false_pos_joined, sum.false_pos_unseen), (8, 2, 2));
        assert_eq!((sum.deferred, sum.deferred_true, sum.deferred_true_pending), (6, 4, 2));
    }
}
