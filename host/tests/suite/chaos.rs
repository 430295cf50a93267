//! Chaos suite: the `semloc` binary run as a careless or hostile user would — killed at
//! random frames, out of disk, unwritable folders, reused folders, wrong models, broken and
//! reversed inputs, broken pipes. Every case asserts the exit status, the message, and that
//! every output file present parses and holds every frame processed before the fault.
//!
//! The data is a small synthetic sequence `semloc synth` writes once per test binary, copied
//! (or linked) into per-case variants.

use core::time::Duration;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::OnceLock;
use std::time::Instant;

use crate::common::{s, semloc, streams as text};

const FRAMES: usize = 14;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_semloc")
}

/// `semloc run` on the shared synthetic sequence into `out`, with `extra` arguments.
fn run_synth(out: &str, extra: &[&str]) -> Output {
    let mut args = vec!["run", s(synth_root()), "--seq", "00", "--out", out];
    args.extend_from_slice(extra);
    semloc(&args)
}

/// The shared synthetic sequence: `ROOT/sequences/00`, `ROOT/poses/00.txt`.
fn synth_root() -> &'static Path {
    static ROOT: OnceLock<tempfile::TempDir> = OnceLock::new();
    ROOT.get_or_init(|| crate::common::synth(&FRAMES.to_string(), "static", "3")).path()
}

/// A copy of the shared sequence under `dir` (images linked, text files copied) whose frame
/// `i` shows original frame `order[i]`.
fn variant(dir: &Path, order: &[usize]) -> PathBuf {
    let src = synth_root().join("sequences/00");
    let root = dir.join("data");
    let seq = root.join("sequences/00");
    for cam in ["image_0", "image_1", "semantic"] {
        std::fs::create_dir_all(seq.join(cam)).unwrap();
        for (i, &j) in order.iter().enumerate() {
            std::os::unix::fs::symlink(
                src.join(cam).join(format!("{j:06}.png")),
                seq.join(cam).join(format!("{i:06}.png")),
            )
            .unwrap();
        }
    }
    std::fs::copy(src.join("calib.txt"), seq.join("calib.txt")).unwrap();
    let times: Vec<String> = std::fs::read_to_string(src.join("times.txt"))
        .unwrap()
        .lines()
        .take(order.len())
        .map(String::from)
        .collect();
    std::fs::write(seq.join("times.txt"), times.join("\n") + "\n").unwrap();
    std::fs::create_dir_all(root.join("poses")).unwrap();
    let poses: Vec<String> = std::fs::read_to_string(synth_root().join("poses/00.txt"))
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    let ordered: Vec<&str> = order.iter().map(|&j| poses[j].as_str()).collect();
    std::fs::write(root.join("poses/00.txt"), ordered.join("\n") + "\n").unwrap();
    root
}

fn identity_order() -> Vec<usize> {
    (0..FRAMES).collect()
}

/// What a run folder holds, parsed; panics (failing the test) on any file that does not
/// parse or on files that disagree about the frames.
#[derive(Debug)]
struct Outputs {
    /// Frames in `trajectory.txt` (= `trajectory_tum.txt` = `frames.csv` rows).
    frames: usize,
    summary: Option<serde_json::Value>,
    statuses: Vec<String>,
}

fn check_outputs(out: &Path) -> Outputs {
    let read = |name: &str| std::fs::read_to_string(out.join(name));
    let mut frames = None;
    if let Ok(t) = read("trajectory.txt") {
        assert!(t.is_empty() || t.ends_with('\n'), "trajectory.txt ends mid-line");
        let poses = semloc::traj::parse_kitti(&t, Path::new("trajectory.txt"));
        let n = match poses {
            Ok(p) => p.len(),
            Err(semloc::traj::TrajError::Empty { .. }) => 0,
            Err(e) => panic!("trajectory.txt does not parse: {e}"),
        };
        frames = Some(n);
    }
    if let Ok(t) = read("trajectory_tum.txt") {
        assert!(t.ends_with('\n'), "trajectory_tum.txt ends mid-line");
        let n = match semloc::traj::parse_tum(&t, Path::new("trajectory_tum.txt")) {
            Ok(p) => p.len(),
            Err(semloc::traj::TrajError::Empty { .. }) => 0,
            Err(e) => panic!("trajectory_tum.txt does not parse: {e}"),
        };
        assert_eq!(Some(n), frames, "TUM and KITTI trajectories disagree");
    }
    let mut statuses = Vec::new();
    if let Ok(t) = read("frames.csv") {
        assert!(t.ends_with('\n'), "frames.csv ends mid-line");
        let mut lines = t.lines();
        let header: Vec<&str> = lines.next().expect("frames.csv header").split(',').collect();
        assert_eq!(header.join(","), semloc::run::frames_csv_header());
        for (k, l) in lines.enumerate() {
            let cells: Vec<&str> = l.split(',').collect();
            assert_eq!(cells.len(), header.len(), "frames.csv row {k}: {l}");
            assert_eq!(cells[0], k.to_string(), "frames.csv row {k} is frame {}", cells[0]);
            statuses.push(cells.last().unwrap().to_string());
        }
        assert_eq!(Some(statuses.len()), frames, "frames.csv and trajectory disagree");
    }
    let summary = read("summary.json").ok().map(|t| {
        let v: serde_json::Value = serde_json::from_str(&t).expect("summary.json parses");
        assert_eq!(
            v["frames_processed"].as_u64().map(|n| n as usize),
            frames,
            "summary and trajectory disagree"
        );
        v
    });
    if let Ok(t) = read("eval.json") {
        let _: serde_json::Value = serde_json::from_str(&t).expect("eval.json parses");
    }
    for e in std::fs::read_dir(out).into_iter().flatten().flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        assert!(!name.ends_with(".tmp"), "temporary file {name} left behind");
    }
    if let Ok(plots) = std::fs::read_dir(out.join("plots")) {
        for p in plots.flatten() {
            let name = p.file_name().to_string_lossy().into_owned();
            assert!(!name.ends_with(".tmp"), "temporary plot {name} left behind");
            if name.ends_with(".svg") {
                let t = std::fs::read_to_string(p.path()).unwrap();
                assert!(t.trim_end().ends_with("</svg>"), "plot {name} is not a whole SVG");
            } else {
                image::open(p.path())
                    .unwrap_or_else(|e| panic!("plot {name} does not decode: {e}"));
            }
        }
    }
    Outputs { frames: frames.unwrap_or(0), summary, statuses }
}

fn spawn_run(data: &Path, out: &Path) -> Child {
    Command::new(bin())
        .args(["run", s(data), "--seq", "00", "--out", s(out), "--threads", "1"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn semloc run")
}

/// Waits until `out/trajectory.txt` holds at least `k` lines.
fn wait_for_frames(out: &Path, k: usize, child: &mut Child) {
    let start = Instant::now();
    loop {
        let n = std::fs::read_to_string(out.join("trajectory.txt"))
            .map(|t| t.lines().count())
            .unwrap_or(0);
        if n >= k {
            return;
        }
        if let Ok(Some(status)) = child.try_wait() {
            panic!("run ended ({status}) before frame {k}");
        }
        assert!(start.elapsed() < Duration::from_secs(300), "no frame {k} after 300 s");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn kill_at(signal: i32, after_frames: usize) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut child = spawn_run(synth_root(), &out);
    wait_for_frames(&out, after_frames, &mut child);
    let pid = child.id().to_string();
    let sig = format!("-{signal}");
    assert!(Command::new("kill").args([&sig, &pid]).status().unwrap().success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    let got = check_outputs(&out);
    assert!(
        got.frames >= after_frames,
        "{} frames written, {after_frames} seen before",
        got.frames
    );
    if got.frames == FRAMES {
        // The signal came after the last frame: a complete run.
        return;
    }
    assert_eq!(o.status.code(), Some(128 + signal), "{err}");
    let name = if signal == 2 { "SIGINT" } else { "SIGTERM" };
    assert!(err.contains(&format!("stopped by {name}")), "{err}");
    let summary = got.summary.expect("summary.json after a signal");
    assert_eq!(summary["complete"], false);
    assert_eq!(summary["stopped_by"], "signal");
    assert_eq!(summary["frames_requested"], FRAMES);
}

#[test]
fn sigint_and_sigterm_at_pseudo_random_frames_keep_every_frame_and_mark_the_summary() {
    // A fixed pseudo-random draw, so a failure is repeatable.
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    for signal in [2, 15, 2] {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let k = 1 + (x % (FRAMES as u64 - 4)) as usize;
        kill_at(signal, k);
    }
}

#[test]
fn sigkill_leaves_whole_lines_for_every_frame_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let mut child = spawn_run(synth_root(), &out);
    wait_for_frames(&out, 3, &mut child);
    child.kill().unwrap();
    child.wait().unwrap();
    let got = check_outputs(&out);
    assert!(got.frames >= 3);
}

#[test]
fn a_full_disk_stops_the_run_with_whole_files_and_a_named_error() {
    let dir = tempfile::tempdir().unwrap();
    let data = synth_root().to_path_buf();
    // File size limits that cut in at different outputs: the per-frame files, the
    // evaluation/plots, the summary.
    for blocks in [2, 8, 40] {
        let out = dir.path().join(format!("out{blocks}"));
        // stdout goes to a file under the same limit, as `semloc run ... > log` would.
        let log = dir.path().join(format!("log{blocks}"));
        let cmd = format!(
            "ulimit -f {blocks}; exec '{}' run '{}' --seq 00 --out '{}' --threads 1 > '{}'",
            bin(),
            s(&data),
            s(&out),
            s(&log)
        );
        let o = Command::new("sh").args(["-c", &cmd]).output().unwrap();
        let stdout = std::fs::read_to_string(&log).unwrap_or_default();
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        let got = check_outputs(&out);
        if o.status.success() {
            // The limit was not reached: everything must be there.
            assert_eq!(got.frames, FRAMES, "{stdout}{err}");
            continue;
        }
        assert_eq!(o.status.code(), Some(1), "limit {blocks}: {stdout}{err}");
        assert!(err.contains("error: "), "{err}");
        assert!(err.contains(s(&out)), "the message names the file: {err}");
        assert!(!err.contains("panicked"), "{err}");
        // The count in the message is the frames the files hold.
        if let Some(rest) = err.split("stopped after ").nth(1) {
            let k: usize = rest.split(' ').next().unwrap().parse().unwrap();
            assert_eq!(k, got.frames, "{err}");
        }
        if let Some(summary) = got.summary {
            // Written: then it says what went wrong.
            let failed = summary["complete"] == false || !summary["eval_error"].is_null();
            assert!(failed, "limit {blocks}: {summary}");
        }
    }
}

#[test]
fn an_unwritable_output_folder_is_an_error_naming_it() {
    let o = run_synth("/proc/semloc-chaos", &[]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("/proc/semloc-chaos"), "{err}");
}

#[test]
fn a_reused_output_folder_is_refused_and_force_replaces_only_what_semloc_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    assert!(run_synth(s(&out), &["--max-frames", "5"]).status.success());
    std::fs::write(out.join("notes.txt"), "mine").unwrap();
    let o = run_synth(s(&out), &["--max-frames", "5"]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(err.contains("is not empty") && err.contains("--force"), "{err}");
    // Nothing of the first run was touched.
    assert_eq!(check_outputs(&out).frames, 5);
    let o = run_synth(s(&out), &["--max-frames", "4", "--force"]);
    let (_, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("notes.txt"), "the kept file is named: {err}");
    assert_eq!(std::fs::read_to_string(out.join("notes.txt")).unwrap(), "mine");
    assert_eq!(check_outputs(&out).frames, 4);
}

#[test]
fn a_network_for_another_image_shape_is_refused() {
    let model =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/artefacts/fastscnn_r2_384x480.slm");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run_synth(s(&out), &["--semantics", "full", "--model", s(&model)]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("fastscnn_r2_384x480.slm") && err.contains("480x384"), "{err}");
    assert!(err.contains("% of the input"), "{err}");
}

#[test]
fn summary_records_provenance() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run_synth(s(&out), &["--max-frames", "3"]);
    assert!(o.status.success(), "{:?}", text(&o));
    let v = check_outputs(&out).summary.unwrap();
    let p = &v["provenance"];
    assert_eq!(p["semloc_version"], env!("CARGO_PKG_VERSION"));
    assert!(p["git_hash"].as_str().is_some_and(|h| !h.is_empty()));
    assert_eq!(p["frames_requested"], 3);
    assert_eq!(p["tracker"]["ransac_iterations"], 100);
    assert_eq!(p["tracker"]["association"], "hard");
    assert!(p["command_line"].as_array().is_some_and(|a| a.iter().any(|x| x == "--max-frames")));
    assert!(p["dataset_path"].as_str().is_some_and(|d| d.ends_with("sequences/00")));
    assert_eq!(v["complete"], true);
}

#[test]
fn a_failed_evaluation_still_writes_the_summary_and_timings() {
    // Ground truth on a straight line: Umeyama alignment is undefined.
    let dir = tempfile::tempdir().unwrap();
    let data = variant(dir.path(), &identity_order());
    let line: String = (0..FRAMES).map(|i| format!("1 0 0 0 0 1 0 0 0 0 1 {i}\n")).collect();
    std::fs::write(data.join("poses/00.txt"), line).unwrap();
    let out = dir.path().join("out");
    let o = semloc(&["run", s(&data), "--seq", "00", "--out", s(&out)]);
    let (stdout, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{stdout}{err}");
    assert!(err.contains("evaluation failed") && err.contains("degenerate"), "{err}");
    assert!(stdout.contains("stage [ms]"), "timing table printed: {stdout}");
    let got = check_outputs(&out);
    assert_eq!(got.frames, FRAMES);
    let summary = got.summary.unwrap();
    assert_eq!(summary["complete"], true);
    assert!(summary["eval_error"].as_str().is_some_and(|e| e.contains("degenerate")), "{summary}");
}

#[test]
fn seq_conflicting_with_the_folder_is_an_error() {
    let seq_dir = synth_root().join("sequences/00");
    let o = semloc(&["info", s(&seq_dir), "--seq", "01"]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("sequence 00") && err.contains("sequence 01"), "{err}");
    // The matching name is fine.
    assert!(semloc(&["info", s(&seq_dir), "--seq", "00"]).status.success());
}

#[test]
fn frames_in_reverse_order_warn_about_the_alignment() {
    let dir = tempfile::tempdir().unwrap();
    let mut order = identity_order();
    order.reverse();
    let data = variant(dir.path(), &order);
    // The reversed images with the forward ground truth: the estimate runs backwards.
    std::fs::copy(synth_root().join("poses/00.txt"), data.join("poses/00.txt")).unwrap();
    let out = dir.path().join("out");
    let o = semloc(&["run", s(&data), "--seq", "00", "--out", s(&out)]);
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}{err}");
    assert!(err.contains("warning:") && err.contains("direction of travel"), "{err}");
    let eval: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
    assert!(eval["alignment_heading_deg"].as_f64().unwrap() > 90.0, "{eval}");
    assert!(!eval["warnings"].as_array().unwrap().is_empty());
    let summary = check_outputs(&out).summary.unwrap();
    assert!(!summary["warnings"].as_array().unwrap().is_empty());
}

#[test]
fn non_increasing_times_and_dropped_frames_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let data = variant(dir.path(), &identity_order());
    let times = data.join("sequences/00/times.txt");
    let mut t: Vec<String> =
        std::fs::read_to_string(&times).unwrap().lines().map(String::from).collect();
    t[5] = t[4].clone();
    std::fs::write(&times, t.join("\n") + "\n").unwrap();
    let o = semloc(&["info", s(&data), "--seq", "00"]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        err.contains("times.txt") && err.contains("frame 5") && err.contains("increase"),
        "{err}"
    );

    let dir = tempfile::tempdir().unwrap();
    let data = variant(dir.path(), &identity_order());
    for cam in ["image_0", "image_1"] {
        std::fs::remove_file(data.join("sequences/00").join(cam).join("000006.png")).unwrap();
    }
    let o = semloc(&["info", s(&data), "--seq", "00"]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        err.contains("000006.png") && err.contains("missing") && err.contains("frame 6"),
        "{err}"
    );
}

#[test]
fn short_or_broken_ground_truth_evaluates_what_it_covers_and_warns_beyond() {
    let dir = tempfile::tempdir().unwrap();
    let data = variant(dir.path(), &identity_order());
    let poses = data.join("poses/00.txt");
    let mut lines: Vec<String> =
        std::fs::read_to_string(&poses).unwrap().lines().map(String::from).collect();
    lines[8] = "1 0 0 broken".into();
    lines.insert(0, "# ground truth with a comment line".into());
    std::fs::write(&poses, lines.join("\n") + "\n").unwrap();
    // Inside the good poses: evaluated.
    let out = dir.path().join("inside");
    let o = semloc(&["run", s(&data), "--seq", "00", "--out", s(&out), "--max-frames", "8"]);
    assert!(o.status.success(), "{:?}", text(&o));
    assert!(out.join("eval.json").is_file());
    // Beyond them: run, warn, no evaluation, exit 0.
    let out = dir.path().join("beyond");
    let o = semloc(&["run", s(&data), "--seq", "00", "--out", s(&out)]);
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}{err}");
    assert!(err.contains("warning:") && err.contains("00.txt:10"), "{err}");
    assert!(!out.join("eval.json").exists());
    let got = check_outputs(&out);
    assert_eq!(got.frames, FRAMES);
    assert!(got.summary.unwrap()["eval"].is_null());
}

#[test]
fn black_frames_are_each_counted_and_flagged() {
    let dir = tempfile::tempdir().unwrap();
    let data = variant(dir.path(), &identity_order());
    let (w, h) =
        image::image_dimensions(synth_root().join("sequences/00/image_0/000000.png")).unwrap();
    let black = image::GrayImage::new(w, h);
    for k in 5..11 {
        for cam in ["image_0", "image_1"] {
            let p = data.join("sequences/00").join(cam).join(format!("{k:06}.png"));
            std::fs::remove_file(&p).unwrap();
            black.save(&p).unwrap();
        }
    }
    let out = dir.path().join("out");
    let o = semloc(&["run", s(&data), "--seq", "00", "--out", s(&out)]);
    assert!(o.status.success(), "{:?}", text(&o));
    let got = check_outputs(&out);
    assert_eq!(
        &got.statuses[5..11],
        ["lost", "coasted", "coasted", "coasted", "coasted", "coasted"]
    );
    assert_eq!(got.statuses[11], "reinitialised");
    let summary = got.summary.unwrap();
    assert_eq!(summary["lost"], 7, "six black frames and the re-initialising one");
    assert_eq!(summary["losses"], 1);
}

#[test]
fn eval_refuses_non_rotations_duplicate_times_and_unflagged_prefixes() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.txt");
    let est = dir.path().join("est.txt");
    let pose = |i: usize| format!("1 0 0 {} 0 1 0 0 0 0 1 {i}\n", (i as f64 * 0.3).sin());
    std::fs::write(&gt, (0..20).map(pose).collect::<String>()).unwrap();
    // A scaled rotation block.
    let mut bad: String = (0..20).map(pose).collect();
    bad = bad.replacen("1 0 0", "1.2 0 0", 1);
    std::fs::write(&est, &bad).unwrap();
    let o = semloc(&["eval", "--gt", s(&gt), "--est", s(&est)]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(err.contains("est.txt:1") && err.contains("not a rotation"), "{err}");
    // A prefix: refused without --prefix, evaluated with it.
    std::fs::write(&est, (0..12).map(pose).collect::<String>()).unwrap();
    let o = semloc(&["eval", "--gt", s(&gt), "--est", s(&est)]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(err.contains("--prefix"), "{err}");
    let o = semloc(&["eval", "--gt", s(&gt), "--est", s(&est), "--prefix"]);
    assert!(o.status.success(), "{:?}", text(&o));
    assert!(text(&o).0.contains("poses          12"));
    // TUM with a repeated timestamp.
    let tum = |t: &[f64]| -> String {
        t.iter().map(|t| format!("{t} {t} 0 {} 0 0 0 1\n", t.sin())).collect()
    };
    std::fs::write(&gt, tum(&[0.0, 0.1, 0.2, 0.3, 0.4, 0.5])).unwrap();
    std::fs::write(&est, tum(&[0.0, 0.1, 0.1, 0.3, 0.4, 0.5])).unwrap();
    let o = semloc(&["eval", "--gt", s(&gt), "--est", s(&est)]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(err.contains("est.txt:3") && err.contains("increase strictly"), "{err}");
}

#[test]
fn a_broken_pipe_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let gt = dir.path().join("gt.txt");
    let pose = |i: usize| format!("1 0 0 {} 0 1 0 0 0 0 1 {i}\n", (i as f64 * 0.3).sin());
    std::fs::write(&gt, (0..300).map(pose).collect::<String>()).unwrap();
    let mut child = Command::new(bin())
        .args(["eval", "--gt", s(&gt), "--est", s(&gt)])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Close the reading end at once, as `| head -0` would.
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{err}");
    use std::os::unix::process::ExitStatusExt;
    assert!(o.status.success() || o.status.signal() == Some(13), "{:?}", o.status);
}

#[test]
fn small_messages_are_right() {
    let dir = tempfile::tempdir().unwrap();
    // --max-frames 0 is a usage error.
    let o = semloc(&[
        "run",
        s(synth_root()),
        "--seq",
        "00",
        "--out",
        s(&dir.path().join("a")),
        "--max-frames",
        "0",
    ]);
    assert_eq!(o.status.code(), Some(2), "{:?}", text(&o));
    // Two frames: said plainly why there is no evaluation.
    let out = dir.path().join("b");
    let o = run_synth(s(&out), &["--max-frames", "2"]);
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}{err}");
    assert!(err.contains("at least 3"), "{err}");
    assert!(!stdout.contains("no ground truth"), "{stdout}");
    // Values are case-insensitive; a model with --semantics off is a warning, not loaded.
    let out = dir.path().join("c");
    let o = run_synth(
        s(&out),
        &["--max-frames", "3", "--semantics", "Off", "--model", "no-such-model.slm"],
    );
    let (stdout, err) = text(&o);
    assert!(o.status.success(), "{stdout}{err}");
    assert!(err.contains("--model is not used"), "{err}");
    // A zero baseline says so, without "-0 m".
    let data = variant(dir.path(), &identity_order());
    let calib = data.join("sequences/00/calib.txt");
    let text0 = std::fs::read_to_string(&calib).unwrap();
    let p0 = text0.lines().find(|l| l.starts_with("P0:")).unwrap().to_string();
    let fixed: String = text0
        .lines()
        .map(|l| if l.starts_with("P1:") { p0.replacen("P0:", "P1:", 1) } else { l.to_string() })
        .map(|l| l + "\n")
        .collect();
    std::fs::write(&calib, fixed).unwrap();
    let o = semloc(&["info", s(&data), "--seq", "00"]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(1));
    assert!(err.contains("baseline is zero") && !err.contains("-0"), "{err}");
    // A cause is printed once.
    let o = semloc(&["eval", "--gt", "/nonexistent/gt.txt", "--est", "/nonexistent/est.txt"]);
    let (_, err) = text(&o);
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
}
