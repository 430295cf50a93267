//! Segmentation metrics as `models/camvid.py` computes them: one confusion matrix over the 11
//! CamVid classes (rows truth, columns prediction; truth ≥ 11 = void ignored), per-class IoU
//! `tp / (tp + fp + fn)` (NaN where a class is absent from truth and prediction), mIoU as the
//! mean over the non-NaN classes, and the paper's category mIoU from the class matrix merged
//! into the categories human {9, 10}, vehicle {8}, construction {1, 7}, object {2, 6},
//! flat {3, 4}, nature {5}, sky {0}; and the pixel precision and recall of the dynamic mask
//! (car, pedestrian, bicyclist: what culling removes), as `camvid.py`'s `dyn_precision` /
//! `dyn_recall`. [`map_cityscapes`] reads Cityscapes label ids (KITTI semantics, KITTI-360) as
//! these classes.
//!
//! Memory: an 11 x 11 `u64` matrix.

use semloc_core::seg::{is_dynamic, NUM_CLASSES, VOID};

/// Category names and their classes, in `camvid.py`'s order.
pub const CATEGORIES: [(&str, &[u8]); 7] = [
    ("human", &[9, 10]),
    ("vehicle", &[8]),
    ("construction", &[1, 7]),
    ("object", &[2, 6]),
    ("flat", &[3, 4]),
    ("nature", &[5]),
    ("sky", &[0]),
];

/// A class confusion matrix.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Confusion {
    /// `m[truth][pred]` pixel counts.
    pub m: [[u64; NUM_CLASSES]; NUM_CLASSES],
}

impl Confusion {
    /// Adds one label map (`truth` ≥ 11 ignored; predictions ≥ 11 clamp to 10, as camvid.py).
    pub fn add(&mut self, truth: &[u8], pred: &[u8]) {
        for (&t, &p) in truth.iter().zip(pred) {
            if (t as usize) < NUM_CLASSES {
                self.m[t as usize][(p as usize).min(NUM_CLASSES - 1)] += 1;
            }
        }
    }

    /// Adds another matrix's counts (integer sums: the totals of frames scored in parts, e.g.
    /// on several threads, are the same in any order).
    pub fn merge(&mut self, other: &Confusion) {
        for (row, orow) in self.m.iter_mut().zip(&other.m) {
            row.iter_mut().zip(orow).for_each(|(a, b)| *a += b);
        }
    }

    /// Per-class IoU (NaN for a class with no truth and no prediction).
    pub fn iou(&self) -> Vec<f64> {
        iou(&self.m.iter().map(|r| r.to_vec()).collect::<Vec<_>>())
    }

    /// Mean IoU over the classes present.
    pub fn miou(&self) -> f64 {
        nanmean(&self.iou())
    }

    /// Per-category IoU, [`CATEGORIES`] order.
    pub fn category_iou(&self) -> Vec<f64> {
        let n = CATEGORIES.len();
        let mut c = vec![vec![0u64; n]; n];
        for (ti, (_, tc)) in CATEGORIES.iter().enumerate() {
            for (pi, (_, pc)) in CATEGORIES.iter().enumerate() {
                c[ti][pi] = tc
                    .iter()
                    .flat_map(|&t| pc.iter().map(move |&p| (t, p)))
                    .map(|(t, p)| self.m[t as usize][p as usize])
                    .sum();
            }
        }
        iou(&c)
    }

    /// Mean category IoU.
    pub fn category_miou(&self) -> f64 {
        nanmean(&self.category_iou())
    }

    /// Of the pixels predicted dynamic (car, pedestrian, bicyclist) with labelled truth, the
    /// share whose truth is dynamic too (any of the three); NaN when none was predicted.
    pub fn dynamic_precision(&self) -> f64 {
        let (tp, pred, _) = self.dynamic_counts();
        tp as f64 / pred as f64
    }

    /// Of the dynamic truth pixels, the share predicted dynamic; NaN when there are none.
    pub fn dynamic_recall(&self) -> f64 {
        let (tp, _, truth) = self.dynamic_counts();
        tp as f64 / truth as f64
    }

    /// (dynamic truth and prediction, dynamic prediction, dynamic truth) pixel counts.
    fn dynamic_counts(&self) -> (u64, u64, u64) {
        let (mut tp, mut pred, mut truth) = (0, 0, 0);
        for (t, row) in self.m.iter().enumerate() {
            for (p, &n) in row.iter().enumerate() {
                let (dt, dp) = (is_dynamic(t as u8), is_dynamic(p as u8));
                tp += if dt && dp { n } else { 0 };
                pred += if dp { n } else { 0 };
                truth += if dt { n } else { 0 };
            }
        }
        (tp, pred, truth)
    }

    /// Fraction of counted pixels labelled right.
    pub fn pixel_accuracy(&self) -> f64 {
        let total: u64 = self.m.iter().flatten().sum();
        let tp: u64 = (0..NUM_CLASSES).map(|i| self.m[i][i]).sum();
        tp as f64 / total.max(1) as f64
    }
}

/// The CamVid class (or [`VOID`]) of a Cityscapes label id, the ids of the KITTI semantic
/// segmentation benchmark and of KITTI-360 (`semantic/*.png`), mapped as the SegNet CamVid
/// classes merge CamVid's 32: wall, bridge and tunnel are building; guard rail is fence;
/// pole group is pole; traffic light and sign are sign-symbol; terrain (grass, soil) is tree,
/// as CamVid's "VegetationMisc"; truck, bus, caravan, trailer and train are car; rider,
/// motorcycle and bicycle are bicyclist. Void: unlabelled, ego vehicle, rectification border,
/// out of ROI, "static" and "dynamic" (unclassified objects), ground, parking, rail track and
/// any other id (license plate, 255).
pub const fn map_cityscapes(id: u8) -> u8 {
    match id {
        23 => 0,
        11 | 12 | 15 | 16 => 1,
        17 | 18 => 2,
        7 => 3,
        8 => 4,
        21 | 22 => 5,
        19 | 20 => 6,
        13 | 14 => 7,
        26..=31 => 8,
        24 => 9,
        25 | 32 | 33 => 10,
        _ => VOID,
    }
}

fn iou(m: &[Vec<u64>]) -> Vec<f64> {
    let n = m.len();
    (0..n)
        .map(|i| {
            let tp = m[i][i];
            let row: u64 = m[i].iter().sum();
            let col: u64 = m.iter().map(|r| r[i]).sum();
            let denom = row + col - tp;
            if denom == 0 {
                f64::NAN
            } else {
                tp as f64 / denom as f64
            }
        })
        .collect()
}

fn nanmean(v: &[f64]) -> f64 {
    let ok: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if ok.is_empty() {
        f64::NAN
    } else {
        ok.iter().sum::<f64>() / ok.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_and_categories_by_hand() {
        let mut c = Confusion::default();
        // truth: 2 sky, 2 road, 1 void; prediction: sky, road, road, pavement, car
        c.add(&[0, 0, 3, 3, 11], &[0, 3, 3, 4, 8]);
        let iou = c.iou();
        assert_eq!(iou[0], 0.5); // tp 1, fn 1
        assert!((iou[3] - 1.0 / 3.0).abs() < 1e-12); // tp 1, fp 1, fn 1
        assert_eq!(iou[4], 0.0);
        assert!(iou[1].is_nan());
        assert!((c.miou() - (0.5 + 1.0 / 3.0 + 0.0) / 3.0).abs() < 1e-12);
        // categories: sky tp 1 fn 1 → 0.5; flat: truth road×2, pred road/pavement: tp 2, fp 1
        let ci = c.category_iou();
        assert_eq!(ci[6], 0.5);
        assert!((ci[4] - 2.0 / 3.0).abs() < 1e-12);
        assert!((c.category_miou() - (0.5 + 2.0 / 3.0) / 2.0).abs() < 1e-12);
        assert_eq!(c.pixel_accuracy(), 0.5);
        // dynamic mask: one pixel predicted car on void truth (not counted), none on truth
        assert!(c.dynamic_precision().is_nan() && c.dynamic_recall().is_nan());
    }

    #[test]
    fn merged_parts_equal_the_whole() {
        let (truth, pred) = ([0u8, 3, 3, 8, 9, 11, 5, 8], [0u8, 3, 4, 8, 8, 2, 5, 12]);
        let mut whole = Confusion::default();
        whole.add(&truth, &pred);
        let (mut a, mut b) = (Confusion::default(), Confusion::default());
        a.add(&truth[..3], &pred[..3]);
        b.add(&truth[3..], &pred[3..]);
        a.merge(&b);
        assert_eq!(a, whole);
        assert_eq!(whole.m.iter().flatten().sum::<u64>(), 7); // the void pixel is not counted
    }

    #[test]
    fn dynamic_mask_precision_and_recall_by_hand() {
        let mut c = Confusion::default();
        // truth: car, car, pedestrian, bicyclist, road, tree, void
        // pred:  car, road, bicyclist, pedestrian, car, car, car
        c.add(&[8, 8, 9, 10, 3, 5, 11], &[8, 3, 10, 9, 8, 8, 8]);
        // predicted dynamic on labelled truth: 5 (car, bicyclist, pedestrian, car, car), of
        // which 3 dynamic in truth (a pedestrian called bicyclist still counts); truth dynamic 4
        assert!((c.dynamic_precision() - 3.0 / 5.0).abs() < 1e-12);
        assert!((c.dynamic_recall() - 3.0 / 4.0).abs() < 1e-12);
    }

    #[test]
    fn cityscapes_ids_map_to_camvid_classes() {
        let pairs = [
            (0, VOID),
            (1, VOID),
            (3, VOID),
            (4, VOID),
            (5, VOID),
            (6, VOID),
            (7, 3),
            (8, 4),
            (9, VOID),
            (10, VOID),
            (11, 1),
            (12, 1),
            (13, 7),
            (14, 7),
            (15, 1),
            (16, 1),
            (17, 2),
            (18, 2),
            (19, 6),
            (20, 6),
            (21, 5),
            (22, 5),
            (23, 0),
            (24, 9),
            (25, 10),
            (26, 8),
            (27, 8),
            (28, 8),
            (29, 8),
            (30, 8),
            (31, 8),
            (32, 10),
            (33, 10),
            (34, VOID),
            (255, VOID),
        ];
        for (id, class) in pairs {
            assert_eq!(map_cityscapes(id), class, "Cityscapes id {id}");
        }
        // the dynamic classes of one are the dynamic classes of the other: person to bicycle
        for id in 0..=255u8 {
            assert_eq!(is_dynamic(map_cityscapes(id)), (24..=33).contains(&id), "id {id}");
        }
    }
}
