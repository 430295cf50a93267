//! The one error type of the dataset readers: every variant names the file or folder it is
//! about, and the line (1-based) where there is one, so a message alone says what to fix.

use std::path::PathBuf;

/// Why a KITTI dataset could not be read.
///
/// Every variant carries the path of the file (or folder) at fault; text-file variants carry
/// the 1-based line number too. The readers never panic on bad input: they return one of these.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DatasetError {
    /// A required file or folder does not exist.
    #[error("{}: missing file or folder", path.display())]
    MissingFile {
        /// The path that was looked for.
        path: PathBuf,
    },
    /// A file exists but could not be read.
    #[error("{}: cannot read: {msg}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        msg: String,
    },
    /// A line could not be parsed.
    #[error("{}:{line}: {msg}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong with the line.
        msg: String,
    },
    /// A line holds the wrong number of numbers.
    #[error("{}:{line}: expected {expected} numbers, found {got}", path.display())]
    BadFieldCount {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// How many numbers the format asks for.
        expected: usize,
        /// How many the line holds.
        got: usize,
    },
    /// A line holds NaN or an infinity.
    #[error("{}:{line}: non-finite number (NaN or infinity)", path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
    },
    /// A calibration file lacks a required `key:` line.
    #[error("{}: no `{key}:` line", path.display())]
    MissingKey {
        /// The calibration file.
        path: PathBuf,
        /// The key looked for (e.g. `P0`, `P_rect_02`, `R`).
        key: String,
    },
    /// Calibration numbers parse but make no sense (zero focal length, non-positive baseline,
    /// singular transform).
    #[error("{}: bad calibration: {msg}", path.display())]
    BadCalib {
        /// The calibration file.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// The timestamp file has fewer entries than there are images.
    #[error("{}: {times} timestamps for {images} images", path.display())]
    TimesTooShort {
        /// The timestamp file.
        path: PathBuf,
        /// Timestamps found.
        times: usize,
        /// Images found.
        images: usize,
    },
    /// The timestamps do not increase strictly.
    #[error(
        "{}: the time of frame {frame} ({time_s} s) is not after frame {}'s ({previous_s} s); \
         timestamps must increase strictly",
        path.display(),
        frame - 1
    )]
    TimesNotIncreasing {
        /// The timestamp file.
        path: PathBuf,
        /// The 0-based frame whose time is not after its predecessor's.
        frame: usize,
        /// Its time (s).
        time_s: f64,
        /// The predecessor's time (s).
        previous_s: f64,
    },
    /// A numbered frame file is missing (a dropped frame).
    #[error(
        "{}: frame file {missing} is missing (frame {frame}; the next file is {})",
        dir.display(),
        next.as_deref().unwrap_or("none")
    )]
    MissingFrame {
        /// The image folder.
        dir: PathBuf,
        /// The file name expected (e.g. `000005.png`).
        missing: String,
        /// The 0-based frame index it would have had.
        frame: usize,
        /// The file found in its place.
        next: Option<String>,
    },
    /// The left and right image of a frame have different names.
    #[error(
        "left image {} is paired with right image {}: the names must match",
        left.display(),
        right.display()
    )]
    FrameNameMismatch {
        /// The left image.
        left: PathBuf,
        /// The right image at the same position.
        right: PathBuf,
    },
    /// The pose file does not have one pose per image.
    #[error("{}: {poses} poses for {images} images", path.display())]
    PoseCountMismatch {
        /// The pose file.
        path: PathBuf,
        /// Poses found.
        poses: usize,
        /// Images found.
        images: usize,
    },
    /// The oxts folder does not have one record per image.
    #[error("{}: {oxts} oxts records for {images} images", dir.display())]
    OxtsCountMismatch {
        /// The `oxts/data` folder.
        dir: PathBuf,
        /// Records found.
        oxts: usize,
        /// Images found.
        images: usize,
    },
    /// An oxts record does not hold the 30 fields of `dataformat.txt`.
    #[error("{}: oxts record has {got} fields, expected 30", path.display())]
    OxtsFields {
        /// The oxts record file.
        path: PathBuf,
        /// Fields found.
        got: usize,
    },
    /// Left and right image folders hold different numbers of images.
    #[error(
        "{} holds {left} images but {} holds {right}",
        left_dir.display(),
        right_dir.display()
    )]
    ImageCountMismatch {
        /// The left camera's image folder.
        left_dir: PathBuf,
        /// The right camera's image folder.
        right_dir: PathBuf,
        /// Left images found.
        left: usize,
        /// Right images found.
        right: usize,
    },
    /// An image is not the size of the sequence (or of its stereo partner).
    #[error(
        "{}: image is {}x{}, expected {}x{}",
        path.display(),
        got.0,
        got.1,
        expected.0,
        expected.1
    )]
    ImageSizeMismatch {
        /// The image file.
        path: PathBuf,
        /// Expected (width, height).
        expected: (u32, u32),
        /// Actual (width, height).
        got: (u32, u32),
    },
    /// An image file could not be decoded.
    #[error("{}: cannot decode image: {msg}", path.display())]
    ImageDecode {
        /// The image file.
        path: PathBuf,
        /// The decoder's reason.
        msg: String,
    },
    /// `--first-frame` asks for a frame the sequence does not have.
    #[error(
        "{}: --first-frame {first} is beyond the sequence's last frame ({} frames, numbered from 0)",
        path.display(),
        frames
    )]
    FirstFrameBeyondEnd {
        /// The sequence folder.
        path: PathBuf,
        /// The frame asked for (the dataset's numbering).
        first: usize,
        /// Frames the dataset has.
        frames: usize,
    },
    /// A sequence folder holds no images.
    #[error("{}: no images (empty sequence)", path.display())]
    EmptySequence {
        /// The folder that should hold images.
        path: PathBuf,
    },
    /// A folder is none of the layouts semloc reads (or is ambiguous).
    #[error("{}: not a dataset folder semloc reads: {msg}", path.display())]
    UnknownLayout {
        /// The folder.
        path: PathBuf,
        /// What was found, or what would disambiguate.
        msg: String,
    },
    /// The folder is one sequence or drive, and a different one was asked for.
    #[error(
        "{}: this is {what} {found}, but {what} {asked} was asked for; give the dataset root \
         with --{} {asked}, or this folder without it",
        path.display(),
        if *what == "drive" { "drive" } else { "seq" }
    )]
    SelectionConflict {
        /// The folder given.
        path: PathBuf,
        /// `sequence` or `drive`.
        what: &'static str,
        /// What was asked for.
        asked: String,
        /// What the folder is.
        found: String,
    },
    /// An image of a stereo folder has no image of the same name on the other side.
    #[error("{}: no image of the same name in {}", path.display(), other_dir.display())]
    UnpairedImage {
        /// The image without a partner.
        path: PathBuf,
        /// The other camera's folder.
        other_dir: PathBuf,
    },
    /// A time file does not have exactly one time per image.
    #[error("{}: {times} times for {images} images (one time per image, in frame order)", path.display())]
    TimesCountMismatch {
        /// The time file.
        path: PathBuf,
        /// Times found.
        times: usize,
        /// Images found.
        images: usize,
    },
    /// A stereo folder has no calibration and none was given.
    #[error(
        "{}: no calibration: add calib.txt (KITTI format, P0 and P1 of the rectified pair) or          pass --config FILE with a [camera] section (fx, fy, cx, cy, baseline or bf;          `semloc config --print-defaults` shows it)",
        path.display()
    )]
    NoCalibration {
        /// The stereo folder.
        path: PathBuf,
    },
    /// A camera timestamp of a stereo pair has no equal timestamp in the other camera's list.
    #[error(
        "{}:{line}: timestamp {timestamp_ns} ns has no image of the same time in {}",
        path.display(),
        other.display()
    )]
    UnpairedTimestamp {
        /// The list holding the timestamp (`camN/data.csv`).
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// The timestamp, ns.
        timestamp_ns: i64,
        /// The other camera's list.
        other: PathBuf,
    },
    /// The ground truth does not reach a frame's time.
    #[error("{}: no ground truth for frame {frame} (t = {time_s} s): {msg}", path.display())]
    GtNotCovered {
        /// The ground-truth file.
        path: PathBuf,
        /// The 0-based frame.
        frame: usize,
        /// Its time, s (the sequence's `times_s`).
        time_s: f64,
        /// Why.
        msg: String,
    },
    /// `--pair` was given for a layout with a single stereo pair.
    #[error(
        "{}: --pair chooses between KITTI's grey and colour cameras; this folder has one          stereo pair (leave --pair out)",
        path.display()
    )]
    PairNotAvailable {
        /// The folder.
        path: PathBuf,
    },
    /// A frame index past the end of the sequence was asked for.
    #[error("{}: frame {index} asked for, the sequence has {frames}", path.display())]
    FrameOutOfRange {
        /// The sequence folder.
        path: PathBuf,
        /// The index asked for.
        index: usize,
        /// Frames in the sequence.
        frames: usize,
    },
}

impl DatasetError {
    /// Maps a settings-parser error on a YAML file (EuRoC `sensor.yaml`) to `Parse`.
    pub(crate) fn from_yaml(path: &std::path::Path, e: crate::settings::SettingsError) -> Self {
        match e {
            crate::settings::SettingsError::Yaml { line, msg, .. } => {
                DatasetError::Parse { path: path.to_path_buf(), line, msg }
            }
            other => DatasetError::Io { path: path.to_path_buf(), msg: other.to_string() },
        }
    }

    /// Maps an I/O error on `path` to `MissingFile` (not found) or `Io` (anything else).
    pub(crate) fn io(path: &std::path::Path, e: &std::io::Error) -> Self {
        if e.kind() == std::io::ErrorKind::NotFound {
            DatasetError::MissingFile { path: path.to_path_buf() }
        } else {
            DatasetError::Io { path: path.to_path_buf(), msg: e.to_string() }
        }
    }
}
