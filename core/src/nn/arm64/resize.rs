//! # arm64 resize: bilinear `Resize` (`half_pixel`) in NEON
//!
//! ONNX `Resize`, `mode = linear`, `coordinate_transformation_mode = half_pixel`, static sizes:
//! the fixed-point blend of [`crate::nn::resize`], the integers of
//! [`crate::nn::resize::resize_bilinear_reference`]:
//! `(2^11 − wy)·((2^11 − wx)·a + wx·b) + wy·((2^11 − wx)·c + wx·d)` over `x − zp`, exact in
//! `i32`, then one requantisation.
//!
//! Separable, as `x86::resize`: the output row is cut into chunks of whole pixels (at most
//! [`CHUNK`] values). Per chunk and pair of source rows `(y0, y1)`, each source row is blended
//! in x once, `h = (a − zp)·2^11 + wx·(b − a)` (= `(2^11 − wx)·a + wx·b`; `ssubl`, `sshll`,
//! `smlal` by the `i16` weight, 8 channels at a time), staged as `s = h0·2^11` and
//! `d = h1 − h0`. Every output row of that pair is then `s + wy·d` (= `(2^11 − wy)·h0 +
//! wy·h1`, the reference's integer; one `mla` per 4 values) over the chunk as one flat run,
//! requantised 8 at a time in registers ([`super::lanes::Rq8Regs`]): no lanes lost to channel
//! counts like 11, and the x blend is done once per source row and chunk instead of twice per
//! output pixel. `|s| < 2^30` and the sum is the reference's integer (`< 2^30`); an
//! intermediate `wy·d` up to `510·2^22 < 2^31` does not wrap either.
//!
//! A pixel's last group of 8 channels is blended from 8-byte loads (the next pixel's bytes, or
//! the zero point past the input's end) and stored whole: the lanes past its channels are
//! overwritten by the next pixel or fall in the staging's 8 values of slack.
//!
//! **Stack:** the staged chunk (2 × 520 `i32`s) and the x taps of its pixels (≤ 64): 4.8 KiB.
//! Inputs with more than [`CHUNK`] channels are left to the portable kernel.

use super::mem::{ld1_s8, ld1q_s32, st1_s8, st1q_s32};
use core::arch::aarch64::*;

use super::lanes::{store8, Rq8, Rq8Regs};
use crate::nn::quant::Lane1;
use crate::nn::resize::{half_pixel_taps, ResizeQuant, RESIZE_FRAC_BITS};
use crate::nn::Shape;

/// Values of an output row staged at once (whole pixels), and the most channels this kernel
/// takes.
const CHUNK: usize = 512;
/// The staging's slack: a pixel's last group of 8 channels is blended and stored whole.
const SLACK: usize = 8;
/// Most output pixels of a chunk (their x taps are made once per chunk: each costs two
/// divisions).
const BAND: usize = 64;

/// The resize on operands [`crate::nn::resize::resize_bilinear_fast`] has checked (`os` the
/// output shape); `false` (nothing written) when the vector requantisation does not hold, the
/// input has more than [`CHUNK`] channels or a row of more than `u32::MAX` bytes.
pub(crate) fn resize_bilinear(
    x: &[i8],
    xs: Shape,
    q: &ResizeQuant,
    out: &mut [i8],
    os: Shape,
) -> bool {
    // a blend is at most 2^22 · 255 in magnitude
    if xs.c > CHUNK
        || u32::try_from(xs.w * xs.c).is_err()
        || !Lane1::fits(q.requant, 255 << (2 * RESIZE_FRAC_BITS))
    {
        return false;
    }
    // SAFETY: this module is compiled only where `neon` is a target feature of the build.
    unsafe { run(x, xs, q, out, os) };
    true
}

/// [`resize_bilinear`] after its check.
#[target_feature(enable = "neon")]
fn run(x: &[i8], xs: Shape, q: &ResizeQuant, out: &mut [i8], os: Shape) {
    let c = xs.c;
    let rq = Rq8::new(&[q.requant; 8]).regs(q.output_zero_point, -128, 127);
    let x = &x[..xs.len()];
    let in_row = xs.w * c;
    let out_row = os.w * c;
    let out = &mut out[..os.len()];
    let mut st = Staged { s: [0; CHUNK + SLACK], d: [0; CHUNK + SLACK] };
    // (x0·c, x1·c, wx) of the chunk's pixels
    let mut taps = [(0u32, 0u32, 0i16); BAND];
    let px_per_chunk = (CHUNK / c).min(BAND);
    let mut p0 = 0;
    while p0 < os.w {
        let np = (os.w - p0).min(px_per_chunk);
        let len = np * c;
        for (i, t) in taps[..np].iter_mut().enumerate() {
            let (x0, x1, wx) = half_pixel_taps(p0 + i, xs.w, os.w);
            // wx ≤ 2^11: an `i16`
            *t = ((x0 * c) as u32, (x1 * c) as u32, wx as i16);
        }
        let mut pair = (usize::MAX, usize::MAX);
        for oy in 0..os.h {
            let (y0, y1, wy) = half_pixel_taps(oy, xs.h, os.h);
            if (y0, y1) != pair {
                pair = (y0, y1);
                st.blend_x(x, (y0 * in_row, y1 * in_row), c, q.input_zero_point as i8, &taps[..np]);
            }
            st.blend_y(wy, &rq, &mut out[oy * out_row + p0 * c..][..len]);
        }
        p0 += np;
    }
}

/// One chunk of an output row, blended in x from a pair of source rows: the output row of
/// vertical weight `wy` is `s + wy·d`.
struct Staged {
    /// `h0·2^11`.
    s: [i32; CHUNK + SLACK],
    /// `h1 − h0`.
    d: [i32; CHUNK + SLACK],
}

impl Staged {
    /// Blends the source rows at offsets `r = (r0, r1)` of `x` in x at the chunk's pixel taps
    /// (`c` channels, input zero point `zp`; `taps.len() · c ≤ CHUNK`).
    #[target_feature(enable = "neon")]
    fn blend_x(&mut self, x: &[i8], r: (usize, usize), c: usize, zp: i8, taps: &[(u32, u32, i16)]) {
        debug_assert!(taps.len() * c <= CHUNK && r.0 <= r.1);
        let zp8 = vdup_n_s8(zp);
        // `x − zp` of 8 bytes
        let sub = |v: &[i8; 8]| {
            // SAFETY: 8 bytes.
            vsubl_s8(unsafe { ld1_s8(v.as_ptr()) }, zp8)
        };
        // the same where the 8 bytes at `off` may pass the input's end (read as the zero point)
        let sub_checked = |off: usize| {
            let mut t = [zp; 8];
            if let Some(v) = x.get(off..) {
                let n = v.len().min(8);
                t[..n].copy_from_slice(&v[..n]);
            }
            sub(&t)
        };
        // every load of the pair inside the input (`x0 ≤ x1`, `r.0 ≤ r.1`)
        let x1_max = taps.iter().map(|t| t.1 as usize).max().unwrap_or(0);
        let fast = r.1 + x1_max + c.next_multiple_of(8) <= x.len();
        for (i, &(x0, x1, wx)) in taps.iter().enumerate() {
            let (x0, x1) = (x0 as usize, x1 as usize);
            let mut ch = 0;
            while ch < c {
                // the x blend of 8 channels of the source row at `r`, low and high 4 lanes
                let h = |r: usize| {
                    let (a, b) = if fast {
                        // SAFETY: `r + x0 + ch + 8 ≤ r + x1 + ch + 8 ≤ r.1 + x1_max +
                        // ceil8(c) ≤ x.len()` (checked in `fast`): 8 bytes of `x` each.
                        let at = |o: usize| unsafe { &*x.as_ptr().add(o).cast::<[i8; 8]>() };
                        (sub(at(r + x0 + ch)), sub(at(r + x1 + ch)))
                    } else {
                        (sub_checked(r + x0 + ch), sub_checked(r + x1 + ch))
                    };
                    let db = vsubq_s16(b, a);
                    [
                        vmlal_n_s16(vshll_n_s16::<11>(vget_low_s16(a)), vget_low_s16(db), wx),
                        vmlal_high_n_s16(vshll_high_n_s16::<11>(a), db, wx),
                    ]
                };
                let h0 = h(r.0);
                let h1 = if r.1 == r.0 { h0 } else { h(r.1) };
                let at = i * c + ch;
                assert!(at + 8 <= CHUNK + SLACK);
                // SAFETY: 8 `i32`s of `s` and of `d` (asserted).
                unsafe {
                    for k in 0..2 {
                        st1q_s32(self.s.as_mut_ptr().add(at + 4 * k), vshlq_n_s32::<11>(h0[k]));
                        st1q_s32(self.d.as_mut_ptr().add(at + 4 * k), vsubq_s32(h1[k], h0[k]));
                    }
                }
                ch += 8;
            }
        }
    }

    /// The output values `dst` (`dst.len() ≤ CHUNK`) of the row of vertical weight `wy`:
    /// `requant(s + wy·d)`, 8 at a time. Out of line, so that the requantiser's registers are
    /// loaded once per row and stay in registers.
    #[target_feature(enable = "neon")]
    #[inline(never)]
    fn blend_y(&self, wy: i32, rq: &Rq8Regs, dst: &mut [i8]) {
        let rq = *rq;
        let len = dst.len().min(CHUNK);
        let mut i = 0;
        while i < len {
            // SAFETY: `i + 8 ≤ len + SLACK ≤ CHUNK + SLACK`: inside `s` and `d`.
            let v = unsafe {
                let (sp, dp) = (self.s.as_ptr().add(i), self.d.as_ptr().add(i));
                rq.requant([
                    vmlaq_n_s32(ld1q_s32(sp), ld1q_s32(dp), wy),
                    vmlaq_n_s32(ld1q_s32(sp.add(4)), ld1q_s32(dp.add(4)), wy),
                ])
            };
            match dst.get_mut(i..i + 8) {
                // SAFETY: 8 bytes of the output.
                Some(o) => unsafe { st1_s8(o.as_mut_ptr(), v) },
                None => store8(&mut dst[i..], v),
            }
            i += 8;
        }
    }
}
