//! The synthetic street: a road centreline of straights and clothoid-eased curves, the static
//! world along it (road, kerbs, pavements, buildings, trees, poles, signs, fences, parked cars),
//! the ego vehicle's motion, and the scripted traffic of each dynamics level.
//!
//! World frame `G`: x right, y **down**, z forward at the start, ground at `y = 0` (KITTI's
//! camera axes), so a camera pose is a rotation whose columns are the camera axes in `G`.
//! Everything is a pure function of the seed (and of the frame time for agents).

use super::material::{FacadeStyle, Mat, PPart, VPart};
use super::texture::Rgb;
use super::Dynamics;

/// A point or direction in the world frame (metres).
pub(crate) type V3 = [f64; 3];

#[inline]
pub(crate) fn add3(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline]
pub(crate) fn sub3(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
pub(crate) fn mul3(a: V3, k: f64) -> V3 {
    [a[0] * k, a[1] * k, a[2] * k]
}
#[inline]
pub(crate) fn dot3(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
pub(crate) fn cross3(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
#[inline]
pub(crate) fn norm3(a: V3) -> V3 {
    let n = dot3(a, a).sqrt();
    if n > 0.0 {
        mul3(a, 1.0 / n)
    } else {
        a
    }
}

const DOWN: V3 = [0.0, 1.0, 0.0];
const UP: V3 = [0.0, -1.0, 0.0];

/// CamVid 11-class ids (the label images' values).
pub(crate) mod class {
    pub const SKY: u8 = 0;
    pub const BUILDING: u8 = 1;
    pub const POLE: u8 = 2;
    pub const ROAD: u8 = 3;
    pub const PAVEMENT: u8 = 4;
    pub const TREE: u8 = 5;
    pub const SIGN: u8 = 6;
    pub const FENCE: u8 = 7;
    pub const CAR: u8 = 8;
    pub const PEDESTRIAN: u8 = 9;
    pub const BICYCLIST: u8 = 10;
}

/// How surface coordinates `(u, v)` are computed from a 3D point on a primitive.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Map {
    /// `u = (P − o)·eu`, `v = (P − o)·ev`.
    Affine { o: V3, eu: V3, ev: V3 },
    /// A road strip between two cross-sections of the centreline (points `c`, tangents `t`,
    /// right normals `n` at arc lengths `s0`, `s1`): `u` = arc length, exact and continuous
    /// across strips; `v` = lateral offset.
    Strip { c: [V3; 2], t: [V3; 2], n: [V3; 2], s: [f64; 2] },
}

/// One planar convex polygon (3 or 4 vertices) of the scene.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Prim {
    /// Vertices in the world frame.
    pub v: [V3; 4],
    /// Number of vertices used.
    pub n: u8,
    /// Surface coordinates.
    pub map: Map,
    /// Look.
    pub mat: Mat,
    /// CamVid class id.
    pub class: u8,
    /// Part of a moving object.
    pub dynamic: bool,
    /// Diffuse lighting factor (sun + sky), fixed per face.
    pub light: f32,
}

/// A tiny deterministic generator (SplitMix64).
#[derive(Clone, Debug)]
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed ^ 0x5eed_1234_abcd_0042)
    }
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub(crate) fn f(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / 9_007_199_254_740_992.0)
    }
    pub(crate) fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.f()
    }
    pub(crate) fn chance(&mut self, p: f64) -> bool {
        self.f() < p
    }
    pub(crate) fn u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }
}

/// Sun direction (towards the sun), world frame.
const SUN: V3 = [0.45, -0.75, 0.48];

fn light_for(normal: V3, two_sided: bool) -> f32 {
    let d = dot3(norm3(normal), norm3(SUN));
    let d = if two_sided { d.abs() } else { d.max(0.0) };
    (0.62 + 0.45 * d) as f32
}

/// Road cross-section (lateral offsets, metres; positive to the right of travel).
pub(crate) mod layout {
    /// Kerb line.
    pub const KERB: f64 = 8.6;
    /// Pavement outer edge / building line.
    pub const BUILDING: f64 = 12.6;
    /// Kerb height (m).
    pub const KERB_H: f64 = 0.12;
    /// Lane centres of the ego's direction: inner (A) and outer (B).
    pub const LANE_A: f64 = 1.6;
    /// Outer lane centre.
    pub const LANE_B: f64 = 4.8;
    /// Parking strip centre.
    pub const PARKING: f64 = 7.7;
}

/// The road centreline, sampled every [`Path::STEP`] metres.
#[derive(Clone, Debug)]
pub(crate) struct Path {
    xz: Vec<[f64; 2]>,
    psi: Vec<f64>,
    kappa: Vec<f64>,
    /// Arc lengths of intersections (on straights).
    pub junctions: Vec<f64>,
}

impl Path {
    pub(crate) const STEP: f64 = 0.5;

    /// A random centreline of at least `len` metres: straights of 50–160 m and curves of
    /// radius 45–160 m turning 20–80°, eased in and out over 12 m.
    pub(crate) fn generate(len: f64, rng: &mut Rng) -> Self {
        let mut kappa_plan: Vec<(f64, f64)> = Vec::new(); // (length, curvature)
        let mut junctions = Vec::new();
        let mut total = 0.0;
        let mut first = true;
        while total < len {
            let straight = if first { rng.range(70.0, 110.0) } else { rng.range(50.0, 160.0) };
            if straight >= 70.0 && !first {
                junctions.push(total + straight * 0.5);
            } else if first && straight >= 90.0 {
                junctions.push(total + straight * 0.8);
            }
            first = false;
            kappa_plan.push((straight, 0.0));
            total += straight;
            let r = rng.range(45.0, 160.0);
            let ang = rng.range(20.0, 80.0).to_radians();
            let sign = if rng.chance(0.5) { 1.0 } else { -1.0 };
            let arc = (r * ang).max(24.0);
            kappa_plan.push((arc, sign / r));
            total += arc;
        }
        let n = (total / Self::STEP).ceil() as usize + 2;
        let mut kappa = vec![0.0; n];
        // Piecewise-constant plan, then a 12 m moving average eases the curvature in and out
        // (a clothoid-like transition, so heading and roll stay smooth).
        let mut raw = vec![0.0; n];
        let mut s0 = 0.0;
        for (l, k) in &kappa_plan {
            let a = (s0 / Self::STEP) as usize;
            let b = (((s0 + l) / Self::STEP) as usize).min(n);
            for r in raw.iter_mut().take(b).skip(a) {
                *r = *k;
            }
            s0 += l;
        }
        let w = (12.0 / Self::STEP) as usize;
        let mut acc = 0.0;
        for i in 0..n {
            acc += raw[i];
            if i >= w {
                acc -= raw[i - w];
            }
            kappa[i] = acc / w as f64;
        }
        let mut xz = vec![[0.0; 2]; n];
        let mut psi = vec![0.0; n];
        for i in 1..n {
            let p = psi[i - 1] + kappa[i - 1] * Self::STEP;
            let mid = 0.5 * (p + psi[i - 1]);
            psi[i] = p;
            xz[i] = [xz[i - 1][0] + Self::STEP * mid.sin(), xz[i - 1][1] + Self::STEP * mid.cos()];
        }
        Self { xz, psi, kappa, junctions }
    }

    /// Length covered (m).
    pub(crate) fn len(&self) -> f64 {
        (self.xz.len() - 1) as f64 * Self::STEP
    }

    fn idx(&self, s: f64) -> (usize, f64) {
        let x = (s / Self::STEP).clamp(0.0, (self.xz.len() - 2) as f64);
        let i = x.floor() as usize;
        (i, x - i as f64)
    }

    /// Centreline point (y = 0), unit tangent and unit right normal at arc length `s`.
    pub(crate) fn frame(&self, s: f64) -> (V3, V3, V3) {
        let (i, f) = self.idx(s);
        let x = self.xz[i][0] + (self.xz[i + 1][0] - self.xz[i][0]) * f;
        let z = self.xz[i][1] + (self.xz[i + 1][1] - self.xz[i][1]) * f;
        let psi = self.psi[i] + (self.psi[i + 1] - self.psi[i]) * f;
        let (sn, cs) = psi.sin_cos();
        ([x, 0.0, z], [sn, 0.0, cs], [cs, 0.0, -sn])
    }

    /// Curvature (1/m; positive turns right) at `s`.
    pub(crate) fn kappa(&self, s: f64) -> f64 {
        let (i, f) = self.idx(s);
        self.kappa[i] + (self.kappa[i + 1] - self.kappa[i]) * f
    }

    /// Largest |curvature| over `[a, b]`.
    fn max_kappa(&self, a: f64, b: f64) -> f64 {
        let mut m: f64 = 0.0;
        let mut s = a;
        while s <= b {
            m = m.max(self.kappa(s).abs());
            s += 2.0;
        }
        m
    }

    /// World point at arc length `s`, lateral offset `lat`, height `h` above the ground.
    pub(crate) fn point(&self, s: f64, lat: f64, h: f64) -> V3 {
        let (c, _, n) = self.frame(s);
        [c[0] + lat * n[0], -h, c[2] + lat * n[2]]
    }

    fn near_junction(&self, s: f64, margin: f64) -> bool {
        self.junctions.iter().any(|j| (s - j).abs() < margin)
    }
}

/// The static scene: primitives bucketed by arc length for per-frame culling.
#[derive(Debug)]
pub(crate) struct World {
    pub path: Path,
    /// Primitives, sorted by the arc length of the bucket they belong to.
    pub prims: Vec<Prim>,
    /// `bucket_start[b]..bucket_start[b+1]` are the primitives whose anchor lies in
    /// `[b·BUCKET, (b+1)·BUCKET)` metres.
    bucket_start: Vec<usize>,
}

const BUCKET: f64 = 10.0;

/// Collects primitives with their anchor arc length.
struct Builder {
    items: Vec<(f64, Prim)>,
    anchor: f64,
}

impl Builder {
    fn push(&mut self, p: Prim) {
        self.items.push((self.anchor, p));
    }

    /// A vertical rectangle seen from outside: bottom-left `a` and bottom-right `b` on the
    /// ground plane (their y ignored), from height `h0` to `h1` above the ground.
    #[allow(clippy::too_many_arguments)]
    fn vquad(&mut self, a: V3, b: V3, h0: f64, h1: f64, mat: Mat, class: u8, dynamic: bool) {
        let right = norm3(sub3([b[0], 0.0, b[2]], [a[0], 0.0, a[2]]));
        let outward = cross3(DOWN, right);
        let v = [[a[0], -h0, a[2]], [b[0], -h0, b[2]], [b[0], -h1, b[2]], [a[0], -h1, a[2]]];
        let two = mat.is_cutout();
        self.push(Prim {
            v,
            n: 4,
            map: Map::Affine { o: [a[0], 0.0, a[2]], eu: right, ev: UP },
            mat,
            class,
            dynamic,
            light: light_for(outward, two),
        });
    }

    /// A horizontal rectangle at height `h`: corner `o`, axes `eu` (length `lu`) and `ev`
    /// (length `lv`).
    #[allow(clippy::too_many_arguments)]
    fn hquad(
        &mut self,
        o: V3,
        eu: V3,
        ev: V3,
        lu: f64,
        lv: f64,
        h: f64,
        mat: Mat,
        class: u8,
        dynamic: bool,
    ) {
        let o = [o[0], -h, o[2]];
        let v = [
            o,
            add3(o, mul3(eu, lu)),
            add3(add3(o, mul3(eu, lu)), mul3(ev, lv)),
            add3(o, mul3(ev, lv)),
        ];
        self.push(Prim {
            v,
            n: 4,
            map: Map::Affine { o, eu, ev },
            mat,
            class,
            dynamic,
            light: light_for(UP, false),
        });
    }

    /// An axis-aligned box in a local frame: bottom centre `c`, forward `f` (horizontal unit),
    /// length `l` along `f`, width `w`, from height `h0` to `h1`. `mat(face, face_width)`
    /// gives each face's material; faces: 0 front, 1 back, 2 right, 3 left, 4 top.
    #[allow(clippy::too_many_arguments)]
    fn boxed(
        &mut self,
        c: V3,
        f: V3,
        l: f64,
        w: f64,
        h0: f64,
        h1: f64,
        class: u8,
        dynamic: bool,
        mat: &dyn Fn(u8, f32) -> Option<Mat>,
    ) {
        let r = cross3(DOWN, f); // the box's right: down × forward
        let faces: [(V3, f64, f64); 4] = [
            (f, l * 0.5, w),
            (mul3(f, -1.0), l * 0.5, w),
            (r, w * 0.5, l),
            (mul3(r, -1.0), w * 0.5, l),
        ];
        for (k, (o, d, fw)) in faces.iter().enumerate() {
            let Some(m) = mat(k as u8, *fw as f32) else { continue };
            let centre = add3(c, mul3(*o, *d));
            let right = mul3(cross3(*o, DOWN), 1.0);
            let a = sub3(centre, mul3(right, fw * 0.5));
            let b = add3(centre, mul3(right, fw * 0.5));
            self.vquad(a, b, h0, h1, m, class, dynamic);
        }
        if let Some(m) = mat(4, w as f32) {
            let o = sub3(sub3(c, mul3(r, w * 0.5)), mul3(f, l * 0.5));
            self.hquad(o, r, f, w, l, h1, m, class, dynamic);
        }
    }

    /// A road-like strip of the centreline between `s0` and `s1`, lateral `[a, b]`, height `h`.
    #[allow(clippy::too_many_arguments)]
    fn strip(
        &mut self,
        path: &Path,
        s0: f64,
        s1: f64,
        a: f64,
        b: f64,
        h: f64,
        mat: Mat,
        class: u8,
    ) {
        let (c0, t0, n0) = path.frame(s0);
        let (c1, t1, n1) = path.frame(s1);
        let p = |c: V3, n: V3, l: f64| [c[0] + n[0] * l, -h, c[2] + n[2] * l];
        let v = [p(c0, n0, a), p(c0, n0, b), p(c1, n1, b), p(c1, n1, a)];
        let c0 = [c0[0], -h, c0[2]];
        let c1 = [c1[0], -h, c1[2]];
        self.push(Prim {
            v,
            n: 4,
            map: Map::Strip { c: [c0, c1], t: [t0, t1], n: [n0, n1], s: [s0, s1] },
            mat,
            class,
            dynamic: false,
            light: light_for(UP, false),
        });
    }
}

impl World {
    /// Builds the static world along a fresh path of at least `len` metres. `kerb_rows` fills
    /// the parking strips' empty slots too (rows of parked cars, as in KITTI's residential
    /// streets) from a generator of their own, so the street is otherwise the same.
    pub(crate) fn build(len: f64, rng: &mut Rng, kerb_rows: bool) -> Self {
        let path = Path::generate(len + 60.0, rng);
        let mut b = Builder { items: Vec::new(), anchor: 0.0 };
        let total = path.len() - 2.0;
        let seg = 2.0;
        let mut s = 0.0;
        let zebra = |s: f64| path.junctions.iter().any(|j| s >= j - 12.0 && s < j - 8.0);
        while s + seg <= total {
            b.anchor = s;
            b.strip(
                &path,
                s,
                s + seg,
                -layout::KERB,
                layout::KERB,
                0.0,
                Mat::Road { zebra: zebra(s) },
                class::ROAD,
            );
            for side in [-1.0, 1.0] {
                if path.near_junction(s + seg * 0.5, 7.0) {
                    continue;
                }
                let (k, pb) = (layout::KERB, layout::BUILDING);
                let (a, bb) = if side > 0.0 { (k, pb) } else { (-pb, -k) };
                b.strip(&path, s, s + seg, a, bb, layout::KERB_H, Mat::Pavement, class::PAVEMENT);
                // Keep the yard short of the centre of curvature on the inner side of a curve.
                let kk = path.kappa(s).abs().max(path.kappa(s + seg).abs());
                let inner = path.kappa(s) * side > 0.0;
                let far = if inner && kk > 1e-4 { (0.7 / kk).min(45.0) } else { 45.0 };
                let (a, bb) = if side > 0.0 { (pb, far) } else { (-far, -pb) };
                b.strip(&path, s, s + seg, a, bb, layout::KERB_H, Mat::Yard, class::PAVEMENT);
                // Kerb face, seen from the road.
                let p0 = path.point(s, side * k, 0.0);
                let p1 = path.point(s + seg, side * k, 0.0);
                let (l, r) = if side > 0.0 { (p1, p0) } else { (p0, p1) };
                b.vquad(l, r, 0.0, layout::KERB_H, Mat::Kerb, class::PAVEMENT, false);
            }
            s += seg;
        }
        for &j in &path.junctions.clone() {
            b.anchor = j;
            let (c, t, n) = path.frame(j);
            for side in [-1.0f64, 1.0] {
                let eu = mul3(n, side);
                let o = add3(add3(c, mul3(eu, layout::KERB)), mul3(t, -7.0));
                b.hquad(o, eu, t, 50.0, 14.0, 0.0, Mat::SideRoad, class::ROAD, false);
                // Buildings closing the view down the side street.
                let far = add3(c, mul3(eu, 62.0));
                let st = facade_style(rng, 40.0);
                b.boxed(
                    far,
                    eu,
                    12.0,
                    40.0,
                    0.0,
                    rng.range(10.0, 24.0),
                    class::BUILDING,
                    false,
                    &|face, _| (face == 1).then_some(Mat::Facade(st)),
                );
                // Traffic lights at the corners.
                let pole =
                    add3(add3(c, mul3(n, side * (layout::KERB + 0.8))), mul3(t, -7.5 * side));
                traffic_light(&mut b, pole, t, side, rng.u32() % 3);
            }
        }
        for side in [-1.0f64, 1.0] {
            street_side(&mut b, &path, side, total, rng, kerb_rows);
        }
        b.items.sort_by(|x, y| x.0.total_cmp(&y.0));
        let nb = (total / BUCKET).ceil() as usize + 2;
        let mut bucket_start = vec![0usize; nb + 1];
        let mut prims = Vec::with_capacity(b.items.len());
        let mut bi = 0;
        for (anchor, p) in b.items {
            let bucket = ((anchor / BUCKET).floor().max(0.0) as usize).min(nb - 1);
            while bi < bucket {
                bi += 1;
                bucket_start[bi] = prims.len();
            }
            prims.push(p);
        }
        while bi < nb {
            bi += 1;
            bucket_start[bi] = prims.len();
        }
        Self { path, prims, bucket_start }
    }

    /// Indices of the primitives anchored in `[a, b)` metres of arc length.
    pub(crate) fn range(&self, a: f64, b: f64) -> core::ops::Range<usize> {
        let nb = self.bucket_start.len() - 1;
        let ba = ((a / BUCKET).floor().max(0.0) as usize).min(nb);
        let bb = ((b / BUCKET).ceil().max(0.0) as usize).min(nb);
        self.bucket_start[ba]..self.bucket_start[bb]
    }
}

fn facade_style(rng: &mut Rng, len: f64) -> FacadeStyle {
    let kind = (rng.u32() % 3) as u8;
    let base: Rgb = match kind {
        0 => [[150.0, 80.0, 60.0], [120.0, 65.0, 50.0], [170.0, 120.0, 90.0]]
            [(rng.u32() % 3) as usize],
        1 => [
            [210.0, 200.0, 180.0],
            [190.0, 170.0, 140.0],
            [200.0, 205.0, 200.0],
            [220.0, 190.0, 150.0],
            [170.0, 170.0, 165.0],
        ][(rng.u32() % 5) as usize],
        _ => [[180.0, 170.0, 150.0], [140.0, 135.0, 130.0]][(rng.u32() % 2) as usize],
    };
    let frame: Rgb =
        [[235.0, 235.0, 230.0], [70.0, 60.0, 50.0], [60.0, 65.0, 70.0]][(rng.u32() % 3) as usize];
    FacadeStyle {
        base,
        kind,
        floor_h: rng.range(2.9, 3.5) as f32,
        ground_h: rng.range(3.4, 4.4) as f32,
        bay: rng.range(2.4, 3.6) as f32,
        win: [rng.range(1.0, 1.6) as f32, rng.range(1.3, 1.8) as f32],
        shop: rng.chance(0.45),
        frame,
        len: len as f32,
        seed: rng.u32(),
    }
}

fn traffic_light(b: &mut Builder, base: V3, t: V3, side: f64, state: u32) {
    // Faces the traffic that approaches it: on the right side that is our direction (−t).
    let face = if side > 0.0 { mul3(t, -1.0) } else { t };
    b.boxed(base, face, 0.14, 0.14, 0.0, 3.6, class::POLE, false, &|_, _| {
        Some(Mat::Metal { base: [90.0, 92.0, 95.0] })
    });
    let head = add3(base, mul3(face, 0.2));
    b.boxed(head, face, 0.25, 0.35, 3.0, 4.0, class::SIGN, false, &|f, _| {
        Some(if f == 0 {
            Mat::TrafficLight { state: state as u8 }
        } else {
            Mat::Metal { base: [40.0, 42.0, 40.0] }
        })
    });
}

fn tree(b: &mut Builder, base: V3, t: V3, rng: &mut Rng) {
    let h = rng.range(2.2, 3.4);
    b.boxed(base, t, 0.32, 0.32, 0.0, h + 1.0, class::TREE, false, &|_, _| Some(Mat::Bark));
    let (cw, ch) = (rng.range(3.5, 5.5), rng.range(3.5, 5.0));
    let seed = rng.u32();
    let rot = rng.range(0.0, core::f64::consts::PI);
    for k in 0..2 {
        let a = rot + k as f64 * core::f64::consts::FRAC_PI_2;
        let d = [a.cos(), 0.0, a.sin()];
        let p0 = sub3(base, mul3(d, cw * 0.5));
        let p1 = add3(base, mul3(d, cw * 0.5));
        let mat = Mat::Leaves { size: [cw as f32, ch as f32], seed: seed.wrapping_add(k) };
        // Leaves' v runs from the crown bottom: shift by the crown base height.
        let mut p = Prim {
            v: [
                [p0[0], -h, p0[2]],
                [p1[0], -h, p1[2]],
                [p1[0], -h - ch, p1[2]],
                [p0[0], -h - ch, p0[2]],
            ],
            n: 4,
            map: Map::Affine { o: [p0[0], -h, p0[2]], eu: d, ev: UP },
            mat,
            class: class::TREE,
            dynamic: false,
            light: 0.9,
        };
        p.light = 0.85 + 0.1 * k as f32;
        b.push(p);
    }
}

fn street_side(
    b: &mut Builder,
    path: &Path,
    side: f64,
    total: f64,
    rng: &mut Rng,
    kerb_rows: bool,
) {
    // Buildings, parks with fences, trees, lamp posts, signs, parked cars.
    let mut s = rng.range(0.0, 8.0);
    while s < total - 30.0 {
        let mut len = rng.range(10.0, 28.0);
        // Fill up to the next junction's clearance, then jump over it.
        if let Some(&j) = path.junctions.iter().find(|&&j| j + 9.0 > s) {
            if s > j - 9.0 {
                s = j + 9.0;
                continue;
            }
            if s + len > j - 9.0 {
                len = j - 9.0 - s;
                if len < 6.0 {
                    s = j + 9.0;
                    continue;
                }
            }
        }
        let sc = s + len * 0.5;
        b.anchor = sc;
        let (c, t, n) = path.frame(sc);
        let k = path.max_kappa(s, s + len);
        // A straight front on a curve cuts towards the road by up to len²·κ/8 on the inner side.
        let intrude = if k > 1e-4 { len * len * k / 8.0 * 1.3 + 0.3 } else { 0.0 };
        if rng.chance(0.16) {
            // A park: fence or hedge along the pavement, trees behind, buildings far back.
            let lat = side * (layout::BUILDING + 0.3 + intrude);
            let fkind = (rng.u32() % 2) as u8;
            let p0 = add3(c, add3(mul3(n, lat), mul3(t, -len * 0.5)));
            let p1 = add3(c, add3(mul3(n, lat), mul3(t, len * 0.5)));
            let (l, r) = if side > 0.0 { (p1, p0) } else { (p0, p1) };
            b.vquad(
                l,
                r,
                0.0,
                if fkind == 0 { 1.2 } else { 1.6 },
                Mat::Fence { kind: fkind },
                class::FENCE,
                false,
            );
            let mut ts = s + 3.0;
            while ts < s + len - 2.0 {
                let p = path.point(
                    ts,
                    side * rng.range(layout::BUILDING + 3.0, layout::BUILDING + 14.0),
                    0.0,
                );
                tree(b, p, t, rng);
                ts += rng.range(4.0, 8.0);
            }
            let back = add3(c, mul3(n, side * (layout::BUILDING + 24.0 + intrude)));
            let st = facade_style(rng, len + 10.0);
            let h = rng.range(12.0, 26.0);
            let f = mul3(n, -side);
            b.boxed(
                add3(back, mul3(n, side * 6.0)),
                f,
                12.0,
                len + 10.0,
                0.0,
                h,
                class::BUILDING,
                false,
                &|face, _| (face == 0).then_some(Mat::Facade(st)),
            );
        } else {
            let setback = if rng.chance(0.6) { 0.0 } else { rng.range(0.5, 3.0) };
            let lat = side * (layout::BUILDING + setback + intrude);
            let depth = 14.0;
            let h = rng.range(7.0, 22.0);
            let st = facade_style(rng, len);
            let wall: Rgb = [st.base[0] * 0.9, st.base[1] * 0.9, st.base[2] * 0.9];
            let wseed = rng.u32();
            let f = mul3(n, -side); // the facade faces the road
            let centre = add3(c, mul3(n, lat + side * depth * 0.5));
            b.boxed(centre, f, depth, len, 0.0, h, class::BUILDING, false, &|face, _| match face {
                0 => Some(Mat::Facade(st)),
                2 | 3 => Some(Mat::Wall { base: wall, seed: wseed }),
                _ => None,
            });
            if setback > 0.4 && rng.chance(0.5) {
                // A hedge in the front garden.
                let hc = add3(c, mul3(n, side * (layout::BUILDING + 0.4)));
                b.boxed(hc, t, len * 0.8, 0.6, 0.0, 1.1, class::TREE, false, &|_, _| {
                    Some(Mat::Hedge)
                });
            }
        }
        let gap = if rng.chance(0.3) { rng.range(2.0, 7.0) } else { 0.0 };
        s += len + gap;
    }
    // Street furniture along the pavement.
    let mut s = rng.range(2.0, 12.0);
    while s < total - 10.0 {
        b.anchor = s;
        let (_, t, _) = path.frame(s);
        if !path.near_junction(s, 9.0) {
            let r = rng.f();
            if r < 0.45 {
                let p = path.point(s, side * (layout::KERB + 1.1), layout::KERB_H);
                tree(b, p, t, rng);
            } else if r < 0.7 {
                // Lamp post with an arm over the road.
                let p = path.point(s, side * (layout::KERB + 0.6), 0.0);
                let metal = Mat::Metal { base: [110.0, 112.0, 108.0] };
                b.boxed(p, t, 0.18, 0.18, 0.0, 7.5, class::POLE, false, &|_, _| Some(metal));
                let (_, _, n) = path.frame(s);
                let arm = add3(p, mul3(n, -side * 0.8));
                b.boxed(arm, mul3(n, -side), 1.6, 0.1, 7.3, 7.42, class::POLE, false, &|_, _| {
                    Some(metal)
                });
                let head = add3(p, mul3(n, -side * 1.6));
                b.boxed(head, t, 0.35, 0.6, 7.1, 7.35, class::POLE, false, &|_, _| {
                    Some(Mat::Metal { base: [60.0, 60.0, 62.0] })
                });
            } else if r < 0.9 {
                // A sign facing the traffic on this side.
                let p = path.point(s, side * (layout::KERB + 0.5), 0.0);
                b.boxed(p, t, 0.07, 0.07, 0.0, 2.9, class::POLE, false, &|_, _| {
                    Some(Mat::Metal { base: [150.0, 152.0, 155.0] })
                });
                let kind = (rng.u32() % 4) as u8;
                let (_, _, n) = path.frame(s);
                let face = if side > 0.0 { mul3(t, -1.0) } else { t };
                let right = cross3(face, DOWN);
                let centre = add3(p, mul3(face, 0.05));
                let a = sub3(centre, mul3(right, 0.36));
                let bb = add3(centre, mul3(right, 0.36));
                let _ = n;
                // Plate: u, v centred (map origin shifted to the plate centre).
                b.vquad(a, bb, 2.15, 2.87, Mat::Sign { kind }, class::SIGN, false);
                if let Some(last) = b.items.last_mut() {
                    last.1.map =
                        Map::Affine { o: [centre[0], -2.51, centre[2]], eu: right, ev: UP };
                    last.1.light = 0.95;
                }
                let back_c = add3(p, mul3(face, 0.035));
                let a2 = add3(back_c, mul3(right, 0.36));
                let b2 = sub3(back_c, mul3(right, 0.36));
                b.vquad(a2, b2, 2.15, 2.87, Mat::SignBack { kind }, class::SIGN, false);
                if let Some(last) = b.items.last_mut() {
                    last.1.map = Map::Affine {
                        o: [back_c[0], -2.51, back_c[2]],
                        eu: mul3(right, -1.0),
                        ev: UP,
                    };
                }
            }
        }
        s += rng.range(9.0, 20.0);
    }
    // Parked cars.
    let mut s = rng.range(0.0, 10.0);
    while s < total - 10.0 {
        if path.near_junction(s, 14.0) || path.near_junction(s + 2.0, 14.0) {
            s += 3.0;
            continue;
        }
        let park = |b: &mut Builder, rng: &mut Rng| {
            b.anchor = s;
            let p = path.point(s, side * (layout::PARKING + rng.range(-0.1, 0.2)), 0.0);
            let (_, t, _) = path.frame(s);
            let f = if rng.chance(0.8) { t } else { mul3(t, -1.0) };
            let kind = if rng.chance(0.15) { VehicleKind::Van } else { VehicleKind::Car };
            vehicle(b, p, f, kind, paint(rng), rng.u32(), false);
        };
        if rng.chance(0.55) {
            park(b, rng);
        } else if kerb_rows {
            let mut own = Rng::new(s.to_bits() ^ side.to_bits() ^ 0x6b65_7262_726f_7773);
            if own.chance(0.85) {
                park(b, &mut own);
            }
        }
        s += rng.range(5.2, 8.0);
    }
}

fn paint(rng: &mut Rng) -> Rgb {
    const P: [Rgb; 9] = [
        [200.0, 200.0, 205.0],
        [30.0, 30.0, 34.0],
        [140.0, 142.0, 146.0],
        [150.0, 20.0, 25.0],
        [25.0, 50.0, 120.0],
        [235.0, 235.0, 235.0],
        [80.0, 90.0, 70.0],
        [100.0, 100.0, 105.0],
        [190.0, 150.0, 60.0],
    ];
    P[(rng.u32() as usize) % P.len()]
}

/// Vehicle body types.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum VehicleKind {
    Car,
    Van,
    Truck,
}

fn vehicle(b: &mut Builder, c: V3, f: V3, kind: VehicleKind, paint: Rgb, seed: u32, dynamic: bool) {
    let cls = class::CAR;
    let (l, w, body0, body1) = match kind {
        VehicleKind::Car => (4.3, 1.8, 0.28, 0.95),
        VehicleKind::Van => (5.2, 2.0, 0.3, 1.0),
        VehicleKind::Truck => (7.2, 2.5, 0.5, 1.1),
    };
    let r = cross3(DOWN, f);
    let vm =
        |part: VPart, fw: f32, h0: f64| Mat::Vehicle { paint, part, dims: [fw, h0 as f32], seed };
    let wheel_r = if kind == VehicleKind::Truck { 0.5 } else { 0.32 };
    for (df, dr) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
        let p = add3(c, add3(mul3(f, df * (l * 0.5 - 0.8)), mul3(r, dr * (w * 0.5 - 0.12))));
        b.boxed(p, f, wheel_r * 2.0, 0.24, 0.0, wheel_r * 2.0, cls, dynamic, &|face, _| {
            Some(if face >= 2 {
                Mat::Vehicle { paint, part: VPart::Wheel, dims: [0.0, wheel_r as f32], seed }
            } else {
                Mat::Metal { base: [28.0, 28.0, 28.0] }
            })
        });
    }
    match kind {
        VehicleKind::Car => {
            b.boxed(c, f, l, w, body0, body1, cls, dynamic, &|face, fw| {
                Some(match face {
                    0 => vm(VPart::BodyFront, fw, body0),
                    1 => vm(VPart::BodyBack, fw, body0),
                    2 | 3 => vm(VPart::BodySide, fw, body0),
                    _ => vm(VPart::Top, fw, body0),
                })
            });
            let cc = add3(c, mul3(f, -0.25));
            b.boxed(cc, f, 2.3, w - 0.16, body1, 1.45, cls, dynamic, &|face, fw| {
                Some(match face {
                    0 => vm(VPart::CabinFront, fw, body1),
                    1 => vm(VPart::CabinBack, fw, body1),
                    2 | 3 => vm(VPart::CabinSide, fw, body1),
                    _ => vm(VPart::Top, fw, body1),
                })
            });
        }
        VehicleKind::Van => {
            b.boxed(c, f, l, w, body0, body1, cls, dynamic, &|face, fw| {
                Some(match face {
                    0 => vm(VPart::BodyFront, fw, body0),
                    1 => vm(VPart::BodyBack, fw, body0),
                    2 | 3 => vm(VPart::BodySide, fw, body0),
                    _ => vm(VPart::Top, fw, body0),
                })
            });
            let cc = add3(c, mul3(f, -0.4));
            b.boxed(cc, f, l - 0.8, w, body1, 2.1, cls, dynamic, &|face, fw| {
                Some(match face {
                    0 => vm(VPart::CabinFront, fw, body1),
                    1 => vm(VPart::CargoBack, fw, body1 - 0.3),
                    2 | 3 => vm(VPart::CabinSide, fw, body1),
                    _ => vm(VPart::Top, fw, body1),
                })
            });
        }
        VehicleKind::Truck => {
            // Cargo box, chassis, cab.
            let cargo = add3(c, mul3(f, -0.9));
            b.boxed(cargo, f, l - 1.8, w, 1.1, 3.7, cls, dynamic, &|face, fw| {
                Some(match face {
                    1 => vm(VPart::CargoBack, fw, 1.1),
                    2 | 3 => vm(VPart::CargoSide, fw, 1.1),
                    _ => vm(VPart::Top, fw, 1.1),
                })
            });
            b.boxed(c, f, l, w - 0.3, body0, 1.1, cls, dynamic, &|_, _| {
                Some(Mat::Metal { base: [35.0, 35.0, 38.0] })
            });
            let cab = add3(c, mul3(f, l * 0.5 - 1.0));
            b.boxed(cab, f, 1.8, w - 0.1, 0.9, 3.1, cls, dynamic, &|face, fw| {
                Some(match face {
                    0 => vm(VPart::CabinFront, fw, 2.3),
                    _ => vm(VPart::BodySide, fw, 0.9),
                })
            });
        }
    }
}

/// A person: `cyclist` draws a rider on a bicycle, else a walker at stride `phase` (radians).
#[allow(clippy::too_many_arguments)]
fn person(
    b: &mut Builder,
    c: V3,
    f: V3,
    phase: f64,
    cloth: [Rgb; 2],
    seed: u32,
    cyclist: bool,
    dynamic: bool,
) {
    let cls = if cyclist { class::BICYCLIST } else { class::PEDESTRIAN };
    let r = cross3(DOWN, f);
    let pm = |part: PPart| Mat::Person { cloth, part, seed };
    let (leg0, leg1, torso1, lean) =
        if cyclist { (0.45, 1.0, 1.55, 0.15) } else { (0.0, 0.85, 1.45, 0.0) };
    for (k, dr) in [(0.0, 1.0f64), (core::f64::consts::PI, -1.0)] {
        let swing = if cyclist { 0.0 } else { 0.18 * (phase + k).sin() };
        let lift = if cyclist { 0.12 * (phase + k).sin() } else { 0.0 };
        let p = add3(c, add3(mul3(f, swing), mul3(r, dr * 0.11)));
        b.boxed(p, f, 0.16, 0.14, leg0 + lift.max(0.0), leg1, cls, dynamic, &|face, _| {
            (face < 4).then_some(pm(PPart::Legs))
        });
    }
    let tc = add3(c, mul3(f, lean));
    b.boxed(tc, f, 0.26, 0.44, leg1, torso1, cls, dynamic, &|_, _| Some(pm(PPart::Torso)));
    let hc = add3(c, mul3(f, lean * 1.4));
    b.boxed(hc, f, 0.21, 0.19, torso1 + 0.03, torso1 + 0.28, cls, dynamic, &|face, _| {
        Some(pm(PPart::Head { front: face == 0 }))
    });
    if cyclist {
        // The bicycle: a cut-out side profile through the rider's centre line.
        let a = sub3(c, mul3(f, 0.85));
        let bb = add3(c, mul3(f, 0.85));
        b.vquad(a, bb, 0.0, 1.05, Mat::Bike, cls, dynamic);
        b.vquad(bb, a, 0.0, 1.05, Mat::Bike, cls, dynamic);
        if let Some(last) = b.items.last_mut() {
            // Same profile from the other side: u must still run rear → front.
            last.1.map = Map::Affine { o: [a[0], 0.0, a[2]], eu: f, ev: UP };
        }
        // Rear rack with a bag: a solid target on the cyclist seen from behind.
        let rc = sub3(c, mul3(f, 0.6));
        b.boxed(rc, f, 0.35, 0.3, 0.55, 0.85, cls, dynamic, &|_, _| Some(pm(PPart::Legs)));
    }
}

/// How an agent moves.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Motion {
    /// Along the road at lateral `lat`: `s(t) = s0 + v·t` (v < 0: oncoming).
    Lane { s0: f64, v: f64, lat: f64 },
    /// Relative to the ego: `s(t) = ego(t) + g0 + ga·sin(2πt/period + phase) + drift·t`.
    Follow { g0: f64, ga: f64, period: f64, phase: f64, drift: f64, lat: f64 },
    /// Across the road at arc length `s`: `lat(t) = lat0 + v·(t − t0)`, shown while
    /// `t ≥ t0` and `|lat| ≤ lat_max`.
    Cross { s: f64, lat0: f64, v: f64, t0: f64, lat_max: f64 },
}

/// What an agent is.
#[derive(Clone, Copy, Debug)]
pub(crate) enum AgentKind {
    Vehicle(VehicleKind, Rgb),
    Pedestrian([Rgb; 2]),
    Cyclist([Rgb; 2]),
}

/// A moving object.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Agent {
    pub kind: AgentKind,
    pub motion: Motion,
    pub seed: u32,
}

/// The ego vehicle's state at each frame.
#[derive(Clone, Debug)]
pub(crate) struct EgoTrack {
    /// Arc length at each frame.
    pub s: Vec<f64>,
    /// Speed (m/s).
    pub v: Vec<f64>,
    /// Longitudinal acceleration (m/s²).
    pub a: Vec<f64>,
}

/// Frame rate (Hz).
pub(crate) const FPS: f64 = 10.0;
/// Arc length where the ego starts.
pub(crate) const EGO_START: f64 = 30.0;

impl EgoTrack {
    /// Speed profile between 5 and 12 m/s from two slow sines, integrated at 100 Hz.
    pub(crate) fn generate(frames: usize, rng: &mut Rng) -> Self {
        let (p1, p2) =
            (rng.range(0.0, core::f64::consts::TAU), rng.range(0.0, core::f64::consts::TAU));
        let (t1, t2) = (rng.range(25.0, 40.0), rng.range(9.0, 15.0));
        let speed = |t: f64| {
            let v = 8.5
                + 2.6 * (t * core::f64::consts::TAU / t1 + p1).sin()
                + 1.0 * (t * core::f64::consts::TAU / t2 + p2).sin();
            v.clamp(5.0, 12.0)
        };
        let mut s = Vec::with_capacity(frames);
        let mut v = Vec::with_capacity(frames);
        let mut a = Vec::with_capacity(frames);
        let mut pos = EGO_START;
        let sub = 10;
        for k in 0..frames {
            let t = k as f64 / FPS;
            s.push(pos);
            v.push(speed(t));
            a.push((speed(t + 0.05) - speed(t - 0.05)) / 0.1);
            for j in 0..sub {
                let tt = t + (j as f64 + 0.5) / (FPS * sub as f64);
                pos += speed(tt) / (FPS * sub as f64);
            }
        }
        Self { s, v, a }
    }

    /// Arc length at time `t` (frames interpolated; clamped to the sequence).
    pub(crate) fn s_at(&self, t: f64) -> f64 {
        let x = (t * FPS).max(0.0);
        let i = (x.floor() as usize).min(self.s.len().saturating_sub(1));
        let f = x - i as f64;
        if i + 1 < self.s.len() {
            self.s[i] + (self.s[i + 1] - self.s[i]) * f
        } else {
            self.s[i] + self.v[i] * f / FPS
        }
    }
}

/// The time when the ego passes arc length `s` (clamped to the sequence).
fn time_at(ego: &EgoTrack, s: f64) -> f64 {
    let k = ego.s.partition_point(|x| *x < s);
    k as f64 / FPS
}

fn cloth(rng: &mut Rng) -> [Rgb; 2] {
    const TOPS: [Rgb; 7] = [
        [180.0, 40.0, 40.0],
        [40.0, 60.0, 140.0],
        [230.0, 230.0, 225.0],
        [60.0, 60.0, 62.0],
        [200.0, 170.0, 60.0],
        [90.0, 130.0, 80.0],
        [140.0, 100.0, 80.0],
    ];
    const BOTTOMS: [Rgb; 4] =
        [[40.0, 50.0, 80.0], [30.0, 30.0, 32.0], [160.0, 150.0, 130.0], [90.0, 90.0, 95.0]];
    [TOPS[(rng.u32() as usize) % TOPS.len()], BOTTOMS[(rng.u32() as usize) % BOTTOMS.len()]]
}

/// The traffic of a dynamics level for a sequence of `ego.s.len()` frames.
pub(crate) fn agents(level: Dynamics, path: &Path, ego: &EgoTrack, rng: &mut Rng) -> Vec<Agent> {
    let mut out = Vec::new();
    let t_end = ego.s.len() as f64 / FPS;
    let s_end = ego.s.last().copied().unwrap_or(EGO_START);
    let (oncoming_every, ped_every, overtake_every) = match level {
        Dynamics::Static => return out,
        Dynamics::Low | Dynamics::Parked => (14.0, 60.0, f64::INFINITY),
        Dynamics::High => (3.5, 14.0, 4.0),
    };
    let veh = |rng: &mut Rng, truck_p: f64| {
        let k = if rng.chance(truck_p) {
            VehicleKind::Truck
        } else if rng.chance(0.25) {
            VehicleKind::Van
        } else {
            VehicleKind::Car
        };
        AgentKind::Vehicle(k, paint(rng))
    };
    // Oncoming traffic: each meets the ego at time tm.
    let mut tm = rng.range(1.0, oncoming_every);
    while tm < t_end + 15.0 {
        let v = -rng.range(8.0, 13.0);
        let lat = if rng.chance(0.5) { -layout::LANE_A } else { -layout::LANE_B };
        let s_meet = ego.s_at(tm);
        let kind = veh(rng, if level == Dynamics::High { 0.25 } else { 0.1 });
        out.push(Agent {
            kind,
            motion: Motion::Lane { s0: s_meet - v * tm, v, lat },
            seed: rng.u32(),
        });
        tm += rng.range(0.6, 1.4) * oncoming_every;
    }
    // Pedestrians on both pavements.
    let mut s = EGO_START + rng.range(5.0, ped_every);
    while s < s_end + 120.0 {
        let side = if rng.chance(0.5) { 1.0 } else { -1.0 };
        let v = rng.range(1.0, 1.7) * if rng.chance(0.5) { 1.0 } else { -1.0 };
        let lat = side * rng.range(layout::KERB + 1.0, layout::BUILDING - 0.6);
        if !path.near_junction(s, 9.0) {
            out.push(Agent {
                kind: AgentKind::Pedestrian(cloth(rng)),
                motion: Motion::Lane { s0: s, v, lat },
                seed: rng.u32(),
            });
        }
        s += rng.range(0.5, 1.5) * ped_every;
    }
    for &j in &path.junctions {
        if j < EGO_START - 20.0 || j > s_end + 150.0 {
            continue;
        }
        // Crossing cars on the side street, well before the ego arrives.
        let lead = if level == Dynamics::High { 75.0 } else { 110.0 };
        let t0 = time_at(ego, j - lead);
        let dir = if rng.chance(0.5) { 1.0 } else { -1.0 };
        out.push(Agent {
            kind: veh(rng, 0.1),
            motion: Motion::Cross {
                s: j + dir * 1.8,
                lat0: -dir * 45.0,
                v: dir * 10.0,
                t0: t0 - 1.5,
                lat_max: 50.0,
            },
            seed: rng.u32(),
        });
        if level == Dynamics::High {
            // Pedestrians on the zebra crossing.
            let t0 = time_at(ego, j - 160.0);
            for k in 0..3 {
                let d = if k % 2 == 0 { 1.0 } else { -1.0 };
                out.push(Agent {
                    kind: AgentKind::Pedestrian(cloth(rng)),
                    motion: Motion::Cross {
                        s: j - 10.0 + k as f64 * 0.7,
                        lat0: -d * 9.5,
                        v: d * rng.range(1.2, 1.6),
                        t0: t0 + k as f64 * 1.5,
                        lat_max: 10.0,
                    },
                    seed: rng.u32(),
                });
            }
        }
    }
    if level == Dynamics::Parked {
        // People standing on the pavements, alone or in twos and threes (a bus stop, a chat):
        // pedestrians by class, static by motion.
        let mut s = EGO_START + rng.range(3.0, 10.0);
        while s < s_end + 120.0 {
            let side = if rng.chance(0.5) { 1.0 } else { -1.0 };
            let lat = side * rng.range(layout::KERB + 0.6, layout::BUILDING - 0.8);
            if !path.near_junction(s, 9.0) {
                for k in 0..1 + (rng.u32() % 3) {
                    out.push(Agent {
                        kind: AgentKind::Pedestrian(cloth(rng)),
                        motion: Motion::Lane { s0: s + 0.7 * f64::from(k), v: 0.0, lat },
                        seed: rng.u32(),
                    });
                }
            }
            s += rng.range(8.0, 16.0);
        }
    }
    match level {
        Dynamics::Low | Dynamics::Parked => {
            // A car far ahead in the other lane of our direction.
            out.push(Agent {
                kind: veh(rng, 0.0),
                motion: Motion::Follow {
                    g0: 50.0,
                    ga: 12.0,
                    period: 37.0,
                    phase: rng.range(0.0, 6.0),
                    drift: 0.0,
                    lat: layout::LANE_A,
                },
                seed: rng.u32(),
            });
        }
        Dynamics::High => {
            // A truck leading the ego in its lane, and a cyclist riding ahead on its right.
            out.push(Agent {
                kind: AgentKind::Vehicle(VehicleKind::Truck, [230.0, 230.0, 225.0]),
                motion: Motion::Follow {
                    g0: 10.8,
                    ga: 2.3,
                    period: 31.0,
                    phase: rng.range(0.0, 6.0),
                    drift: 0.0,
                    lat: layout::LANE_B - 0.3,
                },
                seed: rng.u32(),
            });
            out.push(Agent {
                kind: AgentKind::Cyclist(cloth(rng)),
                motion: Motion::Follow {
                    g0: 11.5,
                    ga: 3.5,
                    period: 23.0,
                    phase: rng.range(0.0, 6.0),
                    drift: 0.0,
                    lat: layout::LANE_B + 1.55,
                },
                seed: rng.u32(),
            });
            // Cars overtaking in the inner lane, passing the ego at ~4 m/s relative speed.
            let mut t = rng.range(-8.0, 0.0);
            while t < t_end {
                let rel = rng.range(3.0, 5.0);
                out.push(Agent {
                    kind: veh(rng, 0.2),
                    motion: Motion::Follow {
                        g0: -25.0 - rel * t,
                        ga: 0.0,
                        period: 1.0,
                        phase: 0.0,
                        drift: rel,
                        lat: layout::LANE_A,
                    },
                    seed: rng.u32(),
                });
                t += rng.range(0.7, 1.3) * overtake_every;
            }
        }
        Dynamics::Static => {}
    }
    out
}

/// Emits the primitives of every agent visible around the ego at frame `k` into `out`.
pub(crate) fn agent_prims(
    agents: &[Agent],
    path: &Path,
    ego: &EgoTrack,
    k: usize,
    out: &mut Vec<Prim>,
) {
    let t = k as f64 / FPS;
    let ego_s = ego.s[k.min(ego.s.len() - 1)];
    let mut b = Builder { items: Vec::new(), anchor: 0.0 };
    for a in agents {
        let (s, lat, f, dist) = match a.motion {
            Motion::Lane { s0, v, lat } => {
                let s = s0 + v * t;
                let (_, tan, _) = path.frame(s);
                (s, lat, if v < 0.0 { mul3(tan, -1.0) } else { tan }, (v * t).abs())
            }
            Motion::Follow { g0, ga, period, phase, drift, lat } => {
                let gap = g0 + ga * (t * core::f64::consts::TAU / period + phase).sin() + drift * t;
                let s = ego.s_at(t) + gap;
                let (_, tan, _) = path.frame(s);
                (s, lat, tan, s)
            }
            Motion::Cross { s, lat0, v, t0, lat_max } => {
                let lat = lat0 + v * (t - t0);
                if t < t0 || lat.abs() > lat_max {
                    continue;
                }
                let (_, _, n) = path.frame(s);
                (s, lat, if v > 0.0 { n } else { mul3(n, -1.0) }, (v * (t - t0)).abs())
            }
        };
        if s < ego_s - 40.0 || s > ego_s + 160.0 || s < 1.0 || s > path.len() - 2.0 {
            continue;
        }
        let c = path.point(s, lat, 0.0);
        // Standing agents (v = 0) are drawn as what they are but are not in the moving mask.
        let moving = !matches!(a.motion, Motion::Lane { v, .. } if v == 0.0);
        match a.kind {
            AgentKind::Vehicle(kind, p) => vehicle(&mut b, c, f, kind, p, a.seed, moving),
            AgentKind::Pedestrian(cl) => {
                let phase = dist / 0.7 * core::f64::consts::PI;
                person(&mut b, c, f, phase, cl, a.seed, false, moving)
            }
            AgentKind::Cyclist(cl) => person(&mut b, c, f, dist / 2.0, cl, a.seed, true, moving),
        }
    }
    out.extend(b.items.into_iter().map(|(_, p)| p));
}

/// Camera-to-world pose of the left camera at frame `k`: rotation (columns are the camera
/// axes in the world) and centre.
pub(crate) fn camera_pose(
    path: &Path,
    ego: &EgoTrack,
    k: usize,
    seed_phase: f64,
) -> ([[f64; 3]; 3], V3) {
    let t = k as f64 / FPS;
    let s = ego.s[k];
    let wander = 0.15 * (t * 0.21 + seed_phase).sin();
    let (_, tan, n) = path.frame(s);
    let mut c = path.point(s, layout::LANE_B + wander, 1.65 + 0.008 * (t * 9.0 + seed_phase).sin());
    // Heading: the path's, plus the slope of the lane wander.
    let dw = 0.15 * 0.21 * (t * 0.21 + seed_phase).cos() / ego.v[k].max(1.0);
    let yaw = dw;
    let pitch = (0.35 * ego.a[k] + 0.3 * (t * 1.3 + seed_phase).sin() + 0.15 * (t * 4.1).sin())
        .to_radians();
    let roll = (0.6 * ego.v[k] * ego.v[k] * path.kappa(s)
        + 0.25 * (t * 0.9 + 2.0 * seed_phase).sin())
    .to_radians();
    // Base frame: x = right normal, y = down, z = tangent; then yaw about y, pitch about x,
    // roll about z (camera axes).
    let base = [[n[0], 0.0, tan[0]], [n[1], 1.0, tan[1]], [n[2], 0.0, tan[2]]];
    let ry = rot_y(yaw);
    let rx = rot_x(pitch);
    let rz = rot_z(roll);
    let r = matmul(&matmul(&matmul(&base, &ry), &rx), &rz);
    c[1] = -1.65 - 0.008 * (t * 9.0 + seed_phase).sin();
    (r, c)
}

fn rot_x(a: f64) -> [[f64; 3]; 3] {
    let (s, c) = a.sin_cos();
    [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
}
fn rot_y(a: f64) -> [[f64; 3]; 3] {
    let (s, c) = a.sin_cos();
    [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
}
fn rot_z(a: f64) -> [[f64; 3]; 3] {
    let (s, c) = a.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}

/// 3×3 matrix product.
pub(crate) fn matmul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut m = [[0.0; 3]; 3];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    m
}
