//! Core allocates nothing per frame: ORB on both images, stereo matching and tracking run under
//! a counting global allocator, and after the first frame the count must stay at zero.
//!
//! The large fixed-size state is built (and boxed) before counting starts; only calls into
//! `semloc-core` are inside the counted region. Both tests take one lock because the counter
//! is process-wide.

use std::alloc::System;
use std::sync::Mutex;

use semloc_core::frame::Frame;
use semloc_core::geom::StereoCamera;
use semloc_core::image::ImageView;
use semloc_core::orb::{KittiOrbExtractor, OrbConfig};
use semloc_core::stereo::{KittiStereoMatcher, StereoParams};
use semloc_core::tracker::{Tracker, TrackerParams};
use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};

#[global_allocator]
static GLOBAL: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

static SERIAL: Mutex<()> = Mutex::new(());

struct Core {
    left: Box<KittiOrbExtractor>,
    right: Box<KittiOrbExtractor>,
    stereo: Box<KittiStereoMatcher>,
    frame: Box<Frame>,
    tracker: Box<Tracker>,
    params: StereoParams,
}

fn build(cam: StereoCamera, w: u32, h: u32) -> Core {
    let mut left = Box::new(KittiOrbExtractor::new());
    let mut right = Box::new(KittiOrbExtractor::new());
    left.configure(OrbConfig::KITTI).unwrap();
    right.configure(OrbConfig::KITTI).unwrap();
    let params = StereoParams::new((cam.fx_px * cam.baseline_m) as f32, cam.baseline_m as f32);
    Core {
        left,
        right,
        stereo: Box::new(KittiStereoMatcher::new()),
        frame: Box::new(Frame::new()),
        tracker: Box::new(Tracker::new(cam, w, h, TrackerParams::default()).unwrap()),
        params,
    }
}

/// Runs the frames through core; returns (allocations, frames tracked) after the first frame.
fn count_allocations(core: &mut Core, frames: &[(Vec<u8>, Vec<u8>)], w: usize, h: usize) -> usize {
    let mut allocations = 0;
    for (i, (l, r)) in frames.iter().enumerate() {
        let lv = ImageView::from_slice(l, w, h).unwrap();
        let rv = ImageView::from_slice(r, w, h).unwrap();
        let region = Region::new(GLOBAL);
        core.left.extract(&lv).unwrap();
        core.right.extract(&rv).unwrap();
        core.stereo
            .match_frame(
                core.left.features(),
                core.left.pyramid(),
                core.right.features(),
                core.right.pyramid(),
                &core.params,
                i as f64 * 0.1,
                &mut core.frame,
            )
            .unwrap();
        let rep = core.tracker.process(&core.frame);
        let change = region.change();
        if i > 0 {
            allocations += change.allocations + change.reallocations;
        }
        eprintln!(
            "frame {i}: stereo {} inliers {} kf {} allocations {}",
            core.frame.stereo_count(),
            rep.inliers,
            rep.keyframe,
            change.allocations
        );
    }
    allocations
}

/// A textured synthetic stereo pair: blocks of pseudo-random grey with a per-row-band
/// disparity, shifted a little each frame to make the camera "move".
fn synthetic_pair(w: usize, h: usize, shift: usize) -> (Vec<u8>, Vec<u8>) {
    let tex = |x: usize, y: usize| -> u8 {
        let (bx, by) = (x / 6, y / 6);
        let v = (bx.wrapping_mul(2654435761) ^ by.wrapping_mul(40503)).wrapping_mul(2246822519);
        ((v >> 13) & 0xff) as u8
    };
    let mut l = vec![0u8; w * h];
    let mut r = vec![0u8; w * h];
    for y in 0..h {
        let d = 8 + (y * 24) / h; // disparity grows towards the bottom (nearer ground)
        for x in 0..w {
            l[y * w + x] = tex(x + shift, y);
            r[y * w + x] = tex(x + shift + d, y);
        }
    }
    (l, r)
}

fn on_big_stack<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::Builder::new().stack_size(64 << 20).spawn(f).unwrap().join().unwrap()
}

#[test]
fn core_allocates_nothing_per_frame_on_synthetic_frames() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let (w, h) = (1241usize, 376usize);
    let frames: Vec<_> = (0..6).map(|k| synthetic_pair(w, h, k * 2)).collect();
    let allocations = on_big_stack(move || {
        let cam = StereoCamera::new(718.856, 718.856, 607.19, 185.22, 0.537).unwrap();
        let mut core = build(cam, w as u32, h as u32);
        count_allocations(&mut core, &frames, w, h)
    });
    assert_eq!(allocations, 0, "heap allocations in core after the first frame");
}

#[test]
#[ignore = "real data in ../shared/data; run with --ignored (CI does)"]
fn core_allocates_nothing_per_frame_on_kitti_raw() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let Some(data) = semloc_tests::shared_data() else { return };
    let seq = semloc::dataset::Sequence::open_raw(&data.join("kitti-raw"), "2011_09_26_0005", None)
        .unwrap();
    let (w, h) = (seq.image_size.0 as usize, seq.image_size.1 as usize);
    let frames: Vec<_> = (0..12)
        .map(|i| {
            let (l, r) = seq.load_luma(i).unwrap();
            (l.into_raw(), r.into_raw())
        })
        .collect();
    let cam = seq.calib.to_camera().unwrap();
    let allocations = on_big_stack(move || {
        let mut core = build(cam, w as u32, h as u32);
        count_allocations(&mut core, &frames, w, h)
    });
    assert_eq!(allocations, 0, "heap allocations in core after the first frame");
}

/// The int8 network (the committed 192x640 model) labels KITTI-sized frames without a single
/// heap allocation: the blob is read in place, activations live in the caller's arena, and
/// the per-frame model view is re-attached, not re-parsed.
#[test]
fn segmentation_allocates_nothing() {
    use semloc_core::nn::graph::{segment_frame, Kernels, Letterbox, SegBuffers};
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models/artefacts/fastscnn_r2_192x640.slm");
    let blob = semloc::nn::SlmBlob::load(&path).unwrap();
    let (w, h) = (1241usize, 376usize);
    let frames: Vec<Vec<u8>> =
        (0..3).map(|k| (0..w * h).map(|i| ((i * 31 + k * 977) % 251) as u8).collect()).collect();
    let arena_len = blob.model().unwrap().arena_len();
    let (mut input, mut labels) = (vec![0u8; 192 * 640], vec![0u8; 192 * 640]);
    let (mut arena, mut out) = (vec![0i8; arena_len], vec![0u8; w * h]);
    let lb = Letterbox::fit(w, h, 192, 640).unwrap();
    let reg = Region::new(GLOBAL);
    for f in &frames {
        let m = blob.model().unwrap();
        let bufs = SegBuffers { input: &mut input, arena: &mut arena, labels: &mut labels };
        segment_frame(&m, &lb, f, bufs, Kernels::Fast, &mut out).unwrap();
    }
    let allocs = reg.change().allocations;
    assert!(out.iter().all(|&l| l <= 10));
    assert_eq!(allocs, 0, "{allocs} heap allocations while segmenting 3 frames");
}
