//! The real recording `leg_tracker_demo_stationary` in both storages: 1265 scans of 512
//! ranges, identical between MCAP and sqlite3, `inf` and `NaN` preserved bit for bit; and
//! `lidar-har bag info` reports it right. Skips with a message when ../shared is absent.

use lidar_har_bag::BagReader;
use lidar_har_e2e::{lidar_har, shared_real_data};
use lidar_har_msgs::sensor_msgs::LaserScan;

fn scans(dir: &std::path::Path) -> Vec<(i64, LaserScan, Vec<u8>)> {
    let reader = BagReader::open(dir).unwrap_or_else(|e| panic!("{e}"));
    reader
        .messages_on(&["/scan"])
        .unwrap()
        .map(|m| {
            let m = m.unwrap_or_else(|e| panic!("{e}"));
            let scan: LaserScan = reader.decode(&m).unwrap_or_else(|e| panic!("{e}"));
            (m.log_time_ns, scan, m.data)
        })
        .collect()
}

#[test]
fn both_storages_hold_the_same_1265_scans() {
    let Some(real) = shared_real_data() else {
        return;
    };
    let base = real.join("leg_tracker_demo_stationary");
    let mcap = scans(&base.join("mcap"));
    let sqlite = scans(&base.join("sqlite3"));
    assert_eq!(mcap.len(), 1265);
    assert_eq!(sqlite.len(), 1265);
    let (mut infs, mut nans) = (0usize, 0usize);
    for ((t1, a, raw1), (t2, b, raw2)) in mcap.iter().zip(&sqlite) {
        assert_eq!(t1, t2);
        assert_eq!(raw1, raw2, "identical CDR bytes at {t1}");
        assert_eq!(a.ranges.len(), 512);
        assert_eq!(a.header, b.header);
        for (x, y) in a.ranges.iter().zip(&b.ranges) {
            assert_eq!(x.to_bits(), y.to_bits());
        }
        infs += a.ranges.iter().filter(|r| r.is_infinite()).count();
        nans += a.ranges.iter().filter(|r| r.is_nan()).count();
    }
    // The README: about 337 of 512 ranges are +inf and about 3.5 are NaN per scan.
    let per_scan_inf = infs as f64 / 1265.0;
    let per_scan_nan = nans as f64 / 1265.0;
    assert!(
        (300.0..380.0).contains(&per_scan_inf),
        "{per_scan_inf} inf per scan"
    );
    assert!(
        (1.0..10.0).contains(&per_scan_nan),
        "{per_scan_nan} NaN per scan"
    );
    assert!(mcap.windows(2).all(|w| w[0].0 <= w[1].0), "log-time order");
    // Re-encoding a decoded scan gives the recorded bytes back (inf/NaN payloads included).
    assert_eq!(lidar_har_msgs::encode(&mcap[10].1).unwrap(), mcap[10].2);
}

#[test]
fn bag_info_prints_the_counts() {
    let Some(real) = shared_real_data() else {
        return;
    };
    for storage in ["mcap", "sqlite3"] {
        let dir = real.join("leg_tracker_demo_stationary").join(storage);
        let out = lidar_har()
            .args(["bag", "info"])
            .arg(&dir)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{text}{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            text.contains(&format!("Storage id:        {storage}")),
            "{text}"
        );
        assert!(text.contains("Messages:          1265"), "{text}");
        assert!(text.contains("Duration:          125.989004529s"), "{text}");
        assert!(
            text.contains("Topic: /scan | Type: sensor_msgs/msg/LaserScan | Count: 1265"),
            "{text}"
        );
    }
}

#[test]
fn bag_info_rejects_what_is_not_a_bag() {
    let tmp = tempfile::tempdir().unwrap();
    let not_bag = tmp.path().join("notes.txt");
    std::fs::write(&not_bag, "hello").unwrap();
    for path in [
        tmp.path().to_path_buf(),
        not_bag,
        tmp.path().join("missing"),
    ] {
        let out = lidar_har()
            .args(["bag", "info"])
            .arg(&path)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(
            err.contains(&path.display().to_string()) && !err.contains("panicked"),
            "{err}"
        );
    }
}
