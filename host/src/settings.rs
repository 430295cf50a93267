//! The settings file: every camera, ORB, stereo, tracker, EM, motion and semantic parameter of a
//! run in one TOML file (`semloc run --config FILE`), and an importer for ORB-SLAM2's stereo
//! YAML settings (`--orbslam2-settings FILE`).
//!
//! Precedence: built-in defaults (ORB-SLAM2's KITTI values), then the file, then flags given on
//! the command line. Every section and key may be left out; an unknown key is an error (a
//! misspelt key must not silently fall back to its default). `semloc config --print-defaults`
//! prints the whole file with each key's meaning, unit and default ([`documented_toml`]).
//!
//! ```toml
//! [camera]            # leave out to use the dataset's calibration (KITTI)
//! fx = 718.856        # px
//! fy = 718.856
//! cx = 607.1928
//! cy = 185.2157
//! bf = 386.1448       # px·m (or baseline = 0.537 in m)
//! [orb]
//! n_features = 2000
//! [tracker]
//! association = "em"
//! [tracker.em]
//! iterations = 3
//! [semantics]
//! mode = "motion"
//! model = "models/artefacts/fastscnn_r2_192x640.slm"
//! ```

use std::path::{Path, PathBuf};

use semloc_core::geom::GeomError;
use semloc_core::orb::{OrbConfig, KITTI_MAX_FEATURES};
use semloc_core::stereo::StereoMatching;
use semloc_core::tracker::TrackerParams;
use serde::{Deserialize, Serialize};

use crate::dataset::StereoCalib;
use crate::run::Semantics;

/// Why a settings file could not be used. Every variant names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SettingsError {
    /// The file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML does not parse or has a key or value of the wrong kind.
    #[error("{}: {msg}", path.display())]
    Toml {
        /// The file.
        path: PathBuf,
        /// The parser's message (with line and column).
        msg: String,
    },
    /// A line of an ORB-SLAM2 YAML file that cannot be read.
    #[error("{}:{line}: {msg}", path.display())]
    Yaml {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        msg: String,
    },
    /// A value outside what semloc can use.
    #[error("{}: {key}: {msg}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// The key, `section.key`.
        key: String,
        /// What is wrong.
        msg: String,
    },
}

/// Everything a run can be configured with (see the module docs).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// The rectified stereo camera; `None` uses the dataset's calibration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraSettings>,
    /// ORB extraction (ORB-SLAM2's `ORBextractor.*`).
    pub orb: OrbConfig,
    /// Stereo matching.
    pub stereo: StereoMatching,
    /// Tracking, keyframes, local BA, association, EM (`tracker.em`) and the motion test
    /// (`tracker.motion`).
    pub tracker: TrackerParams,
    /// Semantic weighting and the segmentation network.
    pub semantics: SemanticsSettings,
}

/// A rectified stereo camera (both images share the intrinsics; the right camera is `baseline`
/// to the right of the left one).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSettings {
    /// Focal length along x (px).
    pub fx: f64,
    /// Focal length along y (px).
    pub fy: f64,
    /// Principal point x (px).
    pub cx: f64,
    /// Principal point y (px).
    pub cy: f64,
    /// Baseline (m). Give this or `bf`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline: Option<f64>,
    /// Baseline times fx (px·m; ORB-SLAM2's `Camera.bf`). Give this or `baseline`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bf: Option<f64>,
    /// Image width (px); when given, the images must have it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    /// Image height (px); when given, the images must have it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
}

impl CameraSettings {
    /// The camera as the dataset readers describe one (`bf` turned into a baseline).
    pub fn calib(&self) -> StereoCalib {
        let baseline_m = self.baseline.unwrap_or_else(|| self.bf.unwrap_or(0.0) / self.fx);
        StereoCalib { fx_px: self.fx, fy_px: self.fy, cx_px: self.cx, cy_px: self.cy, baseline_m }
    }
}

/// Semantic settings.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SemanticsSettings {
    /// `off`, `cull`, `full` or `motion` (see `semloc run --help`).
    pub mode: Semantics,
    /// The int8 segmentation network (`.slm`); relative paths are taken from the settings
    /// file's folder.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<PathBuf>,
}

/// What `--print-defaults` shows, commented out, for the keys without a default.
const EXAMPLES: &[(&str, &str)] = &[
    ("camera.fx", "718.856"),
    ("camera.fy", "718.856"),
    ("camera.cx", "607.1928"),
    ("camera.cy", "185.2157"),
    ("camera.baseline", "0.5371657"),
    ("camera.bf", "386.1448"),
    ("camera.width", "1241"),
    ("camera.height", "376"),
    ("semantics.model", "\"models/artefacts/fastscnn_r2_192x640.slm\""),
];

/// Each key's meaning and unit, in the order `--print-defaults` prints them; a test checks
/// that it names exactly the keys [`Settings`] serialises.
pub const KEY_DOCS: &[(&str, &str)] = &[
    ("camera", "The rectified stereo camera. Leave the section out to use the dataset's calibration (KITTI calib.txt / calib_cam_to_cam.txt); required for a generic stereo folder."),
    ("camera.fx", "Focal length along x, px."),
    ("camera.fy", "Focal length along y, px."),
    ("camera.cx", "Principal point x, px."),
    ("camera.cy", "Principal point y, px."),
    ("camera.baseline", "Distance between the camera centres, m. Give this or bf."),
    ("camera.bf", "Baseline times fx, px·m (ORB-SLAM2's Camera.bf). Give this or baseline."),
    ("camera.width", "Image width, px (optional; checked against the images)."),
    ("camera.height", "Image height, px (optional; checked against the images)."),
    ("orb", "ORB extraction, both images (ORB-SLAM2's ORBextractor.*)."),
    ("orb.n_features", "Features per image over all levels (nFeatures), at most 2048."),
    ("orb.scale_factor", "Scale between pyramid levels (scaleFactor), > 1."),
    ("orb.n_levels", "Pyramid levels (nLevels), 1..=16; all levels must fit the extractor's pyramid memory (8 levels at scale 1.2 for frames up to 1920x1200)."),
    ("orb.ini_th_fast", "FAST threshold tried first in each cell (iniThFAST), grey levels."),
    ("orb.min_th_fast", "FAST threshold for cells with no corner at ini_th_fast (minThFAST), grey levels, 1..=ini_th_fast."),
    ("orb.quota_rule", "Features per level: \"orbslam2\" (geometric, ratio 1/scale, as ORB-SLAM2's code) or \"area\" (ratio 1/scale², as the papers describe it)."),
    ("orb.structure_gain", "Semantic ORB (semantics \"full\" and \"motion\"): the Harris weight of construction and object classes against the other static classes, 1..=16 (the paper: 3; 1 weights every static class alike, which makes \"full\" the same as \"cull\")."),
    ("stereo", "Stereo matching along rectified rows (ORB-SLAM2's ComputeStereoMatches)."),
    ("stereo.max_hamming", "Largest descriptor distance of a stereo match, bits (ORB-SLAM2: 75)."),
    ("stereo.sad_half_window", "Half side of the SAD refinement window, px: 5 is an 11x11 window (1..=10)."),
    ("stereo.sad_search", "Half range of the SAD search, level px (2..=32)."),
    ("tracker", "Tracking, keyframes and local bundle adjustment."),
    ("tracker.close_depth_baselines", "Stereo points closer than this many baselines are \"close\" (ORB-SLAM2's ThDepth)."),
    ("tracker.min_new_landmarks", "A new keyframe creates landmarks from all close points and, if fewer, the nearest up to this count."),
    ("tracker.wide_radius_px", "First-pass search radius of the map projection, px at level 0."),
    ("tracker.narrow_radius_px", "Second-pass search radius, px at level 0."),
    ("tracker.max_hamming", "Largest descriptor distance of a map match, bits (ORB-SLAM2's TH_HIGH)."),
    ("tracker.nn_ratio", "Best/second-best distance ratio a match must beat (0..1]."),
    ("tracker.mono_beyond_baselines", "Stereo points farther than this many baselines are used as bearings only (inf: never)."),
    ("tracker.min_inliers", "Fewer pose inliers than this and the frame is lost."),
    ("tracker.keyframe_ratio", "A keyframe when tracked landmarks fall below this share of the reference keyframe's (0..1]."),
    ("tracker.keyframe_max_interval", "A keyframe at least every this many frames."),
    ("tracker.ba_iterations", "Local bundle adjustment iterations per keyframe."),
    ("tracker.ba_keyframes", "Keyframes local BA optimises (the new one and its best covisible ones)."),
    ("tracker.triangulate", "Triangulate new landmarks between covisible keyframes."),
    ("tracker.cull_keyframes", "Remove redundant keyframes (90 % of their points seen by 3 others)."),
    ("tracker.ransac_iterations", "RANSAC hypotheses per frame before pose optimisation (0: off)."),
    ("tracker.ransac_seed", "Varies RANSAC's hypotheses (0: the default); a few seeds show a result's run-to-run spread."),
    ("tracker.association", "Data association: \"hard\" (nearest neighbour, ORB-SLAM2) or \"em\" (probabilistic, Bowman et al. 2017)."),
    ("tracker.em", "EM association (used when association = \"em\")."),
    ("tracker.em.iterations", "E and M steps per frame."),
    ("tracker.em.tau_orb", "ORB distance scale of the likelihood, bits per nat."),
    ("tracker.em.tau_sem", "Semantic descriptor distance scale, bits per nat."),
    ("tracker.em.class_prior", "Dirichlet prior count per class of a landmark's class histogram."),
    ("tracker.em.class_term", "When the class term (how often a landmark was seen with the feature's class) scores candidates: \"always\", \"not-network\" (not with labels from the network, whose errors on KITTI it would follow) or \"never\"."),
    ("tracker.em.max_hamming", "Largest ORB distance of an EM candidate, bits."),
    ("tracker.em.min_weight", "Weights below this leave a pair out of the M-step."),
    ("tracker.em.final_refine", "One last M-step on the kept pairs with outlier rounds."),
    ("tracker.motion", "The motion test of semantics mode \"motion\"."),
    ("tracker.motion.prior_vehicle", "Prior probability that a car, van or truck moves (0..1]; taken within 0.001..=0.999."),
    ("tracker.motion.prior_human", "Prior probability that a pedestrian or cyclist moves (0..1]; taken within 0.001..=0.999."),
    ("tracker.motion.link_px", "Largest image distance between features of one object, px at level 0."),
    ("tracker.motion.link_m", "Largest 3D gap between features of one object, m."),
    ("tracker.motion.min_evidence", "Matched features an object needs before it can be called parked."),
    ("tracker.motion.max_frame_llr", "Largest evidence one frame adds to an object either way, nats."),
    ("tracker.motion.track_px", "Search radius of the frame-to-frame test for objects without landmarks, px at level 0 (0: off)."),
    ("tracker.motion.epipolar", "Match a depthless feature nothing else measured to the previous frame by appearance; off its epipolar line is evidence of motion."),
    ("tracker.motion.camera_height_m", "Height of the left camera above the road, m (level with it; 0: unknown). In the epipolar test a still point of a dynamic class is neither under the road nor higher than 4.5 m (vehicles) or 2.5 m (people)."),
    ("semantics", "Semantic weighting of features."),
    ("tracker.motion.slow_human_mps", "Slowest walking speed the motion test must tell from standing still, m/s (0: off): a pass that a pedestrian or cyclist moving this fast along the road since it was first seen would also make is no evidence that it stands still."),
    ("tracker.motion.slow_vehicle_mps", "The same for cars, vans and trucks (a car creeping in a queue), m/s (0: off)."),
    ("semantics.mode", "\"off\" (geometric), \"cull\" (no features on dynamic classes), \"full\" (the paper: cull dynamic, x3 construction and object classes) or \"motion\" (as full, but dynamic-class features removed only where the object moves)."),
    ("semantics.model", "The int8 segmentation network (.slm); relative to this file's folder. Without one, labels come from the dataset's semantic/ folder."),
];

impl Settings {
    /// Reads and checks a TOML settings file; a relative `semantics.model` is resolved against
    /// the file's folder.
    ///
    /// # Errors
    /// [`SettingsError`] naming the file: unreadable, bad TOML, unknown key, or a value out of
    /// range ([`Settings::check`]).
    pub fn from_toml_file(path: &Path) -> Result<Self, SettingsError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| SettingsError::Io { path: path.to_path_buf(), source })?;
        let mut s = Self::from_toml_str(&text, path)?;
        if let Some(m) = &s.semantics.model {
            if m.is_relative() {
                let dir = path.parent().unwrap_or_else(|| Path::new(""));
                s.semantics.model = Some(dir.join(m));
            }
        }
        Ok(s)
    }

    /// Parses and checks settings TOML; `path` only names the source in errors.
    ///
    /// # Errors
    /// As [`Settings::from_toml_file`], without the I/O.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, SettingsError> {
        let s: Settings = toml::from_str(text).map_err(|e| SettingsError::Toml {
            path: path.to_path_buf(),
            msg: e.to_string().trim_end().replace('\n', " | "),
        })?;
        s.check(path)?;
        Ok(s)
    }

    /// Checks every value against what the pipeline accepts, naming the key.
    ///
    /// # Errors
    /// [`SettingsError::Invalid`] for the first value out of range.
    pub fn check(&self, path: &Path) -> Result<(), SettingsError> {
        let bad = |key: &str, msg: String| {
            Err(SettingsError::Invalid { path: path.to_path_buf(), key: key.into(), msg })
        };
        if let Some(c) = &self.camera {
            let (baseline_key, given, unit) = match (c.baseline, c.bf) {
                (Some(_), Some(_)) => {
                    return bad("camera", "give baseline or bf, not both".into());
                }
                (None, None) => {
                    return bad(
                        "camera",
                        "the baseline is missing: give baseline (m) or bf (px·m)".into(),
                    )
                }
                (Some(b), None) => ("camera.baseline", b, " m"),
                (None, Some(bf)) => ("camera.bf", bf, " px·m"),
            };
            // Core's rule (`StereoCamera::new`): every value finite, the focal lengths and the
            // baseline (given, or bf / fx) > 0.
            if let Err(e) = c.calib().to_camera() {
                let GeomError::InvalidCamera { field } = e else {
                    return bad("camera", e.to_string());
                };
                return match field {
                    "fx_px" => bad("camera.fx", format!("{} must be finite and > 0", c.fx)),
                    "fy_px" => bad("camera.fy", format!("{} must be finite and > 0", c.fy)),
                    "cx_px" => bad("camera.cx", format!("{} must be finite", c.cx)),
                    "cy_px" => bad("camera.cy", format!("{} must be finite", c.cy)),
                    _ if given.is_finite() && given > 0.0 => bad(
                        baseline_key,
                        format!(
                            "{given:e}{unit} over fx {:e} gives a baseline of {} m, which must \
                             be finite and > 0",
                            c.fx,
                            c.calib().baseline_m
                        ),
                    ),
                    _ => bad(baseline_key, format!("{given}{unit} must be finite and > 0")),
                };
            }
            for (k, v) in [("width", c.width), ("height", c.height)] {
                if v == Some(0) {
                    return bad(&format!("camera.{k}"), "must be > 0".into());
                }
            }
        }
        if let Err(e) = self.orb.check(KITTI_MAX_FEATURES) {
            let key = e.config_field().map_or_else(|| "orb".to_owned(), |f| format!("orb.{f}"));
            return bad(&key, e.to_string());
        }
        if let Err(e) = self.stereo.check() {
            return bad("stereo", e.to_string());
        }
        if let Err(e) = self.tracker.check() {
            return bad(&format!("tracker.{}", e.field), format!("{} {}", e.value, e.rule));
        }
        Ok(())
    }

    /// The settings as TOML with every key's documentation above it ([`documented_toml`]).
    pub fn to_documented_toml(&self) -> String {
        documented_toml(self)
    }
}

/// `settings` as TOML, each section and key preceded by its line of [`KEY_DOCS`] and, where the
/// value differs from the default, the default.
pub fn documented_toml(settings: &Settings) -> String {
    let value = toml::Value::try_from(settings).unwrap_or(toml::Value::Table(Default::default()));
    let defaults = toml::Value::try_from(Settings::default()).ok();
    let mut out = String::from(
        "# semloc settings (semloc run --config FILE). Every key may be left out: it then takes\n\
         # the default shown by `semloc config --print-defaults`. Flags given to `semloc run`\n\
         # override this file.\n",
    );
    if let toml::Value::Table(t) = &value {
        write_table(&mut out, "", t, defaults.as_ref());
    }
    out
}

fn lookup<'a>(v: Option<&'a toml::Value>, key: &str) -> Option<&'a toml::Value> {
    key.split('.').try_fold(v?, |v, k| v.get(k))
}

/// A value as TOML, with floats that are exactly an `f32` printed as that `f32` (the ORB and
/// tracker radii are `f32`: `1.2`, not `1.2000000476837158`).
fn fmt_value(v: &toml::Value) -> String {
    match v {
        toml::Value::Float(f) if f.is_finite() && f64::from(*f as f32) == *f => {
            let s = format!("{}", *f as f32);
            if s.contains(['.', 'e']) {
                s
            } else {
                format!("{s}.0")
            }
        }
        other => other.to_string(),
    }
}

/// The keys directly under `prefix` that [`KEY_DOCS`] names, in its order.
fn doc_children(prefix: &str) -> impl Iterator<Item = (&'static str, &'static str)> + '_ {
    KEY_DOCS.iter().copied().filter(move |(k, _)| match k.rsplit_once('.') {
        Some((p, _)) => p == prefix,
        None => prefix.is_empty(),
    })
}

fn write_table(out: &mut String, prefix: &str, t: &toml::Table, defaults: Option<&toml::Value>) {
    let last = |k: &'static str| k.rsplit_once('.').map_or(k, |(_, l)| l);
    let is_table = |k: &str| t.get(k).is_some_and(toml::Value::is_table);
    // Plain keys, in KEY_DOCS order; an optional key that is absent is shown commented out.
    for (key, doc) in doc_children(prefix) {
        let k = last(key);
        if is_table(k) || (t.get(k).is_none() && !EXAMPLES.iter().any(|(e, _)| *e == key)) {
            continue;
        }
        out.push_str(&format!("# {doc}\n"));
        match t.get(k) {
            Some(v) => {
                if let Some(dv) = lookup(defaults, key).filter(|dv| *dv != v) {
                    out.push_str(&format!("# (default: {})\n", fmt_value(dv)));
                }
                out.push_str(&format!("{k} = {}\n", fmt_value(v)));
            }
            None => {
                let ex = EXAMPLES.iter().find(|(e, _)| *e == key).map_or("", |(_, x)| *x);
                out.push_str(&format!("# {k} = {ex}\n"));
            }
        }
    }
    // Sub-tables; the optional camera section is shown commented out when absent.
    for (key, doc) in doc_children(prefix) {
        let k = last(key);
        let absent_camera = t.get(k).is_none() && key == "camera";
        if !(is_table(k) || absent_camera) {
            continue;
        }
        out.push_str(&format!("\n# {doc}\n"));
        match t.get(k) {
            Some(toml::Value::Table(sub)) => {
                out.push_str(&format!("[{key}]\n"));
                write_table(out, key, sub, defaults);
            }
            _ => {
                out.push_str(&format!("# [{key}]\n"));
                for (ck, cdoc) in doc_children(key) {
                    let ex = EXAMPLES.iter().find(|(e, _)| *e == ck).map_or("", |(_, x)| *x);
                    out.push_str(&format!("# {cdoc}\n# {} = {ex}\n", last(ck)));
                }
            }
        }
    }
}

/// What an ORB-SLAM2 settings file gave, and what of it semloc does not use.
#[derive(Debug, Clone, PartialEq)]
pub struct Imported {
    /// The settings (defaults where the file is silent).
    pub settings: Settings,
    /// Keys read and not used (viewer, fps, colour order, ...), and why.
    pub ignored: Vec<String>,
}

/// Reads an ORB-SLAM2 stereo settings file (`KITTI00-02.yaml`, `EuRoC.yaml`, ...): `Camera.fx/
/// fy/cx/cy`, `Camera.bf`, `Camera.width/height` where present, `ThDepth` and
/// `ORBextractor.{nFeatures, scaleFactor, nLevels, iniThFAST, minThFAST}`. The images semloc
/// reads must already be rectified: a file with non-zero `Camera.k1..k3/p1/p2` and no
/// `LEFT.P`/`RIGHT.P` rectification is refused; a file with rectification matrices is read
/// for its rectified camera, with a note that the images must be rectified beforehand.
///
/// # Errors
/// [`SettingsError`] naming the file and line: unreadable, a line that is not `key: value`,
/// a missing camera key, or a value out of range.
pub fn import_orbslam2(path: &Path) -> Result<Imported, SettingsError> {
    let text = std::fs::read_to_string(path)
        .map_err(|source| SettingsError::Io { path: path.to_path_buf(), source })?;
    import_orbslam2_str(&text, path)
}

/// [`import_orbslam2`] of the file's text (`path` names it in errors).
///
/// # Errors
/// As [`import_orbslam2`], without the I/O.
pub fn import_orbslam2_str(text: &str, path: &Path) -> Result<Imported, SettingsError> {
    let entries = parse_opencv_yaml(text, path)?;
    let yaml_err =
        |line: usize, msg: String| SettingsError::Yaml { path: path.to_path_buf(), line, msg };
    let get = |k: &str| entries.iter().find(|e| e.key == k);
    let num = |k: &str| -> Result<Option<f64>, SettingsError> {
        match get(k) {
            None => Ok(None),
            Some(e) => match &e.value {
                YamlValue::Scalar(s) => s
                    .parse::<f64>()
                    .map(Some)
                    .map_err(|_| yaml_err(e.line, format!("{k}: `{s}` is not a number"))),
                YamlValue::Matrix { .. } => {
                    Err(yaml_err(e.line, format!("{k}: a number was expected, not a matrix")))
                }
            },
        }
    };
    let need = |k: &str| -> Result<f64, SettingsError> {
        num(k)?.ok_or_else(|| SettingsError::Invalid {
            path: path.to_path_buf(),
            key: k.into(),
            msg: "missing (semloc needs Camera.fx, fy, cx, cy and bf)".into(),
        })
    };
    let int = |k: &str, lo: f64, hi: f64| -> Result<Option<f64>, SettingsError> {
        match num(k)? {
            Some(v) if v.fract() != 0.0 || v < lo || v > hi => Err(SettingsError::Invalid {
                path: path.to_path_buf(),
                key: k.into(),
                msg: format!("{v} must be a whole number in {lo}..={hi}"),
            }),
            v => Ok(v),
        }
    };
    let mut ignored = Vec::new();
    let rectified = get("LEFT.P").is_some() && get("RIGHT.P").is_some();
    let distortion = ["Camera.k1", "Camera.k2", "Camera.k3", "Camera.p1", "Camera.p2"];
    for k in distortion {
        if let Some(v) = num(k)? {
            if v != 0.0 && !rectified {
                return Err(SettingsError::Invalid {
                    path: path.to_path_buf(),
                    key: k.into(),
                    msg: format!(
                        "{v}: semloc reads rectified images without distortion; rectify the \
                         images first and give the rectified camera"
                    ),
                });
            }
        }
    }
    if rectified {
        ignored.push(
            "LEFT.*/RIGHT.* (ORB-SLAM2 rectifies raw images with them): semloc reads images \
             already rectified; Camera.* is taken as the rectified camera"
                .to_string(),
        );
    }
    let mut s = Settings {
        camera: Some(CameraSettings {
            fx: need("Camera.fx")?,
            fy: need("Camera.fy")?,
            cx: need("Camera.cx")?,
            cy: need("Camera.cy")?,
            baseline: None,
            bf: Some(need("Camera.bf")?),
            width: int("Camera.width", 1.0, 1e6)?.map(|v| v as u32),
            height: int("Camera.height", 1.0, 1e6)?.map(|v| v as u32),
        }),
        ..Settings::default()
    };
    if let Some(v) = num("ThDepth")? {
        s.tracker.close_depth_baselines = v;
    }
    if let Some(v) = int("ORBextractor.nFeatures", 1.0, 1e6)? {
        s.orb.n_features = v as usize;
    }
    if let Some(v) = num("ORBextractor.scaleFactor")? {
        s.orb.scale_factor = v as f32;
    }
    if let Some(v) = int("ORBextractor.nLevels", 1.0, 1e3)? {
        s.orb.n_levels = v as usize;
    }
    if let Some(v) = int("ORBextractor.iniThFAST", 1.0, 255.0)? {
        s.orb.ini_th_fast = v as u8;
    }
    if let Some(v) = int("ORBextractor.minThFAST", 1.0, 255.0)? {
        s.orb.min_th_fast = v as u8;
    }
    const USED: &[&str] = &[
        "Camera.fx",
        "Camera.fy",
        "Camera.cx",
        "Camera.cy",
        "Camera.bf",
        "Camera.width",
        "Camera.height",
        "Camera.k1",
        "Camera.k2",
        "Camera.k3",
        "Camera.p1",
        "Camera.p2",
        "ThDepth",
        "ORBextractor.nFeatures",
        "ORBextractor.scaleFactor",
        "ORBextractor.nLevels",
        "ORBextractor.iniThFAST",
        "ORBextractor.minThFAST",
    ];
    let mut unused: Vec<&str> = entries
        .iter()
        .map(|e| e.key.as_str())
        .filter(|k| {
            !USED.contains(k) && !(rectified && (k.starts_with("LEFT.") || k.starts_with("RIGHT.")))
        })
        .collect();
    unused.dedup();
    if !unused.is_empty() {
        ignored.push(format!("not used by semloc: {}", unused.join(", ")));
    }
    s.check(path)?;
    Ok(Imported { settings: s, ignored })
}

/// One top-level entry of an OpenCV `FileStorage` YAML file.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct YamlEntry {
    /// The key, as written.
    pub(crate) key: String,
    /// 1-based line of the key.
    pub(crate) line: usize,
    /// Its value.
    pub(crate) value: YamlValue,
}

/// The value of a [`YamlEntry`].
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum YamlValue {
    /// Everything after `key:` on its line, quotes removed (a flow list such as
    /// `[752, 480]` stays text: see [`number_list`]).
    Scalar(String),
    /// `!!opencv-matrix`, or a plain indented block with `rows`, `cols` and `data` (EuRoC's
    /// `sensor.yaml`), with its data, row-major.
    Matrix {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
        /// `rows × cols` values, row-major.
        data: Vec<f64>,
    },
}

/// The numbers of a flow list scalar, `[458.654, 457.296, 367.215, 248.375]`.
pub(crate) fn number_list(s: &str) -> Result<Vec<f64>, String> {
    let inner = s
        .trim()
        .strip_prefix('[')
        .and_then(|r| r.strip_suffix(']'))
        .ok_or_else(|| format!("`{s}` is not a [..] list"))?;
    inner
        .split(',')
        .map(str::trim)
        .filter(|t| !t.is_empty())
        .map(|t| match t.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(format!("list value `{t}` is not a finite number")),
        })
        .collect()
}

/// Reads the subset of YAML that OpenCV's `FileStorage` writes, ORB-SLAM2's settings and the
/// EuRoC/ASL `sensor.yaml` files use: an optional `%YAML:1.0` header, `key: value` lines at the
/// left margin, `#` comments, `!!opencv-matrix` blocks (`rows`, `cols`, `dt`, `data: [..]` over
/// one or more lines), and the same block without the tag under a key with no value on its
/// own line (`T_BS:` then indented `cols: 4`, `rows: 4`, `data: [..]`). Flow lists stay scalars
/// ([`number_list`] reads them).
pub(crate) fn parse_opencv_yaml(text: &str, path: &Path) -> Result<Vec<YamlEntry>, SettingsError> {
    let err =
        |line: usize, msg: String| SettingsError::Yaml { path: path.to_path_buf(), line, msg };
    let mut out: Vec<YamlEntry> = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let n = i + 1;
        let raw = lines[i];
        i += 1;
        let line = strip_comment(raw);
        if line.trim().is_empty() || line.starts_with('%') || line.trim() == "---" {
            continue;
        }
        if line.starts_with([' ', '\t']) {
            return Err(err(n, format!("unexpected indented line `{}`", line.trim())));
        }
        let Some((key, value)) = line.split_once(':') else {
            return Err(err(n, format!("`{}` is not `key: value`", line.trim())));
        };
        let (key, value) = (key.trim().to_string(), value.trim());
        if key.is_empty() {
            return Err(err(n, "empty key".into()));
        }
        if out.iter().any(|e| e.key == key) {
            return Err(err(n, format!("{key} is given twice")));
        }
        let block_follows = value.is_empty()
            && lines.get(i).is_some_and(|l| strip_comment(l).starts_with([' ', '\t']));
        let value = if value.starts_with("!!opencv-matrix") || block_follows {
            let mut body = String::new();
            while i < lines.len() {
                let l = strip_comment(lines[i]);
                if !(l.starts_with([' ', '\t']) || l.trim().is_empty()) {
                    break;
                }
                body.push_str(l.trim());
                body.push(' ');
                i += 1;
            }
            parse_matrix(&body).map_err(|m| err(n, format!("{key}: {m}")))?
        } else {
            YamlValue::Scalar(value.trim_matches(['"', '\'']).to_string())
        };
        out.push(YamlEntry { key, line: n, value });
    }
    Ok(out)
}

fn strip_comment(l: &str) -> &str {
    // ORB-SLAM2's files have no quoted `#`.
    l.split_once('#').map_or(l, |(a, _)| a).trim_end()
}

fn parse_matrix(body: &str) -> Result<YamlValue, String> {
    let field = |name: &str| -> Option<&str> {
        let at = body.find(&format!("{name}:"))?;
        Some(body[at + name.len() + 1..].trim_start())
    };
    let whole = |name: &str| -> Result<usize, String> {
        let v = field(name).ok_or(format!("matrix without `{name}`"))?;
        let digits: String = v.chars().take_while(char::is_ascii_digit).collect();
        digits.parse().map_err(|_| format!("matrix `{name}` is not a whole number"))
    };
    let (rows, cols) = (whole("rows")?, whole("cols")?);
    let data = field("data").ok_or("matrix without `data`")?;
    let inner = data
        .strip_prefix('[')
        .and_then(|d| d.split_once(']'))
        .map(|(a, _)| a)
        .ok_or("matrix `data` is not a [..] list")?;
    let data = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<f64>().map_err(|_| format!("matrix value `{s}` is not a number")))
        .collect::<Result<Vec<_>, _>>()?;
    if data.len() != rows * cols {
        return Err(format!("matrix has {} values, rows × cols is {}", data.len(), rows * cols));
    }
    Ok(YamlValue::Matrix { rows, cols, data })
}

#[cfg(test)]
mod tests;
