//! `semloc ablate`: the paper's ablation on one dataset — every combination of semantics
//! (`off`, `cull`, `full`) and association (`hard`, `em`) tracked in one invocation, one table
//! (ATE, t_rel, r_rel, RPE over one frame, ms/frame, features culled, associations EM changed),
//! plus the share of
//! features on static structure with plain and with semantic ORB (the paper's Fig. 4).

use core::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use semloc::dataset::Sequence;
use semloc::pipeline::{CategoryCounts, Pipeline};
use semloc::run::{association_name, MovingCheck, Network, RunConfig, RunResult, Semantics};
use semloc::settings::Settings;
use semloc_core::assoc::Association;
use semloc_core::seg::WeightScheme;
use semloc_core::tracker::TrackerParams;

use super::eval::AlignArg;
use super::info::DatasetArgs;
use super::run::{
    config_from_settings, run_with_progress, AssocArg, SemanticsArg, SettingsFileArgs,
};

/// Arguments of `semloc ablate`.
#[derive(Args, Debug)]
pub struct AblateArgs {
    /// The dataset.
    #[command(flatten)]
    pub data: DatasetArgs,
    /// Output folder (created): one `semantics-assoc/` folder per row with everything `semloc
    /// run` writes, plus `ablation.json` and `ablation.txt` (the table).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// `--config` / `--orbslam2-settings`: every row starts from these settings (as `semloc
    /// run` takes them); the row sets only its semantics and association.
    #[command(flatten)]
    pub settings: SettingsFileArgs,
    /// Use a non-empty --out: first remove what `semloc ablate` wrote there before.
    #[arg(long)]
    pub force: bool,
    /// The segmentation network (`.slm`) that labels the frames for the semantic rows; without
    /// it the sequence's own `semantic/` labels are used (synthetic sequences have them).
    #[arg(long, value_name = "SLM")]
    pub model: Option<PathBuf>,
    /// Semantic settings to run (comma-separated).
    #[arg(
        long,
        value_enum,
        ignore_case = true,
        value_delimiter = ',',
        default_value = "off,cull,full,motion"
    )]
    pub semantics: Vec<SemanticsArg>,
    /// Association settings to run (comma-separated).
    #[arg(long, value_enum, ignore_case = true, value_delimiter = ',', default_value = "hard,em")]
    pub assoc: Vec<AssocArg>,
    /// Process only the first N frames (N ≥ 1).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub max_frames: Option<u64>,
    /// Worker threads for every row (1 or 2; results are identical, timings are not).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u8).range(1..=2))]
    pub threads: u8,
    /// ATE alignment (see `semloc eval --help`).
    #[arg(long, value_enum, ignore_case = true, default_value_t = AlignArg::Se3)]
    pub align: AlignArg,
    /// Track every row N times, with RANSAC seeds 0 to N-1 (`semloc run --ransac-seed`), and
    /// report the ATE's median and range over them beside seed 0's figures (N ≤ 16). Tracking
    /// is deterministic, so one run is one sample; ORB-SLAM2's published figures are ranges
    /// over runs too. Seed 0's outputs go to `<semantics>-<assoc>/`, seed K's to
    /// `<semantics>-<assoc>-seedK/`.
    #[arg(long, default_value_t = 1, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=MAX_SEEDS))]
    pub seeds: u8,
    /// Also track every row from each of these dataset frames (comma-separated, e.g.
    /// `0,2,4,6,8,10`; `A-B` is every frame from A to B, `A-B:S` every S-th: `0-24:2` is the
    /// same list), each to the end (or `--max-frames` frames), and report per row the
    /// geometric mean over them of its ATE and one-frame RPE relative to the first row run
    /// from the same frame, with the worst ratio. On a clip of a few dozen frames the ATE moves
    /// by tens of per cent with where tracking starts, more than most differences between
    /// rows; the ratios over several starts are what tells rows apart. The main table is the
    /// first start's; every other start's runs go to `first-frames/<row>-from<N>/`.
    #[arg(long, value_delimiter = ',', value_name = "N,...", value_parser = parse_frame_span, conflicts_with_all = ["seeds", "first_frame"])]
    pub first_frames: Vec<FrameSpan>,
}

/// One item of a frame list (`--first-frames`, `compare --starts`): `N`, `A-B` (A to B
/// inclusive) or `A-B:S` (A, A+S, ... up to B).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameSpan(pub Vec<usize>);

/// The frames of a list of [`FrameSpan`]s, in order.
pub fn frames_of(spans: &[FrameSpan]) -> Vec<usize> {
    spans.iter().flat_map(|s| s.0.iter().copied()).collect()
}

/// Parses one [`FrameSpan`]; the message says what is wrong with it.
pub fn parse_frame_span(s: &str) -> core::result::Result<FrameSpan, String> {
    let num = |t: &str| {
        t.trim().parse::<usize>().map_err(|_| format!("{t:?} in {s:?} is not a frame number"))
    };
    let Some((a, rest)) = s.split_once('-') else { return Ok(FrameSpan(vec![num(s)?])) };
    let (b, step) = match rest.split_once(':') {
        Some((b, st)) => (b, num(st)?),
        None => (rest, 1),
    };
    let (a, b) = (num(a)?, num(b)?);
    if step == 0 {
        return Err(format!("{s:?}: the step must be at least 1"));
    }
    if a > b {
        return Err(format!("{s:?}: the range is empty ({a} > {b})"));
    }
    Ok(FrameSpan((a..=b).step_by(step).collect()))
}

/// Most RANSAC seeds `--seeds` runs per row.
pub const MAX_SEEDS: i64 = 16;

/// One row of an ablation or demo table.
pub struct Row {
    /// Semantic setting.
    pub semantics: Semantics,
    /// Association setting.
    pub assoc: Association,
    /// What the run produced.
    pub outcome: RunResult,
    /// ATE RMSE (m) of every run of the row, RANSAC seed 0 first (one entry without
    /// `--seeds`); a run without an evaluation has none.
    pub seed_ates: Vec<f64>,
}

/// Median, minimum and maximum of a non-empty list.
pub fn median_min_max(v: &[f64]) -> (f64, f64, f64) {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) };
    (median, v[0], v[n - 1])
}

impl Row {
    /// Median, minimum and maximum of [`Row::seed_ates`], when there are two or more.
    pub fn seed_spread(&self) -> Option<(f64, f64, f64)> {
        if self.seed_ates.len() < 2 {
            return None;
        }
        Some(median_min_max(&self.seed_ates))
    }
}

/// One row of `ablation.json`.
#[derive(serde::Serialize)]
struct JsonRow<'a> {
    semantics: String,
    association: String,
    ate_rmse_m: Option<f64>,
    t_rel_pct: Option<f64>,
    r_rel_deg_per_100m: Option<f64>,
    path_length_m: Option<f64>,
    rpe_1f_trans_rmse_m: Option<f64>,
    rpe_1f_rot_rmse_deg: Option<f64>,
    rpe_10m_trans_rmse_pct: Option<f64>,
    rpe_10m_rot_rmse_deg: Option<f64>,
    compute_median_ms: Option<f64>,
    compute_p99_ms: Option<f64>,
    lost: u32,
    median_culled_per_frame: f64,
    em_changed_total: u64,
    /// Motion-aware rows: precision and recall of the removed features against the
    /// sequence's moving-object mask (synthetic sequences), else null.
    moving_precision: Option<f64>,
    moving_recall: Option<f64>,
    /// The same for the withheld features (removed less the deferred: unproven and free to
    /// make a landmark, which are treated as parked ones are).
    withheld_precision: Option<f64>,
    withheld_recall: Option<f64>,
    /// The same for the "moving" verdict alone (unproven features left out).
    tested_moving_precision: Option<f64>,
    tested_moving_recall: Option<f64>,
    /// `--seeds`: the ATE of each RANSAC seed's run (seed 0 first) and their median.
    ate_rmse_m_seeds: &'a [f64],
    ate_median_m: Option<f64>,
    folder: &'a str,
}

/// One row's figures over several first frames (`--first-frames`).
#[derive(serde::Serialize)]
struct StartsRow {
    semantics: String,
    association: String,
    /// Per first frame (the order given): ATE RMSE (m), RPE over one frame (m, deg).
    ate_rmse_m: Vec<f64>,
    rpe_1f_trans_rmse_m: Vec<f64>,
    rpe_1f_rot_rmse_deg: Vec<f64>,
    ate_median_m: f64,
    /// Geometric mean over the first frames of the ratio to the first row from the same frame,
    /// and the largest such ratio.
    ate_ratio_geomean: f64,
    ate_ratio_worst: f64,
    /// Standard error of the mean log ratio (sample standard deviation / sqrt(n); NaN, written
    /// as null, from fewer than two starts): `geomean · exp(±2 se)` is a rough 95 % interval.
    ate_ratio_log_se: f64,
    /// The starts from which the row's ATE is below the first row's.
    ate_better_starts: usize,
    rpe_1f_trans_ratio_geomean: f64,
    rpe_1f_rot_ratio_geomean: f64,
}

/// Paired ratios `a[i] / b[i]` summarised on the log scale, where a ratio and its inverse
/// weigh alike (NaN when a pair is not positive).
pub(crate) struct RatioStats {
    pub geomean: f64,
    pub worst: f64,
    /// Standard error of the mean log ratio; NaN from fewer than two pairs.
    pub log_se: f64,
    /// Pairs with `a[i] < b[i]`.
    pub better: usize,
}

pub(crate) fn ratio_stats(a: &[f64], b: &[f64]) -> RatioStats {
    let logs: Vec<f64> = a.iter().zip(b).map(|(x, y)| (x / y).ln()).collect();
    let n = logs.len();
    let mean = logs.iter().sum::<f64>() / n.max(1) as f64;
    let worst = logs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let log_se = if n < 2 {
        f64::NAN
    } else {
        let var = logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        (var / n as f64).sqrt()
    };
    RatioStats {
        geomean: mean.exp(),
        worst: worst.exp(),
        log_se,
        better: logs.iter().filter(|&&l| l < 0.0).count(),
    }
}

/// The rows' figures over the first frames of `per_start` (one row list per first frame, the
/// rows in the same order); ratios are to the first row.
fn starts_rows(per_start: &[&[Row]]) -> Result<Vec<StartsRow>> {
    let n_rows = per_start.first().map_or(0, |r| r.len());
    let mut cols: Vec<[Vec<f64>; 3]> = vec![Default::default(); n_rows];
    for rows in per_start {
        for (c, r) in cols.iter_mut().zip(rows.iter()) {
            let Some(e) = r.outcome.eval.as_ref() else {
                anyhow::bail!(
                    "--first-frames needs ground truth over every run: {} has no evaluation",
                    row_name(r)
                );
            };
            let rpe = e.rpe_1f.as_ref();
            c[0].push(e.ate_rmse_m);
            c[1].push(rpe.map_or(f64::NAN, |p| p.trans_m.rmse));
            c[2].push(rpe.map_or(f64::NAN, |p| p.rot_deg.rmse));
        }
    }
    let Some(base) = cols.first().cloned() else { return Ok(Vec::new()) };
    Ok(per_start[0]
        .iter()
        .zip(cols)
        .map(|(r, [ate, rt, rr])| {
            let a = ratio_stats(&ate, &base[0]);
            StartsRow {
                semantics: r.semantics.name().to_owned(),
                association: association_name(r.assoc),
                ate_median_m: median_min_max(&ate).0,
                ate_ratio_geomean: a.geomean,
                ate_ratio_worst: a.worst,
                ate_ratio_log_se: a.log_se,
                ate_better_starts: a.better,
                rpe_1f_trans_ratio_geomean: ratio_stats(&rt, &base[1]).geomean,
                rpe_1f_rot_ratio_geomean: ratio_stats(&rr, &base[2]).geomean,
                ate_rmse_m: ate,
                rpe_1f_trans_rmse_m: rt,
                rpe_1f_rot_rmse_deg: rr,
            }
        })
        .collect())
}

/// A geometric-mean ratio as the tables print it: `0.914 ± 0.051`, without the standard error
/// when there is none (one start).
pub(crate) fn ratio_cell(geomean: f64, log_se: f64) -> String {
    if log_se.is_finite() {
        format!("{geomean:.3} ± {log_se:.3}")
    } else {
        format!("{geomean:.3}")
    }
}

/// The `--first-frames` table.
fn starts_table(rows: &[StartsRow], starts: &[usize]) -> String {
    let mut s = String::new();
    let base = rows.first().map_or(String::new(), |r| format!("{}/{}", r.semantics, r.association));
    let list: Vec<String> = starts.iter().map(ToString::to_string).collect();
    let _ = writeln!(
        s,
        "\nover {} first frames ({}): ratio to {base} from the same frame, geometric mean ± the \
         standard error of its log, the worst ratio and the starts where the row is better",
        starts.len(),
        list.join(", ")
    );
    let _ = writeln!(
        s,
        "{:<10}{:<6}{:>15}{:>17}{:>7}{:>8}{:>24}",
        "semantics",
        "assoc",
        "ATE median [m]",
        "ATE ratio",
        "worst",
        "better",
        "RPE 1f ratio (t / rot)"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<10}{:<6}{:>15.4}{:>17}{:>7.2}{:>8}{:>24}",
            r.semantics,
            r.association,
            r.ate_median_m,
            ratio_cell(r.ate_ratio_geomean, r.ate_ratio_log_se),
            r.ate_ratio_worst,
            format!("{}/{}", r.ate_better_starts, starts.len()),
            format!("{:.3} / {:.3}", r.rpe_1f_trans_ratio_geomean, r.rpe_1f_rot_ratio_geomean)
        );
    }
    s
}

/// Fig. 4 of the paper on this dataset: features by category, plain and semantic ORB.
#[derive(serde::Serialize)]
struct Share {
    frames: usize,
    plain: CategoryCounts,
    semantic: CategoryCounts,
    structure_pct_plain: f64,
    structure_pct_semantic: f64,
    dynamic_pct_plain: f64,
    dynamic_pct_semantic: f64,
}

/// Formats the table of `rows` (one line each), as `semloc ablate` and `semloc demo` print it.
pub fn table(rows: &[Row]) -> String {
    let mut s = String::new();
    let seeds = rows.iter().map(|r| r.seed_ates.len()).max().unwrap_or(0);
    let spread_col = |top: bool| {
        if seeds < 2 {
            String::new()
        } else if top {
            format!("{:>22}", format!("ATE, {seeds} seeds [m]"))
        } else {
            format!("{:>22}", "median (min-max)")
        }
    };
    let _ = writeln!(
        s,
        "{:<10}{:<6}{:>9}{:>8}{:>10}{:>11}{:>16}{:>10}{:>9}{:>6}{:>9}{:>11}{:>12}{}",
        "semantics",
        "assoc",
        "ATE [m]",
        "ATE %",
        "t_rel [%]",
        "r_rel [°/",
        "RPE 1f (rmse)",
        "ms/frame",
        "p99 ms",
        "lost",
        "culled",
        "EM changed",
        "moving P/R",
        spread_col(true)
    );
    let _ = writeln!(
        s,
        "{:<10}{:<6}{:>9}{:>8}{:>10}{:>11}{:>16}{:>10}{:>9}{:>6}{:>9}{:>11}{:>12}{}",
        "",
        "",
        "",
        "of len",
        "",
        "100 m]",
        "[m / deg]",
        "median",
        "",
        "",
        "/frame",
        "total",
        "[%]",
        spread_col(false)
    );
    for r in rows {
        let e = r.outcome.eval.as_ref();
        let f = |v: Option<f64>, d: usize| v.map_or("n/a".to_owned(), |x| format!("{x:.d$}"));
        let compute = r.outcome.summary.timing.get("compute");
        let _ = writeln!(
            s,
            "{:<10}{:<6}{:>9}{:>8}{:>10}{:>11}{:>16}{:>10}{:>9}{:>6}{:>9.0}{:>11}{:>12}{}",
            r.semantics.name(),
            association_name(r.assoc),
            f(e.map(|e| e.ate_rmse_m), 3),
            f(e.map(|e| 100.0 * e.ate_rmse_m / e.path_length_m.max(1e-9)), 2),
            f(e.and_then(|e| e.t_rel_pct), 3),
            f(e.and_then(|e| e.r_rel_deg_per_100m), 3),
            e.and_then(|e| e.rpe_1f.as_ref()).map_or("n/a".to_owned(), |r| format!(
                "{:.3} / {:.3}",
                r.trans_m.rmse, r.rot_deg.rmse
            )),
            f(compute.map(|p| p.median_ms), 1),
            f(compute.map(|p| p.p99_ms), 1),
            r.outcome.summary.lost,
            r.outcome.summary.median_culled,
            r.outcome.summary.em_changed_total,
            moving_pr(r).map_or("n/a".to_owned(), |(p, r)| format!(
                "{:.0} / {:.0}",
                100.0 * p,
                100.0 * r
            )),
            match (seeds, r.seed_spread()) {
                (0 | 1, _) => String::new(),
                (_, Some((m, lo, hi))) => format!("{:>22}", format!("{m:.3} ({lo:.3}-{hi:.3})")),
                (_, None) => format!("{:>22}", "n/a"),
            },
        );
    }
    let checks: Vec<(&Row, &MovingCheck)> = rows
        .iter()
        .filter_map(|r| Some((r, r.outcome.summary.motion.as_ref()?.moving_check.as_ref()?)))
        .collect();
    if !checks.is_empty() {
        let _ = writeln!(
            s,
            "\nmoving features, precision / recall [%]: removed (moving or unproven) / withheld \
             from pose or map (unproven features free to make a landmark count as kept) / tested \
             moving"
        );
        for (r, c) in &checks {
            let pr = |p: f64, q: f64| {
                let f =
                    |v: f64| if v.is_finite() { format!("{:.1}", 100.0 * v) } else { "n/a".into() };
                format!("{} / {}", f(p), f(q))
            };
            let _ = writeln!(
                s,
                "  {} / {}: {}  |  {}  |  {}",
                r.semantics.name(),
                association_name(r.assoc),
                pr(c.precision(), c.recall()),
                pr(c.withheld_precision(), c.withheld_recall()),
                pr(c.tested_precision(), c.tested_recall()),
            );
        }
    }
    write_shares(
        &mut s,
        "wrongly removed features (on no moving object), by cause: joined to a moving object / \
         parked object tested moving / measured, evidence pending / not yet measured",
        labelled(&checks),
        |c| {
            let parts = vec![
                c.false_pos_joined,
                c.false_pos_tested,
                c.false_pos_pending,
                c.false_pos_unseen,
            ];
            (c.false_pos, parts, None)
        },
    );
    write_shares(
        &mut s,
        "deferred features on moving objects (the withheld recall's loss), by cause: measured, \
         evidence pending / not yet measured; and the share without stereo depth",
        labelled(&checks),
        |c| {
            let parts = vec![c.deferred_true_pending, c.deferred_true_unseen];
            (c.deferred_true, parts, Some(c.deferred_true_depthless))
        },
    );
    if seeds >= 2 {
        let _ = writeln!(
            s,
            "\nEvery column but the last is RANSAC seed 0's run; the last is the ATE over seeds \
             0-{} (`semloc run --ransac-seed`).",
            seeds - 1
        );
    }
    s
}

/// Each motion check with its row's label (`semantics / assoc`).
fn labelled<'c>(
    checks: &'c [(&Row, &'c MovingCheck)],
) -> impl Iterator<Item = (String, &'c MovingCheck)> + 'c {
    checks
        .iter()
        .map(|(r, c)| (format!("{} / {}", r.semantics.name(), association_name(r.assoc)), *c))
}

/// Under `header`, one line per row whose `split` total is not 0: the total and each part's
/// share of it (`a / b / ... %`), then the share of the optional depthless count.
fn write_shares<'c>(
    s: &mut String,
    header: &str,
    checks: impl IntoIterator<Item = (String, &'c MovingCheck)>,
    split: impl Fn(&MovingCheck) -> (u32, Vec<u32>, Option<u32>),
) {
    let mut header = Some(header);
    for (row, c) in checks {
        let (total, parts, depthless) = split(c);
        if total == 0 {
            continue;
        }
        if let Some(h) = header.take() {
            let _ = writeln!(s, "\n{h}");
        }
        let pct = |v: u32| format!("{:.0}", 100.0 * f64::from(v) / f64::from(total));
        let shares: Vec<String> = parts.into_iter().map(pct).collect();
        let tail = depthless.map_or(String::new(), |d| format!(", {} % depthless", pct(d)));
        let _ = writeln!(s, "  {row}: {total} features: {} %{tail}", shares.join(" / "));
    }
}

/// Precision and recall of a motion-aware row's removed features against the moving mask.
fn moving_pr(r: &Row) -> Option<(f64, f64)> {
    let m = r.outcome.summary.motion.as_ref()?;
    Some((m.moving_precision?, m.moving_recall?))
}

/// Tracks once per (semantics, assoc) pair, each row configured as `base()` makes it but for
/// those two; each row's outputs go to `out/<semantics>-<assoc>/`. A row whose tracking stops
/// early is an error naming the row (its outputs so far are kept).
pub fn run_rows<'a>(
    base: &dyn Fn() -> RunConfig<'a>,
    pairs: &[(Semantics, Association)],
    out: &std::path::Path,
) -> Result<Vec<Row>> {
    run_rows_seeded(base, pairs, out, 0)
}

/// [`run_rows`], then the same rows again with RANSAC seeds 1 to `seeds - 1`
/// ([`run_rows_seeded`]), each row's [`Row::seed_ates`] gathering every seed's ATE.
pub fn run_rows_over_seeds<'a>(
    base: &dyn Fn() -> RunConfig<'a>,
    pairs: &[(Semantics, Association)],
    out: &std::path::Path,
    seeds: u8,
) -> Result<Vec<Row>> {
    let mut rows = run_rows(base, pairs, out)?;
    for seed in 1..u64::from(seeds) {
        let more = run_rows_seeded(base, pairs, out, seed)?;
        for (row, other) in rows.iter_mut().zip(more) {
            // A run without an evaluation (no ground truth) has no ATE to add.
            row.seed_ates.extend(other.seed_ates);
        }
    }
    Ok(rows)
}

/// As [`run_rows`] with RANSAC seed `seed` (`semloc run --ransac-seed`); seed 0 leaves
/// `base()`'s and writes each row to `<semantics>-<assoc>/`, any other to
/// `<semantics>-<assoc>-seed<seed>/`.
fn run_rows_seeded<'a>(
    base: &dyn Fn() -> RunConfig<'a>,
    pairs: &[(Semantics, Association)],
    out: &std::path::Path,
    seed: u64,
) -> Result<Vec<Row>> {
    let (suffix, label) = if seed == 0 {
        (String::new(), String::new())
    } else {
        (format!("-seed{seed}"), format!(" (RANSAC seed {seed})"))
    };
    run_rows_named(base, pairs, out, seed, &suffix, &label)
}

/// As [`run_rows_seeded`], each row's outputs in `out/<semantics>-<assoc><suffix>/`, `label`
/// added to the progress line.
fn run_rows_named<'a>(
    base: &dyn Fn() -> RunConfig<'a>,
    pairs: &[(Semantics, Association)],
    out: &std::path::Path,
    seed: u64,
    suffix: &str,
    label: &str,
) -> Result<Vec<Row>> {
    let mut rows = Vec::new();
    let stop = semloc::run::StopFlag::new();
    stop.register_signals().context("installing the SIGINT/SIGTERM handlers")?;
    for &(semantics, assoc) in pairs {
        let (s, a) = (semantics.name(), association_name(assoc));
        let dir = out.join(format!("{s}-{a}{suffix}"));
        let mut cfg = base();
        cfg.out = dir.clone();
        cfg.stop = Some(stop.clone());
        cfg.semantics = semantics;
        cfg.tracker.association = assoc;
        if seed != 0 {
            cfg.tracker.ransac_seed = seed;
        }
        if semantics == Semantics::Off {
            // the network is only needed (and only timed) where labels are used
            cfg.network = None;
        }
        eprintln!("{s} / {a}{label} ...");
        let outcome = run_with_progress(cfg)?;
        super::print_warnings(&outcome.warnings);
        if let Some(e) = &outcome.failure {
            let message = format!(
                "semantics {s} / assoc {a} stopped after {} of {} frames: {} (outputs so far \
                 in {}; the rows after it were not run)",
                outcome.summary.frames_processed,
                outcome.summary.frames_requested,
                semloc::run::outputs::error_chain(e),
                dir.display()
            );
            return Err(super::Exit { code: e.exit_code(), message }.into());
        }
        if let Some(e) = &outcome.eval_error {
            anyhow::bail!(
                "semantics {s} / assoc {a}: the evaluation failed: {} (outputs in {})",
                semloc::run::outputs::error_chain(e),
                dir.display()
            );
        }
        let seed_ates = outcome.eval.iter().map(|e| e.ate_rmse_m).collect();
        rows.push(Row { semantics, assoc, outcome, seed_ates });
    }
    Ok(rows)
}

/// Counts left-image features by category over the first `n` frames, plain and with semantic
/// ORB's weights (the `full` scheme), under the run's ORB settings (feature count, pyramid,
/// thresholds, structure gain): the same extraction as the rows'.
fn feature_share(
    seq: &Sequence,
    model: Option<&PathBuf>,
    settings: &Settings,
    n: usize,
) -> Result<Share> {
    let (w, h) = seq.image_size;
    let mut pipe = Pipeline::with_settings(
        &seq.calib,
        w,
        h,
        settings.orb,
        settings.stereo,
        TrackerParams::default(),
        1,
    )?;
    if let Some(p) = model {
        pipe.set_segmenter(semloc::run::load_network(p, w, h)?);
    }
    let (mut plain, mut semantic) = (CategoryCounts::default(), CategoryCounts::default());
    let pb = super::progress(n as u64, "Fig. 4");
    for i in 0..n {
        let (p, s) = pipe.feature_categories(seq, i, WeightScheme::Full)?;
        plain.merge(&p);
        semantic.merge(&s);
        pb.inc(1);
    }
    pb.finish_and_clear();
    Ok(Share {
        frames: n,
        structure_pct_plain: plain.pct(plain.structure()),
        structure_pct_semantic: semantic.pct(semantic.structure()),
        dynamic_pct_plain: plain.pct(plain.dynamic()),
        dynamic_pct_semantic: semantic.pct(semantic.dynamic()),
        plain,
        semantic,
    })
}

/// Runs `semloc ablate`.
pub fn run(args: &AblateArgs) -> Result<()> {
    let (settings, settings_file) = args.settings.load()?;
    let opened = args.data.open_with_camera(settings.camera.as_ref().map(|c| c.calib()))?;
    for n in &opened.notes {
        eprintln!("note: {n}");
    }
    let model = args.model.clone().or(settings.semantics.model.clone());
    // `--first-frames`: every start is checked before the output folder is touched; the main
    // table, the feature share and the overlay are the first start's (the sequence as opened
    // when there is none).
    let first_frames = frames_of(&args.first_frames);
    let starts: Vec<Sequence> =
        first_frames.iter().map(|&f| opened.starting_at(f)).collect::<Result<_, _>>()?;
    let seq = starts.first().unwrap_or(&opened);
    let labelled = model.is_some() || seq.has_labels();
    if !labelled && args.semantics.iter().any(|&s| s != SemanticsArg::Off) {
        anyhow::bail!(
            "the semantic rows need labels: give the network with --model FILE.slm, use a \
             sequence with a {} folder, or run only --semantics off",
            seq.root.join("semantic").display()
        );
    }
    let kept = semloc::run::prepare_output_dir(&args.out, args.force, &ablate_outputs())?;
    super::print_warnings(kept.as_slice());
    let base = || RunConfig {
        max_frames: args.max_frames.map(|n| usize::try_from(n).unwrap_or(usize::MAX)),
        command_line: super::command_line(),
        threads: args.threads,
        network: model.clone().map(Network::File),
        align: args.align.into(),
        ..config_from_settings(seq, &args.out, &settings, settings_file.clone())
    };
    let pairs: Vec<(Semantics, Association)> = args
        .semantics
        .iter()
        .flat_map(|&s| args.assoc.iter().map(move |&a| (s.into(), a.into())))
        .collect();
    let n = base().frame_count();
    // The feature share (Fig. 4) first: it is quick, and a failure of its own would otherwise
    // come after every row had run and leave no table.
    let share =
        if labelled { Some(feature_share(seq, model.as_ref(), &settings, n)?) } else { None };
    let rows = run_rows_over_seeds(&base, &pairs, &args.out, args.seeds)?;
    let mut per_start = Vec::new();
    let dir = args.out.join("first-frames");
    for (k, s) in starts.iter().enumerate().skip(1) {
        let from = || RunConfig { seq: s, ..base() };
        let f = first_frames[k];
        let more = run_rows_named(
            &from,
            &pairs,
            &dir,
            0,
            &format!("-from{f}"),
            &format!(" (from frame {f})"),
        )?;
        per_start.push(more);
    }

    let mut text = format!(
        "{} frames of {} ({} thread(s)); labels: {}\n\n",
        n,
        seq.summary().name,
        args.threads,
        match &model {
            Some(p) => format!("int8 network {}", p.display()),
            None if labelled => "the sequence's semantic/ folder".to_owned(),
            None => "none".to_owned(),
        }
    );
    text.push_str(&table(&rows));
    let over_starts = if first_frames.len() > 1 {
        let all: Vec<&[Row]> =
            core::iter::once(rows.as_slice()).chain(per_start.iter().map(Vec::as_slice)).collect();
        let r = starts_rows(&all)?;
        text.push_str(&starts_table(&r, &first_frames));
        Some(r)
    } else {
        None
    };
    if let Some(s) = &share {
        let _ = write!(
            text,
            "\nfeatures on static structure (construction + object), left images, {} frames \
             (paper Fig. 4):\n  plain ORB {:.1} % of {} features, semantic ORB {:.1} % of {}; \
             on dynamic classes {:.1} % -> {:.1} %\n",
            s.frames,
            s.structure_pct_plain,
            s.plain.total(),
            s.structure_pct_semantic,
            s.semantic.total(),
            s.dynamic_pct_plain,
            s.dynamic_pct_semantic
        );
    }
    print!("{text}");
    for p in write_overlay(&args.out, seq, &rows, n)? {
        println!("wrote {}", p.display());
    }
    let p = args.out.join("ablation.txt");
    std::fs::write(&p, &text).with_context(|| format!("writing {}", p.display()))?;
    let folders: Vec<String> = rows.iter().map(row_name).collect();
    let json_rows: Vec<JsonRow<'_>> = rows
        .iter()
        .zip(&folders)
        .map(|(r, folder)| {
            let e = r.outcome.eval.as_ref();
            let c = r.outcome.summary.timing.get("compute");
            let motion = r.outcome.summary.motion.as_ref();
            JsonRow {
                semantics: r.semantics.name().to_owned(),
                association: association_name(r.assoc),
                ate_rmse_m: e.map(|e| e.ate_rmse_m),
                t_rel_pct: e.and_then(|e| e.t_rel_pct),
                r_rel_deg_per_100m: e.and_then(|e| e.r_rel_deg_per_100m),
                path_length_m: e.map(|e| e.path_length_m),
                rpe_1f_trans_rmse_m: e.and_then(|e| e.rpe_1f.as_ref()).map(|r| r.trans_m.rmse),
                rpe_1f_rot_rmse_deg: e.and_then(|e| e.rpe_1f.as_ref()).map(|r| r.rot_deg.rmse),
                rpe_10m_trans_rmse_pct: e
                    .and_then(|e| e.rpe_10m.as_ref())
                    .and_then(|r| r.trans_pct)
                    .map(|s| s.rmse),
                rpe_10m_rot_rmse_deg: e.and_then(|e| e.rpe_10m.as_ref()).map(|r| r.rot_deg.rmse),
                compute_median_ms: c.map(|p| p.median_ms),
                compute_p99_ms: c.map(|p| p.p99_ms),
                lost: r.outcome.summary.lost,
                median_culled_per_frame: r.outcome.summary.median_culled,
                em_changed_total: r.outcome.summary.em_changed_total,
                moving_precision: motion.and_then(|m| m.moving_precision),
                moving_recall: motion.and_then(|m| m.moving_recall),
                withheld_precision: motion.and_then(|m| m.withheld_precision),
                withheld_recall: motion.and_then(|m| m.withheld_recall),
                tested_moving_precision: motion.and_then(|m| m.tested_moving_precision),
                tested_moving_recall: motion.and_then(|m| m.tested_moving_recall),
                ate_rmse_m_seeds: &r.seed_ates,
                ate_median_m: r.seed_spread().map(|(m, _, _)| m),
                folder,
            }
        })
        .collect();
    let json = serde_json::json!({
        "dataset": seq.summary(),
        "frames": n,
        "threads": args.threads,
        "seeds": args.seeds,
        "model": model,
        "rows": json_rows,
        "feature_share": share,
        "first_frames": first_frames,
        "over_first_frames": over_starts,
        "align": semloc::eval::Align::from(args.align).to_string(),
    });
    let p = args.out.join("ablation.json");
    std::fs::write(&p, serde_json::to_string_pretty(&json)?)
        .with_context(|| format!("writing {}", p.display()))?;
    println!("outputs in {}", args.out.display());
    Ok(())
}

/// The name of a row: its folder, `semantics-assoc`.
pub fn row_name(r: &Row) -> String {
    format!("{}-{}", r.semantics.name(), association_name(r.assoc))
}

/// Writes `trajectories.svg` and `trajectories.png` into `out`: one top view with the ground
/// truth and every evaluated row's aligned estimate overlaid, the legend naming the rows.
/// Nothing (an empty list) when the sequence has no ground truth or no row was evaluated.
pub fn write_overlay(
    out: &std::path::Path,
    seq: &Sequence,
    rows: &[Row],
    n_frames: usize,
) -> Result<Vec<PathBuf>> {
    let Some(gt) = &seq.gt else { return Ok(Vec::new()) };
    let evaluated: Vec<(String, &semloc::eval::EvalReport)> =
        rows.iter().filter_map(|r| Some((row_name(r), r.outcome.eval.as_ref()?))).collect();
    let Some((_, first)) = evaluated.first() else { return Ok(Vec::new()) };
    let n = evaluated.iter().map(|(_, e)| e.aligned_est.len()).max().unwrap_or(0).min(gt.len());
    let estimates: Vec<(String, Vec<semloc_core::geom::Se3>)> =
        evaluated.iter().map(|(name, e)| (name.clone(), e.aligned_est.clone())).collect();
    let title = format!("Top view of every row, {n_frames} frames of {}", seq.summary().name);
    let stem = out.join("trajectories");
    Ok(semloc::plot::write_overlay_top_view(&stem, &gt[..n], &estimates, first.align, &title)?)
}

/// Every entry `semloc ablate` (or `demo`) may write into its output folder: the tables, the
/// overlaid top view and one `semantics-assoc` folder per possible row.
pub fn ablate_outputs() -> Vec<String> {
    let mut v: Vec<String> = [
        "ablation.json",
        "ablation.txt",
        "sequence",
        "trajectories.svg",
        "trajectories.png",
        "first-frames",
    ]
    .map(String::from)
    .into();
    for s in [Semantics::Off, Semantics::Cull, Semantics::Full, Semantics::Motion] {
        for a in [Association::Hard, Association::Em] {
            let row = format!("{}-{}", s.name(), association_name(a));
            for seed in 1..MAX_SEEDS {
                v.push(format!("{row}-seed{seed}"));
            }
            v.push(row);
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each row's parts as shares of its total, rows with a total of 0 left out, and the
    /// header only above a row.
    #[test]
    fn shares_are_written_per_row_with_their_header() {
        let a = MovingCheck {
            deferred_true: 8,
            deferred_true_pending: 6,
            deferred_true_unseen: 2,
            deferred_true_depthless: 4,
            ..Default::default()
        };
        let none = MovingCheck::default();
        let split = |c: &MovingCheck| {
            (
                c.deferred_true,
                vec![c.deferred_true_pending, c.deferred_true_unseen],
                Some(c.deferred_true_depthless),
            )
        };
        let mut s = String::new();
        write_shares(
            &mut s,
            "head",
            [("x / hard".to_owned(), &a), ("x / em".to_owned(), &none)],
            split,
        );
        assert_eq!(s, "\nhead\n  x / hard: 8 features: 75 / 25 %, 50 % depthless\n");
        let mut s = String::new();
        write_shares(&mut s, "head", [("x / em".to_owned(), &none)], split);
        assert_eq!(s, "");
    }

    /// Frame lists: single frames, inclusive ranges, ranges with a step; what is refused.
    #[test]
    fn frame_spans() {
        let p = |s: &str| parse_frame_span(s).map(|f| f.0);
        assert_eq!(p("7"), Ok(vec![7]));
        assert_eq!(p("3-6"), Ok(vec![3, 4, 5, 6]));
        assert_eq!(p("0-24:2").unwrap(), (0..=24).step_by(2).collect::<Vec<_>>());
        assert_eq!(p("1-23:2").unwrap().last(), Some(&23));
        assert_eq!(p("5-5"), Ok(vec![5]));
        assert!(p("6-3").unwrap_err().contains("empty"));
        assert!(p("0-8:0").unwrap_err().contains("step"));
        assert!(p("x").unwrap_err().contains("not a frame number"));
        assert!(p("-3").is_err() && p("1-").is_err() && p("1-4:").is_err());
        let spans = [FrameSpan(vec![0]), FrameSpan(vec![5, 10]), FrameSpan(vec![3])];
        assert_eq!(frames_of(&spans), [0, 5, 10, 3], "in the order given");
    }

    /// Paired ratios on the log scale: 2x and 0.5x cancel, the standard error is that of the
    /// mean log ratio, a tie is not "better", and one pair has no standard error.
    #[test]
    fn ratio_statistics_over_starts() {
        let r = ratio_stats(&[2.0, 1.0, 3.0, 0.5], &[1.0, 2.0, 3.0, 1.0]);
        let l2 = 2f64.ln();
        let logs = [l2, -l2, 0.0, -l2];
        let mean = -l2 / 4.0;
        let var = logs.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / 3.0;
        assert!((r.geomean - mean.exp()).abs() < 1e-15, "{}", r.geomean);
        assert!((r.worst - 2.0).abs() < 1e-15);
        assert!((r.log_se - (var / 4.0).sqrt()).abs() < 1e-15, "{}", r.log_se);
        assert_eq!(r.better, 2);
        let one = ratio_stats(&[0.9], &[1.0]);
        assert!(one.log_se.is_nan());
        assert_eq!(one.better, 1);
        assert!((one.geomean - 0.9).abs() < 1e-15);
    }
}
