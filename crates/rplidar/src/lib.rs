//! lidar_har rplidar crate.
