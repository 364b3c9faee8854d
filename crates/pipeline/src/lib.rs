//! lidar_har pipeline crate.
