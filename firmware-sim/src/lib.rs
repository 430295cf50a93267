//! # semloc-firmware-sim
//!
//! semloc-core run the way an ECU runs it: one fixed block of state built once, frames pushed
//! through it in a fixed order, results printed as bit patterns so that two targets can be
//! compared for equality rather than closeness.
//!
//! * The frame path is core's [`Localiser`] (re-exported here), the same type the host
//!   pipeline drives; with a [`Network`] (the int8 network reading its blob in place, working
//!   in a [`SegStorage`]) it runs the semantic pipeline. This crate adds no pipeline logic of
//!   its own, so its poses are bit-identical to `semloc run --threads 1` on the same frames by
//!   construction (the QEMU check `qemu-check.sh` stays as the regression test).
//! * [`embedded`] holds a short synthetic sequence compiled into the image (640×192 crops of
//!   `semloc synth` frames, decoded from `firmware-sim/data/*.png` by the build script) and
//!   the 192×640 segmentation network.
//! * [`report`] prints poses as `f64` bit patterns and hashes them (FNV-1a), the same text on
//!   every target; [`report::run_embedded`] is the one driver all binaries call.
//! * [`kernel_check`] holds this build's fast int8 kernels (NEON on aarch64) to the reference
//!   kernels on seeded random convs, on the target itself (`qemu_aarch64` runs it first).
//!
//! * `sim` (feature `std`): the localiser as an ECU task on the host: fixed state built once,
//!   a simulated 10 Hz sensor clock feeding a bounded frame ring, a per-frame deadline with a
//!   degradation policy, seeded fault injection with detection and recovery, and the
//!   `ecu-sim` binary.
//!
//! The binaries: `qemu_aarch64` (bare metal, `aarch64-unknown-none`, ARM semihosting under
//! `qemu-system-aarch64 -M virt`), `host_poses` (x86-64, std) and `thumbv7em_size` (a
//! Cortex-M7 link of the same code, for the section-size report). See `firmware-sim/README.md`.
//!
//! Memory: [`Localiser::MEMORY_BYTES`] (≈ 41 MiB: the tracker's map and the two extractors'
//! pyramids, sized for frames up to 1920 × 1200) plus, with semantics, [`SegStorage::MEMORY_BYTES`] (≈ 2.2 MiB: the
//! network's arena and maps) and the network blob, read in place. Build the localiser where a
//! by-value move of that size is safe (a static slot on bare metal, a `Box` on a big-stack
//! thread on the host): its constructor returns it by value, and on aarch64 the construction
//! peaks at a few times its size in stack (`qemu-check.sh` prints the peak), while processing a
//! frame needs ≈ 15 KB.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

pub mod embedded;
pub mod kernel_check;
pub mod report;
#[cfg(feature = "std")]
pub mod sim;

use semloc_core::assoc::Association;
use semloc_core::seg::WeightScheme;
use semloc_core::tracker::TrackerParams;

pub use semloc_core as core_crate;
pub use semloc_core::localiser::{
    FrameOutput, Localiser, LocaliserConfig, LocaliserError, Network, NetworkMemory,
};

/// Tracker settings of the geometric run: the defaults (ORB-SLAM2's stereo KITTI settings,
/// nearest-neighbour association), as `semloc run` without options.
pub fn geometric_params() -> TrackerParams {
    TrackerParams::default()
}

/// Tracker settings of the semantic run: the defaults with the paper's EM association, as
/// `semloc run --semantics full --assoc em`.
pub fn semantic_params() -> TrackerParams {
    TrackerParams { association: Association::Em, ..TrackerParams::default() }
}

/// The weighting scheme of the semantic run: the paper's semantic ORB.
pub const SEMANTIC_SCHEME: WeightScheme = WeightScheme::Full;

/// The localiser configuration of the [`embedded`] sequence (its camera and image size) with
/// `tracker` settings and `semantics`: the geometric run is `(geometric_params(), None)`, the
/// semantic one `(semantic_params(), Some(SEMANTIC_SCHEME))`.
pub fn embedded_config(tracker: TrackerParams, semantics: Option<WeightScheme>) -> LocaliserConfig {
    LocaliserConfig {
        tracker,
        semantics,
        ..LocaliserConfig::new(embedded::CAMERA, embedded::WIDTH as u32, embedded::HEIGHT as u32)
    }
}

/// A localiser for the [`embedded`] sequence ([`embedded_config`]). Returns
/// ≈ [`Localiser::MEMORY_BYTES`] by value: call it where that fits (see the crate docs).
///
/// # Errors
/// As [`Localiser::new`] (not expected: the embedded camera is valid).
pub fn embedded_localiser(
    tracker: TrackerParams,
    semantics: Option<WeightScheme>,
) -> Result<Localiser, LocaliserError> {
    Localiser::new(&embedded_config(tracker, semantics))
}

/// Arena capacity of [`SegStorage`]: the 192x640 Fast-SCNN export needs 1 495 680 bytes.
pub const SEG_ARENA_BYTES: usize = 2 << 20;

/// Fixed-size storage for the [`Network`] stage on [`embedded`]-sized frames (the 192x640
/// network at letterbox factor 1): `const fn new`, all zeros, so a `static` of it lands in
/// `.bss`.
pub struct SegStorage {
    arena: [i8; SEG_ARENA_BYTES],
    input: [u8; embedded::WIDTH * embedded::HEIGHT],
    model_labels: [u8; embedded::WIDTH * embedded::HEIGHT],
}

impl SegStorage {
    /// Bytes of one storage.
    pub const MEMORY_BYTES: usize = core::mem::size_of::<SegStorage>();

    /// Zeroed storage.
    pub const fn new() -> Self {
        const N: usize = embedded::WIDTH * embedded::HEIGHT;
        Self { arena: [0; SEG_ARENA_BYTES], input: [0; N], model_labels: [0; N] }
    }

    /// The buffers, for [`Network::new`].
    pub fn memory(&mut self) -> NetworkMemory<'_> {
        NetworkMemory {
            arena: &mut self.arena,
            input: &mut self.input,
            model_labels: &mut self.model_labels,
        }
    }
}

impl Default for SegStorage {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests;
