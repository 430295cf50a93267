//! The pipeline's thread schedules: one thread, two stagewise and two overlapped (the next frame
//! labelled and extracted while this one is tracked) give the same bits, frame by frame; work
//! done ahead for a frame that cannot be read is dropped, and that frame's error is its own.

use std::borrow::Cow;
use std::path::Path;

use image::GrayImage;
use semloc::dataset::Sequence;
use semloc::pipeline::{FrameOutput, FrameSource, Pipeline, PipelineError, Schedule};
use semloc::synth::{generate, Dynamics, SynthConfig};
use semloc_core::assoc::Association;
use semloc_core::seg::WeightScheme;
use semloc_core::tracker::TrackerParams;

const FRAMES: usize = 10;

fn drive(dir: &Path) -> Sequence {
    let cfg =
        SynthConfig { frames: FRAMES, dynamics: Dynamics::High, seed: 5, ..SynthConfig::default() };
    generate(dir, &cfg).unwrap();
    Sequence::open_odometry(dir, &cfg.seq, None).unwrap()
}

/// A sequence whose right image of one frame cannot be read.
struct BrokenRight<'a> {
    seq: &'a Sequence,
    frame: usize,
}

impl FrameSource for BrokenRight<'_> {
    fn len(&self) -> usize {
        self.seq.len()
    }
    fn left(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        self.seq.left(i)
    }
    fn right(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        if i == self.frame {
            return Err(PipelineError::Worker(format!("right image of frame {i} unreadable")));
        }
        self.seq.right(i)
    }
    fn labels(&self, i: usize) -> Result<Cow<'_, GrayImage>, PipelineError> {
        self.seq.labels(i)
    }
    fn timestamp_s(&self, i: usize) -> f64 {
        self.seq.timestamp_s(i)
    }
}

/// What must not depend on the schedule.
fn key(o: &FrameOutput) -> impl PartialEq + core::fmt::Debug {
    (o.report.t_wc, o.report.inliers, o.report.matched, o.stereo, o.culled)
}

fn pipeline(seq: &Sequence, threads: usize, schedule: Schedule) -> Pipeline {
    let (w, h) = seq.image_size;
    let params = TrackerParams { association: Association::Em, ..TrackerParams::default() };
    let mut p = Pipeline::new(&seq.calib, w, h, params, threads).unwrap();
    p.set_schedule(schedule);
    p.set_semantics(Some(WeightScheme::Full));
    p
}

#[test]
fn schedules_give_the_same_bits_and_a_broken_frame_fails_as_itself() {
    let dir = tempfile::tempdir().unwrap();
    let seq = drive(dir.path());
    let runs: Vec<Vec<_>> =
        [(1, Schedule::Overlapped), (2, Schedule::Stagewise), (2, Schedule::Overlapped)]
            .into_iter()
            .map(|(threads, schedule)| {
                let mut p = pipeline(&seq, threads, schedule);
                (0..FRAMES)
                    .map(|i| {
                        let o = p.process_frame(&seq, i).unwrap();
                        // The frame's own images, although the extractors may hold the next one's.
                        assert_eq!(p.left_image(), Some(&seq.load_luma(i).unwrap().0), "frame {i}");
                        assert_eq!(p.labels(), Some(&seq.load_labels(i).unwrap()), "frame {i}");
                        key(&o)
                    })
                    .collect()
            })
            .collect();
    assert!(runs[0].iter().skip(1).any(|k| format!("{k:?}") != format!("{:?}", runs[0][0])));
    assert_eq!(runs[1], runs[0], "two threads stagewise against one thread");
    assert_eq!(runs[2], runs[0], "two threads overlapped against one thread");

    // Frame 6's right image is unreadable: frame 5 (which works on frame 6 ahead) succeeds with
    // the same result, frame 6 fails naming itself, and nothing is left over for frame 7.
    let broken = BrokenRight { seq: &seq, frame: 6 };
    let mut p = pipeline(&seq, 2, Schedule::Overlapped);
    for (i, want) in runs[0].iter().enumerate().take(6) {
        assert_eq!(&key(&p.process_frame(&broken, i).unwrap()), want, "frame {i}");
    }
    let err = p.process_frame(&broken, 6).unwrap_err();
    assert!(err.to_string().contains("frame 6"), "{err}");
}
