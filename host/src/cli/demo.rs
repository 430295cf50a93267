//! `semloc demo`: the main job on an embedded default. Generates a short high-dynamic
//! synthetic sequence and tracks it without and with semantics, side by side.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use semloc::dataset::Sequence;
use semloc::run::{Network, RunConfig, Semantics};
use semloc::synth::{generate, Dynamics, SynthConfig};
use semloc_core::assoc::Association;

use super::ablate::{run_rows, table, write_overlay};

/// Arguments of `semloc demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Folder for the generated sequence and the runs (default: a new folder under the system
    /// temp dir, kept and printed at the end).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Use a non-empty --out: first remove what `semloc demo` wrote there before.
    #[arg(long)]
    pub force: bool,
    /// Frames to generate (10 Hz).
    #[arg(long, default_value_t = 120, value_name = "N", value_parser = clap::value_parser!(u64).range(3..))]
    pub frames: u64,
    /// Seed of the synthetic street and traffic.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// How dynamic the traffic is.
    #[arg(long, value_enum, default_value_t = DynamicsArg::High)]
    pub dynamics: DynamicsArg,
    /// Label frames with this int8 network (`.slm`) instead of the generator's ground truth.
    #[arg(long, value_name = "SLM")]
    pub model: Option<PathBuf>,
}

/// `--dynamics` values.
#[derive(Copy, Clone, Debug, clap::ValueEnum)]
pub enum DynamicsArg {
    /// No moving agents.
    Static,
    /// A few agents, mostly far.
    Low,
    /// Agents cover ≥ 30 % of many frames; a truck leads the camera.
    High,
}

/// Runs `semloc demo`.
pub fn run(args: &DemoArgs) -> Result<()> {
    let out = match &args.out {
        Some(d) => d.clone(),
        None => std::env::temp_dir().join(format!("semloc-demo-{}", std::process::id())),
    };
    let kept = semloc::run::prepare_output_dir(&out, args.force, &super::ablate::ablate_outputs())?;
    super::print_warnings(kept.as_slice());
    let dynamics = match args.dynamics {
        DynamicsArg::Static => Dynamics::Static,
        DynamicsArg::Low => Dynamics::Low,
        DynamicsArg::High => Dynamics::High,
    };
    let data = out.join("sequence");
    let cfg = SynthConfig {
        frames: args.frames as usize,
        dynamics,
        seed: args.seed,
        ..SynthConfig::default()
    };
    let t = Instant::now();
    let synth = generate(&data, &cfg)?;
    println!(
        "generated {} frames ({:.1} m, {:.0} % of pixels dynamic on average) in {:.1} s",
        cfg.frames,
        synth.path_length_m,
        synth.dynamic_fraction_mean * 100.0,
        t.elapsed().as_secs_f64()
    );
    let seq = Sequence::open_odometry(&data, &cfg.seq, None)?;
    // `semloc run`'s defaults (two threads, SE(3) alignment, every frame) for every row
    let base = || RunConfig {
        network: args.model.clone().map(Network::File),
        ..RunConfig::new(&seq, &out)
    };
    let pairs = [Semantics::Off, Semantics::Cull, Semantics::Full].map(|s| (s, Association::Hard));
    let rows = run_rows(&base, &pairs, &out)?;
    println!();
    print!("{}", table(&rows));
    println!();
    for p in write_overlay(&out, &seq, &rows, cfg.frames)? {
        println!("wrote {}", p.display());
    }
    println!(
        "semantics: labels are {}; 'cull' drops features on cars, pedestrians and cyclists, 'full' \
         also weights buildings, fences, poles and signs x3 (the paper's semantic ORB).",
        match &args.model {
            Some(p) => format!("the int8 network's ({})", p.display()),
            None => "the generator's ground truth (--model FILE.slm labels with the network)".into(),
        }
    );
    println!("sequence, trajectories, plots: {}", out.display());
    Ok(())
}
