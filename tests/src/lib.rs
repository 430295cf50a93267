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
