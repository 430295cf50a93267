//! # arm64: NEON forms of the int8 kernels (aarch64)
//!
//! The kernels an aarch64 ECU runs for the five op families that hold most of the network's
//! work, beside the safe `nn::portable` kernels (which keep the other families):
//!
//! | file        | ONNX op                                       | instructions                  | stack   |
//! |-------------|-----------------------------------------------|-------------------------------|---------|
//! | `pointwise` | `Conv` 1×1 (int8 GEMM over packed weights)    | `ld4`, `sxtl`, `smlal` (lane) | 13 KiB  |
//! | `depthwise` | `Conv` depthwise 3×3, pad 1, stride 1/2       | `ssubl`, `sxtl`, `smlal`      | 5 KiB   |
//! | `conv1`     | `Conv` 3×3 of a one-channel map (first layer) | `smlal` (lane)                | 2.5 KiB |
//! | `resize`    | `Resize` bilinear, `half_pixel`               | `ssubl`, `smull`, `mla`       | 1.5 KiB |
//! | `eltwise`   | `Add`                                         | `sshll`, `sqrdmulh`           | —       |
//! | `lanes`     | shared: requantisation of 8 lanes             | `sqrdmulh`, `sshl`, `xtn`     | —       |
//!
//! NEON (Advanced SIMD) is part of every aarch64 target this crate builds for
//! (`aarch64-unknown-none`, `aarch64-unknown-linux-gnu`: `target_feature = "neon"`), so the
//! module is compiled for them and needs no run-time check. Only the baseline ARMv8.0 NEON
//! instructions are used: `sdot` (ARMv8.2 dot products) is not on every automotive core
//! (Cortex-A53, A72), and the `i16` products here are exact for any zero point.
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
//! on the same machine); results are the same either way.

#![allow(unsafe_code)]

use core::sync::atomic::{AtomicBool, Ordering};

pub(crate) mod conv1;
pub(crate) mod depthwise;
pub(crate) mod eltwise;
pub(crate) mod lanes;
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
