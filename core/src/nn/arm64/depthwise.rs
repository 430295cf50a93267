//! # arm64 depthwise: the depthwise 3×3 `Conv` in NEON
//!
//! ONNX `Conv` with `group = C`, a 3×3 kernel, pad 1, stride 1 or 2, weights `[3][3][C]` — the
//! integers of [`crate::nn::conv::depthwise3x3_reference`].
//!
//! 8 channels per vector, per output row and group of 8 channels:
//! - **Runs** (`pair_run`): the pixels whose windows are inside the input in x, in every row,
//!   a full group, when no weight is −128 (symmetric int8 weights, as `models/quantise.py`
//!   makes). The sums start at `b − zp·Σw`, and each tap adds `x·w` of the raw bytes: two taps'
//!   products in `i16` (`smull`, `smlal`: `|x·w + x'·w'| ≤ 2·128·127 < 2^15`), widened into
//!   the sums (`saddw`, `saddw2`), since `Σ (x − zp)·w = Σ x·w − zp·Σw`. The taps of a top or
//!   bottom border row read as the zero point, adding `(zp − zp)·w = 0` as the reference
//!   leaves them out; which rows is a constant of the run (`pair_run::<KY0, KY1>`). A run is
//!   out of line, with the 9 weight vectors and the requantiser in registers over it:
//!   about 50 instructions per pixel and group.
//! - **The other pixels** (the first and last columns, a short last group, and every pixel of
//!   a layer with a −128 weight): each valid tap adds `(x − zp)·w` (`ssubl`, two `smlal`) to
//!   sums that start at the biases. Windows inside the input take the 9 taps unrolled, their
//!   loads unchecked after one range check; others take only their valid taps through checked
//!   loads, a short group's missing lanes reading as the zero point (weight 0), and store only
//!   their channels.
//!
//! The 8 sums are requantised in registers ([`super::lanes::Rq8Regs`]).
//!
//! **Stack:** the lane-form requantisers of up to 256 channels (4 KiB; wider layers make the
//! others per row).

use super::mem::{ld1_s8, ld1q_s32, st1_s8};
use core::arch::aarch64::*;

use super::lanes::{block8, load8, store8, Rq8, Rq8Regs, Rq8Table, TABLE};
use crate::nn::conv::ConvQuant;
use crate::nn::portable::conv::tap_range;
use crate::nn::quant::{clamp_range, fits_simd_requant};
use crate::nn::Shape;

/// The depthwise 3×3 conv on operands [`crate::nn::conv::depthwise3x3_fast`] has checked (`os`
/// the output shape); `false` (nothing written) when the vector requantisation does not hold.
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
) -> bool {
    if !fits_simd_requant(9 * 255 * 128, b, q.requant) {
        return false;
    }
    // SAFETY: this module is compiled only where `neon` is a target feature of the build.
    unsafe { run(x, xs, stride, w, b, q, out, os) };
    true
}

/// [`depthwise3x3`] after its check.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "neon")]
fn run(
    x: &[i8],
    xs: Shape,
    stride: usize,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    os: Shape,
) {
    let (lo, hi) = clamp_range(q.output_zero_point, q.relu);
    let c = xs.c;
    let zp = q.input_zero_point as i8;
    let zp8 = vdup_n_s8(zp);
    let x = &x[..xs.len()];
    let w = &w[..9 * c];
    let row = xs.w * c;
    let mut table = [Rq8::ZERO; TABLE];
    let rqs = Rq8Table::new(&mut table, q.requant);
    // the runs add two taps' products in `i16`, exact unless a weight is −128
    let pairs = !w.contains(&i8::MIN);
    // output columns whose windows are inside the input in x: `ox·stride ≥ 1` and
    // `ox·stride + 1 ≤ xs.w − 1`
    let xa = 1.min(os.w);
    let xb = if xs.w >= 2 { ((xs.w - 2) / stride + 1).min(os.w) } else { 0 };
    for (oy, orow) in out[..os.len()].chunks_exact_mut(os.w * c).enumerate() {
        let (ky0, ky1) = tap_range(oy, stride, 1, 3, xs.h);
        for g in 0..c.div_ceil(8) {
            let c0 = 8 * g;
            let nb = (c - c0).min(8);
            let rq = rqs.block(g).regs(q.output_zero_point, lo, hi);
            let bias = block8(b, c0);
            // SAFETY: 8 `i32`s.
            let b0 = unsafe { [ld1q_s32(bias.as_ptr()), ld1q_s32(bias.as_ptr().add(4))] };
            let mut w8 = [vdup_n_s8(0); 9];
            for (t, v) in w8.iter_mut().enumerate() {
                *v = load8(&w[t * c + c0..t * c + c0 + nb], 0);
            }
            let wv = w8.map(|v| vmovl_s8(v));
            // the runs' sums start at `b − zp·Σw` (`Σ (x − zp)·w = Σ x·w − zp·Σw`)
            let sw = wv.iter().fold(vdupq_n_s16(0), |a, &v| vaddq_s16(a, v));
            let bc = [
                vmlsl_n_s16(b0[0], vget_low_s16(sw), zp.into()),
                vmlsl_high_n_s16(b0[1], sw, zp.into()),
            ];
            // `(x − zp)·wt` of the 8 bytes at `x[xo..]` added to `a`
            macro_rules! mac {
                ($a:expr, $xv:expr, $wt:expr) => {{
                    let xv = vsubl_s8($xv, zp8);
                    $a[0] = vmlal_s16($a[0], vget_low_s16(xv), vget_low_s16($wt));
                    $a[1] = vmlal_high_s16($a[1], xv, $wt);
                }};
            }
            // the interior run of this row: windows inside the input, a full group, products
            // in pairs (`pair_run`); the other pixels below
            // the window rows inside the input: all 3, a top or bottom border row, or a one-row
            // map (pad 1 leaves no other case)
            let rows = matches!((ky0, ky1), (0, 3) | (1, 3) | (0, 2) | (1, 2));
            let (ra, rb) = if nb == 8 && pairs && xa < xb && rows {
                // from the window's first row inside the input (`ky0`)
                let base = ((oy * stride + ky0 - 1) * xs.w + xa * stride - 1) * c + c0;
                let g = PairRun { row, c, step: stride * c, n: xb - xa, zp };
                let (xr, or) = (&x[base..], &mut orow[xa * c + c0..]);
                // the rows as constants: no per-tap test in the run
                match (ky0, ky1) {
                    (0, 3) => pair_run::<0, 3>(xr, g, &w8, bc, &rq, or),
                    (1, 3) => pair_run::<1, 3>(xr, g, &w8, bc, &rq, or),
                    (0, 2) => pair_run::<0, 2>(xr, g, &w8, bc, &rq, or),
                    _ => pair_run::<1, 2>(xr, g, &w8, bc, &rq, or),
                }
                (xa, xb)
            } else {
                (0, 0)
            };
            for (ox, opix) in orow.chunks_exact_mut(c).enumerate() {
                if (ra..rb).contains(&ox) {
                    continue;
                }
                let (kx0, kx1) = tap_range(ox, stride, 1, 3, xs.w);
                let mut a = b0;
                // the window's top-left byte of this group, when the window is inside the input
                let base = (ky1 - ky0 == 3 && kx1 - kx0 == 3)
                    .then(|| ((oy * stride - 1) * xs.w + ox * stride - 1) * c + c0);
                match base {
                    // interior, full group: 9 unrolled taps (weights in registers) from one
                    // range check
                    Some(base) if nb == 8 && base + 2 * row + 2 * c + 8 <= x.len() => {
                        let p = x[base..].as_ptr();
                        #[allow(clippy::needless_range_loop)]
                        for t in 0..9 {
                            // SAFETY: `t / 3 · row + t % 3 · c + 8 ≤ 2·row + 2·c + 8`, inside
                            // `x` by the check above.
                            let xv = unsafe { ld1_s8(p.add(t / 3 * row + t % 3 * c)) };
                            mac!(a, xv, wv[t]);
                        }
                    }
                    _ => {
                        for ky in ky0..ky1 {
                            let iy = oy * stride + ky - 1;
                            for kx in kx0..kx1 {
                                let xo = (iy * xs.w + ox * stride + kx - 1) * c + c0;
                                let wo = (ky * 3 + kx) * c + c0;
                                let wt = vmovl_s8(load8(&w[wo..wo + nb], 0));
                                mac!(a, load8(&x[xo..xo + nb], zp), wt);
                            }
                        }
                    }
                }
                store8(&mut opix[c0..c0 + nb], rq.requant(a));
            }
        }
    }
}

/// The geometry of a run of windows inside the input in x: `n` windows `step` bytes apart, each
/// 3 rows `row` bytes apart of 3 pixels `c` bytes apart; outputs `c` bytes apart.
struct PairRun {
    row: usize,
    c: usize,
    step: usize,
    n: usize,
    /// The input zero point.
    zp: i8,
}

/// `n` outputs of one group of 8 channels whose windows are inside the input in x and in rows
/// `KY0..KY1`: per window `requant(bc + Σ x·w)`, the sums starting at
/// `bc = b − zp·Σw` (`Σ (x − zp)·w = Σ x·w − zp·Σw`). The taps of the other rows (a top or
/// bottom border row) read as the zero point, which adds `(zp − zp)·w = 0`, as the reference
/// leaves them out. `x` starts at the first window's top-left byte of the group in row `KY0`,
/// `out` at the first output's. Out of line, so that the weights and the requantiser stay in
/// registers over the run.
#[target_feature(enable = "neon")]
#[inline(never)]
fn pair_run<const KY0: usize, const KY1: usize>(
    x: &[i8],
    g: PairRun,
    w8: &[int8x8_t; 9],
    bc: [int32x4_t; 2],
    rq: &Rq8Regs,
    out: &mut [i8],
) {
    const { assert!(KY0 < KY1 && KY1 <= 3) };
    let PairRun { row, c, step, n, zp } = g;
    if n == 0 {
        return;
    }
    // every window's loads (the last one's end is the furthest) and every 8-byte store inside
    assert!(
        (n - 1) * step + (KY1 - 1 - KY0) * row + 2 * c + 8 <= x.len()
            && (n - 1) * c + 8 <= out.len(),
        "window run outside its operands"
    );
    let (w8, rq) = (*w8, *rq);
    let zp8 = vdup_n_s8(zp);
    // tap `t`'s offset in a window, for the rows inside the input
    let offs: [usize; 9] = core::array::from_fn(|t| (t / 3).saturating_sub(KY0) * row + t % 3 * c);
    for i in 0..n {
        // SAFETY: `i·step + offs[t] + 8 ≤ (n − 1)·step + (KY1 − 1 − KY0)·row + 2·c + 8 ≤
        // x.len()` for the taps of rows `KY0..KY1` (asserted).
        let p = unsafe { x.as_ptr().add(i * step) };
        let ld = |t: usize| {
            if (KY0..KY1).contains(&(t / 3)) {
                // SAFETY: as above.
                unsafe { ld1_s8(p.add(offs[t])) }
            } else {
                zp8
            }
        };
        // two taps' products in `i16` (no weight is −128), widened into the sums
        let mut a = bc;
        for t in [0, 2, 4, 6] {
            let s = vmlal_s8(vmull_s8(ld(t), w8[t]), ld(t + 1), w8[t + 1]);
            a = [vaddw_s16(a[0], vget_low_s16(s)), vaddw_high_s16(a[1], s)];
        }
        let s = vmull_s8(ld(8), w8[8]);
        a = [vaddw_s16(a[0], vget_low_s16(s)), vaddw_high_s16(a[1], s)];
        // SAFETY: `i·c + 8 ≤ (n − 1)·c + 8 ≤ out.len()` (asserted).
        unsafe { st1_s8(out.as_mut_ptr().add(i * c), rq.requant(a)) };
    }
}
