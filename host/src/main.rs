//! `semloc` command-line interface.
fn main() {}
