//! Trajectory files: KITTI pose files and TUM files.
