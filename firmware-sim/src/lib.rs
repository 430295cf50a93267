//! # semloc-firmware-sim
//!
//! The ECU simulation of semloc-core (fixed arena, 10 Hz sensor clock, frame deadlines, fault
//! injection, a bare-metal `aarch64-unknown-none` image under QEMU). It lands with the
//! firmware issue, once the core has a tracker to run; until then this crate only holds the
//! workspace slot fixed by the product shape and proves that core links into a second crate
//! built with the same `no_std` settings.
#![no_std]
#![forbid(unsafe_code)]

pub use semloc_core as core_crate;
