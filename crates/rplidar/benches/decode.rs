//! Decode throughput and rotation-to-scan latency (filled in below).
fn main() {}
