//! # arm64: NEON forms of the int8 kernels (aarch64)
//!
//! The kernels an aarch64 ECU runs for the five op families that hold most of the network's
//! work, beside the safe `nn::portable` kernels (which keep the other families):
//!
//! | file        | ONNX op                                       | instructions                  | stack   |
//! |-------------|-----------------------------------------------|-------------------------------|---------|
//! | `pointwise` | `Conv` 1×1 (int8 GEMM over packed weights)    | `ld4`, `sxtl`, `smlal` (lane) | 12 KiB  |
//! | `dot`       | `Conv` 1×1, on CPUs with FEAT_DotProd         | `sdot` (lane)                 | 13 KiB  |
//! | `depthwise` | `Conv` depthwise 3×3, pad 1, stride 1/2       | `smull`, `smlal`, `saddw`     | 4 KiB   |
//! | `conv1`     | `Conv` 3×3 of a one-channel map (first layer) | `smlal` (lane)                | 2.2 KiB |
//! | `resize`    | `Resize` bilinear, `half_pixel`               | `ssubl`, `smlal`, `mla`       | 4.8 KiB |
//! | `eltwise`   | `Add`                                         | `sshll`, `sqrdmulh`           | —       |
//! | `lanes`     | shared: requantisation of 8 lanes             | `sqrdmulh`, `srshl`, `xtn`    | —       |
//! | `mem`       | shared: vector loads and stores               | `ld1`, `st1` on bare metal    | —       |
//!
//! NEON (Advanced SIMD) is part of every aarch64 target this crate builds for
//! (`aarch64-unknown-none`, `aarch64-unknown-linux-gnu`: `target_feature = "neon"`), so the
//! module is compiled for them and needs no run-time check. Those kernels use only the
//! baseline ARMv8.0 NEON instructions, and their `i16` products are exact for any zero point.
//! The ARMv8.2 dot products (`sdot`, FEAT_DotProd: Cortex-A55, A65, A75, A76, A78AE, Neoverse)
//! are not on every automotive core (Cortex-A53, A72), so the 1×1 GEMM that uses them (`dot`)
//! runs only where [`dotprod_available`] finds them: at compile time (`target_feature =
//! "dotprod"`, e.g. `-C target-cpu=cortex-a76`), else once at run time — on Linux and Android
//! from the kernel's `AT_HWCAP` bits (`HWCAP_ASIMDDP`, as std's `is_aarch64_feature_detected!`
//! reads them), on bare metal (`target_os = "none"`) from `ID_AA64ISAR0_EL1.DP`, which code at
//! EL1 or above may read (the target's code runs there). Elsewhere it is not used.
//!
//! Every kernel computes the very integers of the reference kernels. `nn::dispatch` picks
//! them; the shared `kernel_equivalence!` tests run every family both with these kernels and
//! with the portable ones against the reference (`dispatch::for_each_level`: `neon`,
//! `portable`), on an aarch64 machine or under `qemu-aarch64`. Each family's entry takes the
//! operands its op already checked and returns `false` (writing nothing) when the op is
//! outside what the vector code handles: when [`super::quant::fits_simd_requant`] fails (never
//! for a real network), a 1×1 row is wider than the 4096-channel stage or a first conv has more
//! than 64 output channels. The portable kernel then runs.
//!
//! `unsafe` is allowed in this module (the workspace denies it elsewhere) for the NEON loads
//! and stores through raw pointers, whose ranges each kernel checks by slicing (one bounds
//! check per group of 4 inputs or 8 channels, or one per depthwise window or resize group,
//! not per byte), and for calling the kernels' `#[target_feature(enable = "neon")]` bodies
//! from their safe entries (sound: the module is compiled only with `neon` enabled).
//!
//! [`set_neon`] turns the module off for the process (measurements of the portable kernels
//! on the same machine), [`set_dotprod`] only the `sdot` GEMM; results are the same either way.

#![allow(unsafe_code)]

use core::sync::atomic::{AtomicBool, AtomicU8, Ordering};

pub(crate) mod conv1;
pub(crate) mod depthwise;
pub(crate) mod dot;
pub(crate) mod eltwise;
pub(crate) mod lanes;
pub(crate) mod mem;
pub(crate) mod pointwise;
pub(crate) mod resize;

/// Whether the NEON kernels may run (default: yes), as set by [`set_neon`].
static NEON: AtomicBool = AtomicBool::new(true);

/// Lets the NEON kernels run (`true`, the default) or sends every op to the portable kernels
/// (`false`), process-wide: for measurements (`SEMLOC_NN_ISA=portable` in the nn bench).
pub fn set_neon(enabled: bool) {
    NEON.store(enabled, Ordering::Relaxed);
}

/// Whether the NEON kernels may run ([`set_neon`]).
#[inline]
pub fn neon_enabled() -> bool {
    NEON.load(Ordering::Relaxed)
}

/// Whether the `sdot` GEMM may run where the CPU has it (default: yes), as set by
/// [`set_dotprod`].
static DOTPROD: AtomicBool = AtomicBool::new(true);
/// The run-time probe's answer: 0 not probed yet, 1 no, 2 yes.
static DOTPROD_CPU: AtomicU8 = AtomicU8::new(0);

/// Lets the `sdot` 1×1 GEMM run where the CPU has the dot products (`true`, the default) or
/// keeps the 1×1 convs on the baseline NEON GEMM (`false`), process-wide: for measurements
/// (`SEMLOC_NN_ISA=neon` in the nn bench).
pub fn set_dotprod(enabled: bool) {
    DOTPROD.store(enabled, Ordering::Relaxed);
}

/// Whether this CPU has the ARMv8.2 dot products (FEAT_DotProd), from the build's target
/// features or, once, from the operating system or the ID register (see the module's text).
pub fn dotprod_available() -> bool {
    if cfg!(target_feature = "dotprod") {
        return true;
    }
    match DOTPROD_CPU.load(Ordering::Relaxed) {
        0 => {
            let has = probe_dotprod();
            DOTPROD_CPU.store(if has { 2 } else { 1 }, Ordering::Relaxed);
            has
        }
        v => v == 2,
    }
}

/// Whether the `sdot` GEMM runs: the CPU has it and neither [`set_neon`] nor [`set_dotprod`]
/// turned it off.
#[inline]
pub fn dotprod_enabled() -> bool {
    neon_enabled() && DOTPROD.load(Ordering::Relaxed) && dotprod_available()
}

/// The CPU's `HWCAP_ASIMDDP` as the kernel reports it (`getauxval(AT_HWCAP)`).
#[cfg(any(target_os = "linux", target_os = "android"))]
fn probe_dotprod() -> bool {
    use core::ffi::c_ulong;
    extern "C" {
        fn getauxval(kind: c_ulong) -> c_ulong;
    }
    const AT_HWCAP: c_ulong = 16;
    const HWCAP_ASIMDDP: c_ulong = 1 << 20;
    // SAFETY: the C library's `getauxval` (glibc, musl, bionic) reads the auxiliary vector the
    // kernel passed at start-up; it has no preconditions and returns 0 for an unknown kind.
    unsafe { getauxval(AT_HWCAP) & HWCAP_ASIMDDP != 0 }
}

/// `ID_AA64ISAR0_EL1.DP` (bits 47:44) ≥ 1: the CPU has `sdot`/`udot`.
#[cfg(target_os = "none")]
fn probe_dotprod() -> bool {
    let isar0: u64;
    // SAFETY: reads an ID register, which EL1 and above may always read (bare-metal code for
    // this target runs there); no memory, no flags.
    unsafe {
        core::arch::asm!(
            "mrs {r}, ID_AA64ISAR0_EL1",
            r = out(reg) isar0,
            options(nomem, nostack, preserves_flags),
        );
    }
    (isar0 >> 44) & 0xf >= 1
}

/// No probe on other systems: the baseline NEON GEMM runs.
#[cfg(not(any(target_os = "linux", target_os = "android", target_os = "none")))]
fn probe_dotprod() -> bool {
    false
}
