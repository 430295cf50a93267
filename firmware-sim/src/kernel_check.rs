//! # kernel_check: the fast int8 kernels against the references, on the target itself
//!
//! A self-test of the op families that have instruction-set kernels, as *this build* runs
//! them: the NEON kernels on aarch64 (`nn::arm64`), AVX2 / AVX-512 VNNI or the portable ones on
//! x86-64, the portable ones on Cortex-M. Seeded random 1×1 convs, depthwise 3×3 convs, 3×3
//! convs of a one-channel map, bilinear resizes and quantised adds whose shapes straddle every kernel's
//! blocking — 1×1 rows of 1 to 2100 channels (the stages and tiles), more than 256 output channels (the
//! requantisers the kernels make once), more than 64 first-layer channels, channel counts that
//! are not a multiple of 8 (11 classes), 1 to 25 pixels (the 4-pixel tiles), stride 1 and 2 and
//! padding 0 and 1 on maps down to 1×1 (the borders), up- and downsampling, and every 10th
//! case biases too large for the vector requantisation (the fallback) — and each `*_fast`
//! output must equal `*_reference`'s bit for bit.
//!
//! `qemu_aarch64` runs it before the frames (an `@ kernels` line; exit status 1 on a
//! mismatch), so CI checks the NEON kernels in the bare-metal build itself; the crate's tests
//! run it on the host. The core crate's `kernel_equivalence!` tests hold the same kernels on
//! more shapes where a test harness runs (x86-64, or aarch64 under `qemu-aarch64`).
//!
//! **Memory:** [`KernelCheckBuffers`], ≈ 168 KB of zeros (`.bss` in a `static`).

use core::fmt;

use semloc_core::nn::conv::{
    conv2d_fast, conv2d_reference, depthwise3x3_fast, depthwise3x3_output_shape,
    depthwise3x3_reference, pack_pointwise, pointwise_fast, pointwise_packed_len,
    pointwise_reference, Conv2dParams, ConvQuant,
};
use semloc_core::nn::eltwise::{add_fast, add_reference, AddQuant};
use semloc_core::nn::resize::{resize_bilinear_fast, resize_bilinear_reference, ResizeQuant};
use semloc_core::nn::{NnError, Requant, Shape};

/// Input bytes: 25 pixels × 1100 channels, 9 × 2100, or 300 channels × 9 × 9.
const X: usize = 27_500;
/// Weights (unpacked and packed): 40 × 1100, 16 × 2100 or 270 × 40 (1×1), 9 × 300 (depthwise).
const W: usize = 44_000;
/// Output channels or depthwise channels.
const C: usize = 300;
/// Output bytes.
const O: usize = 24_300;

/// The check's working memory (all zeros: a `static` of it lands in `.bss`).
pub struct KernelCheckBuffers {
    x: [i8; X],
    w: [i8; W],
    packed: [i8; W],
    bias: [i32; C],
    requant: [Requant; C],
    fast: [i8; O],
    reference: [i8; O],
}

impl KernelCheckBuffers {
    /// Bytes of one buffer set.
    pub const MEMORY_BYTES: usize = core::mem::size_of::<KernelCheckBuffers>();

    /// Zeroed buffers.
    pub const fn new() -> Self {
        Self {
            x: [0; X],
            w: [0; W],
            packed: [0; W],
            bias: [0; C],
            requant: [Requant { multiplier: 0, shift: 0 }; C],
            fast: [0; O],
            reference: [0; O],
        }
    }
}

impl KernelCheckBuffers {
    /// A conv case's operands: random `x[..xn]`, weights `w[..wn]` and `c` biases (up to
    /// `±bmax`) and requantisers; returns the input and output zero points and the fused ReLU.
    fn fill(
        &mut self,
        rng: &mut Rng,
        xn: usize,
        wn: usize,
        c: usize,
        bmax: i32,
    ) -> (i32, i32, bool) {
        let q = (rng.zp(), rng.zp(), rng.coin());
        rng.i8s(&mut self.x[..xn]);
        rng.i8s(&mut self.w[..wn]);
        rng.quant(c, bmax, &mut self.bias, &mut self.requant);
        q
    }
}

impl Default for KernelCheckBuffers {
    fn default() -> Self {
        Self::new()
    }
}

/// Cases that passed, per op family (the same number of each).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KernelCheckReport {
    /// 1×1 convs.
    pub pointwise: u32,
    /// Depthwise 3×3 convs.
    pub depthwise: u32,
    /// 3×3 convs of a one-channel map (the first layer's geometry).
    pub first_conv: u32,
    /// Bilinear resizes.
    pub resize: u32,
    /// Quantised adds.
    pub add: u32,
}

/// Why the check failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelCheckError {
    /// The fast kernel's output differs from the reference's.
    Mismatch {
        /// `"pointwise"`, `"depthwise"`, `"first conv"`, `"resize"` or `"add"`.
        op: &'static str,
        /// The case number (with the seed, it regenerates the case).
        case: u32,
        /// Its input shape.
        shape: Shape,
        /// The first differing output byte.
        index: usize,
    },
    /// A kernel refused the operands (a bug of this generator: every case is valid).
    Nn {
        /// As in `Mismatch`.
        op: &'static str,
        /// The case number.
        case: u32,
        /// The kernel's error.
        error: NnError,
    },
}

impl fmt::Display for KernelCheckError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            KernelCheckError::Mismatch { op, case, shape, index } => write!(
                f,
                "kernel check: {op} case {case} ({}x{}x{}, CxHxW): the fast kernel differs \
                 from the reference at output byte {index}",
                shape.c, shape.h, shape.w
            ),
            KernelCheckError::Nn { op, case, error } => {
                write!(f, "kernel check: {op} case {case} rejected: {error}")
            }
        }
    }
}

/// SplitMix64: a small, seeded, portable generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A fair coin.
    fn coin(&mut self) -> bool {
        self.next() & 1 == 1
    }

    /// Uniform in `lo..=hi`.
    fn range(&mut self, lo: usize, hi: usize) -> usize {
        lo + (self.next() % (hi - lo + 1) as u64) as usize
    }

    fn i8s(&mut self, out: &mut [i8]) {
        for v in out {
            *v = self.next() as i8;
        }
    }

    /// A zero point, often near −128 as after a ReLU.
    fn zp(&mut self) -> i32 {
        if self.coin() {
            -128 + self.range(0, 8) as i32
        } else {
            self.range(0, 255) as i32 - 128
        }
    }

    /// Biases up to `±bmax` and requantisers of the network's range (`2^-14 … 2^-6`) into
    /// the first `n` entries.
    fn quant(&mut self, n: usize, bmax: i32, bias: &mut [i32], requant: &mut [Requant]) {
        for (b, r) in bias[..n].iter_mut().zip(&mut requant[..n]) {
            *b = (self.next() % (2 * bmax as u64 + 1)) as i32 - bmax;
            let e = self.range(6, 14) as i32;
            let frac = 1.0 + (self.next() % 1024) as f64 / 1024.0;
            *r = Requant::from_scale(frac / (1u64 << e) as f64);
        }
    }
}

/// The index of the first byte where `a` and `b` differ.
fn first_difference(a: &[i8], b: &[i8]) -> Option<usize> {
    a.iter().zip(b).position(|(x, y)| x != y)
}

/// Runs `cases` 1×1 and `cases` depthwise cases from `seed`; the report, or the first failure.
pub fn run(
    buf: &mut KernelCheckBuffers,
    seed: u64,
    cases: u32,
) -> Result<KernelCheckReport, KernelCheckError> {
    let mut rng = Rng(seed);
    for case in 0..cases {
        pointwise_case(buf, &mut rng, case)?;
    }
    for case in 0..cases {
        depthwise_case(buf, &mut rng, case)?;
    }
    for case in 0..cases {
        first_conv_case(buf, &mut rng, case)?;
    }
    for case in 0..cases {
        resize_case(buf, &mut rng, case)?;
    }
    for case in 0..cases {
        add_case(buf, &mut rng, case)?;
    }
    Ok(KernelCheckReport {
        pointwise: cases,
        depthwise: cases,
        first_conv: cases,
        resize: cases,
        add: cases,
    })
}

fn add_case(
    buf: &mut KernelCheckBuffers,
    rng: &mut Rng,
    case: u32,
) -> Result<(), KernelCheckError> {
    let op = "add";
    let nn = |error| KernelCheckError::Nn { op, case, error };
    // lengths with every remainder mod 8; every 10th an output scale so fine that the output
    // requantiser shifts left (the vector form does not hold: the portable fallback)
    let s = Shape::new(rng.range(1, 150), rng.range(1, 12), rng.range(1, 13));
    let scale = |rng: &mut Rng| 0.002 + (rng.next() % 1000) as f64 / 10_000.0;
    let (s1, s2) = (scale(rng), scale(rng));
    let fine = if case % 10 == 9 { 1e-8 } else { 1.0 };
    let s_out = (s1 + s2) * (0.5 + (rng.next() % 1000) as f64 / 1000.0) * fine;
    let q = AddQuant::new(s1, rng.zp(), s2, rng.zp(), s_out, rng.zp(), rng.coin());
    let n = s.len();
    rng.i8s(&mut buf.x[..n]);
    rng.i8s(&mut buf.w[..n]);
    let (a, b) = (&buf.x[..n], &buf.w[..n]);
    add_reference(a, b, s, &q, &mut buf.reference[..n]).map_err(nn)?;
    add_fast(a, b, s, &q, &mut buf.fast[..n]).map_err(nn)?;
    compare(buf, n, op, case, s)
}

/// `Err(Mismatch)` at the first byte where the fast output (`buf.fast[..n]`) differs.
fn compare(
    buf: &KernelCheckBuffers,
    n: usize,
    op: &'static str,
    case: u32,
    shape: Shape,
) -> Result<(), KernelCheckError> {
    match first_difference(&buf.fast[..n], &buf.reference[..n]) {
        Some(index) => Err(KernelCheckError::Mismatch { op, case, shape, index }),
        None => Ok(()),
    }
}

fn first_conv_case(
    buf: &mut KernelCheckBuffers,
    rng: &mut Rng,
    case: u32,
) -> Result<(), KernelCheckError> {
    let op = "first conv";
    let nn = |error| KernelCheckError::Nn { op, case, error };
    // up to 64 output channels take the NEON and x86 kernels, a few more the portable one
    let co = if case % 8 == 7 { rng.range(65, 66) } else { rng.range(1, 64) };
    let xs = Shape::new(1, rng.range(1, 12), rng.range(1, 30));
    let pads: [usize; 4] = core::array::from_fn(|_| rng.range(0, 1));
    let stride = (rng.range(1, 2), rng.range(1, 2));
    let mut p = Conv2dParams { c_out: co, kernel: (3, 3), stride, pads };
    // a map smaller than the kernel has an output only with padding
    let os = match p.output_shape(xs) {
        Ok(os) => os,
        Err(_) => {
            p.pads = [1; 4];
            p.output_shape(xs).map_err(nn)?
        }
    };
    let bmax = if case % 10 == 9 { 1 << 30 } else { 100_000 };
    let (zi, zo, relu) = buf.fill(rng, xs.len(), 9 * co, co, bmax);
    let q = ConvQuant {
        input_zero_point: zi,
        output_zero_point: zo,
        requant: &buf.requant[..co],
        relu,
    };
    let n = os.len();
    let (x, w, b) = (&buf.x[..xs.len()], &buf.w[..9 * co], &buf.bias[..co]);
    conv2d_reference(x, xs, &p, w, b, &q, &mut buf.reference[..n]).map_err(nn)?;
    conv2d_fast(x, xs, &p, w, b, &q, &mut buf.fast[..n]).map_err(nn)?;
    compare(buf, n, op, case, xs)
}

fn resize_case(
    buf: &mut KernelCheckBuffers,
    rng: &mut Rng,
    case: u32,
) -> Result<(), KernelCheckError> {
    let op = "resize";
    let nn = |error| KernelCheckError::Nn { op, case, error };
    // the network's 11 classes and 128 channels now and then, else up to 20 (short groups)
    let (c, size) = match case % 4 {
        0 => (11, (rng.range(1, 24), rng.range(1, 40))),
        1 => (rng.range(120, 130), (rng.range(1, 12), rng.range(1, 15))),
        _ => (rng.range(1, 20), (rng.range(1, 24), rng.range(1, 40))),
    };
    let xs = Shape::new(c, rng.range(1, 6), rng.range(1, 8));
    let q = ResizeQuant::new(
        0.01 + (rng.next() % 90) as f64 / 1000.0,
        rng.zp(),
        0.01 + (rng.next() % 90) as f64 / 1000.0,
        rng.zp(),
    );
    rng.i8s(&mut buf.x[..xs.len()]);
    let n = c * size.0 * size.1;
    let x = &buf.x[..xs.len()];
    resize_bilinear_reference(x, xs, size, &q, &mut buf.reference[..n]).map_err(nn)?;
    resize_bilinear_fast(x, xs, size, &q, &mut buf.fast[..n]).map_err(nn)?;
    compare(buf, n, op, case, xs)
}

fn pointwise_case(
    buf: &mut KernelCheckBuffers,
    rng: &mut Rng,
    case: u32,
) -> Result<(), KernelCheckError> {
    let op = "pointwise";
    let nn = |error| KernelCheckError::Nn { op, case, error };
    // rows around the portable kernel's 1024-channel stage and the NEON kernel's tile sizes
    // (8 pixels of up to 512 inputs, 4 of 1024, 2 of 2048), every 7th more than 256 output
    // channels (never both: the buffers hold one or the other)
    let (ci, co, side) = match case {
        c if c % 10 == 3 => (rng.range(1000, 1100), rng.range(1, 40), 5),
        // rows the NEON kernel stages one or two at a time
        c if c % 10 == 6 => (rng.range(2000, 2100), rng.range(1, 16), 3),
        c if c % 7 == 5 => (rng.range(1, 40), rng.range(250, 270), 5),
        _ => (rng.range(1, 40), rng.range(1, 40), 5),
    };
    let xs = Shape::new(ci, rng.range(1, side), rng.range(1, side));
    let bmax = if case % 10 == 9 { 1 << 30 } else { 20_000 };
    let (zi, zo, relu) = buf.fill(rng, xs.len(), co * ci, co, bmax);
    let plen = pointwise_packed_len(co, ci);
    pack_pointwise(&buf.w[..co * ci], co, ci, &mut buf.packed[..plen]).map_err(nn)?;
    let q = ConvQuant {
        input_zero_point: zi,
        output_zero_point: zo,
        requant: &buf.requant[..co],
        relu,
    };
    let n = xs.h * xs.w * co;
    let (x, w, b) = (&buf.x[..xs.len()], &buf.packed[..plen], &buf.bias[..co]);
    pointwise_reference(x, xs, w, b, &q, &mut buf.reference[..n]).map_err(nn)?;
    pointwise_fast(x, xs, w, b, &q, &mut buf.fast[..n]).map_err(nn)?;
    compare(buf, n, op, case, xs)
}

fn depthwise_case(
    buf: &mut KernelCheckBuffers,
    rng: &mut Rng,
    case: u32,
) -> Result<(), KernelCheckError> {
    let op = "depthwise";
    let nn = |error| KernelCheckError::Nn { op, case, error };
    // every 9th more than 256 channels, every 5th a network-like width, else narrow groups
    let c = match case {
        c if c % 9 == 4 => rng.range(250, 300),
        c if c % 5 == 0 => rng.range(60, 140),
        _ => rng.range(1, 20),
    };
    let xs = Shape::new(c, rng.range(1, 9), rng.range(1, 9));
    let stride = rng.range(1, 2);
    let bmax = if case % 10 == 9 { 1 << 30 } else { 5000 };
    let (zi, zo, relu) = buf.fill(rng, xs.len(), 9 * c, c, bmax);
    let q =
        ConvQuant { input_zero_point: zi, output_zero_point: zo, requant: &buf.requant[..c], relu };
    let n = depthwise3x3_output_shape(xs, stride).map_err(nn)?.len();
    let (x, w, b) = (&buf.x[..xs.len()], &buf.w[..9 * c], &buf.bias[..c]);
    depthwise3x3_reference(x, xs, stride, w, b, &q, &mut buf.reference[..n]).map_err(nn)?;
    depthwise3x3_fast(x, xs, stride, w, b, &q, &mut buf.fast[..n]).map_err(nn)?;
    compare(buf, n, op, case, xs)
}
