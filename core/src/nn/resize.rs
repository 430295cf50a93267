//! int8 bilinear `Resize` (ONNX `mode = linear`, `coordinate_transformation_mode = half_pixel`,
//! static output `sizes`; torch `interpolate(bilinear, align_corners=False)`).
//!
//! ONNX maps output index `o` of an axis of `n_in → n_out` to the source coordinate
//! `s = (o + ½)·n_in/n_out − ½`, clamped to `[0, n_in − 1]`, and blends the two neighbours
//! `floor(s)`, `floor(s) + 1` with weights `1 − frac`, `frac` (separately in y and x).
//!
//! Fixed point: `s = num / den` exactly, with `num = (2o + 1)·n_in − n_out` and
//! `den = 2·n_out`, so the neighbour index is an exact integer division and only the fraction
//! is rounded, to 11 bits: `w = round_half_up(frac · 2^11)` ∈ `[0, 2^11]`. Then
//! ```text
//! acc = (2^11 − wy)·((2^11 − wx)·a + wx·b) + wy·((2^11 − wx)·c + wx·d)     a..d = x − zp_in
//! y   = clamp(zp_out + M(acc), −128, 127),   M = s_in / (s_out · 2^22)
//! ```
//! `|acc| ≤ 255·2^22 < 2^31`. Against the float op on the dequantised input: each weight is off
//! by at most `2^-12`, so the blend is off by at most `2·2^-12·255 ≈ 0.125` input steps (0 for
//! the network's exact ×4 / ×8 factors, whose fractions are multiples of 1/16); with the final
//! rounding the int8 output is within one output step of `round(float / s_out) + zp_out` (the
//! tests assert exactly this). ONNX computes the scale `n_out/n_in` in f32; the exact rational
//! used here differs from it by less than `10^-6` pixel, far below the weight rounding.
//!
//! This file holds the definition, the checks at entry and the reference kernel, which
//! recomputes everything per element (no scratch memory). [`resize_bilinear_fast`] hands the
//! checked operands to `nn::dispatch`: `nn::x86::resize` (separable, AVX2; 40 KiB of stack)
//! or `nn::portable::resize` (taps hoisted per row and pixel, channel vectors blended in one
//! zipped loop; no scratch).

use super::dispatch;
use super::{check_tensor, check_zero_point, NnError, Requant, Shape};

/// Fractional bits of the interpolation weights.
pub const RESIZE_FRAC_BITS: u32 = 11;
const ONE: i32 = 1 << RESIZE_FRAC_BITS;

/// The `half_pixel` taps of output index `o` on an axis `n_in → n_out` (both `> 0`):
/// `(i0, i1, w1)`, the value being `(2^11 − w1)·x[i0] + w1·x[i1]` (over `2^11`).
#[inline]
pub fn half_pixel_taps(o: usize, n_in: usize, n_out: usize) -> (usize, usize, i32) {
    // clamp at 0 as ONNX/torch do (the first half output pixel of an upsampling)
    let num = ((2 * o as i64 + 1) * n_in as i64 - n_out as i64).max(0);
    let den = 2 * n_out as i64;
    let i0 = (num / den) as usize;
    if i0 + 1 >= n_in {
        return (n_in - 1, n_in - 1, 0);
    }
    let frac = num % den;
    let w1 = ((frac << (RESIZE_FRAC_BITS + 1)) + den) / (2 * den);
    (i0, i0 + 1, w1 as i32)
}

/// Quantisation of a resize: zero points and `M = s_in / (s_out · 2^22)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ResizeQuant {
    /// Zero point of the input.
    pub input_zero_point: i32,
    /// Zero point of the output.
    pub output_zero_point: i32,
    /// `s_in / (s_out · 2^22)`.
    pub requant: Requant,
}

impl ResizeQuant {
    /// From the input and output scales and zero points.
    pub fn new(s_in: f64, zp_in: i32, s_out: f64, zp_out: i32) -> Self {
        Self {
            input_zero_point: zp_in,
            output_zero_point: zp_out,
            requant: Requant::from_scale(s_in / (s_out * (1u64 << (2 * RESIZE_FRAC_BITS)) as f64)),
        }
    }
}

fn check_resize(
    x: &[i8],
    xs: Shape,
    size: (usize, usize),
    q: &ResizeQuant,
    out: &[i8],
) -> Result<Shape, NnError> {
    check_tensor(x.len(), xs)?;
    check_zero_point(q.input_zero_point)?;
    let os = Shape::new(xs.c, size.0, size.1);
    check_tensor(out.len(), os)?;
    Ok(os)
}

/// The 2-D blend of four zero-point-corrected neighbours with 11-bit weights (`|·| < 2^31`).
#[inline]
pub(crate) fn blend(a: i32, b: i32, c: i32, d: i32, wx: i32, wy: i32) -> i32 {
    (ONE - wy) * ((ONE - wx) * a + wx * b) + wy * ((ONE - wx) * c + wx * d)
}

/// Bilinear resize to `size = (h, w)`, reference: every element from the ONNX formula.
pub fn resize_bilinear_reference(
    x: &[i8],
    xs: Shape,
    size: (usize, usize),
    q: &ResizeQuant,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_resize(x, xs, size, q, out)?;
    let zp = q.input_zero_point;
    for oy in 0..os.h {
        for ox in 0..os.w {
            for c in 0..os.c {
                let (y0, y1, wy) = half_pixel_taps(oy, xs.h, os.h);
                let (x0, x1, wx) = half_pixel_taps(ox, xs.w, os.w);
                let v = |yy: usize, xx: usize| x[xs.index(c, yy, xx)] as i32 - zp;
                let acc = blend(v(y0, x0), v(y0, x1), v(y1, x0), v(y1, x1), wx, wy);
                out[os.index(c, oy, ox)] = q.requant.to_i8(acc, q.output_zero_point, -128, 127);
            }
        }
    }
    Ok(os)
}

/// Bilinear resize, fast: the same integers as [`resize_bilinear_reference`]. On x86-64 with
/// AVX2 (outputs up to 2048 wide) `nn::x86::resize`'s separable kernel — each source row
/// blended in `x` once per chunk of output columns, each output row then one flat blend in `y`
/// and requantisation of 8 values at a time, whatever the channel count. Portable
/// (`nn::portable::resize`): taps hoisted per row / pixel, channel vectors blended in one pass.
pub fn resize_bilinear_fast(
    x: &[i8],
    xs: Shape,
    size: (usize, usize),
    q: &ResizeQuant,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_resize(x, xs, size, q, out)?;
    dispatch::resize_bilinear(x, xs, q, out, os);
    Ok(os)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::testutil::{kernel_equivalence, max_diff, quantise, KernelCase, Rng};
    use std::format;
    use std::string::String;
    use std::vec;
    use std::vec::Vec;

    /// ONNX half_pixel linear taps in f64: (i0, i1, frac).
    fn float_taps(o: usize, n_in: usize, n_out: usize) -> (usize, usize, f64) {
        let s = ((o as f64 + 0.5) * n_in as f64 / n_out as f64 - 0.5).max(0.0);
        let i0 = s.floor() as usize;
        if i0 + 1 >= n_in {
            (n_in - 1, n_in - 1, 0.0)
        } else {
            (i0, i0 + 1, s - i0 as f64)
        }
    }

    #[test]
    fn taps_match_float_half_pixel() {
        for n_in in 1..20 {
            for n_out in 1..50 {
                for o in 0..n_out {
                    let (a, b, w) = half_pixel_taps(o, n_in, n_out);
                    let (fa, fb, fw) = float_taps(o, n_in, n_out);
                    assert_eq!((a, b), (fa, fb), "{o} {n_in} {n_out}");
                    assert!((w as f64 / ONE as f64 - fw).abs() <= 0.5 / ONE as f64 + 1e-12);
                }
            }
        }
        // x4 (the FFM) is exact: fractions are multiples of 1/8
        for o in 0..40 {
            let (_, _, w) = half_pixel_taps(o, 10, 40);
            assert_eq!(w % (ONE / 8), 0);
        }
    }

    /// A resize case with its scales (for the float check, when `float`).
    struct ResizeCase {
        x: Vec<i8>,
        xs: Shape,
        size: (usize, usize),
        q: ResizeQuant,
        scales: (f64, f64),
        float: bool,
    }

    impl ResizeCase {
        fn new(rng: &mut Rng, xs: Shape, size: (usize, usize), zp_same: bool, float: bool) -> Self {
            let x = rng.i8s(xs.len());
            let (s_in, zp_in) = (rng.f64(0.01, 0.1), rng.zp());
            let (s_out, zp_out) =
                if zp_same { (s_in, zp_in) } else { (s_in * rng.f64(0.7, 1.3), rng.zp()) };
            let q = ResizeQuant::new(s_in, zp_in, s_out, zp_out);
            Self { x, xs, size, q, scales: (s_in, s_out), float }
        }
    }

    impl KernelCase for ResizeCase {
        fn out_shape(&self) -> Shape {
            Shape::new(self.xs.c, self.size.0, self.size.1)
        }
        fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            resize_bilinear_reference(&self.x, self.xs, self.size, &self.q, out)
        }
        fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            resize_bilinear_fast(&self.x, self.xs, self.size, &self.q, out)
        }
        fn describe(&self) -> String {
            format!("{:?} -> {:?}", self.xs, self.size)
        }
        fn check(&self, r: &[i8]) {
            if !self.float {
                return;
            }
            let (xs, os) = (self.xs, self.out_shape());
            let (s_in, s_out) = self.scales;
            let (zp_in, zp_out) = (self.q.input_zero_point, self.q.output_zero_point);
            let mut e = vec![0i32; os.len()];
            for oy in 0..os.h {
                let (y0, y1, fy) = float_taps(oy, xs.h, os.h);
                for ox in 0..os.w {
                    let (x0, x1, fx) = float_taps(ox, xs.w, os.w);
                    for ch in 0..xs.c {
                        let v =
                            |yy, xx| (self.x[xs.index(ch, yy, xx)] as i32 - zp_in) as f64 * s_in;
                        let top = v(y0, x0) * (1.0 - fx) + v(y0, x1) * fx;
                        let bot = v(y1, x0) * (1.0 - fx) + v(y1, x1) * fx;
                        let y = top * (1.0 - fy) + bot * fy;
                        e[os.index(ch, oy, ox)] = quantise(y, s_out, zp_out, -128, 127);
                    }
                }
            }
            assert!(max_diff(r, &e) <= 1, "{}", self.describe());
        }
    }

    /// The resizes of the 192×640 network (`benches/nn.rs`): the PPM's 1/2/3/6 bins to 6×20,
    /// the FFM's ×4, and the classifier's 11 channels ×8 (on a smaller map).
    const WORKLOAD: [(Shape, (usize, usize)); 7] = [
        (Shape::new(11, 6, 20), (48, 160)),
        (Shape::new(11, 24, 80), (192, 640)),
        (Shape::new(128, 6, 20), (24, 80)),
        (Shape::new(32, 1, 1), (6, 20)),
        (Shape::new(32, 2, 2), (6, 20)),
        (Shape::new(32, 3, 3), (6, 20)),
        (Shape::new(32, 6, 5), (6, 20)),
    ];

    kernel_equivalence!(resize_workload_shapes_are_bit_equal, 0x5f, 7, |rng, i| {
        let (xs, size) = WORKLOAD[i];
        let x = rng.i8s(xs.len());
        let q = ResizeQuant::new(rng.f64(0.01, 0.1), rng.zp(), rng.f64(0.01, 0.1), rng.zp());
        Some(ResizeCase { x, xs, size, q, scales: (0.0, 0.0), float: false })
    });

    kernel_equivalence!(resize_fast_equals_reference_and_float, 0x5e, 300, |rng, i| {
        let c = if i % 9 == 0 { rng.usize(30, 70) } else { rng.usize(1, 13) };
        let xs = Shape::new(c, rng.usize(1, 7), rng.usize(1, 7));
        let size = match i % 3 {
            0 => (xs.h * 4, xs.w * 4),
            1 => (xs.h * 8, xs.w * 8),
            _ => (rng.usize(1, 30), rng.usize(1, 30)),
        };
        // every other case the input's own quantisation
        Some(ResizeCase::new(rng, xs, size, i % 2 == 0, true))
    });

    kernel_equivalence!(resize_beyond_the_x86_limits_is_bit_equal, 0x60, 4, |rng, i| {
        // more channels than the x86 kernel's chunk holds, or a wider output than its column
        // table: the portable kernel on every level
        let (xs, size) = match i {
            0 => (Shape::new(2040, 1, 2), (2, 3)),
            1 => (Shape::new(2100, 2, 1), (3, 1)),
            2 => (Shape::new(1, 2, 3), (2, 2100)),
            _ => (Shape::new(3, 1, 2), (1, 2049)),
        };
        Some(ResizeCase::new(rng, xs, size, false, true))
    });

    kernel_equivalence!(resize_at_the_arm64_chunk_is_bit_equal, 0x61, 5, |rng, i| {
        // `arm64::resize` stages at most 512 values and 64 pixels of an output row: one pixel
        // of 512 channels a chunk, more channels (portable), many 64-pixel chunks of one
        // channel, and a pixel count that leaves a short last chunk
        let (xs, size) = match i {
            0 => (Shape::new(512, 2, 3), (3, 5)),
            1 => (Shape::new(513, 1, 2), (2, 3)),
            2 => (Shape::new(1, 2, 3), (3, 700)),
            3 => (Shape::new(11, 3, 5), (24, 130)),
            _ => (Shape::new(100, 3, 4), (7, 11)),
        };
        Some(ResizeCase::new(rng, xs, size, i % 2 == 0, true))
    });

    #[test]
    fn resize_bad_operands_are_errors() {
        let q = ResizeQuant::new(0.1, 0, 0.1, 0);
        assert_eq!(
            resize_bilinear_fast(&[0; 4], Shape::new(1, 2, 2), (4, 4), &q, &mut [0; 15]),
            Err(NnError::BufferTooSmall { need: 16, got: 15 })
        );
        assert_eq!(
            resize_bilinear_fast(&[0; 4], Shape::new(1, 2, 2), (0, 4), &q, &mut [0; 16]),
            Err(NnError::BadParam)
        );
    }
}
