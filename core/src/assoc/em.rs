//! EM data association (paper §3.3, Eqs. 3–9; after Bowman et al. 2017, "Probabilistic data
//! association for semantic SLAM"): the pose is found without committing any feature to a
//! landmark first.
//!
//! - **Objective.** Instead of maximising `log p(Z | X, D)` for one hard association `D`,
//!   maximise its expectation over the associations given the previous pose estimate,
//!   `X* = argmax_X Σ_D p(D | X⁽ⁱ⁾, Z) log p(Z | X, D)`. Per feature `j` and gated candidate
//!   landmark `k` this becomes a weighted sum of per-pair log-likelihoods.
//! - **E-step** ([`normalise`], `e_step`). Each pair's weight is its likelihood at the current
//!   pose, normalised over the feature's candidates together with a null hypothesis ("no
//!   landmark in the window"): `w_kj = p_kj / (p_0j + Σ_k' p_k'j)`. The log-likelihood of a
//!   pair is a sum of terms in nats: geometry `−χ²/2` of the reprojection, appearance
//!   `−d_ORB/τ_orb`, class `log p(c_j | k)` from the landmark's class histogram with a
//!   Dirichlet prior ([`class_log_likelihood`]; by default not with the network's labels, see
//!   [`ClassTerm`]) and semantic shape `−d_sem/τ_sem` when both sides carry a semantic
//!   descriptor ([`semantic_log_likelihood`]). The null hypothesis scores a candidate that
//!   sits exactly at every gate.
//! - **M-step.** Weighted motion-only pose optimisation: every pair with `w_kj` above
//!   [`EmParams::min_weight`] enters Gauss-Newton with its residual scaled by `w_kj`
//!   (`X = argmin Σ_jk w_kj ‖r_kj(X)‖²_Σ`), one robust round per EM iteration.
//! - **Decision.** After the last iteration a final E-step at the converged pose keeps, per
//!   feature, the candidate with weight ≥ 0.5 that also passes the χ² gate; a landmark goes to
//!   one feature only (the higher weight wins), as hard association guarantees by
//!   construction. The kept weight goes to the keyframe, where bundle adjustment uses it.
//! - **Final M-step** ([`EmParams::final_refine`]). One more pose optimisation on the decided
//!   pairs, weighted by their EM weights, with the backbone's rounds of χ² outlier
//!   classification; pairs that end as outliers are dropped.
//!
//! Memory: `EmScratch` (owned by the tracker): [`MAX_CANDIDATES`] candidates per frame
//! feature and one claim slot per landmark, 0.11 MiB; the pose problem is the tracker's
//! `PoseProblem`.

use super::{Candidate, Candidates, Matches, PoseProblem, MAX_CANDIDATES};
use crate::frame::{Frame, FRAME_CAPACITY};
use crate::geom::{Se3, StereoCamera};
use crate::map::{measurement, Map, MAX_LANDMARKS, NO_LANDMARK};
use crate::math;
use crate::optim::{chi2, PoseObs, PoseOptParams};
use crate::seg::{NUM_CLASSES, VOID};
use crate::semdesc::{self, SemDesc};

/// Parameters of the E-step.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct EmParams {
    /// EM iterations (E + M) per frame.
    pub iterations: u8,
    /// ORB Hamming scale τ_orb (bits per nat).
    pub tau_orb: f64,
    /// Semantic descriptor scale τ_sem (bits per nat).
    pub tau_sem: f64,
    /// Dirichlet prior count per class for landmark class histograms.
    pub class_prior: f64,
    /// When the class term `log p(c_j | k)` scores candidates (the semantic-descriptor term
    /// is not affected).
    pub class_term: ClassTerm,
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
            class_term: ClassTerm::NotNetwork,
            max_hamming: 100,
            min_weight: 1e-3,
            final_refine: true,
        }
    }
}

/// When EM's class term (how often a landmark was seen with the feature's class) scores
/// candidates.
///
/// With ground-truth labels it sharpens association. The int8 network's labels on KITTI
/// (outside its CamVid training set) disagree with themselves from frame to frame and
/// region to region, so a landmark's class histogram mostly records where the network erred
/// and the term pulls features towards wrong landmarks. Over 13 / 13 / 9 starts (2026-12-02),
/// motion + EM with the term left out: 01 clip ATE 0.91×, 06 0.98×, drive 0005 1.01×.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum ClassTerm {
    /// With any labels.
    Always,
    /// Only with labels that do not come from the segmentation network (ground truth, or a
    /// dataset's own label images); see [`crate::tracker::Tracker::set_network_labels`].
    NotNetwork,
    /// Never.
    Never,
}

impl ClassTerm {
    /// Whether the term is used when the labels do (`network_labels`) or do not come from the
    /// segmentation network.
    pub fn applies(self, network_labels: bool) -> bool {
        match self {
            Self::Always => true,
            Self::NotNetwork => !network_labels,
            Self::Never => false,
        }
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

/// What EM reads besides its scratch: the frame, the map and the settings.
pub(crate) struct EmInput<'a> {
    /// The frame (features and semantic descriptors).
    pub frame: &'a Frame,
    /// The window whose landmarks are the candidates.
    pub window: &'a Map,
    /// The camera.
    pub cam: &'a StereoCamera,
    /// EM settings.
    pub params: &'a EmParams,
    /// The ORB Hamming gate the null hypothesis sits at (the nearest-neighbour search's).
    pub null_max_hamming: u32,
    /// Stereo points beyond this depth (m) are monocular measurements.
    pub far_m: f32,
    /// Whether the class term scores candidates ([`ClassTerm::applies`]).
    pub class_term: bool,
}

/// What one EM association did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct EmOutcome {
    /// Features associated with a landmark at the end.
    pub inliers: u32,
    /// Of those, the features whose landmark is not their nearest-neighbour candidate.
    pub changed: u32,
}

/// EM's per-frame scratch: every feature's gated candidates (filled by the final projection
/// search) and the landmark claims of the decision.
pub(crate) struct EmScratch {
    /// Gated candidates of each feature, best (smallest Hamming) first.
    pub cands: [Candidates; FRAME_CAPACITY],
    /// Feature holding each landmark in the decision (u16::MAX: none); reset after use.
    lm_claim: [u16; MAX_LANDMARKS],
}

impl EmScratch {
    /// Empty scratch.
    pub fn new() -> Self {
        Self { cands: [Candidates::EMPTY; FRAME_CAPACITY], lm_claim: [u16::MAX; MAX_LANDMARKS] }
    }

    /// EM association: alternate E-steps over every feature's gated candidates and weighted
    /// M-steps on `t_cw`; then decide per feature and, with `final_refine`, run the final
    /// M-step. Writes the decisions and their weights into `matches`.
    // `j` indexes several parallel per-feature arrays (features, candidates, descriptors,
    // associations); an index loop is the clear form here.
    #[allow(clippy::needless_range_loop)]
    pub fn associate(
        &mut self,
        input: &EmInput<'_>,
        t_cw: &mut Se3,
        problem: &mut PoseProblem,
        matches: &mut Matches,
    ) -> EmOutcome {
        let feats = &input.frame.features[..];
        let n = feats.len();
        let mut w = [0.0f64; MAX_CANDIDATES];
        let m_step = PoseOptParams { rounds: 1, iterations: 5, robust_until_round: 1 };
        for _ in 0..input.params.iterations {
            problem.clear();
            for j in 0..n {
                let mut ids = [0u32; MAX_CANDIDATES];
                let k = self.e_step(input, t_cw, j, &mut ids, &mut w);
                for (&wk, &id) in w[..k].iter().zip(&ids[..k]) {
                    if wk < input.params.min_weight {
                        continue;
                    }
                    let obs = PoseObs {
                        p_w: input.window.lm(id).p_w,
                        z: measurement(&feats[j], input.far_m),
                        weight: wk,
                    };
                    if !problem.push(obs, j) {
                        break;
                    }
                }
            }
            problem.solve(input.cam, t_cw, false, &m_step);
        }
        // Final E-step at the converged pose: hard decisions for the map.
        let (mut inliers, mut changed) = (0u32, 0u32);
        for j in 0..n {
            matches.lm[j] = NO_LANDMARK;
            matches.weight[j] = 0.0;
            let mut ids = [0u32; MAX_CANDIDATES];
            let k = self.e_step(input, t_cw, j, &mut ids, &mut w);
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
            let z = measurement(&feats[j], input.far_m);
            let pc = t_cw.transform_point(&input.window.lm(id).p_w);
            if !chi2(input.cam, &pc, &z).is_some_and(|s| s <= z.chi2_threshold()) {
                continue;
            }
            // One feature per landmark, as hard association guarantees by construction: the
            // feature with the higher weight keeps the landmark.
            let claim = self.lm_claim[id as usize];
            if claim != u16::MAX {
                let other = usize::from(claim);
                if matches.weight[other] >= wb as f32 {
                    continue;
                }
                matches.lm[other] = NO_LANDMARK;
                matches.weight[other] = 0.0;
            }
            self.lm_claim[id as usize] = j as u16;
            matches.lm[j] = id;
            matches.weight[j] = wb as f32;
        }
        // Clear the claims for the next frame (only the entries set).
        for j in 0..n {
            let id = matches.lm[j];
            if id != NO_LANDMARK {
                self.lm_claim[id as usize] = u16::MAX;
            }
        }
        if input.params.final_refine {
            // Soft M-steps never reject a pair outright, so a few confidently wrong pairs
            // would otherwise stay in the pose and in the keyframe.
            problem.collect(input.window, feats, matches, true);
            problem.solve(input.cam, t_cw, false, &PoseOptParams::default());
            problem.drop_outliers(matches);
        }
        for j in 0..n {
            let id = matches.lm[j];
            if id == NO_LANDMARK {
                continue;
            }
            inliers += 1;
            if self.cands[j].iter().next().is_some_and(|nn| nn.lm != id) {
                changed += 1;
            }
        }
        EmOutcome { inliers, changed }
    }

    /// The E-step for feature `j` at `t_cw`: writes the candidates that pass the gate into
    /// `ids` and their normalised weights (against the null hypothesis) into `w`; returns how
    /// many there are.
    fn e_step(
        &self,
        input: &EmInput<'_>,
        t_cw: &Se3,
        j: usize,
        ids: &mut [u32; MAX_CANDIDATES],
        w: &mut [f64; MAX_CANDIDATES],
    ) -> usize {
        let mut logl = [0.0f64; MAX_CANDIDATES];
        let mut k = 0;
        for cand in self.cands[j].iter() {
            if let Some(ll) = candidate_log_likelihood(input, t_cw, j, cand) {
                logl[k] = ll;
                ids[k] = cand.lm;
                k += 1;
            }
        }
        if k > 0 {
            normalise(&logl[..k], null_log_likelihood(input, j), &mut w[..k]);
        }
        k
    }
}

/// Log-likelihood of candidate `c` for feature `j` at `t_cw`, or `None` when it fails the
/// geometric gate (dead, behind the camera or χ² over four times the threshold).
fn candidate_log_likelihood(
    input: &EmInput<'_>,
    t_cw: &Se3,
    j: usize,
    c: &Candidate,
) -> Option<f64> {
    let f = &input.frame.features[j];
    let l = input.window.lm(c.lm);
    if !l.alive {
        return None;
    }
    let z = measurement(f, input.far_m);
    let s = chi2(input.cam, &t_cw.transform_point(&l.p_w), &z)?;
    if s > 4.0 * z.chi2_threshold() {
        return None;
    }
    let em = input.params;
    let mut ll = -0.5 * s - f64::from(c.hamming) / em.tau_orb;
    if f.class != VOID {
        if input.class_term {
            ll += class_log_likelihood(&l.class_hist, f.class, em.class_prior);
        }
        ll += semantic_log_likelihood(input.frame.sem[j].as_ref(), l.sem.as_ref(), em.tau_sem);
    }
    Some(ll)
}

/// The null hypothesis of feature `j`: a candidate sitting exactly at every gate.
fn null_log_likelihood(input: &EmInput<'_>, j: usize) -> f64 {
    let f = &input.frame.features[j];
    let em = input.params;
    let mut ll = -0.5 * measurement(f, input.far_m).chi2_threshold()
        - f64::from(input.null_max_hamming) / em.tau_orb;
    if f.class != VOID {
        if input.class_term {
            ll += math::ln(1.0 / NUM_CLASSES as f64);
        }
        if input.frame.sem[j].is_some() {
            ll -= f64::from(semdesc::MATCH_THRESHOLD) / em.tau_sem;
        }
    }
    ll
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn without_the_class_term_the_labels_do_not_move_the_weights() {
        // The map is ~13 MiB: build it on a thread with room for it.
        crate::testing::on_big_stack(|| {
            let cam = crate::testing::kitti_cam();
            let mut map = std::boxed::Box::new(Map::new());
            map.clear();
            // Two landmarks 10 m ahead: `a` exactly where the feature is, seen five times
            // as building (1); `b` 1.5 px to the right, seen five times as vegetation (4).
            let pa = nalgebra::Vector3::new(0.0, 0.0, 10.0);
            let pb = nalgebra::Vector3::new(1.5 * 10.0 / cam.fx_px, 0.0, 10.0);
            let a = map.new_landmark(pa, [0; 32], 0, 10.0).unwrap();
            let b = map.new_landmark(pb, [0; 32], 0, 10.0).unwrap();
            map.lm_mut(a).class_hist[1] = 5;
            map.lm_mut(b).class_hist[4] = 5;
            let weights = |class: u8, class_term: bool| {
                let mut frame = Frame::new();
                let (u, v) = (cam.cx_px as f32, cam.cy_px as f32);
                let ur = u - (cam.fx_px * cam.baseline_m / 10.0) as f32;
                let f = crate::frame::Feature {
                    x: u,
                    y: v,
                    level: 0,
                    angle: 0.0,
                    desc: [0; 32],
                    ur,
                    depth_m: 10.0,
                    class,
                };
                frame.features.push(f).unwrap();
                let mut scratch = std::boxed::Box::new(EmScratch::new());
                scratch.cands[0].insert(Candidate { lm: a, hamming: 20 });
                scratch.cands[0].insert(Candidate { lm: b, hamming: 20 });
                let params = EmParams::default();
                let input = EmInput {
                    frame: &frame,
                    window: &map,
                    cam: &cam,
                    params: &params,
                    null_max_hamming: 100,
                    far_m: 40.0 * cam.baseline_m as f32,
                    class_term,
                };
                let (mut ids, mut w) = ([0u32; MAX_CANDIDATES], [0.0f64; MAX_CANDIDATES]);
                let k = scratch.e_step(&input, &Se3::identity(), 0, &mut ids, &mut w);
                assert_eq!(k, 2);
                let wa = if ids[0] == a { w[0] } else { w[1] };
                let wb = if ids[0] == b { w[0] } else { w[1] };
                (wa, wb)
            };
            // With the class term a vegetation feature goes to the vegetation landmark
            // despite the 1.5 px; a building feature to the building one.
            let (wa, wb) = weights(4, true);
            assert!(wb > 0.5 && wa < wb, "class term on, vegetation: {wa} vs {wb}");
            let (wa, wb) = weights(1, true);
            assert!(wa > 0.5 && wb < wa, "class term on, building: {wa} vs {wb}");
            // Without it geometry and appearance alone decide, whatever the label.
            let (wa, wb) = weights(4, false);
            assert!(wa > wb, "class term off: {wa} vs {wb}");
            assert_eq!(weights(1, false), (wa, wb));
            assert_eq!(weights(VOID, false), (wa, wb));
        });
    }

    #[test]
    fn the_class_term_follows_the_label_source() {
        assert!(ClassTerm::Always.applies(true) && ClassTerm::Always.applies(false));
        assert!(ClassTerm::NotNetwork.applies(false) && !ClassTerm::NotNetwork.applies(true));
        assert!(!ClassTerm::Never.applies(true) && !ClassTerm::Never.applies(false));
        assert_eq!(EmParams::default().class_term, ClassTerm::NotNetwork);
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
}
