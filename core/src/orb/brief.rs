//! Orientation by intensity centroid and the steered 256-bit rBRIEF descriptor (ORB, Rublee et
//! al. 2011, §3.2 and §4), as ORB-SLAM2's `IC_Angle` / `computeOrbDescriptor`.
//!
//! - Orientation: `θ = atan2(m01, m10)` with the image moments taken over the circular patch of
//!   radius [`HALF_PATCH_SIZE`] (row half-widths [`UMAX`]) on the *unblurred* level.
//! - Descriptor: for each of the 256 point pairs of [`BIT_PATTERN_31`], rotate both points by
//!   `θ` (Q16 fixed point), round to the nearest pixel, and set the bit when the first is darker
//!   than the second — sampled on the *Gaussian-blurred* level.
//! - Matching: [`hamming`] is a popcount over four `u64` words.
//!
//! Memory: none beyond the stack frame. Sine and cosine come from `crate::math` (libm).

use crate::image::{round_i32, ImageView};
use crate::math;

pub use super::pattern::BIT_PATTERN_31;

/// Side of the square the orientation patch and the descriptor pattern live in.
pub const PATCH_SIZE: usize = 31;
/// Radius of the circular orientation patch.
pub const HALF_PATCH_SIZE: usize = 15;

/// Half-width of each row `v = 0..=15` of the circular patch: ORB-SLAM2's `umax`
/// (`round(√(15² − v²))` for the lower rows, then mirrored so the disc is symmetric about the
/// diagonal). Recomputed from its definition in a test.
pub const UMAX: [i32; HALF_PATCH_SIZE + 1] =
    [15, 15, 15, 15, 14, 14, 14, 13, 13, 12, 11, 10, 9, 8, 6, 3];

/// A 256-bit binary descriptor (bit `i` of byte `i / 8`, LSB first: OpenCV's layout).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Descriptor(pub [u8; 32]);

impl Descriptor {
    /// Hamming distance to `other` (0..=256).
    #[inline]
    pub fn distance(&self, other: &Descriptor) -> u32 {
        hamming(self, other)
    }
}

/// Hamming distance between two descriptors: number of differing bits (0..=256).
#[inline]
pub fn hamming(a: &Descriptor, b: &Descriptor) -> u32 {
    let mut d = 0;
    for (x, y) in a.0.chunks_exact(8).zip(b.0.chunks_exact(8)) {
        let x = u64::from_le_bytes([x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]]);
        let y = u64::from_le_bytes([y[0], y[1], y[2], y[3], y[4], y[5], y[6], y[7]]);
        d += (x ^ y).count_ones();
    }
    d
}

/// Intensity-centroid orientation of the patch around `(x, y)`, in degrees `[0, 360)`, image
/// axes (x right, y down), as OpenCV's `fastAtan2(m01, m10)` but with libm's exact `atan2f`.
///
/// # Panics
/// If `(x, y)` is closer than [`HALF_PATCH_SIZE`] to the border.
///
/// Runs as x86-64-v3 code where the CPU has it ([`crate::arch::v3`]; the same bits).
pub fn ic_angle(img: &ImageView<'_>, x: usize, y: usize) -> f32 {
    crate::arch::v3(
        #[inline(always)]
        || ic_angle_body(img, x, y),
    )
}

#[inline(always)]
fn ic_angle_body(img: &ImageView<'_>, x: usize, y: usize) -> f32 {
    let r = HALF_PATCH_SIZE;
    assert!(x >= r && y >= r && x + r < img.width() && y + r < img.height());
    if x + r + 1 < img.width() {
        return ic_angle_wide(img, x, y);
    }
    let centre = img.row(y);
    let mut m10 = 0i32;
    for (u, &p) in (-(r as i32)..=r as i32).zip(&centre[x - r..=x + r]) {
        m10 += u * i32::from(p);
    }
    let mut m01 = 0i32;
    for (v, &d) in UMAX.iter().enumerate().skip(1) {
        let d = d as usize;
        let plus = &img.row(y + v)[x - d..=x + d];
        let minus = &img.row(y - v)[x - d..=x + d];
        let mut v_sum = 0i32;
        for (u, (&p, &m)) in (-(d as i32)..=d as i32).zip(plus.iter().zip(minus)) {
            let (p, m) = (i32::from(p), i32::from(m));
            v_sum += p - m;
            m10 += u * (p + m);
        }
        m01 += v as i32 * v_sum;
    }
    angle_deg_of(m01, m10)
}

/// `u` weights of each row's disc span, 32 columns from `x − 15` (the last one always 0).
const IC_U: [[i16; 32]; HALF_PATCH_SIZE + 1] = {
    let mut t = [[0i16; 32]; HALF_PATCH_SIZE + 1];
    let mut v = 0;
    while v <= HALF_PATCH_SIZE {
        let mut j = 0;
        while j < 32 {
            let u = j as i32 - HALF_PATCH_SIZE as i32;
            if u >= -UMAX[v] && u <= UMAX[v] {
                t[v][j] = u as i16;
            }
            j += 1;
        }
        v += 1;
    }
    t
};

/// `v` weights of each row's disc span (row `v` contributes `v·(I(y+v) − I(y−v))` to `m01`).
const IC_V: [[i16; 32]; HALF_PATCH_SIZE + 1] = {
    let mut t = [[0i16; 32]; HALF_PATCH_SIZE + 1];
    let mut v = 0;
    while v <= HALF_PATCH_SIZE {
        let mut j = 0;
        while j < 32 {
            let u = j as i32 - HALF_PATCH_SIZE as i32;
            if u >= -UMAX[v] && u <= UMAX[v] {
                t[v][j] = v as i16;
            }
            j += 1;
        }
        v += 1;
    }
    t
};

/// [`ic_angle`] with every row read as 32 fixed columns and the disc applied as weight tables:
/// the same integer moments, in straight-line lane arithmetic (needs one column of margin
/// more on the right).
#[inline(always)]
fn ic_angle_wide(img: &ImageView<'_>, x: usize, y: usize) -> f32 {
    let r = HALF_PATCH_SIZE;
    // `row` is wide enough by the caller's margin check; a short row reads as zeros rather
    // than panicking (it cannot happen, and zeros only change the angle).
    let row = |yy: usize| -> &[u8; 32] {
        img.row(yy).get(x - r..).and_then(|s| s.first_chunk::<32>()).unwrap_or(&[0; 32])
    };
    let c = row(y);
    let mut a10 = [0i32; 32];
    let mut a01 = [0i32; 32];
    for j in 0..32 {
        a10[j] = i32::from(IC_U[0][j]) * i32::from(c[j]);
    }
    for v in 1..=r {
        let (p, m) = (row(y + v), row(y - v));
        let (wu, wv) = (&IC_U[v], &IC_V[v]);
        for j in 0..32 {
            let (pj, mj) = (i32::from(p[j]), i32::from(m[j]));
            a10[j] += i32::from(wu[j]) * (pj + mj);
            a01[j] += i32::from(wv[j]) * (pj - mj);
        }
    }
    let m10: i32 = a10.iter().sum();
    let m01: i32 = a01.iter().sum();
    angle_deg_of(m01, m10)
}

#[inline(always)]
fn angle_deg_of(m01: i32, m10: i32) -> f32 {
    let mut deg = math::atan2f(m01 as f32, m10 as f32) * (180.0 / core::f32::consts::PI);
    if deg < 0.0 {
        deg += 360.0;
    }
    if deg >= 360.0 {
        deg = 0.0;
    }
    deg
}

/// Steered rBRIEF descriptor of the key point at `(x, y)` with orientation `angle_deg`, sampled
/// on the blurred level image.
///
/// # Panics
/// If the rotated pattern leaves the image: keep `(x, y)` at least 19 px (ORB-SLAM2's
/// `EDGE_THRESHOLD`) from the border.
///
/// Runs as x86-64-v3 code where the CPU has it ([`crate::arch::v3`]; the same bits).
pub fn describe(blurred: &ImageView<'_>, x: usize, y: usize, angle_deg: f32) -> Descriptor {
    crate::arch::v3(
        #[inline(always)]
        || describe_body(blurred, x, y, angle_deg),
    )
}

#[inline(always)]
fn describe_body(blurred: &ImageView<'_>, x: usize, y: usize, angle_deg: f32) -> Descriptor {
    let ang = angle_deg * (core::f32::consts::PI / 180.0);
    // cos/sin in Q16: the rotated coordinates become exact integer arithmetic that vectorises
    // (a float→int cast per point does not: Rust's saturating `as` stays scalar). The Q16
    // quantisation moves a rotated coordinate by < 2·10⁻⁴ px, so the rounded pixel differs from
    // float rotation only for points within that distance of a half-pixel boundary.
    let a = round_i32(math::cosf(ang) * ROT_ONE as f32);
    let b = round_i32(math::sinf(ang) * ROT_ONE as f32);
    let stride = blurred.stride() as i32;
    let mut offs = [0i32; 512];
    for (o, &(px, py)) in offs.iter_mut().zip(PATTERN_POINTS.iter()) {
        let col = (px * a - py * b + ROT_ONE / 2) >> ROT_BITS;
        let row = (px * b + py * a + ROT_ONE / 2) >> ROT_BITS;
        *o = row * stride + col;
    }
    let centre = (y * blurred.stride() + x) as isize;
    let data = blurred.data();
    let at = |o: i32| data[(centre + o as isize) as usize];
    let mut out = [0u8; 32];
    for (byte, o) in out.iter_mut().zip(offs.chunks_exact(16)) {
        let mut v = 0u8;
        for bit in 0..8 {
            v |= u8::from(at(o[2 * bit]) < at(o[2 * bit + 1])) << bit;
        }
        *byte = v;
    }
    Descriptor(out)
}

/// Fractional bits of the fixed-point rotation in [`describe`].
const ROT_BITS: u32 = 16;
const ROT_ONE: i32 = 1 << ROT_BITS;

/// [`BIT_PATTERN_31`] as 512 `(x, y)` points (pair `i` is points `2i`, `2i + 1`).
const PATTERN_POINTS: [(i32, i32); 512] = {
    let mut out = [(0i32, 0i32); 512];
    let mut i = 0;
    while i < 256 {
        let p = BIT_PATTERN_31[i];
        out[2 * i] = (p[0] as i32, p[1] as i32);
        out[2 * i + 1] = (p[2] as i32, p[3] as i32);
        i += 1;
    }
    out
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing;

    #[test]
    fn umax_matches_orbslam2_construction() {
        let hp = HALF_PATCH_SIZE as i32;
        let mut umax = [0i32; HALF_PATCH_SIZE + 1];
        let vmax = (hp as f64 * 2f64.sqrt() / 2.0 + 1.0).floor() as i32;
        let vmin = (hp as f64 * 2f64.sqrt() / 2.0).ceil() as i32;
        let hp2 = (hp * hp) as f64;
        for v in 0..=vmax {
            umax[v as usize] = (hp2 - (v * v) as f64).sqrt().round() as i32;
        }
        let mut v0 = 0usize;
        let mut v = hp;
        while v >= vmin {
            while umax[v0] == umax[v0 + 1] {
                v0 += 1;
            }
            umax[v as usize] = v0 as i32;
            v0 += 1;
            v -= 1;
        }
        assert_eq!(umax, UMAX);
    }

    #[test]
    fn pattern_is_within_patch() {
        for p in BIT_PATTERN_31.iter() {
            for &c in p {
                assert!((-13..=12).contains(&c));
            }
        }
        // Rotated by any angle the pattern stays within 19 px (ORB-SLAM2's EDGE_THRESHOLD).
        let r = BIT_PATTERN_31
            .iter()
            .flat_map(|p| [(p[0], p[1]), (p[2], p[3])])
            .map(|(x, y)| ((x as f32).powi(2) + (y as f32).powi(2)).sqrt())
            .fold(0.0f32, f32::max);
        assert!(r < 18.5, "{r}");
    }

    #[test]
    fn hamming_counts_bits() {
        let a = Descriptor([0; 32]);
        let mut b = Descriptor([0; 32]);
        assert_eq!(hamming(&a, &b), 0);
        b.0[0] = 0b1011;
        b.0[31] = 0x80;
        assert_eq!(hamming(&a, &b), 4);
        assert_eq!(Descriptor([0xff; 32]).distance(&a), 256);
    }

    fn ramp(w: usize, h: usize, deg: f32) -> Vec<u8> {
        let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
        let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 - cx, (i / w) as f32 - cy);
                (128.0 + 3.0 * (x * c + y * s)).clamp(0.0, 255.0) as u8
            })
            .collect()
    }

    #[test]
    fn orientation_follows_gradient_direction() {
        let (w, h) = (48usize, 48usize);
        for deg in [0.0f32, 30.0, 90.0, 135.0, 200.0, 290.0, 350.0] {
            let img = ramp(w, h, deg);
            let v = ImageView::from_slice(&img, w, h).unwrap();
            let got = ic_angle(&v, 24, 24);
            let mut err = (got - deg).abs();
            err = err.min(360.0 - err);
            assert!(err < 2.0, "gradient at {deg}°: orientation {got}°");
        }
    }

    #[test]
    fn descriptor_of_rotated_patch_is_steered() {
        // A patch and its copy rotated by 90° (exact pixel rotation) give (nearly) the same
        // descriptor once each is steered by its own orientation.
        let n = 61usize;
        let mut noise = vec![0u8; n * n];
        testing::noise(&mut noise, 0x9e37_79b9);
        let mut raw: Vec<f32> = noise.iter().map(|&v| f32::from(v)).collect();
        // Smooth so that rounding the rotated pattern lands on similar values.
        for _ in 0..4 {
            let src = raw.clone();
            for y in 1..n - 1 {
                for x in 1..n - 1 {
                    raw[y * n + x] = (src[y * n + x] * 4.0
                        + src[y * n + x - 1]
                        + src[y * n + x + 1]
                        + src[(y - 1) * n + x]
                        + src[(y + 1) * n + x])
                        / 8.0;
                }
            }
        }
        let a: Vec<u8> = raw.iter().map(|&v| v as u8).collect();
        let mut b = vec![0u8; n * n];
        testing::rotate_90_cw(&a, &mut b, n);
        let av = ImageView::from_slice(&a, n, n).unwrap();
        let bv = ImageView::from_slice(&b, n, n).unwrap();
        let c = n / 2;
        let (ta, tb) = (ic_angle(&av, c, c), ic_angle(&bv, c, c));
        let mut dt = (tb - ta - 90.0).rem_euclid(360.0);
        dt = dt.min(360.0 - dt);
        assert!(dt < 1.0, "angles {ta} {tb}");
        let d = hamming(&describe(&av, c, c, ta), &describe(&bv, c, c, tb));
        let unsteered = hamming(&describe(&av, c, c, 0.0), &describe(&bv, c, c, 0.0));
        assert!(d <= 25, "steered distance {d}");
        assert!(unsteered > 60, "unsteered distance {unsteered}");
    }
}
