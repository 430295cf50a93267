//! # x86: x86-64 AVX2 and AVX-512 VNNI forms of the int8 kernels
//!
//! One file per op family, as tract's `linalg/src/x86_64_fma`, beside the safe
//! `nn::portable` kernels (and, later, an `arm64` family):
//!
//! | file        | ONNX op                                           | ISA                | stack   |
//! |-------------|---------------------------------------------------|--------------------|---------|
//! | `pointwise` | `Conv` 1×1 (int8 GEMM over packed weights)        | AVX2; AVX-512 VNNI | 19/8 KiB|
//! | `depthwise` | `Conv` depthwise 3×3, pad 1, stride 1/2           | AVX2               | 21 KiB  |
//! | `conv1`     | `Conv` 3×3 of a one-channel map (the first layer) | AVX2               | 3 KiB   |
//! | `resize`    | `Resize` bilinear, `half_pixel`                   | AVX2               | 40 KiB  |
//! | `eltwise`   | `Add`; the rescales of `Concat`                   | AVX2               | < 1 KiB |
//! | `lanes`     | shared: requantisation, loads, stores of 8 lanes  | AVX2               | —       |
//!
//! Compiled only for x86-64 builds with AVX2 enabled at compile time (`-C
//! target-cpu=x86-64-v3`, the workspace's host setting); AVX-512 VNNI (`vpdpbusd`, u8×i8 dot
//! products of four) is detected at run time with `cpuid`/`xgetbv` ([`vnni_available`]) and
//! used by the 1×1 GEMM when present. Every kernel computes the very integers of the reference
//! kernels; `nn::dispatch` is the one place that picks them, and the shared
//! `kernel_equivalence!` tests run every family at every level this CPU has against the
//! reference. Each family's safe entry takes the operands its op already checked and returns
//! `false` (writing nothing) when the op is outside what the vector code handles, e.g. when
//! [`super::quant::fits_simd_requant`] fails (never for a real network); the portable kernel
//! then runs.
//!
//! `unsafe` is allowed in this module only (the workspace denies it elsewhere), for two things:
//! calling `#[target_feature]` functions (sound: AVX2 is a compile-time feature of this build,
//! AVX-512 VNNI is checked at run time before the call) and raw-pointer loads/stores in the
//! inner loops, whose ranges the safe entry points check once. Measured gain over the safe,
//! auto-vectorised portable kernels in the same x86-64-v3 build (`benches/nn.rs`,
//! `SEMLOC_NN_ISA`): the 192×640 graph 6.2 ms (VNNI) / 9.2 ms (AVX2) against ~75 ms, the 1×1
//! GEMM 2.8 / 5.7 ms against 24 ms — far beyond the 20 % that would favour safe code. The
//! portable kernels remain the code of the other targets (and are tested on x86 too).
//!
//! [`set_max_isa`] caps the level used (for measurements); results are the same on every level.

#![allow(unsafe_code)]

use core::arch::x86_64::{__cpuid, __cpuid_count, _xgetbv};
use core::sync::atomic::{AtomicU8, Ordering};

pub(crate) mod conv1;
pub(crate) mod depthwise;
pub(crate) mod eltwise;
pub(crate) mod lanes;
pub(crate) mod pointwise;
pub(crate) mod resize;

/// 0: not probed yet, 1: AVX2 only, 2: AVX-512 VNNI usable.
static DETECTED: AtomicU8 = AtomicU8::new(0);
/// The most capable [`Isa`] the kernels may use, as set by [`set_max_isa`] (default: all).
static MAX_ISA: AtomicU8 = AtomicU8::new(Isa::Avx512Vnni as u8);

/// The instruction sets the fast kernels can run on, least capable first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
pub enum Isa {
    /// The portable kernels (safe Rust; auto-vectorised for AVX2 by this build).
    Portable = 0,
    /// The AVX2 intrinsics kernels.
    Avx2 = 1,
    /// AVX2, with AVX-512 VNNI for the 1×1 GEMM.
    Avx512Vnni = 2,
}

fn detect_vnni() -> bool {
    // CPUID.1:ECX.OSXSAVE, then XCR0 has SSE, AVX, opmask, ZMM_Hi256, Hi16_ZMM state enabled
    let l1 = __cpuid(1);
    if l1.ecx & (1 << 27) == 0 {
        return false;
    }
    // SAFETY: `xgetbv` exists when the OS has set CR4.OSXSAVE (checked just above); the `xsave`
    // target feature is part of x86-64-v3, which this module is compiled for.
    let xcr0 = unsafe { _xgetbv(0) };
    if xcr0 & 0xe6 != 0xe6 {
        return false;
    }
    let l7 = __cpuid_count(7, 0);
    let f = l7.ebx & (1 << 16) != 0;
    let bw = l7.ebx & (1 << 30) != 0;
    let vl = l7.ebx & (1 << 31) != 0;
    let vnni = l7.ecx & (1 << 11) != 0;
    f && bw && vl && vnni
}

/// True when the CPU (and OS) support AVX-512 VNNI with 256-bit vectors (probed once).
pub fn vnni_available() -> bool {
    match DETECTED.load(Ordering::Relaxed) {
        1 => false,
        2 => true,
        _ => {
            let v = detect_vnni();
            DETECTED.store(if v { 2 } else { 1 }, Ordering::Relaxed);
            v
        }
    }
}

/// Caps the instruction set the fast kernels use (process-wide; default: the best the CPU
/// has). Results are the same integers on every level; this exists to measure (and compare)
/// the portable and AVX2 kernels on a machine that has more.
pub fn set_max_isa(isa: Isa) {
    MAX_ISA.store(isa as u8, Ordering::Relaxed);
}

/// The instruction set the fast kernels use now: the CPU's best, capped by [`set_max_isa`].
pub fn isa() -> Isa {
    let max = MAX_ISA.load(Ordering::Relaxed);
    if max >= Isa::Avx512Vnni as u8 && vnni_available() {
        Isa::Avx512Vnni
    } else if max >= Isa::Avx2 as u8 {
        Isa::Avx2
    } else {
        Isa::Portable
    }
}
