//! lidar_har bag crate.
