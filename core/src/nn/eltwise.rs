//! Element-wise int8 ops: `Add`, `Concat` (channels), `Relu`.
//!
//! - **Add** (ONNX `Add`, same shapes, no broadcasting): TFLite's quantised add. Both inputs are
//!   moved to a common fixed-point domain with 20 fractional bits, each by its own requantiser,
//!   summed, and the sum requantised to the output:
//!   ```text
//!   t = 2·max(s1, s2)
//!   a = M1((x1 − zp1) << 20),  M1 = s1 / t          (≤ 1/2: a right shift)
//!   b = M2((x2 − zp2) << 20),  M2 = s2 / t
//!   y = clamp(zp_out + Mo(a + b), lo, hi),  Mo = t / (2^20 · s_out)
//!   ```
//!   `|x − zp| ≤ 255` so the shifted values stay below `2^28`: nothing overflows.
//! - **Concat** along channels (ONNX `Concat`, `axis = 1` of NCHW = the innermost axis here):
//!   each input is rescaled to the output's quantisation, `y = clamp(zp_out + M_i(x − zp_i))`
//!   with `M_i = s_i / s_out`; an input with the output's own parameters is copied.
//! - **Relu**: `y = clamp(zp_out + M(x − zp_in), max(zp_out, −128), 127)`; with equal in/out
//!   parameters this is `max(x, zp)`. (After a `Conv` or `Add` the ReLU is fused into that op's
//!   clamp instead: [`crate::nn::quant::clamp_range`].)
//!
//! This file holds the ONNX definitions, the checks at entry and the `*_reference` kernels
//! (index by index). The `*_fast` entries hand the checked operands to `nn::dispatch`: the
//! portable kernels (`nn::portable::eltwise`) walk whole slices (`zip`, no indexing) and take
//! the copy / `max` shortcut when a rescale is the identity; on x86-64 with AVX2 `Add` and the
//! rescales of `Concat` run 8 lanes at a time (`nn::x86::eltwise`). The shared kernel tests
//! require them to equal the references bit for bit. No scratch memory.

use super::dispatch;
use super::quant::{clamp_range, ADD_LEFT_SHIFT};
use super::{check_tensor, check_zero_point, NnError, Requant, Shape};

/// A change of quantisation `(s_in, zp_in) → (s_out, zp_out)`: `y = zp_out + M(x − zp_in)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rescale {
    /// Zero point of the input.
    pub input_zero_point: i32,
    /// Zero point of the output.
    pub output_zero_point: i32,
    /// `s_in / s_out`.
    pub requant: Requant,
}

impl Rescale {
    /// From the two tensors' scales and zero points.
    pub fn new(s_in: f64, zp_in: i32, s_out: f64, zp_out: i32) -> Self {
        Self {
            input_zero_point: zp_in,
            output_zero_point: zp_out,
            requant: Requant::from_scale(s_in / s_out),
        }
    }

    /// True when the rescale maps every int8 value to itself.
    pub fn is_identity(&self) -> bool {
        self.requant == Requant::IDENTITY && self.input_zero_point == self.output_zero_point
    }

    /// One value, clamped to `[lo, hi]`.
    #[inline]
    pub fn apply(&self, x: i8, lo: i32, hi: i32) -> i8 {
        self.requant.to_i8(x as i32 - self.input_zero_point, self.output_zero_point, lo, hi)
    }
}

/// The quantisation of an `Add` (see the module docs for the arithmetic).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AddQuant {
    /// Zero point of the first input.
    pub zero_point1: i32,
    /// Zero point of the second input.
    pub zero_point2: i32,
    /// Zero point of the output.
    pub output_zero_point: i32,
    /// `s1 / (2·max(s1, s2))`.
    pub requant1: Requant,
    /// `s2 / (2·max(s1, s2))`.
    pub requant2: Requant,
    /// `2·max(s1, s2) / (2^20 · s_out)`.
    pub output: Requant,
    /// Clamp at the output zero point (a fused `Relu`).
    pub relu: bool,
}

impl AddQuant {
    /// TFLite's parameters for inputs `(s1, zp1)`, `(s2, zp2)` and output `(s_out, zp_out)`.
    pub fn new(s1: f64, zp1: i32, s2: f64, zp2: i32, s_out: f64, zp_out: i32, relu: bool) -> Self {
        let twice_max = 2.0 * if s1 > s2 { s1 } else { s2 };
        Self {
            zero_point1: zp1,
            zero_point2: zp2,
            output_zero_point: zp_out,
            requant1: Requant::from_scale(s1 / twice_max),
            requant2: Requant::from_scale(s2 / twice_max),
            output: Requant::from_scale(twice_max / ((1u64 << ADD_LEFT_SHIFT) as f64 * s_out)),
            relu,
        }
    }

    /// One output value of the add, clamped to `[lo, hi]`.
    #[inline]
    pub(crate) fn add(&self, a: i8, b: i8, lo: i32, hi: i32) -> i8 {
        let a = self.requant1.apply((a as i32 - self.zero_point1) << ADD_LEFT_SHIFT);
        let b = self.requant2.apply((b as i32 - self.zero_point2) << ADD_LEFT_SHIFT);
        self.output.to_i8(a.saturating_add(b), self.output_zero_point, lo, hi)
    }
}

fn check_add(a: &[i8], b: &[i8], shape: Shape, q: &AddQuant, out: &[i8]) -> Result<(), NnError> {
    check_zero_point(q.zero_point1)?;
    check_zero_point(q.zero_point2)?;
    check_tensor(a.len(), shape)?;
    check_tensor(b.len(), shape)?;
    check_tensor(out.len(), shape)
}

/// `Add` of two same-shaped tensors, reference (element by element in NHWC index order).
pub fn add_reference(
    a: &[i8],
    b: &[i8],
    shape: Shape,
    q: &AddQuant,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    check_add(a, b, shape, q, out)?;
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    for y in 0..shape.h {
        for x in 0..shape.w {
            for c in 0..shape.c {
                let i = shape.index(c, y, x);
                out[i] = q.add(a[i], b[i], lo, hi);
            }
        }
    }
    Ok(shape)
}

/// `Add`, fast: the same integers as [`add_reference`]; one zipped pass over the three slices,
/// or on x86-64 with AVX2 the three requantisations on 8 lanes at a time (`nn::x86::eltwise`).
pub fn add_fast(
    a: &[i8],
    b: &[i8],
    shape: Shape,
    q: &AddQuant,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    check_add(a, b, shape, q, out)?;
    dispatch::add(a, b, shape, q, out);
    Ok(shape)
}

/// One input of a channel `Concat`: its data, shape and rescale to the output.
#[derive(Clone, Copy, Debug)]
pub struct ConcatInput<'a> {
    /// The tensor.
    pub data: &'a [i8],
    /// Its shape; all inputs share `h` and `w`.
    pub shape: Shape,
    /// Its quantisation → the output's.
    pub rescale: Rescale,
}

fn check_concat(inputs: &[ConcatInput<'_>], out: &[i8]) -> Result<Shape, NnError> {
    let first = inputs.first().ok_or(NnError::BadParam)?;
    let mut c = 0usize;
    for i in inputs {
        check_tensor(i.data.len(), i.shape)?;
        check_zero_point(i.rescale.input_zero_point)?;
        if i.shape.h != first.shape.h || i.shape.w != first.shape.w {
            let expected = Shape::new(i.shape.c, first.shape.h, first.shape.w);
            return Err(NnError::ShapeMismatch { expected, got: i.shape });
        }
        if i.rescale.output_zero_point != first.rescale.output_zero_point {
            return Err(NnError::BadParam);
        }
        c += i.shape.c;
    }
    let os = Shape::new(c, first.shape.h, first.shape.w);
    check_tensor(out.len(), os)?;
    Ok(os)
}

/// `Concat` along channels, reference: every output element from its source element.
pub fn concat_reference(inputs: &[ConcatInput<'_>], out: &mut [i8]) -> Result<Shape, NnError> {
    let os = check_concat(inputs, out)?;
    for y in 0..os.h {
        for x in 0..os.w {
            let mut c0 = 0;
            for i in inputs {
                for c in 0..i.shape.c {
                    out[os.index(c0 + c, y, x)] =
                        i.rescale.apply(i.data[i.shape.index(c, y, x)], -128, 127);
                }
                c0 += i.shape.c;
            }
        }
    }
    Ok(os)
}

/// `Concat` along channels, fast: the same integers as [`concat_reference`]; per pixel, each
/// input's channel run is copied (identity rescale) or rescaled as one slice (8 lanes at a time
/// on x86-64 with AVX2).
pub fn concat_fast(inputs: &[ConcatInput<'_>], out: &mut [i8]) -> Result<Shape, NnError> {
    let os = check_concat(inputs, out)?;
    let mut c0 = 0;
    for i in inputs {
        dispatch::concat_input(i, c0, os, out);
        c0 += i.shape.c;
    }
    Ok(os)
}

/// Standalone `Relu` (with a rescale to the output's quantisation), reference.
pub fn relu_reference(
    x: &[i8],
    shape: Shape,
    r: &Rescale,
    out: &mut [i8],
) -> Result<Shape, NnError> {
    check_tensor(x.len(), shape)?;
    check_zero_point(r.input_zero_point)?;
    check_tensor(out.len(), shape)?;
    let (lo, hi) = clamp_range(r.output_zero_point, true);
    for y in 0..shape.h {
        for xx in 0..shape.w {
            for c in 0..shape.c {
                let i = shape.index(c, y, xx);
                out[i] = r.apply(x[i], lo, hi);
            }
        }
    }
    Ok(shape)
}

/// Standalone `Relu`, fast: the same integers as [`relu_reference`]; `max(x, zp)` when the
/// rescale is the identity.
pub fn relu_fast(x: &[i8], shape: Shape, r: &Rescale, out: &mut [i8]) -> Result<Shape, NnError> {
    check_tensor(x.len(), shape)?;
    check_zero_point(r.input_zero_point)?;
    check_tensor(out.len(), shape)?;
    dispatch::relu(x, shape, r, out);
    Ok(shape)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::testutil::{kernel_equivalence, max_diff, quantise, KernelCase, Rng};
    use std::format;
    use std::string::String;
    use std::vec;
    use std::vec::Vec;

    fn rand_shape(rng: &mut Rng) -> Shape {
        Shape::new(rng.usize(1, 9), rng.usize(1, 9), rng.usize(1, 9))
    }

    /// An `Add` case with the scales it was quantised from (for the float check).
    struct AddCase {
        a: Vec<i8>,
        b: Vec<i8>,
        s: Shape,
        q: AddQuant,
        scales: (f64, f64, f64),
        relu: bool,
    }

    impl KernelCase for AddCase {
        fn out_shape(&self) -> Shape {
            self.s
        }
        fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            add_reference(&self.a, &self.b, self.s, &self.q, out)
        }
        fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            add_fast(&self.a, &self.b, self.s, &self.q, out)
        }
        fn describe(&self) -> String {
            format!("{:?} {:?}", self.s, self.q)
        }
        fn check(&self, r: &[i8]) {
            let (s1, s2, s_out) = self.scales;
            let (zp1, zp2, zpo) =
                (self.q.zero_point1, self.q.zero_point2, self.q.output_zero_point);
            let (lo, hi) = clamp_range(zpo, self.relu);
            let e: Vec<i32> = self
                .a
                .iter()
                .zip(&self.b)
                .map(|(&x, &y)| {
                    let v = (x as i32 - zp1) as f64 * s1 + (y as i32 - zp2) as f64 * s2;
                    quantise(if self.relu { v.max(0.0) } else { v }, s_out, zpo, lo, hi)
                })
                .collect();
            assert!(max_diff(r, &e) <= 1, "{}", self.describe());
        }
    }

    kernel_equivalence!(add_fast_equals_reference_and_float, 0xadd, 300, |rng, i| {
        // every 4th a shape of the network (148, 96, 64 or 128 channels; lane tails)
        let s = if i % 4 == 0 {
            let c = [148, 96, 64, 128][i / 4 % 4];
            Shape::new(c, rng.usize(1, 6), rng.usize(1, 20))
        } else {
            rand_shape(rng)
        };
        let a = rng.i8s(s.len());
        let b = rng.i8s(s.len());
        let (s1, s2) = (rng.f64(0.002, 0.1), rng.f64(0.002, 0.1));
        // every 10th an output scale so fine that the output requantiser shifts left and the
        // portable kernel's branch-free requantisation does not hold (its saturating path)
        let fine = if i % 10 == 9 { 1e-8 } else { 1.0 };
        let s_out = (s1 + s2) * rng.f64(0.5, 1.5) * fine;
        let (zp1, zp2, zpo) = (rng.zp(), rng.zp(), rng.zp());
        let relu = rng.int(0, 1) == 1;
        let q = AddQuant::new(s1, zp1, s2, zp2, s_out, zpo, relu);
        assert_eq!(q.output.shift > 0, i % 10 == 9, "{q:?}");
        Some(AddCase { a, b, s, q, scales: (s1, s2, s_out), relu })
    });

    #[test]
    fn add_bad_operands_are_errors() {
        let s = Shape::new(2, 2, 2);
        let bad = AddQuant::new(0.1, 200, 0.1, 0, 0.1, 0, false);
        assert_eq!(add_reference(&[0; 8], &[0; 8], s, &bad, &mut [0; 8]), Err(NnError::BadParam));
        let q = AddQuant::new(0.1, 0, 0.1, 0, 0.1, 0, false);
        assert_eq!(
            add_fast(&[0; 8], &[0; 7], s, &q, &mut [0; 8]),
            Err(NnError::BufferTooSmall { need: 8, got: 7 })
        );
    }

    /// A channel `Concat` case: each part's data, shape, scale and zero point.
    struct ConcatCase {
        parts: Vec<(Vec<i8>, Shape, f64, i32)>,
        s_out: f64,
        zpo: i32,
    }

    impl ConcatCase {
        fn inputs(&self) -> Vec<ConcatInput<'_>> {
            self.parts
                .iter()
                .map(|(d, shape, s, zp)| ConcatInput {
                    data: d,
                    shape: *shape,
                    rescale: Rescale::new(*s, *zp, self.s_out, self.zpo),
                })
                .collect()
        }
    }

    impl KernelCase for ConcatCase {
        fn out_shape(&self) -> Shape {
            let (h, w) = (self.parts[0].1.h, self.parts[0].1.w);
            Shape::new(self.parts.iter().map(|p| p.1.c).sum(), h, w)
        }
        fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            concat_reference(&self.inputs(), out)
        }
        fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            concat_fast(&self.inputs(), out)
        }
        fn describe(&self) -> String {
            let parts: Vec<_> = self.parts.iter().map(|p| (p.1, p.2, p.3)).collect();
            format!("{parts:?} -> ({}, {})", self.s_out, self.zpo)
        }
        fn check(&self, r: &[i8]) {
            let os = self.out_shape();
            let mut e = vec![0i32; os.len()];
            for y in 0..os.h {
                for x in 0..os.w {
                    let mut c0 = 0;
                    for (d, shape, s, zp) in &self.parts {
                        for ch in 0..shape.c {
                            let v = (d[shape.index(ch, y, x)] as i32 - zp) as f64 * s;
                            e[os.index(c0 + ch, y, x)] =
                                quantise(v, self.s_out, self.zpo, -128, 127);
                        }
                        c0 += shape.c;
                    }
                }
            }
            assert!(max_diff(r, &e) <= 1, "{}", self.describe());
        }
    }

    kernel_equivalence!(concat_fast_equals_reference_and_float, 0xcc, 300, |rng, _| {
        let (h, w) = (rng.usize(1, 8), rng.usize(1, 8));
        let n = rng.usize(1, 4);
        let s_out = rng.f64(0.01, 0.1);
        let zpo = rng.zp();
        let mut parts = Vec::new();
        for _ in 0..n {
            // channel counts of the network's concats now and then (lane tails: 148)
            let c = if rng.int(0, 3) == 0 {
                [148, 96, 64, 32, 128][rng.usize(0, 4)]
            } else {
                rng.usize(1, 12)
            };
            let shape = Shape::new(c, h, w);
            // half of the inputs share the output's parameters (the copy path)
            let (s, zp) =
                if rng.int(0, 1) == 1 { (s_out, zpo) } else { (rng.f64(0.005, 0.2), rng.zp()) };
            parts.push((rng.i8s(shape.len()), shape, s, zp));
        }
        Some(ConcatCase { parts, s_out, zpo })
    });

    #[test]
    fn concat_bad_inputs_are_errors() {
        let a = [0i8; 8];
        let r = Rescale::new(1.0, 0, 1.0, 0);
        let bad = [
            ConcatInput { data: &a, shape: Shape::new(2, 2, 2), rescale: r },
            ConcatInput { data: &a, shape: Shape::new(2, 1, 4), rescale: r },
        ];
        assert!(matches!(concat_fast(&bad, &mut [0; 16]), Err(NnError::ShapeMismatch { .. })));
        assert_eq!(concat_fast(&[], &mut [0; 16]), Err(NnError::BadParam));
    }

    /// A standalone `Relu` case with its scales (for the float check).
    struct ReluCase {
        x: Vec<i8>,
        s: Shape,
        rs: Rescale,
        scales: (f64, f64),
    }

    impl KernelCase for ReluCase {
        fn out_shape(&self) -> Shape {
            self.s
        }
        fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            relu_reference(&self.x, self.s, &self.rs, out)
        }
        fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError> {
            relu_fast(&self.x, self.s, &self.rs, out)
        }
        fn describe(&self) -> String {
            format!("{:?} {:?}", self.s, self.rs)
        }
        fn check(&self, r: &[i8]) {
            let (s_in, s_out) = self.scales;
            let (zp_in, zp_out) = (self.rs.input_zero_point, self.rs.output_zero_point);
            let (lo, hi) = clamp_range(zp_out, true);
            let e: Vec<i32> = self
                .x
                .iter()
                .map(|&v| {
                    quantise(((v as i32 - zp_in) as f64 * s_in).max(0.0), s_out, zp_out, lo, hi)
                })
                .collect();
            assert!(max_diff(r, &e) <= 1, "{}", self.describe());
        }
    }

    kernel_equivalence!(relu_fast_equals_reference_and_float, 0x7e1, 200, |rng, i| {
        let s = rand_shape(rng);
        let x = rng.i8s(s.len());
        let (s_in, zp_in) = (rng.f64(0.005, 0.1), rng.zp());
        // every other case an identity rescale (the `max` path)
        let (s_out, zp_out) =
            if i % 2 == 0 { (s_in, zp_in) } else { (rng.f64(0.005, 0.1), rng.zp()) };
        let rs = Rescale::new(s_in, zp_in, s_out, zp_out);
        assert_eq!(rs.is_identity(), i % 2 == 0);
        Some(ReluCase { x, s, rs, scales: (s_in, s_out) })
    });
}
