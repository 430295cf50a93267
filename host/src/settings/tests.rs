use std::path::Path;

use super::*;

const P: &str = "rig.toml";

fn parse(text: &str) -> Result<Settings, SettingsError> {
    Settings::from_toml_str(text, Path::new(P))
}

/// Every key a full settings value serialises to, `section.key`, tables included.
fn keys(v: &toml::Value, prefix: &str, out: &mut Vec<String>) {
    if let toml::Value::Table(t) = v {
        for (k, v) in t {
            let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
            out.push(key.clone());
            keys(v, &key, out);
        }
    }
}

fn full() -> Settings {
    Settings {
        camera: Some(CameraSettings {
            fx: 700.0,
            fy: 701.0,
            cx: 600.0,
            cy: 180.0,
            baseline: Some(0.5),
            bf: Some(350.0),
            width: Some(1240),
            height: Some(376),
        }),
        semantics: SemanticsSettings { mode: Semantics::Motion, model: Some("net.slm".into()) },
        ..Settings::default()
    }
}

#[test]
fn every_key_is_documented_and_every_documented_key_exists() {
    let mut got = Vec::new();
    keys(&toml::Value::try_from(full()).unwrap(), "", &mut got);
    got.sort();
    let mut documented: Vec<String> = KEY_DOCS.iter().map(|(k, _)| k.to_string()).collect();
    documented.sort();
    assert_eq!(got, documented);
}

/// The ranges `KEY_DOCS` writes as literals are core's: a change to a bound in core shows
/// here rather than as documentation that promises the old range.
#[test]
fn documented_ranges_are_the_checked_ranges() {
    use semloc_core::orb::{
        MAX_LEVELS, MAX_STRUCTURE_GAIN, MIN_STRUCTURE_GAIN, PAPER_STRUCTURE_GAIN,
    };
    use semloc_core::stereo::{MAX_SAD_HALF_WINDOW, MAX_SAD_SEARCH};
    let doc = |key: &str| KEY_DOCS.iter().find(|(k, _)| *k == key).map(|(_, d)| *d).unwrap();
    let expect = [
        ("orb.n_features", format!("at most {KITTI_MAX_FEATURES}")),
        ("orb.n_levels", format!("1..={MAX_LEVELS}")),
        ("orb.structure_gain", format!("{MIN_STRUCTURE_GAIN}..={MAX_STRUCTURE_GAIN}")),
        ("orb.structure_gain", format!("the paper: {PAPER_STRUCTURE_GAIN}")),
        ("stereo.sad_half_window", format!("(1..={MAX_SAD_HALF_WINDOW})")),
        ("stereo.sad_search", format!("(2..={MAX_SAD_SEARCH})")),
    ];
    for (key, text) in &expect {
        assert!(doc(key).contains(text.as_str()), "{key}: {text:?} not in {:?}", doc(key));
    }
    // The ends the documentation gives are accepted, one past them refused.
    let s = Settings::default();
    for (n, ok) in
        [(1, true), (KITTI_MAX_FEATURES, true), (0, false), (KITTI_MAX_FEATURES + 1, false)]
    {
        let mut t = s.clone();
        t.orb.n_features = n;
        assert_eq!(t.check(Path::new(P)).is_ok(), ok, "n_features {n}");
    }
    for (n, ok) in [(1, true), (MAX_LEVELS, true), (0, false), (MAX_LEVELS + 1, false)] {
        let mut t = s.clone();
        t.orb.n_levels = n;
        assert_eq!(t.check(Path::new(P)).is_ok(), ok, "n_levels {n}");
    }
    for (g, ok) in
        [(MIN_STRUCTURE_GAIN, true), (MAX_STRUCTURE_GAIN, true), (0.99, false), (16.01, false)]
    {
        let mut t = s.clone();
        t.orb.structure_gain = g;
        assert_eq!(t.check(Path::new(P)).is_ok(), ok, "structure_gain {g}");
    }
    // The tracker's ratios and priors: "(0..1]" as `TrackerParams::check` has it.
    type Field = fn(&mut Settings) -> &mut f32;
    let ratios: [(&str, Field); 4] = [
        ("tracker.nn_ratio", |s| &mut s.tracker.nn_ratio),
        ("tracker.keyframe_ratio", |s| &mut s.tracker.keyframe_ratio),
        ("tracker.motion.prior_vehicle", |s| &mut s.tracker.motion.prior_vehicle),
        ("tracker.motion.prior_human", |s| &mut s.tracker.motion.prior_human),
    ];
    for (key, field) in ratios {
        assert!(doc(key).contains("(0..1]"), "{key}: {:?}", doc(key));
        for (v, ok) in [(1.0, true), (1e-6, true), (0.0, false), (1.0 + 1e-6, false)] {
            let mut t = s.clone();
            *field(&mut t) = v;
            assert_eq!(t.check(Path::new(P)).is_ok(), ok, "{key} {v}");
        }
    }
    for (w, l, ok) in [
        (1, 2, true),
        (MAX_SAD_HALF_WINDOW, MAX_SAD_SEARCH, true),
        (0, 2, false),
        (MAX_SAD_HALF_WINDOW + 1, 2, false),
        (1, 1, false),
        (1, MAX_SAD_SEARCH + 1, false),
    ] {
        let mut t = s.clone();
        t.stereo.sad_half_window = w;
        t.stereo.sad_search = l;
        assert_eq!(t.check(Path::new(P)).is_ok(), ok, "sad {w} {l}");
    }
}

#[test]
fn printed_defaults_parse_back_to_the_defaults_and_document_each_key() {
    let text = documented_toml(&Settings::default());
    assert_eq!(parse(&text).unwrap(), Settings::default());
    for (k, doc) in KEY_DOCS {
        assert!(text.contains(doc), "{k} undocumented in\n{text}");
    }
    assert!(text.contains("scale_factor = 1.2\n") && text.contains("# [camera]\n# "), "{text}");
    // Uncommenting the examples gives a valid file.
    let uncommented: String = text
        .lines()
        .map(|l| match l.strip_prefix("# ") {
            Some(r)
                if r.starts_with('[')
                    || r.split_once(" = ").is_some_and(|(k, _)| {
                        !k.is_empty() && k.chars().all(|c| c.is_ascii_lowercase() || c == '_')
                    }) =>
            {
                r
            }
            _ => l,
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let s = parse(&uncommented.replace("baseline = 0.5371657\n", "")).unwrap();
    assert_eq!(s.camera.unwrap().bf, Some(386.1448));
    assert!(text.contains("[tracker.em]") && text.contains("n_features = 2000"), "{text}");
    // The full form (with a camera) parses back too, and notes values that differ.
    let mut s = full();
    s.camera.as_mut().unwrap().bf = None;
    let text = documented_toml(&s);
    assert_eq!(parse(&text).unwrap(), s);
    assert!(text.contains("# (default: \"off\")\nmode = \"motion\""), "{text}");
}

#[test]
fn a_partial_file_changes_only_what_it_names() {
    let s = parse(
        "[orb]\nn_features = 1200\n[tracker]\nassociation = \"em\"\n[tracker.em]\niterations = 5\n",
    )
    .unwrap();
    let mut want = Settings::default();
    want.orb.n_features = 1200;
    want.tracker.association = semloc_core::assoc::Association::Em;
    want.tracker.em.iterations = 5;
    assert_eq!(s, want);
    assert_eq!(parse("").unwrap(), Settings::default());
    // infinity is a valid "never" for the mono threshold
    let s = parse("[tracker]\nmono_beyond_baselines = inf\n").unwrap();
    assert!(s.tracker.mono_beyond_baselines.is_infinite());
}

#[test]
fn unknown_keys_and_wrong_types_name_the_file_and_the_key() {
    let e = parse("[orb]\nn_feature = 1200\n").unwrap_err().to_string();
    assert!(e.starts_with("rig.toml: ") && e.contains("n_feature"), "{e}");
    let e = parse("[tracker]\nassociation = \"fuzzy\"\n").unwrap_err().to_string();
    assert!(e.contains("rig.toml") && e.contains("fuzzy"), "{e}");
    let e = parse("[orbs]\n").unwrap_err().to_string();
    assert!(e.contains("orbs"), "{e}");
    let e = parse("[orb]\nn_features = \"many\"\n").unwrap_err().to_string();
    assert!(e.contains("line 2"), "{e}");
}

#[test]
fn out_of_range_values_are_refused_with_their_key() {
    for (text, key) in [
        ("[orb]\nn_features = 5000\n", "orb.n_features"),
        ("[orb]\nn_levels = 17\n", "orb.n_levels"),
        ("[orb]\nscale_factor = 1.0\n", "orb.scale_factor"),
        ("[orb]\nmin_th_fast = 30\n", "orb.min_th_fast"),
        ("[orb]\nstructure_gain = 0.5\n", "orb.structure_gain"),
        ("[orb]\nstructure_gain = 17.0\n", "orb.structure_gain"),
        ("[orb]\nstructure_gain = nan\n", "orb.structure_gain"),
        ("[stereo]\nsad_half_window = 11\n", "stereo"),
        ("[tracker]\nnn_ratio = 1.5\n", "tracker.nn_ratio"),
        ("[tracker]\nwide_radius_px = nan\n", "tracker.wide_radius_px"),
        ("[tracker.em]\ntau_orb = -1.0\n", "tracker.em.tau_orb"),
        ("[tracker.motion]\nprior_vehicle = 0.0\n", "tracker.motion.prior_vehicle"),
        ("[tracker.motion]\ntrack_px = -1.0\n", "tracker.motion.track_px"),
        ("[tracker.motion]\ncamera_height_m = -1.65\n", "tracker.motion.camera_height_m"),
        ("[camera]\nfx = 1.0\nfy = 1.0\ncx = 1.0\ncy = 1.0\n", "camera"),
        ("[camera]\nfx = 1.0\nfy = 1.0\ncx = 1.0\ncy = 1.0\nbf = 1.0\nbaseline = 1.0\n", "camera"),
        ("[camera]\nfx = -1.0\nfy = 1.0\ncx = 1.0\ncy = 1.0\nbf = 1.0\n", "camera.fx"),
        ("[camera]\nfx = 1.0\nfy = 1.0\ncx = 1.0\ncy = 1.0\nbaseline = 0.0\n", "camera.baseline"),
        ("[camera]\nfx = 1.0\nfy = 0.0\ncx = 1.0\ncy = 1.0\nbf = 1.0\n", "camera.fy"),
        ("[camera]\nfx = 1.0\nfy = 1.0\ncx = nan\ncy = 1.0\nbf = 1.0\n", "camera.cx"),
        ("[camera]\nfx = 1.0\nfy = 1.0\ncx = 1.0\ncy = inf\nbf = 1.0\n", "camera.cy"),
        ("[camera]\nfx = 1.0\nfy = 1.0\ncx = 1.0\ncy = 1.0\nbf = -386.0\n", "camera.bf"),
        ("[camera]\nfx = 1e-10\nfy = 1.0\ncx = 1.0\ncy = 1.0\nbf = 1e308\n", "camera.bf"),
    ] {
        match parse(text) {
            Err(SettingsError::Invalid { key: k, path, .. }) => {
                assert_eq!((k.as_str(), path.as_path()), (key, Path::new(P)), "{text}")
            }
            other => panic!("{text}: {other:?}"),
        }
    }
    // The camera is checked by core's `StereoCamera::new`; the message keeps the value given.
    let e = parse("[camera]\nfx = 1.0\nfy = 1.0\ncx = 1.0\ncy = 1.0\nbf = -386.0\n");
    let e = e.unwrap_err().to_string();
    assert!(e.contains("camera.bf") && e.contains("-386 px·m must be finite and > 0"), "{e}");
    let e = parse("[camera]\nfx = 1e-10\nfy = 1.0\ncx = 1.0\ncy = 1.0\nbf = 1e308\n");
    let e = e.unwrap_err().to_string();
    assert!(e.contains("camera.bf: 1e308 px·m over fx 1e-10 gives a baseline of inf m"), "{e}");
    // A principal point need only be finite.
    let s = parse("[camera]\nfx = 1.0\nfy = 1.0\ncx = -5.0\ncy = 0.0\nbaseline = 0.5\n").unwrap();
    assert_eq!(s.camera.unwrap().cx, -5.0);
    // The ORB keys are checked by core's `OrbConfig::check`; the message keeps the value.
    let e = parse("[orb]\nstructure_gain = 17.0\n").unwrap_err().to_string();
    assert!(e.contains("rig.toml") && e.contains("orb.structure_gain") && e.contains("17"), "{e}");
    let e = parse("[orb]\nn_features = 0\n").unwrap_err().to_string();
    assert!(e.contains("orb.n_features") && e.contains("1..=2048"), "{e}");
}

#[test]
fn camera_bf_becomes_a_baseline_and_model_paths_follow_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("rig.toml");
    std::fs::write(
        &f,
        "[camera]\nfx = 718.856\nfy = 718.856\ncx = 607.1928\ncy = 185.2157\nbf = 386.1448\n\
         [semantics]\nmode = \"full\"\nmodel = \"nets/a.slm\"\n",
    )
    .unwrap();
    let s = Settings::from_toml_file(&f).unwrap();
    let c = s.camera.unwrap().calib();
    assert!((c.baseline_m - 386.1448 / 718.856).abs() < 1e-12);
    assert_eq!(s.semantics.model.unwrap(), dir.path().join("nets/a.slm"));
    assert_eq!(s.semantics.mode, Semantics::Full);
    let e = Settings::from_toml_file(&dir.path().join("missing.toml")).unwrap_err();
    assert!(e.to_string().contains("missing.toml"), "{e}");
}

/// ORB-SLAM2's `Examples/Stereo/KITTI00-02.yaml`, as its users carry it.
const KITTI_YAML: &str = "%YAML:1.0

#--------------------------------------------------------------------------------------------
# Camera Parameters. Adjust them!
#--------------------------------------------------------------------------------------------

# Camera calibration and distortion parameters (OpenCV)
Camera.fx: 718.856
Camera.fy: 718.856
Camera.cx: 607.1928
Camera.cy: 185.2157

Camera.k1: 0.0
Camera.k2: 0.0
Camera.p1: 0.0
Camera.p2: 0.0

Camera.width: 1241
Camera.height: 376

# Camera frames per second
Camera.fps: 10.0

# stereo baseline times fx
Camera.bf: 386.1448

# Color order of the images (0: BGR, 1: RGB. It is ignored if images are grayscale)
Camera.RGB: 1

# Close/Far threshold. Baseline times.
ThDepth: 35

ORBextractor.nFeatures: 2000
ORBextractor.scaleFactor: 1.2
ORBextractor.nLevels: 8
ORBextractor.iniThFAST: 20
ORBextractor.minThFAST: 7

Viewer.KeyFrameSize: 0.6
Viewer.PointSize:2
Viewer.ViewpointF: 2000
";

#[test]
fn orbslam2_kitti_settings_import_to_the_built_in_kitti_defaults() {
    let imp = import_orbslam2_str(KITTI_YAML, Path::new("KITTI00-02.yaml")).unwrap();
    let s = &imp.settings;
    let c = s.camera.unwrap();
    assert_eq!(
        (c.fx, c.fy, c.cx, c.cy, c.bf),
        (718.856, 718.856, 607.1928, 185.2157, Some(386.1448))
    );
    assert_eq!((c.width, c.height), (Some(1241), Some(376)));
    let defaults = Settings::default();
    assert_eq!(s.orb, defaults.orb);
    assert_eq!(s.tracker, defaults.tracker);
    let ignored = imp.ignored.join("; ");
    for k in ["Camera.fps", "Camera.RGB", "Viewer.PointSize"] {
        assert!(ignored.contains(k), "{ignored}");
    }
    // What it converts to is a valid settings file that reads back the same.
    let text = documented_toml(s);
    assert_eq!(parse(&text).unwrap(), *s);
}

#[test]
fn orbslam2_euroc_settings_with_rectification_matrices_give_the_rectified_camera() {
    let yaml = "%YAML:1.0\nCamera.type: \"PinHole\"\nCamera.fx: 435.2046959714599\n\
        Camera.fy: 435.2046959714599\nCamera.cx: 367.4517211914062\nCamera.cy: 252.2008514404297\n\
        Camera.k1: 0.0\nCamera.width: 752\nCamera.height: 480\nCamera.bf: 47.90639384423901\n\
        ThDepth: 35.0\nLEFT.D: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n\
        \x20  data:[-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05, 0.0]\n\
        LEFT.P:  !!opencv-matrix\n   rows: 3\n   cols: 4\n   dt: d\n   data: [435.2, 0, 367.4, 0,\n\
        \x20     0, 435.2, 252.2, 0,  0, 0, 1, 0]\n\
        RIGHT.P:  !!opencv-matrix\n   rows: 3\n   cols: 4\n   dt: d\n\
        \x20  data: [435.2, 0, 367.4, -47.9, 0, 435.2, 252.2, 0, 0, 0, 1, 0]\n\
        ORBextractor.nFeatures: 1200\n";
    let imp = import_orbslam2_str(yaml, Path::new("EuRoC.yaml")).unwrap();
    assert_eq!(imp.settings.orb.n_features, 1200);
    assert_eq!(imp.settings.camera.unwrap().width, Some(752));
    let ignored = imp.ignored.join("; ");
    assert!(ignored.contains("rectified") && ignored.contains("Camera.type"), "{ignored}");
}

#[test]
fn orbslam2_files_semloc_cannot_use_are_refused_with_file_and_line() {
    let p = Path::new("s.yaml");
    let distorted = KITTI_YAML.replace("Camera.k1: 0.0", "Camera.k1: -0.28");
    let e = import_orbslam2_str(&distorted, p).unwrap_err().to_string();
    assert!(e.contains("s.yaml") && e.contains("Camera.k1") && e.contains("rectif"), "{e}");
    let no_bf = KITTI_YAML.replace("Camera.bf: 386.1448", "");
    let e = import_orbslam2_str(&no_bf, p).unwrap_err().to_string();
    assert!(e.contains("Camera.bf") && e.contains("missing"), "{e}");
    let e = import_orbslam2_str("%YAML:1.0\nCamera.fx 718\n", p).unwrap_err().to_string();
    assert!(e.starts_with("s.yaml:2: "), "{e}");
    let e = import_orbslam2_str("Camera.fx: seven\n", p).unwrap_err().to_string();
    assert!(e.starts_with("s.yaml:1: ") && e.contains("seven"), "{e}");
    let e = import_orbslam2_str("Camera.fx: 1\nCamera.fx: 2\n", p).unwrap_err().to_string();
    assert!(e.contains("twice"), "{e}");
    let bad_matrix = "LEFT.P: !!opencv-matrix\n  rows: 3\n  cols: 4\n  data: [1, 2]\n";
    let e = import_orbslam2_str(bad_matrix, p).unwrap_err().to_string();
    assert!(e.starts_with("s.yaml:1: ") && e.contains("2 values"), "{e}");
    let many = KITTI_YAML.replace("ORBextractor.nFeatures: 2000", "ORBextractor.nFeatures: 3000");
    let e = import_orbslam2_str(&many, p).unwrap_err().to_string();
    assert!(e.contains("orb.n_features"), "{e}");
    let e = import_orbslam2(Path::new("/nonexistent/x.yaml")).unwrap_err().to_string();
    assert!(e.contains("/nonexistent/x.yaml"), "{e}");
}
