//! The segmentation subcommands end to end on a tiny synthetic network (no outside data):
//! `convert`, `segment`, `verify-seg`, and their errors naming the file.

use std::path::Path;

use crate::common::{s, semloc, text};
use semloc::nn::fixtures::write_tiny;

/// A smooth grey test image with some structure.
fn write_image(path: &Path, w: u32, h: u32) {
    let img = image::GrayImage::from_fn(w, h, |x, y| {
        let v = 128.0 + 90.0 * ((x as f32 * 0.31).sin() * (y as f32 * 0.23).cos());
        image::Luma([v as u8])
    });
    img.save(path).unwrap();
}

/// Converts the tiny net (input 24x32) into `dir/tiny.slm`.
fn tiny_model(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let onnx = write_tiny(dir, "tiny", 24, 32).unwrap();
    let slm = dir.join("tiny.slm");
    let o = semloc(&["convert", "--onnx", s(&onnx), "--out", s(&slm)]);
    assert!(o.status.success(), "{}", text(&o));
    let out = text(&o);
    for want in ["tensors 10, ops 9", "MACs", "arena peak", "CRC-32 0x"] {
        assert!(out.contains(want), "missing {want:?} in:\n{out}");
    }
    (onnx, slm)
}

#[test]
fn convert_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.onnx");
    let o = semloc(&["convert", "--onnx", s(&missing), "--out", s(&dir.path().join("x.slm"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains(&format!("{}: missing file", missing.display())), "{}", text(&o));

    // an ONNX without its quant.json
    let onnx = write_tiny(dir.path(), "a", 8, 8).unwrap();
    std::fs::remove_file(dir.path().join("a.quant.json")).unwrap();
    let o = semloc(&["convert", "--onnx", s(&onnx), "--out", s(&dir.path().join("x.slm"))]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("a.quant.json: missing file"), "{}", text(&o));
}

#[test]
fn segment_writes_labels_and_overlays_and_rejects_corrupt_models() {
    let dir = tempfile::tempdir().unwrap();
    let (onnx, slm) = tiny_model(dir.path());
    let img = dir.path().join("frame.png");
    write_image(&img, 64, 40); // factor 2 onto 24x32
    let out = dir.path().join("out");
    let o = semloc(&["segment", s(&img), "--model", s(&slm), "--out", s(&out), "--onnx", s(&onnx)]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("label agreement"), "{}", text(&o));
    let labels = image::open(out.join("frame_labels.png")).unwrap().into_luma8();
    assert_eq!(labels.dimensions(), (64, 40));
    assert!(labels.iter().all(|&v| v < 3), "3-class net");
    assert!(out.join("frame_overlay.png").is_file() && out.join("frame_labels_f32.png").is_file());

    // unreadable image
    let bad = dir.path().join("bad.png");
    std::fs::write(&bad, b"not a png").unwrap();
    let o = semloc(&["segment", s(&bad), "--model", s(&slm), "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains(&format!("{}: cannot decode image", bad.display())), "{}", text(&o));

    // one flipped bit in the blob
    let mut bytes = std::fs::read(&slm).unwrap();
    let k = bytes.len() / 2;
    bytes[k] ^= 0x10;
    let corrupt = dir.path().join("corrupt.slm");
    std::fs::write(&corrupt, bytes).unwrap();
    let o = semloc(&["segment", s(&img), "--model", s(&corrupt), "--out", s(&out)]);
    assert_eq!(o.status.code(), Some(1));
    let t = text(&o);
    assert!(t.contains(&format!("{}: model blob corrupt: CRC-32", corrupt.display())), "{t}");
}

#[test]
fn verify_seg_scores_a_camvid_layout_and_checks_kernels() {
    let dir = tempfile::tempdir().unwrap();
    let (onnx, slm) = tiny_model(dir.path());
    let root = dir.path().join("camvid");
    std::fs::create_dir_all(root.join("val")).unwrap();
    std::fs::create_dir_all(root.join("valannot")).unwrap();
    for (i, name) in ["a", "b"].iter().enumerate() {
        write_image(&root.join("val").join(format!("{name}.png")), 30 + i as u32, 20);
        let lab =
            image::GrayImage::from_fn(30 + i as u32, 20, |x, _| image::Luma([(x % 4) as u8 * 4]));
        lab.save(root.join("valannot").join(format!("{name}.png"))).unwrap();
    }
    let json = dir.path().join("v.json");
    let o = semloc(&[
        "verify-seg",
        "--model",
        s(&slm),
        "--onnx",
        s(&onnx),
        "--camvid",
        s(&root),
        "--json",
        s(&json),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("mIoU: int8") && t.contains("bit-identical"), "{t}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["images"], 2);
    assert_eq!(v["reference_checked"], 2);
    assert_eq!(v["letterbox_factor"], 1.0);
    let agree = v["agreement_pct"].as_f64().unwrap();
    assert!((0.0..=100.0).contains(&agree));
    assert!(v["int8"]["miou"].is_number() && v["f32"]["miou"].is_number());

    // --sequence scores one CamVid sequence (the file-name prefix) of the split alone
    for name in ["0006R0_f1", "0006R0_f2", "0016E5_f1"] {
        write_image(&root.join("val").join(format!("{name}.png")), 30, 20);
        let lab = image::GrayImage::from_fn(30, 20, |x, _| image::Luma([(x % 4) as u8 * 4]));
        lab.save(root.join("valannot").join(format!("{name}.png"))).unwrap();
    }
    let seq = |q: &str| {
        let mut a = vec!["verify-seg", "--model", s(&slm), "--onnx", s(&onnx), "--camvid"];
        a.extend([s(&root), "--sequence", q, "--json", s(&json)]);
        semloc(&a)
    };
    let o = seq("0006R0");
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["images"], 2, "the two 0006R0 images, not a, b or 0016E5");
    let o = seq("Seq05VD");
    assert_eq!(o.status.code(), Some(1));
    let t = text(&o);
    assert!(t.contains("no image of CamVid sequence Seq05VD") && t.contains("val"), "{t}");

    // a missing label file is named
    std::fs::remove_file(root.join("valannot").join("b.png")).unwrap();
    let o = semloc(&["verify-seg", "--model", s(&slm), "--onnx", s(&onnx), "--camvid", s(&root)]);
    assert_eq!(o.status.code(), Some(1));
    assert!(text(&o).contains("valannot/b.png: missing file"), "{}", text(&o));
}

#[test]
fn verify_seg_scores_labelled_kitti_frames_in_cityscapes_or_camvid_ids() {
    let dir = tempfile::tempdir().unwrap();
    let (onnx, slm) = tiny_model(dir.path());
    let (images, cs, cv) =
        (dir.path().join("image_2"), dir.path().join("cs"), dir.path().join("cv"));
    for d in [&images, &cs, &cv] {
        std::fs::create_dir_all(d).unwrap();
    }
    // Three images, two labelled: the same map in Cityscapes ids (sky 23, building 11, pole
    // 17, and 0 unlabelled) and in CamVid ids (0, 1, 2, void 11).
    for (i, name) in ["000000_10", "000001_10", "000002_10"].iter().enumerate() {
        write_image(&images.join(format!("{name}.png")), 30, 20);
        if i == 2 {
            continue;
        }
        let pick = |x: u32, ids: [u8; 4]| image::Luma([ids[(x % 4) as usize]]);
        image::GrayImage::from_fn(30, 20, |x, _| pick(x, [23, 11, 17, 0]))
            .save(cs.join(format!("{name}.png")))
            .unwrap();
        image::GrayImage::from_fn(30, 20, |x, _| pick(x, [0, 1, 2, 11]))
            .save(cv.join(format!("{name}.png")))
            .unwrap();
    }
    let score = |labels: &Path, extra: &[&str]| {
        let json = dir.path().join("v.json");
        let mut a = vec!["verify-seg", "--model", s(&slm), "--onnx", s(&onnx), "--kitti"];
        a.extend([s(&images), "--labels", s(labels), "--json", s(&json)]);
        a.extend(extra);
        let o = semloc(&a);
        assert!(o.status.success(), "{}", text(&o));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        (text(&o), v)
    };
    let (t, a) = score(&cs, &[]);
    assert!(t.contains("labels: Cityscapes ids; 2 images scored, 1 without a label map"), "{t}");
    assert!(
        t.contains("dynamic mask (car, pedestrian, bicyclist) pixel precision / recall"),
        "{t}"
    );
    assert_eq!(a["images"], 2);
    assert_eq!(a["unlabelled_images"], 1);
    assert_eq!(a["label_ids"], "cityscapes");
    // the 3-class net predicts nothing dynamic and the truth holds nothing dynamic: no figure
    assert!(a["int8"]["dynamic_precision"].is_null() && a["int8"]["dynamic_recall"].is_null());
    let (_, b) = score(&cv, &["--label-ids", "camvid"]);
    assert_eq!(b["label_ids"], "camvid");
    for k in ["miou", "category_miou", "pixel_accuracy", "iou"] {
        assert_eq!(a["int8"][k], b["int8"][k], "{k}: Cityscapes and CamVid ids of one map");
        assert_eq!(a["f32"][k], b["f32"][k], "{k}");
    }
    assert!(a["int8"]["miou"].as_f64().unwrap() > 0.0);

    // A run that must fail with exit 1 and name what is wrong.
    let refused = |labels: &Path, want: &str| {
        let mut a = vec!["verify-seg", "--model", s(&slm), "--onnx", s(&onnx), "--kitti"];
        a.extend([s(&images), "--labels", s(labels)]);
        let o = semloc(&a);
        assert_eq!(o.status.code(), Some(1), "{}", text(&o));
        assert!(text(&o).contains(want), "missing {want:?} in:\n{}", text(&o));
    };
    // no label map for any image, or no folder at all: the folder is named
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    refused(&empty, &format!("{}: no label map for any of the 3 images", empty.display()));
    let gone = dir.path().join("gone");
    refused(&gone, &format!("{}: missing folder", gone.display()));
    // a colour label map (KITTI's semantic_rgb/) is refused by name
    let rgb = image::RgbImage::from_pixel(30, 20, image::Rgb([128, 64, 128]));
    rgb.save(cs.join("000000_10.png")).unwrap();
    refused(&cs, "000000_10.png: labels must be 8-bit grey class ids");

    // --labels needs --kitti
    let o = semloc(&["verify-seg", "--model", s(&slm), "--onnx", s(&onnx), "--labels", s(&cs)]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
}
