//! # nn: int8 network kernels
//!
//! The integer operators the segmentation network (Fast-SCNN / Res2Net variant, see
//! `models/README.md`) is made of, each as ONNX defines it, quantised as `models/quantise.py`
//! does: per-tensor asymmetric int8 activations (`real = scale · (q − zero_point)`),
//! per-output-channel symmetric int8 weights, int32 biases at `input_scale · weight_scale`, and
//! a `Relu` after a `Conv`/`Add` fused into that op's output clamp.
//!
//! Every operator exists twice, as tract does it: a `*_reference` kernel written as plain loops
//! that read like the ONNX operator definition, and a `*_fast` kernel that restructures the same
//! integer arithmetic. Each op file below holds the definition, the checks at entry and the
//! reference; its `*_fast` entry checks the operands the same way and calls the op family's one
//! function in `dispatch`, which picks the kernel (the one place of the run-time CPU-feature
//! checks):
//! - `portable/`, one file per op family: safe Rust written for the compiler's auto-vectoriser
//!   (contiguous row slices, hoisted bounds, `chunks_exact`); the code of every target.
//! - `x86/`, one file per op family (`pointwise`, `depthwise`, `conv1`, `resize`,
//!   `eltwise`): AVX2 intrinsics, AVX-512 VNNI for the 1×1 GEMM, compiled into every x86-64
//!   build (a baseline one included) and used where the CPU has them, found at run time.
//! - `arm64/` (`pointwise`, `depthwise`): NEON intrinsics, compiled into every aarch64 build
//!   (NEON is part of the target); the other families run the portable kernels there. With
//!   `x86/`, the only `unsafe` of the crate.
//!
//! One shared test macro (`kernel_equivalence!`, in `testutil`) runs, per op family, the
//! reference and the fast kernel at every instruction-set level this CPU has on seeded random
//! shapes (and the network's shapes) and requires them to be **bit-equal**; the op files'
//! tests add a check of the dequantised result against a float computation.
//!
//! - [`quant`]: [`Requant`] (Q0.31 multiplier + shift, gemmlowp/TFLite rounding).
//! - [`conv`]: general `k×k` conv, depthwise 3×3 (stride 1/2, pad 1), pointwise 1×1 (int8 GEMM).
//! - [`eltwise`]: `Add` (TFLite scheme, left shift 20), `Concat` along channels, `Relu`.
//! - [`pool`]: the PPM's `AveragePool` (window = stride, bottom/right pad, divide by real pixels).
//! - [`resize`]: bilinear `Resize`, `half_pixel`, with fixed-point weights.
//! - [`model`], [`graph`]: the blob parser with its arena plan, and the graph executor.
//!
//! **Rounding.** All requantisation is integer: `acc · M · 2^shift` with `M` a Q0.31 multiplier,
//! rounded as gemmlowp's `SaturatingRoundingDoublingHighMul` (nearest, ties toward +∞ — the
//! code's behaviour, whatever its comment says) + `RoundingDivideByPOT` (nearest, ties away from
//! zero), i.e. TFLite's `MultiplyByQuantizedMultiplier`; [`quant`] bounds the difference to a
//! single round-half-away of the exact product (at most one, on exact ties only). No float is
//! touched when a kernel runs, so the int8 outputs are the same integers on every target; floats
//! are used only to *build* [`Requant`]s from scales (f64, IEEE exact-rounded, so also identical
//! everywhere). Per-op roundings (pool mean, resize weights) are documented in their modules.
//!
//! **Layout.** Tensors are batch-1 **NHWC** (`index = (y·w + x)·c + ch`) `i8` slices described by
//! a [`Shape`]. Channels-last makes the two kernels that dominate the network contiguous: a 1×1
//! conv is a GEMM whose per-pixel input row is one slice (`x[p][..c_in] · w[co][..c_in]`), and a
//! depthwise conv multiplies whole channel vectors of a pixel by the tap's channel vector of
//! weights, so both vectorise over channels without gathers. (NCHW would make the depthwise
//! conv's inner loop a strided 3-tap stencil and the 1×1 conv a strided dot product.)
//! Weights are `O·kh·kw·I` (TFLite's OHWI) for the general conv, `3·3·C` for depthwise, and
//! **packed** for pointwise: [`conv::pack_pointwise`]'s `[⌈O/8⌉][⌈I/4⌉][8][4]` blocks, the
//! operand layout of the register-tiled GEMM (32 bytes = 8 output channels × 4 input channels,
//! one 256-bit load; `vpdpbusd`, `sdot` and `vpmaddwd` pairs all take it as is). The model blob
//! stores that layout (`model::VERSION` 2), so nothing is repacked at run time.
//!
//! **Memory.** No kernel allocates: inputs, weights and outputs are caller-provided slices. The
//! only scratch is on the stack and fixed; the references use none. Portable kernels: a
//! 64-entry `i32` accumulator block (pool: 256 B; depthwise: plus lane-form requantisers,
//! 6.3 KiB), an unpacked weight panel with a staged `i16` row (pointwise: 10 KiB), transposed
//! weights and lane-form requantisers (first conv: 5.8 KiB), 256-entry tables (add: 2 KiB;
//! concat and relu with a rescale: 256 B). The x86
//! kernels (hosts only): 8 KiB staged input tile (VNNI GEMM), 12 + 7 KiB (AVX2 GEMM), 14 KiB of
//! per-group constants and a 256-byte row of zero points (depthwise), 16 KiB of staged row
//! chunks and 24 KiB of column taps (resize), 3 KiB (first conv). Shapes, slice lengths and
//! zero points are checked once at entry and reported as [`NnError`]; the kernels do not panic
//! on bad shapes or parameters.
//!
//! **Speed** — `cargo bench -p semloc-core --bench nn` (the 192×640 Res2Net frame, 373 MMAC,
//! op by op and, with `SEMLOC_SLM`, the real graph through [`graph::run`]); one core of an AMD
//! EPYC Zen 4 VM shared with other jobs, best of 11 runs in one process (criterion's means agree
//! within ~5 % when the machine is quiet; under load they run up to 1.5× higher):
//!
//! | per frame        | reference | fast, VNNI | fast, AVX2 | fast, portable | before |
//! |------------------|----------:|-----------:|-----------:|---------------:|-------:|
//! | 1×1 conv (349 MMAC) | 478 ms | 2.8 ms (125 GMAC/s) | 5.7 ms (61) | 24 ms (15) | 31.8 ms (11) |
//! | depthwise 3×3    | 33 ms     | 1.45 ms    | 1.4 ms     | 6.2 ms         | 14.2 ms |
//! | first conv 1→32  | 48 ms     | 0.39 ms    | 0.39 ms    | 15 ms          | 15.0 ms |
//! | resize           | 18 ms     | 0.70 ms    | 0.66 ms    | 8.3 ms         | 8.7 ms |
//! | concat, add, pool | 13 ms    | 0.75 ms    | 0.77 ms    | 11 ms          | 11.4 ms |
//! | **whole graph**  | 640 ms    | **6.2 ms** | 9.2 ms     | ~75 ms         | 81 ms  |
//!
//! (The reference 1×1 kernel reads the packed weights through an index function, so its time
//! is not comparable with the O·I reference of before; "before" is the previous fast kernels.)
//! The portable column was measured when hosts were built for x86-64-v3; they now build for
//! baseline x86-64 and pick the AVX2/VNNI kernels at run time (same times), and the portable
//! kernels — run on x86 only by a CPU without AVX2 or under `SEMLOC_NN_ISA=portable` — are
//! ~1.55× slower there (whole graph 61 → 95 ms, measured back to back).
//! tract-onnx f32 on one thread takes ~45 ms for the same model on this machine (`semloc bench
//! --seg-only`, median), so the int8 graph is ~6–7× faster. The GEMM reaches 140–180 GMAC/s for
//! 128–592 input channels and 75 GMAC/s for 32, where the per-output requantisation (14 vector
//! ops per 8 outputs, also the bound of the depthwise conv) is a third of the work.
//! On an AVX2-only machine (AMD EPYC Zen 3, no VNNI; 2026-12-07, after the AVX2 epilogue,
//! depthwise and requantisation changes) the whole graph takes 9.3–9.6 ms warm: 1×1 conv
//! 6.05 ms (58 GMAC/s), depthwise 1.22, resize 0.64, first conv 0.50, add 0.40, concat 0.24.

use core::fmt;

#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
pub mod arm64;
pub mod conv;
pub(crate) mod dispatch;
pub mod eltwise;
pub mod graph;
pub mod model;
pub mod pool;
mod portable;
pub mod quant;
pub mod resize;
#[cfg(test)]
mod testutil;
#[cfg(target_arch = "x86_64")]
pub mod x86;

/// The x86 instruction-set cap ([`x86::set_max_isa`], [`x86::Isa`]) under its former path, for
/// the callers that name it (`tests/tests/system/segmentation.rs`).
#[cfg(target_arch = "x86_64")]
pub use x86 as simd;

pub use quant::Requant;

/// The shape of one batch-1 activation tensor, stored NHWC (channels innermost).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Shape {
    /// Channels.
    pub c: usize,
    /// Height in pixels.
    pub h: usize,
    /// Width in pixels.
    pub w: usize,
}

impl Shape {
    /// A shape of `c` channels on an `h × w` map.
    pub const fn new(c: usize, h: usize, w: usize) -> Self {
        Self { c, h, w }
    }

    /// Number of elements, `c·h·w` (saturating, so an absurd shape fails the length check
    /// rather than wrapping).
    pub const fn len(&self) -> usize {
        self.c.saturating_mul(self.h).saturating_mul(self.w)
    }

    /// True when any dimension is zero.
    pub const fn is_empty(&self) -> bool {
        self.c == 0 || self.h == 0 || self.w == 0
    }

    /// Element index of channel `ch` at pixel `(y, x)` (NHWC); no bounds check.
    #[inline]
    pub const fn index(&self, ch: usize, y: usize, x: usize) -> usize {
        (y * self.w + x) * self.c + ch
    }
}

/// Errors of the kernels: all are found by the checks at entry, before anything is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NnError {
    /// Two tensors that must agree in shape do not (e.g. the inputs of `Add`).
    ShapeMismatch {
        /// The shape required.
        expected: Shape,
        /// The shape given.
        got: Shape,
    },
    /// A tensor or parameter slice is shorter than its shape needs.
    BufferTooSmall {
        /// Elements needed.
        need: usize,
        /// Elements in the slice.
        got: usize,
    },
    /// A parameter slice (weights, bias, requantisers) has the wrong length.
    ParamLength {
        /// Elements expected.
        need: usize,
        /// Elements given.
        got: usize,
    },
    /// An empty tensor, a zero kernel/stride, an unsupported stride, a zero point outside
    /// `-128..=127`, or a reduction so long that the `i32` accumulator could overflow.
    BadParam,
}

impl fmt::Display for NnError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            NnError::ShapeMismatch { expected, got } => write!(
                f,
                "tensor shape mismatch: expected {}x{}x{} (c x h x w), got {}x{}x{}",
                expected.c, expected.h, expected.w, got.c, got.h, got.w
            ),
            NnError::BufferTooSmall { need, got } => {
                write!(f, "tensor buffer too small: need {need} elements, got {got}")
            }
            NnError::ParamLength { need, got } => {
                write!(f, "parameter length mismatch: need {need}, got {got}")
            }
            NnError::BadParam => write!(f, "unsupported or empty operator parameters"),
        }
    }
}

impl core::error::Error for NnError {}

/// Checks that a tensor slice holds `shape` (and that the shape is not empty).
pub(crate) fn check_tensor(len: usize, shape: Shape) -> Result<(), NnError> {
    if shape.is_empty() {
        return Err(NnError::BadParam);
    }
    if len < shape.len() {
        return Err(NnError::BufferTooSmall { need: shape.len(), got: len });
    }
    Ok(())
}

/// Checks that a zero point is an int8 value (so `x − zp` fits in `[-255, 255]` and no
/// arithmetic downstream can overflow).
pub(crate) fn check_zero_point(zp: i32) -> Result<(), NnError> {
    if !(-128..=127).contains(&zp) {
        return Err(NnError::BadParam);
    }
    Ok(())
}

/// Checks a parameter slice length exactly.
pub(crate) fn check_param(len: usize, need: usize) -> Result<(), NnError> {
    if len != need {
        return Err(NnError::ParamLength { need, got: len });
    }
    Ok(())
}

/// Longest reduction a kernel accepts: `|x − zp| ≤ 255`, `|w| ≤ 127`, so `2^16` products plus a
/// bias stay far inside `i32` (`255·127·2^16 ≈ 2.1·10^9` is the bound on the product sum alone;
/// biases in the network are orders of magnitude smaller than that).
pub const MAX_REDUCTION: usize = 1 << 16;

#[cfg(test)]
mod tests {
    use super::*;
    use std::string::ToString;

    #[test]
    fn errors_display_their_numbers() {
        let e = NnError::ShapeMismatch { expected: Shape::new(3, 4, 5), got: Shape::new(3, 4, 6) };
        assert_eq!(e.to_string(), "tensor shape mismatch: expected 3x4x5 (c x h x w), got 3x4x6");
        let e = NnError::BufferTooSmall { need: 10, got: 9 };
        assert_eq!(e.to_string(), "tensor buffer too small: need 10 elements, got 9");
        assert!(NnError::BadParam.to_string().contains("unsupported"));
        assert_eq!(Shape::new(2, 3, 4).index(1, 2, 3), (2 * 4 + 3) * 2 + 1);
        assert!(Shape::new(0, 3, 4).is_empty());
    }
}
