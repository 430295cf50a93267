//! What a run was made from, recorded in `summary.json` so a result can be traced and
//! repeated: the semloc version and commit, the command line, the dataset and frame range,
//! every tracker parameter, and the network file by name, SHA-256 and input size.

use std::path::PathBuf;

use semloc_core::nn::graph::Letterbox;
use semloc_core::tracker::TrackerParams;
use sha2::{Digest, Sha256};

use crate::nn::segment::Segmenter;

/// The semloc version (`Cargo.toml`).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
/// The git commit the binary was built from (`-dirty` with uncommitted changes to tracked
/// files; `unknown` when built outside a git checkout).
pub const GIT_HASH: &str = env!("SEMLOC_GIT_HASH");

/// `summary.json`'s `provenance` block.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Provenance {
    /// semloc's version.
    pub semloc_version: &'static str,
    /// The commit semloc was built from.
    pub git_hash: &'static str,
    /// The command line, when the run came from the CLI (empty from the library).
    pub command_line: Vec<String>,
    /// The sequence folder.
    pub dataset_path: PathBuf,
    /// The first frame and the number of frames asked for.
    pub first_frame: usize,
    /// Frames asked for (`--max-frames`, or every frame of the sequence).
    pub frames_requested: usize,
    /// Semantic weighting (`off`, `cull`, `full`, `motion`).
    pub semantics: &'static str,
    /// Where labels came from: `network`, `dataset` (the sequence's `semantic/` folder) or
    /// `none`.
    pub labels: &'static str,
    /// Worker threads.
    pub threads: u8,
    /// ATE alignment of the evaluation.
    pub align: String,
    /// The settings file (`--config` or `--orbslam2-settings`), if one was given.
    pub settings_file: Option<PathBuf>,
    /// The rectified camera the run used.
    pub camera: crate::dataset::StereoCalib,
    /// Where the camera came from: `dataset` (its calibration files) or `settings`.
    pub camera_from: &'static str,
    /// ORB extraction settings.
    pub orb: semloc_core::orb::OrbConfig,
    /// Stereo matching settings.
    pub stereo: semloc_core::stereo::StereoMatching,
    /// Every tracker parameter (association, EM and motion test included).
    pub tracker: TrackerParams,
    /// The network, when one labelled the frames.
    pub model: Option<ModelInfo>,
}

/// The network a run used.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ModelInfo {
    /// The `.slm` file.
    pub path: PathBuf,
    /// Its file name without the extension (e.g. `fastscnn_r2_192x640`).
    pub name: String,
    /// SHA-256 of the file's bytes, lower-case hex.
    pub sha256: String,
    /// Network input width and height (px).
    pub input_width: usize,
    /// Network input height (px).
    pub input_height: usize,
    /// How frames are fitted to the input: the down-scaling (frame pixels per input pixel:
    /// 2 for KITTI into 192x640, 1.5 into 256x832).
    pub downscale: f64,
    /// Share of the network input covered by the frame (0..1).
    pub coverage: f64,
}

impl ModelInfo {
    /// Describes `seg` as used on `width`x`height` frames.
    pub fn of(seg: &Segmenter, width: u32, height: u32) -> Self {
        let path = seg.blob().path().to_path_buf();
        let (h, w) = seg.input_size();
        let (downscale, coverage) = match seg.letterbox(width as usize, height as usize) {
            Ok(lb) => (lb.scale(), input_coverage(&lb)),
            Err(_) => (0.0, 0.0),
        };
        Self {
            name: path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
            sha256: sha256_hex(seg.blob().bytes()),
            path,
            input_width: w,
            input_height: h,
            downscale,
            coverage,
        }
    }
}

/// The share of the network input that the letterboxed frame covers.
pub fn input_coverage(lb: &Letterbox) -> f64 {
    let cw = lb.scaled_w().min(lb.model_w);
    let ch = lb.scaled_h().min(lb.model_h);
    (cw * ch) as f64 / (lb.model_w * lb.model_h).max(1) as f64
}

/// The down-scaling as text: `2`, `3/2`.
pub fn scale_text(lb: &Letterbox) -> String {
    if lb.den == 1 {
        lb.num.to_string()
    } else {
        format!("{}/{}", lb.num, lb.den)
    }
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_of_known_input() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn coverage_of_kitti_on_the_shipped_inputs() {
        let lb = |h, w| Letterbox::fit(1241, 376, h, w).unwrap();
        // 1241x376 on 192x640 at 2: 621x188 of 640x192.
        let c = input_coverage(&lb(192, 640));
        assert!((c - 621.0 * 188.0 / (640.0 * 192.0)).abs() < 1e-12, "{c}");
        assert_eq!(scale_text(&lb(192, 640)), "2");
        // on 256x832 at 3/2: 828x251
        let c = input_coverage(&lb(256, 832));
        assert!((c - 828.0 * 251.0 / (832.0 * 256.0)).abs() < 1e-12, "{c}");
        assert_eq!(scale_text(&lb(256, 832)), "3/2");
        // On CamVid's 384x480 input at 8/3: 466x141, under a third of it.
        assert_eq!(scale_text(&lb(384, 480)), "8/3");
        assert!(input_coverage(&lb(384, 480)) < 0.36);
    }
}
