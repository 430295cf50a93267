//! The image front end on untrusted frames: any size (including empty, one pixel and larger
//! than the extractor's capacity) and any content must give features or a typed error, never a
//! panic — ORB extraction plain and with semantic weights built from a label image, stereo
//! matching of the two sides, per-feature classes and semantic descriptors.
//!
//! Input: width u16, height u16 (taken modulo 256 x 128, or with flag bit 5 modulo a bound
//! just above the KITTI capacity), a flag byte, then bytes tiled over the left image; the right image is the left shifted by a
//! flag-chosen disparity, the label image the left's bytes modulo 12 (11 = void included).
#![no_main]

use std::cell::RefCell;

use libfuzzer_sys::fuzz_target;
use semloc_core::frame::Frame;
use semloc_core::image::{ImageView, ImageViewMut};
use semloc_core::orb::{KittiOrbExtractor, OrbConfig, KITTI_MAX_HEIGHT, KITTI_MAX_WIDTH};
use semloc_core::seg::{weight_image, WeightScheme};
use semloc_core::semdesc;
use semloc_core::stereo::{KittiStereoMatcher, StereoParams};

struct State {
    left: Box<KittiOrbExtractor>,
    right: Box<KittiOrbExtractor>,
    stereo: Box<KittiStereoMatcher>,
    frame: Box<Frame>,
}

thread_local! {
    static STATE: RefCell<State> = RefCell::new({
        let mut left = Box::new(KittiOrbExtractor::new());
        let mut right = Box::new(KittiOrbExtractor::new());
        left.configure(OrbConfig::KITTI).expect("KITTI config");
        right.configure(OrbConfig::KITTI).expect("KITTI config");
        State {
            left,
            right,
            stereo: Box::new(KittiStereoMatcher::new()),
            frame: Box::new(Frame::new()),
        }
    });
}

fuzz_target!(|data: &[u8]| {
    if data.len() < 5 {
        return;
    }
    let flags = data[4];
    // Flag bit 5 opens the full size range (past the capacity); small frames otherwise, so
    // most runs are fast.
    let (bw, bh) =
        if flags & 32 != 0 { (KITTI_MAX_WIDTH + 40, KITTI_MAX_HEIGHT + 20) } else { (256, 128) };
    let w = usize::from(u16::from_le_bytes([data[0], data[1]])) % bw;
    let h = usize::from(u16::from_le_bytes([data[2], data[3]])) % bh;
    let src = &data[5..];
    let n = w * h;
    let left: Vec<u8> =
        if src.is_empty() { vec![0; n] } else { (0..n).map(|i| src[i % src.len()]).collect() };
    let shift = usize::from(flags % 32);
    let right: Vec<u8> = (0..n).map(|i| left[(i + shift).min(n.saturating_sub(1))]).collect();
    let labels: Vec<u8> = left.iter().map(|&v| v % 12).collect();

    // A buffer that does not match its stated size is an error.
    if n > 0 {
        assert!(ImageView::from_slice(&left[1..], w, h).is_err());
    }
    let (Ok(lv), Ok(rv), Ok(labv)) = (
        ImageView::from_slice(&left, w, h),
        ImageView::from_slice(&right, w, h),
        ImageView::from_slice(&labels, w, h),
    ) else {
        return;
    };
    let mut weights = vec![0u8; n];
    let scheme = if flags & 64 != 0 { WeightScheme::Full } else { WeightScheme::Cull };
    let weighted = match ImageViewMut::from_slice(&mut weights, w, h) {
        Ok(mut wv) => weight_image(&labv, scheme, &mut wv).is_ok(),
        Err(_) => false,
    };
    STATE.with(|s| {
        let s = &mut *s.borrow_mut();
        let ok_left = if weighted && flags & 128 != 0 {
            let Ok(wv) = ImageView::from_slice(&weights, w, h) else { return };
            s.left.extract_weighted(&lv, &wv).is_ok()
        } else {
            s.left.extract(&lv).is_ok()
        };
        let ok_right = s.right.extract(&rv).is_ok();
        if ok_left && ok_right {
            let params = StereoParams::new(384.381, 0.537);
            let _ = s.stereo.match_frame(
                s.left.features(),
                s.left.pyramid(),
                s.right.features(),
                s.right.pyramid(),
                &params,
                0.0,
                &mut s.frame,
            );
            semloc_core::assoc::annotate(&mut s.frame, &labv);
        }
        for kp in s.left.features().keypoints().iter().take(64) {
            let (x, y) = (kp.x.max(0.0) as usize, kp.y.max(0.0) as usize);
            let _ = semdesc::describe(&labv, x, y);
            let _ = semdesc::describe_near(&labv, x, y, 2);
        }
    });
    // Descriptors at the image's corners and outside it.
    for (x, y) in [(0, 0), (w.saturating_sub(1), h.saturating_sub(1)), (w, h), (w + 10, 0)] {
        let _ = semdesc::describe(&labv, x, y);
        let _ = semdesc::describe_near(&labv, x, y, 3);
    }
});
