//! # x86 eltwise: `Add` and the rescales of `Concat`, AVX2
//!
//! - ONNX `Add` (same shapes): TFLite's quantised add, `clamp(zo + Mo(M1((a − za) << 20) +
//!   M2((b − zb) << 20)))`, the integers of [`crate::nn::eltwise::add_reference`]. 8 lanes at a
//!   time; `SRDHM(d·2^20, M)` in 32 bits as `d·(M >> 11) + ((d·(M & 2047) + 2^10) >> 11)`.
//! - ONNX `Concat` along channels: one input rescaled into its channel slot of the output,
//!   `clamp(zo + M(x − zp))`, as [`crate::nn::eltwise::concat_reference`] (identity rescales
//!   are plain copies, left to the portable kernel).
//!
//! **ISA:** AVX2 (detected at run time: [`super::Avx2`]). **Stack:** a few vectors of constants.

use core::arch::x86_64::*;

use super::lanes::{finish8, load8, load_n, pack32, rdbpot8, store8, Rq8};
use super::Avx2;
use crate::nn::eltwise::{AddQuant, ConcatInput};
use crate::nn::quant::{clamp_range, fits_simd_requant, ADD_LEFT_SHIFT};
use crate::nn::{Requant, Shape};

/// `Add` on operands [`crate::nn::eltwise::add_fast`] has checked. `false`, with nothing
/// written, on a CPU without AVX2, when an input requantiser shifts left or the sums could
/// leave the range of the vector requantisation ([`fits_simd_requant`]).
pub(crate) fn add(a: &[i8], b: &[i8], shape: Shape, q: &AddQuant, out: &mut [i8]) -> bool {
    let Some(avx2) = Avx2::get() else {
        return false;
    };
    let x = 255i64 << ADD_LEFT_SHIFT;
    let left = q.requant1.shift.max(q.requant2.shift).clamp(0, 30);
    if !(q.requant1.shift <= 0
        && q.requant2.shift <= 0
        && fits_simd_requant(x, &[], &[q.requant1, q.requant2])
        && fits_simd_requant(2 * (x << left) + 2, &[], &[q.output]))
    {
        return false;
    }
    let (lo, _) = clamp_range(q.output_zero_point, q.relu);
    let n = shape.len();
    let op = AddOp {
        a: &a[..n],
        b: &b[..n],
        zp: (q.zero_point1, q.zero_point2),
        rq: (q.requant1, q.requant2),
        out_rq: q.output,
        zo: q.output_zero_point,
        lo,
    };
    run_add(&op, &mut out[..n], avx2);
    true
}

/// One input of a channel `Concat` on operands [`crate::nn::eltwise::concat_fast`] has
/// checked, rescaled into channels `c0..` of the output of shape `os`. `false`, with nothing
/// written, on a CPU without AVX2, for an identity rescale (a copy) or a requantiser outside
/// the range of the vector requantisation ([`fits_simd_requant`]).
pub(crate) fn concat_input(i: &ConcatInput<'_>, c0: usize, os: Shape, out: &mut [i8]) -> bool {
    let Some(avx2) = Avx2::get() else {
        return false;
    };
    if i.rescale.is_identity() || !fits_simd_requant(255, &[], &[i.rescale.requant]) {
        return false;
    }
    let op = RescaleOp {
        x: &i.data[..i.shape.len()],
        c: i.shape.c,
        stride: os.c,
        zp: i.rescale.input_zero_point,
        zo: i.rescale.output_zero_point,
        requant: i.rescale.requant,
    };
    run_rescale(&op, os.h * os.w, &mut out[c0..os.len()], avx2);
    true
}

/// One quantised `Add` over `n` elements (operands checked by the caller).
struct AddOp<'a> {
    /// First input.
    a: &'a [i8],
    /// Second input.
    b: &'a [i8],
    /// Zero points of the inputs.
    zp: (i32, i32),
    /// Requantisers of the inputs (to the common `2^20` domain).
    rq: (Requant, Requant),
    /// Output requantiser.
    out_rq: Requant,
    /// Output zero point.
    zo: i32,
    /// Lower clamp.
    lo: i32,
}

/// TFLite's quantised add, 8 lanes at a time: `clamp(zo + Mo(M1((a − za) << 20) + M2((b − zb)
/// << 20)))`. `out.len()` elements. The input requantisers must have no left shift (scales
/// `≤ 1/2`, which TFLite's construction guarantees).
fn run_add(op: &AddOp<'_>, out: &mut [i8], _avx2: Avx2) {
    assert!(
        op.a.len() >= out.len()
            && op.b.len() >= out.len()
            && op.rq.0.shift <= 0
            && op.rq.1.shift <= 0,
        "add operands checked"
    );
    // SAFETY: AVX2 detected at run time (the `Avx2` token); ranges asserted above
    unsafe { add_avx2(op, out) }
}

/// # Safety
/// Ranges as asserted by [`run_add`].
#[target_feature(enable = "avx2")]
unsafe fn add_avx2(op: &AddOp<'_>, out: &mut [i8]) {
    let n = out.len();
    let (r1, r2, ro) = (Rq8::splat(op.rq.0), Rq8::splat(op.rq.1), Rq8::splat(op.out_rq));
    // SRDHM(d·2^20, M) for |d| ≤ 255 in 32 bits: with M = Mh·2^11 + Ml it is
    // floor((d·M + 2^10) / 2^11) = d·Mh + ((d·Ml + 2^10) >> 11), both products below 2^29
    let split = |m: i32| (_mm256_set1_epi32(m >> 11), _mm256_set1_epi32(m & 0x7ff));
    let (m1h, m1l) = split(op.rq.0.multiplier);
    let (m2h, m2l) = split(op.rq.1.multiplier);
    let r1024 = _mm256_set1_epi32(1 << 10);
    let srdhm20 = |d: __m256i, mh: __m256i, ml: __m256i| {
        let lo = _mm256_srai_epi32::<11>(_mm256_add_epi32(_mm256_mullo_epi32(d, ml), r1024));
        _mm256_add_epi32(_mm256_mullo_epi32(d, mh), lo)
    };
    let (z1, z2) = (_mm256_set1_epi32(op.zp.0), _mm256_set1_epi32(op.zp.1));
    let zo = _mm256_set1_epi32(op.zo);
    let lo = _mm256_set1_epi32(op.lo);
    let (pa, pb, po) = (op.a.as_ptr(), op.b.as_ptr(), out.as_mut_ptr());
    let value = |va: __m256i, vb: __m256i| {
        let xa = rdbpot8(srdhm20(_mm256_sub_epi32(va, z1), m1h, m1l), &r1);
        let xb = rdbpot8(srdhm20(_mm256_sub_epi32(vb, z2), m2h, m2l), &r2);
        finish8(_mm256_add_epi32(xa, xb), &ro, zo, lo)
    };
    let mut i = 0;
    while i + 32 <= n {
        // SAFETY: i + 32 ≤ n elements in all three
        let v = |j: usize| unsafe { value(load8(pa.add(i + j)), load8(pb.add(i + j))) };
        let packed = pack32(v(0), v(8), v(16), v(24));
        unsafe { _mm256_storeu_si256(po.add(i) as *mut __m256i, packed) };
        i += 32;
    }
    while i < n {
        let m = (n - i).min(8);
        // SAFETY: i + m ≤ n elements in all three
        let (va, vb) = unsafe { (load_n(pa.add(i), m), load_n(pb.add(i), m)) };
        unsafe { store8(po.add(i), value(va, vb), m) };
        i += 8;
    }
}

/// `out[p·stride + j] = clamp(zo + M(x[p·c + j] − zp))` for `j < c`, every pixel `p`: one
/// input of a channel `Concat` rescaled into its slot of the output.
struct RescaleOp<'a> {
    /// The input, `pixels × c`.
    x: &'a [i8],
    /// Its channels.
    c: usize,
    /// Output channels (row stride).
    stride: usize,
    /// Input zero point.
    zp: i32,
    /// Output zero point.
    zo: i32,
    /// `s_in / s_out`.
    requant: Requant,
}

/// [`RescaleOp`], AVX2. `out` starts at the input's first output channel.
fn run_rescale(op: &RescaleOp<'_>, pixels: usize, out: &mut [i8], _avx2: Avx2) {
    assert!(
        op.x.len() >= pixels * op.c
            && (pixels == 0 || out.len() >= (pixels - 1) * op.stride + op.c),
        "rescale operands checked"
    );
    // SAFETY: AVX2 detected at run time (the `Avx2` token); ranges asserted above
    unsafe { rescale_avx2(op, pixels, out) }
}

/// # Safety
/// Ranges as asserted by [`run_rescale`].
#[target_feature(enable = "avx2")]
unsafe fn rescale_avx2(op: &RescaleOp<'_>, pixels: usize, out: &mut [i8]) {
    let rq = Rq8::splat(op.requant);
    let zp = _mm256_set1_epi32(op.zp);
    let zo = _mm256_set1_epi32(op.zo);
    let lo = _mm256_set1_epi32(-128);
    let (px, po) = (op.x.as_ptr(), out.as_mut_ptr());
    for p in 0..pixels {
        let mut ch = 0;
        while ch < op.c {
            let m = (op.c - ch).min(8);
            // SAFETY: m bytes of pixel p, channel ch, in the input and the output slot
            let v = unsafe { load_n(px.add(p * op.c + ch), m) };
            let v = finish8(_mm256_sub_epi32(v, zp), &rq, zo, lo);
            unsafe { store8(po.add(p * op.stride + ch), v, m) };
            ch += 8;
        }
    }
}
