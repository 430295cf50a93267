//! Semantic classes, the paper's category table and the class weights of semantic ORB.
//!
//! Labels are the 11 CamVid classes the network is trained on (ids 0–10, 11 = void), grouped
//! into the categories of the paper's Table 1: human and vehicle are dynamic; construction,
//! object, flat and nature are static; sky is its own group. Semantic ORB (paper §3.1) weights
//! a FAST/Harris candidate by its class: ω = 0 on dynamic classes (the candidate is culled
//! before it is described), ×3 on construction and object classes (stable, well-localised
//! structure), ×1 on everything else.
//!
//! Weights are stored as `u8` so a weight image can be handed to the ORB extractor's
//! `WeightMap` (which reads value/255): ×3 ↦ 255, ×1 ↦ 85, 0 ↦ 0 — only the ratio matters for
//! ranking. Memory: tables only; [`weight_image`] writes into the caller's buffer.
//!
//! The ×3 is the paper's; [`crate::orb::OrbConfig::structure_gain`] sets it per rig (1..=16):
//! construction and object keep 255 and the other static classes get `round(255 / gain)`
//! ([`weight_with_gain`], [`weight_image_with_gain`]).

use crate::image::{ImageError, ImageView, ImageViewMut};
use crate::orb::{MAX_STRUCTURE_GAIN, MIN_STRUCTURE_GAIN, PAPER_STRUCTURE_GAIN};

/// Number of real classes (ids `0..NUM_CLASSES`); [`VOID`] is the "unlabelled" id.
pub const NUM_CLASSES: usize = 11;
/// Label id of unlabelled pixels (CamVid "void"), ignored in training.
pub const VOID: u8 = 11;

/// CamVid class names by id.
pub const CLASS_NAMES: [&str; NUM_CLASSES] = [
    "sky",
    "building",
    "pole",
    "road",
    "pavement",
    "tree",
    "sign-symbol",
    "fence",
    "car",
    "pedestrian",
    "bicyclist",
];

/// The paper's categories (Table 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Category {
    /// Pedestrian, bicyclist (dynamic).
    Human,
    /// Car (dynamic; truck, bus, train, motorcycle in richer label sets).
    Vehicle,
    /// Building, fence (static, ×3).
    Construction,
    /// Pole, sign-symbol (static, ×3).
    Object,
    /// Road, pavement (static).
    Flat,
    /// Tree (static).
    Nature,
    /// Sky.
    Sky,
    /// Unlabelled or unknown id.
    Void,
}

/// Category of a label id.
pub const fn category(class: u8) -> Category {
    match class {
        0 => Category::Sky,
        1 | 7 => Category::Construction,
        2 | 6 => Category::Object,
        3 | 4 => Category::Flat,
        5 => Category::Nature,
        8 => Category::Vehicle,
        9 | 10 => Category::Human,
        _ => Category::Void,
    }
}

/// Whether a label id belongs to a dynamic (potentially moving) class.
pub const fn is_dynamic(class: u8) -> bool {
    matches!(category(class), Category::Human | Category::Vehicle)
}

/// Semantic ORB weight of a class as the `u8` a weight image holds (value/255 is the factor
/// applied to the Harris response): 0 dynamic, 255 construction/object (×3), 85 otherwise.
pub const fn orb_weight(class: u8) -> u8 {
    match category(class) {
        Category::Human | Category::Vehicle => 0,
        Category::Construction | Category::Object => 255,
        _ => 85,
    }
}

/// How semantic labels shape feature extraction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum WeightScheme {
    /// Only cull dynamic classes (ω = 0 there, 1 elsewhere).
    Cull,
    /// The paper's semantic ORB: cull dynamic, ×3 construction/object, ×1 others.
    Full,
    /// Motion-aware semantics (beyond the paper, [`crate::motion`]): ×3 construction/object,
    /// ×1 others *including* dynamic classes, whose features the tracker then keeps where their
    /// object is tested static and removes where it moves.
    Motion,
}

/// Weight of a class under `scheme`, as a weight-image value.
pub const fn weight(class: u8, scheme: WeightScheme) -> u8 {
    match scheme {
        WeightScheme::Cull => {
            if is_dynamic(class) {
                0
            } else {
                255
            }
        }
        WeightScheme::Full => orb_weight(class),
        WeightScheme::Motion => {
            if is_dynamic(class) {
                85
            } else {
                orb_weight(class)
            }
        }
    }
}

/// The weight-image value of the static classes other than construction and object when those
/// are weighted `structure_gain` times as much (they keep 255): `round(255 / structure_gain)`,
/// 85 for the paper's ×3. A gain outside [`MIN_STRUCTURE_GAIN`]..=[`MAX_STRUCTURE_GAIN`] is
/// clamped into it, and one that is not a number is the paper's
/// ([`crate::orb::OrbExtractor::configure`] refuses both).
pub fn others_weight(structure_gain: f32) -> u8 {
    let g = if structure_gain.is_nan() {
        PAPER_STRUCTURE_GAIN
    } else {
        structure_gain.clamp(MIN_STRUCTURE_GAIN, MAX_STRUCTURE_GAIN)
    };
    // 255 / g is in 15.9..=255; adding 0.5 and truncating rounds it.
    (255.0 / g + 0.5) as u8
}

/// Weight of a class under `scheme`, as a weight-image value, with construction and object
/// classes weighted `structure_gain` times the other static classes ([`weight`] is the paper's
/// gain, 3). [`WeightScheme::Cull`] weights every static class alike whatever the gain.
pub fn weight_with_gain(class: u8, scheme: WeightScheme, structure_gain: f32) -> u8 {
    match (scheme, category(class)) {
        (WeightScheme::Cull, _) => weight(class, scheme),
        (_, Category::Construction | Category::Object) => 255,
        (WeightScheme::Full, Category::Human | Category::Vehicle) => 0,
        _ => others_weight(structure_gain),
    }
}

/// Writes the weight image of a label image (same size) under `scheme`, with the paper's ×3
/// ([`weight_image_with_gain`] at [`PAPER_STRUCTURE_GAIN`]).
///
/// # Errors
/// [`ImageError::SizeMismatch`]-style errors from the image module when the sizes differ.
pub fn weight_image(
    labels: &ImageView<'_>,
    scheme: WeightScheme,
    out: &mut ImageViewMut<'_>,
) -> Result<(), ImageError> {
    weight_image_with_gain(labels, scheme, PAPER_STRUCTURE_GAIN, out)
}

/// Writes the weight image of a label image (same size) under `scheme`, construction and
/// object classes weighted `structure_gain` times the other static classes
/// ([`weight_with_gain`]).
///
/// # Errors
/// [`ImageError::SizeMismatch`]-style errors from the image module when the sizes differ.
pub fn weight_image_with_gain(
    labels: &ImageView<'_>,
    scheme: WeightScheme,
    structure_gain: f32,
    out: &mut ImageViewMut<'_>,
) -> Result<(), ImageError> {
    out.copy_from(labels)?;
    let mut lut = [0u8; 256];
    for (c, w) in lut.iter_mut().enumerate() {
        *w = weight_with_gain(c as u8, scheme, structure_gain);
    }
    for y in 0..labels.height() {
        for v in out.row_mut(y).iter_mut() {
            *v = lut[usize::from(*v)];
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_one_groups() {
        let dynamic: std::vec::Vec<u8> = (0..12).filter(|&c| is_dynamic(c)).collect();
        assert_eq!(dynamic, [8, 9, 10]);
        assert_eq!(category(1), Category::Construction);
        assert_eq!(category(7), Category::Construction);
        assert_eq!(category(2), Category::Object);
        assert_eq!(category(6), Category::Object);
        assert_eq!(category(VOID), Category::Void);
        assert_eq!(category(200), Category::Void);
    }

    #[test]
    fn weights_follow_the_paper() {
        // ω = 0 dynamic, ×3 construction/object relative to ×1 others.
        assert_eq!(orb_weight(8), 0);
        assert_eq!(orb_weight(9), 0);
        assert_eq!(orb_weight(10), 0);
        assert_eq!(orb_weight(1), 3 * orb_weight(3));
        assert_eq!(orb_weight(6), 3 * orb_weight(5));
        assert_eq!(weight(1, WeightScheme::Cull), weight(3, WeightScheme::Cull));
        assert_eq!(weight(8, WeightScheme::Cull), 0);
        // Motion-aware: dynamic classes are extracted (×1); the tracker decides.
        assert_eq!(weight(8, WeightScheme::Motion), weight(3, WeightScheme::Motion));
        assert_eq!(weight(1, WeightScheme::Motion), orb_weight(1));
    }

    #[test]
    fn the_structure_gain_sets_the_ratio() {
        let schemes = [WeightScheme::Cull, WeightScheme::Full, WeightScheme::Motion];
        // The paper's gain is `weight` exactly, for every id.
        for s in schemes {
            for c in 0..=255u8 {
                assert_eq!(weight_with_gain(c, s, PAPER_STRUCTURE_GAIN), weight(c, s), "{c} {s:?}");
            }
        }
        // Gain 1: every static class alike, so `full` is `cull`; `motion` weights all alike.
        for c in 0..=255u8 {
            assert_eq!(weight_with_gain(c, WeightScheme::Full, 1.0), weight(c, WeightScheme::Cull));
            assert_eq!(weight_with_gain(c, WeightScheme::Motion, 1.0), 255);
        }
        // Between: construction 255, road round(255 / g); dynamic 0 under full.
        assert_eq!(weight_with_gain(1, WeightScheme::Full, 2.0), 255);
        assert_eq!(weight_with_gain(3, WeightScheme::Full, 2.0), 128);
        assert_eq!(weight_with_gain(8, WeightScheme::Full, 2.0), 0);
        assert_eq!(weight_with_gain(8, WeightScheme::Motion, 2.0), 128);
        assert_eq!(others_weight(MAX_STRUCTURE_GAIN), 16);
        // Out of range is clamped, not a number is the paper's (the extractor refuses both).
        assert_eq!(others_weight(100.0), 16);
        assert_eq!(others_weight(0.5), 255);
        assert_eq!(others_weight(f32::NAN), 85);
    }

    #[test]
    fn weight_image_maps_every_pixel() {
        let labels: std::vec::Vec<u8> = (0..24).map(|i| (i % 12) as u8).collect();
        let lv = ImageView::from_slice(&labels, 6, 4).unwrap();
        let mut buf = [0u8; 24];
        let mut out = ImageViewMut::from_slice(&mut buf, 6, 4).unwrap();
        weight_image(&lv, WeightScheme::Full, &mut out).unwrap();
        for (l, w) in labels.iter().zip(buf.iter()) {
            assert_eq!(*w, orb_weight(*l));
        }
        let mut small = [0u8; 4];
        let mut out = ImageViewMut::from_slice(&mut small, 2, 2).unwrap();
        assert!(weight_image(&lv, WeightScheme::Full, &mut out).is_err());
    }
}
