//! KITTI dataset readers (odometry and raw layouts).
