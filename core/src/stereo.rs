//! Stereo matching of ORB key points on a rectified pair: ORB-SLAM2's
//! `Frame::ComputeStereoMatches` (Mur-Artal & Tardós 2017, §III-A, "stereo key points"), in
//! fixed memory.
//!
//! For each left key point `(u_L, v_L)` on level `l`:
//! 1. **Row band.** Every right key point is registered on the level-0 rows
//!    `⌊y − r⌋ ..= ⌈y + r⌉`, `r = 2·sˡᵉᵛᵉˡ` (its own level's scale), in a CSR row index; the
//!    candidates of a left point are the entries of row `⌊v_L⌋`.
//! 2. **Descriptor match.** Among candidates on levels `l − 1 ..= l + 1` with
//!    `u_R ∈ [u_L − maxD, u_L − minD]` (`minZ = b`, `minD = 0`, `maxD = bf / minZ`), the
//!    smallest Hamming distance wins (first on ties); it must be below
//!    `(TH_HIGH + TH_LOW)/2 = 75`.
//! 3. **SAD refinement** on level `l` of both (unblurred) pyramids: an 11 × 11 window around
//!    `round(u_L/sˡ), round(v_L/sˡ)`, each patch minus its centre pixel (ORB-SLAM2's
//!    `IL = IL - IL.at(w,w)`), slid over `round(u_R/sˡ) ± 5`; L1 distance. A minimum at the
//!    search border is rejected; a parabola through the three distances around the minimum
//!    gives `Δ = (d₁ − d₃) / (2(d₁ + d₃ − 2d₂))`, rejected when `|Δ| > 1`; then
//!    `u_R = sˡ(round(u_R/sˡ) + inc + Δ)`, disparity `u_L − u_R` kept when in `[minD, maxD)`
//!    (≤ 0 becomes 0.01, as ORB-SLAM2), depth `bf / disparity`.
//! 4. **Outliers.** Matches sorted by SAD distance; those above `1.5 · 1.4 · median` lose their
//!    depth.
//!
//! **Where this differs from ORB-SLAM2, and why:**
//! - A match is dropped when its SAD distance is *above* the threshold (ORB-SLAM2: *at or
//!   above*), so a median distance of 0 (noise-free input) does not reject every match.
//! - The right search window is bounds-checked as `round(u_R/sˡ) − L − w ≥ 0` and
//!   `round(u_R/sˡ) + L + w < width` (ORB-SLAM2 checks `+L−w` on the left, a typo that lets
//!   OpenCV assert), and the left window and every row are checked too: nothing derived from
//!   key-point data indexes without a check, so no input can panic.
//! - Rows of the row band are clamped to the image (ORB-SLAM2 writes out of its row vector
//!   for key points within `r` of the top or bottom edge).
//! - Pixel arithmetic is integer (exactly ORB-SLAM2's float values, which are integers); the
//!   parabola and depth are `f32` in ORB-SLAM2's operation order: bit-identical on every target.
//!
//! **Memory.** [`StereoMatcher<MAX_KP, MAX_ROWS, MAX_ENTRIES>`] owns the row index
//! (`8·MAX_ROWS + 2·MAX_ENTRIES` bytes) and the match list (`8·MAX_KP` bytes); nothing else,
//! and no stack arrays beyond one 21 × 21 patch. Row entries past `MAX_ENTRIES` are dropped
//! (the latest rows first) and counted in [`StereoStats::row_overflow`]. [`KittiStereoMatcher`]
//! (1248 × 384, 2048 key points) takes [`KITTI_STEREO_MATCHER_BYTES`] ≈ 84 KiB and never
//! overflows with ORB-SLAM2's 8 levels of 1.2 (a key point spans at most 16 rows).
//!
//! ```
//! use semloc_core::frame::Frame;
//! use semloc_core::image::ImageView;
//! use semloc_core::orb::{pyramid_capacity, OrbConfig, OrbExtractor};
//! use semloc_core::stereo::{StereoMatcher, StereoParams};
//!
//! type Ext = OrbExtractor<160, { 160 * 120 }, { pyramid_capacity(160, 120, 8) }, 256, 4096>;
//! let (mut el, mut er) = (Box::new(Ext::new()), Box::new(Ext::new()));
//! el.configure(OrbConfig { n_features: 200, ..OrbConfig::KITTI }).unwrap();
//! er.configure(OrbConfig { n_features: 200, ..OrbConfig::KITTI }).unwrap();
//! // A right image that is the left one shifted by 8 px: disparity 8 everywhere.
//! let tex = |x: usize, y: usize| (((x * 7 + y * 13) ^ (x * y / 5)) % 251) as u8;
//! let left: Vec<u8> = (0..160 * 120).map(|i| tex(i % 160, i / 160)).collect();
//! let right: Vec<u8> = (0..160 * 120).map(|i| tex(i % 160 + 8, i / 160)).collect();
//! el.extract(&ImageView::from_slice(&left, 160, 120).unwrap()).unwrap();
//! er.extract(&ImageView::from_slice(&right, 160, 120).unwrap()).unwrap();
//!
//! let mut matcher = Box::new(StereoMatcher::<256, 128, 4096>::new());
//! let mut frame = Box::new(Frame::new());
//! let params = StereoParams::new(40.0, 0.5); // fx = 80 px, baseline 0.5 m
//! let stats = matcher
//!     .match_frame(el.features(), el.pyramid(), er.features(), er.pyramid(), &params, 0.0, &mut frame)
//!     .unwrap();
//! assert_eq!(frame.features.len(), el.features().len());
//! assert_eq!(frame.stereo_count(), stats.matched as usize);
//! assert!(stats.matched > 0);
//! ```

use core::fmt;

use crate::frame::{Feature, Frame, FRAME_CAPACITY};
use crate::image::ImageView;
use crate::math;
use crate::orb::{
    hamming, Descriptor, Features, KeyPoint, LevelInfo, Pyramid, KITTI_MAX_FEATURES,
    KITTI_MAX_HEIGHT, MAX_FRAME_HEIGHT,
};

/// ORB-SLAM2's `ORBmatcher::TH_HIGH`.
pub const TH_HIGH: u32 = 100;
/// ORB-SLAM2's `ORBmatcher::TH_LOW`.
pub const TH_LOW: u32 = 50;
/// Default Hamming acceptance bound, `(TH_HIGH + TH_LOW) / 2` (a match needs a distance below it).
pub const DEFAULT_MAX_HAMMING: u32 = (TH_HIGH + TH_LOW) / 2;
/// Largest SAD half window [`StereoParams::sad_half_window`] accepts (21 × 21 patch).
pub const MAX_SAD_HALF_WINDOW: usize = 10;
/// Largest SAD search half range [`StereoParams::sad_search`] accepts.
pub const MAX_SAD_SEARCH: i32 = 32;

const MAX_PATCH: usize = (2 * MAX_SAD_HALF_WINDOW + 1) * (2 * MAX_SAD_HALF_WINDOW + 1);
const MAX_DISTS: usize = 2 * MAX_SAD_SEARCH as usize + 1;
/// Shifts whose SADs [`sad_refine`] accumulates at once.
const SAD_LANES: usize = 16;
/// [`MAX_DISTS`] rounded up to whole blocks of [`SAD_LANES`].
const MAX_DISTS_PADDED: usize = MAX_DISTS.div_ceil(SAD_LANES) * SAD_LANES;
/// The padded copy of the right window's rows: `2w + 1` rows of `MAX_DISTS_PADDED + 2w` bytes.
const SAD_ROWS_BYTES: usize =
    (2 * MAX_SAD_HALF_WINDOW + 1) * (MAX_DISTS_PADDED + 2 * MAX_SAD_HALF_WINDOW);

/// Stereo calibration and matching parameters (ORB-SLAM2: `Camera.bf`, `mb`, and constants).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StereoParams {
    /// Baseline times focal length, `b·f_x` (px·m); depth = `bf / disparity`.
    pub bf_px_m: f32,
    /// Baseline (m); the nearest depth searched (`minZ`), so `maxD = bf / baseline`.
    pub baseline_m: f32,
    /// A descriptor match needs a Hamming distance below this (ORB-SLAM2: 75).
    pub max_hamming: u32,
    /// Half side `w` of the SAD window (ORB-SLAM2: 5, an 11 × 11 window),
    /// 1..=[`MAX_SAD_HALF_WINDOW`].
    pub sad_half_window: usize,
    /// Half range `L` of the SAD search in level pixels (ORB-SLAM2: 5), 2..=[`MAX_SAD_SEARCH`].
    pub sad_search: i32,
}

/// The matching settings of [`StereoParams`] that do not come from the rig's geometry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct StereoMatching {
    /// A descriptor match needs a Hamming distance below this (bits; ORB-SLAM2: 75).
    pub max_hamming: u32,
    /// Half side `w` of the SAD window (px; ORB-SLAM2: 5, an 11 × 11 window),
    /// 1..=[`MAX_SAD_HALF_WINDOW`].
    pub sad_half_window: usize,
    /// Half range `L` of the SAD search in level pixels (ORB-SLAM2: 5), 2..=[`MAX_SAD_SEARCH`].
    pub sad_search: i32,
}

impl StereoMatching {
    /// ORB-SLAM2's values.
    pub const ORB_SLAM2: StereoMatching =
        StereoMatching { max_hamming: DEFAULT_MAX_HAMMING, sad_half_window: 5, sad_search: 5 };

    /// Checks the window and search range (what [`StereoMatcher::match_frame`] would refuse).
    ///
    /// # Errors
    /// [`StereoError::BadWindow`] when either is outside its range.
    pub fn check(&self) -> Result<(), StereoError> {
        let (w, l) = (self.sad_half_window, self.sad_search);
        if !(1..=MAX_SAD_HALF_WINDOW).contains(&w) || !(2..=MAX_SAD_SEARCH).contains(&l) {
            return Err(StereoError::BadWindow { half_window: w, search: l });
        }
        Ok(())
    }
}

impl Default for StereoMatching {
    fn default() -> Self {
        Self::ORB_SLAM2
    }
}

impl StereoParams {
    /// ORB-SLAM2's settings for a rig with `bf_px_m` and `baseline_m`.
    pub const fn new(bf_px_m: f32, baseline_m: f32) -> Self {
        Self::with_matching(bf_px_m, baseline_m, StereoMatching::ORB_SLAM2)
    }

    /// The settings for a rig with `bf_px_m` and `baseline_m`, matching with `m`.
    pub const fn with_matching(bf_px_m: f32, baseline_m: f32, m: StereoMatching) -> Self {
        Self {
            bf_px_m,
            baseline_m,
            max_hamming: m.max_hamming,
            sad_half_window: m.sad_half_window,
            sad_search: m.sad_search,
        }
    }

    /// KITTI odometry sequences 00–02 (`KITTI00-02.yaml`: `bf` 386.1448, `fx` 718.856).
    pub const KITTI_00_02: StereoParams = StereoParams::new(386.1448, 386.1448 / 718.856);
}

/// Why [`StereoMatcher::match_frame`] refused a frame (nothing was matched).
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StereoError {
    /// `bf_px_m` or `baseline_m` is not finite and positive.
    BadCalibration {
        /// The `bf_px_m` given.
        bf_px_m: f32,
        /// The `baseline_m` given.
        baseline_m: f32,
    },
    /// The SAD window or search range is outside its supported range.
    BadWindow {
        /// The `sad_half_window` given.
        half_window: usize,
        /// The `sad_search` given.
        search: i32,
    },
    /// A pyramid has no level.
    EmptyPyramid,
    /// The two pyramids have different level counts.
    LevelCountMismatch {
        /// Levels of the left pyramid.
        left: usize,
        /// Levels of the right pyramid.
        right: usize,
    },
    /// A level has different sizes in the two pyramids.
    SizeMismatch {
        /// The level.
        level: usize,
    },
    /// The image has more rows than the row index holds.
    TooManyRows {
        /// Rows of level 0.
        rows: usize,
        /// `MAX_ROWS`.
        cap: usize,
    },
    /// One side has more key points than the matcher (or the output frame) holds.
    TooManyKeypoints {
        /// Key points given.
        got: usize,
        /// What fits.
        cap: usize,
    },
}

impl fmt::Display for StereoError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            StereoError::BadCalibration { bf_px_m, baseline_m } => write!(
                f,
                "bad stereo calibration: bf {bf_px_m} px·m and baseline {baseline_m} m must be \
                 finite and positive"
            ),
            StereoError::BadWindow { half_window, search } => write!(
                f,
                "bad SAD window: half window {half_window} (1..={MAX_SAD_HALF_WINDOW}), search \
                 {search} (2..={MAX_SAD_SEARCH})"
            ),
            StereoError::EmptyPyramid => write!(f, "stereo pyramid has no level"),
            StereoError::LevelCountMismatch { left, right } => {
                write!(f, "pyramid levels differ: left {left}, right {right}")
            }
            StereoError::SizeMismatch { level } => {
                write!(f, "left and right pyramid level {level} sizes differ")
            }
            StereoError::TooManyRows { rows, cap } => {
                write!(f, "image has {rows} rows, the stereo row index holds {cap}")
            }
            StereoError::TooManyKeypoints { got, cap } => {
                write!(f, "{got} key points, the stereo matcher holds {cap}")
            }
        }
    }
}

impl core::error::Error for StereoError {}

/// Counters of one [`StereoMatcher::match_frame`] call.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StereoStats {
    /// Left key points (one output feature each).
    pub left: u32,
    /// Right key points.
    pub right: u32,
    /// Left key points skipped as invalid: level outside the pyramid, or position not finite
    /// or outside the image.
    pub invalid: u32,
    /// Left key points whose best descriptor distance passed `max_hamming`.
    pub descriptor_matched: u32,
    /// Final stereo matches (features with `ur` and `depth_m`).
    pub matched: u32,
    /// Descriptor matches whose SAD window or search range leaves the level image.
    pub rejected_window: u32,
    /// Descriptor matches whose SAD minimum lies on the search border.
    pub rejected_sad_border: u32,
    /// Descriptor matches whose parabola offset `|Δ|` exceeds 1 (or is undefined).
    pub rejected_parabola: u32,
    /// Refined matches whose disparity lies outside `[minD, maxD)`.
    pub rejected_disparity: u32,
    /// Matches dropped by the `1.5 · 1.4 · median` SAD rule.
    pub rejected_median: u32,
    /// Median SAD distance of the refined matches (0 when there were none).
    pub median_sad: u32,
    /// Row-index entries dropped because `MAX_ENTRIES` was full.
    pub row_overflow: u32,
}

/// A refinement outcome other than a match.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reject {
    Window,
    Border,
    Parabola,
}

/// The stereo matcher: a CSR row index over right key points for images up to `MAX_ROWS` rows,
/// `MAX_ENTRIES` row entries, and up to `MAX_KP` key points per side (`MAX_KP ≤ 65536`).
///
/// `const fn new`, so it can live in a `static`; one call of
/// [`StereoMatcher::match_frame`] per frame.
#[derive(Clone, Debug)]
pub struct StereoMatcher<const MAX_KP: usize, const MAX_ROWS: usize, const MAX_ENTRIES: usize> {
    /// End (exclusive) of each row's entries; row `r` starts at `row_end[r − 1]` (0 for r = 0).
    row_end: [u32; MAX_ROWS],
    /// Per-row counts, then per-row fill cursors while the index is built.
    cursor: [u32; MAX_ROWS],
    /// Right key-point indices, grouped by row, in key-point order within a row.
    entries: [u16; MAX_ENTRIES],
    /// (SAD distance, left index) of the refined matches.
    matches: [(u32, u16); MAX_KP],
    /// [`sad_refine`]'s padded copy of the right window's rows.
    sad_rows: [u8; SAD_ROWS_BYTES],
}

/// Row-entry capacity of [`KittiStereoMatcher`]: 16 rows for each of 2048 key points, the most
/// a key point on level 7 at scale 1.2 spans (`r = 2·1.2⁷ ≈ 7.2`).
pub const KITTI_STEREO_MAX_ENTRIES: usize = KITTI_MAX_FEATURES * 16;

/// The matcher sized for KITTI: 384 rows, 2048 key points per side.
pub type KittiStereoMatcher =
    StereoMatcher<KITTI_MAX_FEATURES, KITTI_MAX_HEIGHT, KITTI_STEREO_MAX_ENTRIES>;

/// `size_of::<KittiStereoMatcher>()`.
pub const KITTI_STEREO_MATCHER_BYTES: usize = core::mem::size_of::<KittiStereoMatcher>();

/// Memory budget of [`KittiStereoMatcher`]: 96 KiB (row index 67 KiB, match list 16 KiB).
pub const KITTI_STEREO_MATCHER_BUDGET: usize = 96 << 10;

const _: () = assert!(KITTI_STEREO_MATCHER_BYTES <= KITTI_STEREO_MATCHER_BUDGET);

/// The matcher the localiser uses: [`MAX_FRAME_HEIGHT`] rows, 2048 key points per side (the row
/// entries do not grow with the frame: a key point spans the same rows at any frame size).
pub type FrameStereoMatcher =
    StereoMatcher<KITTI_MAX_FEATURES, MAX_FRAME_HEIGHT, KITTI_STEREO_MAX_ENTRIES>;

impl<const MAX_KP: usize, const MAX_ROWS: usize, const MAX_ENTRIES: usize> Default
    for StereoMatcher<MAX_KP, MAX_ROWS, MAX_ENTRIES>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<const MAX_KP: usize, const MAX_ROWS: usize, const MAX_ENTRIES: usize>
    StereoMatcher<MAX_KP, MAX_ROWS, MAX_ENTRIES>
{
    /// Right key-point indices are stored as `u16`; row offsets as `u32`.
    const CAPACITIES_FIT: () = assert!(
        MAX_KP <= 1 << 16 && MAX_ENTRIES <= u32::MAX as usize,
        "StereoMatcher: MAX_KP must be ≤ 65536 and MAX_ENTRIES < 2³²"
    );

    /// A zeroed matcher (`const`: it can initialise a `static`).
    pub const fn new() -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::CAPACITIES_FIT;
        Self {
            row_end: [0; MAX_ROWS],
            cursor: [0; MAX_ROWS],
            entries: [0; MAX_ENTRIES],
            matches: [(0, 0); MAX_KP],
            sad_rows: [0; SAD_ROWS_BYTES],
        }
    }

    /// Matches the left features against the right ones and writes one [`Feature`] per left
    /// key point (same order) into `out`, with `ur`/`depth_m` set on stereo matches (`ur = −1`,
    /// `depth_m = 0` otherwise) and `out.timestamp_s = timestamp_s`.
    ///
    /// `left_pyr`/`right_pyr` are the (unblurred) pyramids the features were extracted from,
    /// e.g. [`crate::orb::OrbExtractor::pyramid`] of two extractors. On error `out` is left
    /// empty.
    #[allow(clippy::too_many_arguments)]
    pub fn match_frame<const W: usize, const P: usize, const N: usize>(
        &mut self,
        left: &Features<N>,
        left_pyr: &Pyramid<W, P>,
        right: &Features<N>,
        right_pyr: &Pyramid<W, P>,
        params: &StereoParams,
        timestamp_s: f64,
        out: &mut Frame,
    ) -> Result<StereoStats, StereoError> {
        out.features.clear();
        out.timestamp_s = timestamp_s;
        let rows = validate::<MAX_KP, MAX_ROWS, W, P, N>(left, left_pyr, right, right_pyr, params)?;
        let n_levels = left_pyr.n_levels();
        let mut stats = StereoStats {
            left: left.len() as u32,
            right: right.len() as u32,
            ..StereoStats::default()
        };

        stats.row_overflow = self.build_row_index(right.keypoints(), left_pyr, rows);

        let min_d = 0.0f32;
        let max_d = params.bf_px_m / params.baseline_m;
        let mut n_matches = 0usize;
        for (il, (kl, dl)) in left.keypoints().iter().zip(left.descriptors()).enumerate() {
            let mut feat = Feature {
                x: kl.x,
                y: kl.y,
                level: kl.level,
                angle: kl.angle_deg * (core::f32::consts::PI / 180.0),
                desc: dl.0,
                ur: -1.0,
                depth_m: 0.0,
                class: crate::seg::VOID,
            };
            let level = usize::from(kl.level);
            let (u_l, v_l) = (kl.x, kl.y);
            // `!(a >= b)` also catches NaN.
            let row_ok = v_l >= 0.0 && (v_l as usize) < rows;
            if level >= n_levels || !row_ok || !u_l.is_finite() {
                stats.invalid += 1;
                push(out, feat);
                continue;
            }
            let Some(best_r) = self.best_candidate(
                kl,
                dl,
                right,
                v_l as usize,
                (u_l - max_d, u_l - min_d),
                params.max_hamming,
            ) else {
                push(out, feat);
                continue;
            };
            stats.descriptor_matched += 1;
            let Some(kr) = right.keypoints().get(best_r) else {
                push(out, feat);
                continue;
            };
            let info = left_pyr.info(level);
            let refined = sad_refine(
                &left_pyr.level(level),
                &right_pyr.level(level),
                &info,
                u_l,
                v_l,
                kr.x,
                params.sad_half_window,
                params.sad_search,
                &mut self.sad_rows,
            );
            match refined {
                Err(Reject::Window) => stats.rejected_window += 1,
                Err(Reject::Border) => stats.rejected_sad_border += 1,
                Err(Reject::Parabola) => stats.rejected_parabola += 1,
                Ok((mut best_ur, dist)) => {
                    let mut disparity = u_l - best_ur;
                    if disparity >= min_d && disparity < max_d {
                        if disparity <= 0.0 {
                            disparity = 0.01;
                            best_ur = u_l - 0.01;
                        }
                        feat.depth_m = params.bf_px_m / disparity;
                        feat.ur = best_ur;
                        if let Some(m) = self.matches.get_mut(n_matches) {
                            *m = (dist, il as u16);
                            n_matches += 1;
                        }
                    } else {
                        stats.rejected_disparity += 1;
                    }
                }
            }
            push(out, feat);
        }

        let matches = &mut self.matches[..n_matches];
        let (median, rejected) = median_reject(matches);
        stats.median_sad = median;
        for &(_, il) in rejected.iter() {
            if let Some(f) = out.features.get_mut(usize::from(il)) {
                f.ur = -1.0;
                f.depth_m = 0.0;
            }
        }
        stats.rejected_median = rejected.len() as u32;
        stats.matched = (n_matches - rejected.len()) as u32;
        Ok(stats)
    }

    /// Builds the CSR row index of the right key points over `rows` level-0 rows; returns the
    /// number of entries dropped for lack of room.
    fn build_row_index<const W: usize, const P: usize>(
        &mut self,
        right: &[KeyPoint],
        pyr: &Pyramid<W, P>,
        rows: usize,
    ) -> u32 {
        let counts = &mut self.cursor[..rows];
        counts.fill(0);
        for kp in right {
            if let Some((r0, r1)) = row_span(kp, pyr, rows) {
                for c in &mut counts[r0..=r1] {
                    *c += 1;
                }
            }
        }
        // Prefix sums, clamped to the capacity: the rows that do not fit lose their tail.
        let mut total = 0u64;
        let mut end = 0u32;
        for (c, e) in counts.iter_mut().zip(self.row_end[..rows].iter_mut()) {
            total += u64::from(*c);
            let start = end;
            end = (u64::from(end) + u64::from(*c)).min(MAX_ENTRIES as u64) as u32;
            *e = end;
            *c = start;
        }
        for (i, kp) in right.iter().enumerate() {
            if let Some((r0, r1)) = row_span(kp, pyr, rows) {
                for r in r0..=r1 {
                    let cur = self.cursor[r];
                    if cur < self.row_end[r] {
                        if let Some(slot) = self.entries.get_mut(cur as usize) {
                            *slot = i as u16;
                        }
                        self.cursor[r] = cur + 1;
                    }
                }
            }
        }
        (total - u64::from(end)).min(u64::from(u32::MAX)) as u32
    }

    /// The right key point on `row` with the smallest Hamming distance to `(kl, dl)` among
    /// those on levels `level ± 1` with `u_R` in `u_range` (inclusive), if below `max_hamming`.
    fn best_candidate<const N: usize>(
        &self,
        kl: &KeyPoint,
        dl: &Descriptor,
        right: &Features<N>,
        row: usize,
        u_range: (f32, f32),
        max_hamming: u32,
    ) -> Option<usize> {
        let (min_u, max_u) = u_range;
        if max_u < 0.0 {
            return None;
        }
        let start = if row == 0 { 0 } else { *self.row_end.get(row - 1)? as usize };
        let end = *self.row_end.get(row)? as usize;
        let cands = self.entries.get(start..end)?;
        let (kps, descs) = (right.keypoints(), right.descriptors());
        let level = i32::from(kl.level);
        let mut best = (u32::MAX, usize::MAX);
        for &ir in cands {
            let ir = usize::from(ir);
            let (Some(kr), Some(dr)) = (kps.get(ir), descs.get(ir)) else { continue };
            if (i32::from(kr.level) - level).abs() > 1 {
                continue;
            }
            if kr.x >= min_u && kr.x <= max_u {
                let d = hamming(dl, dr);
                if d < best.0 {
                    best = (d, ir);
                }
            }
        }
        (best.0 < max_hamming).then_some(best.1)
    }
}

/// Checks parameters, pyramids and key-point counts; returns the level-0 row count.
fn validate<
    const MAX_KP: usize,
    const MAX_ROWS: usize,
    const W: usize,
    const P: usize,
    const N: usize,
>(
    left: &Features<N>,
    left_pyr: &Pyramid<W, P>,
    right: &Features<N>,
    right_pyr: &Pyramid<W, P>,
    params: &StereoParams,
) -> Result<usize, StereoError> {
    let (bf, b) = (params.bf_px_m, params.baseline_m);
    if !(bf.is_finite() && bf > 0.0 && b.is_finite() && b > 0.0) {
        return Err(StereoError::BadCalibration { bf_px_m: bf, baseline_m: b });
    }
    StereoMatching {
        max_hamming: params.max_hamming,
        sad_half_window: params.sad_half_window,
        sad_search: params.sad_search,
    }
    .check()?;
    let n_levels = left_pyr.n_levels();
    if n_levels != right_pyr.n_levels() {
        return Err(StereoError::LevelCountMismatch {
            left: n_levels,
            right: right_pyr.n_levels(),
        });
    }
    if n_levels == 0 {
        return Err(StereoError::EmptyPyramid);
    }
    for level in 0..n_levels {
        let (a, c) = (left_pyr.info(level), right_pyr.info(level));
        if a.width != c.width || a.height != c.height {
            return Err(StereoError::SizeMismatch { level });
        }
    }
    let rows = left_pyr.info(0).height;
    if rows > MAX_ROWS {
        return Err(StereoError::TooManyRows { rows, cap: MAX_ROWS });
    }
    let cap = MAX_KP.min(FRAME_CAPACITY);
    for got in [left.len(), right.len()] {
        if got > cap {
            return Err(StereoError::TooManyKeypoints { got, cap });
        }
    }
    Ok(rows)
}

/// Pushes into a frame whose capacity was checked by `validate`.
#[inline]
fn push(out: &mut Frame, f: Feature) {
    // `validate` bounds the key points by FRAME_CAPACITY: this cannot fail.
    let _ = out.features.push(f);
}

/// Level-0 rows `⌊y − r⌋ ..= ⌈y + r⌉` (clamped to the image), `r = 2·sˡᵉᵛᵉˡ`, of a right key
/// point; `None` for an invalid level or a span outside the image.
fn row_span<const W: usize, const P: usize>(
    kp: &KeyPoint,
    pyr: &Pyramid<W, P>,
    rows: usize,
) -> Option<(usize, usize)> {
    let level = usize::from(kp.level);
    if level >= pyr.n_levels() || rows == 0 || !kp.y.is_finite() {
        return None;
    }
    let r = 2.0 * pyr.info(level).scale;
    // `as` saturates; ceil(x) = −floor(−x).
    let lo = math::floorf(kp.y - r) as i64;
    let hi = -math::floorf(-(kp.y + r)) as i64;
    let last = rows as i64 - 1;
    if hi < 0 || lo > last {
        return None;
    }
    Some((lo.max(0) as usize, hi.min(last) as usize))
}

/// SAD refinement of a descriptor match on one pyramid level (see the module docs): the
/// refined level-0 `u_R` and the best SAD distance.
#[allow(clippy::too_many_arguments)]
fn sad_refine(
    img_l: &ImageView<'_>,
    img_r: &ImageView<'_>,
    info: &LevelInfo,
    u_l: f32,
    v_l: f32,
    u_r0: f32,
    half_window: usize,
    search: i32,
    rows: &mut [u8; SAD_ROWS_BYTES],
) -> Result<(f32, u32), Reject> {
    let w = half_window.min(MAX_SAD_HALF_WINDOW) as i64;
    let big_l = i64::from(search.clamp(1, MAX_SAD_SEARCH));
    let inv = info.inv_scale;
    if !(u_l.is_finite() && v_l.is_finite() && u_r0.is_finite()) {
        return Err(Reject::Window);
    }
    // Clamped so the bound checks below cannot overflow (`as` saturates).
    let px = |x: f32| (math::roundf(x * inv) as i64).clamp(-(1 << 40), 1 << 40);
    let (su_l, sv_l, su_r0) = (px(u_l), px(v_l), px(u_r0));
    let (width, height) = (img_l.width() as i64, img_l.height() as i64);
    if img_r.width() as i64 != width || img_r.height() as i64 != height {
        return Err(Reject::Window);
    }
    if sv_l - w < 0
        || sv_l + w >= height
        || su_l - w < 0
        || su_l + w >= width
        || su_r0 - big_l - w < 0
        || su_r0 + big_l + w >= width
    {
        return Err(Reject::Window);
    }
    // All indices below are inside the level: checked just above.
    let side = (2 * w + 1) as usize;
    let (x0_l, y0) = ((su_l - w) as usize, (sv_l - w) as usize);
    let centre_l = i32::from(img_l.row(sv_l as usize)[su_l as usize]);
    let mut patch = [0i32; MAX_PATCH];
    for (dy, prow) in patch.chunks_exact_mut(side).take(side).enumerate() {
        let src = &img_l.row(y0 + dy)[x0_l..x0_l + side];
        for (p, &s) in prow.iter_mut().zip(src) {
            *p = i32::from(s) - centre_l;
        }
    }
    // The SAD of every shift `inc` in `-L..=L` (index `k = inc + L`), accumulated for
    // `SAD_LANES` shifts at a time: for each patch pixel, one pass over the lanes reads a
    // contiguous run of the right row, which vectorises (through `arch::v3`). The rows are
    // copied into a zero-padded buffer so every run is a whole block; lanes past the last shift
    // are computed and ignored (`rows` is the caller's buffer, so the padding holds whatever
    // an earlier call left there). Integer sums: any order gives the same values.
    let n_inc = (2 * big_l + 1) as usize;
    let blocks = n_inc.div_ceil(SAD_LANES);
    let stride = blocks * SAD_LANES + side - 1;
    let x0_r = (su_r0 - big_l - w) as usize;
    for (dy, dst) in rows.chunks_exact_mut(stride).take(side).enumerate() {
        dst[..n_inc + side - 1].copy_from_slice(&img_r.row(y0 + dy)[x0_r..][..n_inc + side - 1]);
    }
    let mut centre_r = [0i32; MAX_DISTS_PADDED];
    let centre_row = &img_r.row(sv_l as usize)[x0_r + side / 2..][..n_inc];
    for (c, &s) in centre_r.iter_mut().zip(centre_row) {
        *c = i32::from(s);
    }
    let mut dists = [0u32; MAX_DISTS_PADDED];
    crate::arch::v3(
        #[inline(always)]
        || {
            for b in 0..blocks {
                let o = b * SAD_LANES;
                let c: [i32; SAD_LANES] = centre_r[o..o + SAD_LANES].try_into().unwrap_or_default();
                let mut acc = [0u32; SAD_LANES];
                for (dy, prow) in patch.chunks_exact(side).take(side).enumerate() {
                    let row = &rows[dy * stride + o..];
                    for (dx, &p) in prow.iter().enumerate() {
                        let run: [u8; SAD_LANES] =
                            row[dx..dx + SAD_LANES].try_into().unwrap_or_default();
                        for l in 0..SAD_LANES {
                            acc[l] += (i32::from(run[l]) - c[l] - p).unsigned_abs();
                        }
                    }
                }
                dists[o..o + SAD_LANES].copy_from_slice(&acc);
            }
        },
    );
    let mut best = (u32::MAX, 0i64);
    for inc in -big_l..=big_l {
        let dist = dists[(inc + big_l) as usize];
        if dist < best.0 {
            best = (dist, inc);
        }
    }
    let (best_dist, best_inc) = best;
    if best_inc == -big_l || best_inc == big_l {
        return Err(Reject::Border);
    }
    let k = (best_inc + big_l) as usize;
    let (d1, d2, d3) = (dists[k - 1] as f32, dists[k] as f32, dists[k + 1] as f32);
    let delta = parabola_offset(d1, d2, d3).ok_or(Reject::Parabola)?;
    let best_ur = info.scale * (su_r0 as f32 + best_inc as f32 + delta);
    Ok((best_ur, best_dist))
}

/// Vertex offset of the parabola through `(−1, d1), (0, d2), (1, d3)`, ORB-SLAM2's
/// `(d1 − d3) / (2(d1 + d3 − 2d2))`; `None` when `|Δ| > 1` or undefined.
#[inline]
fn parabola_offset(d1: f32, d2: f32, d3: f32) -> Option<f32> {
    let delta = (d1 - d3) / (2.0 * (d1 + d3 - 2.0 * d2));
    (-1.0..=1.0).contains(&delta).then_some(delta)
}

/// Sorts `(distance, index)` matches and returns the median distance and the tail whose
/// distance exceeds `1.5 · 1.4 · median` (ORB-SLAM2's rule, strict; see the module docs).
fn median_reject(matches: &mut [(u32, u16)]) -> (u32, &[(u32, u16)]) {
    if matches.is_empty() {
        return (0, &[]);
    }
    matches.sort_unstable();
    let median = matches[matches.len() / 2].0;
    let th = 1.5f32 * 1.4f32 * median as f32;
    let keep = matches.partition_point(|&(d, _)| d as f32 <= th);
    (median, &matches[keep..])
}

#[cfg(test)]
mod tests;
