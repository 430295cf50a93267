//! # semloc (host)
//!
//! The std side of semloc: dataset readers (KITTI odometry and raw), trajectory I/O and
//! evaluation (KITTI devkit t_rel/r_rel, SE(3)/Sim(3) Umeyama ATE), plots, and the `semloc` CLI.
//! The core (`semloc-core`) stays `no_std`; everything that touches files lives here, and every
//! file error names the file (and line, where there is one).

#![forbid(unsafe_code)]
pub mod dataset;
pub mod eval;
pub mod pipeline;
pub mod plot;
pub mod synth;
pub mod traj;
