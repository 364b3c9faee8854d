//! Shared plumbing of the lidar_har node binaries.
