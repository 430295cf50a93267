//! `semloc synth`: write a synthetic KITTI-odometry-layout stereo sequence of a street with
//! traffic, with ground-truth poses, semantic labels and moving-object masks
//! (see [`semloc::synth`]).

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use semloc::synth::{generate_with_progress, Dynamics, SynthConfig};

/// Arguments of `semloc synth`.
#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Output root: `sequences/XX/...` and `poses/XX.txt` are written under it (created if
    /// missing). An existing `sequences/XX` is refused unless --force.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Replace an existing synthetic `sequences/XX` (and `poses/XX.txt`): removed first, so no
    /// frame of the old sequence is left among the new ones. A folder `semloc synth` did not
    /// write (no `semantic/` and `dynamic/` folders) is never removed.
    #[arg(long)]
    pub force: bool,
    /// Number of stereo frames (10 Hz).
    #[arg(long, default_value_t = 200)]
    pub frames: usize,
    /// Traffic: `static` (parked cars only), `low` (a few agents, mostly far) or `high`
    /// (a leading truck, a cyclist ahead, overtaking/oncoming/crossing cars, pedestrians).
    #[arg(long, value_enum, default_value_t = DynamicsArg::Low)]
    pub dynamics: DynamicsArg,
    /// Seed of the street, the path, the traffic and the sensor noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the colour pair (`image_2`/`image_3`, RGB) instead of grey (`image_0`/`image_1`).
    #[arg(long)]
    pub colour: bool,
    /// Sequence name.
    #[arg(long, value_name = "XX", default_value = "00")]
    pub seq: String,
    /// Worker threads (0 = all cores); output does not depend on it.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Print the summary as JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `--dynamics` values.
#[derive(Copy, Clone, Debug, ValueEnum)]
pub enum DynamicsArg {
    /// No moving objects.
    Static,
    /// A few agents, mostly far.
    Low,
    /// Dense traffic covering ≥ 30 % of many frames.
    High,
    /// Low traffic in a street lined with parked cars, people standing on the pavements.
    Parked,
}

impl From<DynamicsArg> for Dynamics {
    fn from(d: DynamicsArg) -> Self {
        match d {
            DynamicsArg::Static => Dynamics::Static,
            DynamicsArg::Low => Dynamics::Low,
            DynamicsArg::High => Dynamics::High,
            DynamicsArg::Parked => Dynamics::Parked,
        }
    }
}

/// Runs `semloc synth`.
pub fn run(args: &SynthArgs) -> Result<()> {
    let cfg = SynthConfig {
        frames: args.frames,
        dynamics: args.dynamics.into(),
        seed: args.seed,
        colour: args.colour,
        seq: args.seq.clone(),
        threads: args.threads,
    };
    clear_sequence(&args.out, &args.seq, args.force)?;
    let pb = super::progress(args.frames as u64, "synth");
    let summary = generate_with_progress(&args.out, &cfg, &|done| pb.set_position(done as u64))?;
    pb.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("{summary}");
    }
    Ok(())
}

/// Makes room for sequence `seq` under `out`: nothing to do when `sequences/<seq>` is missing
/// or empty; otherwise an error, unless `force` and the folder is one `semloc synth` wrote,
/// which is then removed with its pose file.
pub fn clear_sequence(out: &std::path::Path, seq: &str, force: bool) -> Result<()> {
    let dir = out.join("sequences").join(seq);
    let occupied = std::fs::read_dir(&dir).is_ok_and(|mut d| d.next().is_some());
    if !occupied {
        return Ok(());
    }
    if !force {
        anyhow::bail!(
            "{} already holds a sequence; choose another --out or --seq, or pass --force to \
             replace it",
            dir.display()
        );
    }
    if !(dir.join("semantic").is_dir() && dir.join("dynamic").is_dir()) {
        anyhow::bail!(
            "{} was not written by `semloc synth` (no semantic/ and dynamic/ folders); it is not \
             removed, even with --force",
            dir.display()
        );
    }
    std::fs::remove_dir_all(&dir).with_context(|| format!("removing {}", dir.display()))?;
    let poses = out.join("poses").join(format!("{seq}.txt"));
    if poses.exists() {
        std::fs::remove_file(&poses).with_context(|| format!("removing {}", poses.display()))?;
    }
    Ok(())
}
