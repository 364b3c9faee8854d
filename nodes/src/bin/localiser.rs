//! `localiser`: finds and tracks the person in each scan. Subscribes /scan, /odom (best
//! effort), /map, /tf, /tf_static; publishes /human/pose, /human/observation and /human/markers. The work is the
//! pipeline's localiser stage, the same code `lidar-har run` runs over a bag.
//!
//! Parameters: `config` (a `config/localiser.yaml`-format file; empty = defaults),
//! `map_file` (a map_server YAML; empty = wait for /map), `learned_background` (no map: learn
//! the room from the first scans of a fixed Lidar), `moving` (odometry moves the robot;
//! false: a fixed Lidar, which its transforms place in the map, `map -> odom -> base_link`
//! on /tf_static or /tf, else the map origin, warned about), `wait_for_map_to_odom` (a moving
//! robot's scans are skipped until the first `map -> odom` on /tf or /tf_static, instead of
//! placed as if `map` were `odom`; a late first one is warned about), `map_transient_local`
//! (/map is asked transient local, as map_server and our replay latch it; false: reliable
//! volatile, for a publisher that does not latch it, such as cartographer's
//! occupancy_grid_node, which a transient-local subscription never matches; nav2's
//! `map_subscribe_transient_local`). A background still not
//! learned twice `background.learn_duration_s` after the first scan is warned about.
//! A scan stamped after the newest odometry waits for it up to the configuration's
//! `odometry.max_wait_s` on this node's monotonic wall clock (also with `use_sim_time`, which
//! changes no stamp: outputs keep their scan's); scans still waiting at shutdown are published.

use std::process::ExitCode;
use std::time::{Duration, Instant};

use lidar_har::{NodeInfo, Outputs, Shutdown, bad_parameter, optional_path};
use lidar_har_msgs::qos::{Durability, History, QosProfile, Reliability};
use lidar_har_msgs::topics::{self, TopicSpec};
use lidar_har_pipeline::{LocaliserStage, PipelineError, RoomSource, Step, files};
use lidar_har_ros::{NodeSetup, ParamDecl, ParamValue, Parameters, RosError};

fn main() -> ExitCode {
    lidar_har::run(
        &NodeInfo {
            name: "localiser",
            about: "finds and tracks the person in each Lidar scan against the room",
            parameters: decls,
        },
        localise,
    )
}

fn decls() -> Vec<ParamDecl> {
    use ParamValue as V;
    vec![
        ParamDecl::new(
            "config",
            V::String(String::new()),
            "localiser configuration file; empty = defaults",
        ),
        ParamDecl::new(
            "map_file",
            V::String(String::new()),
            "map_server YAML of the room; empty = use /map",
        ),
        ParamDecl::new(
            "learned_background",
            V::Bool(false),
            "no map: learn the room from the first scans",
        ),
        ParamDecl::new(
            "moving",
            V::Bool(true),
            "the Lidar moves with the robot (needs /odom or /tf)",
        ),
        ParamDecl::new(
            "wait_for_map_to_odom",
            V::Bool(false),
            "skip scans until the first map -> odom (AMCL, SLAM) instead of taking map = odom",
        ),
        ParamDecl::new(
            "map_transient_local",
            V::Bool(true),
            "subscribe /map transient local (latched, map_server); false: volatile, for a /map \
             publisher that does not latch it (cartographer's occupancy_grid_node)",
        ),
    ]
}

fn stage(p: &Parameters) -> Result<LocaliserStage, RosError> {
    let config = match optional_path(p, "config")? {
        Some(path) => {
            files::load_localiser_config(&path).map_err(|e| bad_parameter("config", e))?
        }
        None => Default::default(),
    };
    let learned = p.bool("learned_background")?;
    let room = match (optional_path(p, "map_file")?, learned) {
        (Some(_), true) => {
            return Err(bad_parameter(
                "map_file",
                "cannot be combined with learned_background:=true",
            ));
        }
        (Some(path), false) => {
            RoomSource::Map(files::load_map(&path).map_err(|e| bad_parameter("map_file", e))?)
        }
        (None, true) => RoomSource::LearnedBackground,
        (None, false) => RoomSource::MapTopic,
    };
    let (moving, wait_for_map_to_odom) = (p.bool("moving")?, p.bool("wait_for_map_to_odom")?);
    if learned && (moving || wait_for_map_to_odom) {
        // `robot.yaml` sets moving: a map-less user who adds only learned_background got a
        // robot's scans placed as a fixed Lidar's without a word (27 tracks for one person).
        let ignored = match (moving, wait_for_map_to_odom) {
            (true, true) => "moving:=true and wait_for_map_to_odom:=true are",
            (true, false) => "moving:=true is",
            _ => "wait_for_map_to_odom:=true is",
        };
        log::warn!(
            "learned_background:=true takes the Lidar as fixed where it learned the room: \
             odometry and map -> odom are not used, so {ignored} ignored (set them false for \
             a fixed Lidar; a robot that moves needs a map: map_file or /map)"
        );
    }
    let mut stage =
        LocaliserStage::new(config, room, moving).map_err(|e| bad_parameter("config", e))?;
    stage.set_wait_for_map_to_odom(wait_for_map_to_odom);
    Ok(stage)
}

/// The QoS the localiser asks for on an input. The contract gives what a topic is asked
/// with; /odom is asked best effort, which matches reliable and best-effort publishers
/// alike (robot bases such as the iRobot Create 3 publish their sensor topics best effort,
/// and a reliable subscription would never match them). A lost odometry message only
/// widens the interpolation between its neighbours. /tf_static is kept 100 deep, as tf2's
/// static listener keeps it: joining late, the node gets every static publisher's latched
/// message at once (robot_state_publisher's and a static_transform_publisher's), and a
/// depth of 1 would keep only the last, perhaps not the one with the Lidar's mount.
/// /map is asked volatile unless `map_transient_local`: a transient-local subscription does
/// not match a volatile publisher (DDS QoS matching), and a volatile one matches both, but
/// gets no map published before it joined.
fn subscription_qos(spec: &TopicSpec, map_transient_local: bool) -> QosProfile {
    if spec.name == topics::MAP.name && !map_transient_local {
        QosProfile {
            durability: Durability::Volatile,
            ..spec.subscribed
        }
    } else if spec.name == topics::ODOM.name {
        QosProfile {
            reliability: Reliability::BestEffort,
            ..spec.subscribed
        }
    } else if spec.name == topics::TF_STATIC.name {
        QosProfile {
            history: History::KeepLast(TF_STATIC_DEPTH),
            ..spec.subscribed
        }
    } else {
        spec.subscribed
    }
}

/// tf2_ros's `StaticListenerQoS` depth.
const TF_STATIC_DEPTH: u32 = 100;

fn localise(shutdown: &Shutdown) -> anyhow::Result<()> {
    let setup = NodeSetup::new("localiser").parameters(decls()).prepare()?;
    // The configuration and the map are checked before the node joins the graph: a bad one
    // used to be found with the participant up, after the DDS stack's discovery warnings.
    let mut stage = stage(setup.params())?;
    let map_transient_local = setup.params().bool("map_transient_local")?;
    let node = lidar_har::join(setup)?;
    let inputs = LocaliserStage::INPUTS
        .into_iter()
        .map(|spec| {
            let sub = node.subscriber(
                spec.name,
                spec.type_name,
                subscription_qos(&spec, map_transient_local),
            )?;
            Ok((spec.name, sub))
        })
        .collect::<Result<Vec<_>, RosError>>()?;
    let outputs = Outputs::new(&node, &LocaliserStage::OUTPUTS)?;
    // Receive time for the stage's wait for odometry: this node's monotonic clock.
    let clock = Instant::now();
    let now_ns = || clock.elapsed().as_nanos() as i64;
    let mut unusable = UnusableMessages::default();
    let mut batch = Vec::new();
    while !shutdown.requested() {
        for (topic, sub) in &inputs {
            while let Some(sample) = sub.try_take()? {
                batch.push((*topic, sample));
            }
        }
        if batch.is_empty() {
            // A scan waiting for odometry goes when its wait is over, message or not.
            unusable.publish(&outputs, stage.release_expired(now_ns()))?;
            node.wait(idle_wait(stage.wait_deadline_ns(), now_ns()))?;
            continue;
        }
        // Messages of different topics that arrived together are used in publication order
        // (odometry before the scan it positions); without source times (the rcl backend),
        // scans go last, after the odometry, map and transforms that came with them.
        batch.sort_by_key(|(topic, sample)| {
            (
                sample.source_time_ns.unwrap_or(0),
                *topic == topics::SCAN.name,
            )
        });
        let received_ns = now_ns();
        for (topic, sample) in batch.drain(..) {
            unusable.publish(&outputs, stage.handle(topic, &sample.bytes, received_ns))?;
        }
    }
    // Scans still waiting for odometry are localised with what there is, not lost.
    unusable.publish(&outputs, stage.finish())?;
    log::info!(
        "localiser: stopped; {} undecodable messages",
        unusable.count
    );
    Ok(())
}

/// Longest wait for messages before the loop looks at shutdown again.
const POLL_INTERVAL: Duration = Duration::from_millis(100);

/// How long to wait for messages: until the oldest scan waiting for odometry stops waiting
/// (`deadline_ns`, on the clock that gives `now_ns`), at most [`POLL_INTERVAL`].
fn idle_wait(deadline_ns: Option<i64>, now_ns: i64) -> Duration {
    deadline_ns.map_or(POLL_INTERVAL, |deadline_ns| {
        let left_ns = u64::try_from(deadline_ns.saturating_sub(now_ns)).unwrap_or(0);
        POLL_INTERVAL.min(Duration::from_nanos(left_ns))
    })
}

/// Counts the messages the stage could not use, and logs them sparingly.
#[derive(Default)]
struct UnusableMessages {
    count: u64,
}

impl UnusableMessages {
    /// Publishes what the stage produced, or counts why it could not.
    fn publish(
        &mut self,
        outputs: &Outputs,
        step: Result<Step, PipelineError>,
    ) -> anyhow::Result<()> {
        match step {
            Ok(step) => outputs.publish(&step.outgoing)?,
            Err(e) => {
                self.count += 1;
                if self.count.is_power_of_two() {
                    log::warn!("{e} ({} undecodable messages so far)", self.count);
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_idle_wait_ends_when_a_scan_stops_waiting_for_odometry() {
        assert_eq!(idle_wait(None, 0), POLL_INTERVAL);
        assert_eq!(
            idle_wait(Some(30_000_000), 10_000_000),
            Duration::from_millis(20)
        );
        assert_eq!(idle_wait(Some(5), 10), Duration::ZERO);
        assert_eq!(idle_wait(Some(i64::MAX), 0), POLL_INTERVAL);
    }

    #[test]
    fn odom_and_scan_are_asked_best_effort_tf_static_deep_and_the_rest_as_the_contract() {
        let odom = subscription_qos(&topics::ODOM, true);
        assert_eq!(odom.reliability, Reliability::BestEffort);
        assert_eq!(odom.history, topics::ODOM.qos.history);
        let tf_static = subscription_qos(&topics::TF_STATIC, true);
        assert_eq!(tf_static.history, History::KeepLast(100));
        assert_eq!(
            (tf_static.reliability, tf_static.durability),
            (Reliability::Reliable, Durability::TransientLocal)
        );
        // Offered reliable by our driver; asked best effort, matching any driver.
        let scan = subscription_qos(&topics::SCAN, true);
        assert_eq!(scan.reliability, Reliability::BestEffort);
        for spec in [topics::SCAN, topics::MAP, topics::TF] {
            assert_eq!(
                subscription_qos(&spec, true),
                spec.subscribed,
                "{}",
                spec.name
            );
        }
    }

    #[test]
    fn map_transient_local_false_asks_map_volatile_and_nothing_else_changes() {
        let map = subscription_qos(&topics::MAP, false);
        assert_eq!(map.durability, Durability::Volatile);
        assert_eq!(
            (map.reliability, map.history),
            (Reliability::Reliable, History::KeepLast(1))
        );
        for spec in [topics::SCAN, topics::ODOM, topics::TF, topics::TF_STATIC] {
            assert_eq!(
                subscription_qos(&spec, false),
                subscription_qos(&spec, true),
                "{}",
                spec.name
            );
        }
    }
}
