//! Writes `firmware-sim/data/` from a `semloc synth` sequence: 640×192 crops of the first
//! frames as grey PNGs, and `manifest.txt` with the crop's camera (principal point moved by
//! the crop), the timestamps and the ground-truth poses.
//!
//! ```text
//! cargo run --release -p semloc -- synth --out /tmp/fw-synth --frames 8 --dynamics static --seed 7
//! cargo run -p semloc-firmware-sim --example make_frames -- \
//!     /tmp/fw-synth/sequences/00 /tmp/fw-synth/poses/00.txt firmware-sim/data 8 300 92 \
//!     "semloc synth --frames 8 --dynamics static --seed 7"
//! ```
//! Arguments: sequence folder, poses file, output folder, frames, crop left column, crop top
//! row, a description of the source. The output is a pure function of the input files.

use core::fmt::Write as _;
use std::path::Path;

use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use image::{ExtendedColorType, GrayImage, ImageEncoder};

const W: u32 = 640;
const H: u32 = 192;

type Res<T> = Result<T, String>;

fn main() {
    if let Err(e) = run() {
        eprintln!("make_frames: {e}");
        std::process::exit(1);
    }
}

fn num<T: core::str::FromStr>(s: &str, what: &str) -> Res<T> {
    s.parse().map_err(|_| format!("{what}: cannot parse `{s}`"))
}

fn run() -> Res<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [seq, poses, out, n, cx0, cy0, source] = args.as_slice() else {
        return Err(
            "usage: make_frames SEQ_DIR POSES_TXT OUT_DIR FRAMES CROP_X CROP_Y SOURCE".into()
        );
    };
    let (seq, out) = (Path::new(seq), Path::new(out));
    let n: usize = num(n, "frames")?;
    let (x0, y0): (u32, u32) = (num(cx0, "crop x")?, num(cy0, "crop y")?);
    let read = |p: &Path| std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()));

    // P0 = K[I|0], P1 = K[I|(-b,0,0)]: fx = P0[0], fy = P0[5], cx = P0[2], cy = P0[6],
    // b = -P1[3] / P1[0].
    let calib = read(&seq.join("calib.txt"))?;
    let row = |name: &str| -> Res<Vec<f64>> {
        let line = calib
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .ok_or_else(|| format!("calib.txt: no {name}"))?;
        line.split_whitespace().map(|t| num(t, "calib")).collect()
    };
    let (p0, p1) = (row("P0:")?, row("P1:")?);
    if p0.len() != 12 || p1.len() != 12 {
        return Err("calib.txt: P0/P1 need 12 numbers".into());
    }
    let times: Vec<f64> = match read(&seq.join("times.txt")) {
        Ok(t) => t.split_whitespace().map(|s| num(s, "times")).collect::<Res<_>>()?,
        Err(_) => (0..n).map(|i| i as f64 * 0.1).collect(),
    };
    let gt: Vec<Vec<f64>> = read(Path::new(poses))?
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(|t| num(t, "pose")).collect::<Res<Vec<f64>>>())
        .collect::<Res<_>>()?;
    if gt.len() < n || times.len() < n || gt.iter().any(|r| r.len() != 12) {
        return Err(format!("need {n} poses and timestamps of 12 numbers"));
    }

    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut m = String::new();
    let _ = writeln!(m, "# Embedded sequence of semloc-firmware-sim (read by build.rs).");
    let _ = writeln!(m, "# Written by examples/make_frames.rs; do not edit by hand.");
    let _ = writeln!(m, "source {source}");
    let _ = writeln!(m, "width {W}\nheight {H}\ncrop_x {x0}\ncrop_y {y0}");
    let _ = writeln!(m, "fx_px {:?}\nfy_px {:?}", p0[0], p0[5]);
    // The crop's principal point as a KITTI calib.txt of the crop would give it (12 digits
    // after the point, as `semloc synth` writes them), so that `semloc run` on a KITTI layout
    // of these crops sees the very same camera (and gives the very same poses).
    let kitti = |x: f64| -> Res<f64> { num(&format!("{x:.12e}"), "principal point") };
    let (cx, cy) = (kitti(p0[2] - f64::from(x0))?, kitti(p0[6] - f64::from(y0))?);
    let _ = writeln!(m, "cx_px {cx:?}\ncy_px {cy:?}");
    let _ = writeln!(m, "baseline_m {:?}", -p1[3] / p1[0]);
    let _ = writeln!(m, "# frame INDEX TIME_S then the left camera-to-world [R | t], row-major");
    for i in 0..n {
        for (side, folder) in [("left", "image_0"), ("right", "image_1")] {
            let src = seq.join(folder).join(format!("{i:06}.png"));
            let img = image::open(&src).map_err(|e| format!("{}: {e}", src.display()))?;
            let img = img.into_luma8();
            if img.width() < x0 + W || img.height() < y0 + H {
                return Err(format!("{}: too small for the crop", src.display()));
            }
            let crop: GrayImage = image::imageops::crop_imm(&img, x0, y0, W, H).to_image();
            let dst = out.join(format!("{side}_{i:02}.png"));
            let mut buf = Vec::new();
            PngEncoder::new_with_quality(&mut buf, CompressionType::Best, FilterType::Adaptive)
                .write_image(crop.as_raw(), W, H, ExtendedColorType::L8)
                .map_err(|e| format!("{}: {e}", dst.display()))?;
            std::fs::write(&dst, buf).map_err(|e| format!("{}: {e}", dst.display()))?;
        }
        let pose: Vec<String> = gt[i].iter().map(|x| format!("{x:?}")).collect();
        let _ = writeln!(m, "frame {i} {:?} {}", times[i], pose.join(" "));
    }
    let path = out.join("manifest.txt");
    std::fs::write(&path, m).map_err(|e| format!("{}: {e}", path.display()))?;
    println!("wrote {n} frames to {}", out.display());
    Ok(())
}
