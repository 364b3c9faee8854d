//! `replay`: plays a rosbag2 directory (MCAP or sqlite3) onto ROS 2 topics, like
//! `ros2 bag play`, with each topic's contract QoS (transient-local topics such as /map stay
//! available to late subscribers), and /clock from the bag's time line for `use_sim_time`.
//!
//! Parameters: `bag` (required), `rate` (1.0; 0 = as fast as possible), `loop`,
//! `start_offset` (s into the bag), `topics` (only these; empty = all), `publish_clock`,
//! `wait_for_subscriber` (a topic to wait on before playing, up to `wait_timeout` s),
//! `wait_for_all_acked` (s to wait at the end for reliable subscribers to acknowledge
//! everything, so the last messages are not lost when the process exits; 0 = don't wait).

use std::collections::HashMap;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use lidar_har::Shutdown;
use lidar_har_bag::BagReader;
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::qos::QosProfile;
use lidar_har_msgs::rosgraph_msgs::Clock;
use lidar_har_msgs::topics;
use lidar_har_ros::{Node, NodeSetup, ParamDecl, ParamValue, Publisher, RosError};

fn main() -> ExitCode {
    lidar_har::run("replay", play)
}

fn decls() -> Vec<ParamDecl> {
    use ParamValue as V;
    vec![
        ParamDecl::new(
            "bag",
            V::String(String::new()),
            "rosbag2 directory (or .mcap file) to play",
        ),
        ParamDecl::new(
            "rate",
            V::Double(1.0),
            "playback speed factor; 0 plays as fast as possible",
        ),
        ParamDecl::new("loop", V::Bool(false), "start again at the end"),
        ParamDecl::new(
            "start_offset",
            V::Double(0.0),
            "seconds into the bag to start at",
        ),
        ParamDecl::new(
            "topics",
            V::StringArray(Vec::new()),
            "topics to play; empty plays all",
        ),
        ParamDecl::new(
            "publish_clock",
            V::Bool(true),
            "publish /clock with the bag's time",
        ),
        ParamDecl::new(
            "wait_for_subscriber",
            V::String(String::new()),
            "topic whose subscriber to wait for",
        ),
        ParamDecl::new(
            "wait_timeout",
            V::Double(10.0),
            "seconds to wait for that subscriber",
        ),
        ParamDecl::new(
            "wait_for_all_acked",
            V::Double(2.0),
            "seconds to wait at the end for reliable subscribers to acknowledge all messages",
        ),
    ]
}

struct Settings {
    bag: String,
    rate: f64,
    looping: bool,
    start_offset_ns: i64,
    topics: Vec<String>,
    publish_clock: bool,
    wait_for: String,
    wait_timeout: Duration,
    acked_timeout: Duration,
}

impl Settings {
    fn from(node: &Node) -> Result<Self, RosError> {
        let p = node.params();
        let bag = p.string("bag")?;
        if bag.is_empty() {
            return Err(RosError::Parameter {
                name: "bag".into(),
                reason: "required: the bag directory to play".into(),
            });
        }
        let rate = p.f64_checked("rate", ">= 0 (0 = as fast as possible)", |v| v >= 0.0)?;
        let offset = p.f64_checked("start_offset", ">= 0 seconds", |v| v >= 0.0)?;
        let wait = p.f64_checked("wait_timeout", ">= 0 seconds", |v| v >= 0.0)?;
        let acked = p.f64_checked("wait_for_all_acked", ">= 0 seconds", |v| v >= 0.0)?;
        Ok(Self {
            bag,
            rate,
            looping: p.bool("loop")?,
            start_offset_ns: (offset * 1e9) as i64,
            topics: p.string_array("topics")?,
            publish_clock: p.bool("publish_clock")?,
            wait_for: p.string("wait_for_subscriber")?,
            wait_timeout: Duration::from_secs_f64(wait),
            acked_timeout: Duration::from_secs_f64(acked),
        })
    }
}

/// The contract's QoS for a known topic, else what the bag says was offered, else reliable.
fn qos_for(topic: &lidar_har_bag::TopicInfo) -> QosProfile {
    topics::ALL
        .iter()
        .find(|spec| spec.name == topic.name)
        .map(|spec| spec.qos)
        .or_else(|| topic.offered_qos.first().and_then(|q| q.to_profile()))
        .unwrap_or(QosProfile::reliable(10))
}

fn play(shutdown: &Shutdown) -> anyhow::Result<()> {
    let node = Node::new(NodeSetup::new("replay").parameters(decls()))?;
    let settings = Settings::from(&node)?;
    let reader = BagReader::open(&settings.bag)
        .with_context(|| format!("parameter `bag`: cannot open {}", settings.bag))?;
    for wanted in &settings.topics {
        if reader.topic(wanted).is_none() {
            return Err(RosError::Parameter {
                name: "topics".into(),
                reason: format!("{wanted} is not in the bag {}", settings.bag),
            }
            .into());
        }
    }
    let mut publishers: HashMap<String, Publisher> = HashMap::new();
    for topic in reader.topics() {
        if settings.topics.is_empty() || settings.topics.contains(&topic.name) {
            let publisher = node.publisher(&topic.name, &topic.type_name, qos_for(topic))?;
            publishers.insert(topic.name.clone(), publisher);
        }
    }
    let clock = if settings.publish_clock {
        Some(node.publisher_for(&topics::CLOCK)?)
    } else {
        None
    };
    if !settings.wait_for.is_empty() {
        let publisher = publishers
            .get(&settings.wait_for)
            .ok_or_else(|| RosError::Parameter {
                name: "wait_for_subscriber".into(),
                reason: format!("{} is not a played topic", settings.wait_for),
            })?;
        let deadline = Instant::now() + settings.wait_timeout;
        while publisher.subscription_count() == 0 {
            if Instant::now() >= deadline {
                bail!(
                    "no subscriber on {} within {:?}",
                    settings.wait_for,
                    settings.wait_timeout
                );
            }
            if !shutdown.sleep_until(Instant::now() + Duration::from_millis(20)) {
                return Ok(());
            }
        }
    }
    let bag_start = reader.metadata().start_ns;
    let mut played = 0u64;
    loop {
        let begin = bag_start + settings.start_offset_ns;
        let wall_start = Instant::now();
        for message in reader.messages()? {
            let message = message.context("reading the bag")?;
            if message.log_time_ns < begin {
                continue;
            }
            let Some(publisher) = publishers.get(&*message.topic) else {
                continue;
            };
            if settings.rate > 0.0 {
                let due = Duration::from_secs_f64(
                    (message.log_time_ns - begin) as f64 / 1e9 / settings.rate,
                );
                if !shutdown.sleep_until(wall_start + due) {
                    log::info!("replay: stopped by signal after {played} messages");
                    return Ok(());
                }
            } else if shutdown.requested() {
                return Ok(());
            }
            if let Some(clock) = &clock {
                clock.publish_msg(&Clock {
                    clock: Time::from_nanos(message.log_time_ns),
                })?;
            }
            publisher.publish(&message.data)?;
            played += 1;
        }
        if !settings.looping || shutdown.requested() {
            break;
        }
    }
    log::info!("replay: played {played} messages from {}", settings.bag);
    if !shutdown.requested() && !settings.acked_timeout.is_zero() {
        wait_for_all_acked(publishers.values(), settings.acked_timeout);
    }
    Ok(())
}

/// Waits, up to `timeout` in all, until the reliable subscribers acknowledged everything.
fn wait_for_all_acked<'a>(publishers: impl Iterator<Item = &'a Publisher>, timeout: Duration) {
    let deadline = Instant::now() + timeout;
    for publisher in publishers {
        let left = deadline.saturating_duration_since(Instant::now());
        match publisher.wait_for_acknowledgments(left) {
            Ok(true) => {}
            Ok(false) => log::warn!(
                "replay: {}: not every subscriber acknowledged within {timeout:?}",
                publisher.topic()
            ),
            Err(e) => {
                log::warn!("replay: {e}");
                return;
            }
        }
    }
}
