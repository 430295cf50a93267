//! `semloc info`: what a KITTI dataset folder holds.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use semloc::dataset::{CameraPair, Sequence};

/// Which dataset a command reads: shared by `info`, `run` and `bench`.
#[derive(Args, Debug)]
pub struct DatasetArgs {
    /// Dataset folder: a KITTI odometry root (holding `sequences/`, use with --seq), a sequence
    /// folder (`.../sequences/00`), a KITTI raw root or date folder (use with --drive), or a raw
    /// drive folder (`..._drive_0005_sync`).
    #[arg(value_name = "DATASET")]
    pub dataset: PathBuf,
    /// Odometry sequence number, e.g. `00` (odometry roots only).
    #[arg(long, value_name = "XX", conflicts_with = "drive")]
    pub seq: Option<String>,
    /// Raw drive, as `2011_09_26_0005` or `2011_09_26_drive_0005_sync` (raw roots only).
    #[arg(long, value_name = "DATE_NNNN")]
    pub drive: Option<String>,
    /// Which stereo pair: `grey` (cameras 0/1) or `colour` (2/3, converted to luma). Default:
    /// grey when the folder has it, else colour.
    #[arg(long, value_enum)]
    pub pair: Option<PairArg>,
}

impl DatasetArgs {
    /// Opens the dataset the arguments name.
    pub fn open(&self) -> Result<Sequence> {
        open(&self.dataset, self.seq.as_deref(), self.drive.as_deref(), self.pair)
    }
}

/// Arguments of `semloc info`.
#[derive(Args, Debug)]
pub struct InfoArgs {
    /// The dataset.
    #[command(flatten)]
    pub data: DatasetArgs,
    /// Print the summary as JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `--pair` values.
#[derive(Copy, Clone, Debug, ValueEnum)]
pub enum PairArg {
    /// Grey cameras 0 and 1.
    Grey,
    /// Colour cameras 2 and 3.
    Colour,
}

impl From<PairArg> for CameraPair {
    fn from(p: PairArg) -> Self {
        match p {
            PairArg::Grey => CameraPair::Grey,
            PairArg::Colour => CameraPair::Colour,
        }
    }
}

/// Opens the dataset the arguments name.
pub fn open(
    dataset: &std::path::Path,
    seq: Option<&str>,
    drive: Option<&str>,
    pair: Option<PairArg>,
) -> Result<Sequence> {
    let pair = pair.map(CameraPair::from);
    Ok(match (seq, drive) {
        (Some(s), _) => Sequence::open_odometry(dataset, s, pair)?,
        (None, Some(d)) => Sequence::open_raw(dataset, d, pair)?,
        (None, None) => Sequence::open(dataset, pair)?,
    })
}

/// Runs `semloc info`.
pub fn run(args: &InfoArgs) -> Result<()> {
    let seq = args.data.open()?;
    let summary = seq.summary();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("{summary}");
    }
    Ok(())
}
