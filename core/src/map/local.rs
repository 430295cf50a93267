//! The local map of a frame, as ORB-SLAM2's `Tracking::UpdateLocalMap`: the keyframes that
//! observe the landmarks the frame matched (K1), their best covisible neighbours (K2), and
//! every landmark those keyframes observe. Tracking searches only these landmarks, so the map
//! can remember far more than one frame can see.
//!
//! Memory: the keyframe list and the landmark list (64 KiB at [`MAX_LANDMARKS`]).

use heapless::Vec;

use super::{Map, MAX_KEYFRAMES, MAX_LANDMARKS, NO_LANDMARK};

/// Keyframes a local map holds at most (ORB-SLAM2: 80).
pub const MAX_LOCAL_KEYFRAMES: usize = 40;
/// Covisible neighbours each K1 keyframe adds at most (ORB-SLAM2: 10).
const NEIGHBOURS_PER_KF: usize = 10;

/// A local map: keyframes and landmarks.
pub struct LocalSet {
    /// Local keyframe slots: K1 by shared landmarks (most first), then K2.
    pub kfs: Vec<u8, MAX_LOCAL_KEYFRAMES>,
    /// Landmark ids of the local keyframes (each once).
    pub lms: Vec<u32, MAX_LANDMARKS>,
    /// The keyframe sharing most landmarks with the frame (ORB-SLAM2's reference keyframe).
    pub reference: Option<u8>,
}

impl LocalSet {
    /// An empty set.
    pub const fn new() -> Self {
        Self { kfs: Vec::new(), lms: Vec::new(), reference: None }
    }

    /// Rebuilds the set around the landmarks in `seeds` (a frame's matches, [`NO_LANDMARK`]
    /// where none). With no usable seed it is the newest keyframe and its neighbours. Marks
    /// every local keyframe as used at frame `now` (the map's eviction order).
    pub fn update(&mut self, map: &mut Map, seeds: &[u32], now: u32) {
        self.kfs.clear();
        self.lms.clear();
        self.reference = None;
        let mut count = [0u32; MAX_KEYFRAMES];
        for &id in seeds {
            if id == NO_LANDMARK || !map.lm(id).alive {
                continue;
            }
            for o in map.lm(id).observations() {
                count[usize::from(o.kf)] += 1;
            }
        }
        let stamp = map.next_stamp();
        // K1 by count, most first (ties: newer first).
        while let Some(s) = map.take_best(stamp, |s| count[usize::from(s)]) {
            if self.kfs.push(s).is_err() {
                break;
            }
        }
        if self.kfs.is_empty() {
            if let Some(s) = map.newest_slot() {
                map.kf_mut(s).stamp = stamp;
                let _ = self.kfs.push(s);
            }
        }
        self.reference = self.kfs.first().copied();
        // K2: the best covisible neighbours of each K1 keyframe, in K1 order.
        let k1 = self.kfs.len();
        for i in 0..k1 {
            if self.kfs.is_full() {
                break;
            }
            let s = self.kfs[i];
            map.best_covisible(s, NEIGHBOURS_PER_KF, 1, stamp, &mut self.kfs);
        }
        for &s in self.kfs.iter() {
            map.kf_mut(s).last_used = now;
        }
        self.collect_landmarks(map);
    }

    fn collect_landmarks(&mut self, map: &mut Map) {
        let stamp = map.next_stamp();
        for k in 0..self.kfs.len() {
            let s = self.kfs[k];
            let n = map.kf(s).features.len();
            for i in 0..n {
                let id = map.kf(s).landmark[i];
                if id == NO_LANDMARK {
                    continue;
                }
                let l = map.lm_mut(id);
                if !l.alive || l.local_stamp == stamp {
                    continue;
                }
                l.local_stamp = stamp;
                // Cannot fail: every landmark is listed once and the capacity is the store's.
                let _ = self.lms.push(id);
            }
        }
    }
}

impl Default for LocalSet {
    fn default() -> Self {
        Self::new()
    }
}
