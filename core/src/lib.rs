//! # semloc-core
//!
//! The `#![no_std]`, allocation-free heart of semloc: the part that runs on the ECU.
//! Everything here works on caller-provided, fixed-size storage; nothing touches a heap.
//!
//! Modules:
//! - [`math`]: the one place float transcendental functions come from (libm, same bits on
//!   every target).
//! - [`geom`]: SE(3) (exp/log, compose, inverse), the pinhole stereo camera and projection
//!   Jacobians.
//! - [`frame`]: the tracker's input, one stereo frame's features.
//! - [`optim`]: motion-only pose optimisation and sliding-window bundle adjustment.
//! - [`assoc`]: data association, nearest neighbour or EM (paper §3.3), and the pose solve.
//! - [`map`]: the bounded window of keyframes and landmarks and its keyframe maintenance.
//! - [`tracker`]: the per-frame stereo tracker, core's SLAM entry point.
//! - [`image`], [`orb`], [`stereo`], [`ransac`]: the geometric front end.
//! - [`seg`], [`semdesc`]: class table, semantic ORB weights and the semantic descriptor.
//! - [`image`]: luma image views and buffers, bilinear resize, 7×7 Gaussian blur.
//! - [`orb`]: ORB extraction as ORB-SLAM2's `ORBextractor`, in fixed memory, with a
//!   semantic weight hook.
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

pub mod assoc;
pub mod frame;
pub mod geom;
pub mod image;
pub mod map;
pub mod math;
pub mod nn;
pub mod optim;
pub mod orb;
pub mod ransac;
pub mod seg;
pub mod semdesc;
pub mod stereo;
pub mod tracker;
