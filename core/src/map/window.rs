//! The bounded sliding window: keyframes and the landmarks they observe.
//!
//! Capacity is fixed at compile time: [`MAX_KEYFRAMES`] keyframes (oldest evicted first) and
//! [`MAX_LANDMARKS`] landmarks (a free list recycles slots). A landmark lives while at least
//! one window keyframe observes it; evicting a keyframe drops its observations and frees the
//! landmarks nobody else sees. Observations are stored once, on the keyframe side
//! (`KeyFrame::landmark[i]` for feature `i`), so there is no per-landmark list to overflow.
//!
//! Memory: 2.6 MiB, keyframes (10 × 2048 features) and landmarks (8192) together, as the
//! tracker's memory test prints it.

use heapless::Vec;
use nalgebra::Vector3;

use crate::frame::{Descriptor, Feature, FRAME_CAPACITY};
use crate::geom::Se3;
use crate::optim::MAX_WINDOW;
use crate::seg::NUM_CLASSES;
use crate::semdesc::SemDesc;

/// Keyframes in the window (the BA window is the whole window).
pub const MAX_KEYFRAMES: usize = MAX_WINDOW;
/// Landmarks the window can hold.
pub const MAX_LANDMARKS: usize = 8192;
/// "No landmark" in a keyframe's feature-to-landmark table.
pub const NO_LANDMARK: u32 = u32::MAX;

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
    /// Window keyframes that observe it.
    pub n_obs: u8,
    /// Keyframe id that created it.
    pub created_kf: u32,
    /// Frames in which it was predicted visible.
    pub visible: u32,
    /// Frames in which it was matched.
    pub found: u32,
    /// Frame index of the last time it was matched (avoids double matching in one frame).
    pub last_matched_frame: u32,
    /// Whether the slot is in use.
    pub alive: bool,
    /// Classes of its keyframe observations (counts, saturating): the class distribution the
    /// EM association's class term uses.
    pub class_hist: [u8; NUM_CLASSES],
    /// Semantic descriptor of its latest keyframe observation on a class boundary.
    pub sem: Option<SemDesc>,
}

impl Landmark {
    const EMPTY: Landmark = Landmark {
        p_w: Vector3::new(0.0, 0.0, 0.0),
        desc: [0; 32],
        ref_level: 0,
        ref_dist_m: 0.0,
        n_obs: 0,
        created_kf: 0,
        visible: 0,
        found: 0,
        last_matched_frame: u32::MAX,
        alive: false,
        class_hist: [0; NUM_CLASSES],
        sem: None,
    };
}

/// A keyframe: a frame's features, its pose and which landmark each feature observes.
#[derive(Clone, Debug)]
pub struct KeyFrame {
    /// Monotonic keyframe id.
    pub id: u32,
    /// Index of the frame it was made from.
    pub frame_index: u32,
    /// World-to-camera pose.
    pub t_cw: Se3,
    /// The features.
    pub features: Vec<Feature, FRAME_CAPACITY>,
    /// Landmark observed by each feature, or [`NO_LANDMARK`].
    pub landmark: [u32; FRAME_CAPACITY],
    /// Association weight of each observation (1 for hard association, the E-step weight
    /// under EM), used by bundle adjustment.
    pub weight: [f32; FRAME_CAPACITY],
}

impl KeyFrame {
    const fn empty() -> Self {
        Self {
            id: 0,
            frame_index: 0,
            t_cw: Se3::IDENTITY,
            features: Vec::new(),
            landmark: [NO_LANDMARK; FRAME_CAPACITY],
            weight: [1.0; FRAME_CAPACITY],
        }
    }
}

/// The sliding window.
pub struct Window {
    /// Keyframe slots; `order[..len]` lists the live ones oldest first.
    kfs: [KeyFrame; MAX_KEYFRAMES],
    order: [u8; MAX_KEYFRAMES],
    len: usize,
    next_kf_id: u32,
    lms: [Landmark; MAX_LANDMARKS],
    free: Vec<u32, MAX_LANDMARKS>,
    /// Landmark creations refused because the store was full.
    pub landmark_overflow: u32,
}

impl Window {
    /// An empty window. `const` so it can live in a `static` on the target.
    pub const fn new() -> Self {
        const KF: KeyFrame = KeyFrame::empty();
        Self {
            kfs: [KF; MAX_KEYFRAMES],
            order: [0; MAX_KEYFRAMES],
            len: 0,
            next_kf_id: 0,
            lms: [Landmark::EMPTY; MAX_LANDMARKS],
            free: Vec::new(),
            landmark_overflow: 0,
        }
    }

    /// Empties the window (keeps the keyframe id counter running).
    pub fn clear(&mut self) {
        self.len = 0;
        for l in self.lms.iter_mut() {
            l.alive = false;
        }
        self.free.clear();
        // Push in reverse so slot 0 is handed out first: fixed, reproducible slot order.
        for i in (0..MAX_LANDMARKS as u32).rev() {
            // Cannot fail: capacity equals the number of slots.
            let _ = self.free.push(i);
        }
    }

    /// Number of keyframes.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no keyframes.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Live landmark count.
    pub fn landmark_count(&self) -> usize {
        MAX_LANDMARKS - self.free.len()
    }

    /// The `i`-th keyframe, oldest first.
    pub fn kf(&self, i: usize) -> &KeyFrame {
        &self.kfs[usize::from(self.order[i])]
    }

    /// Mutable `i`-th keyframe, oldest first.
    pub fn kf_mut(&mut self, i: usize) -> &mut KeyFrame {
        &mut self.kfs[usize::from(self.order[i])]
    }

    /// The newest keyframe.
    pub fn newest(&self) -> Option<&KeyFrame> {
        self.len.checked_sub(1).map(|i| self.kf(i))
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

    /// All landmark slots, mutable.
    pub fn landmarks_mut(&mut self) -> &mut [Landmark] {
        &mut self.lms
    }

    /// Appends a keyframe made of `features` at `t_cw`, evicting the oldest if the window is
    /// full. Returns its position (always the last). Feature-to-landmark links start empty.
    pub fn push_keyframe(&mut self, frame_index: u32, t_cw: Se3, features: &[Feature]) -> usize {
        if self.len == MAX_KEYFRAMES {
            self.evict_oldest();
        }
        // A free slot: the one not listed in order[..len].
        let mut used = [false; MAX_KEYFRAMES];
        for &o in &self.order[..self.len] {
            used[usize::from(o)] = true;
        }
        let slot = used.iter().position(|u| !u).unwrap_or(0);
        let kf = &mut self.kfs[slot];
        kf.id = self.next_kf_id;
        kf.frame_index = frame_index;
        kf.t_cw = t_cw;
        kf.features.clear();
        let n = features.len().min(FRAME_CAPACITY);
        // Cannot fail: n ≤ capacity.
        let _ = kf.features.extend_from_slice(&features[..n]);
        kf.landmark.fill(NO_LANDMARK);
        kf.weight.fill(1.0);
        self.next_kf_id += 1;
        self.order[self.len] = slot as u8;
        self.len += 1;
        self.len - 1
    }

    /// Removes the oldest keyframe, dropping its observations.
    pub fn evict_oldest(&mut self) {
        if self.len == 0 {
            return;
        }
        let slot = usize::from(self.order[0]);
        for i in 0..self.kfs[slot].features.len() {
            let id = self.kfs[slot].landmark[i];
            if id != NO_LANDMARK {
                self.kfs[slot].landmark[i] = NO_LANDMARK;
                self.release_observation(id);
            }
        }
        self.order.copy_within(1..self.len, 0);
        self.len -= 1;
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
            self.landmark_overflow += 1;
            return None;
        };
        let kf_id = self.next_kf_id.saturating_sub(1);
        self.lms[id as usize] = Landmark {
            p_w,
            desc,
            ref_level: level,
            ref_dist_m: dist_m,
            n_obs: 0,
            created_kf: kf_id,
            visible: 1,
            found: 1,
            last_matched_frame: u32::MAX,
            alive: true,
            class_hist: [0; NUM_CLASSES],
            sem: None,
        };
        Some(id)
    }

    /// Links feature `feat` of the keyframe at position `pos` to landmark `id`.
    pub fn add_observation(&mut self, pos: usize, feat: usize, id: u32) {
        let slot = usize::from(self.order[pos]);
        if feat >= self.kfs[slot].features.len() || !self.lms[id as usize].alive {
            return;
        }
        let old = self.kfs[slot].landmark[feat];
        if old == id {
            return;
        }
        if old != NO_LANDMARK {
            self.release_observation(old);
        }
        self.kfs[slot].landmark[feat] = id;
        let l = &mut self.lms[id as usize];
        l.n_obs = l.n_obs.saturating_add(1);
    }

    /// Unlinks feature `feat` of the keyframe at position `pos` from its landmark.
    pub fn remove_observation(&mut self, pos: usize, feat: usize) {
        let slot = usize::from(self.order[pos]);
        if feat >= self.kfs[slot].features.len() {
            return;
        }
        let id = self.kfs[slot].landmark[feat];
        if id != NO_LANDMARK {
            self.kfs[slot].landmark[feat] = NO_LANDMARK;
            self.release_observation(id);
        }
    }

    /// Removes a landmark and every observation of it.
    pub fn remove_landmark(&mut self, id: u32) {
        if !self.lms[id as usize].alive {
            return;
        }
        for p in 0..self.len {
            let slot = usize::from(self.order[p]);
            let kf = &mut self.kfs[slot];
            let n = kf.features.len();
            for l in kf.landmark[..n].iter_mut() {
                if *l == id {
                    *l = NO_LANDMARK;
                }
            }
        }
        self.lms[id as usize].alive = false;
        self.lms[id as usize].n_obs = 0;
        // Cannot fail: a live id is never in the free list.
        let _ = self.free.push(id);
    }

    fn release_observation(&mut self, id: u32) {
        let l = &mut self.lms[id as usize];
        l.n_obs = l.n_obs.saturating_sub(1);
        if l.n_obs == 0 && l.alive {
            l.alive = false;
            let _ = self.free.push(id);
        }
    }
}

impl Default for Window {
    fn default() -> Self {
        let mut w = Self::new();
        w.clear();
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feats(n: usize) -> std::vec::Vec<Feature> {
        (0..n)
            .map(|i| Feature {
                x: i as f32,
                y: 0.0,
                level: 0,
                angle: 0.0,
                desc: [i as u8; 32],
                ur: -1.0,
                depth_m: 0.0,
                class: crate::seg::VOID,
            })
            .collect()
    }

    /// The window is ~2 MiB: tests build it on a thread with room for it.
    fn big_stack<F: FnOnce() + Send + 'static>(f: F) {
        std::thread::Builder::new().stack_size(32 << 20).spawn(f).unwrap().join().unwrap();
    }

    #[test]
    fn landmarks_die_with_their_last_observer() {
        big_stack(landmarks_die_with_their_last_observer_body);
    }

    fn landmarks_die_with_their_last_observer_body() {
        let mut w = Box::new(Window::new());
        w.clear();
        let f = feats(4);
        let a = w.push_keyframe(0, Se3::identity(), &f);
        let l0 = w.new_landmark(Vector3::new(0.0, 0.0, 5.0), [0; 32], 0, 5.0).unwrap();
        let l1 = w.new_landmark(Vector3::new(1.0, 0.0, 5.0), [1; 32], 0, 5.0).unwrap();
        w.add_observation(a, 0, l0);
        w.add_observation(a, 1, l1);
        let b = w.push_keyframe(1, Se3::identity(), &f);
        w.add_observation(b, 2, l1);
        assert_eq!(w.landmark_count(), 2);
        w.evict_oldest();
        assert_eq!(w.len(), 1);
        assert!(!w.lm(l0).alive, "only the evicted keyframe saw l0");
        assert!(w.lm(l1).alive);
        assert_eq!(w.lm(l1).n_obs, 1);
        assert_eq!(w.landmark_count(), 1);
    }

    #[test]
    fn window_evicts_oldest_when_full() {
        big_stack(window_evicts_oldest_when_full_body);
    }

    fn window_evicts_oldest_when_full_body() {
        let mut w = Box::new(Window::new());
        w.clear();
        let f = feats(2);
        for i in 0..(MAX_KEYFRAMES as u32 + 3) {
            w.push_keyframe(i, Se3::identity(), &f);
        }
        assert_eq!(w.len(), MAX_KEYFRAMES);
        assert_eq!(w.kf(0).frame_index, 3);
        assert_eq!(w.newest().unwrap().frame_index, MAX_KEYFRAMES as u32 + 2);
    }

    #[test]
    fn landmark_store_overflow_is_counted() {
        big_stack(landmark_store_overflow_is_counted_body);
    }

    fn landmark_store_overflow_is_counted_body() {
        let mut w = Box::new(Window::new());
        w.clear();
        for _ in 0..MAX_LANDMARKS {
            assert!(w.new_landmark(Vector3::zeros(), [0; 32], 0, 1.0).is_some());
        }
        assert!(w.new_landmark(Vector3::zeros(), [0; 32], 0, 1.0).is_none());
        assert_eq!(w.landmark_overflow, 1);
        w.remove_landmark(5);
        assert_eq!(w.new_landmark(Vector3::zeros(), [0; 32], 0, 1.0), Some(5));
    }
}
