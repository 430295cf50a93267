//! Input and tracking health: what the ECU checks on every frame, and what it does about it.
//!
//! Checks, in order (the first four before any image processing, so a bad frame costs little):
//!
//! | check | detection | action |
//! |---|---|---|
//! | timestamp not after the last one | [`Detection::ClockBackwards`] | process the frame as one period later (re-base the clock) |
//! | gap of 1.5 … `max_coast + 1` periods | [`Detection::ClockGap`] | coast the tracker once per missing frame |
//! | larger gap | [`Detection::ClockJump`] | forget the motion model (map kept) |
//! | delivered bytes ≠ frame size | [`Detection::Truncated`] | reject the frame (coast) |
//! | left image hash = previous left's | [`Detection::Duplicate`] | reject (coast) |
//! | contrast (σ of a 1/49 sample) below `min_contrast` | [`Detection::Blank`] | reject (coast) |
//! | core error in the front end | [`Detection::FrontEnd`] | reject (coast) |
//! | fewer than `min_features` left key points | [`Detection::LowTexture`] | reject (coast) |
//! | stereo matches / key points below `stereo_rel_min` × the recent level | [`Detection::StereoImplausible`] | reject (coast) |
//! | the tracker lost the map | [`Detection::TrackingLost`] | the tracker re-initialised at the predicted pose |
//!
//! "Reject" means the tracker never sees the frame: a blank or desynchronised pair would
//! otherwise become a keyframe with wrong depths and poison the window. "Coast" advances the
//! constant-velocity prediction by one period ([`crate::Localiser::coast`]), so the next good
//! frame is searched where the camera should be. A frame is *good* when it was tracked (not
//! initialised from scratch, not lost) with at least `good_inliers` inliers; the recovery time
//! of a fault is the number of sensor frames from the fault to the next good frame.

use crate::report::Fnv1a;

/// One thing the ECU noticed about a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Detection {
    /// Timestamp not after the previous frame's.
    ClockBackwards,
    /// Frames missing (gap of 2 … `max_coast + 1` periods); the tracker coasted over them.
    ClockGap,
    /// Gap beyond what coasting can bridge; the motion model was dropped.
    ClockJump,
    /// The sensor delivered fewer bytes than a frame.
    Truncated,
    /// Same left image as the previous frame.
    Duplicate,
    /// No contrast (blank, saturated or covered camera).
    Blank,
    /// The core refused the frame.
    FrontEnd,
    /// Too few key points.
    LowTexture,
    /// Too few stereo matches for this scene: the pair does not belong together.
    StereoImplausible,
    /// The tracker lost the map and re-initialised.
    TrackingLost,
}

impl Detection {
    /// Every detection, in report order.
    pub const ALL: [Detection; 10] = [
        Self::ClockBackwards,
        Self::ClockGap,
        Self::ClockJump,
        Self::Truncated,
        Self::Duplicate,
        Self::Blank,
        Self::FrontEnd,
        Self::LowTexture,
        Self::StereoImplausible,
        Self::TrackingLost,
    ];

    /// Flag in a per-frame detection mask.
    pub const fn bit(self) -> u16 {
        1 << self as u16
    }

    /// Short name.
    pub const fn name(self) -> &'static str {
        match self {
            Self::ClockBackwards => "clock-backwards",
            Self::ClockGap => "clock-gap",
            Self::ClockJump => "clock-jump",
            Self::Truncated => "truncated",
            Self::Duplicate => "duplicate",
            Self::Blank => "blank",
            Self::FrontEnd => "front-end-error",
            Self::LowTexture => "low-texture",
            Self::StereoImplausible => "stereo-implausible",
            Self::TrackingLost => "tracking-lost",
        }
    }

    /// Whether the frame is rejected (never reaches the tracker).
    pub const fn rejects(self) -> bool {
        matches!(
            self,
            Self::Truncated
                | Self::Duplicate
                | Self::Blank
                | Self::FrontEnd
                | Self::LowTexture
                | Self::StereoImplausible
        )
    }
}

impl core::fmt::Display for Detection {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Thresholds of the health checks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HealthParams {
    /// Smallest standard deviation of the luma sample (grey levels) of a usable image.
    pub min_contrast: f32,
    /// Fewest left key points of a usable frame.
    pub min_features: u32,
    /// A timestamp step above this many periods means frames are missing.
    pub gap_factor: f64,
    /// Most missing frames bridged by coasting; beyond, the motion model is dropped.
    pub max_coast: u32,
    /// Stereo match share below this fraction of the recent level: the pair is implausible.
    pub stereo_rel_min: f32,
    /// Stereo match share below this is implausible whatever the recent level.
    pub stereo_abs_min: f32,
    /// Inliers of a good frame.
    pub good_inliers: u32,
}

impl Default for HealthParams {
    fn default() -> Self {
        Self {
            min_contrast: 3.0,
            min_features: 100,
            gap_factor: 1.5,
            max_coast: 3,
            stereo_rel_min: 0.8,
            stereo_abs_min: 0.05,
            good_inliers: 30,
        }
    }
}

/// What the clock check asks of the tracker.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockAction {
    /// Nothing.
    None,
    /// Coast over this many missing frames.
    Coast(u32),
    /// Forget the motion model.
    ForgetMotion,
}

/// The per-frame checks' memory: last timestamp, last image hash, recent stereo level.
#[derive(Clone, Copy, Debug)]
pub struct Monitor {
    params: HealthParams,
    last_ts: Option<f64>,
    last_hash: Option<u64>,
    stereo_level: Option<f32>,
}

impl Monitor {
    /// A monitor with `params`.
    pub fn new(params: HealthParams) -> Self {
        Self { params, last_ts: None, last_hash: None, stereo_level: None }
    }

    /// The thresholds.
    pub fn params(&self) -> &HealthParams {
        &self.params
    }

    /// Checks the timestamp against the last one (`period_s` nominal).
    pub fn check_clock(&mut self, ts: f64, period_s: f64) -> (Option<Detection>, ClockAction) {
        let Some(last) = self.last_ts else {
            self.last_ts = Some(ts);
            return (None, ClockAction::None);
        };
        let dt = ts - last;
        self.last_ts = Some(ts);
        if !dt.is_finite() || dt <= 0.0 {
            return (Some(Detection::ClockBackwards), ClockAction::None);
        }
        if dt <= self.params.gap_factor * period_s {
            return (None, ClockAction::None);
        }
        let missing = ((dt / period_s).round() as u64).saturating_sub(1);
        if missing <= u64::from(self.params.max_coast) {
            (Some(Detection::ClockGap), ClockAction::Coast(missing as u32))
        } else {
            (Some(Detection::ClockJump), ClockAction::ForgetMotion)
        }
    }

    /// Checks the delivered buffers (`frame_bytes` each): length, duplicate, contrast.
    pub fn check_images(
        &mut self,
        left: &[u8],
        right: &[u8],
        width: usize,
        frame_bytes: usize,
    ) -> Option<Detection> {
        if left.len() != frame_bytes || right.len() != frame_bytes {
            self.last_hash = None;
            return Some(Detection::Truncated);
        }
        let mut h = Fnv1a::new();
        h.write(left);
        let hash = h.finish();
        let dup = self.last_hash == Some(hash);
        self.last_hash = Some(hash);
        if dup {
            return Some(Detection::Duplicate);
        }
        if contrast(left, width) < self.params.min_contrast
            || contrast(right, width) < self.params.min_contrast
        {
            return Some(Detection::Blank);
        }
        None
    }

    /// Checks the front end's output: key points and the stereo match share. Updates the
    /// recent stereo level on accepted frames.
    pub fn check_front_end(&mut self, features: u32, stereo_matched: u32) -> Option<Detection> {
        if features < self.params.min_features {
            return Some(Detection::LowTexture);
        }
        let share = stereo_matched as f32 / features.max(1) as f32;
        let floor = self.stereo_level.map_or(self.params.stereo_abs_min, |l| {
            (l * self.params.stereo_rel_min).max(self.params.stereo_abs_min)
        });
        if share < floor {
            return Some(Detection::StereoImplausible);
        }
        self.stereo_level = Some(self.stereo_level.map_or(share, |l| 0.7 * l + 0.3 * share));
        None
    }
}

/// Standard deviation of every 7th pixel of every 7th row (grey levels).
pub fn contrast(img: &[u8], width: usize) -> f32 {
    let (mut n, mut s, mut s2) = (0u64, 0u64, 0u64);
    for row in img.chunks(width.max(1)).step_by(7) {
        for &p in row.iter().step_by(7) {
            n += 1;
            s += u64::from(p);
            s2 += u64::from(p) * u64::from(p);
        }
    }
    if n == 0 {
        return 0.0;
    }
    let mean = s as f64 / n as f64;
    let var = (s2 as f64 / n as f64 - mean * mean).max(0.0);
    var.sqrt() as f32
}

/// The degradation state machine: what the ECU does after a deadline overrun.
///
/// ```text
///            overrun                      (always)
/// Nominal ───────────► Degraded (1 frame) ────────► Nominal
///    ▲ └── in budget ──┘
/// ```
///
/// In `Degraded` the ECU (1) reuses the last frame's labels and weights instead of running the
/// network (semantic mode; the network is ≈ 3/4 of a frame's work) and (2) drops every frame
/// waiting in the ring but the newest (catch-up; the tracker coasts over them through the
/// clock-gap check). It returns to `Nominal` after one frame whatever that frame took, so the
/// labels are never more than one frame old.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// Full processing.
    #[default]
    Nominal,
    /// The previous frame overran.
    Degraded,
}

impl Mode {
    /// The mode of the next frame after a frame in `self` that did (or did not) overrun.
    pub fn next(self, overran: bool) -> Mode {
        match (self, overran) {
            (Mode::Nominal, true) => Mode::Degraded,
            _ => Mode::Nominal,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clock_checks() {
        let mut m = Monitor::new(HealthParams::default());
        assert_eq!(m.check_clock(0.0, 0.1), (None, ClockAction::None));
        assert_eq!(m.check_clock(0.105, 0.1), (None, ClockAction::None));
        assert_eq!(m.check_clock(0.3, 0.1), (Some(Detection::ClockGap), ClockAction::Coast(1)));
        assert_eq!(m.check_clock(0.2, 0.1).0, Some(Detection::ClockBackwards));
        assert_eq!(
            m.check_clock(3.0, 0.1),
            (Some(Detection::ClockJump), ClockAction::ForgetMotion)
        );
        assert_eq!(m.check_clock(f64::NAN, 0.1).0, Some(Detection::ClockBackwards));
    }

    #[test]
    fn image_checks() {
        let mut m = Monitor::new(HealthParams::default());
        let a: Vec<u8> = (0..64 * 48).map(|i| (i * 37 % 251) as u8).collect();
        let b: Vec<u8> = (0..64 * 48).map(|i| (i * 53 % 241) as u8).collect();
        assert_eq!(m.check_images(&a, &b, 64, a.len()), None);
        assert_eq!(m.check_images(&a, &b, 64, a.len()), Some(Detection::Duplicate));
        assert_eq!(m.check_images(&b[..10], &a, 64, a.len()), Some(Detection::Truncated));
        let zero = vec![0u8; a.len()];
        assert_eq!(m.check_images(&zero, &zero, 64, a.len()), Some(Detection::Blank));
        assert!(contrast(&a, 64) > 20.0, "{}", contrast(&a, 64));
        assert_eq!(contrast(&zero, 64), 0.0);
    }

    #[test]
    fn degradation_returns_to_nominal() {
        assert_eq!(Mode::Nominal.next(false), Mode::Nominal);
        assert_eq!(Mode::Nominal.next(true), Mode::Degraded);
        assert_eq!(Mode::Degraded.next(true), Mode::Nominal);
        assert_eq!(Mode::Degraded.next(false), Mode::Nominal);
    }

    #[test]
    fn stereo_plausibility_follows_the_recent_level() {
        let mut m = Monitor::new(HealthParams::default());
        assert_eq!(m.check_front_end(50, 40), Some(Detection::LowTexture));
        assert_eq!(m.check_front_end(1000, 600), None);
        assert_eq!(m.check_front_end(1000, 550), None);
        assert_eq!(m.check_front_end(1000, 400), Some(Detection::StereoImplausible));
        assert_eq!(m.check_front_end(1000, 20), Some(Detection::StereoImplausible));
    }
}
