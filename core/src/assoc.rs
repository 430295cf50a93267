//! Probabilistic data association (paper §3.3, after Bowman et al., ICRA 2017).
//!
//! Instead of committing each feature to its nearest landmark, every feature keeps up to
//! [`MAX_CANDIDATES`] gated landmark candidates and the pose is found by EM on the expected
//! measurement likelihood:
//! - **E-step**: for feature `j` and candidate `k`,
//!   `w_kj ∝ p(class_j | k) · p(ORB Hamming) · p(semantic descriptor) · N(reprojection; Σ)`,
//!   normalised together with a null ("new / no landmark") hypothesis `w_0j`;
//! - **M-step**: weighted Gauss-Newton on the pose with every `(j, k)` pair weighted by
//!   `w_kj` ([`crate::optim::optimize_pose`]); local BA later uses the weight of the kept
//!   association.
//!
//! The terms are log-likelihoods in nats so they add: geometry `−χ²/2`, appearance
//! `−d/τ_orb`, class `log p(c | k)` from the landmark's class histogram with a Dirichlet
//! prior, semantic shape `−d_sem/τ_sem` when both sides have a semantic descriptor. The null
//! hypothesis scores a match that sits exactly at every gate. Memory: fixed per-feature
//! candidate arrays owned by the tracker.

use crate::frame::{Frame, FRAME_CAPACITY};
use crate::image::ImageView;
use crate::math;
use crate::seg::{NUM_CLASSES, VOID};
use crate::semdesc::{self, SemDesc};

/// Candidate landmarks kept per feature.
pub const MAX_CANDIDATES: usize = 4;

/// How features are associated with landmarks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Association {
    /// Nearest neighbour in descriptor space within the projection gate (ORB-SLAM2).
    Hard,
    /// EM over gated candidates (the paper's method).
    Em,
}

/// Parameters of the E-step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EmParams {
    /// EM iterations (E + M) per frame.
    pub iterations: u8,
    /// ORB Hamming scale τ_orb (bits per nat).
    pub tau_orb: f64,
    /// Semantic descriptor scale τ_sem (bits per nat).
    pub tau_sem: f64,
    /// Dirichlet prior count per class for landmark class histograms.
    pub class_prior: f64,
    /// Largest ORB Hamming distance a candidate may have (gate).
    pub max_hamming: u32,
    /// Weight below which a pair is left out of the M-step.
    pub min_weight: f64,
    /// After the hard decisions, one last M-step on the kept pairs with χ² outlier rounds
    /// (pairs ending as outliers are dropped).
    pub final_refine: bool,
}

impl Default for EmParams {
    fn default() -> Self {
        Self {
            iterations: 3,
            tau_orb: 8.0,
            tau_sem: 27.5,
            class_prior: 0.5,
            max_hamming: 100,
            min_weight: 1e-3,
            final_refine: true,
        }
    }
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

/// Log-likelihood that a landmark with class histogram `hist` produced a feature of class
/// `class` (Dirichlet-smoothed); 0 when the feature's class is unknown.
pub fn class_log_likelihood(hist: &[u8; NUM_CLASSES], class: u8, prior: f64) -> f64 {
    if usize::from(class) >= NUM_CLASSES {
        return 0.0;
    }
    let total: f64 = hist.iter().map(|&c| f64::from(c)).sum();
    let n = f64::from(hist[usize::from(class)]);
    math::ln((n + prior) / (total + prior * NUM_CLASSES as f64))
}

/// Log-likelihood of the semantic-descriptor agreement; 0 when either side has none.
pub fn semantic_log_likelihood(f: Option<&SemDesc>, l: Option<&SemDesc>, tau: f64) -> f64 {
    match (f, l) {
        (Some(a), Some(b)) => {
            let d = f64::from(semdesc::hamming(a, b));
            let class_penalty = if a.class == b.class { 0.0 } else { 3.0 };
            -d / tau - class_penalty
        }
        _ => 0.0,
    }
}

/// The E-step for one feature: given each candidate's total log-likelihood `logl[k]` and the
/// null hypothesis' `log_null`, writes normalised weights into `w[k]` and returns the null's.
pub fn normalise(logl: &[f64], log_null: f64, w: &mut [f64]) -> f64 {
    let max = logl.iter().copied().fold(log_null, f64::max);
    let mut sum = math::exp(log_null - max);
    for (l, wk) in logl.iter().zip(w.iter_mut()) {
        *wk = math::exp(l - max);
        sum += *wk;
    }
    for wk in w.iter_mut().take(logl.len()) {
        *wk /= sum;
    }
    math::exp(log_null - max) / sum
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
    fn weights_sum_to_one_with_the_null_hypothesis() {
        let mut w = [0.0; 3];
        let null = normalise(&[-1.0, -3.0, -10.0], -2.0, &mut w);
        let total: f64 = w.iter().sum::<f64>() + null;
        assert!((total - 1.0).abs() < 1e-12);
        assert!(w[0] > null && null > w[1] && w[1] > w[2]);
        // Far below the null: essentially no weight.
        let null = normalise(&[-50.0], 0.0, &mut w);
        assert!(w[0] < 1e-20 && (null - 1.0).abs() < 1e-12);
    }

    #[test]
    fn class_term_prefers_the_landmarks_class() {
        let mut hist = [0u8; NUM_CLASSES];
        hist[1] = 5; // a building landmark
        let same = class_log_likelihood(&hist, 1, 0.5);
        let other = class_log_likelihood(&hist, 3, 0.5);
        assert!(same > other + 2.0, "{same} vs {other}");
        assert_eq!(class_log_likelihood(&hist, VOID, 0.5), 0.0);
        // An empty histogram is uniform.
        let u = class_log_likelihood(&[0; NUM_CLASSES], 4, 0.5);
        assert!((u - math::ln(1.0 / NUM_CLASSES as f64)).abs() < 1e-12);
    }

    #[test]
    fn semantic_term_rewards_matching_shapes() {
        let a = SemDesc { bits: [u64::MAX; semdesc::WORDS], class: 1 };
        let mut b = a;
        b.bits[0] = 0; // 64 bits differ
        let c = SemDesc { class: 2, ..a };
        assert_eq!(semantic_log_likelihood(Some(&a), Some(&a), 27.5), 0.0);
        assert!(semantic_log_likelihood(Some(&a), Some(&b), 27.5) < -2.0);
        assert!(semantic_log_likelihood(Some(&a), Some(&c), 27.5) <= -3.0);
        assert_eq!(semantic_log_likelihood(None, Some(&a), 27.5), 0.0);
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
