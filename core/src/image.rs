//! 8-bit luma images in borrowed or fixed-capacity storage, and the two filters the ORB
//! pyramid needs.
//!
//! - [`ImageView`] / [`ImageViewMut`]: a `width × height` window over a byte slice with a row
//!   `stride` (so a crop or a padded buffer is a view too).
//! - [`ImageBuf<CAP>`]: owns `CAP` bytes and holds any image of at most `CAP` pixels; the size
//!   is chosen at run time, the memory at compile time (`const fn new` so it can be a `static`).
//! - [`resize_bilinear`]: OpenCV `cv::resize(.., INTER_LINEAR)` semantics (pixel centres aligned,
//!   `src_x = (dst_x + 0.5)·sx − 0.5`, clamped at the borders) with OpenCV's 11-bit fixed-point
//!   weights, as ORB-SLAM2 uses it to build its scale pyramid.
//! - [`gaussian_blur_7x7`]: the 7×7, σ = 2 Gaussian with `BORDER_REFLECT_101` that ORB-SLAM2
//!   applies to every level before sampling rBRIEF pairs; separable, 8-bit fixed-point taps.
//!
//! Every filter is integer arithmetic end to end, so its output is bit-identical on every
//! target (the float weights of the resize are computed once per row/column with IEEE
//! single/double operations, which are exact-rounded everywhere). Neither filter allocates:
//! their row buffers live in caller-owned scratch structs ([`ResizeScratch`], [`BlurScratch`])
//! of `O(MAX_W)` bytes.

use core::fmt;

/// Errors from constructing views or running the filters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ImageError {
    /// The slice is shorter than `stride·(height−1) + width`.
    BufferTooSmall {
        /// Bytes the view needs.
        need: usize,
        /// Bytes the slice has.
        got: usize,
    },
    /// `stride < width`.
    BadStride {
        /// Image width in pixels.
        width: usize,
        /// Row stride in bytes.
        stride: usize,
    },
    /// A size exceeds a compile-time capacity (pixels of a buffer, width of a scratch row).
    Capacity {
        /// What was asked for.
        need: usize,
        /// What the storage holds.
        cap: usize,
    },
    /// Source and destination sizes disagree (blur), or an image is empty.
    SizeMismatch,
}

impl fmt::Display for ImageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            ImageError::BufferTooSmall { need, got } => {
                write!(f, "image buffer too small: need {need} bytes, got {got}")
            }
            ImageError::BadStride { width, stride } => {
                write!(f, "image stride {stride} smaller than width {width}")
            }
            ImageError::Capacity { need, cap } => {
                write!(f, "image size {need} exceeds capacity {cap}")
            }
            ImageError::SizeMismatch => write!(f, "image sizes do not match or are empty"),
        }
    }
}

impl core::error::Error for ImageError {}

/// Bytes a `width × height` image with `stride` occupies (the last row needs only `width`).
const fn needed_len(width: usize, height: usize, stride: usize) -> usize {
    if height == 0 || width == 0 {
        0
    } else {
        stride * (height - 1) + width
    }
}

fn check_dims(len: usize, width: usize, height: usize, stride: usize) -> Result<(), ImageError> {
    if stride < width {
        return Err(ImageError::BadStride { width, stride });
    }
    let need = needed_len(width, height, stride);
    if len < need {
        return Err(ImageError::BufferTooSmall { need, got: len });
    }
    Ok(())
}

/// A read-only 8-bit luma image: `width × height` pixels, rows `stride` bytes apart.
#[derive(Clone, Copy, Debug)]
pub struct ImageView<'a> {
    data: &'a [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> ImageView<'a> {
    /// A view over `data` with an explicit row stride (bytes).
    pub fn new(
        data: &'a [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, ImageError> {
        check_dims(data.len(), width, height, stride)?;
        Ok(Self { data, width, height, stride })
    }

    /// A view over a tightly packed buffer (`stride == width`).
    pub fn from_slice(data: &'a [u8], width: usize, height: usize) -> Result<Self, ImageError> {
        Self::new(data, width, height, width)
    }

    /// A packed view over a slice the caller sized itself (`data.len() == width·height`).
    pub(crate) fn packed(data: &'a [u8], width: usize, height: usize) -> Self {
        debug_assert_eq!(data.len(), width * height);
        Self { data, width, height, stride: width }
    }

    /// Width in pixels.
    #[inline]
    pub const fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    #[inline]
    pub const fn height(&self) -> usize {
        self.height
    }

    /// Distance between the starts of two rows, in bytes.
    #[inline]
    pub const fn stride(&self) -> usize {
        self.stride
    }

    /// The underlying bytes, starting at pixel (0, 0).
    #[inline]
    pub const fn data(&self) -> &'a [u8] {
        self.data
    }

    /// Row `y` (exactly `width` pixels).
    ///
    /// # Panics
    /// If `y >= height` (a caller bug, like slice indexing).
    #[inline]
    pub fn row(&self, y: usize) -> &'a [u8] {
        assert!(y < self.height, "row {y} out of {}", self.height);
        let start = y * self.stride;
        &self.data[start..start + self.width]
    }

    /// Pixel at column `x`, row `y`.
    ///
    /// # Panics
    /// If the pixel is outside the image.
    #[inline]
    pub fn get(&self, x: usize, y: usize) -> u8 {
        assert!(x < self.width, "column {x} out of {}", self.width);
        self.row(y)[x]
    }
}

/// A mutable 8-bit luma image: `width × height` pixels, rows `stride` bytes apart.
#[derive(Debug)]
pub struct ImageViewMut<'a> {
    data: &'a mut [u8],
    width: usize,
    height: usize,
    stride: usize,
}

impl<'a> ImageViewMut<'a> {
    /// A mutable view over `data` with an explicit row stride (bytes).
    pub fn new(
        data: &'a mut [u8],
        width: usize,
        height: usize,
        stride: usize,
    ) -> Result<Self, ImageError> {
        check_dims(data.len(), width, height, stride)?;
        Ok(Self { data, width, height, stride })
    }

    /// A mutable view over a tightly packed buffer (`stride == width`).
    pub fn from_slice(data: &'a mut [u8], width: usize, height: usize) -> Result<Self, ImageError> {
        Self::new(data, width, height, width)
    }

    /// Width in pixels.
    #[inline]
    pub const fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    #[inline]
    pub const fn height(&self) -> usize {
        self.height
    }

    /// Distance between the starts of two rows, in bytes.
    #[inline]
    pub const fn stride(&self) -> usize {
        self.stride
    }

    /// A read-only view of the same pixels.
    #[inline]
    pub fn as_view(&self) -> ImageView<'_> {
        ImageView { data: self.data, width: self.width, height: self.height, stride: self.stride }
    }

    /// Row `y` (exactly `width` pixels), mutable.
    ///
    /// # Panics
    /// If `y >= height`.
    #[inline]
    pub fn row_mut(&mut self, y: usize) -> &mut [u8] {
        assert!(y < self.height, "row {y} out of {}", self.height);
        let start = y * self.stride;
        &mut self.data[start..start + self.width]
    }

    /// Sets every pixel to `value`.
    pub fn fill(&mut self, value: u8) {
        for y in 0..self.height {
            self.row_mut(y).fill(value);
        }
    }

    /// Copies `src` (same size) into this image.
    pub fn copy_from(&mut self, src: &ImageView<'_>) -> Result<(), ImageError> {
        if src.width != self.width || src.height != self.height {
            return Err(ImageError::SizeMismatch);
        }
        for y in 0..self.height {
            self.row_mut(y).copy_from_slice(src.row(y));
        }
        Ok(())
    }
}

/// An owned image of at most `CAP` pixels, tightly packed, with its size set at run time.
///
/// `new` is `const` and zero-fills, so a large buffer can live in a `static` (`.bss`) on the
/// target instead of on a stack.
#[derive(Clone, Debug)]
pub struct ImageBuf<const CAP: usize> {
    data: [u8; CAP],
    width: usize,
    height: usize,
}

impl<const CAP: usize> Default for ImageBuf<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAP: usize> ImageBuf<CAP> {
    /// An empty (0 × 0) image.
    pub const fn new() -> Self {
        Self { data: [0; CAP], width: 0, height: 0 }
    }

    /// Pixel capacity.
    pub const fn capacity(&self) -> usize {
        CAP
    }

    /// Width in pixels.
    pub const fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub const fn height(&self) -> usize {
        self.height
    }

    /// Sets the size; the pixel contents are left as they are (reinterpreted).
    pub fn set_size(&mut self, width: usize, height: usize) -> Result<(), ImageError> {
        let need =
            width.checked_mul(height).ok_or(ImageError::Capacity { need: usize::MAX, cap: CAP })?;
        if need > CAP {
            return Err(ImageError::Capacity { need, cap: CAP });
        }
        self.width = width;
        self.height = height;
        Ok(())
    }

    /// Resizes to `src`'s size and copies its pixels.
    pub fn copy_from(&mut self, src: &ImageView<'_>) -> Result<(), ImageError> {
        self.set_size(src.width(), src.height())?;
        self.view_mut().copy_from(src)
    }

    /// A read-only view.
    pub fn view(&self) -> ImageView<'_> {
        let n = self.width * self.height;
        ImageView {
            data: &self.data[..n],
            width: self.width,
            height: self.height,
            stride: self.width,
        }
    }

    /// A mutable view.
    pub fn view_mut(&mut self) -> ImageViewMut<'_> {
        let n = self.width * self.height;
        ImageViewMut {
            data: &mut self.data[..n],
            width: self.width,
            height: self.height,
            stride: self.width,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Bilinear resize
// ---------------------------------------------------------------------------------------------

/// Fractional bits of the bilinear weights (OpenCV's `INTER_RESIZE_COEF_BITS`).
pub const RESIZE_COEF_BITS: u32 = 11;
const RESIZE_ONE: u32 = 1 << RESIZE_COEF_BITS;

/// Rounds half away from zero to `i32` without libm: IEEE add and truncating conversion give the
/// same bits on every target.
#[inline]
pub(crate) fn round_i32(v: f32) -> i32 {
    if v >= 0.0 {
        (v + 0.5) as i32
    } else {
        (v - 0.5) as i32
    }
}

/// Source index and weight of the next sample for destination index `d`, OpenCV-style:
/// `f = (d + 0.5)·scale − 0.5`, `i = ⌊f⌋`, clamped to `[0, n−1]` with weight 0 at the clamp.
#[inline(always)]
fn resize_coord(d: usize, scale: f64, n: usize) -> (usize, u32) {
    let f = ((d as f64 + 0.5) * scale - 0.5) as f32;
    let mut i = f as i32;
    if (i as f32) > f {
        i -= 1; // floor for negative f
    }
    let mut frac = f - i as f32;
    if i < 0 {
        i = 0;
        frac = 0.0;
    }
    if i as usize >= n - 1 {
        i = n as i32 - 1;
        frac = 0.0;
    }
    let w1 = round_i32(frac * RESIZE_ONE as f32).clamp(0, RESIZE_ONE as i32) as u32;
    (i as usize, w1)
}

/// Row buffers for [`resize_bilinear`] with destinations up to `MAX_W` pixels wide
/// (`22·MAX_W + 16` bytes), and the byte-shuffle plan of the vector horizontal pass.
#[derive(Clone, Debug)]
pub struct ResizeScratch<const MAX_W: usize> {
    x0: [u32; MAX_W],
    wx: [u32; MAX_W],
    rows: [[u32; MAX_W]; 2],
    tags: [usize; 2],
    /// Per 8-pixel block: first source index (only the first `MAX_W / 8` are used).
    block_base: [u32; MAX_W],
    /// Per destination pixel: its two taps relative to its block's base.
    taps: [[u8; 2]; MAX_W],
    /// Per destination pixel: `(2048 − w, w)`.
    weights: [[i16; 2]; MAX_W],
}

impl<const MAX_W: usize> Default for ResizeScratch<MAX_W> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const MAX_W: usize> ResizeScratch<MAX_W> {
    /// Zeroed scratch (`const`, so it can be part of a `static`).
    pub const fn new() -> Self {
        Self {
            x0: [0; MAX_W],
            wx: [0; MAX_W],
            rows: [[0; MAX_W]; 2],
            tags: [usize::MAX; 2],
            block_base: [0; MAX_W],
            taps: [[0; 2]; MAX_W],
            weights: [[0; 2]; MAX_W],
        }
    }
}

/// Horizontal pass for one source row: `out[x] = src[x0]·(2048−w) + src[x0+1]·w`; the
/// pixels `plan` covers by the x86-64-v3 byte-shuffle pass where it runs, the rest here.
#[inline(always)]
fn resize_row_h(
    src: &[u8],
    x0: &[u32],
    wx: &[u32],
    plan: &crate::arch::ResizePlan<'_>,
    out: &mut [u32],
) {
    let last = src.len() - 1;
    let done = crate::arch::resize_rows_h(src, plan, out);
    let (out, x0, wx) = (&mut out[done..], &x0[done..], &wx[done..]);
    for ((o, &i), &w) in out.iter_mut().zip(x0).zip(wx) {
        let i = i as usize;
        let a = u32::from(src[i]);
        let b = u32::from(src[if i < last { i + 1 } else { last }]);
        *o = a * (RESIZE_ONE - w) + b * w;
    }
}

/// Bilinear resize of `src` into `dst` (whose size is the target size), with OpenCV
/// `INTER_LINEAR` semantics and fixed-point weights (11 bits per axis, one rounding at the end).
///
/// Each source row is interpolated horizontally once and kept while two consecutive
/// destination rows need it; the vertical blend is a plain `u32` loop that vectorises.
///
/// Runs as x86-64-v3 code where the CPU has it ([`crate::arch::v3`]; the same bits).
pub fn resize_bilinear<const MAX_W: usize>(
    src: &ImageView<'_>,
    dst: &mut ImageViewMut<'_>,
    scratch: &mut ResizeScratch<MAX_W>,
) -> Result<(), ImageError> {
    crate::arch::v3(
        #[inline(always)]
        || resize_bilinear_body(src, dst, scratch),
    )
}

#[inline(always)]
fn resize_bilinear_body<const MAX_W: usize>(
    src: &ImageView<'_>,
    dst: &mut ImageViewMut<'_>,
    scratch: &mut ResizeScratch<MAX_W>,
) -> Result<(), ImageError> {
    let (sw, sh, dw, dh) = (src.width(), src.height(), dst.width(), dst.height());
    if sw == 0 || sh == 0 || dw == 0 || dh == 0 {
        return Err(ImageError::SizeMismatch);
    }
    if dw > MAX_W {
        return Err(ImageError::Capacity { need: dw, cap: MAX_W });
    }
    let sx = sw as f64 / dw as f64;
    let sy = sh as f64 / dh as f64;
    for d in 0..dw {
        let (i, w) = resize_coord(d, sx, sw);
        scratch.x0[d] = i as u32;
        scratch.wx[d] = w;
    }
    scratch.tags = [usize::MAX; 2];
    let ResizeScratch { x0, wx, rows, tags, block_base, taps, weights } = scratch;
    let (x0, wx) = (&x0[..dw], &wx[..dw]);
    let taps = taps.as_flattened_mut().as_chunks_mut::<16>().0;
    let weights = weights.as_flattened_mut().as_chunks_mut::<16>().0;
    let plan = crate::arch::plan_resize_h(x0, wx, sw, block_base, taps, weights);
    for dy in 0..dh {
        let (r0, wy) = resize_coord(dy, sy, sh);
        let r1 = if r0 + 1 < sh { r0 + 1 } else { r0 };
        // Pick slots: keep whichever cached row is still needed.
        let s0 = if tags[0] == r0 {
            0
        } else if tags[1] == r0 {
            1
        } else {
            let s = if tags[0] == r1 { 1 } else { 0 };
            resize_row_h(src.row(r0), x0, wx, &plan, &mut rows[s][..dw]);
            tags[s] = r0;
            s
        };
        let s1 = if tags[s0] == r1 {
            s0
        } else if tags[1 - s0] == r1 {
            1 - s0
        } else {
            let s = 1 - s0;
            resize_row_h(src.row(r1), x0, wx, &plan, &mut rows[s][..dw]);
            tags[s] = r1;
            s
        };
        let (a, b) = (&rows[s0][..dw], &rows[s1][..dw]);
        let w0 = RESIZE_ONE - wy;
        let out = dst.row_mut(dy);
        for ((o, &p), &q) in out.iter_mut().zip(a).zip(b) {
            *o = ((p * w0 + q * wy + (1 << (2 * RESIZE_COEF_BITS - 1))) >> (2 * RESIZE_COEF_BITS))
                as u8;
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Gaussian blur
// ---------------------------------------------------------------------------------------------

/// The 7-tap σ = 2 Gaussian, quantised to 8 fractional bits (sum 256).
///
/// Exact taps `exp(−i²/8)/Σ · 256` are 17.96, 33.56, 48.82, 55.32; the rounding that keeps the
/// sum at 256 with the smallest largest error (0.68) is 18, 33, 49, 56.
pub const GAUSS7_Q8: [u32; 7] = [18, 33, 49, 56, 49, 33, 18];

/// `BORDER_REFLECT_101` index: `…, 2, 1 | 0, 1, 2, … n−1 | n−2, …`.
#[inline(always)]
fn reflect101(i: isize, n: usize) -> usize {
    let n = n as isize;
    if n == 1 {
        return 0;
    }
    let mut i = i;
    loop {
        if i < 0 {
            i = -i;
        } else if i >= n {
            i = 2 * n - 2 - i;
        } else {
            return i as usize;
        }
    }
}

/// Ring of seven horizontally filtered rows for [`gaussian_blur_7x7`] (`14·MAX_W` bytes).
#[derive(Clone, Debug)]
pub struct BlurScratch<const MAX_W: usize> {
    rows: [[u16; MAX_W]; 7],
}

impl<const MAX_W: usize> Default for BlurScratch<MAX_W> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const MAX_W: usize> BlurScratch<MAX_W> {
    /// Zeroed scratch (`const`).
    pub const fn new() -> Self {
        Self { rows: [[0; MAX_W]; 7] }
    }
}

/// Horizontal 7-tap pass of one row into `u16` (exact: at most 255·256).
#[inline(always)]
fn blur_row_h(src: &[u8], out: &mut [u16]) {
    let w = src.len();
    let k = &GAUSS7_Q8;
    let tap = |x: usize| -> u16 {
        let mut acc = 0u32;
        for (t, &kt) in k.iter().enumerate() {
            acc += kt * u32::from(src[reflect101(x as isize + t as isize - 3, w)]);
        }
        acc as u16
    };
    if w < 7 {
        for (x, o) in out.iter_mut().enumerate().take(w) {
            *o = tap(x);
        }
        return;
    }
    for x in (0..3).chain(w - 3..w) {
        out[x] = tap(x);
    }
    let n = w - 6;
    let (s0, s1, s2, s3) = (&src[0..n], &src[1..n + 1], &src[2..n + 2], &src[3..n + 3]);
    let (s4, s5, s6) = (&src[4..n + 4], &src[5..n + 5], &src[6..n + 6]);
    let out = &mut out[3..n + 3];
    for i in 0..n {
        let e0 = u16::from(s0[i]) + u16::from(s6[i]);
        let e1 = u16::from(s1[i]) + u16::from(s5[i]);
        let e2 = u16::from(s2[i]) + u16::from(s4[i]);
        out[i] =
            e0 * k[0] as u16 + e1 * k[1] as u16 + e2 * k[2] as u16 + u16::from(s3[i]) * k[3] as u16;
    }
}

/// 7×7 Gaussian blur, σ = 2, `BORDER_REFLECT_101` (as `cv::GaussianBlur(src, dst, {7, 7}, 2, 2,
/// BORDER_REFLECT_101)`), separable with 8-bit taps ([`GAUSS7_Q8`]) and one
/// round-half-up at the end: bit-identical on every target.
///
/// `src` and `dst` must have the same size; `src.width() <= MAX_W`.
///
/// Runs as x86-64-v3 code where the CPU has it ([`crate::arch::v3`]; the same bits).
pub fn gaussian_blur_7x7<const MAX_W: usize>(
    src: &ImageView<'_>,
    dst: &mut ImageViewMut<'_>,
    scratch: &mut BlurScratch<MAX_W>,
) -> Result<(), ImageError> {
    crate::arch::v3(
        #[inline(always)]
        || gaussian_blur_7x7_body(src, dst, scratch),
    )
}

#[inline(always)]
fn gaussian_blur_7x7_body<const MAX_W: usize>(
    src: &ImageView<'_>,
    dst: &mut ImageViewMut<'_>,
    scratch: &mut BlurScratch<MAX_W>,
) -> Result<(), ImageError> {
    let (w, h) = (src.width(), src.height());
    if w == 0 || h == 0 || dst.width() != w || dst.height() != h {
        return Err(ImageError::SizeMismatch);
    }
    if w > MAX_W {
        return Err(ImageError::Capacity { need: w, cap: MAX_W });
    }
    let k = &GAUSS7_Q8;
    // Row r lives in slot r % 7; rows are filtered lazily in increasing order, and the seven
    // rows one output row needs always lie in [y−3, y+3], so they never collide.
    let mut next_row = 0usize;
    for y in 0..h {
        let need_upto = (y + 3).min(h - 1);
        while next_row <= need_upto {
            blur_row_h(src.row(next_row), &mut scratch.rows[next_row % 7][..w]);
            next_row += 1;
        }
        let r = |d: isize| -> &[u16] { &scratch.rows[reflect101(y as isize + d, h) % 7][..w] };
        let (a, b, c, d, e, f, g) = (r(-3), r(-2), r(-1), r(0), r(1), r(2), r(3));
        let out = dst.row_mut(y);
        for i in 0..w {
            let acc = k[0] * (u32::from(a[i]) + u32::from(g[i]))
                + k[1] * (u32::from(b[i]) + u32::from(f[i]))
                + k[2] * (u32::from(c[i]) + u32::from(e[i]))
                + k[3] * u32::from(d[i]);
            out[i] = ((acc + (1 << 15)) >> 16) as u8;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn view_checks_dims() {
        let buf = [0u8; 10];
        assert!(ImageView::new(&buf, 4, 3, 3).is_err());
        assert_eq!(
            ImageView::new(&buf, 4, 3, 4).unwrap_err(),
            ImageError::BufferTooSmall { need: 12, got: 10 }
        );
        let v = ImageView::new(&buf, 4, 2, 5).unwrap();
        assert_eq!(v.row(1).len(), 4);
    }

    #[test]
    fn imagebuf_capacity_is_checked() {
        let mut b = ImageBuf::<100>::new();
        assert!(b.set_size(10, 10).is_ok());
        assert_eq!(b.set_size(11, 10), Err(ImageError::Capacity { need: 110, cap: 100 }));
    }

    #[test]
    fn gauss_taps_sum_to_256() {
        assert_eq!(GAUSS7_Q8.iter().sum::<u32>(), 256);
    }

    #[test]
    fn blur_keeps_constant_and_matches_float_reference() {
        let (w, h) = (23usize, 17usize);
        let mut src = [0u8; 23 * 17];
        for (i, p) in src.iter_mut().enumerate() {
            *p = ((i * 37 + (i / w) * 11) % 251) as u8;
        }
        let mut out = [0u8; 23 * 17];
        let mut s = BlurScratch::<32>::new();
        let sv = ImageView::from_slice(&src, w, h).unwrap();
        gaussian_blur_7x7(&sv, &mut ImageViewMut::from_slice(&mut out, w, h).unwrap(), &mut s)
            .unwrap();
        // Float reference with the exact Gaussian and reflect-101 borders.
        let g: Vec<f64> = (-3..=3).map(|i: i32| (-(i * i) as f64 / 8.0).exp()).collect();
        let sum: f64 = g.iter().sum();
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for (j, gy) in g.iter().enumerate() {
                    for (i, gx) in g.iter().enumerate() {
                        let yy = reflect101(y as isize + j as isize - 3, h);
                        let xx = reflect101(x as isize + i as isize - 3, w);
                        acc += gx * gy * src[yy * w + xx] as f64;
                    }
                }
                let r = acc / (sum * sum);
                let got = out[y * w + x] as f64;
                assert!((got - r).abs() <= 1.6, "({x},{y}) got {got} ref {r}");
            }
        }
        let flat = [77u8; 23 * 17];
        let fv = ImageView::from_slice(&flat, w, h).unwrap();
        gaussian_blur_7x7(&fv, &mut ImageViewMut::from_slice(&mut out, w, h).unwrap(), &mut s)
            .unwrap();
        assert!(out.iter().all(|&p| p == 77));
    }

    #[test]
    fn resize_identity_and_constant() {
        let (w, h) = (19usize, 11usize);
        let src: Vec<u8> = (0..w * h).map(|i| (i * 13 % 256) as u8).collect();
        let sv = ImageView::from_slice(&src, w, h).unwrap();
        let mut out = vec![0u8; w * h];
        let mut s = ResizeScratch::<32>::new();
        resize_bilinear(&sv, &mut ImageViewMut::from_slice(&mut out, w, h).unwrap(), &mut s)
            .unwrap();
        assert_eq!(out, src);
        let flat = vec![200u8; w * h];
        let fv = ImageView::from_slice(&flat, w, h).unwrap();
        let (dw, dh) = (16usize, 9usize);
        let mut out2 = vec![0u8; dw * dh];
        resize_bilinear(&fv, &mut ImageViewMut::from_slice(&mut out2, dw, dh).unwrap(), &mut s)
            .unwrap();
        assert!(out2.iter().all(|&p| p == 200));
    }

    /// The x86-64-v3 byte-shuffle horizontal pass gives the scalar pass's bytes, for
    /// down-scaling (the pyramid's 1.2, and up to where blocks no longer fit), up-scaling and
    /// widths around the 8-pixel blocks and the 16-byte loads.
    #[test]
    fn resize_is_the_same_on_every_kernel_level() {
        let sizes = [
            (1241usize, 376usize, 1034usize, 313usize),
            (1034, 313, 862, 261),
            (100, 40, 83, 33),
            (60, 36, 50, 30),
            (301, 20, 160, 11),
            (301, 20, 151, 10),
            (64, 9, 33, 5),
            (17, 5, 14, 4),
            (15, 5, 12, 4),
            (40, 12, 97, 29),
            (1241, 6, 1241, 6),
        ];
        let mut s = ResizeScratch::<1300>::new();
        for (k, &(w, h, dw, dh)) in sizes.iter().enumerate() {
            let src: Vec<u8> =
                (0..w * h).map(|i| ((i * 2_654_435_761usize + k) >> 7) as u8).collect();
            let sv = ImageView::from_slice(&src, w, h).unwrap();
            let mut outs = Vec::new();
            crate::nn::dispatch::for_each_level(|level| {
                let mut out = vec![0u8; dw * dh];
                resize_bilinear(
                    &sv,
                    &mut ImageViewMut::from_slice(&mut out, dw, dh).unwrap(),
                    &mut s,
                )
                .unwrap();
                outs.push((level, out));
            });
            for (level, out) in &outs[1..] {
                assert!(
                    out == &outs[0].1,
                    "{w}x{h} -> {dw}x{dh}: {level} differs from {}",
                    outs[0].0
                );
            }
        }
    }

    #[test]
    fn resize_matches_float_bilinear() {
        let (w, h) = (60usize, 36usize);
        let src: Vec<u8> = (0..w * h).map(|i| ((i % w) * 4 + (i / w) * 3) as u8).collect();
        let sv = ImageView::from_slice(&src, w, h).unwrap();
        let (dw, dh) = (50usize, 30usize);
        let mut out = vec![0u8; dw * dh];
        let mut s = ResizeScratch::<64>::new();
        resize_bilinear(&sv, &mut ImageViewMut::from_slice(&mut out, dw, dh).unwrap(), &mut s)
            .unwrap();
        for dy in 0..dh {
            for dx in 0..dw {
                let fx = ((dx as f64 + 0.5) * 1.2 - 0.5).clamp(0.0, (w - 1) as f64);
                let fy = ((dy as f64 + 0.5) * 1.2 - 0.5).clamp(0.0, (h - 1) as f64);
                let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
                let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
                let (ax, ay) = (fx - x0 as f64, fy - y0 as f64);
                let p = |x: usize, y: usize| src[y * w + x] as f64;
                let r = (1.0 - ay) * ((1.0 - ax) * p(x0, y0) + ax * p(x1, y0))
                    + ay * ((1.0 - ax) * p(x0, y1) + ax * p(x1, y1));
                let got = out[dy * dw + dx] as f64;
                assert!((got - r).abs() <= 1.0, "({dx},{dy}) got {got} ref {r}");
            }
        }
    }
}
