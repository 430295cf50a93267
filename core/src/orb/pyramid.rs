//! The ORB scale pyramid in one flat fixed-capacity buffer.
//!
//! Level `i` is `round(w / sᶦ) × round(h / sᶦ)` (`s` = scale factor, `sᶦ` accumulated in `f32`
//! as ORB-SLAM2 does) and is resized bilinearly from level `i − 1`, as ORB-SLAM2's
//! `ComputePyramid`. Levels are stored back to back, tightly packed, in `[u8; CAP]`; ORB-SLAM2's
//! 19-px reflected padding is not stored because nothing downstream reads outside a level (all
//! detection keeps `EDGE_THRESHOLD` pixels from the border). The levels stay available after
//! extraction, e.g. for stereo SAD refinement on the key point's level.
//!
//! Memory: `CAP + 12·MAX_W + O(1)` bytes; [`pyramid_capacity`] gives `CAP` for a frame size.

use crate::image::{
    resize_bilinear, round_i32, ImageError, ImageView, ImageViewMut, ResizeScratch,
};

/// Most pyramid levels any configuration may ask for.
pub const MAX_LEVELS: usize = 16;

/// Geometry of one pyramid level.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LevelInfo {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Offset of pixel (0, 0) in the pyramid buffer.
    pub offset: usize,
    /// `sᶦ`: multiply level coordinates by this to get level-0 coordinates.
    pub scale: f32,
    /// `1 / sᶦ`.
    pub inv_scale: f32,
}

impl LevelInfo {
    const ZERO: LevelInfo =
        LevelInfo { width: 0, height: 0, offset: 0, scale: 0.0, inv_scale: 0.0 };
}

/// Pyramid buffer bytes sufficient for a `width × height` frame with `n_levels` levels at any
/// scale factor ≥ 1.2 (each level bounded by `⌊w·(5/6)ᶦ⌋ + 1` per side).
pub const fn pyramid_capacity(width: usize, height: usize, n_levels: usize) -> usize {
    let mut total: u64 = 0;
    let (mut num, mut den) = (1u64, 1u64);
    let mut i = 0;
    while i < n_levels {
        let (w, h) = if i == 0 {
            (width as u64, height as u64)
        } else {
            (width as u64 * num / den + 1, height as u64 * num / den + 1)
        };
        total += w * h;
        num *= 5;
        den *= 6;
        i += 1;
    }
    total as usize
}

/// Level sizes and scales for a frame, as ORB-SLAM2 computes them, without building anything.
pub fn level_geometry(
    width: usize,
    height: usize,
    scale_factor: f32,
    n_levels: usize,
) -> [LevelInfo; MAX_LEVELS] {
    let mut out = [LevelInfo::ZERO; MAX_LEVELS];
    let mut scale = 1.0f32;
    let mut offset = 0;
    for (i, l) in out.iter_mut().enumerate().take(n_levels.min(MAX_LEVELS)) {
        if i > 0 {
            scale *= scale_factor;
        }
        let inv = 1.0 / scale;
        let w = round_i32(width as f32 * inv).max(1) as usize;
        let h = round_i32(height as f32 * inv).max(1) as usize;
        *l = LevelInfo { width: w, height: h, offset, scale, inv_scale: inv };
        offset += w * h;
    }
    out
}

/// An image pyramid of at most `CAP` pixels in total, levels at most `MAX_W` wide.
#[derive(Clone, Debug)]
pub struct Pyramid<const MAX_W: usize, const CAP: usize> {
    data: [u8; CAP],
    levels: [LevelInfo; MAX_LEVELS],
    n_levels: usize,
    resize: ResizeScratch<MAX_W>,
}

impl<const MAX_W: usize, const CAP: usize> Default for Pyramid<MAX_W, CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const MAX_W: usize, const CAP: usize> Pyramid<MAX_W, CAP> {
    /// An empty pyramid (`const`, zero-filled: can live in a `static`).
    pub const fn new() -> Self {
        Self {
            data: [0; CAP],
            levels: [LevelInfo::ZERO; MAX_LEVELS],
            n_levels: 0,
            resize: ResizeScratch::new(),
        }
    }

    /// Builds `n_levels` levels from `image` with `scale_factor` between levels.
    ///
    /// Errors (nothing is built) when the frame is wider than `MAX_W`, the levels do not fit
    /// in `CAP`, or `n_levels` is 0 or above [`MAX_LEVELS`].
    pub fn build(
        &mut self,
        image: &ImageView<'_>,
        scale_factor: f32,
        n_levels: usize,
    ) -> Result<(), ImageError> {
        self.n_levels = 0;
        if n_levels == 0 || n_levels > MAX_LEVELS {
            return Err(ImageError::Capacity { need: n_levels, cap: MAX_LEVELS });
        }
        if image.width() == 0 || image.height() == 0 {
            return Err(ImageError::SizeMismatch);
        }
        if image.width() > MAX_W {
            return Err(ImageError::Capacity { need: image.width(), cap: MAX_W });
        }
        let levels = level_geometry(image.width(), image.height(), scale_factor, n_levels);
        let last = levels[n_levels - 1];
        let need = last.offset + last.width * last.height;
        if need > CAP {
            return Err(ImageError::Capacity { need, cap: CAP });
        }
        self.levels = levels;
        let l0 = levels[0];
        ImageViewMut::from_slice(&mut self.data[..l0.width * l0.height], l0.width, l0.height)?
            .copy_from(image)?;
        for i in 1..n_levels {
            let (p, c) = (levels[i - 1], levels[i]);
            let (head, tail) = self.data.split_at_mut(c.offset);
            let src = ImageView::from_slice(&head[p.offset..], p.width, p.height)?;
            let mut dst =
                ImageViewMut::from_slice(&mut tail[..c.width * c.height], c.width, c.height)?;
            resize_bilinear(&src, &mut dst, &mut self.resize)?;
        }
        self.n_levels = n_levels;
        Ok(())
    }

    /// Number of levels built by the last successful [`Pyramid::build`].
    pub fn n_levels(&self) -> usize {
        self.n_levels
    }

    /// Geometry of level `i`.
    ///
    /// # Panics
    /// If `i >= n_levels()`.
    pub fn info(&self, i: usize) -> LevelInfo {
        assert!(i < self.n_levels, "level {i} of {}", self.n_levels);
        self.levels[i]
    }

    /// Pixels of level `i`.
    ///
    /// # Panics
    /// If `i >= n_levels()`.
    pub fn level(&self, i: usize) -> ImageView<'_> {
        let l = self.info(i);
        ImageView::packed(&self.data[l.offset..l.offset + l.width * l.height], l.width, l.height)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kitti_level_sizes_match_orbslam2() {
        let g = level_geometry(1241, 376, 1.2, 8);
        let sizes: Vec<(usize, usize)> = g[..8].iter().map(|l| (l.width, l.height)).collect();
        // round(1241 / 1.2^i), round(376 / 1.2^i)
        assert_eq!(
            sizes,
            vec![
                (1241, 376),
                (1034, 313),
                (862, 261),
                (718, 218),
                (598, 181),
                (499, 151),
                (416, 126),
                (346, 105)
            ]
        );
        assert!(g[7].offset + 346 * 105 <= pyramid_capacity(1248, 384, 8));
    }

    #[test]
    fn capacity_bounds_every_size_up_to_the_max() {
        for (w, h) in [(1248usize, 384usize), (1241, 376), (1242, 375), (640, 480), (97, 61)] {
            let g = level_geometry(w, h, 1.2, 8);
            assert!(g[7].offset + g[7].width * g[7].height <= pyramid_capacity(w, h, 8));
        }
    }

    #[test]
    fn builds_levels_from_the_previous_one() {
        let (w, h) = (120usize, 80usize);
        let img: Vec<u8> = (0..w * h).map(|i| ((i % w) * 2) as u8).collect();
        let v = ImageView::from_slice(&img, w, h).unwrap();
        let mut p = Pyramid::<128, { pyramid_capacity(120, 80, 4) }>::new();
        p.build(&v, 1.2, 4).unwrap();
        assert_eq!(p.n_levels(), 4);
        assert_eq!(p.level(0).data(), &img[..]);
        let l1 = p.level(1);
        assert_eq!((l1.width(), l1.height()), (100, 67));
        // A horizontal ramp stays a ramp: value ≈ 2·x·1.2 at level 1.
        let x = 50usize;
        let expect = 2.0 * ((x as f64 + 0.5) * 1.2 - 0.5);
        assert!((l1.get(x, 30) as f64 - expect).abs() <= 1.0);
        assert!(p.build(&v, 1.05, 4).is_err(), "a slower scale needs more room than CAP");
    }
}
