//! lidar_har sim crate.
