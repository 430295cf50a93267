//! `semloc info`: what a dataset folder holds.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, ValueEnum};
use semloc::dataset::{CameraPair, Sequence, StereoCalib};

/// Which dataset a command reads: shared by `info`, `run` and `bench`.
#[derive(Args, Debug)]
pub struct DatasetArgs {
    /// Dataset folder: a KITTI odometry root (holding `sequences/`, use with --seq), a sequence
    /// folder (`.../sequences/00`), a KITTI raw root or date folder (use with --drive), a raw
    /// drive folder (`..._drive_0005_sync`), a stereo folder (`left/`, `right/`, rectified
    /// images; calibration from its calib.txt or --config's [camera]) or a EuRoC MAV sequence
    /// (the folder holding `mav0`, or `mav0`).
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
    /// Start at the dataset's frame N (numbered from 0): the frames before it, their times and
    /// ground-truth poses are left out, and the ground truth is re-based to start at the
    /// identity, as the estimate does. `--max-frames` then counts from N; `frames.csv` numbers
    /// the processed frames from 0 and `summary.json`'s `dataset.first_frame` records N. A
    /// short clip's ATE moves by tens of per cent with where it starts: `semloc ablate
    /// --first-frames` runs every row from several starts.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub first_frame: usize,
}

impl DatasetArgs {
    /// Opens the dataset the arguments name.
    pub fn open(&self) -> Result<Sequence> {
        self.open_with_camera(None)
    }

    /// Opens the dataset with the settings file's camera (a stereo folder's calibration when
    /// given). The caller prints [`Sequence::notes`].
    pub fn open_with_camera(&self, camera: Option<StereoCalib>) -> Result<Sequence> {
        let pair = self.pair.map(CameraPair::from);
        let seq = match (self.seq.as_deref(), self.drive.as_deref()) {
            (Some(s), _) => Sequence::open_odometry(&self.dataset, s, pair)?,
            (None, Some(d)) => Sequence::open_raw(&self.dataset, d, pair)?,
            (None, None) => Sequence::open_with_camera(&self.dataset, pair, camera)?,
        };
        Ok(if self.first_frame == 0 { seq } else { seq.starting_at(self.first_frame)? })
    }
}

/// The `[camera]` of a settings file, for commands that read only the camera from it.
pub fn settings_camera(config: Option<&std::path::Path>) -> Result<Option<StereoCalib>> {
    Ok(match config {
        Some(p) => semloc::settings::Settings::from_toml_file(p)?.camera.map(|c| c.calib()),
        None => None,
    })
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
    /// Settings file (TOML) whose [camera] section calibrates a stereo folder without
    /// calib.txt (the other sections are not used here).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
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

/// Runs `semloc info`.
pub fn run(args: &InfoArgs) -> Result<()> {
    let seq = args.data.open_with_camera(settings_camera(args.config.as_deref())?)?;
    let summary = seq.summary();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("{summary}");
    }
    Ok(())
}
