//! Segmentation metrics as `models/camvid.py` computes them: one confusion matrix over the 11
//! CamVid classes (rows truth, columns prediction; truth ≥ 11 = void ignored), per-class IoU
//! `tp / (tp + fp + fn)` (NaN where a class is absent from truth and prediction), mIoU as the
//! mean over the non-NaN classes, and the paper's category mIoU from the class matrix merged
//! into the categories human {9, 10}, vehicle {8}, construction {1, 7}, object {2, 6},
//! flat {3, 4}, nature {5}, sky {0}.
//!
//! Memory: an 11 x 11 `u64` matrix.

use semloc_core::seg::NUM_CLASSES;

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

    /// Fraction of counted pixels labelled right.
    pub fn pixel_accuracy(&self) -> f64 {
        let total: u64 = self.m.iter().flatten().sum();
        let tp: u64 = (0..NUM_CLASSES).map(|i| self.m[i][i]).sum();
        tp as f64 / total.max(1) as f64
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
    }
}
