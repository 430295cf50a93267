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
/// The grid coordinate of `v` (pixels) with cells `1 / inv` wide: the truncated `v · inv`
/// clamped to `0..=n − 1`, NaN as 0. Clamped before the conversion (the same cell: truncation
/// is monotonic), which then vectorises ([`crate::arch::trunc_clamped`]).
#[inline(always)]
fn cell_coord(v: f32, inv: f32, n: usize) -> usize {
    crate::arch::trunc_clamped(v * inv, (n - 1) as f32) as usize
}

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
        (cell_coord(x, self.inv_cell_w, GRID_COLS), cell_coord(y, self.inv_cell_h, GRID_ROWS))
    }

    /// The boxes of cells `cell_of(x − r, y − r) ..= cell_of(x + r, y + r)` around the points
    /// of a walk along a segment: step `s` of `out.len()` is at `t = t0 + (t1 − t0)·s / steps`,
    /// `(x, y) = ((lo.0 + d.0·t) as f32, (lo.1 + d.1·t) as f32)`. Each box is packed as
    /// `cx0 | cy0 << 8 | cx1 << 16 | cy1 << 24`. All steps are computed in one loop that
    /// vectorises (through [`crate::arch::v3`]); the values are those of one `cell_of` pair
    /// per step.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn boxes_along(
        &self,
        lo: (f64, f64),
        d: (f64, f64),
        t0: f64,
        t1: f64,
        steps: usize,
        r: f32,
        out: &mut [u32],
    ) {
        let (iw, ih) = (self.inv_cell_w, self.inv_cell_h);
        let n = out.len().min(i32::MAX as usize) as i32;
        crate::arch::v3(
            #[inline(always)]
            || {
                for s in 0..n {
                    let t = t0 + (t1 - t0) * f64::from(s) / steps as f64;
                    let (x, y) = ((lo.0 + d.0 * t) as f32, (lo.1 + d.1 * t) as f32);
                    let cx0 = cell_coord(x - r, iw, GRID_COLS) as u32;
                    let cy0 = cell_coord(y - r, ih, GRID_ROWS) as u32;
                    let cx1 = cell_coord(x + r, iw, GRID_COLS) as u32;
                    let cy1 = cell_coord(y + r, ih, GRID_ROWS) as u32;
                    out[s as usize] = cx0 | cy0 << 8 | cx1 << 16 | cy1 << 24;
                }
            },
        );
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_along_match_cell_of_at_every_step() {
        // Segments of every direction and length, partly outside the image, on a KITTI-sized
        // grid and an odd one: the packed boxes equal the per-step `cell_of` pairs, at every
        // instruction-set level.
        let mut rng = crate::testing::Rng::new(0xce11_b0c5);
        for (w, h) in [(1241.0f32, 376.0f32), (333.0, 1001.0)] {
            let mut grid = FeatureGrid::new();
            grid.build(&[], w, h);
            for _ in 0..300 {
                let lo = (rng.range(-200.0, 1500.0), rng.range(-200.0, 1200.0));
                let d = (rng.signed() * 1500.0, rng.signed() * 900.0);
                let (t0, t1) = (rng.range(0.0, 0.5), rng.range(0.5, 1.0));
                let steps = rng.below(400) + 1;
                let want: std::vec::Vec<u32> = (0..=steps)
                    .map(|s| {
                        let t = t0 + (t1 - t0) * s as f64 / steps as f64;
                        let (x, y) = ((lo.0 + d.0 * t) as f32, (lo.1 + d.1 * t) as f32);
                        let (cx0, cy0) = grid.cell_of(x - 8.0, y - 8.0);
                        let (cx1, cy1) = grid.cell_of(x + 8.0, y + 8.0);
                        u32::from_le_bytes([cx0, cy0, cx1, cy1].map(|v| v as u8))
                    })
                    .collect();
                crate::nn::dispatch::for_each_level(|level| {
                    let mut got = [u32::MAX; 401];
                    grid.boxes_along(lo, d, t0, t1, steps, 8.0, &mut got[..=steps]);
                    assert_eq!(&got[..=steps], &want[..], "{level}: {lo:?} {d:?} {steps}");
                });
            }
        }
    }

    #[test]
    fn cell_of_clamps_like_a_wide_conversion() {
        let mut grid = FeatureGrid::new();
        grid.build(&[], 1241.0, 376.0);
        for (x, y) in [(-1e30f32, 1e30f32), (f32::NAN, -0.5), (0.99 * 1241.0 / 64.0, 375.999)] {
            let wide =
                |v: f32, inv: f32, n: usize| ((v * inv) as isize).clamp(0, n as isize - 1) as usize;
            assert_eq!(
                grid.cell_of(x, y),
                (wide(x, grid.inv_cell_w, GRID_COLS), wide(y, grid.inv_cell_h, GRID_ROWS))
            );
        }
    }
}
