//! The text both binaries print, so that two targets can be compared with `diff`.
//!
//! Per frame: one `#` comment line (tracker state and counters, pose error against the ground
//! truth) and one pose line: the 12 numbers of `t_wc = [R | t]` (row-major) as the hex bit
//! patterns of the `f64`s (`{:016x}` of `to_bits()`), so equal text means bit-identical
//! poses. At the end, a `#` summary line and `fnv1a64 <hex>`: FNV-1a (64 bit) over the
//! little-endian bytes of all printed pose numbers in order.
//!
//! Lines starting with `@` are target-specific (timings, stack use); they are not written
//! here but by a binary's per-frame hook, and the QEMU check drops them before comparing.
//! Floating-point text in the `#` lines goes through `core::fmt`, which is deterministic on
//! every target.

use core::fmt::{self, Write};

use semloc_core::geom::Se3;
use semloc_core::math;
use semloc_core::tracker::TrackState;

use crate::embedded::{EmbeddedFrame, HEIGHT, WIDTH};
use crate::{FrameOutput, Localiser, LocaliserError, Network};

/// FNV-1a, 64 bit: a hash with no tables and no platform dependence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv1a(u64);

impl Fnv1a {
    /// FNV-1a 64-bit offset basis.
    pub const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    /// FNV-1a 64-bit prime.
    pub const PRIME: u64 = 0x0000_0100_0000_01b3;

    /// A hasher at the offset basis.
    pub const fn new() -> Self {
        Self(Self::OFFSET)
    }

    /// Feeds `bytes`.
    pub fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(Self::PRIME);
        }
    }

    /// Feeds the bit pattern of `x`, little-endian.
    pub fn write_f64(&mut self, x: f64) {
        self.write(&x.to_bits().to_le_bytes());
    }

    /// The hash so far.
    pub const fn finish(&self) -> u64 {
        self.0
    }
}

impl Default for Fnv1a {
    fn default() -> Self {
        Self::new()
    }
}

/// `[R | t]` of `pose`, row-major (a KITTI pose row).
pub fn pose_row(pose: &Se3) -> [f64; 12] {
    let mut m = [0.0; 12];
    for i in 0..3 {
        for j in 0..3 {
            m[i * 4 + j] = pose.rot[(i, j)];
        }
        m[i * 4 + 3] = pose.trans[i];
    }
    m
}

/// Writes the 12 numbers of `row` as `{:016x}` bit patterns, space-separated, and a newline.
///
/// # Errors
/// Whatever `out` returns.
pub fn write_pose_line<W: Write + ?Sized>(out: &mut W, row: &[f64; 12]) -> fmt::Result {
    for (k, x) in row.iter().enumerate() {
        if k > 0 {
            out.write_char(' ')?;
        }
        write!(out, "{:016x}", x.to_bits())?;
    }
    out.write_char('\n')
}

/// Translation error (m) and rotation error (degrees) of `est` against `gt` (both pose rows):
/// `‖t − t_gt‖` and the angle of `Rᵀ R_gt`.
pub fn pose_error(est: &[f64; 12], gt: &[f64; 12]) -> (f64, f64) {
    let mut d2 = 0.0;
    let mut trace = 0.0;
    for i in 0..3 {
        let d = est[i * 4 + 3] - gt[i * 4 + 3];
        d2 += d * d;
        // (Rᵀ R_gt)_ii = Σ_k R_ki R_gt,ki
        for k in 0..3 {
            trace += est[k * 4 + i] * gt[k * 4 + i];
        }
    }
    let c = ((trace - 1.0) * 0.5).clamp(-1.0, 1.0);
    (math::sqrt(d2), math::acos(c).to_degrees())
}

/// What a run over the embedded frames did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunSummary {
    /// Frames processed.
    pub frames: u32,
    /// Frames that ended in [`TrackState::Tracking`].
    pub tracking: u32,
    /// Frames on which tracking was lost.
    pub lost: u32,
    /// FNV-1a over the pose bit patterns (see the module docs).
    pub hash: u64,
    /// Distance of the last estimated pose from the first (m).
    pub moved_m: f64,
    /// The same for the ground truth (m).
    pub gt_moved_m: f64,
    /// Largest translation error over the frames (m).
    pub max_err_t_m: f64,
    /// Largest rotation error over the frames (degrees).
    pub max_err_r_deg: f64,
}

impl RunSummary {
    /// Largest translation error accepted by [`Self::tracked`]: 2 % of the distance driven
    /// plus 5 cm.
    pub fn err_budget_m(&self) -> f64 {
        0.05 + 0.02 * self.gt_moved_m
    }

    /// The tracker tracked: every frame ended tracking, none was lost, the estimate moved at
    /// least half the ground truth's distance and (at least 0.5 m), and its translation error
    /// stayed within [`Self::err_budget_m`].
    pub fn tracked(&self) -> bool {
        self.frames > 1
            && self.tracking == self.frames
            && self.lost == 0
            && self.moved_m >= 0.5
            && self.moved_m >= 0.5 * self.gt_moved_m
            && self.max_err_t_m <= self.err_budget_m()
    }
}

/// Why a run stopped.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum RunError {
    /// The localiser failed on frame `frame`.
    Frame {
        /// Frame index.
        frame: usize,
        /// The error.
        err: LocaliserError,
    },
    /// The output sink failed.
    Output,
}

impl From<fmt::Error> for RunError {
    fn from(_: fmt::Error) -> Self {
        Self::Output
    }
}

impl fmt::Display for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Frame { frame, err } => write!(f, "frame {frame}: {err}"),
            Self::Output => f.write_str("output failed"),
        }
    }
}

impl core::error::Error for RunError {}

fn state_name(s: TrackState) -> &'static str {
    match s {
        TrackState::Uninitialised => "uninitialised",
        TrackState::Tracking => "tracking",
    }
}

/// Writes the `#` line of one frame.
///
/// # Errors
/// Whatever `out` returns.
pub fn write_frame_comment<W: Write + ?Sized>(
    out: &mut W,
    index: usize,
    o: &FrameOutput,
    err: (f64, f64),
) -> fmt::Result {
    let r = &o.report;
    writeln!(
        out,
        "# frame {index}: {} stereo {}/{} matched {} inliers {} keyframe {} landmarks {} \
         err_t_m {:.4} err_r_deg {:.4}",
        state_name(r.state),
        o.stereo.matched,
        o.stereo.left,
        r.matched,
        r.inliers,
        u8::from(r.keyframe),
        r.landmarks,
        err.0,
        err.1,
    )
}

/// Writes the `#` line of a frame's labels (semantic runs): dynamic-class pixels and the
/// FNV-1a of the label image, so the network's output is compared bit for bit too.
///
/// # Errors
/// Whatever `out` returns.
pub fn write_labels_comment<W: Write + ?Sized>(
    out: &mut W,
    index: usize,
    labels: &[u8],
) -> fmt::Result {
    let mut h = Fnv1a::new();
    h.write(labels);
    let dynamic = labels.iter().filter(|&&c| semloc_core::seg::is_dynamic(c)).count();
    writeln!(out, "# frame {index} labels: dynamic_px {dynamic} fnv1a64 {:016x}", h.finish())
}

/// Runs `frames` through `loc` (with the semantic front end when `semantics` is given) and
/// writes the report to `out`: a header, per frame `#` lines and a pose line, then the
/// summary and the hash line. `after_frame(out, index)` runs after each frame's lines
/// (binaries add their `@` lines there).
///
/// # Errors
/// [`RunError::Frame`] when the localiser fails (the lines so far are written),
/// [`RunError::Output`] when `out` fails.
pub fn run_frames<W, H>(
    loc: &mut Localiser,
    frames: &[EmbeddedFrame],
    mut network: Option<&mut Network<'_>>,
    out: &mut W,
    mut after_frame: H,
) -> Result<RunSummary, RunError>
where
    W: Write + ?Sized,
    H: FnMut(&mut W, usize) -> fmt::Result,
{
    write!(out, "# semloc firmware-sim: {} frames {WIDTH}x{HEIGHT}, ", frames.len())?;
    match (network.is_some(), loc.config().semantics) {
        (true, Some(scheme)) => writeln!(
            out,
            "int8 network {} + semantic ORB ({:?} weights) + stereo + tracker ({:?} association)",
            crate::embedded::MODEL_NAME,
            scheme,
            loc.config().tracker.association,
        )?,
        _ => writeln!(out, "ORB + stereo + tracker, semantics off")?,
    }
    let mut hash = Fnv1a::new();
    let mut s = RunSummary {
        frames: 0,
        tracking: 0,
        lost: 0,
        hash: 0,
        moved_m: 0.0,
        gt_moved_m: 0.0,
        max_err_t_m: 0.0,
        max_err_r_deg: 0.0,
    };
    let (mut first, mut gt_first) = ([0.0; 12], [0.0; 12]);
    for (i, f) in frames.iter().enumerate() {
        let o = loc
            .process_raw(f.left, f.right, f.timestamp_s, network.as_deref_mut())
            .map_err(|err| RunError::Frame { frame: i, err })?;
        if let (true, Some(labels)) = (network.is_some(), loc.labels()) {
            write_labels_comment(out, i, labels)?;
        }
        let row = pose_row(&o.report.t_wc);
        if i == 0 {
            (first, gt_first) = (row, f.gt_pose);
        }
        let err = pose_error(&row, &f.gt_pose);
        write_frame_comment(out, i, &o, err)?;
        write_pose_line(out, &row)?;
        for x in row {
            hash.write_f64(x);
        }
        s.frames += 1;
        s.tracking += u32::from(o.report.state == TrackState::Tracking);
        s.lost += u32::from(o.report.lost);
        s.max_err_t_m = s.max_err_t_m.max(err.0);
        s.max_err_r_deg = s.max_err_r_deg.max(err.1);
        s.moved_m = pose_error(&row, &first).0;
        s.gt_moved_m = pose_error(&f.gt_pose, &gt_first).0;
        after_frame(out, i)?;
    }
    s.hash = hash.finish();
    writeln!(
        out,
        "# summary: frames {} tracking {} lost {} moved_m {:.4} gt_moved_m {:.4} \
         max_err_t_m {:.4} max_err_r_deg {:.4} tracked {}",
        s.frames,
        s.tracking,
        s.lost,
        s.moved_m,
        s.gt_moved_m,
        s.max_err_t_m,
        s.max_err_r_deg,
        if s.tracked() { "yes" } else { "no" },
    )?;
    writeln!(out, "fnv1a64 {:016x}", s.hash)?;
    Ok(s)
}

/// [`run_frames`] over [`crate::embedded::FRAMES`].
///
/// # Errors
/// As [`run_frames`].
pub fn run_embedded<W, H>(
    loc: &mut Localiser,
    network: Option<&mut Network<'_>>,
    out: &mut W,
    after_frame: H,
) -> Result<RunSummary, RunError>
where
    W: Write + ?Sized,
    H: FnMut(&mut W, usize) -> fmt::Result,
{
    run_frames(loc, &crate::embedded::FRAMES, network, out, after_frame)
}
