//! Dataset readers: KITTI odometry and raw, generic stereo folders, EuRoC MAV.
//!
//! [`Sequence`] is one rectified stereo sequence: image paths, calibration, timestamps and,
//! where the dataset has it, ground truth. Open one with [`Sequence::open_odometry`],
//! [`Sequence::open_raw`], [`Sequence::open_folder`], [`Sequence::open_euroc`] or
//! [`Sequence::open`] (layout auto-detected), then read frames with [`Sequence::load_luma`].
//!
//! * Odometry: `sequences/XX/{image_0,image_1|image_2,image_3}/NNNNNN.png`, `calib.txt`
//!   (`P0`..`P3`), `times.txt`, optional `poses/XX.txt`.
//! * Raw: `DATE/calib_{cam_to_cam,imu_to_velo,velo_to_cam}.txt`,
//!   `DATE/DATE_drive_NNNN_sync/{image_0X/{data/*.png,timestamps.txt}, oxts/data/*.txt}`;
//!   ground truth is derived from the OXTS records exactly as pykitti and the KITTI odometry
//!   poses do (see [`oxts`] and [`raw`]).
//! * Stereo folder: `left/`, `right/` (rectified images of equal names), `calib.txt` or the
//!   settings file's `[camera]`, optional `times.txt`, `gt.txt` or `gt_tum.txt` (see [`folder`]).
//! * EuRoC MAV: `mav0/cam{0,1}/{data.csv, sensor.yaml, data/*.png}` and
//!   `mav0/state_groundtruth_estimate0/data.csv`; the distorted images are rectified on
//!   loading (see [`euroc`] and [`rectify`]).
//!
//! Opening reads every text file and the first stereo pair's image headers; images are decoded
//! only by [`Sequence::load_luma`]. Memory: the path lists and poses, O(frames). Every error is a
//! [`DatasetError`] naming the file (and line); nothing here panics on bad input.

mod calib;
mod error;
pub mod euroc;
pub mod folder;
pub mod luma;
mod odometry;
pub mod oxts;
pub mod raw;
pub mod rectify;
#[cfg(test)]
mod tests;
mod text;

use std::path::{Path, PathBuf};
use std::sync::Arc;

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
    /// A generic stereo folder (`left/`, `right/`, rectified images).
    Folder,
    /// EuRoC MAV (`mav0/cam0`, `mav0/cam1`), rectified on loading.
    Euroc,
}

impl Layout {
    /// The layout's name as `semloc info` prints it.
    pub fn describe(self) -> &'static str {
        match self {
            Layout::Odometry => "KITTI odometry",
            Layout::Raw => "KITTI raw",
            Layout::Folder => "stereo folder",
            Layout::Euroc => "EuRoC MAV",
        }
    }
}

/// Which stereo pair of the KITTI rig (the other layouts have one pair, reported as `Grey`).
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

/// One rectified stereo sequence.
#[derive(Debug, Clone)]
pub struct Sequence {
    /// Layout the sequence was read from.
    pub layout: Layout,
    /// Sequence name: `00` for odometry, `2011_09_26_drive_0005_sync` for raw, the folder's
    /// name for a stereo folder, the folder holding `mav0` for EuRoC.
    pub name: String,
    /// The sequence folder (`.../sequences/00`, `.../DATE_drive_NNNN_sync`, the stereo folder,
    /// or EuRoC's `mav0`).
    pub root: PathBuf,
    /// The stereo pair in use.
    pub pair: CameraPair,
    /// Rectified intrinsics and baseline of the pair.
    pub calib: StereoCalib,
    /// Left images, one per frame, in frame order.
    pub left: Vec<PathBuf>,
    /// Right images, one per frame, in frame order.
    pub right: Vec<PathBuf>,
    /// Frame times in seconds (odometry and stereo folders: `times.txt`; raw and EuRoC:
    /// relative to the first frame).
    pub times_s: Vec<f64>,
    /// Recording time of `times_s`' zero, in seconds, so that `time_origin_s + times_s[i]` is
    /// frame `i`'s recording time (what TUM files carry). Raw: the first left-camera timestamp
    /// as seconds since 1970-01-01 00:00, the civil time of `timestamps.txt` read as UTC.
    /// Odometry: 0, because `times.txt` already is the recording time from the sequence start
    /// (KITTI publishes no absolute time for the odometry sequences). Stereo folder: 0
    /// (`times.txt` is taken as the recording time). EuRoC: the first image's timestamp,
    /// UNIX seconds.
    pub time_origin_s: f64,
    /// Camera-to-world poses of the left camera of the pair, one per frame, if the dataset has
    /// ground truth. Odometry grey: `poses/XX.txt` as is; odometry colour: the same trajectory
    /// moved to camera 2 (`T₂ G T₂⁻¹`); raw: from OXTS, first pose identity; stereo folder and
    /// EuRoC: see [`folder`] and [`euroc`], first pose identity.
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
    /// What the reader assumed or left out that a user should know (e.g. frame times at a
    /// default rate because a stereo folder has no `times.txt`); `semloc info`, `run` and `gt`
    /// print them.
    pub notes: Vec<String>,
    /// EuRoC: the rectification [`Sequence::load_luma`] applies to the distorted images.
    pub remap: Option<Arc<rectify::StereoRemap>>,
    /// The dataset's frame number of this sequence's frame 0: 0 as opened, N after
    /// [`Sequence::starting_at`]`(N)` (`--first-frame N`).
    pub first_frame: usize,
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
    /// Folder names of the left and right camera (`image_0`, `image_02`, `left`, `cam0`, ...).
    pub cameras: [String; 2],
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Rectified intrinsics and baseline.
    pub calib: StereoCalib,
    /// The dataset's frame number of the first frame (`--first-frame`; 0: from the start).
    pub first_frame: usize,
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
    /// Whether the images are rectified on loading (EuRoC).
    pub rectified_on_load: bool,
    /// What the reader assumed ([`Sequence::notes`]).
    pub notes: Vec<String>,
}

impl core::fmt::Display for DatasetSummary {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let layout = self.layout.describe();
        let c = &self.calib;
        writeln!(f, "{layout} sequence {} ({})", self.name, self.root.display())?;
        if self.first_frame == 0 {
            writeln!(f, "  frames:     {}", self.frames)?;
        } else {
            writeln!(
                f,
                "  frames:     {} (the dataset's frames {} to {}: --first-frame)",
                self.frames,
                self.first_frame,
                self.first_frame + self.frames - 1
            )?;
        }
        match self.layout {
            Layout::Odometry | Layout::Raw => writeln!(
                f,
                "  cameras:    {} / {} ({:?} pair)",
                self.cameras[0], self.cameras[1], self.pair
            )?,
            Layout::Folder | Layout::Euroc => {
                writeln!(f, "  cameras:    {} / {}", self.cameras[0], self.cameras[1])?
            }
        }
        if self.rectified_on_load {
            writeln!(f, "  rectified:  on loading (Bouguet, alpha 0); the intrinsics below are the rectified camera")?;
        }
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
        for n in &self.notes {
            write!(f, "\n  note: {n}")?;
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

    /// Opens a generic stereo folder (`left/`, `right/`; see [`folder`]). `camera` (the
    /// settings file's `[camera]`) is the calibration when given, else `calib.txt` is read;
    /// with neither: [`DatasetError::NoCalibration`].
    pub fn open_folder(root: &Path, camera: Option<StereoCalib>) -> Result<Self, DatasetError> {
        folder::open(root, camera)
    }

    /// Opens a EuRoC MAV sequence (the folder holding `mav0`, or `mav0`; see [`euroc`]).
    pub fn open_euroc(root: &Path) -> Result<Self, DatasetError> {
        euroc::open(root)
    }

    /// [`Sequence::open_with_camera`] without a settings camera.
    pub fn open(path: &Path, pair: Option<CameraPair>) -> Result<Self, DatasetError> {
        Self::open_with_camera(path, pair, None)
    }

    /// Opens whatever sequence `path` names, detecting the layout by the first rule that
    /// matches:
    ///
    /// 1. EuRoC: `path/mav0/cam0` or `path/cam0` holds `data.csv` or `sensor.yaml`;
    /// 2. stereo folder: `path/left/` and `path/right/` exist (`camera`, from the settings
    ///    file, is its calibration when given);
    /// 3. an odometry sequence folder (holds `calib.txt`, `times.txt` or `image_0`/`image_2`),
    ///    or an odometry root whose `sequences/` holds exactly one sequence;
    /// 4. a raw drive folder (holds `oxts` or `image_0X`), a raw date folder with exactly one
    ///    `*_drive_*_sync` folder, or a raw root with exactly one such date folder and drive.
    ///
    /// `pair` applies to KITTI only; given for a stereo folder or EuRoC it is
    /// [`DatasetError::PairNotAvailable`]. `camera` is only read for a stereo folder (a run
    /// applies it to every layout itself).
    pub fn open_with_camera(
        path: &Path,
        pair: Option<CameraPair>,
        camera: Option<StereoCalib>,
    ) -> Result<Self, DatasetError> {
        if !path.is_dir() {
            return Err(DatasetError::MissingFile { path: path.to_path_buf() });
        }
        let single_pair = euroc::mav_dir(path).is_some() || folder::is_folder(path);
        if single_pair && pair.is_some() {
            return Err(DatasetError::PairNotAvailable { path: path.to_path_buf() });
        }
        if euroc::mav_dir(path).is_some() {
            return euroc::open(path);
        }
        if folder::is_folder(path) {
            return folder::open(path, camera);
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
            msg: "looked for EuRoC MAV (mav0/cam0/data.csv), a stereo folder (left/ and right/), \
                  KITTI odometry (calib.txt, image_0/image_2, or sequences/) and KITTI raw \
                  (oxts, image_0X, calib_cam_to_cam.txt, or a YYYY_MM_DD folder); found none"
                .into(),
        })
    }

    /// The same sequence from its frame `first` on (`--first-frame`): images, times and the
    /// ground truth lose their first `first` entries, and the ground truth is re-based so that
    /// its first pose is the identity, as every reader delivers it (and as the tracker starts),
    /// so that even an unaligned comparison holds. Frame times keep their values, so TUM files
    /// still carry the recording time. Applied twice, the offsets add up
    /// ([`Sequence::first_frame`]).
    ///
    /// # Errors
    /// [`DatasetError::FirstFrameBeyondEnd`] when `first` is not below [`Sequence::len`].
    pub fn starting_at(&self, first: usize) -> Result<Sequence, DatasetError> {
        if first >= self.len() {
            return Err(DatasetError::FirstFrameBeyondEnd {
                path: self.root.clone(),
                first: self.first_frame + first,
                frames: self.first_frame + self.len(),
            });
        }
        let mut s = self.clone();
        if first == 0 {
            return Ok(s);
        }
        s.left.drain(..first);
        s.right.drain(..first);
        s.times_s.drain(..first.min(s.times_s.len()));
        if let Some(gt) = &mut s.gt {
            gt.drain(..first.min(gt.len()));
            if let Some(g0) = gt.first().map(Se3::inverse) {
                for g in gt.iter_mut() {
                    *g = g0.compose(g);
                }
            }
        }
        s.first_frame += first;
        Ok(s)
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
            Layout::Folder => ["left".into(), "right".into()],
            Layout::Euroc => ["cam0".into(), "cam1".into()],
        }
    }

    /// Frame `i` as 8-bit luma (left, right).
    ///
    /// Grey PNGs are returned as stored; colour is converted with ITU-R BT.601 in Pillow's
    /// fixed-point form, `Y = (19595 R + 38470 G + 7471 B + 32768) >> 16` (see [`luma`]).
    /// Both images must have the sequence's [`image_size`](Sequence::image_size). EuRoC images
    /// are returned rectified ([`Sequence::remap`]).
    pub fn load_luma(&self, i: usize) -> Result<(GrayImage, GrayImage), DatasetError> {
        Ok((self.load_luma_side(i, false)?, self.load_luma_side(i, true)?))
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
        Ok(match &self.remap {
            Some(m) if right => m.right.apply(&img),
            Some(m) => m.left.apply(&img),
            None => img,
        })
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
            first_frame: self.first_frame,
            has_gt: self.gt.is_some(),
            gt_frames: self.gt.as_ref().map_or(0, Vec::len),
            gt_problem: self.gt_problem.as_ref().map(ToString::to_string),
            duration_s: self.duration_s(),
            gt_length_m: self.gt_length_m(),
            rectified_on_load: self.remap.is_some(),
            notes: self.notes.clone(),
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

/// The note for a timestamps file longer than the image list (its extra entries are left
/// out): a clip cut from a longer drive, or images missing at the end.
fn extra_times_note(path: &Path, times: usize, images: usize) -> Option<String> {
    (times > images).then(|| {
        format!(
            "{}: {times} timestamps for {images} images; the first {images} are used (a clip of a \
             longer drive, or are the last {} frames' images missing?)",
            path.display(),
            times - images
        )
    })
}

/// Times of the first `images` frames from a list, and the note for a longer list
/// ([`extra_times_note`]); shorter lists, and times that do not increase strictly (a duplicate
/// or a step back would reach the TUM output and break every time association downstream),
/// are errors.
fn check_times(
    path: &Path,
    mut times: Vec<f64>,
    images: usize,
) -> Result<(Vec<f64>, Option<String>), DatasetError> {
    if times.len() < images {
        return Err(DatasetError::TimesTooShort {
            path: path.to_path_buf(),
            times: times.len(),
            images,
        });
    }
    // Extra entries (e.g. a timestamps file of a longer drive) belong to frames not present.
    let note = extra_times_note(path, times.len(), images);
    times.truncate(images);
    if let Some(k) = times.windows(2).position(|w| w[1] <= w[0]) {
        return Err(DatasetError::TimesNotIncreasing {
            path: path.to_path_buf(),
            frame: k + 1,
            time_s: times[k + 1],
            previous_s: times[k],
        });
    }
    Ok((times, note))
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
