//! The localiser on a real recording (`../shared/data/real/leg_tracker_demo_stationary`,
//! both storages): a stationary Lidar, no map, people walking through. With a background
//! learned from the first seconds: no panic, no NaN in any output, people found as tracks.
//! Skips when the shared data is absent.

use lidar_har_bag::BagReader;
use lidar_har_e2e::shared_real_data;
use lidar_har_msgs::geometry_msgs::PoseWithCovarianceStamped;
use lidar_har_msgs::lidar_har_msgs::HumanObservation;
use lidar_har_pipeline::bag_run::{RunOptions, RunSummary, run_bag};

fn run(
    storage: &str,
) -> Option<(
    RunSummary,
    Vec<HumanObservation>,
    Vec<PoseWithCovarianceStamped>,
)> {
    let bag = shared_real_data()?
        .join("leg_tracker_demo_stationary")
        .join(storage);
    let out = tempfile::tempdir().unwrap();
    let out_dir = out.path().join("out");
    let summary = run_bag(&bag, &out_dir, RunOptions::default()).expect("run over the real bag");
    let reader = BagReader::open(&out_dir).expect("output bag opens");
    let mut observations = Vec::new();
    let mut poses = Vec::new();
    for m in reader.messages().unwrap() {
        let m = m.unwrap();
        match &*m.topic {
            "/human/observation" => {
                observations.push(reader.decode::<HumanObservation>(&m).unwrap())
            }
            "/human/pose" => poses.push(reader.decode::<PoseWithCovarianceStamped>(&m).unwrap()),
            _ => {}
        }
    }
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(written["scans"], 1265);
    Some((summary, observations, poses))
}

#[test]
fn people_walking_past_a_stationary_lidar_are_tracked_in_both_storages() {
    let Some((mcap, observations, poses)) = run("mcap") else {
        return;
    };
    let Some((sqlite, _, _)) = run("sqlite3") else {
        return;
    };
    eprintln!(
        "real recording (mcap): {}",
        serde_json::to_string_pretty(&mcap).unwrap()
    );

    assert_eq!(mcap.room, "learned_background");
    assert_eq!(mcap.scans, 1265);
    assert!(
        mcap.scans_learning > 20 && mcap.scans_learning < 40,
        "3 s at 10 Hz: {}",
        mcap.scans_learning
    );
    assert_eq!(
        mcap.scans_localised + mcap.scans_learning,
        mcap.scans,
        "no scan skipped: {:?}",
        mcap.warnings
    );
    assert!(
        mcap.warnings.get("nan_ranges").copied().unwrap_or(0) > 0,
        "the recording has NaN ranges"
    );
    assert!(
        mcap.tracks_confirmed >= 2,
        "people walk through: {} tracks",
        mcap.tracks_confirmed
    );
    assert!(
        mcap.visible_ratio > 0.2,
        "visible in {:.0} % of scans",
        100.0 * mcap.visible_ratio
    );

    // Both storages hold the same scans, so they give the same tracks.
    assert_eq!(
        (
            mcap.scans_localised,
            mcap.tracks_confirmed,
            mcap.visible_ratio
        ),
        (
            sqlite.scans_localised,
            sqlite.tracks_confirmed,
            sqlite.visible_ratio
        )
    );

    assert!(!observations.is_empty());
    for o in &observations {
        let numbers = [
            o.position.x,
            o.position.y,
            o.velocity.x,
            o.velocity.y,
            o.covariance[0],
            o.covariance[3],
        ];
        assert!(numbers.iter().all(|v| v.is_finite()), "NaN in {o:?}");
        assert!(o.points.iter().all(|p| p.x.is_finite() && p.y.is_finite()));
        assert_eq!(o.visible, !o.points.is_empty());
        assert_eq!(o.header.frame_id, "laser");
        // The Lidar's range is 5.6 m: the person cannot be farther (plus the prediction).
        assert!(o.position.x.hypot(o.position.y) < 8.0, "{:?}", o.position);
    }
    assert!(
        poses
            .iter()
            .all(|p| p.pose.covariance.iter().all(|c| c.is_finite()))
    );
    let time = mcap.scan_time_us.unwrap();
    eprintln!(
        "time per scan: median {:.1} us, p99 {:.1} us (debug build)",
        time.median, time.p99
    );
}
