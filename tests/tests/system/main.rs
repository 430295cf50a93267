//! semloc's end-to-end and real-data tests, as one test binary (each test binary links the
//! whole host crate, tract included: one per file filled a CI disk once). `ecu_sim` and
//! `no_alloc` stay binaries of their own because each installs a counting global allocator;
//! `fuzz_parsers` because CI runs it alone with its own time budget.

mod e2e_synth;
mod eval_reference;
mod kitti_odometry_run;
mod kitti_raw_run;
mod raw_oracle;
mod segmentation;
mod synth;
