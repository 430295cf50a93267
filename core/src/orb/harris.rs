//! Harris corner response at a pixel, as OpenCV's ORB `HarrisResponses` computes it.
//!
//! Over a 7 × 7 block centred on the pixel, with 3 × 3 Sobel derivatives `Ix`, `Iy`:
//! `a = ΣIx²`, `b = ΣIy²`, `c = ΣIxIy`, `R = (ab − c² − k(a + b)²)·s⁴` with `k = 0.04` and
//! `s = 1 / (4 · 7 · 255)` (the normalisation OpenCV uses, so responses are comparable to
//! OpenCV's). Positive on corners, negative on edges, near zero on flat patches.
//!
//! The sums are integers and `k = 1/25`, so `25R/s⁴ = 25(ab − c²) − (a + b)²` is computed exactly in
//! `i64`; only the final scaling is floating point. Ranking is therefore exact and identical on
//! every target. Memory: none beyond the stack frame.

use crate::image::ImageView;

/// Side of the summation block (OpenCV ORB's default `blockSize`).
pub const HARRIS_BLOCK_SIZE: usize = 7;
/// Harris `k`.
pub const HARRIS_K: f32 = 0.04;
/// Pixels of margin [`harris_response`] needs on every side (block radius + Sobel radius).
pub const HARRIS_MARGIN: usize = HARRIS_BLOCK_SIZE / 2 + 1;

/// `s⁴ / 25` with `s = 1/(4·7·255)`: maps the exact integer `25(ab − c²) − (a + b)²` to OpenCV's
/// response scale.
const RESPONSE_SCALE: f64 = {
    let s = 1.0 / (4.0 * HARRIS_BLOCK_SIZE as f64 * 255.0);
    s * s * s * s / 25.0
};

/// Exact integer Harris numerator `25(ab − c²) − (a + b)²` at `(x, y)`.
///
/// # Panics
/// If the pixel is closer than [`HARRIS_MARGIN`] to the border.
pub fn harris_numerator(img: &ImageView<'_>, x: usize, y: usize) -> i64 {
    const N: usize = HARRIS_BLOCK_SIZE + 2;
    let r = HARRIS_BLOCK_SIZE / 2;
    assert!(x >= HARRIS_MARGIN && y >= HARRIS_MARGIN);
    assert!(x + HARRIS_MARGIN < img.width() && y + HARRIS_MARGIN < img.height());
    let xs = x - r - 1; // first column any Sobel tap touches
    #[cfg(target_arch = "x86_64")]
    if xs + 10 <= img.width() {
        // The 9 rows any tap touches, 10 columns each, summed with SSE2 (x86-64's baseline).
        let rows: [[u8; 10]; N] = core::array::from_fn(|k| {
            img.row(y - r - 1 + k)
                .get(xs..)
                .and_then(|s| s.first_chunk::<10>())
                .copied()
                .unwrap_or([0; 10])
        });
        let (a, b, c) = crate::arch::harris_sums(&rows);
        return numerator_of_sums(a, b, c);
    }
    #[cfg(not(target_arch = "x86_64"))]
    if xs + 10 <= img.width() {
        return numerator_wide(img, xs, y);
    }
    let (mut a, mut b, mut c) = (0i32, 0i32, 0i32);
    let row = |yy: usize| -> [i32; N] {
        let s = &img.row(yy)[xs..xs + N];
        core::array::from_fn(|k| i32::from(s[k]))
    };
    // Fixed-size rows: the 7-wide inner loop unrolls and vectorises.
    let (mut up, mut mid) = (row(y - r - 1), row(y - r));
    for yy in y - r..=y + r {
        let dn = row(yy + 1);
        for j in 1..=HARRIS_BLOCK_SIZE {
            let ix =
                (mid[j + 1] - mid[j - 1]) * 2 + (up[j + 1] - up[j - 1]) + (dn[j + 1] - dn[j - 1]);
            let iy = (dn[j] - up[j]) * 2 + (dn[j - 1] - up[j - 1]) + (dn[j + 1] - up[j + 1]);
            a += ix * ix;
            b += iy * iy;
            c += ix * iy;
        }
        up = mid;
        mid = dn;
    }
    numerator_of_sums(a, b, c)
}

/// [`harris_numerator`] on 8 lanes of `i16` derivatives (the eighth masked to 0), from rows of
/// 10 columns starting at `xs`: the Sobel pass is separable (`Ix` = horizontal difference of
/// the vertically smoothed rows, `Iy` = horizontal smoothing of the vertical difference), and
/// every sum is the same exact integer as the reference loop.
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
fn numerator_wide(img: &ImageView<'_>, xs: usize, y: usize) -> i64 {
    const R: usize = HARRIS_BLOCK_SIZE / 2;
    let row = |yy: usize| -> [i16; 10] {
        // the caller keeps 10 columns of margin; a short row would read as zeros, not panic
        let s: &[u8; 10] =
            img.row(yy).get(xs..).and_then(|s| s.first_chunk::<10>()).unwrap_or(&[0; 10]);
        s.map(i16::from)
    };
    // Per row: horizontal difference and smoothing (the separable halves of the Sobel pair).
    let terms = |r: &[i16; 10]| -> ([i16; 8], [i16; 8]) {
        let h = core::array::from_fn(|j| if j < 7 { r[j + 2] - r[j] } else { 0 });
        let s = core::array::from_fn(|j| if j < 7 { r[j] + 2 * r[j + 1] + r[j + 2] } else { 0 });
        (h, s)
    };
    let (mut aa, mut bb, mut cc) = ([0i32; 8], [0i32; 8], [0i32; 8]);
    let (mut h0, mut s0) = terms(&row(y - R - 1));
    let (mut h1, mut s1) = terms(&row(y - R));
    for yy in y - R..=y + R {
        let (h2, s2) = terms(&row(yy + 1));
        for j in 0..8 {
            let ix = h0[j] + 2 * h1[j] + h2[j];
            let iy = s2[j] - s0[j];
            aa[j] += i32::from(ix) * i32::from(ix);
            bb[j] += i32::from(iy) * i32::from(iy);
            cc[j] += i32::from(ix) * i32::from(iy);
        }
        (h0, s0, h1, s1) = (h1, s1, h2, s2);
    }
    numerator_of_sums(aa.iter().sum(), bb.iter().sum(), cc.iter().sum())
}

/// `25(ab − c²) − (a + b)²` from the block sums `a = ΣIx²`, `b = ΣIy²`, `c = ΣIxIy`, exact in
/// `i64`.
#[inline(always)]
fn numerator_of_sums(a: i32, b: i32, c: i32) -> i64 {
    let (a, b, c) = (i64::from(a), i64::from(b), i64::from(c));
    25 * (a * b - c * c) - (a + b) * (a + b)
}

/// Harris response at `(x, y)` on OpenCV ORB's scale.
///
/// # Panics
/// If the pixel is closer than [`HARRIS_MARGIN`] to the border.
pub fn harris_response(img: &ImageView<'_>, x: usize, y: usize) -> f32 {
    (harris_numerator(img, x, y) as f64 * RESPONSE_SCALE) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> u8) -> Vec<u8> {
        (0..w * h).map(|i| f(i % w, i / w)).collect()
    }

    #[test]
    fn corner_positive_edge_negative_flat_zero() {
        let (w, h) = (32usize, 32usize);
        let corner = image(w, h, |x, y| if x >= 16 && y >= 16 { 220 } else { 30 });
        let edge = image(w, h, |x, _| if x >= 16 { 220 } else { 30 });
        let flat = image(w, h, |_, _| 90);
        let cv = ImageView::from_slice(&corner, w, h).unwrap();
        let ev = ImageView::from_slice(&edge, w, h).unwrap();
        let fv = ImageView::from_slice(&flat, w, h).unwrap();
        let rc = harris_response(&cv, 16, 16);
        let re = harris_response(&ev, 16, 10);
        assert!(rc > 0.0, "corner response {rc}");
        assert!(re < 0.0, "edge response {re}");
        assert_eq!(harris_response(&fv, 16, 16), 0.0);
    }

    /// The definition's sums `(ΣIx², ΣIy², ΣIxIy)` (3 × 3 Sobel, 7 × 7 block), exact.
    fn sums(img: &[u8], w: usize, x: usize, y: usize) -> (i64, i64, i64) {
        let p = |x: usize, y: usize| i64::from(img[y * w + x]);
        let (mut a, mut b, mut c) = (0i64, 0i64, 0i64);
        for yy in y - 3..=y + 3 {
            for xx in x - 3..=x + 3 {
                let ix = (p(xx + 1, yy) - p(xx - 1, yy)) * 2 + p(xx + 1, yy - 1)
                    - p(xx - 1, yy - 1)
                    + p(xx + 1, yy + 1)
                    - p(xx - 1, yy + 1);
                let iy = (p(xx, yy + 1) - p(xx, yy - 1)) * 2 + p(xx - 1, yy + 1)
                    - p(xx - 1, yy - 1)
                    + p(xx + 1, yy + 1)
                    - p(xx + 1, yy - 1);
                a += ix * ix;
                b += iy * iy;
                c += ix * iy;
            }
        }
        (a, b, c)
    }

    /// The exact integer numerator by the definition.
    fn reference(img: &[u8], w: usize, x: usize, y: usize) -> i64 {
        let (a, b, c) = sums(img, w, x, y);
        25 * (a * b - c * c) - (a + b) * (a + b)
    }

    #[test]
    fn numerator_is_exact_everywhere() {
        // Random and extreme (0/255 checkerboard: the largest derivatives) images, every pixel
        // the block fits at, up to the right edge where the 10-column fast path gives way to
        // the row loop.
        let mut rng = crate::testing::Rng::new(0x4a22_1500);
        let (w, h) = (41usize, 23usize);
        let random: Vec<u8> = (0..w * h).map(|_| rng.below(256) as u8).collect();
        let checker = image(w, h, |x, y| if (x + y) % 2 == 0 { 255 } else { 0 });
        let stripes = image(w, h, |x, y| if (x / 2 + y) % 2 == 0 { 255 } else { 0 });
        for img in [&random, &checker, &stripes] {
            let v = ImageView::from_slice(img, w, h).unwrap();
            for y in HARRIS_MARGIN..h - HARRIS_MARGIN {
                for x in HARRIS_MARGIN..w - HARRIS_MARGIN {
                    assert_eq!(harris_numerator(&v, x, y), reference(img, w, x, y), "({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn matches_float_formula() {
        let (w, h) = (20usize, 20usize);
        let img = image(w, h, |x, y| ((x * 31 + y * 17 + x * y) % 256) as u8);
        let v = ImageView::from_slice(&img, w, h).unwrap();
        let (x, y) = (9usize, 10usize);
        let (a, b, c) = sums(&img, w, x, y);
        let (a, b, c) = (a as f64, b as f64, c as f64);
        let s = 1.0 / (4.0 * 7.0 * 255.0);
        let r = (a * b - c * c - 0.04 * (a + b) * (a + b)) * s * s * s * s;
        let got = harris_response(&v, x, y) as f64;
        assert!((got - r).abs() <= 1e-6 * r.abs().max(1e-12), "{got} vs {r}");
    }
}
