//! Helpers shared by the CLI tests: run the `semloc` binary, read its output, make a small
//! synthetic sequence once per test run.
#![allow(dead_code)] // not every helper is used by every build (the rerun module is optional)

use std::path::Path;
use std::process::{Command, Output};
use std::sync::OnceLock;

/// Runs the `semloc` binary built for these tests.
pub fn semloc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_semloc")).args(args).output().expect("run semloc")
}

/// stdout and stderr of `o`, for assertion messages.
pub fn text(o: &Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// stdout and stderr of `o`, separately (for assertions on one of them).
pub fn streams(o: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// `p` as UTF-8 (temporary paths are).
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A `semloc synth` KITTI odometry root in a temporary folder: `ROOT/sequences/00` and
/// `ROOT/poses/00.txt`, `frames` frames of `dynamics` traffic from `seed`.
pub fn synth(frames: &str, dynamics: &str, seed: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let o = semloc(&[
        "synth",
        "--out",
        s(dir.path()),
        "--frames",
        frames,
        "--dynamics",
        dynamics,
        "--seed",
        seed,
    ]);
    assert!(o.status.success(), "synth: {}", text(&o));
    dir
}

/// `ROOT/sequences/00` of `semloc synth` (10 frames, a street lined with parked cars, with
/// `semantic/` labels) and `ROOT/poses/00.txt`, written once per test binary.
pub fn parked_root() -> &'static Path {
    static ROOT: OnceLock<tempfile::TempDir> = OnceLock::new();
    ROOT.get_or_init(|| synth("10", "parked", "11")).path()
}

/// `semloc run` on [`parked_root`]'s sequence 00 into `out`, with `extra` arguments.
pub fn run_parked(out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["run", s(parked_root()), "--seq", "00", "--out", s(out)];
    args.extend_from_slice(extra);
    semloc(&args)
}
