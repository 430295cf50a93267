//! `semloc compare`: two `semloc ablate` results paired start by start, a variant against a
//! reference (another build, network, settings file or row of the same run).
//!
//! On a clip of a few dozen frames the ATE moves by tens of per cent with where tracking
//! starts, more than most changes do; what tells a change from that spread is the ratio of the
//! two runs *from the same start*, over many starts, on the log scale (where 2x and 0.5x weigh
//! alike), with its standard error and the count of starts where the variant is better.

use core::fmt::Write as _;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;

use super::ablate::{frames_of, parse_frame_span, ratio_cell, ratio_stats, FrameSpan};

/// Arguments of `semloc compare`.
#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The reference: a `semloc ablate --out` folder, or its `ablation.json`.
    #[arg(value_name = "REFERENCE")]
    pub reference: PathBuf,
    /// The variant: the same kind of path, on the same dataset and from the same starts
    /// (`--first-frames`) or RANSAC seeds (`--seeds`). It may be the reference itself, with
    /// `--against`.
    #[arg(value_name = "VARIANT")]
    pub variant: PathBuf,
    /// Pair every row of the variant with this one row of the reference (`SEMANTICS/ASSOC`, e.g.
    /// `off/hard` for the backbone, `off/em`) instead of with the reference's row of the same
    /// name.
    #[arg(long, value_name = "SEMANTICS/ASSOC")]
    pub against: Option<String>,
    /// Only these starts (dataset frame numbers, comma-separated; `A-B` and `A-B:S` as in
    /// `ablate --first-frames`), each one both runs were started from: e.g. the starts no
    /// setting was chosen on, `1-23:2`. For runs paired by seed, these seeds.
    #[arg(long, value_delimiter = ',', value_name = "N,...", value_parser = parse_frame_span)]
    pub starts: Vec<FrameSpan>,
    /// Also write the comparison as JSON here (see docs/outputs.md).
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// What one ATE of a row belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Unit {
    /// `--first-frames`: one ATE per start.
    Starts,
    /// `--seeds`: one ATE per RANSAC seed.
    Seeds,
    /// One run per row.
    Single,
}

impl Unit {
    fn name(self) -> &'static str {
        match self {
            Self::Starts => "first_frames",
            Self::Seeds => "seeds",
            Self::Single => "single",
        }
    }
}

/// The parts of an `ablation.json` a comparison needs.
#[derive(Debug)]
struct Ablation {
    path: PathBuf,
    dataset: String,
    frames: u64,
    gt_length_m: f64,
    /// The main start (`dataset.first_frame`).
    first_frame: usize,
    align: Option<String>,
    unit: Unit,
    /// Start frames (`Starts`, `Single`) or seeds, in the order of each row's ATEs.
    keys: Vec<usize>,
    /// `semantics/association` → its figures.
    rows: BTreeMap<String, RowRuns>,
    /// Row names in the file's order.
    order: Vec<String>,
}

/// One row's figures per key.
#[derive(Debug)]
struct RowRuns {
    ate: Vec<f64>,
    /// One-frame RPE, translation (m) and rotation (deg); NaN where the file has none (runs
    /// paired by seed, or too few frames).
    rpe: [Vec<f64>; 2],
}

/// `ablation.json` in `path`, or `path` itself when it is a file.
fn ablation_file(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join("ablation.json")
    } else {
        path.to_path_buf()
    }
}

fn load(path: &Path) -> Result<Ablation> {
    let file = ablation_file(path);
    let text = std::fs::read_to_string(&file).with_context(|| {
        format!("reading {} (a `semloc ablate --out` folder or its ablation.json)", file.display())
    })?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}: not JSON", file.display()))?;
    parse(&file, &v).with_context(|| format!("{}: not a `semloc ablate` result", file.display()))
}

fn parse(file: &Path, v: &serde_json::Value) -> Result<Ablation> {
    let d = &v["dataset"];
    let dataset = d["name"].as_str().context("no dataset.name")?.to_owned();
    let frames = v["frames"].as_u64().context("no frames")?;
    let gt_length_m = d["gt_length_m"].as_f64().unwrap_or(f64::NAN);
    let first_frame = d["first_frame"].as_u64().unwrap_or(0) as usize;
    let align = v["align"].as_str().map(str::to_owned);
    let nums = |x: &serde_json::Value, what: &str| -> Result<Vec<f64>> {
        x.as_array()
            .with_context(|| format!("{what} is not a list"))?
            .iter()
            .map(|a| {
                a.as_f64().with_context(|| format!("{what} holds a value that is not a number"))
            })
            .collect()
    };
    let name = |r: &serde_json::Value| -> Result<String> {
        let s = r["semantics"].as_str().context("a row without semantics")?;
        let a = r["association"].as_str().context("a row without association")?;
        Ok(format!("{s}/{a}"))
    };
    let mut rows = BTreeMap::new();
    let mut order = Vec::new();
    // RPE lists may hold null (a NaN written by serde_json): kept as NaN.
    let maybe_nums = |x: &serde_json::Value, n: usize| -> Vec<f64> {
        let a = x.as_array().map(Vec::as_slice).unwrap_or_default();
        (0..n).map(|i| a.get(i).and_then(serde_json::Value::as_f64).unwrap_or(f64::NAN)).collect()
    };
    let (unit, keys) = if let Some(over) = v["over_first_frames"].as_array() {
        let keys: Vec<usize> = v["first_frames"]
            .as_array()
            .context("over_first_frames without first_frames")?
            .iter()
            .map(|f| f.as_u64().map(|f| f as usize).context("first_frames holds a non-number"))
            .collect::<Result<_>>()?;
        for r in over {
            let n = name(r)?;
            let ates = nums(&r["ate_rmse_m"], &format!("{n}'s ate_rmse_m"))?;
            if ates.len() != keys.len() {
                bail!("{n} has {} ATEs for {} first frames", ates.len(), keys.len());
            }
            let rpe = ["rpe_1f_trans_rmse_m", "rpe_1f_rot_rmse_deg"]
                .map(|k| maybe_nums(&r[k], keys.len()));
            order.push(n.clone());
            rows.insert(n, RowRuns { ate: ates, rpe });
        }
        (Unit::Starts, keys)
    } else {
        let list = v["rows"].as_array().context("no rows")?;
        let seeds = v["seeds"].as_u64().unwrap_or(1) as usize;
        for r in list {
            let n = name(r)?;
            let ates = if seeds > 1 {
                nums(&r["ate_rmse_m_seeds"], &format!("{n}'s ate_rmse_m_seeds"))?
            } else {
                match r["ate_rmse_m"].as_f64() {
                    Some(a) => vec![a],
                    None => Vec::new(),
                }
            };
            if ates.is_empty() {
                bail!("{n} has no ATE (the dataset has no ground truth, or the run failed)");
            }
            let rpe = ["rpe_1f_trans_rmse_m", "rpe_1f_rot_rmse_deg"].map(|k| {
                let x = r[k].as_f64().filter(|_| seeds == 1).unwrap_or(f64::NAN);
                vec![x; ates.len()]
            });
            order.push(n.clone());
            rows.insert(n, RowRuns { ate: ates, rpe });
        }
        if seeds > 1 {
            (Unit::Seeds, (0..seeds).collect())
        } else {
            (Unit::Single, vec![first_frame])
        }
    };
    if rows.is_empty() {
        bail!("no rows");
    }
    Ok(Ablation {
        path: file.to_path_buf(),
        dataset,
        frames,
        gt_length_m,
        first_frame,
        align,
        unit,
        keys,
        rows,
        order,
    })
}

/// One paired row of the comparison.
#[derive(Debug, serde::Serialize)]
struct Paired {
    variant_row: String,
    reference_row: String,
    /// Variant / reference, geometric mean over the pairs, its log's standard error (null from
    /// one pair), the largest ratio, and the pairs where the variant's ATE is lower.
    ate_ratio_geomean: f64,
    ate_ratio_log_se: f64,
    ate_ratio_worst: f64,
    better: usize,
    ate_rmse_m_variant: Vec<f64>,
    ate_rmse_m_reference: Vec<f64>,
    /// The same geometric mean for the one-frame RPE, translation and rotation (null where a
    /// run has none).
    rpe_1f_trans_ratio_geomean: f64,
    rpe_1f_rot_ratio_geomean: f64,
}

/// Pairs the rows of `var` with those of `reference` over `keys` (all the reference's when
/// empty). Errors when the two are not paired runs of one dataset.
fn compare(
    reference: &Ablation,
    var: &Ablation,
    against: Option<&str>,
    keys: &[usize],
) -> Result<(Vec<usize>, Vec<Paired>, Vec<String>)> {
    let (r, v) = (reference.path.display(), var.path.display());
    // Frame count and ground-truth length are those of the main start: comparable only when
    // both runs' main start is the same frame.
    let same_start = reference.first_frame == var.first_frame;
    let same_gt = (reference.gt_length_m - var.gt_length_m).abs() <= 1e-6 * reference.gt_length_m
        || (reference.gt_length_m.is_nan() && var.gt_length_m.is_nan());
    if reference.dataset != var.dataset
        || (same_start && (reference.frames != var.frames || !same_gt))
    {
        bail!(
            "{r} is of dataset {} ({} frames, {:.3} m of ground truth) and {v} of {} ({} frames, \
             {:.3} m): a paired comparison needs runs of the same frames",
            reference.dataset,
            reference.frames,
            reference.gt_length_m,
            var.dataset,
            var.frames,
            var.gt_length_m
        );
    }
    let mut notes = Vec::new();
    match (&reference.align, &var.align) {
        (Some(a), Some(b)) if a != b => {
            bail!("{r} aligns the ATE by {a} and {v} by {b}: the ATEs are not comparable")
        }
        (Some(_), Some(_)) => {}
        _ => notes.push(
            "one of the two files does not record its ATE alignment (made before `align` was \
             written): check that both used the same --align"
                .to_owned(),
        ),
    }
    if reference.unit != var.unit {
        bail!(
            "{r} holds one ATE per {} and {v} per {}: runs paired by start need --first-frames on \
             both, by seed --seeds on both",
            reference.unit.name(),
            var.unit.name()
        );
    }
    let keys: Vec<usize> = if keys.is_empty() { reference.keys.clone() } else { keys.to_vec() };
    let index = |a: &Ablation, k: usize| a.keys.iter().position(|&x| x == k);
    let missing: Vec<String> = keys
        .iter()
        .filter(|&&k| index(reference, k).is_none() || index(var, k).is_none())
        .map(ToString::to_string)
        .collect();
    if !missing.is_empty() {
        let what = if reference.unit == Unit::Seeds { "seeds" } else { "starts" };
        bail!(
            "{what} not in both runs: {} ({r}: {:?}; {v}: {:?})",
            missing.join(", "),
            reference.keys,
            var.keys
        );
    }
    if let Some(a) = against {
        if !reference.rows.contains_key(a) {
            bail!("{r} has no row {a} (it has {})", reference.order.join(", "));
        }
    }
    let mut out = Vec::new();
    for name in &var.order {
        let ref_name = against.unwrap_or(name);
        let Some(ref_row) = reference.rows.get(ref_name) else {
            notes.push(format!("{name}: not in the reference, left out"));
            continue;
        };
        let pick = |a: &Ablation, ates: &[f64]| -> Vec<f64> {
            keys.iter().filter_map(|&k| index(a, k).map(|i| ates[i])).collect()
        };
        let var_row = &var.rows[name];
        let va = pick(var, &var_row.ate);
        let ra = pick(reference, &ref_row.ate);
        let s = ratio_stats(&va, &ra);
        let rpe_ratio = |c: usize| {
            ratio_stats(&pick(var, &var_row.rpe[c]), &pick(reference, &ref_row.rpe[c])).geomean
        };
        out.push(Paired {
            variant_row: name.clone(),
            reference_row: ref_name.to_owned(),
            ate_ratio_geomean: s.geomean,
            ate_ratio_log_se: s.log_se,
            ate_ratio_worst: s.worst,
            better: s.better,
            ate_rmse_m_variant: va,
            ate_rmse_m_reference: ra,
            rpe_1f_trans_ratio_geomean: rpe_ratio(0),
            rpe_1f_rot_ratio_geomean: rpe_ratio(1),
        });
    }
    if out.is_empty() {
        bail!("no row of {v} has a counterpart in {r} (use --against SEMANTICS/ASSOC)");
    }
    Ok((keys, out, notes))
}

fn table(reference: &Ablation, var: &Ablation, keys: &[usize], rows: &[Paired]) -> String {
    let mut s = String::new();
    let what = match reference.unit {
        Unit::Starts => "first frames",
        Unit::Seeds => "RANSAC seeds",
        Unit::Single => "run (one start: no standard error)",
    };
    let list: Vec<String> = keys.iter().map(ToString::to_string).collect();
    let _ = writeln!(
        s,
        "{} against {}\ndataset {} ({} frames), ATE aligned by {}, paired over {} {what} ({})\n\
         ratio variant / reference: geometric mean ± the standard error of its log, the worst \
         ratio and the pairs where the variant is better",
        var.path.display(),
        reference.path.display(),
        reference.dataset,
        reference.frames,
        reference.align.as_deref().unwrap_or("(not recorded)"),
        keys.len(),
        list.join(", ")
    );
    let _ = writeln!(
        s,
        "{:<14}{:<14}{:>17}{:>7}{:>8}{:>24}",
        "variant", "reference", "ATE ratio", "worst", "better", "RPE 1f ratio (t / rot)"
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:<14}{:<14}{:>17}{:>7.2}{:>8}{:>24}",
            r.variant_row,
            r.reference_row,
            ratio_cell(r.ate_ratio_geomean, r.ate_ratio_log_se),
            r.ate_ratio_worst,
            format!("{}/{}", r.better, keys.len()),
            if r.rpe_1f_trans_ratio_geomean.is_finite() || r.rpe_1f_rot_ratio_geomean.is_finite() {
                format!("{:.3} / {:.3}", r.rpe_1f_trans_ratio_geomean, r.rpe_1f_rot_ratio_geomean)
            } else {
                "n/a".to_owned()
            }
        );
    }
    s
}

/// Runs `semloc compare`.
pub fn run(args: &CompareArgs) -> Result<()> {
    let reference = load(&args.reference)?;
    let var = load(&args.variant)?;
    let (keys, rows, notes) =
        compare(&reference, &var, args.against.as_deref(), &frames_of(&args.starts))?;
    super::print_warnings(&notes);
    super::write_stdout(&table(&reference, &var, &keys, &rows));
    if let Some(p) = &args.json {
        let json = serde_json::json!({
            "reference": reference.path,
            "variant": var.path,
            "dataset": reference.dataset,
            "frames": reference.frames,
            "align": reference.align,
            "paired_by": reference.unit.name(),
            "keys": keys,
            "rows": rows,
        });
        semloc::run::outputs::write_json(p, &json)
            .with_context(|| format!("writing {}", p.display()))?;
        println!("wrote {}", p.display());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn abl(path: &str, keys: &[usize], rows: &[(&str, &[f64])]) -> Ablation {
        Ablation {
            path: PathBuf::from(path),
            dataset: "06".into(),
            frames: 51,
            gt_length_m: 59.86,
            first_frame: keys[0],
            align: Some("sim3".into()),
            unit: Unit::Starts,
            keys: keys.to_vec(),
            rows: rows
                .iter()
                .map(|(n, a)| {
                    let rpe = [a.iter().map(|x| x / 10.0).collect(), a.to_vec()];
                    ((*n).to_owned(), RowRuns { ate: a.to_vec(), rpe })
                })
                .collect(),
            order: rows.iter().map(|(n, _)| (*n).to_owned()).collect(),
        }
    }

    /// Pairs by start value, not position; `--against` pairs every variant row with one
    /// reference row; a row the reference lacks is left out with a note.
    #[test]
    fn pairs_by_start_and_by_row() {
        let r =
            abl("r", &[0, 2, 4], &[("off/hard", &[1.0, 2.0, 4.0]), ("off/em", &[2.0, 2.0, 2.0])]);
        let v = abl("v", &[4, 0, 2], &[("off/hard", &[2.0, 0.5, 2.0]), ("motion/em", &[1.0; 3])]);
        let (keys, rows, notes) = compare(&r, &v, None, &[]).unwrap();
        assert_eq!(keys, [0, 2, 4]);
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].ate_rmse_m_variant, [0.5, 2.0, 2.0]);
        // Ratios 0.5, 1, 0.5: geometric mean 0.5^(2/3), better from 2 (a tie is not better).
        assert!((rows[0].ate_ratio_geomean - 0.5f64.powf(2.0 / 3.0)).abs() < 1e-12);
        // The RPE ratios pair the same starts (the helper's RPEs are the ATEs / 10 and as is).
        assert!((rows[0].rpe_1f_trans_ratio_geomean - rows[0].ate_ratio_geomean).abs() < 1e-12);
        assert!((rows[0].rpe_1f_rot_ratio_geomean - rows[0].ate_ratio_geomean).abs() < 1e-12);
        assert_eq!(rows[0].better, 2);
        assert_eq!(notes, ["motion/em: not in the reference, left out"]);
        let (_, rows, _) = compare(&r, &v, Some("off/em"), &[2]).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(
            (rows[1].variant_row.as_str(), rows[1].reference_row.as_str()),
            ("motion/em", "off/em")
        );
        assert_eq!((rows[1].ate_ratio_geomean, rows[1].better), (0.5, 1));
        assert!(rows[1].ate_ratio_log_se.is_nan(), "one pair has no standard error");
    }

    /// Runs that are not paired are refused, each with what differs.
    #[test]
    fn unpaired_runs_are_refused() {
        let r = abl("r", &[0, 2], &[("off/hard", &[1.0, 1.0])]);
        let mut v = abl("v", &[0, 2], &[("off/hard", &[1.0, 1.0])]);
        v.align = Some("se3".into());
        let e = compare(&r, &v, None, &[]).unwrap_err().to_string();
        assert!(e.contains("sim3") && e.contains("se3"), "{e}");
        let mut v = abl("v", &[0, 2], &[("off/hard", &[1.0, 1.0])]);
        v.dataset = "01".into();
        let e = compare(&r, &v, None, &[]).unwrap_err().to_string();
        assert!(e.contains("same frames"), "{e}");
        let v = abl("v", &[0], &[("off/hard", &[1.0])]);
        let e = compare(&r, &v, None, &[]).unwrap_err().to_string();
        assert!(e.contains("starts not in both runs: 2"), "{e}");
        let v = abl("v", &[0, 2], &[("full/em", &[1.0, 1.0])]);
        let e = compare(&r, &v, None, &[]).unwrap_err().to_string();
        assert!(e.contains("no row of v"), "{e}");
        let e = compare(&r, &v, Some("cull/em"), &[]).unwrap_err().to_string();
        assert!(e.contains("has no row cull/em"), "{e}");
        let mut v = abl("v", &[0, 2], &[("off/hard", &[1.0, 1.0])]);
        v.unit = Unit::Seeds;
        let e = compare(&r, &v, None, &[]).unwrap_err().to_string();
        assert!(e.contains("per first_frames") && e.contains("per seeds"), "{e}");
    }

    /// A file that is not an ablation names itself and what is missing.
    #[test]
    fn a_file_that_is_not_an_ablation_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ablation.json");
        std::fs::write(&p, "{\"dataset\": {\"name\": \"06\"}}").unwrap();
        let e = format!("{:#}", load(dir.path()).unwrap_err());
        assert!(
            e.contains("ablation.json: not a `semloc ablate` result") && e.contains("no frames"),
            "{e}"
        );
        std::fs::write(&p, "not json").unwrap();
        let e = format!("{:#}", load(&p).unwrap_err());
        assert!(e.contains("not JSON"), "{e}");
        let e = format!("{:#}", load(&dir.path().join("nope")).unwrap_err());
        assert!(e.contains("reading") && e.contains("nope"), "{e}");
    }
}
