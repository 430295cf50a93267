//! Unit tests of the generator's pieces.

use super::*;

#[test]
fn kitti_numbers_have_two_digit_signed_exponents() {
    assert_eq!(kitti_num(718.856, 12), "7.188560000000e+02");
    assert_eq!(kitti_num(0.0, 6), "0.000000e+00");
    assert_eq!(kitti_num(-0.001, 3), "-1.000e-03");
}

#[test]
fn noise_and_line_coverage_stay_in_range_and_fade_to_their_mean() {
    for k in 0..2000 {
        let (x, y) = (k as f32 * 0.37 - 300.0, k as f32 * 0.11 + 17.0);
        let n = texture::vnoise(x, y, k);
        assert!((0.0..=1.0).contains(&n));
        let f = texture::fbm(x, y, 0.5, 4, 0.001, 3);
        assert!((-1.0..=1.0).contains(&f));
        let c = texture::lines(x, 0.5, 0.05, 0.01);
        assert!((0.0..=1.0).contains(&c));
    }
    // A footprint wider than half a period: the mean coverage, no flicker.
    assert!((texture::lines(0.123, 0.24, 0.012, 0.2) - 0.05).abs() < 1e-6);
    assert_eq!(texture::lod(10.0, 1.0), 0.0);
    assert_eq!(texture::lod(0.1, 0.01), 1.0);
    assert_eq!(texture::ifloor(-0.5), -1);
    assert_eq!(texture::ifloor(2.0), 2);
}

#[test]
fn poses_start_at_identity_and_stay_rotations() {
    let sc = Scene::new(&SynthConfig { frames: 50, ..Default::default() }).unwrap();
    let p0 = sc.pose_row(0);
    let id = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    for (a, b) in p0.iter().zip(id) {
        assert!((a - b).abs() < 1e-12);
    }
    for k in 0..50 {
        let m = sc.pose_row(k);
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|l| m[i * 4 + l] * m[j * 4 + l]).sum();
                assert!((d - if i == j { 1.0 } else { 0.0 }).abs() < 1e-9);
            }
        }
    }
    // 5–12 m/s at 10 Hz.
    let len = sc.path_length_m();
    assert!(len > 49.0 * 0.5 && len < 49.0 * 1.2, "{len}");
}

#[test]
fn ground_is_covered_without_holes_and_rendering_is_repeatable() {
    let cfg = SynthConfig { frames: 1, dynamics: Dynamics::High, seed: 9, ..Default::default() };
    let sc = Scene::new(&cfg).unwrap();
    let a = sc.render(0);
    // Below the horizon (ground nearer than ~30 m) no pixel may see the sky: adjacent road
    // strips and faces share edges exactly.
    let w = WIDTH as usize;
    let first = (CY + 40.0) as usize;
    for (i, &c) in a.labels.as_raw().iter().enumerate().skip(first * w) {
        assert_ne!(c, class::SKY, "sky at ({}, {})", i % w, i / w);
    }
    assert!(a.depth_m.iter().all(|z| *z > 0.0));
    let b = sc.render(0);
    assert_eq!(a.left.as_bytes(), b.left.as_bytes());
    assert_eq!(a.right.as_bytes(), b.right.as_bytes());
    assert_ne!(a.left.as_bytes(), a.right.as_bytes());
}

#[test]
fn zero_frames_and_bad_sequence_names_are_errors_naming_the_folder() {
    let dir = std::path::Path::new("/nonexistent/synth");
    let e = generate(dir, &SynthConfig { frames: 0, ..Default::default() }).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/synth"), "{e}");
    let e = generate(dir, &SynthConfig { seq: "a/b".into(), ..Default::default() }).unwrap_err();
    assert!(e.to_string().contains("not a folder name"), "{e}");
}

/// Stage timings of one thread (run with `--release -- --ignored --nocapture`).
#[test]
#[ignore]
fn time_stages() {
    use std::time::Instant;
    let cfg = SynthConfig { frames: 30, dynamics: Dynamics::High, seed: 1, ..Default::default() };
    let sc = Scene::new(&cfg).unwrap();
    let mut ws = Workspace::new();
    let (mut t_r, mut t_s, mut t_all, mut t_png) = (0.0, 0.0, 0.0, 0.0);
    let mut buf = Vec::new();
    for k in 0..cfg.frames {
        let s = sc.ego.s[k];
        let mut dynp = Vec::new();
        scene::agent_prims(&sc.agents, &sc.world.path, &sc.ego, k, &mut dynp);
        let list: Vec<&Prim> =
            sc.world.prims[sc.world.range(s - 20.0, s + 230.0)].iter().chain(dynp.iter()).collect();
        let cam = sc.cam(k, false);
        let t0 = Instant::now();
        ws.gbuf.render(&cam, &list);
        let t1 = Instant::now();
        for j in 0..HEIGHT as usize {
            ws.gbuf.shade(&cam, &list, j..j + 1, &mut ws.row, &material::sky);
        }
        let t2 = Instant::now();
        t_r += (t1 - t0).as_secs_f64();
        t_s += (t2 - t1).as_secs_f64();
        if k == 0 {
            println!("prims {}", list.len());
        }
        let t3 = Instant::now();
        let fr = sc.render_into(k, &mut ws, false);
        let t4 = Instant::now();
        t_all += (t4 - t3).as_secs_f64();
        let p = std::env::temp_dir().join("synth_time_stage.png");
        encode_png(&p, fr.left.as_bytes(), ExtendedColorType::L8, &mut buf).unwrap();
        encode_png(&p, fr.right.as_bytes(), ExtendedColorType::L8, &mut buf).unwrap();
        encode_png(&p, fr.labels.as_raw(), ExtendedColorType::L8, &mut buf).unwrap();
        encode_png(&p, fr.dynamic.as_raw(), ExtendedColorType::L8, &mut buf).unwrap();
        t_png += t4.elapsed().as_secs_f64();
    }
    let n = cfg.frames as f64 * 1e-3;
    println!(
        "per frame (ms): raster(1 cam) {:.1} shade(1 cam) {:.1} render_into {:.1} png(4) {:.1}",
        t_r / n,
        t_s / n,
        t_all / n,
        t_png / n
    );
}
