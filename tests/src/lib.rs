//! Shared helpers for semloc's end-to-end tests (the tests themselves live in `tests/tests/`; most are modules of `tests/tests/system/`).
#![forbid(unsafe_code)]
use std::path::PathBuf;

/// The shared real-data folder (`../shared/data` from the workspace root), if it exists.
///
/// Real-data tests skip (with a message) when it is absent so a plain `cargo test` works on a
/// fresh machine; CI sets `SEMLOC_REQUIRE_DATA=1` so that absence is a failure there.
pub fn shared_data() -> Option<PathBuf> {
    let root =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("..").join("shared").join("data");
    if root.is_dir() {
        Some(root)
    } else if std::env::var_os("SEMLOC_REQUIRE_DATA").is_some() {
        panic!("SEMLOC_REQUIRE_DATA is set but {} does not exist", root.display());
    } else {
        eprintln!("skipping: {} not found", root.display());
        None
    }
}

/// Runs `f` on a thread with a 1 GiB stack and returns its result: core's map, tracker and
/// localiser are tens of MiB of fixed arrays, which the ECU keeps in static memory and a test
/// builds on its stack. The stack is only reserved; pages are touched as the test uses them.
/// A panic in `f` fails the calling test. (Core's own unit tests have
/// `semloc_core::testing::on_big_stack`, which exists only under `cfg(test)` there.)
pub fn on_big_stack<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::Builder::new().stack_size(1 << 30).spawn(f).unwrap().join().unwrap()
}
