//! The host's schedule of core's one frame path ([`Localiser`]): frames are loaded (PNG
//! decoding), and with two threads the next frame is labelled by the int8 network and its ORB
//! features extracted while this one is tracked ([`Schedule`]); the pipeline itself is core's,
//! so the poses are the same bits as on the ECU, with any schedule.
//!
//! All working memory is core's fixed-size [`Localiser`] (≈ 11 MiB, see
//! [`Pipeline::memory_bytes`]), created once; it is far larger than a default thread stack, so
//! [`Pipeline::new`] builds it on a temporary thread with a big stack and hands back a box.
//! After that, processing a frame allocates nothing in core; the host's only per-frame
//! allocations are image decoding, the network's label image and the scoped worker threads.

use std::sync::Mutex;
use std::time::Instant;

use image::GrayImage;
use semloc_core::image::ImageView;
use semloc_core::localiser::{
    LeftExtraction, Localiser, LocaliserConfig, LocaliserError, RightExtraction,
};
use semloc_core::nn::graph::Kernels;
use semloc_core::orb::{FrameOrbExtractor, OrbConfig};
use semloc_core::seg::WeightScheme;
use semloc_core::stereo::{StereoMatching, StereoStats};
use semloc_core::tracker::{FrameReport, Tracker, TrackerParams};

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
    /// Frame `i`'s ground-truth mask of moving objects (non-zero where something moves), when
    /// the source has one (`semloc synth`'s `dynamic/` folder); `None` otherwise or when it
    /// cannot be read (it only feeds the motion test's precision/recall, never tracking).
    fn moving_mask(&self, _i: usize) -> Option<GrayImage> {
        None
    }
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
    fn moving_mask(&self, i: usize) -> Option<GrayImage> {
        let name = self.left.get(i)?.file_name()?;
        let img = image::open(self.root.join("dynamic").join(name)).ok()?.into_luma8();
        (img.dimensions() == self.image_size).then_some(img)
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
    /// Core refused the configuration (camera, image size, settings).
    #[error("localiser: {0}")]
    Config(LocaliserError),
    /// Core's frame path failed on a frame (ORB, stereo matching, labels, image size).
    #[error("frame {frame}: {err}")]
    Frame {
        /// Frame index.
        frame: usize,
        /// The core error.
        err: LocaliserError,
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
    /// The part of the frame's wall time spent decoding images (`total_ms - compute_ms`;
    /// decoding on two threads at once counts once).
    pub load_ms: f64,
    /// ORB on the left image (with two threads, overlapped: made while the previous frame was
    /// tracked).
    pub orb_left_ms: f64,
    /// ORB on the right image (beside the left, or, overlapped, beside the previous frame).
    pub orb_right_ms: f64,
    /// Wall time until the frame's features were extracted: 0 when the previous frame made
    /// them (two threads, overlapped).
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

/// How a two-thread [`Pipeline`] uses its second thread. Both give the same bits (and the
/// same as one thread); only the time differs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Schedule {
    /// While frame `i` is tracked, the second thread labels frame `i + 1` and extracts its left
    /// ORB features; its right features go to whichever thread is free first. A frame then
    /// costs about max(stereo + tracking, labelling + extraction) instead of their sum.
    #[default]
    Overlapped,
    /// Stage by stage: the two extractions side by side, then stereo matching and tracking
    /// beside the next frame's labelling (the schedule before 2026-12-03; `semloc bench`'s
    /// reference).
    Stagewise,
}

/// Core's frame path for one stereo sequence, with the host's loading, labelling and thread
/// schedule around it.
pub struct Pipeline {
    loc: Box<Localiser>,
    /// Worker threads: 1 runs everything on the caller's thread, 2 runs the [`Schedule`] (the
    /// deployment setting: the machine has two cores).
    threads: usize,
    schedule: Schedule,
    /// Frames from this index on are not worked on ahead (the caller stops before them).
    end: Option<usize>,
    /// The network that labels left frames when semantics are on (else the dataset's labels).
    segmenter: Option<Segmenter>,
    /// The next frame's left image and labels, made while this frame was tracked (stagewise).
    prefetched: Option<Prefetch>,
    /// The next frame's features, already in the localiser's extractors (overlapped).
    extracted: Option<Extracted>,
    /// The last processed frame's left image and labels (the extractors may hold the next
    /// frame's by then).
    current: Option<(GrayImage, Option<GrayImage>)>,
}

/// A frame segmented ahead of its turn.
struct Prefetch {
    index: usize,
    left: GrayImage,
    labels: GrayImage,
    seg_ms: f64,
}

/// A frame extracted ahead of its turn: the localiser's extractors and labels hold its
/// features; its images and stage times are kept for its own frame's output.
struct Extracted {
    index: usize,
    frame: InExtractors,
}

/// Frame `i` in the extractors: its images and what putting it there cost.
struct InExtractors {
    left: GrayImage,
    labels: Option<GrayImage>,
    orb_left_ms: f64,
    orb_right_ms: f64,
    seg_ms: f64,
    /// Decoding on the critical path of the extraction step.
    load_ms: f64,
}

/// The next frame's work on the second thread of the overlapped schedule.
struct NextLeft {
    left: GrayImage,
    labels: Option<GrayImage>,
    seg_ms: f64,
    orb_left_ms: f64,
    /// The right extraction, when this thread took it: (load, ORB) ms.
    right: Option<Result<(f64, f64), PipelineError>>,
}

/// What the second thread did for the next frame, failed or not: its wall time counts towards
/// the frame's compute time either way.
struct Ahead {
    next: Result<NextLeft, PipelineError>,
    /// Decoding (left image and dataset labels) on that thread.
    load_ms: f64,
    /// Since the frame started, when the thread finished or failed.
    end_ms: f64,
}

/// Stack for threads that construct or run core's large fixed-size state.
pub const BIG_STACK_BYTES: usize = 1 << 30;

impl Pipeline {
    /// Builds the pipeline for `calib` and `width`x`height` images, with ORB-SLAM2's KITTI
    /// extractor and stereo settings.
    pub fn new(
        calib: &StereoCalib,
        width: u32,
        height: u32,
        tracker_params: TrackerParams,
        threads: usize,
    ) -> Result<Self, PipelineError> {
        Self::with_settings(
            calib,
            width,
            height,
            OrbConfig::KITTI,
            StereoMatching::ORB_SLAM2,
            tracker_params,
            threads,
        )
    }

    /// [`Pipeline::new`] with the ORB and stereo matching settings given.
    pub fn with_settings(
        calib: &StereoCalib,
        width: u32,
        height: u32,
        orb: OrbConfig,
        stereo: StereoMatching,
        tracker_params: TrackerParams,
        threads: usize,
    ) -> Result<Self, PipelineError> {
        let cam = calib.to_camera().map_err(|e| PipelineError::Calib(e.to_string()))?;
        let config = LocaliserConfig {
            tracker: tracker_params,
            orb,
            stereo,
            ..LocaliserConfig::new(cam, width, height)
        };
        // Construct the multi-MiB state where a big stack makes the by-value move safe.
        let loc = std::thread::Builder::new()
            .stack_size(BIG_STACK_BYTES)
            .spawn(move || Localiser::new(&config).map(Box::new))
            .map_err(|e| PipelineError::Worker(e.to_string()))?
            .join()
            .map_err(|_| PipelineError::Worker("constructor thread panicked".into()))?
            .map_err(PipelineError::Config)?;
        Ok(Self {
            loc,
            threads: threads.clamp(1, 2),
            schedule: Schedule::default(),
            end: None,
            segmenter: None,
            prefetched: None,
            extracted: None,
            current: None,
        })
    }

    /// Bytes of core state this pipeline holds (the whole [`Localiser`]).
    pub fn memory_bytes() -> usize {
        Localiser::MEMORY_BYTES
    }

    /// Weights left-image features by semantic class; `None` turns it off. Labels come from
    /// the network set with [`Pipeline::set_segmenter`], else from the sequence's `semantic/`
    /// folder (see [`Sequence::load_labels`]).
    pub fn set_semantics(&mut self, scheme: Option<WeightScheme>) {
        // Labels are checked when set, so rebuilding their weights cannot fail.
        let _ = self.loc.set_semantics(scheme);
        self.forget_ahead();
    }

    /// How the second thread is used (two threads only; the results are the same bits).
    pub fn set_schedule(&mut self, schedule: Schedule) {
        self.schedule = schedule;
        self.forget_ahead();
    }

    /// Frames from `end` on will not be processed: no work is done ahead for them.
    pub fn set_end(&mut self, end: Option<usize>) {
        self.end = end;
    }

    /// Drops work done ahead for the next frame (its settings changed, or the extractors were
    /// used for something else); that frame is then made in turn.
    fn forget_ahead(&mut self) {
        self.prefetched = None;
        self.extracted = None;
    }

    /// The last processed frame's left image.
    pub fn left_image(&self) -> Option<&GrayImage> {
        self.current.as_ref().map(|c| &c.0)
    }

    /// The last processed frame's labels (network or dataset), when semantics are on.
    pub fn labels(&self) -> Option<&GrayImage> {
        self.current.as_ref().and_then(|c| c.1.as_ref())
    }

    /// Labels left frames with the int8 network (pipelined on the second thread). The
    /// network's input must take this pipeline's frames (see [`Segmenter::letterbox`]).
    pub fn set_segmenter(&mut self, segmenter: Segmenter) {
        self.segmenter = Some(segmenter);
        self.forget_ahead();
        self.loc.set_network_labels(true);
    }

    /// The network segmenter, if one is set.
    pub fn segmenter(&self) -> Option<&Segmenter> {
        self.segmenter.as_ref()
    }

    /// The tracker (for counters and the window).
    pub fn tracker(&self) -> &Tracker {
        self.loc.tracker()
    }

    /// Core's localiser.
    pub fn localiser(&self) -> &Localiser {
        &self.loc
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

    /// Processes frame `i` of `src`. With two threads the [`Schedule`] says what the second
    /// one does: by default it labels and extracts frame `i + 1` while this thread matches and
    /// tracks frame `i`. One thread does the same steps in sequence; the results are identical.
    /// Work done ahead for frame `i + 1` that fails is dropped, and frame `i + 1` is made in
    /// turn, so its error is reported as its own.
    pub fn process_frame(
        &mut self,
        src: &(impl FrameSource + ?Sized),
        i: usize,
    ) -> Result<FrameOutput, PipelineError> {
        let t0 = Instant::now();
        let ts = src.timestamp_s(i);
        let core_err = |err| PipelineError::Frame { frame: i, err };
        // Frame i's features: extracted while the previous frame was tracked, or now.
        let this = match self.extracted.take().filter(|x| x.index == i) {
            Some(x) => x.frame,
            None => self.extract_in_turn(src, i)?,
        };
        let extract_wall_ms = ms(t0);
        let limit = self.end.map_or(src.len(), |e| e.min(src.len()));
        let next = (i + 1 < limit).then_some(i + 1);
        let scheme = self.loc.config().semantics;
        let use_net = scheme.is_some() && self.segmenter.is_some();

        let Pipeline { loc, segmenter, threads, schedule, .. } = self;
        let two = *threads >= 2;
        let (stereo, stereo_ms, report, track_ms, culled, compute_ms);
        match (two, *schedule, next) {
            (true, Schedule::Overlapped, Some(j)) => {
                let out = overlapped(loc, segmenter.as_mut(), src, i, j, scheme)?;
                (stereo, stereo_ms, report, track_ms, culled) =
                    (out.stereo, out.stereo_ms, out.report, out.track_ms, out.culled);
                let base = extract_wall_ms - this.load_ms;
                compute_ms = base + out.critical_ms;
                self.extracted = out.next;
            }
            _ => {
                // Stagewise (or nothing ahead to do): the next frame's labels beside tracking.
                let next_seg = next.filter(|_| use_net);
                // The prefetch (dropped if it fails) and its decoding time, failed or not.
                let seg_work = |seg: Option<&mut Segmenter>| -> (Option<Prefetch>, f64) {
                    let (Some(j), Some(seg)) = (next_seg, seg) else { return (None, 0.0) };
                    let t = Instant::now();
                    let img = src.left(j);
                    let load_ms = ms(t);
                    let Ok(img) = img else { return (None, load_ms) };
                    let img = img.into_owned();
                    let t = Instant::now();
                    let pre = segment(seg, &img, j).ok().map(|labels| Prefetch {
                        index: j,
                        left: img,
                        labels,
                        seg_ms: ms(t),
                    });
                    (pre, load_ms)
                };
                let track = |loc: &mut Localiser| -> Result<_, PipelineError> {
                    let t = Instant::now();
                    let stereo = loc.match_stereo(ts).map_err(core_err)?;
                    let stereo_ms = ms(t);
                    let culled = loc.culled();
                    let t = Instant::now();
                    let report = loc.track();
                    Ok((stereo, stereo_ms, report, ms(t), culled))
                };
                let (tracked, pre) = if two {
                    std::thread::scope(|s| {
                        let seg = segmenter.as_mut();
                        let h = s.spawn(move || seg_work(seg));
                        let tracked = track(loc);
                        (tracked, h.join())
                    })
                } else {
                    let tracked = track(loc);
                    let pre =
                        if tracked.is_ok() { seg_work(segmenter.as_mut()) } else { (None, 0.0) };
                    (tracked, Ok(pre))
                };
                let (pre, next_load_ms) =
                    pre.map_err(|_| PipelineError::Worker("segmentation worker panicked".into()))?;
                (stereo, stereo_ms, report, track_ms, culled) = tracked?;
                compute_ms = (ms(t0) - this.load_ms - next_load_ms).max(0.0);
                self.prefetched = pre;
            }
        }
        let total_ms = ms(t0);
        let compute_ms = compute_ms.min(total_ms);
        self.current = Some((this.left, this.labels));
        let times = StageTimes {
            load_ms: total_ms - compute_ms,
            orb_left_ms: this.orb_left_ms,
            orb_right_ms: this.orb_right_ms,
            extract_wall_ms,
            stereo_ms,
            track_ms,
            seg_ms: this.seg_ms,
            total_ms,
            compute_ms,
        };
        Ok(FrameOutput { report, stereo, times, culled })
    }

    /// Puts frame `i` into the extractors on this pipeline's threads: its labels (made by the
    /// previous frame, made now, or the dataset's), then the left and right extractions side
    /// by side (two threads) or in turn.
    fn extract_in_turn(
        &mut self,
        src: &(impl FrameSource + ?Sized),
        i: usize,
    ) -> Result<InExtractors, PipelineError> {
        let scheme = self.loc.config().semantics;
        let use_net = scheme.is_some() && self.segmenter.is_some();
        let core_err = |err| PipelineError::Frame { frame: i, err };
        let mut seg_ms = 0.0;
        let mut seg_load_ms = 0.0;
        let (left_img, labels): (Option<GrayImage>, Option<GrayImage>) =
            match self.prefetched.take().filter(|p| p.index == i) {
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
        // The right image: load and extract (the second thread's job).
        let right_work = |ex: &mut RightExtraction<'_>| extract_right(ex, src, i);
        // This thread: the left image and its labels, weighted ORB.
        type Left = (GrayImage, Option<GrayImage>, f64, f64);
        let left_work = |ex: &mut LeftExtraction<'_>| -> Result<Left, PipelineError> {
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
            if let Some(l) = &labels {
                view(l).and_then(|v| ex.set_labels(&v)).map_err(core_err)?;
            }
            view(&img).and_then(|v| ex.run(&v)).map_err(core_err)?;
            Ok((img, labels, load, ms(t)))
        };
        let (mut l_ex, mut r_ex) = self.loc.extractors_mut();
        let (l, r) = if self.threads >= 2 {
            let (l, r) = std::thread::scope(|s| {
                let h = s.spawn(move || right_work(&mut r_ex));
                let l = left_work(&mut l_ex);
                (l, h.join())
            });
            (l, r.map_err(|_| PipelineError::Worker("right-image worker panicked".into()))?)
        } else {
            let r = right_work(&mut r_ex);
            (left_work(&mut l_ex), r)
        };
        let ((left, labels, left_load_ms, orb_left_ms), (right_load_ms, orb_right_ms)) = (l?, r?);
        let load_ms = seg_load_ms
            + if self.threads >= 2 {
                left_load_ms.max(right_load_ms)
            } else {
                left_load_ms + right_load_ms
            };
        Ok(InExtractors { left, labels, orb_left_ms, orb_right_ms, seg_ms, load_ms })
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
        // The left extractor is used here: work done ahead for the next frame is gone.
        self.forget_ahead();
        let img = src.left(i)?.into_owned();
        let labels = match self.segmenter.as_mut() {
            Some(seg) => segment(seg, &img, i)?,
            None => src.labels(i)?.into_owned(),
        };
        let count = |ex: &FrameOrbExtractor| {
            let mut c = CategoryCounts::default();
            for kp in ex.features().keypoints() {
                let x = (kp.x.round().max(0.0) as u32).min(labels.width().saturating_sub(1));
                let y = (kp.y.round().max(0.0) as u32).min(labels.height().saturating_sub(1));
                c.add(labels.get_pixel(x, y)[0]);
            }
            c
        };
        let core_err = |err| PipelineError::Frame { frame: i, err };
        let kept = self.loc.config().semantics;
        self.loc.set_semantics(Some(scheme)).map_err(core_err)?;
        let (mut left, _) = self.loc.extractors_mut();
        let mut counted = || -> Result<_, LocaliserError> {
            let v = view(&img)?;
            left.run_unweighted(&v)?;
            let plain = count(left.extractor());
            left.set_labels(&view(&labels)?)?;
            left.run(&v)?;
            Ok((plain, count(left.extractor())))
        };
        let counted = counted().map_err(core_err);
        self.loc.set_semantics(kept).map_err(core_err)?;
        counted
    }
}

/// What the overlapped schedule's step gives for frame `i`, and frame `j`'s features made
/// beside it.
struct Overlapped {
    stereo: StereoStats,
    stereo_ms: f64,
    report: FrameReport,
    track_ms: f64,
    culled: u32,
    /// Wall time of the step on the slower thread, less that thread's decoding.
    critical_ms: f64,
    /// Frame `j`, extracted (`None` when any part of it failed: it is then made in turn).
    next: Option<Extracted>,
}

/// Frame `i`'s stereo matching and tracking on this thread while a second one labels frame `j`
/// and extracts its left features; `j`'s right extraction goes to whichever thread is free
/// first. Frame `i`'s results are the same bits as in turn ([`Localiser::split_for_tracking`]).
fn overlapped<S: FrameSource + ?Sized>(
    loc: &mut Localiser,
    segmenter: Option<&mut Segmenter>,
    src: &S,
    i: usize,
    j: usize,
    scheme: Option<WeightScheme>,
) -> Result<Overlapped, PipelineError> {
    let t0 = Instant::now();
    let ts = src.timestamp_s(i);
    let right_slot = Mutex::new(None);
    let slot = &right_slot;
    let (tx, rx) = std::sync::mpsc::channel::<LeftExtraction<'_>>();
    // Frame j's labels and left features (the second thread).
    let next_left = move || -> Ahead {
        let mut load_ms = 0.0;
        let work = || -> Result<NextLeft, PipelineError> {
            // Decoding counts as loading whether it succeeds or not.
            let t = Instant::now();
            let left = src.left(j);
            load_ms += ms(t);
            let left = left?.into_owned();
            let t = Instant::now();
            let (labels, seg_ms) = match (scheme, segmenter) {
                (None, _) => (None, 0.0),
                (Some(_), Some(seg)) => {
                    let l = segment(seg, &left, j)?;
                    (Some(l), ms(t))
                }
                (Some(_), None) => {
                    let l = src.labels(j);
                    load_ms += ms(t);
                    (Some(l?.into_owned()), 0.0)
                }
            };
            // The extractors are free once frame i is matched.
            let mut ex =
                rx.recv().map_err(|_| PipelineError::Worker(format!("frame {i} not matched")))?;
            let err = |err| PipelineError::Frame { frame: j, err };
            let t = Instant::now();
            if let Some(l) = &labels {
                view(l).and_then(|v| ex.set_labels(&v)).map_err(err)?;
            }
            view(&left).and_then(|v| ex.run(&v)).map_err(err)?;
            let orb_left_ms = ms(t);
            let right = take_right(slot, src, j);
            Ok(NextLeft { left, labels, seg_ms, orb_left_ms, right })
        };
        let next = work();
        Ahead { next, load_ms, end_ms: ms(t0) }
    };
    std::thread::scope(move |s| {
        let h = s.spawn(next_left);
        let t = Instant::now();
        let stereo = loc.match_stereo(ts);
        let stereo_ms = ms(t);
        let stereo = match stereo {
            Ok(st) => st,
            Err(err) => {
                drop(tx);
                let _ = h.join();
                return Err(PipelineError::Frame { frame: i, err });
            }
        };
        let culled = loc.culled();
        let (mut tracking, l_ex, r_ex) = loc.split_for_tracking();
        if let Ok(mut g) = slot.lock() {
            *g = Some(r_ex);
        }
        if tx.send(l_ex).is_err() {
            // The second thread stopped before (frame j failed to load or label).
            if let Ok(mut g) = slot.lock() {
                g.take();
            }
        }
        let t = Instant::now();
        let report = tracking.track();
        let track_ms = ms(t);
        let right_here = take_right(slot, src, j);
        let end_here = ms(t0);
        let there =
            h.join().map_err(|_| PipelineError::Worker("next-frame worker panicked".into()))?;
        let load_here = match &right_here {
            Some(Ok((load, _))) => *load,
            _ => 0.0,
        };
        // The slower thread's wall time less its decoding, whether its work succeeded or not
        // (failed work ahead is made again in turn by the next frame, but it took this
        // frame's time).
        let right_load_there = match there.next.as_ref().map(|nl| &nl.right) {
            Ok(Some(Ok((load, _)))) => *load,
            _ => 0.0,
        };
        let critical_ms =
            (end_here - load_here).max(there.end_ms - there.load_ms - right_load_there);
        let next = there.next.ok().and_then(|nl| {
            // Exactly one thread took the right extraction.
            let right = match (right_here, nl.right) {
                (Some(r), None) | (None, Some(r)) => r.ok()?,
                _ => return None,
            };
            let frame = InExtractors {
                left: nl.left,
                labels: nl.labels,
                orb_left_ms: nl.orb_left_ms,
                orb_right_ms: right.1,
                seg_ms: nl.seg_ms,
                // Decoded beside the previous frame: none of it is on this frame's wall time.
                load_ms: 0.0,
            };
            Some(Extracted { index: j, frame })
        });
        Ok(Overlapped { stereo, stereo_ms, report, track_ms, culled, critical_ms, next })
    })
}

/// Frame `j`'s right extraction, when no thread has taken it yet: (load, ORB) ms.
fn take_right<S: FrameSource + ?Sized>(
    slot: &Mutex<Option<RightExtraction<'_>>>,
    src: &S,
    j: usize,
) -> Option<Result<(f64, f64), PipelineError>> {
    let mut ex = slot.lock().ok()?.take()?;
    Some(extract_right(&mut ex, src, j))
}

/// Loads frame `i`'s right image and extracts its features: (load, ORB) ms.
fn extract_right<S: FrameSource + ?Sized>(
    ex: &mut RightExtraction<'_>,
    src: &S,
    i: usize,
) -> Result<(f64, f64), PipelineError> {
    let t = Instant::now();
    let img = src.right(i)?;
    let load = ms(t);
    let t = Instant::now();
    view(&img).and_then(|v| ex.run(&v)).map_err(|err| PipelineError::Frame { frame: i, err })?;
    Ok((load, ms(t)))
}

/// The network's labels of one left frame, as an image.
fn segment(seg: &mut Segmenter, img: &GrayImage, frame: usize) -> Result<GrayImage, PipelineError> {
    let labels =
        seg.segment(img, Kernels::Fast).map_err(|err| PipelineError::Segment { frame, err })?;
    GrayImage::from_raw(img.width(), img.height(), labels.frame)
        .ok_or_else(|| PipelineError::Worker(format!("frame {frame}: label image size")))
}

/// A borrowed core view of a decoded luma image.
fn view(img: &GrayImage) -> Result<ImageView<'_>, LocaliserError> {
    ImageView::from_slice(img.as_raw(), img.width() as usize, img.height() as usize)
        .map_err(LocaliserError::Image)
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
