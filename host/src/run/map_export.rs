//! `semloc run --export-map FILE.ply`: the map points a run built, with their class, as a PLY
//! point cloud (CloudCompare, MeshLab, Open3D, rerun and Blender read it).
//!
//! The core keeps a bounded local map: keyframes and their points are evicted as the car drives
//! on. The collector therefore looks at the map after every frame and remembers every point it
//! has seen, keyed by its slot and the keyframe that created it (a slot is reused only by a
//! point of a later keyframe), with the point's latest position (bundle adjustment moves it).
//! A point is exported when it was confirmed: seen by at least [`MIN_OBSERVATIONS`] keyframes
//! at some time, as ORB-SLAM2 keeps only such points. Points the mapper culled before their
//! second observation are not exported.
//!
//! Coordinates are the world frame of the run: the first left camera, x right, y down,
//! z forward, metres (the frame `trajectory.txt` is in). The class is the most frequent class of
//! the point's keyframe observations (CamVid ids, see `semloc_core::seg::CLASS_NAMES`), 255 when
//! the run had no labels; the colour is the CamVid palette's, grey for 255.

use core::fmt::Write as _;
use std::collections::BTreeMap;
use std::path::Path;

use semloc_core::map::Map;

use crate::nn::segment::CAMVID_PALETTE;

use super::{write_atomic, RunError};

/// Keyframe observations a point needs (at some time) to be exported.
pub const MIN_OBSERVATIONS: u8 = 2;

/// Class id of a point without class evidence.
pub const NO_CLASS: u8 = 255;

/// One exported map point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapPoint {
    /// Latest position in the world frame (m).
    pub p_w: [f64; 3],
    /// Most frequent class of its keyframe observations, [`NO_CLASS`] without labels.
    pub class: u8,
    /// Most keyframe observations it had at once.
    pub observations: u8,
    /// Frame index at which it was first in the map.
    pub first_frame: u32,
    /// Frame index at which it was last in the map.
    pub last_frame: u32,
    /// Frames whose final matches (outliers of the pose solve dropped) included it: how long
    /// it was tracked (ORB-SLAM2's `nFound`; a fused point adds its duplicate's).
    pub found: u32,
    /// Frames in which tracking predicted it in view (ORB-SLAM2's `nVisible`).
    pub visible: u32,
}

/// Remembers every point of the map over a run (see the module docs).
#[derive(Debug, Default)]
pub struct MapCollector {
    points: BTreeMap<(u32, u32), MapPoint>,
}

impl MapCollector {
    /// An empty collector.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records the map as it is after frame `frame`.
    pub fn observe(&mut self, map: &Map, frame: u32) {
        for (id, lm) in map.landmarks().iter().enumerate() {
            if !lm.alive {
                continue;
            }
            let class = lm.class().unwrap_or(NO_CLASS);
            let p = [lm.p_w.x, lm.p_w.y, lm.p_w.z];
            self.points
                .entry((id as u32, lm.created_kf))
                .and_modify(|m| {
                    m.p_w = p;
                    m.class = class;
                    m.observations = m.observations.max(lm.n_obs);
                    m.last_frame = frame;
                    m.found = m.found.max(lm.found);
                    m.visible = m.visible.max(lm.visible);
                })
                .or_insert(MapPoint {
                    p_w: p,
                    class,
                    observations: lm.n_obs,
                    first_frame: frame,
                    last_frame: frame,
                    found: lm.found,
                    visible: lm.visible,
                });
        }
    }

    /// The points to export ([`MIN_OBSERVATIONS`] or more), in slot order.
    pub fn confirmed(&self) -> impl Iterator<Item = &MapPoint> {
        self.points.values().filter(|m| m.observations >= MIN_OBSERVATIONS && finite(m.p_w))
    }

    /// Every point seen, confirmed or not.
    pub fn seen(&self) -> usize {
        self.points.len()
    }

    /// The confirmed points as an ASCII PLY file (see the module docs for the fields).
    pub fn to_ply(&self) -> String {
        let pts: Vec<&MapPoint> = self.confirmed().collect();
        let mut s = String::with_capacity(64 * pts.len() + 512);
        s.push_str("ply\nformat ascii 1.0\n");
        s.push_str(
            "comment semloc map points: world = first left camera (x right, y down, z forward), metres\n",
        );
        s.push_str("comment class: CamVid id (0 sky .. 10 bicyclist), 255 = no labels\n");
        let _ = writeln!(s, "element vertex {}", pts.len());
        for p in ["float x", "float y", "float z", "uchar red", "uchar green", "uchar blue"] {
            let _ = writeln!(s, "property {p}");
        }
        for p in [
            "uchar class",
            "uchar observations",
            "uint first_frame",
            "uint last_frame",
            "uint found",
            "uint visible",
        ] {
            let _ = writeln!(s, "property {p}");
        }
        s.push_str("end_header\n");
        for m in pts {
            let [r, g, b] =
                CAMVID_PALETTE.get(usize::from(m.class)).copied().unwrap_or([160, 160, 160]);
            let _ = writeln!(
                s,
                "{:.4} {:.4} {:.4} {r} {g} {b} {} {} {} {} {} {}",
                m.p_w[0],
                m.p_w[1],
                m.p_w[2],
                m.class,
                m.observations,
                m.first_frame,
                m.last_frame,
                m.found,
                m.visible
            );
        }
        s
    }

    /// Writes [`Self::to_ply`] to `path` (atomically: a temporary file renamed into place).
    ///
    /// # Errors
    /// [`RunError::Write`] naming `path`.
    pub fn write_ply(&self, path: &Path) -> Result<usize, RunError> {
        write_atomic(path, self.to_ply().as_bytes())?;
        Ok(self.confirmed().count())
    }
}

fn finite(p: [f64; 3]) -> bool {
    p.iter().all(|v| v.is_finite())
}
