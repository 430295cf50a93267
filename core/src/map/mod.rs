//! The map: the bounded window of keyframes and landmarks ([`Window`]) and its maintenance on
//! a keyframe (landmark creation, local bundle adjustment, outlier observation removal and
//! landmark culling, in `mapping`).
//!
//! This is ORB-SLAM2's `LocalMapping` in a bounded window: the tracker hands the map a frame,
//! its pose and, per feature, the landmark it was matched to and the association weight
//! (1 for nearest-neighbour association, the E-step weight under EM, paper §3.3); the map
//! decides everything else. A covisibility graph and triangulation between keyframes belong
//! here when they come.
//!
//! Memory: about 4.2 MiB, fixed at compile time: the window (2.6 MiB: 10 keyframes × 2048
//! features and 8192 landmarks) plus the bundle-adjustment scratch (1.6 MiB: observations of
//! every window keyframe, points and their backup); the tracker's memory test prints both.

pub(crate) mod mapping;
mod window;

pub(crate) use mapping::{LocalMap, MappingParams, NewKeyframe};
pub use window::{KeyFrame, Landmark, Window, MAX_KEYFRAMES, MAX_LANDMARKS, NO_LANDMARK};

use crate::frame::{level_inv_sigma2, Feature};
use crate::geom::Se3;
use crate::optim::Measurement;

/// The optimisation measurement of a feature: the same for the pose solve, EM, RANSAC and
/// bundle adjustment.
#[inline]
pub(crate) fn measurement(f: &Feature) -> Measurement {
    Measurement {
        u: f64::from(f.x),
        v: f64::from(f.y),
        ur: if f.is_stereo() { f64::from(f.ur) } else { -1.0 },
        inv_sigma2: level_inv_sigma2(f.level),
    }
}

/// `t` with its rotation block projected back onto SO(3) (unchanged if that fails, which
/// only a corrupted pose can make happen).
#[inline]
pub(crate) fn renormalize(t: &Se3) -> Se3 {
    t.normalized().unwrap_or(*t)
}
