//! `semloc run --rerun FILE.rrd`: a recording of the run for the rerun viewer
//! (<https://rerun.io>, `rerun FILE.rrd`), built with the `rerun` cargo feature (on by default).
//!
//! Entities (world = the first left camera's frame, x right, y down, z forward, metres, as
//! `trajectory.txt`), on the timelines `frame` (0-based frame index) and `time` (seconds since
//! the first frame):
//!
//! | entity | what | when |
//! |---|---|---|
//! | `world` | view coordinates (RDF) and the CamVid annotation context (class names, colours) | static |
//! | `world/camera` | the left camera's pose (camera to world) | per frame |
//! | `world/camera/image` | pinhole intrinsics (static) and the left image | per frame |
//! | `world/camera/image/segmentation` | the labels the features were weighted with (network or dataset) | per frame, with semantics |
//! | `world/camera/image/features/class` | every ORB feature, coloured by the class under it | per frame |
//! | `world/camera/image/features/tracking` | every ORB feature: green inlier, red outlier, grey unmatched | per frame |
//! | `world/camera/image/features/moving` | features the motion test removed (moving or unproven) | per frame, `--semantics motion` |
//! | `world/map` | the local map's points, coloured by class | per frame |
//! | `world/path/estimated` | the estimated path so far | per frame |
//! | `world/path/ground_truth` | the ground-truth path over the frames run | static, when the dataset has one |
//! | `stats/features`, `stats/inliers`, `stats/map_points` | counts | per frame |
//!
//! The file is written as the run goes (every frame's messages are encoded and appended before
//! the next frame), so I/O errors are reported like those of the other outputs, and what was
//! recorded before an interruption stays readable.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use rerun::external::re_build_info::CrateVersion;
use rerun::external::re_log_encoding::encoder::Encoder;
use rerun::external::re_log_encoding::EncodingOptions;
use rerun::sink::MemorySinkStorage;
use rerun::RecordingStream;
use semloc_core::frame::FRAME_CAPACITY;
use semloc_core::geom::Se3;
use semloc_core::seg::{CLASS_NAMES, VOID};
use semloc_core::tracker::FeatureUse;

use crate::dataset::StereoCalib;
use crate::nn::segment::CAMVID_PALETTE;
use crate::pipeline::Pipeline;

use super::{FrameRecord, RunError};

/// JPEG quality of the recorded left images.
const JPEG_QUALITY: u8 = 90;

/// Colours of [`FeatureUse`]: inlier, outlier, unmatched.
const USE_COLOURS: [[u8; 3]; 3] = [[40, 220, 60], [235, 40, 40], [150, 150, 150]];

/// Writes a run's rerun recording (see the module docs).
pub struct Recorder {
    rec: RecordingStream,
    storage: MemorySinkStorage,
    encoder: Encoder<BufWriter<File>>,
    path: PathBuf,
    width: u32,
    height: u32,
    first_time_s: Option<f64>,
    path_est: Vec<[f32; 3]>,
    uses: Box<[FeatureUse; FRAME_CAPACITY]>,
}

type BoxError = Box<dyn core::error::Error + Send + Sync>;

fn write_err(path: &Path, e: impl Into<BoxError>) -> RunError {
    RunError::Write { path: path.to_path_buf(), source: std::io::Error::other(e) }
}

fn position(t_wc: &Se3) -> [f32; 3] {
    [t_wc.trans.x as f32, t_wc.trans.y as f32, t_wc.trans.z as f32]
}

impl Recorder {
    /// Creates `path` and records the static parts: coordinates, classes, intrinsics and the
    /// ground-truth path (`gt`, camera-to-world poses of the frames to be run).
    ///
    /// # Errors
    /// [`RunError::Create`] when the file cannot be created, [`RunError::Write`] when the
    /// first messages cannot be written.
    pub fn create(
        path: &Path,
        calib: &StereoCalib,
        width: u32,
        height: u32,
        gt: Option<&[Se3]>,
    ) -> Result<Self, RunError> {
        let file = File::create(path)
            .map_err(|source| RunError::Create { path: path.to_path_buf(), source })?;
        let encoder = Encoder::new(
            CrateVersion::LOCAL,
            EncodingOptions::PROTOBUF_COMPRESSED,
            BufWriter::new(file),
        )
        .map_err(|e| write_err(path, e))?;
        // `enabled(true)`: the recording does not depend on the RERUN environment variable.
        let (rec, storage) = rerun::RecordingStreamBuilder::new("semloc")
            .enabled(true)
            .memory()
            .map_err(|e| write_err(path, e))?;
        let mut r = Self {
            rec,
            storage,
            encoder,
            path: path.to_path_buf(),
            width,
            height,
            first_time_s: None,
            path_est: Vec::new(),
            uses: Box::new([FeatureUse::Unmatched; FRAME_CAPACITY]),
        };
        r.log_static(calib, gt).map_err(|e| write_err(path, e))?;
        r.drain()?;
        Ok(r)
    }

    fn log_static(&self, calib: &StereoCalib, gt: Option<&[Se3]>) -> Result<(), BoxError> {
        let rec = &self.rec;
        rec.log_static("world", &rerun::ViewCoordinates::RDF())?;
        let classes: Vec<rerun::datatypes::AnnotationInfo> = (0..=VOID)
            .map(|id| {
                let name = CLASS_NAMES.get(usize::from(id)).copied().unwrap_or("void");
                let [r, g, b] = CAMVID_PALETTE[usize::from(id)];
                (u16::from(id), name, rerun::Rgba32::from_rgb(r, g, b)).into()
            })
            .collect();
        rec.log_static("world", &rerun::AnnotationContext::new(classes))?;
        rec.log_static(
            "world/camera/image",
            // Column-major: the principal point is the third column.
            &rerun::Pinhole::new([
                [calib.fx_px as f32, 0.0, 0.0],
                [0.0, calib.fy_px as f32, 0.0],
                [calib.cx_px as f32, calib.cy_px as f32, 1.0],
            ])
            .with_resolution([self.width as f32, self.height as f32]),
        )?;
        if let Some(gt) = gt.filter(|g| g.len() >= 2) {
            let strip: Vec<[f32; 3]> = gt.iter().map(position).collect();
            rec.log_static(
                "world/path/ground_truth",
                &rerun::LineStrips3D::new([strip])
                    .with_colors([rerun::Color::from_rgb(230, 160, 30)]),
            )?;
        }
        Ok(())
    }

    /// Records frame `r`: the pipeline holds its left image (the extractor's pyramid level 0,
    /// an exact copy), features, labels, matches and map.
    ///
    /// # Errors
    /// [`RunError::Write`] naming the file.
    pub fn record(&mut self, pipe: &Pipeline, r: &FrameRecord) -> Result<(), RunError> {
        self.log_frame(pipe, r).map_err(|e| write_err(&self.path, e))?;
        self.drain()
    }

    fn log_frame(&mut self, pipe: &Pipeline, r: &FrameRecord) -> Result<(), BoxError> {
        let rep = &r.output.report;
        let rec = &self.rec;
        let t0 = *self.first_time_s.get_or_insert(r.timestamp_s);
        rec.set_time_sequence("frame", i64::from(rep.frame_index));
        rec.set_duration_secs("time", r.timestamp_s - t0);

        let t_wc = &rep.t_wc;
        let q = nalgebra::UnitQuaternion::from_matrix(&t_wc.rot);
        let q = [q.i as f32, q.j as f32, q.k as f32, q.w as f32];
        rec.log(
            "world/camera",
            &rerun::Transform3D::from_translation_rotation(
                position(t_wc),
                rerun::Quaternion::from_xyzw(q),
            ),
        )?;
        // The frame's left image as the pipeline decoded it (no second decode from disk), as
        // JPEG (quality 90): a KITTI frame takes ~70 KB instead of 467 KB raw. The extractors
        // may already hold the next frame.
        if let Some(left) = pipe.left_image() {
            let mut jpeg = Vec::new();
            image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, JPEG_QUALITY).encode(
                left.as_raw(),
                left.width(),
                left.height(),
                image::ExtendedColorType::L8,
            )?;
            rec.log(
                "world/camera/image",
                &rerun::EncodedImage::from_file_contents(jpeg)
                    .with_media_type(rerun::MediaType::JPEG),
            )?;
        }
        if let Some(labels) = pipe.labels() {
            let format = rerun::datatypes::ImageFormat::segmentation(
                [self.width, self.height],
                rerun::datatypes::ChannelDatatype::U8,
            );
            rec.log(
                "world/camera/image/segmentation",
                &rerun::SegmentationImage::new(labels.as_raw().clone(), format).with_opacity(0.45),
            )?;
        }

        let loc = pipe.localiser();
        let feats = &loc.frame().features;
        let xy: Vec<[f32; 2]> = feats.iter().map(|f| [f.x, f.y]).collect();
        let class: Vec<u16> = feats.iter().map(|f| u16::from(f.class.min(VOID))).collect();
        rec.log(
            "world/camera/image/features/class",
            &rerun::Points2D::new(xy.iter().copied()).with_class_ids(class).with_radii([2.0]),
        )?;
        let tracker = pipe.tracker();
        let n = tracker.feature_use(&mut self.uses[..]);
        let colours = self.uses[..n].iter().map(|u| {
            let [r, g, b] = USE_COLOURS[match u {
                FeatureUse::Inlier => 0,
                FeatureUse::Outlier => 1,
                FeatureUse::Unmatched => 2,
            }];
            rerun::Color::from_rgb(r, g, b)
        });
        rec.log(
            "world/camera/image/features/tracking",
            &rerun::Points2D::new(xy[..n].iter().copied()).with_colors(colours).with_radii([2.0]),
        )?;
        if tracker.motion_aware() {
            let moving = tracker
                .feature_motion()
                .iter()
                .zip(&xy)
                .filter(|(m, _)| m.removed())
                .map(|(_, p)| *p);
            rec.log(
                "world/camera/image/features/moving",
                &rerun::Points2D::new(moving)
                    .with_colors([rerun::Color::from_rgb(255, 0, 255)])
                    .with_radii([4.0]),
            )?;
        }

        let map = tracker.map();
        let (mut pts, mut pcls) = (Vec::new(), Vec::new());
        for lm in map.landmarks().iter().filter(|l| l.alive) {
            let p = [lm.p_w.x as f32, lm.p_w.y as f32, lm.p_w.z as f32];
            if !p.iter().all(|v| v.is_finite()) {
                continue;
            }
            pcls.push(u16::from(lm.class().unwrap_or(VOID)));
            pts.push(p);
        }
        let n_map = pts.len();
        rec.log("world/map", &rerun::Points3D::new(pts).with_class_ids(pcls).with_radii([0.05]))?;

        self.path_est.push(position(t_wc));
        rec.log(
            "world/path/estimated",
            &rerun::LineStrips3D::new([self.path_est.iter().copied()])
                .with_colors([rerun::Color::from_rgb(40, 120, 255)]),
        )?;
        rec.log("stats/features", &rerun::Scalars::new([feats.len() as f64]))?;
        rec.log("stats/inliers", &rerun::Scalars::new([f64::from(rep.inliers)]))?;
        rec.log("stats/map_points", &rerun::Scalars::new([n_map as f64]))?;
        Ok(())
    }

    /// Encodes and appends everything logged so far.
    fn drain(&mut self) -> Result<(), RunError> {
        self.rec.flush_blocking();
        for msg in self.storage.take() {
            self.encoder.append(&msg).map_err(|e| write_err(&self.path, e))?;
        }
        self.encoder.flush_blocking().map_err(|e| write_err(&self.path, e))
    }

    /// Appends what is left and the end-of-stream marker, and syncs the file.
    ///
    /// # Errors
    /// [`RunError::Write`] naming the file.
    pub fn finish(mut self) -> Result<(), RunError> {
        self.drain()?;
        self.encoder.finish().map_err(|e| write_err(&self.path, e))?;
        let path = self.path.clone();
        let file =
            self.encoder.into_inner().into_inner().map_err(|e| write_err(&path, e.into_error()))?;
        file.sync_all().map_err(|e| write_err(&path, e))
    }
}
