//! The one per-frame pipeline: a rectified stereo pair (and, with semantics, the left image's
//! class labels) in, a camera pose out — the same code on the desk and on the ECU.
//!
//! Per frame ([`Localiser::process`] runs these in this order on one thread):
//! 1. **semantics** ([`Localiser::set_labels`], §3.1): the left frame's labels (from the int8
//!    network, [`Network`], or a dataset) are kept and turned into the semantic ORB weight
//!    image of the [`WeightScheme`] (Eq. 2: ω = 0 on dynamic classes, ×3 on construction and
//!    object classes);
//! 2. **ORB** on both images (Eq. 1 level quotas; the left image weighted by class) — the two
//!    extractions are independent, so a host borrows both through
//!    [`Localiser::extractors_mut`] and runs them on two threads, while a bare-metal loop calls
//!    [`Localiser::extract`];
//! 3. **stereo matching** and per-feature semantics (class and the §3.2 21×21 semantic
//!    descriptor, for the EM association) — [`Localiser::match_stereo`];
//! 4. **tracking** ([`Localiser::track`]): prediction, search, association (hard or the §3.3
//!    EM), motion-only optimisation, keyframe decision and window BA ([`crate::tracker`]).
//!
//! Because every caller (the host CLI, the ECU simulation, the bare-metal image, the tests)
//! drives this one type, host and target compute the same bits by construction; the QEMU check
//! in `firmware-sim` is the regression test.
//!
//! Memory: one [`Localiser`] holds all of its working memory ([`Localiser::MEMORY_BYTES`],
//! ≈ 41 MiB: the tracker, two extractors with their pyramids, the stereo matcher, one frame,
//! and a label and a weight image of [`MAX_PIXELS`] each); nothing is allocated per frame. It
//! is returned by value from [`Localiser::new`]: build it where a move of that size is safe (a
//! `static` on a target, a `Box` on a big-stack thread on a host). The optional [`Network`]
//! stage reads its model in place and works in caller-provided buffers
//! ([`NetworkMemory::bytes_needed`]).
//!
//! ```
//! use semloc_core::geom::StereoCamera;
//! use semloc_core::localiser::{Localiser, LocaliserConfig};
//! # fn run() -> Result<(), semloc_core::localiser::LocaliserError> {
//! let (w, h) = (320usize, 96usize);
//! let cam = StereoCamera::new(180.0, 180.0, 160.0, 48.0, 0.54).expect("camera");
//! // ≈ 41 MiB: box it on the host (a `static` on a target).
//! let mut loc = Box::new(Localiser::new(&LocaliserConfig::new(cam, w as u32, h as u32))?);
//! // A textured left image and the same scene 8 px further left in the right image.
//! let tex = |x: usize, y: usize| ((x * 7 + y * 13) ^ (x * y / 5)) as u8;
//! let left: Vec<u8> = (0..w * h).map(|i| tex(i % w, i / w)).collect();
//! let right: Vec<u8> = (0..w * h).map(|i| tex(i % w + 8, i / w)).collect();
//! let out = loc.process_raw(&left, &right, 0.0, None)?;
//! assert_eq!(out.report.frame_index, 0);
//! assert!(out.report.t_wc.trans.norm() < 1e-9); // the first frame defines the world
//! # Ok(()) }
//! # fn main() {
//! #     // ≈ 41 MiB by value: more than a main thread's default stack.
//! #     let t = std::thread::Builder::new().stack_size(1 << 30).spawn(run).unwrap();
//! #     t.join().unwrap().unwrap();
//! # }
//! ```

use crate::assoc::annotate;
use crate::frame::Frame;
use crate::geom::{GeomError, StereoCamera};
use crate::image::{ImageError, ImageView, ImageViewMut};
use crate::nn::graph::{self, Kernels, Letterbox, SegBuffers};
use crate::nn::model::{Model, ModelError};
use crate::orb::{
    FrameOrbExtractor, NoWeights, OrbConfig, OrbError, MAX_FRAME_HEIGHT, MAX_FRAME_WIDTH,
};
use crate::seg::{weight_image_with_gain, WeightScheme};
use crate::stereo::{FrameStereoMatcher, StereoError, StereoMatching, StereoParams, StereoStats};
use crate::tracker::{FrameReport, Tracker, TrackerError, TrackerParams};

/// Most pixels of a frame (and of its label and weight images): the extractors' capacity.
pub const MAX_PIXELS: usize = MAX_FRAME_WIDTH * MAX_FRAME_HEIGHT;

/// Why the localiser could not be built or could not process a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum LocaliserError {
    /// The camera parameters are not usable.
    Camera(GeomError),
    /// An image buffer does not match its stated size.
    Image(ImageError),
    /// An image (or label image) is not the size the localiser was built for.
    FrameSize {
        /// Width and height the localiser was built for.
        expected: (usize, usize),
        /// Width and height given.
        got: (usize, usize),
    },
    /// Semantics are on but no labels were ever given ([`Localiser::set_labels`]).
    NoLabels,
    /// ORB configuration or extraction failed (`right` tells which side).
    Orb {
        /// True for the right image.
        right: bool,
        /// The core error.
        err: OrbError,
    },
    /// Stereo matching failed.
    Stereo(StereoError),
    /// The tracker refused the configuration.
    Tracker(TrackerError),
    /// The segmentation network (blob, buffers or run) failed.
    Model(ModelError),
}

impl core::fmt::Display for LocaliserError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Camera(e) => write!(f, "camera: {e}"),
            Self::Image(e) => write!(f, "image: {e}"),
            Self::FrameSize { expected, got } => write!(
                f,
                "image is {}x{}, the localiser was built for {}x{}",
                got.0, got.1, expected.0, expected.1
            ),
            Self::NoLabels => write!(f, "semantics are on but the frame has no labels"),
            Self::Orb { right, err } => {
                write!(f, "ORB ({} image): {err}", if *right { "right" } else { "left" })
            }
            Self::Stereo(e) => write!(f, "stereo matching: {e}"),
            Self::Tracker(e) => write!(f, "tracker: {e}"),
            Self::Model(e) => write!(f, "segmentation network: {e}"),
        }
    }
}

impl core::error::Error for LocaliserError {}

/// Everything a [`Localiser`] is built from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocaliserConfig {
    /// The rectified stereo camera (left camera intrinsics and baseline).
    pub camera: StereoCamera,
    /// Image width (px), at most [`MAX_FRAME_WIDTH`].
    pub width: u32,
    /// Image height (px), at most [`MAX_FRAME_HEIGHT`].
    pub height: u32,
    /// ORB extractor settings (both images).
    pub orb: OrbConfig,
    /// Stereo matching settings (descriptor distance, SAD window and search).
    pub stereo: StereoMatching,
    /// Tracker settings (association, keyframes, BA).
    pub tracker: TrackerParams,
    /// Semantic weighting of left-image features; `None` is the geometric backbone.
    pub semantics: Option<WeightScheme>,
}

impl LocaliserConfig {
    /// The geometric backbone for `camera` and `width`x`height` images: ORB-SLAM2's KITTI
    /// extractor and tracker settings, no semantics.
    pub fn new(camera: StereoCamera, width: u32, height: u32) -> Self {
        Self {
            camera,
            width,
            height,
            orb: OrbConfig::KITTI,
            stereo: StereoMatching::ORB_SLAM2,
            tracker: TrackerParams::default(),
            semantics: None,
        }
    }

    /// The stereo matching parameters derived from the camera (`bf` and baseline, narrowed to
    /// `f32`).
    pub fn stereo_params(&self) -> StereoParams {
        let cam = &self.camera;
        StereoParams::with_matching(
            (cam.fx_px * cam.baseline_m) as f32,
            cam.baseline_m as f32,
            self.stereo,
        )
    }
}

/// The result of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameOutput {
    /// The tracker's report (pose `t_wc`, state, counters).
    pub report: FrameReport,
    /// Stereo matching counters.
    pub stereo: StereoStats,
    /// Left-image FAST candidates dropped by a zero semantic weight (dynamic classes).
    pub culled: u32,
}

/// The stereo localisation pipeline in fixed memory (see the module docs).
pub struct Localiser {
    left: FrameOrbExtractor,
    right: FrameOrbExtractor,
    stereo: FrameStereoMatcher,
    frame: Frame,
    tracker: Tracker,
    config: LocaliserConfig,
    stereo_params: StereoParams,
    width: usize,
    height: usize,
    sem: SemanticImages,
}

/// The left frame's labels and their semantic ORB weight image (Eq. 2).
struct SemanticImages {
    /// `width · height` class ids, valid when `labelled`.
    labels: [u8; MAX_PIXELS],
    /// The weight image of `labels` under the configured scheme.
    weights: [u8; MAX_PIXELS],
    labelled: bool,
}

impl SemanticImages {
    /// Rebuilds the weight image from the labels (nothing to do without a scheme), construction
    /// and object classes weighted `gain` times the other static classes.
    fn build_weights(
        &mut self,
        scheme: Option<WeightScheme>,
        gain: f32,
        (w, h): (usize, usize),
    ) -> Result<(), LocaliserError> {
        let Some(scheme) = scheme else { return Ok(()) };
        let lv =
            ImageView::from_slice(&self.labels[..w * h], w, h).map_err(LocaliserError::Image)?;
        let mut wv = ImageViewMut::from_slice(&mut self.weights[..w * h], w, h)
            .map_err(LocaliserError::Image)?;
        weight_image_with_gain(&lv, scheme, gain, &mut wv).map_err(LocaliserError::Image)
    }

    fn set(
        &mut self,
        labels: &ImageView<'_>,
        scheme: Option<WeightScheme>,
        gain: f32,
        (w, h): (usize, usize),
    ) -> Result<(), LocaliserError> {
        check_size(labels, (w, h))?;
        let mut dst = ImageViewMut::from_slice(&mut self.labels[..w * h], w, h)
            .map_err(LocaliserError::Image)?;
        dst.copy_from(labels).map_err(LocaliserError::Image)?;
        self.labelled = true;
        self.build_weights(scheme, gain, (w, h))
    }
}

fn check_size(img: &ImageView<'_>, size: (usize, usize)) -> Result<(), LocaliserError> {
    if (img.width(), img.height()) != size {
        return Err(LocaliserError::FrameSize { expected: size, got: (img.width(), img.height()) });
    }
    Ok(())
}

/// Memory budget of one [`Localiser`] (bytes), checked at compile time: of the ECU's 48 MiB for
/// the localisation stack, 44 MiB for the pipeline — ≈ 23 MiB of frame-sized buffers for frames
/// up to [`MAX_FRAME_WIDTH`] × [`MAX_FRAME_HEIGHT`] (two pyramids and scratches, labels, weights),
/// most of the rest the tracker's persistent map
/// (the network's ≈ 2.5 MiB arena comes on top).
pub const LOCALISER_BUDGET_BYTES: usize = 44 << 20;
const _: () = assert!(core::mem::size_of::<Localiser>() <= LOCALISER_BUDGET_BYTES);

impl Localiser {
    /// Bytes one localiser occupies: all of its working memory.
    pub const MEMORY_BYTES: usize = core::mem::size_of::<Localiser>();

    /// A localiser for `config`. Returns ≈ [`Self::MEMORY_BYTES`] by value (see the module
    /// docs for where to call it).
    ///
    /// # Errors
    /// [`LocaliserError::Camera`] for an invalid camera, [`LocaliserError::FrameSize`] for
    /// images beyond the capacity, [`LocaliserError::Tracker`] / [`LocaliserError::Orb`] for
    /// settings they refuse.
    pub fn new(config: &LocaliserConfig) -> Result<Self, LocaliserError> {
        // Re-validate: the fields are public and may have been filled without `new`.
        let c = &config.camera;
        let camera = StereoCamera::new(c.fx_px, c.fy_px, c.cx_px, c.cy_px, c.baseline_m)
            .map_err(LocaliserError::Camera)?;
        let config = LocaliserConfig { camera, ..*config };
        let (width, height) = (config.width as usize, config.height as usize);
        if width > MAX_FRAME_WIDTH || height > MAX_FRAME_HEIGHT {
            return Err(LocaliserError::FrameSize {
                expected: (MAX_FRAME_WIDTH, MAX_FRAME_HEIGHT),
                got: (width, height),
            });
        }
        config.stereo.check().map_err(LocaliserError::Stereo)?;
        let mut tracker = Tracker::new(camera, config.width, config.height, config.tracker)
            .map_err(LocaliserError::Tracker)?;
        tracker.set_motion_aware(config.semantics == Some(WeightScheme::Motion));
        // One value built in its final place as far as the compiler allows (the extractors,
        // matcher and frame have `const fn new`); configured afterwards, so no multi-MiB
        // temporaries are moved around.
        let mut loc = Self {
            left: FrameOrbExtractor::new(),
            right: FrameOrbExtractor::new(),
            stereo: FrameStereoMatcher::new(),
            frame: Frame::new(),
            tracker,
            config,
            stereo_params: config.stereo_params(),
            width,
            height,
            sem: SemanticImages {
                labels: [0; MAX_PIXELS],
                weights: [0; MAX_PIXELS],
                labelled: false,
            },
        };
        loc.left.configure(config.orb).map_err(|err| LocaliserError::Orb { right: false, err })?;
        loc.right.configure(config.orb).map_err(|err| LocaliserError::Orb { right: true, err })?;
        Ok(loc)
    }

    /// The configuration (with the validated camera).
    pub fn config(&self) -> &LocaliserConfig {
        &self.config
    }

    /// Image `(width, height)` this localiser takes.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Sets the current left frame's class labels (`width · height` ids, any stride) and,
    /// with semantics on, builds the semantic ORB weight image from them. A frame for which
    /// no labels are set reuses the last ones (the ECU's degraded mode after a deadline
    /// overrun); without semantics the labels are ignored. ([`LeftExtraction::set_labels`]
    /// does the same on the left extraction's thread.)
    ///
    /// # Errors
    /// [`LocaliserError::FrameSize`] when the labels are not the frame's size.
    pub fn set_labels(&mut self, labels: &ImageView<'_>) -> Result<(), LocaliserError> {
        let gain = self.config.orb.structure_gain;
        self.sem.set(labels, self.config.semantics, gain, (self.width, self.height))
    }

    /// Labels the left frame `left` (`width · height` luma, row-major) with the int8 network
    /// straight into the localiser's label image, then as [`Self::set_labels`].
    ///
    /// # Errors
    /// [`LocaliserError::FrameSize`] when the network stage was built for another frame size,
    /// [`LocaliserError::Image`] when `left` is shorter than one frame,
    /// [`LocaliserError::Model`] when the network fails.
    pub fn label_with(
        &mut self,
        network: &mut Network<'_>,
        left: &[u8],
    ) -> Result<(), LocaliserError> {
        let n = self.width * self.height;
        if network.frame_size() != (self.width, self.height) {
            return Err(LocaliserError::FrameSize {
                expected: (self.width, self.height),
                got: network.frame_size(),
            });
        }
        // As an `ImageView`: a longer buffer is read up to the frame, a shorter one refused.
        let left = left.get(..n).ok_or(LocaliserError::Image(ImageError::BufferTooSmall {
            need: n,
            got: left.len(),
        }))?;
        self.sem.labelled = false;
        network.label(left, &mut self.sem.labels[..n])?;
        self.sem.labelled = true;
        self.tracker.set_network_labels(true);
        let gain = self.config.orb.structure_gain;
        self.sem.build_weights(self.config.semantics, gain, (self.width, self.height))
    }

    /// The current left frame's labels, if any were set.
    pub fn labels(&self) -> Option<&[u8]> {
        self.sem.labelled.then(|| &self.sem.labels[..self.width * self.height])
    }

    /// Changes the semantic weighting (`None`: the geometric backbone); the weight image of
    /// labels already set is rebuilt.
    ///
    /// # Errors
    /// As [`Self::set_labels`] (not expected: the labels were checked when set).
    pub fn set_semantics(&mut self, scheme: Option<WeightScheme>) -> Result<(), LocaliserError> {
        self.config.semantics = scheme;
        self.tracker.set_motion_aware(scheme == Some(WeightScheme::Motion));
        if self.sem.labelled {
            let gain = self.config.orb.structure_gain;
            self.sem.build_weights(scheme, gain, (self.width, self.height))?;
        }
        Ok(())
    }

    /// The two extraction stages, borrowed apart so a host can run them on two threads; both
    /// must have run before [`Self::match_stereo`]. The left one owns the frame's labels (set
    /// them there or before) and applies their semantic weights.
    pub fn extractors_mut(&mut self) -> (LeftExtraction<'_>, RightExtraction<'_>) {
        let (_, left, right) = self.split_for_tracking();
        (left, right)
    }

    /// Both extractions on this thread (right, then left: the order does not matter, the two
    /// are independent).
    ///
    /// # Errors
    /// As [`LeftExtraction::run`] and [`RightExtraction::run`].
    pub fn extract(
        &mut self,
        left: &ImageView<'_>,
        right: &ImageView<'_>,
    ) -> Result<(), LocaliserError> {
        let (mut l, mut r) = self.extractors_mut();
        r.run(right)?;
        l.run(left)
    }

    /// Stereo matching of the extracted features into the localiser's frame and, with
    /// semantics on, each feature's class and semantic descriptor (§3.2) for the EM
    /// association. Returns the stereo counters; [`Self::track`] then tracks the frame, or a
    /// caller that finds it implausible skips it and [`Self::coast`]s.
    ///
    /// # Errors
    /// [`LocaliserError::Stereo`].
    pub fn match_stereo(&mut self, timestamp_s: f64) -> Result<StereoStats, LocaliserError> {
        let stats = self
            .stereo
            .match_frame(
                self.left.features(),
                self.left.pyramid(),
                self.right.features(),
                self.right.pyramid(),
                &self.stereo_params,
                timestamp_s,
                &mut self.frame,
            )
            .map_err(LocaliserError::Stereo)?;
        if self.config.semantics.is_some() && self.sem.labelled {
            let (w, h) = (self.width, self.height);
            let lv = ImageView::from_slice(&self.sem.labels[..w * h], w, h)
                .map_err(LocaliserError::Image)?;
            annotate(&mut self.frame, &lv);
        }
        Ok(stats)
    }

    /// Tracks the frame the last [`Self::match_stereo`] built (the tracker itself cannot fail
    /// on a frame).
    pub fn track(&mut self) -> FrameReport {
        self.tracker.process(&self.frame)
    }

    /// After [`Self::match_stereo`]: the tracking stage and the two extraction stages borrowed
    /// apart, so a host can extract the next frame while this one is tracked. The frame the
    /// stereo matcher built is all that tracking reads; the extractors and the labels are free
    /// once it is built, and the next frame's features and labels replace this one's there,
    /// never in the frame. The poses are the same bits as extracting after
    /// [`Self::track`] (read [`Self::culled`] before: it counts the extractor's last run).
    pub fn split_for_tracking(
        &mut self,
    ) -> (TrackingStage<'_>, LeftExtraction<'_>, RightExtraction<'_>) {
        let size = (self.width, self.height);
        (
            TrackingStage { tracker: &mut self.tracker, frame: &self.frame },
            LeftExtraction {
                ex: &mut self.left,
                sem: &mut self.sem,
                scheme: self.config.semantics,
                gain: self.config.orb.structure_gain,
                size,
            },
            RightExtraction { ex: &mut self.right, size },
        )
    }

    /// One whole frame on this thread: extraction, stereo matching, tracking. Labels for the
    /// frame, when semantics are on, are set before ([`Self::set_labels`] or
    /// [`Self::label_with`]).
    ///
    /// # Errors
    /// As [`Self::extract`] and [`Self::match_stereo`].
    pub fn process(
        &mut self,
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        timestamp_s: f64,
    ) -> Result<FrameOutput, LocaliserError> {
        self.extract(left, right)?;
        let stereo = self.match_stereo(timestamp_s)?;
        let report = self.track();
        Ok(FrameOutput { report, stereo, culled: self.culled() })
    }

    /// The front end of one frame on row-major `width · height` luma buffers, on this thread:
    /// with a `network`, the left image is labelled first ([`Self::label_with`]); without one
    /// the labels set before are used (or reused); then both extractions and
    /// [`Self::match_stereo`]. [`Self::track`] then tracks the frame; a caller that finds it
    /// implausible can skip it and [`Self::coast`] instead.
    ///
    /// # Errors
    /// [`LocaliserError::Image`] when a buffer is shorter than the frame; else as
    /// [`Self::label_with`], [`Self::extract`] and [`Self::match_stereo`].
    pub fn front_end(
        &mut self,
        left: &[u8],
        right: &[u8],
        timestamp_s: f64,
        network: Option<&mut Network<'_>>,
    ) -> Result<StereoStats, LocaliserError> {
        let (w, h) = (self.width, self.height);
        let l = ImageView::from_slice(left, w, h).map_err(LocaliserError::Image)?;
        let r = ImageView::from_slice(right, w, h).map_err(LocaliserError::Image)?;
        if let Some(net) = network {
            self.label_with(net, left)?;
        }
        self.extract(&l, &r)?;
        self.match_stereo(timestamp_s)
    }

    /// One whole frame on raw buffers: [`Self::front_end`], then [`Self::track`].
    ///
    /// # Errors
    /// As [`Self::front_end`].
    pub fn process_raw(
        &mut self,
        left: &[u8],
        right: &[u8],
        timestamp_s: f64,
        network: Option<&mut Network<'_>>,
    ) -> Result<FrameOutput, LocaliserError> {
        let stereo = self.front_end(left, right, timestamp_s, network)?;
        let report = self.track();
        Ok(FrameOutput { report, stereo, culled: self.culled() })
    }

    /// Left-image FAST candidates the last extraction dropped for a zero semantic weight.
    pub fn culled(&self) -> u32 {
        self.left.features().stats().levels().iter().map(|l| l.weight_dropped).sum()
    }

    /// A frame period passed without a usable frame: the tracker advances its prediction by
    /// one period ([`Tracker::coast`]).
    pub fn coast(&mut self) {
        self.tracker.coast();
    }

    /// The time since the last frame is unknown: the tracker forgets its motion model.
    pub fn forget_motion(&mut self) {
        self.tracker.forget_motion();
    }

    /// The tracker (pose, counters, window).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// Says whether the labels given with [`Self::set_labels`] come from the segmentation
    /// network ([`Tracker::set_network_labels`]; [`Self::label_with`] says so itself).
    pub fn set_network_labels(&mut self, on: bool) {
        self.tracker.set_network_labels(on);
    }

    /// The last frame the front end built (features with stereo depth and semantics).
    pub fn frame(&self) -> &Frame {
        &self.frame
    }

    /// The left extractor (its last features and statistics).
    pub fn left_extractor(&self) -> &FrameOrbExtractor {
        &self.left
    }
}

/// The tracking stage, borrowed from a [`Localiser`] apart from its extractors
/// ([`Localiser::split_for_tracking`]).
pub struct TrackingStage<'a> {
    tracker: &'a mut Tracker,
    frame: &'a Frame,
}

impl TrackingStage<'_> {
    /// As [`Localiser::track`].
    pub fn track(&mut self) -> FrameReport {
        self.tracker.process(self.frame)
    }
}

/// The left-image extraction stage, borrowed from a [`Localiser`] with the frame's labels
/// (`Send`: run it on any thread).
pub struct LeftExtraction<'a> {
    ex: &'a mut FrameOrbExtractor,
    sem: &'a mut SemanticImages,
    scheme: Option<WeightScheme>,
    gain: f32,
    size: (usize, usize),
}

impl LeftExtraction<'_> {
    /// As [`Localiser::set_labels`].
    ///
    /// # Errors
    /// [`LocaliserError::FrameSize`] when the labels are not the frame's size.
    pub fn set_labels(&mut self, labels: &ImageView<'_>) -> Result<(), LocaliserError> {
        self.sem.set(labels, self.scheme, self.gain, self.size)
    }

    /// ORB on the left image, weighted by class when semantics are on (Eq. 2).
    ///
    /// # Errors
    /// [`LocaliserError::NoLabels`] when semantics are on and no labels were ever set,
    /// [`LocaliserError::FrameSize`] for an image of another size, [`LocaliserError::Orb`].
    pub fn run(&mut self, img: &ImageView<'_>) -> Result<(), LocaliserError> {
        if self.scheme.is_none() {
            return extract(self.ex, img, self.size, &NoWeights, false);
        }
        if !self.sem.labelled {
            return Err(LocaliserError::NoLabels);
        }
        let (w, h) = self.size;
        let wv = ImageView::from_slice(&self.sem.weights[..w * h], w, h)
            .map_err(LocaliserError::Image)?;
        extract(self.ex, img, self.size, &wv, false)
    }

    /// ORB on the left image without semantic weights, whatever the configuration (the
    /// plain-ORB side of the paper's Fig. 4 comparison).
    ///
    /// # Errors
    /// As [`Self::run`].
    pub fn run_unweighted(&mut self, img: &ImageView<'_>) -> Result<(), LocaliserError> {
        extract(self.ex, img, self.size, &NoWeights, false)
    }

    /// The extractor (its last features).
    pub fn extractor(&self) -> &FrameOrbExtractor {
        self.ex
    }
}

/// The right-image extraction stage, borrowed from a [`Localiser`] (`Send`).
pub struct RightExtraction<'a> {
    ex: &'a mut FrameOrbExtractor,
    size: (usize, usize),
}

impl RightExtraction<'_> {
    /// ORB on the right image (never weighted: labels exist for the left image only).
    ///
    /// # Errors
    /// [`LocaliserError::FrameSize`] for an image of another size, [`LocaliserError::Orb`].
    pub fn run(&mut self, img: &ImageView<'_>) -> Result<(), LocaliserError> {
        extract(self.ex, img, self.size, &NoWeights, true)
    }
}

fn extract<M: crate::orb::WeightMap + ?Sized>(
    ex: &mut FrameOrbExtractor,
    img: &ImageView<'_>,
    size: (usize, usize),
    weights: &M,
    right: bool,
) -> Result<(), LocaliserError> {
    check_size(img, size)?;
    ex.extract_weighted(img, weights).map_err(|err| LocaliserError::Orb { right, err })?;
    Ok(())
}

/// Working memory of the [`Network`] stage, provided by the caller (static buffers on bare
/// metal, `Vec`s on a host); [`NetworkMemory::bytes_needed`] gives the sizes.
pub struct NetworkMemory<'b> {
    /// Activation arena, at least [`Model::arena_len`] bytes.
    pub arena: &'b mut [i8],
    /// Network input map, `model_h · model_w` bytes.
    pub input: &'b mut [u8],
    /// Labels on the network's output map, `model_h · model_w` bytes.
    pub model_labels: &'b mut [u8],
}

impl NetworkMemory<'_> {
    /// `(arena, model map)` sizes in bytes for `model`: the arena once, the model map twice
    /// (input, labels).
    pub fn bytes_needed(model: &Model<'_>) -> (usize, usize) {
        let (mh, mw) = model.input_size();
        (model.arena_len(), mh * mw)
    }
}

/// The int8 segmentation network (§3.1, Fast-SCNN with Res2Net blocks) as a frame stage:
/// letterbox the left frame onto the network input, run it with the fast kernels, arg-max,
/// labels back on the frame ([`graph::segment_frame`]). The model blob is read in place.
pub struct Network<'a> {
    model: Model<'a>,
    letterbox: Letterbox,
    mem: NetworkMemory<'a>,
}

impl<'a> Network<'a> {
    /// The stage for `width`x`height` frames with the `.slm` network `blob` (4-byte aligned)
    /// and the caller's buffers.
    ///
    /// # Errors
    /// [`LocaliserError::Model`]: a bad blob, a network that cannot take the frames (or a 1/8
    /// export), or a buffer smaller than [`NetworkMemory::bytes_needed`] says.
    pub fn new(
        blob: &'a [u8],
        width: usize,
        height: usize,
        mem: NetworkMemory<'a>,
    ) -> Result<Self, LocaliserError> {
        let model = Model::parse(blob).map_err(LocaliserError::Model)?;
        let (mh, mw) = model.input_size();
        let letterbox = Letterbox::fit(width, height, mh, mw).map_err(LocaliserError::Model)?;
        let os = model.output_shape();
        if (os.h, os.w) != (mh, mw) {
            // A 1/8 export: the frame path needs the full-resolution output.
            return Err(LocaliserError::Model(ModelError::BadIo));
        }
        let (arena, map) = NetworkMemory::bytes_needed(&model);
        for (need, got) in
            [(arena, mem.arena.len()), (map, mem.input.len()), (map, mem.model_labels.len())]
        {
            if got < need {
                return Err(LocaliserError::Model(ModelError::Truncated { need, got }));
            }
        }
        Ok(Self { model, letterbox, mem })
    }

    /// Frame `(width, height)` the stage takes.
    pub fn frame_size(&self) -> (usize, usize) {
        (self.letterbox.src_w, self.letterbox.src_h)
    }

    /// The model.
    pub fn model(&self) -> &Model<'a> {
        &self.model
    }

    /// Labels `left` (`width · height` luma, row-major) into `out` (`width · height`).
    ///
    /// # Errors
    /// [`LocaliserError::Model`] when a buffer does not fit or the run fails.
    pub fn label(&mut self, left: &[u8], out: &mut [u8]) -> Result<(), LocaliserError> {
        let m = &mut self.mem;
        let bufs = SegBuffers { input: m.input, arena: m.arena, labels: m.model_labels };
        graph::segment_frame(&self.model, &self.letterbox, left, bufs, Kernels::Fast, out)
            .map_err(LocaliserError::Model)
    }
}

#[cfg(test)]
mod tests;
