//! The per-frame pipeline on the host: images → ORB (left ∥ right on two threads) → stereo
//! matching → tracker, with per-stage timings.
//!
//! All working memory is core's fixed-size state, created once: two ORB extractors, the stereo
//! matcher, one [`Frame`] and the [`Tracker`] (together ≈ 11 MiB, see
//! [`Pipeline::memory_bytes`]). These are far larger than a default thread stack, so
//! [`Pipeline::new`] builds them on a temporary thread with a big stack and hands back boxes.
//! After that, processing a frame allocates nothing in core; the host's only per-frame
//! allocations are image decoding and the scoped worker thread.

use std::time::Instant;

use image::GrayImage;
use semloc_core::frame::Frame;
use semloc_core::image::ImageView;
use semloc_core::image::ImageViewMut;
use semloc_core::orb::{KittiOrbExtractor, NoWeights, OrbConfig, OrbError};
use semloc_core::seg::{weight_image, WeightScheme};
use semloc_core::stereo::{KittiStereoMatcher, StereoError, StereoParams, StereoStats};
use semloc_core::tracker::{FrameReport, Tracker, TrackerError, TrackerParams};

use crate::dataset::{DatasetError, Sequence, StereoCalib};

/// Why the pipeline could not be built or could not process a frame.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// The calibration does not describe a usable camera.
    #[error("calibration unusable: {0}")]
    Calib(String),
    /// The tracker refused the configuration.
    #[error("tracker: {0}")]
    Tracker(#[from] TrackerError),
    /// ORB extraction failed (image larger than the extractor's capacity, …).
    #[error("ORB extraction on frame {frame} ({side} image): {err}")]
    Orb {
        /// Frame index.
        frame: usize,
        /// `left` or `right`.
        side: &'static str,
        /// The core error.
        err: OrbError,
    },
    /// Stereo matching failed.
    #[error("stereo matching on frame {frame}: {err}")]
    Stereo {
        /// Frame index.
        frame: usize,
        /// The core error.
        err: StereoError,
    },
    /// Loading a frame's images failed.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The worker thread died (a bug; reported, not propagated as a panic).
    #[error("worker thread failed: {0}")]
    Worker(String),
}

/// Milliseconds spent in each stage of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Decoding both PNGs (in parallel: the slower of the two).
    pub load_ms: f64,
    /// ORB on the left image.
    pub orb_left_ms: f64,
    /// ORB on the right image (in parallel with the left).
    pub orb_right_ms: f64,
    /// Wall time of the parallel load + extraction step.
    pub extract_wall_ms: f64,
    /// Stereo matching.
    pub stereo_ms: f64,
    /// Tracking (search, pose optimisation, keyframe, BA).
    pub track_ms: f64,
    /// Wall time of the whole frame, loading included.
    pub total_ms: f64,
    /// Wall time without image decoding: what the ECU pipeline would spend.
    pub compute_ms: f64,
}

/// Result of one frame.
#[derive(Clone, Copy, Debug)]
pub struct FrameOutput {
    /// The tracker's report (pose, counters).
    pub report: FrameReport,
    /// Stereo matching counters.
    pub stereo: StereoStats,
    /// Stage timings.
    pub times: StageTimes,
    /// Left-image FAST candidates dropped by a zero semantic weight (dynamic classes).
    pub culled: u32,
}

/// Core state for one stereo sequence.
pub struct Pipeline {
    left: Box<KittiOrbExtractor>,
    right: Box<KittiOrbExtractor>,
    stereo: Box<KittiStereoMatcher>,
    frame: Box<Frame>,
    tracker: Box<Tracker>,
    params: StereoParams,
    /// Worker threads: 1 runs everything on the caller's thread, 2 extracts left and right
    /// in parallel (the deployment setting: the machine has two cores).
    threads: usize,
    /// Semantic weighting of left-image features, if on.
    semantics: Option<WeightScheme>,
    /// Weight image buffer (host side; reused every frame).
    weights: Vec<u8>,
    /// The current frame's left labels, when semantics are on.
    labels: Option<GrayImage>,
}

/// Stack for threads that construct or run core's large fixed-size state.
pub const BIG_STACK_BYTES: usize = 64 << 20;

impl Pipeline {
    /// Builds the pipeline for `calib` and `width`x`height` images.
    pub fn new(
        calib: &StereoCalib,
        width: u32,
        height: u32,
        tracker_params: TrackerParams,
        threads: usize,
    ) -> Result<Self, PipelineError> {
        let cam = calib.to_camera().map_err(|e| PipelineError::Calib(e.to_string()))?;
        let params = StereoParams::new((cam.fx_px * cam.baseline_m) as f32, cam.baseline_m as f32);
        // Construct the multi-MiB structs where a big stack makes the by-value moves safe.
        let built = std::thread::Builder::new()
            .stack_size(BIG_STACK_BYTES)
            .spawn(move || -> Result<_, PipelineError> {
                let mut left = Box::new(KittiOrbExtractor::new());
                let mut right = Box::new(KittiOrbExtractor::new());
                left.configure(OrbConfig::KITTI).map_err(|err| PipelineError::Orb {
                    frame: 0,
                    side: "left",
                    err,
                })?;
                right.configure(OrbConfig::KITTI).map_err(|err| PipelineError::Orb {
                    frame: 0,
                    side: "right",
                    err,
                })?;
                let stereo = Box::new(KittiStereoMatcher::new());
                let frame = Box::new(Frame::new());
                let tracker = Box::new(Tracker::new(cam, width, height, tracker_params)?);
                Ok((left, right, stereo, frame, tracker))
            })
            .map_err(|e| PipelineError::Worker(e.to_string()))?
            .join()
            .map_err(|_| PipelineError::Worker("constructor thread panicked".into()))??;
        let (left, right, stereo, frame, tracker) = built;
        Ok(Self {
            left,
            right,
            stereo,
            frame,
            tracker,
            params,
            threads: threads.clamp(1, 2),
            semantics: None,
            weights: Vec::new(),
            labels: None,
        })
    }

    /// Bytes of core state this pipeline holds (extractors, matcher, frame, tracker).
    pub fn memory_bytes() -> usize {
        2 * core::mem::size_of::<KittiOrbExtractor>()
            + core::mem::size_of::<KittiStereoMatcher>()
            + core::mem::size_of::<Frame>()
            + core::mem::size_of::<Tracker>()
    }

    /// Weights left-image features by semantic class (labels from the sequence's `semantic/`
    /// folder, see [`Sequence::load_labels`]); `None` turns it off.
    pub fn set_semantics(&mut self, scheme: Option<WeightScheme>) {
        self.semantics = scheme;
    }

    /// The tracker (for counters and the window).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// Loads frame `i` of `seq` and processes it.
    pub fn process_sequence_frame(
        &mut self,
        seq: &Sequence,
        i: usize,
    ) -> Result<FrameOutput, PipelineError> {
        let t0 = Instant::now();
        let ts = seq.times_s.get(i).copied().unwrap_or(i as f64 * 0.1);
        let (left_ex, right_ex) = (&mut self.left, &mut self.right);
        let (scheme, weights, kept) = (self.semantics, &mut self.weights, &mut self.labels);
        let mut left_side = |ex: &mut KittiOrbExtractor| -> Result<(f64, f64), PipelineError> {
            let t = Instant::now();
            let img = seq.load_luma_side(i, false)?;
            *kept = scheme.map(|_| seq.load_labels(i)).transpose()?;
            let load = ms(t);
            let t = Instant::now();
            match (scheme, kept.as_ref()) {
                (Some(scheme), Some(labels)) => {
                    extract_weighted(ex, &img, labels, scheme, weights, i)?
                }
                _ => extract(ex, &img, i, "left")?,
            }
            Ok((load, ms(t)))
        };
        let right_side = |ex: &mut KittiOrbExtractor| -> Result<(f64, f64), PipelineError> {
            let t = Instant::now();
            let img = seq.load_luma_side(i, true)?;
            let load = ms(t);
            let t = Instant::now();
            extract(ex, &img, i, "right")?;
            Ok((load, ms(t)))
        };
        let ((_, orb_left_ms), (_, orb_right_ms), load_ms) = if self.threads >= 2 {
            let (l, r) = std::thread::scope(|s| {
                let h = s.spawn(|| right_side(right_ex));
                let l = left_side(left_ex);
                (l, h.join())
            });
            let l = l?;
            let r =
                r.map_err(|_| PipelineError::Worker("right-image worker panicked".into()))??;
            (l, r, l.0.max(r.0))
        } else {
            let l = left_side(left_ex)?;
            let r = right_side(right_ex)?;
            (l, r, l.0 + r.0)
        };
        let extract_wall_ms = ms(t0);
        let (stereo, stereo_ms, report, track_ms) = self.match_and_track(i, ts)?;
        let total_ms = ms(t0);
        let times = StageTimes {
            load_ms,
            orb_left_ms,
            orb_right_ms,
            extract_wall_ms,
            stereo_ms,
            track_ms,
            total_ms,
            compute_ms: total_ms - load_ms,
        };
        Ok(FrameOutput { report, stereo, times, culled: self.culled() })
    }

    /// Candidates the left extractor dropped for a zero weight on the last frame.
    fn culled(&self) -> u32 {
        self.left.features().stats().levels().iter().map(|l| l.weight_dropped).sum()
    }

    /// Processes one stereo pair given as luma images (for callers with images in memory).
    pub fn process_images(
        &mut self,
        left: &GrayImage,
        right: &GrayImage,
        index: usize,
        timestamp_s: f64,
    ) -> Result<FrameOutput, PipelineError> {
        let t0 = Instant::now();
        self.labels = None;
        let (orb_left_ms, orb_right_ms) = if self.threads >= 2 {
            let (left_ex, right_ex) = (&mut self.left, &mut self.right);
            let (l, r) = std::thread::scope(|s| {
                let h = s.spawn(|| timed(|| extract(right_ex, right, index, "right")));
                let l = timed(|| extract(left_ex, left, index, "left"));
                (l, h.join())
            });
            let (lr, lt) = l;
            let (rr, rt) =
                r.map_err(|_| PipelineError::Worker("right-image worker panicked".into()))?;
            lr?;
            rr?;
            (lt, rt)
        } else {
            let (lr, lt) = timed(|| extract(&mut self.left, left, index, "left"));
            lr?;
            let (rr, rt) = timed(|| extract(&mut self.right, right, index, "right"));
            rr?;
            (lt, rt)
        };
        let extract_wall_ms = ms(t0);
        let (stereo, stereo_ms, report, track_ms) = self.match_and_track(index, timestamp_s)?;
        let total_ms = ms(t0);
        let times = StageTimes {
            load_ms: 0.0,
            orb_left_ms,
            orb_right_ms,
            extract_wall_ms,
            stereo_ms,
            track_ms,
            total_ms,
            compute_ms: total_ms,
        };
        Ok(FrameOutput { report, stereo, times, culled: 0 })
    }

    fn match_and_track(
        &mut self,
        index: usize,
        timestamp_s: f64,
    ) -> Result<(StereoStats, f64, FrameReport, f64), PipelineError> {
        let t = Instant::now();
        let stats = self
            .stereo
            .match_frame(
                self.left.features(),
                self.left.pyramid(),
                self.right.features(),
                self.right.pyramid(),
                &self.params,
                timestamp_s,
                &mut self.frame,
            )
            .map_err(|err| PipelineError::Stereo { frame: index, err })?;
        if let Some(labels) = &self.labels {
            // Class and semantic descriptor per feature, for the EM association.
            let (w, h) = (labels.width() as usize, labels.height() as usize);
            let lv = ImageView::from_slice(labels.as_raw(), w, h)
                .map_err(|e| PipelineError::Orb { frame: index, side: "left", err: e.into() })?;
            semloc_core::assoc::annotate(&mut self.frame, &lv);
        }
        let stereo_ms = ms(t);
        let t = Instant::now();
        let report = self.tracker.process(&self.frame);
        Ok((stats, stereo_ms, report, ms(t)))
    }
}

fn extract(
    ex: &mut KittiOrbExtractor,
    img: &GrayImage,
    frame: usize,
    side: &'static str,
) -> Result<(), PipelineError> {
    let view = ImageView::from_slice(img.as_raw(), img.width() as usize, img.height() as usize)
        .map_err(|e| PipelineError::Orb { frame, side, err: e.into() })?;
    ex.extract_weighted(&view, &NoWeights).map_err(|err| PipelineError::Orb {
        frame,
        side,
        err,
    })?;
    Ok(())
}

/// ORB on `img` with the semantic weight image of `labels` (built in `buf`).
fn extract_weighted(
    ex: &mut KittiOrbExtractor,
    img: &GrayImage,
    labels: &GrayImage,
    scheme: WeightScheme,
    buf: &mut Vec<u8>,
    frame: usize,
) -> Result<(), PipelineError> {
    let (w, h) = (labels.width() as usize, labels.height() as usize);
    buf.resize(w * h, 0);
    let orb = |err: OrbError| PipelineError::Orb { frame, side: "left", err };
    let lv = ImageView::from_slice(labels.as_raw(), w, h).map_err(|e| orb(e.into()))?;
    let mut wv = ImageViewMut::from_slice(buf, w, h).map_err(|e| orb(e.into()))?;
    weight_image(&lv, scheme, &mut wv).map_err(|e| orb(e.into()))?;
    let view = ImageView::from_slice(img.as_raw(), img.width() as usize, img.height() as usize)
        .map_err(|e| orb(e.into()))?;
    let weights = ImageView::from_slice(buf, w, h).map_err(|e| orb(e.into()))?;
    ex.extract_weighted(&view, &weights).map_err(orb)?;
    Ok(())
}

fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let r = f();
    (r, ms(t))
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
