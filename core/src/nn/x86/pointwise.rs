//! # x86 pointwise: the 1×1 `Conv` as an int8 GEMM, AVX2 and AVX-512 VNNI
//!
//! ONNX `Conv` with a 1×1 kernel, stride 1, no padding, `group = 1`:
//! `out[p][c] = clamp(zo + requant[c](bias[c] + Σ_k (x[p][k] − zp)·w[c][k]))` — the integers of
//! [`crate::nn::conv::pointwise_reference`].
//!
//! Weights come packed from the model blob (see [`crate::nn::conv::pack_pointwise`]): blocks
//! of 8 output channels, `c_in` in groups of 4, 32 bytes per (block, group) — one `ymm`. Per
//! block of output channels (outer loop, its weights stay in L1) the kernel walks the pixels in
//! tiles; per pixel it broadcasts 4 input bytes.
//! - VNNI: `vpdpbusd` wants unsigned × signed bytes, so the input goes in as `x ^ 0x80 = x + 128`
//!   (u8) and the kernel starts the accumulator at `bias − (zp + 128)·Σw`: the sum ends at
//!   exactly `bias + Σ (x − zp)·w`. Tiles of 8 pixels × 24 channels (24 accumulators of 32).
//! - AVX2: the 4 bytes are sign-extended to `i16` and multiplied with `vpmaddwd` against the
//!   sign-extended weights (pairs of products per lane, the two halves of a channel's sum in
//!   adjacent lanes, added by one `vphaddd` at the end); start `bias − zp·Σw`. Tiles of 6
//!   pixels × 8 channels. The sums stay in `vphaddd`'s lane order (the block's bias and
//!   requantisers are permuted to it once), and pixels are packed and stored two at a time.
//!
//! **ISA:** AVX2 (detected at run time: [`super::Avx2`]); AVX-512 F/BW/VL + VNNI for the VNNI form
//! (probed at run time, [`super::vnni_available`]). **Stack:** the AVX2 form a 12 KiB staged `i16`
//! input tile and 7 KiB of per-block constants, the VNNI form an 8 KiB staged `u8` tile; rows wider
//! than 1024 channels are read in place instead.

use core::arch::x86_64::*;

use super::lanes::{finish8, store8, store8_avx512, Rq8};
use super::{vnni_available, Avx2};
use crate::nn::conv::ConvQuant;
use crate::nn::quant::{clamp_range, fits_simd_requant};
use crate::nn::{Requant, Shape};

/// The 1×1 conv on operands [`crate::nn::conv::pointwise_fast`] has checked: VNNI when `vnni`
/// (and the CPU has it), else AVX2. `false`, with nothing written, on a CPU without AVX2 or when
/// the accumulators could leave the range of the vector requantisation ([`fits_simd_requant`]).
pub(crate) fn pointwise(
    x: &[i8],
    xs: Shape,
    w: &[i8],
    b: &[i32],
    q: &ConvQuant<'_>,
    out: &mut [i8],
    vnni: bool,
) -> bool {
    let Some(avx2) = Avx2::get() else {
        return false;
    };
    if !fits_simd_requant(xs.c as i64 * 255 * 127, b, q.requant) {
        return false;
    }
    let (lo, _) = clamp_range(q.output_zero_point, q.relu);
    let a = Pw {
        x,
        p: xs.h * xs.w,
        k: xs.c,
        w,
        bias: b,
        requant: q.requant,
        zp: q.input_zero_point,
        zo: q.output_zero_point,
        lo,
    };
    run(&a, out, vnni, avx2);
    true
}

/// Geometry and quantisation of one pointwise call (all checked by the caller).
struct Pw<'a> {
    /// `P × K` input, NHWC rows.
    x: &'a [i8],
    /// Pixels.
    p: usize,
    /// Input channels.
    k: usize,
    /// Packed weights, `ceil(n/8)` panels of `ceil(k/4)·32` bytes.
    w: &'a [i8],
    /// One bias per output channel (`n` of them).
    bias: &'a [i32],
    /// One requantiser per output channel.
    requant: &'a [Requant],
    /// Input zero point.
    zp: i32,
    /// Output zero point.
    zo: i32,
    /// Lower clamp (`-128`, or the output zero point with a fused ReLU).
    lo: i32,
}

/// Four input bytes at `p` as one little-endian `i32`.
///
/// # Safety
/// `p..p + 4` readable.
#[inline(always)]
unsafe fn quad(p: *const i8) -> i32 {
    // SAFETY: by the caller
    unsafe { (p as *const i32).read_unaligned() }
}

/// The last `n < 4` bytes of a row, zero-padded to a quad (its weights are zero).
///
/// # Safety
/// `p..p + n` readable.
#[inline(always)]
unsafe fn tail_quad(p: *const i8, n: usize) -> i32 {
    let mut b = [0u8; 4];
    for (t, v) in b.iter_mut().enumerate().take(n) {
        // SAFETY: t < n
        *v = unsafe { *p.add(t) } as u8;
    }
    i32::from_le_bytes(b)
}

/// `out[p][c] = requant(bias[c] + Σ_k (x[p][k] − zp)·w[c][k])` for all pixels and channels:
/// VNNI when `vnni` and the CPU has it, else AVX2. `out` holds `p × n` bytes, `n = bias.len()`.
fn run(a: &Pw<'_>, out: &mut [i8], vnni: bool, _avx2: Avx2) {
    let n = a.bias.len();
    let panel = a.k.div_ceil(4) * 32;
    assert!(
        a.x.len() >= a.p * a.k
            && a.w.len() >= n.div_ceil(8) * panel
            && a.requant.len() == n
            && out.len() >= a.p * n,
        "pointwise operands checked by the caller"
    );
    if vnni && vnni_available() {
        // SAFETY: VNNI + AVX-512 VL/BW/F probed at run time; ranges asserted above
        unsafe { pw_vnni(a, out) }
    } else {
        // SAFETY: AVX2 detected at run time (the `Avx2` token); ranges asserted above
        unsafe { pw_avx2(a, out) }
    }
}

/// Per output-channel block: `c0 = bias − corr_zp · Σ_k w` (the accumulator's start), the
/// requantisers and the number of real channels.
#[inline]
#[target_feature(enable = "avx2")]
fn block_consts(a: &Pw<'_>, block: usize, wsum: __m256i, corr_zp: i32) -> (__m256i, Rq8, usize) {
    let n = a.bias.len();
    let c = block * 8;
    let nb = (n - c).min(8);
    let mut b = [0i32; 8];
    b[..nb].copy_from_slice(&a.bias[c..c + nb]);
    let bias = _mm256_setr_epi32(b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]);
    let corr = _mm256_mullo_epi32(wsum, _mm256_set1_epi32(corr_zp));
    (_mm256_sub_epi32(bias, corr), Rq8::new(&a.requant[c..c + nb]), nb)
}

// ---- AVX2 ----

/// Pixels per AVX2 tile.
const MR_AVX2: usize = 6;

/// `Σ_k w[c][k]` of one 8-channel panel, AVX2.
///
/// # Safety
/// `w..w + kq·32` readable.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn wsum_avx2(w: *const i8, kq: usize) -> __m256i {
    let ones = _mm256_set1_epi16(1);
    let (mut lo, mut hi) = (_mm256_setzero_si256(), _mm256_setzero_si256());
    for q in 0..kq {
        // SAFETY: q < kq
        let (wl, wh) = unsafe { weights_i16(w.add(q * 32)) };
        lo = _mm256_add_epi32(lo, _mm256_madd_epi16(wl, ones));
        hi = _mm256_add_epi32(hi, _mm256_madd_epi16(wh, ones));
    }
    _mm256_permute4x64_epi64::<0xd8>(_mm256_hadd_epi32(lo, hi))
}

/// The 32 bytes of one (block, group) as `i16`: channels 0–3 and 4–7, four `k` each.
///
/// # Safety
/// `w..w + 32` readable.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn weights_i16(w: *const i8) -> (__m256i, __m256i) {
    // SAFETY: by the caller
    unsafe {
        (
            _mm256_cvtepi8_epi16(_mm_loadu_si128(w as *const __m128i)),
            _mm256_cvtepi8_epi16(_mm_loadu_si128(w.add(16) as *const __m128i)),
        )
    }
}

/// Output-channel blocks the AVX2 kernel keeps constants for at once (7 KiB).
const AVX2_BLOCKS: usize = 32;
/// `i16`s of the AVX2 kernel's staged input tile (6 rows of up to 1024 channels, 12 KiB).
const STAGE_AVX2: usize = MR_AVX2 * 1024;

/// # Safety
/// Ranges as asserted by [`pointwise`].
#[target_feature(enable = "avx2")]
unsafe fn pw_avx2(a: &Pw<'_>, out: &mut [i8]) {
    let n = a.bias.len();
    let kq = a.k.div_ceil(4);
    let kpad = kq * 4;
    let panel = kq * 32;
    if kpad * MR_AVX2 > STAGE_AVX2 {
        // SAFETY: as for this function
        return unsafe { pw_avx2_direct(a, out) };
    }
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(a.lo);
    let blocks = n.div_ceil(8);
    let mut c0 = [_mm256_setzero_si256(); AVX2_BLOCKS];
    let mut rq = [Rq8::splat(Requant { multiplier: 0, shift: 0 }); AVX2_BLOCKS];
    let mut nb = [0usize; AVX2_BLOCKS];
    // the tile's rows as i16 with the zero point subtracted (so no correction term), each
    // padded with zeros to whole groups
    let mut stage = [0i16; STAGE_AVX2];
    let mut b0 = 0;
    while b0 < blocks {
        let nbk = (blocks - b0).min(AVX2_BLOCKS);
        for j in 0..nbk {
            // in the order the tiles' `vphaddd` leaves the channels in ([`store_pair`])
            let (c, r, n) = block_consts(a, b0 + j, _mm256_setzero_si256(), 0);
            (c0[j], rq[j], nb[j]) = (_mm256_permute4x64_epi64::<0xd8>(c), r.in_hadd_order(), n);
        }
        let mut p0 = 0;
        while p0 < a.p {
            let mr = (a.p - p0).min(MR_AVX2);
            let rows = &a.x[p0 * a.k..(p0 + mr) * a.k];
            for (d, s) in stage.chunks_exact_mut(kpad).zip(rows.chunks_exact(a.k)) {
                for (d, &v) in d.iter_mut().zip(s) {
                    *d = v as i16 - a.zp as i16;
                }
            }
            for j in 0..nbk {
                let block = b0 + j;
                // SAFETY: block < ceil(n/8) panels; rows p0..p0+mr of the output
                let w = unsafe { a.w.as_ptr().add(block * panel) };
                let o = unsafe { out.as_mut_ptr().add(p0 * n + block * 8) };
                let e = (c0[j], &rq[j], zo, lo, nb[j]);
                unsafe {
                    match mr {
                        6 => tile_avx2::<6>(&stage, kpad, w, o, n, e),
                        5 => tile_avx2::<5>(&stage, kpad, w, o, n, e),
                        4 => tile_avx2::<4>(&stage, kpad, w, o, n, e),
                        3 => tile_avx2::<3>(&stage, kpad, w, o, n, e),
                        2 => tile_avx2::<2>(&stage, kpad, w, o, n, e),
                        _ => tile_avx2::<1>(&stage, kpad, w, o, n, e),
                    }
                }
            }
            p0 += mr;
        }
        b0 += nbk;
    }
}

/// One AVX2 tile over the staged rows: `MR` pixels × 8 channels, the accumulators by value.
///
/// # Safety
/// `stage` holds `MR` rows of `kpad` values; `w` a panel of `kpad·8` bytes; `e.4` writable
/// bytes at `o + i·n` for `i < MR`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn tile_avx2<const MR: usize>(
    stage: &[i16],
    kpad: usize,
    w: *const i8,
    o: *mut i8,
    n: usize,
    (c0, rq, zo, lo, nb): (__m256i, &Rq8, __m256i, __m256i, usize),
) {
    let acc = [[_mm256_setzero_si256(); 2]; MR];
    // SAFETY: by the caller
    let acc = unsafe { kloop_avx2::<MR>(acc, stage.as_ptr(), kpad, w) };
    // the channel sums in `vphaddd` order, as `c0` and `rq` are
    let value = |i: usize| {
        finish8(_mm256_add_epi32(_mm256_hadd_epi32(acc[i][0], acc[i][1]), c0), rq, zo, lo)
    };
    let mut i = 0;
    while i + 2 <= MR {
        // SAFETY: by the caller
        unsafe { store_pair(o.add(i * n), o.add((i + 1) * n), value(i), value(i + 1), nb) };
        i += 2;
    }
    if i < MR {
        let v = value(i);
        // SAFETY: by the caller (the pair's second pixel is this one again)
        unsafe { store_pair(o.add(i * n), o.add(i * n), v, v, nb) };
    }
}

/// Two pixels' 8 channels in `vphaddd` order (`[c0 c1 c4 c5 | c2 c3 c6 c7]`, `i32`), saturated
/// to `i8` and stored in channel order: the first `nb` (≤ 8) bytes at `d0` and at `d1`. One
/// pack of both pixels and one 16-bit interleave of its halves put the bytes in order, where
/// a pixel alone in channel order took a lane permute and a pack of its own.
///
/// # Safety
/// `nb` writable bytes at `d0` and at `d1`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn store_pair(d0: *mut i8, d1: *mut i8, a: __m256i, b: __m256i, nb: usize) {
    // per 128-bit lane: a0 a1 a4 a5 b0 b1 b4 b5 | a2 a3 a6 a7 b2 b3 b6 b7
    let w = _mm256_packs_epi32(a, b);
    let y = _mm256_packs_epi16(w, w);
    // 16-bit pairs of the two halves interleaved: a0 .. a7 b0 .. b7
    let r = _mm_unpacklo_epi16(_mm256_castsi256_si128(y), _mm256_extracti128_si256::<1>(y));
    let (lo, hi) = (_mm_cvtsi128_si64(r) as u64, _mm_extract_epi64::<1>(r) as u64);
    if nb >= 8 {
        // SAFETY: by the caller
        unsafe {
            (d0 as *mut u64).write_unaligned(lo);
            (d1 as *mut u64).write_unaligned(hi);
        }
    } else {
        for (t, (&u, &v)) in lo.to_le_bytes().iter().zip(&hi.to_le_bytes()).enumerate().take(nb) {
            // SAFETY: t < nb
            unsafe {
                *d0.add(t) = u as i8;
                *d1.add(t) = v as i8;
            }
        }
    }
}

/// `acc[i] += Σ_k x[i][k]·w[.][k]` over staged `i16` rows: per group of 4, the weights
/// sign-extended once, each pixel's 4 values broadcast (one 64-bit load) into two `vpmaddwd`.
///
/// # Safety
/// As [`tile_avx2`].
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn kloop_avx2<const MR: usize>(
    mut acc: [[__m256i; 2]; MR],
    x: *const i16,
    kpad: usize,
    w: *const i8,
) -> [[__m256i; 2]; MR] {
    for q in 0..kpad / 4 {
        // SAFETY: group q of the panel
        let (wl, wh) = unsafe { weights_i16(w.add(q * 32)) };
        #[allow(clippy::needless_range_loop)]
        for i in 0..MR {
            // SAFETY: 4 values of row i
            let xq = unsafe { (x.add(i * kpad + 4 * q) as *const i64).read_unaligned() };
            let xv = _mm256_set1_epi64x(xq);
            acc[i][0] = _mm256_add_epi32(acc[i][0], _mm256_madd_epi16(xv, wl));
            acc[i][1] = _mm256_add_epi32(acc[i][1], _mm256_madd_epi16(xv, wh));
        }
    }
    acc
}

/// The AVX2 GEMM for rows too wide to stage: inputs sign-extended in registers, the zero point
/// as a correction `− zp·Σw` in the accumulator's start.
///
/// # Safety
/// Ranges as asserted by [`pointwise`].
#[target_feature(enable = "avx2")]
unsafe fn pw_avx2_direct(a: &Pw<'_>, out: &mut [i8]) {
    let n = a.bias.len();
    let kq = a.k.div_ceil(4);
    let panel = kq * 32;
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(a.lo);
    let k = a.k;
    for block in 0..n.div_ceil(8) {
        // SAFETY: block < ceil(n/8), the weights hold that many panels
        let w = unsafe { a.w.as_ptr().add(block * panel) };
        let wsum = unsafe { wsum_avx2(w, kq) };
        let (c0, rq, nb) = block_consts(a, block, wsum, a.zp);
        for p in 0..a.p {
            let x = &a.x[p * k..(p + 1) * k];
            let (mut lo_acc, mut hi_acc) = (_mm256_setzero_si256(), _mm256_setzero_si256());
            for q in 0..kq {
                let mut b = [0u8; 4];
                for (d, &v) in b.iter_mut().zip(&x[4 * q..(4 * q + 4).min(k)]) {
                    *d = v as u8;
                }
                // SAFETY: group q of the panel
                let (wl, wh) = unsafe { weights_i16(w.add(q * 32)) };
                let xv = _mm256_cvtepi8_epi16(_mm_set1_epi32(i32::from_le_bytes(b)));
                lo_acc = _mm256_add_epi32(lo_acc, _mm256_madd_epi16(xv, wl));
                hi_acc = _mm256_add_epi32(hi_acc, _mm256_madd_epi16(xv, wh));
            }
            let s = _mm256_permute4x64_epi64::<0xd8>(_mm256_hadd_epi32(lo_acc, hi_acc));
            let v = finish8(_mm256_add_epi32(s, c0), &rq, zo, lo);
            // SAFETY: nb bytes of pixel p's block
            unsafe { store8(out.as_mut_ptr().add(p * n + block * 8), v, nb) };
        }
    }
}

// ---- AVX-512 VNNI ----

/// A tile's input rows and output position.
struct Tile {
    x: *const i8,
    k: usize,
    out: *mut i8,
    n: usize,
}

/// Pixels per VNNI tile.
const MR_VNNI: usize = 8;
/// Bytes of the VNNI kernel's staged input tile (8 rows of up to 1024 channels): the rows as
/// `u8`, so the inner loop broadcasts straight from memory. Wider rows are read in place and
/// flipped in registers.
const STAGE_VNNI: usize = MR_VNNI * 1024;

/// # Safety
/// VNNI available; ranges as asserted by [`pointwise`].
#[target_feature(enable = "avx2,avx512f,avx512bw,avx512vl,avx512vnni")]
unsafe fn pw_vnni(a: &Pw<'_>, out: &mut [i8]) {
    let n = a.bias.len();
    let kq = a.k.div_ceil(4);
    let panel = kq * 32;
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(a.lo);
    let ones = _mm256_set1_epi8(1);
    let blocks = n.div_ceil(8);
    let kpad = kq * 4;
    // padding bytes meet zero weights: any value will do
    let mut stage = [0x80u8; STAGE_VNNI];
    let mut b = 0;
    while b < blocks {
        // groups of 3 blocks (24 channels); a remainder of 4 as 2 + 2, of 1 alone
        let rem = blocks - b;
        let j = if rem >= 3 && rem != 4 { 3 } else { rem.min(2) };
        let mut c0 = [_mm256_setzero_si256(); 3];
        let mut rq = [Rq8::splat(Requant { multiplier: 0, shift: 0 }); 3];
        let mut nb = [0usize; 3];
        for jj in 0..j {
            // SAFETY: b + jj < blocks panels
            let w = unsafe { a.w.as_ptr().add((b + jj) * panel) };
            let mut s = _mm256_setzero_si256();
            for q in 0..kq {
                let wv = unsafe { _mm256_loadu_si256(w.add(q * 32) as *const __m256i) };
                s = _mm256_dpbusd_epi32(s, ones, wv);
            }
            (c0[jj], rq[jj], nb[jj]) = block_consts(a, b + jj, s, a.zp + 128);
        }
        let w = unsafe { a.w.as_ptr().add(b * panel) };
        let mut p0 = 0;
        while p0 < a.p {
            let mr = (a.p - p0).min(MR_VNNI);
            let out = unsafe { out.as_mut_ptr().add(p0 * n + b * 8) };
            let e = Epi { c0: &c0, rq: &rq, nb: &nb, zo, lo, panel };
            let rows = &a.x[p0 * a.k..(p0 + mr) * a.k];
            let staged = kpad * MR_VNNI <= STAGE_VNNI;
            if staged {
                // the tile's rows as u8 (x ^ 0x80 = x + 128), each padded to whole groups
                for (d, s) in stage.chunks_exact_mut(kpad).zip(rows.chunks_exact(a.k)) {
                    for (d, &v) in d.iter_mut().zip(s) {
                        *d = v as u8 ^ 0x80;
                    }
                }
            }
            let t = if staged {
                Tile { x: stage.as_ptr() as *const i8, k: kpad, out, n }
            } else {
                Tile { x: rows.as_ptr(), k: a.k, out, n }
            };
            macro_rules! go {
                ($($m:literal)*) => {
                    match (mr, j, staged) {
                        $(
                            ($m, 3, true) => unsafe { tile_vnni::<$m, 3, false>(&t, w, &e) },
                            ($m, 2, true) => unsafe { tile_vnni::<$m, 2, false>(&t, w, &e) },
                            ($m, _, true) => unsafe { tile_vnni::<$m, 1, false>(&t, w, &e) },
                            ($m, 3, false) => unsafe { tile_vnni::<$m, 3, true>(&t, w, &e) },
                            ($m, 2, false) => unsafe { tile_vnni::<$m, 2, true>(&t, w, &e) },
                            ($m, _, false) => unsafe { tile_vnni::<$m, 1, true>(&t, w, &e) },
                        )*
                        _ => unreachable!(),
                    }
                };
            }
            go!(8 7 6 5 4 3 2 1);
            p0 += mr;
        }
        b += j;
    }
}

/// The per-block constants of a VNNI tile.
struct Epi<'a> {
    c0: &'a [__m256i; 3],
    rq: &'a [Rq8; 3],
    nb: &'a [usize; 3],
    zo: __m256i,
    lo: __m256i,
    /// Bytes per weight panel.
    panel: usize,
}

/// The reduction of a VNNI tile: `acc[i][j] += Σ_k (x[i][k] + 128)·w[8j..8j+8][k]`, the rows
/// read as `u8` (staged, `FLIP = false`) or as the `i8` tensor flipped in registers. The
/// accumulators go in and out by value so that they live in registers for the whole loop.
///
/// # Safety
/// VNNI available; `MR` rows of `k` bytes at `t.x` (`k` a multiple of 4 unless `FLIP`); `J`
/// panels of `panel` bytes from `w`.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512bw,avx512vl,avx512vnni")]
unsafe fn kloop_vnni<const MR: usize, const J: usize, const FLIP: bool>(
    mut acc: [[__m256i; J]; MR],
    t: &Tile,
    w: *const i8,
    panel: usize,
) -> [[__m256i; J]; MR] {
    let k = t.k;
    let flip = _mm256_set1_epi8(-128);
    let kf = k / 4;
    // one group of 4 input channels: J weight loads, MR broadcasts, MR·J dot products
    macro_rules! step {
        ($q:expr, $xq:expr) => {
            let q = $q;
            let mut wv = [_mm256_setzero_si256(); J];
            #[allow(clippy::needless_range_loop)]
            for j in 0..J {
                // SAFETY: panel j, group q < ceil(k/4)
                wv[j] = unsafe { _mm256_loadu_si256(w.add(j * panel + q * 32) as *const __m256i) };
            }
            #[allow(clippy::needless_range_loop)]
            for i in 0..MR {
                let xv = _mm256_set1_epi32($xq(i, q));
                let xv = if FLIP { _mm256_xor_si256(xv, flip) } else { xv };
                for j in 0..J {
                    acc[i][j] = _mm256_dpbusd_epi32(acc[i][j], xv, wv[j]);
                }
            }
        };
    }
    for q in 0..kf {
        // SAFETY: 4q + 4 ≤ k bytes in each of the MR rows
        step!(q, |i: usize, q: usize| unsafe { quad(t.x.add(i * k + 4 * q)) });
    }
    if !k.is_multiple_of(4) {
        // SAFETY: the row's last k % 4 bytes
        step!(kf, |i: usize, q: usize| unsafe { tail_quad(t.x.add(i * k + 4 * q), k % 4) });
    }
    acc
}

/// # Safety
/// VNNI available; `MR` rows of `k` bytes at `t.x`; `J` panels from `w`; `nb[j]` writable
/// bytes at `t.out + i·n + 8j`.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512bw,avx512vl,avx512vnni")]
unsafe fn tile_vnni<const MR: usize, const J: usize, const FLIP: bool>(
    t: &Tile,
    w: *const i8,
    e: &Epi<'_>,
) {
    let mut acc = [[_mm256_setzero_si256(); J]; MR];
    #[allow(clippy::needless_range_loop)]
    for i in 0..MR {
        for j in 0..J {
            acc[i][j] = e.c0[j];
        }
    }
    // SAFETY: by the caller
    let acc = unsafe { kloop_vnni::<MR, J, FLIP>(acc, t, w, e.panel) };
    #[allow(clippy::needless_range_loop)]
    for i in 0..MR {
        for j in 0..J {
            let v = finish8(acc[i][j], &e.rq[j], e.zo, e.lo);
            // SAFETY: by the caller
            unsafe { store8_avx512(t.out.add(i * t.n + 8 * j), v, e.nb[j]) };
        }
    }
}
