//! `semloc segment`: label images with the int8 network (and optionally the float reference),
//! writing a grey class-id map and a colour overlay per image.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use semloc::dataset::luma::load_luma_file;
use semloc::dataset::Sequence;
use semloc::nn::segment::{label_image, overlay_with_legend, to_frame, Segmenter};
use semloc::nn::tract_ref::TractRef;
use semloc::nn::SlmBlob;
use semloc::run::percentiles;
use semloc_core::nn::graph::Kernels;

/// Arguments of `semloc segment`.
#[derive(Args, Debug)]
pub struct SegmentArgs {
    /// An image (PNG/JPEG), a folder of images, or a sequence folder (KITTI odometry sequence
    /// or raw drive, stereo folder, EuRoC MAV): its left camera, loaded as `run` loads it
    /// (EuRoC rectified).
    #[arg(value_name = "IMAGE|DIR|KITTI-SEQUENCE")]
    pub input: PathBuf,
    /// The int8 model (`semloc convert`).
    #[arg(long, value_name = "X.slm")]
    pub model: PathBuf,
    /// Output folder (created): `<name>_labels.png` (class ids) and `<name>_overlay.png` (with a class legend).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Also run the float ONNX in tract: writes `<name>_labels_f32.png` and reports the label
    /// agreement.
    #[arg(long, value_name = "X.onnx")]
    pub onnx: Option<PathBuf>,
    /// Only the first N images.
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,
}

/// The images a path names: itself, the PNG/JPEG files of a folder (sorted), or the left
/// images of a KITTI sequence.
pub fn list_images(input: &Path) -> Result<Vec<PathBuf>> {
    if input.is_file() {
        return Ok(vec![input.to_path_buf()]);
    }
    if !input.is_dir() {
        bail!("{}: missing file or folder", input.display());
    }
    let mut images: Vec<PathBuf> = std::fs::read_dir(input)
        .with_context(|| format!("{}: cannot list", input.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && is_image(p))
        .collect();
    images.sort();
    if !images.is_empty() {
        return Ok(images);
    }
    match semloc::dataset::Sequence::open(input, None) {
        Ok(seq) => Ok(seq.left),
        Err(e) => bail!("{}: no PNG/JPEG images, and not a KITTI sequence ({e})", input.display()),
    }
}

fn is_image(p: &Path) -> bool {
    let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    matches!(ext.as_str(), "png" | "jpg" | "jpeg")
}

/// What `semloc segment` labels: image files, or the left camera of a dataset sequence
/// (loaded as tracking loads it: EuRoC images rectified).
enum Images {
    Files(Vec<PathBuf>),
    Sequence(Box<Sequence>),
}

impl Images {
    fn open(input: &Path) -> Result<Self> {
        if input.is_dir() {
            if let Ok(seq) = Sequence::open(input, None) {
                return Ok(Self::Sequence(Box::new(seq)));
            }
        }
        list_images(input).map(Self::Files)
    }

    fn paths(&self) -> &[PathBuf] {
        match self {
            Self::Files(p) => p,
            Self::Sequence(seq) => &seq.left,
        }
    }

    fn load(&self, i: usize) -> Result<image::GrayImage> {
        Ok(match self {
            Self::Files(p) => load_luma_file(&p[i])?,
            Self::Sequence(seq) => seq.load_luma_side(i, false)?,
        })
    }
}

/// Runs `semloc segment`.
pub fn run(args: &SegmentArgs) -> Result<()> {
    let images = Images::open(&args.input)?;
    if let Images::Sequence(seq) = &images {
        if seq.remap.is_some() {
            eprintln!(
                "note: {}: the left images are labelled rectified, as `run` tracks them",
                seq.root.display()
            );
        }
    }
    let n = args.limit.map_or(images.paths().len(), |n| n.min(images.paths().len()));
    let mut seg = Segmenter::new(SlmBlob::load(&args.model)?)?;
    let tract = args.onnx.as_deref().map(TractRef::load).transpose()?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create", args.out.display()))?;
    let pb = super::progress(n as u64, "segment");
    let (mut ms, mut same, mut total) = (Vec::new(), 0u64, 0u64);
    for (i, path) in images.paths()[..n].iter().enumerate() {
        let frame = images.load(i)?;
        let (w, h) = frame.dimensions();
        let t = Instant::now();
        let labels = seg.segment(&frame, Kernels::Fast)?;
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        let name = path.file_stem().and_then(|s| s.to_str()).unwrap_or("image");
        let save = |img: &dyn Fn(&Path) -> image::ImageResult<()>, suffix: &str| -> Result<()> {
            let p = args.out.join(format!("{name}_{suffix}.png"));
            img(&p).with_context(|| format!("{}: cannot write", p.display()))
        };
        save(&|p| label_image(&labels.frame, w, h).save(p), "labels")?;
        save(&|p| overlay_with_legend(&frame, &labels.frame).save(p), "overlay")?;
        if let Some(tract) = &tract {
            let lb = seg.letterbox(w as usize, h as usize)?;
            let f32_model = seg.reference(tract)?;
            let f32_frame = to_frame(&f32_model, &lb)
                .map_err(|e| semloc::nn::NnFileError::model(&args.model, e))?;
            same += labels.frame.iter().zip(&f32_frame).filter(|(a, b)| a == b).count() as u64;
            total += f32_frame.len() as u64;
            save(&|p| label_image(&f32_frame, w, h).save(p), "labels_f32")?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    let p = percentiles(&ms);
    println!(
        "{n} images -> {}: int8 (fast kernels, 1 thread) median {:.1} ms, p99 {:.1} ms per frame",
        args.out.display(),
        p.median_ms,
        p.p99_ms
    );
    if total > 0 {
        println!("int8 vs f32 (tract) label agreement {:.3} %", 100.0 * same as f64 / total as f64);
    }
    Ok(())
}
