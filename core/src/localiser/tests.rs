//! The localiser's contracts: one-thread and split schedules give the same bits, sizes and
//! missing labels are typed errors, labels are reused until replaced.

extern crate std;

use std::boxed::Box;
use std::vec::Vec;

use super::*;
use crate::orb::PAPER_STRUCTURE_GAIN;
use crate::seg::WeightScheme;
use crate::testing::on_big_stack;

const W: usize = 320;
const H: usize = 96;

fn cam() -> StereoCamera {
    StereoCamera::new(180.0, 180.0, 160.0, 48.0, 0.54).unwrap()
}

/// A textured pair: the right image is the left shifted by a disparity that grows downwards,
/// so the stereo matcher finds depths; frame `k` moves the texture by `k` px (forward motion
/// is not needed for these contracts).
fn pair(k: usize) -> (Vec<u8>, Vec<u8>) {
    // Random 4x4 blocks (a splitmix hash of the block index): corners everywhere, distinctive
    // descriptors.
    let tex = |x: usize, y: usize| {
        let mut z = ((x / 4) as u64) << 32 | (y / 4) as u64;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        (z ^ (z >> 31)) as u8
    };
    let d = |y: usize| 6 + y / 16;
    // A scene point at texture column u is at x = u + d in the left image, u in the right.
    let left = (0..W * H).map(|i| tex(i % W + 64 - d(i / W) + k, i / W)).collect();
    let right = (0..W * H).map(|i| tex(i % W + 64 + k, i / W)).collect();
    (left, right)
}

/// Labels: a "car" (class 8) block in the middle, "building" (1) elsewhere.
fn labels() -> Vec<u8> {
    (0..W * H).map(|i| if (100..200).contains(&(i % W)) { 8 } else { 1 }).collect()
}

fn localiser(semantics: Option<WeightScheme>) -> Box<Localiser> {
    let mut c = LocaliserConfig::new(cam(), W as u32, H as u32);
    c.semantics = semantics;
    Box::new(Localiser::new(&c).unwrap())
}

#[test]
fn split_extraction_equals_one_thread() {
    on_big_stack(|| {
        let lab = labels();
        let lv = ImageView::from_slice(&lab, W, H).unwrap();
        let mut a = localiser(Some(WeightScheme::Full));
        let mut b = localiser(Some(WeightScheme::Full));
        for k in 0..4 {
            let (l, r) = pair(k);
            let (l, r) = (
                ImageView::from_slice(&l, W, H).unwrap(),
                ImageView::from_slice(&r, W, H).unwrap(),
            );
            a.set_labels(&lv).unwrap();
            let oa = a.process(&l, &r, k as f64 * 0.1).unwrap();
            b.set_labels(&lv).unwrap();
            {
                let (mut le, mut re) = b.extractors_mut();
                std::thread::scope(|s| {
                    let h = s.spawn(move || re.run(&r));
                    le.run(&l).unwrap();
                    h.join().unwrap().unwrap();
                });
            }
            let stereo = b.match_stereo(k as f64 * 0.1).unwrap();
            let rep = b.track();
            assert_eq!(oa.stereo, stereo);
            assert_eq!(oa.report.t_wc, rep.t_wc);
            assert_eq!(oa.report.inliers, rep.inliers);
            assert!(oa.culled > 0, "the car block must cull candidates");
            assert_eq!(oa.culled, b.culled());
        }
        assert!(a.frame().features.iter().any(|f| f.class == 8) || a.culled() > 0);
    });
}

/// The next frame extracted beside this one's tracking (a host's overlapped schedule) gives
/// the same stereo matches, poses and culled counts as extracting it after.
#[test]
fn next_frame_extracted_while_tracking_equals_in_turn() {
    on_big_stack(|| {
        let frames: Vec<_> = (0..5).map(pair).collect();
        // Labels that change per frame, so a frame tracked with the next one's labels would
        // show: the "car" block moves.
        let labs: Vec<Vec<u8>> = (0..5)
            .map(|k| {
                (0..W * H)
                    .map(|i| if (90 + 8 * k..190 + 8 * k).contains(&(i % W)) { 8 } else { 1 })
                    .collect()
            })
            .collect();
        fn view(v: &[u8]) -> ImageView<'_> {
            ImageView::from_slice(v, W, H).unwrap()
        }
        let mut a = localiser(Some(WeightScheme::Full));
        let mut in_turn = Vec::new();
        for (k, (l, r)) in frames.iter().enumerate() {
            a.set_labels(&view(&labs[k])).unwrap();
            let o = a.process(&view(l), &view(r), k as f64 * 0.1).unwrap();
            in_turn.push((o.stereo, o.report.t_wc, o.report.inliers, o.culled));
        }
        let mut b = localiser(Some(WeightScheme::Full));
        b.set_labels(&view(&labs[0])).unwrap();
        b.extract(&view(&frames[0].0), &view(&frames[0].1)).unwrap();
        for k in 0..frames.len() {
            let stereo = b.match_stereo(k as f64 * 0.1).unwrap();
            let culled = b.culled();
            let (mut tracking, mut le, mut re) = b.split_for_tracking();
            let rep = std::thread::scope(|s| {
                let h = s.spawn(|| tracking.track());
                if let Some((l, r)) = frames.get(k + 1) {
                    le.set_labels(&view(&labs[k + 1])).unwrap();
                    le.run(&view(l)).unwrap();
                    re.run(&view(r)).unwrap();
                }
                h.join().unwrap()
            });
            assert_eq!((stereo, rep.t_wc, rep.inliers, culled), in_turn[k], "frame {k}");
        }
        assert!(in_turn.iter().all(|f| f.3 > 0), "the car block must cull candidates");
        assert!(in_turn.iter().skip(1).all(|f| f.2 > 0), "frames must be tracked");
    });
}

#[test]
fn wrong_sizes_and_missing_labels_are_typed_errors() {
    on_big_stack(|| {
        let mut loc = localiser(Some(WeightScheme::Cull));
        let (l, r) = pair(0);
        // semantics on, no labels yet
        assert_eq!(loc.process_raw(&l, &r, 0.0, None), Err(LocaliserError::NoLabels));
        // labels of another size
        let small = std::vec![1u8; 10 * 10];
        let sv = ImageView::from_slice(&small, 10, 10).unwrap();
        assert_eq!(
            loc.set_labels(&sv),
            Err(LocaliserError::FrameSize { expected: (W, H), got: (10, 10) })
        );
        // an image of another size
        let lab = labels();
        loc.set_labels(&ImageView::from_slice(&lab, W, H).unwrap()).unwrap();
        let lv = ImageView::from_slice(&l, W, H).unwrap();
        let half = ImageView::from_slice(&r, W / 2, H).unwrap();
        assert!(matches!(loc.process(&lv, &half, 0.0), Err(LocaliserError::FrameSize { .. })));
        // a short buffer
        assert!(matches!(loc.process_raw(&l[..100], &r, 0.0, None), Err(LocaliserError::Image(_))));
        // beyond capacity
        let c = LocaliserConfig::new(cam(), 4000, 100);
        assert!(matches!(Localiser::new(&c), Err(LocaliserError::FrameSize { .. })));
    });
}

#[test]
fn labels_are_reused_until_replaced() {
    on_big_stack(|| {
        let lab = labels();
        let lv = ImageView::from_slice(&lab, W, H).unwrap();
        let mut a = localiser(Some(WeightScheme::Full));
        let mut b = localiser(Some(WeightScheme::Full));
        let (l, r) = pair(0);
        a.set_labels(&lv).unwrap();
        b.set_labels(&lv).unwrap();
        a.process_raw(&l, &r, 0.0, None).unwrap();
        b.process_raw(&l, &r, 0.0, None).unwrap();
        let (l, r) = pair(1);
        a.set_labels(&lv).unwrap(); // the same labels again
        let oa = a.process_raw(&l, &r, 0.1, None).unwrap();
        let ob = b.process_raw(&l, &r, 0.1, None).unwrap(); // reused
        assert_eq!(oa, ob);
        assert_eq!(b.labels(), Some(&lab[..]));
    });
}

#[test]
fn without_semantics_labels_do_not_change_the_result() {
    on_big_stack(|| {
        let lab = labels();
        let mut a = localiser(None);
        let mut b = localiser(None);
        let (l, r) = pair(0);
        a.set_labels(&ImageView::from_slice(&lab, W, H).unwrap()).unwrap();
        let oa = a.process_raw(&l, &r, 0.0, None).unwrap();
        let ob = b.process_raw(&l, &r, 0.0, None).unwrap();
        assert_eq!(oa, ob);
        assert_eq!(oa.culled, 0);
        assert!(oa.stereo.matched > 50, "the test pair must give stereo points: {:?}", oa.stereo);
    });
}

#[test]
fn localiser_fits_its_budget() {
    // Printed for the README's figures.
    std::println!(
        "Localiser::MEMORY_BYTES = {} (budget {})",
        Localiser::MEMORY_BYTES,
        LOCALISER_BUDGET_BYTES
    );
    // The state is the core pieces and the two frame images, nothing else (up to padding).
    use core::mem::size_of;
    let parts = 2 * size_of::<FrameOrbExtractor>()
        + size_of::<FrameStereoMatcher>()
        + size_of::<Frame>()
        + size_of::<Tracker>()
        + 2 * MAX_PIXELS;
    let total = core::hint::black_box(Localiser::MEMORY_BYTES);
    assert!(total >= parts && total - parts < 512, "{total} vs {parts}");
}

/// Tracks the rendered corridor ([`crate::testing::corridor`]) at a frame size other than
/// KITTI's, the camera moving 0.8 m forward per frame with a lateral weave; returns the largest
/// position error (m) against the rendered path.
fn corridor_run(w: usize, h: usize, fx: f64, frames: usize) -> f64 {
    use crate::testing::corridor;
    let (cx, cy, b) = (w as f64 / 2.0 - 0.5, h as f64 / 2.0 - 0.5, 0.5);
    let cam = StereoCamera::new(fx, fx, cx, cy, b).unwrap();
    let mut loc = Box::new(Localiser::new(&LocaliserConfig::new(cam, w as u32, h as u32)).unwrap());
    let (mut l, mut r) = (std::vec![0u8; w * h], std::vec![0u8; w * h]);
    let mut worst: f64 = 0.0;
    for k in 0..frames {
        let eye = [0.3 * libm::sin(k as f64 / 3.0), 0.0, 0.8 * k as f64];
        corridor(&mut l, w, h, fx, cx, cy, eye);
        corridor(&mut r, w, h, fx, cx, cy, [eye[0] + b, eye[1], eye[2]]);
        let out = loc.process_raw(&l, &r, k as f64 * 0.1, None).unwrap();
        assert!(out.stereo.matched > 100, "{w}x{h} frame {k}: {:?}", out.stereo);
        let t = out.report.t_wc.trans;
        let err = libm::sqrt(
            (t.x - eye[0]) * (t.x - eye[0]) + (t.y - eye[1]).powi(2) + (t.z - eye[2]).powi(2),
        );
        worst = worst.max(err);
    }
    worst
}

#[test]
fn any_frame_size_up_to_the_maximum_is_tracked() {
    on_big_stack(|| {
        // Automotive 2.3 MP (the compile-time maximum), EuRoC's 752 × 480, 720p.
        for (w, h, fx, frames) in
            [(1920, 1200, 1000.0, 6), (752, 480, 458.0, 10), (1280, 720, 700.0, 8)]
        {
            let worst = corridor_run(w, h, fx, frames);
            std::println!("{w}x{h}: worst position error {worst:.4} m over {frames} frames");
            // 0.8 m per frame: a few cm is tracking, a scale or axis mix-up is metres.
            assert!(worst < 0.05, "{w}x{h}: worst position error {worst} m");
        }
    });
}

#[test]
fn frames_beyond_the_maximum_are_refused() {
    on_big_stack(|| {
        for (w, h) in [(MAX_FRAME_WIDTH + 1, 100), (100, MAX_FRAME_HEIGHT + 1)] {
            let c = LocaliserConfig::new(cam(), w as u32, h as u32);
            assert_eq!(
                Localiser::new(&c).err(),
                Some(LocaliserError::FrameSize {
                    expected: (MAX_FRAME_WIDTH, MAX_FRAME_HEIGHT),
                    got: (w, h)
                })
            );
        }
    });
}

/// `orb.structure_gain` reaches the weight image: at 1, `full` extracts exactly what `cull`
/// does; at the paper's 3 more of the features are on the construction class; out of range,
/// the localiser refuses it.
#[test]
fn the_structure_gain_reaches_the_extractor() {
    on_big_stack(|| {
        // Stripes of building (construction) and road 24 px wide, so that the quadtree's nodes
        // span both.
        let lab: Vec<u8> =
            (0..W * H).map(|i| if (i % W / 24).is_multiple_of(2) { 1 } else { 3 }).collect();
        let lv = ImageView::from_slice(&lab, W, H).unwrap();
        let (l, r) = pair(0);
        let run = |scheme: WeightScheme, gain: f32| {
            let mut c = LocaliserConfig::new(cam(), W as u32, H as u32);
            c.semantics = Some(scheme);
            c.orb.structure_gain = gain;
            // Few features, so the quadtree's nodes hold several candidates to choose from.
            c.orb.n_features = 150;
            let mut loc = Box::new(Localiser::new(&c).unwrap());
            loc.set_labels(&lv).unwrap();
            loc.process_raw(&l, &r, 0.0, None).unwrap();
            let f = &loc.frame().features;
            let xy: Vec<(f32, f32)> = f.iter().map(|f| (f.x, f.y)).collect();
            let on_building = f.iter().filter(|f| f.class == 1).count();
            (xy, on_building)
        };
        let cull = run(WeightScheme::Cull, PAPER_STRUCTURE_GAIN);
        let flat = run(WeightScheme::Full, 1.0);
        let paper = run(WeightScheme::Full, PAPER_STRUCTURE_GAIN);
        assert_eq!(flat, cull);
        // The quadtree keeps the strongest weighted corner of each node: where a node spans
        // both classes, x3 picks the building's.
        assert!(paper.1 > flat.1, "x3: {} on the building, x1: {}", paper.1, flat.1);
        let mut c = LocaliserConfig::new(cam(), W as u32, H as u32);
        c.orb.structure_gain = 0.5;
        assert_eq!(
            Localiser::new(&c).err(),
            Some(LocaliserError::Orb {
                right: false,
                err: OrbError::BadStructureGain { value: 0.5 }
            })
        );
    });
}
