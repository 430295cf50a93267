//! `semloc demo`: the main job on an embedded default. Generates a short high-dynamic
//! synthetic sequence and tracks it without and with semantics, side by side.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use semloc::dataset::Sequence;
use semloc::synth::{generate, Dynamics, SynthConfig};

use super::eval::AlignArg;
use super::run::{execute, RunConfig, RunOutcome, SemanticsArg};

/// Arguments of `semloc demo`.
#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Folder for the generated sequence and the runs (default: a new folder under the system
    /// temp dir, kept and printed at the end).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Frames to generate (10 Hz).
    #[arg(long, default_value_t = 120, value_name = "N")]
    pub frames: usize,
    /// Seed of the synthetic street and traffic.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// How dynamic the traffic is.
    #[arg(long, value_enum, default_value_t = DynamicsArg::High)]
    pub dynamics: DynamicsArg,
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
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let dynamics = match args.dynamics {
        DynamicsArg::Static => Dynamics::Static,
        DynamicsArg::Low => Dynamics::Low,
        DynamicsArg::High => Dynamics::High,
    };
    let data = out.join("sequence");
    let cfg =
        SynthConfig { frames: args.frames, dynamics, seed: args.seed, ..SynthConfig::default() };
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
    let modes = [SemanticsArg::Off, SemanticsArg::Cull, SemanticsArg::Full];
    let mut rows: Vec<(SemanticsArg, RunOutcome)> = Vec::new();
    for mode in modes {
        let rc = RunConfig {
            threads: 2,
            ransac_iterations: semloc_core::tracker::TrackerParams::default().ransac_iterations,
            semantics: mode,
            assoc: super::run::AssocArg::Hard,
            align: AlignArg::Se3,
            max_frames: None,
            model: None,
        };
        let dir = out.join(format!("run-{}", format!("{mode:?}").to_lowercase()));
        let o = execute(&seq, &rc, &dir)?;
        if let Some(e) = &o.failure {
            anyhow::bail!("tracking {mode:?} failed: {e}");
        }
        rows.push((mode, o));
    }
    println!();
    println!(
        "{:<10}{:>10}{:>12}{:>12}{:>16}{:>10}{:>8}{:>10}",
        "semantics",
        "ATE [m]",
        "ATE [%len]",
        "t_rel [%]",
        "r_rel [°/100m]",
        "ms/frame",
        "lost",
        "culled"
    );
    for (mode, o) in &rows {
        let e = o.eval.as_ref();
        let f = |v: Option<f64>| v.map_or("n/a".to_owned(), |x| format!("{x:.3}"));
        println!(
            "{:<10}{:>10}{:>12}{:>12}{:>16}{:>10.1}{:>8}{:>10.0}",
            format!("{mode:?}").to_lowercase(),
            f(e.map(|e| e.ate_rmse_m)),
            f(e.map(|e| 100.0 * e.ate_rmse_m / e.path_length_m.max(1e-9))),
            f(e.and_then(|e| e.t_rel_pct)),
            f(e.and_then(|e| e.r_rel_deg_per_100m)),
            o.summary.timing.get("compute").map_or(f64::NAN, |p| p.median_ms),
            o.summary.lost,
            o.summary.median_culled,
        );
    }
    println!();
    println!(
        "semantics: labels are the generator's ground truth (the network arrives with the \
         segmentation model); 'cull' drops features on cars, pedestrians and cyclists, 'full' \
         also weights buildings, fences, poles and signs x3 (the paper's semantic ORB)."
    );
    println!("sequence, trajectories, plots: {}", out.display());
    Ok(())
}
