//! A small software rasteriser: planar convex polygons into a z-buffer of `1/Z` and primitive
//! ids, then one deferred shading pass that evaluates each visible surface's procedural
//! texture once per pixel.
//!
//! Pixel `(i, j)` samples the ray through its centre at integer coordinates (the KITTI /
//! OpenCV convention, principal point `(cx, cy)` in the same coordinates). Spans are half-open
//! (`ceil(x_left) ≤ i < ceil(x_right)`) with edges evaluated in a canonical vertex order, so
//! polygons that share an edge cover every pixel exactly once. `1/Z` is affine in screen space
//! for a plane, so depth is exact per pixel; texture coordinates come from the 3D point
//! `P = Z·d(i, j)` and are perspective-correct by construction.

use super::scene::{dot3, sub3, Map, Prim, V3};
use super::texture::{mix, Rgb};

/// Nearest depth drawn (m).
const NEAR: f64 = 0.25;
/// Sentinel id of pixels that see the sky.
pub(crate) const SKY: u32 = u32::MAX;

/// A pinhole camera: intrinsics, image size, and the world → camera transform
/// `P_c = R·P_w + t`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Cam {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub r: [[f64; 3]; 3],
    pub t: V3,
}

impl Cam {
    #[inline]
    fn world_to_cam(&self, p: V3) -> V3 {
        let r = &self.r;
        [
            r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + self.t[0],
            r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + self.t[1],
            r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + self.t[2],
        ]
    }

    /// A world-frame direction in camera coordinates.
    #[inline]
    fn dir_to_cam(&self, d: V3) -> V3 {
        let r = &self.r;
        [
            r[0][0] * d[0] + r[0][1] * d[1] + r[0][2] * d[2],
            r[1][0] * d[0] + r[1][1] * d[1] + r[1][2] * d[2],
            r[2][0] * d[0] + r[2][1] * d[1] + r[2][2] * d[2],
        ]
    }

    /// A linear functional `a·P_w + d` of world points as one of camera points.
    fn functional(&self, a: V3, d: f64) -> [f32; 4] {
        let ac = self.dir_to_cam(a);
        // a·P_w = a·Rᵀ(P_c − t) = (R a)·P_c − (R a)·t
        [ac[0] as f32, ac[1] as f32, ac[2] as f32, (d - dot3(ac, self.t)) as f32]
    }
}

/// Per-frame, per-camera form of a primitive: texture functionals in camera coordinates.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PrimCam {
    /// Affine: `u = l[0]·P`, `v = l[1]·P`. Strip: `d0 = l[0]·P`, `d1 = l[1]·P`,
    /// `lat0 = l[2]·P`, `lat1 = l[3]·P` (each `[a; d]` acting on `[P; 1]`).
    l: [[f32; 4]; 4],
    strip: Option<[f32; 2]>,
    /// Unit normal in camera coordinates.
    n: [f32; 3],
}

impl PrimCam {
    fn new(p: &Prim, cam: &Cam, normal: V3) -> Self {
        let nc = cam.dir_to_cam(normal);
        let n = [nc[0] as f32, nc[1] as f32, nc[2] as f32];
        match p.map {
            Map::Affine { o, eu, ev } => {
                let zero = [0.0; 4];
                Self {
                    l: [
                        cam.functional(eu, -dot3(eu, o)),
                        cam.functional(ev, -dot3(ev, o)),
                        zero,
                        zero,
                    ],
                    strip: None,
                    n,
                }
            }
            Map::Strip { c, t, n: nn, s } => Self {
                l: [
                    cam.functional(t[0], -dot3(t[0], c[0])),
                    cam.functional([-t[1][0], -t[1][1], -t[1][2]], dot3(t[1], c[1])),
                    cam.functional(nn[0], -dot3(nn[0], c[0])),
                    cam.functional(nn[1], -dot3(nn[1], c[1])),
                ],
                strip: Some([s[0] as f32, (s[1] - s[0]) as f32]),
                n,
            },
        }
    }

    /// Surface coordinates of camera point `p`.
    #[inline]
    fn uv(&self, p: [f32; 3]) -> (f32, f32) {
        let f = |l: &[f32; 4]| l[0] * p[0] + l[1] * p[1] + l[2] * p[2] + l[3];
        match self.strip {
            None => (f(&self.l[0]), f(&self.l[1])),
            Some([s0, ds]) => {
                let d0 = f(&self.l[0]);
                let d1 = f(&self.l[1]);
                let a = (d0 / (d0 + d1)).clamp(0.0, 1.0);
                let lat = f(&self.l[2]) * (1.0 - a) + f(&self.l[3]) * a;
                (s0 + ds * a, lat)
            }
        }
    }
}

/// Depth and id buffers of one camera.
#[derive(Clone, Debug)]
pub(crate) struct GBuf {
    pub w: usize,
    pub h: usize,
    /// `1/Z` of the nearest surface (0 = nothing).
    pub invz: Vec<f32>,
    /// Index of the nearest primitive in the frame's list, or [`SKY`].
    pub id: Vec<u32>,
    pcam: Vec<PrimCam>,
}

impl GBuf {
    pub(crate) fn new(w: usize, h: usize) -> Self {
        Self { w, h, invz: vec![0.0; w * h], id: vec![SKY; w * h], pcam: Vec::new() }
    }

    /// Rasterises `prims` seen by `cam` (clears first).
    pub(crate) fn render(&mut self, cam: &Cam, prims: &[&Prim]) {
        self.invz.fill(0.0);
        self.id.fill(SKY);
        self.pcam.clear();
        for (k, p) in prims.iter().enumerate() {
            let nw = {
                let e1 = sub3(p.v[1], p.v[0]);
                let e2 = sub3(p.v[2], p.v[0]);
                super::scene::norm3(super::scene::cross3(e1, e2))
            };
            let pc = PrimCam::new(p, cam, nw);
            self.pcam.push(pc);
            self.raster(cam, p, &pc, k as u32);
        }
    }

    fn raster(&mut self, cam: &Cam, p: &Prim, pc: &PrimCam, id: u32) {
        // Camera-space vertices, clipped to z ≥ NEAR (Sutherland–Hodgman, one plane).
        let mut vc = [[0.0f64; 3]; 4];
        for (i, v) in p.v.iter().take(p.n as usize).enumerate() {
            vc[i] = cam.world_to_cam(*v);
        }
        let n = p.n as usize;
        if vc[..n].iter().all(|v| v[2] < NEAR) {
            return;
        }
        let mut poly = [[0.0f64; 3]; 8];
        let mut m = 0;
        for i in 0..n {
            let a = vc[i];
            let b = vc[(i + 1) % n];
            let (ina, inb) = (a[2] >= NEAR, b[2] >= NEAR);
            if ina {
                poly[m] = a;
                m += 1;
            }
            if ina != inb {
                let t = (NEAR - a[2]) / (b[2] - a[2]);
                poly[m] = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), NEAR];
                m += 1;
            }
        }
        if m < 3 {
            return;
        }
        // Plane of the polygon in camera coordinates: n·P = k, so 1/Z = (n·d(i, j))/k.
        let nc = [pc.n[0] as f64, pc.n[1] as f64, pc.n[2] as f64];
        let k = dot3(nc, vc[0]);
        if k.abs() < 1e-9 {
            return; // seen exactly edge-on
        }
        let ai = nc[0] / (cam.fx * k);
        let bj = nc[1] / (cam.fy * k);
        let c0 = (nc[2] - nc[0] * cam.cx / cam.fx - nc[1] * cam.cy / cam.fy) / k;
        let mut sx = [0.0f64; 8];
        let mut sy = [0.0f64; 8];
        let (mut ymin, mut ymax) = (f64::MAX, f64::MIN);
        for i in 0..m {
            let q = poly[i];
            sx[i] = cam.fx * q[0] / q[2] + cam.cx;
            sy[i] = cam.fy * q[1] / q[2] + cam.cy;
            ymin = ymin.min(sy[i]);
            ymax = ymax.max(sy[i]);
        }
        let j0 = ymin.ceil().max(0.0) as usize;
        let j1 = (ymax.ceil().min(self.h as f64)).max(0.0) as usize;
        if j0 >= j1 {
            return;
        }
        // Edges in canonical order (top vertex first), as (x_top, y_top, y_bot, dx/dy).
        let mut edges = [(0.0f64, 0.0f64, 0.0f64, 0.0f64); 8];
        let mut ne = 0;
        for i in 0..m {
            let (mut a, mut b) = (i, (i + 1) % m);
            if sy[a] == sy[b] {
                continue;
            }
            if sy[a] > sy[b] || (sy[a] == sy[b] && sx[a] > sx[b]) {
                core::mem::swap(&mut a, &mut b);
            }
            edges[ne] = (sx[a], sy[a], sy[b], (sx[b] - sx[a]) / (sy[b] - sy[a]));
            ne += 1;
        }
        let cutout = p.mat.is_cutout();
        let w = self.w;
        let (fx, fy, cx, cy) = (cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32);
        for j in j0..j1 {
            let y = j as f64;
            let (mut xl, mut xr) = (f64::MAX, f64::MIN);
            for e in &edges[..ne] {
                if y >= e.1 && y < e.2 {
                    let x = e.0 + (y - e.1) * e.3;
                    xl = xl.min(x);
                    xr = xr.max(x);
                }
            }
            if xl > xr {
                continue;
            }
            let i0 = xl.ceil().max(0.0) as usize;
            let i1 = (xr.ceil().min(w as f64)).max(0.0) as usize;
            if i0 >= i1 {
                continue;
            }
            let row = j * w;
            let rowc = (bj * y + c0) as f32;
            let a = ai as f32;
            let zrow = &mut self.invz[row + i0..row + i1];
            let idrow = &mut self.id[row + i0..row + i1];
            for (o, (zb, ib)) in zrow.iter_mut().zip(idrow.iter_mut()).enumerate() {
                let i = i0 + o;
                let iz = a * i as f32 + rowc;
                if iz > *zb && iz > 0.0 {
                    if cutout {
                        let z = 1.0 / iz;
                        let pt = [(i as f32 - cx) / fx * z, (j as f32 - cy) / fy * z, z];
                        let (u, v) = pc.uv(pt);
                        if !p.mat.alpha(u, v) {
                            continue;
                        }
                    }
                    *zb = iz;
                    *ib = id;
                }
            }
        }
    }

    /// Shades every pixel into `out` (RGB, 0..255 before exposure) — `sky(dir)` gets the
    /// world-frame ray direction of sky pixels; fog fades far surfaces towards `haze`.
    pub(crate) fn shade(
        &self,
        cam: &Cam,
        prims: &[&Prim],
        rows: core::ops::Range<usize>,
        out: &mut [[f32; 3]],
        sky: &dyn Fn([f32; 3]) -> Rgb,
    ) {
        let (fx, fy, cx, cy) = (cam.fx as f32, cam.fy as f32, cam.cx as f32, cam.cy as f32);
        // World direction of a camera ray: Rᵀ d.
        let r = cam.r;
        let haze: Rgb = [200.0, 206.0, 214.0];
        let w = self.w;
        for j in rows.clone() {
            let dy = (j as f32 - cy) / fy;
            for i in 0..w {
                let idx = j * w + i;
                let o = &mut out[(j - rows.start) * w + i];
                let dx = (i as f32 - cx) / fx;
                let id = self.id[idx];
                if id == SKY {
                    let d = [dx as f64, dy as f64, 1.0];
                    let dw = [
                        r[0][0] * d[0] + r[1][0] * d[1] + r[2][0] * d[2],
                        r[0][1] * d[0] + r[1][1] * d[1] + r[2][1] * d[2],
                        r[0][2] * d[0] + r[1][2] * d[1] + r[2][2] * d[2],
                    ];
                    *o = sky([dw[0] as f32, dw[1] as f32, dw[2] as f32]);
                    continue;
                }
                let p = prims[id as usize];
                let pc = &self.pcam[id as usize];
                let z = 1.0 / self.invz[idx];
                let pt = [dx * z, dy * z, z];
                let (u, v) = pc.uv(pt);
                // Footprint: metres per pixel across the surface (geometric mean of the two
                // axes of the pixel's ellipse, so grazing surfaces blur only moderately).
                let dn = (dx * dx + dy * dy + 1.0).sqrt();
                let cos = ((pc.n[0] * dx + pc.n[1] * dy + pc.n[2]) / dn).abs().max(0.03);
                let fp = z * dn / fx / cos.sqrt();
                let c = p.mat.shade(u, v, fp);
                let c = [c[0] * p.light, c[1] * p.light, c[2] * p.light];
                let dist = z * dn;
                let fog = dist / (dist + 400.0);
                *o = mix(c, haze, fog);
            }
        }
    }
}
