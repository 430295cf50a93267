//! Synthetic rectified pairs: the right image is the left one shifted by a known disparity
//! per row band, so every match has an exact expected `u_R`. Extractors are megabytes, so
//! they live in a `static` (built by their `const fn new`, as on the target).

use std::boxed::Box;
use std::sync::Mutex;
use std::vec::Vec;

use super::*;
use crate::orb::{pyramid_capacity, OrbConfig, OrbExtractor};
use crate::testing;

const W: usize = 640;
const H: usize = 240;
const PYR: usize = pyramid_capacity(W, H, 8);
type TestExt = OrbExtractor<W, { W * H }, PYR, 2048, 16384>;
type TestMatcher = StereoMatcher<2048, 256, { 2048 * 16 }>;

static EXTS: Mutex<(TestExt, TestExt)> = Mutex::new((TestExt::new(), TestExt::new()));

/// fx = 500 px, baseline 0.5 m.
const PARAMS: StereoParams = StereoParams::new(250.0, 0.5);

/// Value noise on 9- and 4-px grids under random rectangles, blurred
/// ([`testing::value_noise_texture`]): unique texture everywhere and corners at every scale.
/// `(left, right)` with `right(x, y) = left(x + d(y), y)`.
fn pair(seed: u32, d: impl Fn(usize) -> usize) -> (Vec<u8>, Vec<u8>) {
    let tw = W + 64;
    let mut t = vec![0u8; tw * H];
    testing::value_noise_texture(&mut t, tw, H, seed, &[9, 4]);
    let (mut l, mut r) = (vec![0u8; W * H], vec![0u8; W * H]);
    testing::stereo_pair(&t, tw, &mut l, &mut r, W, d);
    (l, r)
}

fn run<const K: usize, const R: usize, const E: usize>(
    matcher: &mut StereoMatcher<K, R, E>,
    left: &[u8],
    right: &[u8],
    params: &StereoParams,
    out: &mut Frame,
) -> Result<StereoStats, StereoError> {
    let mut g = EXTS.lock().unwrap_or_else(|e| e.into_inner());
    let (el, er) = &mut *g;
    el.configure(OrbConfig::KITTI).unwrap();
    er.configure(OrbConfig::KITTI).unwrap();
    el.extract(&ImageView::from_slice(left, W, H).unwrap()).unwrap();
    er.extract(&ImageView::from_slice(right, W, H).unwrap()).unwrap();
    matcher.match_frame(el.features(), el.pyramid(), er.features(), er.pyramid(), params, 1.5, out)
}

fn check_stats(s: &StereoStats, out: &Frame) {
    assert_eq!(out.features.len() as u32, s.left);
    assert_eq!(out.stereo_count() as u32, s.matched);
    assert_eq!(
        s.descriptor_matched,
        s.matched
            + s.rejected_window
            + s.rejected_sad_border
            + s.rejected_parabola
            + s.rejected_disparity
            + s.rejected_median,
        "{s:?}"
    );
}

/// `u_R` errors of the matches against `x − d(y)`, skipping rows within `margin(level)` of
/// a disparity change; also checks depth = bf / disparity.
fn ur_errors(out: &Frame, d: impl Fn(f32) -> Option<f32>) -> Vec<f32> {
    let mut errs = Vec::new();
    for f in out.features.iter().filter(|f| f.is_stereo()) {
        let Some(dd) = d(f.y) else { continue };
        let disp = f.x - f.ur;
        assert!((f.depth_m - PARAMS.bf_px_m / disp).abs() <= 1e-4 * f.depth_m);
        errs.push((f.ur - (f.x - dd)).abs());
    }
    errs.sort_by(f32::total_cmp);
    errs
}

fn pct(v: &[f32], p: f32) -> f32 {
    v[((v.len() - 1) as f32 * p) as usize]
}

#[test]
fn constant_disparity_gives_bf_over_d() {
    let (l, r) = pair(7, |_| 20);
    let mut m = Box::new(TestMatcher::new());
    let mut out = Box::new(Frame::new());
    let s = run(&mut m, &l, &r, &PARAMS, &mut out).unwrap();
    check_stats(&s, &out);
    assert_eq!(out.timestamp_s, 1.5);
    let errs = ur_errors(&out, |_| Some(20.0));
    let rate = s.matched as f32 / s.left as f32;
    std::println!(
        "d=20: {s:?}\n  rate {rate:.3}, |ur err| median {:.3} p90 {:.3} max {:.3}",
        pct(&errs, 0.5),
        pct(&errs, 0.9),
        pct(&errs, 1.0)
    );
    for level in 0..8u8 {
        let on = out.features.iter().filter(|f| f.level == level);
        let n = on.clone().count();
        let k = on.filter(|f| f.is_stereo()).count();
        std::println!("  level {level}: {k}/{n}");
    }
    assert!(s.left > 500, "{s:?}");
    assert!(rate > 0.55, "match rate {rate}");
    assert!(pct(&errs, 0.5) < 0.2, "median |ur error| {}", pct(&errs, 0.5));
    assert!(pct(&errs, 0.9) < 1.0, "p90 |ur error| {}", pct(&errs, 0.9));
    let depths: Vec<f32> =
        out.features.iter().filter(|f| f.is_stereo()).map(|f| f.depth_m).collect();
    let mut depths = depths;
    depths.sort_by(f32::total_cmp);
    assert!((pct(&depths, 0.5) - 12.5).abs() < 0.15, "median depth {}", pct(&depths, 0.5));
    assert_eq!(s.row_overflow, 0);
}

#[test]
fn two_planes_get_two_depths() {
    let split = H / 2;
    let (l, r) = pair(11, |y| if y < split { 10 } else { 30 });
    let mut m = Box::new(TestMatcher::new());
    let mut out = Box::new(Frame::new());
    let s = run(&mut m, &l, &r, &PARAMS, &mut out).unwrap();
    check_stats(&s, &out);
    // Away from the seam (SAD windows span ±5 level rows, ≤ ±18 level-0 rows on level 7).
    let d = |y: f32| {
        if y < split as f32 - 20.0 {
            Some(10.0)
        } else if y > split as f32 + 20.0 {
            Some(30.0)
        } else {
            None
        }
    };
    let errs = ur_errors(&out, d);
    let rate = s.matched as f32 / s.left as f32;
    std::println!(
        "two planes: {s:?}\n  rate {rate:.3}, |ur err| median {:.3} p90 {:.3}",
        pct(&errs, 0.5),
        pct(&errs, 0.9)
    );
    assert!(rate > 0.4, "match rate {rate}");
    assert!(pct(&errs, 0.5) < 0.2, "median |ur error| {}", pct(&errs, 0.5));
    for (lo, hi, z) in
        [(0.0, split as f32 - 20.0, 25.0f32), (split as f32 + 20.0, H as f32, 250.0 / 30.0)]
    {
        let mut zs: Vec<f32> = out
            .features
            .iter()
            .filter(|f| f.is_stereo() && f.y >= lo && f.y < hi)
            .map(|f| f.depth_m)
            .collect();
        zs.sort_by(f32::total_cmp);
        assert!(zs.len() > 100, "{} matches in [{lo}, {hi})", zs.len());
        assert!((pct(&zs, 0.5) - z).abs() < 0.02 * z, "median depth {} vs {z}", pct(&zs, 0.5));
    }
}

#[test]
fn unrelated_right_image_matches_little() {
    let (l, _) = pair(3, |_| 20);
    let (r, _) = pair(99, |_| 20);
    let mut m = Box::new(TestMatcher::new());
    let mut out = Box::new(Frame::new());
    let s = run(&mut m, &l, &r, &PARAMS, &mut out).unwrap();
    check_stats(&s, &out);
    std::println!("unrelated: {s:?}");
    // Chance descriptor matches survive only rarely, and with large SAD distances: under
    // 10 % of the key points (a true pair matches 60 %), median SAD ≥ 5× a true pair's.
    assert!(s.matched * 10 < s.left, "{s:?}");
    let mut m2 = Box::new(TestMatcher::new());
    let t = run(&mut m2, &l, &pair(3, |_| 20).1, &PARAMS, &mut out).unwrap();
    assert!(s.matched * 5 < t.matched, "{s:?} vs {t:?}");
    assert!(s.median_sad > 5 * t.median_sad, "{s:?} vs {t:?}");
}

#[test]
fn deterministic() {
    let (l, r) = pair(5, |y| 12 + y / 16);
    let bits = |f: &Frame| -> Vec<(u32, u32, u32, u32)> {
        f.features
            .iter()
            .map(|f| (f.x.to_bits(), f.angle.to_bits(), f.ur.to_bits(), f.depth_m.to_bits()))
            .collect()
    };
    let mut m = Box::new(TestMatcher::new());
    let mut a = Box::new(Frame::new());
    let sa = run(&mut m, &l, &r, &PARAMS, &mut a).unwrap();
    // Same matcher again (stale state must not leak), then a fresh one.
    let mut b = Box::new(Frame::new());
    let sb = run(&mut m, &l, &r, &PARAMS, &mut b).unwrap();
    let mut m2 = Box::new(TestMatcher::new());
    let mut c = Box::new(Frame::new());
    let sc = run(&mut m2, &l, &r, &PARAMS, &mut c).unwrap();
    assert_eq!(sa, sb);
    assert_eq!(sa, sc);
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(bits(&a), bits(&c));
    assert!(sa.matched > 0);
}

#[test]
fn row_overflow_is_counted_not_fatal() {
    let (l, r) = pair(7, |_| 20);
    let mut m = Box::new(StereoMatcher::<2048, 256, 500>::new());
    let mut out = Box::new(Frame::new());
    let s = run(&mut m, &l, &r, &PARAMS, &mut out).unwrap();
    check_stats(&s, &out);
    std::println!("overflow: {s:?}");
    assert!(s.row_overflow > 0);
    // Only the top rows were indexed: no match below them.
    assert!(s.matched > 0);
    let max_y = out.features.iter().filter(|f| f.is_stereo()).map(|f| f.y).fold(0.0, f32::max);
    assert!(max_y < H as f32 / 2.0, "{max_y}");
    let mut full = Box::new(TestMatcher::new());
    let sf = run(&mut full, &l, &r, &PARAMS, &mut out).unwrap();
    assert!(sf.matched > s.matched);
}

#[test]
fn bad_inputs_are_errors() {
    let (l, r) = pair(7, |_| 20);
    let mut m = Box::new(TestMatcher::new());
    let mut out = Box::new(Frame::new());
    for (bf, b) in [(f32::NAN, 0.5), (250.0, 0.0), (-1.0, 0.5), (250.0, f32::INFINITY)] {
        let p = StereoParams::new(bf, b);
        let e = run(&mut m, &l, &r, &p, &mut out).unwrap_err();
        assert!(matches!(e, StereoError::BadCalibration { .. }), "{e:?}");
        assert!(out.features.is_empty());
    }
    for (w, ls) in [(0, 5), (MAX_SAD_HALF_WINDOW + 1, 5), (5, 1), (5, MAX_SAD_SEARCH + 1)] {
        let p = StereoParams { sad_half_window: w, sad_search: ls, ..PARAMS };
        let e = run(&mut m, &l, &r, &p, &mut out).unwrap_err();
        assert_eq!(e, StereoError::BadWindow { half_window: w, search: ls });
    }
    let mut short = Box::new(StereoMatcher::<2048, 100, 4096>::new());
    let e = run(&mut short, &l, &r, &PARAMS, &mut out).unwrap_err();
    assert_eq!(e, StereoError::TooManyRows { rows: H, cap: 100 });
    let mut few = Box::new(StereoMatcher::<16, 256, 4096>::new());
    let e = run(&mut few, &l, &r, &PARAMS, &mut out).unwrap_err();
    assert!(matches!(e, StereoError::TooManyKeypoints { cap: 16, .. }), "{e:?}");

    // Pyramids that disagree.
    let g = EXTS.lock().unwrap_or_else(|e| e.into_inner());
    let (el, _) = &*g;
    let img = ImageView::from_slice(&l, W, H).unwrap();
    let mut p4 = Box::new(Pyramid::<W, PYR>::new());
    p4.build(&img, 1.2, 4).unwrap();
    let e = m
        .match_frame(el.features(), el.pyramid(), el.features(), &p4, &PARAMS, 0.0, &mut out)
        .unwrap_err();
    assert_eq!(e, StereoError::LevelCountMismatch { left: 8, right: 4 });
    let small = ImageView::from_slice(&l[..W * 200], W, 200).unwrap();
    p4.build(&small, 1.2, 8).unwrap();
    let e = m
        .match_frame(el.features(), el.pyramid(), el.features(), &p4, &PARAMS, 0.0, &mut out)
        .unwrap_err();
    assert_eq!(e, StereoError::SizeMismatch { level: 0 });
    let empty = Box::new(Pyramid::<W, PYR>::new());
    let e = m
        .match_frame(el.features(), &empty, el.features(), &empty, &PARAMS, 0.0, &mut out)
        .unwrap_err();
    assert_eq!(e, StereoError::EmptyPyramid);
    for e in [
        StereoError::EmptyPyramid,
        StereoError::BadCalibration { bf_px_m: 0.0, baseline_m: 0.0 },
        StereoError::TooManyRows { rows: 1, cap: 0 },
    ] {
        assert!(!std::format!("{e}").is_empty());
    }
}

#[test]
fn parabola_and_median_rules() {
    assert_eq!(parabola_offset(10.0, 0.0, 10.0), Some(0.0));
    let d = parabola_offset(30.0, 10.0, 20.0).unwrap();
    assert!((d - 10.0 / 60.0).abs() < 1e-6);
    assert_eq!(parabola_offset(10.0, 10.0, 10.0), None); // 0/0
    assert_eq!(parabola_offset(100.0, 0.0, -90.0), None); // |Δ| > 1

    let mut m = [(5u32, 0u16), (100, 1), (4, 2), (6, 3), (13, 4)];
    let (median, rej) = median_reject(&mut m);
    assert_eq!(median, 6);
    assert_eq!(rej, &[(13, 4), (100, 1)]); // > 12.6
    let mut z = [(0u32, 0u16), (0, 1), (0, 2), (7, 3)];
    let (median, rej) = median_reject(&mut z);
    assert_eq!((median, rej), (0, &[(7u32, 3u16)][..]));
    assert_eq!(median_reject(&mut []).1.len(), 0);
}

#[test]
fn row_spans_follow_level_scale_and_clamp() {
    let mut pyr = Box::new(Pyramid::<W, PYR>::new());
    let px = vec![0u8; W * H];
    pyr.build(&ImageView::from_slice(&px, W, H).unwrap(), 1.2, 8).unwrap();
    let kp = |y: f32, level: u8| KeyPoint { x: 100.0, y, level, ..KeyPoint::default() };
    assert_eq!(row_span(&kp(50.0, 0), &pyr, H), Some((48, 52)));
    assert_eq!(row_span(&kp(50.5, 0), &pyr, H), Some((48, 53)));
    // Level 7: r = 2·1.2⁷ ≈ 7.17 → 16 rows.
    assert_eq!(row_span(&kp(50.5, 7), &pyr, H), Some((43, 58)));
    assert_eq!(row_span(&kp(1.0, 1), &pyr, H), Some((0, 4)));
    assert_eq!(row_span(&kp(H as f32 - 1.0, 0), &pyr, H), Some((H - 3, H - 1)));
    assert_eq!(row_span(&kp(-10.0, 0), &pyr, H), None);
    assert_eq!(row_span(&kp(f32::NAN, 0), &pyr, H), None);
    assert_eq!(row_span(&kp(1e30, 0), &pyr, H), None);
    assert_eq!(row_span(&kp(50.0, 8), &pyr, H), None);
}

#[test]
fn sad_window_outside_the_image_is_rejected() {
    let (l, r) = pair(7, |_| 20);
    let mut pl = Box::new(Pyramid::<W, PYR>::new());
    let mut pr = Box::new(Pyramid::<W, PYR>::new());
    pl.build(&ImageView::from_slice(&l, W, H).unwrap(), 1.2, 8).unwrap();
    pr.build(&ImageView::from_slice(&r, W, H).unwrap(), 1.2, 8).unwrap();
    let (il, ir, info) = (pl.level(0), pr.level(0), pl.info(0));
    let refine = |u: f32, v: f32, ur: f32| {
        sad_refine(&il, &ir, &info, u, v, ur, 5, 5, &mut [0; SAD_ROWS_BYTES])
    };
    assert_eq!(refine(100.0, 3.0, 80.0), Err(Reject::Window));
    assert_eq!(refine(100.0, H as f32 - 3.0, 80.0), Err(Reject::Window));
    assert_eq!(refine(30.0, 100.0, 8.0), Err(Reject::Window));
    assert_eq!(refine(f32::NAN, 100.0, 80.0), Err(Reject::Window));
    assert_eq!(refine(1e30, -1e30, 80.0), Err(Reject::Window));
    assert_eq!(refine(W as f32 - 3.0, 100.0, W as f32 - 8.0), Err(Reject::Window));
    // The true match refines to 80 ± 0.5 px.
    let (ur, _) = refine(100.0, 100.0, 81.0).unwrap();
    assert!((ur - 80.0).abs() <= 0.5, "{ur}");
}

#[test]
fn sad_refine_equals_the_per_shift_definition() {
    // The refinement accumulates all shifts at once; the definition sums each shift's window
    // in turn. Random positions, windows and search ranges on three pyramid levels, at every
    // instruction-set level: same best distance, same refined u_R bits, same rejections.
    let (l, r) = pair(11, |y| 12 + y % 9);
    let mut pl = Box::new(Pyramid::<W, PYR>::new());
    let mut pr = Box::new(Pyramid::<W, PYR>::new());
    pl.build(&ImageView::from_slice(&l, W, H).unwrap(), 1.2, 8).unwrap();
    pr.build(&ImageView::from_slice(&r, W, H).unwrap(), 1.2, 8).unwrap();
    let definition = |lv: usize, u_l: f32, v_l: f32, u_r0: f32, hw: usize, search: i32| {
        let (il, ir, info) = (pl.level(lv), pr.level(lv), pl.info(lv));
        let (w, big_l) = (hw as i64, i64::from(search));
        let px = |x: f32| math::roundf(x * info.inv_scale) as i64;
        let (su_l, sv_l, su_r0) = (px(u_l), px(v_l), px(u_r0));
        let (wd, ht) = (il.width() as i64, il.height() as i64);
        if sv_l - w < 0
            || sv_l + w >= ht
            || su_l - w < 0
            || su_l + w >= wd
            || su_r0 - big_l - w < 0
            || su_r0 + big_l + w >= wd
        {
            return Err(Reject::Window);
        }
        let at = |img: &ImageView<'_>, x: i64, y: i64| i64::from(img.row(y as usize)[x as usize]);
        let cl = at(&il, su_l, sv_l);
        let mut dists = Vec::new();
        for inc in -big_l..=big_l {
            let cr = at(&ir, su_r0 + inc, sv_l);
            let mut d = 0i64;
            for dy in -w..=w {
                for dx in -w..=w {
                    let pl_ = at(&il, su_l + dx, sv_l + dy) - cl;
                    d += (at(&ir, su_r0 + inc + dx, sv_l + dy) - cr - pl_).abs();
                }
            }
            dists.push(d as u32);
        }
        let k = (0..dists.len()).min_by_key(|&k| (dists[k], k)).unwrap();
        if k == 0 || k == dists.len() - 1 {
            return Err(Reject::Border);
        }
        let (d1, d2, d3) = (dists[k - 1] as f32, dists[k] as f32, dists[k + 1] as f32);
        let delta = parabola_offset(d1, d2, d3).ok_or(Reject::Parabola)?;
        Ok((info.scale * (su_r0 as f32 + (k as i64 - big_l) as f32 + delta), dists[k]))
    };
    let mut rng = testing::Rng::new(0x5ad_5ad);
    let mut refined = 0;
    for _ in 0..400 {
        let lv = rng.below(3);
        let (hw, search) = (rng.below(8) + 1, rng.below(12) as i32 + 1);
        let u_l = rng.range(-5.0, W as f64 + 5.0) as f32;
        let v_l = rng.range(-5.0, H as f64 + 5.0) as f32;
        let u_r0 = u_l - rng.range(5.0, 30.0) as f32;
        let want = definition(lv, u_l, v_l, u_r0, hw, search);
        refined += usize::from(want.is_ok());
        crate::nn::dispatch::for_each_level(|isa| {
            let (il, ir, info) = (pl.level(lv), pr.level(lv), pl.info(lv));
            // Garbage in the padding must not matter.
            let mut rows = [0xa5u8; SAD_ROWS_BYTES];
            let got = sad_refine(&il, &ir, &info, u_l, v_l, u_r0, hw, search, &mut rows);
            let bits = |x: &Result<(f32, u32), Reject>| x.map(|(u, d)| (u.to_bits(), d));
            assert_eq!(bits(&got), bits(&want), "{isa}: level {lv} ({u_l}, {v_l}) -> {u_r0}");
        });
    }
    assert!(refined > 100, "only {refined} of 400 refined");
}

#[test]
fn kitti_matcher_fits_its_budget() {
    std::println!("KittiStereoMatcher: {KITTI_STEREO_MATCHER_BYTES} bytes");
    const { assert!(KITTI_STEREO_MATCHER_BYTES <= KITTI_STEREO_MATCHER_BUDGET) };
    let m = Box::new(KittiStereoMatcher::new());
    assert_eq!(m.entries.len(), 32768);
}
