//! The tracker's input: one stereo frame's left-image features with their stereo depth.
//!
//! A [`Frame`] is what extraction (ORB on both images) and stereo matching hand to the
//! tracker; it is plain data so the two extractions can run on two threads and the tracker
//! never sees an image. Memory: [`FRAME_CAPACITY`] features of 56 bytes plus an optional
//! semantic descriptor each (72 bytes), 256 KiB a frame.

use heapless::Vec;

use crate::semdesc::SemDesc;

/// Most features a frame holds (ORB-SLAM2 extracts 2000 on KITTI; the rest is headroom).
pub const FRAME_CAPACITY: usize = 2048;

/// A 256-bit binary descriptor (rBRIEF) as its 32 raw bytes, OpenCV's bit layout: the bytes of
/// [`crate::orb::Descriptor`] (`desc.0`). Kept as a plain array here because the map stores
/// and compares descriptors as bytes.
pub type Descriptor = [u8; 32];

/// Hamming distance between two 256-bit descriptors; the one popcount kernel is
/// [`crate::orb::hamming`], this only adapts the raw-byte form.
#[inline]
pub fn hamming(a: &Descriptor, b: &Descriptor) -> u32 {
    crate::orb::hamming(&crate::orb::Descriptor(*a), &crate::orb::Descriptor(*b))
}

/// One left-image feature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Feature {
    /// Column in the level-0 image (px).
    pub x: f32,
    /// Row in the level-0 image (px).
    pub y: f32,
    /// Pyramid level it was detected on.
    pub level: u8,
    /// Orientation (radians).
    pub angle: f32,
    /// The rBRIEF descriptor.
    pub desc: Descriptor,
    /// Matching column in the right image (px), or a negative value when unmatched.
    pub ur: f32,
    /// Depth (m) from the stereo disparity, or 0 when unmatched.
    pub depth_m: f32,
    /// Semantic class at the key point ([`crate::seg::VOID`] when no labels were given).
    pub class: u8,
}

impl Feature {
    /// Whether the feature has a stereo match (and so a depth).
    #[inline]
    pub fn is_stereo(&self) -> bool {
        self.ur >= 0.0 && self.depth_m > 0.0
    }
}

/// The features of one stereo frame, with its timestamp.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Left-image features; stereo ones carry `ur` and `depth_m`.
    pub features: Vec<Feature, FRAME_CAPACITY>,
    /// Capture time (s).
    pub timestamp_s: f64,
    /// Semantic descriptor of each feature that lies on or near a class boundary (index =
    /// feature index); meaningful only for features whose `class` is not void.
    pub sem: [Option<SemDesc>; FRAME_CAPACITY],
}

impl Frame {
    /// An empty frame.
    pub const fn new() -> Self {
        Self { features: Vec::new(), timestamp_s: 0.0, sem: [None; FRAME_CAPACITY] }
    }

    /// Features that have a stereo depth.
    pub fn stereo_count(&self) -> usize {
        self.features.iter().filter(|f| f.is_stereo()).count()
    }
}

impl Default for Frame {
    fn default() -> Self {
        Self::new()
    }
}

/// Inverse variance `1/σ²` of a key point on pyramid `level`, σ = 1.2^level (ORB-SLAM2).
#[inline]
pub fn level_inv_sigma2(level: u8) -> f64 {
    const INV: [f64; 8] = {
        let mut t = [1.0; 8];
        let mut s2 = 1.0;
        let mut i = 0;
        while i < 8 {
            t[i] = 1.0 / s2;
            s2 *= 1.44;
            i += 1;
        }
        t
    };
    INV[usize::from(level.min(7))]
}

/// Scale factor 1.2^level.
#[inline]
pub fn level_scale(level: u8) -> f32 {
    const S: [f32; 8] = [1.0, 1.2, 1.44, 1.728, 2.0736, 2.48832, 2.985_984, 3.583_181];
    S[usize::from(level.min(7))]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hamming_counts_differing_bits() {
        let a = [0u8; 32];
        let mut b = [0u8; 32];
        assert_eq!(hamming(&a, &b), 0);
        b[0] = 0b1011;
        b[31] = 0x80;
        assert_eq!(hamming(&a, &b), 4);
        assert_eq!(hamming(&[0xff; 32], &a), 256);
    }

    #[test]
    fn level_tables_follow_scale_1_2() {
        for l in 0..8u8 {
            let s = 1.2f64.powi(i32::from(l));
            assert!((f64::from(level_scale(l)) - s).abs() < 1e-5);
            assert!((level_inv_sigma2(l) - 1.0 / (s * s)).abs() < 1e-12);
        }
    }
}
