//! # dispatch: which fast kernel runs, one function per op family
//!
//! The one place that picks the fast kernel of each op family: an instruction-set kernel where
//! the CPU has one (and it takes the op: each returns `false` otherwise), else the
//! [`super::portable`] kernel. Every `*_fast` op checks its operands and then calls exactly
//! one function here. The choice is made at run time: every x86-64 build (a baseline one
//! included) has the `x86` kernels, and `level` is the CPU's best as `x86::isa` probes it
//! (`cpuid`/`xgetbv`: AVX2, AVX-512 VNNI), `Portable` on a CPU without AVX2 — the x86 entries
//! also refuse (return `false`) there, so no AVX2 instruction runs on such a CPU. Another
//! On aarch64 the 1×1 GEMM takes the dot products (`sdot`) where `arm64::dotprod_enabled`
//! finds them at run time, the other families the baseline NEON kernels.
//!
//! | family                    | x86-64, CPU with AVX2                    | aarch64 (NEON)          | elsewhere             |
//! |---------------------------|------------------------------------------|-------------------------|-----------------------|
//! | [`conv2d`]                | `x86::conv1` (3×3, one input channel)    | `arm64::conv1` (same)   | `portable::conv`      |
//! | [`depthwise3x3`]          | `x86::depthwise`                         | `arm64::depthwise`      | `portable::depthwise` |
//! | [`pointwise`]             | `x86::pointwise` (AVX-512 VNNI or AVX2)  | `arm64::dot` (`sdot`) or `arm64::pointwise` | `portable::pointwise` |
//! | [`resize_bilinear`]       | `x86::resize`                            | `arm64::resize`         | `portable::resize`    |
//! | [`add`]                   | `x86::eltwise`                           | `arm64::eltwise`        | `portable::eltwise`   |
//! | [`concat_input`]          | `x86::eltwise`                           | `portable::eltwise`     | `portable::eltwise`   |
//! | [`relu`], [`avgpool`]     | —                                        | —                       | `portable::{eltwise, pool}` |
//!
//! The level is the CPU's best, capped process-wide by `x86::set_max_isa` (measurements) and,
//! in tests, per thread by [`for_each_level`], which runs a closure once per level this CPU
//! has (the shared `kernel_equivalence!` tests use it). On aarch64 there is no run-time probe
//! for NEON (part of the target), one for the dot products: `arm64::set_neon` turns the NEON
//! kernels off process-wide, `arm64::set_dotprod` the `sdot` GEMM, and [`for_each_level`] runs
//! `dotprod` (where the CPU has it), `neon`, then `portable`. **Memory:** none of its own.
//!
//! **Stack:** a dispatcher's frame stays small: the portable kernels with KiBs of staged rows
//! (`pointwise`, `depthwise3x3`, `conv2d`) are `#[inline(never)]`, so their frames never add to
//! the SIMD kernel's the dispatcher tries first. When LLVM once inlined the portable 1×1 GEMM here
//! (a change to another kernel tipped it), the bare-metal image's semantic frame stack rose from
//! 19.0 to 30.7 KB; `firmware-sim/qemu-check.sh` fails on such a rise.

#[cfg(all(test, any(target_arch = "x86_64", target_arch = "aarch64")))]
use core::cell::Cell;

#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
use super::arm64;
use super::conv::{Conv2dParams, ConvQuant};
use super::eltwise::{AddQuant, ConcatInput, Rescale};
use super::pool::{AvgPoolParams, PoolQuant};
use super::portable;
use super::resize::ResizeQuant;
#[cfg(target_arch = "x86_64")]
use super::x86::{self, Isa};
use super::Shape;

#[cfg(all(test, target_arch = "x86_64"))]
std::thread_local! {
    /// The highest level the fast kernels may use on this test thread.
    static TEST_CAP: Cell<Isa> = const { Cell::new(Isa::Avx512Vnni) };
}

/// The cap of this thread (none outside tests).
#[cfg(all(not(test), target_arch = "x86_64"))]
#[inline(always)]
fn thread_cap() -> Isa {
    Isa::Avx512Vnni
}

#[cfg(all(test, target_arch = "x86_64"))]
fn thread_cap() -> Isa {
    TEST_CAP.with(Cell::get)
}

/// The instruction-set level of this call: the CPU's best, capped by `x86::set_max_isa` (and,
/// in tests, by the thread's cap).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(crate) fn level() -> Isa {
    x86::isa().min(thread_cap())
}

/// Whether the NEON kernels may run on this call: [`arm64::set_neon`] and, in tests, the
/// thread's cap ([`for_each_level`]).
#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
#[inline]
fn neon() -> bool {
    arm_cap() >= ARM_NEON && arm64::neon_enabled()
}

/// Whether the `sdot` 1×1 GEMM may run on this call: the CPU has the dot products
/// ([`arm64::dotprod_enabled`]) and, in tests, the thread's cap allows them.
#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
#[inline]
fn dot() -> bool {
    arm_cap() >= ARM_DOT && arm64::dotprod_enabled()
}

/// Test caps on aarch64: the portable kernels only, NEON, NEON with `sdot`.
#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
const ARM_NEON: u8 = 1;
#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
const ARM_DOT: u8 = 2;

/// The cap of this thread (none outside tests).
#[cfg(all(not(test), target_arch = "aarch64", target_feature = "neon"))]
#[inline(always)]
fn arm_cap() -> u8 {
    ARM_DOT
}

#[cfg(all(test, target_arch = "aarch64", target_feature = "neon"))]
fn arm_cap() -> u8 {
    ARM_CAP.with(Cell::get)
}

#[cfg(all(test, target_arch = "aarch64", target_feature = "neon"))]
std::thread_local! {
    /// The highest aarch64 level the fast kernels may use on this test thread.
    static ARM_CAP: Cell<u8> = const { Cell::new(ARM_DOT) };
}

/// General conv (`os`: the output shape).
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv2d(
    x: &[i8],
    xs: Shape,
    p: &Conv2dParams,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) {
    #[cfg(target_arch = "x86_64")]
    if level() >= Isa::Avx2 && x86::conv1::conv3x3_c1(x, xs, p, w, b, q, out, os) {
        return;
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    if neon() && arm64::conv1::conv3x3_c1(x, xs, p, w, b, q, out, os) {
        return;
    }
    portable::conv::conv2d(x, xs, p, w, b, q, out, os)
}

/// Depthwise 3×3 conv, pad 1 (`os`: the output shape).
#[allow(clippy::too_many_arguments)]
pub(crate) fn depthwise3x3(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) {
    #[cfg(target_arch = "x86_64")]
    if level() >= Isa::Avx2 && x86::depthwise::depthwise3x3(x, xs, stride, w, b, q, out) {
        return;
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    if neon() && arm64::depthwise::depthwise3x3(x, xs, stride, w, b, q, out, os) {
        return;
    }
    portable::depthwise::depthwise3x3(x, xs, stride, w, b, q, out, os)
}

/// Pointwise 1×1 conv over packed weights.
pub(crate) fn pointwise(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
) {
    #[cfg(target_arch = "x86_64")]
    {
        let level = level();
        let vnni = level == Isa::Avx512Vnni;
        if level >= Isa::Avx2 && x86::pointwise::pointwise(x, xs, w, b, q, out, vnni) {
            return;
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    if dot() && arm64::dot::pointwise(x, xs, w, b, q, out)
        || neon() && arm64::pointwise::pointwise(x, xs, w, b, q, out)
    {
        return;
    }
    portable::pointwise::pointwise(x, xs, w, b, q, out)
}

/// Bilinear resize (`os`: the output shape).
pub(crate) fn resize_bilinear(x: &[i8], xs: Shape, q: &ResizeQuant, out: &mut [i8], os: Shape) {
    #[cfg(target_arch = "x86_64")]
    if level() >= Isa::Avx2 && x86::resize::resize_bilinear(x, xs, q, out, os) {
        return;
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    if neon() && arm64::resize::resize_bilinear(x, xs, q, out, os) {
        return;
    }
    portable::resize::resize_bilinear(x, xs, q, out, os)
}

/// `Add` of two same-shaped tensors.
pub(crate) fn add(a: &[i8], b: &[i8], shape: Shape, q: &AddQuant, out: &mut [i8]) {
    #[cfg(target_arch = "x86_64")]
    if level() >= Isa::Avx2 && x86::eltwise::add(a, b, shape, q, out) {
        return;
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    if neon() && arm64::eltwise::add(a, b, shape, q, out) {
        return;
    }
    portable::eltwise::add(a, b, shape, q, out)
}

/// One input of a channel `Concat`, into channels `c0..` of the output of shape `os`.
pub(crate) fn concat_input(i: &ConcatInput<'_>, c0: usize, os: Shape, out: &mut [i8]) {
    #[cfg(target_arch = "x86_64")]
    if level() >= Isa::Avx2 && x86::eltwise::concat_input(i, c0, os, out) {
        return;
    }
    portable::eltwise::concat_input(i, c0, os, out)
}

/// Standalone `Relu` (portable on every target: a `max` or one rescale per byte).
pub(crate) fn relu(x: &[i8], shape: Shape, r: &Rescale, out: &mut [i8]) {
    portable::eltwise::relu(x, shape, r, out)
}

/// The PPM's average pool (portable on every target).
pub(crate) fn avgpool(
    x: &[i8],
    xs: Shape,
    p: &AvgPoolParams,
    q: &PoolQuant,
    out: &mut [i8],
    os: Shape,
) {
    portable::pool::avgpool(x, xs, p, q, out, os)
}

/// Runs `f` once per fast-kernel level this build and CPU have, most capable first, with the
/// level capped to it on this thread; `f` gets the level's name (tests). Levels the CPU lacks
/// are skipped (on x86-64 without AVX2 only `portable` runs).
#[cfg(test)]
pub(crate) fn for_each_level(mut f: impl FnMut(&'static str)) {
    #[cfg(target_arch = "x86_64")]
    {
        /// Lifts the cap when dropped, also when `f` panics.
        struct Cap;
        impl Drop for Cap {
            fn drop(&mut self) {
                TEST_CAP.with(|c| c.set(Isa::Avx512Vnni));
            }
        }
        let levels =
            [(Isa::Avx512Vnni, "avx512vnni"), (Isa::Avx2, "avx2"), (Isa::Portable, "portable")];
        for (isa, name) in levels {
            if isa > x86::cpu_isa() {
                continue;
            }
            TEST_CAP.with(|c| c.set(isa));
            let _cap = Cap;
            f(name);
        }
    }
    #[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
    {
        /// Lifts the cap when dropped, also when `f` panics.
        struct Cap;
        impl Drop for Cap {
            fn drop(&mut self) {
                ARM_CAP.with(|c| c.set(ARM_DOT));
            }
        }
        for (cap, name) in [(ARM_DOT, "dotprod"), (ARM_NEON, "neon"), (0, "portable")] {
            if cap == ARM_DOT && !arm64::dotprod_available() {
                continue;
            }
            ARM_CAP.with(|c| c.set(cap));
            let _cap = Cap;
            f(name);
        }
    }
    #[cfg(not(any(
        target_arch = "x86_64",
        all(target_arch = "aarch64", target_feature = "neon")
    )))]
    f("portable");
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use std::vec::Vec;

    /// The run-time probe finds what std's detection finds, so the `kernel_equivalence!` tests
    /// really run the AVX2 (and AVX-512 VNNI) kernels on a CPU that has them.
    #[test]
    fn run_time_detection_agrees_with_std() {
        use std::arch::is_x86_feature_detected as has;
        let avx2 = has!("avx2");
        let vnni = has!("avx512f") && has!("avx512bw") && has!("avx512vl") && has!("avx512vnni");
        assert_eq!(x86::cpu_isa() >= Isa::Avx2, avx2);
        assert_eq!(x86::vnni_available(), avx2 && vnni);
        let mut levels = Vec::new();
        for_each_level(|name| levels.push(name));
        let want: &[&str] = match (avx2, vnni) {
            (true, true) => &["avx512vnni", "avx2", "portable"],
            (true, false) => &["avx2", "portable"],
            _ => &["portable"],
        };
        assert_eq!(levels, want);
    }
}

#[cfg(all(test, target_arch = "aarch64", target_feature = "neon"))]
mod tests_arm {
    use super::*;
    use std::vec::Vec;

    /// The run-time probe finds what std's detection finds, so the `kernel_equivalence!` tests
    /// really run the `sdot` GEMM on a CPU (or `qemu-aarch64 -cpu`) that has it.
    #[test]
    fn run_time_detection_agrees_with_std() {
        let dot = std::arch::is_aarch64_feature_detected!("dotprod");
        assert_eq!(arm64::dotprod_available(), dot);
        let mut levels = Vec::new();
        for_each_level(|name| levels.push(name));
        let want: &[&str] =
            if dot { &["dotprod", "neon", "portable"] } else { &["neon", "portable"] };
        assert_eq!(levels, want);
    }
}
