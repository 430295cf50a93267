//! Motion-aware semantics (beyond the paper): features on dynamic classes are removed only
//! where their object actually moves.
//!
//! Table-1 culling (§3.1) drops every feature on a car, pedestrian or bicyclist. In real
//! traffic most cars are parked: they are well-textured, static structure, and on a highway
//! on-ramp they may be most of what there is to track. With motion-aware semantics the
//! extractor keeps dynamic-class features ([`crate::seg::WeightScheme::Motion`]) and the
//! tracker decides per object whether they may be used:
//!
//! 1. **Hold.** A match whose feature is on a dynamic class is held out of the pose solve
//!    (search passes, RANSAC, the association, EM) unless its landmark is already *confirmed
//!    static*; a match to a landmark *confirmed moving* is held whatever its class.
//! 2. **Segment.** After the pose solve the frame's dynamic-class features are grouped into
//!    segments, one per object: single linkage between features of the same category (vehicle
//!    or human) closer than [`MotionParams::link_px`] in the image and, when both have stereo
//!    depth, less than [`MotionParams::link_m`] apart in 3D. Connected label regions would
//!    join a row of parked cars, and the car driving past them, into one region; a metric gap
//!    keeps them apart. A feature without depth never links two segments: chained through
//!    such features, the passing car and the parked one were one object again (on synthetic
//!    `high` a third of the wrongly removed features were parked cars joined to moving ones
//!    that way). It joins the neighbouring segment whose depth explains its motion since the
//!    previous frame (the depthless test, below), else its nearest stereo neighbour (within
//!    half the pixel distance).
//! 3. **Test against the ego-motion.** Every matched feature of a segment is a measurement of
//!    its landmark at the solved pose: χ² at most the 95 % gate (as ORB-SLAM2's) is evidence
//!    for "static", above it for "moving". Per feature the log-likelihood ratio
//!    `ln p(·|moving)/p(·|static)` is `ln(0.25/0.85)` for a consistent and `ln(0.75/0.15)` for
//!    an inconsistent measurement (a segment is called moving above ~43 % inconsistent); the
//!    segment sums them (clamped to ±[`MotionParams::max_frame_llr`]).
//!    **Frame to frame.** A moving object makes no landmarks, and an object seen for the
//!    first time has none yet, so most of their features had nothing to be measured against
//!    and stayed unproven. Each dynamic-class feature without a landmark match is therefore
//!    matched to the previous frame's dynamic-class stereo features (same category, ORB
//!    distance ≤ [`TRACK_MAX_HAMMING`] with a ratio test, within [`MotionParams::track_px`] of
//!    where the previous feature appears if its object stood still) and measured the same
//!    way against the 3D point where its chain of such matches began, with that point's
//!    stereo noise added. Measuring against the chain's start, not the last frame, lets a car
//!    creeping ahead along the line of sight add up its motion as it would against a landmark.
//!    **Depthless features** (more than half of ORB's, and without a 3D point to start a
//!    chain) are matched to the previous frame's depthless features of their category (ORB
//!    distance ≤ [`DEPTHLESS_MAX_HAMMING`], ratio test) near where they would have been if
//!    they stood still at the depth of a neighbouring segment (the nearest stereo feature of
//!    each of up to [`MAX_HYPOTHESES`] segments within [`MotionParams::link_px`]). Each
//!    depth is tested with its uncertainty along the epipolar line (the object's extent,
//!    [`MotionParams::link_m`] plus 5 %); the feature joins the segment with the smallest χ²
//!    and, if that passes the 2D gate, counts as a consistent measurement there. A failed
//!    test is no evidence of motion (the feature may lie on another object than the ones
//!    whose depths were tried), and motion along the epipolar line passes it, as it passes
//!    any one-frame test.
//!    **Epipolar test.** A feature that none of these measured (an object with no stereo
//!    feature, whose depthless features have no depth to be tested at, or a stereo feature
//!    whose previous sighting had no depth to start a chain) is matched by appearance alone
//!    to the previous frame's dynamic-class features (same category, ORB distance ≤
//!    [`TRACK_MAX_HAMMING`], ratio test) within [`MotionParams::track_px`] of where it is
//!    now. Had it stood still, it lies on the epipolar segment of the ray it was first seen
//!    on (a depthless feature matched this way, or by the depthless test, continues the
//!    chain of its match, so motion along the line of sight adds up over frames as the
//!    chain test's does): between where that ray's points from [`EPIPOLAR_NEAR_M`] and from
//!    as far as a still point of its class can be ([`static_depth`]) project now. A feature
//!    off it (beyond the 2D χ² gate) counts as an inconsistent measurement; on it, for
//!    nothing. How far a still point can be follows from the camera's height above the road
//!    ([`MotionParams::camera_height_m`]): below the horizon it is not under the road, above
//!    it not higher than the tallest of its class, with slack for pitch and grade. A cyclist
//!    riding ahead at the ego's speed, whose features do not move in the image, is then off
//!    its segment, as is a lorry's top; a car oncoming, or ahead at another speed, still
//!    moves along it until the chain's segment ends.
//!    **No evidence from a pass a mover would make too.** A pass counts as evidence of
//!    standing still only where the test could have seen motion: not where an object that
//!    kept its place relative to the camera since the reference observation (a car ahead at
//!    our speed) would have passed too, nor where one that moved
//!    [`MotionParams::slow_human_mps`] (people) or [`MotionParams::slow_vehicle_mps`]
//!    (vehicles; off by default) along the road since then would have (a pedestrian walking
//!    away along the pavement 20 m ahead). Such a pass adds nothing; by the time a slow mover
//!    would fail a chain or landmark match, a real one fails too. A depthless pass, one frame
//!    with the object's depth extent along the epipolar line, is one a walker makes too when
//!    driving forward: a person's depthless passes count for nothing.
//! 4. **A latent "moving" variable per landmark**, accumulated over frames: each matched
//!    landmark of the segment adds the segment's evidence to its log-odds (clamped to ±4). The
//!    A feature matched frame to frame carries the log-odds of the feature it matched the
//!    same way, and a landmark a keyframe creates from a feature starts with the feature's
//!    log-odds. Only measured features carry log-odds on: an unmeasured feature may belong to
//!    another object that its segment wrongly joined. The
//!    segment's posterior is the class prior ([`MotionParams::prior_vehicle`],
//!    [`MotionParams::prior_human`]: cars in a city are mostly parked) plus the mean log-odds of
//!    its landmarks after the update.
//! 5. **Decide.** A segment with at least [`MotionParams::min_evidence`] matched features and
//!    posterior `p(moving) < 0.1` is *parked*: its consistent matches rejoin the pose solve
//!    (one more solve) and the keyframe. A segment with `p(moving) > 0.5` is *moving*: its
//!    features are unlinked and create no landmarks. Anything else is *unproven*: excluded
//!    from this frame's pose, but while it is more likely parked than moving (a car untested,
//!    with its prior, not a person) its unmatched features may create landmarks so that the
//!    next frames can test it; not, though, while nothing of it has been measured and none of
//!    its features has stereo depth: such an object (a lorry too near for the stereo search,
//!    a car oncoming in the next lane) cannot start a chain, and if it moves, a landmark
//!    triangulated from its features between two keyframes is placed by its motion as much
//!    as by ours.
//!
//! The EM association sees the outcome through its candidates: held features have none.
//!
//! Memory: the tracker's `MotionScratch` is ≈ 320 KiB: per-frame arrays, and the previous
//! and current frame's dynamic-class features for the frame-to-frame and depthless tests
//! (up to [`PREV_CAPACITY`] each, stereo ones first, ≈ 104 KiB per list). The per-landmark log-odds live in
//! [`crate::map::Landmark::moving_lo`]. No allocation, deterministic.

use heapless::Vec;
use nalgebra::{Vector2, Vector3};

use crate::frame::{hamming, level_inv_sigma2, level_scale, Descriptor, Feature, FRAME_CAPACITY};
use crate::geom::{Se3, StereoCamera};
use crate::map::{measurement, NO_LANDMARK};
use crate::optim::{chi2, Measurement};
use crate::seg::{category, is_dynamic, Category};

/// Settings of the motion test.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct MotionParams {
    /// Prior probability that a vehicle (car, van, truck) is moving.
    pub prior_vehicle: f32,
    /// Prior probability that a pedestrian or bicyclist is moving.
    pub prior_human: f32,
    /// Largest image distance (px, level 0) between linked features of one segment.
    pub link_px: f32,
    /// Largest metric gap (m) between linked stereo features: the image offset at their
    /// depth, and the depth difference beyond 5 % of the depth (stereo noise).
    pub link_m: f32,
    /// Matched features a segment needs before it can be called parked.
    pub min_evidence: u32,
    /// Largest evidence (nats) one frame adds to a segment either way.
    pub max_frame_llr: f32,
    /// Search radius (px at level 0, scaled by the level) of the frame-to-frame test around
    /// where a previous-frame feature of a dynamic class would appear if its object stood
    /// still; 0 turns the frame-to-frame test off (only landmarks are tested).
    pub track_px: f32,
    /// Whether a depthless feature that no other test measured is matched by appearance to
    /// the previous frame and tested against its epipolar segment (a match off it is
    /// evidence of motion).
    pub epipolar: bool,
    /// Height (m) of the left camera above the road, the camera level with it; 0 if unknown.
    /// A dynamic-class point that stood still is neither under the road nor above the
    /// tallest of its class, so its depth in the epipolar test is bounded ([`static_depth`]):
    /// a cyclist riding ahead at the ego's speed, whose features do not move in the image, is
    /// then off its epipolar segment.
    pub camera_height_m: f32,
    /// Slowest walking speed (m/s) the test must tell from standing still: a pass of a
    /// stereo chain or landmark match that a pedestrian or cyclist moving this fast along the
    /// road (the camera's optical axis) since the reference observation would also make is no
    /// evidence of standing still; 0 turns this off. Needs the frames' times.
    pub slow_human_mps: f32,
    /// The same for vehicles (a car creeping in a queue, or pulling away slowly); 0 (off) by
    /// default: at 1.5 m/s parked cars were withheld longer and withheld precision fell on
    /// synthetic `high` and `parked` more than recall rose.
    pub slow_vehicle_mps: f32,
}

impl Default for MotionParams {
    fn default() -> Self {
        Self {
            prior_vehicle: 0.3,
            prior_human: 0.5,
            link_px: 40.0,
            link_m: 1.0,
            min_evidence: 3,
            max_frame_llr: 1.0,
            track_px: 48.0,
            epipolar: true,
            camera_height_m: 1.65,
            slow_human_mps: 1.0,
            slow_vehicle_mps: 0.0,
        }
    }
}

impl MotionParams {
    /// Prior log-odds of moving for a label id (0 for static classes: never used).
    pub fn prior_logit(&self, class: u8) -> f32 {
        let p = match category(class) {
            Category::Vehicle => self.prior_vehicle,
            Category::Human => self.prior_human,
            _ => return 0.0,
        };
        let p = p.clamp(1e-3, 1.0 - 1e-3);
        libm::logf(p / (1.0 - p))
    }

    /// Slowest speed (m/s) of a moving object of this class the test must detect.
    pub fn slow_mps(&self, class: u8) -> f32 {
        match category(class) {
            Category::Vehicle => self.slow_vehicle_mps,
            Category::Human => self.slow_human_mps,
            _ => 0.0,
        }
    }
}

/// Log-odds below which a landmark (with its class prior) is confirmed static: p < 0.1, which
/// with [`MotionParams::max_frame_llr`] = 1 takes two frames of consistent evidence for a car
/// (a pedestrian walking along the line of sight looks static for a frame).
pub const STATIC_LOGIT: f32 = -2.197_224_5;
/// Log-odds above which a landmark is confirmed moving: p > 0.5.
pub const MOVING_LOGIT: f32 = 0.0;
/// Evidence of one consistent measurement, `ln(0.25 / 0.85)`: a moving object's match still
/// passes the gate one time in four (slow, or moving along the ray).
pub const LLR_CONSISTENT: f32 = -1.223_775_4;
/// Evidence of one inconsistent measurement, `ln(0.75 / 0.15)`: a static object's match fails
/// the gate one time in seven (repeated texture on cars, mismatches at borders).
pub const LLR_INCONSISTENT: f32 = 1.609_438;
/// Bound of a landmark's accumulated log-odds (a parked car that pulls out is called moving
/// within a few frames).
pub const MAX_LANDMARK_LOGIT: f32 = 4.0;

/// What the motion test made of a feature.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FeatureMotion {
    /// Static class (or motion-aware semantics off): used as any feature.
    #[default]
    Static,
    /// Dynamic class, its object tested static: used.
    Parked,
    /// Dynamic class, its object tested moving: removed.
    Moving,
    /// Dynamic class, not enough evidence yet: not used for the pose.
    Unproven,
}

impl FeatureMotion {
    /// Whether the feature is kept out of the pose (moving or unproven).
    pub fn removed(self) -> bool {
        matches!(self, Self::Moving | Self::Unproven)
    }
}

/// Counters of one frame's motion test.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MotionReport {
    /// Segments (objects) found among the dynamic-class features.
    pub segments: u32,
    /// Segments tested moving.
    pub moving_segments: u32,
    /// Segments tested parked.
    pub parked_segments: u32,
    /// Dynamic-class features used for the pose (parked objects).
    pub parked_features: u32,
    /// Dynamic-class features removed as moving.
    pub moving_features: u32,
    /// Dynamic-class features removed for lack of evidence.
    pub unproven_features: u32,
}

/// The object (segment) a dynamic-class feature was grouped into by the last motion test
/// ([`crate::tracker::Tracker::feature_segment`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MotionSegment {
    /// The segment's id on this frame: the index of one of its features (the same for all).
    pub id: u16,
    /// The segment's features measured on this frame (against a landmark, frame to frame or
    /// by the depthless test): its evidence, consistent and inconsistent together.
    pub measured: u32,
}

/// Most dynamic-class features of the previous frame the frame-to-frame test remembers.
pub const PREV_CAPACITY: usize = 1024;

/// A dynamic-class stereo feature of the previous frame: where it was in the world if its
/// object stood still, where its chain of frame-to-frame matches started, what it looked
/// like, and its object's moving log-odds.
#[derive(Clone, Copy, Debug)]
struct PrevFeature {
    /// Its stereo point at the previous frame's pose: where the search looks.
    p_w: Vector3<f64>,
    /// The stereo point of the chain's first frame: what the test measures against, so that
    /// an object creeping along the line of sight (a car ahead in the same lane) accumulates
    /// its motion over frames, as it would against a landmark.
    anchor_w: Vector3<f64>,
    /// Depth (m) and level of the chain's first observation (its noise).
    anchor_depth: f32,
    anchor_level: u8,
    /// The chain's first observation (u, v, right-image u; level-0 px): what this frame would
    /// measure if the object had kept its place relative to the camera since then.
    anchor_obs: [f32; 3],
    /// Time (s) of the chain's first observation.
    anchor_s: f64,
    desc: Descriptor,
    level: u8,
    class: u8,
    lo: f32,
    /// Where it was seen (level-0 px). For a feature without stereo depth (after the first
    /// [`MotionScratch::prev_stereo`]) the chain's first sighting is a ray, not a point:
    /// `anchor_w` is that frame's camera centre, `p_w` the ray's step per metre of depth
    /// (world), `anchor_depth` the farthest depth on it at which a point of its class could
    /// stand still ([`static_depth`]), and `anchor_level` its level.
    uv: [f32; 2],
}

/// Most segments a feature without stereo depth is tested against (the nearest ones).
pub const MAX_HYPOTHESES: usize = 4;

/// Largest ORB distance of a frame-to-frame match (ORB-SLAM2's `TH_LOW`): without a landmark's
/// history a match rests on one descriptor, and on a car's repeated texture a loose match
/// would read as motion.
pub const TRACK_MAX_HAMMING: u32 = 50;

/// Largest ORB distance of a match between depthless features of consecutive frames: the
/// search is confined to where the neighbouring objects' depths put the feature, and at
/// [`TRACK_MAX_HAMMING`] two thirds of them found no match (on synthetic `high`, seed 1, 19 %
/// of such features were matched at 50 and 34 % at 80).
pub const DEPTHLESS_MAX_HAMMING: u32 = 80;

/// Depth (m) that stands for "infinitely far" in the epipolar test.
pub const EPIPOLAR_FAR_M: f64 = 1.0e5;
/// Nearest depth (m) a point tested by the epipolar test is taken to have.
pub const EPIPOLAR_NEAR_M: f64 = 1.0;
/// How far (m) below the camera's road plane a static point may lie: the road's camber and
/// kerbs, and the height error of the mounting.
pub const GROUND_MARGIN_M: f64 = 0.3;
/// How much steeper (rad) than the camera's road plane the road may fall away: the car's
/// pitch under braking and the road's change of grade (2°).
pub const GROUND_TOLERANCE_RAD: f64 = 0.034_906_6;
/// Tallest vehicle (m above the road) the epipolar test allows for: a bus or a lorry.
pub const VEHICLE_MAX_HEIGHT_M: f64 = 4.5;
/// Tallest pedestrian or bicyclist (m above the road) the epipolar test allows for.
pub const HUMAN_MAX_HEIGHT_M: f64 = 2.5;

/// The two smallest ORB distances offered, and where the smallest came from.
#[derive(Clone, Copy)]
struct Nearest2 {
    best: u32,
    second: u32,
    at: usize,
}

impl Nearest2 {
    const NONE: Self = Self { best: u32::MAX, second: u32::MAX, at: usize::MAX };

    fn offer(&mut self, d: u32, j: usize) {
        if d < self.best {
            (self.second, self.best, self.at) = (self.best, d, j);
        } else if d < self.second {
            self.second = d;
        }
    }

    /// Whether the best is within `max` and below `ratio` of the second best (if any).
    fn passes(&self, max: u32, ratio: f32) -> bool {
        self.best <= max
            && (self.second == u32::MAX || (self.best as f32) < ratio * self.second as f32)
    }
}

/// No current feature has claimed a previous one.
const NO_CLAIM: u16 = u16::MAX;

/// Per-frame arrays of the motion test, and the previous frame's dynamic-class features.
pub(crate) struct MotionScratch {
    /// Landmark each dynamic-class (or held) feature matched before the association
    /// ([`NO_LANDMARK`] if none).
    pub cand: [u32; FRAME_CAPACITY],
    /// χ² of that match at the solved pose (negative: none or behind the camera).
    pub chi2: [f32; FRAME_CAPACITY],
    /// χ² gate of that match.
    pub gate: [f32; FRAME_CAPACITY],
    /// Whether the feature is held out of the solve.
    pub held: [bool; FRAME_CAPACITY],
    /// The outcome per feature.
    pub state: [FeatureMotion; FRAME_CAPACITY],
    /// Whether the feature may create a landmark in a keyframe.
    pub blocked: [bool; FRAME_CAPACITY],
    parent: [u16; FRAME_CAPACITY],
    dyn_idx: Vec<u16, FRAME_CAPACITY>,
    ev: [f32; FRAME_CAPACITY],
    n_ok: [u16; FRAME_CAPACITY],
    n_bad: [u16; FRAME_CAPACITY],
    lo_sum: [f32; FRAME_CAPACITY],
    n_lm: [u16; FRAME_CAPACITY],
    /// Per segment root: whether any of its features has stereo depth.
    has_depth: [bool; FRAME_CAPACITY],
    /// Grouping: a depthless feature with no stereo neighbour.
    unattached: [bool; FRAME_CAPACITY],
    /// Grouping, per depthless group root: squared pixel distance to, and index of, the
    /// nearest attached feature.
    join_d2: [f32; FRAME_CAPACITY],
    join_to: [u16; FRAME_CAPACITY],
    /// Per feature: whether its measurement could not tell its object from one moving with
    /// the camera, so that a pass is no evidence: the depthless test's match with no image
    /// motion at all, the chain test's with the chain's first observation, or a landmark
    /// match's with the landmark's latest keyframe observation (set by the tracker) would
    /// have passed too. Set by the test that measured the feature, whatever else it was
    /// matched to (an unmeasured landmark candidate).
    pub(crate) uninformative: [bool; FRAME_CAPACITY],
    /// Frame to frame: the moving log-odds of the previous-frame feature this feature matched
    /// (NaN if none; only for features without a landmark match).
    prev_lo: [f32; FRAME_CAPACITY],
    /// The feature's moving log-odds after this frame, without the class prior: its
    /// landmark's, or its frame-to-frame chain's, updated with its segment's evidence (0 when
    /// it was not measured). Carried to the next frame and into the landmark it creates.
    pub lo_out: [f32; FRAME_CAPACITY],
    /// The previous frame's dynamic-class stereo features (world points at its pose).
    prev: Vec<PrevFeature, PREV_CAPACITY>,
    /// This frame's, built by [`Self::remember`] and then swapped with `prev`.
    next: Vec<PrevFeature, PREV_CAPACITY>,
    /// Per feature: the previous feature it matched ([`NO_CLAIM`]: none).
    prev_of: [u16; FRAME_CAPACITY],
    /// Per previous feature: the current feature that claims it, and their ORB distance.
    prev_claim: [u16; PREV_CAPACITY],
    prev_dist: [u16; PREV_CAPACITY],
    /// Per previous feature: its projection at the current pose (u, v; v < 0 off-image or
    /// behind the camera).
    prev_uv: [[f32; 2]; PREV_CAPACITY],
    /// The previous frame's final pose (camera from world), for its depthless features.
    prev_t_cw: Se3,
    /// The previous frame's time (s; NaN before the first), for the depthless test's movers.
    prev_s: f64,
    /// How many of [`Self::prev`] have stereo depth (they come first).
    prev_stereo: usize,
    /// The ratio test of this frame's matches (set by [`Self::match_previous`]).
    nn_ratio: f32,
    /// This frame's time (s), set by the tracker.
    pub(crate) now_s: f64,
}

impl MotionScratch {
    pub const fn new() -> Self {
        Self {
            cand: [NO_LANDMARK; FRAME_CAPACITY],
            chi2: [-1.0; FRAME_CAPACITY],
            gate: [0.0; FRAME_CAPACITY],
            held: [false; FRAME_CAPACITY],
            state: [FeatureMotion::Static; FRAME_CAPACITY],
            blocked: [false; FRAME_CAPACITY],
            parent: [0; FRAME_CAPACITY],
            dyn_idx: Vec::new(),
            ev: [0.0; FRAME_CAPACITY],
            n_ok: [0; FRAME_CAPACITY],
            n_bad: [0; FRAME_CAPACITY],
            lo_sum: [0.0; FRAME_CAPACITY],
            n_lm: [0; FRAME_CAPACITY],
            has_depth: [false; FRAME_CAPACITY],
            unattached: [false; FRAME_CAPACITY],
            join_d2: [f32::INFINITY; FRAME_CAPACITY],
            join_to: [0; FRAME_CAPACITY],
            uninformative: [false; FRAME_CAPACITY],
            prev_lo: [f32::NAN; FRAME_CAPACITY],
            lo_out: [0.0; FRAME_CAPACITY],
            prev: Vec::new(),
            next: Vec::new(),
            prev_of: [NO_CLAIM; FRAME_CAPACITY],
            prev_claim: [NO_CLAIM; PREV_CAPACITY],
            prev_dist: [0; PREV_CAPACITY],
            prev_uv: [[0.0; 2]; PREV_CAPACITY],
            prev_t_cw: Se3::IDENTITY,
            prev_s: f64::NAN,
            prev_stereo: 0,
            nn_ratio: 0.8,
            now_s: 0.0,
        }
    }

    /// Resets the per-frame arrays for a frame of `n` features (all static, nothing held).
    pub fn reset(&mut self, n: usize) {
        self.cand[..n].fill(NO_LANDMARK);
        self.chi2[..n].fill(-1.0);
        self.held[..n].fill(false);
        self.state[..n].fill(FeatureMotion::Static);
        self.blocked[..n].fill(false);
        self.prev_lo[..n].fill(f32::NAN);
        self.prev_of[..n].fill(NO_CLAIM);
        self.uninformative[..n].fill(false);
        self.lo_out[..n].fill(0.0);
    }

    /// Forgets the previous frame (a lost frame, a new map).
    pub fn forget_previous(&mut self) {
        self.prev.clear();
        self.prev_stereo = 0;
    }

    /// Remembers this frame's dynamic-class stereo features (nearer than `far_m`) at its
    /// final pose `t_wc`, with the log-odds [`Self::decide`] gave them, for the next frame's
    /// frame-to-frame test, then its dynamic-class features without stereo depth (image
    /// position, with the pose) for the depthless test; the first [`PREV_CAPACITY`] in all.
    pub fn remember(
        &mut self,
        feats: &[Feature],
        cam: &StereoCamera,
        t_wc: &Se3,
        far_m: f32,
        params: &MotionParams,
    ) {
        self.next.clear();
        for (i, f) in feats.iter().enumerate() {
            if !is_dynamic(f.class) || !f.is_stereo() || f.depth_m > far_m {
                continue;
            }
            let pc = cam.backproject(f64::from(f.x), f64::from(f.y), f64::from(f.depth_m));
            let p_w = t_wc.transform_point(&pc);
            // A feature matched to a stereo one continues its chain: the anchor stays where
            // the chain began.
            let link = usize::from(self.prev_of[i]);
            let (anchor_w, anchor_depth, anchor_level, anchor_obs, anchor_s) =
                match self.prev.get(link) {
                    Some(p) if link < self.prev_stereo => {
                        (p.anchor_w, p.anchor_depth, p.anchor_level, p.anchor_obs, p.anchor_s)
                    }
                    _ => (p_w, f.depth_m, f.level, [f.x, f.y, f.ur], self.now_s),
                };
            let p = PrevFeature {
                p_w,
                anchor_w,
                anchor_depth,
                anchor_level,
                anchor_obs,
                anchor_s,
                desc: f.desc,
                level: f.level,
                class: f.class,
                lo: self.lo_out[i],
                uv: [f.x, f.y],
            };
            if self.next.push(p).is_err() {
                break;
            }
        }
        let stereo = self.next.len();
        // Then the features without stereo depth: the next frame tests them against the depth
        // of the objects around them, and against the ray of their chain's first sighting (a
        // feature matched to a depthless one continues its chain).
        for (i, f) in feats.iter().enumerate() {
            if !is_dynamic(f.class) || f.is_stereo() {
                continue;
            }
            let link = usize::from(self.prev_of[i]);
            let (ray_w, anchor_w, anchor_depth, anchor_level, anchor_s) = match self.prev.get(link)
            {
                Some(p) if link >= self.prev_stereo => {
                    (p.p_w, p.anchor_w, p.anchor_depth, p.anchor_level, p.anchor_s)
                }
                _ => {
                    let (origin, step, far) =
                        sighting_ray(cam, t_wc, f.x, f.y, f.class, params.camera_height_m);
                    (step, origin, far as f32, f.level, self.now_s)
                }
            };
            let p = PrevFeature {
                p_w: ray_w,
                anchor_w,
                anchor_depth,
                anchor_level,
                anchor_obs: [f.x, f.y, -1.0],
                anchor_s,
                desc: f.desc,
                level: f.level,
                class: f.class,
                lo: self.lo_out[i],
                uv: [f.x, f.y],
            };
            if self.next.push(p).is_err() {
                break;
            }
        }
        core::mem::swap(&mut self.prev, &mut self.next);
        self.prev_stereo = stereo;
        self.prev_t_cw = t_wc.inverse();
        self.prev_s = self.now_s;
    }

    /// The frame-to-frame test: each dynamic-class feature without a landmark match is
    /// matched to the previous frame's features (same category, ORB distance at most
    /// `max_hamming` and below `nn_ratio` of the second best, within
    /// [`MotionParams::track_px`] of where the previous feature projects at `t_cw` if its
    /// object stood still, each previous feature to one feature) and measured like a landmark
    /// match: χ² at the solved pose of the 3D point where the chain of such matches began,
    /// with that observation's key-point noise (grown as the object nears) added to this
    /// one's. A moving object makes no landmarks, so without
    /// this test most of its features, and every object seen for the first time, would stay
    /// unproven. Returns how many features it measured.
    #[allow(clippy::too_many_arguments)]
    pub fn match_previous(
        &mut self,
        feats: &[Feature],
        cam: &StereoCamera,
        t_cw: &Se3,
        far_m: f32,
        params: &MotionParams,
        max_hamming: u32,
        nn_ratio: f32,
    ) -> u32 {
        self.nn_ratio = nn_ratio;
        let m = self.prev_stereo;
        if params.track_px <= 0.0 || m == 0 {
            return 0;
        }
        for j in 0..m {
            self.prev_claim[j] = NO_CLAIM;
            let pc = t_cw.transform_point(&self.prev[j].p_w);
            self.prev_uv[j] = match cam.project(&pc) {
                Some(uv) if pc.z > 0.0 => [uv.x as f32, uv.y as f32],
                _ => [0.0, -1.0],
            };
        }
        for (i, f) in feats.iter().enumerate() {
            if !is_dynamic(f.class) || self.cand[i] != NO_LANDMARK {
                continue;
            }
            let r = params.track_px * level_scale(f.level);
            let cat = category(f.class);
            let mut near = Nearest2::NONE;
            for j in 0..m {
                let [u, v] = self.prev_uv[j];
                let p = &self.prev[j];
                if v < 0.0
                    || (u - f.x).abs() > r
                    || (v - f.y).abs() > r
                    || p.level.abs_diff(f.level) > 1
                    || category(p.class) != cat
                {
                    continue;
                }
                near.offer(hamming(&p.desc, &f.desc), j);
            }
            if !near.passes(max_hamming, nn_ratio) {
                continue;
            }
            let (best, best_j) = (near.best, near.at);
            // One feature per previous feature: the nearest in ORB distance (ties: the first).
            let c = self.prev_claim[best_j];
            if c == NO_CLAIM || best < u32::from(self.prev_dist[best_j]) {
                self.prev_claim[best_j] = i as u16;
                self.prev_dist[best_j] = best as u16;
            }
        }
        let mut measured = 0;
        for j in 0..m {
            let i = self.prev_claim[j];
            if i == NO_CLAIM {
                continue;
            }
            let i = usize::from(i);
            let p = self.prev[j];
            let f = &feats[i];
            let mut z = measurement(f, far_m);
            // The anchor's key-point noise adds to this one's, grown as the object nears
            // (its disparity error scales with the squared depth ratio).
            let grow = if f.is_stereo() { (p.anchor_depth / f.depth_m).max(1.0) } else { 1.0 };
            let grow2 = f64::from(grow * grow);
            let var_anchor = grow2 * grow2 / level_inv_sigma2(p.anchor_level);
            z.inv_sigma2 = 1.0 / (1.0 / z.inv_sigma2 + var_anchor);
            self.prev_of[i] = j as u16;
            let pred = t_cw.transform_point(&p.anchor_w);
            if let Some(c) = chi2(cam, &pred, &z) {
                self.prev_lo[i] = p.lo;
                self.chi2[i] = c as f32;
                self.gate[i] = z.chi2_threshold() as f32;
                // Would an object that kept its place relative to the camera since the chain
                // began (a car ahead at our speed), or one walking slowly along the road, have
                // passed too? Then the pass is no evidence of standing still.
                self.uninformative[i] = a_mover_passes_too(
                    cam,
                    &pred,
                    &z,
                    Some(p.anchor_obs),
                    self.now_s - p.anchor_s,
                    params.slow_mps(f.class),
                );
                measured += 1;
            }
        }
        measured
    }

    fn find(&mut self, mut i: usize) -> usize {
        while usize::from(self.parent[i]) != i {
            let p = usize::from(self.parent[i]);
            self.parent[i] = self.parent[p];
            i = p;
        }
        i
    }

    /// Groups the dynamic-class features of `feats` into segments (see the module
    /// documentation); afterwards [`Self::root`] names each feature's segment.
    ///
    /// Stereo features link to each other by image and metric distance. A feature without
    /// depth joins the neighbouring segment whose depth explains its motion since the
    /// previous frame at the solved pose `t_cw` (the depthless test), else the segment of its
    /// nearest stereo neighbour (same category, within half of [`MotionParams::link_px`]),
    /// and never links two segments: in traffic a monocular feature
    /// on the border between a car driving past and the parked car behind it would otherwise
    /// chain the two into one object. Features without depth and without a stereo neighbour
    /// link among themselves.
    pub fn segment(
        &mut self,
        feats: &[Feature],
        cam: &StereoCamera,
        t_cw: &Se3,
        params: &MotionParams,
    ) -> u32 {
        let (fx, fy) = (cam.fx_px as f32, cam.fy_px as f32);
        self.dyn_idx.clear();
        for (i, f) in feats.iter().enumerate() {
            self.parent[i] = i as u16;
            if is_dynamic(f.class) {
                let _ = self.dyn_idx.push(i as u16);
            }
        }
        let n = self.dyn_idx.len();
        let near = |fa: &Feature, fb: &Feature, px: f32| {
            (fa.x - fb.x).abs() <= px
                && (fa.y - fb.y).abs() <= px
                && category(fa.class) == category(fb.class)
        };
        // Stereo with stereo.
        for a in 0..n {
            let ia = usize::from(self.dyn_idx[a]);
            let fa = feats[ia];
            if !fa.is_stereo() {
                continue;
            }
            for b in a + 1..n {
                let ib = usize::from(self.dyn_idx[b]);
                let fb = feats[ib];
                if !fb.is_stereo() || !near(&fa, &fb, params.link_px) {
                    continue;
                }
                // Metric gap at the pair's depth; the depth difference counts beyond 5 % of the
                // depth (stereo noise).
                let z = 0.5 * (fa.depth_m + fb.depth_m);
                let dx = (fa.x - fb.x) * z / fx;
                let dy = (fa.y - fb.y) * z / fy;
                let dz = ((fa.depth_m - fb.depth_m).abs() - 0.05 * z).max(0.0);
                if dx * dx + dy * dy + dz * dz <= params.link_m * params.link_m {
                    self.union(ia, ib);
                }
            }
        }
        // A monocular feature joins the neighbouring object whose depth explains its motion
        // since the previous frame, if one does; else its nearest stereo neighbour (ties: the
        // lower index). The unattached ones are marked for the last passes.
        let half = 0.5 * params.link_px;
        let t_prev_cur = self.prev_t_cw.compose(&t_cw.inverse());
        for a in 0..n {
            let ia = usize::from(self.dyn_idx[a]);
            let fa = feats[ia];
            self.unattached[ia] = false;
            if fa.is_stereo() {
                self.test_epipolar(ia, feats, cam, t_cw, params);
                continue;
            }
            if let Some(ib) = self.test_depthless(ia, feats, cam, &t_prev_cur, params) {
                self.union(ia, ib);
                continue;
            }
            self.test_epipolar(ia, feats, cam, t_cw, params);
            let mut best: Option<(f32, usize)> = None;
            for b in 0..n {
                let ib = usize::from(self.dyn_idx[b]);
                let fb = feats[ib];
                if !fb.is_stereo() || !near(&fa, &fb, half) {
                    continue;
                }
                let d = (fa.x - fb.x) * (fa.x - fb.x) + (fa.y - fb.y) * (fa.y - fb.y);
                if best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, ib));
                }
            }
            match best {
                Some((_, ib)) => self.union(ia, ib),
                None => self.unattached[ia] = true,
            }
        }
        // Unattached monocular features with each other.
        for a in 0..n {
            let ia = usize::from(self.dyn_idx[a]);
            if !self.unattached[ia] {
                continue;
            }
            for b in a + 1..n {
                let ib = usize::from(self.dyn_idx[b]);
                if self.unattached[ib] && near(&feats[ia], &feats[ib], half) {
                    self.union(ia, ib);
                }
            }
        }
        // Each such group joins the one segment nearest to any of its features (through a
        // monocular feature attached in the second pass), never two.
        for a in 0..n {
            let ia = usize::from(self.dyn_idx[a]);
            self.join_d2[ia] = f32::INFINITY;
        }
        for a in 0..n {
            let ia = usize::from(self.dyn_idx[a]);
            if !self.unattached[ia] {
                continue;
            }
            let r = self.find(ia);
            for b in 0..n {
                let ib = usize::from(self.dyn_idx[b]);
                let (fa, fb) = (feats[ia], feats[ib]);
                if self.unattached[ib] || !near(&fa, &fb, half) {
                    continue;
                }
                let d = (fa.x - fb.x) * (fa.x - fb.x) + (fa.y - fb.y) * (fa.y - fb.y);
                if d < self.join_d2[r] {
                    self.join_d2[r] = d;
                    self.join_to[r] = ib as u16;
                }
            }
        }
        for a in 0..n {
            let ia = usize::from(self.dyn_idx[a]);
            if self.unattached[ia] && self.find(ia) == ia && self.join_d2[ia].is_finite() {
                let target = usize::from(self.join_to[ia]);
                self.union(ia, target);
            }
        }
        let mut segments = 0;
        for k in 0..n {
            let i = usize::from(self.dyn_idx[k]);
            if self.find(i) == i {
                segments += 1;
            }
        }
        segments
    }

    /// The depthless test: feature `ia` (dynamic class, no stereo depth, not measured) is
    /// matched to the previous frame's depthless features of its category and tested, for
    /// each neighbouring segment (the nearest stereo feature of each, within
    /// [`MotionParams::link_px`]), against the ego-motion as if it stood still at that
    /// feature's depth, give or take the object's extent ([`MotionParams::link_m`] plus 5 %).
    /// If the best segment's test passes its χ² gate, records it as the feature's measurement
    /// ([`Self::chi2`], [`Self::gate`], and the matched feature's log-odds) and returns that
    /// segment's stereo feature; else changes nothing.
    fn test_depthless(
        &mut self,
        ia: usize,
        feats: &[Feature],
        cam: &StereoCamera,
        t_prev_cur: &Se3,
        params: &MotionParams,
    ) -> Option<usize> {
        if params.track_px <= 0.0 || self.prev.len() == self.prev_stereo || self.measured(ia) {
            return None;
        }
        let fa = feats[ia];
        let cat = category(fa.class);
        // The nearest stereo feature of each neighbouring segment.
        let mut hyp: Vec<(f32, usize, usize), MAX_HYPOTHESES> = Vec::new();
        for k in 0..self.dyn_idx.len() {
            let ib = usize::from(self.dyn_idx[k]);
            let fb = feats[ib];
            if !fb.is_stereo()
                || category(fb.class) != cat
                || (fa.x - fb.x).abs() > params.link_px
                || (fa.y - fb.y).abs() > params.link_px
            {
                continue;
            }
            let d = (fa.x - fb.x) * (fa.x - fb.x) + (fa.y - fb.y) * (fa.y - fb.y);
            let r = self.find(ib);
            if let Some(h) = hyp.iter_mut().find(|h| h.2 == r) {
                if d < h.0 {
                    *h = (d, ib, r);
                }
            } else if hyp.push((d, ib, r)).is_err() {
                // Full: replace the farthest if this one is nearer.
                let (w, _) = hyp.iter().enumerate().fold((0, f32::MIN), |acc, (k, h)| {
                    if h.0 > acc.1 {
                        (k, h.0)
                    } else {
                        acc
                    }
                });
                if d < hyp[w].0 {
                    hyp[w] = (d, ib, r);
                }
            }
        }
        if hyp.is_empty() {
            return None;
        }
        // Per hypothesis: where the feature was in the previous frame if it stood still at
        // that depth, and how that moves over the object's depth extent.
        let mut pred: [([f64; 2], [f64; 2]); MAX_HYPOTHESES] =
            [([0.0; 2], [0.0; 2]); MAX_HYPOTHESES];
        let (u, v) = (f64::from(fa.x), f64::from(fa.y));
        let mut ok = [false; MAX_HYPOTHESES];
        for (k, h) in hyp.iter().enumerate() {
            let z = f64::from(feats[h.1].depth_m);
            let dz = (f64::from(params.link_m) + 0.05 * z).min(0.5 * z);
            let at = |z: f64| cam.project(&t_prev_cur.transform_point(&cam.backproject(u, v, z)));
            if let (Some(c), Some(n), Some(f)) = (at(z), at(z - dz), at(z + dz)) {
                pred[k] = ([c.x, c.y], [0.5 * (f.x - n.x), 0.5 * (f.y - n.y)]);
                ok[k] = true;
            }
        }
        let r = params.track_px * level_scale(fa.level);
        let mut nearest = Nearest2::NONE;
        for j in self.prev_stereo..self.prev.len() {
            let p = &self.prev[j];
            if p.level.abs_diff(fa.level) > 1 || category(p.class) != cat {
                continue;
            }
            let near = (0..hyp.len()).any(|k| {
                ok[k]
                    && (f64::from(p.uv[0]) - pred[k].0[0]).abs() <= f64::from(r)
                    && (f64::from(p.uv[1]) - pred[k].0[1]).abs() <= f64::from(r)
            });
            if !near {
                continue;
            }
            nearest.offer(hamming(&p.desc, &fa.desc), j);
        }
        if !nearest.passes(DEPTHLESS_MAX_HAMMING, self.nn_ratio) {
            return None;
        }
        let p = self.prev[nearest.at];
        let s2 = 1.0 / level_inv_sigma2(fa.level) + 1.0 / level_inv_sigma2(p.level);
        let mut win: Option<(f64, usize)> = None;
        for k in 0..hyp.len() {
            if !ok[k] {
                continue;
            }
            let (c, d) = pred[k];
            let chi = mahalanobis2(s2, d, f64::from(p.uv[0]) - c[0], f64::from(p.uv[1]) - c[1]);
            if win.is_none_or(|(w, _)| chi < w) {
                win = Some((chi, k));
            }
        }
        let (chi, k) = win?;
        let gate = crate::optim::CHI2_MONO;
        let consistent = chi <= gate;
        if !consistent {
            // Not evidence of motion: the feature may lie on another object than the
            // neighbours whose depths were tried.
            return None;
        }
        // Would a match that had not moved in the image have passed too? Then so would an
        // object moving with the camera (a car ahead near the focus of expansion, anything
        // far): the pass cannot tell it from a parked one. Nor can it if a slow mover (a
        // pedestrian walking along the pavement) would have passed: the object's depth
        // extent along the epipolar line hides a step along the road.
        let (c, d) = pred[k];
        let chi_still = mahalanobis2(s2, d, f64::from(fa.x) - c[0], f64::from(fa.y) - c[1]);
        let z = f64::from(feats[hyp[k].1].depth_m);
        let step = f64::from(params.slow_mps(fa.class)) * (self.now_s - self.prev_s);
        // Where the previous camera saw a point that is now at `x` and stepped along the road.
        let x = cam.backproject(u, v, z);
        let mover = |q: Vector2<f64>| mahalanobis2(s2, d, q.x - c[0], q.y - c[1]) <= gate;
        self.uninformative[ia] = chi_still <= gate
            || road_steps(step)
                .filter_map(|s| cam.project(&t_prev_cur.transform_point(&(x - s))))
                .any(mover);
        self.prev_lo[ia] = p.lo;
        self.prev_of[ia] = nearest.at as u16;
        self.chi2[ia] = chi as f32;
        self.gate[ia] = gate as f32;
        Some(hyp[k].1)
    }

    /// The epipolar test, for a dynamic-class feature `ia` that nothing else measured (no
    /// landmark, no frame-to-frame chain, no neighbouring depth that explains it): matched by
    /// appearance alone to the previous frame's dynamic-class features of its category near
    /// where it is now (within [`MotionParams::track_px`], ORB distance at most
    /// [`TRACK_MAX_HAMMING`] with the ratio test), whatever its depth (a stereo feature's is
    /// not used: the chain test is the one that does).
    /// The match gives the ray the feature was first seen on: a depthless match's chain's
    /// first sighting (the match continues that chain), a stereo match's ray at the previous
    /// pose. A point that stood still is now on that ray's epipolar segment: where its points
    /// from [`EPIPOLAR_NEAR_M`] (and at least that far in front of this camera) to
    /// [`static_depth`] project at `t_cw`. A feature off that segment (χ² of the distance to
    /// it above the 2D gate) is recorded as an inconsistent measurement: evidence of motion
    /// with no depth to go on. On the segment it is no evidence either way: a car driving
    /// along the line of sight (ahead, oncoming) moves along it.
    fn test_epipolar(
        &mut self,
        ia: usize,
        feats: &[Feature],
        cam: &StereoCamera,
        t_cw: &Se3,
        params: &MotionParams,
    ) {
        if !params.epipolar || params.track_px <= 0.0 || self.prev.is_empty() || self.measured(ia) {
            return;
        }
        let fa = feats[ia];
        let cat = category(fa.class);
        let r = params.track_px * level_scale(fa.level);
        let mut nearest = Nearest2::NONE;
        for (j, p) in self.prev.iter().enumerate() {
            if p.level.abs_diff(fa.level) > 1
                || category(p.class) != cat
                || (p.uv[0] - fa.x).abs() > r
                || (p.uv[1] - fa.y).abs() > r
            {
                continue;
            }
            nearest.offer(hamming(&p.desc, &fa.desc), j);
        }
        if !nearest.passes(TRACK_MAX_HAMMING, self.nn_ratio) {
            return;
        }
        let j = nearest.at;
        let p = self.prev[j];
        // The ray the feature was first seen on: a depthless chain's anchor, else the
        // previous sighting's ray at the previous pose.
        let (origin, step, far, level) = if j >= self.prev_stereo {
            // A depthless match continues its chain (a stereo one's is the chain test's).
            self.prev_of[ia] = j as u16;
            (p.anchor_w, p.p_w, f64::from(p.anchor_depth), p.anchor_level)
        } else {
            let t_wp = self.prev_t_cw.inverse();
            let h = params.camera_height_m;
            let (origin, step, far) = sighting_ray(cam, &t_wp, p.uv[0], p.uv[1], p.class, h);
            (origin, step, far, p.level)
        };
        // Its stretch from EPIPOLAR_NEAR_M to `far` that is at least EPIPOLAR_NEAR_M in
        // front of this camera: depth here is z0 + s dz at depth s there.
        let o_c = t_cw.transform_point(&origin);
        let dz = t_cw.transform_point(&(origin + step)).z - o_c.z;
        let (mut s0, mut s1) = (EPIPOLAR_NEAR_M, far.max(EPIPOLAR_NEAR_M));
        if dz.abs() > 1e-12 {
            let s_min = (EPIPOLAR_NEAR_M - o_c.z) / dz;
            if dz > 0.0 {
                s0 = s0.max(s_min);
            } else {
                s1 = s1.min(s_min);
            }
        } else if o_c.z < EPIPOLAR_NEAR_M {
            return;
        }
        if s0 > s1 {
            return;
        }
        let at = |s: f64| cam.project(&t_cw.transform_point(&(origin + step * s)));
        let (Some(a), Some(b)) = (at(s0), at(s1)) else {
            return;
        };
        // Distance from the feature to that segment, in this image.
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let (px, py) = (f64::from(fa.x) - a.x, f64::from(fa.y) - a.y);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 { ((px * dx + py * dy) / len2).clamp(0.0, 1.0) } else { 0.0 };
        let (ex, ey) = (px - t * dx, py - t * dy);
        let s2 = 1.0 / level_inv_sigma2(fa.level) + 1.0 / level_inv_sigma2(level);
        let chi = (ex * ex + ey * ey) / s2;
        let gate = crate::optim::CHI2_MONO;
        if chi <= gate {
            return;
        }
        self.prev_lo[ia] = p.lo;
        self.chi2[ia] = chi as f32;
        self.gate[ia] = gate as f32;
    }

    /// Joins the segments of `a` and `b`; the smaller root index stays the root
    /// (deterministic whatever the link order).
    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
            self.parent[hi] = lo as u16;
        }
    }

    /// The segment of feature `i` after the last [`Self::decide`] (`None` for a static-class
    /// feature, or when no motion test ran on the frame). Read-only: follows the parent links
    /// without compressing them.
    pub fn segment_of(&self, i: usize) -> Option<MotionSegment> {
        if self.state.get(i).is_none_or(|&st| st == FeatureMotion::Static) {
            return None;
        }
        let mut r = i;
        while usize::from(self.parent[r]) != r {
            r = usize::from(self.parent[r]);
        }
        let measured = u32::from(self.n_ok[r]) + u32::from(self.n_bad[r]);
        Some(MotionSegment { id: r as u16, measured })
    }

    /// Whether feature `i` has a match (to a landmark, or frame to frame) measured at the
    /// solved pose.
    fn measured(&self, i: usize) -> bool {
        (self.cand[i] != NO_LANDMARK || !self.prev_lo[i].is_nan()) && self.chi2[i] >= 0.0
    }

    /// Whether feature `i`'s match was measured and passed its χ² gate.
    pub fn consistent(&self, i: usize) -> bool {
        self.measured(i) && self.chi2[i] <= self.gate[i]
    }

    /// The segment (root feature index) of dynamic feature `i` after [`Self::segment`].
    #[cfg(test)]
    pub fn root(&mut self, i: usize) -> usize {
        self.find(i)
    }

    /// Decides every segment from the measured χ² of its matches and the landmarks' log-odds
    /// (`update(id, evidence)` adds this frame's evidence to landmark `id` and returns its new
    /// log-odds): fills [`Self::state`] and [`Self::blocked`] and returns the frame's counters.
    pub fn decide(
        &mut self,
        feats: &[Feature],
        cam: &StereoCamera,
        t_cw: &Se3,
        params: &MotionParams,
        mut update: impl FnMut(u32, f32) -> f32,
    ) -> MotionReport {
        let segments = self.segment(feats, cam, t_cw, params);
        let mut rep = MotionReport { segments, ..Default::default() };
        let n = self.dyn_idx.len();
        for k in 0..n {
            let i = usize::from(self.dyn_idx[k]);
            let r = self.find(i);
            if r == i {
                self.ev[r] = 0.0;
                self.n_ok[r] = 0;
                self.n_bad[r] = 0;
                self.lo_sum[r] = 0.0;
                self.n_lm[r] = 0;
                self.has_depth[r] = false;
            }
        }
        for k in 0..n {
            let i = usize::from(self.dyn_idx[k]);
            if feats[i].is_stereo() {
                let r = self.find(i);
                self.has_depth[r] = true;
            }
        }
        // Evidence of this frame, per segment.
        for k in 0..n {
            let i = usize::from(self.dyn_idx[k]);
            if !self.measured(i) {
                continue;
            }
            let r = self.find(i);
            if self.consistent(i) {
                self.n_ok[r] = self.n_ok[r].saturating_add(1);
                // A pass is evidence only where a feature that had kept its place relative
                // to the camera would have failed.
                self.ev[r] += if self.uninformative[i] { 0.0 } else { LLR_CONSISTENT };
            } else {
                self.n_bad[r] = self.n_bad[r].saturating_add(1);
                self.ev[r] += LLR_INCONSISTENT;
            }
        }
        // Landmark update, then the posterior from the updated log-odds.
        for k in 0..n {
            let i = usize::from(self.dyn_idx[k]);
            let r = self.find(i);
            if !self.measured(i) {
                continue;
            }
            let id = self.cand[i];
            let e = self.ev[r].clamp(-params.max_frame_llr, params.max_frame_llr);
            let lo = if id != NO_LANDMARK {
                update(id, e)
            } else {
                // Frame to frame: the previous feature's log-odds carries the evidence.
                (self.prev_lo[i] + e).clamp(-MAX_LANDMARK_LOGIT, MAX_LANDMARK_LOGIT)
            };
            // Only a measured feature carries log-odds on: an unmeasured one may belong to
            // another object the segment wrongly joined (a car passing a parked one).
            self.lo_out[i] = lo;
            self.lo_sum[r] += lo;
            self.n_lm[r] = self.n_lm[r].saturating_add(1);
        }
        for k in 0..n {
            let i = usize::from(self.dyn_idx[k]);
            let r = self.find(i);
            let evidence = u32::from(self.n_ok[r]) + u32::from(self.n_bad[r]);
            let lo = if self.n_lm[r] > 0 { self.lo_sum[r] / f32::from(self.n_lm[r]) } else { 0.0 };
            let post = params.prior_logit(feats[r].class) + lo;
            let state = if evidence >= params.min_evidence && post < STATIC_LOGIT {
                FeatureMotion::Parked
            } else if evidence > 0 && post > MOVING_LOGIT {
                FeatureMotion::Moving
            } else {
                FeatureMotion::Unproven
            };
            self.state[i] = state;
            // Moving objects make no landmarks; an unproven object's matched features do not
            // duplicate the landmark they matched, and its others make landmarks only while it
            // is more likely parked than moving, and, while nothing of it is measured, only if
            // some of it has stereo depth.
            self.blocked[i] = match state {
                FeatureMotion::Moving => true,
                FeatureMotion::Unproven => {
                    self.cand[i] != NO_LANDMARK
                        || post >= MOVING_LOGIT
                        || (evidence == 0 && !self.has_depth[r])
                }
                _ => false,
            };
            if i == r {
                match state {
                    FeatureMotion::Moving => rep.moving_segments += 1,
                    FeatureMotion::Parked => rep.parked_segments += 1,
                    _ => {}
                }
            }
            match state {
                FeatureMotion::Moving => rep.moving_features += 1,
                FeatureMotion::Parked => rep.parked_features += 1,
                FeatureMotion::Unproven => rep.unproven_features += 1,
                FeatureMotion::Static => {}
            }
        }
        rep
    }
}

/// Whether measurement `z` would also pass its χ² gate against the predicted camera-frame
/// point `pred` had it been taken where the same point was seen before, `obs` (u, v and the
/// right image's u, level-0 px; a negative right u: no stereo): what an object that kept its
/// place relative to the camera since then would measure. The right u is used only when both
/// have one. A pass that such an object would also make is no evidence of standing still
/// (the chain test's first observation, a landmark's latest keyframe observation).
fn passes_where_seen_before(
    cam: &StereoCamera,
    pred: &Vector3<f64>,
    z: &Measurement,
    obs: [f32; 3],
) -> bool {
    let [u, v, ur] = obs.map(f64::from);
    let kept = Measurement { u, v, ur: if z.is_stereo() && ur >= 0.0 { ur } else { -1.0 }, ..*z };
    chi2(cam, pred, &kept).is_some_and(|c| c <= kept.chi2_threshold())
}

/// Whether a pass of measurement `z` against the predicted camera-frame point `pred` is no
/// evidence of standing still, because a mover would have passed too: an object that kept
/// its place relative to the camera since it was seen at `seen` ([`passes_where_seen_before`];
/// a car ahead at our speed), or one that moved `slow_mps` along the road in the `since_s`
/// seconds since then ([`passes_if_moved_along_road`]; a pedestrian walking on the pavement).
/// The chain test asks it of the chain's first observation, the tracker of a landmark's
/// latest keyframe observation.
pub(crate) fn a_mover_passes_too(
    cam: &StereoCamera,
    pred: &Vector3<f64>,
    z: &Measurement,
    seen: Option<[f32; 3]>,
    since_s: f64,
    slow_mps: f32,
) -> bool {
    seen.is_some_and(|obs| passes_where_seen_before(cam, pred, z, obs))
        || passes_if_moved_along_road(cam, pred, z, f64::from(slow_mps) * since_s.max(0.0))
}

/// Whether measurement `z` would also pass its χ² gate against the predicted camera-frame
/// point `pred` had the point moved `d` metres forward or back along the camera's optical
/// axis (the road) since it was first seen: what a slow mover (a pedestrian walking on the
/// pavement, a car creeping in a queue) would measure. Such a pass is no evidence of
/// standing still.
fn passes_if_moved_along_road(
    cam: &StereoCamera,
    pred: &Vector3<f64>,
    z: &Measurement,
    d: f64,
) -> bool {
    road_steps(d).any(|s| {
        let h = pred + s;
        let Some(p) = (h.z > 0.0).then(|| cam.project_stereo(&h)).flatten() else {
            return false;
        };
        let moved =
            Measurement { u: p.x, v: p.y, ur: if z.is_stereo() { p.z } else { -1.0 }, ..*z };
        chi2(cam, pred, &moved).is_some_and(|c| c <= moved.chi2_threshold())
    })
}

/// The steps a slow mover may have taken: `d` metres back or forward along the camera's
/// optical axis (the road); none when `d` is not positive (NaN: no time).
fn road_steps(d: f64) -> impl Iterator<Item = Vector3<f64>> {
    (d > 0.0).then_some([-d, d]).into_iter().flatten().map(|s| Vector3::new(0.0, 0.0, s))
}

/// Squared Mahalanobis distance of the image residual (`rx`, `ry`) under Σ = `s2` I + d dᵀ: the
/// feature's isotropic noise and its object's depth extent along the epipolar line `d`.
fn mahalanobis2(s2: f64, d: [f64; 2], rx: f64, ry: f64) -> f64 {
    let (a, b, c) = (s2 + d[0] * d[0], d[0] * d[1], s2 + d[1] * d[1]);
    let det = a * c - b * b;
    (c * rx * rx - 2.0 * b * rx * ry + a * ry * ry) / det
}

/// The ray through pixel (`u`, `v`) of a camera at `t_wc` (world from camera), for a feature
/// of label `class`: the camera centre and the step per metre of depth (world), and the
/// farthest depth at which a point of that class could stand still on it ([`static_depth`]).
fn sighting_ray(
    cam: &StereoCamera,
    t_wc: &Se3,
    u: f32,
    v: f32,
    class: u8,
    camera_height_m: f32,
) -> (Vector3<f64>, Vector3<f64>, f64) {
    let (u, v) = (f64::from(u), f64::from(v));
    let origin = t_wc.transform_point(&Vector3::zeros());
    let step = t_wc.transform_point(&cam.backproject(u, v, 1.0)) - origin;
    (origin, step, static_depth(cam, v, class, camera_height_m))
}

/// Farthest depth (m, along the optical axis) at which a point of label `class` on image row
/// `v` could stand still, for a level camera `camera_height_m` above the road: not under the
/// road ([`GROUND_MARGIN_M`] of slack) below the horizon, not above the tallest of its kind
/// ([`VEHICLE_MAX_HEIGHT_M`], [`HUMAN_MAX_HEIGHT_M`]) above it, the ray taken
/// [`GROUND_TOLERANCE_RAD`] nearer the horizon (the car's pitch, the road's change of grade).
/// [`EPIPOLAR_FAR_M`] within that tolerance of the horizon, for a static class, or when the
/// height is unknown (0).
pub fn static_depth(cam: &StereoCamera, v: f64, class: u8, camera_height_m: f32) -> f64 {
    let h = f64::from(camera_height_m);
    let top = match category(class) {
        Category::Vehicle => VEHICLE_MAX_HEIGHT_M,
        Category::Human => HUMAN_MAX_HEIGHT_M,
        _ => return EPIPOLAR_FAR_M,
    };
    if h <= 0.0 {
        return EPIPOLAR_FAR_M;
    }
    // The ray falls (v − cy) / fy per metre of depth; the road, at most tan(tolerance).
    let slope = (v - cam.cy_px) / cam.fy_px;
    let (room, steep) = if slope > 0.0 { (h + GROUND_MARGIN_M, slope) } else { (top - h, -slope) };
    let steep = steep - libm::tan(GROUND_TOLERANCE_RAD);
    if room <= 0.0 || steep <= room / EPIPOLAR_FAR_M {
        return EPIPOLAR_FAR_M;
    }
    room / steep
}

#[cfg(test)]
mod tests {
    use super::*;
    use NO_LANDMARK;

    fn feat(x: f32, y: f32, depth: f32, class: u8) -> Feature {
        Feature {
            x,
            y,
            level: 0,
            angle: 0.0,
            desc: [0; 32],
            ur: if depth > 0.0 { x - 380.0 / depth } else { -1.0 },
            depth_m: if depth > 0.0 { depth } else { -1.0 },
            class,
        }
    }

    #[test]
    fn segments_split_by_category_image_distance_and_depth() {
        let mut s = std::boxed::Box::new(MotionScratch::new());
        let p = MotionParams::default();
        let feats = [
            feat(100.0, 100.0, 10.0, 8), // car A
            feat(130.0, 110.0, 10.5, 8), // car A (linked)
            feat(160.0, 100.0, 10.2, 8), // car A (chained through the second)
            feat(140.0, 100.0, 16.0, 8), // car B: same pixels, 6 m behind
            feat(400.0, 100.0, 10.0, 8), // car C: far in the image
            feat(120.0, 100.0, 10.0, 9), // pedestrian next to car A
            feat(110.0, 100.0, 10.0, 1), // building: not dynamic
        ];
        s.reset(feats.len());
        assert_eq!(s.segment(&feats, &crate::testing::kitti_cam(), &Se3::IDENTITY, &p), 4);
        assert_eq!(s.root(1), 0);
        assert_eq!(s.root(2), 0);
        assert_eq!(s.root(3), 3);
        assert_eq!(s.root(4), 4);
        assert_eq!(s.root(5), 5);
    }

    /// A feature without depth between a passing car and a parked one joins the nearer and
    /// does not chain the two; depthless groups join one segment through their nearest
    /// attached feature.
    #[test]
    fn depthless_features_do_not_bridge_objects() {
        let mut s = std::boxed::Box::new(MotionScratch::new());
        let p = MotionParams::default();
        let feats = [
            feat(100.0, 100.0, 8.0, 8),  // passing car
            feat(120.0, 100.0, 8.1, 8),  // passing car
            feat(150.0, 100.0, 12.0, 8), // parked car, 4 m behind
            feat(170.0, 100.0, 12.1, 8), // parked car
            feat(136.0, 100.0, 0.0, 8),  // no depth: 16 px from the first, 14 px from the second
            feat(185.0, 100.0, 0.0, 8),  // no depth, next to the parked car
            feat(200.0, 100.0, 0.0, 8),  // no depth, 30 px from any stereo feature
            feat(215.0, 100.0, 0.0, 8),  // no depth, chained to the one before
            feat(400.0, 100.0, 0.0, 8),  // no depth, alone
        ];
        s.reset(feats.len());
        assert_eq!(s.segment(&feats, &crate::testing::kitti_cam(), &Se3::IDENTITY, &p), 3);
        assert_eq!(s.root(1), 0);
        assert_eq!(s.root(3), 2);
        assert_eq!(s.root(4), 2, "joins the nearer (parked) car only");
        assert_eq!(s.root(5), 2);
        assert_eq!(s.root(6), 2, "a depthless group joins through its nearest attached feature");
        assert_eq!(s.root(7), 2);
        assert_eq!(s.root(8), 8);
    }

    /// A parked car (consistent matches) is used, a moving one (inconsistent) removed, and a
    /// pedestrian and a car without matches stay unproven: the car (more likely parked than
    /// moving) may make landmarks, the pedestrian (as likely moving) may not, nor a car none of
    /// whose features has stereo depth. The landmarks accumulate the evidence.
    #[test]
    fn decisions_follow_the_evidence() {
        let mut s = std::boxed::Box::new(MotionScratch::new());
        let p = MotionParams::default();
        let mut feats = std::vec::Vec::new();
        for k in 0..5 {
            feats.push(feat(100.0 + 10.0 * k as f32, 100.0, 10.0, 8)); // parked
        }
        for k in 0..5 {
            feats.push(feat(600.0 + 10.0 * k as f32, 100.0, 12.0, 8)); // moving
        }
        for k in 0..3 {
            feats.push(feat(1000.0 + 10.0 * k as f32, 100.0, 12.0, 9)); // unmatched pedestrian
        }
        for k in 0..3 {
            feats.push(feat(1400.0 + 10.0 * k as f32, 100.0, 12.0, 8)); // unmatched car
        }
        feats.push(feat(1435.0, 100.0, 0.0, 8)); // its depthless feature
        for k in 0..3 {
            feats.push(feat(200.0 + 10.0 * k as f32, 300.0, 0.0, 8)); // car without depth
        }
        let mut lo = [0.0f32; 16];
        let frame = |s: &mut MotionScratch, lo: &mut [f32; 16]| {
            s.reset(feats.len());
            for i in 0..10 {
                s.cand[i] = i as u32;
                s.gate[i] = 7.8;
                s.chi2[i] = if i < 5 { 1.0 } else { 60.0 };
            }
            s.decide(&feats, &crate::testing::kitti_cam(), &Se3::IDENTITY, &p, |id, e| {
                let l = &mut lo[id as usize];
                *l = (*l + e).clamp(-MAX_LANDMARK_LOGIT, MAX_LANDMARK_LOGIT);
                *l
            })
        };
        // One frame of consistent matches is not yet enough to call a car parked; one frame
        // of inconsistent ones calls the other moving.
        let rep = frame(&mut s, &mut lo);
        assert_eq!((rep.parked_features, rep.moving_features, rep.unproven_features), (0, 5, 15));
        assert!(lo[..5].iter().all(|&l| (l + p.max_frame_llr).abs() < 1e-6));
        let rep = frame(&mut s, &mut lo);
        assert_eq!(rep.segments, 5);
        assert_eq!(rep.parked_segments, 1);
        assert_eq!(rep.moving_segments, 1);
        assert_eq!((rep.parked_features, rep.moving_features, rep.unproven_features), (5, 5, 10));
        assert!(s.state[..5].iter().all(|&m| m == FeatureMotion::Parked));
        assert!(s.state[5..10].iter().all(|&m| m == FeatureMotion::Moving));
        assert!(s.state[10..20].iter().all(|&m| m == FeatureMotion::Unproven));
        assert!(s.blocked[5..13].iter().all(|&b| b) && s.blocked[17..20].iter().all(|&b| b));
        assert!(!s.blocked[..5].iter().any(|&b| b) && !s.blocked[13..17].iter().any(|&b| b));
        // Clamped frame evidence went to each landmark, twice.
        assert!(lo[..5].iter().all(|&l| (l + 2.0 * p.max_frame_llr).abs() < 1e-6));
        assert!(lo[5..10].iter().all(|&l| (l - 2.0 * p.max_frame_llr).abs() < 1e-6));
        assert_eq!(s.cand[12], NO_LANDMARK);
        // The objects as `segment_of` reports them: one id per object, its measured features.
        let seg: std::vec::Vec<MotionSegment> =
            (0..16).map(|i| s.segment_of(i).expect("dynamic class")).collect();
        for (range, measured) in [(0..5, 5), (5..10, 5), (10..13, 0)] {
            let id = seg[range.start].id;
            assert!(seg[range].iter().all(|g| g.id == id && g.measured == measured));
        }
        assert!(seg[0].id != seg[5].id && seg[5].id != seg[10].id && seg[0].id != seg[10].id);
        assert_eq!(s.segment_of(16).map(|g| g.id), Some(seg[13].id), "joined its car");
        assert_eq!(s.segment_of(20), None, "beyond the frame's features");
        s.reset(feats.len());
        assert_eq!(s.segment_of(0), None, "no motion test on this frame yet");
    }

    /// Two matched features are not enough to call a car parked; one inconsistent match in a
    /// big parked segment does not make it moving.
    #[test]
    fn thin_evidence_and_single_outliers() {
        let mut s = std::boxed::Box::new(MotionScratch::new());
        let p = MotionParams::default();
        let feats: std::vec::Vec<Feature> =
            (0..8).map(|k| feat(100.0 + 10.0 * k as f32, 100.0, 10.0, 8)).collect();
        s.reset(feats.len());
        for i in 0..2 {
            s.cand[i] = i as u32;
            s.gate[i] = 7.8;
            s.chi2[i] = 1.0;
        }
        let rep = s.decide(&feats, &crate::testing::kitti_cam(), &Se3::IDENTITY, &p, |_, _| -2.67);
        assert_eq!(rep.parked_segments, 0);
        assert_eq!(rep.unproven_features, 8);
        s.reset(feats.len());
        for i in 0..8 {
            s.cand[i] = i as u32;
            s.gate[i] = 7.8;
            s.chi2[i] = if i == 3 { 50.0 } else { 1.0 };
        }
        let rep = s.decide(&feats, &crate::testing::kitti_cam(), &Se3::IDENTITY, &p, |_, _| -6.0);
        assert_eq!(rep.parked_segments, 1);
        assert_eq!(rep.parked_features, 8);
    }

    /// A pass of the depthless test is evidence of standing still only where a feature that
    /// had not moved in the image would have failed: one inconsistent stereo match outweighs
    /// two passes that could not tell, but not two that could.
    #[test]
    fn a_depthless_pass_counts_only_where_it_could_have_seen_motion() {
        let p = MotionParams::default();
        let cam = crate::testing::kitti_cam();
        // One car: a stereo feature that failed its frame-to-frame test and two depthless
        // features that passed the depthless test.
        let frame_evidence = |informative: bool| {
            let mut s = std::boxed::Box::new(MotionScratch::new());
            let feats = [
                feat(100.0, 100.0, 10.0, 8),
                feat(110.0, 100.0, 10.0, 8),
                feat(105.0, 108.0, 0.0, 8),
                feat(115.0, 108.0, 0.0, 8),
            ];
            s.reset(feats.len());
            for i in 1..4 {
                s.prev_lo[i] = 0.0;
                s.gate[i] = 5.99;
                s.chi2[i] = if i == 1 { 60.0 } else { 1.0 };
            }
            s.uninformative[2..4].fill(!informative);
            let rep = s.decide(&feats, &cam, &Se3::IDENTITY, &p, |_, e| e);
            assert_eq!(rep.segments, 1);
            assert!((1..4).all(|i| s.measured(i)));
            s.lo_out[1]
        };
        let could = frame_evidence(true);
        let could_not = frame_evidence(false);
        assert!((could - (LLR_INCONSISTENT + 2.0 * LLR_CONSISTENT)).abs() < 1e-5, "{could}");
        assert!((could_not - p.max_frame_llr).abs() < 1e-6, "{could_not}");
    }

    /// A depthless feature that had a landmark candidate but no measurement of it is measured by
    /// the depthless test; a pass that could not tell still adds nothing to its landmark.
    #[test]
    fn an_uninformative_depthless_pass_adds_nothing_to_a_landmark_either() {
        let p = MotionParams::default();
        let cam = crate::testing::kitti_cam();
        let evidence_to_landmark = |uninformative: bool| {
            let mut s = std::boxed::Box::new(MotionScratch::new());
            let feats = [feat(100.0, 100.0, 10.0, 8), feat(105.0, 108.0, 0.0, 8)];
            s.reset(feats.len());
            (s.cand[1], s.prev_lo[1], s.gate[1], s.chi2[1]) = (7, 0.0, 5.99, 1.0);
            s.uninformative[1] = uninformative;
            let mut sent = std::vec::Vec::new();
            s.decide(&feats, &cam, &Se3::IDENTITY, &p, |id, e| {
                sent.push((id, e));
                e
            });
            sent
        };
        assert_eq!(evidence_to_landmark(true), [(7, 0.0)]);
        // (The frame's evidence is clamped to ±max_frame_llr.)
        assert_eq!(evidence_to_landmark(false), [(7, LLR_CONSISTENT.max(-p.max_frame_llr))]);
    }

    /// The depthless test on a car ahead near the focus of expansion, driving at the camera's
    /// speed: its depthless feature does not move in the image and passes at the car's depth,
    /// but a parked car there would barely have moved either, so the pass is no evidence.
    #[test]
    fn a_car_ahead_at_our_speed_passes_the_depthless_test_uninformatively() {
        let cam = crate::testing::kitti_cam();
        let mut s = std::boxed::Box::new(MotionScratch::new());
        let car: std::vec::Vec<Vector3<f64>> =
            (0..3).map(|k| Vector3::new(-0.3 + 0.3 * f64::from(k), 0.2, 20.0)).collect();
        let lone = Vector3::new(0.1, 0.3, 20.0);
        let mut passes = std::vec::Vec::new();
        for t in 0..3 {
            let with_us = Vector3::new(0.0, 0.0, t as f64);
            let mut feats: std::vec::Vec<Feature> = car
                .iter()
                .enumerate()
                .map(|(k, &q)| seen(&cam, &driving(t), q + with_us, 8, k as u8))
                .collect();
            let mut d = seen(&cam, &driving(t), lone + with_us, 8, 50);
            (d.ur, d.depth_m) = (-1.0, -1.0);
            feats.push(d);
            landmarkless_frame(&mut s, &feats, t);
            passes.push((s.consistent(3), !s.uninformative[3]));
        }
        assert_eq!(passes[1..], [(true, false), (true, false)], "{passes:?}");
    }

    /// A stereo feature of `class` seeing world point `p_w` from pose `t_cw`, with a
    /// descriptor made from `seed`.
    fn seen(cam: &StereoCamera, t_cw: &Se3, p_w: Vector3<f64>, class: u8, seed: u8) -> Feature {
        let z = cam.project_stereo(&t_cw.transform_point(&p_w)).unwrap();
        let pc = t_cw.transform_point(&p_w);
        let mut desc = [0u8; 32];
        for (k, d) in desc.iter_mut().enumerate() {
            *d = seed.wrapping_mul(37).wrapping_add((k as u8).wrapping_mul(101)) ^ seed;
        }
        Feature {
            x: z.x as f32,
            y: z.y as f32,
            level: 0,
            angle: 0.0,
            desc,
            ur: z.z as f32,
            depth_m: pc.z as f32,
            class,
        }
    }

    /// Pose of frame `t` of a camera driving 1 m forward per frame.
    fn driving(t: usize) -> Se3 {
        Se3::new(nalgebra::Matrix3::identity(), Vector3::new(0.0, 0.0, -(t as f64)))
    }

    /// One frame of the motion test on objects without landmarks (KITTI camera, default
    /// settings): match to the previous frame, decide, remember; returns how many features
    /// were measured frame to frame.
    fn landmarkless_frame(s: &mut MotionScratch, feats: &[Feature], t: usize) -> u32 {
        landmarkless_frame_with(s, feats, t, &MotionParams::default())
    }

    /// [`landmarkless_frame`] with settings `p`; frames are 0.1 s apart (10 Hz, as KITTI).
    fn landmarkless_frame_with(
        s: &mut MotionScratch,
        feats: &[Feature],
        t: usize,
        p: &MotionParams,
    ) -> u32 {
        let cam = crate::testing::kitti_cam();
        let p = *p;
        let far = 40.0 * cam.baseline_m as f32;
        s.reset(feats.len());
        s.now_s = 0.1 * t as f64;
        let measured = s.match_previous(feats, &cam, &driving(t), far, &p, TRACK_MAX_HAMMING, 0.8);
        s.decide(feats, &cam, &driving(t), &p, |_, _| unreachable!("no landmarks"));
        s.remember(feats, &cam, &driving(t).inverse(), far, &p);
        measured
    }

    /// Objects without landmarks are tested frame to frame: a parked car (its points where the
    /// ego-motion puts them) becomes parked in its third frame, a car that moved 0.6 m is
    /// called moving in its second, and the log-odds carry over from frame to frame.
    #[test]
    fn objects_without_landmarks_are_tested_frame_to_frame() {
        let cam = crate::testing::kitti_cam();
        let p = MotionParams::default();
        let mut s = std::boxed::Box::new(MotionScratch::new());
        // Parked car 12 m ahead on the right, moving car 15 m ahead on the left (it drives
        // 0.6 m to the left per frame); the camera drives 1 m forward per frame.
        let parked: std::vec::Vec<Vector3<f64>> = (0..6)
            .map(|k| Vector3::new(3.0 + 0.3 * f64::from(k), 0.5 + 0.1 * f64::from(k % 2), 12.0))
            .collect();
        let moving: std::vec::Vec<Vector3<f64>> = (0..6)
            .map(|k| Vector3::new(-3.0 - 0.3 * f64::from(k), 0.4 + 0.1 * f64::from(k % 2), 15.0))
            .collect();
        let pose = driving;
        let frame = |t: usize| -> std::vec::Vec<Feature> {
            let shift = Vector3::new(-0.6 * t as f64, 0.0, 0.0);
            let mut f: std::vec::Vec<Feature> = parked
                .iter()
                .enumerate()
                .map(|(k, &q)| seen(&cam, &pose(t), q, 8, k as u8))
                .collect();
            f.extend(
                moving
                    .iter()
                    .enumerate()
                    .map(|(k, &q)| seen(&cam, &pose(t), q + shift, 8, 100 + k as u8)),
            );
            f
        };
        let far = 40.0 * cam.baseline_m as f32;
        let mut states = std::vec::Vec::new();
        for t in 0..3 {
            let measured = landmarkless_frame(&mut s, &frame(t), t);
            assert_eq!(measured, if t == 0 { 0 } else { 12 }, "frame {t}");
            states.push((s.state[0], s.state[6], s.lo_out[0], s.lo_out[6]));
        }
        use FeatureMotion::*;
        assert_eq!((states[0].0, states[0].1), (Unproven, Unproven), "first sight: no evidence");
        assert_eq!((states[1].0, states[1].1), (Unproven, Moving));
        assert_eq!((states[2].0, states[2].1), (Parked, Moving));
        assert!((states[2].2 + 2.0 * p.max_frame_llr).abs() < 1e-5, "{states:?}");
        assert!((states[2].3 - 2.0 * p.max_frame_llr).abs() < 1e-5, "{states:?}");
        // A feature matched to a landmark is measured against it, not frame to frame; a
        // feature whose descriptor differs is not matched; off, nothing is measured.
        let mut feats = frame(3);
        feats[1].desc = [0xff; 32];
        s.reset(feats.len());
        s.cand[2] = 7;
        assert_eq!(s.match_previous(&feats, &cam, &pose(3), far, &p, TRACK_MAX_HAMMING, 0.8), 10);
        assert!(s.prev_lo[1].is_nan() && s.prev_lo[2].is_nan() && !s.prev_lo[0].is_nan());
        let off = MotionParams { track_px: 0.0, ..p };
        s.reset(feats.len());
        assert_eq!(s.match_previous(&feats, &cam, &pose(3), far, &off, TRACK_MAX_HAMMING, 0.8), 0);
        s.forget_previous();
        assert_eq!(s.match_previous(&feats, &cam, &pose(3), far, &p, TRACK_MAX_HAMMING, 0.8), 0);
    }

    /// A car ahead creeping away along the line of sight (0.3 m per frame while the camera
    /// drives 1 m) looks static from one frame to the next; measured against where its
    /// chain of matches began, its motion adds up and it is called moving.
    #[test]
    fn a_car_creeping_along_the_line_of_sight_is_caught_by_the_chain_anchor() {
        let cam = crate::testing::kitti_cam();
        let mut s = std::boxed::Box::new(MotionScratch::new());
        let car: std::vec::Vec<Vector3<f64>> = (0..6)
            .map(|k| Vector3::new(-0.2 + 0.08 * f64::from(k), 0.3 + 0.1 * f64::from(k % 3), 12.0))
            .collect();
        let mut states = std::vec::Vec::new();
        for t in 0..6 {
            let ahead = Vector3::new(0.0, 0.0, 0.3 * t as f64);
            let feats: std::vec::Vec<Feature> = car
                .iter()
                .enumerate()
                .map(|(k, &q)| seen(&cam, &driving(t), q + ahead, 8, k as u8))
                .collect();
            let measured = landmarkless_frame(&mut s, &feats, t);
            assert_eq!(measured as usize, if t == 0 { 0 } else { feats.len() }, "frame {t}");
            states.push((s.state[0], s.chi2[0]));
        }
        // One frame's step is within the gate; against the anchor the residual grows every
        // frame, and a parked call made on the first two frames is taken back.
        assert!(states[1].1 < 7.8 && states[2].1 < 7.8, "{states:?}");
        assert!(states.windows(2).skip(1).all(|w| w[1].1 > w[0].1), "{states:?}");
        assert!(states[3..].iter().all(|&(m, c)| m != FeatureMotion::Parked && c > 7.8));
        assert_eq!(states[5].0, FeatureMotion::Moving, "{states:?}");
    }

    /// A car 20 m ahead driving at our speed, seen in stereo: its chain test's first step
    /// passes (1 m along the line of sight is about a disparity pixel there), but a car that
    /// kept its place relative to the camera would pass too, so the pass is no evidence and
    /// the chain's failure on the next frame calls it moving at once (counted as evidence of
    /// standing still, the pass had cancelled that failure). A parked car 3.5 m to the side at
    /// the same depth moves in the image as the camera drives; its passes park it.
    #[test]
    fn a_car_ahead_at_our_speed_passes_the_chain_test_uninformatively() {
        let cam = crate::testing::kitti_cam();
        let mut s = std::boxed::Box::new(MotionScratch::new());
        let ahead: std::vec::Vec<Vector3<f64>> = (0..6)
            .map(|k| Vector3::new(-0.5 + 0.2 * f64::from(k), 0.3 + 0.1 * f64::from(k % 3), 20.0))
            .collect();
        let side: std::vec::Vec<Vector3<f64>> = (0..6)
            .map(|k| Vector3::new(3.5 + 0.3 * f64::from(k), 0.5 + 0.1 * f64::from(k % 2), 20.0))
            .collect();
        let mut got = std::vec::Vec::new();
        for t in 0..4 {
            let with_us = Vector3::new(0.0, 0.0, t as f64);
            let mut feats: std::vec::Vec<Feature> = ahead
                .iter()
                .enumerate()
                .map(|(k, &q)| seen(&cam, &driving(t), q + with_us, 8, k as u8))
                .collect();
            feats.extend(
                side.iter().enumerate().map(|(k, &q)| seen(&cam, &driving(t), q, 8, 100 + k as u8)),
            );
            landmarkless_frame(&mut s, &feats, t);
            got.push((
                s.consistent(0),
                s.uninformative[0],
                s.state[0],
                s.uninformative[6],
                s.state[6],
            ));
        }
        use FeatureMotion::*;
        assert_eq!((got[1].0, got[1].1, got[1].2), (true, true, Unproven), "{got:?}");
        assert_eq!((got[2].2, got[3].2), (Moving, Moving), "{got:?}");
        assert!(got[1..].iter().all(|g| !g.3), "the parked car's passes are evidence: {got:?}");
        assert_eq!((got[2].4, got[3].4), (Parked, Parked), "{got:?}");
    }

    /// Two people on the pavements while the camera drives at 10 m/s: one 18 m ahead on the
    /// right walks away along the pavement at 1 m/s, the other, 13 m ahead on the left,
    /// stands. Over a few frames the walker's steps are inside the stereo noise, and under
    /// the old rule its first three passes parked it (frame 3, taken back only on frame 7).
    /// A pass that a walker at [`MotionParams::slow_human_mps`] would also make is no
    /// evidence, and by the time a walker would fail, this one fails too. The standing one
    /// is parked once its passes could have told (frame 4; frame 3 under the old rule).
    #[test]
    fn a_pedestrian_walking_along_the_pavement_is_not_parked_by_its_first_passes() {
        let cam = crate::testing::kitti_cam();
        let person = |x: f64, z: f64| -> std::vec::Vec<Vector3<f64>> {
            (0..6)
                .map(|k| Vector3::new(x + 0.1 * f64::from(k % 3), 1.3 - 0.25 * f64::from(k), z))
                .collect()
        };
        let (walker, stander) = (person(3.5, 18.0), person(-4.0, 13.0));
        let run = |p: &MotionParams| {
            let mut s = std::boxed::Box::new(MotionScratch::new());
            let mut got = std::vec::Vec::new();
            for t in 0..8 {
                let step = Vector3::new(0.0, 0.0, 0.1 * t as f64);
                let mut feats: std::vec::Vec<Feature> = walker
                    .iter()
                    .enumerate()
                    .map(|(k, &q)| seen(&cam, &driving(t), q + step, 9, k as u8))
                    .collect();
                feats.extend(
                    stander
                        .iter()
                        .enumerate()
                        .map(|(k, &q)| seen(&cam, &driving(t), q, 9, 100 + k as u8)),
                );
                landmarkless_frame_with(&mut s, &feats, t, p);
                got.push((s.state[0], s.state[6]));
            }
            got
        };
        use FeatureMotion::*;
        let p = MotionParams::default();
        let got = run(&p);
        assert!(got.iter().all(|g| g.0 != Parked), "walker parked: {got:?}");
        assert_eq!(got[7].0, Moving, "{got:?}");
        assert!(got[4..].iter().all(|g| g.1 == Parked), "stander: {got:?}");
        // Without the rule the walker's first passes park it.
        let old = run(&MotionParams { slow_human_mps: 0.0, ..p });
        assert!(old.iter().any(|g| g.0 == Parked), "{old:?}");
    }

    /// A parked car's feature without stereo depth, closer in the image to a car driving
    /// alongside than to the parked car's own stereo features, joins the parked car: its
    /// motion since the previous frame is what the ego-motion gives at the parked car's
    /// depth, not at the other car's. Without the previous frame it joins its nearest stereo
    /// neighbour, the wrong car.
    #[test]
    fn a_depthless_feature_joins_the_object_whose_depth_explains_its_motion() {
        let cam = crate::testing::kitti_cam();
        let mut s = std::boxed::Box::new(MotionScratch::new());
        // Parked car 12 m ahead on the right (stereo features), one of its points without
        // stereo depth 0.45 m further out.
        let parked: std::vec::Vec<Vector3<f64>> = (0..4)
            .map(|k| Vector3::new(3.0 + 0.15 * f64::from(k), 0.8 + 0.05 * f64::from(k % 2), 12.0))
            .collect();
        let lone = Vector3::new(3.9, 0.8, 12.0);
        let frame = |t: usize| -> std::vec::Vec<Feature> {
            let mut f: std::vec::Vec<Feature> = parked
                .iter()
                .enumerate()
                .map(|(k, &q)| seen(&cam, &driving(t), q, 8, k as u8))
                .collect();
            let mut d = seen(&cam, &driving(t), lone, 8, 50);
            (d.ur, d.depth_m) = (-1.0, -1.0);
            // A car driving alongside at 8 m, always 8-14 px to the right of that point in
            // the image (stereo features).
            for k in 0..3 {
                let pc =
                    cam.backproject(f64::from(d.x) + 8.0 + 3.0 * k as f64, f64::from(d.y), 8.0);
                f.push(seen(
                    &cam,
                    &driving(t),
                    driving(t).inverse().transform_point(&pc),
                    8,
                    200 + k,
                ));
            }
            f.push(d);
            f
        };
        let lone_idx = parked.len() + 3;
        let mut roots = std::vec::Vec::new();
        for t in 0..3 {
            let feats = frame(t);
            landmarkless_frame(&mut s, &feats, t);
            roots.push((s.root(lone_idx), s.state[lone_idx], s.state[0]));
        }
        use FeatureMotion::*;
        assert_eq!(roots[0].0, parked.len(), "first frame: the nearest stereo neighbour");
        assert_eq!(roots[1].0, 0, "{roots:?}");
        assert_eq!(roots[2], (0, Parked, Parked), "{roots:?}");
        assert!(s.consistent(lone_idx), "measured, and consistent, at the parked car's depth");
        // 3.9 m to the side at 12 m, the parked car's point moves 21 px per frame: a pass there
        // could have seen motion, and is evidence.
        assert!(!s.uninformative[lone_idx]);
    }

    /// Driving forward, a step along the road moves a point's image along its epipolar line,
    /// where the depthless test allows for the object's depth extent: its pass cannot tell a
    /// person walking along the pavement from one standing, so it is no evidence for either.
    /// A car's pass (no slow speed for vehicles by default) still is.
    #[test]
    fn a_depthless_pass_cannot_tell_a_walker_from_a_person_standing() {
        let cam = crate::testing::kitti_cam();
        let lone_pass = |class: u8, p: &MotionParams| {
            let mut s = std::boxed::Box::new(MotionScratch::new());
            // An object 12 m ahead on the right (stereo features), one of its points without
            // stereo depth.
            let object: std::vec::Vec<Vector3<f64>> = (0..4)
                .map(|k| {
                    Vector3::new(3.0 + 0.15 * f64::from(k), 0.8 + 0.05 * f64::from(k % 2), 12.0)
                })
                .collect();
            let lone = Vector3::new(3.5, 0.6, 12.2);
            let mut got = std::vec::Vec::new();
            for t in 0..3 {
                let mut feats: std::vec::Vec<Feature> = object
                    .iter()
                    .enumerate()
                    .map(|(k, &q)| seen(&cam, &driving(t), q, class, k as u8))
                    .collect();
                let mut d = seen(&cam, &driving(t), lone, class, 50);
                (d.ur, d.depth_m) = (-1.0, -1.0);
                feats.push(d);
                landmarkless_frame_with(&mut s, &feats, t, p);
                got.push((s.measured(4), s.consistent(4), s.uninformative[4]));
            }
            got
        };
        let p = MotionParams::default();
        let person = lone_pass(9, &p);
        assert_eq!(person[2], (true, true, true), "{person:?}");
        let without = lone_pass(9, &MotionParams { slow_human_mps: 0.0, ..p });
        assert_eq!(without[2], (true, true, false), "{without:?}");
        let car = lone_pass(8, &p);
        assert_eq!(car[2], (true, true, false), "{car:?}");
    }

    /// Objects without a single stereo feature (no depth to test them at): a car crossing
    /// 0.6 m per frame leaves its epipolar segment and is called moving in its second frame;
    /// a parked car, and a car ahead driving at the camera's speed (it moves along its
    /// epipolar line), are not measured and stay unproven. Without the epipolar test the
    /// crossing car stays unproven too. A stereo feature with nothing to chain to is tested
    /// the same way.
    #[test]
    fn a_depthless_object_crossing_is_caught_by_the_epipolar_test() {
        let cam = crate::testing::kitti_cam();
        let far = 40.0 * cam.baseline_m as f32;
        let crossing: std::vec::Vec<Vector3<f64>> = (0..4)
            .map(|k| Vector3::new(-4.0 + 0.3 * f64::from(k), 0.4 + 0.1 * f64::from(k % 2), 25.0))
            .collect();
        let parked: std::vec::Vec<Vector3<f64>> = (0..4)
            .map(|k| Vector3::new(5.0 + 0.3 * f64::from(k), 0.6 + 0.1 * f64::from(k % 2), 20.0))
            .collect();
        let ahead: std::vec::Vec<Vector3<f64>> = (0..4)
            .map(|k| Vector3::new(0.3 * f64::from(k), 0.2 + 0.1 * f64::from(k % 2), 30.0))
            .collect();
        let frame = |t: usize| -> std::vec::Vec<Feature> {
            let mut f = std::vec::Vec::new();
            let objects = [
                (&crossing, Vector3::new(0.6 * t as f64, 0.0, 0.0), 0u8),
                (&parked, Vector3::zeros(), 50),
                (&ahead, Vector3::new(0.0, 0.0, t as f64), 100),
            ];
            for (obj, shift, seed) in objects {
                for (k, &q) in obj.iter().enumerate() {
                    let mut d = seen(&cam, &driving(t), q + shift, 8, seed + k as u8);
                    (d.ur, d.depth_m) = (-1.0, -1.0);
                    f.push(d);
                }
            }
            f
        };
        let run = |p: MotionParams| {
            let mut s = std::boxed::Box::new(MotionScratch::new());
            let mut states = std::vec::Vec::new();
            for t in 0..3 {
                let feats = frame(t);
                s.reset(feats.len());
                s.match_previous(&feats, &cam, &driving(t), far, &p, TRACK_MAX_HAMMING, 0.8);
                s.decide(&feats, &cam, &driving(t), &p, |_, _| unreachable!("no landmarks"));
                s.remember(&feats, &cam, &driving(t).inverse(), far, &p);
                let measured = (0..feats.len()).filter(|&i| s.measured(i)).count();
                states.push((s.state[0], s.state[4], s.state[8], measured));
            }
            states
        };
        use FeatureMotion::*;
        let on = run(MotionParams::default());
        assert_eq!(on[0], (Unproven, Unproven, Unproven, 0), "first sight: no previous frame");
        assert_eq!(on[1], (Moving, Unproven, Unproven, 4), "{on:?}");
        assert_eq!(on[2], (Moving, Unproven, Unproven, 4), "{on:?}");
        let off = run(MotionParams { epipolar: false, ..MotionParams::default() });
        assert!(off.iter().all(|&m| m == (Unproven, Unproven, Unproven, 0)), "{off:?}");
        // A stereo feature whose previous sighting had no depth (no chain to measure it
        // against) is tested the same way.
        let p = MotionParams::default();
        let mut s = std::boxed::Box::new(MotionScratch::new());
        for t in 0..2 {
            let mut feats = frame(t);
            if t == 1 {
                for f in &mut feats[..4] {
                    f.depth_m = 25.0 - 1.0;
                    f.ur = f.x - (cam.fx_px * cam.baseline_m) as f32 / f.depth_m;
                }
            }
            s.reset(feats.len());
            let n = s.match_previous(&feats, &cam, &driving(t), far, &p, TRACK_MAX_HAMMING, 0.8);
            assert_eq!(n, 0, "no stereo feature in the previous frame");
            s.decide(&feats, &cam, &driving(t), &p, |_, _| unreachable!("no landmarks"));
            s.remember(&feats, &cam, &driving(t).inverse(), far, &p);
        }
        assert!((0..4).all(|i| s.measured(i) && !s.consistent(i)));
        assert_eq!((s.state[0], s.state[4]), (Moving, Unproven));
    }

    /// A cyclist riding ahead at the camera's speed, without stereo depth: its features do
    /// not move in the image, which a point that stood still could only do from far beyond
    /// where its ray meets the road. With the camera's height the epipolar segment ends
    /// there, and the cyclist is called moving in its second frame; without it (0) it stays
    /// unproven. A parked car's features below the horizon stay unmeasured either way.
    #[test]
    fn a_depthless_cyclist_riding_ahead_is_off_its_segment_above_the_road() {
        let cam = crate::testing::kitti_cam();
        let far = 40.0 * cam.baseline_m as f32;
        // 0.15-0.45 m above the road (camera 1.65 m up), 10 m ahead, 1.5-2.4 m to the right.
        let cyclist: std::vec::Vec<Vector3<f64>> = (0..4)
            .map(|k| Vector3::new(1.5 + 0.3 * f64::from(k), 1.5 - 0.1 * f64::from(k % 4), 10.0))
            .collect();
        let parked: std::vec::Vec<Vector3<f64>> = (0..4)
            .map(|k| Vector3::new(3.0 + 0.3 * f64::from(k), 1.5 - 0.3 * f64::from(k % 2), 8.0))
            .collect();
        let run = |p: MotionParams| {
            let mut s = std::boxed::Box::new(MotionScratch::new());
            let mut states = std::vec::Vec::new();
            for t in 0..3 {
                let mut feats = std::vec::Vec::new();
                let objects = [
                    (&cyclist, Vector3::new(0.0, 0.0, t as f64), 0u8, 10u8),
                    (&parked, Vector3::zeros(), 50, 8),
                ];
                for (obj, shift, seed, class) in objects {
                    for (k, &q) in obj.iter().enumerate() {
                        let mut d = seen(&cam, &driving(t), q + shift, class, seed + k as u8);
                        (d.ur, d.depth_m) = (-1.0, -1.0);
                        feats.push(d);
                    }
                }
                s.reset(feats.len());
                s.match_previous(&feats, &cam, &driving(t), far, &p, TRACK_MAX_HAMMING, 0.8);
                s.decide(&feats, &cam, &driving(t), &p, |_, _| unreachable!("no landmarks"));
                s.remember(&feats, &cam, &driving(t).inverse(), far, &p);
                let measured = (0..feats.len()).filter(|&i| s.measured(i)).count();
                states.push((s.state[0], s.state[4], measured));
            }
            states
        };
        use FeatureMotion::*;
        let on = run(MotionParams::default());
        assert_eq!(on[0], (Unproven, Unproven, 0), "first sight: no previous frame");
        assert_eq!(on[1], (Moving, Unproven, 4), "{on:?}");
        assert_eq!(on[2], (Moving, Unproven, 4), "{on:?}");
        let off = run(MotionParams { camera_height_m: 0.0, ..MotionParams::default() });
        assert!(off.iter().all(|&m| m == (Unproven, Unproven, 0)), "{off:?}");
    }

    /// A depthless chain measures against the ray it began on: a cyclist riding ahead at the
    /// camera's speed, 0.85-0.9 m above the road, is within its one-frame segment (2.9 px
    /// beyond its end, under the gate), but two frames from the chain's first sighting it is
    /// 5.8 px beyond it and called moving.
    #[test]
    fn a_depthless_chain_accumulates_motion_along_the_line_of_sight() {
        let cam = crate::testing::kitti_cam();
        let far = 40.0 * cam.baseline_m as f32;
        let p = MotionParams::default();
        let cyclist: std::vec::Vec<Vector3<f64>> = (0..4)
            .map(|k| Vector3::new(1.5 + 0.1 * f64::from(k), 0.8 - 0.02 * f64::from(k), 10.0))
            .collect();
        let mut s = std::boxed::Box::new(MotionScratch::new());
        let mut states = std::vec::Vec::new();
        for t in 0..4 {
            let feats: std::vec::Vec<Feature> = cyclist
                .iter()
                .enumerate()
                .map(|(k, &q)| {
                    let mut d =
                        seen(&cam, &driving(t), q + Vector3::new(0.0, 0.0, t as f64), 10, k as u8);
                    (d.ur, d.depth_m) = (-1.0, -1.0);
                    d
                })
                .collect();
            s.reset(feats.len());
            s.match_previous(&feats, &cam, &driving(t), far, &p, TRACK_MAX_HAMMING, 0.8);
            s.decide(&feats, &cam, &driving(t), &p, |_, _| unreachable!("no landmarks"));
            s.remember(&feats, &cam, &driving(t).inverse(), far, &p);
            let measured = (0..feats.len()).filter(|&i| s.measured(i)).count();
            states.push((s.state[0], measured));
        }
        use FeatureMotion::*;
        assert_eq!(states, [(Unproven, 0), (Unproven, 0), (Moving, 4), (Moving, 4)]);
    }

    /// The bound on a static point's depth: below the horizon where the ray, 2° less steep,
    /// meets the road 0.3 m lower; above it, where it reaches the tallest of the class (4.5 m
    /// for a vehicle, 2.5 m for a person); unbounded within 2° of the horizon, for static
    /// classes and without a camera height.
    #[test]
    fn static_depth_bounds_rays_by_the_road_and_the_class_height() {
        let cam = crate::testing::kitti_cam();
        let tol = libm::tan(2f64.to_radians());
        for class in [8, 9, 10] {
            assert_eq!(static_depth(&cam, cam.cy_px + 10.0, class, 1.65), EPIPOLAR_FAR_M);
            assert_eq!(static_depth(&cam, cam.cy_px - 10.0, class, 1.65), EPIPOLAR_FAR_M);
            assert_eq!(static_depth(&cam, cam.cy_px + 200.0, class, 0.0), EPIPOLAR_FAR_M);
            let z = static_depth(&cam, cam.cy_px + 200.0, class, 1.65);
            let want = 1.95 / (200.0 / cam.fy_px - tol);
            assert!((z - want).abs() < 1e-5 && z > 7.5 && z < 8.5, "{z}");
        }
        assert_eq!(static_depth(&cam, cam.cy_px + 200.0, 1, 1.65), EPIPOLAR_FAR_M);
        let car = static_depth(&cam, cam.cy_px - 100.0, 8, 1.65);
        assert!((car - 2.85 / (100.0 / cam.fy_px - tol)).abs() < 1e-5, "{car}");
        let person = static_depth(&cam, cam.cy_px - 100.0, 9, 1.65);
        assert!((person - 0.85 / (100.0 / cam.fy_px - tol)).abs() < 1e-5, "{person}");
    }
}
