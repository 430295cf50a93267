//! # semloc-core
//!
//! The `#![no_std]`, allocation-free heart of semloc: the part that runs on the ECU. It
//! implements Yang et al., *Accurate Location in Dynamic Traffic Environment Using Semantic
//! Information and Probabilistic Data Association* (Sensors 2022, 22, 5042) on an ORB-SLAM2-style
//! stereo backbone. Everything here works on caller-provided, fixed-size storage; nothing
//! touches a heap, and the same input gives the same bits on every target and thread count.
//!
//! ## The one entry point
//! [`localiser::Localiser`] is the per-frame pipeline — labels → semantic weights → ORB (left ∥
//! right) → stereo → semantic annotation → tracking — that the host CLI, the ECU simulation,
//! the bare-metal image and the tests all drive:
//!
//! ```
//! use semloc_core::geom::StereoCamera;
//! use semloc_core::localiser::{Localiser, LocaliserConfig};
//! use semloc_core::seg::WeightScheme;
//! # fn main() {
//! #     // ≈ 11 MiB by value: more than a main thread's default stack.
//! #     let t = std::thread::Builder::new().stack_size(1 << 30).spawn(run).unwrap();
//! #     t.join().unwrap();
//! # }
//! # fn run() {
//! let (w, h) = (320usize, 96usize);
//! let cam = StereoCamera::new(180.0, 180.0, 160.0, 48.0, 0.54).expect("camera");
//! let mut config = LocaliserConfig::new(cam, w as u32, h as u32);
//! config.semantics = Some(WeightScheme::Full); // the paper's semantic ORB (Eq. 2)
//! let mut loc = Box::new(Localiser::new(&config).expect("config"));
//! // A synthetic frame: random 4x4 blocks, the right image the left seen 8 px further left;
//! // labels "building" (1) with a "car" (8) in the middle.
//! let tex = |x: usize, y: usize| {
//!     let v = (x / 4).wrapping_mul(2_654_435_761) ^ (y / 4).wrapping_mul(40_503);
//!     (v.wrapping_mul(2_246_822_519) >> 13) as u8
//! };
//! let left: Vec<u8> = (0..w * h).map(|i| tex(i % w, i / w)).collect();
//! let right: Vec<u8> = (0..w * h).map(|i| tex(i % w + 8, i / w)).collect();
//! let labels: Vec<u8> =
//!     (0..w * h).map(|i| if (100..200).contains(&(i % w)) { 8 } else { 1 }).collect();
//! let lv = semloc_core::image::ImageView::from_slice(&labels, w, h).expect("labels");
//! loc.set_labels(&lv).expect("label size");
//! let out = loc.process_raw(&left, &right, 0.0, None).expect("frame");
//! assert!(out.culled > 0); // FAST candidates on the car got weight 0
//! println!("pose {:?}, {} stereo points", out.report.t_wc.trans, out.stereo.matched);
//! # }
//! ```
//!
//! ## Module map (paper section / equation → module)
//! - [`localiser`]: the per-frame pipeline and the int8 network as a frame stage
//!   ([`localiser::Network`]).
//! - [`nn`] — §3.1, the segmentation network: `.slm` blob parser, arena planner, graph
//!   executor and int8 kernels (improved Fast-SCNN with Res2Net blocks).
//! - [`seg`] — §3.1 / Table 1 and Eq. 2's weights: CamVid classes → categories, the
//!   semantic weight image (ω = 0 on dynamic classes, ×3 on construction and object).
//! - [`orb`] — §3.1, semantic ORB: image pyramid 8 × 1.2, **Eq. 1** per-level feature
//!   quotas, FAST-9, Harris response weighted by class (**Eq. 2**), quadtree distribution,
//!   orientation and rBRIEF — ORB-SLAM2's `ORBextractor` in fixed memory.
//! - [`semdesc`] — **§3.2**, the 21×21 same-class semantic descriptor at class boundaries and
//!   its matching threshold (55).
//! - [`assoc`] — **§3.3, Eqs. 3–9**: data association — nearest neighbour (ORB-SLAM2) and
//!   the EM probabilistic association (maximum expected measurement likelihood after Bowman
//!   et al. 2017: E-step weights over gated candidates with a null hypothesis, weighted M-step
//!   pose optimisation, the final decision); per-feature classes and descriptors.
//! - [`tracker`] — orchestration per frame: constant-velocity prediction, projection search,
//!   association, motion-only optimisation, keyframe decision, loss and re-initialisation.
//! - [`map`] — the bounded map of keyframes and landmarks and its maintenance (keyframe
//!   insertion, local bundle adjustment, culling).
//! - [`stereo`] — ORB-SLAM2's stereo matching (row band, Hamming, SAD sub-pixel refinement).
//! - [`optim`] — motion-only pose optimisation and window bundle adjustment (Gauss-Newton /
//!   Levenberg-Marquardt with Huber weights, χ² outlier rounds).
//! - [`ransac`] — RANSAC pose hypotheses (3-point stereo) before optimisation.
//! - [`frame`] — one stereo frame's features, the tracker's input.
//! - [`geom`] — SE(3) (exp/log, compose, inverse), the pinhole stereo camera, projection
//!   Jacobians.
//! - [`image`] — luma image views and buffers, bilinear resize, 7×7 Gaussian blur.
//! - [`math`] — the one place float transcendental functions come from (libm, same bits on
//!   every target).
//! - `testing` (only under `cfg(test)` or the `testing` feature): the fixtures every crate's
//!   tests share — KITTI camera, seeded generators, procedural images, golden hashes.
#![cfg_attr(not(test), no_std)]
// Nothing reachable from input may panic through these (indexing is bounded by the checks at
// each entry, fuzzed in tests/fuzz); tests may unwrap.
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::todo,
        clippy::unimplemented
    )
)]

pub mod arch;
pub mod assoc;
pub mod frame;
pub mod geom;
pub mod image;
pub mod localiser;
pub mod map;
pub mod math;
pub mod motion;
pub mod nn;
pub mod optim;
pub mod orb;
pub mod ransac;
pub mod seg;
pub mod semdesc;
pub mod stereo;
#[cfg(any(test, feature = "testing"))]
pub mod testing;
pub mod tracker;
