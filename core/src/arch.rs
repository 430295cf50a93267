//! # arch: the safe scalar kernels, compiled a second time for x86-64-v3
//!
//! The hot loops of ORB extraction, the image filters and the descriptor matching are plain safe
//! Rust written to auto-vectorise. A baseline x86-64 build (a plain `cargo install`, no
//! `-C target-cpu`) compiles them for SSE2 only: 16-byte vectors, and `count_ones` as a
//! shift-and-add sequence instead of one `popcnt`. [`v3`] runs a closure compiled with AVX2,
//! POPCNT, BMI1/2 and LZCNT when the CPU has them (probed once with `cpuid`/`xgetbv`, as the
//! network's kernels are: [`crate::nn::x86`]), and the baseline code otherwise. A kernel opts in
//! by passing its body as an `#[inline(always)]` closure, the body and the helpers it calls
//! marked `#[inline(always)]` as well: only code inlined into the `#[target_feature]` function
//! is compiled for it (a closure left out of line is a plain baseline function, and a large one
//! is left out of line).
//!
//! **Same bits on every level.** The code is the same source: integer arithmetic is exact, and
//! floating point is IEEE-754 per operation at any vector width (Rust never fuses a multiply
//! and an add, and FMA is not among the features enabled here), so results are identical to
//! the baseline build's and to every other target's; `tests` compares both levels on real
//! work. The level follows the network's cap ([`crate::nn::x86::set_max_isa`]): capped at
//! `Portable`, these kernels run their baseline code too.
//!
//! `unsafe` is allowed in this module and in `nn::x86` only: calling the `#[target_feature]`
//! function is sound because it is called only after the run-time check.

#![allow(unsafe_code)]

/// Runs `f`, compiled for AVX2 + POPCNT + BMI1/2 + LZCNT when this x86-64 CPU has them (and the
/// instruction-set cap allows AVX2), else as the build's baseline code. `f` and whatever it
/// calls that should be compiled for the faster level must be inlined into it: pass
/// `#[inline(always)] || body(..)` with `body` `#[inline(always)]`. Results are the same either
/// way.
#[inline(always)]
pub(crate) fn v3<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if x86::v3_allowed() {
        // SAFETY: `v3_allowed` is true only when `cpuid`/`xgetbv` report every feature
        // `x86::run_v3` is compiled with, and the OS saves the YMM state.
        return unsafe { x86::run_v3(f) };
    }
    f()
}

/// Whether [`v3`] runs its closure compiled for x86-64-v3 on this thread now.
pub fn v3_active() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        x86::v3_allowed()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    use core::arch::x86_64::{__cpuid, __cpuid_count};
    use core::sync::atomic::{AtomicU8, Ordering};

    use crate::nn::x86::Isa;

    /// 0: not probed; 1: the CPU lacks one of the extra features; 2: it has them all.
    static EXTRAS: AtomicU8 = AtomicU8::new(0);

    /// POPCNT, BMI1, BMI2 and LZCNT, beside the AVX2 (and OS YMM state) that
    /// `nn::x86::cpu_isa` checks.
    fn probe_extras() -> bool {
        let l1 = __cpuid(1);
        let popcnt = l1.ecx & (1 << 23) != 0;
        if __cpuid(0).eax < 7 || __cpuid(0x8000_0000).eax < 0x8000_0001 {
            return false;
        }
        let l7 = __cpuid_count(7, 0);
        let (bmi1, bmi2) = (l7.ebx & (1 << 3) != 0, l7.ebx & (1 << 8) != 0);
        let lzcnt = __cpuid(0x8000_0001).ecx & (1 << 5) != 0;
        popcnt && bmi1 && bmi2 && lzcnt
    }

    /// True when the CPU has every feature of [`run_v3`] and the cap allows AVX2.
    #[inline]
    pub(super) fn v3_allowed() -> bool {
        if crate::nn::dispatch::level() < Isa::Avx2 {
            return false;
        }
        match EXTRAS.load(Ordering::Relaxed) {
            0 => {
                let ok = probe_extras();
                EXTRAS.store(1 + u8::from(ok), Ordering::Relaxed);
                ok
            }
            v => v == 2,
        }
    }

    /// `f()`, compiled with the x86-64-v3 integer and vector features (FMA left out: it would
    /// not change Rust's arithmetic, which never fuses, but nothing here needs it).
    ///
    /// # Safety
    /// The CPU must have AVX2, POPCNT, BMI1, BMI2 and LZCNT, and the OS must save the YMM
    /// state ([`v3_allowed`]).
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    #[inline]
    pub(super) unsafe fn run_v3<R>(f: impl FnOnce() -> R) -> R {
        f()
    }
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    /// The probe finds what std's detection finds, so the tests that compare the levels
    /// (`orb::tests::golden_output_is_unchanged`) really run the x86-64-v3 code where the CPU
    /// has it, and it is off when the cap is below AVX2.
    #[test]
    fn probe_agrees_with_std() {
        use std::arch::is_x86_feature_detected as has;
        let all = has!("avx2") && has!("popcnt") && has!("bmi1") && has!("bmi2") && has!("lzcnt");
        let mut seen = std::vec::Vec::new();
        crate::nn::dispatch::for_each_level(|level| seen.push((level, super::v3_active())));
        for (level, active) in seen {
            assert_eq!(active, all && level != "portable", "level {level}");
        }
    }
}
