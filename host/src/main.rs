//! `semloc` command-line interface: see `semloc --help`.
//!
//! Each subcommand lives in its own module under `cli/`; this file only parses arguments,
//! dispatches, and turns errors into a message naming the file and problem plus exit code 1
//! (clap uses 2 for usage errors; a run stopped by a signal exits 128 + the signal).
#![deny(unsafe_code)]

use clap::{Parser, Subcommand};

mod cli;

/// semloc — semantic visual localisation for automotive ECUs.
///
/// Stereo SLAM with semantic ORB features and EM probabilistic data association
/// (Yang et al., Sensors 2022). The CLI runs the tracker on KITTI data, inspects datasets
/// and evaluates trajectories the way the KITTI devkit and evo do.
#[derive(Parser, Debug)]
#[command(name = "semloc", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Evaluate an estimated trajectory against ground truth (KITTI devkit t_rel/r_rel, ATE).
    Eval(cli::eval::EvalArgs),
    /// Describe what a dataset folder (KITTI odometry or raw, stereo folder, EuRoC MAV) holds.
    Info(cli::info::InfoArgs),
    /// The settings file: print the defaults (every key documented), check a file, or convert
    /// an ORB-SLAM2 YAML file.
    Config(cli::config::ConfigArgs),
    /// Write a dataset's ground truth as KITTI poses and TUM (recording times), for evo or the
    /// devkit.
    Gt(cli::gt::GtArgs),
    /// Run the stereo tracker on a sequence; write trajectory, timings and evaluation.
    Run(cli::run::RunArgs),
    /// The main job on an embedded default: a synthetic high-traffic drive tracked without and
    /// with semantics, side by side.
    Demo(cli::demo::DemoArgs),
    /// The paper's ablation on one dataset: semantics off/cull/full x association hard/em in
    /// one invocation, one table, and the share of features on static structure (Fig. 4).
    Ablate(cli::ablate::AblateArgs),
    /// Two `semloc ablate` results paired start by start (or seed by seed): per row, the
    /// variant's ATE against the reference's, geometric mean ± standard error, worst, starts
    /// better.
    Compare(cli::compare::CompareArgs),
    /// Time the pipeline per stage, against OpenCV's ORB and a one-thread run of itself.
    Bench(cli::bench::BenchArgs),
    /// Every sequence of a KITTI odometry root, one Table-3-style table (t_rel, r_rel, ATE per
    /// sequence and configuration), optionally beside reference trajectories (e.g. ORB-SLAM2).
    BenchKitti(cli::bench_kitti::BenchKittiArgs),
    /// Write a synthetic KITTI-layout stereo sequence with traffic, GT poses and labels.
    Synth(cli::synth::SynthArgs),
    /// Convert a float ONNX export + its quant.json to the int8 .slm blob the core runs.
    Convert(cli::convert::ConvertArgs),
    /// Label images with the int8 network: class-id maps and colour overlays.
    Segment(cli::segment::SegmentArgs),
    /// Compare the int8 network with its float ONNX (tract): label agreement, CamVid mIoU.
    VerifySeg(cli::verify_seg::VerifySegArgs),
}

/// Unix conventions the Rust runtime does not follow by default: SIGPIPE back to its default
/// action, so `semloc eval ... | head` ends quietly as other tools do instead of panicking in
/// `println!`; SIGXFSZ ignored, so a file size limit (`ulimit -f`) turns into a write error
/// that is reported and leaves whole files, not a kill mid-write.
#[allow(unsafe_code)]
fn unix_signal_defaults() {
    // SAFETY: `signal` with SIG_DFL / SIG_IGN installs no handler code; it runs before any
    // other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
}

fn main() -> std::process::ExitCode {
    unix_signal_defaults();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Eval(args) => cli::eval::run(&args),
        Command::Info(args) => cli::info::run(&args),
        Command::Gt(args) => cli::gt::run(&args),
        Command::Config(args) => cli::config::run(&args),
        Command::Run(args) => cli::run::run(&args),
        Command::Ablate(args) => cli::ablate::run(&args),
        Command::Compare(args) => cli::compare::run(&args),
        Command::Bench(args) => cli::bench::run(&args),
        Command::BenchKitti(args) => cli::bench_kitti::run(&args),
        Command::Demo(args) => cli::demo::run(&args),
        Command::Synth(args) => cli::synth::run(&args),
        Command::Convert(args) => cli::convert::run(&args),
        Command::Segment(args) => cli::segment::run(&args),
        Command::VerifySeg(args) => cli::verify_seg::run(&args),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", cli::error_text(&e));
            let code = e.downcast_ref::<cli::Exit>().map_or(1, |x| x.code);
            std::process::ExitCode::from(code)
        }
    }
}
