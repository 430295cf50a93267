//! Data association: which window landmark each feature of a frame observes, and the
//! motion-only pose problem those associations pose.
//!
//! Two ways, chosen by [`Association`]:
//! - `hard` — nearest neighbour (ORB-SLAM2's `SearchByProjection`): each window landmark is
//!   projected at the current pose estimate and matched to the feature nearest in descriptor
//!   space within a radius, a pyramid-level window and a best/second-best ratio. The final
//!   pass also gathers every gated candidate of each feature for EM.
//! - [`em`] — the paper's probabilistic association (§3.3, Eqs. 3–9, after Bowman et al.
//!   2017): E-step weights over each feature's gated candidates, weighted M-steps on the pose,
//!   then a decision per feature.
//!
//! Both end in the same pose solve (`PoseProblem::solve`: optimise, re-orthonormalise,
//! classify outliers) and hand the tracker one landmark and one weight per feature.
//! [`annotate`] labels a frame's features for EM's class and semantic terms.
//!
//! Memory: the per-feature candidates and landmark claims of EM (`EmScratch`, 0.11 MiB), the
//! projection search's feature grid (15 KiB) and the pose problem (0.52 MiB: up to
//! [`MAX_CANDIDATES`] pairs per feature), all owned by the tracker.

pub mod em;
pub(crate) mod hard;

pub use em::{class_log_likelihood, normalise, semantic_log_likelihood, ClassTerm, EmParams};
pub(crate) use em::{EmInput, EmScratch};
pub(crate) use hard::{FeatureGrid, ProjectionSearch, SearchQuery, LN_SCALE};

use heapless::Vec;

use crate::frame::{Feature, Frame, FRAME_CAPACITY};
use crate::geom::{Se3, StereoCamera};
use crate::image::ImageView;
use crate::map::{measurement, renormalize, Map, NO_LANDMARK};
use crate::math;
use crate::optim::{chi2, optimize_pose, PoseObs, PoseOptParams, PoseOptReport};
use crate::seg::VOID;
use crate::semdesc;

/// Candidate landmarks kept per feature.
pub const MAX_CANDIDATES: usize = 4;

/// How features are associated with landmarks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum Association {
    /// Nearest neighbour in descriptor space within the projection gate (ORB-SLAM2).
    Hard,
    /// EM over gated candidates (the paper's method).
    Em,
}

/// A gated candidate: landmark id and ORB Hamming distance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Candidate {
    /// Landmark id.
    pub lm: u32,
    /// ORB Hamming distance between the feature and the landmark.
    pub hamming: u32,
}

/// Up to [`MAX_CANDIDATES`] candidates of one feature, best (smallest Hamming) first.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Candidates {
    items: [Option<Candidate>; MAX_CANDIDATES],
}

impl Candidates {
    /// No candidates.
    pub const EMPTY: Candidates = Candidates { items: [None; MAX_CANDIDATES] };

    /// Inserts `c`, keeping the best [`MAX_CANDIDATES`] by Hamming distance (ties: earlier
    /// first, so the result does not depend on anything but insertion order).
    pub fn insert(&mut self, c: Candidate) {
        let mut pos = MAX_CANDIDATES;
        for (i, it) in self.items.iter().enumerate() {
            match it {
                None => {
                    pos = i;
                    break;
                }
                Some(o) if c.hamming < o.hamming => {
                    pos = i;
                    break;
                }
                _ => {}
            }
        }
        if pos == MAX_CANDIDATES {
            return;
        }
        self.items.copy_within(pos..MAX_CANDIDATES - 1, pos + 1);
        self.items[pos] = Some(c);
    }

    /// The candidates, best first.
    pub fn iter(&self) -> impl Iterator<Item = &Candidate> {
        self.items.iter().flatten()
    }

    /// Number of candidates.
    pub fn len(&self) -> usize {
        self.iter().count()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.items[0].is_none()
    }
}

/// Most (feature, candidate) pairs one pose problem holds.
pub(crate) const MAX_PAIRS: usize = FRAME_CAPACITY * MAX_CANDIDATES;

/// One frame's associations: per feature, its landmark ([`NO_LANDMARK`] if none) and the
/// association weight (1 for nearest neighbour, the E-step weight under EM).
pub(crate) struct Matches {
    /// Landmark of each feature.
    pub lm: [u32; FRAME_CAPACITY],
    /// Association weight of each feature.
    pub weight: [f32; FRAME_CAPACITY],
}

impl Matches {
    /// No associations.
    pub const fn new() -> Self {
        Self { lm: [NO_LANDMARK; FRAME_CAPACITY], weight: [1.0; FRAME_CAPACITY] }
    }

    /// Number of the first `n` features that have a landmark.
    pub fn count(&self, n: usize) -> u32 {
        self.lm[..n].iter().filter(|&&l| l != NO_LANDMARK).count() as u32
    }

    /// Unlinks feature `j` from its landmark.
    pub fn unlink(&mut self, j: usize) {
        self.lm[j] = NO_LANDMARK;
        self.weight[j] = 0.0;
    }
}

/// The motion-only pose problem of one frame: weighted observations, the feature each came
/// from and, after a solve, which are outliers.
pub(crate) struct PoseProblem {
    /// Stereo points beyond this depth (m) are monocular measurements.
    pub far_m: f32,
    obs: Vec<PoseObs, MAX_PAIRS>,
    feat: [u16; MAX_PAIRS],
    outlier: [bool; MAX_PAIRS],
}

impl PoseProblem {
    /// An empty problem.
    pub const fn new() -> Self {
        Self {
            far_m: f32::INFINITY,
            obs: Vec::new(),
            feat: [0; MAX_PAIRS],
            outlier: [false; MAX_PAIRS],
        }
    }

    /// Removes every observation.
    pub fn clear(&mut self) {
        self.obs.clear();
    }

    /// Adds `obs` of feature `feat`; false when the problem is full.
    pub fn push(&mut self, obs: PoseObs, feat: usize) -> bool {
        let k = self.obs.len();
        if self.obs.push(obs).is_err() {
            return false;
        }
        self.feat[k] = feat as u16;
        true
    }

    /// Refills the problem with every feature's current match, weight 1 or, with
    /// `em_weights`, the association weight; returns how many.
    pub fn collect(
        &mut self,
        window: &Map,
        feats: &[Feature],
        matches: &Matches,
        em_weights: bool,
    ) -> usize {
        self.clear();
        for (j, f) in feats.iter().enumerate() {
            let id = matches.lm[j];
            if id == NO_LANDMARK {
                continue;
            }
            let weight = if em_weights { f64::from(matches.weight[j]) } else { 1.0 };
            let obs = PoseObs { p_w: window.lm(id).p_w, z: measurement(f, self.far_m), weight };
            if !self.push(obs, j) {
                break;
            }
        }
        self.obs.len()
    }

    /// The one pose solve of tracking and EM: optimises `t_cw` against the observations
    /// (all starting as inliers or, with `classify`, split at the current pose first, as after
    /// RANSAC) and re-orthonormalises the result; the outlier classification stays for
    /// [`PoseProblem::drop_outliers`] and [`PoseProblem::inlier_coverage`].
    pub fn solve(
        &mut self,
        cam: &StereoCamera,
        t_cw: &mut Se3,
        classify: bool,
        params: &PoseOptParams,
    ) -> PoseOptReport {
        let n = self.obs.len();
        self.outlier[..n].fill(false);
        if classify {
            let t = *t_cw;
            for (o, out) in self.obs.iter().zip(self.outlier[..n].iter_mut()) {
                let s = chi2(cam, &t.transform_point(&o.p_w), &o.z);
                *out = !s.is_some_and(|s| s <= o.z.chi2_threshold());
            }
        }
        let rep = optimize_pose(cam, t_cw, &self.obs, &mut self.outlier[..n], params);
        *t_cw = renormalize(t_cw);
        rep
    }

    /// Unlinks the features whose observations the last solve classified as outliers.
    pub fn drop_outliers(&self, matches: &mut Matches) {
        for (k, &j) in self.feat[..self.obs.len()].iter().enumerate() {
            if self.outlier[k] {
                matches.unlink(usize::from(j));
            }
        }
    }

    /// The features with an observation the last solve classified as an outlier (a feature
    /// may appear more than once under EM, one observation per candidate).
    pub fn outlier_features(&self) -> impl Iterator<Item = usize> + '_ {
        let n = self.obs.len();
        self.feat[..n]
            .iter()
            .zip(&self.outlier[..n])
            .filter(|(_, &o)| o)
            .map(|(&j, _)| usize::from(j))
    }

    /// Number of cells of a 16x8 grid over a `width`x`height` image holding at least one
    /// inlier of the last solve.
    pub fn inlier_coverage(&self, feats: &[Feature], width: f32, height: f32) -> u32 {
        let mut cells = [false; 128];
        for (k, &fi) in self.feat[..self.obs.len()].iter().enumerate() {
            if self.outlier[k] {
                continue;
            }
            let f = &feats[usize::from(fi)];
            let cx = ((f.x / width) * 16.0) as usize;
            let cy = ((f.y / height) * 8.0) as usize;
            cells[cy.min(7) * 16 + cx.min(15)] = true;
        }
        cells.iter().filter(|&&c| c).count() as u32
    }
}

/// Labels the features of `frame` from the left label image: class at the key point and, for
/// key points within 2 px of a class boundary, a semantic descriptor.
pub fn annotate(frame: &mut Frame, labels: &ImageView<'_>) {
    let n = frame.features.len().min(FRAME_CAPACITY);
    for i in 0..n {
        let f = &mut frame.features[i];
        let x = math::roundf(f.x).max(0.0) as usize;
        let y = math::roundf(f.y).max(0.0) as usize;
        if x >= labels.width() || y >= labels.height() {
            f.class = VOID;
            frame.sem[i] = None;
            continue;
        }
        f.class = labels.get(x, y);
        frame.sem[i] = semdesc::describe_near(labels, x, y, 2).map(|(_, _, d)| d);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_keep_the_best_four_in_order() {
        let mut c = Candidates::EMPTY;
        for (lm, h) in [(1, 50), (2, 30), (3, 70), (4, 30), (5, 10), (6, 90)] {
            c.insert(Candidate { lm, hamming: h });
        }
        let got: std::vec::Vec<_> = c.iter().map(|x| (x.lm, x.hamming)).collect();
        assert_eq!(got, [(5, 10), (2, 30), (4, 30), (1, 50)]);
        assert_eq!(c.len(), 4);
    }

    #[test]
    fn annotate_reads_classes_and_boundary_descriptors() {
        let mut labels = std::vec![1u8; 64 * 48];
        for y in 0..48 {
            for x in 32..64 {
                labels[y * 64 + x] = 8;
            }
        }
        let lv = ImageView::from_slice(&labels, 64, 48).unwrap();
        let mut frame = std::boxed::Box::new(Frame::new());
        let f = |x: f32| crate::frame::Feature {
            x,
            y: 20.0,
            level: 0,
            angle: 0.0,
            desc: [0; 32],
            ur: -1.0,
            depth_m: 0.0,
            class: VOID,
        };
        frame.features.push(f(10.0)).unwrap();
        frame.features.push(f(31.4)).unwrap();
        frame.features.push(f(40.0)).unwrap();
        annotate(&mut frame, &lv);
        let classes: std::vec::Vec<u8> = frame.features.iter().map(|f| f.class).collect();
        assert_eq!(classes, [1, 1, 8]);
        assert!(frame.sem[0].is_none(), "far from the edge");
        assert_eq!(frame.sem[1].map(|d| d.class), Some(1));
        assert!(frame.sem[2].is_none());
    }
}
