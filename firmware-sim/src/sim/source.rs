//! Where the simulated camera's frames come from: the embedded sequence (no outside data) or a
//! KITTI sequence read by the host crate (`semloc::dataset`). Decoding a PNG is the sensor's
//! work and happens outside the ECU's timed and allocation-counted region.

use std::path::{Path, PathBuf};

use semloc::dataset::Sequence;
use semloc_core::geom::StereoCamera;

use super::SimError;
use crate::embedded;

/// A stereo camera that can be replayed.
pub trait FrameSource: Send {
    /// Human-readable name (dataset path, "embedded").
    fn name(&self) -> String;
    /// Frames available.
    fn len(&self) -> usize;
    /// No frames.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// `(width, height)` in pixels.
    fn size(&self) -> (usize, usize);
    /// The rectified stereo camera.
    fn camera(&self) -> Result<StereoCamera, SimError>;
    /// Capture time of frame `i` relative to frame 0 (s).
    fn timestamp_s(&self, i: usize) -> f64;
    /// Writes frame `i`'s left (or right) luma, `width · height` bytes, into `out`.
    fn load(&mut self, i: usize, right: bool, out: &mut [u8]) -> Result<(), SimError>;
}

/// The six embedded 640×192 frames ([`crate::embedded`]), replayed back and forth
/// (0 1 2 3 4 5 4 3 2 1 0 1 …) for as many frames as asked, at 10 Hz: the camera drives forward
/// 2.75 m and reverses, so a long run needs no outside data. The turns are real motion
/// changes the constant-velocity model has to absorb.
#[derive(Clone, Copy, Debug)]
pub struct EmbeddedSource {
    frames: usize,
}

impl EmbeddedSource {
    /// `frames` frames (the six embedded ones ping-ponged).
    pub fn new(frames: usize) -> Self {
        Self { frames }
    }

    /// Which embedded frame sensor frame `i` shows.
    pub fn index(i: usize) -> usize {
        let n = embedded::FRAMES.len();
        if n < 2 {
            return 0;
        }
        let m = i % (2 * (n - 1));
        if m < n {
            m
        } else {
            2 * (n - 1) - m
        }
    }
}

impl FrameSource for EmbeddedSource {
    fn name(&self) -> String {
        format!("embedded ({} frames of {}, ping-pong)", self.frames, embedded::SOURCE)
    }
    fn len(&self) -> usize {
        if embedded::FRAMES.is_empty() {
            0
        } else {
            self.frames
        }
    }
    fn size(&self) -> (usize, usize) {
        (embedded::WIDTH, embedded::HEIGHT)
    }
    fn camera(&self) -> Result<StereoCamera, SimError> {
        Ok(embedded::CAMERA)
    }
    fn timestamp_s(&self, i: usize) -> f64 {
        i as f64 * 0.1
    }
    fn load(&mut self, i: usize, right: bool, out: &mut [u8]) -> Result<(), SimError> {
        let f = embedded::FRAMES.get(Self::index(i)).ok_or_else(|| SimError::Source {
            path: PathBuf::from("embedded"),
            problem: format!("frame {i} out of range"),
        })?;
        let src = if right { f.right } else { f.left };
        out[..src.len()].copy_from_slice(src);
        Ok(())
    }
}

/// A KITTI odometry sequence or raw drive (`semloc::dataset::Sequence`), as luma.
#[derive(Debug)]
pub struct KittiSource {
    seq: Sequence,
}

impl KittiSource {
    /// Opens `path` (a sequence or drive folder, as `semloc run DATASET`), or, with `drive`, the
    /// raw drive `DATE_NNNN` under the raw root `path`, or with `seq` the odometry sequence
    /// under the odometry root `path`.
    pub fn open(path: &Path, drive: Option<&str>, seq: Option<&str>) -> Result<Self, SimError> {
        let r = match (drive, seq) {
            (Some(d), _) => Sequence::open_raw(path, d, None),
            (None, Some(s)) => Sequence::open_odometry(path, s, None),
            (None, None) => Sequence::open(path, None),
        };
        let seq =
            r.map_err(|e| SimError::Source { path: path.to_path_buf(), problem: e.to_string() })?;
        Ok(Self { seq })
    }

    /// The sequence.
    pub fn sequence(&self) -> &Sequence {
        &self.seq
    }
}

impl FrameSource for KittiSource {
    fn name(&self) -> String {
        format!("{} ({})", self.seq.root.display(), self.seq.name)
    }
    fn len(&self) -> usize {
        self.seq.len()
    }
    fn size(&self) -> (usize, usize) {
        (self.seq.image_size.0 as usize, self.seq.image_size.1 as usize)
    }
    fn camera(&self) -> Result<StereoCamera, SimError> {
        self.seq.calib.to_camera().map_err(|e| SimError::Source {
            path: self.seq.root.clone(),
            problem: format!("calibration: {e}"),
        })
    }
    fn timestamp_s(&self, i: usize) -> f64 {
        let t0 = self.seq.times_s.first().copied().unwrap_or(0.0);
        self.seq.times_s.get(i).map_or(i as f64 * 0.1, |t| t - t0)
    }
    fn load(&mut self, i: usize, right: bool, out: &mut [u8]) -> Result<(), SimError> {
        let img = self.seq.load_luma_side(i, right).map_err(|e| SimError::Source {
            path: self.seq.root.clone(),
            problem: e.to_string(),
        })?;
        let raw = img.as_raw();
        if raw.len() != out.len() {
            return Err(SimError::Source {
                path: self.seq.root.clone(),
                problem: format!("frame {i}: {} bytes, expected {}", raw.len(), out.len()),
            });
        }
        out.copy_from_slice(raw);
        Ok(())
    }
}
