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
use semloc_core::nn::graph::Kernels;
use semloc_core::orb::{KittiOrbExtractor, NoWeights, OrbConfig, OrbError};
use semloc_core::seg::{weight_image, WeightScheme};
use semloc_core::stereo::{KittiStereoMatcher, StereoError, StereoParams, StereoStats};
use semloc_core::tracker::{FrameReport, Tracker, TrackerError, TrackerParams};

use std::borrow::Cow;

use crate::dataset::{DatasetError, Sequence, StereoCalib};
use crate::nn::segment::Segmenter;
use crate::nn::NnFileError;

/// Where a pipeline gets a frame's images (and, without a network, its labels).
pub trait FrameSource: Sync {
    /// Number of frames.
    fn len(&self) -> usize;
    /// True when there are no frames.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Frame `i`'s left luma image.
    fn left(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError>;
    /// Frame `i`'s right luma image.
    fn right(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError>;
    /// Frame `i`'s left labels from the dataset (used when no network is set).
    fn labels(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError>;
    /// Frame `i`'s timestamp in seconds.
    fn timestamp_s(&self, i: usize) -> f64;
}

impl FrameSource for Sequence {
    fn len(&self) -> usize {
        Sequence::len(self)
    }
    fn left(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        Ok(Cow::Owned(self.load_luma_side(i, false)?))
    }
    fn right(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        Ok(Cow::Owned(self.load_luma_side(i, true)?))
    }
    fn labels(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        Ok(Cow::Owned(self.load_labels(i)?))
    }
    fn timestamp_s(&self, i: usize) -> f64 {
        self.times_s.get(i).copied().unwrap_or(i as f64 * 0.1)
    }
}

/// Frames already decoded in memory (benchmarks, synthetic runs): frame `first_index + k` is
/// `left[k]`, `right[k]`.
#[derive(Clone, Copy, Debug)]
pub struct MemoryFrames<'a> {
    /// Left luma images.
    pub left: &'a [GrayImage],
    /// Right luma images.
    pub right: &'a [GrayImage],
    /// Left labels, if the frames come with them.
    pub labels: Option<&'a [GrayImage]>,
    /// Index of the first frame.
    pub first_index: usize,
    /// Timestamps (missing ones: 10 Hz).
    pub times_s: &'a [f64],
}

impl MemoryFrames<'_> {
    fn get<'b>(&self, v: &'b [GrayImage], i: usize) -> Result<&'b GrayImage, PipelineError> {
        i.checked_sub(self.first_index)
            .and_then(|k| v.get(k))
            .ok_or_else(|| PipelineError::Worker(format!("frame {i} is not in memory")))
    }
}

impl FrameSource for MemoryFrames<'_> {
    fn len(&self) -> usize {
        self.first_index + self.left.len().min(self.right.len())
    }
    fn left(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        self.get(self.left, i).map(Cow::Borrowed)
    }
    fn right(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        self.get(self.right, i).map(Cow::Borrowed)
    }
    fn labels(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        match self.labels {
            Some(l) => self.get(l, i).map(Cow::Borrowed),
            None => Err(PipelineError::Worker(format!("frame {i} has no labels in memory"))),
        }
    }
    fn timestamp_s(&self, i: usize) -> f64 {
        i.checked_sub(self.first_index)
            .and_then(|k| self.times_s.get(k))
            .copied()
            .unwrap_or(i as f64 * 0.1)
    }
}

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
    /// The segmentation network failed on a frame.
    #[error("segmentation of frame {frame}: {err}")]
    Segment {
        /// Frame index.
        frame: usize,
        /// The model file's error.
        err: NnFileError,
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
    /// Network segmentation of this frame's left image (run on the second thread while the
    /// previous frame was tracked, when two threads are used); 0 without a network.
    pub seg_ms: f64,
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

/// Left-image ORB features counted by the category (the paper's Table 1) of the label under
/// each key point: the measure of the paper's Fig. 4 (share of features on static structure).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[allow(missing_docs)] // one counter per category, named as `semloc_core::seg::Category`
pub struct CategoryCounts {
    pub human: u64,
    pub vehicle: u64,
    pub construction: u64,
    pub object: u64,
    pub flat: u64,
    pub nature: u64,
    pub sky: u64,
    pub void: u64,
}

impl CategoryCounts {
    /// Counts one feature of label `class`.
    pub fn add(&mut self, class: u8) {
        use semloc_core::seg::Category as C;
        *match semloc_core::seg::category(class) {
            C::Human => &mut self.human,
            C::Vehicle => &mut self.vehicle,
            C::Construction => &mut self.construction,
            C::Object => &mut self.object,
            C::Flat => &mut self.flat,
            C::Nature => &mut self.nature,
            C::Sky => &mut self.sky,
            C::Void => &mut self.void,
        } += 1;
    }

    /// Adds another tally.
    pub fn merge(&mut self, o: &CategoryCounts) {
        self.human += o.human;
        self.vehicle += o.vehicle;
        self.construction += o.construction;
        self.object += o.object;
        self.flat += o.flat;
        self.nature += o.nature;
        self.sky += o.sky;
        self.void += o.void;
    }

    /// All features.
    pub fn total(&self) -> u64 {
        self.human
            + self.vehicle
            + self.construction
            + self.object
            + self.flat
            + self.nature
            + self.sky
            + self.void
    }

    /// Features on static structure (construction and object classes, weighted ×3).
    pub fn structure(&self) -> u64 {
        self.construction + self.object
    }

    /// Features on dynamic classes (human, vehicle).
    pub fn dynamic(&self) -> u64 {
        self.human + self.vehicle
    }

    /// `part` as a percentage of all features (0 when there are none).
    pub fn pct(&self, part: u64) -> f64 {
        let t = self.total();
        if t == 0 {
            0.0
        } else {
            100.0 * part as f64 / t as f64
        }
    }
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
    /// The network that labels left frames when semantics are on (else the dataset's labels).
    segmenter: Option<Segmenter>,
    /// The next frame's left image and labels, made while this frame was tracked.
    prefetched: Option<Prefetch>,
}

/// A frame segmented ahead of its turn.
struct Prefetch {
    index: usize,
    left: GrayImage,
    labels: GrayImage,
    seg_ms: f64,
    load_ms: f64,
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
            segmenter: None,
            prefetched: None,
        })
    }

    /// Bytes of core state this pipeline holds (extractors, matcher, frame, tracker).
    pub fn memory_bytes() -> usize {
        2 * core::mem::size_of::<KittiOrbExtractor>()
            + core::mem::size_of::<KittiStereoMatcher>()
            + core::mem::size_of::<Frame>()
            + core::mem::size_of::<Tracker>()
    }

    /// Weights left-image features by semantic class; `None` turns it off. Labels come from
    /// the network set with [`Pipeline::set_segmenter`], else from the sequence's `semantic/`
    /// folder (see [`Sequence::load_labels`]).
    pub fn set_semantics(&mut self, scheme: Option<WeightScheme>) {
        self.semantics = scheme;
    }

    /// Labels left frames with the int8 network (pipelined on the second thread). The
    /// network's input must take this pipeline's frames (see [`Segmenter::letterbox`]).
    pub fn set_segmenter(&mut self, segmenter: Segmenter) {
        self.segmenter = Some(segmenter);
        self.prefetched = None;
    }

    /// The network segmenter, if one is set.
    pub fn segmenter(&self) -> Option<&Segmenter> {
        self.segmenter.as_ref()
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
        self.process_frame(seq, i)
    }

    /// Processes one stereo pair given as luma images (for callers with images in memory). With
    /// semantics on, its labels come from the network (no prefetch: a single pair has no next
    /// frame).
    pub fn process_images(
        &mut self,
        left: &GrayImage,
        right: &GrayImage,
        index: usize,
        timestamp_s: f64,
    ) -> Result<FrameOutput, PipelineError> {
        let pair = MemoryFrames {
            left: core::slice::from_ref(left),
            right: core::slice::from_ref(right),
            labels: None,
            first_index: index,
            times_s: &[timestamp_s],
        };
        self.process_frame(&pair, index)
    }

    /// Processes frame `i` of `src`. With two threads the second one extracts the right
    /// image's ORB and then, while this thread matches and tracks frame `i`, decodes and
    /// segments frame `i + 1` (when a network labels the frames), so a frame costs
    /// max(segmentation, tracking) rather than their sum. One thread does the same steps in
    /// sequence; the results are identical.
    pub fn process_frame(
        &mut self,
        src: &(impl FrameSource + ?Sized),
        i: usize,
    ) -> Result<FrameOutput, PipelineError> {
        let t0 = Instant::now();
        let ts = src.timestamp_s(i);
        let scheme = self.semantics;
        let use_net = scheme.is_some() && self.segmenter.is_some();
        // Frame i's left image and labels: prefetched by the previous frame, or made now.
        let prefetched = self.prefetched.take().filter(|p| p.index == i);
        let mut seg_ms = 0.0;
        let mut seg_load_ms = 0.0;
        let (left_img, labels): (Option<GrayImage>, Option<GrayImage>) = match prefetched {
            Some(p) => {
                seg_ms = p.seg_ms;
                (Some(p.left), Some(p.labels))
            }
            None if use_net => {
                let t = Instant::now();
                let img = src.left(i)?.into_owned();
                seg_load_ms = ms(t);
                let t = Instant::now();
                let seg = self
                    .segmenter
                    .as_mut()
                    .ok_or_else(|| PipelineError::Worker("segmenter vanished".into()))?;
                let labels = segment(seg, &img, i)?;
                seg_ms = ms(t);
                (Some(img), Some(labels))
            }
            None => (None, None),
        };
        let next = (use_net && i + 1 < src.len()).then_some(i + 1);
        let threads = self.threads;
        let Pipeline { left, right, stereo, frame, tracker, params, segmenter, weights, .. } = self;
        let (left_ex, right_ex, seg) = (&mut **left, &mut **right, segmenter.as_mut());
        let (stereo, frame, tracker, params) =
            (&mut **stereo, &mut **frame, &mut **tracker, &*params);

        // The right image: load and extract (the second thread's first job).
        let right_work = |ex: &mut KittiOrbExtractor| -> Result<(f64, f64), PipelineError> {
            let t = Instant::now();
            let img = src.right(i)?;
            let load = ms(t);
            let t = Instant::now();
            extract(ex, &img, i, "right")?;
            Ok((load, ms(t)))
        };
        // The next frame's labels (the second thread's second job).
        let seg_work = |seg: Option<&mut Segmenter>| -> Result<Option<Prefetch>, PipelineError> {
            let (Some(j), Some(seg)) = (next, seg) else { return Ok(None) };
            let t = Instant::now();
            let img = src.left(j)?.into_owned();
            let load_ms = ms(t);
            let t = Instant::now();
            let labels = segment(seg, &img, j)?;
            Ok(Some(Prefetch { index: j, left: img, labels, seg_ms: ms(t), load_ms }))
        };
        // This thread: left image, weighted ORB; then (with the right features) stereo + track.
        let left_work =
            |ex: &mut KittiOrbExtractor,
             weights: &mut Vec<u8>|
             -> Result<(GrayImage, Option<GrayImage>, f64, f64), PipelineError> {
                let t = Instant::now();
                let img = match left_img {
                    Some(img) => img,
                    None => src.left(i)?.into_owned(),
                };
                let labels = match (scheme, labels) {
                    (Some(_), Some(l)) => Some(l),
                    (Some(_), None) => Some(src.labels(i)?.into_owned()),
                    (None, _) => None,
                };
                let load = ms(t);
                let t = Instant::now();
                match (scheme, labels.as_ref()) {
                    (Some(scheme), Some(l)) => extract_weighted(ex, &img, l, scheme, weights, i)?,
                    _ => extract(ex, &img, i, "left")?,
                }
                Ok((img, labels, load, ms(t)))
            };

        // Stereo + tracking once both extractions are done (the same call in both schedules).
        let mut match_track =
            |left: &KittiOrbExtractor, right: &KittiOrbExtractor, labels: Option<&GrayImage>| {
                match_and_track(left, right, stereo, frame, tracker, params, labels, i, ts)
            };

        let (l, r, pre, track) = if threads >= 2 {
            let (tx, rx) = std::sync::mpsc::sync_channel::<&KittiOrbExtractor>(1);
            let scoped = std::thread::scope(|s| {
                let h = s.spawn(move || {
                    let r = right_work(right_ex);
                    let r = match r {
                        Ok(r) => r,
                        Err(e) => return (Err(e), Ok(None)),
                    };
                    let shared: &KittiOrbExtractor = right_ex;
                    // the receiver only disappears when this frame already failed
                    let _ = tx.send(shared);
                    (Ok(r), seg_work(seg))
                });
                let l = left_work(left_ex, weights);
                let track = match (&l, rx.recv()) {
                    (Ok((_, labels, _, _)), Ok(right_ex)) => {
                        Some(match_track(left_ex, right_ex, labels.as_ref()))
                    }
                    _ => None,
                };
                let joined = h.join();
                (l, joined, track)
            });
            let (l, joined, track) = scoped;
            let (r, pre) =
                joined.map_err(|_| PipelineError::Worker("right-image worker panicked".into()))?;
            (l, r, pre, track)
        } else {
            let r = right_work(right_ex);
            let l = left_work(left_ex, weights);
            let track = match (&l, &r) {
                (Ok((_, labels, _, _)), Ok(_)) => {
                    Some(match_track(left_ex, right_ex, labels.as_ref()))
                }
                _ => None,
            };
            let pre =
                if track.as_ref().is_some_and(|t| t.is_ok()) { seg_work(seg) } else { Ok(None) };
            (l, r, pre, track)
        };
        let (_img, _labels, left_load_ms, orb_left_ms) = l?;
        let (right_load_ms, orb_right_ms) = r?;
        let (stereo_stats, stereo_ms, report, track_ms, extract_done_ms) = match track {
            Some(t) => t?,
            None => return Err(PipelineError::Worker("frame aborted".into())),
        };
        let pre = pre?;
        let next_load_ms = pre.as_ref().map_or(0.0, |p| p.load_ms);
        self.prefetched = pre;
        let total_ms = ms(t0);
        let load_ms = seg_load_ms + left_load_ms.max(right_load_ms) + next_load_ms;
        let times = StageTimes {
            load_ms,
            orb_left_ms,
            orb_right_ms,
            extract_wall_ms: extract_done_ms
                .map_or(0.0, |t| t.duration_since(t0).as_secs_f64() * 1e3),
            stereo_ms,
            track_ms,
            seg_ms,
            total_ms,
            compute_ms: (total_ms - load_ms).max(0.0),
        };
        Ok(FrameOutput { report, stereo: stereo_stats, times, culled: self.culled() })
    }

    /// Extracts frame `i`'s left ORB features twice, plain and with `scheme`'s semantic
    /// weights, and counts each set by the category under its key points (the paper's Fig. 4).
    /// Labels come from the network when one is set, else from the dataset. Only the left
    /// extractor is used; tracking state is untouched, so a pipeline kept for this alone can
    /// measure a whole sequence.
    pub fn feature_categories(
        &mut self,
        src: &(impl FrameSource + ?Sized),
        i: usize,
        scheme: WeightScheme,
    ) -> Result<(CategoryCounts, CategoryCounts), PipelineError> {
        let img = src.left(i)?.into_owned();
        let labels = match self.segmenter.as_mut() {
            Some(seg) => segment(seg, &img, i)?,
            None => src.labels(i)?.into_owned(),
        };
        let count = |ex: &KittiOrbExtractor| {
            let mut c = CategoryCounts::default();
            for kp in ex.features().keypoints() {
                let x = (kp.x.round().max(0.0) as u32).min(labels.width().saturating_sub(1));
                let y = (kp.y.round().max(0.0) as u32).min(labels.height().saturating_sub(1));
                c.add(labels.get_pixel(x, y)[0]);
            }
            c
        };
        extract(&mut self.left, &img, i, "left")?;
        let plain = count(&self.left);
        extract_weighted(&mut self.left, &img, &labels, scheme, &mut self.weights, i)?;
        let weighted = count(&self.left);
        Ok((plain, weighted))
    }

    /// Candidates the left extractor dropped for a zero weight on the last frame.
    fn culled(&self) -> u32 {
        self.left.features().stats().levels().iter().map(|l| l.weight_dropped).sum()
    }
}

/// Stereo matching, per-feature semantics for the EM association, and tracking of one frame.
/// Returns the stereo counters, stereo ms, the tracker's report, track ms, and when the
/// extraction had finished (this is called once both extractions are done).
#[allow(clippy::too_many_arguments)]
fn match_and_track(
    left: &KittiOrbExtractor,
    right: &KittiOrbExtractor,
    stereo: &mut KittiStereoMatcher,
    frame: &mut Frame,
    tracker: &mut Tracker,
    params: &StereoParams,
    labels: Option<&GrayImage>,
    index: usize,
    timestamp_s: f64,
) -> Result<(StereoStats, f64, FrameReport, f64, Option<Instant>), PipelineError> {
    let t = Instant::now();
    let stats = stereo
        .match_frame(
            left.features(),
            left.pyramid(),
            right.features(),
            right.pyramid(),
            params,
            timestamp_s,
            frame,
        )
        .map_err(|err| PipelineError::Stereo { frame: index, err })?;
    if let Some(labels) = labels {
        // Class and semantic descriptor per feature, for the EM association.
        let (w, h) = (labels.width() as usize, labels.height() as usize);
        let lv = ImageView::from_slice(labels.as_raw(), w, h).map_err(|e| PipelineError::Orb {
            frame: index,
            side: "left",
            err: e.into(),
        })?;
        semloc_core::assoc::annotate(frame, &lv);
    }
    let stereo_ms = ms(t);
    let t2 = Instant::now();
    let report = tracker.process(frame);
    Ok((stats, stereo_ms, report, ms(t2), Some(t)))
}

/// The network's labels of one left frame, as an image.
fn segment(seg: &mut Segmenter, img: &GrayImage, frame: usize) -> Result<GrayImage, PipelineError> {
    let labels =
        seg.segment(img, Kernels::Fast).map_err(|err| PipelineError::Segment { frame, err })?;
    GrayImage::from_raw(img.width(), img.height(), labels.frame)
        .ok_or_else(|| PipelineError::Worker(format!("frame {frame}: label image size")))
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

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
