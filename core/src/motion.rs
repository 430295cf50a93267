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
//!    keeps them apart. A feature without depth joins its nearest stereo neighbour (within
//!    half the pixel distance) and never links two segments: chained through such features,
//!    the passing car and the parked one were one object again (on synthetic `high` a third
//!    of the wrongly removed features were parked cars joined to moving ones that way).
//! 3. **Test against the ego-motion.** Every matched feature of a segment is a measurement of
//!    its landmark at the solved pose: χ² at most the 95 % gate (as ORB-SLAM2's) is evidence
//!    for "static", above it for "moving". Per feature the log-likelihood ratio
//!    `ln p(·|moving)/p(·|static)` is `ln(0.25/0.85)` for a consistent and `ln(0.75/0.15)` for
//!    an inconsistent measurement (a segment is called moving above ~43 % inconsistent); the
//!    segment sums them (clamped to ±[`MotionParams::max_frame_llr`]).
//! 4. **A latent "moving" variable per landmark**, accumulated over frames: each matched
//!    landmark of the segment adds the segment's evidence to its log-odds (clamped to ±4). The
//!    segment's posterior is the class prior ([`MotionParams::prior_vehicle`],
//!    [`MotionParams::prior_human`]: cars in a city are mostly parked) plus the mean log-odds of
//!    its landmarks after the update.
//! 5. **Decide.** A segment with at least [`MotionParams::min_evidence`] matched features and
//!    posterior `p(moving) < 0.1` is *parked*: its consistent matches rejoin the pose solve
//!    (one more solve) and the keyframe. A segment with `p(moving) > 0.5` is *moving*: its
//!    features are unlinked and create no landmarks. Anything else is *unproven*: excluded
//!    from this frame's pose, but its unmatched features may create landmarks so that the
//!    next frames can test it.
//!
//! The EM association sees the outcome through its candidates: held features have none.
//!
//! Memory: [`MotionScratch`] is ≈ 54 KiB of per-frame arrays; the per-landmark log-odds live
//! in [`crate::map::Landmark::moving_lo`]. No allocation, deterministic.

use heapless::Vec;

use crate::frame::{Feature, FRAME_CAPACITY};
use crate::geom::StereoCamera;
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

/// Per-frame arrays of the motion test.
pub(crate) struct MotionScratch {
    /// Landmark each dynamic-class (or held) feature matched before the association
    /// ([`crate::map::NO_LANDMARK`] if none).
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
    /// Grouping: a depthless feature with no stereo neighbour.
    unattached: [bool; FRAME_CAPACITY],
    /// Grouping, per depthless group root: squared pixel distance to, and index of, the
    /// nearest attached feature.
    join_d2: [f32; FRAME_CAPACITY],
    join_to: [u16; FRAME_CAPACITY],
}

impl MotionScratch {
    pub const fn new() -> Self {
        Self {
            cand: [crate::map::NO_LANDMARK; FRAME_CAPACITY],
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
            unattached: [false; FRAME_CAPACITY],
            join_d2: [f32::INFINITY; FRAME_CAPACITY],
            join_to: [0; FRAME_CAPACITY],
        }
    }

    /// Resets the per-frame arrays for a frame of `n` features (all static, nothing held).
    pub fn reset(&mut self, n: usize) {
        self.cand[..n].fill(crate::map::NO_LANDMARK);
        self.chi2[..n].fill(-1.0);
        self.held[..n].fill(false);
        self.state[..n].fill(FeatureMotion::Static);
        self.blocked[..n].fill(false);
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
    /// depth joins the segment of its nearest stereo neighbour (same category, within half of
    /// [`MotionParams::link_px`]) and never links two segments: in traffic a monocular feature
    /// on the border between a car driving past and the parked car behind it would otherwise
    /// chain the two into one object. Features without depth and without a stereo neighbour
    /// link among themselves.
    pub fn segment(&mut self, feats: &[Feature], cam: &StereoCamera, params: &MotionParams) -> u32 {
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
        // A monocular feature joins its nearest stereo neighbour (ties: the lower index); the
        // unattached ones are marked for the last passes.
        let half = 0.5 * params.link_px;
        for a in 0..n {
            let ia = usize::from(self.dyn_idx[a]);
            let fa = feats[ia];
            self.unattached[ia] = false;
            if fa.is_stereo() {
                continue;
            }
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

    /// Joins the segments of `a` and `b`; the smaller root index stays the root
    /// (deterministic whatever the link order).
    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (lo, hi) = if ra < rb { (ra, rb) } else { (rb, ra) };
            self.parent[hi] = lo as u16;
        }
    }

    /// Whether feature `i` has a match measured at the solved pose.
    fn measured(&self, i: usize) -> bool {
        self.cand[i] != crate::map::NO_LANDMARK && self.chi2[i] >= 0.0
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
        params: &MotionParams,
        mut update: impl FnMut(u32, f32) -> f32,
    ) -> MotionReport {
        let segments = self.segment(feats, cam, params);
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
                self.ev[r] += LLR_CONSISTENT;
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
            self.lo_sum[r] += update(id, e);
            self.n_lm[r] = self.n_lm[r].saturating_add(1);
        }
        for k in 0..n {
            let i = usize::from(self.dyn_idx[k]);
            let r = self.find(i);
            let evidence = u32::from(self.n_ok[r]) + u32::from(self.n_bad[r]);
            let post = params.prior_logit(feats[r].class)
                + if self.n_lm[r] > 0 { self.lo_sum[r] / f32::from(self.n_lm[r]) } else { 0.0 };
            let state = if evidence >= params.min_evidence && post < STATIC_LOGIT {
                FeatureMotion::Parked
            } else if evidence > 0 && post > MOVING_LOGIT {
                FeatureMotion::Moving
            } else {
                FeatureMotion::Unproven
            };
            self.state[i] = state;
            // Moving objects make no landmarks; an unproven object's matched features do not
            // duplicate the landmark they matched.
            self.blocked[i] = match state {
                FeatureMotion::Moving => true,
                FeatureMotion::Unproven => self.cand[i] != crate::map::NO_LANDMARK,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::NO_LANDMARK;

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
        assert_eq!(s.segment(&feats, &crate::testing::kitti_cam(), &p), 4);
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
        assert_eq!(s.segment(&feats, &crate::testing::kitti_cam(), &p), 3);
        assert_eq!(s.root(1), 0);
        assert_eq!(s.root(3), 2);
        assert_eq!(s.root(4), 2, "joins the nearer (parked) car only");
        assert_eq!(s.root(5), 2);
        assert_eq!(s.root(6), 2, "a depthless group joins through its nearest attached feature");
        assert_eq!(s.root(7), 2);
        assert_eq!(s.root(8), 8);
    }

    /// A parked car (consistent matches) is used, a moving one (inconsistent) removed, and a
    /// car without matches stays unproven; the landmarks accumulate the evidence.
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
        let mut lo = [0.0f32; 16];
        let frame = |s: &mut MotionScratch, lo: &mut [f32; 16]| {
            s.reset(feats.len());
            for i in 0..10 {
                s.cand[i] = i as u32;
                s.gate[i] = 7.8;
                s.chi2[i] = if i < 5 { 1.0 } else { 60.0 };
            }
            s.decide(&feats, &crate::testing::kitti_cam(), &p, |id, e| {
                let l = &mut lo[id as usize];
                *l = (*l + e).clamp(-MAX_LANDMARK_LOGIT, MAX_LANDMARK_LOGIT);
                *l
            })
        };
        // One frame of consistent matches is not yet enough to call a car parked; one frame
        // of inconsistent ones calls the other moving.
        let rep = frame(&mut s, &mut lo);
        assert_eq!((rep.parked_features, rep.moving_features, rep.unproven_features), (0, 5, 8));
        assert!(lo[..5].iter().all(|&l| (l + p.max_frame_llr).abs() < 1e-6));
        let rep = frame(&mut s, &mut lo);
        assert_eq!(rep.segments, 3);
        assert_eq!(rep.parked_segments, 1);
        assert_eq!(rep.moving_segments, 1);
        assert_eq!((rep.parked_features, rep.moving_features, rep.unproven_features), (5, 5, 3));
        assert!(s.state[..5].iter().all(|&m| m == FeatureMotion::Parked));
        assert!(s.state[5..10].iter().all(|&m| m == FeatureMotion::Moving));
        assert!(s.state[10..13].iter().all(|&m| m == FeatureMotion::Unproven));
        assert!(s.blocked[5..10].iter().all(|&b| b));
        assert!(!s.blocked[..5].iter().any(|&b| b) && !s.blocked[10..13].iter().any(|&b| b));
        // Clamped frame evidence went to each landmark, twice.
        assert!(lo[..5].iter().all(|&l| (l + 2.0 * p.max_frame_llr).abs() < 1e-6));
        assert!(lo[5..10].iter().all(|&l| (l - 2.0 * p.max_frame_llr).abs() < 1e-6));
        assert_eq!(s.cand[12], NO_LANDMARK);
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
        let rep = s.decide(&feats, &crate::testing::kitti_cam(), &p, |_, _| -2.67);
        assert_eq!(rep.parked_segments, 0);
        assert_eq!(rep.unproven_features, 8);
        s.reset(feats.len());
        for i in 0..8 {
            s.cand[i] = i as u32;
            s.gate[i] = 7.8;
            s.chi2[i] = if i == 3 { 50.0 } else { 1.0 };
        }
        let rep = s.decide(&feats, &crate::testing::kitti_cam(), &p, |_, _| -6.0);
        assert_eq!(rep.parked_segments, 1);
        assert_eq!(rep.parked_features, 8);
    }
}
