//! The ROS-free, I/O-free heart of lidar_har: geometry, scans, maps, the localiser and
//! tracker, image representations, windows, fall-alert logic and metrics. Everything here is
//! plain computation on plain data, tested without ROS, files or threads.

pub mod activity;
pub mod background;
pub mod classifier;
pub mod cluster;
pub mod fall;
pub mod geometry;
pub mod localiser;
pub mod localiser_accuracy;
pub mod map;
pub mod metrics;
pub mod pose_head;
pub mod representation;
pub mod scan;
pub mod stats;
pub mod sweep;
pub mod tracker;
pub mod truth_match;
pub mod visibility;
