//! `semloc verify-seg`: the int8 engine against its float reference on real images.
//!
//! Per image: the core int8 network (fast kernels), on the first `--reference-check` images
//! also the reference kernels (the logits must be bit-identical, else the command fails), and
//! the float ONNX in tract on the same input map. Reports the pixel label agreement int8 vs
//! f32 and, on CamVid (labels in `<split>annot/`), mIoU and category mIoU of both and the
//! difference — the figures `models/quantise.py` estimates with its int8 simulation. With
//! `--kitti DIR --labels DIR` the same figures on labelled KITTI frames (Cityscapes label ids,
//! as the KITTI semantic benchmark and KITTI-360 give them, or CamVid ids). Every labelled
//! run also reports the dynamic mask's pixel precision and recall (car, pedestrian,
//! bicyclist), what culling removes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use image::GrayImage;
use semloc::dataset::luma::load_luma_file;
use semloc::nn::metrics::{map_cityscapes, Confusion, CATEGORIES};
use semloc::nn::segment::{to_frame, Segmenter};
use semloc::nn::tract_ref::TractRef;
use semloc::nn::{NnFileError, SlmBlob};
use semloc::run::{percentiles, Percentiles};
use semloc_core::nn::graph::Kernels;
use semloc_core::seg::{CLASS_NAMES, VOID};

use super::segment::list_images;

/// Arguments of `semloc verify-seg`.
#[derive(Args, Debug)]
pub struct VerifySegArgs {
    /// The int8 model (`semloc convert`).
    #[arg(long, value_name = "X.slm")]
    pub model: PathBuf,
    /// The float ONNX it was converted from.
    #[arg(long, value_name = "X.onnx")]
    pub onnx: PathBuf,
    /// CamVid root (holding `<split>/` and `<split>annot/`): adds mIoU against the labels.
    #[arg(long, value_name = "DIR", required_unless_present = "kitti", conflicts_with = "kitti")]
    pub camvid: Option<PathBuf>,
    /// CamVid split.
    #[arg(long, default_value = "val", value_name = "SPLIT")]
    pub split: String,
    /// Only the images of this CamVid sequence (the file-name prefix before `_`, e.g.
    /// `0006R0`): the sequence a model was trained without (`train.py --holdout-seq`), scored
    /// on its own. It may sit in any split; name that one with --split.
    #[arg(long, value_name = "SEQ", requires = "camvid")]
    pub sequence: Option<String>,
    /// A KITTI sequence folder (or a folder of images): agreement, and with --labels the
    /// scores against them.
    #[arg(long, value_name = "SEQUENCE_DIR")]
    pub kitti: Option<PathBuf>,
    /// Label maps for the --kitti images: `<DIR>/<image stem>.png`, 8-bit label ids (e.g. the
    /// KITTI semantic benchmark's `training/semantic/` beside `training/image_2/`). Images
    /// without one are not scored (the count is reported); none labelled is an error.
    #[arg(long, value_name = "DIR", requires = "kitti")]
    pub labels: Option<PathBuf>,
    /// The ids the --labels maps hold: Cityscapes (KITTI semantics, KITTI-360), read as the
    /// CamVid classes (`semloc::nn::metrics::map_cityscapes`), or CamVid's own.
    #[arg(long, value_enum, default_value = "cityscapes", requires = "labels")]
    pub label_ids: LabelIds,
    /// Only the first N images.
    #[arg(long, value_name = "N")]
    pub limit: Option<usize>,
    /// Check fast against reference kernels (bit-identical logits) on the first N images.
    #[arg(long, default_value_t = 3, value_name = "N")]
    pub reference_check: usize,
    /// Also write the figures as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

/// The label ids of a `--labels` folder.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum LabelIds {
    /// Cityscapes ids (0-33): KITTI semantic segmentation, KITTI-360.
    Cityscapes,
    /// CamVid's 11 classes (0-10), anything above void.
    Camvid,
}

impl LabelIds {
    fn name(self) -> &'static str {
        match self {
            Self::Cityscapes => "Cityscapes",
            Self::Camvid => "CamVid",
        }
    }

    fn to_camvid(self, id: u8) -> u8 {
        match self {
            Self::Cityscapes => map_cityscapes(id),
            Self::Camvid => id.min(VOID),
        }
    }
}

/// mIoU figures of one engine.
#[derive(Debug, serde::Serialize)]
struct Scores {
    miou: f64,
    category_miou: f64,
    pixel_accuracy: f64,
    /// Pixel precision of the dynamic mask (car, pedestrian, bicyclist); NaN (null) when
    /// nothing was predicted dynamic.
    dynamic_precision: f64,
    /// Pixel recall of the dynamic mask; NaN (null) without dynamic truth.
    dynamic_recall: f64,
    iou: std::collections::BTreeMap<&'static str, f64>,
    category_iou: std::collections::BTreeMap<&'static str, f64>,
}

impl Scores {
    fn of(c: &Confusion) -> Self {
        let names = |v: Vec<f64>, n: &[&'static str]| n.iter().copied().zip(v).collect();
        let cat_names: Vec<&'static str> = CATEGORIES.iter().map(|c| c.0).collect();
        Scores {
            miou: c.miou(),
            category_miou: c.category_miou(),
            pixel_accuracy: c.pixel_accuracy(),
            dynamic_precision: c.dynamic_precision(),
            dynamic_recall: c.dynamic_recall(),
            iou: names(c.iou(), &CLASS_NAMES),
            category_iou: names(c.category_iou(), &cat_names),
        }
    }
}

#[derive(Debug, serde::Serialize)]
struct Report {
    model: PathBuf,
    onnx: PathBuf,
    images: usize,
    /// With --labels: the ids they hold, and the images left unscored for want of a label map.
    label_ids: Option<LabelIds>,
    unlabelled_images: usize,
    input_hw: (usize, usize),
    letterbox_factor: f64,
    reference_checked: usize,
    agreement_pct: f64,
    min_image_agreement_pct: f64,
    int8_ms: Percentiles,
    tract_f32_ms: Percentiles,
    int8: Option<Scores>,
    f32: Option<Scores>,
    miou_drop: Option<f64>,
    category_miou_drop: Option<f64>,
}

/// The CamVid sequence of an image: its file name up to the first `_` (`0006R0_f02100.png`
/// → `0006R0`); `None` without one.
fn camvid_sequence(p: &Path) -> Option<&str> {
    p.file_name()?.to_str()?.split_once('_').map(|(seq, _)| seq)
}

/// Runs `semloc verify-seg`.
pub fn run(args: &VerifySegArgs) -> Result<()> {
    let mut unlabelled = 0;
    let (mut images, annot, ids) = match (&args.camvid, &args.kitti) {
        (Some(root), _) => {
            let dir = root.join(&args.split);
            let mut images = list_images(&dir)?;
            if let Some(seq) = &args.sequence {
                images.retain(|p| camvid_sequence(p) == Some(seq.as_str()));
                if images.is_empty() {
                    bail!("{}: no image of CamVid sequence {seq} (`{seq}_*`)", dir.display());
                }
            }
            (images, Some(root.join(format!("{}annot", args.split))), LabelIds::Camvid)
        }
        (None, Some(k)) => {
            let mut images = list_images(k)?;
            if let Some(dir) = &args.labels {
                if !dir.is_dir() {
                    bail!("{}: missing folder (--labels)", dir.display());
                }
                let n = images.len();
                images.retain(|p| label_path(dir, p).is_file());
                unlabelled = n - images.len();
                if images.is_empty() {
                    bail!(
                        "{}: no label map for any of the {n} images (`<image stem>.png` expected)",
                        dir.display()
                    );
                }
            }
            (images, args.labels.clone(), args.label_ids)
        }
        (None, None) => bail!("give --camvid DIR or --kitti SEQUENCE_DIR"),
    };
    if let Some(n) = args.limit {
        images.truncate(n);
    }
    if images.is_empty() {
        bail!("no images to verify");
    }
    let mut seg = Segmenter::new(SlmBlob::load(&args.model)?)?;
    let tract = TractRef::load(&args.onnx)?;
    let (mut c8, mut c32) = (Confusion::default(), Confusion::default());
    let (mut same, mut total, mut min_agree) = (0u64, 0u64, f64::INFINITY);
    let (mut ms8, mut ms32) = (Vec::new(), Vec::new());
    let mut factor = 0.0;
    let pb = super::progress(images.len() as u64, "verify");
    for (i, path) in images.iter().enumerate() {
        let frame = load_luma_file(path)?;
        let (w, h) = frame.dimensions();
        let t = Instant::now();
        let labels = seg.segment(&frame, Kernels::Fast)?;
        ms8.push(t.elapsed().as_secs_f64() * 1e3);
        if i < args.reference_check {
            let diff = seg.compare_kernels()?;
            if diff > 0 {
                bail!(
                    "{}: fast and reference kernels differ in {diff} output logits (must be \
                     bit-identical)",
                    path.display()
                );
            }
        }
        let lb = seg.letterbox(w as usize, h as usize)?;
        factor = lb.scale();
        let t = Instant::now();
        let f32_model = seg.reference(&tract)?;
        ms32.push(t.elapsed().as_secs_f64() * 1e3);
        let f32_frame =
            to_frame(&f32_model, &lb).map_err(|e| NnFileError::model(&args.model, e))?;
        let s = labels.frame.iter().zip(&f32_frame).filter(|(a, b)| a == b).count() as u64;
        min_agree = min_agree.min(100.0 * s as f64 / f32_frame.len() as f64);
        same += s;
        total += f32_frame.len() as u64;
        if let Some(dir) = &annot {
            let truth = load_truth(dir, path, w, h, ids)?;
            c8.add(truth.as_raw(), &labels.frame);
            c32.add(truth.as_raw(), &f32_frame);
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    let scored = annot.is_some();
    let (s8, s32) = (scored.then(|| Scores::of(&c8)), scored.then(|| Scores::of(&c32)));
    let report = Report {
        model: args.model.clone(),
        onnx: args.onnx.clone(),
        images: images.len(),
        label_ids: args.labels.is_some().then_some(ids),
        unlabelled_images: unlabelled,
        input_hw: seg.input_size(),
        letterbox_factor: factor,
        reference_checked: args.reference_check.min(images.len()),
        agreement_pct: 100.0 * same as f64 / total.max(1) as f64,
        min_image_agreement_pct: min_agree,
        int8_ms: percentiles(&ms8),
        tract_f32_ms: percentiles(&ms32),
        miou_drop: s8.as_ref().zip(s32.as_ref()).map(|(a, b)| b.miou - a.miou),
        category_miou_drop: s8
            .as_ref()
            .zip(s32.as_ref())
            .map(|(a, b)| b.category_miou - a.category_miou),
        int8: s8,
        f32: s32,
    };
    print_report(&report);
    if let Some(path) = &args.json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("{}: cannot write", path.display()))?;
    }
    Ok(())
}

/// Where the label map of `image` is: `<dir>/<image stem>.png`.
fn label_path(dir: &Path, image: &Path) -> PathBuf {
    let stem = image.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
    dir.join(format!("{stem}.png"))
}

/// The label map of `image` (`<annot>/<stem>.png`, 8-bit ids) as CamVid classes: CamVid ids
/// above 11 read as void, as `camvid.py`; Cityscapes ids mapped by [`map_cityscapes`].
fn load_truth(annot: &Path, image: &Path, w: u32, h: u32, ids: LabelIds) -> Result<GrayImage> {
    let p = label_path(annot, image);
    let img = image::open(&p).map_err(|e| match e {
        image::ImageError::IoError(io) => anyhow::Error::new(NnFileError::io(&p, &io)),
        e => anyhow::anyhow!("{}: cannot decode labels: {e}", p.display()),
    })?;
    let image::DynamicImage::ImageLuma8(mut g) = img else {
        bail!("{}: labels must be 8-bit grey class ids", p.display());
    };
    if g.dimensions() != (w, h) {
        bail!("{}: labels are {:?}, the image {w}x{h}", p.display(), g.dimensions());
    }
    for v in g.iter_mut() {
        *v = ids.to_camvid(*v);
    }
    Ok(g)
}

fn print_report(r: &Report) {
    if let Some(ids) = r.label_ids {
        println!(
            "labels: {} ids; {} images scored, {} without a label map left out",
            ids.name(),
            r.images,
            r.unlabelled_images
        );
    }
    println!(
        "{} images, model input {}x{} (letterbox factor {}), fast = reference kernels on the \
         first {} (bit-identical)",
        r.images, r.input_hw.0, r.input_hw.1, r.letterbox_factor, r.reference_checked
    );
    println!(
        "label agreement int8 vs f32: {:.3} % of pixels (worst image {:.3} %)",
        r.agreement_pct, r.min_image_agreement_pct
    );
    println!(
        "time per frame (1 thread): int8 median {:.1} ms, tract f32 median {:.1} ms",
        r.int8_ms.median_ms, r.tract_f32_ms.median_ms
    );
    if let (Some(a), Some(b)) = (&r.int8, &r.f32) {
        println!("{:<14}{:>10}{:>10}", "IoU [%]", "int8", "f32");
        for k in CLASS_NAMES {
            println!("{k:<14}{:>10.2}{:>10.2}", 100.0 * a.iou[k], 100.0 * b.iou[k]);
        }
        println!(
            "mIoU: int8 {:.2} %, f32 {:.2} % (drop {:.2}); category mIoU: int8 {:.2} %, f32 {:.2} % \
             (drop {:.2})",
            100.0 * a.miou,
            100.0 * b.miou,
            100.0 * (b.miou - a.miou),
            100.0 * a.category_miou,
            100.0 * b.category_miou,
            100.0 * (b.category_miou - a.category_miou)
        );
        println!(
            "dynamic mask (car, pedestrian, bicyclist) pixel precision / recall: int8 {:.2} / \
             {:.2} %, f32 {:.2} / {:.2} %",
            100.0 * a.dynamic_precision,
            100.0 * a.dynamic_recall,
            100.0 * b.dynamic_precision,
            100.0 * b.dynamic_recall
        );
    }
}
