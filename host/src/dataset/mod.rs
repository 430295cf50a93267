//! KITTI dataset readers (odometry and raw layouts).
//!
//! [`Sequence`] is one rectified stereo sequence: image paths, calibration, timestamps and,
//! where the dataset has it, ground truth. Open one with [`Sequence::open_odometry`],
//! [`Sequence::open_raw`] or [`Sequence::open`] (layout auto-detected), then read frames with
//! [`Sequence::load_luma`].
//!
//! * Odometry: `sequences/XX/{image_0,image_1|image_2,image_3}/NNNNNN.png`, `calib.txt`
//!   (`P0`..`P3`), `times.txt`, optional `poses/XX.txt`.
//! * Raw: `DATE/calib_{cam_to_cam,imu_to_velo,velo_to_cam}.txt`,
//!   `DATE/DATE_drive_NNNN_sync/{image_0X/{data/*.png,timestamps.txt}, oxts/data/*.txt}`;
//!   ground truth is derived from the OXTS records exactly as pykitti and the KITTI odometry
//!   poses do (see [`oxts`] and [`raw`]).
//!
//! Opening reads every text file and the first stereo pair's image headers; images are decoded
//! only by [`Sequence::load_luma`]. Memory: the path lists and poses, O(frames). Every error is a
//! [`DatasetError`] naming the file (and line); nothing here panics on bad input.

mod calib;
mod error;
pub mod luma;
mod odometry;
pub mod oxts;
pub mod raw;
#[cfg(test)]
mod tests;
mod text;

use std::path::{Path, PathBuf};

use image::GrayImage;
use semloc_core::geom::{GeomError, Se3, StereoCamera};
use serde::Serialize;

pub use error::DatasetError;

/// Rectified stereo intrinsics of a camera pair (left camera's intrinsics, shared by both).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StereoCalib {
    /// Focal length along x, pixels.
    pub fx_px: f64,
    /// Focal length along y, pixels.
    pub fy_px: f64,
    /// Principal point x, pixels.
    pub cx_px: f64,
    /// Principal point y, pixels.
    pub cy_px: f64,
    /// Distance between the two camera centres along x, metres.
    pub baseline_m: f64,
}

impl StereoCalib {
    /// The core stereo camera model with these parameters.
    ///
    /// # Errors
    /// [`GeomError::InvalidCamera`] if a value is not finite or a focal length or the baseline
    /// is not positive (cannot happen for a calibration read by this module, which checks).
    pub fn to_camera(&self) -> Result<StereoCamera, GeomError> {
        StereoCamera::new(self.fx_px, self.fy_px, self.cx_px, self.cy_px, self.baseline_m)
    }
}

/// Which on-disk layout a sequence came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// KITTI odometry benchmark (`sequences/XX`).
    Odometry,
    /// KITTI raw (`DATE/DATE_drive_NNNN_sync`).
    Raw,
}

/// Which stereo pair of the KITTI rig.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CameraPair {
    /// Grey cameras 0 (left) and 1 (right).
    Grey,
    /// Colour cameras 2 (left) and 3 (right); read as BT.601 luma.
    Colour,
}

impl CameraPair {
    /// KITTI camera numbers (left, right).
    pub fn cameras(self) -> (usize, usize) {
        match self {
            CameraPair::Grey => (0, 1),
            CameraPair::Colour => (2, 3),
        }
    }
}

/// One rectified KITTI stereo sequence.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// Layout the sequence was read from.
    pub layout: Layout,
    /// Sequence name: `00` for odometry, `2011_09_26_drive_0005_sync` for raw.
    pub name: String,
    /// The sequence folder (`.../sequences/00` or `.../DATE_drive_NNNN_sync`).
    pub root: PathBuf,
    /// The stereo pair in use.
    pub pair: CameraPair,
    /// Rectified intrinsics and baseline of the pair.
    pub calib: StereoCalib,
    /// Left images, one per frame, in frame order.
    pub left: Vec<PathBuf>,
    /// Right images, one per frame, in frame order.
    pub right: Vec<PathBuf>,
    /// Frame times in seconds (odometry: `times.txt`; raw: relative to the first frame).
    pub times_s: Vec<f64>,
    /// Recording time of `times_s`' zero, in seconds, so that `time_origin_s + times_s[i]` is
    /// frame `i`'s recording time (what TUM files carry). Raw: the first left-camera timestamp
    /// as seconds since 1970-01-01 00:00, the civil time of `timestamps.txt` read as UTC.
    /// Odometry: 0, because `times.txt` already is the recording time from the sequence start
    /// (KITTI publishes no absolute time for the odometry sequences).
    pub time_origin_s: f64,
    /// Camera-to-world poses of the left camera of the pair, one per frame, if the dataset has
    /// ground truth. Odometry grey: `poses/XX.txt` as is; odometry colour: the same trajectory
    /// moved to camera 2 (`T₂ G T₂⁻¹`); raw: from OXTS, first pose identity.
    ///
    /// When the ground-truth file is shorter than the sequence or has a bad line, this holds the
    /// poses before the problem (possibly none) and [`Sequence::gt_problem`] says what it was:
    /// a run that stays inside them is still evaluated, a longer one skips the evaluation with
    /// a warning instead of failing.
    pub gt: Option<Vec<Se3>>,
    /// Why the ground truth does not cover every frame, if it does not.
    pub gt_problem: Option<DatasetError>,
    /// Image size (width, height) in pixels, the same for every image.
    pub image_size: (u32, u32),
}

/// What `semloc info` prints about a sequence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DatasetSummary {
    /// Layout the sequence was read from.
    pub layout: Layout,
    /// Sequence name.
    pub name: String,
    /// Sequence folder.
    pub root: PathBuf,
    /// Number of stereo frames.
    pub frames: usize,
    /// Stereo pair in use.
    pub pair: CameraPair,
    /// Folder names of the left and right camera (`image_0`, `image_02`, ...).
    pub cameras: [String; 2],
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Rectified intrinsics and baseline.
    pub calib: StereoCalib,
    /// Whether ground-truth poses are available.
    pub has_gt: bool,
    /// Frames the ground truth covers (from the first); fewer than `frames` when its file is
    /// short or has a bad line.
    pub gt_frames: usize,
    /// Why the ground truth does not cover every frame, if it does not.
    pub gt_problem: Option<String>,
    /// Time from the first to the last frame, seconds.
    pub duration_s: f64,
    /// Length of the ground-truth path (sum of distances between consecutive positions),
    /// metres; `None` without ground truth.
    pub gt_length_m: Option<f64>,
}

impl core::fmt::Display for DatasetSummary {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let layout = match self.layout {
            Layout::Odometry => "KITTI odometry",
            Layout::Raw => "KITTI raw",
        };
        let c = &self.calib;
        writeln!(f, "{layout} sequence {} ({})", self.name, self.root.display())?;
        writeln!(f, "  frames:     {}", self.frames)?;
        writeln!(
            f,
            "  cameras:    {} / {} ({:?} pair)",
            self.cameras[0], self.cameras[1], self.pair
        )?;
        writeln!(f, "  image size: {}x{}", self.width_px, self.height_px)?;
        writeln!(
            f,
            "  intrinsics: fx {:.4} fy {:.4} cx {:.4} cy {:.4} px",
            c.fx_px, c.fy_px, c.cx_px, c.cy_px
        )?;
        writeln!(
            f,
            "  baseline:   {:.6} m (baseline·fx {:.3} px·m)",
            c.baseline_m,
            c.baseline_m * c.fx_px
        )?;
        writeln!(f, "  duration:   {:.3} s", self.duration_s)?;
        match self.gt_length_m {
            Some(l) if self.gt_frames == self.frames => {
                write!(f, "  ground truth: yes, path length {l:.2} m")?
            }
            Some(l) => write!(
                f,
                "  ground truth: frames 0..{} only, path length {l:.2} m",
                self.gt_frames
            )?,
            None => write!(f, "  ground truth: no")?,
        }
        if let Some(p) = &self.gt_problem {
            write!(f, "\n  ground-truth problem: {p}")?;
        }
        Ok(())
    }
}

impl Sequence {
    /// Opens KITTI odometry sequence `seq` (e.g. `00`; `0` is read as `00`).
    ///
    /// `root` is the odometry root holding `sequences/` (and optionally `poses/`), or the
    /// sequence folder itself, in which case poses are looked for at `../../poses/XX.txt`.
    /// `pair = None` picks grey when `image_0`/`image_1` exist, else colour.
    pub fn open_odometry(
        root: &Path,
        seq: &str,
        pair: Option<CameraPair>,
    ) -> Result<Self, DatasetError> {
        odometry::open(root, seq, pair)
    }

    /// Opens KITTI raw drive `drive` (`2011_09_26_0005` or `2011_09_26_drive_0005_sync`).
    ///
    /// `root` holds `DATE/`; the date folder or the drive folder itself is accepted too.
    /// `pair = None` picks grey when `image_00`/`image_01` exist, else colour.
    pub fn open_raw(
        root: &Path,
        drive: &str,
        pair: Option<CameraPair>,
    ) -> Result<Self, DatasetError> {
        raw::open(root, drive, pair)
    }

    /// Opens whatever KITTI sequence `path` names, detecting the layout:
    ///
    /// * an odometry sequence folder (holds `calib.txt` or `image_0`/`image_2`), or an odometry
    ///   root whose `sequences/` holds exactly one sequence;
    /// * a raw drive folder (holds `oxts` or `image_0X`), a raw date folder with exactly one
    ///   `*_drive_*_sync` folder, or a raw root with exactly one such date folder and drive.
    pub fn open(path: &Path, pair: Option<CameraPair>) -> Result<Self, DatasetError> {
        if !path.is_dir() {
            return Err(DatasetError::MissingFile { path: path.to_path_buf() });
        }
        let has = |name: &str| path.join(name).exists();
        if has("calib.txt") || has("times.txt") || has("image_0") || has("image_2") {
            let name = dir_name(path);
            return odometry::open(path, &name, pair);
        }
        if has("oxts") || has("image_00") || has("image_02") {
            let name = dir_name(path);
            return raw::open(path, &name, pair);
        }
        if has("sequences") {
            let seqs = subdirs(&path.join("sequences"), |_| true)?;
            return match seqs.as_slice() {
                [one] => odometry::open(path, one, pair),
                _ => Err(ambiguous(path, "sequences", &seqs, "use --seq")),
            };
        }
        if has("calib_cam_to_cam.txt") {
            let drives = subdirs(path, raw::is_drive_dir_name)?;
            return match drives.as_slice() {
                [one] => raw::open(path, one, pair),
                _ => Err(ambiguous(path, "drives", &drives, "use --drive")),
            };
        }
        let dates = subdirs(path, raw::is_date_name)?;
        if let [date] = dates.as_slice() {
            let date_dir = path.join(date);
            let drives = subdirs(&date_dir, raw::is_drive_dir_name)?;
            return match drives.as_slice() {
                [one] => raw::open(path, one, pair),
                _ => Err(ambiguous(&date_dir, "drives", &drives, "use --drive")),
            };
        }
        let empty =
            std::fs::read_dir(path).map_err(|e| DatasetError::io(path, &e))?.next().is_none();
        if empty {
            return Err(DatasetError::EmptySequence { path: path.to_path_buf() });
        }
        Err(DatasetError::UnknownLayout {
            path: path.to_path_buf(),
            msg: "no calib.txt, image_0X folders, oxts, sequences/ or DATE/ folder".into(),
        })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.left.len()
    }

    /// Whether the sequence has no frames (never true for an opened sequence).
    pub fn is_empty(&self) -> bool {
        self.left.is_empty()
    }

    /// Folder names of the left and right camera images.
    pub fn camera_names(&self) -> [String; 2] {
        let (l, r) = self.pair.cameras();
        match self.layout {
            Layout::Odometry => [format!("image_{l}"), format!("image_{r}")],
            Layout::Raw => [format!("image_{l:02}"), format!("image_{r:02}")],
        }
    }

    /// Frame `i` as 8-bit luma (left, right).
    ///
    /// Grey PNGs are returned as stored; colour is converted with ITU-R BT.601 in Pillow's
    /// fixed-point form, `Y = (19595 R + 38470 G + 7471 B + 32768) >> 16` (see [`luma`]).
    /// Both images must have the sequence's [`image_size`](Sequence::image_size).
    pub fn load_luma(&self, i: usize) -> Result<(GrayImage, GrayImage), DatasetError> {
        let (Some(lp), Some(rp)) = (self.left.get(i), self.right.get(i)) else {
            return Err(DatasetError::FrameOutOfRange {
                path: self.root.clone(),
                index: i,
                frames: self.len(),
            });
        };
        let l = luma::load_luma_file(lp)?;
        self.check_size(lp, &l)?;
        let r = luma::load_luma_file(rp)?;
        self.check_size(rp, &r)?;
        Ok((l, r))
    }

    /// One image of frame `i` as luma: the left one, or the right one when `right` is true.
    /// Lets two threads decode the two images of a frame in parallel.
    pub fn load_luma_side(&self, i: usize, right: bool) -> Result<GrayImage, DatasetError> {
        let paths = if right { &self.right } else { &self.left };
        let Some(p) = paths.get(i) else {
            return Err(DatasetError::FrameOutOfRange {
                path: self.root.clone(),
                index: i,
                frames: self.len(),
            });
        };
        let img = luma::load_luma_file(p)?;
        self.check_size(p, &img)?;
        Ok(img)
    }

    /// The semantic label image of frame `i`'s left camera, if the sequence has labels:
    /// `semantic/NAME.png` beside the image folders, named like the left image (the layout
    /// `semloc synth` writes; 8-bit CamVid class ids, see `semloc_core::seg`).
    pub fn label_path(&self, i: usize) -> Option<PathBuf> {
        let name = self.left.get(i)?.file_name()?;
        Some(self.root.join("semantic").join(name))
    }

    /// Whether the sequence has a `semantic/` label folder.
    pub fn has_labels(&self) -> bool {
        self.root.join("semantic").is_dir()
    }

    /// Frame `i`'s left-camera labels (8-bit class ids), size-checked.
    pub fn load_labels(&self, i: usize) -> Result<GrayImage, DatasetError> {
        let Some(p) = self.label_path(i) else {
            return Err(DatasetError::FrameOutOfRange {
                path: self.root.clone(),
                index: i,
                frames: self.len(),
            });
        };
        if !p.is_file() {
            return Err(DatasetError::MissingFile { path: p });
        }
        let img = image::open(&p)
            .map_err(|e| DatasetError::ImageDecode { path: p.clone(), msg: e.to_string() })?;
        let img = match img {
            image::DynamicImage::ImageLuma8(g) => g,
            other => {
                return Err(DatasetError::ImageDecode {
                    path: p,
                    msg: format!("labels must be 8-bit grey class ids, found {:?}", other.color()),
                })
            }
        };
        self.check_size(&p, &img)?;
        Ok(img)
    }

    fn check_size(&self, path: &Path, img: &GrayImage) -> Result<(), DatasetError> {
        if img.dimensions() == self.image_size {
            Ok(())
        } else {
            Err(DatasetError::ImageSizeMismatch {
                path: path.to_path_buf(),
                expected: self.image_size,
                got: img.dimensions(),
            })
        }
    }

    /// Time from the first to the last frame, seconds.
    pub fn duration_s(&self) -> f64 {
        match (self.times_s.first(), self.times_s.last()) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }

    /// Length of the ground-truth path in metres (sum of consecutive translation distances).
    pub fn gt_length_m(&self) -> Option<f64> {
        self.gt.as_ref().map(|g| g.windows(2).map(|w| (w[1].trans - w[0].trans).norm()).sum())
    }

    /// A description of the sequence for `semloc info`.
    pub fn summary(&self) -> DatasetSummary {
        DatasetSummary {
            layout: self.layout,
            name: self.name.clone(),
            root: self.root.clone(),
            frames: self.len(),
            pair: self.pair,
            cameras: self.camera_names(),
            width_px: self.image_size.0,
            height_px: self.image_size.1,
            calib: self.calib,
            has_gt: self.gt.is_some(),
            gt_frames: self.gt.as_ref().map_or(0, Vec::len),
            gt_problem: self.gt_problem.as_ref().map(ToString::to_string),
            duration_s: self.duration_s(),
            gt_length_m: self.gt_length_m(),
        }
    }
}

/// The last component of `path` as a string (`""` if none).
fn dir_name(path: &Path) -> String {
    let p = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
}

/// Names of the sub-folders of `dir` accepted by `keep`, sorted.
fn subdirs(dir: &Path, keep: impl Fn(&str) -> bool) -> Result<Vec<String>, DatasetError> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| DatasetError::io(dir, &e))? {
        let entry = entry.map_err(|e| DatasetError::io(dir, &e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.path().is_dir() && keep(&name) {
            out.push(name);
        }
    }
    out.sort();
    Ok(out)
}

fn ambiguous(path: &Path, what: &str, found: &[String], hint: &str) -> DatasetError {
    DatasetError::UnknownLayout {
        path: path.to_path_buf(),
        msg: if found.is_empty() {
            format!("no {what} found")
        } else {
            format!("{} {what} found ({}); {hint}", found.len(), found.join(", "))
        },
    }
}

/// Lists the left and right images of a pair and checks the counts agree and are non-zero.
fn list_pair(
    left_dir: &Path,
    right_dir: &Path,
) -> Result<(Vec<PathBuf>, Vec<PathBuf>), DatasetError> {
    let left = text::list_files(left_dir, "png")?;
    let right = text::list_files(right_dir, "png")?;
    if left.is_empty() && right.is_empty() {
        return Err(DatasetError::EmptySequence { path: left_dir.to_path_buf() });
    }
    check_numbering(left_dir, &left)?;
    check_numbering(right_dir, &right)?;
    if left.len() != right.len() {
        return Err(DatasetError::ImageCountMismatch {
            left_dir: left_dir.to_path_buf(),
            right_dir: right_dir.to_path_buf(),
            left: left.len(),
            right: right.len(),
        });
    }
    if let Some((l, r)) = left.iter().zip(&right).find(|(l, r)| l.file_name() != r.file_name()) {
        return Err(DatasetError::FrameNameMismatch { left: l.clone(), right: r.clone() });
    }
    Ok((left, right))
}

/// The size of the first left image, checked against the first right image.
fn first_pair_size(left: &[PathBuf], right: &[PathBuf]) -> Result<(u32, u32), DatasetError> {
    let (Some(l), Some(r)) = (left.first(), right.first()) else {
        return Err(DatasetError::EmptySequence { path: PathBuf::new() });
    };
    let size = luma::image_size(l)?;
    let rsize = luma::image_size(r)?;
    if rsize != size {
        return Err(DatasetError::ImageSizeMismatch {
            path: r.clone(),
            expected: size,
            got: rsize,
        });
    }
    Ok(size)
}

/// Times of the first `images` frames from a list; shorter lists, and times that do not
/// increase strictly (a duplicate or a step back would reach the TUM output and break every
/// time association downstream), are errors.
fn check_times(path: &Path, mut times: Vec<f64>, images: usize) -> Result<Vec<f64>, DatasetError> {
    if times.len() < images {
        return Err(DatasetError::TimesTooShort {
            path: path.to_path_buf(),
            times: times.len(),
            images,
        });
    }
    // Extra entries (e.g. a timestamps file of a longer drive) belong to frames not present.
    times.truncate(images);
    if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
        return Err(DatasetError::TimesNotIncreasing {
            path: path.to_path_buf(),
            frame: k + 1,
            time_s: times[k + 1],
            previous_s: times[k],
        });
    }
    Ok(times)
}

/// The frame number a file name stands for (`000042.png` → 42), if its stem is all digits.
fn frame_number(path: &Path) -> Option<u64> {
    let stem = path.file_stem()?.to_str()?;
    (!stem.is_empty() && stem.bytes().all(|b| b.is_ascii_digit())).then(|| stem.parse().ok())?
}

/// Checks that numbered frame files (`000000.png`, `000001.png`, ...) have no gap: a dropped
/// file would otherwise shift every later frame against its timestamp and ground truth.
fn check_numbering(dir: &Path, files: &[PathBuf]) -> Result<(), DatasetError> {
    let Some(numbers) = files.iter().map(|f| frame_number(f)).collect::<Option<Vec<u64>>>() else {
        return Ok(()); // not numbered: nothing to check
    };
    for (k, w) in numbers.windows(2).enumerate() {
        if w[1] != w[0] + 1 {
            let width = files[k].file_stem().map_or(6, |s| s.len());
            let ext = files[k].extension().map(|e| e.to_string_lossy().into_owned());
            return Err(DatasetError::MissingFrame {
                dir: dir.to_path_buf(),
                missing: format!("{:0width$}.{}", w[0] + 1, ext.unwrap_or_default()),
                frame: k + 1,
                next: files[k + 1].file_name().map(|n| n.to_string_lossy().into_owned()),
            });
        }
    }
    Ok(())
}
