//! Core allocates nothing per frame: core's one frame path ([`Localiser`]) runs under a counting
//! global allocator — the geometric backbone, and the paper's full path (the int8 network's
//! labels, semantic ORB, semantic descriptors, EM association) — and after the first frame the
//! count must stay at zero.
//!
//! The large fixed-size state and the network's buffers are built before counting starts; only
//! calls into `semloc-core` are inside the counted region. The counter is per thread: `core` is
//! `no_std` and never starts a thread, so everything it does runs on the thread that counts,
//! while the test harness's own allocations on other threads (printing a finished test's
//! result, spawning the next one) stay out of the count. With a process-wide counter they
//! landed in the region on a loaded machine: 19 "allocations while segmenting" in a CI run
//! that shared its two cores with a training job, none of them core's.

use core::alloc::{GlobalAlloc, Layout};
use core::cell::Cell;
use std::alloc::System;
use std::sync::Mutex;

use semloc_core::assoc::Association;
use semloc_core::geom::StereoCamera;
use semloc_core::localiser::{Localiser, LocaliserConfig, Network, NetworkMemory};
use semloc_core::seg::WeightScheme;
use semloc_core::tracker::TrackerParams;
use semloc_tests::on_big_stack;

thread_local! {
    /// Allocations and reallocations made by this thread so far. A `const` initialiser and a
    /// type without `Drop`: reading it never allocates nor registers a destructor.
    static THREAD_ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

/// The system allocator, counting each thread's allocations and reallocations.
struct PerThreadCounting;

fn count_one() {
    // `try_with`: a thread being torn down (its locals gone) may still free or allocate.
    let _ = THREAD_ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

#[allow(unsafe_code)]
// SAFETY: every call is forwarded unchanged to `System`, which upholds `GlobalAlloc`'s
// contract; the counting touches only a thread-local `Cell` and never allocates.
unsafe impl GlobalAlloc for PerThreadCounting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count_one();
        // SAFETY: the caller's layout contract is passed on as is.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count_one();
        // SAFETY: as for `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count_one();
        // SAFETY: `ptr` was allocated by `System` through this allocator with `layout`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as for `realloc`.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: PerThreadCounting = PerThreadCounting;

/// Allocations and reallocations this thread has made so far.
fn thread_allocations() -> usize {
    THREAD_ALLOCATIONS.with(Cell::get)
}

/// The tests still run one at a time, as before the counter became per thread: each holds a
/// localiser and the network's buffers, and one at a time bounds the peak memory.
static SERIAL: Mutex<()> = Mutex::new(());

/// The committed network the semantic path labels frames with.
fn model_blob() -> semloc::nn::SlmBlob {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../models/artefacts/fastscnn_r2_192x640.slm");
    semloc::nn::SlmBlob::load(&path).unwrap()
}

/// Stereo frames (left, right luma) of one camera.
struct Clip {
    cam: StereoCamera,
    frames: Vec<(Vec<u8>, Vec<u8>)>,
    w: usize,
    h: usize,
}

/// Runs the clip through a localiser (the paper's full path with network labels and EM when
/// `semantic`); returns the heap allocations after the first frame.
fn count_allocations(clip: Clip, semantic: bool) -> usize {
    on_big_stack(move || {
        let Clip { cam, frames, w, h } = clip;
        let mut config = LocaliserConfig::new(cam, w as u32, h as u32);
        let blob = model_blob();
        let (arena_len, map_len) = NetworkMemory::bytes_needed(
            &semloc_core::nn::model::Model::parse(blob.bytes()).unwrap(),
        );
        let (mut arena, mut input, mut model_labels) =
            (vec![0i8; arena_len], vec![0u8; map_len], vec![0u8; map_len]);
        let mut network = semantic.then(|| {
            let mem = NetworkMemory {
                arena: &mut arena,
                input: &mut input,
                model_labels: &mut model_labels,
            };
            Network::new(blob.bytes(), w, h, mem).unwrap()
        });
        if semantic {
            config.semantics = Some(WeightScheme::Full);
            config.tracker = TrackerParams { association: Association::Em, ..config.tracker };
        }
        let mut loc = Box::new(Localiser::new(&config).unwrap());
        let mut allocations = 0;
        for (i, (l, r)) in frames.iter().enumerate() {
            let before = thread_allocations();
            let out = loc.process_raw(l, r, i as f64 * 0.1, network.as_mut()).unwrap();
            let change = thread_allocations() - before;
            if i > 0 {
                allocations += change;
            }
            eprintln!(
                "frame {i}: stereo {} inliers {} kf {} culled {} allocations {}",
                out.stereo.matched, out.report.inliers, out.report.keyframe, out.culled, change
            );
            if semantic {
                assert!(loc.labels().is_some(), "the network labelled frame {i}");
            }
        }
        allocations
    })
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

fn synthetic_frames() -> Clip {
    let (w, h) = (1241usize, 376usize);
    let frames: Vec<_> = (0..6).map(|k| synthetic_pair(w, h, k * 2)).collect();
    let cam = StereoCamera::new(718.856, 718.856, 607.19, 185.22, 0.537).unwrap();
    Clip { cam, frames, w, h }
}

/// The counter sees this thread's allocations and reallocations, and not another thread's, so a
/// zero below means core allocated nothing rather than that nothing was counted.
#[test]
fn the_counter_counts_this_threads_allocations_only() {
    let before = thread_allocations();
    let mut v = core::hint::black_box(Vec::<u8>::with_capacity(8));
    v.extend_from_slice(&[0; 64]);
    assert_eq!(thread_allocations() - before, 2, "one allocation and one reallocation");
    let before = thread_allocations();
    let other = std::thread::spawn(|| {
        let b = thread_allocations();
        let v: Vec<Vec<u8>> = (0..1000).map(|i| core::hint::black_box(vec![0u8; 16 + i])).collect();
        (thread_allocations() - b, v.len())
    });
    let (theirs, _) = other.join().unwrap();
    let here = thread_allocations() - before;
    assert!(theirs >= 1000, "the other thread counts its own: {theirs}");
    assert!(here < 100, "{here}: spawning counts here, the other thread's allocations do not");
}

#[test]
fn core_allocates_nothing_per_frame_on_synthetic_frames() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let allocations = count_allocations(synthetic_frames(), false);
    assert_eq!(allocations, 0, "heap allocations in core after the first frame");
}

#[test]
fn semantic_em_path_allocates_nothing_per_frame_on_synthetic_frames() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let allocations = count_allocations(synthetic_frames(), true);
    assert_eq!(allocations, 0, "heap allocations in the semantic + EM path after the first frame");
}

fn kitti_raw_frames() -> Option<Clip> {
    let data = semloc_tests::shared_data()?;
    let seq = semloc::dataset::Sequence::open_raw(&data.join("kitti-raw"), "2011_09_26_0005", None)
        .unwrap();
    let (w, h) = (seq.image_size.0 as usize, seq.image_size.1 as usize);
    let frames: Vec<_> = (0..12)
        .map(|i| {
            let (l, r) = seq.load_luma(i).unwrap();
            (l.into_raw(), r.into_raw())
        })
        .collect();
    Some(Clip { cam: seq.calib.to_camera().unwrap(), frames, w, h })
}

#[test]
#[ignore = "real data in ../shared/data; run with --ignored (CI does)"]
fn core_allocates_nothing_per_frame_on_kitti_raw() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let Some(clip) = kitti_raw_frames() else { return };
    let allocations = count_allocations(clip, false);
    assert_eq!(allocations, 0, "heap allocations in core after the first frame");
}

#[test]
#[ignore = "real data in ../shared/data; run with --ignored (CI does)"]
fn semantic_em_path_allocates_nothing_per_frame_on_kitti_raw() {
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let Some(clip) = kitti_raw_frames() else { return };
    let allocations = count_allocations(clip, true);
    assert_eq!(allocations, 0, "heap allocations in the semantic + EM path after the first frame");
}

/// The int8 network (the committed 192x640 model) labels KITTI-sized frames without a single
/// heap allocation: the blob is read in place, activations live in the caller's arena, and
/// the per-frame model view is re-attached, not re-parsed.
#[test]
fn segmentation_allocates_nothing() {
    use semloc_core::nn::graph::{segment_frame, Kernels, Letterbox, SegBuffers};
    let _g = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let blob = model_blob();
    let (w, h) = (1241usize, 376usize);
    let frames: Vec<Vec<u8>> =
        (0..3).map(|k| (0..w * h).map(|i| ((i * 31 + k * 977) % 251) as u8).collect()).collect();
    let arena_len = blob.model().unwrap().arena_len();
    let (mut input, mut labels) = (vec![0u8; 192 * 640], vec![0u8; 192 * 640]);
    let (mut arena, mut out) = (vec![0i8; arena_len], vec![0u8; w * h]);
    let lb = Letterbox::fit(w, h, 192, 640).unwrap();
    let before = thread_allocations();
    for f in &frames {
        let m = blob.model().unwrap();
        let bufs = SegBuffers { input: &mut input, arena: &mut arena, labels: &mut labels };
        segment_frame(&m, &lb, f, bufs, Kernels::Fast, &mut out).unwrap();
    }
    let allocs = thread_allocations() - before;
    assert!(out.iter().all(|&l| l <= 10));
    assert_eq!(allocs, 0, "{allocs} heap allocations while segmenting 3 frames");
}
