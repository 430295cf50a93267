//! Crash-consistent outputs: files streamed a line per frame, whole files replaced atomically,
//! output folders that never mix two runs, and the stop request a signal handler sets.
//!
//! * [`StreamWriter`] appends each frame's line to `trajectory.txt`, `trajectory_tum.txt` and
//!   `frames.csv` with one `write` each as soon as the frame is tracked, so a reader, or
//!   whatever is left after a kill, sees every frame processed so far as whole lines. A failed
//!   write (disk full, file size limit) cuts the file back to its last whole line.
//! * [`write_atomic`] writes `summary.json`, `eval.json` and the plots through a temporary file
//!   in the same folder and a rename: a reader sees the old file, the new one, or none, never
//!   half of one.
//! * [`prepare_output_dir`]: a non-empty `--out` is refused unless `--force`, which removes
//!   what semloc writes there (and only that).
//! * [`StopFlag`]: SIGINT/SIGTERM end the run after the current frame; a second signal ends
//!   the process at once.

use core::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::{frames_csv_header, FrameRecord, RunError};

/// Writes `bytes` to `path` through `path`'s folder: a temporary `.NAME.tmp` file, flushed to
/// disk, then renamed over `path`. On failure the temporary file is removed and `path` is
/// left as it was.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), RunError> {
    write_atomic_io(path, bytes)
        .map_err(|source| RunError::Write { path: path.to_path_buf(), source })
}

/// [`write_atomic`] with the bare I/O error.
pub fn write_atomic_io(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.tmp"));
    let written = (|| -> std::io::Result<()> {
        let mut f = File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })()
    .and_then(|()| std::fs::rename(&tmp, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// One output file written a line at a time.
struct LineFile {
    path: PathBuf,
    file: File,
    /// Bytes of whole lines written so far.
    len: u64,
}

impl LineFile {
    fn create(path: PathBuf, header: Option<&str>) -> Result<Self, RunError> {
        let file = File::create(&path)
            .map_err(|source| RunError::Create { path: path.clone(), source })?;
        let mut f = Self { path, file, len: 0 };
        if let Some(h) = header {
            f.append(h)?;
        }
        Ok(f)
    }

    /// Appends `line` (newline included) in one write; on failure the file is cut back to
    /// its last whole line.
    fn append(&mut self, line: &str) -> Result<(), RunError> {
        match self.file.write_all(line.as_bytes()).and_then(|()| self.file.flush()) {
            Ok(()) => {
                self.len += line.len() as u64;
                Ok(())
            }
            Err(source) => {
                let _ = self.file.set_len(self.len);
                Err(RunError::Write { path: self.path.clone(), source })
            }
        }
    }
}

/// The per-frame files of a run, written as frames are tracked (see the module docs).
pub struct StreamWriter {
    kitti: LineFile,
    tum: LineFile,
    csv: LineFile,
    /// Added to each frame's timestamp in `trajectory_tum.txt` (the recording time of the
    /// source's time zero, [`crate::dataset::Sequence::time_origin_s`]).
    tum_time_origin_s: f64,
    /// Set once a write failed: nothing more is written (every file stays whole).
    failed: bool,
}

impl StreamWriter {
    /// Creates `trajectory.txt`, `trajectory_tum.txt` (with its `#` header) and `frames.csv`
    /// (with its header) in `out`. TUM lines carry `tum_time_origin_s` plus the frame's time,
    /// the recording time.
    pub fn create(out: &Path, tum_time_origin_s: f64) -> Result<Self, RunError> {
        Ok(Self {
            kitti: LineFile::create(out.join("trajectory.txt"), None)?,
            tum: LineFile::create(out.join("trajectory_tum.txt"), Some(crate::traj::TUM_HEADER))?,
            csv: LineFile::create(
                out.join("frames.csv"),
                Some(&format!("{}\n", frames_csv_header())),
            )?,
            tum_time_origin_s,
            failed: false,
        })
    }

    /// Appends frame `r`'s line to each file. After a failure every file holds the same frames
    /// (the ones before the failed frame) and later calls write nothing.
    pub fn append(&mut self, r: &FrameRecord) -> Result<(), RunError> {
        if self.failed {
            return Ok(());
        }
        let pose = r.output.report.t_wc;
        let row = super::outputs::frames_csv_row(r).map_err(|e| {
            self.failed = true;
            RunError::Write { path: self.csv.path.clone(), source: std::io::Error::other(e) }
        })?;
        let lines = [
            crate::traj::format_kitti(&[pose]),
            crate::traj::format_tum_line(self.tum_time_origin_s + r.timestamp_s, &pose),
            row,
        ];
        let before = [self.kitti.len, self.tum.len, self.csv.len];
        for (i, line) in lines.iter().enumerate() {
            if let Err(e) = self.file_mut(i).append(line) {
                self.failed = true;
                // Cut the files already written for this frame back too.
                for (j, &len) in before.iter().enumerate().take(i) {
                    let g = self.file_mut(j);
                    let _ = g.file.set_len(len);
                    g.len = len;
                }
                return Err(e);
            }
        }
        Ok(())
    }

    fn file_mut(&mut self, i: usize) -> &mut LineFile {
        match i {
            0 => &mut self.kitti,
            1 => &mut self.tum,
            _ => &mut self.csv,
        }
    }
}

/// What semloc writes into an output folder: the only entries `--force` removes. Temporary
/// files of an interrupted write (`.NAME.tmp`) are included.
pub const RUN_OUTPUTS: &[&str] =
    &["trajectory.txt", "trajectory_tum.txt", "frames.csv", "summary.json", "eval.json", "plots"];

/// Makes `out` ready for a run: created if missing; an empty folder is used as it is. A
/// non-empty one is refused unless `force`, which removes the entries named in `ours` (and
/// `.*.tmp` leftovers) and leaves anything else in place: the returned warning names it.
pub fn prepare_output_dir(
    out: &Path,
    force: bool,
    ours: &[impl AsRef<str>],
) -> Result<Option<String>, RunError> {
    if out.exists() && !out.is_dir() {
        return Err(RunError::OutputFolder {
            path: out.to_path_buf(),
            source: std::io::Error::other("exists and is not a folder"),
        });
    }
    std::fs::create_dir_all(out)
        .map_err(|source| RunError::OutputFolder { path: out.to_path_buf(), source })?;
    let listing = |source| RunError::OutputFolder { path: out.to_path_buf(), source };
    let mut names: Vec<String> = std::fs::read_dir(out)
        .map_err(listing)?
        .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect::<Result<_, _>>()
        .map_err(listing)?;
    names.sort();
    if names.is_empty() {
        return Ok(None);
    }
    if !force {
        return Err(RunError::OutputNotEmpty { path: out.to_path_buf(), entries: names });
    }
    let mut kept = Vec::new();
    for name in names {
        let leftover = name.starts_with('.') && name.ends_with(".tmp");
        if !ours.iter().any(|o| o.as_ref() == name) && !leftover {
            kept.push(name);
            continue;
        }
        let p = out.join(&name);
        let removed =
            if p.is_dir() { std::fs::remove_dir_all(&p) } else { std::fs::remove_file(&p) };
        removed.map_err(|source| RunError::Write { path: p, source })?;
    }
    Ok((!kept.is_empty()).then(|| {
        format!(
            "{} holds files semloc did not write ({}); they were left in place",
            out.display(),
            super::list_names(&kept)
        )
    }))
}

/// A request to end a run after the current frame. [`StopFlag::register_signals`] makes
/// SIGINT and SIGTERM set it (a second signal then ends the process at once, exit status
/// 128 + signal); other code may [`StopFlag::request`] it.
#[derive(Clone, Debug, Default)]
pub struct StopFlag {
    signal: Arc<AtomicUsize>,
    armed: Arc<AtomicBool>,
}

impl StopFlag {
    /// A flag nobody has set.
    pub fn new() -> Self {
        Self::default()
    }

    /// Asks the run to stop, as signal `signal` would.
    pub fn request(&self, signal: i32) {
        self.signal.store(signal.max(1) as usize, Ordering::SeqCst);
        self.armed.store(true, Ordering::SeqCst);
    }

    /// The signal that asked the run to stop, if one did.
    pub fn requested(&self) -> Option<i32> {
        match self.signal.load(Ordering::SeqCst) {
            0 => None,
            s => Some(s as i32),
        }
    }

    /// Routes SIGINT and SIGTERM to this flag.
    pub fn register_signals(&self) -> std::io::Result<()> {
        use signal_hook::consts::{SIGINT, SIGTERM};
        for sig in [SIGINT, SIGTERM] {
            // Order matters: the shutdown check sees the flag before this signal arms it.
            signal_hook::flag::register_conditional_shutdown(sig, 128 + sig, self.armed.clone())?;
            signal_hook::flag::register(sig, self.armed.clone())?;
            signal_hook::flag::register_usize(sig, self.signal.clone(), sig as usize)?;
        }
        Ok(())
    }
}

/// The usual name of a signal number (`SIGINT`, `SIGTERM`, else `signal N`).
pub fn signal_name(sig: i32) -> String {
    match sig {
        signal_hook::consts::SIGINT => "SIGINT".into(),
        signal_hook::consts::SIGTERM => "SIGTERM".into(),
        s => format!("signal {s}"),
    }
}
