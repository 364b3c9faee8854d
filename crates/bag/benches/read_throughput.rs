//! Read + decode throughput of a 10-minute, 20 Hz, 720-beam LaserScan bag (12,000 messages)
//! in MCAP (uncompressed, zstd, lz4) and sqlite3, on one core; writer throughput; peak memory
//! (VmHWM) of each read, reset just before it, to show reading does not grow with the bag.
//! Run: `cargo bench -p lidar-har-bag --bench read_throughput`.

use std::path::Path;
use std::time::Instant;

use lidar_har_bag::{BagReader, BagWriter, Compression, StorageId, WriterOptions};
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::qos::QosProfile;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;

const SCANS: u32 = 12_000; // 10 min at 20 Hz
const BEAMS: usize = 720;

fn scan(i: u32) -> LaserScan {
    let ranges = (0..BEAMS)
        .map(|b| match (i as usize + b) % 97 {
            0 => f32::INFINITY,
            1 => f32::NAN,
            k => 0.2 + k as f32 * 0.05,
        })
        .collect();
    LaserScan {
        header: Header {
            stamp: Time {
                sec: (i / 20) as i32,
                nanosec: (i % 20) * 50_000_000,
            },
            frame_id: "laser".into(),
        },
        angle_min: -std::f32::consts::PI,
        angle_max: std::f32::consts::PI,
        angle_increment: 2.0 * std::f32::consts::PI / BEAMS as f32,
        time_increment: 0.05 / BEAMS as f32,
        scan_time: 0.05,
        range_min: 0.15,
        range_max: 12.0,
        ranges,
        intensities: vec![47.0; BEAMS],
    }
}

/// The process's peak resident memory (VmHWM), in KiB.
fn peak_rss_kib() -> Result<u64, String> {
    let status = std::fs::read_to_string("/proc/self/status")
        .map_err(|e| format!("/proc/self/status: {e}"))?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .ok_or_else(|| "/proc/self/status: no VmHWM line".to_string())
}

/// Resets the peak resident memory to the current one (Linux >= 4.0). Without it each read's
/// peak would be hidden under the writers' earlier one: the sqlite3 writer holds up to a
/// 64 MiB transaction in memory, as much as a reader that loaded the whole bag would need.
fn reset_peak_rss() -> Result<(), String> {
    std::fs::write("/proc/self/clear_refs", "5")
        .map_err(|e| format!("cannot reset it, /proc/self/clear_refs: {e}"))
}

/// "before -> after KiB" around a read whose peak was reset first, or "n/a" and why.
fn peak_during(before: Result<u64, String>) -> String {
    match (before, peak_rss_kib()) {
        (Ok(before), Ok(after)) => format!("{before} -> {after} KiB"),
        (Err(e), _) | (_, Err(e)) => format!("n/a: {e}"),
    }
}

/// Encodes and writes the scans one by one (no payloads kept).
fn write(dir: &Path, storage: StorageId, compression: Compression) {
    let start = Instant::now();
    let options = WriterOptions {
        storage,
        compression,
        ..WriterOptions::default()
    };
    let mut writer = BagWriter::create(dir, options).expect("create bag");
    let topic = writer
        .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
        .expect("add topic");
    let mut bytes = 0;
    for i in 0..SCANS {
        let payload = lidar_har_msgs::encode(&scan(i)).expect("encode");
        bytes += payload.len();
        writer
            .write(
                topic,
                1_700_000_000_000_000_000 + i64::from(i) * 50_000_000,
                &payload,
            )
            .expect("write");
    }
    writer.finish().expect("finish");
    let secs = start.elapsed().as_secs_f64();
    let file_size: u64 = std::fs::read_dir(dir)
        .expect("list bag")
        .filter_map(|e| e.ok()?.metadata().ok())
        .map(|m| m.len())
        .sum();
    println!(
        "encode+write {:<12}: {:>9.0} msg/s {:>7.1} MB/s  ({:.1} MB on disk)",
        format!(
            "{}/{}",
            storage.as_str(),
            format!("{compression:?}").to_lowercase()
        ),
        f64::from(SCANS) / secs,
        bytes as f64 / secs / 1e6,
        file_size as f64 / 1e6
    );
}

fn read(dir: &Path, label: &str) {
    let before = reset_peak_rss().and_then(|()| peak_rss_kib());
    let start = Instant::now();
    let reader = BagReader::open(dir).expect("open bag");
    let (mut count, mut bytes, mut beams) = (0usize, 0usize, 0usize);
    for message in reader.messages().expect("messages") {
        let message = message.expect("message");
        let scan: LaserScan = reader.decode(&message).expect("decode");
        count += 1;
        bytes += message.data.len();
        beams += scan.ranges.len();
    }
    let secs = start.elapsed().as_secs_f64();
    assert_eq!(count, SCANS as usize);
    assert_eq!(beams, SCANS as usize * BEAMS);
    println!(
        "read+decode {label:<13}: {:>9.0} msg/s {:>7.1} MB/s  (VmHWM {})",
        count as f64 / secs,
        bytes as f64 / secs / 1e6,
        peak_during(before)
    );
}

fn main() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let one = lidar_har_msgs::encode(&scan(0)).expect("encode").len();
    println!(
        "{SCANS} LaserScans x {BEAMS} beams, {one} bytes each ({:.1} MB of CDR); one core; {} build",
        (one * SCANS as usize) as f64 / 1e6,
        if cfg!(debug_assertions) {
            "debug"
        } else {
            "release"
        }
    );
    let cases = [
        ("mcap", StorageId::Mcap, Compression::None),
        ("mcap_zstd", StorageId::Mcap, Compression::Zstd),
        ("mcap_lz4", StorageId::Mcap, Compression::Lz4),
        ("sqlite3", StorageId::Sqlite3, Compression::None),
    ];
    for (name, storage, compression) in cases {
        write(&tmp.path().join(name), storage, compression);
    }
    for (name, _, _) in cases {
        read(&tmp.path().join(name), name);
    }
}
