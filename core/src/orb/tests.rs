//! Extractor-level tests (std is available under `cfg(test)`).
//!
//! Extractors are megabytes, so tests keep them in `static` mutexes (initialised at compile
//! time through the `const fn new`, exactly as firmware would) instead of on a test thread's
//! stack.

use std::string::ToString;
use std::sync::Mutex;
use std::vec::Vec;

use super::*;
use crate::testing::{self, Fnv1a};

/// Extractor for synthetic frames up to 640 × 480.
type TestExt = OrbExtractor<640, { 640 * 480 }, { pyramid_capacity(640, 480, 8) }, 2048, 16384>;

static TEST_EXT: Mutex<TestExt> = Mutex::new(TestExt::new());
static KITTI_EXT: Mutex<KittiOrbExtractor> = Mutex::new(KittiOrbExtractor::new());

fn with_ext<R>(f: impl FnOnce(&mut TestExt) -> R) -> R {
    let mut g = TEST_EXT.lock().unwrap_or_else(|e| e.into_inner());
    f(&mut g)
}

/// Random overlapping rectangles, lightly blurred ([`testing::rect_texture`]).
pub(crate) fn textured(w: usize, h: usize, seed: u32) -> Vec<u8> {
    let mut img = vec![0u8; w * h];
    testing::rect_texture(&mut img, w, h, seed);
    img
}

/// Every output bit of a feature: position, level, angle, response, size, descriptor.
type FeatureBits = (u32, u32, u8, u32, u32, u32, [u8; 32]);

fn bits(f: &Features<2048>) -> Vec<FeatureBits> {
    f.keypoints()
        .iter()
        .zip(f.descriptors())
        .map(|(k, d)| {
            (
                k.x.to_bits(),
                k.y.to_bits(),
                k.level,
                k.angle_deg.to_bits(),
                k.response.to_bits(),
                k.size.to_bits(),
                d.0,
            )
        })
        .collect()
}

#[test]
fn quotas_sum_to_n_features() {
    for rule in [QuotaRule::OrbSlam2, QuotaRule::Area] {
        for (n, s, m) in [
            (2000usize, 1.2f32, 8usize),
            (1000, 1.2, 8),
            (500, 1.5, 4),
            (7, 1.2, 8),
            (1200, 1.1, 12),
        ] {
            let q = level_quotas(n, s, m, rule);
            assert_eq!(q.iter().sum::<usize>(), n, "{rule:?} {n} {s} {m}: {q:?}");
            assert!(q[m..].iter().all(|&x| x == 0));
        }
    }
    let q = OrbConfig::KITTI.level_quotas();
    // ORB-SLAM2 with nFeatures 2000, scale 1.2, 8 levels.
    assert_eq!(&q[..8], &[434, 362, 302, 251, 209, 175, 145, 122]);
    let qa = level_quotas(2000, 1.2, 8, QuotaRule::Area);
    assert_eq!(qa[0], 646);
    assert!(qa[0] > q[0] && qa[7] < q[7]);
}

#[test]
fn extractor_size_is_within_budget() {
    let size = core::mem::size_of::<KittiOrbExtractor>();
    println!(
        "size_of::<KittiOrbExtractor>() = {size} bytes ({:.2} MiB), budget {} bytes",
        size as f64 / (1024.0 * 1024.0),
        KITTI_EXTRACTOR_BUDGET
    );
    assert_eq!(size, KITTI_EXTRACTOR_BYTES);
    assert!(size <= KITTI_EXTRACTOR_BUDGET);
}

#[test]
fn config_check_names_the_field() {
    let k = OrbConfig::KITTI;
    assert_eq!(k.check(2000), Ok(()));
    assert_eq!(k.check(1999), Err(OrbError::BadFeatureCount { requested: 2000, cap: 1999 }));
    let cases: [(OrbConfig, &str); 5] = [
        (OrbConfig { n_features: 0, ..k }, "n_features"),
        (OrbConfig { n_levels: 0, ..k }, "n_levels"),
        (OrbConfig { scale_factor: f32::NAN, ..k }, "scale_factor"),
        (OrbConfig { min_th_fast: 21, ..k }, "min_th_fast"),
        (OrbConfig { structure_gain: 0.0, ..k }, "structure_gain"),
    ];
    for (c, field) in cases {
        let e = c.check(KITTI_MAX_FEATURES).unwrap_err();
        assert_eq!(e.config_field(), Some(field), "{e}");
    }
    // Errors of a frame name no field.
    assert_eq!(OrbError::FrameTooLarge { width: 1, height: 1 }.config_field(), None);
    assert_eq!(OrbError::TooManyCells { need: 1 }.config_field(), None);
    // The messages carry the value given.
    let e = OrbConfig { structure_gain: 17.5, ..k }.check(KITTI_MAX_FEATURES).unwrap_err();
    assert_eq!(e.to_string(), "structure gain 17.5 is outside 1..=16");
    let e = OrbConfig { n_features: 5000, ..k }.check(KITTI_MAX_FEATURES).unwrap_err();
    assert_eq!(e.to_string(), "5000 features requested, 1..=2048 allowed");
}

#[test]
fn config_is_validated() {
    with_ext(|ext| {
        for n in [0, 2049, 5000] {
            assert_eq!(
                ext.configure(OrbConfig { n_features: n, ..OrbConfig::KITTI }),
                Err(OrbError::BadFeatureCount { requested: n, cap: 2048 })
            );
        }
        for sf in [1.0, 0.5, f32::NAN, f32::INFINITY] {
            let e = ext.configure(OrbConfig { scale_factor: sf, ..OrbConfig::KITTI });
            assert!(
                matches!(e, Err(OrbError::BadScaleFactor { value }) if value.to_bits() == sf.to_bits()),
                "{sf}"
            );
        }
        for g in [0.99, 16.01, f32::NAN, f32::INFINITY] {
            let e = ext.configure(OrbConfig { structure_gain: g, ..OrbConfig::KITTI });
            assert!(
                matches!(e, Err(OrbError::BadStructureGain { value }) if value.to_bits() == g.to_bits()),
                "{g}"
            );
        }
        for g in [MIN_STRUCTURE_GAIN, PAPER_STRUCTURE_GAIN, MAX_STRUCTURE_GAIN] {
            ext.configure(OrbConfig { structure_gain: g, ..OrbConfig::KITTI }).unwrap();
        }
        for l in [0, MAX_LEVELS + 1] {
            assert_eq!(
                ext.configure(OrbConfig { n_levels: l, ..OrbConfig::KITTI }),
                Err(OrbError::BadLevelCount { requested: l })
            );
        }
        for (ini, min) in [(20, 30), (20, 0), (0, 0)] {
            assert_eq!(
                ext.configure(OrbConfig { ini_th_fast: ini, min_th_fast: min, ..OrbConfig::KITTI }),
                Err(OrbError::BadThresholds { ini, min })
            );
        }
        ext.configure(OrbConfig { ini_th_fast: 7, min_th_fast: 7, ..OrbConfig::KITTI }).unwrap();
        // A refused configuration leaves the current one in place.
        ext.configure(OrbConfig { n_features: 1000, ..OrbConfig::KITTI }).unwrap();
        assert!(ext
            .configure(OrbConfig { n_features: 1500, n_levels: 0, ..OrbConfig::KITTI })
            .is_err());
        assert_eq!(ext.config().n_features, 1000);
        ext.configure(OrbConfig::KITTI).unwrap();
        let big = vec![0u8; 700 * 10];
        let v = ImageView::from_slice(&big, 700, 10).unwrap();
        assert_eq!(
            ext.extract(&v).unwrap_err(),
            OrbError::FrameTooLarge { width: 700, height: 10 }
        );
    });
}

#[test]
fn flat_image_gives_no_features() {
    with_ext(|ext| {
        ext.configure(OrbConfig::KITTI).unwrap();
        let img = vec![90u8; 320 * 240];
        let v = ImageView::from_slice(&img, 320, 240).unwrap();
        let f = ext.extract(&v).unwrap();
        assert!(f.is_empty());
        assert_eq!(f.stats().n_levels, 8);
        // Every cell fell back to the low threshold and still found nothing.
        let l0 = f.stats().levels()[0];
        assert_eq!(l0.low_threshold_cells, l0.cells);
    });
}

#[test]
fn textured_frame_features_are_consistent() {
    with_ext(|ext| {
        ext.configure(OrbConfig { n_features: 1000, ..OrbConfig::KITTI }).unwrap();
        let (w, h) = (640usize, 480usize);
        let img = textured(w, h, 7);
        let v = ImageView::from_slice(&img, w, h).unwrap();
        ext.extract(&v).unwrap();
        let f = ext.features();
        let quotas = OrbConfig { n_features: 1000, ..OrbConfig::KITTI }.level_quotas();
        assert_eq!(f.keypoints().len(), f.descriptors().len());
        assert!(f.len() >= 900 && f.len() <= 1000 + 3 * 8, "{} features", f.len());
        for (l, s) in f.stats().levels().iter().enumerate() {
            println!("level {l}: {s:?}");
            assert!(usize::from(s.selected) <= quotas[l] + 3);
            assert_eq!(s.selection_overflow, 0);
        }
        let scale: Vec<f32> = (0..8).map(|l| ext.pyramid().info(l).scale).collect();
        for k in f.keypoints() {
            let s = scale[k.level as usize];
            let (lx, ly) = (k.x / s, k.y / s);
            let info = ext.pyramid().info(k.level as usize);
            assert!(lx >= 19.0 - 1e-3 && ly >= 19.0 - 1e-3, "{k:?}");
            assert!(lx < (info.width - 19) as f32 + 1e-3 && ly < (info.height - 19) as f32 + 1e-3);
            assert!((0.0..360.0).contains(&k.angle_deg));
            assert_eq!(k.size, (31.0 * s) as i32 as f32);
        }
        // Grouped by level, increasing.
        assert!(f.keypoints().windows(2).all(|p| p[0].level <= p[1].level));
    });
}

#[test]
fn quadtree_spreads_features_over_the_frame() {
    with_ext(|ext| {
        ext.configure(OrbConfig { n_features: 1000, ..OrbConfig::KITTI }).unwrap();
        let (w, h) = (640usize, 480usize);
        let img = textured(w, h, 99);
        let v = ImageView::from_slice(&img, w, h).unwrap();
        let f = ext.extract(&v).unwrap();
        // Level-0 features over a 4 × 4 grid of the detection area.
        let (x0, x1, y0, y1) = (19.0f32, (w - 19) as f32, 19.0f32, (h - 19) as f32);
        let mut grid = [0usize; 16];
        let mut n = 0;
        for k in f.keypoints().iter().filter(|k| k.level == 0) {
            let gx = (((k.x - x0) / (x1 - x0) * 4.0) as usize).min(3);
            let gy = (((k.y - y0) / (y1 - y0) * 4.0) as usize).min(3);
            grid[gy * 4 + gx] += 1;
            n += 1;
        }
        let share = n as f32 / 16.0;
        println!("level-0 features per 4x4 cell: {grid:?}");
        for &c in &grid {
            assert!((c as f32) <= 1.6 * share && (c as f32) >= 0.4 * share, "{grid:?}");
        }
    });
}

#[test]
fn extraction_is_deterministic() {
    with_ext(|ext| {
        ext.configure(OrbConfig::KITTI).unwrap();
        let a = textured(640, 480, 1);
        let b = textured(600, 400, 2);
        let va = ImageView::from_slice(&a, 640, 480).unwrap();
        let vb = ImageView::from_slice(&b, 600, 400).unwrap();
        let first = bits(ext.extract(&va).unwrap());
        let stats1 = *ext.features().stats();
        ext.extract(&vb).unwrap();
        let again = bits(ext.extract(&va).unwrap());
        assert!(!first.is_empty());
        assert_eq!(first, again);
        assert_eq!(stats1, *ext.features().stats());
    });
}

#[test]
fn zero_weights_remove_features_before_description() {
    with_ext(|ext| {
        ext.configure(OrbConfig::KITTI).unwrap();
        let (w, h) = (640usize, 480usize);
        let img = textured(w, h, 5);
        let v = ImageView::from_slice(&img, w, h).unwrap();
        let weights: Vec<u8> = (0..w * h).map(|i| if i % w < w / 2 { 0 } else { 255 }).collect();
        let wv = ImageView::from_slice(&weights, w, h).unwrap();
        let f = ext.extract_weighted(&v, &wv).unwrap();
        assert!(f.len() > 500);
        assert!(f.keypoints().iter().all(|k| k.x >= (w / 2) as f32), "feature in the zero half");
        let dropped: u32 = f.stats().levels().iter().map(|l| l.weight_dropped).sum();
        assert!(dropped > 0);
        // Half weights only rescale responses: same selection on a uniform map.
        let uni = FnWeights(|_x: f32, _y: f32| 1.0f32);
        let plain = bits(ext.extract_weighted(&v, &uni).unwrap());
        let none = bits(ext.extract(&v).unwrap());
        assert_eq!(plain, none);
    });
}

#[test]
fn descriptors_survive_a_90_degree_rotation() {
    with_ext(|ext| {
        ext.configure(OrbConfig { n_features: 1500, ..OrbConfig::KITTI }).unwrap();
        let n = 400usize;
        let a = textured(n, n, 11);
        let mut b = vec![0u8; n * n];
        testing::rotate_90_cw(&a, &mut b, n);
        let va = ImageView::from_slice(&a, n, n).unwrap();
        let vb = ImageView::from_slice(&b, n, n).unwrap();
        let fa: Vec<(KeyPoint, Descriptor)> = {
            let f = ext.extract(&va).unwrap();
            f.keypoints().iter().copied().zip(f.descriptors().iter().copied()).collect()
        };
        let fb: Vec<(KeyPoint, Descriptor)> = {
            let f = ext.extract(&vb).unwrap();
            f.keypoints().iter().copied().zip(f.descriptors().iter().copied()).collect()
        };
        let mut matched = Vec::new();
        let mut level0 = 0;
        for (ka, da) in fa.iter().filter(|(k, _)| k.level == 0) {
            level0 += 1;
            let (ex, ey) = ((n - 1) as f32 - ka.y, ka.x);
            if let Some((kb, db)) = fb.iter().find(|(k, _)| k.level == 0 && k.x == ex && k.y == ey)
            {
                let mut da_deg = (kb.angle_deg - ka.angle_deg - 90.0).rem_euclid(360.0);
                da_deg = da_deg.min(360.0 - da_deg);
                matched.push((hamming(da, db), da_deg));
            }
        }
        assert!(
            matched.len() * 2 >= level0,
            "{} of {level0} level-0 points re-found",
            matched.len()
        );
        let mut d: Vec<u32> = matched.iter().map(|m| m.0).collect();
        d.sort_unstable();
        let median = d[d.len() / 2];
        let mut unrelated: Vec<u32> =
            fa.iter().zip(fb.iter().rev()).map(|((_, x), (_, y))| hamming(x, y)).collect();
        unrelated.sort_unstable();
        let median_unrelated = unrelated[unrelated.len() / 2];
        println!(
            "90° rotation: {} matched, median Hamming {median}, unrelated {median_unrelated}",
            d.len()
        );
        assert!(median <= 16, "median distance {median}");
        assert!(median_unrelated >= 90);
        assert!(matched.iter().filter(|m| m.1 < 3.0).count() * 10 >= matched.len() * 9);
    });
}

/// Reads a binary PGM (P5, maxval 255).
pub(crate) fn read_pgm(path: &std::path::Path) -> Option<(usize, usize, Vec<u8>)> {
    let bytes = std::fs::read(path).ok()?;
    let mut fields = Vec::new();
    let mut i = 0;
    while fields.len() < 4 && i < bytes.len() {
        while i < bytes.len() && bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        if i < bytes.len() && bytes[i] == b'#' {
            while i < bytes.len() && bytes[i] != b'\n' {
                i += 1;
            }
            continue;
        }
        let s = i;
        while i < bytes.len() && !bytes[i].is_ascii_whitespace() {
            i += 1;
        }
        fields.push(core::str::from_utf8(&bytes[s..i]).ok()?.to_owned());
    }
    if fields.len() < 4 || fields[0] != "P5" || fields[3] != "255" {
        return None;
    }
    let (w, h): (usize, usize) = (fields[1].parse().ok()?, fields[2].parse().ok()?);
    let data = bytes.get(i + 1..i + 1 + w * h)?.to_vec();
    Some((w, h, data))
}

/// The first KITTI raw frame as luma: `$SEMLOC_KITTI_FRAME` (a P5 PGM), or converted once with
/// python3/PIL from the shared data set into the temp dir. `None` when neither is available.
fn kitti_frame() -> Option<(usize, usize, Vec<u8>)> {
    if let Ok(p) = std::env::var("SEMLOC_KITTI_FRAME") {
        return read_pgm(std::path::Path::new(&p));
    }
    // ../shared/data beside the checkout, wherever the checkout is (CI clones elsewhere).
    let png = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(
        "../../shared/data/kitti-raw/2011_09_26/2011_09_26_drive_0005_sync/image_02/data/0000000000.png",
    );
    let png = png.as_path();
    let pgm = std::env::temp_dir().join("semloc_kitti_2011_09_26_0005_0000000000.pgm");
    if !pgm.exists() {
        if !png.exists() {
            return None;
        }
        let script = "import sys; from PIL import Image; Image.open(sys.argv[1]).convert('L').save(sys.argv[2])";
        // SEMLOC_PYTHON: an interpreter with Pillow (CI's oracle venv); default python3.
        let python = std::env::var_os("SEMLOC_PYTHON").unwrap_or_else(|| "python3".into());
        let ok = std::process::Command::new(python)
            .args(["-c", script])
            .arg(png)
            .arg(&pgm)
            .status()
            .map(|s| s.success())
            .unwrap_or(false);
        if !ok {
            return None;
        }
    }
    read_pgm(&pgm)
}

#[test]
fn real_kitti_frame() {
    let Some((w, h, img)) = kitti_frame() else {
        println!("skipped: no KITTI frame (set SEMLOC_KITTI_FRAME to a P5 PGM)");
        return;
    };
    let mut ext = KITTI_EXT.lock().unwrap_or_else(|e| e.into_inner());
    ext.configure(OrbConfig::KITTI).unwrap();
    let v = ImageView::from_slice(&img, w, h).unwrap();
    let t = std::time::Instant::now();
    let f = ext.extract(&v).unwrap();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    println!("KITTI {w}x{h}: {} features in {ms:.1} ms (test profile)", f.len());
    for (l, s) in f.stats().levels().iter().enumerate() {
        println!(
            "  level {l}: {}x{} quota {} corners {} low-th cells {}/{} candidates {} dropped {} selected {}",
            s.width, s.height, s.quota, s.fast_corners, s.low_threshold_cells, s.cells, s.candidates,
            s.candidates_dropped, s.selected
        );
    }
    assert!(f.len() >= 1900 && f.len() <= 2000 + 24, "{} features", f.len());
    assert_eq!(f.stats().output_dropped, 0);
}

/// FNV-1a over every output bit of an extraction: key point fields, descriptors and counters.
fn fnv1a_features(f: &Features<2048>) -> u64 {
    let mut h = Fnv1a::new();
    let mut eat = |bytes: &[u8]| h.eat(bytes);
    eat(&(f.len() as u64).to_le_bytes());
    for (k, d) in f.keypoints().iter().zip(f.descriptors()) {
        eat(&k.x.to_bits().to_le_bytes());
        eat(&k.y.to_bits().to_le_bytes());
        eat(&[k.level]);
        eat(&k.angle_deg.to_bits().to_le_bytes());
        eat(&k.response.to_bits().to_le_bytes());
        eat(&k.size.to_bits().to_le_bytes());
        eat(&d.0);
    }
    let s = f.stats();
    eat(&[s.n_levels]);
    eat(&s.output_dropped.to_le_bytes());
    for l in s.levels() {
        for v in [l.width, l.height, l.quota, l.cells, l.low_threshold_cells, l.selected] {
            eat(&v.to_le_bytes());
        }
        eat(&l.selection_overflow.to_le_bytes());
        for v in [l.fast_corners, l.weight_dropped, l.candidates_dropped, l.candidates] {
            eat(&v.to_le_bytes());
        }
    }
    h.finish()
}

/// Uniform 8-bit noise: a corner at almost every pixel, so candidate storage overflows.
fn noise_frame(w: usize, h: usize, seed: u32) -> Vec<u8> {
    let mut img = vec![0u8; w * h];
    testing::noise(&mut img, seed | 1);
    img
}

/// Name, configuration, width, height, pixels, weighted, expected hash.
type GoldenCase = (&'static str, OrbConfig, usize, usize, Vec<u8>, bool, u64);

/// Golden hashes of the extraction output, pinned from the reference implementation: any
/// optimisation must leave every key point and descriptor bit-identical. A changed hash means a
/// behaviour change, not a test to update. Checked on every kernel level this CPU has: the
/// x86-64-v3 build of the kernels ([`crate::arch`]) and the baseline code.
#[test]
fn golden_output_is_unchanged() {
    crate::nn::dispatch::for_each_level(|level| {
        println!("kernel level {level}: x86-64-v3 kernels {}", crate::arch::v3_active());
        golden_output_at_this_level();
    });
}

fn golden_output_at_this_level() {
    let cases: Vec<GoldenCase> = vec![
        (
            "textured 640x480 #7",
            OrbConfig::KITTI,
            640,
            480,
            textured(640, 480, 7),
            false,
            0x9205faadfb517f1c,
        ),
        (
            "textured 601x397 #3, 1000 area",
            OrbConfig { n_features: 1000, quota_rule: QuotaRule::Area, ..OrbConfig::KITTI },
            601,
            397,
            textured(601, 397, 3),
            false,
            0xc54d8aec9db96dcf,
        ),
        (
            "textured 333x217 #9, 1.3x6 t30/10",
            OrbConfig {
                n_features: 700,
                scale_factor: 1.3,
                n_levels: 6,
                ini_th_fast: 30,
                min_th_fast: 10,
                ..OrbConfig::KITTI
            },
            333,
            217,
            textured(333, 217, 9),
            false,
            0x9f38f43aedafbad5,
        ),
        (
            "noise 640x480",
            OrbConfig::KITTI,
            640,
            480,
            noise_frame(640, 480, 77),
            false,
            0x369112557e0ac120,
        ),
        (
            "textured 640x480 #5 weighted",
            OrbConfig::KITTI,
            640,
            480,
            textured(640, 480, 5),
            true,
            0xd333920f542f5d66,
        ),
    ];
    let mut got = Vec::new();
    with_ext(|ext| {
        for (name, cfg, w, h, img, weighted, _) in &cases {
            ext.configure(*cfg).unwrap();
            let v = ImageView::from_slice(img, *w, *h).unwrap();
            let f = if *weighted {
                let wm = FnWeights(|x: f32, y: f32| {
                    if x < 200.0 {
                        0.0
                    } else {
                        0.25 + ((x as u32 * 7 + y as u32 * 3) % 16) as f32 / 16.0
                    }
                });
                ext.extract_weighted(&v, &wm).unwrap()
            } else {
                ext.extract(&v).unwrap()
            };
            let hash = fnv1a_features(f);
            let dropped: u32 = f.stats().levels().iter().map(|l| l.candidates_dropped).sum();
            println!(
                "{name}: {} features, {dropped} candidates dropped, hash {hash:#018x}",
                f.len()
            );
            got.push(hash);
        }
    });
    let expect: Vec<u64> = cases.iter().map(|c| c.6).collect();
    assert_eq!(got, expect);

    if let Some((w, h, img)) = kitti_frame() {
        let mut ext = KITTI_EXT.lock().unwrap_or_else(|e| e.into_inner());
        ext.configure(OrbConfig::KITTI).unwrap();
        let v = ImageView::from_slice(&img, w, h).unwrap();
        let hash = fnv1a_features(ext.extract(&v).unwrap());
        println!("KITTI {w}x{h}: hash {hash:#018x}");
        assert_eq!(hash, 0x37d755df075230e8);
        // The same frame shifted into a wider, odd-sized crop exercises other level sizes.
        let (cw, ch) = (1111usize, 333usize);
        let crop: Vec<u8> = (0..cw * ch).map(|i| img[(i / cw + 20) * w + i % cw + 61]).collect();
        let cv = ImageView::from_slice(&crop, cw, ch).unwrap();
        let hash = fnv1a_features(ext.extract(&cv).unwrap());
        println!("KITTI crop {cw}x{ch}: hash {hash:#018x}");
        assert_eq!(hash, 0x8cfc129b3bf2a290);
    } else {
        println!("KITTI frame unavailable: real-frame golden hash skipped");
    }
}
