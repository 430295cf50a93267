//! The host's schedule of core's one frame path ([`Localiser`]): frames are loaded (PNG
//! decoding), labelled by the int8 network one frame ahead, and the two ORB extractions run on
//! two threads; the pipeline itself is core's, so the poses are the same bits as on the ECU.
//!
//! All working memory is core's fixed-size [`Localiser`] (≈ 11 MiB, see
//! [`Pipeline::memory_bytes`]), created once; it is far larger than a default thread stack, so
//! [`Pipeline::new`] builds it on a temporary thread with a big stack and hands back a box.
//! After that, processing a frame allocates nothing in core; the host's only per-frame
//! allocations are image decoding, the network's label image and the scoped worker threads.

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

/// Core's frame path for one stereo sequence, with the host's loading, labelling and thread
/// schedule around it.
pub struct Pipeline {
    loc: Box<Localiser>,
    /// Worker threads: 1 runs everything on the caller's thread, 2 extracts left and right
    /// in parallel and labels the next frame while this one is tracked (the deployment
    /// setting: the machine has two cores).
    threads: usize,
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
        Ok(Self { loc, threads: threads.clamp(1, 2), segmenter: None, prefetched: None })
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
    }

    /// Labels left frames with the int8 network (pipelined on the second thread). The
    /// network's input must take this pipeline's frames (see [`Segmenter::letterbox`]).
    pub fn set_segmenter(&mut self, segmenter: Segmenter) {
        self.segmenter = Some(segmenter);
        self.prefetched = None;
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
        let scheme = self.loc.config().semantics;
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
        let core_err = |err| PipelineError::Frame { frame: i, err };

        // The right image: load and extract (the second thread's first job).
        let right_work = |ex: &mut RightExtraction<'_>| -> Result<(f64, f64), PipelineError> {
            let t = Instant::now();
            let img = src.right(i)?;
            let load = ms(t);
            let t = Instant::now();
            view(&img).and_then(|v| ex.run(&v)).map_err(core_err)?;
            Ok((load, ms(t)))
        };
        // This thread: the left image and its labels, weighted ORB.
        let left_work = |ex: &mut LeftExtraction<'_>| -> Result<(f64, f64), PipelineError> {
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
            Ok((load, ms(t)))
        };
        // The next frame's labels (the second thread's job while this frame is tracked).
        let seg_work = |seg: Option<&mut Segmenter>| -> Result<Option<Prefetch>, PipelineError> {
            let (Some(j), Some(seg)) = (next, seg) else { return Ok(None) };
            let t = Instant::now();
            let img = src.left(j)?.into_owned();
            let load_ms = ms(t);
            let t = Instant::now();
            let labels = segment(seg, &img, j)?;
            Ok(Some(Prefetch { index: j, left: img, labels, seg_ms: ms(t), load_ms }))
        };
        // Stereo matching + tracking (the same call in both schedules).
        let track = |loc: &mut Localiser| -> Result<Tracked, PipelineError> {
            let t = Instant::now();
            let stereo = loc.match_stereo(ts).map_err(core_err)?;
            let stereo_ms = ms(t);
            let t = Instant::now();
            let report = loc.track();
            Ok(Tracked { stereo, stereo_ms, report, track_ms: ms(t) })
        };

        let Pipeline { loc, segmenter, threads, .. } = self;
        let (left, right, extract_done, tracked, pre) = if *threads >= 2 {
            let (mut l_ex, mut r_ex) = loc.extractors_mut();
            let (l, r) = std::thread::scope(|s| {
                let h = s.spawn(move || right_work(&mut r_ex));
                let l = left_work(&mut l_ex);
                (l, h.join())
            });
            let r = r.map_err(|_| PipelineError::Worker("right-image worker panicked".into()))?;
            let extract_done = Instant::now();
            let (l, r) = (l?, r?);
            let (tracked, pre) = std::thread::scope(|s| {
                let seg = segmenter.as_mut();
                let h = s.spawn(move || seg_work(seg));
                let tracked = track(loc);
                (tracked, h.join())
            });
            let pre =
                pre.map_err(|_| PipelineError::Worker("segmentation worker panicked".into()))?;
            (l, r, extract_done, tracked, pre)
        } else {
            let (mut l_ex, mut r_ex) = loc.extractors_mut();
            let r = right_work(&mut r_ex)?;
            let l = left_work(&mut l_ex)?;
            let extract_done = Instant::now();
            let tracked = track(loc);
            let pre = if tracked.is_ok() { seg_work(segmenter.as_mut()) } else { Ok(None) };
            (l, r, extract_done, tracked, pre)
        };
        let ((left_load_ms, orb_left_ms), (right_load_ms, orb_right_ms)) = (left, right);
        let tracked = tracked?;
        let pre = pre?;
        let next_load_ms = pre.as_ref().map_or(0.0, |p| p.load_ms);
        self.prefetched = pre;
        let total_ms = ms(t0);
        let load_ms = seg_load_ms + left_load_ms.max(right_load_ms) + next_load_ms;
        let times = StageTimes {
            load_ms,
            orb_left_ms,
            orb_right_ms,
            extract_wall_ms: extract_done.duration_since(t0).as_secs_f64() * 1e3,
            stereo_ms: tracked.stereo_ms,
            track_ms: tracked.track_ms,
            seg_ms,
            total_ms,
            compute_ms: (total_ms - load_ms).max(0.0),
        };
        Ok(FrameOutput {
            report: tracked.report,
            stereo: tracked.stereo,
            times,
            culled: self.loc.culled(),
        })
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

/// Stereo matching and tracking of one frame, with their times.
struct Tracked {
    stereo: StereoStats,
    stereo_ms: f64,
    report: FrameReport,
    track_ms: f64,
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
