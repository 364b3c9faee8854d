//! Messages to core types and back. Pure functions: no state, no logging.

use glam::{DQuat, DVec2, DVec3};
use lidar_har_core::geometry::Pose2;
use lidar_har_core::localiser::LocaliserOutput;
use lidar_har_core::map::{MapError, MapGeometry, OccupancyMap};
use lidar_har_core::scan::Scan;
use lidar_har_core::tracker::PersonEstimate;
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::geometry_msgs::{
    Point, Point32, Pose, PoseWithCovariance, PoseWithCovarianceStamped, Quaternion, Transform,
    Vector3,
};
use lidar_har_msgs::lidar_har_msgs::HumanObservation;
use lidar_har_msgs::nav_msgs::OccupancyGrid;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::{ColorRGBA, Header};
use lidar_har_msgs::visualization_msgs::{Marker, MarkerArray};

/// The scan's geometry and ranges, stamped with its header time.
pub fn scan_from_msg(msg: &LaserScan) -> Scan {
    Scan {
        stamp_ns: msg.header.stamp.to_nanos(),
        angle_min: msg.angle_min,
        angle_increment: msg.angle_increment,
        time_increment: msg.time_increment,
        range_min: msg.range_min,
        range_max: msg.range_max,
        ranges: msg.ranges.clone(),
    }
}

/// The planar part of a 3D pose (x, y and the heading about +z).
pub fn pose2_from_pose(pose: &Pose) -> Pose2 {
    Pose2::new(pose.position.x, pose.position.y, pose.orientation.yaw())
}

/// The planar part of a transform.
pub fn pose2_from_transform(t: &Transform) -> Pose2 {
    Pose2::new(t.translation.x, t.translation.y, t.rotation.yaw())
}

/// `scan` as seen from its Lidar turned upside down: each beam at the opposite angle, in the
/// same order, so measured at the same time.
pub fn mirrored_scan(scan: Scan) -> Scan {
    Scan {
        angle_min: -scan.angle_min,
        angle_increment: -scan.angle_increment,
        ..scan
    }
}

/// A transform between two frames in space, so that a chain of them composes as tf2
/// composes it before it is laid into the plane of the scans: a Lidar mounted upside down
/// through a chain of rolled frames is only seen as such in the whole.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpatialTransform {
    pub translation: DVec3,
    /// Unit length; not finite when the message's quaternion has no direction (all zeros),
    /// which tf2 refuses too.
    pub rotation: DQuat,
}

impl SpatialTransform {
    pub const IDENTITY: Self = Self {
        translation: DVec3::ZERO,
        rotation: DQuat::IDENTITY,
    };

    pub fn from_msg(t: &Transform) -> Self {
        let q = t.rotation;
        Self {
            translation: DVec3::new(t.translation.x, t.translation.y, t.translation.z),
            rotation: DQuat::from_xyzw(q.x, q.y, q.z, q.w).normalize(),
        }
    }

    /// A planar pose as a transform in the plane of the scans.
    pub fn from_pose2(pose: Pose2) -> Self {
        Self {
            translation: DVec3::new(pose.x, pose.y, 0.0),
            rotation: DQuat::from_rotation_z(pose.theta),
        }
    }

    /// `self` followed by `child`, the pose of `child`'s frame in `self`'s parent.
    pub fn compose(&self, child: &Self) -> Self {
        Self {
            translation: self.translation + self.rotation * child.translation,
            rotation: self.rotation * child.rotation,
        }
    }

    pub fn inverse(&self) -> Self {
        let rotation = self.rotation.inverse();
        Self {
            translation: rotation * -self.translation,
            rotation,
        }
    }

    /// The transform laid into the plane of the scans (z up, REP-103): the position, the
    /// heading of the child's x axis, and how the child's z axis lies.
    pub fn in_scan_plane(&self) -> PlanarTransform {
        let x_axis = self.rotation * DVec3::X;
        let z_up = (self.rotation * DVec3::Z).z;
        PlanarTransform {
            pose: Pose2::new(
                self.translation.x,
                self.translation.y,
                x_axis.y.atan2(x_axis.x),
            ),
            mirrored: z_up < 0.0,
            tilt_rad: z_up.abs().min(1.0).acos(),
        }
    }
}

/// A [`SpatialTransform`] in the plane of the scans.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarTransform {
    pub pose: Pose2,
    /// The child's z axis points down (a Lidar mounted upside down): its scans turn the other
    /// way ([`mirrored_scan`]) before `pose` places them.
    pub mirrored: bool,
    /// The angle of the child's z axis from the vertical (up, or down when mirrored), rad:
    /// a tilted Lidar's scan plane meets the floor, or passes over people.
    pub tilt_rad: f64,
}

/// An OccupancyGrid as the localiser's map; cells above `occupied_thresh` (0..1) are obstacles.
pub fn map_from_grid(grid: &OccupancyGrid, occupied_thresh: f64) -> Result<OccupancyMap, MapError> {
    let geometry = MapGeometry {
        resolution: f64::from(grid.info.resolution),
        origin: pose2_from_pose(&grid.info.origin),
        width: grid.info.width as usize,
        height: grid.info.height as usize,
    };
    OccupancyMap::from_grid_values(geometry, &grid.data, occupied_thresh)
}

/// Variance reported for what the localiser does not estimate (height, tilt, heading):
/// large, so consumers treat it as unknown (REP-145 style).
const UNKNOWN_VARIANCE: f64 = 1e6;

/// Below this speed the heading of the person is unknown and left at zero.
const HEADING_MIN_SPEED_MPS: f64 = 0.2;

fn point(p: DVec2) -> Point {
    Point::new(p.x, p.y, 0.0)
}

fn person_pose(person: &PersonEstimate) -> Pose {
    let heading = if person.velocity.length() >= HEADING_MIN_SPEED_MPS {
        person.velocity.to_angle()
    } else {
        0.0
    };
    Pose {
        position: point(person.position),
        orientation: Quaternion::from_yaw(heading),
    }
}

/// `/human/pose`: the person's position with its covariance (x, y from the filter).
pub fn pose_msg(
    output: &LocaliserOutput,
    person: &PersonEstimate,
    frame_id: &str,
) -> PoseWithCovarianceStamped {
    PoseWithCovarianceStamped {
        header: Header::new(Time::from_nanos(output.stamp_ns), frame_id),
        pose: PoseWithCovariance {
            pose: person_pose(person),
            covariance: planar_covariance(person.covariance),
        },
    }
}

/// A 6x6 pose covariance from the covariance of (x, y); z and the rotations unknown.
pub fn planar_covariance(xy: [[f64; 2]; 2]) -> [f64; 36] {
    let mut covariance = [0.0; 36];
    covariance[0] = xy[0][0];
    covariance[1] = xy[0][1];
    covariance[6] = xy[1][0];
    covariance[7] = xy[1][1];
    for i in [14, 21, 28, 35] {
        covariance[i] = UNKNOWN_VARIANCE;
    }
    covariance
}

/// `/human/observation`: the person's state and points for the classifier.
pub fn observation_msg(
    output: &LocaliserOutput,
    person: &PersonEstimate,
    frame_id: &str,
) -> HumanObservation {
    let c = person.covariance;
    HumanObservation {
        header: Header::new(Time::from_nanos(output.stamp_ns), frame_id),
        track_id: u32::try_from(person.track_id).unwrap_or(u32::MAX),
        visible: person.visible,
        seconds_since_seen: person.unseen_s as f32,
        position: point(person.position),
        velocity: Vector3::new(person.velocity.x, person.velocity.y, 0.0),
        covariance: [c[0][0], c[0][1], c[1][0], c[1][1]],
        sensor_position: point(output.laser_pose.position()),
        points: person
            .points
            .iter()
            .map(|p| Point32::new(p.x as f32, p.y as f32, 0.0))
            .collect(),
    }
}

/// Height of the cylinder drawn for the person, m.
const PERSON_HEIGHT_M: f64 = 1.7;

/// `/human/markers`: a cylinder at the person (green when seen, orange when predicted
/// through an occlusion) and their points, both in the namespace `person`; always led by a
/// DELETEALL of that namespace, so a lost person and their old points disappear from rviz2
/// (rviz2 applies a DELETEALL that names a namespace to that namespace only, and the
/// classifier's markers on the same topic live in others).
pub fn markers_msg(output: &LocaliserOutput, frame_id: &str) -> MarkerArray {
    let header = Header::new(Time::from_nanos(output.stamp_ns), frame_id);
    let mut markers = vec![Marker {
        header: header.clone(),
        ns: "person".into(),
        action: Marker::DELETEALL,
        ..Marker::default()
    }];
    if let Some(person) = &output.person {
        let color = if person.visible {
            ColorRGBA::new(0.1, 0.8, 0.2, 0.6)
        } else {
            ColorRGBA::new(1.0, 0.6, 0.0, 0.4)
        };
        let mut pose = person_pose(person);
        pose.position.z = PERSON_HEIGHT_M / 2.0;
        markers.push(Marker {
            header: header.clone(),
            ns: "person".into(),
            id: 0,
            r#type: Marker::CYLINDER,
            action: Marker::ADD,
            pose,
            scale: Vector3::new(0.5, 0.5, PERSON_HEIGHT_M),
            color,
            ..Marker::default()
        });
        if !person.points.is_empty() {
            markers.push(Marker {
                header,
                ns: "person".into(),
                id: 1,
                r#type: Marker::POINTS,
                action: Marker::ADD,
                pose: Pose::default(),
                scale: Vector3::new(0.05, 0.05, 0.0),
                color: ColorRGBA::new(1.0, 0.1, 0.1, 1.0),
                points: person.points.iter().map(|&p| point(p)).collect(),
                ..Marker::default()
            });
        }
    }
    MarkerArray { markers }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use lidar_har_core::map::MAP_SERVER_OCCUPIED_THRESH;
    use lidar_har_msgs::nav_msgs::MapMetaData;
    use std::f64::consts::PI;

    fn output(visible: bool) -> LocaliserOutput {
        LocaliserOutput {
            stamp_ns: 1_500_000_000,
            laser_pose: Pose2::new(1.0, 2.0, 0.0),
            last_beam_pose: Pose2::new(1.0, 2.0, 0.0),
            foreground_points: 3,
            clusters: 1,
            person: Some(PersonEstimate {
                track_id: 7,
                position: DVec2::new(3.0, 4.0),
                velocity: DVec2::new(0.0, 1.0),
                covariance: [[0.01, 0.0], [0.0, 0.02]],
                visible,
                points: if visible {
                    vec![DVec2::new(3.0, 3.9), DVec2::new(3.1, 3.9)]
                } else {
                    vec![]
                },
                unseen_s: if visible { 0.0 } else { 0.5 },
            }),
        }
    }

    #[test]
    fn person_messages_carry_the_estimate() {
        let out = output(true);
        let person = out.person.as_ref().unwrap();
        let pose = pose_msg(&out, person, "map");
        assert_eq!(
            pose.header.stamp,
            Time {
                sec: 1,
                nanosec: 500_000_000
            }
        );
        assert_eq!(pose.pose.pose.position, Point::new(3.0, 4.0, 0.0));
        assert!((pose.pose.pose.orientation.yaw() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(
            (pose.pose.covariance[0], pose.pose.covariance[7]),
            (0.01, 0.02)
        );
        let obs = observation_msg(&out, person, "map");
        assert_eq!(obs.track_id, 7);
        assert!(obs.visible);
        assert_eq!(obs.points.len(), 2);
        assert_eq!(obs.sensor_position, Point::new(1.0, 2.0, 0.0));
        let markers = markers_msg(&out, "map");
        let kinds: Vec<i32> = markers.markers.iter().map(|m| m.r#type).collect();
        assert_eq!(markers.markers[0].action, Marker::DELETEALL);
        assert_eq!(&kinds[1..], &[Marker::CYLINDER, Marker::POINTS]);
        // The DELETEALL clears only its namespace in rviz2: everything it must clear is in it.
        assert!(
            markers
                .markers
                .iter()
                .all(|m| m.ns == markers.markers[0].ns)
        );
    }

    #[test]
    fn without_a_person_markers_only_clear() {
        let mut out = output(false);
        assert_eq!(
            markers_msg(&out, "map").markers.len(),
            2,
            "predicted: cylinder, no points"
        );
        out.person = None;
        let markers = markers_msg(&out, "map");
        assert_eq!(markers.markers.len(), 1);
        assert_eq!(markers.markers[0].action, Marker::DELETEALL);
    }

    /// `q` as a message's quaternion.
    pub(crate) fn quaternion(q: DQuat) -> Quaternion {
        Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        }
    }

    /// A chain of static transforms composed in space, as tf2 composes it: a Lidar rolled
    /// upside down through one frame and turned in the next is mirrored, with the heading of
    /// its x axis; the roll and the turn in one transform give the same.
    #[test]
    fn an_upside_down_chain_lies_mirrored_in_the_scan_plane() {
        let transform = |x: f64, rotation: DQuat| Transform {
            translation: Vector3::new(x, 0.0, 0.3),
            rotation: quaternion(rotation),
        };
        let flip = SpatialTransform::from_msg(&transform(0.2, DQuat::from_rotation_x(PI)));
        let turn = SpatialTransform::from_msg(&transform(0.1, DQuat::from_rotation_z(0.5)));
        let chain = flip.compose(&turn).in_scan_plane();
        assert!(chain.mirrored && chain.tilt_rad < 1e-9, "{chain:?}");
        assert!((chain.pose.x - 0.3).abs() < 1e-12, "{chain:?}");
        assert!((chain.pose.theta + 0.5).abs() < 1e-12, "{chain:?}");
        let one = transform(
            0.3,
            DQuat::from_rotation_x(PI) * DQuat::from_rotation_z(0.5),
        );
        let one = SpatialTransform::from_msg(&one).in_scan_plane();
        assert!(one.mirrored && (one.pose.theta - chain.pose.theta).abs() < 1e-12);
        // Upright, a transform is its planar part; tilted, it says by how much.
        let upright = SpatialTransform::from_msg(&transform(0.2, DQuat::from_rotation_z(0.5)));
        let planar = upright.in_scan_plane();
        assert!(!planar.mirrored && planar.tilt_rad < 1e-9);
        assert!((planar.pose.theta - 0.5).abs() < 1e-12);
        let pitched = transform(0.2, DQuat::from_rotation_y(0.1));
        let tilt = SpatialTransform::from_msg(&pitched)
            .in_scan_plane()
            .tilt_rad;
        assert!((tilt - 0.1).abs() < 1e-9, "{tilt}");
        // The inverse undoes it.
        let back = flip.compose(&turn).compose(&flip.compose(&turn).inverse());
        assert!(back.translation.length() < 1e-12 && back.rotation.w.abs() > 1.0 - 1e-12);
    }

    #[test]
    fn a_mirrored_scan_points_each_beam_the_other_way() {
        let scan = Scan {
            stamp_ns: 1,
            angle_min: -1.0,
            angle_increment: 0.5,
            time_increment: 0.001,
            range_min: 0.1,
            range_max: 10.0,
            ranges: vec![1.0, 2.0, 3.0],
        };
        let mirrored = mirrored_scan(scan.clone());
        for beam in 0..3 {
            assert_eq!(mirrored.beam_angle(beam), -scan.beam_angle(beam));
        }
        assert_eq!(
            (mirrored.ranges, mirrored.time_increment),
            (scan.ranges, scan.time_increment)
        );
    }

    #[test]
    fn occupancy_grid_becomes_a_map() {
        let grid = OccupancyGrid {
            info: MapMetaData {
                resolution: 0.5,
                width: 3,
                height: 1,
                origin: Pose {
                    position: Point::new(1.0, 0.0, 0.0),
                    orientation: Quaternion::IDENTITY,
                },
                ..MapMetaData::default()
            },
            data: vec![0, 100, -1],
            ..OccupancyGrid::default()
        };
        let map = map_from_grid(&grid, MAP_SERVER_OCCUPIED_THRESH).unwrap();
        assert_eq!(map.distance_to_obstacle(DVec2::new(1.75, 0.25)), Some(0.0));
        assert_eq!(map.distance_to_obstacle(DVec2::new(1.25, 0.25)), Some(0.5));
        let mut short = grid.clone();
        short.data.pop();
        assert!(matches!(
            map_from_grid(&short, MAP_SERVER_OCCUPIED_THRESH),
            Err(MapError::CellCount { .. })
        ));
    }
}
