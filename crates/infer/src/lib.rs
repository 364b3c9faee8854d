//! lidar_har infer crate.
