//! # mem: the NEON kernels' vector loads and stores, as `ld1` / `st1` of their element size
//!
//! `aarch64-unknown-none` builds with `strict-align`: bare-metal code may run with the MMU off
//! (every access Device memory) or with alignment checking on, where an access not aligned to
//! its size faults. LLVM then may not use `ldr q` / `ldr d` / `str d` for an access it cannot
//! prove aligned to 16 or 8 bytes, and the intrinsics (`vld1q_s8` and the rest are unaligned
//! reads) become byte loads and inserts: ~40 instructions for one 16-byte load. `ld1` / `st1`
//! need only the alignment of their element (ARM ARM: the alignment check of a SIMD element or
//! structure access is against the element size), which every `*const i8`, `i16` and `i32` the
//! kernels pass has, so they are legal for both. So bare-metal builds (`target_os = "none"`)
//! load and store through `ld1` / `st1` in `asm!`. Elsewhere the intrinsics stay: the compiler
//! folds their addressing and pairs them (`ldp`), which `asm!` prevents (+8-10 % instructions
//! per frame on Linux). `--cfg semloc_ld1` selects the `asm!` form on any aarch64 target, to
//! measure a `+strict-align` build under `qemu-aarch64` as bare metal runs it (README,
//! "Bare-metal builds: vector loads under strict alignment").
//!
//! Each function is `unsafe` as the intrinsic it replaces: the caller guarantees that the
//! bytes at `p` are readable (writable for a store) for the vector's size.

use core::arch::aarch64::*;
#[cfg(any(target_os = "none", semloc_ld1))]
use core::arch::asm;

/// Defines an `ld1` load of one vector register.
macro_rules! ld1 {
    ($(#[$doc:meta])* $name:ident, $intrinsic:ident, $elem:ty, $vec:ty, $arr:literal) => {
        $(#[$doc])*
        #[target_feature(enable = "neon")]
        #[inline]
        pub(crate) unsafe fn $name(p: *const $elem) -> $vec {
            #[cfg(any(target_os = "none", semloc_ld1))]
            {
                let v: $vec;
                // SAFETY: the caller's: the vector's bytes at `p` are readable; `p` is aligned
                // to its element (a pointer to that type).
                unsafe {
                    asm!(
                        concat!("ld1 {{{v:v}.", $arr, "}}, [{p}]"),
                        v = out(vreg) v,
                        p = in(reg) p,
                        options(pure, readonly, nostack, preserves_flags),
                    );
                }
                v
            }
            // SAFETY: the caller's, as above.
            #[cfg(not(any(target_os = "none", semloc_ld1)))]
            unsafe {
                $intrinsic(p)
            }
        }
    };
}

ld1!(
    /// 8 bytes (`vld1_s8`).
    ld1_s8, vld1_s8, i8, int8x8_t, "8b"
);
ld1!(
    /// 16 bytes (`vld1q_s8`).
    ld1q_s8, vld1q_s8, i8, int8x16_t, "16b"
);
ld1!(
    /// 4 `i16`s (`vld1_s16`).
    ld1_s16, vld1_s16, i16, int16x4_t, "4h"
);
ld1!(
    /// 8 `i16`s (`vld1q_s16`).
    ld1q_s16, vld1q_s16, i16, int16x8_t, "8h"
);
ld1!(
    /// 4 `i32`s (`vld1q_s32`).
    ld1q_s32, vld1q_s32, i32, int32x4_t, "4s"
);

/// Defines an `st1` store of one vector register.
macro_rules! st1 {
    ($(#[$doc:meta])* $name:ident, $intrinsic:ident, $elem:ty, $vec:ty, $arr:literal) => {
        $(#[$doc])*
        #[target_feature(enable = "neon")]
        #[inline]
        pub(crate) unsafe fn $name(p: *mut $elem, v: $vec) {
            // SAFETY: the caller's: the vector's bytes at `p` are writable; `p` is aligned to
            // its element (a pointer to that type).
            #[cfg(any(target_os = "none", semloc_ld1))]
            unsafe {
                asm!(
                    concat!("st1 {{{v:v}.", $arr, "}}, [{p}]"),
                    v = in(vreg) v,
                    p = in(reg) p,
                    options(nostack, preserves_flags),
                );
            }
            // SAFETY: the caller's, as above.
            #[cfg(not(any(target_os = "none", semloc_ld1)))]
            unsafe {
                $intrinsic(p, v)
            }
        }
    };
}

st1!(
    /// Stores 8 bytes (`vst1_s8`).
    st1_s8, vst1_s8, i8, int8x8_t, "8b"
);
st1!(
    /// Stores 4 `i32`s (`vst1q_s32`).
    st1q_s32, vst1q_s32, i32, int32x4_t, "4s"
);
