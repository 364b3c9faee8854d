//! Recording a simulation as a rosbag2 directory (MCAP), with the map beside it in
//! map_server format. Everything written derives from the scene and the seed: no wall clock,
//! and the bag writer never flushes on a timer, so the same inputs give the same bytes.

use std::path::{Path, PathBuf};
use std::time::Duration;

use lidar_har_bag::{BagWriter, MetadataVersion, WriterOptions};
use lidar_har_core::geometry::Pose2;
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::geometry_msgs::{
    Point, Pose, PoseStamped, PoseWithCovariance, Quaternion, Transform, TransformStamped, Twist,
    TwistWithCovariance, Vector3,
};
use lidar_har_msgs::lidar_har_msgs::Activity as ActivityMsg;
use lidar_har_msgs::nav_msgs::{MapMetaData, OccupancyGrid, Odometry};
use lidar_har_msgs::rosgraph_msgs::Clock;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_msgs::topics;

use crate::map::{OccupancyMap, check_map_server_free};
use crate::simulator::{Frame, Simulator};

// The bag's frame names, following REP 105 (`map` -> `odom` -> `base_link` -> `laser`), so
// that the nodes' default `FrameConfig` reads the bag unconfigured.
/// The fixed world frame: the map and the ground truth.
pub const MAP_FRAME: &str = "map";
/// Odometry's frame; the simulated odometry has no drift, so `map` -> `odom` is identity.
pub const ODOM_FRAME: &str = "odom";
/// The robot's body.
pub const BASE_FRAME: &str = "base_link";
/// The Lidar's own frame, mounted on `base_link` by `/tf_static`.
pub const LASER_FRAME: &str = "laser";

/// Why a recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error(transparent)]
    Bag(#[from] lidar_har_bag::BagError),
    #[error("cannot write the map beside the bag in {path}: {cause}")]
    Map { path: String, cause: std::io::Error },
}

/// What was recorded.
#[derive(Debug, Clone)]
pub struct RecordSummary {
    pub bag_dir: PathBuf,
    pub frames: u64,
    pub messages: u64,
    pub first_stamp_ns: u64,
    pub last_stamp_ns: u64,
}

fn time(ns: u64) -> Time {
    Time::from_nanos(ns as i64)
}

fn pose_msg(p: Pose2) -> Pose {
    Pose::from_xy_yaw(p.x, p.y, p.theta)
}

fn transform(stamp: Time, parent: &str, child: &str, p: Pose2, z: f64) -> TransformStamped {
    TransformStamped {
        header: Header::new(stamp, parent),
        child_frame_id: child.to_string(),
        transform: Transform {
            translation: Vector3 { x: p.x, y: p.y, z },
            rotation: Quaternion::from_yaw(p.theta),
        },
    }
}

/// The map as a `nav_msgs/OccupancyGrid` in the `map` frame.
pub fn occupancy_grid_msg(map: &OccupancyMap, stamp_ns: u64) -> OccupancyGrid {
    OccupancyGrid {
        header: Header::new(time(stamp_ns), MAP_FRAME),
        info: MapMetaData {
            map_load_time: time(stamp_ns),
            resolution: map.resolution as f32,
            width: map.width,
            height: map.height,
            origin: Pose {
                position: Point {
                    x: map.origin.x,
                    y: map.origin.y,
                    z: 0.0,
                },
                orientation: Quaternion::IDENTITY,
            },
        },
        data: map.data.clone(),
    }
}

/// The frame's scan as a `sensor_msgs/LaserScan` in the `laser` frame.
pub fn laser_scan_msg(sim: &Simulator, frame: &Frame) -> LaserScan {
    let g = sim.scan_geometry();
    LaserScan {
        header: Header::new(time(frame.stamp_ns), LASER_FRAME),
        angle_min: g.angle_min as f32,
        angle_max: g.angle_max() as f32,
        angle_increment: g.angle_increment as f32,
        // 0 unless the scene's Lidar sweeps: then beam i is measured i * time_increment after
        // the stamp, which is negative (see docs/simulator.md).
        time_increment: g.time_increment as f32,
        scan_time: g.scan_time as f32,
        range_min: g.range_min as f32,
        range_max: g.range_max as f32,
        ranges: frame.ranges.clone(),
        intensities: Vec::new(),
    }
}

/// Runs `sim` to its end into a new rosbag2 directory `out` (MCAP, metadata version 9), and
/// writes `out/map.pgm` + `out/map.yaml`. `on_frame` sees every frame (progress, renders).
pub fn record(
    sim: &mut Simulator,
    out: &Path,
    map_resolution: f64,
    on_frame: impl FnMut(&Frame),
) -> Result<RecordSummary, RecordError> {
    record_as(
        sim,
        out,
        map_resolution,
        MetadataVersion::default(),
        on_frame,
    )
}

/// [`record`] with the bag's metadata version chosen: 8 for a bag that ROS 2 Humble or Iron
/// must read.
pub fn record_as(
    sim: &mut Simulator,
    out: &Path,
    map_resolution: f64,
    metadata_version: MetadataVersion,
    mut on_frame: impl FnMut(&Frame),
) -> Result<RecordSummary, RecordError> {
    // The bag writer refuses only a bag already there: a map from an earlier run in the same
    // folder must stop the run before the bag's files are created beside it.
    check_map_server_free(out, "map").map_err(|cause| RecordError::Map {
        path: out.display().to_string(),
        cause,
    })?;
    let options = WriterOptions {
        flush_interval: Duration::MAX,
        metadata_version,
        ..WriterOptions::default()
    };
    let mut bag = BagWriter::create(out, options)?;
    let scan_t = bag.add_contract_topic(&topics::SCAN)?;
    let odom_t = bag.add_contract_topic(&topics::ODOM)?;
    let tf_t = bag.add_contract_topic(&topics::TF)?;
    let tf_static_t = bag.add_contract_topic(&topics::TF_STATIC)?;
    let map_t = bag.add_contract_topic(&topics::MAP)?;
    let clock_t = bag.add_contract_topic(&topics::CLOCK)?;
    let has_person = sim.scene().person.is_some();
    let truth_t = if has_person {
        Some((
            bag.add_contract_topic(&topics::GROUND_TRUTH_POSE)?,
            bag.add_contract_topic(&topics::GROUND_TRUTH_ACTIVITY)?,
        ))
    } else {
        None
    };

    let start = sim.start_ns();
    let map = OccupancyMap::from_world(sim.world(), map_resolution);
    map.write_map_server(out, "map")
        .map_err(|source| RecordError::Map {
            path: out.display().to_string(),
            cause: source,
        })?;
    let t0 = time(start);
    let log0 = start as i64;
    bag.write_message(map_t, log0, &occupancy_grid_msg(&map, start))?;
    let laser_z = sim.scene().robot.lidar_height;
    let mount = sim.lidar_mount();
    bag.write_message(
        tf_static_t,
        log0,
        &TFMessage {
            transforms: vec![transform(t0, BASE_FRAME, LASER_FRAME, mount, laser_z)],
        },
    )?;

    let mut frame = Frame::default();
    let mut summary = RecordSummary {
        bag_dir: out.to_path_buf(),
        frames: 0,
        messages: 2,
        first_stamp_ns: start,
        last_stamp_ns: start,
    };
    while sim.step_into(&mut frame) {
        let stamp = time(frame.stamp_ns);
        let log = frame.stamp_ns as i64;
        bag.write_message(clock_t, log, &Clock { clock: stamp })?;
        bag.write_message(
            tf_t,
            log,
            &TFMessage {
                transforms: vec![
                    transform(stamp, MAP_FRAME, ODOM_FRAME, Pose2::IDENTITY, 0.0),
                    transform(stamp, ODOM_FRAME, BASE_FRAME, frame.robot, 0.0),
                ],
            },
        )?;
        let odom = Odometry {
            header: Header::new(stamp, ODOM_FRAME),
            child_frame_id: BASE_FRAME.to_string(),
            pose: PoseWithCovariance {
                pose: pose_msg(frame.robot),
                ..PoseWithCovariance::default()
            },
            twist: TwistWithCovariance {
                twist: Twist {
                    linear: Vector3 {
                        x: frame.robot_twist.linear,
                        y: 0.0,
                        z: 0.0,
                    },
                    angular: Vector3 {
                        x: 0.0,
                        y: 0.0,
                        z: frame.robot_twist.angular,
                    },
                },
                ..TwistWithCovariance::default()
            },
        };
        bag.write_message(odom_t, log, &odom)?;
        bag.write_message(scan_t, log, &laser_scan_msg(sim, &frame))?;
        summary.messages += 4;
        if let (Some((pose_t, activity_t)), Some(person)) = (truth_t, &frame.person) {
            bag.write_message(
                pose_t,
                log,
                &PoseStamped {
                    header: Header::new(stamp, MAP_FRAME),
                    pose: pose_msg(person.pose),
                },
            )?;
            let class = person.activity.index();
            let mut probabilities = vec![0.0f32; lidar_har_core::activity::Activity::COUNT];
            probabilities[class] = 1.0;
            let msg = ActivityMsg {
                header: Header::new(stamp, MAP_FRAME),
                activity: class as u8,
                label: person.activity.label().to_string(),
                confidence: 1.0,
                probabilities,
            };
            bag.write_message(activity_t, log, &msg)?;
            summary.messages += 2;
        }
        summary.frames += 1;
        summary.last_stamp_ns = frame.stamp_ns;
        on_frame(&frame);
    }
    bag.finish()?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn refuses_a_folder_holding_a_map_before_writing_anything() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/hall.yaml");
        let mut scene = Scene::load(&path).unwrap();
        scene.duration = 0.5;
        for existing in ["map.pgm", "map.yaml"] {
            let dir = tempfile::tempdir().unwrap();
            std::fs::write(dir.path().join(existing), "mine").unwrap();
            let mut sim = Simulator::new(scene.clone(), 1).unwrap();
            let err = record(&mut sim, dir.path(), 0.05, |_| {}).unwrap_err();
            let want = format!("{} already exists", dir.path().join(existing).display());
            assert!(err.to_string().ends_with(&want), "{err}");
            let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
            assert_eq!(left.len(), 1, "only {existing} is there");
            assert_eq!(std::fs::read(dir.path().join(existing)).unwrap(), b"mine");
        }
    }

    /// A recording for a Humble or Iron robot: the simulator wrote only version 9, which
    /// their `ros2 bag info` and `play` cannot parse.
    #[test]
    fn records_the_metadata_version_asked_for() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/hall.yaml");
        let mut scene = Scene::load(&path).unwrap();
        scene.duration = 0.2;
        for version in [MetadataVersion::V8, MetadataVersion::V9] {
            let dir = tempfile::tempdir().unwrap();
            let mut sim = Simulator::new(scene.clone(), 1).unwrap();
            record_as(&mut sim, dir.path(), 0.05, version, |_| {}).unwrap();
            let reader = lidar_har_bag::BagReader::open(dir.path()).unwrap();
            assert_eq!(reader.metadata().metadata_version, Some(version.number()));
            assert_eq!(
                reader.topic(topics::SCAN.name).unwrap().offered_qos[0].to_profile(),
                Some(topics::SCAN.qos),
                "{version:?}"
            );
        }
    }

    /// A bag records what the robot's publishers offer, which `ros2 bag play` offers again:
    /// /scan was recorded best effort (the localiser's subscription), so a reliable subscriber
    /// (rclcpp's default) of a played simulator bag got nothing.
    #[test]
    fn records_scan_offered_reliable_as_the_driver_offers_it() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scenes/hall.yaml");
        let mut scene = Scene::load(&path).unwrap();
        scene.duration = 0.2;
        let dir = tempfile::tempdir().unwrap();
        let mut sim = Simulator::new(scene, 1).unwrap();
        record(&mut sim, dir.path(), 0.05, |_| {}).unwrap();
        let reader = lidar_har_bag::BagReader::open(dir.path()).unwrap();
        let scan = reader.topic("/scan").unwrap().offered_qos[0]
            .to_profile()
            .unwrap();
        assert_eq!(scan.reliability, lidar_har_msgs::qos::Reliability::Reliable);
    }
}
