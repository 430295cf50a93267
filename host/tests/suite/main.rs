//! The host crate's integration tests, as one test binary: every module runs the `semloc`
//! binary or the library the way a user would. One binary, not one per file, because each
//! test binary links tract, image and rerun (tens of MB apiece): a dozen of them filled a CI
//! disk once.

mod common;

mod bench_kitti;
mod chaos;
mod cli;
mod inputs_cli;
mod map_export;
mod outputs_doc;
mod rerun_viewer;
mod runner;
mod schedules;
mod seg_cli;
mod settings_gt;
