//! `localiser`: finds and tracks the person in each scan. Subscribes /scan, /odom (best
//! effort), /map, /tf, /tf_static; publishes /human/pose, /human/observation and /human/markers. The work is the
//! pipeline's localiser stage, the same code `lidar-har run` runs over a bag.
//!
//! Parameters: `config` (a `config/localiser.yaml`-format file; empty = defaults),
//! `map_file` (a map_server YAML; empty = wait for /map), `learned_background` (no map: learn
//! the room from the first scans of a fixed Lidar), `moving` (odometry moves the robot).

use std::process::ExitCode;
use std::time::Duration;

use lidar_har::{NodeInfo, Outputs, Shutdown, bad_parameter, optional_path};
use lidar_har_msgs::qos::{QosProfile, Reliability};
use lidar_har_msgs::topics::{self, TopicSpec};
use lidar_har_pipeline::{LocaliserStage, RoomSource, files};
use lidar_har_ros::{Node, NodeSetup, ParamDecl, ParamValue, RosError};

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
    ]
}

fn stage(node: &Node) -> Result<LocaliserStage, RosError> {
    let p = node.params();
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
    LocaliserStage::new(config, room, p.bool("moving")?).map_err(|e| bad_parameter("config", e))
}

/// The QoS the localiser asks for on an input. The contract gives what a topic is offered
/// with; /odom is asked best effort, which matches reliable and best-effort publishers
/// alike (robot bases such as the iRobot Create 3 publish their sensor topics best effort,
/// and a reliable subscription would never match them). A lost odometry message only
/// widens the interpolation between its neighbours.
fn subscription_qos(spec: &TopicSpec) -> QosProfile {
    if spec.name == topics::ODOM.name {
        QosProfile {
            reliability: Reliability::BestEffort,
            ..spec.qos
        }
    } else {
        spec.qos
    }
}

fn localise(shutdown: &Shutdown) -> anyhow::Result<()> {
    let node = Node::new(NodeSetup::new("localiser").parameters(decls()))?;
    let mut stage = stage(&node)?;
    let inputs = LocaliserStage::INPUTS
        .into_iter()
        .map(|spec| {
            let sub = node.subscriber(spec.name, spec.type_name, subscription_qos(&spec))?;
            Ok((spec.name, sub))
        })
        .collect::<Result<Vec<_>, RosError>>()?;
    let outputs = Outputs::new(&node, &LocaliserStage::OUTPUTS)?;
    let mut decode_errors = 0u64;
    let mut batch = Vec::new();
    while !shutdown.requested() {
        for (topic, sub) in &inputs {
            while let Some(sample) = sub.try_take()? {
                batch.push((*topic, sample));
            }
        }
        if batch.is_empty() {
            node.wait(Duration::from_millis(100))?;
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
        for (topic, sample) in batch.drain(..) {
            match stage.handle(topic, &sample.bytes) {
                Ok(step) => outputs.publish(&step.outgoing)?,
                Err(e) => {
                    decode_errors += 1;
                    if decode_errors.is_power_of_two() {
                        log::warn!("{e} ({decode_errors} undecodable messages so far)");
                    }
                }
            }
        }
    }
    log::info!("localiser: stopped; {decode_errors} undecodable messages");
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn odom_is_asked_best_effort_and_the_rest_as_offered() {
        let odom = subscription_qos(&topics::ODOM);
        assert_eq!(odom.reliability, Reliability::BestEffort);
        assert_eq!(odom.history, topics::ODOM.qos.history);
        for spec in [topics::SCAN, topics::MAP, topics::TF, topics::TF_STATIC] {
            assert_eq!(subscription_qos(&spec), spec.qos, "{}", spec.name);
        }
    }
}
