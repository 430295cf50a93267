//! # x86: x86-64 AVX2 and AVX-512 VNNI forms of the int8 kernels
//!
//! One file per op family, as tract's `linalg/src/x86_64_fma`, beside the safe
//! `nn::portable` kernels (and the `nn::arm64` NEON family):
//!
//! | file        | ONNX op                                           | ISA                | stack   |
//! |-------------|---------------------------------------------------|--------------------|---------|
//! | `pointwise` | `Conv` 1×1 (int8 GEMM over packed weights)        | AVX2; AVX-512 VNNI | 19/8 KiB|
//! | `depthwise` | `Conv` depthwise 3×3, pad 1, stride 1/2           | AVX2               | 14 KiB  |
//! | `conv1`     | `Conv` 3×3 of a one-channel map (the first layer) | AVX2               | 3 KiB   |
//! | `resize`    | `Resize` bilinear, `half_pixel`                   | AVX2               | 40 KiB  |
//! | `eltwise`   | `Add`; the rescales of `Concat`                   | AVX2               | < 1 KiB |
//! | `lanes`     | shared: requantisation, loads, stores of 8 lanes  | AVX2               | —       |
//!
//! Compiled for every x86-64 build; which kernels run is chosen at **run time**, so one
//! baseline x86-64 binary (a plain `cargo install`, no `-C target-cpu`) runs on any x86-64 CPU
//! and still uses the vector kernels where it can: [`cpu_isa`] probes the CPU once with
//! `cpuid`/`xgetbv` — AVX2 with the YMM state enabled by the OS, and AVX-512 F/BW/VL + VNNI
//! (`vpdpbusd`, u8×i8 dot products of four) with the ZMM and opmask state enabled — and
//! [`isa`] is [`Isa::Portable`] on a CPU without AVX2, so `nn::dispatch` runs the portable
//! kernels there. The 1×1 GEMM uses VNNI when present. Every kernel computes the very integers
//! of the reference kernels; `nn::dispatch` is the one place that picks them, and the shared
//! `kernel_equivalence!` tests run every family at every level this CPU has against the
//! reference. Each family's safe entry takes the operands its op already checked and returns
//! `false` (writing nothing) when the CPU has no AVX2 or the op is outside what the vector code
//! handles, e.g. when [`super::quant::fits_simd_requant`] fails (never for a real network); the
//! portable kernel then runs.
//!
//! `unsafe` is allowed in this module only (the workspace denies it elsewhere), for two things:
//! calling `#[target_feature]` functions (sound: each family's safe entry gets an `Avx2`
//! token, which only the run-time check makes, before it calls its AVX2 kernel, and the VNNI
//! GEMM checks [`vnni_available`] before the call; the kernels' helpers in `lanes` carry
//! `#[target_feature(enable = "avx2")]` themselves, so they inline into the kernels) and
//! raw-pointer loads/stores in the inner loops, whose ranges the safe entry points check once.
//! Measured gain over the safe portable kernels (`benches/nn.rs`, `SEMLOC_NN_ISA`): the 192×640
//! graph 6.2 ms (VNNI) / 9.2 ms (AVX2) against ~75 ms when the portable kernels were
//! auto-vectorised for x86-64-v3 (the hosts' former `-C target-cpu`), the 1×1 GEMM 2.8 / 5.7 ms
//! against 24 ms — far beyond the 20 % that would favour safe code; in today's baseline x86-64
//! build (SSE2 only outside these kernels) the portable graph is ~1.55× slower again (61 → 95
//! ms back to back), while the AVX2 and VNNI times are unchanged (run-time dispatch costs
//! nothing measurable). The portable kernels remain the code of the other targets (and are
//! tested on x86 too).
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

/// The CPU's best [`Isa`] plus one; 0: not probed yet.
static DETECTED: AtomicU8 = AtomicU8::new(0);
/// The most capable [`Isa`] the kernels may use, as set by [`set_max_isa`] (default: all).
static MAX_ISA: AtomicU8 = AtomicU8::new(Isa::Avx512Vnni as u8);

/// The instruction sets the fast kernels can run on, least capable first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
pub enum Isa {
    /// The portable kernels (safe Rust, auto-vectorised for the build's target CPU).
    Portable = 0,
    /// The AVX2 intrinsics kernels.
    Avx2 = 1,
    /// AVX2, with AVX-512 VNNI for the 1×1 GEMM.
    Avx512Vnni = 2,
}

impl Isa {
    /// The level stored as `v` (values above the top one: the top one).
    fn from_u8(v: u8) -> Self {
        match v {
            0 => Isa::Portable,
            1 => Isa::Avx2,
            _ => Isa::Avx512Vnni,
        }
    }
}

/// Proof that the CPU and OS support AVX2: only [`Avx2::get`] makes one, after the run-time
/// check. Each family's safe entry gets one (or returns `false`) and hands it to the function
/// that calls its `#[target_feature(enable = "avx2")]` kernel, which is sound because of it.
#[derive(Clone, Copy)]
pub(crate) struct Avx2(());

impl Avx2 {
    /// The token, when [`cpu_isa`] has AVX2 (whatever [`set_max_isa`] says).
    #[inline]
    pub(crate) fn get() -> Option<Self> {
        (cpu_isa() >= Isa::Avx2).then_some(Avx2(()))
    }
}

/// The best level the CPU and the OS support, by `cpuid` and `xgetbv`.
fn detect() -> Isa {
    // CPUID.1:ECX: OSXSAVE (27: the OS uses XSAVE, so `xgetbv` exists), AVX (28)
    let l1 = __cpuid(1);
    if l1.ecx & (1 << 27) == 0 || l1.ecx & (1 << 28) == 0 || __cpuid(0).eax < 7 {
        return Isa::Portable;
    }
    // SAFETY: `xgetbv` (the `xsave` target feature) exists when CPUID.1:ECX.OSXSAVE is set,
    // checked just above.
    let xcr0 = unsafe { _xgetbv(0) };
    let l7 = __cpuid_count(7, 0);
    // AVX2: CPUID.7.0:EBX bit 5, and XCR0 has the XMM (bit 1) and YMM (bit 2) state enabled
    let avx2 = l7.ebx & (1 << 5) != 0;
    if !avx2 || xcr0 & 0x6 != 0x6 {
        return Isa::Portable;
    }
    // AVX-512 F, BW, VL, VNNI, and XCR0 has the opmask, ZMM_Hi256, Hi16_ZMM state enabled too
    let f = l7.ebx & (1 << 16) != 0;
    let bw = l7.ebx & (1 << 30) != 0;
    let vl = l7.ebx & (1 << 31) != 0;
    let vnni = l7.ecx & (1 << 11) != 0;
    if f && bw && vl && vnni && xcr0 & 0xe6 == 0xe6 {
        Isa::Avx512Vnni
    } else {
        Isa::Avx2
    }
}

/// The best [`Isa`] the CPU (and OS) support, probed once; not capped by [`set_max_isa`].
#[inline]
pub fn cpu_isa() -> Isa {
    match DETECTED.load(Ordering::Relaxed) {
        0 => {
            let isa = detect();
            DETECTED.store(isa as u8 + 1, Ordering::Relaxed);
            isa
        }
        v => Isa::from_u8(v - 1),
    }
}

/// True when the CPU (and OS) support AVX-512 VNNI with 256-bit vectors (probed once).
pub fn vnni_available() -> bool {
    cpu_isa() == Isa::Avx512Vnni
}

/// Caps the instruction set the fast kernels use (process-wide; default: the best the CPU
/// has). Results are the same integers on every level; this exists to measure (and compare)
/// the portable and AVX2 kernels on a machine that has more.
pub fn set_max_isa(isa: Isa) {
    MAX_ISA.store(isa as u8, Ordering::Relaxed);
}

/// The instruction set the fast kernels use now: the CPU's best ([`cpu_isa`]; `Portable` on a
/// CPU without AVX2), capped by [`set_max_isa`].
pub fn isa() -> Isa {
    cpu_isa().min(Isa::from_u8(MAX_ISA.load(Ordering::Relaxed)))
}
