//! Mutation fuzzing of the host's text parsers — odometry `calib.txt`, `times.txt` and
//! `poses/XX.txt`; raw `calib_*.txt`, `timestamps.txt` and oxts packets; KITTI and TUM
//! trajectories — for a bounded time, seeded (a proptest-style harness; cargo fuzz covers
//! core in `tests/fuzz`). Every mutated input must give `Ok` or an error whose message names
//! the file; a panic fails the test and prints the input that caused it.
//!
//! `SEMLOC_FUZZ_SECS` sets the time per target (default 2 s; CI runs 30 s each);
//! `SEMLOC_FUZZ_SEED` the seed (default 1, so a failure reproduces).

use core::time::Duration;
use std::path::{Path, PathBuf};
use std::time::Instant;

use semloc::dataset::Sequence;
// A seeded xorshift: the harness must be reproducible from its seed.
use semloc_core::testing::Rng;

/// Tokens that break number and line parsers in interesting ways.
const TOKENS: &[&str] = &[
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e999",
    "-1e999",
    "-0",
    "0x1f",
    "1.2.3",
    "",
    ":",
    "::",
    "\n",
    "\r\n",
    " ",
    "\t",
    "e",
    "+",
    "-",
    "99999999999999999999999",
    "P0:",
    "R:",
    "T:",
    "\u{feff}",
    "é",
    "2011-09-26 25:61:61.9999999999",
    "1970-01-01 00:00:00.0",
    "0",
    "1e-320",
];

/// One random mutation of `s` (byte flip, deletion, duplication, token insertion, truncation,
/// line shuffle).
fn mutate(rng: &mut Rng, s: &str) -> String {
    let mut b = s.as_bytes().to_vec();
    for _ in 0..1 + rng.below(3) {
        let n = b.len();
        match rng.below(7) {
            0 if n > 0 => {
                let i = rng.below(n);
                b[i] ^= 1 << rng.below(8);
            }
            1 if n > 0 => {
                let i = rng.below(n);
                let j = (i + 1 + rng.below(12)).min(n);
                b.drain(i..j);
            }
            2 if n > 0 => {
                let i = rng.below(n);
                let j = (i + 1 + rng.below(40)).min(n);
                let part = b[i..j].to_vec();
                let at = rng.below(n + 1);
                b.splice(at..at, part);
            }
            3 => {
                let at = rng.below(n + 1);
                let t = TOKENS[rng.below(TOKENS.len())].as_bytes();
                b.splice(at..at, t.iter().copied());
            }
            4 => b.truncate(rng.below(n + 1)),
            5 => {
                let text = String::from_utf8_lossy(&b).into_owned();
                let mut lines: Vec<&str> = text.lines().collect();
                if lines.len() > 1 {
                    let (i, j) = (rng.below(lines.len()), rng.below(lines.len()));
                    lines.swap(i, j);
                }
                b = lines.join("\n").into_bytes();
            }
            _ => {
                // replace one whitespace-separated number by a token
                let text = String::from_utf8_lossy(&b).into_owned();
                let words: Vec<&str> = text.split(' ').collect();
                let k = rng.below(words.len());
                let t = TOKENS[rng.below(TOKENS.len())];
                b = words
                    .iter()
                    .enumerate()
                    .map(|(i, w)| if i == k { t } else { w })
                    .collect::<Vec<_>>()
                    .join(" ")
                    .into_bytes();
            }
        }
    }
    // Mostly valid UTF-8 (the parsers read text); sometimes raw bytes, as a broken file has.
    String::from_utf8(b.clone()).unwrap_or_else(|_| String::from_utf8_lossy(&b).into_owned())
}

fn budget() -> Duration {
    let s = std::env::var("SEMLOC_FUZZ_SECS").ok().and_then(|v| v.parse::<f64>().ok());
    Duration::from_secs_f64(s.unwrap_or(2.0))
}

fn seed() -> u64 {
    std::env::var("SEMLOC_FUZZ_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(1)
}

/// Runs `case` on mutations of `seeds` until the time budget is spent; returns how many ran.
/// A panic is reported with the input and the seed, then fails the test.
fn fuzz(name: &str, seeds: &[&str], mut case: impl FnMut(&str, usize)) -> usize {
    let mut rng = Rng::new(seed().wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    let (t0, limit) = (Instant::now(), budget());
    let mut n = 0;
    while t0.elapsed() < limit {
        let which = rng.below(seeds.len());
        let input = if n < seeds.len() {
            seeds[n].to_owned() // the unmutated seeds first: they must parse
        } else {
            mutate(&mut rng, seeds[which])
        };
        let r = std::panic::catch_unwind(core::panic::AssertUnwindSafe(|| case(&input, which)));
        if r.is_err() {
            panic!("{name}: panic on case {n} (SEMLOC_FUZZ_SEED={}), input:\n{input:?}", seed());
        }
        n += 1;
    }
    eprintln!("{name}: {n} inputs in {:.1} s", t0.elapsed().as_secs_f64());
    n
}

const P0: &str = "7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 0.000000000000e+00 \
                  0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 \
                  0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00";
const P1: &str = "7.188560000000e+02 0.000000000000e+00 6.071928000000e+02 -3.861448000000e+02 \
                  0.000000000000e+00 7.188560000000e+02 1.852157000000e+02 0.000000000000e+00 \
                  0.000000000000e+00 0.000000000000e+00 1.000000000000e+00 0.000000000000e+00";
const POSES: &str = "1 0 0 0 0 1 0 0 0 0 1 0\n\
                     9.999978e-01 5.272628e-04 -2.066935e-03 -4.690294e-02 -5.296506e-04 \
                     9.999992e-01 -1.154865e-03 -2.839928e-02 2.066324e-03 1.155958e-03 \
                     9.999971e-01 8.586941e-01\n";
const OXTS: &str = "49.011212804408 8.4228850417969 112.83492279053 0.022447 1e-05 \
                    -1.2219096732051 -3.3256321640686 1.1384311814592 3.5147680214713 \
                    0.037625160413037 -0.03878884255623 -0.29437452763793 0.037166856911681 \
                    9.9957015129717 -0.30581030960531 -0.19635662515203 9.9942128010936 \
                    -0.017332142869546 0.024792163815438 0.14511808479348 -0.017498934149631 \
                    0.021393359392165 0.14563031426063 0.49229361157748 0.068883960397178 4 10 \
                    4 4 0";
const STAMPS: &str = "2011-09-26 13:04:32.349659964\n2011-09-26 13:04:32.459792166\n";
const CAM_TO_CAM: &str = "calib_time: 09-Jan-2012 13:57:47\n\
    S_rect_02: 8.000000e+00 4.000000e+00\n\
    R_rect_00: 1 0 0 0 1 0 0 0 1\n\
    P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 \
    1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03\n\
    P_rect_03: 7.215377e+02 0.000000e+00 6.095593e+02 -3.395242e+02 0.000000e+00 7.215377e+02 \
    1.728540e+02 2.199936e+00 0.000000e+00 0.000000e+00 1.000000e+00 2.729905e-03\n";
const IMU_TO_VELO: &str = "calib_time: 25-May-2012 16:47:16\n\
    R: 9.999976e-01 7.553071e-04 -2.035826e-03 -7.854027e-04 9.998898e-01 -1.482298e-02 \
    2.024406e-03 1.482454e-02 9.998881e-01\nT: -8.086759e-01 3.195559e-01 -7.997231e-01\n";
const VELO_TO_CAM: &str = "calib_time: 15-Mar-2012 11:37:16\n\
    R: 7.533745e-03 -9.999714e-01 -6.166020e-04 1.480249e-02 7.280733e-04 -9.998902e-01 \
    9.998621e-01 7.523790e-03 1.480755e-02\nT: -4.069766e-03 -7.631618e-02 -2.717806e-01\n\
    delta_f: 0.000000e+00 0.000000e+00\ndelta_c: 0.000000e+00 0.000000e+00\n";

fn png(path: &Path) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::GrayImage::from_fn(8, 4, |x, y| image::Luma([(x * 31 + y * 7) as u8]))
        .save(path)
        .unwrap();
}

/// Every error must name a file under the test's folder.
fn names_a_file(err: &dyn core::fmt::Display, root: &Path, input: &str) {
    let msg = err.to_string();
    assert!(
        msg.contains(&*root.to_string_lossy()),
        "error does not name the file: {msg:?}\ninput: {input:?}"
    );
}

#[test]
fn odometry_calib_times_and_poses_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let seq = root.join("sequences").join("00");
    for cam in ["image_0", "image_1"] {
        for i in 0..2 {
            png(&seq.join(cam).join(format!("{i:06}.png")));
        }
    }
    std::fs::create_dir_all(root.join("poses")).unwrap();
    let calib = format!("P0: {P0}\nP1: {P1}\nP2: {P0}\nP3: {P1}\n");
    let files: [(PathBuf, String); 3] = [
        (seq.join("calib.txt"), calib),
        (seq.join("times.txt"), "0.000000e+00\n1.036000e-01\n".into()),
        (root.join("poses").join("00.txt"), POSES.into()),
    ];
    let seeds: Vec<&str> = files.iter().map(|(_, s)| s.as_str()).collect();
    let (mut ok, mut err) = (0, 0);
    let n = fuzz("odometry", &seeds, |input, which| {
        for (k, (p, s)) in files.iter().enumerate() {
            std::fs::write(p, if k == which { input } else { s }).unwrap();
        }
        match Sequence::open_odometry(root, "00", None) {
            Ok(s) => {
                ok += 1;
                assert_eq!(s.len(), 2);
            }
            Err(e) => {
                err += 1;
                names_a_file(&e, root, input);
            }
        }
    });
    assert!(n >= 3 && ok >= 3 && err > 0, "{n} cases, {ok} ok, {err} errors");
}

#[test]
fn raw_calib_timestamps_and_oxts_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let date = dir.path().join("2011_09_26");
    let drive = date.join("2011_09_26_drive_0001_sync");
    for cam in ["image_02", "image_03"] {
        for i in 0..2 {
            png(&drive.join(cam).join("data").join(format!("{i:010}.png")));
        }
    }
    std::fs::create_dir_all(drive.join("oxts").join("data")).unwrap();
    let files: [(PathBuf, String); 7] = [
        (date.join("calib_cam_to_cam.txt"), CAM_TO_CAM.into()),
        (date.join("calib_imu_to_velo.txt"), IMU_TO_VELO.into()),
        (date.join("calib_velo_to_cam.txt"), VELO_TO_CAM.into()),
        (drive.join("image_02").join("timestamps.txt"), STAMPS.into()),
        (drive.join("oxts").join("data").join("0000000000.txt"), OXTS.into()),
        (drive.join("oxts").join("data").join("0000000001.txt"), OXTS.replace("8.42", "8.43")),
        (drive.join("oxts").join("timestamps.txt"), STAMPS.into()),
    ];
    let seeds: Vec<&str> = files.iter().map(|(_, s)| s.as_str()).collect();
    let (mut ok, mut err) = (0, 0);
    let n = fuzz("raw", &seeds, |input, which| {
        for (k, (p, s)) in files.iter().enumerate() {
            std::fs::write(p, if k == which { input } else { s }).unwrap();
        }
        match Sequence::open_raw(dir.path(), "2011_09_26_0001", None) {
            Ok(s) => {
                ok += 1;
                assert_eq!(s.len(), 2);
                // A bad oxts record ends the ground truth there, with the problem named.
                if let Some(e) = &s.gt_problem {
                    names_a_file(e, dir.path(), input);
                } else {
                    assert_eq!(s.gt.as_ref().map(Vec::len), Some(2), "oxts ground truth");
                }
                let gt = s.gt.as_deref().unwrap_or(&[]);
                assert!(gt.iter().all(|p| p.trans.iter().all(|v| v.is_finite())));
            }
            Err(e) => {
                err += 1;
                names_a_file(&e, dir.path(), input);
            }
        }
    });
    assert!(n >= 7 && ok >= 7 && err > 0, "{n} cases, {ok} ok, {err} errors");
}

#[test]
fn trajectory_and_packet_parsers_never_panic() {
    let path = Path::new("/fuzz/input.txt");
    let tum = "1.0 0 0 0 0 0 0 1\n1.1 0.1 0 0.5 0 0 0.0499792 0.9987503\n";
    let seeds = [POSES, tum, OXTS, STAMPS];
    let n = fuzz("text parsers", &seeds, |input, _| {
        let check = |r: Result<(), String>| {
            if let Err(msg) = r {
                assert!(msg.contains("/fuzz/input.txt"), "{msg:?}\ninput: {input:?}");
            }
        };
        check(semloc::traj::parse_kitti(input, path).map(|_| ()).map_err(|e| e.to_string()));
        check(semloc::traj::parse_tum(input, path).map(|_| ()).map_err(|e| e.to_string()));
        check(semloc::traj::detect_format_of(input, path).map(|_| ()).map_err(|e| e.to_string()));
        check(
            semloc::dataset::oxts::parse_packet(path, input)
                .map(|p| {
                    let _ = semloc::dataset::oxts::pose_from_packet(&p, 0.66);
                })
                .map_err(|e| e.to_string()),
        );
        for (i, line) in input.lines().enumerate() {
            check(
                semloc::dataset::raw::parse_timestamp(path, i + 1, line)
                    .map(|_| ())
                    .map_err(|e| e.to_string()),
            );
        }
    });
    assert!(n >= 4);
}
