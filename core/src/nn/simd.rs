//! # simd: x86-64 AVX2 and AVX-512 VNNI forms of the int8 kernels
//!
//! The hot loops of [`super::conv`], [`super::eltwise`] and [`super::resize`] written with
//! `core::arch` intrinsics. Compiled only for x86-64 builds with AVX2 enabled at compile time
//! (`-C target-cpu=x86-64-v3`, the workspace's host setting); AVX-512 VNNI (`vpdpbusd`, u8×i8
//! dot products of four) is detected at run time with `cpuid`/`xgetbv` and used by the 1×1
//! GEMM when present. Every function computes the very integers of the reference kernels —
//! the shared op tests run each SIMD path against them (and force the AVX2 path too).
//!
//! **Requantisation, 8 lanes at once.** [`Requant::apply`] needs a 32×32→64-bit product; AVX2
//! has it for the even lanes (`vpmuldq`), so odd lanes are shifted down and multiplied
//! separately. gemmlowp's SRDHM `(p + nudge) / 2^31` truncated, with the sign-dependent nudge,
//! is exactly `floor((p + 2^30) / 2^31)` for every `p` (for `p < 0`: `trunc((p + 1 − 2^30) /
//! 2^31) = ceil(…) = floor((p + 2^30) / 2^31)`), i.e. bits 31..62 of `p + 2^30`: one add and one
//! 64-bit shift per half, no compare. `RoundingDivideByPOT` is the reference's own
//! mask/threshold form with `vpsravd`. Bias adds and left shifts are plain (wrapping) ops, valid
//! under [`super::quant::fits_simd_requant`], which the callers check once per op (else they
//! take the scalar path). Output: `+ zero_point`, `max(lo)` for a fused ReLU, and the signed
//! saturating packs (`vpackssdw`/`vpacksswb`) do the clamp to `[-128, 127]`.
//!
//! **1×1 conv (GEMM).** Weights come packed from the model blob (see
//! [`super::conv::pack_pointwise`]): blocks of 8 output channels, `c_in` in groups of 4, 32
//! bytes per (block, group) — one `ymm`. Per block of output channels (outer loop, its weights
//! stay in L1) the kernel walks the pixels in tiles; per pixel it broadcasts 4 input bytes.
//! - VNNI: `vpdpbusd` wants unsigned × signed bytes, so the input goes in as `x ^ 0x80 = x + 128`
//!   (u8) and the kernel starts the accumulator at `bias − (zp + 128)·Σw`: the sum ends at
//!   exactly `bias + Σ (x − zp)·w`. Tiles of 8 pixels × 24 channels (24 accumulators of 32).
//! - AVX2: the 4 bytes are sign-extended to `i16` and multiplied with `vpmaddwd` against the
//!   sign-extended weights (pairs of products per lane, the two halves of a channel's sum in
//!   adjacent lanes, added by one `vphaddd` at the end); start `bias − zp·Σw`. Tiles of 6
//!   pixels × 8 channels.
//!
//! `unsafe` is allowed in this module only (the workspace denies it elsewhere), for two things:
//! calling `#[target_feature]` functions (sound: AVX2 is a compile-time feature of this build,
//! AVX-512 VNNI is checked at run time before the call) and raw-pointer loads/stores in the
//! inner loops, whose ranges the safe entry points check once. Measured gain over the safe,
//! auto-vectorised portable kernels in the same x86-64-v3 build (`benches/nn.rs`,
//! `SEMLOC_NN_ISA`): the 192×640 graph 6.2 ms (VNNI) / 9.2 ms (AVX2) against ~75 ms, the 1×1
//! GEMM 2.8 / 5.7 ms against 24 ms — far beyond the 20 % that would favour safe code. The
//! portable kernels remain the code of the other targets (and are tested on x86 too).
//!
//! **Other kernels.** Depthwise 3×3: interior pixels sum raw bytes from `bias − zp·Σw`, taps
//! interleaved in pairs into `vpmaddwd`; border pixels `(x − zp)·w` over their valid taps.
//! First conv (one input channel, 3×3): the 9 taps as five `i16` pairs broadcast into
//! `vpmaddwd` per 8 output channels; with stride 2, eight pixels' pairs come from 16-byte row
//! loads. Resize: separable, each source row blended in `x` once per chunk of output columns,
//! each output row one flat run of `s + wy·d` over the chunk (no lanes lost to 11 channels).
//! Add: `SRDHM(d·2^20, M)` in 32 bits as `d·(M >> 11) + ((d·(M & 2047) + 2^10) >> 11)`.
//! [`set_max_isa`] caps the level used (for measurements); results are the same on every level.

#![allow(unsafe_code)]

use core::arch::x86_64::*;
use core::sync::atomic::{AtomicU8, Ordering};

use super::Requant;

// ------------------------------------------------------------------------------------------
// instruction set selection
// ------------------------------------------------------------------------------------------

/// 0: not probed yet, 1: AVX2 only, 2: AVX-512 VNNI usable.
static DETECTED: AtomicU8 = AtomicU8::new(0);
/// The most capable [`Isa`] the kernels may use, as set by [`set_max_isa`] (default: all).
static MAX_ISA: AtomicU8 = AtomicU8::new(Isa::Avx512Vnni as u8);

/// The instruction sets the fast kernels can run on, least capable first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[repr(u8)]
pub enum Isa {
    /// The portable kernels (safe Rust; auto-vectorised for AVX2 by this build).
    Portable = 0,
    /// The AVX2 intrinsics kernels.
    Avx2 = 1,
    /// AVX2, with AVX-512 VNNI for the 1×1 GEMM.
    Avx512Vnni = 2,
}

fn detect_vnni() -> bool {
    // CPUID.1:ECX.OSXSAVE, then XCR0 has SSE, AVX, opmask, ZMM_Hi256, Hi16_ZMM state enabled
    let l1 = __cpuid(1);
    if l1.ecx & (1 << 27) == 0 {
        return false;
    }
    // SAFETY: `xgetbv` exists when the OS has set CR4.OSXSAVE (checked just above); the `xsave`
    // target feature is part of x86-64-v3, which this module is compiled for.
    let xcr0 = unsafe { _xgetbv(0) };
    if xcr0 & 0xe6 != 0xe6 {
        return false;
    }
    let l7 = __cpuid_count(7, 0);
    let f = l7.ebx & (1 << 16) != 0;
    let bw = l7.ebx & (1 << 30) != 0;
    let vl = l7.ebx & (1 << 31) != 0;
    let vnni = l7.ecx & (1 << 11) != 0;
    f && bw && vl && vnni
}

/// True when the CPU (and OS) support AVX-512 VNNI with 256-bit vectors (probed once).
pub fn vnni_available() -> bool {
    match DETECTED.load(Ordering::Relaxed) {
        1 => false,
        2 => true,
        _ => {
            let v = detect_vnni();
            DETECTED.store(if v { 2 } else { 1 }, Ordering::Relaxed);
            v
        }
    }
}

/// Caps the instruction set the fast kernels use (process-wide; default: the best the CPU
/// has). Results are the same integers on every level; this exists to measure (and compare)
/// the portable and AVX2 kernels on a machine that has more.
pub fn set_max_isa(isa: Isa) {
    MAX_ISA.store(isa as u8, Ordering::Relaxed);
}

/// The instruction set the fast kernels use now: the CPU's best, capped by [`set_max_isa`].
pub fn isa() -> Isa {
    let max = MAX_ISA.load(Ordering::Relaxed);
    if max >= Isa::Avx512Vnni as u8 && vnni_available() {
        Isa::Avx512Vnni
    } else if max >= Isa::Avx2 as u8 {
        Isa::Avx2
    } else {
        Isa::Portable
    }
}

fn use_vnni() -> bool {
    isa() == Isa::Avx512Vnni
}

/// Whether the AVX2 kernels may run (not capped to [`Isa::Portable`]).
#[inline]
pub(crate) fn simd_enabled() -> bool {
    MAX_ISA.load(Ordering::Relaxed) != Isa::Portable as u8
}

// ------------------------------------------------------------------------------------------
// requantisation of 8 i32 lanes
// ------------------------------------------------------------------------------------------

/// The requantisers of 8 lanes, in the forms the vector code needs.
#[derive(Clone, Copy)]
pub(crate) struct Rq8 {
    mult: __m256i,
    /// The odd lanes' multipliers moved to the low half of each 64-bit lane (for `vpmuldq`).
    mult_odd: __m256i,
    left: __m256i,
    right: __m256i,
    /// `(1 << right) − 1`.
    mask: __m256i,
    /// `mask >> 1`.
    half: __m256i,
    /// Some lane shifts left (never for the network's convs: their scales are `< 1/2`).
    left_any: bool,
}

impl Rq8 {
    /// From up to 8 requantisers (missing lanes: zero multiplier).
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(crate) fn new(r: &[Requant]) -> Self {
        let mut m = [0i32; 8];
        let mut l = [0i32; 8];
        let mut e = [0i32; 8];
        for (i, q) in r.iter().take(8).enumerate() {
            m[i] = q.multiplier;
            l[i] = q.shift.clamp(0, 30);
            e[i] = (-q.shift).clamp(0, 31);
        }
        Self::from_lanes(m, l, e)
    }

    /// The same requantiser in all 8 lanes.
    #[inline]
    #[target_feature(enable = "avx2")]
    pub(crate) fn splat(q: Requant) -> Self {
        Self::from_lanes([q.multiplier; 8], [q.shift.clamp(0, 30); 8], [(-q.shift).clamp(0, 31); 8])
    }

    #[inline]
    #[target_feature(enable = "avx2")]
    fn from_lanes(m: [i32; 8], l: [i32; 8], e: [i32; 8]) -> Self {
        let mask = e.map(|e| ((1i64 << e) - 1) as i32);
        let v = |a: [i32; 8]| _mm256_setr_epi32(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]);
        let mult = v(m);
        Self {
            mult,
            mult_odd: _mm256_srli_epi64::<32>(mult),
            left: v(l),
            right: v(e),
            mask: v(mask),
            half: v(mask.map(|m| m >> 1)),
            left_any: l.iter().any(|&l| l != 0),
        }
    }
}

/// [`Requant::apply`] on 8 lanes, for `|x| · 2^left ≤ 2^30` (see the module docs).
#[inline]
#[target_feature(enable = "avx2")]
pub(crate) fn requant8(x: __m256i, p: &Rq8) -> __m256i {
    let nudge = _mm256_set1_epi64x(1 << 30);
    let x = if p.left_any { _mm256_sllv_epi32(x, p.left) } else { x };
    let pe = _mm256_add_epi64(_mm256_mul_epi32(x, p.mult), nudge);
    let po = _mm256_add_epi64(_mm256_mul_epi32(_mm256_srli_epi64::<32>(x), p.mult_odd), nudge);
    // bits 31..62 of each product: the even ones to the low, the odd ones to the high half
    let s =
        _mm256_blend_epi32::<0b1010_1010>(_mm256_srli_epi64::<31>(pe), _mm256_slli_epi64::<1>(po));
    rdbpot8(s, p)
}

/// gemmlowp's `RoundingDivideByPOT` by `p.right` on 8 lanes, in the reference's own form:
/// `(s >> e) + (s & mask > (mask >> 1) + (s < 0))`.
#[inline]
#[target_feature(enable = "avx2")]
fn rdbpot8(s: __m256i, p: &Rq8) -> __m256i {
    let q = _mm256_srav_epi32(s, p.right);
    let rem = _mm256_and_si256(s, p.mask);
    let thr = _mm256_sub_epi32(p.half, _mm256_srai_epi32::<31>(s));
    _mm256_sub_epi32(q, _mm256_cmpgt_epi32(rem, thr))
}

/// 4 × 8 lanes to 32 saturated bytes in lane order (`a` first).
#[inline]
#[target_feature(enable = "avx2")]
fn pack32(a: __m256i, b: __m256i, c: __m256i, d: __m256i) -> __m256i {
    let abcd = _mm256_packs_epi16(_mm256_packs_epi32(a, b), _mm256_packs_epi32(c, d));
    _mm256_permutevar8x32_epi32(abcd, _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7))
}

/// `max(zero_point + requant(x), lo)`; the packs clamp the top and the bottom at −128.
#[inline]
#[target_feature(enable = "avx2")]
pub(crate) fn finish8(x: __m256i, p: &Rq8, zp: __m256i, lo: __m256i) -> __m256i {
    _mm256_max_epi32(_mm256_add_epi32(requant8(x, p), zp), lo)
}

/// 8 lanes to 8 saturated bytes (little-endian in the `u64`).
#[inline]
#[target_feature(enable = "avx2")]
pub(crate) fn pack8(v: __m256i) -> u64 {
    let w = _mm256_packs_epi32(v, v);
    let b = _mm256_packs_epi16(w, w);
    let lo = _mm256_castsi256_si128(b);
    let hi = _mm256_extracti128_si256::<1>(b);
    _mm_cvtsi128_si64(_mm_unpacklo_epi32(lo, hi)) as u64
}

/// Stores the first `n ≤ 8` bytes of [`pack8`]`(v)` at `dst`.
///
/// # Safety
/// `dst..dst + n` must be writable.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn store8(dst: *mut i8, v: __m256i, n: usize) {
    let b = pack8(v);
    if n >= 8 {
        // SAFETY: the caller guarantees 8 writable bytes
        unsafe { (dst as *mut u64).write_unaligned(b) };
    } else {
        let bytes = b.to_le_bytes();
        for (t, &v) in bytes.iter().enumerate().take(n) {
            // SAFETY: t < n, writable by the caller's guarantee
            unsafe { *dst.add(t) = v as i8 };
        }
    }
}

/// [`store8`] with AVX-512's saturating narrow (`vpmovsdb`): one instruction for the packs.
///
/// # Safety
/// AVX-512 F/VL available; `dst..dst + n` writable.
#[inline]
#[target_feature(enable = "avx2,avx512f,avx512vl")]
unsafe fn store8_avx512(dst: *mut i8, v: __m256i, n: usize) {
    let b = _mm_cvtsi128_si64(_mm256_cvtsepi32_epi8(v)) as u64;
    if n >= 8 {
        // SAFETY: the caller guarantees 8 writable bytes
        unsafe { (dst as *mut u64).write_unaligned(b) };
    } else {
        for (t, &v) in b.to_le_bytes().iter().enumerate().take(n) {
            // SAFETY: t < n
            unsafe { *dst.add(t) = v as i8 };
        }
    }
}

// ------------------------------------------------------------------------------------------
// 1x1 conv: int8 GEMM over the packed weights
// ------------------------------------------------------------------------------------------

/// Geometry and quantisation of one pointwise call (all checked by the caller).
pub(crate) struct Pw<'a> {
    /// `P × K` input, NHWC rows.
    pub x: &'a [i8],
    /// Pixels.
    pub p: usize,
    /// Input channels.
    pub k: usize,
    /// Packed weights, `ceil(n/8)` panels of `ceil(k/4)·32` bytes.
    pub w: &'a [i8],
    /// One bias per output channel (`n` of them).
    pub bias: &'a [i32],
    /// One requantiser per output channel.
    pub requant: &'a [Requant],
    /// Input zero point.
    pub zp: i32,
    /// Output zero point.
    pub zo: i32,
    /// Lower clamp (`-128`, or the output zero point with a fused ReLU).
    pub lo: i32,
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
/// VNNI where available, else AVX2. `out` holds `p × n` bytes, `n = bias.len()`.
pub(crate) fn pointwise(a: &Pw<'_>, out: &mut [i8]) {
    pointwise_isa(a, out, use_vnni());
}

/// [`pointwise`] with the instruction set chosen by the caller (`vnni` only where available).
pub(crate) fn pointwise_isa(a: &Pw<'_>, out: &mut [i8], vnni: bool) {
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
        // SAFETY: AVX2 is enabled for the whole build (this module's cfg); ranges asserted
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
            (c0[j], rq[j], nb[j]) = block_consts(a, b0 + j, _mm256_setzero_si256(), 0);
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
    #[allow(clippy::needless_range_loop)]
    for i in 0..MR {
        let s = _mm256_permute4x64_epi64::<0xd8>(_mm256_hadd_epi32(acc[i][0], acc[i][1]));
        let v = finish8(_mm256_add_epi32(s, c0), rq, zo, lo);
        // SAFETY: by the caller
        unsafe { store8(o.add(i * n), v, nb) };
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

// ------------------------------------------------------------------------------------------
// common loads
// ------------------------------------------------------------------------------------------

/// 8 bytes at `p` sign-extended to 8 `i32` lanes.
///
/// # Safety
/// `p..p + 8` readable.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn load8(p: *const i8) -> __m256i {
    // SAFETY: by the caller
    _mm256_cvtepi8_epi32(unsafe { _mm_loadl_epi64(p as *const __m128i) })
}

/// The first `n ≤ 8` bytes at `p` sign-extended (the other lanes 0).
///
/// # Safety
/// `p..p + n` readable.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn load_n(p: *const i8, n: usize) -> __m256i {
    if n >= 8 {
        // SAFETY: 8 bytes readable
        return unsafe { load8(p) };
    }
    let mut b = [0i8; 8];
    for (t, v) in b.iter_mut().enumerate().take(n) {
        // SAFETY: t < n
        *v = unsafe { *p.add(t) };
    }
    _mm256_cvtepi8_epi32(_mm_set1_epi64x(i64::from_le_bytes(b.map(|v| v as u8))))
}

/// Up to 8 `i32`s as a vector (missing lanes 0).
#[inline]
#[target_feature(enable = "avx2")]
fn lanes(v: &[i32]) -> __m256i {
    let mut a = [0i32; 8];
    for (d, &s) in a.iter_mut().zip(v) {
        *d = s;
    }
    _mm256_setr_epi32(a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7])
}

// ------------------------------------------------------------------------------------------
// depthwise 3x3
// ------------------------------------------------------------------------------------------

/// One depthwise call (operands checked by the caller).
pub(crate) struct Dw<'a> {
    /// Input `h × w × c`.
    pub x: &'a [i8],
    /// Input height, width, channels.
    pub h: usize,
    /// Input width.
    pub w: usize,
    /// Channels.
    pub c: usize,
    /// 1 or 2.
    pub stride: usize,
    /// `[3][3][c]` weights.
    pub wt: &'a [i8],
    /// Per-channel bias.
    pub bias: &'a [i32],
    /// Per-channel requantisers.
    pub requant: &'a [Requant],
    /// Input zero point.
    pub zp: i32,
    /// Output zero point.
    pub zo: i32,
    /// Lower clamp.
    pub lo: i32,
}

/// The constants of one 8-channel group of the depthwise kernel.
#[derive(Clone, Copy)]
struct DwGroup {
    /// The 9 taps' weights, `i32`.
    w: [__m256i; 9],
    /// Taps `(2i, 2i + 1)`'s weights as `i16` pairs per channel, for `vpmaddwd`.
    wp: [__m256i; 4],
    /// `bias − zp·Σw`: the start of an interior pixel's sum over raw inputs.
    c_int: __m256i,
    bias: __m256i,
    rq: Rq8,
    /// Real channels (8, or fewer in the last group).
    nb: usize,
}

/// Groups whose constants the depthwise kernel keeps at once (21 KiB of stack): 256 channels,
/// more than any layer of the network has, so one pass over the pixels.
const DW_GROUPS: usize = 32;

/// Depthwise 3×3, pad 1, AVX2: per output pixel and 8-channel group, interior pixels sum the
/// raw inputs of all 9 taps on top of `bias − zp·Σw`; border pixels sum `(x − zp)·w` over
/// their valid taps from `bias`. Groups of four full groups are packed and stored as 32 bytes.
/// `out` is `oh × ow × c`.
pub(crate) fn depthwise(a: &Dw<'_>, out: &mut [i8]) {
    let oh = (a.h - 1) / a.stride + 1;
    let ow = (a.w - 1) / a.stride + 1;
    assert!(
        a.x.len() >= a.h * a.w * a.c
            && a.wt.len() == 9 * a.c
            && a.bias.len() == a.c
            && a.requant.len() == a.c
            && out.len() >= oh * ow * a.c,
        "depthwise operands checked by the caller"
    );
    // SAFETY: AVX2 is enabled for the whole build; ranges asserted above
    unsafe { dw_avx2(a, out, oh, ow) }
}

/// # Safety
/// Ranges as asserted by [`depthwise`].
#[target_feature(enable = "avx2")]
unsafe fn dw_avx2(a: &Dw<'_>, out: &mut [i8], oh: usize, ow: usize) {
    let c = a.c;
    let s = a.stride;
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(a.lo);
    let zpv = _mm256_set1_epi32(a.zp);
    let groups = c.div_ceil(8);
    let empty = DwGroup {
        w: [_mm256_setzero_si256(); 9],
        wp: [_mm256_setzero_si256(); 4],
        c_int: _mm256_setzero_si256(),
        bias: _mm256_setzero_si256(),
        rq: Rq8::splat(Requant { multiplier: 0, shift: 0 }),
        nb: 0,
    };
    let mut g = [empty; DW_GROUPS];
    let x = a.x.as_ptr();
    let x_len = a.h * a.w * c;
    let o = out.as_mut_ptr();
    let out_len = oh * ow * c;
    let mut g0 = 0;
    while g0 < groups {
        let ng = (groups - g0).min(DW_GROUPS);
        // a short last group may store 8 bytes (spilling into the next pixel, written later)
        // only when all groups are done in this one pass
        let single_pass = g0 == 0 && ng == groups;
        for (j, gr) in g.iter_mut().enumerate().take(ng) {
            let c0 = (g0 + j) * 8;
            let nb = (c - c0).min(8);
            let mut sum = _mm256_setzero_si256();
            for (t, wv) in gr.w.iter_mut().enumerate() {
                // SAFETY: tap t's channels c0..c0+nb exist
                *wv = unsafe { load_n(a.wt.as_ptr().add(t * c + c0), nb) };
                sum = _mm256_add_epi32(sum, *wv);
            }
            for (i, wp) in gr.wp.iter_mut().enumerate() {
                let mut l = [0i16; 16];
                for ch in 0..nb {
                    l[2 * ch] = a.wt[2 * i * c + c0 + ch] as i16;
                    l[2 * ch + 1] = a.wt[(2 * i + 1) * c + c0 + ch] as i16;
                }
                *wp = _mm256_setr_epi16(
                    l[0], l[1], l[2], l[3], l[4], l[5], l[6], l[7], l[8], l[9], l[10], l[11],
                    l[12], l[13], l[14], l[15],
                );
            }
            gr.bias = lanes(&a.bias[c0..c0 + nb]);
            gr.c_int = _mm256_sub_epi32(gr.bias, _mm256_mullo_epi32(sum, zpv));
            gr.rq = Rq8::new(&a.requant[c0..c0 + nb]);
            gr.nb = nb;
        }
        for oy in 0..oh {
            let iy = (oy * s) as isize - 1;
            let (ky0, ky1) = (usize::from(iy < 0), 3.min((a.h as isize - iy) as usize));
            for ox in 0..ow {
                let ix = (ox * s) as isize - 1;
                let (kx0, kx1) = (usize::from(ix < 0), 3.min((a.w as isize - ix) as usize));
                let inside = ky0 == 0 && ky1 == 3 && kx0 == 0 && kx1 == 3;
                // the pixel's first tap (may be virtual: outside taps are never read)
                let base = ((iy * a.w as isize + ix) * c as isize + (g0 * 8) as isize) as usize;
                let obase = (oy * ow + ox) * c + g0 * 8;
                // the last tap's end: 8-byte loads of a short group stay inside the input
                let last = base.wrapping_add((2 * a.w + 2) * c + 8);
                // one group's accumulator (lanes past the group's channels meet zero weights)
                let group = |j: usize| -> __m256i {
                    let gr = &g[j];
                    let p0 = base.wrapping_add(j * 8);
                    if inside && (gr.nb == 8 || last + j * 8 <= x_len) {
                        // SAFETY: an interior pixel's taps are inside the input
                        unsafe { dw_taps9(x.add(p0), a.w * c, c, gr) }
                    } else {
                        let mut acc = gr.bias;
                        for ky in ky0..ky1 {
                            for kx in kx0..kx1 {
                                let p = p0.wrapping_add(ky * a.w * c + kx * c);
                                // SAFETY: a valid tap
                                let v = if p + 8 <= x_len {
                                    unsafe { load8(x.add(p)) }
                                } else {
                                    unsafe { load_n(x.add(p), gr.nb) }
                                };
                                let d = _mm256_sub_epi32(v, zpv);
                                acc =
                                    _mm256_add_epi32(acc, _mm256_mullo_epi32(d, gr.w[ky * 3 + kx]));
                            }
                        }
                        acc
                    }
                };
                let mut j = 0;
                while j + 4 <= ng && g[j + 3].nb == 8 {
                    let v = pack32(
                        finish8(group(j), &g[j].rq, zo, lo),
                        finish8(group(j + 1), &g[j + 1].rq, zo, lo),
                        finish8(group(j + 2), &g[j + 2].rq, zo, lo),
                        finish8(group(j + 3), &g[j + 3].rq, zo, lo),
                    );
                    // SAFETY: 32 bytes of this pixel's groups j..j+4
                    unsafe { _mm256_storeu_si256(o.add(obase + j * 8) as *mut __m256i, v) };
                    j += 4;
                }
                while j < ng {
                    let at = obase + j * 8;
                    let nb = g[j].nb;
                    let m = if nb == 8 || (single_pass && at + 8 <= out_len) { 8 } else { nb };
                    // SAFETY: m bytes inside `out`
                    unsafe { store8(o.add(at), finish8(group(j), &g[j].rq, zo, lo), m) };
                    j += 1;
                }
            }
        }
        g0 += ng;
    }
}

/// `c_int + Σ x·w` over the 9 taps of an interior pixel (raw inputs, the zero point being in
/// `c_int`): taps `(2i, 2i + 1)` interleaved byte by byte and sign-extended to `i16` pairs,
/// one `vpmaddwd` per pair (`|x·w| ≤ 128·127`, a pair's sum fits its `i32` lane), tap 8 alone.
///
/// # Safety
/// 8 readable bytes at `p + ky·row + kx·c` for `ky, kx < 3`.
#[inline]
#[target_feature(enable = "avx2")]
unsafe fn dw_taps9(p: *const i8, row: usize, c: usize, g: &DwGroup) -> __m256i {
    // SAFETY: by the caller
    let tap =
        |t: usize| unsafe { _mm_loadl_epi64(p.add(t / 3 * row + t % 3 * c) as *const __m128i) };
    let (mut a0, mut a1) = (g.c_int, _mm256_setzero_si256());
    for i in 0..4 {
        let v = _mm256_cvtepi8_epi16(_mm_unpacklo_epi8(tap(2 * i), tap(2 * i + 1)));
        let m = _mm256_madd_epi16(v, g.wp[i]);
        if i % 2 == 0 {
            a0 = _mm256_add_epi32(a0, m);
        } else {
            a1 = _mm256_add_epi32(a1, m);
        }
    }
    let m8 = _mm256_mullo_epi32(_mm256_cvtepi8_epi32(tap(8)), g.w[8]);
    _mm256_add_epi32(_mm256_add_epi32(a0, m8), a1)
}

// ------------------------------------------------------------------------------------------
// general conv with one input channel, 3x3 (the network's first layer)
// ------------------------------------------------------------------------------------------

/// A 3×3 conv of a one-channel input (operands checked by the caller).
pub(crate) struct Conv1<'a> {
    /// Input `h × w`.
    pub x: &'a [i8],
    /// Input height.
    pub h: usize,
    /// Input width.
    pub w: usize,
    /// Output height.
    pub oh: usize,
    /// Output width.
    pub ow: usize,
    /// Vertical and horizontal stride.
    pub stride: (usize, usize),
    /// Top and left padding.
    pub pad: (usize, usize),
    /// `[c_out][9]` weights.
    pub wt: &'a [i8],
    /// Per-channel bias (`c_out`).
    pub bias: &'a [i32],
    /// Per-channel requantisers.
    pub requant: &'a [Requant],
    /// Input zero point.
    pub zp: i32,
    /// Output zero point.
    pub zo: i32,
    /// Lower clamp.
    pub lo: i32,
}

/// 8-channel groups of the one-channel conv kept at once.
const C1_GROUPS: usize = 8;
/// The one-channel conv's taps (`ky·3 + kx`) in `i16` pairs: the three rows' `(kx 0, kx 1)`,
/// then `kx = 2` of rows 0 and 1, then row 2's alone — pairs a 16-byte row load gives directly
/// for 8 stride-2 pixels.
const TAP_PAIRS: [(usize, usize); 5] = [(0, 1), (3, 4), (6, 7), (2, 5), (8, 9)];

/// 3×3 conv of a one-channel map, AVX2: per output pixel the 9 taps `x − zp` (0 outside) as
/// five `i16` pairs ([`TAP_PAIRS`]), each broadcast and multiplied into every 8-channel group
/// with `vpmaddwd` against the matching weight pairs. With stride 2, runs of 8 interior pixels
/// get their pairs from six 16-byte row loads (bytes `2i, 2i + 1` are pixel `i`'s `kx = 0, 1`).
pub(crate) fn conv1(a: &Conv1<'_>, out: &mut [i8]) {
    let n = a.bias.len();
    assert!(
        a.x.len() >= a.h * a.w
            && a.wt.len() == 9 * n
            && a.requant.len() == n
            && out.len() >= a.oh * a.ow * n,
        "conv operands checked by the caller"
    );
    // SAFETY: AVX2 is enabled for the whole build; ranges asserted above
    unsafe { conv1_avx2(a, out) }
}

/// # Safety
/// Ranges as asserted by [`conv1`].
#[target_feature(enable = "avx2")]
unsafe fn conv1_avx2(a: &Conv1<'_>, out: &mut [i8]) {
    let n = a.bias.len();
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(a.lo);
    let groups = n.div_ceil(8);
    let mut wp = [[_mm256_setzero_si256(); 5]; C1_GROUPS];
    let mut bias = [_mm256_setzero_si256(); C1_GROUPS];
    let mut rq = [Rq8::splat(Requant { multiplier: 0, shift: 0 }); C1_GROUPS];
    let mut nbs = [0usize; C1_GROUPS];
    let (sy, sx) = a.stride;
    let (pt, pl) = a.pad;
    let mut g0 = 0;
    while g0 < groups {
        let ng = (groups - g0).min(C1_GROUPS);
        for j in 0..ng {
            let c0 = (g0 + j) * 8;
            let nb = (n - c0).min(8);
            for (&(ta, tb), v) in TAP_PAIRS.iter().zip(wp[j].iter_mut()) {
                let mut l = [0i16; 16];
                for ch in 0..nb {
                    let w = &a.wt[(c0 + ch) * 9..(c0 + ch) * 9 + 9];
                    l[2 * ch] = w[ta] as i16;
                    l[2 * ch + 1] = if tb < 9 { w[tb] as i16 } else { 0 };
                }
                *v = _mm256_setr_epi16(
                    l[0], l[1], l[2], l[3], l[4], l[5], l[6], l[7], l[8], l[9], l[10], l[11],
                    l[12], l[13], l[14], l[15],
                );
            }
            bias[j] = lanes(&a.bias[c0..c0 + nb]);
            rq[j] = Rq8::new(&a.requant[c0..c0 + nb]);
            nbs[j] = nb;
        }
        let op = out.as_mut_ptr();
        // one output pixel from its five tap pairs (broadcast), every group of this pass
        let emit = |pairs: &[__m256i; 5], o: usize| {
            let group = |j: usize| {
                let mut acc = bias[j];
                for (p, w) in pairs.iter().zip(&wp[j]) {
                    acc = _mm256_add_epi32(acc, _mm256_madd_epi16(*p, *w));
                }
                finish8(acc, &rq[j], zo, lo)
            };
            let mut j = 0;
            while j + 4 <= ng && nbs[j + 3] == 8 {
                let v = pack32(group(j), group(j + 1), group(j + 2), group(j + 3));
                // SAFETY: 32 bytes of this pixel's groups j..j+4 inside `out`
                unsafe { _mm256_storeu_si256(op.add(o + j * 8) as *mut __m256i, v) };
                j += 4;
            }
            while j < ng {
                // SAFETY: nb bytes of this pixel's group inside `out`
                unsafe { store8(op.add(o + j * 8), group(j), nbs[j]) };
                j += 1;
            }
        };
        let zp16 = _mm256_set1_epi16(a.zp as i16);
        let x = a.x.as_ptr();
        for oy in 0..a.oh {
            let iy0 = (oy * sy) as isize - pt as isize;
            let rows_inside = iy0 >= 0 && iy0 + 2 < a.h as isize;
            let mut ox = 0;
            while ox < a.ow {
                let ix0 = (ox * sx) as isize - pl as isize;
                let o = (oy * a.ow + ox) * n + g0 * 8;
                // stride 2, 8 interior pixels: the tap pairs of all 8 from 16-byte row loads
                // (pixel i's taps kx = 0, 1 are bytes 2i, 2i + 1 from ix0: one i16 pair each)
                if sx == 2 && rows_inside && ix0 >= 0 && ox + 8 <= a.ow && ix0 as usize + 18 <= a.w
                {
                    let r = iy0 as usize * a.w + ix0 as usize;
                    // SAFETY: rows iy0..iy0+3, bytes ix0..ix0+18 are inside the input
                    let row = |ky: usize, off: usize| unsafe {
                        _mm256_sub_epi16(
                            _mm256_cvtepi8_epi16(_mm_loadu_si128(
                                x.add(r + ky * a.w + off) as *const __m128i
                            )),
                            zp16,
                        )
                    };
                    let lo16 = _mm256_set1_epi32(0xffff);
                    let p3 = _mm256_blend_epi16::<0b1010_1010>(
                        row(0, 2),
                        _mm256_slli_epi32::<16>(row(1, 2)),
                    );
                    let p4 = _mm256_and_si256(row(2, 2), lo16);
                    let mut tab = [[0i32; 8]; 5];
                    for (t, v) in tab.iter_mut().zip([row(0, 0), row(1, 0), row(2, 0), p3, p4]) {
                        // SAFETY: 32 writable bytes
                        unsafe { _mm256_storeu_si256(t.as_mut_ptr() as *mut __m256i, v) };
                    }
                    #[allow(clippy::needless_range_loop)]
                    for i in 0..8 {
                        let pairs = [
                            _mm256_set1_epi32(tab[0][i]),
                            _mm256_set1_epi32(tab[1][i]),
                            _mm256_set1_epi32(tab[2][i]),
                            _mm256_set1_epi32(tab[3][i]),
                            _mm256_set1_epi32(tab[4][i]),
                        ];
                        emit(&pairs, o + i * n);
                    }
                    ox += 8;
                    continue;
                }
                // one pixel, taps gathered one by one (0 outside the input)
                let mut t = [0i32; 10];
                for ky in 0..3 {
                    let yy = iy0 + ky as isize;
                    for kx in 0..3 {
                        let xx = ix0 + kx as isize;
                        if yy >= 0 && xx >= 0 && yy < a.h as isize && xx < a.w as isize {
                            t[ky * 3 + kx] = a.x[yy as usize * a.w + xx as usize] as i32 - a.zp;
                        }
                    }
                }
                // pairs (0,1) (3,4) (6,7) (2,5) (8,-): the same sums as the 16-byte path
                let pair = |a: i32, b: i32| _mm256_set1_epi32((a & 0xffff) | (b << 16));
                let pairs = [
                    pair(t[0], t[1]),
                    pair(t[3], t[4]),
                    pair(t[6], t[7]),
                    pair(t[2], t[5]),
                    pair(t[8], 0),
                ];
                emit(&pairs, o);
                ox += 1;
            }
        }
        g0 += ng;
    }
}

// ------------------------------------------------------------------------------------------
// bilinear resize
// ------------------------------------------------------------------------------------------

/// `i32`s per chunk of an output row in the resize kernel (two stacked chunks: 16 KiB).
const RESIZE_CHUNK: usize = 2048;
/// Widest output of the SIMD resize (its x taps are tabulated once per call, 24 KiB).
pub(crate) const RESIZE_MAX_OW: usize = 2048;
/// Most channels of the SIMD resize (a chunk holds at least one output pixel).
pub(crate) const RESIZE_MAX_C: usize = RESIZE_CHUNK - 16;

/// One resize call (operands checked by the caller; `c ≤ RESIZE_MAX_C`, `ow ≤ RESIZE_MAX_OW`).
pub(crate) struct Rs<'a> {
    /// Input `h × w × c`.
    pub x: &'a [i8],
    /// Input height.
    pub h: usize,
    /// Input width.
    pub w: usize,
    /// Channels.
    pub c: usize,
    /// Output height.
    pub oh: usize,
    /// Output width.
    pub ow: usize,
    /// Input zero point.
    pub zp: i32,
    /// Output zero point.
    pub zo: i32,
    /// `s_in / (s_out · 2^22)`.
    pub requant: Requant,
    /// `half_pixel_taps` of the crate (passed in to keep one definition).
    pub taps: fn(usize, usize, usize) -> (usize, usize, i32),
}

/// Bilinear resize, AVX2, separable and flat. The output row is cut into chunks of whole
/// pixels (≤ 2048 values). Per chunk and pair of source rows `(y0, y1)`, each source row is
/// blended in x once, `h = (a − zp)·2^11 + wx·(b − a)` (= the reference's `(2^11 − wx)·a +
/// wx·b`), staged as `s = h0·2^11` and `d = h1 − h0`; every output row of that pair is then
/// `s + wy·d` (= `(2^11 − wy)·h0 + wy·h1`, the reference's integer) over the chunk as one flat
/// run of values — no lanes wasted on channel counts like 11 — requantised 8 at a time and
/// stored 32 bytes at a time. `|s|, |d·wy| < 2^31`: nothing overflows.
pub(crate) fn resize(a: &Rs<'_>, out: &mut [i8]) {
    assert!(
        a.x.len() >= a.h * a.w * a.c
            && a.c <= RESIZE_MAX_C
            && a.ow <= RESIZE_MAX_OW
            && out.len() >= a.oh * a.ow * a.c,
        "resize operands checked by the caller"
    );
    // SAFETY: AVX2 is enabled for the whole build; ranges asserted above
    unsafe { resize_avx2(a, out) }
}

/// # Safety
/// Ranges as asserted by [`resize`].
#[target_feature(enable = "avx2")]
unsafe fn resize_avx2(a: &Rs<'_>, out: &mut [i8]) {
    let c = a.c;
    let in_row = a.w * c;
    let x_len = a.h * in_row;
    let out_row = a.ow * c;
    let rq = Rq8::splat(a.requant);
    let zo = _mm256_set1_epi32(a.zo);
    let lo = _mm256_set1_epi32(-128);
    let zpv = _mm256_set1_epi32(a.zp);
    let x = a.x.as_ptr();
    let o = out.as_mut_ptr();
    // (x0·c, x1·c, wx) per output column
    let mut xt = [(0u32, 0u32, 0i32); RESIZE_MAX_OW];
    for (ox, t) in xt.iter_mut().enumerate().take(a.ow) {
        let (x0, x1, wx) = (a.taps)(ox, a.w, a.ow);
        *t = ((x0 * c) as u32, (x1 * c) as u32, wx);
    }
    // chunk: + 16 values of slack for the last pixel's vectors
    let mut s = [0i32; RESIZE_CHUNK];
    let mut d = [0i32; RESIZE_CHUNK];
    let px_per_chunk = (RESIZE_CHUNK - 16) / c;
    // the source value `x[r + off .. + 8] − zp` (8-byte loads inside the input, else fewer)
    let src = |off: usize| {
        if off + 8 <= x_len {
            // SAFETY: 8 bytes inside the input
            _mm256_sub_epi32(unsafe { load8(x.add(off)) }, zpv)
        } else {
            // SAFETY: the bytes up to the input's end
            _mm256_sub_epi32(unsafe { load_n(x.add(off), x_len - off) }, zpv)
        }
    };
    let mut p0 = 0;
    while p0 < a.ow {
        let np = (a.ow - p0).min(px_per_chunk);
        let len = np * c;
        let mut pair = (usize::MAX, usize::MAX);
        for oy in 0..a.oh {
            let (y0, y1, wy) = (a.taps)(oy, a.h, a.oh);
            if (y0, y1) != pair {
                pair = (y0, y1);
                // x-blend both source rows over the chunk's pixels (lanes past the pixel's
                // channels are overwritten by the next pixel or lie in the slack)
                for (i, &(x0, x1, wx)) in xt[p0..p0 + np].iter().enumerate() {
                    let wxv = _mm256_set1_epi32(wx);
                    let mut ch = 0;
                    while ch < c {
                        let (o0, o1) = (x0 as usize + ch, x1 as usize + ch);
                        let (r0, r1) = (y0 * in_row, y1 * in_row);
                        let (a0, b0) = (src(r0 + o0), src(r0 + o1));
                        let (a1, b1) = (src(r1 + o0), src(r1 + o1));
                        let h0 = _mm256_add_epi32(
                            _mm256_slli_epi32::<11>(a0),
                            _mm256_mullo_epi32(wxv, _mm256_sub_epi32(b0, a0)),
                        );
                        let h1 = _mm256_add_epi32(
                            _mm256_slli_epi32::<11>(a1),
                            _mm256_mullo_epi32(wxv, _mm256_sub_epi32(b1, a1)),
                        );
                        let at = i * c + ch;
                        // SAFETY: at + 8 ≤ len + 8 ≤ RESIZE_CHUNK
                        unsafe {
                            _mm256_storeu_si256(
                                s.as_mut_ptr().add(at) as *mut __m256i,
                                _mm256_slli_epi32::<11>(h0),
                            );
                            _mm256_storeu_si256(
                                d.as_mut_ptr().add(at) as *mut __m256i,
                                _mm256_sub_epi32(h1, h0),
                            );
                        }
                        ch += 8;
                    }
                }
            }
            let wyv = _mm256_set1_epi32(wy);
            // SAFETY: the chunk's values of output row oy
            let dst = unsafe { o.add(oy * out_row + p0 * c) };
            let value = |i: usize| {
                // SAFETY: i + 8 ≤ len + 8 ≤ RESIZE_CHUNK
                let (sv, dv) = unsafe {
                    (
                        _mm256_loadu_si256(s.as_ptr().add(i) as *const __m256i),
                        _mm256_loadu_si256(d.as_ptr().add(i) as *const __m256i),
                    )
                };
                finish8(_mm256_add_epi32(sv, _mm256_mullo_epi32(wyv, dv)), &rq, zo, lo)
            };
            let mut i = 0;
            while i + 32 <= len {
                let v = pack32(value(i), value(i + 8), value(i + 16), value(i + 24));
                // SAFETY: 32 bytes of the chunk
                unsafe { _mm256_storeu_si256(dst.add(i) as *mut __m256i, v) };
                i += 32;
            }
            while i < len {
                // SAFETY: min(8, len − i) bytes of the chunk
                unsafe { store8(dst.add(i), value(i), (len - i).min(8)) };
                i += 8;
            }
        }
        p0 += np;
    }
}

// ------------------------------------------------------------------------------------------
// element-wise: Add and the rescales of Concat
// ------------------------------------------------------------------------------------------

/// One quantised `Add` over `n` elements (operands checked by the caller).
pub(crate) struct AddOp<'a> {
    /// First input.
    pub a: &'a [i8],
    /// Second input.
    pub b: &'a [i8],
    /// Zero points of the inputs.
    pub zp: (i32, i32),
    /// Requantisers of the inputs (to the common `2^20` domain).
    pub rq: (Requant, Requant),
    /// Output requantiser.
    pub out_rq: Requant,
    /// Output zero point.
    pub zo: i32,
    /// Lower clamp.
    pub lo: i32,
}

/// TFLite's quantised add, 8 lanes at a time: `clamp(zo + Mo(M1((a − za) << 20) + M2((b − zb)
/// << 20)))`. `out.len()` elements. The input requantisers must have no left shift (scales
/// `≤ 1/2`, which TFLite's construction guarantees).
pub(crate) fn add(op: &AddOp<'_>, out: &mut [i8]) {
    assert!(
        op.a.len() >= out.len()
            && op.b.len() >= out.len()
            && op.rq.0.shift <= 0
            && op.rq.1.shift <= 0,
        "add operands checked"
    );
    // SAFETY: AVX2 is enabled for the whole build; ranges asserted above
    unsafe { add_avx2(op, out) }
}

/// # Safety
/// Ranges as asserted by [`add`].
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
pub(crate) struct RescaleOp<'a> {
    /// The input, `pixels × c`.
    pub x: &'a [i8],
    /// Its channels.
    pub c: usize,
    /// Output channels (row stride).
    pub stride: usize,
    /// Input zero point.
    pub zp: i32,
    /// Output zero point.
    pub zo: i32,
    /// `s_in / s_out`.
    pub requant: Requant,
}

/// [`RescaleOp`], AVX2. `out` starts at the input's first output channel.
pub(crate) fn rescale_into(op: &RescaleOp<'_>, pixels: usize, out: &mut [i8]) {
    assert!(
        op.x.len() >= pixels * op.c
            && (pixels == 0 || out.len() >= (pixels - 1) * op.stride + op.c),
        "rescale operands checked"
    );
    // SAFETY: AVX2 is enabled for the whole build; ranges asserted above
    unsafe { rescale_avx2(op, pixels, out) }
}

/// # Safety
/// Ranges as asserted by [`rescale_into`].
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::quant::SIMD_REQUANT_BOUND;
    use crate::nn::testutil::Rng;

    #[test]
    fn requant8_equals_the_scalar_requantisation() {
        let mut rng = Rng::new(0x51d);
        for i in 0..20_000 {
            // scales from 2^-32 to 2^8: right shifts 0..31, left shifts up to 9, ties reached
            // by powers of two every 4th lane set
            let rq: [Requant; 8] = core::array::from_fn(|_| {
                let s = if i % 4 == 0 {
                    1.0 / (1u64 << rng.int(0, 31)) as f64
                } else {
                    libm::exp(rng.f64(-22.0, 6.0))
                };
                if rng.int(0, 50) == 0 {
                    Requant { multiplier: 0, shift: 0 }
                } else {
                    Requant::from_scale(s)
                }
            });
            let x: [i32; 8] = core::array::from_fn(|l| {
                let bound = SIMD_REQUANT_BOUND >> rq[l].shift.clamp(0, 30);
                match rng.int(0, 3) {
                    0 => rng.int(-300, 300) as i32,
                    1 => rng.int(-bound, bound) as i32,
                    _ => [-bound, bound, -1, 0][rng.usize(0, 3)] as i32,
                }
            });
            let (zp, relu) = (rng.zp(), rng.int(0, 1) == 1);
            let (lo, hi) = crate::nn::quant::clamp_range(zp, relu);
            let want: [i32; 8] = core::array::from_fn(|l| rq[l].apply(x[l]));
            let want8: [i8; 8] = core::array::from_fn(|l| rq[l].to_i8(x[l], zp, lo, hi));
            // SAFETY: AVX2 is a compile-time feature of this build
            let (got, got8) = unsafe { lanes_of(&rq, &x, zp, lo) };
            assert_eq!(got, want, "{rq:?} {x:?}");
            assert_eq!(got8, want8, "{rq:?} {x:?} {zp} {relu}");
        }
    }

    /// `requant8` and `finish8` + `pack8` of one vector, as arrays.
    #[target_feature(enable = "avx2")]
    fn lanes_of(rq: &[Requant; 8], x: &[i32; 8], zp: i32, lo: i32) -> ([i32; 8], [i8; 8]) {
        let p = Rq8::new(rq);
        let v = _mm256_setr_epi32(x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7]);
        let mut out = [0i32; 8];
        let r = requant8(v, &p);
        for (l, o) in out.iter_mut().enumerate() {
            let mut a = [0i32; 8];
            // SAFETY: 32 writable bytes
            unsafe { _mm256_storeu_si256(a.as_mut_ptr() as *mut __m256i, r) };
            *o = a[l];
        }
        let b = pack8(finish8(v, &p, _mm256_set1_epi32(zp), _mm256_set1_epi32(lo)));
        (out, b.to_le_bytes().map(|v| v as i8))
    }
}
