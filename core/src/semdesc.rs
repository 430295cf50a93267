//! The semantic descriptor (paper §3.2): a 21×21 binary patch of the label image around a
//! semantic key point, bit = 1 where the pixel has the key point's class.
//!
//! Semantic key points are pixels on a class boundary (a 4-neighbour has another class): there
//! the patch describes the local shape of the boundary (a pole's edge against a facade, a
//! kerb against the road), which stays stable when appearance (and so ORB) changes. Two
//! descriptors match when their key points have the same class and their patches differ in at
//! most [`MATCH_THRESHOLD`] = 55 of the 441 bits (12.5 %). Pixels outside the image count as
//! "another class", so a patch is defined at every key point.
//!
//! Memory: a descriptor is 7 words + the class (64 bytes); nothing else is kept.

use crate::image::ImageView;

/// Side of the patch (px).
pub const PATCH: usize = 21;
/// Half side.
pub const HALF: usize = PATCH / 2;
/// Bits in a descriptor.
pub const BITS: usize = PATCH * PATCH;
/// Words holding the bits (441 bits in 7 × 64).
pub const WORDS: usize = BITS.div_ceil(64);
/// The paper's match threshold on the Hamming distance.
pub const MATCH_THRESHOLD: u32 = 55;

/// A semantic descriptor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SemDesc {
    /// Patch bits, row-major from the top-left, bit `i` of the patch in word `i / 64`.
    pub bits: [u64; WORDS],
    /// The key point's class id.
    pub class: u8,
}

impl SemDesc {
    /// Number of set bits (pixels of the key point's class in the patch).
    pub fn ones(&self) -> u32 {
        self.bits.iter().map(|w| w.count_ones()).sum()
    }
}

/// Hamming distance between the patches (ignores the classes).
pub fn hamming(a: &SemDesc, b: &SemDesc) -> u32 {
    a.bits.iter().zip(b.bits.iter()).map(|(x, y)| (x ^ y).count_ones()).sum()
}

/// Whether two descriptors match: same class and at most [`MATCH_THRESHOLD`] differing bits.
pub fn matches(a: &SemDesc, b: &SemDesc) -> bool {
    a.class == b.class && hamming(a, b) <= MATCH_THRESHOLD
}

/// Whether `(x, y)` lies on a class boundary: a 4-neighbour inside the image has another
/// class. `false` outside the image.
pub fn is_keypoint(labels: &ImageView<'_>, x: usize, y: usize) -> bool {
    if x >= labels.width() || y >= labels.height() {
        return false;
    }
    let c = labels.get(x, y);
    let differs = |nx: usize, ny: usize| labels.get(nx, ny) != c;
    (x > 0 && differs(x - 1, y))
        || (x + 1 < labels.width() && differs(x + 1, y))
        || (y > 0 && differs(x, y - 1))
        || (y + 1 < labels.height() && differs(x, y + 1))
}

/// The descriptor of the patch centred on `(x, y)`; `None` when the centre is outside the image.
pub fn describe(labels: &ImageView<'_>, x: usize, y: usize) -> Option<SemDesc> {
    let (w, h) = (labels.width(), labels.height());
    if x >= w || y >= h {
        return None;
    }
    let class = labels.get(x, y);
    let mut bits = [0u64; WORDS];
    for dy in 0..PATCH {
        let Some(py) = (y + dy).checked_sub(HALF).filter(|&py| py < h) else { continue };
        let row = labels.row(py);
        let x0 = x as isize - HALF as isize;
        for dx in 0..PATCH {
            let px = x0 + dx as isize;
            if px < 0 || px as usize >= w {
                continue;
            }
            if row[px as usize] == class {
                let i = dy * PATCH + dx;
                bits[i / 64] |= 1 << (i % 64);
            }
        }
    }
    Some(SemDesc { bits, class })
}

/// The descriptor at the boundary pixel nearest to `(x, y)` (Euclidean; ties in scan order)
/// within a square of `radius` pixels, if there is one: how a feature detected near, but not
/// exactly on, a class edge gets its semantic descriptor.
pub fn describe_near(
    labels: &ImageView<'_>,
    x: usize,
    y: usize,
    radius: usize,
) -> Option<(usize, usize, SemDesc)> {
    let mut best: Option<(usize, usize, usize)> = None;
    let (w, h) = (labels.width(), labels.height());
    for ny in y.saturating_sub(radius)..=(y + radius).min(h.saturating_sub(1)) {
        for nx in x.saturating_sub(radius)..=(x + radius).min(w.saturating_sub(1)) {
            if is_keypoint(labels, nx, ny) {
                let d = nx.abs_diff(x).pow(2) + ny.abs_diff(y).pow(2);
                if best.is_none_or(|b| d < b.2) {
                    best = Some((nx, ny, d));
                }
            }
        }
    }
    let (bx, by, _) = best?;
    describe(labels, bx, by).map(|d| (bx, by, d))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A w×h label image: class `a` left of column `edge` (tilted by `slope` px per row), `b`
    /// right of it.
    fn edge_image(w: usize, h: usize, edge: usize, slope: f32, a: u8, b: u8) -> std::vec::Vec<u8> {
        let mut v = std::vec![0u8; w * h];
        for y in 0..h {
            let e = edge as f32 + slope * y as f32;
            for x in 0..w {
                v[y * w + x] = if (x as f32) < e { a } else { b };
            }
        }
        v
    }

    #[test]
    fn vertical_edge_descriptor_has_the_expected_bits() {
        let img = edge_image(64, 48, 30, 0.0, 1, 3);
        let v = ImageView::from_slice(&img, 64, 48).unwrap();
        assert!(is_keypoint(&v, 29, 20) && is_keypoint(&v, 30, 20));
        assert!(!is_keypoint(&v, 10, 20));
        // Key point at x = 29 (class 1, last column of the left region): columns 19..=29 of
        // the patch (11 of 21) are class 1.
        let d = describe(&v, 29, 20).unwrap();
        assert_eq!(d.class, 1);
        assert_eq!(d.ones(), 11 * 21);
    }

    #[test]
    fn small_shifts_match_and_other_shapes_do_not() {
        let a = edge_image(64, 48, 30, 0.3, 1, 3);
        let va = ImageView::from_slice(&a, 64, 48).unwrap();
        let da = describe(&va, 29, 24).unwrap();
        // The same edge one pixel to the right: descriptor at the corresponding point.
        let b = edge_image(64, 48, 31, 0.3, 1, 3);
        let vb = ImageView::from_slice(&b, 64, 48).unwrap();
        let db = describe(&vb, 30, 24).unwrap();
        assert!(matches(&da, &db), "same edge moved: {}", hamming(&da, &db));
        // Same point, but the key point sits one pixel off the edge: 21 bits differ at most.
        let dc = describe(&vb, 29, 24).unwrap();
        assert!(hamming(&da, &dc) <= 21 + 7, "{}", hamming(&da, &dc));
        // A horizontal edge through the same pixel is a different shape.
        let mut hz = std::vec![1u8; 64 * 48];
        for y in 24..48 {
            for x in 0..64 {
                hz[y * 64 + x] = 3;
            }
        }
        let vh = ImageView::from_slice(&hz, 64, 48).unwrap();
        let dh = describe(&vh, 29, 23).unwrap();
        assert!(!matches(&da, &dh), "horizontal vs vertical edge: {}", hamming(&da, &dh));
        // Same shape, other class: no match.
        let other = edge_image(64, 48, 30, 0.3, 2, 3);
        let vo = ImageView::from_slice(&other, 64, 48).unwrap();
        let dov = describe(&vo, 29, 24).unwrap();
        assert_eq!(hamming(&da, &dov), 0);
        assert!(!matches(&da, &dov));
    }

    #[test]
    fn borders_and_out_of_range_are_handled() {
        let img = edge_image(30, 20, 15, 0.0, 1, 3);
        let v = ImageView::from_slice(&img, 30, 20).unwrap();
        let d = describe(&v, 0, 0).unwrap();
        // Only the in-image quarter can be set: rows 10..21, columns 10..21 of the patch.
        assert_eq!(d.ones(), 11 * 11);
        assert!(describe(&v, 30, 0).is_none());
        assert!(!is_keypoint(&v, 100, 100));
        let (x, y, near) = describe_near(&v, 10, 5, 5).unwrap();
        assert_eq!((x, y), (14, 5));
        assert_eq!(near.class, 1);
        assert!(describe_near(&v, 2, 5, 3).is_none());
    }
}
