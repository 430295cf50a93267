//! Unit tests on the host: output format, hash, the embedded data, and the localiser on the
//! embedded frames (tracks, close to the ground truth, deterministic).

use std::string::String;

use crate::embedded::{self, CAMERA, FRAMES, HEIGHT, WIDTH};
use crate::report::{self, pose_error, write_pose_line, Fnv1a, RunSummary};

/// Stack for threads that build the ≈ 41 MiB localiser.
const BIG_STACK_BYTES: usize = 1 << 30;

fn on_big_stack<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::Builder::new()
        .stack_size(BIG_STACK_BYTES)
        .spawn(f)
        .expect("spawn")
        .join()
        .expect("worker panicked")
}

/// The whole report text and summary of one run over the embedded frames.
fn run_once() -> (String, RunSummary) {
    on_big_stack(|| {
        let mut loc = Box::new(
            crate::embedded_localiser(crate::geometric_params(), None).expect("localiser"),
        );
        let mut text = String::new();
        let s = report::run_embedded(&mut loc, None, &mut text, |_, _| Ok(())).expect("run");
        (text, s)
    })
}

#[test]
fn fnv1a_reference_values() {
    // Published FNV-1a 64-bit test vectors.
    let h = |s: &str| {
        let mut f = Fnv1a::new();
        f.write(s.as_bytes());
        f.finish()
    };
    assert_eq!(h(""), 0xcbf2_9ce4_8422_2325);
    assert_eq!(h("a"), 0xaf63_dc4c_8601_ec8c);
    assert_eq!(h("foobar"), 0x8594_4171_f739_67e8);
}

#[test]
fn pose_line_is_twelve_bit_patterns() {
    let mut row = [0.0; 12];
    row[0] = 1.0;
    row[5] = 1.0;
    row[10] = 1.0;
    row[3] = -0.5;
    let mut s = String::new();
    write_pose_line(&mut s, &row).unwrap();
    assert_eq!(
        s,
        "3ff0000000000000 0000000000000000 0000000000000000 bfe0000000000000 \
         0000000000000000 3ff0000000000000 0000000000000000 0000000000000000 \
         0000000000000000 0000000000000000 3ff0000000000000 0000000000000000\n"
    );
    let back: Vec<f64> =
        s.split_whitespace().map(|t| f64::from_bits(u64::from_str_radix(t, 16).unwrap())).collect();
    assert_eq!(back, row);
}

#[test]
fn pose_error_of_known_offsets() {
    let id = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    assert_eq!(pose_error(&id, &id), (0.0, 0.0));
    let mut moved = id;
    moved[3] = 3.0;
    moved[11] = 4.0;
    assert_eq!(pose_error(&moved, &id).0, 5.0);
    // 10° about the y axis.
    let (s, c) = 10f64.to_radians().sin_cos();
    let rot = [c, 0.0, s, 0.0, 0.0, 1.0, 0.0, 0.0, -s, 0.0, c, 0.0];
    let (t, r) = pose_error(&rot, &id);
    assert_eq!(t, 0.0);
    assert!((r - 10.0).abs() < 1e-6, "{r}");
}

#[test]
fn embedded_data_is_consistent() {
    assert!(FRAMES.len() >= 4, "{} frames", FRAMES.len());
    for (i, f) in FRAMES.iter().enumerate() {
        assert_eq!(f.left.len(), WIDTH * HEIGHT, "frame {i}");
        assert_eq!(f.right.len(), WIDTH * HEIGHT, "frame {i}");
        assert!(f.left != f.right, "frame {i}: left and right must differ");
        assert!((f.timestamp_s - i as f64 * 0.1).abs() < 1e-9, "frame {i}: 10 Hz");
    }
    assert_eq!(pose_error(&FRAMES[0].gt_pose, &FRAMES[0].gt_pose), (0.0, 0.0));
    let id = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let (t, r) = pose_error(&FRAMES[0].gt_pose, &id);
    assert!(t < 1e-12 && r < 1e-6, "ground truth starts at the identity: {t} m, {r} deg");
    // The principal point moved with the crop and stays inside it.
    assert!(CAMERA.cx_px > 0.0 && CAMERA.cx_px < WIDTH as f64);
    assert!(CAMERA.cy_px > 0.0 && CAMERA.cy_px < HEIGHT as f64);
    assert!(embedded::SOURCE.contains("semloc synth"));
}

#[test]
fn tracks_the_embedded_sequence_deterministically() {
    let (a, sa) = run_once();
    print!("{a}");
    assert_eq!(sa.frames as usize, FRAMES.len());
    assert!(sa.tracked(), "did not track: {sa:?}");
    assert!(sa.max_err_r_deg < 0.5, "rotation error {} deg", sa.max_err_r_deg);
    // Pose lines: one per frame, 12 hex numbers each; then the hash line.
    let poses: Vec<&str> =
        a.lines().filter(|l| !l.starts_with('#') && !l.starts_with("fnv1a64")).collect();
    assert_eq!(poses.len(), FRAMES.len());
    assert!(poses.iter().all(|l| l.split(' ').count() == 12 && l.len() == 12 * 17 - 1));
    assert_eq!(a.lines().last(), Some(format!("fnv1a64 {:016x}", sa.hash).as_str()));
    // A second run from a fresh localiser gives the same bits.
    let (b, sb) = run_once();
    assert_eq!(a, b);
    assert_eq!(sa, sb);
}

/// The semantic run (network, semantic ORB, EM): text and summary.
fn run_semantic() -> (String, RunSummary) {
    on_big_stack(|| {
        let mut loc = Box::new(
            crate::embedded_localiser(crate::semantic_params(), Some(crate::SEMANTIC_SCHEME))
                .expect("loc"),
        );
        let mut storage = Box::new(crate::SegStorage::new());
        let mut sem = crate::Network::new(embedded::MODEL_BLOB, WIDTH, HEIGHT, storage.memory())
            .expect("network");
        let mut text = String::new();
        let s =
            report::run_embedded(&mut loc, Some(&mut sem), &mut text, |_, _| Ok(())).expect("run");
        (text, s)
    })
}

#[test]
fn semantic_run_tracks_deterministically_and_labels_frames() {
    let (a, sa) = run_semantic();
    print!("{a}");
    assert!(sa.tracked(), "did not track: {sa:?}");
    assert!(sa.max_err_r_deg < 0.5, "rotation error {} deg", sa.max_err_r_deg);
    // One labels line per frame; the parked cars are labelled (potentially dynamic).
    let dynamic: Vec<u64> = a
        .lines()
        .filter_map(|l| l.split_once("labels: dynamic_px ")?.1.split(' ').next()?.parse().ok())
        .collect();
    assert_eq!(dynamic.len(), FRAMES.len());
    assert!(dynamic.iter().all(|&d| d > 0 && d < (WIDTH * HEIGHT / 2) as u64), "{dynamic:?}");
    // The semantic weights change the features, so the poses are not the geometric run's.
    let (g, sg) = run_once();
    assert_ne!(sg.hash, sa.hash);
    assert!(!g.contains("labels:"));
    let (b, sb) = run_semantic();
    assert_eq!(a, b);
    assert_eq!(sa, sb);
}

#[test]
fn semantics_refuses_small_buffers() {
    let mut arena = vec![0i8; 1000];
    let (mut i, mut m) = (vec![0u8; WIDTH * HEIGHT], vec![0u8; WIDTH * HEIGHT]);
    let mem = crate::NetworkMemory { arena: &mut arena, input: &mut i, model_labels: &mut m };
    let r = crate::Network::new(embedded::MODEL_BLOB, WIDTH, HEIGHT, mem);
    assert!(
        matches!(
            r,
            Err(crate::LocaliserError::Model(semloc_core::nn::model::ModelError::Truncated { .. }))
        ),
        "{:?}",
        r.err()
    );
}

#[test]
fn wrong_buffer_size_is_an_error_not_a_panic() {
    on_big_stack(|| {
        let mut loc = Box::new(
            crate::embedded_localiser(crate::geometric_params(), None).expect("localiser"),
        );
        let short = vec![0u8; 100];
        let r = loc.process_raw(&short, &short, 0.0, None);
        assert!(matches!(r, Err(crate::LocaliserError::Image(_))), "{r:?}");
    });
}

#[test]
fn segmentation_memory_figures() {
    let m = semloc_core::nn::model::Model::parse(embedded::MODEL_BLOB).expect("model");
    let need = crate::NetworkMemory::bytes_needed(&m);
    println!("model {} bytes, arena/map {need:?}", embedded::MODEL_BLOB.len());
    assert_eq!(m.input_size(), (HEIGHT, WIDTH));
}

#[test]
fn network_labelling_names_a_short_buffer_and_a_mismatched_stage() {
    on_big_stack(|| {
        let mut loc = Box::new(
            crate::embedded_localiser(crate::semantic_params(), Some(crate::SEMANTIC_SCHEME))
                .expect("loc"),
        );
        let mut storage = Box::new(crate::SegStorage::new());
        let mut net = crate::Network::new(embedded::MODEL_BLOB, WIDTH, HEIGHT, storage.memory())
            .expect("network");
        let short = vec![0u8; WIDTH * HEIGHT - 1];
        let r = loc.label_with(&mut net, &short);
        assert!(
            matches!(
                r,
                Err(crate::LocaliserError::Image(
                    semloc_core::image::ImageError::BufferTooSmall { .. }
                ))
            ),
            "{r:?}"
        );
        assert!(loc.labels().is_none(), "a refused frame leaves no labels");
        // A stage for another frame size (half height, same network) is refused by size.
        let mut storage2 = Box::new(crate::SegStorage::new());
        let mut half =
            crate::Network::new(embedded::MODEL_BLOB, WIDTH, HEIGHT / 2, storage2.memory());
        if let Ok(half) = half.as_mut() {
            let frame = vec![0u8; WIDTH * HEIGHT];
            let r = loc.label_with(half, &frame);
            assert!(matches!(r, Err(crate::LocaliserError::FrameSize { .. })), "{r:?}");
        }
    });
}

/// The on-target kernel check (`qemu_aarch64` runs it with these arguments) passes on the
/// host's kernels too, and a different seed draws different cases.
#[test]
fn kernel_check_passes_on_this_build() {
    use crate::kernel_check::{run, KernelCheckBuffers, KernelCheckReport};
    let mut buf = Box::new(KernelCheckBuffers::new());
    for seed in [0x5e10_c0de, 7] {
        let r = run(&mut buf, seed, 500).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let want = KernelCheckReport {
            pointwise: 500,
            depthwise: 500,
            first_conv: 500,
            resize: 500,
            add: 500,
        };
        assert_eq!(r, want);
    }
}
