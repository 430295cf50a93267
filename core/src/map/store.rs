//! The persistent, bounded map: keyframes, landmarks with every observation, and the
//! covisibility graph (ORB-SLAM2's `Map`, `KeyFrame` and `MapPoint` in fixed memory).
//!
//! - [`MAX_KEYFRAMES`] keyframe slots. A keyframe keeps its features, its pose and, per
//!   feature, the landmark it observes and the association weight of that observation.
//! - [`MAX_LANDMARKS`] landmark slots (a free list recycles them). A landmark keeps the list
//!   of its observations (keyframe slot, feature) — up to [`MAX_OBS`]; when full, the
//!   observation from the oldest keyframe makes room (counted in [`MapCounters`]).
//! - The covisibility graph is a dense [`MAX_KEYFRAMES`]² matrix of shared-landmark counts,
//!   kept exact on every observation added or removed.
//!
//! A landmark dies with its last observation; a keyframe leaves by culling (redundant, decided
//! by local mapping) or, when the store is full, by eviction of the least recently used one
//! (the keyframe that has been out of every local map the longest: with no loop closing, the
//! map behind the car is never searched again). Every eviction is counted; nothing panics.
//!
//! Capacities: 64 keyframes × 2048 features. With keyframe culling the local map of KITTI
//! stereo holds 10–30 keyframes (covisibility ends after ~30–60 m of forward driving, when
//! the landmarks leave the view), so 64 keep every keyframe a local map can reach plus a
//! margin for standstill and slow turns; 16384 landmarks hold 64 keyframes' worth of
//! observed points at the ~250–600 landmarks per keyframe measured on KITTI.
//!
//! Memory: about 13 MiB (keyframes 8.4 MiB, landmarks 4.2 MiB, covisibility 8 KiB); the
//! tracker's memory test prints it.

use heapless::Vec;
use nalgebra::Vector3;

use crate::frame::{Descriptor, Feature, FRAME_CAPACITY};
use crate::geom::Se3;
use crate::seg::NUM_CLASSES;
use crate::semdesc::SemDesc;

/// Keyframe slots of the map.
pub const MAX_KEYFRAMES: usize = 64;
/// Landmark slots of the map.
pub const MAX_LANDMARKS: usize = 16384;
/// Observations one landmark keeps.
pub const MAX_OBS: usize = 16;
/// "No landmark" in a keyframe's feature-to-landmark table.
pub const NO_LANDMARK: u32 = u32::MAX;
/// "No keyframe" slot.
pub const NO_KF: u8 = u8::MAX;

const _: () = assert!(MAX_KEYFRAMES < NO_KF as usize);
const _: () = assert!(FRAME_CAPACITY <= u16::MAX as usize);

/// One observation of a landmark: feature `feat` of the keyframe in slot `kf`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Obs {
    /// Keyframe slot.
    pub kf: u8,
    /// Feature index in that keyframe.
    pub feat: u16,
}

/// A 3D point in the world with what is needed to find it again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landmark {
    /// Position in the world frame (m).
    pub p_w: Vector3<f64>,
    /// Descriptor of its latest keyframe observation (tracks appearance change).
    pub desc: Descriptor,
    /// Pyramid level of the latest keyframe observation.
    pub ref_level: u8,
    /// Camera-to-point distance at that observation (m): predicts the level it appears on.
    pub ref_dist_m: f32,
    /// Number of observations (`obs[..n_obs]`).
    pub n_obs: u8,
    /// The observations, oldest keyframe first.
    pub obs: [Obs; MAX_OBS],
    /// Keyframe id that created it.
    pub created_kf: u32,
    /// Frames in which it was predicted visible.
    pub visible: u32,
    /// Frames in which it was matched.
    pub found: u32,
    /// Frame index of the last time it was matched (avoids double matching in one frame).
    pub last_matched_frame: u32,
    /// Stamp of the last local map that listed it (de-duplicates the local landmark list).
    pub local_stamp: u32,
    /// Whether the slot is in use.
    pub alive: bool,
    /// Classes of its keyframe observations (counts, saturating): the class distribution the
    /// EM association's class term uses.
    pub class_hist: [u8; NUM_CLASSES],
    /// Semantic descriptor of its latest keyframe observation on a class boundary.
    pub sem: Option<SemDesc>,
    /// Accumulated evidence (log-odds, without the class prior) that the landmark's object
    /// moves, from the motion test ([`crate::motion`]); 0 when never tested.
    pub moving_lo: f32,
}

impl Landmark {
    const EMPTY: Landmark = Landmark {
        p_w: Vector3::new(0.0, 0.0, 0.0),
        desc: [0; 32],
        ref_level: 0,
        ref_dist_m: 0.0,
        n_obs: 0,
        obs: [Obs { kf: NO_KF, feat: 0 }; MAX_OBS],
        created_kf: 0,
        visible: 0,
        found: 0,
        last_matched_frame: u32::MAX,
        local_stamp: 0,
        alive: false,
        class_hist: [0; NUM_CLASSES],
        sem: None,
        moving_lo: 0.0,
    };

    /// The most frequent class of its keyframe observations (ties: the lowest id); `None`
    /// without class evidence (no labels).
    pub fn class(&self) -> Option<u8> {
        let best =
            self.class_hist.iter().enumerate().max_by_key(|&(i, &n)| (n, core::cmp::Reverse(i)));
        match best {
            Some((i, &n)) if n > 0 => Some(i as u8),
            _ => None,
        }
    }

    /// The observations.
    pub fn observations(&self) -> &[Obs] {
        &self.obs[..usize::from(self.n_obs)]
    }

    /// The feature of keyframe slot `kf` that observes it, if any.
    pub fn feature_in(&self, kf: u8) -> Option<usize> {
        self.observations().iter().find(|o| o.kf == kf).map(|o| usize::from(o.feat))
    }
}

/// A keyframe: a frame's features, its pose and which landmark each feature observes.
#[derive(Clone, Debug)]
pub struct KeyFrame {
    /// Monotonic keyframe id.
    pub id: u32,
    /// Index of the frame it was made from.
    pub frame_index: u32,
    /// Time (s) of that frame.
    pub timestamp_s: f64,
    /// World-to-camera pose.
    pub t_cw: Se3,
    /// The features.
    pub features: Vec<Feature, FRAME_CAPACITY>,
    /// Landmark observed by each feature, or [`NO_LANDMARK`].
    pub landmark: [u32; FRAME_CAPACITY],
    /// Association weight of each observation (1 for hard association, the E-step weight
    /// under EM), used by bundle adjustment.
    pub weight: [f32; FRAME_CAPACITY],
    /// Frame index of the last local map (tracking or mapping) it was part of: the eviction
    /// order when the store is full.
    pub last_used: u32,
    /// Scratch stamp for set membership in local-map and BA selection.
    pub stamp: u32,
    /// Whether the slot is in use.
    pub alive: bool,
}

impl KeyFrame {
    const fn empty() -> Self {
        Self {
            id: 0,
            frame_index: 0,
            timestamp_s: 0.0,
            t_cw: Se3::IDENTITY,
            features: Vec::new(),
            landmark: [NO_LANDMARK; FRAME_CAPACITY],
            weight: [1.0; FRAME_CAPACITY],
            last_used: 0,
            stamp: 0,
            alive: false,
        }
    }

    /// Landmarks observed (count of linked features).
    pub fn landmark_count(&self) -> usize {
        self.landmark[..self.features.len()].iter().filter(|&&l| l != NO_LANDMARK).count()
    }
}

/// What the map had to give up because a capacity was reached (never a panic).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MapCounters {
    /// Landmark creations refused because every slot was in use.
    pub landmark_overflow: u32,
    /// Keyframes evicted (least recently used) to make room.
    pub keyframe_evictions: u32,
    /// Observations dropped because a landmark's list was full.
    pub observation_overflow: u32,
    /// Keyframes removed as redundant by local mapping.
    pub keyframes_culled: u32,
    /// Landmarks merged into another by fusion.
    pub landmarks_fused: u32,
}

/// The map. See the module documentation.
pub struct Map {
    kfs: [KeyFrame; MAX_KEYFRAMES],
    /// Live keyframe slots, oldest (smallest id) first.
    live: Vec<u8, MAX_KEYFRAMES>,
    next_kf_id: u32,
    lms: [Landmark; MAX_LANDMARKS],
    free: Vec<u32, MAX_LANDMARKS>,
    covis: [[u16; MAX_KEYFRAMES]; MAX_KEYFRAMES],
    stamp: u32,
    /// What capacity limits cost so far.
    pub counters: MapCounters,
}

impl Map {
    /// An empty map. `const` so it can live in a `static` on the target; call
    /// [`Map::clear`] before use.
    pub const fn new() -> Self {
        const KF: KeyFrame = KeyFrame::empty();
        Self {
            kfs: [KF; MAX_KEYFRAMES],
            live: Vec::new(),
            next_kf_id: 0,
            lms: [Landmark::EMPTY; MAX_LANDMARKS],
            free: Vec::new(),
            covis: [[0; MAX_KEYFRAMES]; MAX_KEYFRAMES],
            stamp: 0,
            counters: MapCounters {
                landmark_overflow: 0,
                keyframe_evictions: 0,
                observation_overflow: 0,
                keyframes_culled: 0,
                landmarks_fused: 0,
            },
        }
    }

    /// Empties the map (keeps the keyframe id counter and the counters running).
    pub fn clear(&mut self) {
        self.live.clear();
        for k in self.kfs.iter_mut() {
            k.alive = false;
        }
        for l in self.lms.iter_mut() {
            l.alive = false;
            l.n_obs = 0;
        }
        for row in self.covis.iter_mut() {
            row.fill(0);
        }
        self.free.clear();
        // Push in reverse so slot 0 is handed out first: fixed, reproducible slot order.
        for i in (0..MAX_LANDMARKS as u32).rev() {
            // Cannot fail: capacity equals the number of slots.
            let _ = self.free.push(i);
        }
    }

    /// A fresh stamp for set membership (keyframe `stamp`, landmark `local_stamp`).
    pub fn next_stamp(&mut self) -> u32 {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // Wrapped: old stamps could collide with new ones, so reset them all.
            for k in self.kfs.iter_mut() {
                k.stamp = 0;
            }
            for l in self.lms.iter_mut() {
                l.local_stamp = 0;
            }
            self.stamp = 1;
        }
        self.stamp
    }

    /// Number of keyframes.
    pub fn len(&self) -> usize {
        self.live.len()
    }

    /// Whether there are no keyframes.
    pub fn is_empty(&self) -> bool {
        self.live.is_empty()
    }

    /// Live keyframe slots, oldest first.
    pub fn keyframe_slots(&self) -> &[u8] {
        &self.live
    }

    /// Live landmark count.
    pub fn landmark_count(&self) -> usize {
        MAX_LANDMARKS - self.free.len()
    }

    /// Free landmark slots.
    pub fn free_landmarks(&self) -> usize {
        self.free.len()
    }

    /// The keyframe in `slot`.
    pub fn kf(&self, slot: u8) -> &KeyFrame {
        &self.kfs[usize::from(slot)]
    }

    /// The keyframe in `slot`, mutable.
    pub fn kf_mut(&mut self, slot: u8) -> &mut KeyFrame {
        &mut self.kfs[usize::from(slot)]
    }

    /// The newest keyframe's slot.
    pub fn newest_slot(&self) -> Option<u8> {
        self.live.last().copied()
    }

    /// The newest keyframe.
    pub fn newest(&self) -> Option<&KeyFrame> {
        self.newest_slot().map(|s| self.kf(s))
    }

    /// A landmark by id.
    pub fn lm(&self, id: u32) -> &Landmark {
        &self.lms[id as usize]
    }

    /// A mutable landmark by id.
    pub fn lm_mut(&mut self, id: u32) -> &mut Landmark {
        &mut self.lms[id as usize]
    }

    /// All landmark slots (check `alive`).
    pub fn landmarks(&self) -> &[Landmark] {
        &self.lms
    }

    /// Shared landmarks of keyframe slots `a` and `b` (the covisibility edge weight).
    pub fn covisibility(&self, a: u8, b: u8) -> u16 {
        self.covis[usize::from(a)][usize::from(b)]
    }

    /// The up to `n` keyframes sharing most landmarks with `slot` (at least `min_weight`),
    /// best first (ties: newer first), appended to `out` unless already stamped `stamp`; each
    /// one added is stamped. Returns how many were added.
    pub fn best_covisible<const N: usize>(
        &mut self,
        slot: u8,
        n: usize,
        min_weight: u16,
        stamp: u32,
        out: &mut Vec<u8, N>,
    ) -> usize {
        let mut added = 0;
        let row = self.covis[usize::from(slot)];
        let min = u32::from(min_weight.max(1));
        while added < n && !out.is_full() {
            let score = |s: u8| {
                let w = u32::from(row[usize::from(s)]);
                if s == slot || w < min {
                    0
                } else {
                    w
                }
            };
            let Some(s) = self.take_best(stamp, score) else { break };
            let _ = out.push(s);
            added += 1;
        }
        added
    }

    /// The live keyframe not yet stamped `stamp` with the highest positive `score` (ties:
    /// newer first), stamped; `None` when every score is 0. Repeated calls list keyframes best
    /// first: a selection by repeated maximum, cheap at this map's keyframe count.
    pub fn take_best(&mut self, stamp: u32, score: impl Fn(u8) -> u32) -> Option<u8> {
        let mut best: Option<(u32, u32, u8)> = None;
        for &s in self.live.iter() {
            let c = score(s);
            let k = &self.kfs[usize::from(s)];
            if c == 0 || k.stamp == stamp {
                continue;
            }
            if best.is_none_or(|(bc, bid, _)| (c, k.id) > (bc, bid)) {
                best = Some((c, k.id, s));
            }
        }
        let (_, _, s) = best?;
        self.kfs[usize::from(s)].stamp = stamp;
        Some(s)
    }

    /// Appends a keyframe made of `features` at `t_cw`; when every slot is taken the least
    /// recently used keyframe (never one used at `now` or later) is evicted first. Returns its
    /// slot, or `None` when nothing could be evicted (every keyframe in use at `now`).
    pub fn push_keyframe(
        &mut self,
        frame_index: u32,
        t_cw: Se3,
        features: &[Feature],
        now: u32,
    ) -> Option<u8> {
        if self.live.is_full() && !self.evict_lru(now) {
            return None;
        }
        let slot = (0..MAX_KEYFRAMES).find(|&s| !self.kfs[s].alive)? as u8;
        let kf = &mut self.kfs[usize::from(slot)];
        kf.id = self.next_kf_id;
        kf.frame_index = frame_index;
        kf.t_cw = t_cw;
        kf.features.clear();
        let n = features.len().min(FRAME_CAPACITY);
        // Cannot fail: n ≤ capacity.
        let _ = kf.features.extend_from_slice(&features[..n]);
        kf.landmark.fill(NO_LANDMARK);
        kf.weight.fill(1.0);
        kf.last_used = now;
        kf.stamp = 0;
        kf.alive = true;
        self.next_kf_id += 1;
        // Cannot fail: a free slot was found, so fewer than MAX_KEYFRAMES are live.
        let _ = self.live.push(slot);
        Some(slot)
    }

    /// Evicts the least recently used keyframe that was not used at `now` (ties: the oldest).
    /// Returns whether one was evicted.
    pub fn evict_lru(&mut self, now: u32) -> bool {
        let mut victim: Option<(u32, u32, u8)> = None;
        for &s in self.live.iter() {
            let k = &self.kfs[usize::from(s)];
            if k.last_used >= now {
                continue;
            }
            if victim.is_none_or(|(lu, id, _)| (k.last_used, k.id) < (lu, id)) {
                victim = Some((k.last_used, k.id, s));
            }
        }
        let Some((_, _, s)) = victim else { return false };
        self.remove_keyframe(s);
        self.counters.keyframe_evictions += 1;
        true
    }

    /// Removes the keyframe in `slot` and all its observations (landmarks nobody else sees die).
    pub fn remove_keyframe(&mut self, slot: u8) {
        let s = usize::from(slot);
        if !self.kfs[s].alive {
            return;
        }
        for i in 0..self.kfs[s].features.len() {
            self.remove_observation(slot, i);
        }
        self.kfs[s].alive = false;
        self.live.retain(|&x| x != slot);
        // Already zero if every observation went through remove_observation; cleared anyway.
        for k in 0..MAX_KEYFRAMES {
            self.covis[s][k] = 0;
            self.covis[k][s] = 0;
        }
    }

    /// Creates a landmark; `None` (and a counted overflow) when the store is full.
    pub fn new_landmark(
        &mut self,
        p_w: Vector3<f64>,
        desc: Descriptor,
        level: u8,
        dist_m: f32,
    ) -> Option<u32> {
        let Some(id) = self.free.pop() else {
            self.counters.landmark_overflow += 1;
            return None;
        };
        let kf_id = self.next_kf_id.saturating_sub(1);
        self.lms[id as usize] = Landmark {
            p_w,
            desc,
            ref_level: level,
            ref_dist_m: dist_m,
            created_kf: kf_id,
            visible: 1,
            found: 1,
            alive: true,
            ..Landmark::EMPTY
        };
        Some(id)
    }

    /// Links feature `feat` of keyframe `slot` to landmark `id` (replacing the feature's
    /// previous landmark, and the landmark's previous observation in that keyframe). A full
    /// observation list drops its oldest keyframe's observation (counted).
    pub fn add_observation(&mut self, slot: u8, feat: usize, id: u32) {
        let s = usize::from(slot);
        if !self.kfs[s].alive || feat >= self.kfs[s].features.len() || !self.lms[id as usize].alive
        {
            return;
        }
        let old = self.kfs[s].landmark[feat];
        if old == id {
            return;
        }
        if old != NO_LANDMARK {
            self.remove_observation(slot, feat);
        }
        // One observation per keyframe and landmark.
        if let Some(f) = self.lms[id as usize].feature_in(slot) {
            self.remove_observation(slot, f);
            if !self.lms[id as usize].alive {
                return;
            }
        }
        if usize::from(self.lms[id as usize].n_obs) == MAX_OBS {
            let oldest = self.oldest_observation(id);
            self.remove_observation(oldest.kf, usize::from(oldest.feat));
            self.counters.observation_overflow += 1;
            if !self.lms[id as usize].alive {
                return;
            }
        }
        let l = &mut self.lms[id as usize];
        for o in &l.obs[..usize::from(l.n_obs)] {
            let k = usize::from(o.kf);
            self.covis[s][k] = self.covis[s][k].saturating_add(1);
            self.covis[k][s] = self.covis[k][s].saturating_add(1);
        }
        l.obs[usize::from(l.n_obs)] = Obs { kf: slot, feat: feat as u16 };
        l.n_obs += 1;
        self.kfs[s].landmark[feat] = id;
    }

    fn oldest_observation(&self, id: u32) -> Obs {
        let l = &self.lms[id as usize];
        let mut best = l.obs[0];
        for o in l.observations() {
            if self.kfs[usize::from(o.kf)].id < self.kfs[usize::from(best.kf)].id {
                best = *o;
            }
        }
        best
    }

    /// Unlinks feature `feat` of keyframe `slot` from its landmark; the landmark dies with its
    /// last observation.
    pub fn remove_observation(&mut self, slot: u8, feat: usize) {
        let s = usize::from(slot);
        if feat >= self.kfs[s].features.len() {
            return;
        }
        let id = self.kfs[s].landmark[feat];
        if id == NO_LANDMARK {
            return;
        }
        self.kfs[s].landmark[feat] = NO_LANDMARK;
        let l = &mut self.lms[id as usize];
        let n = usize::from(l.n_obs);
        let Some(pos) = l.obs[..n].iter().position(|o| o.kf == slot) else { return };
        l.obs.copy_within(pos + 1..n, pos);
        l.n_obs -= 1;
        for o in &l.obs[..n - 1] {
            let k = usize::from(o.kf);
            self.covis[s][k] = self.covis[s][k].saturating_sub(1);
            self.covis[k][s] = self.covis[k][s].saturating_sub(1);
        }
        if l.n_obs == 0 && l.alive {
            l.alive = false;
            // Cannot fail: a live id is never in the free list.
            let _ = self.free.push(id);
        }
    }

    /// Removes a landmark and every observation of it.
    pub fn remove_landmark(&mut self, id: u32) {
        while self.lms[id as usize].alive && self.lms[id as usize].n_obs > 0 {
            let o = self.lms[id as usize].obs[0];
            self.remove_observation(o.kf, usize::from(o.feat));
        }
        let l = &mut self.lms[id as usize];
        if l.alive {
            // A landmark without observations (only possible right after creation).
            l.alive = false;
            let _ = self.free.push(id);
        }
    }

    /// Fusion: every observation of `from` moves to `into` (where `into` is not already
    /// observed in that keyframe), then `from` is removed. Counted.
    pub fn merge_landmark(&mut self, from: u32, into: u32) {
        if from == into || !self.lms[from as usize].alive || !self.lms[into as usize].alive {
            return;
        }
        let l = self.lms[from as usize];
        for o in l.observations() {
            let feat = usize::from(o.feat);
            let weight = self.kfs[usize::from(o.kf)].weight[feat];
            self.remove_observation(o.kf, feat);
            if self.lms[into as usize].feature_in(o.kf).is_none() {
                self.add_observation(o.kf, feat, into);
                self.kfs[usize::from(o.kf)].weight[feat] = weight;
            }
        }
        let into_l = &mut self.lms[into as usize];
        into_l.visible = into_l.visible.saturating_add(l.visible);
        into_l.found = into_l.found.saturating_add(l.found);
        for (a, b) in into_l.class_hist.iter_mut().zip(l.class_hist.iter()) {
            *a = a.saturating_add(*b);
        }
        // Two views of one point: the stronger motion evidence either way wins.
        if l.moving_lo.abs() > into_l.moving_lo.abs() {
            into_l.moving_lo = l.moving_lo;
        }
        self.remove_landmark(from);
        self.counters.landmarks_fused += 1;
    }
}

impl Default for Map {
    fn default() -> Self {
        let mut m = Self::new();
        m.clear();
        m
    }
}

#[cfg(test)]
mod tests;
