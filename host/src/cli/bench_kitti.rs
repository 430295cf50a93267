//! `semloc bench-kitti ROOT`: every sequence of a KITTI odometry root, each configuration, one
//! Table-3-style table (KITTI devkit t_rel / r_rel and ATE per sequence), optionally beside a
//! reference system's trajectories (e.g. published ORB-SLAM2 runs) evaluated the same way on
//! the same frames.

use core::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use semloc::dataset::Sequence;
use semloc::eval::{evaluate, EvalReport};
use semloc::run::{association_name, Network, RunConfig, Semantics};
use semloc_core::assoc::Association;

use super::ablate::{median_min_max as spread, run_rows_over_seeds, MAX_SEEDS};
use super::eval::AlignArg;
use super::run::{config_from_settings, AssocArg, SemanticsArg, SettingsFileArgs};

/// Arguments of `semloc bench-kitti`.
#[derive(Args, Debug)]
pub struct BenchKittiArgs {
    /// A KITTI odometry root: the folder holding `sequences/` (and `poses/` for the ground
    /// truth). Every sequence folder in it is run, in name order.
    #[arg(value_name = "ROOT")]
    pub root: PathBuf,
    /// Output folder (created): `XX/<semantics>-<assoc>/` with everything `semloc run` writes,
    /// per sequence and configuration, plus `bench.txt` (the table) and `bench.json`.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Use a non-empty --out: first remove what `semloc bench-kitti` wrote there before.
    #[arg(long)]
    pub force: bool,
    /// `--config` / `--orbslam2-settings`: every configuration starts from these settings (as
    /// `semloc run` takes them); each sets only its semantics and association.
    #[command(flatten)]
    pub settings: SettingsFileArgs,
    /// Only these sequences (comma-separated, e.g. `01,06`); default: every one in ROOT.
    #[arg(long, value_delimiter = ',', value_name = "XX")]
    pub seqs: Vec<String>,
    /// Semantic settings to run (comma-separated; see `semloc run --help`).
    #[arg(long, value_enum, ignore_case = true, value_delimiter = ',', default_value = "off")]
    pub semantics: Vec<SemanticsArg>,
    /// Association settings to run (comma-separated).
    #[arg(long, value_enum, ignore_case = true, value_delimiter = ',', default_value = "hard")]
    pub assoc: Vec<AssocArg>,
    /// The segmentation network (`.slm`) for the semantic settings.
    #[arg(long, value_name = "SLM")]
    pub model: Option<PathBuf>,
    /// A folder of reference trajectories in KITTI format named `XX.txt` (e.g. ORB-SLAM2's
    /// published runs): each is cut to the frames run and evaluated against the same ground
    /// truth with the same alignment, as an extra column group.
    #[arg(long, value_name = "DIR")]
    pub reference: Option<PathBuf>,
    /// Name of the reference in the table.
    #[arg(long, default_value = "reference", value_name = "NAME")]
    pub reference_name: String,
    /// Process only the first N frames of each sequence (N ≥ 1).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub max_frames: Option<u64>,
    /// Worker threads (1 or 2; results are identical, timings are not).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub threads: u8,
    /// ATE alignment (see `semloc eval --help`).
    #[arg(long, value_enum, ignore_case = true, default_value_t = AlignArg::Se3)]
    pub align: AlignArg,
    /// Track every configuration N times, with RANSAC seeds 0 to N-1 (`semloc run
    /// --ransac-seed`), and add a table of the ATE's median and range over them (N ≤ 16); the
    /// main table is seed 0's. Seed K's outputs go to `XX/<semantics>-<assoc>-seedK/`.
    #[arg(long, default_value_t = 1, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=MAX_SEEDS))]
    pub seeds: u8,
}

/// One (sequence, system) cell group of the table.
#[derive(serde::Serialize, Clone, Debug, PartialEq)]
pub struct Cell {
    /// `<semantics>-<assoc>`, or the reference's name.
    pub system: String,
    /// Devkit translation error (%), null on paths shorter than 100 m.
    pub t_rel_pct: Option<f64>,
    /// Devkit rotation error (deg / 100 m), null on paths shorter than 100 m.
    pub r_rel_deg_per_100m: Option<f64>,
    /// ATE RMSE (m) after the alignment used.
    pub ate_rmse_m: Option<f64>,
    /// RPE over one frame, translation RMSE (m).
    pub rpe_1f_trans_m: Option<f64>,
    /// RPE over one frame, rotation RMSE (deg).
    pub rpe_1f_rot_deg: Option<f64>,
    /// Frames not tracked.
    pub lost: Option<u32>,
    /// Compute time per frame, median (ms).
    pub median_ms: Option<f64>,
    /// `--seeds`: the ATE (m) of each RANSAC seed's run, seed 0 first (empty for a
    /// reference).
    pub ate_seeds_m: Vec<f64>,
    /// Why a figure is missing, if one is.
    pub note: Option<String>,
}

impl Cell {
    fn from_eval(system: String, e: Option<&EvalReport>, note: Option<String>) -> Self {
        Self {
            system,
            t_rel_pct: e.and_then(|e| e.t_rel_pct),
            r_rel_deg_per_100m: e.and_then(|e| e.r_rel_deg_per_100m),
            ate_rmse_m: e.map(|e| e.ate_rmse_m),
            rpe_1f_trans_m: e.and_then(|e| e.rpe_1f.as_ref()).map(|r| r.trans_m.rmse),
            rpe_1f_rot_deg: e.and_then(|e| e.rpe_1f.as_ref()).map(|r| r.rot_deg.rmse),
            lost: None,
            median_ms: None,
            ate_seeds_m: Vec::new(),
            note,
        }
    }
}

/// One sequence of the table.
#[derive(serde::Serialize, Clone, Debug, PartialEq)]
pub struct SeqRow {
    /// Sequence name (`01`).
    pub seq: String,
    /// Frames run.
    pub frames: usize,
    /// Ground-truth path length over those frames (m), if there is ground truth.
    pub length_m: Option<f64>,
    /// One cell per system, in the order of the table's columns.
    pub cells: Vec<Cell>,
}

/// The sequences of `root/sequences` to run: `only` if given (each must exist), else every
/// sub-folder, in name order.
fn sequences(root: &Path, only: &[String]) -> Result<Vec<String>> {
    let dir = root.join("sequences");
    if !dir.is_dir() {
        anyhow::bail!(
            "{} is not a KITTI odometry root: it has no sequences/ folder",
            root.display()
        );
    }
    if !only.is_empty() {
        for s in only {
            if !dir.join(s).is_dir() {
                anyhow::bail!("sequence {s}: {} does not exist", dir.join(s).display());
            }
        }
        return Ok(only.to_vec());
    }
    let mut v: Vec<String> = std::fs::read_dir(&dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    if v.is_empty() {
        anyhow::bail!("{} holds no sequence folders", dir.display());
    }
    Ok(v)
}

/// The reference trajectory of `seq`, cut to `n` frames and evaluated like semloc's rows.
fn reference_cell(
    dir: &Path,
    name: &str,
    seq: &Sequence,
    n: usize,
    align: semloc::eval::Align,
) -> Cell {
    let path = dir.join(format!("{}.txt", seq.name));
    let cell =
        |e: Option<&EvalReport>, note: Option<String>| Cell::from_eval(name.to_owned(), e, note);
    let est = match semloc::traj::read_kitti(&path) {
        Ok(p) => p,
        Err(e) => return cell(None, Some(format!("{e}"))),
    };
    let Some(gt) = seq.gt.as_ref().filter(|g| g.len() >= n) else {
        return cell(None, Some("no ground truth for these frames".into()));
    };
    if est.len() < n {
        return cell(
            None,
            Some(format!("{} has {} poses, {n} frames were run", path.display(), est.len())),
        );
    }
    match evaluate(&gt[..n], &est[..n], align) {
        Ok(e) => cell(Some(&e), None),
        Err(e) => cell(None, Some(format!("{}: {e}", path.display()))),
    }
}

/// What `semloc bench-kitti` writes at the top of `--out` (besides the sequence folders).
pub fn bench_outputs(seqs: &[String]) -> Vec<String> {
    let mut v: Vec<String> = ["bench.txt", "bench.json"].map(String::from).into();
    v.extend(seqs.iter().cloned());
    v
}

fn fmt(v: Option<f64>, d: usize) -> String {
    v.map_or("n/a".to_owned(), |x| format!("{x:.d$}"))
}

/// The Table-3-style table: one line per sequence, per system `t_rel r_rel ATE`.
pub fn table(rows: &[SeqRow], align: &str) -> String {
    let mut s = String::new();
    let Some(first) = rows.first() else { return s };
    let _ = write!(s, "{:<5}{:>7}{:>10}", "seq", "frames", "length");
    for c in &first.cells {
        let _ = write!(s, " | {:^26}", c.system);
    }
    s.push('\n');
    let _ = write!(s, "{:<5}{:>7}{:>10}", "", "", "[m]");
    for _ in &first.cells {
        let _ = write!(s, " | {:>8}{:>9}{:>9}", "t_rel %", "r_rel °", "ATE m");
    }
    s.push('\n');
    for r in rows {
        let _ = write!(s, "{:<5}{:>7}{:>10}", r.seq, r.frames, fmt(r.length_m, 1));
        for c in &r.cells {
            let _ = write!(
                s,
                " | {:>8}{:>9}{:>9}",
                fmt(c.t_rel_pct, 2),
                fmt(c.r_rel_deg_per_100m, 2),
                fmt(c.ate_rmse_m, 3)
            );
        }
        s.push('\n');
    }
    let _ = writeln!(
        s,
        "\nt_rel / r_rel: KITTI devkit (segments of 100..800 m; n/a on shorter paths), r_rel in \
         °/100 m; ATE: RMSE after {align} alignment."
    );
    let seeds = rows.iter().flat_map(|r| &r.cells).map(|c| c.ate_seeds_m.len()).max();
    if let Some(seeds @ 2..) = seeds {
        let _ = writeln!(
            s,
            "\nATE [m] over RANSAC seeds 0-{} (`semloc run --ransac-seed`): median (min-max)",
            seeds - 1
        );
        for r in rows {
            let _ = write!(s, "{:<5}", r.seq);
            for c in r.cells.iter().filter(|c| !c.ate_seeds_m.is_empty()) {
                let (m, lo, hi) = spread(&c.ate_seeds_m);
                let _ = write!(s, " | {:<14}{:>22}", c.system, format!("{m:.3} ({lo:.3}-{hi:.3})"));
            }
            s.push('\n');
        }
    }
    for r in rows {
        for c in &r.cells {
            if let Some(n) = &c.note {
                let _ = writeln!(s, "{} {}: {n}", r.seq, c.system);
            }
        }
    }
    s
}

/// Runs `semloc bench-kitti`.
pub fn run(args: &BenchKittiArgs) -> Result<()> {
    let seqs = sequences(&args.root, &args.seqs)?;
    let (settings, settings_file) = args.settings.load()?;
    let model = args.model.clone().or(settings.semantics.model.clone());
    if let Some(r) = &args.reference {
        if !r.is_dir() {
            anyhow::bail!("--reference {}: not a folder", r.display());
        }
    }
    let kept = semloc::run::prepare_output_dir(&args.out, args.force, &bench_outputs(&seqs))?;
    super::print_warnings(kept.as_slice());
    let pairs: Vec<(Semantics, Association)> = args
        .semantics
        .iter()
        .flat_map(|&s| args.assoc.iter().map(move |&a| (s.into(), a.into())))
        .collect();
    let align: semloc::eval::Align = args.align.into();
    let mut rows = Vec::new();
    for name in &seqs {
        let seq = Sequence::open_odometry(&args.root, name, None)
            .with_context(|| format!("sequence {name}"))?;
        eprintln!("== sequence {name} ({} frames)", seq.len());
        let out = args.out.join(name);
        std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
        let base = || RunConfig {
            max_frames: args.max_frames.map(|n| usize::try_from(n).unwrap_or(usize::MAX)),
            command_line: super::command_line(),
            threads: args.threads,
            network: model.clone().map(Network::File),
            align,
            ..config_from_settings(&seq, &out, &settings, settings_file.clone())
        };
        let n = base().frame_count();
        let runs = run_rows_over_seeds(&base, &pairs, &out, args.seeds)?;
        let mut cells: Vec<Cell> = runs
            .iter()
            .map(|r| {
                let system = format!("{}-{}", r.semantics.name(), association_name(r.assoc));
                let note =
                    r.outcome.eval.is_none().then(|| "not evaluated (no ground truth)".into());
                let mut c = Cell::from_eval(system, r.outcome.eval.as_ref(), note);
                c.lost = Some(r.outcome.summary.lost);
                c.median_ms = r.outcome.summary.timing.get("compute").map(|p| p.median_ms);
                c.ate_seeds_m = r.seed_ates.clone();
                c
            })
            .collect();
        if let Some(dir) = &args.reference {
            cells.push(reference_cell(dir, &args.reference_name, &seq, n, align));
        }
        let length_m =
            seq.gt.as_ref().filter(|g| g.len() >= n).map(|g| {
                semloc::eval::trajectory_distances(&g[..n]).last().copied().unwrap_or(0.0)
            });
        rows.push(SeqRow { seq: name.clone(), frames: n, length_m, cells });
    }
    let text = table(&rows, &align.to_string());
    print!("{text}");
    let p = args.out.join("bench.txt");
    semloc::run::write_atomic(&p, text.as_bytes())?;
    let json = serde_json::to_vec_pretty(&rows).context("serialising bench.json")?;
    semloc::run::write_atomic(&args.out.join("bench.json"), &json)?;
    Ok(())
}
