//! The stereo sequence compiled into every binary of this crate.
//!
//! `firmware-sim/data/` holds 640×192 crops of a `semloc synth` sequence as 8-bit grey PNGs,
//! the crop's camera and the ground-truth poses (`manifest.txt`, written with the images by
//! `cargo run -p semloc-firmware-sim --example make_frames`). The build script decodes the
//! PNGs to raw luma in `OUT_DIR` and generates the constants below, so the binaries carry
//! `2 · WIDTH · HEIGHT` bytes of `.rodata` per frame and no decoder. The segmentation network
//! is embedded as it is ([`MODEL_BLOB`]).

use semloc_core::geom::StereoCamera;

/// One embedded stereo frame.
#[derive(Clone, Copy, Debug)]
pub struct EmbeddedFrame {
    /// Left luma, row-major, [`WIDTH`]x[`HEIGHT`].
    pub left: &'static [u8],
    /// Right luma, row-major, [`WIDTH`]x[`HEIGHT`].
    pub right: &'static [u8],
    /// Timestamp (s), from the sequence's `times.txt`.
    pub timestamp_s: f64,
    /// Ground truth: left camera-to-world `[R | t]`, row-major, relative to frame 0 (KITTI
    /// pose row).
    pub gt_pose: [f64; 12],
}

/// 16-byte alignment for an embedded blob.
#[repr(C, align(16))]
struct Aligned<T: ?Sized>(T);

include!(concat!(env!("OUT_DIR"), "/embedded_data.rs"));

/// The int8 Fast-SCNN segmentation network (`models/artefacts/`[`MODEL_NAME`], the `.slm`
/// blob the host loads), 16-byte aligned.
pub static MODEL_BLOB: &[u8] = &MODEL_ALIGNED.0;
