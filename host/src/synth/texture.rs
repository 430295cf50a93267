//! Procedural textures: every surface colour is a function of the surface point's own
//! coordinates (metres along and up the surface), so the left and right cameras see the same
//! pattern on the same 3D point, and stereo depth is right by construction.
//!
//! Detail is band-limited by the pixel footprint `fp` (metres per pixel on the surface):
//! stripes and grain whose period drops below ~2 px fade to their mean instead of aliasing.

/// An RGB colour, 0..255 per channel (before exposure).
pub(crate) type Rgb = [f32; 3];

/// A 32-bit integer hash of a 2D lattice point and a seed (lowbias32-style finaliser).
#[inline]
pub(crate) fn hash3(x: i32, y: i32, seed: u32) -> u32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841)
        ^ seed.wrapping_mul(0xcb1a_b31f);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^= h >> 16;
    h
}

/// Uniform in [0, 1) from a lattice point.
#[inline]
pub(crate) fn rnd(x: i32, y: i32, seed: u32) -> f32 {
    (hash3(x, y, seed) >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// `floor(x)` as an integer without a libm call (the x86-64 baseline has no SSE4.1 `roundss`,
/// and `f32::floor` becomes a function call in the hottest loop). Exact for |x| < 2³¹.
#[inline]
pub(crate) fn ifloor(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) > x {
        i - 1
    } else {
        i
    }
}

/// `floor(x)` (see [`ifloor`]).
#[inline]
pub(crate) fn ffloor(x: f32) -> f32 {
    ifloor(x) as f32
}

/// `x mod 1` in `[0, 1)`.
#[inline]
pub(crate) fn fract(x: f32) -> f32 {
    x - ffloor(x)
}

#[inline]
fn smooth(t: f32) -> f32 {
    t * t * (3.0 - 2.0 * t)
}

/// Random lattice values for [`vnoise`]: 256 × 256 bytes, built at compile time from the same
/// hash as [`rnd`], so noise costs four table reads instead of four hashes.
static LATTICE: [u8; 65536] = lattice();

const fn lattice() -> [u8; 65536] {
    let mut t = [0u8; 65536];
    let mut i = 0;
    while i < 65536 {
        let mut h = (i as u32).wrapping_mul(0x8da6_b343) ^ 0x2545_f491;
        h ^= h >> 16;
        h = h.wrapping_mul(0x7feb_352d);
        h ^= h >> 15;
        h = h.wrapping_mul(0x846c_a68b);
        h ^= h >> 16;
        t[i] = (h >> 24) as u8;
        i += 1;
    }
    t
}

/// Value noise in [0, 1] with unit lattice spacing (period 256 lattice cells; the seed shifts
/// the lattice so different seeds give unrelated patterns).
#[inline]
pub(crate) fn vnoise(x: f32, y: f32, seed: u32) -> f32 {
    let (ix, iy) = (ifloor(x), ifloor(y));
    let (tx, ty) = (smooth(x - ix as f32), smooth(y - iy as f32));
    let sh = seed.wrapping_mul(0x9e37_79b9);
    let (ox, oy) = ((sh >> 8) as i32, (sh >> 20) as i32);
    let x0 = (ix.wrapping_add(ox) & 255) as usize;
    let y0 = (iy.wrapping_add(oy) & 255) as usize;
    let x1 = (x0 + 1) & 255;
    let y1 = (y0 + 1) & 255;
    let l = |x: usize, y: usize| LATTICE[(y << 8) | x] as f32;
    let (a, b, c, d) = (l(x0, y0), l(x1, y0), l(x0, y1), l(x1, y1));
    let top = a + (b - a) * tx;
    let bot = c + (d - c) * tx;
    (top + (bot - top) * ty) * (1.0 / 255.0)
}

/// How much of a pattern with `freq` cycles per metre survives a footprint of `fp` metres:
/// 1 when a cycle spans ≥ 4 px, 0 below ~1.5 px.
#[inline]
pub(crate) fn lod(freq: f32, fp: f32) -> f32 {
    (1.6 - 2.4 * freq * fp).clamp(0.0, 1.0)
}

/// Band-limited noise in [-1, 1]: octaves of value noise from `freq` upwards (gain 0.55, lacunarity
/// 2.03), each faded by [`lod`]; octaves that are faded out entirely are not evaluated.
#[inline]
pub(crate) fn fbm(x: f32, y: f32, freq: f32, octaves: u32, fp: f32, seed: u32) -> f32 {
    let mut sum = 0.0;
    let mut amp = 1.0;
    let mut f = freq;
    let mut norm = 0.0;
    for o in 0..octaves {
        norm += amp;
        let w = lod(f, fp);
        if w > 0.0 {
            sum += amp * w * (vnoise(x * f, y * f, seed.wrapping_add(o * 101)) * 2.0 - 1.0);
        }
        amp *= 0.55;
        f *= 2.03;
    }
    sum / norm
}

/// Fine per-cell grain in [-1, 1] (cells of `cell` metres), faded with distance.
#[inline]
pub(crate) fn grain(x: f32, y: f32, cell: f32, fp: f32, seed: u32) -> f32 {
    let w = lod(0.5 / cell, fp);
    if w <= 0.0 {
        return 0.0;
    }
    let inv = 1.0 / cell;
    w * (rnd(ifloor(x * inv), ifloor(y * inv), seed) * 2.0 - 1.0)
}

/// Coverage in [0, 1] of lines of `width` metres repeating every `period` metres (centred at
/// multiples of `period`), box-filtered over the footprint so far-away lines turn to their
/// mean grey instead of flickering.
#[inline]
pub(crate) fn lines(x: f32, period: f32, width: f32, fp: f32) -> f32 {
    // Reciprocals of constants fold at the (inlined) call sites; one division per call.
    let ip = 1.0 / period;
    let mean = width * ip;
    if fp > period * 0.5 {
        return mean;
    }
    let d = (fract(x * ip + 0.5) - 0.5).abs() * period;
    let half = width * 0.5 + fp * 0.5;
    if d >= half {
        // Outside the line's reach: only the far-distance fade towards the mean remains.
        let fade = fp * ip * 2.0;
        return mean * fade * fade;
    }
    let ifp = 1.0 / fp.max(1e-4);
    let cov = ((half - d) * ifp).clamp(0.0, 1.0).min(width * ifp).min(1.0);
    let fade = (fp * ip * 2.0).min(1.0);
    cov + (mean - cov) * fade * fade
}

/// Coverage of one line of `width` metres centred at `x = 0` (see [`lines`]).
#[inline]
pub(crate) fn line1(x: f32, width: f32, fp: f32) -> f32 {
    let half = (width + fp) * 0.5;
    let d = x.abs();
    if d >= half {
        return 0.0;
    }
    let ifp = 1.0 / fp.max(1e-4);
    ((half - d) * ifp).min(width * ifp).min(1.0)
}

/// Coverage of the box `[x0, x1] × [y0, y1]`, soft over the footprint.
#[inline]
pub(crate) fn rect(x: f32, y: f32, x0: f32, x1: f32, y0: f32, y1: f32, fp: f32) -> f32 {
    let h = fp.max(1e-4) * 0.5;
    if x < x0 - h || x > x1 + h || y < y0 - h || y > y1 + h {
        return 0.0;
    }
    let ih = 1.0 / fp.max(1e-4);
    let cx = ((x - x0) * ih + 0.5).min((x1 - x) * ih + 0.5).clamp(0.0, 1.0);
    let cy = ((y - y0) * ih + 0.5).min((y1 - y) * ih + 0.5).clamp(0.0, 1.0);
    cx * cy
}

/// Coverage of a disc.
#[inline]
pub(crate) fn disc(x: f32, y: f32, cx: f32, cy: f32, r: f32, fp: f32) -> f32 {
    let reach = r + fp;
    let d2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
    if d2 > reach * reach {
        return 0.0;
    }
    ((r - d2.sqrt()) / fp.max(1e-4) + 0.5).clamp(0.0, 1.0)
}

#[inline]
pub(crate) fn mix(a: Rgb, b: Rgb, t: f32) -> Rgb {
    [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t]
}

#[inline]
pub(crate) fn scale(a: Rgb, s: f32) -> Rgb {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline]
pub(crate) fn add(a: Rgb, d: f32) -> Rgb {
    [a[0] + d, a[1] + d, a[2] + d]
}

/// A colour from a palette picked by hash.
#[inline]
pub(crate) fn pick(palette: &[Rgb], h: u32) -> Rgb {
    palette[(h as usize) % palette.len()]
}

/// Pixel font: a pseudo-glyph of 3×5 cells chosen by hash; returns ink coverage in a text band
/// with letters `lw` metres wide (incl. spacing), `lh` tall, starting at `(x0, y0)`.
#[inline]
pub(crate) fn text(x: f32, y: f32, lw: f32, lh: f32, fp: f32, seed: u32) -> f32 {
    if x < 0.0 || y < 0.0 || y >= lh {
        return 0.0;
    }
    // Too small to resolve: mean ink.
    if fp * 4.0 > lh / 5.0 {
        return 0.35 * lod(1.0 / lw, fp * 0.5);
    }
    let letter = ffloor(x / lw);
    let lx = (x - letter * lw) / lw * 4.0; // 3 columns + 1 spacing
    let ly = y / lh * 5.0;
    if lx >= 3.0 {
        return 0.0;
    }
    let (cx, cy) = (ifloor(lx), ifloor(ly));
    let h = hash3(letter as i32, 7, seed);
    // Space between words now and then.
    if h.is_multiple_of(7) {
        return 0.0;
    }
    let bit = cy * 3 + cx;
    let on = (h >> (bit % 30)) & 1 == 1 || (cx == 0 && h & 0x4000_0000 != 0);
    if !on {
        return 0.0;
    }
    let cell_w = lw / 4.0;
    let cell_h = lh / 5.0;
    let fx = x - letter * lw - cx as f32 * cell_w;
    let fy = y - cy as f32 * cell_h;
    rect(fx, fy, 0.0, cell_w, 0.0, cell_h, fp)
}
