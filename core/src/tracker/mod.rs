//! The per-frame stereo tracker: the one entry point of core's SLAM. It orchestrates; the
//! work is done in [`crate::assoc`] (search and association) and [`crate::map`] (keyframes).
//!
//! Per frame (the structure of ORB-SLAM2's `Tracking` + `LocalMapping`, in fixed memory):
//! 1. predict the pose with a constant-velocity model;
//! 2. search: project the landmarks of the local map (the keyframes observing what the last
//!    frame matched and their covisible neighbours, [`crate::map::LocalSet`]) and match them by
//!    nearest neighbour ([`crate::assoc`]) — a wide pass, a motion-only pose optimisation (and
//!    one from a RANSAC start when that is better supported); without a motion estimate (the
//!    first frame after initialisation) the first pass matches by appearance alone over the
//!    whole image instead, as ORB-SLAM2's `TrackReferenceKeyFrame`; then, as ORB-SLAM2's
//!    `TrackLocalMap`, the local map around this frame's own matches in a narrow pass;
//! 3. associate and optimise: nearest neighbour with a final pose optimisation whose outliers
//!    are unlinked, or EM over the gated candidates (paper §3.3, [`crate::assoc::em`]);
//! 4. decide on a keyframe (tracked share of the reference keyframe's landmarks, close stereo
//!    points, a maximum interval) and hand it to the map: observations, new landmarks from
//!    stereo features and by triangulation, fusion, local BA weighted by the association
//!    weights with covisible keyframes fixed, landmark and keyframe culling;
//! 5. if too few inliers remain the map is re-initialised at the predicted pose (counted).
//!
//! Memory: one [`Tracker`] holds everything (see [`Tracker::MEMORY_BYTES`], within
//! [`TRACKER_BUDGET_BYTES`]); `process` allocates nothing. Build it once (in a `static` on a
//! target, on a large-stack thread or in a `Box` on a host) and reuse it.

use heapless::Vec;

use crate::assoc::{
    Association, EmInput, EmParams, EmScratch, Matches, PoseProblem, ProjectionSearch, SearchQuery,
};
use crate::frame::{Feature, Frame, FRAME_CAPACITY};
use crate::geom::{Se3, StereoCamera};
use crate::map::{
    measurement, renormalize, LocalMap, LocalSet, Map, MappingParams, NewKeyframe, NO_LANDMARK,
};
use crate::motion::{
    a_mover_passes_too, FeatureMotion, MotionParams, MotionReport, MotionScratch, MotionSegment,
    MAX_LANDMARK_LOGIT, MOVING_LOGIT, STATIC_LOGIT,
};
use crate::optim::{chi2, PoseOptParams};
use crate::ransac::{count_inliers, ransac_pose, Correspondence};
use crate::seg::is_dynamic;

/// Largest ORB distance of a match by appearance alone (ORB-SLAM2's `TH_LOW`).
const APPEARANCE_MAX_HAMMING: u32 = 50;
/// Best/second-best ratio of a match by appearance alone. ORB-SLAM2's `TrackReferenceKeyFrame`
/// uses 0.7, but compares only the features under one vocabulary node; here the second best is
/// sought over the whole image (±1 level), where every window of a facade is one. At 0.7 the
/// facades of synthetic `high` seed 4 at frame 40 failed the test, the frame was solved from
/// lane markings and tree crowns alone, 0.9 m off, and motion + EM locked onto the truck ahead
/// (16 m of ATE). RANSAC and the pose solve reject what a looser test lets through.
const APPEARANCE_NN_RATIO: f32 = 0.9;

/// Tracker settings; defaults follow ORB-SLAM2's stereo KITTI configuration where it has one.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct TrackerParams {
    /// Stereo points closer than this many baselines are "close" (ORB-SLAM2 `ThDepth` 35).
    pub close_depth_baselines: f64,
    /// A new keyframe creates landmarks from all close stereo points and, if fewer, the
    /// nearest ones up to this count. 300 measured best before triangulation existed
    /// (synthetic high traffic with culling: ATE 0.72 m → 0.22 m); with triangulation and the
    /// persistent map, ORB-SLAM2's 100 changes the KITTI clips by under 5 mm, so it stays.
    pub min_new_landmarks: usize,
    /// First-pass search radius at level 0 (px).
    pub wide_radius_px: f32,
    /// Second-pass search radius at level 0 (px).
    pub narrow_radius_px: f32,
    /// Largest Hamming distance accepted for a match (ORB-SLAM2 `TH_HIGH`).
    pub max_hamming: u32,
    /// Best/second-best ratio when both are on the same level (ORB-SLAM2 0.8).
    pub nn_ratio: f32,
    /// Stereo points farther than this many baselines are monocular (bearing-only)
    /// measurements in tracking and BA (infinite: every stereo point is a stereo measurement).
    pub mono_beyond_baselines: f64,
    /// Fewer inliers than this and tracking is lost.
    pub min_inliers: u32,
    /// Keyframe when tracked landmarks fall below this share of the reference keyframe's.
    pub keyframe_ratio: f32,
    /// Keyframe at least every this many frames.
    pub keyframe_max_interval: u32,
    /// BA iterations per keyframe.
    pub ba_iterations: u8,
    /// Keyframes local BA optimises (the new one and its best covisible ones); the other
    /// keyframes observing their landmarks are held fixed, up to the BA capacity.
    pub ba_keyframes: usize,
    /// Triangulate new landmarks between covisible keyframes.
    pub triangulate: bool,
    /// Remove redundant keyframes (≥ 90 % of their landmarks seen by ≥ 3 others).
    pub cull_keyframes: bool,
    /// RANSAC hypotheses per frame (0 disables RANSAC).
    pub ransac_iterations: u32,
    /// Varies RANSAC's hypotheses between runs (0: the default stream). Tracking is
    /// deterministic, so one run is one sample; running a few seeds shows how far a result
    /// moves with the hypotheses drawn, as ORB-SLAM2's results move from run to run.
    pub ransac_seed: u64,
    /// Nearest-neighbour or EM association.
    pub association: Association,
    /// EM settings (used with [`Association::Em`]).
    pub em: EmParams,
    /// Motion test settings (used when motion-aware semantics are on,
    /// [`Tracker::set_motion_aware`]).
    pub motion: MotionParams,
}

/// A [`TrackerParams`] value outside its range ([`TrackerParams::check`]).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BadParam {
    /// The field's path below the tracker's settings (`"nn_ratio"`, `"em.tau_orb"`,
    /// `"motion.link_px"`), as the settings file's `[tracker]` keys name it.
    pub field: &'static str,
    /// The value given.
    pub value: f64,
    /// What it must be (`"must be in (0, 1]"`).
    pub rule: &'static str,
}

impl core::fmt::Display for BadParam {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{} = {} {}", self.field, self.value, self.rule)
    }
}

impl TrackerParams {
    /// Checks every value against what the tracker accepts: distances, radii, scales and
    /// temperatures > 0 (only `mono_beyond_baselines` may be infinite), ratios and priors in
    /// (0, 1], `em.min_weight` in [0, 1), the motion test's lengths and speeds finite and
    /// ≥ 0, and at least one keyframe interval, BA keyframe and EM iteration.
    ///
    /// # Errors
    /// The first value out of range, naming its field.
    pub fn check(&self) -> Result<(), BadParam> {
        let bad = |field, value: f64, rule| Err(BadParam { field, value, rule });
        let (em, m) = (&self.em, &self.motion);
        for (field, v) in [
            ("close_depth_baselines", self.close_depth_baselines),
            ("wide_radius_px", f64::from(self.wide_radius_px)),
            ("narrow_radius_px", f64::from(self.narrow_radius_px)),
            ("em.tau_orb", em.tau_orb),
            ("em.tau_sem", em.tau_sem),
            ("em.class_prior", em.class_prior),
            ("motion.link_px", f64::from(m.link_px)),
            ("motion.link_m", f64::from(m.link_m)),
            ("motion.max_frame_llr", f64::from(m.max_frame_llr)),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, v, "must be > 0 and finite");
            }
        }
        if self.mono_beyond_baselines.is_nan() || self.mono_beyond_baselines <= 0.0 {
            return bad("mono_beyond_baselines", self.mono_beyond_baselines, "must be > 0");
        }
        for (field, v) in [
            ("nn_ratio", f64::from(self.nn_ratio)),
            ("keyframe_ratio", f64::from(self.keyframe_ratio)),
            ("motion.prior_vehicle", f64::from(m.prior_vehicle)),
            ("motion.prior_human", f64::from(m.prior_human)),
        ] {
            if !(v > 0.0 && v <= 1.0) {
                return bad(field, v, "must be in (0, 1]");
            }
        }
        if !(em.min_weight.is_finite() && (0.0..1.0).contains(&em.min_weight)) {
            return bad("em.min_weight", em.min_weight, "must be in [0, 1)");
        }
        for (field, v) in [
            ("motion.track_px", m.track_px),
            ("motion.camera_height_m", m.camera_height_m),
            ("motion.slow_human_mps", m.slow_human_mps),
            ("motion.slow_vehicle_mps", m.slow_vehicle_mps),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, f64::from(v), "must be finite and ≥ 0");
            }
        }
        for (field, v) in [
            ("keyframe_max_interval", u64::from(self.keyframe_max_interval)),
            ("ba_keyframes", self.ba_keyframes as u64),
            ("em.iterations", u64::from(em.iterations)),
        ] {
            if v == 0 {
                return bad(field, 0.0, "must be ≥ 1");
            }
        }
        Ok(())
    }
}

impl Default for TrackerParams {
    fn default() -> Self {
        Self {
            close_depth_baselines: 35.0,
            min_new_landmarks: 300,
            wide_radius_px: 15.0,
            narrow_radius_px: 4.0,
            max_hamming: 100,
            nn_ratio: 0.8,
            mono_beyond_baselines: 40.0,
            min_inliers: 20,
            keyframe_ratio: 0.75,
            keyframe_max_interval: 10,
            ba_iterations: 5,
            ba_keyframes: 15,
            triangulate: true,
            cull_keyframes: true,
            ransac_iterations: 100,
            ransac_seed: 0,
            association: Association::Hard,
            em: EmParams::default(),
            motion: MotionParams::default(),
        }
    }
}

/// Tracking state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TrackState {
    /// No map yet (waiting for a frame with enough stereo points).
    Uninitialised,
    /// Tracking against the map.
    Tracking,
}

/// How a frame's pose was obtained: what a user must know before trusting it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameStatus {
    /// The first map was started on this frame (its pose is the origin, or the prediction).
    Initialised,
    /// Tracked against the map: the pose is measured.
    Tracked,
    /// Tracking failed on this frame and no new map could be started: the pose is extrapolated
    /// with the constant-velocity model.
    Lost,
    /// No map (still lost after a loss, or not yet initialised): the pose is extrapolated, not
    /// measured.
    Coasted,
    /// A new map was started on this frame after tracking had been lost: the pose is the
    /// extrapolated one, and poses after it are relative to it.
    Reinitialised,
}

impl FrameStatus {
    /// The name written to `frames.csv`: `initialised`, `tracked`, `lost`, `coasted`,
    /// `reinitialised`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Initialised => "initialised",
            Self::Tracked => "tracked",
            Self::Lost => "lost",
            Self::Coasted => "coasted",
            Self::Reinitialised => "reinitialised",
        }
    }

    /// Whether the pose was measured on this frame (tracked, or the first map's origin), as
    /// opposed to extrapolated.
    pub fn measured(self) -> bool {
        matches!(self, Self::Initialised | Self::Tracked)
    }
}

/// How a feature of the last processed frame served its pose ([`Tracker::feature_use`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FeatureUse {
    /// Matched to a map point and kept by the final pose solve.
    Inlier,
    /// Matched to a map point, rejected by the final pose solve (reprojection χ² over the
    /// threshold).
    Outlier,
    /// Not matched to any map point (or the frame was not tracked against a map).
    #[default]
    Unmatched,
}

/// What happened on one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameReport {
    /// Frame number (0-based, counts every call to `process`).
    pub frame_index: u32,
    /// Camera-to-world pose estimate.
    pub t_wc: Se3,
    /// State after the frame.
    pub state: TrackState,
    /// How the pose was obtained (measured or extrapolated).
    pub status: FrameStatus,
    /// Features with stereo depth in the input.
    pub stereo_features: u32,
    /// Landmark matches found by the projection search (final pass).
    pub matched: u32,
    /// Matches that survived pose optimisation.
    pub inliers: u32,
    /// Whether the frame became a keyframe.
    pub keyframe: bool,
    /// Landmarks created on this frame.
    pub new_landmarks: u32,
    /// The map was (re-)initialised on this frame.
    pub initialised: bool,
    /// Tracking was lost on this frame and the map re-initialised.
    pub lost: bool,
    /// Live landmarks after the frame.
    pub landmarks: u32,
    /// Keyframes in the map after the frame.
    pub keyframes: u32,
    /// BA iterations run on this frame.
    pub ba_iterations: u32,
    /// Features whose EM association differs from the nearest-neighbour candidate.
    pub em_changed: u32,
    /// The motion test of motion-aware semantics (all zero when off).
    pub motion: MotionReport,
}

/// Counters over the whole run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TrackerStats {
    /// Frames processed.
    pub frames: u32,
    /// Keyframes made.
    pub keyframes: u32,
    /// Times tracking was lost (each followed by re-initialisation).
    pub lost: u32,
    /// Frames whose pose was extrapolated rather than measured: [`FrameStatus::Lost`],
    /// [`FrameStatus::Coasted`] and [`FrameStatus::Reinitialised`] (six black frames in a row
    /// are one loss but six untracked frames).
    pub untracked_frames: u32,
    /// Maps started (the first one included).
    pub initialisations: u32,
    /// Landmark creations refused because the store was full.
    pub landmark_overflow: u32,
    /// Keyframes evicted (least recently used) because the store was full.
    pub keyframe_evictions: u32,
    /// Landmark observations dropped because a landmark's list was full.
    pub observation_overflow: u32,
    /// Keyframes removed as redundant by local mapping.
    pub keyframes_culled: u32,
    /// Landmarks created by triangulation between keyframes.
    pub triangulated: u32,
    /// Duplicate landmarks merged by fusion.
    pub landmarks_fused: u32,
    /// Dynamic-class features used as parked (motion-aware semantics), over the run.
    pub parked_features: u32,
    /// Dynamic-class features removed as moving, over the run.
    pub moving_features: u32,
    /// Dynamic-class features removed for lack of evidence, over the run.
    pub unproven_features: u32,
}

/// Why a tracker cannot be built.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TrackerError {
    /// Image size zero or beyond `u16`.
    BadImageSize {
        /// Width (px).
        width: u32,
        /// Height (px).
        height: u32,
    },
    /// A parameter is out of its range ([`TrackerParams::check`]).
    BadParam(BadParam),
}

impl core::fmt::Display for TrackerError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::BadImageSize { width, height } => {
                write!(f, "image size {width}x{height} is not usable (1..=65535 each)")
            }
            Self::BadParam(p) => write!(f, "tracker parameter {p}"),
        }
    }
}

impl core::error::Error for TrackerError {}

/// The stereo tracker. See the module documentation.
pub struct Tracker {
    cam: StereoCamera,
    params: TrackerParams,
    width: f32,
    height: f32,
    map: LocalMap,
    local: LocalSet,
    last_features: usize,
    state: TrackState,
    frame_index: u32,
    t_cw: Se3,
    velocity: Se3,
    has_velocity: bool,
    frames_since_kf: u32,
    stats: TrackerStats,
    // Per-frame scratch.
    search: ProjectionSearch,
    matches: Matches,
    problem: PoseProblem,
    corr: Vec<Correspondence, FRAME_CAPACITY>,
    em: EmScratch,
    motion_aware: bool,
    motion: MotionScratch,
    /// Whether the labels come from the segmentation network ([`Self::set_network_labels`]).
    network_labels: bool,
    /// Whether the last frame was tracked against the map (its matches and the pose
    /// problem's outlier flags describe it).
    solved: bool,
}

/// Memory budget of one tracker (bytes), checked at compile time: the ECU target gives the
/// whole localisation stack 32 MiB, of which the tracker (mostly its map) may take 18.
pub const TRACKER_BUDGET_BYTES: usize = 18 << 20;
const _: () = assert!(core::mem::size_of::<Tracker>() <= TRACKER_BUDGET_BYTES);

impl Tracker {
    /// Bytes one tracker occupies (all of its state; nothing else is allocated).
    pub const MEMORY_BYTES: usize = core::mem::size_of::<Tracker>();

    /// A tracker for images of `width`x`height` pixels from `cam`.
    ///
    /// # Errors
    /// [`TrackerError::BadImageSize`], or [`TrackerError::BadParam`] for parameters
    /// [`TrackerParams::check`] refuses.
    pub fn new(
        cam: StereoCamera,
        width: u32,
        height: u32,
        params: TrackerParams,
    ) -> Result<Self, TrackerError> {
        if width == 0 || height == 0 || width > 65535 || height > 65535 {
            return Err(TrackerError::BadImageSize { width, height });
        }
        params.check().map_err(TrackerError::BadParam)?;
        let mut problem = PoseProblem::new();
        problem.far_m = (params.mono_beyond_baselines * cam.baseline_m) as f32;
        Ok(Self {
            cam,
            params,
            width: width as f32,
            height: height as f32,
            map: LocalMap::new(width as f32, height as f32),
            local: LocalSet::new(),
            last_features: 0,
            state: TrackState::Uninitialised,
            frame_index: 0,
            t_cw: Se3::identity(),
            velocity: Se3::identity(),
            has_velocity: false,
            frames_since_kf: 0,
            stats: TrackerStats::default(),
            search: ProjectionSearch::new(width as f32, height as f32),
            matches: Matches::new(),
            problem,
            corr: Vec::new(),
            em: EmScratch::new(),
            motion_aware: false,
            motion: MotionScratch::new(),
            network_labels: false,
            solved: false,
        })
    }

    /// Turns motion-aware semantics on or off ([`crate::motion`]): dynamic-class features are
    /// then used where their object is tested static and removed where it moves. Meant for
    /// frames whose extractor keeps dynamic-class features
    /// ([`crate::seg::WeightScheme::Motion`]).
    pub fn set_motion_aware(&mut self, on: bool) {
        self.motion_aware = on;
    }

    /// Says whether the frames' labels come from the segmentation network (set by whoever
    /// supplies them; off at first). EM's class term depends on it ([`EmParams::class_term`]).
    pub fn set_network_labels(&mut self, on: bool) {
        self.network_labels = on;
    }

    /// Whether the frames' labels come from the segmentation network.
    pub fn network_labels(&self) -> bool {
        self.network_labels
    }

    /// Whether motion-aware semantics are on.
    pub fn motion_aware(&self) -> bool {
        self.motion_aware
    }

    /// What the motion test made of each feature of the last processed frame (all
    /// [`FeatureMotion::Static`] when motion-aware semantics are off).
    pub fn feature_motion(&self) -> &[FeatureMotion] {
        &self.motion.state[..self.last_features.min(FRAME_CAPACITY)]
    }

    /// Which features of the last processed frame the motion test kept from making a landmark
    /// (moving ones, and unproven ones matched to the landmark they would duplicate, on an
    /// object as likely moving as not, or on an object nothing of which is measured or has
    /// stereo depth); all `false` when motion-aware semantics are off. Any other unproven
    /// feature is not blocked: it had no match to hold out of the pose, and the landmark it may
    /// make is tested like any other dynamic-class landmark before it is used, so it is treated
    /// exactly as a parked car's feature would be.
    pub fn feature_blocked(&self) -> &[bool] {
        &self.motion.blocked[..self.last_features.min(FRAME_CAPACITY)]
    }

    /// The object the motion test grouped feature `i` of the last processed frame into, and
    /// how many of that object's features it measured (`None` for static-class features, and
    /// for every feature when motion-aware semantics are off or the frame was not tracked).
    /// Features with the same [`MotionSegment::id`] were decided together.
    pub fn feature_segment(&self, i: usize) -> Option<MotionSegment> {
        if i >= self.last_features.min(FRAME_CAPACITY) {
            return None;
        }
        self.motion.segment_of(i)
    }

    /// How each feature of the last processed frame served its pose: writes the first
    /// `out.len()` features' [`FeatureUse`] and returns how many were written (the frame's
    /// feature count at most). On a frame that was not tracked against the map (initialised,
    /// lost, coasted) every feature is [`FeatureUse::Unmatched`].
    pub fn feature_use(&self, out: &mut [FeatureUse]) -> usize {
        let n = self.last_features.min(FRAME_CAPACITY).min(out.len());
        out[..n].fill(FeatureUse::Unmatched);
        if !self.solved {
            return n;
        }
        for j in self.problem.outlier_features() {
            if let Some(u) = out[..n].get_mut(j) {
                *u = FeatureUse::Outlier;
            }
        }
        for (u, &id) in out[..n].iter_mut().zip(&self.matches.lm[..n]) {
            if id != NO_LANDMARK {
                *u = FeatureUse::Inlier;
            }
        }
        n
    }

    /// Forgets the map and the motion; the next frame initialises again at the identity.
    pub fn reset(&mut self) {
        self.map.clear();
        self.motion.forget_previous();
        self.last_features = 0;
        self.solved = false;
        self.state = TrackState::Uninitialised;
        self.frame_index = 0;
        self.t_cw = Se3::identity();
        self.velocity = Se3::identity();
        self.has_velocity = false;
        self.frames_since_kf = 0;
        self.stats = TrackerStats::default();
    }

    /// A frame period passed without a usable frame (the sensor dropped it, or the caller
    /// rejected it as corrupt): advances the constant-velocity prediction by one period, so the
    /// next frame is searched where the camera should be by then. The map is kept; without a
    /// motion estimate this does nothing. Allocation-free, like [`Tracker::process`].
    pub fn coast(&mut self) {
        if self.has_velocity {
            self.t_cw = renormalize(&self.velocity.compose(&self.t_cw));
        }
    }

    /// Forgets the motion model but keeps the map (the time since the last frame is unknown,
    /// e.g. after a timestamp jump): the next frame is predicted at the last pose, and if the
    /// search fails there the tracker re-initialises as on any loss.
    pub fn forget_motion(&mut self) {
        self.velocity = Se3::identity();
        self.has_velocity = false;
    }

    /// The current pose estimate, camera to world (the last frame's, or the coasted
    /// prediction after [`Tracker::coast`]).
    pub fn pose_wc(&self) -> Se3 {
        self.t_cw.inverse()
    }

    /// The camera.
    pub fn camera(&self) -> &StereoCamera {
        &self.cam
    }

    /// Counters over the run.
    pub fn stats(&self) -> TrackerStats {
        let mut s = self.stats;
        let c = self.map.map().counters;
        s.landmark_overflow = c.landmark_overflow;
        s.keyframe_evictions = c.keyframe_evictions;
        s.observation_overflow = c.observation_overflow;
        s.keyframes_culled = c.keyframes_culled;
        s.landmarks_fused = c.landmarks_fused;
        s
    }

    /// The map (read-only), for inspection and plots.
    pub fn map(&self) -> &Map {
        self.map.map()
    }

    /// Tracks one frame and returns its pose and counters.
    pub fn process(&mut self, frame: &Frame) -> FrameReport {
        let index = self.frame_index;
        self.frame_index = self.frame_index.wrapping_add(1);
        self.stats.frames += 1;
        let mut rep = FrameReport {
            frame_index: index,
            t_wc: self.t_cw.inverse(),
            state: self.state,
            status: FrameStatus::Tracked,
            stereo_features: frame.stereo_count() as u32,
            matched: 0,
            inliers: 0,
            keyframe: false,
            new_landmarks: 0,
            initialised: false,
            lost: false,
            landmarks: 0,
            keyframes: 0,
            ba_iterations: 0,
            em_changed: 0,
            motion: MotionReport::default(),
        };
        self.motion.reset(frame.features.len());
        self.motion.now_s = frame.timestamp_s;
        self.solved = false;
        let last = self.t_cw;
        // Every pose that feeds back into the next frame is re-orthonormalised: the
        // constant-velocity loop multiplies any drift of R from a rotation about threefold per
        // frame, which from rounding alone reaches centimetres within 30 frames.
        let predicted =
            if self.has_velocity { renormalize(&self.velocity.compose(&last)) } else { last };
        let had_map = self.stats.initialisations > 0;
        match self.state {
            TrackState::Uninitialised => {
                self.initialise(frame, index, predicted, &mut rep);
                rep.status = match (rep.initialised, had_map) {
                    (true, false) => FrameStatus::Initialised,
                    (true, true) => FrameStatus::Reinitialised,
                    (false, _) => FrameStatus::Coasted,
                };
            }
            TrackState::Tracking => {
                if self.track(frame, predicted, &mut rep) {
                    self.solved = true;
                    self.velocity = renormalize(&self.t_cw.compose(&last.inverse()));
                    self.has_velocity = true;
                    if self.need_keyframe(frame, &rep) {
                        self.insert_keyframe(frame, index, &mut rep);
                    } else {
                        self.frames_since_kf += 1;
                    }
                } else {
                    rep.lost = true;
                    self.stats.lost += 1;
                    self.initialise(frame, index, predicted, &mut rep);
                    rep.status = if rep.initialised {
                        FrameStatus::Reinitialised
                    } else {
                        FrameStatus::Lost
                    };
                }
            }
        }
        if rep.initialised {
            self.stats.initialisations += 1;
        }
        if !rep.status.measured() {
            self.stats.untracked_frames += 1;
        }
        rep.t_wc = self.t_cw.inverse();
        // The frame-to-frame motion test compares the next frame with this one's final pose.
        if self.motion_aware && self.solved {
            self.motion.remember(
                &frame.features,
                &self.cam,
                &rep.t_wc,
                self.problem.far_m,
                &self.params.motion,
            );
        } else {
            self.motion.forget_previous();
        }
        rep.state = self.state;
        rep.landmarks = self.map.map().landmark_count() as u32;
        rep.keyframes = self.map.map().len() as u32;
        self.last_features = frame.features.len();
        rep
    }

    /// Starts a new map from this frame's stereo points at pose `t_cw`.
    fn initialise(&mut self, frame: &Frame, index: u32, t_cw: Se3, rep: &mut FrameReport) {
        self.t_cw = t_cw;
        if frame.stereo_count() < 50 {
            // Not enough structure: keep predicting, try again next frame.
            self.state = TrackState::Uninitialised;
            return;
        }
        self.map.clear();
        self.matches.lm.fill(NO_LANDMARK);
        self.insert_keyframe(frame, index, rep);
        self.state = TrackState::Tracking;
        rep.initialised = true;
    }

    /// Projection search, association, pose optimisation; false when tracking is lost.
    fn track(&mut self, frame: &Frame, predicted: Se3, rep: &mut FrameReport) -> bool {
        let feats = &frame.features[..];
        self.search.prepare(feats);
        self.t_cw = predicted;
        // The local map around what the last frame matched (ORB-SLAM2 tracks the motion
        // model against the last frame's points, which this covers).
        let n_last = self.last_features.min(FRAME_CAPACITY);
        self.local.update(self.map.map_mut(), &self.matches.lm[..n_last], self.frame_index);
        let mut matched = if self.has_velocity {
            let m = self.search_pass(feats, self.params.wide_radius_px, false);
            if m < 30 {
                self.search_pass(feats, self.params.wide_radius_px * 3.0, false)
            } else {
                m
            }
        } else {
            self.appearance_pass(feats)
        };
        matched -= self.hold_unproven(feats);
        if matched < 10 {
            return false;
        }
        // Optimise from the prediction and, when RANSAC finds a better-supported start, from
        // that too; keep whichever ends with more inliers (ties: the prediction).
        // From the prediction every match starts as an inlier (the prediction may be pixels
        // off); from a RANSAC start its consensus decides.
        let mut first = self.optimise(feats, false);
        if let Some(start) = self.ransac_start(feats, &predicted) {
            let from_prediction = (self.t_cw, self.inlier_coverage(feats));
            self.t_cw = start;
            let from_ransac = self.optimise(feats, true);
            // The winner is the start whose inliers cover more of the image, not the one with
            // more inliers: a van or cyclist moving with the camera can supply as many
            // consistent matches as the static scene, but only from a compact patch of it.
            if self.inlier_coverage(feats) > from_prediction.1 {
                first = from_ransac;
            } else {
                self.t_cw = from_prediction.0;
            }
        }
        if first < 10 {
            return false;
        }
        // TrackLocalMap: the local map around this frame's own matches, searched narrowly.
        self.problem.drop_outliers(&mut self.matches);
        self.local.update(self.map.map_mut(), &self.matches.lm[..feats.len()], self.frame_index);
        matched = self.search_pass(feats, self.params.narrow_radius_px, true);
        self.hold_unproven(feats);
        let mut inliers = if self.params.association == Association::Em {
            let input = EmInput {
                frame,
                window: self.map.map(),
                cam: &self.cam,
                params: &self.params.em,
                null_max_hamming: self.params.max_hamming,
                far_m: self.problem.far_m,
                class_term: self.params.em.class_term.applies(self.network_labels),
            };
            let em =
                self.em.associate(&input, &mut self.t_cw, &mut self.problem, &mut self.matches);
            rep.em_changed = em.changed;
            em.inliers
        } else {
            let inliers = self.optimise(feats, false);
            // Drop outlier matches so keyframes record only inliers.
            self.problem.drop_outliers(&mut self.matches);
            inliers
        };
        if self.motion_aware {
            let (report, relinked) = self.motion_test(feats);
            rep.motion = report;
            self.stats.parked_features += report.parked_features;
            self.stats.moving_features += report.moving_features;
            self.stats.unproven_features += report.unproven_features;
            if relinked > 0 {
                // Parked objects rejoin the pose (moving ones leave it): one more solve.
                self.problem.collect(self.map.map(), feats, &self.matches, true);
                let params = PoseOptParams::default();
                inliers = self.problem.solve(&self.cam, &mut self.t_cw, true, &params).inliers;
                self.problem.drop_outliers(&mut self.matches);
            }
        }
        rep.matched = matched;
        rep.inliers = inliers;
        let window = self.map.map_mut();
        for i in 0..feats.len() {
            let id = self.matches.lm[i];
            if id != NO_LANDMARK {
                let l = window.lm_mut(id);
                l.found += 1;
                l.last_matched_frame = self.frame_index;
            }
        }
        inliers >= self.params.min_inliers
    }

    /// One projection-search pass at the current pose with radius `radius_px` at level 0; the
    /// final pass (`last`) counts landmark visibility and, under EM, gathers the candidates.
    fn search_pass(&mut self, feats: &[Feature], radius_px: f32, last: bool) -> u32 {
        let em = last && self.params.association == Association::Em;
        let q = SearchQuery {
            t_cw: self.t_cw,
            radius_px,
            max_hamming: self.params.max_hamming,
            nn_ratio: self.params.nn_ratio,
            ratio_any_level: false,
            count_visible: last,
            em_gate: em.then_some(self.params.em.max_hamming),
        };
        self.search_local_map(feats, &q)
    }

    /// Matches the local map's landmarks to `feats` as `q` says (into `matches` and, with an EM
    /// gate, EM's candidates); returns the number of matched features.
    fn search_local_map(&mut self, feats: &[Feature], q: &SearchQuery) -> u32 {
        self.search.search(
            self.map.map_mut(),
            &self.local.lms,
            &self.cam,
            feats,
            q,
            &mut self.matches,
            &mut self.em.cands,
        )
    }

    /// The first search when there is no motion estimate (the first frame after the map is
    /// initialised, or after [`Tracker::forget_motion`]): the prediction is then the last pose,
    /// and a camera that moves a metre per frame moves near points far outside the wide
    /// radius, so only far points (rotation, not translation) would match by projection and the
    /// pose would hang on which RANSAC hypotheses were drawn (KITTI 01: Sim(3) ATE 0.03 m or
    /// 0.5–5.5 m depending on the seed). As ORB-SLAM2's `TrackReferenceKeyFrame`, the local map
    /// is matched by appearance alone, anywhere in the image (±1 pyramid level of the
    /// predicted one), with its stricter `TH_LOW` and a ratio test over all levels (0.9, not its
    /// 0.7: see [`APPEARANCE_NN_RATIO`]); RANSAC and the pose solve then find the motion.
    fn appearance_pass(&mut self, feats: &[Feature]) -> u32 {
        let q = SearchQuery {
            t_cw: self.t_cw,
            radius_px: self.width.max(self.height),
            max_hamming: APPEARANCE_MAX_HAMMING,
            nn_ratio: APPEARANCE_NN_RATIO,
            ratio_any_level: true,
            count_visible: false,
            em_gate: None,
        };
        self.search_local_map(feats, &q)
    }

    /// Motion-aware semantics: takes the matches of dynamic-class features whose landmark is
    /// not confirmed static, and any match to a landmark confirmed moving, out of the pose
    /// problem (and EM's candidates), remembering them for [`Self::motion_test`]. Holds nothing
    /// when fewer than [`TrackerParams::min_inliers`] other matches would remain: the frame
    /// could not be tracked on them, so a frame filled by a wrongly labelled "car" is still
    /// tracked. (At 30, a truck ahead filling a frame of synthetic `high` with 20-29 static
    /// matches left was solved with, dragged the pose and was then found consistent with it:
    /// tracking from that frame on broke as the backbone's does, 16 m of ATE.) Returns how
    /// many matches it held.
    fn hold_unproven(&mut self, feats: &[Feature]) -> u32 {
        if !self.motion_aware {
            return 0;
        }
        let n = feats.len();
        let m = &mut self.motion;
        m.cand[..n].fill(NO_LANDMARK);
        m.held[..n].fill(false);
        let window = self.map.map();
        let (mut held, mut kept) = (0u32, 0u32);
        for (i, f) in feats.iter().enumerate() {
            let id = self.matches.lm[i];
            if id == NO_LANDMARK {
                continue;
            }
            let lo = window.lm(id).moving_lo;
            let dynamic = is_dynamic(f.class);
            // Static-class features leave a landmark only on strong evidence (p > 0.88 without
            // a prior): labels flicker at object borders.
            let hold = if dynamic {
                self.params.motion.prior_logit(f.class) + lo >= STATIC_LOGIT
            } else {
                lo > MOVING_LOGIT + 2.0
            };
            // Every dynamic-class match is measured after the solve, held or not.
            if dynamic || hold {
                m.cand[i] = id;
            }
            if hold {
                m.held[i] = true;
                held += 1;
            } else {
                kept += 1;
            }
        }
        if held == 0 || kept < self.params.min_inliers {
            m.held[..n].fill(false);
            return 0;
        }
        for i in 0..n {
            if m.held[i] {
                self.matches.lm[i] = NO_LANDMARK;
                self.em.cands[i] = crate::assoc::Candidates::EMPTY;
            }
        }
        held
    }

    /// Motion-aware semantics after the pose solve: measures every remembered dynamic-class
    /// match at the solved pose, segments the objects and decides which are parked, moving or
    /// unproven ([`MotionScratch::decide`]). Consistent matches of parked objects are linked
    /// again; matches of moving ones are unlinked. Returns the report and how many links
    /// changed (the pose is then solved again).
    fn motion_test(&mut self, feats: &[Feature]) -> (MotionReport, u32) {
        let window = self.map.map_mut();
        for (i, f) in feats.iter().enumerate() {
            let id = self.motion.cand[i];
            if id == NO_LANDMARK {
                continue;
            }
            let z = measurement(f, self.problem.far_m);
            let l = window.lm(id);
            let pc = self.t_cw.transform_point(&l.p_w);
            match chi2(&self.cam, &pc, &z) {
                Some(c) => {
                    self.motion.chi2[i] = c as f32;
                    self.motion.gate[i] = z.chi2_threshold() as f32;
                    // Would an object that kept its place relative to the camera since the
                    // landmark's latest keyframe observation, or one walking slowly along the
                    // road since then, have passed too? Then the pass is no evidence of
                    // standing still.
                    let last = l.obs[..usize::from(l.n_obs)].last();
                    let seen = last.and_then(|o| window.kf(o.kf).features.get(usize::from(o.feat)));
                    let obs = seen.map(|k| [k.x, k.y, if k.is_stereo() { k.ur } else { -1.0 }]);
                    let since =
                        last.map_or(0.0, |o| self.motion.now_s - window.kf(o.kf).timestamp_s);
                    self.motion.uninformative[i] = a_mover_passes_too(
                        &self.cam,
                        &pc,
                        &z,
                        obs,
                        since,
                        self.params.motion.slow_mps(f.class),
                    );
                }
                None => self.motion.chi2[i] = -1.0,
            }
        }
        self.motion.match_previous(
            feats,
            &self.cam,
            &self.t_cw,
            self.problem.far_m,
            &self.params.motion,
            self.params.max_hamming.min(crate::motion::TRACK_MAX_HAMMING),
            self.params.nn_ratio,
        );
        let report =
            self.motion.decide(feats, &self.cam, &self.t_cw, &self.params.motion, |id, e| {
                let l = window.lm_mut(id);
                l.moving_lo = (l.moving_lo + e).clamp(-MAX_LANDMARK_LOGIT, MAX_LANDMARK_LOGIT);
                l.moving_lo
            });
        let mut relinked = 0;
        for i in 0..feats.len() {
            match self.motion.state[i] {
                FeatureMotion::Parked if self.motion.held[i] && self.motion.consistent(i) => {
                    self.matches.lm[i] = self.motion.cand[i];
                    self.matches.weight[i] = 1.0;
                    relinked += 1;
                }
                // Linked only when nothing was held (too few other matches): solved with.
                FeatureMotion::Moving if self.matches.lm[i] != NO_LANDMARK => {
                    self.matches.unlink(i);
                    relinked += 1;
                }
                _ => {}
            }
        }
        (report, relinked)
    }

    /// RANSAC over the wide-pass matches: the best three-point hypothesis if it explains more
    /// matches than the constant-velocity prediction. In traffic this is what keeps a vehicle
    /// driving ahead of the camera from dragging the pose along.
    fn ransac_start(&mut self, feats: &[Feature], predicted: &Se3) -> Option<Se3> {
        self.corr.clear();
        for (i, f) in feats.iter().enumerate() {
            let id = self.matches.lm[i];
            if id == NO_LANDMARK {
                continue;
            }
            let p_c = f.is_stereo().then(|| {
                self.cam.backproject(f64::from(f.x), f64::from(f.y), f64::from(f.depth_m))
            });
            let z = measurement(f, self.problem.far_m);
            let c = Correspondence { p_w: self.map.map().lm(id).p_w, p_c, z };
            let _ = self.corr.push(c);
        }
        // Seed 0 keeps the stream every earlier result was measured with.
        let seed = (u64::from(self.frame_index) ^ 0x5e31_0c00_0000_0001)
            .wrapping_add(self.params.ransac_seed.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let r = ransac_pose(&self.cam, &self.corr, self.params.ransac_iterations, seed)?;
        (r.inliers > count_inliers(&self.cam, predicted, &self.corr)).then_some(r.t_cw)
    }

    /// Number of cells of a 16x8 image grid holding at least one inlier of the last
    /// [`Tracker::optimise`] call.
    fn inlier_coverage(&self, feats: &[Feature]) -> u32 {
        self.problem.inlier_coverage(feats, self.width, self.height)
    }

    /// Motion-only optimisation against the current matches (weight 1); returns the inlier
    /// count. With `classify`, matches are first split into inliers and outliers at the
    /// current pose (after RANSAC) instead of all starting as inliers.
    fn optimise(&mut self, feats: &[Feature], classify: bool) -> u32 {
        self.problem.collect(self.map.map(), feats, &self.matches, false);
        let params = PoseOptParams::default();
        self.problem.solve(&self.cam, &mut self.t_cw, classify, &params).inliers
    }

    /// ORB-SLAM2's keyframe criteria, with local mapping always idle (we run it inline).
    fn need_keyframe(&self, frame: &Frame, rep: &FrameReport) -> bool {
        if self.frames_since_kf + 1 >= self.params.keyframe_max_interval {
            return true;
        }
        let th_close = self.params.close_depth_baselines * self.cam.baseline_m;
        let (mut tracked_close, mut untracked_close) = (0u32, 0u32);
        for (i, f) in frame.features.iter().enumerate() {
            if f.is_stereo() && f64::from(f.depth_m) < th_close {
                if self.matches.lm[i] != NO_LANDMARK {
                    tracked_close += 1;
                } else {
                    untracked_close += 1;
                }
            }
        }
        let need_close = tracked_close < 100 && untracked_close > 70;
        let weak =
            (rep.inliers as f32) < self.params.keyframe_ratio * self.reference_tracked() as f32;
        (weak || need_close) && rep.inliers > 15
    }

    /// Landmarks of the reference keyframe (the one sharing most landmarks with this frame)
    /// seen by at least `min_obs` keyframes (ORB-SLAM2's `TrackedMapPoints(nMinObs)`: 3, or 2
    /// while the map has two keyframes or fewer). A keyframe's freshly created points have
    /// one observation and do not count, or every frame would look weak against the keyframe
    /// that made them.
    fn reference_tracked(&self) -> u32 {
        let window = self.map.map();
        let Some(slot) = self.local.reference.or(window.newest_slot()) else { return 0 };
        let kf = window.kf(slot);
        if !kf.alive {
            return 0;
        }
        let min_obs = if window.len() <= 2 { 2 } else { 3 };
        kf.landmark[..kf.features.len()]
            .iter()
            .filter(|&&id| {
                id != NO_LANDMARK && window.lm(id).alive && window.lm(id).n_obs >= min_obs
            })
            .count() as u32
    }

    /// Makes the current frame a keyframe: the map records the tracked observations with
    /// their association weights, creates landmarks, runs BA (whose result becomes the
    /// current pose) and culls.
    fn insert_keyframe(&mut self, frame: &Frame, index: u32, rep: &mut FrameReport) {
        let params = MappingParams {
            close_depth_baselines: self.params.close_depth_baselines,
            min_new_landmarks: self.params.min_new_landmarks,
            ba_iterations: self.params.ba_iterations,
            ba_keyframes: self.params.ba_keyframes,
            triangulate: self.params.triangulate,
            cull_keyframes: self.params.cull_keyframes,
            far_m: self.problem.far_m,
        };
        let kf = NewKeyframe {
            frame,
            frame_index: index,
            t_cw: self.t_cw,
            landmark: &self.matches.lm,
            weight: &self.matches.weight,
            blocked: self.motion_aware.then_some(&self.motion.blocked),
            moving_lo: self.motion_aware.then_some(&self.motion.lo_out),
        };
        let out = self.map.insert_keyframe(&self.cam, &params, &kf, self.frame_index);
        rep.new_landmarks = out.new_landmarks + out.triangulated;
        self.stats.triangulated += out.triangulated;
        rep.keyframe = true;
        self.stats.keyframes += 1;
        self.frames_since_kf = 0;
        rep.ba_iterations = out.ba_iterations;
        if let Some(t_cw) = out.t_cw {
            self.t_cw = t_cw;
        }
    }
}

#[cfg(test)]
mod tests;
