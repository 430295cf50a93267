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
#![cfg_attr(not(test), no_std)]

pub mod geom;
pub mod math;
