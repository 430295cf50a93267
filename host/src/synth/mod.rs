//! Synthetic stereo sequences of a street with traffic, written in the KITTI odometry layout
//! with ground-truth poses, semantic labels and moving-object masks.
//!
//! [`generate`] writes, for [`SynthConfig::frames`] frames at 10 Hz:
//!
//! ```text
//! DIR/sequences/XX/image_0/NNNNNN.png   left  (8-bit grey; image_2 with `colour`, RGB)
//! DIR/sequences/XX/image_1/NNNNNN.png   right (image_3 with `colour`)
//! DIR/sequences/XX/semantic/NNNNNN.png  left-camera class ids, 8-bit (CamVid 11 classes)
//! DIR/sequences/XX/dynamic/NNNNNN.png   255 where a moving object is, 0 elsewhere
//! DIR/sequences/XX/calib.txt            P0..P3 (P2 = P0, P3 = P1), KITTI format
//! DIR/sequences/XX/times.txt            0.0, 0.1, ...
//! DIR/poses/XX.txt                      left camera-to-world, 12 numbers a line, first = I
//! ```
//!
//! Images are 1241 × 376 with KITTI-like intrinsics ([`FX`], [`CX`], [`CY`], baseline
//! [`BASELINE_M`]); the set opens with [`crate::dataset::Sequence::open_odometry`].
//!
//! **Class ids** (CamVid 11-class scheme, as in `../shared/data/camvid`): 0 sky, 1 building,
//! 2 pole, 3 road, 4 pavement (incl. kerbs and yards), 5 tree (incl. hedges), 6 sign-symbol
//! (incl. traffic lights), 7 fence, 8 car (incl. vans, trucks, parked cars), 9 pedestrian,
//! 10 bicyclist (rider and bicycle). Parked cars are class 8 but not in the dynamic mask: the
//! mask marks what *moves*, the labels what things *are*.
//!
//! **The scene** (`scene.rs`, `material.rs`): a road of straights and eased curves with two lanes each
//! way, parking strips, kerbs, paved pavements, junctions with side streets, zebra crossings
//! and traffic lights; building fronts of brick, plaster or stone with windows (blinds,
//! curtains, reflections), shop signs with lettering and doors; parks with fences and trees;
//! trees, lamp posts and signs on the pavements; parked cars. The ego drives the outer lane at
//! 5–12 m/s with lane wander, pitch from acceleration and road, roll from lateral
//! acceleration; camera height 1.65 m. Per frame, exposure varies (±8 %), and each image gets
//! deterministic sensor noise and a light optical blur.
//!
//! **Traffic** ([`Dynamics`]): `static` none; `low` oncoming cars every ~14 s, a car far ahead,
//! a few pedestrians and the odd crossing car; `high` a truck leading the ego in its lane (rear
//! 5–10 m ahead), a cyclist riding at the ego's speed 8–15 m ahead, cars overtaking every ~4 s,
//! dense oncoming traffic (trucks included), pedestrians on the pavements and the zebra
//! crossings, crossing cars at junctions.
//!
//! **Rendering** (`raster.rs`, `texture.rs`): a software z-buffer rasteriser of planar convex polygons
//! with deferred procedural texturing (each surface's pattern is a function of its own metric
//! coordinates, band-limited by the pixel footprint), so both cameras see one consistent 3D
//! world: stereo disparity is exactly `fx·b/Z` up to noise. Right camera = left moved
//! +0.54 m along its x axis.
//!
//! **Determinism.** Everything derives from [`SynthConfig::seed`] through a SplitMix64 generator
//! and integer hashes; frames are independent, so the files are byte-identical for the same
//! arguments whatever the thread count. The street and ego path depend only on the seed (not on
//! the dynamics level), so `static` and `high` with one seed drive the same street.
//!
//! Memory: the static scene (~100 bytes per polygon, a few hundred thousand polygons per km) plus,
//! per worker thread, two depth/id buffers and the output images of one frame (~10 MB).

mod material;
mod raster;
mod scene;
#[cfg(test)]
mod tests;
mod texture;

use core::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{DynamicImage, ExtendedColorType, GrayImage, ImageEncoder, RgbImage};
use serde::Serialize;

use raster::{Cam, GBuf, SKY};
use scene::{class, EgoTrack, Prim, Rng, World};

/// Image width (px), as KITTI odometry sequence 00.
pub const WIDTH: u32 = 1241;
/// Image height (px).
pub const HEIGHT: u32 = 376;
/// Focal length (px), both axes.
pub const FX: f64 = 718.856;
/// Principal point x (px).
pub const CX: f64 = 607.1928;
/// Principal point y (px).
pub const CY: f64 = 185.2157;
/// Stereo baseline (m).
pub const BASELINE_M: f64 = 0.54;
/// Frame rate (Hz).
pub const FRAME_RATE_HZ: f64 = scene::FPS;

/// The CamVid 11-class names, indexed by the ids in the `semantic/` images: the same table
/// the core's semantic front end uses.
pub use semloc_core::seg::CLASS_NAMES;

/// How much traffic moves in the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Dynamics {
    /// No moving objects (parked cars only).
    Static,
    /// A few agents, mostly far away.
    Low,
    /// Dense traffic: a truck and a cyclist leading the ego, overtaking and oncoming cars,
    /// crowds; moving objects cover ≥ 30 % of many frames.
    High,
    /// `low`'s traffic in a street lined with parked cars (the parking strips' empty slots
    /// filled, as KITTI's residential streets) and people standing on the pavements: most
    /// car and pedestrian pixels do not move. The street is `static`'s plus the extra cars.
    Parked,
}

impl core::fmt::Display for Dynamics {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Dynamics::Static => "static",
            Dynamics::Low => "low",
            Dynamics::High => "high",
            Dynamics::Parked => "parked",
        })
    }
}

/// What to generate.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SynthConfig {
    /// Number of stereo frames (≥ 1).
    pub frames: usize,
    /// Traffic level.
    pub dynamics: Dynamics,
    /// Seed of everything random (street, path, traffic, exposure, noise).
    pub seed: u64,
    /// Write the colour pair (`image_2`, `image_3`, RGB) instead of the grey one.
    pub colour: bool,
    /// Sequence name, e.g. `00`.
    pub seq: String,
    /// Worker threads (frames are rendered in parallel); 0 = all available cores.
    pub threads: usize,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            frames: 100,
            dynamics: Dynamics::Low,
            seed: 0,
            colour: false,
            seq: "00".into(),
            threads: 2,
        }
    }
}

/// What [`generate`] did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SynthSummary {
    /// The sequence folder written (`DIR/sequences/XX`).
    pub sequence_dir: PathBuf,
    /// Frames written.
    pub frames: usize,
    /// Length of the left camera's path (m).
    pub path_length_m: f64,
    /// Mean over frames of the fraction of pixels marked dynamic.
    pub dynamic_fraction_mean: f64,
    /// Largest per-frame dynamic fraction.
    pub dynamic_fraction_max: f64,
    /// Frames whose dynamic fraction is at least 0.3.
    pub frames_dynamic_over_30pct: usize,
    /// Wall time (s), rendering and writing.
    pub seconds: f64,
}

impl core::fmt::Display for SynthSummary {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        writeln!(f, "synthetic sequence {}", self.sequence_dir.display())?;
        writeln!(f, "  frames:      {}", self.frames)?;
        writeln!(f, "  path length: {:.1} m", self.path_length_m)?;
        writeln!(
            f,
            "  dynamic px:  mean {:.1} %, max {:.1} %, {} frames ≥ 30 %",
            self.dynamic_fraction_mean * 100.0,
            self.dynamic_fraction_max * 100.0,
            self.frames_dynamic_over_30pct
        )?;
        write!(
            f,
            "  time:        {:.2} s ({:.1} stereo frames/s)",
            self.seconds,
            self.frames as f64 / self.seconds.max(1e-9)
        )
    }
}

/// Errors of the generator; each names the path involved.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SynthError {
    /// A file or folder could not be created or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// PNG encoding failed.
    #[error("{path}: PNG encoding failed: {msg}")]
    Encode {
        /// The image file.
        path: PathBuf,
        /// The encoder's message.
        msg: String,
    },
    /// The configuration cannot be generated (e.g. zero frames, a sequence name with `/`).
    #[error("{path}: invalid configuration: {msg}")]
    Config {
        /// The output folder.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SynthError + '_ {
    move |source| SynthError::Io { path: path.to_path_buf(), source }
}

/// One rendered stereo frame, for callers that want pixels rather than files.
#[derive(Debug, Clone)]
pub struct SynthFrame {
    /// Left image (grey `Luma8`, or `Rgb8` with [`SynthConfig::colour`]).
    pub left: DynamicImage,
    /// Right image.
    pub right: DynamicImage,
    /// Left-camera CamVid class ids.
    pub labels: GrayImage,
    /// Left-camera moving-object mask (255 / 0).
    pub dynamic: GrayImage,
    /// Left-camera depth `Z` (m) per pixel, row-major; `f32::INFINITY` for sky. A debugging
    /// aid (not written by [`generate`]): the ground truth the stereo images were made from.
    pub depth_m: Vec<f32>,
}

impl SynthFrame {
    /// Fraction of pixels in the moving-object mask.
    pub fn dynamic_fraction(&self) -> f64 {
        let n = self.dynamic.as_raw().iter().filter(|&&v| v != 0).count();
        n as f64 / self.dynamic.as_raw().len() as f64
    }
}

/// A generated world and trajectory: renders any frame on demand, in any order.
#[derive(Debug)]
pub struct Scene {
    cfg: SynthConfig,
    world: World,
    ego: EgoTrack,
    agents: Vec<scene::Agent>,
    /// Left camera-to-world rotation and centre per frame (world frame of the scene).
    poses: Vec<([[f64; 3]; 3], [f64; 3])>,
    gains: Vec<[f32; 2]>,
}

/// Per-thread render buffers.
struct Workspace {
    gbuf: GBuf,
    row: Vec<[f32; 3]>,
    prims: Vec<Prim>,
    plane: Vec<u8>,
    tmp: Vec<u8>,
}

impl Workspace {
    fn new() -> Self {
        let (w, h) = (WIDTH as usize, HEIGHT as usize);
        Self {
            gbuf: GBuf::new(w, h),
            row: vec![[0.0; 3]; w],
            prims: Vec::new(),
            plane: Vec::new(),
            tmp: Vec::new(),
        }
    }
}

impl Scene {
    /// Builds the street, the ego trajectory and the traffic for `cfg`.
    ///
    /// # Errors
    /// [`SynthError::Config`] when `cfg.frames` is 0 (the path names nothing: `""`).
    pub fn new(cfg: &SynthConfig) -> Result<Self, SynthError> {
        if cfg.frames == 0 {
            return Err(SynthError::Config {
                path: PathBuf::new(),
                msg: "frames must be ≥ 1".into(),
            });
        }
        let mut rng_ego = Rng::new(cfg.seed.wrapping_mul(3).wrapping_add(1));
        let ego = EgoTrack::generate(cfg.frames, &mut rng_ego);
        let travel = ego.s.last().copied().unwrap_or(scene::EGO_START);
        let mut rng_world = Rng::new(cfg.seed);
        // The street depends on the seed only; its length is rounded up so that sequences of
        // different lengths with one seed share their beginning.
        let len = ((travel + 260.0) / 500.0).ceil() * 500.0;
        let world = World::build(len, &mut rng_world, cfg.dynamics == Dynamics::Parked);
        let mut rng_agents = Rng::new(cfg.seed.wrapping_mul(7).wrapping_add(2));
        let agents = scene::agents(cfg.dynamics, &world.path, &ego, &mut rng_agents);
        let phase = rng_ego.range(0.0, core::f64::consts::TAU);
        let poses =
            (0..cfg.frames).map(|k| scene::camera_pose(&world.path, &ego, k, phase)).collect();
        let (g1, g2) = (
            rng_ego.range(0.0, core::f64::consts::TAU),
            rng_ego.range(0.0, core::f64::consts::TAU),
        );
        let gains = (0..cfg.frames)
            .map(|k| {
                let t = k as f64 / scene::FPS;
                let g = (0.07 * (t * 0.45 + g1).sin() + 0.03 * (t * 1.7 + g2).sin()).exp();
                let j = 1.0 + 0.02 * (rng_ego.f() - 0.5);
                [(g * j) as f32, (g * j * (1.0 + 0.006 * (t * 0.8).sin())) as f32]
            })
            .collect();
        Ok(Self { cfg: cfg.clone(), world, ego, agents, poses, gains })
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.cfg.frames
    }

    /// Ground truth of frame `k` as a KITTI pose row: the left camera-to-world 3×4 matrix,
    /// row-major, relative to frame 0 (so frame 0 is the identity).
    ///
    /// # Panics
    /// If `k ≥ frames()`.
    pub fn pose_row(&self, k: usize) -> [f64; 12] {
        let (r0, c0) = &self.poses[0];
        let (rk, ck) = &self.poses[k];
        // R = R0ᵀ Rk, t = R0ᵀ (ck − c0)
        let mut m = [0.0; 12];
        let d = scene::sub3(*ck, *c0);
        for i in 0..3 {
            for j in 0..3 {
                m[i * 4 + j] = (0..3).map(|l| r0[l][i] * rk[l][j]).sum();
            }
            m[i * 4 + 3] = (0..3).map(|l| r0[l][i] * d[l]).sum();
        }
        m
    }

    /// Length of the left camera's path over all frames (m).
    pub fn path_length_m(&self) -> f64 {
        self.poses
            .windows(2)
            .map(|w| scene::sub3(w[1].1, w[0].1))
            .map(|d| scene::dot3(d, d).sqrt())
            .sum()
    }

    fn cam(&self, k: usize, right: bool) -> Cam {
        let (r, c) = self.poses[k];
        let c = if right {
            // Right camera centre: +b along the left camera's x axis (first column).
            [c[0] + BASELINE_M * r[0][0], c[1] + BASELINE_M * r[1][0], c[2] + BASELINE_M * r[2][0]]
        } else {
            c
        };
        // World → camera: Rᵀ, −Rᵀ c.
        let rt =
            [[r[0][0], r[1][0], r[2][0]], [r[0][1], r[1][1], r[2][1]], [r[0][2], r[1][2], r[2][2]]];
        let t = [
            -(rt[0][0] * c[0] + rt[0][1] * c[1] + rt[0][2] * c[2]),
            -(rt[1][0] * c[0] + rt[1][1] * c[1] + rt[1][2] * c[2]),
            -(rt[2][0] * c[0] + rt[2][1] * c[1] + rt[2][2] * c[2]),
        ];
        Cam { fx: FX, fy: FX, cx: CX, cy: CY, r: rt, t }
    }

    /// Renders frame `k` (left, right, labels, mask, depth).
    ///
    /// # Panics
    /// If `k ≥ frames()`.
    pub fn render(&self, k: usize) -> SynthFrame {
        let mut ws = Workspace::new();
        self.render_into(k, &mut ws, true)
    }

    fn render_into(&self, k: usize, ws: &mut Workspace, want_depth: bool) -> SynthFrame {
        let s = self.ego.s[k];
        ws.prims.clear();
        scene::agent_prims(&self.agents, &self.world.path, &self.ego, k, &mut ws.prims);
        let range = self.world.range(s - 20.0, s + 230.0);
        let dynamic_prims = core::mem::take(&mut ws.prims);
        let list: Vec<&Prim> = self.world.prims[range].iter().chain(dynamic_prims.iter()).collect();
        let (w, h) = (WIDTH as usize, HEIGHT as usize);

        let left_cam = self.cam(k, false);
        ws.gbuf.render(&left_cam, &list);
        let mut labels = vec![class::SKY; w * h];
        let mut dynamic = vec![0u8; w * h];
        for (i, &id) in ws.gbuf.id.iter().enumerate() {
            if id != SKY {
                let p = list[id as usize];
                labels[i] = p.class;
                dynamic[i] = if p.dynamic { 255 } else { 0 };
            }
        }
        let depth_m = if want_depth {
            ws.gbuf.invz.iter().map(|&iz| if iz > 0.0 { 1.0 / iz } else { f32::INFINITY }).collect()
        } else {
            Vec::new()
        };
        let left = self.develop(k, 0, &left_cam, &list, ws);
        let right_cam = self.cam(k, true);
        ws.gbuf.render(&right_cam, &list);
        let right = self.develop(k, 1, &right_cam, &list, ws);
        drop(list);
        ws.prims = dynamic_prims;
        SynthFrame {
            left,
            right,
            labels: GrayImage::from_raw(WIDTH, HEIGHT, labels).unwrap_or_default(),
            dynamic: GrayImage::from_raw(WIDTH, HEIGHT, dynamic).unwrap_or_default(),
            depth_m,
        }
    }

    /// Shades the G-buffer and turns radiance into a sensor image: exposure, vignetting,
    /// quantisation, a light optical blur, then noise.
    fn develop(
        &self,
        k: usize,
        cam_no: u32,
        cam: &Cam,
        list: &[&Prim],
        ws: &mut Workspace,
    ) -> DynamicImage {
        let (w, h) = (WIDTH as usize, HEIGHT as usize);
        let ch = if self.cfg.colour { 3 } else { 1 };
        let gain = self.gains[k][cam_no as usize];
        ws.plane.resize(w * h * ch, 0);
        for j in 0..h {
            ws.gbuf.shade(cam, list, j..j + 1, &mut ws.row, &material::sky);
            let dy = (j as f32 - CY as f32) / FX as f32;
            let out = &mut ws.plane[j * w * ch..(j + 1) * w * ch];
            for (i, c) in ws.row.iter().enumerate() {
                let dx = (i as f32 - CX as f32) / FX as f32;
                let g = gain * (1.0 - 0.22 * (dx * dx + dy * dy));
                if ch == 1 {
                    let y = (0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2]) * g;
                    out[i] = y.clamp(0.0, 255.0) as u8;
                } else {
                    for q in 0..3 {
                        out[i * 3 + q] = (c[q] * g).clamp(0.0, 255.0) as u8;
                    }
                }
            }
        }
        blur_121(&mut ws.plane, &mut ws.tmp, w, h, ch);
        let seed =
            (self.cfg.seed as u32) ^ ((self.cfg.seed >> 32) as u32).wrapping_mul(0x9e37_79b9);
        let frame_key = (k as u32).wrapping_mul(2).wrapping_add(cam_no);
        for (idx, px) in ws.plane.iter_mut().enumerate() {
            let hsh = texture::hash3(idx as i32, frame_key as i32, seed);
            let a = (hsh & 0xffff) as f32 * (1.0 / 65536.0);
            let b = (hsh >> 16) as f32 * (1.0 / 65536.0);
            let v = *px as f32;
            // Triangular noise (variance σ²): read noise + a little shot noise.
            let sigma = 1.5 + 0.015 * v;
            let n = (a + b - 1.0) * sigma * 2.449_49;
            *px = (v + n + 0.5).clamp(0.0, 255.0) as u8;
        }
        let data = ws.plane.clone();
        if ch == 1 {
            DynamicImage::ImageLuma8(GrayImage::from_raw(WIDTH, HEIGHT, data).unwrap_or_default())
        } else {
            DynamicImage::ImageRgb8(RgbImage::from_raw(WIDTH, HEIGHT, data).unwrap_or_default())
        }
    }
}

/// Separable `[1 6 1]/8` blur (a lens that is slightly soft, as KITTI's), in place.
fn blur_121(img: &mut [u8], tmp: &mut Vec<u8>, w: usize, h: usize, ch: usize) {
    tmp.resize(img.len(), 0);
    let stride = w * ch;
    for j in 0..h {
        let row = &img[j * stride..(j + 1) * stride];
        let out = &mut tmp[j * stride..(j + 1) * stride];
        for x in 0..stride {
            let l = if x >= ch { row[x - ch] } else { row[x] };
            let r = if x + ch < stride { row[x + ch] } else { row[x] };
            out[x] = ((l as u16 + 6 * row[x] as u16 + r as u16 + 4) >> 3) as u8;
        }
    }
    for j in 0..h {
        let up = j.saturating_sub(1);
        let dn = (j + 1).min(h - 1);
        for x in 0..stride {
            let v = tmp[up * stride + x] as u16
                + 6 * tmp[j * stride + x] as u16
                + tmp[dn * stride + x] as u16;
            img[j * stride + x] = ((v + 4) >> 3) as u8;
        }
    }
}

/// KITTI-style number: `%.{digits}e` with a signed two-digit exponent (`7.188560000000e+02`).
fn kitti_num(x: f64, digits: usize) -> String {
    let s = format!("{:.*e}", digits, x);
    match s.split_once('e') {
        Some((m, e)) => {
            let (sign, e) =
                if let Some(rest) = e.strip_prefix('-') { ('-', rest) } else { ('+', e) };
            format!("{m}e{sign}{e:0>2}")
        }
        None => s,
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), SynthError> {
    std::fs::write(path, bytes).map_err(io_err(path))
}

fn encode_png(
    path: &Path,
    data: &[u8],
    color: ExtendedColorType,
    buf: &mut Vec<u8>,
) -> Result<(), SynthError> {
    buf.clear();
    let enc = PngEncoder::new_with_quality(&mut *buf, CompressionType::Fast, FilterType::Sub);
    enc.write_image(data, WIDTH, HEIGHT, color)
        .map_err(|e| SynthError::Encode { path: path.to_path_buf(), msg: e.to_string() })?;
    write_file(path, buf)
}

/// The `calib.txt` text: P0/P2 = K[I|0], P1/P3 = K[I|(−b, 0, 0)].
pub fn calib_text() -> String {
    let p = |tx: f64| {
        let m = [FX, 0.0, CX, -FX * tx, 0.0, FX, CY, 0.0, 0.0, 0.0, 1.0, 0.0];
        m.iter().map(|v| kitti_num(*v, 12)).collect::<Vec<_>>().join(" ")
    };
    let (l, r) = (p(0.0), p(BASELINE_M));
    format!("P0: {l}\nP1: {r}\nP2: {l}\nP3: {r}\n")
}

/// Writes a synthetic sequence to `out_dir` (see the module docs); same as
/// [`generate_with_progress`] without a progress callback.
///
/// # Errors
/// [`SynthError`] naming the file or folder that could not be written.
pub fn generate(out_dir: &Path, cfg: &SynthConfig) -> Result<SynthSummary, SynthError> {
    generate_with_progress(out_dir, cfg, &|_| {})
}

/// Writes a synthetic sequence, calling `progress(frames_done)` after each frame (from the
/// calling thread).
///
/// # Errors
/// [`SynthError`] naming the file or folder that could not be written; [`SynthError::Config`]
/// for zero frames or a sequence name that is not a plain folder name.
pub fn generate_with_progress(
    out_dir: &Path,
    cfg: &SynthConfig,
    progress: &dyn Fn(usize),
) -> Result<SynthSummary, SynthError> {
    let start = Instant::now();
    if cfg.seq.is_empty() || cfg.seq.contains(['/', '\\']) || cfg.seq == "." || cfg.seq == ".." {
        return Err(SynthError::Config {
            path: out_dir.to_path_buf(),
            msg: format!("sequence name {:?} is not a folder name", cfg.seq),
        });
    }
    let scene = Scene::new(cfg).map_err(|e| match e {
        SynthError::Config { msg, .. } => SynthError::Config { path: out_dir.to_path_buf(), msg },
        other => other,
    })?;
    let seq_dir = out_dir.join("sequences").join(&cfg.seq);
    let (lname, rname) = if cfg.colour { ("image_2", "image_3") } else { ("image_0", "image_1") };
    let dirs = [
        seq_dir.join(lname),
        seq_dir.join(rname),
        seq_dir.join("semantic"),
        seq_dir.join("dynamic"),
    ];
    for d in dirs.iter().chain([&out_dir.join("poses")]) {
        std::fs::create_dir_all(d).map_err(io_err(d))?;
    }
    write_file(&seq_dir.join("calib.txt"), calib_text().as_bytes())?;
    let times: String =
        (0..cfg.frames).map(|k| kitti_num(k as f64 / scene::FPS, 6) + "\n").collect();
    write_file(&seq_dir.join("times.txt"), times.as_bytes())?;
    let poses: String = (0..cfg.frames)
        .map(|k| {
            let row = scene.pose_row(k);
            row.iter().map(|v| kitti_num(*v, 9)).collect::<Vec<_>>().join(" ") + "\n"
        })
        .collect();
    write_file(&out_dir.join("poses").join(format!("{}.txt", cfg.seq)), poses.as_bytes())?;

    let threads = match cfg.threads {
        0 => std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
        n => n,
    }
    .min(cfg.frames)
    .max(1);
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let first_err: Mutex<Option<SynthError>> = Mutex::new(None);
    let fracs: Mutex<Vec<f64>> = Mutex::new(vec![0.0; cfg.frames]);
    let (tx, rx) = std::sync::mpsc::channel::<()>();
    std::thread::scope(|sc| {
        for _ in 0..threads {
            let tx = tx.clone();
            let (scene, dirs, next, failed, first_err, fracs) =
                (&scene, &dirs, &next, &failed, &first_err, &fracs);
            sc.spawn(move || {
                let mut ws = Workspace::new();
                let mut buf = Vec::new();
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    if k >= scene.frames() || failed.load(Ordering::Relaxed) {
                        break;
                    }
                    match write_frame(scene, k, dirs, &mut ws, &mut buf) {
                        Ok(f) => {
                            if let Ok(mut v) = fracs.lock() {
                                v[k] = f;
                            }
                            let _ = tx.send(());
                        }
                        Err(e) => {
                            failed.store(true, Ordering::Relaxed);
                            if let Ok(mut slot) = first_err.lock() {
                                slot.get_or_insert(e);
                            }
                            break;
                        }
                    }
                }
            });
        }
        drop(tx);
        let mut done = 0;
        for () in rx {
            done += 1;
            progress(done);
        }
    });
    if let Some(e) = first_err.into_inner().ok().flatten() {
        return Err(e);
    }
    let fracs = fracs.into_inner().unwrap_or_default();
    let n = fracs.len().max(1) as f64;
    Ok(SynthSummary {
        sequence_dir: seq_dir,
        frames: cfg.frames,
        path_length_m: scene.path_length_m(),
        dynamic_fraction_mean: fracs.iter().sum::<f64>() / n,
        dynamic_fraction_max: fracs.iter().copied().fold(0.0, f64::max),
        frames_dynamic_over_30pct: fracs.iter().filter(|&&f| f >= 0.3).count(),
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Renders and writes frame `k`; returns its dynamic pixel fraction.
fn write_frame(
    scene: &Scene,
    k: usize,
    dirs: &[PathBuf; 4],
    ws: &mut Workspace,
    buf: &mut Vec<u8>,
) -> Result<f64, SynthError> {
    let fr = scene.render_into(k, ws, false);
    let name = format!("{k:06}.png");
    let color = if scene.cfg.colour { ExtendedColorType::Rgb8 } else { ExtendedColorType::L8 };
    encode_png(&dirs[0].join(&name), fr.left.as_bytes(), color, buf)?;
    encode_png(&dirs[1].join(&name), fr.right.as_bytes(), color, buf)?;
    encode_png(&dirs[2].join(&name), fr.labels.as_raw(), ExtendedColorType::L8, buf)?;
    encode_png(&dirs[3].join(&name), fr.dynamic.as_raw(), ExtendedColorType::L8, buf)?;
    Ok(fr.dynamic_fraction())
}
