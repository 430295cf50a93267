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
//! The fast kernel computes the y taps once per output row and the x taps once per output
//! pixel, and blends whole channel vectors (NHWC) in one zipped loop; the reference recomputes
//! everything per element. No scratch memory.

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

#[inline]
fn blend(a: i32, b: i32, c: i32, d: i32, wx: i32, wy: i32) -> i32 {
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

/// Bilinear resize, fast. On x86-64 with AVX2 (outputs up to 2048 wide): `nn::simd`'s
/// separable kernel — each source row blended in `x` once per chunk of output columns, each
/// output row then one flat blend in `y` and requantisation of 8 values at a time, whatever
/// the channel count. Portable: taps hoisted per row / pixel, channel vectors blended in one
/// pass.
pub fn resize_bilinear_fast(
    x: &[i8],
    xs: Shape,
    size: (usize, usize),
    q: &ResizeQuant,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_resize(x, xs, size, q, out)?;
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    if super::quant::simd_allowed()
        && xs.c <= super::simd::RESIZE_MAX_C
        && os.w <= super::simd::RESIZE_MAX_OW
        && super::quant::fits_simd_requant(255 << (2 * RESIZE_FRAC_BITS), &[], &[q.requant])
    {
        let a = super::simd::Rs {
            x,
            h: xs.h,
            w: xs.w,
            c: xs.c,
            oh: os.h,
            ow: os.w,
            zp: q.input_zero_point,
            zo: q.output_zero_point,
            requant: q.requant,
            taps: half_pixel_taps,
        };
        super::simd::resize(&a, out);
        return Ok(os);
    }
    resize_portable(x, xs, q, out, os);
    Ok(os)
}

/// The portable resize kernel (see [`resize_bilinear_fast`]).
fn resize_portable(x: &[i8], xs: Shape, q: &ResizeQuant, out: &mut [i8], os: Shape) {
    let c = xs.c;
    let zp = q.input_zero_point;
    let zo = q.output_zero_point;
    let rq = q.requant;
    let out = &mut out[..os.len()];
    for (oy, orow) in out.chunks_exact_mut(os.w * c).enumerate() {
        let (y0, y1, wy) = half_pixel_taps(oy, xs.h, os.h);
        let (r0, r1) = (y0 * xs.w * c, y1 * xs.w * c);
        for (ox, opix) in orow.chunks_exact_mut(c).enumerate() {
            let (x0, x1, wx) = half_pixel_taps(ox, xs.w, os.w);
            let (p0, p1) = (x0 * c, x1 * c);
            let a = &x[r0 + p0..r0 + p0 + c];
            let b = &x[r0 + p1..r0 + p1 + c];
            let cc = &x[r1 + p0..r1 + p0 + c];
            let d = &x[r1 + p1..r1 + p1 + c];
            for ((((o, &va), &vb), &vc), &vd) in opix.iter_mut().zip(a).zip(b).zip(cc).zip(d) {
                let acc =
                    blend(va as i32 - zp, vb as i32 - zp, vc as i32 - zp, vd as i32 - zp, wx, wy);
                *o = rq.to_i8(acc, zo, -128, 127);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::quant::portable;
    use crate::nn::testutil::{max_diff, quantise, Rng};
    use std::vec;

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

    /// The resizes of the 192×640 network (`benches/nn.rs`): the PPM's 1/2/3/6 bins to 6×20,
    /// the FFM's ×4, and the classifier's 11 channels ×8 (on a smaller map).
    #[test]
    fn resize_workload_shapes_are_bit_equal() {
        let mut rng = Rng::new(0x5f);
        let cases = [
            (Shape::new(11, 6, 20), (48, 160)),
            (Shape::new(11, 24, 80), (192, 640)),
            (Shape::new(128, 6, 20), (24, 80)),
            (Shape::new(32, 1, 1), (6, 20)),
            (Shape::new(32, 2, 2), (6, 20)),
            (Shape::new(32, 3, 3), (6, 20)),
            (Shape::new(32, 6, 5), (6, 20)),
        ];
        for (xs, size) in cases {
            let os = Shape::new(xs.c, size.0, size.1);
            let x = rng.i8s(xs.len());
            let q = ResizeQuant::new(rng.f64(0.01, 0.1), rng.zp(), rng.f64(0.01, 0.1), rng.zp());
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            let mut g = vec![2i8; os.len()];
            resize_bilinear_reference(&x, xs, size, &q, &mut r).unwrap();
            resize_bilinear_fast(&x, xs, size, &q, &mut f).unwrap();
            portable(|| resize_bilinear_fast(&x, xs, size, &q, &mut g)).unwrap();
            assert_eq!(r, f, "{xs:?} {size:?}");
            assert_eq!(r, g, "portable {xs:?} {size:?}");
        }
    }

    #[test]
    fn resize_fast_equals_reference_and_float() {
        let mut rng = Rng::new(0x5e);
        for i in 0..300 {
            let c = if i % 9 == 0 { rng.usize(30, 70) } else { rng.usize(1, 13) };
            let xs = Shape::new(c, rng.usize(1, 7), rng.usize(1, 7));
            let size = match i % 3 {
                0 => (xs.h * 4, xs.w * 4),
                1 => (xs.h * 8, xs.w * 8),
                _ => (rng.usize(1, 30), rng.usize(1, 30)),
            };
            let os = Shape::new(c, size.0, size.1);
            let x = rng.i8s(xs.len());
            let (s_in, zp_in) = (rng.f64(0.01, 0.1), rng.zp());
            let (s_out, zp_out) =
                if i % 2 == 0 { (s_in, zp_in) } else { (s_in * rng.f64(0.7, 1.3), rng.zp()) };
            let q = ResizeQuant::new(s_in, zp_in, s_out, zp_out);
            let mut r = vec![0i8; os.len()];
            let mut f = vec![1i8; os.len()];
            assert_eq!(resize_bilinear_reference(&x, xs, size, &q, &mut r), Ok(os));
            assert_eq!(resize_bilinear_fast(&x, xs, size, &q, &mut f), Ok(os));
            assert_eq!(r, f, "{xs:?} {size:?}");
            let mut g = vec![2i8; os.len()];
            portable(|| resize_bilinear_fast(&x, xs, size, &q, &mut g)).unwrap();
            assert_eq!(r, g, "portable {xs:?} {size:?}");
            let mut e = vec![0i32; os.len()];
            for oy in 0..os.h {
                let (y0, y1, fy) = float_taps(oy, xs.h, os.h);
                for ox in 0..os.w {
                    let (x0, x1, fx) = float_taps(ox, xs.w, os.w);
                    for ch in 0..c {
                        let v = |yy, xx| (x[xs.index(ch, yy, xx)] as i32 - zp_in) as f64 * s_in;
                        let top = v(y0, x0) * (1.0 - fx) + v(y0, x1) * fx;
                        let bot = v(y1, x0) * (1.0 - fx) + v(y1, x1) * fx;
                        let y = top * (1.0 - fy) + bot * fy;
                        e[os.index(ch, oy, ox)] = quantise(y, s_out, zp_out, -128, 127);
                    }
                }
            }
            assert!(max_diff(&r, &e) <= 1, "{xs:?} {size:?}");
        }
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
