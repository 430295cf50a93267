//! Local mapping on a keyframe, as ORB-SLAM2's `LocalMapping` run inline:
//! 1. record the tracked observations (with their association weights, paper §3.3);
//! 2. create landmarks from the close stereo points (and the nearest others up to a count);
//! 3. triangulate new landmarks between the keyframe and its covisible keyframes
//!    (epipolar-constrained descriptor search, parallax, reprojection and scale checks);
//! 4. fuse duplicates between the keyframe and its neighbours (and neighbours' neighbours);
//! 5. local bundle adjustment over the keyframe and its covisible keyframes, with the other
//!    keyframes that observe those landmarks held fixed; outlier observations leave the map;
//! 6. cull recent landmarks that are rarely found or weakly observed, and keyframes whose
//!    landmarks are ≥ 90 % seen by at least 3 other keyframes.
//!
//! Memory: [`LocalMap`] owns the [`Map`] and the scratch that maintains it (BA observations
//! and points, the grid of one keyframe's features); nothing is allocated per keyframe.

use heapless::Vec;
use nalgebra::Vector3;

use super::{
    measurement, predict_level, renormalize, Landmark, Map, MAX_KEYFRAMES, MAX_LANDMARKS, NO_KF,
    NO_LANDMARK,
};
use crate::assoc::FeatureGrid;
use crate::frame::{hamming, level_inv_sigma2, level_scale, Feature, Frame, FRAME_CAPACITY};
use crate::geom::{Se3, StereoCamera};
use crate::optim::{bundle_adjust, chi2, BaObs, BaParams, BaScratch, MAX_WINDOW};
use crate::seg::NUM_CLASSES;
use crate::semdesc::SemDesc;

/// Most observations one BA problem holds.
const MAX_BA_OBS: usize = MAX_WINDOW * FRAME_CAPACITY;
/// Descriptor distance accepted for triangulation and fusion (ORB-SLAM2 `TH_LOW`).
const TH_LOW: u32 = 50;
/// Covisible keyframes searched for triangulation (ORB-SLAM2 stereo: 10).
const TRIANGULATION_NEIGHBOURS: usize = 6;
/// Second-order neighbours per neighbour in fusion (ORB-SLAM2: 5).
const FUSION_SECOND_NEIGHBOURS: usize = 5;
/// ORB-SLAM2's scale consistency factor (1.5 × scale factor).
const RATIO_FACTOR: f64 = 1.5 * 1.2;

/// The mapping settings (a subset of the tracker's).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MappingParams {
    /// Stereo points closer than this many baselines are "close".
    pub close_depth_baselines: f64,
    /// Landmarks a keyframe creates at least (nearest first) besides its close points.
    pub min_new_landmarks: usize,
    /// BA iterations per keyframe.
    pub ba_iterations: u8,
    /// Keyframes optimised by local BA (the new one and its best covisible ones).
    pub ba_keyframes: usize,
    /// Triangulate between keyframes.
    pub triangulate: bool,
    /// Remove redundant keyframes.
    pub cull_keyframes: bool,
    /// Stereo points beyond this depth (m) are monocular measurements in BA.
    pub far_m: f32,
}

/// What the tracker hands the map for a new keyframe.
pub(crate) struct NewKeyframe<'a> {
    /// The frame (features and their semantic descriptors).
    pub frame: &'a Frame,
    /// Index of the frame.
    pub frame_index: u32,
    /// Its tracked world-to-camera pose.
    pub t_cw: Se3,
    /// Landmark matched to each feature, or [`NO_LANDMARK`].
    pub landmark: &'a [u32; FRAME_CAPACITY],
    /// Association weight of each matched feature.
    pub weight: &'a [f32; FRAME_CAPACITY],
    /// Features that may not create landmarks (on moving objects, [`crate::motion`]); `None`:
    /// all may.
    pub blocked: Option<&'a [bool; FRAME_CAPACITY]>,
    /// Moving log-odds each feature's new landmark starts with ([`crate::motion`]: what the
    /// frame-to-frame test learnt of its object); `None`: 0.
    pub moving_lo: Option<&'a [f32; FRAME_CAPACITY]>,
}

/// What inserting a keyframe did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct KeyframeOutcome {
    /// Whether the keyframe was stored (false only if no slot could be freed).
    pub stored: bool,
    /// Landmarks created from stereo points.
    pub new_landmarks: u32,
    /// Landmarks created by triangulation between keyframes.
    pub triangulated: u32,
    /// Landmarks fused or observations added by fusion.
    pub fused: u32,
    /// Keyframes culled as redundant.
    pub culled_keyframes: u32,
    /// BA iterations run (0 when the map holds a single keyframe).
    pub ba_iterations: u32,
    /// The keyframe's pose after BA, when BA ran.
    pub t_cw: Option<Se3>,
}

/// The map and the scratch that maintains it.
pub(crate) struct LocalMap {
    map: Map,
    order_keys: Vec<u64, FRAME_CAPACITY>,
    grid: FeatureGrid,
    cell_stamp: [u32; 64 * 24],
    cell_epoch: u32,
    width: f32,
    height: f32,
    neighbours: Vec<u8, MAX_KEYFRAMES>,
    ba: BaScratch,
    ba_keys: Vec<u64, MAX_BA_OBS>,
    ba_obs: Vec<BaObs, MAX_BA_OBS>,
    ba_points: [Vector3<f64>; MAX_LANDMARKS],
    ba_backup: [Vector3<f64>; MAX_LANDMARKS],
    ba_ids: [u32; MAX_LANDMARKS],
    lm_compact: [u32; MAX_LANDMARKS],
    /// The current keyframe's features that may not create landmarks.
    blocked: [bool; FRAME_CAPACITY],
    /// The current keyframe's moving log-odds per feature, for the landmarks it creates.
    init_lo: [f32; FRAME_CAPACITY],
}

impl LocalMap {
    /// An empty map for images of `width`x`height` pixels.
    pub fn new(width: f32, height: f32) -> Self {
        let mut m = Self {
            map: Map::new(),
            order_keys: Vec::new(),
            grid: FeatureGrid::new(),
            cell_stamp: [0; 64 * 24],
            cell_epoch: 0,
            width,
            height,
            neighbours: Vec::new(),
            ba: BaScratch::new(),
            ba_keys: Vec::new(),
            ba_obs: Vec::new(),
            ba_points: [Vector3::new(0.0, 0.0, 0.0); MAX_LANDMARKS],
            ba_backup: [Vector3::new(0.0, 0.0, 0.0); MAX_LANDMARKS],
            ba_ids: [0; MAX_LANDMARKS],
            lm_compact: [u32::MAX; MAX_LANDMARKS],
            blocked: [false; FRAME_CAPACITY],
            init_lo: [0.0; FRAME_CAPACITY],
        };
        m.map.clear();
        m
    }

    /// The map.
    pub fn map(&self) -> &Map {
        &self.map
    }

    /// The map, mutable (the tracker counts landmark visibility and matches in it).
    pub fn map_mut(&mut self) -> &mut Map {
        &mut self.map
    }

    /// Empties the map.
    pub fn clear(&mut self) {
        self.map.clear();
    }

    /// Makes `kf` a keyframe and maintains the map around it (see the module documentation).
    /// `now` is the frame index: keyframes of the current local map are not evicted.
    pub fn insert_keyframe(
        &mut self,
        cam: &StereoCamera,
        params: &MappingParams,
        kf: &NewKeyframe<'_>,
        now: u32,
    ) -> KeyframeOutcome {
        let mut out = KeyframeOutcome::default();
        // Room for a keyframe's worth of landmarks: evict the least recently used keyframes.
        while self.map.free_landmarks() < FRAME_CAPACITY
            && self.map.len() > 2
            && self.map.evict_lru(now)
        {}
        let frame = kf.frame;
        let feats = &frame.features[..];
        let Some(slot) = self.map.push_keyframe(kf.frame_index, kf.t_cw, feats, now) else {
            return out;
        };
        out.stored = true;
        self.map.kf_mut(slot).timestamp_s = frame.timestamp_s;
        match kf.blocked {
            Some(b) => self.blocked[..feats.len()].copy_from_slice(&b[..feats.len()]),
            None => self.blocked[..feats.len()].fill(false),
        }
        match kf.moving_lo {
            Some(lo) => self.init_lo[..feats.len()].copy_from_slice(&lo[..feats.len()]),
            None => self.init_lo[..feats.len()].fill(0.0),
        }
        let center = kf.t_cw.inverse().trans;
        for (i, f) in feats.iter().enumerate() {
            let id = kf.landmark[i];
            if id == NO_LANDMARK || !self.map.lm(id).alive {
                continue;
            }
            self.map.add_observation(slot, i, id);
            if self.map.kf(slot).landmark[i] != id {
                continue;
            }
            self.map.kf_mut(slot).weight[i] = kf.weight[i];
            let l = self.map.lm_mut(id);
            l.desc = f.desc;
            l.ref_level = f.level;
            l.ref_dist_m = (l.p_w - center).norm() as f32;
            note_semantics(l, f, frame.sem[i]);
        }
        out.new_landmarks = self.create_stereo_landmarks(cam, params, slot, frame);
        // The covisible keyframes, best first (stamps keep the list free of repeats).
        self.neighbours.clear();
        let stamp = self.map.next_stamp();
        self.map.kf_mut(slot).stamp = stamp;
        self.map.best_covisible(slot, TRIANGULATION_NEIGHBOURS, 1, stamp, &mut self.neighbours);
        if params.triangulate {
            out.triangulated = self.triangulate(cam, slot, frame, params.far_m);
        }
        out.fused = self.fuse_neighbours(cam, slot, frame);
        if self.map.len() >= 2 {
            out.ba_iterations = self.local_ba(cam, slot, params, now);
            out.t_cw = Some(self.map.kf(slot).t_cw);
            self.cull_landmarks();
            if params.cull_keyframes {
                out.culled_keyframes = self.cull_keyframes(cam, params, slot);
            }
        }
        out
    }

    /// Landmarks from the keyframe's unmatched stereo points: all close ones and at least
    /// `min_new_landmarks` nearest. Far stereo depth alone is too noisy to anchor a map; far
    /// points enter when a second keyframe triangulates them.
    fn create_stereo_landmarks(
        &mut self,
        cam: &StereoCamera,
        params: &MappingParams,
        slot: u8,
        frame: &Frame,
    ) -> u32 {
        let feats = &frame.features[..];
        let t_wc = self.map.kf(slot).t_cw.inverse();
        self.order_keys.clear();
        for (i, f) in feats.iter().enumerate() {
            if f.is_stereo() && self.map.kf(slot).landmark[i] == NO_LANDMARK && !self.blocked[i] {
                let key = (u64::from(f.depth_m.to_bits()) << 32) | i as u64;
                let _ = self.order_keys.push(key);
            }
        }
        self.order_keys.sort_unstable();
        let th_close = params.close_depth_baselines * cam.baseline_m;
        let mut created = 0u32;
        for k in 0..self.order_keys.len() {
            let i = (self.order_keys[k] & 0xffff_ffff) as usize;
            let f = &feats[i];
            let depth = f64::from(f.depth_m);
            if depth > th_close && created as usize >= params.min_new_landmarks {
                break;
            }
            let pc = cam.backproject(f64::from(f.x), f64::from(f.y), depth);
            let p_w = t_wc.transform_point(&pc);
            // The scale prediction compares camera-centre distances, so store the distance, not
            // the depth (they differ by up to 40 % at the image edges).
            let dist = pc.norm() as f32;
            let Some(id) = self.map.new_landmark(p_w, f.desc, f.level, dist) else {
                break;
            };
            self.map.add_observation(slot, i, id);
            let l = self.map.lm_mut(id);
            note_semantics(l, f, frame.sem[i]);
            l.moving_lo = self.init_lo[i];
            created += 1;
        }
        created
    }

    /// ORB-SLAM2's `CreateNewMapPoints` for a stereo rig: for each covisible keyframe far
    /// enough away, match the unmatched features along their epipolar segments and
    /// triangulate what passes the parallax, depth, reprojection and scale checks.
    fn triangulate(&mut self, cam: &StereoCamera, slot: u8, frame: &Frame, far_m: f32) -> u32 {
        let mut created = 0u32;
        let t1 = self.map.kf(slot).t_cw;
        let c1 = t1.inverse().trans;
        let bf = cam.bf();
        for k in 0..self.neighbours.len() {
            let n = self.neighbours[k];
            let t2 = self.map.kf(n).t_cw;
            let c2 = t2.inverse().trans;
            if (c2 - c1).norm() < cam.baseline_m {
                continue;
            }
            // Only the features still free can match (a feature matched in this loop is
            // skipped by `epipolar_match` itself); the rest keep their order in each cell.
            let kf_n = self.map.kf(n);
            self.grid.build_where(&kf_n.features, self.width, self.height, |i| {
                kf_n.landmark[i] == NO_LANDMARK
            });
            let r21 = t2.rot * t1.rot.transpose();
            for i1 in 0..frame.features.len() {
                if self.map.kf(slot).landmark[i1] != NO_LANDMARK || self.blocked[i1] {
                    continue;
                }
                let f1 = frame.features[i1];
                // The ray of f1 in camera 1, and the depth range along it.
                let ray1 = Vector3::new(
                    (f64::from(f1.x) - cam.cx_px) / cam.fx_px,
                    (f64::from(f1.y) - cam.cy_px) / cam.fy_px,
                    1.0,
                );
                let (d_min, d_max) = if f1.is_stereo() {
                    let disp = f64::from(f1.x - f1.ur);
                    let s = 2.0 * f64::from(level_scale(f1.level));
                    (bf / (disp + s), if disp > s + 0.5 { bf / (disp - s) } else { 400.0 })
                } else {
                    (0.5, 400.0)
                };
                // Camera-2 coordinates of the ray: a + d·b.
                let a = t2.transform_point(&c1);
                let b = r21 * ray1;
                let d_front = if b.z < 0.0 {
                    // Points beyond this depth are behind camera 2.
                    let d = (0.1 - a.z) / b.z;
                    if d <= d_min {
                        continue;
                    }
                    d_max.min(d)
                } else {
                    d_max
                };
                let d_lo = if a.z + d_min * b.z < 0.1 {
                    if b.z <= 0.0 {
                        continue;
                    }
                    (0.1 - a.z) / b.z
                } else {
                    d_min
                };
                let p_lo = a + b * d_lo;
                let p_hi = a + b * d_front;
                let (u_lo, v_lo) = proj(cam, &p_lo);
                let (u_hi, v_hi) = proj(cam, &p_hi);
                let Some(i2) = self.epipolar_match(cam, n, &f1, (u_lo, v_lo), (u_hi, v_hi)) else {
                    continue;
                };
                let f2 = self.map.kf(n).features[i2];
                let Some(p_w) = triangulate_pair(cam, &t1, &f1, &t2, &f2, far_m) else {
                    continue;
                };
                let dist = (p_w - c1).norm() as f32;
                let Some(id) = self.map.new_landmark(p_w, f1.desc, f1.level, dist) else {
                    return created;
                };
                self.map.add_observation(slot, i1, id);
                self.map.add_observation(n, i2, id);
                let l = self.map.lm_mut(id);
                note_semantics(l, &f1, frame.sem[i1]);
                note_semantics(l, &f2, None);
                l.moving_lo = self.init_lo[i1];
                created += 1;
            }
        }
        created
    }

    /// The best unmatched feature of keyframe `n` (gridded in `self.grid`) along the image
    /// segment from `lo` to `hi`: same level ±2, within the epipolar band, under `TH_LOW` and
    /// clear of the second best by the 0.8 ratio.
    fn epipolar_match(
        &mut self,
        _cam: &StereoCamera,
        n: u8,
        f1: &Feature,
        lo: (f64, f64),
        hi: (f64, f64),
    ) -> Option<usize> {
        let (dx, dy) = (hi.0 - lo.0, hi.1 - lo.1);
        let len = crate::math::sqrt(dx * dx + dy * dy);
        if !len.is_finite() {
            return None;
        }
        // Clip the segment to the image.
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (p, d, max) in [(lo.0, dx, w), (lo.1, dy, h)] {
            if crate::math::abs(d) < 1e-9 {
                if p < 0.0 || p >= max {
                    return None;
                }
                continue;
            }
            let (ta, tb) = ((0.0 - p) / d, (max - p) / d);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
        if t0 > t1 {
            return None;
        }
        let (nx, ny) = if len > 1e-9 { (-dy / len, dx / len) } else { (0.0, 0.0) };
        self.cell_epoch = self.cell_epoch.wrapping_add(1);
        if self.cell_epoch == 0 {
            self.cell_stamp.fill(0);
            self.cell_epoch = 1;
        }
        let epoch = self.cell_epoch;
        let kf = self.map.kf(n);
        let steps = ((len * (t1 - t0)) / 8.0).clamp(0.0, 399.0) as usize + 1;
        let mut best = (u32::MAX, usize::MAX);
        let mut second = u32::MAX;
        // Consecutive steps mostly cover the same cells (steps of 8 px, cells of ~19 × 16 px):
        // a step whose box of cells equals the previous step's has nothing new to visit.
        // The boxes of all steps first, in one vectorised pass (packed, see `boxes_along`).
        let mut boxes = [0u32; 400 + 1];
        self.grid.boxes_along(lo, (dx, dy), t0, t1, steps, 8.0, &mut boxes[..=steps]);
        let mut prev_box = u32::MAX;
        for &b in &boxes[..=steps] {
            if b == prev_box {
                continue;
            }
            prev_box = b;
            let [cx0, cy0, cx1, cy1] = b.to_le_bytes().map(usize::from);
            for cy in cy0..=cy1 {
                for cx in cx0..=cx1 {
                    let c = cy * 64 + cx;
                    if self.cell_stamp[c] == epoch {
                        continue;
                    }
                    self.cell_stamp[c] = epoch;
                    for &i2 in self.grid.row_items(cy, cx, cx) {
                        let i2 = usize::from(i2);
                        if kf.landmark[i2] != NO_LANDMARK {
                            continue;
                        }
                        let f2 = &kf.features[i2];
                        if (i32::from(f2.level) - i32::from(f1.level)).abs() > 2 {
                            continue;
                        }
                        // Distance to the epipolar line, against ORB-SLAM2's 3.84·σ² band.
                        let e = if len > 1e-9 {
                            (f64::from(f2.x) - lo.0) * nx + (f64::from(f2.y) - lo.1) * ny
                        } else {
                            let (ex, ey) = (f64::from(f2.x) - lo.0, f64::from(f2.y) - lo.1);
                            crate::math::sqrt(ex * ex + ey * ey)
                        };
                        if e * e * level_inv_sigma2(f2.level) > 3.84 {
                            continue;
                        }
                        let d = hamming(&f1.desc, &f2.desc);
                        if d < best.0 {
                            second = best.0;
                            best = (d, i2);
                        } else if d < second {
                            second = d;
                        }
                    }
                }
            }
        }
        if best.0 > TH_LOW || (best.0 as f32) > 0.8 * second as f32 {
            return None;
        }
        Some(best.1)
    }

    /// ORB-SLAM2's `SearchInNeighbors`: the new keyframe's landmarks are projected into its
    /// neighbours and their neighbours, and theirs into it; a match on a feature that already
    /// has a landmark merges the two (the better observed one stays), one on a free feature
    /// adds the observation. Returns merges plus added observations.
    fn fuse_neighbours(&mut self, cam: &StereoCamera, slot: u8, frame: &Frame) -> u32 {
        // Targets: neighbours and their best neighbours (stamped, so each appears once).
        let stamp = self.map.next_stamp();
        self.map.kf_mut(slot).stamp = stamp;
        let mut targets: Vec<u8, MAX_KEYFRAMES> = Vec::new();
        for &n in self.neighbours.iter() {
            self.map.kf_mut(n).stamp = stamp;
            let _ = targets.push(n);
        }
        for k in 0..self.neighbours.len() {
            let n = self.neighbours[k];
            self.map.best_covisible(n, FUSION_SECOND_NEIGHBOURS, 1, stamp, &mut targets);
        }
        let mut fused = 0u32;
        // The keyframe's landmarks into each target.
        for &t in targets.iter() {
            self.grid.build(&self.map.kf(t).features, self.width, self.height);
            for i in 0..frame.features.len() {
                let id = self.map.kf(slot).landmark[i];
                if id != NO_LANDMARK {
                    fused += self.fuse_one(cam, t, id);
                }
            }
        }
        // The targets' landmarks into the keyframe.
        self.grid.build(&frame.features, self.width, self.height);
        let lstamp = self.map.next_stamp();
        for &t in targets.iter() {
            let n = self.map.kf(t).features.len();
            for i in 0..n {
                let id = self.map.kf(t).landmark[i];
                if id == NO_LANDMARK || self.map.lm(id).local_stamp == lstamp {
                    continue;
                }
                self.map.lm_mut(id).local_stamp = lstamp;
                fused += self.fuse_one(cam, slot, id);
            }
        }
        fused
    }

    /// ORB-SLAM2's `Fuse` of one landmark into keyframe `t` (its features gridded in
    /// `self.grid`). Returns 1 when it merged or added an observation.
    fn fuse_one(&mut self, cam: &StereoCamera, t: u8, id: u32) -> u32 {
        let l = self.map.lm(id);
        let l_obs = l.n_obs;
        if !l.alive || l.feature_in(t).is_some() {
            return 0;
        }
        let kf = self.map.kf(t);
        let pc = kf.t_cw.transform_point(&l.p_w);
        if pc.z < 0.1 {
            return 0;
        }
        let (u, v) = proj(cam, &pc);
        if !(u >= 0.0 && v >= 0.0 && u < f64::from(self.width) && v < f64::from(self.height)) {
            return 0;
        }
        let dist = pc.norm();
        let pred = predict_level(l.ref_level, l.ref_dist_m, dist);
        let r = 3.0 * level_scale(pred as u8);
        let ur = u - cam.bf() / pc.z;
        let mut best = (u32::MAX, usize::MAX);
        self.grid.for_each_near(u as f32, v as f32, r, |i| {
            let f = &kf.features[i];
            let lvl = i32::from(f.level);
            if lvl < pred - 1 || lvl > pred {
                return;
            }
            let (ex, ey) = (f64::from(f.x) - u, f64::from(f.y) - v);
            let inv_s2 = level_inv_sigma2(f.level);
            let e2 = if f.is_stereo() {
                let er = f64::from(f.ur) - ur;
                (ex * ex + ey * ey + er * er) * inv_s2
            } else {
                (ex * ex + ey * ey) * inv_s2
            };
            let th = if f.is_stereo() { 7.8 } else { 5.99 };
            if e2 > th {
                return;
            }
            let d = hamming(&l.desc, &f.desc);
            if d < best.0 {
                best = (d, i);
            }
        });
        if best.0 > TH_LOW {
            return 0;
        }
        let i = best.1;
        let other = kf.landmark[i];
        if other == NO_LANDMARK {
            self.map.add_observation(t, i, id);
            return 1;
        }
        if other == id || !self.map.lm(other).alive {
            return 0;
        }
        // The better observed landmark stays.
        if self.map.lm(other).n_obs >= l_obs {
            self.map.merge_landmark(id, other);
        } else {
            self.map.merge_landmark(other, id);
        }
        1
    }

    /// Local BA: the keyframe and its best covisible keyframes are optimised, every other
    /// keyframe observing their landmarks (the most observing first, as many as fit) is held
    /// fixed; outlier observations are removed afterwards. Returns the iterations run.
    fn local_ba(&mut self, cam: &StereoCamera, slot: u8, params: &MappingParams, now: u32) -> u32 {
        let n_local_max = params.ba_keyframes.clamp(1, MAX_WINDOW - 1);
        let stamp = self.map.next_stamp();
        let mut local: Vec<u8, MAX_WINDOW> = Vec::new();
        self.map.kf_mut(slot).stamp = stamp;
        let _ = local.push(slot);
        self.map.best_covisible(slot, n_local_max - 1, 1, stamp, &mut local);
        // Points: the landmarks of the local keyframes, in id order (deterministic).
        let pstamp = self.map.next_stamp();
        let mut obs_count = [0u32; MAX_KEYFRAMES];
        for &s in local.iter() {
            let n = self.map.kf(s).features.len();
            for i in 0..n {
                let id = self.map.kf(s).landmark[i];
                if id == NO_LANDMARK || self.map.lm(id).local_stamp == pstamp {
                    continue;
                }
                self.map.lm_mut(id).local_stamp = pstamp;
                for o in self.map.lm(id).observations() {
                    obs_count[usize::from(o.kf)] += 1;
                }
            }
        }
        // Fixed keyframes: observers outside the local set, most observations first.
        let mut fixed: Vec<u8, MAX_WINDOW> = Vec::new();
        while local.len() + fixed.len() < MAX_WINDOW {
            let Some(s) = self.map.take_best(stamp, |s| obs_count[usize::from(s)]) else { break };
            let _ = fixed.push(s);
        }
        // No fixed keyframe (a young map): the oldest local keyframe anchors the gauge.
        if fixed.is_empty() {
            let oldest = (0..local.len()).min_by_key(|&k| self.map.kf(local[k]).id).unwrap_or(0);
            let s = local[oldest];
            local.retain(|&x| x != s);
            let _ = fixed.push(s);
        }
        if local.is_empty() {
            return 0;
        }
        for &s in local.iter().chain(fixed.iter()) {
            self.map.kf_mut(s).last_used = now;
        }
        // Pose index of each slot: fixed first.
        let mut pose_of = [NO_KF; MAX_KEYFRAMES];
        let mut poses = [Se3::identity(); MAX_WINDOW];
        let nposes = fixed.len() + local.len();
        for (k, &s) in fixed.iter().chain(local.iter()).enumerate() {
            pose_of[usize::from(s)] = k as u8;
            poses[k] = self.map.kf(s).t_cw;
        }
        // Compact point indices in landmark-id order.
        let mut npts = 0usize;
        for (id, l) in self.map.landmarks().iter().enumerate() {
            if l.alive && l.local_stamp == pstamp {
                self.lm_compact[id] = npts as u32;
                self.ba_ids[npts] = id as u32;
                self.ba_points[npts] = l.p_w;
                npts += 1;
            } else {
                self.lm_compact[id] = u32::MAX;
            }
        }
        // Observations keyed (point, pose, feature) so sorting groups them.
        self.ba_keys.clear();
        for c in 0..npts {
            let id = self.ba_ids[c];
            for o in self.map.lm(id).observations() {
                let p = pose_of[usize::from(o.kf)];
                if p == NO_KF {
                    continue;
                }
                let key = ((c as u64) << 32) | (u64::from(p) << 16) | u64::from(o.feat);
                if self.ba_keys.push(key).is_err() {
                    break;
                }
            }
        }
        self.ba_keys.sort_unstable();
        let mut slot_of = [0u8; MAX_WINDOW];
        for (k, &s) in fixed.iter().chain(local.iter()).enumerate() {
            slot_of[k] = s;
        }
        self.ba_obs.clear();
        for &key in self.ba_keys.iter() {
            let point = (key >> 32) as u32;
            let p = ((key >> 16) & 0xffff) as usize;
            let feat = (key & 0xffff) as usize;
            let kf = self.map.kf(slot_of[p]);
            let f = &kf.features[feat];
            let weight = f64::from(kf.weight[feat]);
            let _ = self.ba_obs.push(BaObs {
                kf: p as u8,
                point,
                z: measurement(f, params.far_m),
                weight,
            });
        }
        let ba_params = BaParams { iterations: params.ba_iterations, robust: true };
        let report = bundle_adjust(
            cam,
            &mut poses[..nposes],
            fixed.len(),
            &mut self.ba_points[..npts],
            &self.ba_obs,
            &mut self.ba_backup[..npts],
            &mut self.ba,
            &ba_params,
        );
        let Ok(report) = report else { return 0 };
        for (k, &s) in local.iter().enumerate() {
            self.map.kf_mut(s).t_cw = renormalize(&poses[fixed.len() + k]);
        }
        for c in 0..npts {
            let id = self.ba_ids[c];
            self.map.lm_mut(id).p_w = self.ba_points[c];
        }
        // Outlier observations leave the map.
        for k in 0..self.ba_obs.len() {
            let o = self.ba_obs[k];
            let pc = poses[usize::from(o.kf)].transform_point(&self.ba_points[o.point as usize]);
            let bad = match chi2(cam, &pc, &o.z) {
                Some(s) => s > o.z.chi2_threshold(),
                None => true,
            };
            if bad {
                let feat = (self.ba_keys[k] & 0xffff) as usize;
                self.map.remove_observation(slot_of[usize::from(o.kf)], feat);
            }
        }
        report.iterations
    }

    /// ORB-SLAM2's `MapPointCulling`: landmarks found in under a quarter of the frames that
    /// should have seen them go; so do recent ones (2–3 keyframes old) seen by one keyframe.
    fn cull_landmarks(&mut self) {
        let newest_id = self.map.newest().map(|k| k.id).unwrap_or(0);
        for id in 0..MAX_LANDMARKS as u32 {
            let l = self.map.lm(id);
            if !l.alive {
                continue;
            }
            let age = newest_id.saturating_sub(l.created_kf);
            let ratio_bad = l.visible >= 4 && (l.found as f32) < 0.25 * l.visible as f32;
            let recent_weak = (2..=3).contains(&age) && l.n_obs <= 1;
            if ratio_bad || recent_weak {
                self.map.remove_landmark(id);
            }
        }
    }

    /// ORB-SLAM2's `KeyFrameCulling`: a covisible keyframe (not the new one) whose close
    /// landmarks are ≥ 90 % observed by at least 3 other keyframes at the same or a finer
    /// scale is redundant and removed. Returns the number removed.
    fn cull_keyframes(&mut self, cam: &StereoCamera, params: &MappingParams, slot: u8) -> u32 {
        let th_close = params.close_depth_baselines * cam.baseline_m;
        let mut culled = 0u32;
        let neighbours = self.neighbours.clone();
        for &s in neighbours.iter() {
            if s == slot || !self.map.kf(s).alive || self.map.len() <= 2 {
                continue;
            }
            let kf = self.map.kf(s);
            let (mut total, mut redundant) = (0u32, 0u32);
            for (i, f) in kf.features.iter().enumerate() {
                let id = kf.landmark[i];
                if id == NO_LANDMARK {
                    continue;
                }
                if f.is_stereo() && f64::from(f.depth_m) > th_close {
                    continue;
                }
                total += 1;
                let l = self.map.lm(id);
                let others = l
                    .observations()
                    .iter()
                    .filter(|o| {
                        o.kf != s
                            && self.map.kf(o.kf).features[usize::from(o.feat)].level
                                <= f.level.saturating_add(1)
                    })
                    .count();
                if others >= 3 {
                    redundant += 1;
                }
            }
            if total > 0 && redundant as f32 > 0.9 * total as f32 {
                self.map.remove_keyframe(s);
                self.map.counters.keyframes_culled += 1;
                culled += 1;
            }
        }
        culled
    }
}

/// Pixel projection of a camera-frame point (no validity check: callers ensure `z > 0`).
#[inline]
fn proj(cam: &StereoCamera, p: &Vector3<f64>) -> (f64, f64) {
    (cam.fx_px * p.x / p.z + cam.cx_px, cam.fy_px * p.y / p.z + cam.cy_px)
}

/// Triangulates features `f1` (camera `t1`) and `f2` (camera `t2`) as ORB-SLAM2's
/// `CreateNewMapPoints` does: from the two rays when their parallax beats both stereo
/// parallaxes (and exceeds ~1.1° unless one side is stereo), else from the stereo point with
/// the larger stereo parallax; then depth, reprojection (χ² at 95 %) and scale checks.
fn triangulate_pair(
    cam: &StereoCamera,
    t1: &Se3,
    f1: &Feature,
    t2: &Se3,
    f2: &Feature,
    far_m: f32,
) -> Option<Vector3<f64>> {
    let ray = |t: &Se3, f: &Feature| {
        let r = Vector3::new(
            (f64::from(f.x) - cam.cx_px) / cam.fx_px,
            (f64::from(f.y) - cam.cy_px) / cam.fy_px,
            1.0,
        );
        t.rot.transpose() * r
    };
    let (r1, r2) = (ray(t1, f1), ray(t2, f2));
    let cos_rays = r1.dot(&r2) / (r1.norm() * r2.norm());
    let stereo_cos = |f: &Feature| {
        if f.is_stereo() {
            crate::math::cos(2.0 * crate::math::atan2(cam.baseline_m / 2.0, f64::from(f.depth_m)))
        } else {
            2.0
        }
    };
    let (cs1, cs2) = (stereo_cos(f1), stereo_cos(f2));
    let cos_stereo = cs1.min(cs2);
    let (c1, c2) = (t1.inverse().trans, t2.inverse().trans);
    let p = if cos_rays < cos_stereo
        && cos_rays > 0.0
        && (f1.is_stereo() || f2.is_stereo() || cos_rays < 0.9998)
    {
        // Midpoint of the closest approach of the two rays.
        let w0 = c1 - c2;
        let (a, b, c) = (r1.dot(&r1), r1.dot(&r2), r2.dot(&r2));
        let (d, e) = (r1.dot(&w0), r2.dot(&w0));
        let den = a * c - b * b;
        if crate::math::abs(den) < 1e-12 {
            return None;
        }
        let s = (b * e - c * d) / den;
        let u = (a * e - b * d) / den;
        ((c1 + r1 * s) + (c2 + r2 * u)) * 0.5
    } else if f1.is_stereo() && cs1 < cs2 {
        t1.inverse().transform_point(&cam.backproject(
            f64::from(f1.x),
            f64::from(f1.y),
            f64::from(f1.depth_m),
        ))
    } else if f2.is_stereo() && cs2 < cs1 {
        t2.inverse().transform_point(&cam.backproject(
            f64::from(f2.x),
            f64::from(f2.y),
            f64::from(f2.depth_m),
        ))
    } else {
        return None;
    };
    for (t, f) in [(t1, f1), (t2, f2)] {
        let pc = t.transform_point(&p);
        let z = measurement(f, far_m);
        let s = chi2(cam, &pc, &z)?;
        if s > z.chi2_threshold() {
            return None;
        }
    }
    let (dist1, dist2) = ((p - c1).norm(), (p - c2).norm());
    if dist1 < 1e-6 || dist2 < 1e-6 {
        return None;
    }
    let ratio_dist = dist2 / dist1;
    let ratio_octave = f64::from(level_scale(f1.level)) / f64::from(level_scale(f2.level));
    if ratio_dist * RATIO_FACTOR < ratio_octave || ratio_dist > ratio_octave * RATIO_FACTOR {
        return None;
    }
    Some(p)
}

/// Adds a keyframe observation's class to a landmark's histogram and keeps its semantic
/// descriptor (features without labels leave both unchanged).
fn note_semantics(l: &mut Landmark, f: &Feature, sem: Option<SemDesc>) {
    if usize::from(f.class) < NUM_CLASSES {
        let c = &mut l.class_hist[usize::from(f.class)];
        *c = c.saturating_add(1);
        if sem.is_some() {
            l.sem = sem;
        }
    }
}
