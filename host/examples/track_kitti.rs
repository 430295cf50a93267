//! A user's own program on semloc: open a KITTI sequence, run core's localiser on every frame
//! and print the poses (KITTI format: the 3x4 camera-to-world matrix, row-major, per line).
//!
//! ```sh
//! cargo run --release -p semloc --example track_kitti -- ../shared/data/kitti-odometry/sequences/06
//! cargo run --release -p semloc --example track_kitti -- ../shared/data/kitti-raw/2011_09_26/2011_09_26_drive_0005_sync 20
//! ```
//! The second argument caps the frame count. Everything the `semloc run` CLI adds (two
//! threads, the network, outputs, evaluation) is optional around these few calls.

use std::path::PathBuf;
use std::process::ExitCode;

use semloc::dataset::Sequence;
use semloc_core::image::ImageView;
use semloc_core::localiser::{Localiser, LocaliserConfig};

fn run(path: PathBuf, max_frames: usize) -> Result<(), Box<dyn core::error::Error>> {
    // A KITTI odometry sequence folder (…/sequences/NN) or a raw drive folder (…_sync).
    let seq = Sequence::open(&path, None)?;
    let (w, h) = seq.image_size;
    let config = LocaliserConfig::new(seq.calib.to_camera()?, w, h);
    // Core's state is ≈ 11 MiB of fixed arrays: build it on a thread with a big stack and keep
    // it in a box (on an ECU it would be a `static`).
    let mut loc = std::thread::Builder::new()
        .stack_size(1 << 30)
        .spawn(move || Localiser::new(&config).map(Box::new))?
        .join()
        .map_err(|_| "constructor thread panicked")??;
    for i in 0..seq.len().min(max_frames) {
        let (left, right) = seq.load_luma(i)?;
        let l = ImageView::from_slice(left.as_raw(), w as usize, h as usize)?;
        let r = ImageView::from_slice(right.as_raw(), w as usize, h as usize)?;
        let out = loc.process(&l, &r, seq.times_s.get(i).copied().unwrap_or(i as f64 * 0.1))?;
        let t = out.report.t_wc;
        let m = t.rot;
        println!(
            "{:.6e} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e}",
            m[(0, 0)],
            m[(0, 1)],
            m[(0, 2)],
            t.trans.x,
            m[(1, 0)],
            m[(1, 1)],
            m[(1, 2)],
            t.trans.y,
            m[(2, 0)],
            m[(2, 1)],
            m[(2, 2)],
            t.trans.z,
        );
    }
    let s = loc.tracker().stats();
    eprintln!("{} frames, {} keyframes, {} losses", seq.len().min(max_frames), s.keyframes, s.lost);
    Ok(())
}

fn main() -> ExitCode {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next() else {
        eprintln!("usage: track_kitti SEQUENCE_FOLDER [MAX_FRAMES]");
        return ExitCode::from(2);
    };
    let max_frames = match args.next().map(|s| s.parse::<usize>()) {
        None => usize::MAX,
        Some(Ok(n)) => n,
        Some(Err(e)) => {
            eprintln!("MAX_FRAMES: {e}");
            return ExitCode::from(2);
        }
    };
    match run(PathBuf::from(path), max_frames) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
