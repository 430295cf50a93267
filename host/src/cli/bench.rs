//! `semloc bench`: whole-pipeline and per-stage timings, as ratios to references measured in
//! the same invocation (OpenCV's ORB on the same frames; the pipeline on one thread and with
//! the stagewise two-thread schedule; with `--model`, the pipeline with the network, full
//! semantics and EM as well; with `--onnx` too, the int8 segmentation network against tract
//! running its float ONNX).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use image::GrayImage;
use semloc::pipeline::{MemoryFrames, Pipeline, Schedule, BIG_STACK_BYTES};
use semloc::run::{
    load_network, percentiles, stats::stage_percentiles, track_frames, FrameRecord, Percentiles,
};
use semloc_core::assoc::Association;
use semloc_core::image::ImageView;
use semloc_core::orb::{KittiOrbExtractor, OrbConfig};
use semloc_core::seg::WeightScheme;
use semloc_core::tracker::TrackerParams;

use super::info::DatasetArgs;

/// Arguments of `semloc bench`.
#[derive(Args, Debug)]
pub struct BenchArgs {
    /// The dataset.
    #[command(flatten)]
    pub data: DatasetArgs,
    /// Frames to time (from the start of the sequence), loaded into memory first so disk and
    /// PNG decoding are not timed.
    #[arg(long, default_value_t = 40, value_name = "N")]
    pub frames: usize,
    /// Passes over the frames for the ORB-only comparison.
    #[arg(long, default_value_t = 3, value_name = "R")]
    pub repeat: usize,
    /// Python interpreter with opencv-python for the OpenCV ORB reference.
    #[arg(long, default_value = "python3", value_name = "PYTHON")]
    pub python: String,
    /// Skip the OpenCV reference.
    #[arg(long)]
    pub no_opencv: bool,
    /// Also write the figures as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// The int8 model (`semloc convert`): the pipeline is timed a second time with it labelling
    /// the frames, full semantics and EM association (the deployed setting); with --onnx, the
    /// segmentation section times it against tract.
    #[arg(long, value_name = "X.slm")]
    pub model: Option<PathBuf>,
    /// The float ONNX the model was converted from, run by tract (f32, 1 thread).
    #[arg(long, value_name = "X.onnx", requires = "model")]
    pub onnx: Option<PathBuf>,
    /// Only the segmentation section (skips ORB, OpenCV and the pipeline).
    #[arg(long, requires = "onnx")]
    pub seg_only: bool,
}

/// The segmentation section: network time per frame on the same input maps (letterboxed left
/// images), int8 core (fast kernels) and tract f32, both on one thread, interleaved per frame.
#[derive(Debug, serde::Serialize)]
struct SegBench {
    input_hw: (usize, usize),
    letterbox_factor: f64,
    runs: usize,
    int8_core_1thread: Percentiles,
    tract_f32_1thread: Percentiles,
    ratio_int8_over_f32_median: f64,
    /// Where the int8 time goes, by op kind.
    int8_by_op_kind: std::collections::BTreeMap<&'static str, OpKindTime>,
}

/// int8 time of one op kind per frame.
#[derive(Debug, serde::Serialize)]
struct OpKindTime {
    ops: usize,
    median_ms: f64,
    macs: u64,
    gmac_per_s: f64,
}

#[derive(Debug, serde::Serialize)]
struct BenchReport {
    frames: usize,
    image_size: (u32, u32),
    orb_semloc_1thread: Percentiles,
    /// The same extractions with the image and ORB kernels capped at baseline x86-64 (SSE2)
    /// code; only where the CPU has x86-64-v3 (`semloc_core::arch`).
    #[serde(skip_serializing_if = "Option::is_none")]
    orb_semloc_1thread_baseline_x86_64: Option<Percentiles>,
    /// Median ORB time, x86-64-v3 kernels over the baseline code, same frames alternating.
    #[serde(skip_serializing_if = "Option::is_none")]
    orb_ratio_v3_over_baseline: Option<f64>,
    orb_opencv_1thread: Option<serde_json::Value>,
    orb_ratio_semloc_over_opencv: Option<f64>,
    /// The geometric backbone.
    pipeline: PipelineBench,
    /// With `--model`: the network labelling, full semantics, EM association.
    #[serde(skip_serializing_if = "Option::is_none")]
    pipeline_network_full_em: Option<PipelineBench>,
    #[serde(skip_serializing_if = "Option::is_none")]
    segmentation: Option<SegBench>,
}

type StageTable = std::collections::BTreeMap<&'static str, Percentiles>;

/// One pipeline setup timed three ways on the same frames, one after the other.
#[derive(Debug, serde::Serialize)]
struct PipelineBench {
    one_thread: StageTable,
    /// Two threads, [`Schedule::Stagewise`]: both extractions side by side, then tracking
    /// beside the next frame's labelling.
    two_threads_stagewise: StageTable,
    /// Two threads, [`Schedule::Overlapped`] (the default): the next frame labelled and
    /// extracted while this one is tracked.
    two_threads: StageTable,
    /// Median frame time, two threads (default schedule) over one thread.
    wall_ratio_2_over_1_threads: f64,
    /// Median frame time, overlapped over stagewise.
    wall_ratio_overlapped_over_stagewise: f64,
}

/// Runs `semloc bench`.
pub fn run(args: &BenchArgs) -> Result<()> {
    let seq = args.data.open()?;
    let n = args.frames.min(seq.len());
    if n == 0 {
        bail!("{}: no frames to time", seq.root.display());
    }
    let pb = super::progress(n as u64, "loading");
    let (mut lefts, mut rights) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for i in 0..n {
        let (l, r) = seq.load_luma(i)?;
        lefts.push(l);
        rights.push(r);
        pb.inc(1);
    }
    pb.finish_and_clear();
    let (w, h) = seq.image_size;
    let repeat = args.repeat.max(1);
    let seg = match (&args.model, &args.onnx) {
        (Some(m), Some(o)) => Some(seg_times(m, o, &lefts, repeat)?),
        _ => None,
    };
    if let (true, Some(s)) = (args.seg_only, &seg) {
        println!("{n} frames, {w}x{h}");
        print_seg(s);
        if let Some(path) = &args.json {
            let v = serde_json::json!({ "frames": n, "image_size": (w, h), "segmentation": s });
            std::fs::write(path, serde_json::to_string_pretty(&v)?)
                .with_context(|| format!("writing {}", path.display()))?;
        }
        return Ok(());
    }

    // ORB alone, one thread, left images; where the CPU has x86-64-v3, each frame is also
    // extracted with the kernels capped at the baseline x86-64 code, alternating, and the two
    // outputs must be the same.
    let orb_lefts = lefts.clone();
    let (orb_ms, baseline_ms) = std::thread::Builder::new()
        .stack_size(BIG_STACK_BYTES)
        .spawn(move || orb_times(&orb_lefts, repeat))?
        .join()
        .map_err(|_| anyhow::anyhow!("ORB timing thread panicked"))??;
    let orb = percentiles(&orb_ms);
    let orb_baseline = (!baseline_ms.is_empty()).then(|| percentiles(&baseline_ms));

    let opencv = if args.no_opencv { None } else { opencv_reference(args, &lefts, repeat)? };
    let ratio = opencv.as_ref().and_then(|v| v["median_ms"].as_f64()).map(|cv| orb.median_ms / cv);

    // Whole pipeline: one thread (reference), two stagewise, two overlapped; same frames, a
    // fresh tracker each.
    let frames = MemoryFrames {
        left: &lefts,
        right: &rights,
        labels: None,
        first_index: 0,
        times_s: &seq.times_s,
    };
    let pipeline = pipeline_bench(&seq, &frames, None)?;
    let pipeline_network_full_em = match &args.model {
        Some(m) => Some(pipeline_bench(&seq, &frames, Some(m))?),
        None => None,
    };
    let report = BenchReport {
        frames: n,
        image_size: (w, h),
        orb_ratio_v3_over_baseline: orb_baseline.as_ref().map(|b| orb.median_ms / b.median_ms),
        orb_semloc_1thread: orb,
        orb_semloc_1thread_baseline_x86_64: orb_baseline,
        orb_opencv_1thread: opencv,
        orb_ratio_semloc_over_opencv: ratio,
        pipeline,
        pipeline_network_full_em,
        segmentation: seg,
    };
    print_report(&report);
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// ORB extraction times (ms) of `lefts`, `repeat` passes, one thread: at the CPU's best level,
/// and, where that is x86-64-v3 ([`semloc_core::arch::v3_active`]), capped at the baseline
/// code right after on the same frame (the order alternates per frame). Fails if the two
/// extractions differ in any key point or descriptor.
fn orb_times(lefts: &[GrayImage], repeat: usize) -> Result<(Vec<f64>, Vec<f64>)> {
    #[cfg(target_arch = "x86_64")]
    use semloc_core::nn::x86::{set_max_isa, Isa};
    let mut ex = Box::new(KittiOrbExtractor::new());
    ex.configure(OrbConfig::KITTI)?;
    let mut base = Box::new(KittiOrbExtractor::new());
    base.configure(OrbConfig::KITTI)?;
    let compare = semloc_core::arch::v3_active();
    let (mut times, mut base_times) = (Vec::new(), Vec::new());
    for pass in 0..repeat {
        for (i, img) in lefts.iter().enumerate() {
            let view =
                ImageView::from_slice(img.as_raw(), img.width() as usize, img.height() as usize)?;
            let baseline_first = compare && (pass + i) % 2 == 1;
            for run_baseline in [baseline_first, !baseline_first] {
                if run_baseline && !compare {
                    continue;
                }
                #[cfg(target_arch = "x86_64")]
                set_max_isa(if run_baseline { Isa::Portable } else { Isa::Avx512Vnni });
                let (e, out) =
                    if run_baseline { (&mut base, &mut base_times) } else { (&mut ex, &mut times) };
                let t = Instant::now();
                let r = e.extract(&view).map(|_| ());
                out.push(t.elapsed().as_secs_f64() * 1e3);
                #[cfg(target_arch = "x86_64")]
                set_max_isa(Isa::Avx512Vnni);
                r?;
            }
            if compare {
                let (a, b) = (ex.features(), base.features());
                if a.keypoints() != b.keypoints() || a.descriptors() != b.descriptors() {
                    bail!(
                        "frame {i}: ORB features differ between the x86-64-v3 and baseline kernels"
                    );
                }
            }
        }
    }
    Ok((times, base_times))
}

/// Times the int8 network and tract's f32 run of its ONNX on the left frames (`repeat` passes),
/// alternating per frame so load changes on a shared machine hit both alike. Letterboxing is
/// done once per frame, outside the timed region; argmax is inside both.
fn seg_times(
    model: &std::path::Path,
    onnx: &std::path::Path,
    lefts: &[GrayImage],
    repeat: usize,
) -> Result<SegBench> {
    use semloc::nn::convert::kind_name;
    use semloc::nn::segment::Segmenter;
    use semloc_core::nn::graph::Kernels;
    use std::collections::BTreeMap;
    let mut seg = Segmenter::new(semloc::nn::SlmBlob::load(model)?)?;
    let tract = semloc::nn::tract_ref::TractRef::load(onnx)?;
    // op kinds and MACs per kind, for the per-kind split of the int8 time
    let (kinds, mut by_kind) = {
        let m = seg.model()?;
        let mut by_kind: BTreeMap<&'static str, (usize, u64, Vec<f64>)> = BTreeMap::new();
        let mut kinds = Vec::new();
        for k in 0..m.n_ops() {
            let op = m.op(k);
            let name = kind_name(op.kind());
            let (ins, _) = op.inputs();
            let shape = |t: u32| m.tensor(t as usize).map(|t| t.shape);
            let macs = match (shape(ins[0]), shape(op.output())) {
                (Some(i), Some(o)) => op.macs(i, o),
                _ => 0,
            };
            let e = by_kind.entry(name).or_default();
            e.0 += 1;
            e.1 += macs;
            kinds.push(name);
        }
        (kinds, by_kind)
    };
    let mut factor = 0.0;
    let (mut t8, mut t32) = (Vec::new(), Vec::new());
    let pb = super::progress((lefts.len() * repeat) as u64, "seg bench");
    for _ in 0..repeat {
        for left in lefts {
            let (lb, _) = seg.prepare(left)?;
            factor = lb.scale();
            let mut frame: BTreeMap<&'static str, f64> = BTreeMap::new();
            let t = Instant::now();
            let mut last = t;
            seg.run_prepared_observed(Kernels::Fast, &mut |k| {
                let now = Instant::now();
                *frame.entry(kinds[k]).or_default() += (now - last).as_secs_f64() * 1e3;
                last = now;
            })?;
            t8.push(t.elapsed().as_secs_f64() * 1e3);
            for (k, ms) in frame {
                if let Some(e) = by_kind.get_mut(k) {
                    e.2.push(ms);
                }
            }
            let t = Instant::now();
            seg.reference(&tract)?;
            t32.push(t.elapsed().as_secs_f64() * 1e3);
            pb.inc(1);
        }
    }
    pb.finish_and_clear();
    let (a, b) = (percentiles(&t8), percentiles(&t32));
    Ok(SegBench {
        input_hw: seg.input_size(),
        letterbox_factor: factor,
        runs: t8.len(),
        int8_core_1thread: a,
        tract_f32_1thread: b,
        ratio_int8_over_f32_median: a.median_ms / b.median_ms,
        int8_by_op_kind: by_kind
            .into_iter()
            .map(|(k, (ops, macs, ms))| {
                let median_ms = percentiles(&ms).median_ms;
                let gmac_per_s = macs as f64 / (median_ms * 1e-3) * 1e-9;
                (k, OpKindTime { ops, median_ms, macs, gmac_per_s })
            })
            .collect(),
    })
}

fn print_seg(s: &SegBench) {
    println!(
        "segmentation {}x{} (letterbox factor {}), {} runs, 1 thread: int8 core median {:.1} ms, \
         p99 {:.1} ms; tract f32 median {:.1} ms, p99 {:.1} ms -> int8/f32 = {:.2}",
        s.input_hw.0,
        s.input_hw.1,
        s.letterbox_factor,
        s.runs,
        s.int8_core_1thread.median_ms,
        s.int8_core_1thread.p99_ms,
        s.tract_f32_1thread.median_ms,
        s.tract_f32_1thread.p99_ms,
        s.ratio_int8_over_f32_median
    );
    println!("{:<14}{:>6}{:>12}{:>10}{:>12}", "int8 op kind", "ops", "median ms", "GMAC", "GMAC/s");
    for (k, t) in &s.int8_by_op_kind {
        println!(
            "{k:<14}{:>6}{:>12.2}{:>10.3}{:>12.2}",
            t.ops,
            t.median_ms,
            t.macs as f64 * 1e-9,
            t.gmac_per_s
        );
    }
}

/// Times the pipeline on `frames` with one thread, then two stagewise, then two overlapped
/// (with `network`: that model labelling, full semantics, EM association).
fn pipeline_bench(
    seq: &semloc::dataset::Sequence,
    frames: &MemoryFrames<'_>,
    network: Option<&std::path::Path>,
) -> Result<PipelineBench> {
    // `semloc run`'s stages without loading (the frames are in memory); `frame` is `compute`
    let table = |threads, schedule| -> Result<StageTable> {
        let records = pipeline_times(seq, frames, threads, schedule, network)?;
        let all = stage_percentiles(&records, network.is_some());
        let mut m: StageTable =
            ["orb_left", "orb_right", "extract_wall", "stereo", "track", "segment"]
                .into_iter()
                .filter_map(|k| Some((k, *all.get(k)?)))
                .collect();
        m.insert("frame", all.get("compute").copied().unwrap_or_default());
        Ok(m)
    };
    let one_thread = table(1, Schedule::Overlapped)?;
    let two_threads_stagewise = table(2, Schedule::Stagewise)?;
    let two_threads = table(2, Schedule::Overlapped)?;
    let med = |t: &StageTable| t["frame"].median_ms;
    Ok(PipelineBench {
        wall_ratio_2_over_1_threads: med(&two_threads) / med(&one_thread),
        wall_ratio_overlapped_over_stagewise: med(&two_threads) / med(&two_threads_stagewise),
        one_thread,
        two_threads_stagewise,
        two_threads,
    })
}

/// Tracks the in-memory `frames` with a fresh pipeline on `threads` threads.
fn pipeline_times(
    seq: &semloc::dataset::Sequence,
    frames: &MemoryFrames<'_>,
    threads: usize,
    schedule: Schedule,
    network: Option<&std::path::Path>,
) -> Result<Vec<FrameRecord>> {
    let (w, h) = seq.image_size;
    let mut params = TrackerParams::default();
    if network.is_some() {
        params.association = Association::Em;
    }
    let mut p = Pipeline::new(&seq.calib, w, h, params, threads)?;
    p.set_schedule(schedule);
    if let Some(m) = network {
        p.set_segmenter(load_network(m, w, h)?);
        p.set_semantics(Some(WeightScheme::Full));
    }
    let tracked = track_frames(&mut p, frames, frames.left.len(), None, &mut |_, _| Ok(()));
    match tracked.failure {
        Some(e) => Err(e.into()),
        None => Ok(tracked.frames),
    }
}

/// Times OpenCV's ORB on the same luma frames (written as PGM) through the bundled script.
fn opencv_reference(
    args: &BenchArgs,
    lefts: &[GrayImage],
    repeat: usize,
) -> Result<Option<serde_json::Value>> {
    let dir = tempfile_dir()?;
    let mut paths = Vec::new();
    for (i, l) in lefts.iter().enumerate() {
        let p = dir.join(format!("{i:06}.pgm"));
        write_pgm(&p, l)?;
        paths.push(p);
    }
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("bench").join("orb_opencv.py");
    let out = std::process::Command::new(&args.python)
        .arg(&script)
        .arg(repeat.to_string())
        .args(&paths)
        .output();
    let _ = std::fs::remove_dir_all(&dir);
    let out = match out {
        Ok(o) => o,
        Err(e) => {
            eprintln!("OpenCV reference skipped: cannot run {}: {e}", args.python);
            return Ok(None);
        }
    };
    if out.status.code() == Some(3) {
        eprintln!(
            "OpenCV reference skipped: {} (pip install opencv-python-headless)",
            String::from_utf8_lossy(&out.stderr).trim()
        );
        return Ok(None);
    }
    if !out.status.success() {
        bail!("{} failed: {}", script.display(), String::from_utf8_lossy(&out.stderr).trim());
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("parsing the output of {}", script.display()))?;
    Ok(Some(v))
}

/// Binary PGM (P5): lossless, and readable by OpenCV without the image crate's PNM codec.
fn write_pgm(path: &std::path::Path, img: &GrayImage) -> Result<()> {
    let mut bytes = format!("P5\n{} {}\n255\n", img.width(), img.height()).into_bytes();
    bytes.extend_from_slice(img.as_raw());
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

fn tempfile_dir() -> Result<PathBuf> {
    let d = std::env::temp_dir().join(format!("semloc-bench-{}", std::process::id()));
    std::fs::create_dir_all(&d).with_context(|| format!("creating {}", d.display()))?;
    Ok(d)
}

fn print_pipeline(p: &PipelineBench) {
    println!(
        "{:<14}{:>12}{:>10}{:>12}{:>10}{:>12}{:>10}",
        "stage [ms]", "1 thr med", "p99", "stagewise", "p99", "2 thr med", "p99"
    );
    for (k, a) in &p.one_thread {
        let (b, c) = (p.two_threads_stagewise[k], p.two_threads[k]);
        println!(
            "{k:<14}{:>12.2}{:>10.2}{:>12.2}{:>10.2}{:>12.2}{:>10.2}",
            a.median_ms, a.p99_ms, b.median_ms, b.p99_ms, c.median_ms, c.p99_ms
        );
    }
    println!(
        "frame wall time, 2 threads / 1 thread = {:.2}; overlapped / stagewise = {:.2}",
        p.wall_ratio_2_over_1_threads, p.wall_ratio_overlapped_over_stagewise
    );
}

fn print_report(r: &BenchReport) {
    println!("{} frames, {}x{}", r.frames, r.image_size.0, r.image_size.1);
    println!(
        "ORB (2000 features, 1 thread): semloc median {:.2} ms, p99 {:.2} ms",
        r.orb_semloc_1thread.median_ms, r.orb_semloc_1thread.p99_ms
    );
    if let (Some(b), Some(ratio)) =
        (&r.orb_semloc_1thread_baseline_x86_64, r.orb_ratio_v3_over_baseline)
    {
        println!(
            "ORB kernels capped at baseline x86-64 (SSE2): median {:.2} ms, p99 {:.2} ms -> x86-64-v3/baseline = {ratio:.2}",
            b.median_ms, b.p99_ms
        );
    }
    if let (Some(cv), Some(ratio)) = (&r.orb_opencv_1thread, r.orb_ratio_semloc_over_opencv) {
        println!(
            "ORB reference: OpenCV {} median {:.2} ms, p99 {:.2} ms -> semloc/OpenCV = {ratio:.2}",
            cv["opencv"].as_str().unwrap_or("?"),
            cv["median_ms"].as_f64().unwrap_or(f64::NAN),
            cv["p99_ms"].as_f64().unwrap_or(f64::NAN)
        );
    }
    println!("pipeline, geometric backbone:");
    print_pipeline(&r.pipeline);
    if let Some(p) = &r.pipeline_network_full_em {
        println!("pipeline, network labels + full semantics + EM:");
        print_pipeline(p);
    }
    if let Some(s) = &r.segmentation {
        print_seg(s);
    }
}
