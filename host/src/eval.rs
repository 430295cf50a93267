//! Trajectory evaluation: KITTI devkit t_rel/r_rel and Umeyama-aligned ATE.
