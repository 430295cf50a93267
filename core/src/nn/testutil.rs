//! Shared test support of the op families: seeded random tensors, float helpers, and the one
//! equivalence test every family instantiates, [`kernel_equivalence!`].
//!
//! As tract's `linalg` kernel tests: a family describes one random case (operands, expected
//! output shape, its reference and its fast kernel) as a [`KernelCase`]; the macro turns a seed,
//! a case count and a generator into a `#[test]` that runs the reference and then the fast
//! kernel at every instruction-set level this CPU has (`dispatch::for_each_level`: AVX-512
//! VNNI, AVX2 and portable on an x86-64 host) and requires the outputs to be bit-equal. A case
//! may add its own check of the reference output (the float computation).

use std::string::String;
use std::vec;
use std::vec::Vec;

use super::dispatch::for_each_level;
use super::{NnError, Shape};
use crate::ransac::XorShift64;

/// A seeded generator with the helpers the op tests need.
pub struct Rng(pub XorShift64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(XorShift64::new(seed))
    }
    /// Uniform in `lo..=hi`.
    pub fn int(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.0.next_u64() % (hi - lo + 1) as u64) as i64
    }
    pub fn usize(&mut self, lo: usize, hi: usize) -> usize {
        self.int(lo as i64, hi as i64) as usize
    }
    /// Uniform in `[lo, hi)`.
    pub fn f64(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.0.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }
    pub fn i8s(&mut self, n: usize) -> Vec<i8> {
        (0..n).map(|_| self.int(-128, 127) as i8).collect()
    }
    /// Symmetric weights in `[-127, 127]`.
    pub fn weights(&mut self, n: usize) -> Vec<i8> {
        (0..n).map(|_| self.int(-127, 127) as i8).collect()
    }
    pub fn zp(&mut self) -> i32 {
        self.int(-128, 127) as i32
    }
}

/// `clamp(round_half_away(y / scale) + zp, lo, hi)`: what a float engine would store.
pub fn quantise(y: f64, scale: f64, zp: i32, lo: i32, hi: i32) -> i32 {
    ((y / scale).round() as i64 + zp as i64).clamp(lo as i64, hi as i64) as i32
}

/// Largest `|a − b|` over two int8 tensors.
pub fn max_diff(a: &[i8], b: &[i32]) -> i32 {
    a.iter().zip(b).map(|(&x, &y)| (x as i32 - y).abs()).max().unwrap_or(0)
}

/// One random case of an op family: its operands, the reference and the fast kernel.
pub trait KernelCase {
    /// The output shape both kernels must return.
    fn out_shape(&self) -> Shape;
    /// The reference kernel into `out` (`out_shape().len()` bytes).
    fn reference(&self, out: &mut [i8]) -> Result<Shape, NnError>;
    /// The fast kernel into `out`, at whatever level the dispatcher allows now.
    fn fast(&self, out: &mut [i8]) -> Result<Shape, NnError>;
    /// The case in a few words for a failure message (shapes, parameters).
    fn describe(&self) -> String;
    /// Further checks of the reference output (e.g. against a float computation).
    fn check(&self, _reference: &[i8]) {}
}

/// The body of [`kernel_equivalence!`]: `cases` cases from `generate(rng, i)` (`None` skips a
/// draw, e.g. a geometry without output), each run by the reference and by the fast kernel at
/// every level; outputs start from different fill bytes, so a byte a kernel leaves unwritten
/// shows up as a difference.
pub fn check_equivalence<C: KernelCase>(
    seed: u64,
    cases: usize,
    mut generate: impl FnMut(&mut Rng, usize) -> Option<C>,
) {
    let mut rng = Rng::new(seed);
    let mut ran = 0;
    for i in 0..cases {
        let Some(case) = generate(&mut rng, i) else { continue };
        let os = case.out_shape();
        let mut want = vec![0i8; os.len()];
        assert_eq!(case.reference(&mut want), Ok(os), "reference, case {i}: {}", case.describe());
        let mut fill = 0i8;
        for_each_level(|level| {
            fill += 1;
            let mut got = vec![fill; os.len()];
            assert_eq!(case.fast(&mut got), Ok(os), "{level}, case {i}: {}", case.describe());
            assert!(got == want, "{level} != reference, case {i}: {}", case.describe());
        });
        case.check(&want);
        ran += 1;
    }
    assert!(ran > 0, "no case generated");
}

/// `kernel_equivalence!(name, seed, cases, |rng, i| -> Option<Case>)`: a `#[test]` named `name`
/// that requires an op family's fast kernel, at every instruction-set level of this CPU, to
/// equal its reference bit for bit on `cases` seeded random cases (see [`check_equivalence`]).
macro_rules! kernel_equivalence {
    ($(#[$meta:meta])* $name:ident, $seed:expr, $cases:expr, $generate:expr $(,)?) => {
        $(#[$meta])*
        #[test]
        fn $name() {
            $crate::nn::testutil::check_equivalence($seed, $cases, $generate);
        }
    };
}
pub(crate) use kernel_equivalence;
