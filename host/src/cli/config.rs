//! `semloc config`: the settings file, documented — the defaults, a file checked, or an
//! ORB-SLAM2 YAML file converted.

use std::path::PathBuf;

use anyhow::{bail, Result};
use clap::Args;

/// Arguments of `semloc config`.
#[derive(Args, Debug)]
pub struct ConfigArgs {
    /// Print every setting with its meaning, unit and default, as a TOML file to start from
    /// (`semloc config --print-defaults > rig.toml`).
    #[arg(long)]
    pub print_defaults: bool,
    /// Check a TOML settings file and print it in full (defaults filled in, documented).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["print_defaults", "orbslam2_settings"])]
    pub check: Option<PathBuf>,
    /// Convert an ORB-SLAM2 stereo settings file (YAML) to semloc's TOML, printed.
    #[arg(long, value_name = "FILE", conflicts_with = "print_defaults")]
    pub orbslam2_settings: Option<PathBuf>,
}

/// Runs `semloc config`.
pub fn run(args: &ConfigArgs) -> Result<()> {
    let (settings, file, notes) = match (&args.check, &args.orbslam2_settings, args.print_defaults)
    {
        (None, None, false) => {
            bail!("say what to print: --print-defaults, --check FILE or --orbslam2-settings FILE")
        }
        (c, o, _) => super::run::load_settings(c.as_deref(), o.as_deref())?,
    };
    for n in &notes {
        eprintln!("note: {}: {n}", file.as_deref().unwrap_or(std::path::Path::new("")).display());
    }
    let mut text = String::new();
    if let Some(f) = &file {
        text.push_str(&format!("# from {}\n", f.display()));
    }
    text.push_str(&settings.to_documented_toml());
    super::write_stdout(&text);
    Ok(())
}
