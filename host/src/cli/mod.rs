//! Subcommands of the `semloc` binary.

pub mod ablate;
pub mod bench;
pub mod convert;
pub mod demo;
pub mod eval;
pub mod info;
pub mod run;
pub mod segment;
pub mod synth;
pub mod verify_seg;

/// A bar for work that takes over a second; indicatif hides it when stderr is not a terminal,
/// so logs and CI output stay clean.
pub fn progress(len: u64, what: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(len);
    pb.set_style(
        indicatif::ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} ({eta})")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb.set_message(what.to_owned());
    pb
}
