//! The files of a run and the `summary.json` schema: `trajectory.txt` (KITTI poses),
//! `trajectory_tum.txt`, `frames.csv` (one row of stage timings and counters per frame),
//! `summary.json`, and with ground truth `eval.json` and `plots/`.
//!
//! Field names are the file's keys and columns; they are a published format (README, scripts
//! in `models/` and CI read them), so they change only with a note there. Memory: the text of
//! one trajectory file at a time (about 200 bytes per frame).

use std::collections::BTreeMap;
use std::path::Path;

use semloc_core::geom::Se3;
use semloc_core::tracker::TrackerStats;

use super::stats::{column, median, stage_percentiles, Percentiles};
use super::{association_name, FrameRecord, MovingCheck, Provenance, RunError, RunFailure};
use crate::dataset::{DatasetSummary, Sequence};
use crate::eval::{evaluate, Align, EvalReport};

/// One row of `frames.csv`: its fields, in order, are the columns (the header is made from
/// them, see [`frames_csv_header`]). Times in ms with three decimals, the timestamp in s with
/// six, flags as 0/1, the status by name (`initialised`, `tracked`, `lost`, `coasted`,
/// `reinitialised`: see `semloc_core::tracker::FrameStatus`). docs/outputs.md documents every
/// column (a test checks it).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameRow {
    /// Frame index in the sequence (0-based).
    pub frame: u32,
    /// Frame time (s from the source's time zero).
    #[serde(serialize_with = "fixed6")]
    pub timestamp_s: f64,
    /// The part of the frame's wall time spent decoding images (ms; `total_ms - compute_ms`).
    #[serde(serialize_with = "fixed3")]
    pub load_ms: f64,
    /// ORB extraction on the left image (ms; with two threads, made while the previous frame
    /// was tracked).
    #[serde(serialize_with = "fixed3")]
    pub orb_left_ms: f64,
    /// ORB extraction on the right image (ms).
    #[serde(serialize_with = "fixed3")]
    pub orb_right_ms: f64,
    /// Wall time until the frame's features were extracted (ms; 0 when the previous frame made
    /// them).
    #[serde(serialize_with = "fixed3")]
    pub extract_wall_ms: f64,
    /// Stereo matching (ms).
    #[serde(serialize_with = "fixed3")]
    pub stereo_ms: f64,
    /// Tracking: search, pose optimisation, keyframe, BA (ms).
    #[serde(serialize_with = "fixed3")]
    pub track_ms: f64,
    /// Semantic segmentation by the network (ms; 0 without one).
    #[serde(serialize_with = "fixed3")]
    pub seg_ms: f64,
    /// Wall time without image decoding (ms): what the ECU pipeline would spend.
    #[serde(serialize_with = "fixed3")]
    pub compute_ms: f64,
    /// Wall time of the whole frame, loading included (ms).
    #[serde(serialize_with = "fixed3")]
    pub total_ms: f64,
    /// Left features with a stereo match.
    pub stereo_matches: u32,
    /// Landmark matches found by the projection search (final pass).
    pub matched: u32,
    /// Matches that survived pose optimisation.
    pub inliers: u32,
    /// 1 when the frame became a keyframe.
    pub keyframe: u8,
    /// 1 on the frame where tracking failed.
    pub lost: u8,
    /// 1 when the map was (re-)initialised on this frame.
    pub initialised: u8,
    /// Live landmarks after the frame.
    pub landmarks: u32,
    /// Keyframes in the map after the frame.
    pub keyframes: u32,
    /// Local BA iterations run.
    pub ba_iterations: u32,
    /// Features dropped by semantic culling.
    pub culled: u32,
    /// Features whose EM association differs from the nearest-neighbour candidate.
    pub em_changed: u32,
    /// Motion-aware semantics: dynamic-class features used as parked.
    pub parked: u32,
    /// Motion-aware semantics: features removed as moving.
    pub moving: u32,
    /// Motion-aware semantics: features removed as unproven.
    pub unproven: u32,
    /// How the pose was obtained.
    pub status: &'static str,
}

fn fixed3<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(&format_args!("{v:.3}"))
}

fn fixed6<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(&format_args!("{v:.6}"))
}

impl FrameRow {
    /// The row of frame record `r`.
    pub fn of(r: &FrameRecord) -> Self {
        let (o, rep) = (&r.output, &r.output.report);
        let s = o.times;
        Self {
            frame: rep.frame_index,
            timestamp_s: r.timestamp_s,
            load_ms: s.load_ms,
            orb_left_ms: s.orb_left_ms,
            orb_right_ms: s.orb_right_ms,
            extract_wall_ms: s.extract_wall_ms,
            stereo_ms: s.stereo_ms,
            track_ms: s.track_ms,
            seg_ms: s.seg_ms,
            compute_ms: s.compute_ms,
            total_ms: s.total_ms,
            stereo_matches: o.stereo.matched,
            matched: rep.matched,
            inliers: rep.inliers,
            keyframe: u8::from(rep.keyframe),
            lost: u8::from(rep.lost),
            initialised: u8::from(rep.initialised),
            landmarks: rep.landmarks,
            keyframes: rep.keyframes,
            ba_iterations: rep.ba_iterations,
            culled: o.culled,
            em_changed: rep.em_changed,
            parked: rep.motion.parked_features,
            moving: rep.motion.moving_features,
            unproven: rep.motion.unproven_features,
            status: rep.status.name(),
        }
    }
}

/// `row` as CSV (`header`: the header line before it), newline included, ready for one write.
fn csv_text(row: &FrameRow, header: bool) -> Result<String, csv::Error> {
    let mut w = csv::WriterBuilder::new().has_headers(header).from_writer(Vec::new());
    w.serialize(row)?;
    let bytes = w.into_inner().map_err(|e| csv::Error::from(e.into_error()))?;
    // Every field is a number or an ASCII name.
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

/// The header line of `frames.csv` (no newline): [`FrameRow`]'s field names.
pub fn frames_csv_header() -> &'static str {
    static HEADER: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HEADER.get_or_init(|| {
        let text = csv_text(&FrameRow::default(), true).unwrap_or_default();
        text.lines().next().unwrap_or_default().to_owned()
    })
}

/// What `summary.json` holds.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[allow(missing_docs)] // field names are the JSON keys; see the README
pub struct Summary {
    /// Every requested frame was processed and every output written.
    pub complete: bool,
    /// What ended the run early: `signal`, `frame_error` or `output_error` (`null` when
    /// complete).
    pub stopped_by: Option<&'static str>,
    /// The message of what ended it.
    pub stop_reason: Option<String>,
    pub frames_requested: usize,
    pub dataset: DatasetSummary,
    pub frames_processed: usize,
    pub threads: u8,
    pub keyframes: u32,
    /// Frames whose pose was extrapolated, not measured (`frames.csv` status `lost`,
    /// `coasted` or `reinitialised`).
    pub lost: u32,
    /// Times tracking was lost (a run of lost frames is one loss).
    pub losses: u32,
    pub landmark_overflow: u32,
    pub keyframe_evictions: u32,
    pub observation_overflow: u32,
    pub keyframes_culled: u32,
    pub landmarks_triangulated: u32,
    pub landmarks_fused: u32,
    pub core_memory_bytes: usize,
    pub network_memory_bytes: usize,
    pub median_stereo_matches: f64,
    pub median_inliers: f64,
    pub semantics: String,
    pub association: String,
    pub median_culled: f64,
    pub em_changed_total: u64,
    pub motion: Option<MotionSummary>,
    pub timing: BTreeMap<&'static str, Percentiles>,
    pub eval: Option<EvalSummary>,
    /// Why there is no evaluation (or why writing it failed) although there is ground truth.
    pub eval_error: Option<String>,
    /// Everything the user was warned about.
    pub warnings: Vec<String>,
    /// What the run was made from.
    pub provenance: Provenance,
}

/// Motion-aware semantics' totals inside `summary.json` (`null` with other settings).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[allow(missing_docs)]
pub struct MotionSummary {
    /// Dynamic-class features used as parked, removed as moving, removed as unproven.
    pub parked_features: u32,
    pub moving_features: u32,
    pub unproven_features: u32,
    /// Against the source's moving-object mask, when it has one (`semloc synth`'s `dynamic/`):
    /// the summed counts, precision and recall of "removed" (moving or unproven), and of the
    /// "moving" verdict alone (tested moving; unproven features left out), and of "withheld"
    /// (kept out of the pose or the map: removed, less the unproven features free to make a
    /// landmark, which are treated as parked ones are).
    pub moving_check: Option<MovingCheck>,
    pub moving_precision: Option<f64>,
    pub moving_recall: Option<f64>,
    pub withheld_precision: Option<f64>,
    pub withheld_recall: Option<f64>,
    pub tested_moving_precision: Option<f64>,
    pub tested_moving_recall: Option<f64>,
}

/// The evaluation figures inside `summary.json`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[allow(missing_docs)]
pub struct EvalSummary {
    pub align: String,
    /// The alignment's rotation (deg): large values mean the estimate only matches the ground
    /// truth turned around (see `eval.json`'s warnings).
    pub alignment_rotation_deg: f64,
    /// How far the alignment turns the direction of travel (deg; see `eval.json`).
    pub alignment_heading_deg: f64,
    pub ate_rmse_m: f64,
    pub t_rel_pct: Option<f64>,
    pub r_rel_deg_per_100m: Option<f64>,
    pub path_length_m: f64,
    pub rpe_1f_trans_rmse_m: Option<f64>,
    pub rpe_1f_rot_rmse_deg: Option<f64>,
    pub rpe_10m_trans_rmse_pct: Option<f64>,
    pub rpe_10m_rot_rmse_deg: Option<f64>,
}

impl From<&EvalReport> for EvalSummary {
    fn from(e: &EvalReport) -> Self {
        Self {
            align: e.align.to_string(),
            alignment_rotation_deg: e.alignment_rotation_deg,
            alignment_heading_deg: e.alignment_heading_deg,
            ate_rmse_m: e.ate_rmse_m,
            t_rel_pct: e.t_rel_pct,
            r_rel_deg_per_100m: e.r_rel_deg_per_100m,
            path_length_m: e.path_length_m,
            rpe_1f_trans_rmse_m: e.rpe_1f.as_ref().map(|r| r.trans_m.rmse),
            rpe_1f_rot_rmse_deg: e.rpe_1f.as_ref().map(|r| r.rot_deg.rmse),
            rpe_10m_trans_rmse_pct: e.rpe_10m.as_ref().and_then(|r| r.trans_pct).map(|s| s.rmse),
            rpe_10m_rot_rmse_deg: e.rpe_10m.as_ref().map(|r| r.rot_deg.rmse),
        }
    }
}

/// What [`Summary`] is made of besides the records.
pub(super) struct SummaryInputs<'a> {
    pub seq: &'a Sequence,
    pub threads: u8,
    pub semantics: &'static str,
    pub association: semloc_core::assoc::Association,
    /// The `segment` timing row is reported (a network labelled the frames).
    pub segment_timed: bool,
    pub stats: TrackerStats,
    pub core_memory_bytes: usize,
    pub network_memory_bytes: usize,
    pub frames_requested: usize,
    pub failure: Option<&'a RunFailure>,
    pub eval_error: Option<&'a RunError>,
    pub warnings: &'a [String],
    pub provenance: Provenance,
}

/// An error and its causes on one line, each once (`a: b: c`).
pub fn error_chain(e: &dyn core::error::Error) -> String {
    let mut parts = vec![e.to_string()];
    let mut cur = e.source();
    while let Some(c) = cur {
        let text = c.to_string();
        // Messages that already quote their cause are not repeated.
        if !parts.iter().any(|p| p.contains(&text)) {
            parts.push(text);
        }
        cur = c.source();
    }
    parts.join(": ")
}

/// Builds `summary.json`'s content.
pub(super) fn summarise(
    frames: &[FrameRecord],
    inputs: &SummaryInputs<'_>,
    eval: Option<&EvalReport>,
) -> Summary {
    let counter = |f: fn(&FrameRecord) -> f64| median(column(frames, f));
    Summary {
        complete: inputs.failure.is_none(),
        stopped_by: inputs.failure.map(RunFailure::stopped_by),
        stop_reason: inputs.failure.map(|f| error_chain(f)),
        frames_requested: inputs.frames_requested,
        dataset: inputs.seq.summary(),
        frames_processed: frames.len(),
        threads: inputs.threads,
        keyframes: inputs.stats.keyframes,
        lost: inputs.stats.untracked_frames,
        losses: inputs.stats.lost,
        landmark_overflow: inputs.stats.landmark_overflow,
        keyframe_evictions: inputs.stats.keyframe_evictions,
        observation_overflow: inputs.stats.observation_overflow,
        keyframes_culled: inputs.stats.keyframes_culled,
        landmarks_triangulated: inputs.stats.triangulated,
        landmarks_fused: inputs.stats.landmarks_fused,
        core_memory_bytes: inputs.core_memory_bytes,
        network_memory_bytes: inputs.network_memory_bytes,
        median_stereo_matches: counter(|r| f64::from(r.output.stereo.matched)),
        median_inliers: counter(|r| f64::from(r.output.report.inliers)),
        semantics: inputs.semantics.to_owned(),
        association: association_name(inputs.association),
        em_changed_total: frames.iter().map(|r| u64::from(r.output.report.em_changed)).sum(),
        median_culled: counter(|r| f64::from(r.output.culled)),
        motion: (inputs.semantics == super::Semantics::Motion.name())
            .then(|| motion_summary(frames, &inputs.stats)),
        timing: stage_percentiles(frames, inputs.segment_timed),
        eval: eval.map(EvalSummary::from),
        eval_error: inputs.eval_error.map(|e| error_chain(e)),
        warnings: inputs.warnings.to_vec(),
        provenance: inputs.provenance.clone(),
    }
}

fn motion_summary(frames: &[FrameRecord], stats: &TrackerStats) -> MotionSummary {
    let mut check: Option<MovingCheck> = None;
    for c in frames.iter().filter_map(|r| r.moving_check.as_ref()) {
        check.get_or_insert_with(MovingCheck::default).add(c);
    }
    let finite = |x: f64| x.is_finite().then_some(x);
    MotionSummary {
        parked_features: stats.parked_features,
        moving_features: stats.moving_features,
        unproven_features: stats.unproven_features,
        moving_precision: check.and_then(|c| finite(c.precision())),
        moving_recall: check.and_then(|c| finite(c.recall())),
        withheld_precision: check.and_then(|c| finite(c.withheld_precision())),
        withheld_recall: check.and_then(|c| finite(c.withheld_recall())),
        tested_moving_precision: check.and_then(|c| finite(c.tested_precision())),
        tested_moving_recall: check.and_then(|c| finite(c.tested_recall())),
        moving_check: check,
    }
}

/// One `frames.csv` row (newline included): [`FrameRow::of`] `r` written by the `csv` crate.
pub fn frames_csv_row(r: &FrameRecord) -> Result<String, csv::Error> {
    csv_text(&FrameRow::of(r), false)
}

/// Evaluates `poses` against `gt` (the same length, at least three poses) and writes
/// `eval.json` and `plots/` into `out` (`times_s`: each frame's time for the over-time plots); the evaluation's warnings (e.g. a large alignment
/// rotation) are appended to `warnings`. Returns the report when the evaluation worked, and
/// the error when it or writing it failed (both when only the writing failed).
pub fn write_eval(
    out: &Path,
    gt: &[Se3],
    poses: &[Se3],
    align: Align,
    times_s: &[f64],
    warnings: &mut Vec<String>,
) -> (Option<EvalReport>, Option<RunError>) {
    let report = match evaluate(gt, poses, align) {
        Ok(r) => r,
        Err(e) => return (None, Some(RunError::Eval(e))),
    };
    warnings.extend(report.warnings.iter().cloned());
    if let Err(e) = write_json(&out.join("eval.json"), &report) {
        return (Some(report), Some(e));
    }
    let plots = out.join("plots");
    if let Err(source) = std::fs::create_dir_all(&plots) {
        return (Some(report), Some(RunError::Create { path: plots, source }));
    }
    if let Err(e) = crate::plot::write_eval_plots(&plots, gt, &report, Some(times_s)) {
        return (Some(report), Some(RunError::Plot(e)));
    }
    (Some(report), None)
}

/// Written through a temporary file and a rename: a reader never sees half of it.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<(), RunError> {
    let text = serde_json::to_string_pretty(value)?;
    super::stream::write_atomic(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The header is the published column list (README, scripts), now made from [`FrameRow`].
    #[test]
    fn frames_csv_header_is_the_published_one() {
        assert_eq!(
            frames_csv_header(),
            "frame,timestamp_s,load_ms,orb_left_ms,orb_right_ms,extract_wall_ms,stereo_ms,\
             track_ms,seg_ms,compute_ms,total_ms,stereo_matches,matched,inliers,keyframe,lost,\
             initialised,landmarks,keyframes,ba_iterations,culled,em_changed,parked,moving,\
             unproven,status"
        );
    }

    /// A row: one line, fixed decimals, flags as 0/1, the status by name.
    #[test]
    fn frames_csv_row_formats_like_before() {
        let row = FrameRow {
            frame: 7,
            timestamp_s: 0.7,
            load_ms: 1.23456,
            keyframe: 1,
            status: "tracked",
            ..FrameRow::default()
        };
        let text = csv_text(&row, false).unwrap();
        assert_eq!(
            text,
            "7,0.700000,1.235,0.000,0.000,0.000,0.000,0.000,0.000,0.000,0.000,0,0,0,1,0,0,0,0,0,\
             0,0,0,0,0,tracked\n"
        );
    }
}
