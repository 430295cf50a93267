//! `ecu-sim`: the localiser as an ECU task on a simulated 10 Hz sensor clock, with a bounded
//! frame ring, a per-frame deadline, a degradation policy and seeded fault injection (see
//! `semloc_firmware_sim::sim`). A counting global allocator proves that the ECU allocates
//! nothing after start-up.
//!
//! ```text
//! cargo run --release -p semloc-firmware-sim --features std --bin ecu-sim -- \
//!     --kitti ../shared/data/kitti-raw --drive 2011_09_26_0005 --semantic
//! cargo run --release -p semloc-firmware-sim --features std --bin ecu-sim -- \
//!     --embedded 40 --faults drop@5,dup@9,blank@13,noise@17,truncate@21,desync@25,jump@29:+2,jump@33:-1 --seed 1
//! ```
//!
//! Exit status: 0 when the run ends tracking and the ECU allocated nothing after start-up, 2
//! when not, 1 on a setup error (bad arguments, unreadable dataset, corrupt network with
//! `--strict-model`).
#![forbid(unsafe_code)]

use std::alloc::System;
use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;

use semloc_firmware_sim::sim::source::{EmbeddedSource, FrameSource, KittiSource};
use semloc_firmware_sim::sim::{self, ModelSource, SimConfig};
use stats_alloc::{StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn allocations() -> u64 {
    let s = GLOBAL.stats();
    (s.allocations + s.reallocations) as u64
}

const USAGE: &str =
    "usage: ecu-sim [--embedded FRAMES | --kitti PATH [--drive DATE_NNNN | --seq NN]]
               [--semantic] [--model FILE.slm] [--strict-model]
               [--budget-ms MS] [--period-ms MS] [--ring SLOTS] [--cpu-scale X] [--no-degrade]
               [--faults SPEC] [--seed N] [--frames N] [--csv FILE]
faults SPEC: comma-separated drop@K dup@K blank@K noise@K truncate@K desync@K[:D]
             jump@K:SECONDS jitter:MS bitflip:N (or KIND~RATE for per-frame kinds)";

struct Args {
    cfg: SimConfig,
    embedded: usize,
    kitti: Option<PathBuf>,
    drive: Option<String>,
    seq: Option<String>,
    csv: Option<PathBuf>,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        cfg: SimConfig { alloc_counter: Some(allocations), ..SimConfig::default() },
        embedded: 30,
        kitti: None,
        drive: None,
        seq: None,
        csv: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut val = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        let num =
            |v: String| v.parse::<f64>().map_err(|_| format!("{flag}: `{v}` is not a number"));
        match flag.as_str() {
            "--embedded" => a.embedded = num(val()?)? as usize,
            "--kitti" => a.kitti = Some(PathBuf::from(val()?)),
            "--drive" => a.drive = Some(val()?),
            "--seq" => a.seq = Some(val()?),
            "--semantic" => a.cfg.semantics = true,
            "--model" => a.cfg.model = ModelSource::File(PathBuf::from(val()?)),
            "--strict-model" => a.cfg.strict_model = true,
            "--budget-ms" => a.cfg.budget_s = num(val()?)? * 1e-3,
            "--period-ms" => a.cfg.period_s = num(val()?)? * 1e-3,
            "--ring" => a.cfg.ring_capacity = num(val()?)? as usize,
            "--cpu-scale" => a.cfg.cpu_scale = num(val()?)?,
            "--no-degrade" => a.cfg.degrade = false,
            "--faults" => a.cfg.faults = val()?.parse().map_err(|e| format!("--faults: {e}"))?,
            "--seed" => a.cfg.seed = num(val()?)? as u64,
            "--frames" => a.cfg.max_frames = Some(num(val()?)? as usize),
            "--csv" => a.csv = Some(PathBuf::from(val()?)),
            "-h" | "--help" => return Err(String::new()),
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    Ok(a)
}

fn write_csv(path: &PathBuf, r: &sim::SimReport) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(
        f,
        "sensor_index,arrival_s,start_s,finish_s,exec_ms,mode,labelled,injected,detections,tracked,inliers,features,stereo_matched,good,tx,ty,tz"
    )?;
    for x in &r.frames {
        writeln!(
            f,
            "{},{:.4},{:.4},{:.4},{:.3},{:?},{},{:#x},{:#x},{},{},{},{},{},{:.4},{:.4},{:.4}",
            x.sensor_index,
            x.arrival_s,
            x.start_s,
            x.finish_s,
            x.exec_ms,
            x.mode,
            x.labelled,
            x.injected,
            x.detections,
            x.tracked,
            x.inliers,
            x.features,
            x.stereo_matched,
            x.good,
            x.t_wc[3],
            x.t_wc[7],
            x.t_wc[11]
        )?;
    }
    f.flush()
}

fn main() -> ExitCode {
    let a = match parse() {
        Ok(a) => a,
        Err(e) => {
            if !e.is_empty() {
                eprintln!("error: {e}");
            }
            eprintln!("{USAGE}");
            return ExitCode::from(if e.is_empty() { 0 } else { 1 });
        }
    };
    let mut source: Box<dyn FrameSource> = match &a.kitti {
        Some(p) => match KittiSource::open(p, a.drive.as_deref(), a.seq.as_deref()) {
            Ok(s) => Box::new(s),
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::from(1);
            }
        },
        None => Box::new(EmbeddedSource::new(a.embedded)),
    };
    let report = match sim::run(source.as_mut(), &a.cfg) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(1);
        }
    };
    if let Some(e) = &report.semantics_error {
        eprintln!("warning: network not loaded ({e}); running geometric-only");
    }
    println!("{report}");
    if let Some(p) = &a.csv {
        if let Err(e) = write_csv(p, &report) {
            eprintln!("error: {}: {e}", p.display());
            return ExitCode::from(1);
        }
    }
    if report.ends_good() && report.ecu_allocations == Some(0) {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(2)
    }
}
