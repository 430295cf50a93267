//! The map: a persistent, bounded store of keyframes, landmarks with all their observations
//! and the covisibility graph ([`Map`], in `store`); the local map a frame is tracked against
//! ([`LocalSet`], in `local`); and its maintenance on a keyframe (`mapping`: stereo and
//! triangulated landmarks, fusion, local bundle adjustment with fixed covisible neighbours,
//! landmark and keyframe culling).
//!
//! This is ORB-SLAM2's `Map` + `LocalMapping` in fixed memory, run inline: the tracker hands
//! the map a frame, its pose and, per feature, the landmark it was matched to and the
//! association weight (1 for nearest-neighbour association, the E-step weight under EM,
//! paper §3.3); the map decides everything else.
//!
//! Memory: about 17 MiB, fixed at compile time: the store (≈13 MiB: 64 keyframes × 2048
//! features, 16384 landmarks with up to 16 observations each) plus the bundle-adjustment
//! scratch (observations of up to 24 keyframes, points and their backup) and the local
//! landmark list; the tracker's memory test prints them.

mod local;
pub(crate) mod mapping;
mod store;

pub use local::{LocalSet, MAX_LOCAL_KEYFRAMES};
pub(crate) use mapping::{LocalMap, MappingParams, NewKeyframe};
pub use store::{
    KeyFrame, Landmark, Map, MapCounters, Obs, MAX_KEYFRAMES, MAX_LANDMARKS, MAX_OBS, NO_KF,
    NO_LANDMARK,
};

use crate::frame::{level_inv_sigma2, Feature};
use crate::geom::Se3;
use crate::optim::Measurement;

/// The optimisation measurement of a feature: the same for the pose solve, EM, RANSAC and
/// bundle adjustment. A stereo point farther than `far_m` is a monocular (bearing)
/// measurement, as in ORB-SLAM3: its disparity is a pixel or two, so its depth says little,
/// while its direction is what holds rotation.
#[inline]
pub(crate) fn measurement(f: &Feature, far_m: f32) -> Measurement {
    Measurement {
        u: f64::from(f.x),
        v: f64::from(f.y),
        ur: if f.is_stereo() && f.depth_m <= far_m { f64::from(f.ur) } else { -1.0 },
        inv_sigma2: level_inv_sigma2(f.level),
    }
}

/// The pyramid level a landmark last observed on `ref_level` at `ref_dist_m` is predicted to
/// appear on at distance `dist` (m): the projection search and fusion both use it.
#[inline]
pub(crate) fn predict_level(ref_level: u8, ref_dist_m: f32, dist: f64) -> i32 {
    if ref_dist_m > 0.0 && dist > 1e-6 {
        let d = crate::math::ln(f64::from(ref_dist_m) / dist) / crate::assoc::LN_SCALE;
        (i32::from(ref_level) + crate::math::roundf(d as f32) as i32).clamp(0, 7)
    } else {
        i32::from(ref_level)
    }
}

/// `t` with its rotation block projected back onto SO(3) (unchanged if that fails, which
/// only a corrupted pose can make happen).
#[inline]
pub(crate) fn renormalize(t: &Se3) -> Se3 {
    t.normalized().unwrap_or(*t)
}
