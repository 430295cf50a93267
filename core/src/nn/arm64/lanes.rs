//! # lanes: the requantisation of 8 `i32` lanes in NEON
//!
//! [`Rq8`] holds 8 requantisers in the lane form of `nn::quant`'s `Lanes8` and computes
//! `clamp(zp + apply(acc), lo, hi)` for two `int32x4_t` with the same integers as
//! [`Requant::to_i8`], for `|acc| · 2^left ≤ 2^30` ([`super::super::quant::fits_simd_requant`]):
//! 1. `sshl` by `left` (no saturation under the bound),
//! 2. `sqrdmulh` by the multiplier: `sat((2·v·M + 2^31) >> 32)` = `floor((v·M + 2^30) / 2^31)`,
//!    gemmlowp's `SaturatingRoundingDoublingHighMul` (its only saturating case, `v = M =
//!    i32::MIN`, cannot occur: `M ≥ 0`),
//! 3. gemmlowp's `RoundingDivideByPOT` by `e`, which rounds ties away from zero, as an `srshl`
//!    by `−e` (a rounding shift: `(u + 2^(e−1)) >> e`, ties up) of `u = s − 1` on negative lanes
//!    with `e > 0`, else `u = s`. Write `s = q·2^e + r` (`0 ≤ r < 2^e`): gemmlowp gives
//!    `q + (r > 2^(e−1) − 1 + [s < 0])`, and `srshl` of `u` gives `q + (r + 2^(e−1) − [s < 0] ≥
//!    2^e)`, the same predicate; `s − 1` cannot wrap (`|s| ≤ 2^30` under the bound). Three
//!    instructions and the `srshl`, where the portable lanes' `(s >> e) + ((s & mask) > half −
//!    (s >> 31))` takes six;
//! 4. for `i8` outputs ([`Rq8Regs::requant`]): saturating narrows to `i16` (`sqxtn`,
//!    `sqxtn2`), `+ zp` saturating (`sqadd`), a saturating narrow to `i8`, then the clamp to
//!    `[lo, hi]`, whose `hi` is 127 for every `i8` output (`clamp_range`), so only the `max`
//!    remains. With `|zp| ≤ 128` and `−128 ≤ lo ≤ 127` that is `clamp(q + zp, lo, 127)`: where
//!    `q + zp` fits an `i16` the narrows only clamp it to `[−128, 127]`; beyond, the saturated
//!    value stays beyond the `i8` range on the same side, so the result is `lo` or 127, as
//!    `clamp` gives. 5 instructions per 8 lanes where `+ zp`, `max` and `min` on the `i32`
//!    lanes and three narrowing moves took 9. `i32` outputs ([`Rq8Regs::requant_i32`], `Add`'s inputs) add `zp`
//!    and clamp on the `i32` lanes.

use super::mem::{ld1_s8, ld1q_s32, st1_s8};
use core::arch::aarch64::*;

use crate::nn::quant::{Lane1, Requant};

/// Up to 8 requantisers in NEON lane form (missing lanes: zero multiplier, output `zp`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rq8 {
    m: [i32; 8],
    left: [i32; 8],
    /// `−e`: `srshl` by it is the rounding right shift by `e`.
    right: [i32; 8],
    /// All ones where `e > 0` (a negative lane takes the tie fix-up), else 0.
    nz: [i32; 8],
}

/// [`Rq8`]'s constants in registers, for a loop that requantises many pixels of one group.
#[derive(Clone, Copy)]
pub(crate) struct Rq8Regs {
    m: [int32x4_t; 2],
    left: [int32x4_t; 2],
    right: [int32x4_t; 2],
    nz: [int32x4_t; 2],
    zp: int32x4_t,
    lo: int32x4_t,
    hi: int32x4_t,
    /// `zp` and `lo` for the `i8` outputs (saturated to their types: [`Rq8Regs::requant`] is
    /// used only with zero points and clamp ranges within `i8`, and `hi = 127`).
    zp16: int16x8_t,
    lo8: int8x8_t,
}

impl Rq8 {
    /// All lanes zero.
    pub(crate) const ZERO: Rq8 = Rq8 { m: [0; 8], left: [0; 8], right: [0; 8], nz: [0; 8] };

    /// From up to 8 requantisers.
    pub(crate) fn new(r: &[Requant]) -> Self {
        let mut l = Rq8::ZERO;
        for (i, q) in r.iter().take(8).enumerate() {
            let q = Lane1::new(*q);
            // M < 2^31 and the shifts ≤ 31 fit the `i32` lanes
            (l.m[i], l.left[i], l.right[i], l.nz[i]) =
                (q.m as i32, q.left as i32, -(q.right as i32), -((q.right > 0) as i32));
        }
        l
    }

    /// The constants in registers, with the output zero point and clamp range.
    #[target_feature(enable = "neon")]
    #[inline]
    pub(crate) fn regs(&self, zp: i32, lo: i32, hi: i32) -> Rq8Regs {
        let two = |a: &[i32; 8]| {
            let (l, h) = a.split_at(4);
            // SAFETY: `l` and `h` are 4 `i32`s each.
            unsafe { [ld1q_s32(l.as_ptr()), ld1q_s32(h.as_ptr())] }
        };
        Rq8Regs {
            m: two(&self.m),
            left: two(&self.left),
            right: two(&self.right),
            nz: two(&self.nz),
            zp: vdupq_n_s32(zp),
            lo: vdupq_n_s32(lo),
            hi: vdupq_n_s32(hi),
            zp16: vdupq_n_s16(zp.clamp(i16::MIN.into(), i16::MAX.into()) as i16),
            lo8: vdup_n_s8(lo.clamp(-128, 127) as i8),
        }
    }
}

/// Blocks of 8 channels whose lane-form requantisers [`Rq8Table`] makes once per call (4 KiB).
pub(crate) const TABLE: usize = 32;

/// The lane-form requantisers of a layer's blocks of 8 channels: the first [`TABLE`] made once
/// per call into the caller's array, those beyond (wider layers) when asked for.
///
/// The array is the caller's (a local of the kernel's frame) rather than a field: a 4 KiB
/// table built in [`Rq8Table::new`] and moved into its return value left two copies in each
/// GEMM's frame, and the bare-metal image's semantic frame stack peak rose from 18.9 to
/// 22.1 KB.
pub(crate) struct Rq8Table<'a> {
    first: &'a [Rq8; TABLE],
    all: &'a [Requant],
}

impl<'a> Rq8Table<'a> {
    /// The table of `all` (one requantiser per channel), its first blocks made into `first`.
    pub(crate) fn new(first: &'a mut [Rq8; TABLE], all: &'a [Requant]) -> Self {
        for (r, qq) in first.iter_mut().zip(all.chunks(8)) {
            *r = Rq8::new(qq);
        }
        Rq8Table { first, all }
    }

    /// Block `blk`'s (channels `8·blk..`) lane form.
    #[inline]
    pub(crate) fn block(&self, blk: usize) -> Rq8 {
        match self.first.get(blk) {
            Some(r) => *r,
            None => Rq8::new(&self.all[8 * blk..(8 * blk + 8).min(self.all.len())]),
        }
    }
}

/// The up to 8 values `v[k0..]` of a block of channels, the missing ones 0 (biases).
#[inline]
pub(crate) fn block8(v: &[i32], k0: usize) -> [i32; 8] {
    let mut b = [0i32; 8];
    let nb = (v.len() - k0).min(8);
    b[..nb].copy_from_slice(&v[k0..k0 + nb]);
    b
}

impl Rq8Regs {
    /// `clamp(zp + apply(acc), lo, hi)` of the 8 lanes `acc[0] ++ acc[1]`, as `i8`.
    #[target_feature(enable = "neon")]
    #[inline]
    pub(crate) fn requant(&self, acc: [int32x4_t; 2]) -> int8x8_t {
        // every `i8` output's range ends at 127 (`clamp_range`), where `sqxtn` saturates
        debug_assert_eq!(vgetq_lane_s32::<0>(self.hi), 127);
        let h = vqmovn_high_s32(vqmovn_s32(self.apply4(acc[0], 0)), self.apply4(acc[1], 1));
        vmax_s8(vqmovn_s16(vqaddq_s16(h, self.zp16)), self.lo8)
    }

    /// `clamp(zp + apply(acc), lo, hi)` of the 8 lanes, not narrowed (with `zp = 0`,
    /// `lo = i32::MIN`, `hi = i32::MAX`: `apply(acc)` itself, as `Add` needs per input).
    #[target_feature(enable = "neon")]
    #[inline]
    pub(crate) fn requant_i32(&self, acc: [int32x4_t; 2]) -> [int32x4_t; 2] {
        let c = |q: int32x4_t| vminq_s32(vmaxq_s32(vaddq_s32(q, self.zp), self.lo), self.hi);
        [c(self.apply4(acc[0], 0)), c(self.apply4(acc[1], 1))]
    }

    /// `apply(acc)` of lanes `4j..4j + 4` (steps 1-3 of the module's text).
    #[target_feature(enable = "neon")]
    #[inline]
    fn apply4(&self, acc: int32x4_t, j: usize) -> int32x4_t {
        let v = vshlq_s32(acc, self.left[j]);
        let s = vqrdmulhq_s32(v, self.m[j]);
        // s − 1 on negative lanes with e > 0 (`s >> 31` is −1 there), then the rounding shift
        let u = vaddq_s32(s, vandq_s32(vshrq_n_s32::<31>(s), self.nz[j]));
        vrshlq_s32(u, self.right[j])
    }
}

/// Stores the first `min(8, out.len())` lanes of `v` to `out`.
#[target_feature(enable = "neon")]
#[inline]
pub(crate) fn store8(out: &mut [i8], v: int8x8_t) {
    match <&mut [i8; 8]>::try_from(&mut *out) {
        // SAFETY: 8 bytes of `out`.
        Ok(o) => unsafe { st1_s8(o.as_mut_ptr(), v) },
        Err(_) => {
            let mut t = [0i8; 8];
            // SAFETY: 8 bytes of `t`.
            unsafe { st1_s8(t.as_mut_ptr(), v) };
            let n = out.len().min(8);
            out[..n].copy_from_slice(&t[..n]);
        }
    }
}

/// Up to 8 bytes as a vector, the missing lanes `pad`.
#[target_feature(enable = "neon")]
#[inline]
pub(crate) fn load8(v: &[i8], pad: i8) -> int8x8_t {
    match <&[i8; 8]>::try_from(v) {
        // SAFETY: 8 bytes.
        Ok(a) => unsafe { ld1_s8(a.as_ptr()) },
        Err(_) => {
            let t: [i8; 8] = core::array::from_fn(|i| v.get(i).copied().unwrap_or(pad));
            // SAFETY: 8 bytes of `t`.
            unsafe { ld1_s8(t.as_ptr()) }
        }
    }
}
