//! # semloc-firmware-sim
//!
//! semloc-core run the way an ECU runs it: one fixed block of state built once, frames pushed
//! through it in a fixed order, results printed as bit patterns so that two targets can be
//! compared for equality rather than closeness.
//!
//! * [`Localiser`] owns the core pieces (two ORB extractors, the stereo matcher, one
//!   [`Frame`], the [`Tracker`]) and runs one stereo frame in the host pipeline's single-thread
//!   order (`semloc::pipeline::Pipeline` with 1 thread): right ORB, left ORB, stereo matching,
//!   tracking. With [`Semantics`] (the int8 network's labels, the semantic ORB weights, the
//!   per-feature classes for EM) it runs the semantic pipeline the same way. The poses are
//!   bit-identical to `semloc run --threads 1` on the same frames (checked by
//!   `host_pipeline_check.py`).
//! * [`embedded`] holds a short synthetic sequence compiled into the image (640×192 crops of
//!   `semloc synth` frames, decoded from `firmware-sim/data/*.png` by the build script) and
//!   the 192×640 segmentation network.
//! * [`report`] prints poses as `f64` bit patterns and hashes them (FNV-1a), the same text on
//!   every target; [`report::run_embedded`] is the one driver all binaries call.
//!
//! * `sim` (feature `std`): the localiser as an ECU task on the host: fixed state built once,
//!   a simulated 10 Hz sensor clock feeding a bounded frame ring, a per-frame deadline with a
//!   degradation policy, seeded fault injection with detection and recovery, and the
//!   `ecu-sim` binary.
//!
//! The binaries: `qemu_aarch64` (bare metal, `aarch64-unknown-none`, ARM semihosting under
//! `qemu-system-aarch64 -M virt`), `host_poses` (x86-64, std) and `thumbv7em_size` (a
//! Cortex-M7 link of the same code, for the section-size report). See `firmware-sim/README.md`.
//!
//! Memory: [`Localiser::MEMORY_BYTES`] (≈ 10 MiB, dominated by the tracker and the two
//! extractors' pyramids) plus, with semantics, [`SegStorage::MEMORY_BYTES`] (≈ 2.5 MiB: the
//! network's arena and maps) and the network blob, read in place. Build the localiser where a
//! by-value move of that size is safe (a static slot on bare metal, a `Box` on a big-stack
//! thread on the host): its constructor returns it by value, and on aarch64 the construction
//! peaks at ≈ 36 MB of stack, while processing a frame needs ≈ 15 KB.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

pub mod embedded;
pub mod report;
#[cfg(feature = "std")]
pub mod sim;

use semloc_core::assoc::Association;
use semloc_core::frame::Frame;
use semloc_core::geom::{GeomError, StereoCamera};
use semloc_core::image::{ImageError, ImageView, ImageViewMut};
use semloc_core::nn::graph::{self, Kernels, Letterbox, SegBuffers};
use semloc_core::nn::model::{Model, ModelError};
use semloc_core::orb::{KittiOrbExtractor, NoWeights, OrbConfig, OrbError};
use semloc_core::seg::{weight_image, WeightScheme};
use semloc_core::stereo::{KittiStereoMatcher, StereoError, StereoParams, StereoStats};
use semloc_core::tracker::{FrameReport, Tracker, TrackerError, TrackerParams};

pub use semloc_core as core_crate;

/// Why the localiser could not be built or could not process a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum LocaliserError {
    /// The camera parameters are not usable.
    Camera(GeomError),
    /// An image buffer does not match its stated size.
    Image(ImageError),
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

/// The result of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameOutput {
    /// The tracker's report (pose `t_wc`, state, counters).
    pub report: FrameReport,
    /// Stereo matching counters.
    pub stereo: StereoStats,
}

/// Tracker settings of the geometric run: the defaults (ORB-SLAM2's stereo KITTI settings,
/// nearest-neighbour association), as `semloc run` without options.
pub fn geometric_params() -> TrackerParams {
    TrackerParams::default()
}

/// Tracker settings of the semantic run: the defaults with the paper's EM association, as
/// `semloc run --semantics full --assoc em`.
pub fn semantic_params() -> TrackerParams {
    TrackerParams { association: Association::Em, ..TrackerParams::default() }
}

/// The weighting scheme of the semantic run: the paper's semantic ORB.
pub const SEMANTIC_SCHEME: WeightScheme = WeightScheme::Full;

/// Working memory of the segmentation stage, provided by the caller (static buffers on bare
/// metal, `Vec`s on the host). [`SegMemory::bytes_needed`] gives the sizes.
pub struct SegMemory<'b> {
    /// Activation arena, at least [`Model::arena_len`] bytes.
    pub arena: &'b mut [i8],
    /// Network input map, `model_h · model_w` bytes.
    pub input: &'b mut [u8],
    /// Labels on the network's output map, `model_h · model_w` bytes.
    pub model_labels: &'b mut [u8],
    /// Labels on the frame, `width · height` bytes.
    pub labels: &'b mut [u8],
    /// Semantic ORB weight image, `width · height` bytes.
    pub weights: &'b mut [u8],
}

impl SegMemory<'_> {
    /// `(arena, model map, frame map)` sizes in bytes for `model` on `width`x`height` frames:
    /// the arena once, the model map twice (input, labels), the frame map twice (labels,
    /// weights).
    pub fn bytes_needed(model: &Model<'_>, width: usize, height: usize) -> (usize, usize, usize) {
        let (mh, mw) = model.input_size();
        (model.arena_len(), mh * mw, width * height)
    }
}

/// Arena capacity of [`SegStorage`]: the 192x640 Fast-SCNN export needs 1 495 680 bytes.
pub const SEG_ARENA_BYTES: usize = 2 << 20;

/// Fixed-size storage for [`SegMemory`] on [`embedded`]-sized frames: `const fn new`, all
/// zeros, so a `static` of it lands in `.bss`.
pub struct SegStorage {
    arena: [i8; SEG_ARENA_BYTES],
    input: [u8; embedded::WIDTH * embedded::HEIGHT],
    model_labels: [u8; embedded::WIDTH * embedded::HEIGHT],
    labels: [u8; embedded::WIDTH * embedded::HEIGHT],
    weights: [u8; embedded::WIDTH * embedded::HEIGHT],
}

impl SegStorage {
    /// Bytes of one storage.
    pub const MEMORY_BYTES: usize = core::mem::size_of::<SegStorage>();

    /// Zeroed storage.
    pub const fn new() -> Self {
        const N: usize = embedded::WIDTH * embedded::HEIGHT;
        Self {
            arena: [0; SEG_ARENA_BYTES],
            input: [0; N],
            model_labels: [0; N],
            labels: [0; N],
            weights: [0; N],
        }
    }

    /// The buffers, for [`Semantics::new`] (network maps of the embedded frame size: the
    /// 192x640 network at letterbox factor 1).
    pub fn memory(&mut self) -> SegMemory<'_> {
        SegMemory {
            arena: &mut self.arena,
            input: &mut self.input,
            model_labels: &mut self.model_labels,
            labels: &mut self.labels,
            weights: &mut self.weights,
        }
    }
}

impl Default for SegStorage {
    fn default() -> Self {
        Self::new()
    }
}

/// The semantic front end of the paper on the left image: the int8 network's labels (core's
/// [`graph::segment_frame`], the host `Segmenter`'s path, fast kernels), the semantic ORB
/// weight image under a [`WeightScheme`], and per-feature classes for the EM association.
pub struct Semantics<'a> {
    model: Model<'a>,
    letterbox: Letterbox,
    scheme: WeightScheme,
    width: usize,
    height: usize,
    mem: SegMemory<'a>,
}

impl<'a> Semantics<'a> {
    /// The stage for `width`x`height` frames with the `.slm` network `blob` (4-byte aligned,
    /// read in place) and the caller's buffers.
    ///
    /// # Errors
    /// [`LocaliserError::Model`]: a bad blob, a network that cannot take the frames, or a
    /// buffer smaller than [`SegMemory::bytes_needed`] says.
    pub fn new(
        blob: &'a [u8],
        width: usize,
        height: usize,
        scheme: WeightScheme,
        mem: SegMemory<'a>,
    ) -> Result<Self, LocaliserError> {
        let model = Model::parse(blob).map_err(LocaliserError::Model)?;
        let (mh, mw) = model.input_size();
        let letterbox = Letterbox::fit(width, height, mh, mw).map_err(LocaliserError::Model)?;
        let os = model.output_shape();
        if (os.h, os.w) != (mh, mw) {
            // A 1/8 export: the frame path needs the full-resolution output.
            return Err(LocaliserError::Model(ModelError::BadIo));
        }
        let (arena, map, frame) = SegMemory::bytes_needed(&model, width, height);
        for (need, got) in [
            (arena, mem.arena.len()),
            (map, mem.input.len()),
            (map, mem.model_labels.len()),
            (frame, mem.labels.len()),
            (frame, mem.weights.len()),
        ] {
            if got < need {
                return Err(LocaliserError::Model(ModelError::Truncated { need, got }));
            }
        }
        Ok(Self { model, letterbox, scheme, width, height, mem })
    }

    /// The last frame's labels (`width · height` class ids, row-major).
    pub fn labels(&self) -> &[u8] {
        &self.mem.labels[..self.width * self.height]
    }

    /// The weighting scheme.
    pub fn scheme(&self) -> WeightScheme {
        self.scheme
    }

    /// Labels `left` (`width · height` luma) and builds the weight image.
    fn label(&mut self, left: &[u8]) -> Result<(), LocaliserError> {
        let n = self.width * self.height;
        let m = &mut self.mem;
        let bufs = SegBuffers { input: m.input, arena: m.arena, labels: m.model_labels };
        graph::segment_frame(
            &self.model,
            &self.letterbox,
            left,
            bufs,
            Kernels::Fast,
            &mut m.labels[..n],
        )
        .map_err(LocaliserError::Model)?;
        let lv = ImageView::from_slice(&m.labels[..n], self.width, self.height)
            .map_err(LocaliserError::Image)?;
        let mut wv = ImageViewMut::from_slice(&mut m.weights[..n], self.width, self.height)
            .map_err(LocaliserError::Image)?;
        weight_image(&lv, self.scheme, &mut wv).map_err(LocaliserError::Image)
    }
}

/// The geometric localisation pipeline in fixed memory: ORB left and right → stereo matching
/// → tracker.
pub struct Localiser {
    left: KittiOrbExtractor,
    right: KittiOrbExtractor,
    stereo: KittiStereoMatcher,
    frame: Frame,
    tracker: Tracker,
    tracker_params: TrackerParams,
    params: StereoParams,
}

/// Memory budget of one [`Localiser`] (bytes), checked at compile time: of the ECU's 32 MiB for
/// the localisation stack, 12 MiB for the geometric pipeline.
pub const LOCALISER_BUDGET_BYTES: usize = 12 << 20;
const _: () = assert!(core::mem::size_of::<Localiser>() <= LOCALISER_BUDGET_BYTES);

impl Localiser {
    /// Bytes one localiser occupies: all of its working memory.
    pub const MEMORY_BYTES: usize = core::mem::size_of::<Localiser>();

    /// A localiser for `width`x`height` images from `cam`, with ORB-SLAM2's KITTI extractor
    /// settings and the stereo parameters the host pipeline derives from the camera.
    ///
    /// Returns ≈ [`Self::MEMORY_BYTES`] by value: call it where that fits (see the crate docs).
    ///
    /// # Errors
    /// [`LocaliserError::Camera`] for an invalid camera, [`LocaliserError::Tracker`] for an
    /// unusable image size.
    pub fn new(
        cam: StereoCamera,
        width: u32,
        height: u32,
        tracker: TrackerParams,
    ) -> Result<Self, LocaliserError> {
        // Re-validate: the fields are public and may have been filled without `new`.
        let cam = StereoCamera::new(cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px, cam.baseline_m)
            .map_err(LocaliserError::Camera)?;
        // As host/src/pipeline.rs: bf and baseline narrowed to f32 from the f64 camera.
        let params = StereoParams::new((cam.fx_px * cam.baseline_m) as f32, cam.baseline_m as f32);
        // One value built in its final place as far as the compiler allows (the extractors,
        // matcher and frame have `const fn new`); configured afterwards, so no multi-MiB
        // temporaries are moved around.
        let mut loc = Self {
            left: KittiOrbExtractor::new(),
            right: KittiOrbExtractor::new(),
            stereo: KittiStereoMatcher::new(),
            frame: Frame::new(),
            tracker: Tracker::new(cam, width, height, tracker).map_err(LocaliserError::Tracker)?,
            tracker_params: tracker,
            params,
        };
        loc.left
            .configure(OrbConfig::KITTI)
            .map_err(|err| LocaliserError::Orb { right: false, err })?;
        loc.right
            .configure(OrbConfig::KITTI)
            .map_err(|err| LocaliserError::Orb { right: true, err })?;
        Ok(loc)
    }

    /// A localiser for the [`embedded`] sequence: its camera and image size, and `tracker`
    /// (e.g. [`geometric_params`] or [`semantic_params`]).
    ///
    /// # Errors
    /// As [`Self::new`] (not expected: the embedded camera is valid).
    pub fn new_embedded(tracker: TrackerParams) -> Result<Self, LocaliserError> {
        Self::new(embedded::CAMERA, embedded::WIDTH as u32, embedded::HEIGHT as u32, tracker)
    }

    /// Processes one rectified stereo pair (8-bit luma, same size as given to [`Self::new`]).
    ///
    /// The order is the host pipeline's single-thread schedule: right ORB, left ORB, stereo
    /// matching, tracking. The two extractions are independent, so the order only matters for
    /// reading the code side by side with `host/src/pipeline.rs`.
    ///
    /// # Errors
    /// [`LocaliserError::Orb`] (e.g. a frame larger than the extractor's capacity) or
    /// [`LocaliserError::Stereo`]; the tracker itself cannot fail on a frame.
    pub fn process(
        &mut self,
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        timestamp_s: f64,
    ) -> Result<FrameOutput, LocaliserError> {
        self.right
            .extract_weighted(right, &NoWeights)
            .map_err(|err| LocaliserError::Orb { right: true, err })?;
        self.left
            .extract_weighted(left, &NoWeights)
            .map_err(|err| LocaliserError::Orb { right: false, err })?;
        let stereo = self.match_stereo(timestamp_s)?;
        let report = self.tracker.process(&self.frame);
        Ok(FrameOutput { report, stereo })
    }

    /// Processes one pair given as raw row-major luma buffers of `width`x`height`, with the
    /// semantic front end when `semantics` is given.
    ///
    /// With semantics the order is the host pipeline's single-thread schedule with a network
    /// (`Pipeline::process_frame`, semantics on, 1 thread): label the left image, right ORB,
    /// left ORB weighted by class, stereo matching, per-feature classes
    /// ([`semloc_core::assoc::annotate`]), tracking.
    ///
    /// # Errors
    /// [`LocaliserError::Image`] when a buffer's length or the frame size does not match;
    /// [`LocaliserError::Model`] when the network fails; else as [`Self::process`].
    pub fn process_raw(
        &mut self,
        left: &[u8],
        right: &[u8],
        width: usize,
        height: usize,
        timestamp_s: f64,
        semantics: Option<&mut Semantics<'_>>,
    ) -> Result<FrameOutput, LocaliserError> {
        let stereo = self.front_end(left, right, width, height, timestamp_s, semantics, true)?;
        let report = self.track();
        Ok(FrameOutput { report, stereo })
    }

    /// The front end of [`Self::process_raw`] without tracking: (labels,) ORB on both images
    /// and stereo matching into the localiser's frame, whose stereo counters are returned.
    /// [`Self::track`] then tracks that frame; a caller that finds the frame implausible (see
    /// `sim::health`, std feature) can skip it instead and [`Self::coast`].
    ///
    /// With `relabel` false and `semantics` given, the network is not run: the labels and
    /// weights of the last labelled frame are reused (the ECU simulation's degraded mode after
    /// a deadline overrun).
    ///
    /// # Errors
    /// As [`Self::process_raw`].
    #[allow(clippy::too_many_arguments)]
    pub fn front_end(
        &mut self,
        left: &[u8],
        right: &[u8],
        width: usize,
        height: usize,
        timestamp_s: f64,
        semantics: Option<&mut Semantics<'_>>,
        relabel: bool,
    ) -> Result<StereoStats, LocaliserError> {
        let l = ImageView::from_slice(left, width, height).map_err(LocaliserError::Image)?;
        let r = ImageView::from_slice(right, width, height).map_err(LocaliserError::Image)?;
        let Some(sem) = semantics else {
            self.right
                .extract_weighted(&r, &NoWeights)
                .map_err(|err| LocaliserError::Orb { right: true, err })?;
            self.left
                .extract_weighted(&l, &NoWeights)
                .map_err(|err| LocaliserError::Orb { right: false, err })?;
            return self.match_stereo(timestamp_s);
        };
        if (sem.width, sem.height) != (width, height) || left.len() != width * height {
            // The stage was built for another frame size (or the luma is strided).
            return Err(LocaliserError::Model(ModelError::BadIo));
        }
        if relabel {
            sem.label(left)?;
        }
        let n = width * height;
        let labels = ImageView::from_slice(&sem.mem.labels[..n], width, height)
            .map_err(LocaliserError::Image)?;
        let weights = ImageView::from_slice(&sem.mem.weights[..n], width, height)
            .map_err(LocaliserError::Image)?;
        self.right
            .extract_weighted(&r, &NoWeights)
            .map_err(|err| LocaliserError::Orb { right: true, err })?;
        self.left
            .extract_weighted(&l, &weights)
            .map_err(|err| LocaliserError::Orb { right: false, err })?;
        let stereo = self.match_stereo(timestamp_s)?;
        semloc_core::assoc::annotate(&mut self.frame, &labels);
        Ok(stereo)
    }

    /// Tracks the frame the last [`Self::front_end`] built.
    pub fn track(&mut self) -> FrameReport {
        self.tracker.process(&self.frame)
    }

    /// A frame period passed without a usable frame: the tracker advances its prediction by
    /// one period ([`Tracker::coast`]).
    pub fn coast(&mut self) {
        self.tracker.coast();
    }

    /// The time since the last frame is unknown: the tracker forgets its motion model
    /// ([`Tracker::forget_motion`]).
    pub fn forget_motion(&mut self) {
        self.tracker.forget_motion();
    }

    /// Features of the last frame the front end built (left key points).
    pub fn frame_features(&self) -> usize {
        self.frame.features.len()
    }

    fn match_stereo(&mut self, timestamp_s: f64) -> Result<StereoStats, LocaliserError> {
        self.stereo
            .match_frame(
                self.left.features(),
                self.left.pyramid(),
                self.right.features(),
                self.right.pyramid(),
                &self.params,
                timestamp_s,
                &mut self.frame,
            )
            .map_err(LocaliserError::Stereo)
    }

    /// The tracker's settings.
    pub fn tracker_params(&self) -> TrackerParams {
        self.tracker_params
    }

    /// The tracker (counters, window).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }
}

#[cfg(test)]
mod tests;
