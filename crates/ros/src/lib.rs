//! lidar_har ros crate.
