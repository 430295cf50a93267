//! Subcommands of the `semloc` binary.

pub mod eval;
pub mod info;
