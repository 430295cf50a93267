//! The PPM's int8 `AveragePool`.
//!
//! ONNX `AveragePool` as `models/semloc_models/fastscnn.py` exports it for the pyramid pooling
//! module: window = stride = `kh × kw` (for `b` bins on an `h × w` map, `ceil(h/b) × ceil(w/b)`),
//! zero padding on the bottom/right only (`pads = [0, 0, pb, pr]`, so the last window is whole),
//! `count_include_pad = 0`: each output is the mean over the *real* pixels of its window.
//!
//! Integer form, per window with `n` real pixels and channel `c`:
//! ```text
//! sum = Σ (x − zp_in)                                   (exact, |sum| ≤ 255·n)
//! avg = round_half_away(sum · 2^16 / n)                 (the mean with 16 fractional bits)
//! y   = clamp(zp_out + M(avg), −128, 127),  M = s_in / (s_out · 2^16)
//! ```
//! The mean is kept with 16 fractional bits before the one requantisation, so the only
//! rounding that matters is the final one (the `2^-17` error of `avg` is far below an output
//! step): the result is within one step of `round(mean_real / s_out) + zp_out`.
//! The reference loops per element (no scratch). [`avgpool_fast`] hands the checked operands to
//! `nn::dispatch`, whose kernel on every target is `nn::portable::pool`: each real pixel of a
//! window adds its channel vector to a 64-channel stack block (256 bytes), which vectorises
//! over channels.

use super::dispatch;
use super::{check_tensor, check_zero_point, NnError, Requant, Shape};

/// Fractional bits of the window mean before requantisation.
pub const AVG_FRAC_BITS: u32 = 16;

/// Geometry of the PPM average pool: window = stride, bottom/right zero padding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AvgPoolParams {
    /// Window (and stride) height and width.
    pub kernel: (usize, usize),
    /// Zero padding at the bottom and on the right (ONNX `pads[2]`, `pads[3]`).
    pub pad_bottom_right: (usize, usize),
}

impl AvgPoolParams {
    /// The parameters `fastscnn._bin_geometry` gives for `bins` bins on `input`.
    pub fn ppm(input: Shape, bins: usize) -> Result<Self, NnError> {
        if bins == 0 || input.is_empty() {
            return Err(NnError::BadParam);
        }
        let kh = input.h.div_ceil(bins);
        let kw = input.w.div_ceil(bins);
        Ok(Self {
            kernel: (kh, kw),
            pad_bottom_right: (
                input.h.div_ceil(kh) * kh - input.h,
                input.w.div_ceil(kw) * kw - input.w,
            ),
        })
    }

    /// The output shape (ONNX, floor mode: `(h + pb − kh)/kh + 1`).
    pub fn output_shape(&self, input: Shape) -> Result<Shape, NnError> {
        let (kh, kw) = self.kernel;
        let (pb, pr) = self.pad_bottom_right;
        // a pad of a whole window would make an all-padding window with no real pixel
        if input.is_empty()
            || kh == 0
            || kw == 0
            || pb >= kh
            || pr >= kw
            || kh.saturating_mul(kw) > 1 << 16
        {
            return Err(NnError::BadParam);
        }
        if input.h + pb < kh || input.w + pr < kw {
            return Err(NnError::BadParam);
        }
        Ok(Shape::new(input.c, (input.h + pb - kh) / kh + 1, (input.w + pr - kw) / kw + 1))
    }
}

/// Quantisation of the pool: zero points and `M = s_in / (s_out · 2^16)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoolQuant {
    /// Zero point of the input.
    pub input_zero_point: i32,
    /// Zero point of the output.
    pub output_zero_point: i32,
    /// `s_in / (s_out · 2^16)`.
    pub requant: Requant,
}

impl PoolQuant {
    /// From the input and output scales and zero points.
    pub fn new(s_in: f64, zp_in: i32, s_out: f64, zp_out: i32) -> Self {
        Self {
            input_zero_point: zp_in,
            output_zero_point: zp_out,
            requant: Requant::from_scale(s_in / (s_out * (1u64 << AVG_FRAC_BITS) as f64)),
        }
    }

    /// The output value of a window with sum `sum` over `n > 0` real pixels.
    #[inline]
    pub(crate) fn finish(&self, sum: i32, n: i32) -> i8 {
        let num = (sum as i64).abs() << AVG_FRAC_BITS;
        let d = n as i64;
        let avg = ((2 * num + d) / (2 * d)) as i32;
        let avg = if sum < 0 { -avg } else { avg };
        self.requant.to_i8(avg, self.output_zero_point, -128, 127)
    }
}

fn check_pool(
    x: &[i8],
    xs: Shape,
    p: &AvgPoolParams,
    q: &PoolQuant,
    out: &[i8],
) -> Result<Shape, NnError> {
    check_tensor(x.len(), xs)?;
    check_zero_point(q.input_zero_point)?;
    let os = p.output_shape(xs)?;
    check_tensor(out.len(), os)?;
    Ok(os)
}

/// Average pool, reference: for each output element, the mean over the real pixels of its
/// window, as the ONNX definition with `count_include_pad = 0`.
pub fn avgpool_reference(
    x: &[i8],
    xs: Shape,
    p: &AvgPoolParams,
    q: &PoolQuant,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_pool(x, xs, p, q, out)?;
    let (kh, kw) = p.kernel;
    for oy in 0..os.h {
        for ox in 0..os.w {
            for c in 0..os.c {
                let (mut sum, mut n) = (0i32, 0i32);
                for ky in 0..kh {
                    for kx in 0..kw {
                        let (iy, ix) = (oy * kh + ky, ox * kw + kx);
                        if iy < xs.h && ix < xs.w {
                            sum += x[xs.index(c, iy, ix)] as i32 - q.input_zero_point;
                            n += 1;
                        }
                    }
                }
                out[os.index(c, oy, ox)] = q.finish(sum, n);
            }
        }
    }
    Ok(os)
}

/// Average pool, fast: the same integers as [`avgpool_reference`]; per window and 64-channel
/// block, each real pixel adds its channel vector to a stack accumulator.
pub fn avgpool_fast(
    x: &[i8],
    xs: Shape,
    p: &AvgPoolParams,
    q: &PoolQuant,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    let os = check_pool(x, xs, p, q, out)?;
    dispatch::avgpool(x, xs, p, q, out, os);
    Ok(os)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::testutil::{kernel_equivalence, max_diff, quantise, KernelCase};
    use std::format;
    use std::string::String;
    use std::vec;
    use std::vec::Vec;

    #[test]
    fn ppm_params_match_the_python_definition() {
        // models/README.md: at 384x1248 the 1/32 map is 12x39; bins 6 → 2x7 windows, pad right 3
        let p = AvgPoolParams::ppm(Shape::new(128, 12, 39), 6).unwrap();
        assert_eq!(p, AvgPoolParams { kernel: (2, 7), pad_bottom_right: (0, 3) });
        assert_eq!(p.output_shape(Shape::new(128, 12, 39)), Ok(Shape::new(128, 6, 6)));
        // 192x624 → 6x20, bin 6: 1x4 windows, 6x5 outputs
        let s = Shape::new(8, 6, 20);
        assert_eq!(AvgPoolParams::ppm(s, 6).unwrap().output_shape(s), Ok(Shape::new(8, 6, 5)));
        assert_eq!(AvgPoolParams::ppm(s, 1).unwrap().output_shape(s), Ok(Shape::new(8, 1, 1)));
    }

    /// An average-pool case with its scales (for the float check).
    struct PoolCase {
        x: Vec<i8>,
        xs: Shape,
        p: AvgPoolParams,
        q: PoolQuant,
        scales: (f64, f64),
    }

    impl KernelCase for PoolCase {
        fn out_shape(&self) -> Shape {
            self.p.output_shape(self.xs).unwrap()
        }
        fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            avgpool_reference(&self.x, self.xs, &self.p, &self.q, out)
        }
        fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            avgpool_fast(&self.x, self.xs, &self.p, &self.q, out)
        }
        fn describe(&self) -> String {
            format!("{:?} {:?}", self.xs, self.p)
        }
        fn check(&self, r: &[i8]) {
            let (xs, p, os) = (self.xs, self.p, self.out_shape());
            let (s_in, s_out) = self.scales;
            let (zp_in, zp_out) = (self.q.input_zero_point, self.q.output_zero_point);
            let mut e = vec![0i32; os.len()];
            for oy in 0..os.h {
                for ox in 0..os.w {
                    for ch in 0..xs.c {
                        let (mut s, mut n) = (0.0, 0.0);
                        for iy in oy * p.kernel.0..((oy + 1) * p.kernel.0).min(xs.h) {
                            for ix in ox * p.kernel.1..((ox + 1) * p.kernel.1).min(xs.w) {
                                s += (self.x[xs.index(ch, iy, ix)] as i32 - zp_in) as f64 * s_in;
                                n += 1.0;
                            }
                        }
                        e[os.index(ch, oy, ox)] = quantise(s / n, s_out, zp_out, -128, 127);
                    }
                }
            }
            assert!(max_diff(r, &e) <= 1, "{}", self.describe());
        }
    }

    kernel_equivalence!(avgpool_fast_equals_reference_and_float, 0x9001, 300, |rng, i| {
        // every 7th case more channels than the 64-channel accumulator block
        let c = if i % 7 == 0 { rng.usize(60, 130) } else { rng.usize(1, 6) };
        let xs = Shape::new(c, rng.usize(1, 14), rng.usize(1, 41));
        let p = AvgPoolParams::ppm(xs, rng.usize(1, 6)).unwrap();
        let x = rng.i8s(xs.len());
        let (s_in, zp_in) = (rng.f64(0.01, 0.1), rng.zp());
        let (s_out, zp_out) = (s_in * rng.f64(0.5, 1.5), rng.zp());
        let q = PoolQuant::new(s_in, zp_in, s_out, zp_out);
        Some(PoolCase { x, xs, p, q, scales: (s_in, s_out) })
    });

    #[test]
    fn avgpool_bad_parameters_are_errors() {
        let huge = AvgPoolParams { kernel: (usize::MAX, usize::MAX), pad_bottom_right: (0, 0) };
        let q = PoolQuant::new(0.1, 0, 0.1, 0);
        assert_eq!(
            avgpool_reference(&[0; 16], Shape::new(1, 4, 4), &huge, &q, &mut [0; 16]),
            Err(NnError::BadParam)
        );
        let p = AvgPoolParams { kernel: (2, 2), pad_bottom_right: (2, 0) };
        let q = PoolQuant::new(0.1, 0, 0.1, 0);
        assert_eq!(
            avgpool_fast(&[0; 16], Shape::new(1, 4, 4), &p, &q, &mut [0; 16]),
            Err(NnError::BadParam)
        );
    }
}
