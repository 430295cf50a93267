//! Nearest-neighbour association by projection (ORB-SLAM2's `SearchByProjection`): every
//! live window landmark is projected at the current pose estimate and matched to the feature
//! with the smallest ORB Hamming distance among those within a radius (scaled by the predicted
//! pyramid level), on the predicted level ±1, consistent with the stereo column, under
//! `max_hamming` and passing the best/second-best ratio when both lie on one level. A feature
//! claimed by several landmarks keeps the nearest in descriptor space. Under EM the final pass
//! also records every candidate under the EM gate for each feature.
//!
//! It lives here rather than in the tracker because it is the hard association itself and the
//! candidate source of EM; the tracker only decides radii and passes.
//!
//! Memory: [`ProjectionSearch`] holds a 64×24 cell grid over the frame's features (counting
//! sort) and one best distance per feature, 15 KiB.

use super::{Candidate, Candidates, Matches};
use crate::frame::{hamming, level_scale, Feature, FRAME_CAPACITY};
use crate::geom::{Se3, StereoCamera};
use crate::map::{predict_level, Map, NO_LANDMARK};

/// Grid used to look up features near a projected landmark.
const GRID_COLS: usize = 64;
const GRID_ROWS: usize = 24;
const GRID_CELLS: usize = GRID_COLS * GRID_ROWS;

/// `ln(1.2)`, for predicting the pyramid level a landmark appears on.
pub(crate) const LN_SCALE: f64 = 0.182_321_556_793_954_6;

/// Features of one frame bucketed by image cell (counting sort, no allocation). Also used by
/// local mapping over keyframe features.
pub(crate) struct FeatureGrid {
    start: [u16; GRID_CELLS + 1],
    items: [u16; FRAME_CAPACITY],
    inv_cell_w: f32,
    inv_cell_h: f32,
}

impl FeatureGrid {
    pub(crate) const fn new() -> Self {
        Self {
            start: [0; GRID_CELLS + 1],
            items: [0; FRAME_CAPACITY],
            inv_cell_w: 1.0,
            inv_cell_h: 1.0,
        }
    }

    pub(crate) fn cell_of(&self, x: f32, y: f32) -> (usize, usize) {
        let cx = (x * self.inv_cell_w) as isize;
        let cy = (y * self.inv_cell_h) as isize;
        (cx.clamp(0, GRID_COLS as isize - 1) as usize, cy.clamp(0, GRID_ROWS as isize - 1) as usize)
    }

    pub(crate) fn build(&mut self, features: &[Feature], width: f32, height: f32) {
        self.build_where(features, width, height, |_| true);
    }

    /// [`Self::build`] over the features `keep` accepts (by index); each cell keeps them in
    /// index order, as `build` does.
    pub(crate) fn build_where(
        &mut self,
        features: &[Feature],
        width: f32,
        height: f32,
        keep: impl Fn(usize) -> bool,
    ) {
        self.inv_cell_w = GRID_COLS as f32 / width;
        self.inv_cell_h = GRID_ROWS as f32 / height;
        let mut count = [0u16; GRID_CELLS];
        for (i, f) in features.iter().enumerate() {
            if !keep(i) {
                continue;
            }
            let (cx, cy) = self.cell_of(f.x, f.y);
            count[cy * GRID_COLS + cx] += 1;
        }
        self.start[0] = 0;
        for (c, n) in count.iter().enumerate() {
            self.start[c + 1] = self.start[c] + n;
        }
        let mut fill = [0u16; GRID_CELLS];
        for (i, f) in features.iter().enumerate() {
            if !keep(i) {
                continue;
            }
            let (cx, cy) = self.cell_of(f.x, f.y);
            let c = cy * GRID_COLS + cx;
            self.items[usize::from(self.start[c] + fill[c])] = i as u16;
            fill[c] += 1;
        }
    }

    /// Indices of the features in cells `x0..=x1` of row `cy`.
    pub(crate) fn row_items(&self, cy: usize, x0: usize, x1: usize) -> &[u16] {
        let row = cy * GRID_COLS;
        &self.items[usize::from(self.start[row + x0])..usize::from(self.start[row + x1 + 1])]
    }

    /// Features whose cell lies in the box around (`x`, `y`) of half-size `r` (px).
    pub(crate) fn for_each_near(&self, x: f32, y: f32, r: f32, mut f: impl FnMut(usize)) {
        let (x0, y0) = self.cell_of(x - r, y - r);
        let (x1, y1) = self.cell_of(x + r, y + r);
        for cy in y0..=y1 {
            for &i in self.row_items(cy, x0, x1) {
                f(usize::from(i));
            }
        }
    }
}

/// One projection-search pass.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SearchQuery {
    /// Pose estimate to project at.
    pub t_cw: Se3,
    /// Search radius at level 0 (px).
    pub radius_px: f32,
    /// Largest Hamming distance accepted for a match.
    pub max_hamming: u32,
    /// Best/second-best ratio when both are on the same level.
    pub nn_ratio: f32,
    /// Apply the ratio test whatever the second-best's level (matching by appearance alone,
    /// where no position narrows the candidates down).
    pub ratio_any_level: bool,
    /// Count the pass in each projected landmark's `visible` (the final pass only).
    pub count_visible: bool,
    /// With a gate, also record every candidate within it for EM.
    pub em_gate: Option<u32>,
}

/// The projection search and its per-frame scratch.
pub(crate) struct ProjectionSearch {
    grid: FeatureGrid,
    dist: [u32; FRAME_CAPACITY],
    width: f32,
    height: f32,
}

impl ProjectionSearch {
    /// A search over images of `width`x`height` pixels.
    pub const fn new(width: f32, height: f32) -> Self {
        Self { grid: FeatureGrid::new(), dist: [u32::MAX; FRAME_CAPACITY], width, height }
    }

    /// Buckets a new frame's features (once per frame, before any pass).
    pub fn prepare(&mut self, feats: &[Feature]) {
        self.grid.build(feats, self.width, self.height);
    }

    /// Matches the landmarks `ids` (the local map) to `feats` by projection at `q.t_cw`.
    /// Overwrites `matches` (weight 1 for every feature) and, with an EM gate, `cands`;
    /// returns the number of matched features.
    #[allow(clippy::too_many_arguments)] // each slice is separate caller-owned storage
    pub fn search(
        &mut self,
        window: &mut Map,
        ids: &[u32],
        cam: &StereoCamera,
        feats: &[Feature],
        q: &SearchQuery,
        matches: &mut Matches,
        cands: &mut [Candidates; FRAME_CAPACITY],
    ) -> u32 {
        matches.lm[..feats.len()].fill(NO_LANDMARK);
        self.dist[..feats.len()].fill(u32::MAX);
        matches.weight[..feats.len()].fill(1.0);
        let collect = q.em_gate.is_some();
        if collect {
            cands[..feats.len()].fill(Candidates::EMPTY);
        }
        let em_gate = q.em_gate.unwrap_or(0);
        let t_cw = q.t_cw;
        let center = t_cw.inverse().trans;
        let bf = cam.fx_px * cam.baseline_m;
        for &id in ids {
            // Only what the search reads: a landmark is ~250 bytes with its observation list.
            let l = LmView::of(window.lm(id));
            if !l.alive {
                continue;
            }
            let pc = t_cw.transform_point(&l.p_w);
            if pc.z < 0.1 {
                continue;
            }
            let u = (cam.fx_px * pc.x / pc.z + cam.cx_px) as f32;
            let v = (cam.fy_px * pc.y / pc.z + cam.cy_px) as f32;
            if !(u >= 0.0 && v >= 0.0 && u < self.width && v < self.height) {
                continue;
            }
            let dist = (l.p_w - center).norm();
            let pred = predict_level(l.ref_level, l.ref_dist_m, dist);
            if q.count_visible {
                window.lm_mut(id).visible += 1;
            }
            let r = q.radius_px * level_scale(pred as u8);
            let ur_pred = u - (bf / pc.z) as f32;
            let (x0, y0) = self.grid.cell_of(u - r, v - r);
            let (x1, y1) = self.grid.cell_of(u + r, v + r);
            let mut best = (u32::MAX, usize::MAX, 0u8);
            let mut second = (u32::MAX, 0u8);
            for cy in y0..=y1 {
                for &fi in self.grid.row_items(cy, x0, x1) {
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
                        cands[fi].insert(Candidate { lm: id, hamming: d });
                    }
                    if d < best.0 {
                        second = (best.0, best.2);
                        best = (d, fi, f.level);
                    } else if d < second.0 {
                        second = (d, f.level);
                    }
                }
            }
            if best.0 > q.max_hamming || best.1 == usize::MAX {
                continue;
            }
            if (q.ratio_any_level || best.2 == second.1)
                && (best.0 as f32) > q.nn_ratio * second.0 as f32
            {
                continue;
            }
            let fi = best.1;
            if best.0 < self.dist[fi] {
                self.dist[fi] = best.0;
                matches.lm[fi] = id;
            }
        }
        matches.count(feats.len())
    }
}

/// The fields of a landmark the projection search reads.
struct LmView {
    p_w: nalgebra::Vector3<f64>,
    desc: crate::frame::Descriptor,
    ref_level: u8,
    ref_dist_m: f32,
    alive: bool,
}

impl LmView {
    #[inline]
    fn of(l: &crate::map::Landmark) -> Self {
        Self {
            p_w: l.p_w,
            desc: l.desc,
            ref_level: l.ref_level,
            ref_dist_m: l.ref_dist_m,
            alive: l.alive,
        }
    }
}
