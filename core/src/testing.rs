//! Test fixtures shared by core's unit tests, its benches and the other crates' tests: the
//! KITTI stereo camera, seeded generators, procedural images and a golden-hash accumulator.
//!
//! One copy of each, so a test's data cannot drift from the copy another test was tuned on.
//! Every fixture is a pure function of its arguments: the same bytes on every target and run.
//! No paper section; these only feed the code that implements one.
//!
//! Compiled under `cfg(test)` or the `testing` feature, which other crates and core's benches
//! enable from `[dev-dependencies]` only: no firmware or release binary contains it. Like the
//! rest of core it is `no_std` and allocation-free; images are written into caller slices.
//!
//! **Memory.** Two rows of at most [`MAX_WIDTH`] bytes on the stack while an image is
//! blurred; nothing else.

use crate::geom::StereoCamera;
use crate::ransac::XorShift64;

/// Runs `f` on a thread with a 1 GiB stack and returns its result: the map, tracker and
/// localiser are tens of MiB of fixed arrays, which the ECU keeps in static memory and a test
/// builds on its stack. The stack is only reserved; pages are touched as the test uses them.
/// A panic in `f` fails the calling test. Unit tests only (it needs `std`): under the `testing`
/// feature this module builds `no_std`.
#[cfg(test)]
pub fn on_big_stack<T: Send + 'static, F: FnOnce() -> T + Send + 'static>(f: F) -> T {
    std::thread::Builder::new().stack_size(1 << 30).spawn(f).unwrap().join().unwrap()
}

/// KITTI odometry 00–02 grey pair (`P0`/`P1` of `calib.txt`): `fx = fy = 718.856 px`,
/// principal point `(607.19, 185.22) px`, baseline 0.537 m.
pub const fn kitti_cam() -> StereoCamera {
    StereoCamera { fx_px: 718.856, fy_px: 718.856, cx_px: 607.19, cy_px: 185.22, baseline_m: 0.537 }
}

/// KITTI-like intrinsics with `fx != fy` and `cx != cy`, so a test that swaps the image axes
/// somewhere fails.
pub const fn asymmetric_cam() -> StereoCamera {
    StereoCamera { fx_px: 718.0, fy_px: 702.0, cx_px: 607.2, cy_px: 185.2, baseline_m: 0.537 }
}

/// Seeded 64-bit generator: [`XorShift64`] (the stream RANSAC draws from) with the draws tests
/// need.
#[derive(Clone, Copy, Debug)]
pub struct Rng(XorShift64);

impl Rng {
    /// A generator; a zero seed is replaced as [`XorShift64::new`] does.
    pub const fn new(seed: u64) -> Self {
        Self(XorShift64::new(seed))
    }

    /// Next raw value.
    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform index in `0..n`; `0` for `n == 0`.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }

    /// Uniform integer in `lo..=hi` (`lo <= hi`).
    pub fn int(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.next_u64() % (hi - lo + 1) as u64) as i64
    }

    /// Uniform in `[0, 1)` from the top 53 bits.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[-1, 1)` from the top 53 bits.
    pub fn signed(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// A random 256-bit ORB descriptor (one draw per byte, low byte kept).
    pub fn descriptor(&mut self) -> [u8; 32] {
        let mut d = [0u8; 32];
        for b in d.iter_mut() {
            *b = self.next_u64() as u8;
        }
        d
    }
}

/// Seeded 32-bit xorshift (13, 17, 5), the generator of the image fixtures.
#[derive(Clone, Copy, Debug)]
pub struct Rng32(u32);

impl Rng32 {
    /// A generator; a zero seed (xorshift would stay at zero) is replaced.
    pub const fn new(seed: u32) -> Self {
        Self(if seed == 0 { 0x2545_f491 } else { seed })
    }

    /// Next raw value.
    pub fn next_u32(&mut self) -> u32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        self.0
    }

    /// `next_u32() % n` (`n > 0`).
    pub fn below(&mut self, n: u32) -> u32 {
        self.next_u32() % n
    }

    /// Draws `n` values and forgets them.
    fn skip(&mut self, n: usize) {
        for _ in 0..n {
            self.next_u32();
        }
    }
}

/// Widest image the fixtures blur (the blur keeps two rows of this many bytes).
pub const MAX_WIDTH: usize = 4096;

/// Uniform 8-bit noise (the top byte of each [`Rng32`] draw from `seed`): a FAST corner at almost
/// every pixel.
pub fn noise(img: &mut [u8], seed: u32) {
    let mut rng = Rng32::new(seed);
    for p in img {
        *p = (rng.next_u32() >> 24) as u8;
    }
}

/// Random overlapping flat rectangles (4–39 px, `w·h/300` of them) on grey 128, then
/// [`box_blur_3x3`]: corners at every scale, uniform over the frame. Draws from
/// `Rng32::new(seed | 1)`.
///
/// # Panics
/// If `img` is shorter than `w·h`, or `w > MAX_WIDTH`.
pub fn rect_texture(img: &mut [u8], w: usize, h: usize, seed: u32) {
    let img = &mut img[..w * h];
    let mut rng = Rng32::new(seed | 1);
    img.fill(128);
    for _ in 0..w * h / 300 {
        let rw = 4 + rng.below(36) as usize;
        let rh = 4 + rng.below(36) as usize;
        let x0 = rng.below(w as u32) as usize;
        let y0 = rng.below(h as u32) as usize;
        let v = rng.below(256) as u8;
        for y in y0..(y0 + rh).min(h) {
            img[y * w + x0..y * w + (x0 + rw).min(w)].fill(v);
        }
    }
    box_blur_3x3(img, w, h);
}

/// Most octaves [`value_noise_texture`] takes.
pub const MAX_OCTAVES: usize = 4;

/// Value noise — random levels on a grid of `cell` px per octave, bilinearly interpolated and
/// averaged over the octaves — under `w·h/400` random rectangles (3–32 px) blended 3:1 over it,
/// then [`box_blur_3x3`]: unique texture everywhere (a stereo matcher finds one minimum) and
/// corners at every scale. Draws from `Rng32::new(seed | 1)`: each octave's grid of
/// `(w/cell + 2) × (h/cell + 2)` levels row by row, then the rectangles.
///
/// # Panics
/// If `img` is shorter than `w·h`, `w > MAX_WIDTH`, `cells` is empty or longer than
/// [`MAX_OCTAVES`], or a cell is 0.
pub fn value_noise_texture(img: &mut [u8], w: usize, h: usize, seed: u32, cells: &[u32]) {
    assert!(!cells.is_empty() && cells.len() <= MAX_OCTAVES, "1..={MAX_OCTAVES} octaves");
    let img = &mut img[..w * h];
    let mut rng = Rng32::new(seed | 1);
    // The grid is never stored: a grid row is a run of `gw` draws, so two cursors walking grid
    // rows `gy` and `gy + 1` alongside the pixel row give the four corners of every pixel.
    let mut octaves = [Octave::new(1, w, rng); MAX_OCTAVES]; // slots past `cells.len()` unused
    for (o, &cell) in octaves.iter_mut().zip(cells) {
        *o = Octave::new(cell, w, rng);
        rng.skip(o.gw * (h / cell as usize + 2));
    }
    let octaves = &mut octaves[..cells.len()];
    for y in 0..h {
        for o in octaves.iter_mut() {
            o.start_row(y);
        }
        for x in 0..w {
            let acc: u32 = octaves.iter_mut().map(|o| o.level(x, y)).sum();
            img[y * w + x] = (acc / cells.len() as u32) as u8;
        }
    }
    for _ in 0..w * h / 400 {
        let (rw, rh) = (3 + rng.below(30) as usize, 3 + rng.below(30) as usize);
        let (x0, y0) = (rng.below(w as u32) as usize, rng.below(h as u32) as usize);
        let v = rng.below(256) as u16;
        for y in y0..(y0 + rh).min(h) {
            for p in &mut img[y * w + x0..y * w + (x0 + rw).min(w)] {
                *p = ((u16::from(*p) + 3 * v) / 4) as u8;
            }
        }
    }
    box_blur_3x3(img, w, h);
}

/// One octave of [`value_noise_texture`], streamed along the pixel rows.
#[derive(Clone, Copy)]
struct Octave {
    cell: u32,
    /// Grid columns (`w/cell + 2`): the draws of one grid row.
    gw: usize,
    /// Generator at the start of grid row `y / cell`.
    row: Rng32,
    /// Cursors in grid rows `y / cell` and `y / cell + 1`.
    top: Rng32,
    bot: Rng32,
    /// Corner levels `[top-left, top-right, bottom-left, bottom-right]` of the current grid cell.
    g: [u32; 4],
}

impl Octave {
    fn new(cell: u32, w: usize, start: Rng32) -> Self {
        assert!(cell > 0, "zero cell size");
        let gw = w / cell as usize + 2;
        Self { cell, gw, row: start, top: start, bot: start, g: [0; 4] }
    }

    fn start_row(&mut self, y: usize) {
        if y > 0 && y.is_multiple_of(self.cell as usize) {
            self.row.skip(self.gw);
        }
        self.top = self.row;
        self.bot = self.row;
        self.bot.skip(self.gw);
        let (t0, b0) = (self.top.below(256), self.bot.below(256));
        self.g = [t0, self.top.below(256), b0, self.bot.below(256)];
    }

    /// Interpolated level at `(x, y)`; `x` runs `0..w` after [`Self::start_row`].
    fn level(&mut self, x: usize, y: usize) -> u32 {
        let c = self.cell;
        if x > 0 && x.is_multiple_of(c as usize) {
            self.g = [self.g[1], self.top.below(256), self.g[3], self.bot.below(256)];
        }
        let (fx, fy) = ((x % c as usize) as u32, (y % c as usize) as u32);
        let [g00, g10, g01, g11] = self.g;
        let top = g00 * (c - fx) + g10 * fx;
        let bot = g01 * (c - fx) + g11 * fx;
        (top * (c - fy) + bot * fy) / (c * c)
    }
}

/// 3×3 box blur (integer mean, truncated) of every pixel not on the border, in place.
///
/// # Panics
/// If `img` is shorter than `w·h`, or `w > MAX_WIDTH`.
pub fn box_blur_3x3(img: &mut [u8], w: usize, h: usize) {
    assert!(w <= MAX_WIDTH, "width {w} > MAX_WIDTH {MAX_WIDTH}");
    let img = &mut img[..w * h];
    if w < 3 || h < 3 {
        return;
    }
    // Row y is overwritten as it is blurred while row y + 1 still needs its original: keep
    // the unblurred rows y - 1 (`up`) and y (`mid`).
    let mut up = [0u8; MAX_WIDTH];
    let mut mid = [0u8; MAX_WIDTH];
    up[..w].copy_from_slice(&img[..w]);
    for y in 1..h - 1 {
        mid[..w].copy_from_slice(&img[y * w..(y + 1) * w]);
        let (row, down) = img[y * w..(y + 2) * w].split_at_mut(w);
        for x in 1..w - 1 {
            let s: u32 = [&up[..w], &mid[..w], &*down]
                .iter()
                .map(|r| r[x - 1..x + 2].iter().map(|&p| u32::from(p)).sum::<u32>())
                .sum();
            row[x] = (s / 9) as u8;
        }
        core::mem::swap(&mut up, &mut mid);
    }
}

/// `dst` = `src` (an `n × n` image) rotated 90° clockwise: `dst(n-1-y, x) = src(x, y)`.
///
/// # Panics
/// If `src` or `dst` is shorter than `n·n`.
pub fn rotate_90_cw(src: &[u8], dst: &mut [u8], n: usize) {
    for y in 0..n {
        for x in 0..n {
            dst[x * n + (n - 1 - y)] = src[y * n + x];
        }
    }
}

/// A rectified stereo pair cut from a texture `tw` px wide: `left(x, y) = t(x, y)` and
/// `right(x, y) = t(x + d(y), y)`, so every left pixel has its match `d(y)` px to its left in
/// the right image (the texture supplies what lies beyond the left image's right edge).
/// `left` and `right` are `w` px wide and as many rows high as they hold.
///
/// # Panics
/// If `w + d(y) > tw` on some row, or `texture` has fewer rows than `left`.
pub fn stereo_pair(
    texture: &[u8],
    tw: usize,
    left: &mut [u8],
    right: &mut [u8],
    w: usize,
    d: impl Fn(usize) -> usize,
) {
    for (y, (l, r)) in left.chunks_exact_mut(w).zip(right.chunks_exact_mut(w)).enumerate() {
        let (t, dy) = (&texture[y * tw..(y + 1) * tw], d(y));
        l.copy_from_slice(&t[..w]);
        r.copy_from_slice(&t[dy..dy + w]);
    }
}

/// Renders what a pinhole camera at `eye` (metres, camera axes: x right, y down, z forward; no
/// rotation) sees of a textured corridor: a floor 1.6 m below the eye's start height (y = 1.6),
/// walls at x = ±5 m, an end wall at z = 80 m; above the walls' 6 m height is a flat grey sky.
/// Each surface carries 0.3 m blocks of hashed grey levels (20..=235) with a 0.075 m sub-block
/// layer of ±24, so corners exist at every pyramid level and at every distance. The image is
/// `w × h`, intrinsics `fx = fy`, principal point `(cx, cy)`; any size, so tests can check the
/// localiser at frame sizes other than KITTI's. Pixel centres are sampled once (no
/// anti-aliasing): the same bytes on every target.
///
/// # Panics
/// If `img` is shorter than `w·h`.
#[allow(clippy::too_many_arguments)]
pub fn corridor(img: &mut [u8], w: usize, h: usize, fx: f64, cx: f64, cy: f64, eye: [f64; 3]) {
    const FLOOR_Y: f64 = 1.6;
    const WALL_X: f64 = 5.0;
    const WALL_TOP_Y: f64 = -4.4;
    const END_Z: f64 = 80.0;
    fn hash(a: i64, b: i64, c: u64) -> u64 {
        let mut z = (a as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ (b as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            ^ c.wrapping_mul(0x1656_67b1_9e37_79f9);
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    let shade = |s: f64, t: f64, surface: u64| -> u8 {
        let (bs, bt) = (libm::floor(s / 0.3) as i64, libm::floor(t / 0.3) as i64);
        let (fs, ft) = (libm::floor(s / 0.075) as i64, libm::floor(t / 0.075) as i64);
        let base = 20 + (hash(bs, bt, surface) % 216) as i64;
        let fine = (hash(fs, ft, surface + 8) % 49) as i64 - 24;
        (base + fine).clamp(0, 255) as u8
    };
    for (i, p) in img[..w * h].iter_mut().enumerate() {
        let (u, v) = ((i % w) as f64, (i / w) as f64);
        let d = [(u - cx) / fx, (v - cy) / fx, 1.0];
        let mut best = (f64::INFINITY, 200u8);
        let mut hit = |t: f64, value: &dyn Fn([f64; 3]) -> Option<u8>| {
            if t > 1e-6 && t < best.0 {
                let q = [eye[0] + t * d[0], eye[1] + t * d[1], eye[2] + t * d[2]];
                if let Some(g) = value(q) {
                    best = (t, g);
                }
            }
        };
        if d[1] > 0.0 {
            hit((FLOOR_Y - eye[1]) / d[1], &|q| Some(shade(q[0], q[2], 1)));
        }
        if d[0] != 0.0 {
            let x = if d[0] > 0.0 { WALL_X } else { -WALL_X };
            let surface = if d[0] > 0.0 { 2 } else { 3 };
            hit((x - eye[0]) / d[0], &|q| (q[1] >= WALL_TOP_Y).then(|| shade(q[2], q[1], surface)));
        }
        hit((END_Z - eye[2]) / d[2], &|q| (q[1] >= WALL_TOP_Y).then(|| shade(q[0], q[1], 4)));
        *p = best.1;
    }
}

/// FNV-1a (64-bit) over byte slices, for golden hashes of a test's whole output.
#[derive(Clone, Copy, Debug)]
pub struct Fnv1a(u64);

impl Fnv1a {
    /// The empty hash (the FNV offset basis).
    pub const fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }

    /// Hashes `bytes` after everything eaten before.
    pub fn eat(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }

    /// The hash so far.
    pub const fn finish(self) -> u64 {
        self.0
    }
}

impl Default for Fnv1a {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec;

    fn fnv(bytes: &[u8]) -> u64 {
        let mut h = Fnv1a::new();
        h.eat(bytes);
        h.finish()
    }

    /// The images as the per-file copies these fixtures replaced drew them (checked bit for
    /// bit against those copies when they were merged here): tests were tuned on these bytes.
    #[test]
    fn images_are_the_pinned_bytes() {
        let mut img = vec![0u8; 640 * 480];
        rect_texture(&mut img, 640, 480, 7);
        assert_eq!(fnv(&img), 0xee51_ec37_7873_c633, "rect_texture (orb tests)");
        let mut img = vec![0u8; 704 * 240];
        value_noise_texture(&mut img, 704, 240, 7, &[9, 4]);
        assert_eq!(fnv(&img), 0xfdf5_c0df_a1a6_1f55, "value_noise_texture (stereo tests)");
        let mut img = vec![0u8; 1305 * 376];
        value_noise_texture(&mut img, 1305, 376, 0x2545_f491, &[6]);
        assert_eq!(fnv(&img), 0x15d5_ea29_fed2_e43b, "value_noise_texture (stereo bench)");
        let mut img = vec![0u8; 1000];
        noise(&mut img, 0x1234_5678);
        assert_eq!(fnv(&img), 0xac47_3a84_17f2_a6eb, "noise (FAST tests)");
    }

    #[test]
    fn fnv1a_known_values() {
        assert_eq!(fnv(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv(b"a"), 0xaf63_dc4c_8601_ec8c);
        let mut h = Fnv1a::default();
        h.eat(b"foo");
        h.eat(b"bar");
        assert_eq!(h.finish(), fnv(b"foobar"));
    }

    #[test]
    fn generators_stay_in_range_and_follow_xorshift() {
        let mut r = Rng::new(7);
        let mut x = XorShift64::new(7);
        assert_eq!(r.next_u64(), x.next_u64());
        for _ in 0..1000 {
            assert!((0.0..1.0).contains(&r.unit()));
            assert!((-1.0..1.0).contains(&r.signed()));
            assert!((2.0..3.0).contains(&r.range(2.0, 3.0)));
            assert!((-3..=4).contains(&r.int(-3, 4)));
            assert!(r.below(5) < 5);
        }
        assert_eq!(r.below(0), 0);
        let mut s = Rng32::new(0);
        assert_ne!(s.next_u32(), 0, "a zero seed must not stick");
        assert!((0..1000).all(|_| s.below(7) < 7));
    }

    #[test]
    fn blur_rotate_and_pair_move_the_right_pixels() {
        let (w, h) = (7usize, 5usize);
        let mut img: std::vec::Vec<u8> = (0..w * h).map(|i| (i * 7) as u8).collect();
        let orig = img.clone();
        box_blur_3x3(&mut img, w, h);
        // A linear ramp is its own 3×3 mean inside; the border is untouched.
        assert_eq!(img, orig);
        let mut flat = vec![77u8; w * h];
        flat[2 * w + 3] = 86;
        box_blur_3x3(&mut flat, w, h);
        assert_eq!(flat[2 * w + 3], 78);
        assert_eq!(flat[w + 2], 78);
        assert_eq!(flat[w + 1], 77);

        let n = 3;
        let mut rot = [0u8; 9];
        rotate_90_cw(&[1, 2, 3, 4, 5, 6, 7, 8, 9], &mut rot, n);
        assert_eq!(rot, [7, 4, 1, 8, 5, 2, 9, 6, 3]);

        let t: std::vec::Vec<u8> = (0..2 * 6).map(|i| i as u8).collect();
        let (mut l, mut r) = ([0u8; 8], [0u8; 8]);
        stereo_pair(&t, 6, &mut l, &mut r, 4, |y| y + 1);
        assert_eq!(l, [0, 1, 2, 3, 6, 7, 8, 9]);
        assert_eq!(r, [1, 2, 3, 4, 8, 9, 10, 11]);
    }
}
