//! CDR throughput of the message types on the hot paths: a 720-beam LaserScan (the paper's
//! Lidar), an Odometry and a HumanObservation with 40 points, per second of CPU time on one
//! core. Prints figures; asserts nothing.
//!
//!   cargo bench -p lidar-har-msgs --bench codec

use std::hint::black_box;
use std::time::{Duration, Instant};

use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::geometry_msgs::Point32;
use lidar_har_msgs::lidar_har_msgs::HumanObservation;
use lidar_har_msgs::nav_msgs::Odometry;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;
use lidar_har_msgs::{RosMessage, decode, encode};

/// CPU time this thread has run, from /proc/thread-self/schedstat (Linux); on a shared,
/// busy machine it measures one core's throughput where wall time would not.
fn thread_cpu_time() -> Option<Duration> {
    let stat = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let nanos: u64 = stat.split_whitespace().next()?.parse().ok()?;
    Some(Duration::from_nanos(nanos))
}

/// Runs `f` repeatedly for about `budget` of wall time and returns calls per second of CPU
/// time (of wall time where CPU time cannot be read).
fn rate(budget: Duration, mut f: impl FnMut()) -> f64 {
    let start = Instant::now();
    let cpu_start = thread_cpu_time();
    let mut calls = 0u64;
    while start.elapsed() < budget {
        for _ in 0..100 {
            f();
        }
        calls += 100;
    }
    let elapsed = match (cpu_start, thread_cpu_time()) {
        (Some(a), Some(b)) if b > a => b - a,
        _ => start.elapsed(),
    };
    calls as f64 / elapsed.as_secs_f64()
}

fn report<M: RosMessage>(label: &str, msg: &M) {
    let bytes = encode(msg).expect("encodes");
    let budget = Duration::from_secs(2);
    let decode_rate = rate(budget, || {
        black_box(decode::<M>(black_box(&bytes)).expect("decodes"));
    });
    let encode_rate = rate(budget, || {
        black_box(encode(black_box(msg)).expect("encodes"));
    });
    let mb = bytes.len() as f64 / 1e6;
    println!(
        "{label:<32} {:>6} B   decode {:>10.0} msg/s {:>7.0} MB/s   encode {:>10.0} msg/s {:>7.0} MB/s",
        bytes.len(),
        decode_rate,
        decode_rate * mb,
        encode_rate,
        encode_rate * mb
    );
}

fn main() {
    let header = Header::new(Time::from_nanos(1_700_000_000_123_456_789), "laser");
    let scan = LaserScan {
        header: header.clone(),
        angle_min: -std::f32::consts::PI,
        angle_max: std::f32::consts::PI,
        angle_increment: std::f32::consts::TAU / 720.0,
        time_increment: 0.05 / 720.0,
        scan_time: 0.05,
        range_min: 0.15,
        range_max: 12.0,
        ranges: (0..720)
            .map(|i| {
                if i % 25 == 0 {
                    f32::INFINITY
                } else {
                    1.0 + i as f32 * 0.01
                }
            })
            .collect(),
        intensities: vec![47.0; 720],
    };
    let odom = Odometry {
        header: header.clone(),
        child_frame_id: "base_link".into(),
        ..Default::default()
    };
    let observation = HumanObservation {
        header,
        visible: true,
        points: (0..40)
            .map(|i| Point32::new(2.0 + i as f32 * 0.01, 0.5, 0.0))
            .collect(),
        ..Default::default()
    };
    report("LaserScan (720 ranges + intensities)", &scan);
    report("Odometry", &odom);
    report("HumanObservation (40 points)", &observation);
}
