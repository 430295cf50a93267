//! The per-frame stereo tracker: the one entry point of core's SLAM.
//!
//! Per frame (the structure of ORB-SLAM2's `Tracking` + `LocalMapping`, in a bounded window):
//! 1. predict the pose with a constant-velocity model;
//! 2. project every window landmark, search the frame's features near it (grid lookup,
//!    predicted scale level ±1, stereo column check, Hamming best/second ratio) — a wide pass,
//!    motion-only pose optimisation, then a narrow pass and a final optimisation;
//! 3. decide on a keyframe (tracked share of the reference keyframe's landmarks, close stereo
//!    points, a maximum interval);
//! 4. for a keyframe: record observations, create landmarks from stereo features, run
//!    sliding-window BA (oldest keyframe fixed), drop outlier observations, cull landmarks;
//! 5. if too few inliers remain the map is re-initialised at the predicted pose (counted).
//!
//! Memory: one [`Tracker`] holds everything (see [`Tracker::MEMORY_BYTES`]); `process`
//! allocates nothing. Build it once (in a `static` on a target, on a large-stack thread or in
//! a `Box` on a host) and reuse it.

use heapless::Vec;
use nalgebra::Vector3;

use crate::assoc::{
    class_log_likelihood, normalise, semantic_log_likelihood, Association, Candidate, Candidates,
    EmParams, MAX_CANDIDATES,
};
use crate::frame::{hamming, level_inv_sigma2, level_scale, Feature, Frame, FRAME_CAPACITY};
use crate::geom::{Se3, StereoCamera};
use crate::map::{Window, MAX_KEYFRAMES, MAX_LANDMARKS, NO_LANDMARK};
use crate::math;
use crate::optim::{
    bundle_adjust, chi2, optimize_pose, BaObs, BaParams, BaScratch, Measurement, PoseObs,
    PoseOptParams,
};
use crate::ransac::{count_inliers, ransac_pose, Correspondence};
use crate::seg::{NUM_CLASSES, VOID};

/// Grid used to look up features near a projected landmark.
const GRID_COLS: usize = 64;
const GRID_ROWS: usize = 24;
const GRID_CELLS: usize = GRID_COLS * GRID_ROWS;
/// Most (feature, candidate) pairs one EM M-step holds.
const MAX_PAIRS: usize = FRAME_CAPACITY * MAX_CANDIDATES;
/// Most observations one BA problem holds.
const MAX_BA_OBS: usize = MAX_KEYFRAMES * FRAME_CAPACITY;

/// Tracker settings; defaults follow ORB-SLAM2's stereo KITTI configuration where it has one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerParams {
    /// Stereo points closer than this many baselines are "close" (ORB-SLAM2 `ThDepth` 35).
    pub close_depth_baselines: f64,
    /// A new keyframe creates landmarks from all close stereo points and, if fewer, the
    /// nearest ones up to this count. ORB-SLAM2 uses 100 but adds many more points later by
    /// triangulating between keyframes, which this tracker does not do; 300 measured best
    /// overall (synthetic high traffic with culling: ATE 0.72 m → 0.22 m and no losses;
    /// static 0.20 → 0.08 m; KITTI raw 0005 0.677 → 0.680 m; 500 helps synthetic data
    /// further but costs KITTI accuracy and BA time).
    pub min_new_landmarks: usize,
    /// First-pass search radius at level 0 (px).
    pub wide_radius_px: f32,
    /// Second-pass search radius at level 0 (px).
    pub narrow_radius_px: f32,
    /// Largest Hamming distance accepted for a match (ORB-SLAM2 `TH_HIGH`).
    pub max_hamming: u32,
    /// Best/second-best ratio when both are on the same level (ORB-SLAM2 0.8).
    pub nn_ratio: f32,
    /// Fewer inliers than this and tracking is lost.
    pub min_inliers: u32,
    /// Keyframe when tracked landmarks fall below this share of the reference keyframe's.
    pub keyframe_ratio: f32,
    /// Keyframe at least every this many frames.
    pub keyframe_max_interval: u32,
    /// BA iterations per keyframe.
    pub ba_iterations: u8,
    /// RANSAC hypotheses per frame (0 disables RANSAC).
    pub ransac_iterations: u32,
    /// Nearest-neighbour or EM association.
    pub association: Association,
    /// EM settings (used with [`Association::Em`]).
    pub em: EmParams,
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
            min_inliers: 20,
            keyframe_ratio: 0.75,
            keyframe_max_interval: 10,
            ba_iterations: 8,
            ransac_iterations: 100,
            association: Association::Hard,
            em: EmParams::default(),
        }
    }
}

/// Tracking state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TrackState {
    /// No map yet (waiting for a frame with enough stereo points).
    Uninitialised,
    /// Tracking against the window.
    Tracking,
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
    /// Keyframes in the window after the frame.
    pub keyframes: u32,
    /// BA iterations run on this frame.
    pub ba_iterations: u32,
    /// Features whose EM association differs from the nearest-neighbour candidate.
    pub em_changed: u32,
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
    /// Landmark creations refused because the store was full.
    pub landmark_overflow: u32,
}

/// Why a tracker cannot be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
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
}

impl core::fmt::Display for TrackerError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::BadImageSize { width, height } => {
                write!(f, "image size {width}x{height} is not usable (1..=65535 each)")
            }
        }
    }
}

impl core::error::Error for TrackerError {}

/// Features of the current frame bucketed by image cell (counting sort, no allocation).
struct FeatureGrid {
    start: [u16; GRID_CELLS + 1],
    items: [u16; FRAME_CAPACITY],
    inv_cell_w: f32,
    inv_cell_h: f32,
}

impl FeatureGrid {
    const fn new() -> Self {
        Self {
            start: [0; GRID_CELLS + 1],
            items: [0; FRAME_CAPACITY],
            inv_cell_w: 1.0,
            inv_cell_h: 1.0,
        }
    }

    fn cell_of(&self, x: f32, y: f32) -> (usize, usize) {
        let cx = (x * self.inv_cell_w) as isize;
        let cy = (y * self.inv_cell_h) as isize;
        (cx.clamp(0, GRID_COLS as isize - 1) as usize, cy.clamp(0, GRID_ROWS as isize - 1) as usize)
    }

    fn build(&mut self, features: &[Feature], width: f32, height: f32) {
        self.inv_cell_w = GRID_COLS as f32 / width;
        self.inv_cell_h = GRID_ROWS as f32 / height;
        let mut count = [0u16; GRID_CELLS];
        for f in features {
            let (cx, cy) = self.cell_of(f.x, f.y);
            count[cy * GRID_COLS + cx] += 1;
        }
        self.start[0] = 0;
        for (c, n) in count.iter().enumerate() {
            self.start[c + 1] = self.start[c] + n;
        }
        let mut fill = [0u16; GRID_CELLS];
        for (i, f) in features.iter().enumerate() {
            let (cx, cy) = self.cell_of(f.x, f.y);
            let c = cy * GRID_COLS + cx;
            self.items[usize::from(self.start[c] + fill[c])] = i as u16;
            fill[c] += 1;
        }
    }
}

/// The stereo tracker. See the module documentation.
pub struct Tracker {
    cam: StereoCamera,
    params: TrackerParams,
    width: f32,
    height: f32,
    window: Window,
    state: TrackState,
    frame_index: u32,
    t_cw: Se3,
    velocity: Se3,
    has_velocity: bool,
    frames_since_kf: u32,
    stats: TrackerStats,
    // Per-frame scratch.
    grid: FeatureGrid,
    feat_lm: [u32; FRAME_CAPACITY],
    feat_dist: [u32; FRAME_CAPACITY],
    pose_obs: Vec<PoseObs, MAX_PAIRS>,
    corr: Vec<Correspondence, FRAME_CAPACITY>,
    pose_feat: [u16; MAX_PAIRS],
    pose_lm: [u32; MAX_PAIRS],
    outlier: [bool; MAX_PAIRS],
    cands: [Candidates; FRAME_CAPACITY],
    feat_weight: [f32; FRAME_CAPACITY],
    /// Feature holding each landmark in the EM decision (u16::MAX: none); reset after use.
    lm_claim: [u16; MAX_LANDMARKS],
    // Keyframe scratch.
    order_keys: Vec<u64, FRAME_CAPACITY>,
    ba: BaScratch,
    ba_keys: Vec<u64, MAX_BA_OBS>,
    ba_obs: Vec<BaObs, MAX_BA_OBS>,
    ba_points: [Vector3<f64>; MAX_LANDMARKS],
    ba_backup: [Vector3<f64>; MAX_LANDMARKS],
    ba_ids: [u32; MAX_LANDMARKS],
    lm_compact: [u32; MAX_LANDMARKS],
}

/// Memory budget of one tracker (bytes), checked at compile time: the ECU target gives the
/// whole localisation stack 32 MiB, of which the tracker may take 8.
pub const TRACKER_BUDGET_BYTES: usize = 8 << 20;
const _: () = assert!(core::mem::size_of::<Tracker>() <= TRACKER_BUDGET_BYTES);

/// `ln(1.2)`, for predicting the pyramid level a landmark appears on.
const LN_SCALE: f64 = 0.182_321_556_793_954_6;

impl Tracker {
    /// Bytes one tracker occupies (all of its state; nothing else is allocated).
    pub const MEMORY_BYTES: usize = core::mem::size_of::<Tracker>();

    /// A tracker for images of `width`x`height` pixels from `cam`.
    pub fn new(
        cam: StereoCamera,
        width: u32,
        height: u32,
        params: TrackerParams,
    ) -> Result<Self, TrackerError> {
        if width == 0 || height == 0 || width > 65535 || height > 65535 {
            return Err(TrackerError::BadImageSize { width, height });
        }
        let mut t = Self {
            cam,
            params,
            width: width as f32,
            height: height as f32,
            window: Window::new(),
            state: TrackState::Uninitialised,
            frame_index: 0,
            t_cw: Se3::identity(),
            velocity: Se3::identity(),
            has_velocity: false,
            frames_since_kf: 0,
            stats: TrackerStats::default(),
            grid: FeatureGrid::new(),
            feat_lm: [NO_LANDMARK; FRAME_CAPACITY],
            feat_dist: [u32::MAX; FRAME_CAPACITY],
            pose_obs: Vec::new(),
            corr: Vec::new(),
            pose_feat: [0; MAX_PAIRS],
            pose_lm: [0; MAX_PAIRS],
            outlier: [false; MAX_PAIRS],
            cands: [Candidates::EMPTY; FRAME_CAPACITY],
            feat_weight: [1.0; FRAME_CAPACITY],
            lm_claim: [u16::MAX; MAX_LANDMARKS],
            order_keys: Vec::new(),
            ba: BaScratch::new(),
            ba_keys: Vec::new(),
            ba_obs: Vec::new(),
            ba_points: [Vector3::new(0.0, 0.0, 0.0); MAX_LANDMARKS],
            ba_backup: [Vector3::new(0.0, 0.0, 0.0); MAX_LANDMARKS],
            ba_ids: [0; MAX_LANDMARKS],
            lm_compact: [u32::MAX; MAX_LANDMARKS],
        };
        t.window.clear();
        Ok(t)
    }

    /// Forgets the map and the motion; the next frame initialises again at the identity.
    pub fn reset(&mut self) {
        self.window.clear();
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
        s.landmark_overflow = self.window.landmark_overflow;
        s
    }

    /// The window (read-only), for inspection and plots.
    pub fn window(&self) -> &Window {
        &self.window
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
        };
        let last = self.t_cw;
        // Every pose that feeds back into the next frame is re-orthonormalised: the
        // constant-velocity loop multiplies any drift of R from a rotation about threefold per
        // frame, which from rounding alone reaches centimetres within 30 frames.
        let predicted =
            if self.has_velocity { renormalize(&self.velocity.compose(&last)) } else { last };
        match self.state {
            TrackState::Uninitialised => self.initialise(frame, index, predicted, &mut rep),
            TrackState::Tracking => {
                if self.track(frame, predicted, &mut rep) {
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
                }
            }
        }
        rep.t_wc = self.t_cw.inverse();
        rep.state = self.state;
        rep.landmarks = self.window.landmark_count() as u32;
        rep.keyframes = self.window.len() as u32;
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
        self.window.clear();
        self.feat_lm.fill(NO_LANDMARK);
        self.outlier.fill(false);
        self.insert_keyframe(frame, index, rep);
        self.state = TrackState::Tracking;
        rep.initialised = true;
    }

    /// Projection search, pose optimisation; false when tracking is lost.
    fn track(&mut self, frame: &Frame, predicted: Se3, rep: &mut FrameReport) -> bool {
        let feats = &frame.features[..];
        self.grid.build(feats, self.width, self.height);
        self.t_cw = predicted;
        let mut matched = self.search(feats, self.params.wide_radius_px, false);
        if matched < 30 {
            matched = self.search(feats, self.params.wide_radius_px * 3.0, false);
        }
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
        matched = self.search(feats, self.params.narrow_radius_px, true);
        let inliers = if self.params.association == Association::Em {
            let (inliers, changed) = self.em_associate(frame);
            rep.em_changed = changed;
            inliers
        } else {
            let inliers = self.optimise(feats, false);
            // Drop outlier matches so keyframes record only inliers.
            for (k, &f) in self.pose_feat[..self.pose_obs.len()].iter().enumerate() {
                if self.outlier[k] {
                    self.feat_lm[usize::from(f)] = NO_LANDMARK;
                }
            }
            inliers
        };
        rep.matched = matched;
        rep.inliers = inliers;
        for i in 0..feats.len() {
            let id = self.feat_lm[i];
            if id != NO_LANDMARK {
                let l = self.window.lm_mut(id);
                l.found += 1;
                l.last_matched_frame = self.frame_index;
            }
        }
        inliers >= self.params.min_inliers
    }

    /// Matches window landmarks to features by projection at the current pose estimate.
    /// Writes `feat_lm`/`feat_dist`; returns the number of matched features.
    fn search(&mut self, feats: &[Feature], radius_px: f32, count_visible: bool) -> u32 {
        self.feat_lm[..feats.len()].fill(NO_LANDMARK);
        self.feat_dist[..feats.len()].fill(u32::MAX);
        self.feat_weight[..feats.len()].fill(1.0);
        // The final pass under EM also keeps every gated candidate of each feature.
        let collect = count_visible && self.params.association == Association::Em;
        if collect {
            self.cands[..feats.len()].fill(Candidates::EMPTY);
        }
        let em_gate = self.params.em.max_hamming;
        let t_cw = self.t_cw;
        let center = t_cw.inverse().trans;
        let bf = self.cam.fx_px * self.cam.baseline_m;
        let n_lm = self.window.landmarks().len();
        for id in 0..n_lm as u32 {
            let l = *self.window.lm(id);
            if !l.alive {
                continue;
            }
            let pc = t_cw.transform_point(&l.p_w);
            if pc.z < 0.1 {
                continue;
            }
            let u = (self.cam.fx_px * pc.x / pc.z + self.cam.cx_px) as f32;
            let v = (self.cam.fy_px * pc.y / pc.z + self.cam.cy_px) as f32;
            if !(u >= 0.0 && v >= 0.0 && u < self.width && v < self.height) {
                continue;
            }
            let dist = (l.p_w - center).norm();
            let pred = if l.ref_dist_m > 0.0 && dist > 1e-6 {
                let d = math::ln(f64::from(l.ref_dist_m) / dist) / LN_SCALE;
                (i32::from(l.ref_level) + math::roundf(d as f32) as i32).clamp(0, 7)
            } else {
                i32::from(l.ref_level)
            };
            if count_visible {
                self.window.lm_mut(id).visible += 1;
            }
            let r = radius_px * level_scale(pred as u8);
            let ur_pred = u - (bf / pc.z) as f32;
            let (x0, y0) = self.grid.cell_of(u - r, v - r);
            let (x1, y1) = self.grid.cell_of(u + r, v + r);
            let mut best = (u32::MAX, usize::MAX, 0u8);
            let mut second = (u32::MAX, 0u8);
            for cy in y0..=y1 {
                let row = cy * GRID_COLS;
                let s = usize::from(self.grid.start[row + x0]);
                let e = usize::from(self.grid.start[row + x1 + 1]);
                for &fi in &self.grid.items[s..e] {
                    let fi = usize::from(fi);
                    let f = &feats[fi];
                    let lvl = i32::from(f.level);
                    if lvl < pred - 1 || lvl > pred + 1 {
                        continue;
                    }
                    if (f.x - u).abs() > r || (f.y - v).abs() > r {
                        continue;
                    }
                    if f.ur >= 0.0 && (f.ur - ur_pred).abs() > r {
                        continue;
                    }
                    let d = hamming(&l.desc, &f.desc);
                    if collect && d <= em_gate {
                        self.cands[fi].insert(Candidate { lm: id, hamming: d });
                    }
                    if d < best.0 {
                        second = (best.0, best.2);
                        best = (d, fi, f.level);
                    } else if d < second.0 {
                        second = (d, f.level);
                    }
                }
            }
            if best.0 > self.params.max_hamming || best.1 == usize::MAX {
                continue;
            }
            if best.2 == second.1 && (best.0 as f32) > self.params.nn_ratio * second.0 as f32 {
                continue;
            }
            let fi = best.1;
            if best.0 < self.feat_dist[fi] {
                self.feat_dist[fi] = best.0;
                self.feat_lm[fi] = id;
            }
        }
        self.feat_lm[..feats.len()].iter().filter(|&&l| l != NO_LANDMARK).count() as u32
    }

    /// RANSAC over the wide-pass matches: the best three-point hypothesis if it explains more
    /// matches than the constant-velocity prediction. In traffic this is what keeps a vehicle
    /// driving ahead of the camera from dragging the pose along.
    fn ransac_start(&mut self, feats: &[Feature], predicted: &Se3) -> Option<Se3> {
        self.corr.clear();
        for (i, f) in feats.iter().enumerate() {
            let id = self.feat_lm[i];
            if id == NO_LANDMARK {
                continue;
            }
            let p_c = f.is_stereo().then(|| {
                self.cam.backproject(f64::from(f.x), f64::from(f.y), f64::from(f.depth_m))
            });
            let c = Correspondence { p_w: self.window.lm(id).p_w, p_c, z: measurement(f) };
            let _ = self.corr.push(c);
        }
        let seed = u64::from(self.frame_index) ^ 0x5e31_0c00_0000_0001;
        let r = ransac_pose(&self.cam, &self.corr, self.params.ransac_iterations, seed)?;
        (r.inliers > count_inliers(&self.cam, predicted, &self.corr)).then_some(r.t_cw)
    }

    /// E-step log-likelihood of candidate `c` for feature `j` at the current pose, or `None`
    /// when it fails the geometric gate (behind the camera or χ² over four times the
    /// threshold).
    fn candidate_log_likelihood(&self, frame: &Frame, j: usize, c: &Candidate) -> Option<f64> {
        let f = &frame.features[j];
        let l = self.window.lm(c.lm);
        if !l.alive {
            return None;
        }
        let z = measurement(f);
        let s = chi2(&self.cam, &self.t_cw.transform_point(&l.p_w), &z)?;
        if s > 4.0 * z.chi2_threshold() {
            return None;
        }
        let em = &self.params.em;
        let mut ll = -0.5 * s - f64::from(c.hamming) / em.tau_orb;
        if f.class != VOID {
            ll += class_log_likelihood(&l.class_hist, f.class, em.class_prior);
            ll += semantic_log_likelihood(frame.sem[j].as_ref(), l.sem.as_ref(), em.tau_sem);
        }
        Some(ll)
    }

    /// The null hypothesis of feature `j`: a candidate sitting exactly at every gate.
    fn null_log_likelihood(&self, frame: &Frame, j: usize) -> f64 {
        let f = &frame.features[j];
        let em = &self.params.em;
        let mut ll = -0.5 * measurement(f).chi2_threshold()
            - f64::from(self.params.max_hamming) / em.tau_orb;
        if f.class != VOID {
            ll += math::ln(1.0 / NUM_CLASSES as f64);
            if frame.sem[j].is_some() {
                ll -= f64::from(crate::semdesc::MATCH_THRESHOLD) / em.tau_sem;
            }
        }
        ll
    }

    /// The E-step for feature `j` at the current pose: writes the candidates that pass the
    /// gate into `ids` and their normalised weights (against the null hypothesis) into `w`;
    /// returns how many there are.
    fn e_step(
        &self,
        frame: &Frame,
        j: usize,
        ids: &mut [u32; MAX_CANDIDATES],
        w: &mut [f64; MAX_CANDIDATES],
    ) -> usize {
        let mut logl = [0.0f64; MAX_CANDIDATES];
        let mut k = 0;
        for cand in self.cands[j].iter() {
            if let Some(ll) = self.candidate_log_likelihood(frame, j, cand) {
                logl[k] = ll;
                ids[k] = cand.lm;
                k += 1;
            }
        }
        if k > 0 {
            normalise(&logl[..k], self.null_log_likelihood(frame, j), &mut w[..k]);
        }
        k
    }

    /// EM association (paper §3.3): alternate E-steps over every feature's gated candidates
    /// and weighted M-steps on the pose; then keep, per feature, the candidate with weight
    /// ≥ 0.5 (its weight goes to the keyframe for BA). Returns (inliers, features whose
    /// association differs from the nearest-neighbour candidate).
    // `j` indexes several parallel per-feature arrays (features, candidates, descriptors,
    // associations); an index loop is the clear form here.
    #[allow(clippy::needless_range_loop)]
    fn em_associate(&mut self, frame: &Frame) -> (u32, u32) {
        let feats = &frame.features[..];
        let n = feats.len();
        let mut w = [0.0f64; MAX_CANDIDATES];
        let m_step = PoseOptParams { rounds: 1, iterations: 5, robust_until_round: 1 };
        for _ in 0..self.params.em.iterations {
            self.pose_obs.clear();
            for j in 0..n {
                let mut ids = [0u32; MAX_CANDIDATES];
                let k = self.e_step(frame, j, &mut ids, &mut w);
                for (&wk, &id) in w[..k].iter().zip(&ids[..k]) {
                    if wk < self.params.em.min_weight {
                        continue;
                    }
                    let idx = self.pose_obs.len();
                    let obs = PoseObs {
                        p_w: self.window.lm(id).p_w,
                        z: measurement(&feats[j]),
                        weight: wk,
                    };
                    if self.pose_obs.push(obs).is_err() {
                        break;
                    }
                    self.pose_feat[idx] = j as u16;
                    self.pose_lm[idx] = id;
                }
            }
            let m = self.pose_obs.len();
            self.outlier[..m].fill(false);
            optimize_pose(
                &self.cam,
                &mut self.t_cw,
                &self.pose_obs,
                &mut self.outlier[..m],
                &m_step,
            );
            self.t_cw = renormalize(&self.t_cw);
        }
        // Final E-step at the converged pose: hard decisions for the map.
        let (mut inliers, mut changed) = (0u32, 0u32);
        for j in 0..n {
            self.feat_lm[j] = NO_LANDMARK;
            self.feat_weight[j] = 0.0;
            let mut ids = [0u32; MAX_CANDIDATES];
            let k = self.e_step(frame, j, &mut ids, &mut w);
            if k == 0 {
                continue;
            }
            let (best, wb) =
                w[..k]
                    .iter()
                    .enumerate()
                    .fold((0, 0.0), |acc, (i, &x)| if x > acc.1 { (i, x) } else { acc });
            if wb < 0.5 {
                continue;
            }
            let id = ids[best];
            let z = measurement(&feats[j]);
            let pc = self.t_cw.transform_point(&self.window.lm(id).p_w);
            if !chi2(&self.cam, &pc, &z).is_some_and(|s| s <= z.chi2_threshold()) {
                continue;
            }
            // One feature per landmark, as hard association guarantees by construction: the
            // feature with the higher weight keeps the landmark.
            let claim = self.lm_claim[id as usize];
            if claim != u16::MAX {
                let other = usize::from(claim);
                if self.feat_weight[other] >= wb as f32 {
                    continue;
                }
                self.feat_lm[other] = NO_LANDMARK;
                self.feat_weight[other] = 0.0;
            }
            self.lm_claim[id as usize] = j as u16;
            self.feat_lm[j] = id;
            self.feat_weight[j] = wb as f32;
        }
        // Clear the claims for the next frame (only the entries set).
        for j in 0..n {
            let id = self.feat_lm[j];
            if id != NO_LANDMARK {
                self.lm_claim[id as usize] = u16::MAX;
            }
        }
        if self.params.em.final_refine {
            self.refine_decided(feats);
        }
        for j in 0..n {
            let id = self.feat_lm[j];
            if id == NO_LANDMARK {
                continue;
            }
            inliers += 1;
            if self.cands[j].iter().next().is_some_and(|nn| nn.lm != id) {
                changed += 1;
            }
        }
        (inliers, changed)
    }

    /// The last M-step, on the associations EM decided: pose optimisation weighted by each
    /// kept pair's EM weight, with the backbone's rounds of χ² outlier classification; pairs
    /// that end as outliers are dropped. Soft M-steps never reject a pair outright, so a few
    /// confidently wrong pairs would otherwise stay in the pose and in the keyframe.
    fn refine_decided(&mut self, feats: &[Feature]) {
        let m = self.collect_matches(feats, true);
        self.outlier[..m].fill(false);
        optimize_pose(
            &self.cam,
            &mut self.t_cw,
            &self.pose_obs,
            &mut self.outlier[..m],
            &PoseOptParams::default(),
        );
        self.t_cw = renormalize(&self.t_cw);
        for k in 0..m {
            if self.outlier[k] {
                let j = usize::from(self.pose_feat[k]);
                self.feat_lm[j] = NO_LANDMARK;
                self.feat_weight[j] = 0.0;
            }
        }
    }

    /// Number of cells of a 16x8 image grid holding at least one inlier of the last
    /// [`Tracker::optimise`] call.
    fn inlier_coverage(&self, feats: &[Feature]) -> u32 {
        let mut cells = [false; 128];
        for (k, &fi) in self.pose_feat[..self.pose_obs.len()].iter().enumerate() {
            if self.outlier[k] {
                continue;
            }
            let f = &feats[usize::from(fi)];
            let cx = ((f.x / self.width) * 16.0) as usize;
            let cy = ((f.y / self.height) * 8.0) as usize;
            cells[cy.min(7) * 16 + cx.min(15)] = true;
        }
        cells.iter().filter(|&&c| c).count() as u32
    }

    /// Fills the pose problem with every feature's current match (`feat_lm`), weight 1 or,
    /// with `em_weights`, the EM weight of the kept association; returns how many.
    fn collect_matches(&mut self, feats: &[Feature], em_weights: bool) -> usize {
        self.pose_obs.clear();
        for (j, f) in feats.iter().enumerate() {
            let id = self.feat_lm[j];
            if id == NO_LANDMARK {
                continue;
            }
            let k = self.pose_obs.len();
            let weight = if em_weights { f64::from(self.feat_weight[j]) } else { 1.0 };
            let obs = PoseObs { p_w: self.window.lm(id).p_w, z: measurement(f), weight };
            if self.pose_obs.push(obs).is_err() {
                break;
            }
            self.pose_feat[k] = j as u16;
        }
        self.pose_obs.len()
    }

    /// Motion-only optimisation against the current matches; returns the inlier count. With
    /// `classify`, matches are first split into inliers and outliers at the current pose
    /// (after RANSAC) instead of all starting as inliers.
    fn optimise(&mut self, feats: &[Feature], classify: bool) -> u32 {
        let n = self.collect_matches(feats, false);
        self.outlier[..n].fill(false);
        if classify {
            let t = self.t_cw;
            for (o, out) in self.pose_obs.iter().zip(self.outlier[..n].iter_mut()) {
                let s = chi2(&self.cam, &t.transform_point(&o.p_w), &o.z);
                *out = !s.is_some_and(|s| s <= o.z.chi2_threshold());
            }
        }
        let rep = optimize_pose(
            &self.cam,
            &mut self.t_cw,
            &self.pose_obs,
            &mut self.outlier[..n],
            &PoseOptParams::default(),
        );
        self.t_cw = renormalize(&self.t_cw);
        rep.inliers
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
                if self.feat_lm[i] != NO_LANDMARK {
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

    /// Landmarks of the newest keyframe seen by at least `min_obs` window keyframes
    /// (ORB-SLAM2's `TrackedMapPoints(nMinObs)`: 3, or 2 while the map has two keyframes or
    /// fewer). A keyframe's freshly created points have one observation and do not count, or
    /// every frame would look weak against the keyframe that made them.
    fn reference_tracked(&self) -> u32 {
        let Some(kf) = self.window.newest() else { return 0 };
        let min_obs = if self.window.len() <= 2 { 2 } else { 3 };
        kf.landmark[..kf.features.len()]
            .iter()
            .filter(|&&id| {
                id != NO_LANDMARK && self.window.lm(id).alive && self.window.lm(id).n_obs >= min_obs
            })
            .count() as u32
    }

    /// Makes the current frame a keyframe: observations, new landmarks, BA, culling. Landmarks
    /// come from the close stereo points and at least `min_new_landmarks` nearest ones: far
    /// stereo depth is too noisy to anchor a map (initialising from every stereo point, as
    /// ORB-SLAM2 does, measured worse on KITTI raw 0005: ATE 0.678 m against 0.609 m).
    fn insert_keyframe(&mut self, frame: &Frame, index: u32, rep: &mut FrameReport) {
        let feats = &frame.features[..];
        let pos = self.window.push_keyframe(index, self.t_cw, feats);
        let t_wc = self.t_cw.inverse();
        let center = t_wc.trans;
        for (i, f) in feats.iter().enumerate() {
            let id = self.feat_lm[i];
            if id == NO_LANDMARK || !self.window.lm(id).alive {
                continue;
            }
            self.window.add_observation(pos, i, id);
            self.window.kf_mut(pos).weight[i] = self.feat_weight[i];
            let l = self.window.lm_mut(id);
            l.desc = f.desc;
            l.ref_level = f.level;
            l.ref_dist_m = (l.p_w - center).norm() as f32;
            note_semantics(l, f, frame.sem[i]);
        }
        // New landmarks from unmatched stereo features, nearest first.
        self.order_keys.clear();
        for (i, f) in feats.iter().enumerate() {
            if f.is_stereo() && self.feat_lm[i] == NO_LANDMARK {
                let key = (u64::from(f.depth_m.to_bits()) << 32) | i as u64;
                let _ = self.order_keys.push(key);
            }
        }
        self.order_keys.sort_unstable();
        let th_close = self.params.close_depth_baselines * self.cam.baseline_m;
        let mut created = 0u32;
        for k in 0..self.order_keys.len() {
            let i = (self.order_keys[k] & 0xffff_ffff) as usize;
            let f = &feats[i];
            let depth = f64::from(f.depth_m);
            if depth > th_close && created as usize >= self.params.min_new_landmarks {
                break;
            }
            let pc = self.cam.backproject(f64::from(f.x), f64::from(f.y), depth);
            let p_w = t_wc.transform_point(&pc);
            // The scale prediction compares camera-centre distances, so store the distance, not
            // the depth (they differ by up to 40 % at the image edges).
            let dist = pc.norm() as f32;
            let Some(id) = self.window.new_landmark(p_w, f.desc, f.level, dist) else {
                break;
            };
            self.window.add_observation(pos, i, id);
            note_semantics(self.window.lm_mut(id), f, frame.sem[i]);
            created += 1;
        }
        rep.new_landmarks = created;
        rep.keyframe = true;
        self.stats.keyframes += 1;
        self.frames_since_kf = 0;
        if self.window.len() >= 2 {
            rep.ba_iterations = self.local_ba();
            let newest = self.window.len() - 1;
            self.t_cw = self.window.kf(newest).t_cw;
            self.cull_landmarks();
        }
    }

    /// Sliding-window BA over all window keyframes (oldest fixed); removes outlier
    /// observations afterwards. Returns the iterations run.
    fn local_ba(&mut self) -> u32 {
        let nkf = self.window.len();
        // Compact point indices in landmark-id order (deterministic).
        let mut npts = 0usize;
        for (id, l) in self.window.landmarks().iter().enumerate() {
            if l.alive {
                self.lm_compact[id] = npts as u32;
                self.ba_ids[npts] = id as u32;
                self.ba_points[npts] = l.p_w;
                npts += 1;
            } else {
                self.lm_compact[id] = u32::MAX;
            }
        }
        // Observations keyed (point, keyframe position, feature) so sorting groups them.
        self.ba_keys.clear();
        for pos in 0..nkf {
            let kf = self.window.kf(pos);
            for (i, &id) in kf.landmark[..kf.features.len()].iter().enumerate() {
                if id == NO_LANDMARK {
                    continue;
                }
                let c = self.lm_compact[id as usize];
                if c == u32::MAX {
                    continue;
                }
                let key = (u64::from(c) << 32) | ((pos as u64) << 16) | i as u64;
                let _ = self.ba_keys.push(key);
            }
        }
        self.ba_keys.sort_unstable();
        self.ba_obs.clear();
        for &key in self.ba_keys.iter() {
            let point = (key >> 32) as u32;
            let pos = ((key >> 16) & 0xffff) as usize;
            let feat = (key & 0xffff) as usize;
            let f = &self.window.kf(pos).features[feat];
            let weight = f64::from(self.window.kf(pos).weight[feat]);
            let _ = self.ba_obs.push(BaObs { kf: pos as u8, point, z: measurement(f), weight });
        }
        let mut poses = [Se3::identity(); MAX_KEYFRAMES];
        for (pos, p) in poses.iter_mut().enumerate().take(nkf) {
            *p = self.window.kf(pos).t_cw;
        }
        let params = BaParams { iterations: self.params.ba_iterations, robust: true };
        let report = bundle_adjust(
            &self.cam,
            &mut poses[..nkf],
            1,
            &mut self.ba_points[..npts],
            &self.ba_obs,
            &mut self.ba_backup[..npts],
            &mut self.ba,
            &params,
        );
        let Ok(report) = report else { return 0 };
        for (pos, p) in poses.iter().enumerate().take(nkf) {
            self.window.kf_mut(pos).t_cw = renormalize(p);
        }
        for c in 0..npts {
            let id = self.ba_ids[c];
            self.window.lm_mut(id).p_w = self.ba_points[c];
        }
        // Outlier observations leave the map.
        for k in 0..self.ba_obs.len() {
            let o = self.ba_obs[k];
            let pc = poses[usize::from(o.kf)].transform_point(&self.ba_points[o.point as usize]);
            let bad = match chi2(&self.cam, &pc, &o.z) {
                Some(s) => s > o.z.chi2_threshold(),
                None => true,
            };
            if bad {
                let feat = (self.ba_keys[k] & 0xffff) as usize;
                self.window.remove_observation(usize::from(o.kf), feat);
            }
        }
        report.iterations
    }

    /// ORB-SLAM2-style landmark culling: rarely found, or weakly observed once old enough.
    fn cull_landmarks(&mut self) {
        let newest_id = self.window.newest().map(|k| k.id).unwrap_or(0);
        for id in 0..MAX_LANDMARKS as u32 {
            let l = *self.window.lm(id);
            if !l.alive {
                continue;
            }
            let ratio_bad = l.visible >= 4 && (l.found as f32) < 0.25 * l.visible as f32;
            let old_weak = newest_id >= l.created_kf + 2 && l.n_obs <= 1;
            if ratio_bad || old_weak {
                self.window.remove_landmark(id);
            }
        }
    }
}

/// `t` with its rotation block projected back onto SO(3) (unchanged if that fails, which
/// only a corrupted pose can make happen).
#[inline]
fn renormalize(t: &Se3) -> Se3 {
    t.normalized().unwrap_or(*t)
}

/// Adds a keyframe observation's class to a landmark's histogram and keeps its semantic
/// descriptor (features without labels leave both unchanged).
fn note_semantics(l: &mut crate::map::Landmark, f: &Feature, sem: Option<crate::semdesc::SemDesc>) {
    if usize::from(f.class) < NUM_CLASSES {
        let c = &mut l.class_hist[usize::from(f.class)];
        *c = c.saturating_add(1);
        if sem.is_some() {
            l.sem = sem;
        }
    }
}

/// The optimisation measurement of a feature.
#[inline]
fn measurement(f: &Feature) -> Measurement {
    Measurement {
        u: f64::from(f.x),
        v: f64::from(f.y),
        ur: if f.is_stereo() { f64::from(f.ur) } else { -1.0 },
        inv_sigma2: level_inv_sigma2(f.level),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;
    use std::boxed::Box;
    use std::vec::Vec as StdVec;

    const W: u32 = 1241;
    const H: u32 = 376;

    fn cam() -> StereoCamera {
        StereoCamera {
            fx_px: 718.856,
            fy_px: 718.856,
            cx_px: 607.19,
            cy_px: 185.22,
            baseline_m: 0.537,
        }
    }

    struct Rng(u64);
    impl Rng {
        fn next_u64(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
        fn uniform(&mut self) -> f64 {
            (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A landmark of the synthetic world: position, descriptor and the distance at which it
    /// appears on pyramid level 0 (closer, it is found on higher levels, as a real detector
    /// finds a feature on the level where it has its native size).
    type Point = (Vector3<f64>, [u8; 32], f64);

    /// A corridor of textured points along +z (building facades left/right, ground).
    fn world(rng: &mut Rng) -> StdVec<Point> {
        (0..6000)
            .map(|_| {
                let z = rng.uniform() * 120.0;
                let side = rng.next_u64() % 3;
                let p = match side {
                    0 => Vector3::new(-6.0 - rng.uniform(), -rng.uniform() * 6.0 + 1.6, z),
                    1 => Vector3::new(6.0 + rng.uniform(), -rng.uniform() * 6.0 + 1.6, z),
                    _ => Vector3::new(rng.uniform() * 12.0 - 6.0, 1.6, z),
                };
                let mut d = [0u8; 32];
                for b in d.iter_mut() {
                    *b = rng.next_u64() as u8;
                }
                (p, d, 10.0 + rng.uniform() * 50.0)
            })
            .collect()
    }

    /// Ground-truth camera-to-world pose at frame k: forward 1 m/frame with a gentle turn.
    fn truth(k: usize) -> Se3 {
        let yaw = 0.004 * k as f64;
        let xi = Vector6::new(0.0, 0.0, 0.0, 0.0, yaw, 0.0);
        let r = Se3::exp(&xi).rot;
        Se3::new(r, Vector3::new(0.05 * k as f64 * yaw, 0.0, k as f64))
    }

    fn render(pts: &[Point], t_wc: &Se3, rng: &mut Rng) -> Frame {
        let c = cam();
        let t_cw = t_wc.inverse();
        let mut f = Frame::new();
        for (p, d, native) in pts {
            let pc = t_cw.transform_point(p);
            if pc.z < 1.0 || pc.z > 80.0 {
                continue;
            }
            // Level on which a detector finds it; too far (smaller than level 0) is not found.
            let lv = libm::round(libm::log(native / pc.norm()) / LN_SCALE);
            if !(0.0..=7.0).contains(&lv) {
                continue;
            }
            let u = c.fx_px * pc.x / pc.z + c.cx_px + (rng.uniform() - 0.5) * 0.5;
            let v = c.fy_px * pc.y / pc.z + c.cy_px + (rng.uniform() - 0.5) * 0.5;
            if !(u > 0.0 && v > 0.0 && u < f64::from(W) && v < f64::from(H)) {
                continue;
            }
            let ur = u - c.fx_px * c.baseline_m / pc.z;
            let mut desc = *d;
            desc[(rng.next_u64() % 32) as usize] ^= 1 << (rng.next_u64() % 8);
            let feature = Feature {
                x: u as f32,
                y: v as f32,
                level: lv as u8,
                angle: 0.0,
                desc,
                ur: ur as f32,
                depth_m: (c.fx_px * c.baseline_m / (u - ur)) as f32,
                class: crate::seg::VOID,
            };
            if f.features.push(feature).is_err() {
                break;
            }
        }
        f
    }

    fn run_on_big_stack<F: FnOnce() + Send + 'static>(f: F) {
        std::thread::Builder::new().stack_size(64 << 20).spawn(f).unwrap().join().unwrap();
    }

    #[test]
    fn tracks_a_synthetic_drive() {
        run_on_big_stack(|| {
            let mut rng = Rng(0xdead_beef_cafe_f00d);
            let pts = world(&mut rng);
            let mut tracker =
                Box::new(Tracker::new(cam(), W, H, TrackerParams::default()).unwrap());
            let mut max_err: f64 = 0.0;
            let mut keyframes = 0;
            for k in 0..40 {
                let gt = truth(k);
                let frame = render(&pts, &gt, &mut rng);
                let rep = tracker.process(&frame);
                assert!(!rep.lost, "frame {k}: lost ({rep:?})");
                keyframes += usize::from(rep.keyframe);
                let e = (rep.t_wc.trans - gt.trans).norm();
                max_err = max_err.max(e);
            }
            assert!(max_err < 0.05, "max position error {max_err} m over 40 m");
            assert!(keyframes >= 4, "{keyframes} keyframes");
            assert_eq!(tracker.stats().lost, 0);
        });
    }

    #[test]
    fn em_association_tracks_a_synthetic_drive() {
        run_on_big_stack(|| {
            let mut rng = Rng(0xdead_beef_cafe_f00d);
            let pts = world(&mut rng);
            let params = TrackerParams { association: Association::Em, ..TrackerParams::default() };
            let mut tracker = Box::new(Tracker::new(cam(), W, H, params).unwrap());
            let (mut max_err, mut changed): (f64, u32) = (0.0, 0);
            for k in 0..40 {
                let gt = truth(k);
                let rep = tracker.process(&render(&pts, &gt, &mut rng));
                assert!(!rep.lost, "frame {k}: lost ({rep:?})");
                max_err = max_err.max((rep.t_wc.trans - gt.trans).norm());
                changed += rep.em_changed;
            }
            assert!(max_err < 0.05, "max position error {max_err} m over 40 m");
            // Unique descriptors: EM keeps the nearest neighbour almost always.
            assert!(changed < 40, "{changed} associations changed");
        });
    }

    #[test]
    fn coasting_bridges_skipped_frames() {
        run_on_big_stack(|| {
            let mut rng = Rng(0xdead_beef_cafe_f00d);
            let pts = world(&mut rng);
            let mut tracker =
                Box::new(Tracker::new(cam(), W, H, TrackerParams::default()).unwrap());
            tracker.coast();
            assert_eq!(tracker.pose_wc().trans.norm(), 0.0, "no motion model yet: no-op");
            for k in 0..24 {
                let gt = truth(k);
                if k == 10 || k == 11 {
                    // Frames the caller never saw: the prediction moves on without them.
                    tracker.coast();
                    assert!((tracker.pose_wc().trans - gt.trans).norm() < 0.05, "frame {k}");
                    continue;
                }
                if k == 18 {
                    tracker.forget_motion();
                }
                let frame = render(&pts, &gt, &mut rng);
                let rep = tracker.process(&frame);
                assert!(!rep.lost, "frame {k}: lost ({rep:?})");
                assert!((rep.t_wc.trans - gt.trans).norm() < 0.05, "frame {k}");
            }
        });
    }

    #[test]
    fn loss_is_counted_and_the_map_restarts() {
        run_on_big_stack(|| {
            let mut rng = Rng(42);
            let pts = world(&mut rng);
            let mut tracker =
                Box::new(Tracker::new(cam(), W, H, TrackerParams::default()).unwrap());
            for k in 0..5 {
                tracker.process(&render(&pts, &truth(k), &mut rng));
            }
            // A frame of unrelated features: nothing matches.
            let mut other = Rng(7);
            let unrelated = world(&mut other);
            let rep = tracker.process(&render(&unrelated, &truth(5), &mut rng));
            assert!(rep.lost && rep.initialised);
            assert_eq!(tracker.stats().lost, 1);
            assert_eq!(rep.state, TrackState::Tracking);
        });
    }

    #[test]
    fn too_few_stereo_points_waits_for_initialisation() {
        run_on_big_stack(|| {
            let mut tracker =
                Box::new(Tracker::new(cam(), W, H, TrackerParams::default()).unwrap());
            let rep = tracker.process(&Frame::new());
            assert_eq!(rep.state, TrackState::Uninitialised);
            assert!(!rep.initialised);
        });
    }

    #[test]
    fn bad_image_size_is_an_error() {
        run_on_big_stack(|| {
            assert_eq!(
                Tracker::new(cam(), 0, 10, TrackerParams::default()).err(),
                Some(TrackerError::BadImageSize { width: 0, height: 10 })
            );
        });
    }

    #[test]
    fn tracker_memory_is_reported() {
        std::println!(
            "Tracker: {} bytes ({:.2} MiB)",
            Tracker::MEMORY_BYTES,
            Tracker::MEMORY_BYTES as f64 / 1048576.0
        );
    }
}
