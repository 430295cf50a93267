//! Subcommands of the `semloc` binary.

pub mod ablate;
pub mod bench;
pub mod bench_kitti;
pub mod compare;
pub mod config;
pub mod convert;
pub mod demo;
pub mod eval;
pub mod gt;
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

/// An error that ends the process with a particular exit status (e.g. 130 after SIGINT).
#[derive(Debug)]
pub struct Exit {
    /// The exit status.
    pub code: u8,
    /// What to print after `error: `.
    pub message: String,
}

impl core::fmt::Display for Exit {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&self.message)
    }
}

impl core::error::Error for Exit {}

/// An error and its causes on one line, `a: b: c`, each said once (see
/// [`semloc::run::outputs::error_chain`]).
pub fn error_text(e: &anyhow::Error) -> String {
    semloc::run::outputs::error_chain(e.as_ref())
}

/// Prints warnings to stderr, each on its own `warning:` line.
pub fn print_warnings(warnings: &[String]) {
    for w in warnings {
        eprintln!("warning: {w}");
    }
}

/// The command line as typed, for provenance.
pub fn command_line() -> Vec<String> {
    std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect()
}

/// Writes `text` to stdout; a failure other than a closed pipe (a full disk behind `> log`)
/// becomes a warning on stderr instead of the panic `println!` would end in.
pub fn write_stdout(text: &str) {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        eprintln!("warning: writing the report to stdout failed: {e}");
    }
}
