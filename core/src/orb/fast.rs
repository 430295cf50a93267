//! FAST-9 corner detection (Rosten & Drummond), with OpenCV's score and non-maximum suppression.
//!
//! A pixel `p` is a corner at threshold `t` when 9 contiguous pixels of the 16-pixel Bresenham
//! circle of radius 3 are all brighter than `p + t` or all darker than `p − t`. Its **score** is
//! the largest `t` for which it is still a corner (OpenCV's `cornerScore`), so
//! `score ≥ t ⇔ corner at t`: one score map serves both of ORB-SLAM2's thresholds (`iniThFAST`
//! and the `minThFAST` fallback). Non-maximum suppression keeps a corner whose score is strictly
//! greater than all 8 neighbours' (non-corners score 0), as OpenCV's `FAST(.., true)`.
//!
//! Speed: a row is screened with a vectorised necessary condition (for one polarity, every
//! antipodal pair of circle pixels must contain a pixel of that polarity, since any 9-arc covers
//! one of each pair). Blocks of 32 pixels holding a survivor are then scored whole, vectorised
//! across the pixels (about 6 % of a KITTI frame's pixels pass the screen at `t = 20` and 4 % are
//! corners, so most survivors need their score anyway); the row's tail, pixel by pixel.
//!
//! Memory: the caller provides the score map (one byte per pixel) and a row of flags.

use crate::image::{ImageView, ImageViewMut};

/// Circle radius; detection needs this many pixels of margin on every side.
pub const FAST_RADIUS: usize = 3;

/// The 16 circle offsets `(dx, dy)` in circular order (OpenCV's `offsets16`).
pub const CIRCLE: [(i32, i32); 16] = [
    (0, 3),
    (1, 3),
    (2, 2),
    (3, 1),
    (3, 0),
    (3, -1),
    (2, -2),
    (1, -3),
    (0, -3),
    (-1, -3),
    (-2, -2),
    (-3, -1),
    (-3, 0),
    (-3, 1),
    (-2, 2),
    (-1, 3),
];

/// True when the 16-bit circular mask `m` has 9 contiguous set bits.
#[inline(always)]
fn has_arc9(m: u32) -> bool {
    let x = m | (m << 16);
    let mut a = x & (x >> 1); // runs of 2
    a &= a >> 2; // 4
    a &= a >> 4; // 8
    a &= x >> 8; // 9
    a & 0xFFFF != 0
}

/// Largest `max over 9-arcs of (min over the arc of v)` for the circular sequence `v`.
#[inline(always)]
fn best_arc_min(v: &[i16; 16]) -> i16 {
    let mut e = [0i16; 25];
    for (i, x) in e.iter_mut().enumerate() {
        *x = v[i & 15];
    }
    let mut m2 = [0i16; 24];
    for i in 0..24 {
        m2[i] = e[i].min(e[i + 1]);
    }
    let mut m4 = [0i16; 22];
    for i in 0..22 {
        m4[i] = m2[i].min(m2[i + 2]);
    }
    let mut best = i16::MIN;
    for i in 0..16 {
        best = best.max(m4[i].min(m4[i + 4]).min(e[i + 8]));
    }
    best
}

/// FAST score of the pixel at `idx` of `data` given the 16 circle offsets (in bytes), or 0 when it
/// is not a corner at threshold `t` (`t >= 1`).
#[inline(always)]
fn score_at(data: &[u8], idx: usize, offs: &[isize; 16], t: i16) -> u8 {
    let p = i16::from(data[idx]);
    let mut d = [0i16; 16];
    let (mut bright, mut dark) = (0u32, 0u32);
    for k in 0..16 {
        let v = i16::from(data[(idx as isize + offs[k]) as usize]) - p;
        d[k] = v;
        bright |= u32::from(v > t) << k;
        dark |= u32::from(v < -t) << k;
    }
    // Only a polarity with a 9-arc above `t` can hold the maximum, so score just that one.
    let s = if has_arc9(bright) {
        let b = best_arc_min(&d);
        if has_arc9(dark) {
            b.max(best_arc_min(&d.map(|v| -v)))
        } else {
            b
        }
    } else if has_arc9(dark) {
        best_arc_min(&d.map(|v| -v))
    } else {
        return 0;
    } - 1;
    // s >= t >= 1 for a corner; clamp for the (impossible) rest so 0 keeps meaning "none".
    s.clamp(1, 255) as u8
}

/// FAST score of pixel `(x, y)` (0 when not a corner even at threshold 1): the reference the
/// row kernel is tested against.
///
/// # Panics
/// If the pixel is closer than [`FAST_RADIUS`] to the border.
pub fn corner_score(img: &ImageView<'_>, x: usize, y: usize) -> u8 {
    assert!(x >= FAST_RADIUS && y >= FAST_RADIUS);
    assert!(x + FAST_RADIUS < img.width() && y + FAST_RADIUS < img.height());
    let offs = circle_offsets(img.stride());
    score_at(img.data(), y * img.stride() + x, &offs, 1)
}

#[inline(always)]
fn circle_offsets(stride: usize) -> [isize; 16] {
    let mut o = [0isize; 16];
    for (k, &(dx, dy)) in CIRCLE.iter().enumerate() {
        o[k] = dy as isize * stride as isize + dx as isize;
    }
    o
}

/// Scores row `y` of `img` for `x in xs` at threshold `t` into `scores` (same geometry,
/// only corners written), calls `on_corner(x)` for each corner, and returns how many it found.
///
/// `flags` is scratch of at least `xs.len()` bytes. Pixels must be at least [`FAST_RADIUS`] from
/// the border. Runs as x86-64-v3 code where the CPU has it ([`crate::arch::v3`]; the same bits).
pub fn score_row(
    img: &ImageView<'_>,
    y: usize,
    xs: core::ops::Range<usize>,
    t: u8,
    flags: &mut [u8],
    scores: &mut ImageViewMut<'_>,
    on_corner: impl FnMut(usize),
) -> usize {
    crate::arch::v3(
        #[inline(always)]
        || score_row_body(img, y, xs, t, flags, scores, on_corner, BLOCK_SCORING),
    )
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn score_row_body(
    img: &ImageView<'_>,
    y: usize,
    xs: core::ops::Range<usize>,
    t: u8,
    flags: &mut [u8],
    scores: &mut ImageViewMut<'_>,
    mut on_corner: impl FnMut(usize),
    blocks: bool,
) -> usize {
    let (x0, x1) = (xs.start, xs.end);
    if x1 <= x0 {
        return 0;
    }
    debug_assert!(x0 >= FAST_RADIUS && x1 + FAST_RADIUS <= img.width());
    debug_assert!(y >= FAST_RADIUS && y + FAST_RADIUS < img.height());
    let n = x1 - x0;
    let flags = &mut flags[..n];
    screen_row(img, y, x0, n, t, flags);
    let offs = circle_offsets(img.stride());
    let data = img.data();
    let base = y * img.stride() + x0;
    let out = &mut scores.row_mut(y)[x0..x1];
    let t16 = i16::from(t);
    let mut found = 0;
    let mut i = 0;
    // Whole blocks of LANES pixels with a screened pixel are scored all at once (every lane,
    // vectorised; a score below `t` means "not a corner at t"); the tail pixel by pixel.
    while blocks && i + LANES <= n {
        let w = &flags[i..i + LANES];
        if w.iter().fold(0u8, |a, &f| a | f) == 0 {
            i += LANES;
            continue;
        }
        let s = score_lanes(img, y, x0 + i);
        let mut mask = 0u32;
        for (l, &v) in s.iter().enumerate() {
            mask |= u32::from(v >= t) << l;
        }
        while mask != 0 {
            let l = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            out[i + l] = s[l];
            found += 1;
            on_corner(x0 + i + l);
        }
        i += LANES;
    }
    while i < n {
        if flags[i] != 0 {
            let s = score_at(data, base + i, &offs, t16);
            if s != 0 {
                out[i] = s;
                found += 1;
                on_corner(x0 + i);
            }
        }
        i += 1;
    }
    found
}

/// Pixels scored at once by [`score_lanes`] (one 256-bit vector of bytes).
const LANES: usize = 32;

/// Whether whole blocks are scored at once: on targets with byte vectors (x86-64, AArch64
/// NEON). Without them (Cortex-M4) scoring all 32 pixels of a block would cost more than
/// scoring its few survivors one by one; the scores are the same either way.
const BLOCK_SCORING: bool = cfg!(any(target_arch = "x86_64", target_arch = "aarch64"));

/// FAST scores of the [`LANES`] pixels from `(x, y)`, the same as [`score_at`] gives at
/// threshold 1 (0 where a pixel is no corner even at 1), so a score `>= t` is a corner at `t`
/// with that score and a score `< t` is none. Per lane: the 9-arc minimum of the
/// saturated differences for each polarity (circular runs of 2, 4, 8, then 9 by halving), the
/// larger over arcs and polarities, less one. Written lane by lane over fixed arrays, which
/// vectorises across the lanes.
#[inline(always)]
fn score_lanes(img: &ImageView<'_>, y: usize, x: usize) -> [u8; LANES] {
    // Seventeen named slices, written out as in `screen_row` on purpose: a shared helper that
    // returned the circle rows as an array of slices kept the bounds checks in both loops (a
    // one-thread 06 run executed 1.6 times the instructions).
    let row = |dy: i32, dx: i32| -> &[u8] {
        let r = img.row((y as i32 + dy) as usize);
        let s = (x as i32 + dx) as usize;
        &r[s..s + LANES]
    };
    let p = |k: usize| row(CIRCLE[k].1, CIRCLE[k].0);
    let c = row(0, 0);
    let (p0, p1, p2, p3, p4, p5, p6, p7) = (p(0), p(1), p(2), p(3), p(4), p(5), p(6), p(7));
    let (p8, p9, p10, p11, p12, p13, p14, p15) =
        (p(8), p(9), p(10), p(11), p(12), p(13), p(14), p(15));
    #[inline(always)]
    fn best_arc(x: [u8; 16]) -> u8 {
        let m2: [u8; 16] = core::array::from_fn(|k| x[k].min(x[(k + 1) & 15]));
        let m4: [u8; 16] = core::array::from_fn(|k| m2[k].min(m2[(k + 2) & 15]));
        let m8: [u8; 16] = core::array::from_fn(|k| m4[k].min(m4[(k + 4) & 15]));
        let mut best = 0u8;
        for k in 0..16 {
            best = best.max(m8[k].min(x[(k + 8) & 15]));
        }
        best
    }
    let mut out = [0u8; LANES];
    for (l, o) in out.iter_mut().enumerate() {
        let v = c[l];
        let q = [
            p0[l], p1[l], p2[l], p3[l], p4[l], p5[l], p6[l], p7[l], p8[l], p9[l], p10[l], p11[l],
            p12[l], p13[l], p14[l], p15[l],
        ];
        let bright = best_arc(q.map(|a| a.saturating_sub(v)));
        let dark = best_arc(q.map(|a| v.saturating_sub(a)));
        *o = bright.max(dark).saturating_sub(1);
    }
    out
}

/// Vectorised necessary condition for a FAST-9 corner: writes 1 into `flags[i]` when pixel
/// `x0 + i` may be a corner at threshold `t`.
#[inline(always)]
fn screen_row(img: &ImageView<'_>, y: usize, x0: usize, n: usize, t: u8, flags: &mut [u8]) {
    let row = |dy: i32, dx: i32| -> &[u8] {
        let r = img.row((y as i32 + dy) as usize);
        let s = (x0 as i32 + dx) as usize;
        &r[s..s + n]
    };
    let p = |k: usize| row(CIRCLE[k].1, CIRCLE[k].0);
    // Sixteen named slices of exactly `n` bytes: the bounds checks hoist out of the loop and it
    // vectorises (an array of slices would keep a check per access).
    let c = row(0, 0);
    let (p0, p1, p2, p3, p4, p5, p6, p7) = (p(0), p(1), p(2), p(3), p(4), p(5), p(6), p(7));
    let (p8, p9, p10, p11, p12, p13, p14, p15) =
        (p(8), p(9), p(10), p(11), p(12), p(13), p(14), p(15));
    let flags = &mut flags[..n];
    for i in 0..n {
        let v = c[i];
        let hi = v.saturating_add(t);
        let lo = v.saturating_sub(t);
        let b = |a: u8, o: u8| u8::from(a > hi) | u8::from(o > hi);
        let d = |a: u8, o: u8| u8::from(a < lo) | u8::from(o < lo);
        let bright = b(p0[i], p8[i])
            & b(p1[i], p9[i])
            & b(p2[i], p10[i])
            & b(p3[i], p11[i])
            & b(p4[i], p12[i])
            & b(p5[i], p13[i])
            & b(p6[i], p14[i])
            & b(p7[i], p15[i]);
        let dark = d(p0[i], p8[i])
            & d(p1[i], p9[i])
            & d(p2[i], p10[i])
            & d(p3[i], p11[i])
            & d(p4[i], p12[i])
            & d(p5[i], p13[i])
            & d(p6[i], p14[i])
            & d(p7[i], p15[i]);
        // A 9-arc also covers two neighbouring points of the compass {0, 4, 8, 12}.
        let q = |a: u8, b: u8, c: u8, d: u8| (a & b) | (b & c) | (c & d) | (d & a);
        let (b0, b4, b8, b12) = (
            u8::from(p0[i] > hi),
            u8::from(p4[i] > hi),
            u8::from(p8[i] > hi),
            u8::from(p12[i] > hi),
        );
        let (d0, d4, d8, d12) = (
            u8::from(p0[i] < lo),
            u8::from(p4[i] < lo),
            u8::from(p8[i] < lo),
            u8::from(p12[i] < lo),
        );
        flags[i] = (bright & q(b0, b4, b8, b12)) | (dark & q(d0, d4, d8, d12));
    }
}

/// Calls `f(x, y, score)` for every non-maximum-suppressed corner of `scores` with `y in
/// y0..y1`, `x in x0..x1`, in raster order. Scores outside the region must be 0 (or be real
/// scores: they take part in the comparison); the region must keep one pixel of margin.
///
/// Rows are compared in blocks of 32 pixels against their 8 neighbours at once (vectorised;
/// as x86-64-v3 code where the CPU has it, [`crate::arch::v3`]), and `f` runs on the maxima
/// outside that kernel.
pub fn for_each_nms_max(
    scores: &ImageView<'_>,
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
    mut f: impl FnMut(usize, usize, u8),
) {
    debug_assert!(x0 >= 1 && y0 >= 1 && x1 < scores.width() && y1 < scores.height());
    if x1 <= x0 {
        return;
    }
    /// Blocks handed to the kernel per call.
    const CHUNK: usize = 16;
    for y in y0..y1 {
        let (up, cur, dn) = (scores.row(y - 1), scores.row(y), scores.row(y + 1));
        let mut x = x0;
        while x < x1 {
            let blocks = ((x1 - x) / LANES).min(CHUNK);
            let mut masks = [0u32; CHUNK];
            if blocks > 0 {
                let masks = &mut masks[..blocks];
                crate::arch::v3(
                    #[inline(always)]
                    || {
                        for (b, m) in masks.iter_mut().enumerate() {
                            *m = nms_block(up, cur, dn, x + b * LANES);
                        }
                    },
                );
            } else {
                // The row's tail, shorter than a block.
                for (l, xx) in (x..x1).enumerate() {
                    masks[0] |= u32::from(is_nms_max(up, cur, dn, xx)) << l;
                }
            }
            for (b, &m) in masks[..blocks.max(1)].iter().enumerate() {
                let mut m = m;
                while m != 0 {
                    let xx = x + b * LANES + m.trailing_zeros() as usize;
                    m &= m - 1;
                    f(xx, y, cur[xx]);
                }
            }
            x = if blocks > 0 { x + blocks * LANES } else { x1 };
        }
    }
}

/// Whether the score at `x` of row `cur` is strictly greater than its 8 neighbours' (so not 0).
#[inline(always)]
fn is_nms_max(up: &[u8], cur: &[u8], dn: &[u8], x: usize) -> bool {
    let m = up[x - 1]
        .max(up[x])
        .max(up[x + 1])
        .max(cur[x - 1])
        .max(cur[x + 1])
        .max(dn[x - 1])
        .max(dn[x])
        .max(dn[x + 1]);
    cur[x] > m
}

/// [`is_nms_max`] for the [`LANES`] pixels from `x`, as bits (bit `l`: pixel `x + l`); nine
/// slices of exactly one block, so the comparison vectorises across the pixels.
#[inline(always)]
fn nms_block(up: &[u8], cur: &[u8], dn: &[u8], x: usize) -> u32 {
    let at = |r: &[u8], dx: usize| -> [u8; LANES] {
        let s = &r[x + dx - 1..x + dx - 1 + LANES];
        core::array::from_fn(|l| s[l])
    };
    let (u0, u1, u2) = (at(up, 0), at(up, 1), at(up, 2));
    let (c0, c1, c2) = (at(cur, 0), at(cur, 1), at(cur, 2));
    let (d0, d1, d2) = (at(dn, 0), at(dn, 1), at(dn, 2));
    let mut mask = 0u32;
    for l in 0..LANES {
        let m = u0[l].max(u1[l]).max(u2[l]).max(c0[l]).max(c2[l]).max(d0[l]).max(d1[l]).max(d2[l]);
        mask |= u32::from(c1[l] > m) << l;
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Straightforward FAST-9 score from the definition, for cross-checking.
    fn naive_score(img: &[u8], w: usize, x: usize, y: usize) -> u8 {
        let p = img[y * w + x] as i32;
        let v: Vec<i32> = CIRCLE
            .iter()
            .map(|&(dx, dy)| img[(y as i32 + dy) as usize * w + (x as i32 + dx) as usize] as i32)
            .collect();
        let mut best = 0;
        for t in 1..=255 {
            let corner = (0..16).any(|s| {
                (0..9).all(|j| v[(s + j) % 16] > p + t) || (0..9).all(|j| v[(s + j) % 16] < p - t)
            });
            if corner {
                best = t;
            } else {
                break;
            }
        }
        best as u8
    }

    fn noise(w: usize, h: usize, seed: u32) -> Vec<u8> {
        let mut img = vec![0u8; w * h];
        crate::testing::noise(&mut img, seed);
        img
    }

    #[test]
    fn row_scores_match_definition() {
        let (w, h) = (40usize, 12usize);
        let img = noise(w, h, 0x1234_5678);
        let view = ImageView::from_slice(&img, w, h).unwrap();
        for t in [1u8, 7, 20, 40] {
            let mut sc = vec![0u8; w * h];
            let mut flags = vec![0u8; w];
            for y in 3..h - 3 {
                let mut sm = ImageViewMut::from_slice(&mut sc, w, h).unwrap();
                score_row(&view, y, 3..w - 3, t, &mut flags, &mut sm, |_| {});
            }
            for y in 3..h - 3 {
                for x in 3..w - 3 {
                    let n = naive_score(&img, w, x, y);
                    let expect = if n >= t { n } else { 0 };
                    assert_eq!(sc[y * w + x], expect, "t={t} ({x},{y})");
                    assert_eq!(corner_score(&view, x, y), n);
                }
            }
        }
    }

    /// Rows wide enough for several whole blocks, ranges that start and end anywhere, blocks
    /// scored at once or pixel by pixel: the same scores as the definition, and `on_corner`
    /// called once per corner, in order.
    #[test]
    fn blocks_and_tails_agree_with_the_definition() {
        let (w, h) = (150usize, 9usize);
        let img = noise(w, h, 0x0bad_cafe);
        let view = ImageView::from_slice(&img, w, h).unwrap();
        let y = 4;
        for (x0, x1, blocks) in [(3, w - 3), (5, 69), (3, 35), (40, 72), (10, 11)]
            .into_iter()
            .flat_map(|(a, b)| [(a, b, true), (a, b, false)])
        {
            for t in [1u8, 7, 20] {
                let mut sc = vec![0u8; w * h];
                let mut flags = vec![0u8; w];
                let mut called = Vec::new();
                let mut sm = ImageViewMut::from_slice(&mut sc, w, h).unwrap();
                let on = |x| called.push(x);
                let n = score_row_body(&view, y, x0..x1, t, &mut flags, &mut sm, on, blocks);
                let want: Vec<usize> =
                    (x0..x1).filter(|&x| naive_score(&img, w, x, y) >= t).collect();
                if x1 - x0 > 100 {
                    assert!(want.len() > 5, "the noise row has corners at t={t}");
                }
                assert_eq!(called, want, "x in {x0}..{x1}, t={t}");
                assert_eq!(n, want.len());
                for x in 0..w {
                    let expect = if want.contains(&x) { naive_score(&img, w, x, y) } else { 0 };
                    assert_eq!(sc[y * w + x], expect, "({x},{y}) in {x0}..{x1}, t={t}");
                }
            }
        }
    }

    /// Suppression over regions of several widths (whole blocks, tails, both) on sparse
    /// random scores with ties: exactly the strict maxima of the definition, in raster order.
    #[test]
    fn nms_keeps_exactly_the_strict_maxima() {
        let (w, h) = (140usize, 12usize);
        let mut sc = noise(w, h, 0x5eed);
        for v in sc.iter_mut() {
            // ~70 % zeros and few distinct values, so ties are common.
            *v = if *v < 180 { 0 } else { 1 + *v % 6 };
        }
        let view = ImageView::from_slice(&sc, w, h).unwrap();
        for (x0, x1) in [(1, w - 1), (1, 33), (5, 100), (7, 20), (30, 31)] {
            let mut got = Vec::new();
            for_each_nms_max(&view, x0, x1, 1, h - 1, |x, y, s| got.push((x, y, s)));
            let mut want = Vec::new();
            for y in 1..h - 1 {
                for x in x0..x1 {
                    let c = sc[y * w + x];
                    let m = (0..9)
                        .filter(|&k| k != 4)
                        .map(|k| sc[(y + k / 3 - 1) * w + x + k % 3 - 1])
                        .max()
                        .unwrap();
                    if c > m {
                        want.push((x, y, c));
                    }
                }
            }
            assert!(x1 - x0 < 50 || want.len() > 10, "the map has maxima");
            assert_eq!(got, want, "x in {x0}..{x1}");
        }
    }

    #[test]
    fn flat_image_has_no_corners() {
        let (w, h) = (32usize, 32usize);
        let img = vec![128u8; w * h];
        let view = ImageView::from_slice(&img, w, h).unwrap();
        let mut sc = vec![0u8; w * h];
        let mut flags = vec![0u8; w];
        let mut n = 0;
        for y in 3..h - 3 {
            let mut sm = ImageViewMut::from_slice(&mut sc, w, h).unwrap();
            n += score_row(&view, y, 3..w - 3, 1, &mut flags, &mut sm, |_| {});
        }
        assert_eq!(n, 0);
        assert!(sc.iter().all(|&s| s == 0));
    }

    #[test]
    fn bright_square_corners_are_found_at_its_corners() {
        let (w, h) = (64usize, 64usize);
        // Small noise breaks the exact score ties a perfect synthetic corner has (strict
        // suppression would drop all of them, in OpenCV as here); it is far below t = 20.
        let mut img: Vec<u8> = noise(w, h, 42).iter().map(|&n| 40 + n % 5).collect();
        for y in 20..44 {
            for x in 20..44 {
                img[y * w + x] += 160;
            }
        }
        let view = ImageView::from_slice(&img, w, h).unwrap();
        let mut sc = vec![0u8; w * h];
        let mut flags = vec![0u8; w];
        for y in 3..h - 3 {
            let mut sm = ImageViewMut::from_slice(&mut sc, w, h).unwrap();
            score_row(&view, y, 3..w - 3, 20, &mut flags, &mut sm, |_| {});
        }
        let sv = ImageView::from_slice(&sc, w, h).unwrap();
        let mut found = Vec::new();
        for_each_nms_max(&sv, 4, w - 4, 4, h - 4, |x, y, s| found.push((x, y, s)));
        let corners = [(20, 20), (43, 20), (20, 43), (43, 43)];
        assert!(!found.is_empty());
        for &(x, y, _) in &found {
            let near = corners
                .iter()
                .any(|&(cx, cy)| (x as i32 - cx).abs() <= 2 && (y as i32 - cy).abs() <= 2);
            assert!(near, "corner at ({x},{y}) is not near a square corner");
        }
        for &(cx, cy) in &corners {
            assert!(
                found
                    .iter()
                    .any(|&(x, y, _)| (x as i32 - cx).abs() <= 2 && (y as i32 - cy).abs() <= 2),
                "no corner near ({cx},{cy})"
            );
        }
    }

    #[test]
    fn arc_mask() {
        assert!(has_arc9(0x01FF));
        assert!(has_arc9(0xF80F)); // wraps: bits 11..15 and 0..3
        assert!(!has_arc9(0x00FF));
        assert!(!has_arc9(0x7F7F));
    }
}
