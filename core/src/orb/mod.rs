//! ORB feature extraction as ORB-SLAM2's `ORBextractor`, in fixed memory (paper: "ORB as in
//! ORB-SLAM2" front end; Rublee et al. 2011; Mur-Artal & Tardós 2017 §III).
//!
//! Per frame: an 8-level pyramid with scale 1.2 ([`pyramid`]); per level, FAST-9 in a grid of
//! 30-px cells with ORB-SLAM2's adaptive threshold (`iniThFAST` 20, cells without a corner
//! retried at `minThFAST` 7) and non-maximum suppression ([`fast`]); a Harris response
//! ([`harris`]) multiplied by the optional semantic weight `ω(x, y)` ([`WeightMap`]; `ω = 0`
//! drops the candidate before it costs anything more); the quadtree ([`quadtree`]) keeps the
//! best candidate of up to the level's quota of cells; intensity-centroid orientation and
//! steered rBRIEF on the 7×7 σ=2 blurred level ([`brief`]); coordinates scaled to level 0.
//!
//! **Per-level quota.** `Nᵢ = N(1 − f)/(1 − fᵐ)·fⁱ` rounded, with the remainder on the last
//! level. ORB-SLAM2's code uses `f = 1/s` ([`QuotaRule::OrbSlam2`], the default); the ORB-SLAM
//! papers describe the number of features as proportional to the level's *area*, `f = 1/s²`
//! ([`QuotaRule::Area`]). With `N = 2000, s = 1.2, m = 8` the first gives 434 features at level 0,
//! the second 646.
//!
//! **Where this differs from ORB-SLAM2, and why:**
//! - Candidates are ranked by the Harris response (OpenCV ORB's `HARRIS_SCORE`), not by the FAST
//!   score ORB-SLAM2 keeps: Harris separates corners from edges, and it is the quantity the
//!   semantic weight multiplies.
//! - Non-maximum suppression runs over the whole level, not inside each FAST cell (ORB-SLAM2
//!   can keep two adjacent corners on either side of a cell seam). A cell falls back to
//!   `minThFAST` when it has no raw corner at `iniThFAST` (ORB-SLAM2: no corner after its
//!   per-cell suppression; the same except for exact score ties).
//! - Angles use libm's `atan2f` (OpenCV's `fastAtan2` is accurate to ~0.3°), pixel rounding is
//!   half away from zero (OpenCV: half to even), and the blur and resize are fixed-point. None of
//!   this changes the algorithm; all of it makes the output bit-identical on every target.
//!
//! **Memory.** [`OrbExtractor`] owns everything it uses: the pyramid, one level-sized scratch
//! (the FAST score map, then the blurred level), candidates, quadtree nodes, and the output.
//! Capacities are const generics; the configuration and frame size are checked against them
//! and an over-capacity frame is an error, over-capacity candidates or features are dropped
//! weakest-first and counted in [`ExtractorStats`]. [`KittiOrbExtractor`] (1248 × 384, 2048
//! features) takes [`KITTI_EXTRACTOR_BYTES`] bytes (budget [`KITTI_EXTRACTOR_BUDGET`]); it has a
//! `const fn new`, so on the ECU it lives in a `static`, never on a stack.
//!
//! ```
//! use semloc_core::image::ImageView;
//! use semloc_core::orb::{OrbConfig, OrbExtractor, pyramid_capacity};
//!
//! // A small extractor for 160 × 120 frames, 256 features (lives in a static on a target).
//! type Ext = OrbExtractor<160, { 160 * 120 }, { pyramid_capacity(160, 120, 8) }, 256, 4096>;
//! let mut ext = Box::new(Ext::new());
//! ext.configure(OrbConfig { n_features: 200, ..OrbConfig::KITTI }).unwrap();
//! let pixels: Vec<u8> = (0..160 * 120).map(|i| ((i * 7919) % 251) as u8).collect();
//! let frame = ImageView::from_slice(&pixels, 160, 120).unwrap();
//! let features = ext.extract(&frame).unwrap();
//! assert_eq!(features.keypoints().len(), features.descriptors().len());
//! ```

pub mod brief;
pub mod fast;
pub mod harris;
pub mod pattern;
pub mod pyramid;
pub mod quadtree;

use core::fmt;

pub use brief::{hamming, Descriptor, HALF_PATCH_SIZE, PATCH_SIZE};
pub use pyramid::{level_geometry, pyramid_capacity, LevelInfo, Pyramid, MAX_LEVELS};
pub use quadtree::Candidate;

use crate::image::{gaussian_blur_7x7, BlurScratch, ImageError, ImageView, ImageViewMut};
use quadtree::QuadTree;

/// Margin (px) kept free of key points at every level, so the rotated rBRIEF pattern (radius
/// ≤ 18.4) and the blur never leave the image (ORB-SLAM2's `EDGE_THRESHOLD`).
pub const EDGE_THRESHOLD: usize = 19;
/// Side of ORB-SLAM2's FAST cells at every level.
pub const FAST_CELL_SIZE: usize = 30;
/// Most FAST cells one level may have (1248 × 384 needs 40 × 11).
pub const MAX_CELLS: usize = 4096;

/// How the feature budget is split over the levels (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "lowercase"))]
pub enum QuotaRule {
    /// ORB-SLAM2's code: geometric with ratio `1/s`.
    OrbSlam2,
    /// Proportional to level area: ratio `1/s²` (the papers' description).
    Area,
}

/// Extraction parameters (ORB-SLAM2's `ORBextractor.*` settings).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(default, deny_unknown_fields))]
pub struct OrbConfig {
    /// Features per frame over all levels (`nFeatures`).
    pub n_features: usize,
    /// Scale between consecutive levels (`scaleFactor`), > 1.
    pub scale_factor: f32,
    /// Pyramid levels (`nLevels`), 1..=[`MAX_LEVELS`].
    pub n_levels: usize,
    /// FAST threshold tried first in every cell (`iniThFAST`).
    pub ini_th_fast: u8,
    /// FAST threshold for cells with no corner at `ini_th_fast` (`minThFAST`).
    pub min_th_fast: u8,
    /// Per-level quota rule.
    pub quota_rule: QuotaRule,
    /// Semantic ORB (Eq. 2): the Harris weight of construction and object classes relative to
    /// the other static classes, in [`MIN_STRUCTURE_GAIN`]..=[`MAX_STRUCTURE_GAIN`] (the paper:
    /// [`PAPER_STRUCTURE_GAIN`], ×3). Used by the semantic schemes that weight classes
    /// ([`crate::seg::WeightScheme::Full`] and [`crate::seg::WeightScheme::Motion`]); 1 weights
    /// every static class alike.
    pub structure_gain: f32,
}

/// The paper's Harris weight of construction and object classes (×3, Eq. 2).
pub const PAPER_STRUCTURE_GAIN: f32 = 3.0;
/// Smallest [`OrbConfig::structure_gain`]: every static class alike.
pub const MIN_STRUCTURE_GAIN: f32 = 1.0;
/// Largest [`OrbConfig::structure_gain`] (the other static classes keep a weight-image value of
/// at least 16 of 255).
pub const MAX_STRUCTURE_GAIN: f32 = 16.0;

impl OrbConfig {
    /// ORB-SLAM2's KITTI settings (`KITTI00-02.yaml`): 2000 features, 1.2, 8 levels, 20/7.
    pub const KITTI: OrbConfig = OrbConfig {
        n_features: 2000,
        scale_factor: 1.2,
        n_levels: 8,
        ini_th_fast: 20,
        min_th_fast: 7,
        quota_rule: QuotaRule::OrbSlam2,
        structure_gain: PAPER_STRUCTURE_GAIN,
    };

    /// Checks every parameter for an extractor that holds at most `max_features` features
    /// ([`OrbExtractor::configure`] uses its `MAX_KP`; a settings file can check against
    /// [`KITTI_MAX_FEATURES`] before any extractor exists). The error names the field
    /// ([`OrbError::config_field`]).
    ///
    /// # Errors
    /// The first of [`OrbError::BadFeatureCount`], [`OrbError::BadLevelCount`],
    /// [`OrbError::BadScaleFactor`], [`OrbError::BadThresholds`] and
    /// [`OrbError::BadStructureGain`] that applies.
    pub fn check(&self, max_features: usize) -> Result<(), OrbError> {
        if self.n_features == 0 || self.n_features > max_features {
            return Err(OrbError::BadFeatureCount {
                requested: self.n_features,
                cap: max_features,
            });
        }
        if self.n_levels == 0 || self.n_levels > MAX_LEVELS {
            return Err(OrbError::BadLevelCount { requested: self.n_levels });
        }
        if !(self.scale_factor.is_finite() && self.scale_factor > 1.0) {
            return Err(OrbError::BadScaleFactor { value: self.scale_factor });
        }
        if self.min_th_fast == 0 || self.min_th_fast > self.ini_th_fast {
            return Err(OrbError::BadThresholds { ini: self.ini_th_fast, min: self.min_th_fast });
        }
        if !(MIN_STRUCTURE_GAIN..=MAX_STRUCTURE_GAIN).contains(&self.structure_gain) {
            return Err(OrbError::BadStructureGain { value: self.structure_gain });
        }
        Ok(())
    }

    /// Feature quota of each level (entries past `n_levels` are 0); they sum to `n_features`.
    pub fn level_quotas(&self) -> [usize; MAX_LEVELS] {
        level_quotas(self.n_features, self.scale_factor, self.n_levels, self.quota_rule)
    }
}

impl Default for OrbConfig {
    fn default() -> Self {
        Self::KITTI
    }
}

/// `Nᵢ = round(N(1 − f)/(1 − fᵐ)·fⁱ)` for `i < m − 1` and the remainder on level `m − 1`, as
/// ORB-SLAM2's constructor computes it (`f` per [`QuotaRule`]), except that a level never takes
/// more than what is left, so the quotas always sum to `N` (ORB-SLAM2 can overshoot by the
/// rounding when `N` is tiny).
pub fn level_quotas(
    n_features: usize,
    scale_factor: f32,
    n_levels: usize,
    rule: QuotaRule,
) -> [usize; MAX_LEVELS] {
    let mut q = [0usize; MAX_LEVELS];
    let m = n_levels.min(MAX_LEVELS);
    if m == 0 {
        return q;
    }
    let mut f = 1.0 / scale_factor;
    if rule == QuotaRule::Area {
        f *= f;
    }
    let mut fm = 1.0f64;
    for _ in 0..m {
        fm *= f64::from(f);
    }
    let mut desired = n_features as f32 * (1.0 - f) / (1.0 - fm as f32);
    let mut sum = 0usize;
    for qi in q.iter_mut().take(m - 1) {
        // ORB-SLAM2 does not cap here, so for tiny N its rounding can overshoot N.
        *qi = (crate::image::round_i32(desired).max(0) as usize).min(n_features - sum);
        sum += *qi;
        desired *= f;
    }
    q[m - 1] = n_features.saturating_sub(sum);
    q
}

/// A key point in level-0 pixel coordinates.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct KeyPoint {
    /// Column at level 0 (px): level column × `scale_factorˡᵉᵛᵉˡ`.
    pub x: f32,
    /// Row at level 0 (px).
    pub y: f32,
    /// Pyramid level it was detected on (ORB-SLAM2's `octave`).
    pub level: u8,
    /// Orientation in degrees, `[0, 360)`, image axes (x right, y down).
    pub angle_deg: f32,
    /// Harris response × semantic weight; larger is stronger.
    pub response: f32,
    /// Diameter of the described patch at level 0 (px): `⌊31 · scaleˡᵉᵛᵉˡ⌋`.
    pub size: f32,
}

/// What happened on one pyramid level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LevelStats {
    /// Level width (px).
    pub width: u16,
    /// Level height (px).
    pub height: u16,
    /// Feature quota of the level.
    pub quota: u16,
    /// FAST cells of the level.
    pub cells: u16,
    /// Cells that fell back to `min_th_fast`.
    pub low_threshold_cells: u16,
    /// FAST corners after non-maximum suppression.
    pub fast_corners: u32,
    /// Corners dropped because their weight was 0.
    pub weight_dropped: u32,
    /// Corners dropped (weakest first) because the candidate storage was full.
    pub candidates_dropped: u32,
    /// Candidates handed to the quadtree.
    pub candidates: u32,
    /// Key points the quadtree selected (may exceed the quota by up to 3, as in ORB-SLAM2).
    pub selected: u16,
    /// Key points lost because quadtree node storage or the level buffer was full.
    pub selection_overflow: u16,
}

/// Counters of one extraction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ExtractorStats {
    /// Per-level counters; entries past `n_levels` are zero.
    pub levels: [LevelStats; MAX_LEVELS],
    /// Levels processed (fewer than configured when upper levels are too small to hold a
    /// key point, as in ORB-SLAM2).
    pub n_levels: u8,
    /// Key points dropped (weakest first) because the output was full.
    pub output_dropped: u32,
}

impl ExtractorStats {
    const EMPTY: ExtractorStats =
        ExtractorStats { levels: [LEVEL_STATS_ZERO; MAX_LEVELS], n_levels: 0, output_dropped: 0 };

    /// Per-level counters of the processed levels.
    pub fn levels(&self) -> &[LevelStats] {
        &self.levels[..usize::from(self.n_levels)]
    }
}

const LEVEL_STATS_ZERO: LevelStats = LevelStats {
    width: 0,
    height: 0,
    quota: 0,
    cells: 0,
    low_threshold_cells: 0,
    fast_corners: 0,
    weight_dropped: 0,
    candidates_dropped: 0,
    candidates: 0,
    selected: 0,
    selection_overflow: 0,
};

impl Default for ExtractorStats {
    fn default() -> Self {
        Self::EMPTY
    }
}

/// Per-pixel weights `ω ∈ [0, 1]` that multiply the Harris response before selection — the
/// hook for semantics (`ω = 0` on dynamic classes drops those corners before they are
/// described). Evaluated at level-0 pixel coordinates.
pub trait WeightMap {
    /// Weight at level-0 position `(x, y)`; `<= 0` drops the candidate.
    fn weight(&self, x: f32, y: f32) -> f32;
}

/// Every weight is 1 (plain ORB).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoWeights;

impl WeightMap for NoWeights {
    #[inline]
    fn weight(&self, _x: f32, _y: f32) -> f32 {
        1.0
    }
}

/// A level-0-sized `u8` map: `ω = value / 255`, nearest pixel (coordinates truncated, clamped
/// to the map).
impl WeightMap for ImageView<'_> {
    #[inline]
    fn weight(&self, x: f32, y: f32) -> f32 {
        if self.width() == 0 || self.height() == 0 {
            return 1.0;
        }
        let xi = (x.max(0.0) as usize).min(self.width() - 1);
        let yi = (y.max(0.0) as usize).min(self.height() - 1);
        f32::from(self.get(xi, yi)) * (1.0 / 255.0)
    }
}

/// A closure `Fn(x, y) -> ω` as a [`WeightMap`].
#[derive(Clone, Copy, Debug)]
pub struct FnWeights<F>(pub F);

impl<F: Fn(f32, f32) -> f32> WeightMap for FnWeights<F> {
    #[inline]
    fn weight(&self, x: f32, y: f32) -> f32 {
        (self.0)(x, y)
    }
}

/// Errors of configuration and extraction.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum OrbError {
    /// `n_features` is 0 or exceeds the output capacity.
    BadFeatureCount {
        /// Requested.
        requested: usize,
        /// Capacity (`MAX_KP`).
        cap: usize,
    },
    /// `n_levels` is 0 or above [`MAX_LEVELS`].
    BadLevelCount {
        /// Requested.
        requested: usize,
    },
    /// `scale_factor` is not a finite number > 1.
    BadScaleFactor {
        /// The value given.
        value: f32,
    },
    /// `structure_gain` is not a number in
    /// [`MIN_STRUCTURE_GAIN`]..=[`MAX_STRUCTURE_GAIN`].
    BadStructureGain {
        /// The value given.
        value: f32,
    },
    /// Thresholds must satisfy `1 <= min_th_fast <= ini_th_fast`.
    BadThresholds {
        /// `ini_th_fast`.
        ini: u8,
        /// `min_th_fast`.
        min: u8,
    },
    /// The frame has more pixels than the level scratch holds, or is too wide.
    FrameTooLarge {
        /// Frame width.
        width: usize,
        /// Frame height.
        height: usize,
    },
    /// A level has more FAST cells than [`MAX_CELLS`].
    TooManyCells {
        /// Cells needed.
        need: usize,
    },
    /// The pyramid could not be built (capacity or geometry).
    Image(ImageError),
}

impl From<ImageError> for OrbError {
    fn from(e: ImageError) -> Self {
        OrbError::Image(e)
    }
}

impl fmt::Display for OrbError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            OrbError::BadFeatureCount { requested, cap } => {
                write!(f, "{requested} features requested, 1..={cap} allowed")
            }
            OrbError::BadLevelCount { requested } => {
                write!(f, "{requested} pyramid levels requested, 1..={MAX_LEVELS} allowed")
            }
            OrbError::BadScaleFactor { value } => {
                write!(f, "scale factor {value} must be finite and > 1")
            }
            OrbError::BadStructureGain { value } => write!(
                f,
                "structure gain {value} is outside {MIN_STRUCTURE_GAIN}..={MAX_STRUCTURE_GAIN}"
            ),
            OrbError::BadThresholds { ini, min } => {
                write!(f, "FAST thresholds need 1 <= min ({min}) <= ini ({ini})")
            }
            OrbError::FrameTooLarge { width, height } => {
                write!(f, "frame {width}x{height} exceeds the extractor's capacity")
            }
            OrbError::TooManyCells { need } => {
                write!(f, "{need} FAST cells needed, at most {MAX_CELLS}")
            }
            OrbError::Image(e) => write!(f, "pyramid: {e}"),
        }
    }
}

impl core::error::Error for OrbError {}

impl OrbError {
    /// The [`OrbConfig`] field a configuration error is about (`"n_features"`, ...); `None` for
    /// errors of a frame.
    pub fn config_field(&self) -> Option<&'static str> {
        match self {
            OrbError::BadFeatureCount { .. } => Some("n_features"),
            OrbError::BadLevelCount { .. } => Some("n_levels"),
            OrbError::BadScaleFactor { .. } => Some("scale_factor"),
            OrbError::BadStructureGain { .. } => Some("structure_gain"),
            OrbError::BadThresholds { .. } => Some("min_th_fast"),
            OrbError::FrameTooLarge { .. } | OrbError::TooManyCells { .. } | OrbError::Image(_) => {
                None
            }
        }
    }
}

/// Key points and their descriptors (index-aligned), grouped by level in increasing order
/// unless output overflow replaced weak points, plus the counters of the extraction.
#[derive(Clone, Debug)]
pub struct Features<const N: usize> {
    keypoints: heapless::Vec<KeyPoint, N>,
    descriptors: heapless::Vec<Descriptor, N>,
    stats: ExtractorStats,
}

impl<const N: usize> Default for Features<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Features<N> {
    /// Empty (`const`).
    pub const fn new() -> Self {
        Self {
            keypoints: heapless::Vec::new(),
            descriptors: heapless::Vec::new(),
            stats: ExtractorStats::EMPTY,
        }
    }

    /// Key points, level-0 coordinates.
    pub fn keypoints(&self) -> &[KeyPoint] {
        &self.keypoints
    }

    /// Descriptors, `descriptors()[i]` belongs to `keypoints()[i]`.
    pub fn descriptors(&self) -> &[Descriptor] {
        &self.descriptors
    }

    /// Number of features.
    pub fn len(&self) -> usize {
        self.keypoints.len()
    }

    /// True when no feature was found.
    pub fn is_empty(&self) -> bool {
        self.keypoints.is_empty()
    }

    /// Counters of the extraction that produced these features.
    pub fn stats(&self) -> &ExtractorStats {
        &self.stats
    }

    fn clear(&mut self) {
        self.keypoints.clear();
        self.descriptors.clear();
        self.stats = ExtractorStats::EMPTY;
    }

    /// Appends, or when full replaces the weakest feature if `kp` is stronger; either way a
    /// full output counts one drop.
    fn push_or_replace_weakest(&mut self, kp: KeyPoint, d: Descriptor) {
        if self.keypoints.len() < N {
            // Both vectors have the same length and capacity: neither push can fail.
            let _ = self.keypoints.push(kp);
            let _ = self.descriptors.push(d);
            return;
        }
        self.stats.output_dropped += 1;
        let mut weakest: Option<usize> = None;
        for (i, k) in self.keypoints.iter().enumerate() {
            if weakest.is_none_or(|w| k.response < self.keypoints[w].response) {
                weakest = Some(i);
            }
        }
        if let Some(w) = weakest {
            if kp.response > self.keypoints[w].response {
                self.keypoints[w] = kp;
                self.descriptors[w] = d;
            }
        }
    }
}

/// The ORB extractor: all working memory for frames up to `MAX_W` wide and `MAX_PIX` pixels,
/// a pyramid of `PYR_PIX` pixels in total, `MAX_KP` output features and `MAX_CAND` candidates
/// per level.
///
/// Construct with the `const fn` [`OrbExtractor::new`] into a `static` (on a target) or a
/// `Box` (host); configure once with [`OrbExtractor::configure`]; then call
/// [`OrbExtractor::extract`] per frame. Results live in the extractor until the next frame.
#[derive(Clone, Debug)]
pub struct OrbExtractor<
    const MAX_W: usize,
    const MAX_PIX: usize,
    const PYR_PIX: usize,
    const MAX_KP: usize,
    const MAX_CAND: usize,
> {
    config: OrbConfig,
    quotas: [usize; MAX_LEVELS],
    pyramid: Pyramid<MAX_W, PYR_PIX>,
    /// FAST score map of the current level, then its blurred copy.
    scratch: [u8; MAX_PIX],
    flags: [u8; MAX_W],
    blur: BlurScratch<MAX_W>,
    cells: [u8; MAX_CELLS],
    cands: [Candidate; MAX_CAND],
    quadtree: QuadTree<MAX_KP>,
    /// Selected key points of the current level, level coordinates.
    level_kps: heapless::Vec<KeyPoint, MAX_KP>,
    out: Features<MAX_KP>,
}

/// Widest KITTI frame supported by [`KittiOrbExtractor`] (KITTI: 1241 or 1242).
pub const KITTI_MAX_WIDTH: usize = 1248;
/// Tallest KITTI frame supported by [`KittiOrbExtractor`] (KITTI: 375 or 376).
pub const KITTI_MAX_HEIGHT: usize = 384;
/// Output capacity of [`KittiOrbExtractor`] (ORB-SLAM2 asks for 2000 on KITTI).
pub const KITTI_MAX_FEATURES: usize = 2048;
/// Candidate capacity per level of [`KittiOrbExtractor`] (a KITTI frame yields a few thousand
/// FAST corners at level 0).
pub const KITTI_MAX_CANDIDATES: usize = 16384;

/// The extractor sized for KITTI frames: 8 levels at scale ≥ 1.2, up to 1248 × 384.
pub type KittiOrbExtractor = OrbExtractor<
    KITTI_MAX_WIDTH,
    { KITTI_MAX_WIDTH * KITTI_MAX_HEIGHT },
    { pyramid_capacity(KITTI_MAX_WIDTH, KITTI_MAX_HEIGHT, 8) },
    KITTI_MAX_FEATURES,
    KITTI_MAX_CANDIDATES,
>;

/// Widest frame the [`Localiser`](crate::localiser::Localiser) takes: 1920 px, the common
/// automotive 2.3 MP format (1920 × 1200 sensors such as AR0231 and IMX390; 1920 × 1080 fits too).
/// A compile-time maximum: every buffer below is sized for it, so memory stays fixed.
pub const MAX_FRAME_WIDTH: usize = 1920;
/// Tallest frame the [`Localiser`](crate::localiser::Localiser) takes: 1200 px (see
/// [`MAX_FRAME_WIDTH`]). KITTI (1241 × 376), EuRoC (752 × 480) and 1280 × 720 all fit.
pub const MAX_FRAME_HEIGHT: usize = 1200;
/// Candidate capacity per level of [`FrameOrbExtractor`]: [`KITTI_MAX_CANDIDATES`] scaled with
/// the frame area (a 1920 × 1200 level 0 yields up to ≈ 5× KITTI's corners).
pub const FRAME_MAX_CANDIDATES: usize = 65536;

/// The extractor the localiser uses: 8 levels at scale ≥ 1.2 of frames up to
/// [`MAX_FRAME_WIDTH`] × [`MAX_FRAME_HEIGHT`], [`KITTI_MAX_FEATURES`] output features.
pub type FrameOrbExtractor = OrbExtractor<
    MAX_FRAME_WIDTH,
    { MAX_FRAME_WIDTH * MAX_FRAME_HEIGHT },
    { pyramid_capacity(MAX_FRAME_WIDTH, MAX_FRAME_HEIGHT, 8) },
    KITTI_MAX_FEATURES,
    FRAME_MAX_CANDIDATES,
>;

/// `size_of::<FrameOrbExtractor>()`.
pub const FRAME_EXTRACTOR_BYTES: usize = core::mem::size_of::<FrameOrbExtractor>();

/// Memory budget of [`FrameOrbExtractor`]: 10.5 MiB — pyramid (≈ 7.1 MB), one level of scratch
/// (2.3 MB), candidates (0.5 MB), output (0.11 MB), the rest row buffers and nodes.
pub const FRAME_EXTRACTOR_BUDGET: usize = 21 << 19;

const _: () = assert!(FRAME_EXTRACTOR_BYTES <= FRAME_EXTRACTOR_BUDGET);
// The FAST cell grid of the largest level 0 fits the cell buffer.
const _: () = assert!(
    MAX_FRAME_WIDTH.div_ceil(FAST_CELL_SIZE) * MAX_FRAME_HEIGHT.div_ceil(FAST_CELL_SIZE)
        <= MAX_CELLS
);

/// `size_of::<KittiOrbExtractor>()`.
pub const KITTI_EXTRACTOR_BYTES: usize = core::mem::size_of::<KittiOrbExtractor>();

/// Memory budget of [`KittiOrbExtractor`]: 2.5 MiB — pyramid (≈1.49 MB), one level of scratch
/// (0.48 MB), candidates (0.13 MB), output (0.11 MB), the rest row buffers and nodes. ECU-class
/// SoCs targeted (S32G, TDA4, R-Car) have several MiB of on-chip SRAM or DRAM for this.
pub const KITTI_EXTRACTOR_BUDGET: usize = 5 << 19;

const _: () = assert!(KITTI_EXTRACTOR_BYTES <= KITTI_EXTRACTOR_BUDGET);

impl<
        const MAX_W: usize,
        const MAX_PIX: usize,
        const PYR_PIX: usize,
        const MAX_KP: usize,
        const MAX_CAND: usize,
    > Default for OrbExtractor<MAX_W, MAX_PIX, PYR_PIX, MAX_KP, MAX_CAND>
{
    fn default() -> Self {
        Self::new()
    }
}

impl<
        const MAX_W: usize,
        const MAX_PIX: usize,
        const PYR_PIX: usize,
        const MAX_KP: usize,
        const MAX_CAND: usize,
    > OrbExtractor<MAX_W, MAX_PIX, PYR_PIX, MAX_KP, MAX_CAND>
{
    /// A zeroed extractor with [`OrbConfig::KITTI`] (its feature count capped at `MAX_KP`).
    /// `const`, so it can initialise a `static` (all zeros: it costs `.bss`, not flash).
    pub const fn new() -> Self {
        let mut config = OrbConfig::KITTI;
        if config.n_features > MAX_KP {
            config.n_features = MAX_KP;
        }
        Self {
            config,
            quotas: [0; MAX_LEVELS],
            pyramid: Pyramid::new(),
            scratch: [0; MAX_PIX],
            flags: [0; MAX_W],
            blur: BlurScratch::new(),
            cells: [0; MAX_CELLS],
            cands: [Candidate::ZERO; MAX_CAND],
            quadtree: QuadTree::new(),
            level_kps: heapless::Vec::new(),
            out: Features::new(),
        }
    }

    /// Validates `config` against the capacities ([`OrbConfig::check`] with `MAX_KP`) and makes
    /// it current.
    ///
    /// # Errors
    /// [`OrbConfig::check`]'s; the current configuration is kept.
    pub fn configure(&mut self, config: OrbConfig) -> Result<(), OrbError> {
        config.check(MAX_KP)?;
        self.config = config;
        self.quotas = config.level_quotas();
        Ok(())
    }

    /// The current configuration.
    pub fn config(&self) -> &OrbConfig {
        &self.config
    }

    /// The pyramid of the last frame (levels stay valid until the next extraction).
    pub fn pyramid(&self) -> &Pyramid<MAX_W, PYR_PIX> {
        &self.pyramid
    }

    /// The features of the last frame.
    pub fn features(&self) -> &Features<MAX_KP> {
        &self.out
    }

    /// Extracts ORB features from `image` (no semantic weights).
    pub fn extract(&mut self, image: &ImageView<'_>) -> Result<&Features<MAX_KP>, OrbError> {
        self.extract_weighted(image, &NoWeights)
    }

    /// Extracts ORB features from `image`, multiplying each candidate's Harris response by
    /// `weights` at its level-0 position and dropping candidates of weight ≤ 0.
    pub fn extract_weighted<M: WeightMap + ?Sized>(
        &mut self,
        image: &ImageView<'_>,
        weights: &M,
    ) -> Result<&Features<MAX_KP>, OrbError> {
        self.out.clear();
        self.level_kps.clear();
        let (w, h) = (image.width(), image.height());
        if w > MAX_W || w.saturating_mul(h) > MAX_PIX || w > usize::from(u16::MAX) {
            return Err(OrbError::FrameTooLarge { width: w, height: h });
        }
        if self.quotas.iter().all(|&q| q == 0) && self.config.n_features > 0 {
            // `new()` leaves the quotas to the first `configure`; do it implicitly.
            self.configure(self.config)?;
        }
        let cfg = self.config;
        self.pyramid.build(image, cfg.scale_factor, cfg.n_levels)?;

        let Self {
            quotas,
            pyramid,
            scratch,
            flags,
            blur,
            cells,
            cands,
            quadtree,
            level_kps,
            out,
            ..
        } = self;
        let mut n_done = 0;
        for (level, &quota) in quotas.iter().enumerate().take(cfg.n_levels) {
            let info = pyramid.info(level);
            let img = pyramid.level(level);
            let (lw, lh) = (info.width, info.height);
            let stats = &mut out.stats.levels[level];
            stats.width = lw as u16;
            stats.height = lh as u16;
            stats.quota = quota.min(usize::from(u16::MAX)) as u16;
            // ORB-SLAM2: FAST cells span [EDGE−3, size−EDGE+3); corners land in [EDGE, size−EDGE).
            let min_b = (EDGE_THRESHOLD - 3) as i32;
            let (max_bx, max_by) = (lw as i32 - min_b, lh as i32 - min_b);
            if max_bx <= min_b || max_by <= min_b {
                break;
            }
            n_done = level + 1;
            let grid = CellGrid::new(min_b, max_bx, max_by);
            if grid.n_cols * grid.n_rows > MAX_CELLS {
                return Err(OrbError::TooManyCells { need: grid.n_cols * grid.n_rows });
            }
            stats.cells = (grid.n_cols * grid.n_rows) as u16;

            // 1. FAST scores at iniThFAST everywhere, then minThFAST in empty cells.
            let map = &mut scratch[..lw * lh];
            map.fill(0);
            let mut scores = ImageViewMut::from_slice(map, lw, lh)?;
            let cells = &mut cells[..grid.n_cols * grid.n_rows];
            cells.fill(0);
            let (dx0, dx1) = (grid.det_x0, grid.det_x1);
            for y in grid.det_y0..grid.det_y1 {
                let ci = grid.row_of(y) * grid.n_cols;
                fast::score_row(&img, y, dx0..dx1, cfg.ini_th_fast, flags, &mut scores, |x| {
                    cells[ci + grid.col_of(x)] = 1;
                });
            }
            let mut low = 0u16;
            for cy in 0..grid.n_rows {
                for cx in 0..grid.n_cols {
                    if cells[cy * grid.n_cols + cx] != 0 {
                        continue;
                    }
                    let (x0, x1) = grid.col_span(cx);
                    let (y0, y1) = grid.row_span(cy);
                    if x1 <= x0 || y1 <= y0 {
                        continue;
                    }
                    low += 1;
                    for y in y0..y1 {
                        fast::score_row(
                            &img,
                            y,
                            x0..x1,
                            cfg.min_th_fast,
                            flags,
                            &mut scores,
                            |_| {},
                        );
                    }
                }
            }
            stats.low_threshold_cells = low;

            // 2. Non-maximum suppression, weight, Harris; bounded candidate storage.
            let mut n_cand = 0usize;
            let mut cutoff: Option<f32> = None;
            let scale = info.scale;
            let score_view = scores.as_view();
            let mut fast_corners = 0u32;
            let mut weight_dropped = 0u32;
            let mut dropped = 0u32;
            fast::for_each_nms_max(&score_view, dx0, dx1, grid.det_y0, grid.det_y1, |x, y, _s| {
                fast_corners += 1;
                let wgt = weights.weight(x as f32 * scale, y as f32 * scale);
                if wgt.is_nan() || wgt <= 0.0 {
                    weight_dropped += 1;
                    return;
                }
                let mut r = harris::harris_response(&img, x, y);
                if wgt != 1.0 {
                    r *= wgt;
                }
                if cutoff.is_some_and(|c| r <= c) {
                    dropped += 1;
                    return;
                }
                if n_cand == MAX_CAND {
                    // Keep the stronger half; later candidates must beat the weakest kept.
                    let keep = MAX_CAND / 2;
                    cands[..n_cand].sort_unstable_by(cmp_strongest_first);
                    dropped += (n_cand - keep) as u32;
                    n_cand = keep;
                    cutoff =
                        if keep > 0 { Some(cands[keep - 1].response) } else { Some(f32::INFINITY) };
                    if cutoff.is_some_and(|c| r <= c) {
                        dropped += 1;
                        return;
                    }
                }
                cands[n_cand] = Candidate { x: x as u16, y: y as u16, response: r };
                n_cand += 1;
            });
            stats.fast_corners = fast_corners;
            stats.weight_dropped = weight_dropped;
            stats.candidates_dropped = dropped;
            stats.candidates = n_cand as u32;

            // 3. Quadtree selection.
            level_kps.clear();
            let mut overflow = 0u16;
            let outcome = quadtree.distribute(
                &mut cands[..n_cand],
                min_b..max_bx,
                min_b..max_by,
                quota,
                |c| {
                    let kp = KeyPoint {
                        x: f32::from(c.x),
                        y: f32::from(c.y),
                        level: level as u8,
                        angle_deg: 0.0,
                        response: c.response,
                        size: 0.0,
                    };
                    if level_kps.push(kp).is_err() {
                        overflow += 1;
                    }
                },
            );
            if outcome.node_overflow {
                overflow = overflow.saturating_add(1);
            }
            stats.selected = level_kps.len() as u16;
            stats.selection_overflow = overflow;
            if level_kps.is_empty() {
                continue;
            }

            // 4. Orientation on the level, descriptors on its blurred copy; raster order keeps
            // consecutive patches in cache (and makes the output order independent of the
            // quadtree's node order).
            level_kps.sort_unstable_by_key(|k| ((k.y as u32) << 16) | k.x as u32);
            for kp in level_kps.iter_mut() {
                kp.angle_deg = brief::ic_angle(&img, kp.x as usize, kp.y as usize);
            }
            let blurred_buf = &mut scratch[..lw * lh];
            let mut blurred = ImageViewMut::from_slice(blurred_buf, lw, lh)?;
            gaussian_blur_7x7(&img, &mut blurred, blur)?;
            let blurred = blurred.as_view();
            let size = (PATCH_SIZE as f32 * scale) as i32 as f32;
            for kp in level_kps.iter() {
                let d = brief::describe(&blurred, kp.x as usize, kp.y as usize, kp.angle_deg);
                let mut k = *kp;
                if level != 0 {
                    k.x *= scale;
                    k.y *= scale;
                }
                k.size = size;
                out.push_or_replace_weakest(k, d);
            }
        }
        out.stats.n_levels = n_done as u8;
        Ok(&self.out)
    }
}

/// Orders candidates strongest first, ties by position (a total order: deterministic).
fn cmp_strongest_first(a: &Candidate, b: &Candidate) -> core::cmp::Ordering {
    b.response.total_cmp(&a.response).then(a.y.cmp(&b.y)).then(a.x.cmp(&b.x))
}

/// ORB-SLAM2's FAST cell grid of one level.
///
/// Cells are `w_cell × h_cell` (≈ 30 px) windows starting at `min_b + j·w_cell`; OpenCV's FAST on
/// a window of `w_cell + 6` detects in its interior `[3, w − 3)`, so the detection areas of the
/// cells tile `[min_b + 3, max_b − 3)` exactly.
#[derive(Clone, Copy, Debug)]
struct CellGrid {
    n_cols: usize,
    n_rows: usize,
    w_cell: usize,
    h_cell: usize,
    det_x0: usize,
    det_x1: usize,
    det_y0: usize,
    det_y1: usize,
}

impl CellGrid {
    fn new(min_b: i32, max_bx: i32, max_by: i32) -> Self {
        let width = (max_bx - min_b) as f32;
        let height = (max_by - min_b) as f32;
        let n_cols = ((width / FAST_CELL_SIZE as f32) as usize).max(1);
        let n_rows = ((height / FAST_CELL_SIZE as f32) as usize).max(1);
        let w_cell = (width as usize).div_ceil(n_cols);
        let h_cell = (height as usize).div_ceil(n_rows);
        CellGrid {
            n_cols,
            n_rows,
            w_cell,
            h_cell,
            det_x0: (min_b + 3) as usize,
            det_x1: (max_bx - 3) as usize,
            det_y0: (min_b + 3) as usize,
            det_y1: (max_by - 3) as usize,
        }
    }

    #[inline]
    fn col_of(&self, x: usize) -> usize {
        ((x - self.det_x0) / self.w_cell).min(self.n_cols - 1)
    }

    #[inline]
    fn row_of(&self, y: usize) -> usize {
        ((y - self.det_y0) / self.h_cell).min(self.n_rows - 1)
    }

    /// Detection columns of cell column `j`.
    fn col_span(&self, j: usize) -> (usize, usize) {
        let x0 = self.det_x0 + j * self.w_cell;
        let x1 =
            if j + 1 == self.n_cols { self.det_x1 } else { (x0 + self.w_cell).min(self.det_x1) };
        (x0.min(self.det_x1), x1)
    }

    /// Detection rows of cell row `i`.
    fn row_span(&self, i: usize) -> (usize, usize) {
        let y0 = self.det_y0 + i * self.h_cell;
        let y1 =
            if i + 1 == self.n_rows { self.det_y1 } else { (y0 + self.h_cell).min(self.det_y1) };
        (y0.min(self.det_y1), y1)
    }
}

#[cfg(test)]
mod tests;
