//! # semloc (host)
//!
//! The std side of semloc: dataset readers (KITTI odometry and raw), trajectory I/O and
//! evaluation (KITTI devkit t_rel/r_rel, SE(3)/Sim(3) Umeyama ATE), plots, the segmentation
//! network's files (ONNX → `.slm` conversion, tract float reference: [`nn`]), the run loop with
//! its output files ([`run`]), and the `semloc` CLI.
//! The core (`semloc-core`) stays `no_std`; everything that touches files lives here, and every
//! file error names the file (and line, where there is one).
#![forbid(unsafe_code)]

pub mod dataset;
pub mod eval;
pub mod nn;
pub mod pipeline;
pub mod plot;
pub mod run;
pub mod settings;
pub mod synth;
pub mod traj;
