//! `replay`: plays a rosbag2 directory (MCAP or sqlite3) onto ROS 2 topics, like
//! `ros2 bag play`, with each topic's contract QoS (transient-local topics such as /map stay
//! available to late subscribers; /scan reliable, as the driver offers it), and /clock from
//! the bag's time line for `use_sim_time`.
//!
//! Parameters: `bag` (required), `rate` (1.0; 0 = as fast as possible), `loop`,
//! `start_offset` (s into the bag, up to its length), `topics` (only these; empty = all;
//! those the bag lacks are skipped with a warning, none present is an error), `publish_clock`
//! (then the bag's own /clock is not played), `wait_for_subscriber` (a topic to wait on before playing, up to `wait_timeout` s),
//! `wait_for_all_acked` (s to wait at the end for reliable subscribers to acknowledge
//! everything, so the last messages are not lost when the process exits, and, while the
//! replay has run for less than that, for a subscriber to match each reliable topic first;
//! 0 = don't wait).
//!
//! With `loop`, each pass lasts the whole bag (from `start_offset` to its last message, of any
//! topic) and at least a second of bag time, both over the rate: a selection of topics that
//! spans no bag time (`topics:=[/map]`) used to be published again and again without a pause.
//!
//! A bag cut short (a killed recorder) is played up to its last complete message, with a
//! warning naming the file and how many complete messages it holds; each `loop` pass ends
//! there. Without `loop` the replay then waits for acknowledgements as usual and exits with
//! status 1 and that error, as `lidar-har run` does on such a bag; it used to exit at the
//! cut, without the wait, and never looped.
//!
//! /tf_static is played as tf2's StaticTransformBroadcaster publishes it: each recorded
//! message is merged into the static transforms played so far (one per child frame), and the
//! whole set is published, so that its depth of 1 still gives a late subscriber every static
//! transform of the bag ([`StaticTransforms`]).

use std::collections::HashMap;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::bail;
use lidar_har::{NodeInfo, Shutdown, bad_parameter, seconds};
use lidar_har_bag::{BagError, BagReader, OfferedQos, PROCESS_ENDING, qos};
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::qos::{QosProfile, Reliability};
use lidar_har_msgs::rosgraph_msgs::Clock;
use lidar_har_msgs::tf2_msgs::TFMessage;
use lidar_har_msgs::{RosMessage, topics};
use lidar_har_ros::{NodeSetup, ParamDecl, ParamValue, Parameters, Publisher, RosError};

fn main() -> ExitCode {
    lidar_har::run(
        &NodeInfo {
            name: "replay",
            about: "plays a rosbag2 directory (MCAP or sqlite3) onto ROS 2 topics",
            parameters: decls,
        },
        |shutdown| match play(shutdown) {
            // The signal deletes the bag's temporary copies, which fails a read under way.
            Err(e) if shutdown.requested() && format!("{e:#}").contains(PROCESS_ENDING) => {
                log::info!("replay: stopped by signal ({e:#})");
                Ok(())
            }
            done => done,
        },
    )
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
            "seconds into the bag to start at, up to its length",
        ),
        ParamDecl::new(
            "topics",
            V::StringArray(Vec::new()),
            "topics to play; empty plays all; those the bag lacks are skipped",
        ),
        ParamDecl::new(
            "publish_clock",
            V::Bool(true),
            "publish /clock with the bag's time (instead of the bag's own /clock)",
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
            "seconds to wait at the end for reliable subscribers to acknowledge all messages \
             (and, in a shorter replay, for them to match first)",
        ),
    ]
}

/// Slowest playback `rate` other than 0.
const MIN_RATE: f64 = 0.001;
/// Longest `start_offset`: a year of recording.
const MAX_OFFSET_S: f64 = 365.0 * 86_400.0;
/// Longest `wait_timeout` / `wait_for_all_acked`: a day.
const MAX_WAIT_S: f64 = 86_400.0;

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
    fn from(p: &Parameters) -> Result<Self, RosError> {
        let bag = p.string("bag")?;
        if bag.is_empty() {
            return Err(RosError::Parameter {
                name: "bag".into(),
                reason: "required: the bag directory to play".into(),
            });
        }
        // A tiny positive rate would stretch a message's due time past what a Duration holds.
        let rule = format!("0 (as fast as possible) or >= {MIN_RATE}");
        let rate = p.f64_checked("rate", &rule, |v| v == 0.0 || v >= MIN_RATE)?;
        let offset = seconds(p, "start_offset", 0.0..=MAX_OFFSET_S)?;
        Ok(Self {
            bag,
            rate,
            looping: p.bool("loop")?,
            start_offset_ns: i64::try_from(offset.as_nanos()).unwrap_or(i64::MAX),
            topics: p.string_array("topics")?,
            publish_clock: p.bool("publish_clock")?,
            wait_for: p.string("wait_for_subscriber")?,
            wait_timeout: seconds(p, "wait_timeout", 0.0..=MAX_WAIT_S)?,
            acked_timeout: seconds(p, "wait_for_all_acked", 0.0..=MAX_WAIT_S)?,
        })
    }
}

/// Which of the bag's topics to play.
#[derive(Debug)]
struct Selection {
    play: Vec<String>,
    /// Requested topics the bag does not have.
    missing: Vec<String>,
}

/// All of the bag's topics when none are requested, else the requested ones it has. Missing
/// ones are only skipped: launch files ask for /odom and /map, which the bag of a fixed
/// Lidar lacks. None present is an error (a typo, or the wrong bag).
fn select_topics(
    requested: &[String],
    in_bag: &[String],
    bag: &str,
) -> Result<Selection, RosError> {
    if requested.is_empty() {
        return Ok(Selection {
            play: in_bag.to_vec(),
            missing: Vec::new(),
        });
    }
    let (play, missing): (Vec<String>, Vec<String>) =
        requested.iter().cloned().partition(|t| in_bag.contains(t));
    if play.is_empty() {
        return Err(RosError::Parameter {
            name: "topics".into(),
            reason: format!(
                "none of {} is in the bag {bag}, which has {}",
                missing.join(", "),
                if in_bag.is_empty() {
                    "no topics".to_string()
                } else {
                    in_bag.join(", ")
                }
            ),
        });
    }
    Ok(Selection { play, missing })
}

/// With `publish_clock`, the bag's own /clock (a bag recorded with one) is not played: two
/// clocks on /clock made the simulated time of `use_sim_time` nodes jump between the bag's
/// and the other's at every message. True when it was left out; an error when it was the
/// only topic to play.
fn leave_out_bag_clock(selection: &mut Selection, publish_clock: bool) -> Result<bool, RosError> {
    let clock = topics::CLOCK.name;
    if !publish_clock || !selection.play.iter().any(|t| t == clock) {
        return Ok(false);
    }
    selection.play.retain(|t| t != clock);
    if selection.play.is_empty() {
        return Err(bad_parameter(
            "publish_clock",
            "true replaces the bag's /clock, the only topic to play: set publish_clock:=false \
             to play it",
        ));
    }
    Ok(true)
}

/// A `start_offset` past the bag's last message would play nothing (with `loop`, nothing
/// again and again) and exit 0 as if all went well: refused like any other bad parameter.
fn check_start_offset(offset_ns: i64, bag_length_ns: i64, bag: &str) -> Result<(), RosError> {
    if offset_ns <= bag_length_ns {
        return Ok(());
    }
    Err(bad_parameter(
        "start_offset",
        format!(
            "{} s is past the end of the bag {bag}, which is {:.3} s long: nothing would be played",
            offset_ns as f64 / 1e9,
            bag_length_ns as f64 / 1e9
        ),
    ))
}

/// The contract's QoS for a known topic (/scan as its driver offers it, whatever the bag
/// recorded: [`topics::SCAN_OFFERED_QOS`]), else the one rosbag2's player would offer for
/// what the bag says its publishers offered.
fn qos_for(topic: &str, offered: &[OfferedQos]) -> QosProfile {
    if topic == topics::SCAN.name {
        return topics::SCAN_OFFERED_QOS;
    }
    if let Some(spec) = topics::find(topic) {
        return spec.qos;
    }
    let playback = qos::playback_qos(offered);
    if playback.offers_disagree {
        let recorded: Vec<String> = offered.iter().map(|q| q.describe()).collect();
        log::warn!(
            "replay: the publishers recorded on {} offered different QoS ({}); offering {}, \
             rosbag2's default for this case",
            topic,
            recorded.join("; "),
            OfferedQos::from(playback.profile).describe()
        );
    }
    playback.profile
}

fn play(shutdown: &Shutdown) -> anyhow::Result<()> {
    // No `ros2 param` services: ros2-client's server subscribes /clock as
    // builtin_interfaces/msg/Time, which clashes with the /clock the replay publishes.
    let setup = NodeSetup::new("replay")
        .parameters(decls())
        .without_parameter_services()
        .prepare()?;
    // The bag and what the parameters ask of it are checked before the node joins the graph.
    let settings = Settings::from(setup.params())?;
    // A bag that cannot be opened is a bad parameter (exit status 2), like any other.
    let reader = BagReader::open(&settings.bag)
        .map_err(|e| bad_parameter("bag", format!("cannot open it: {e:#}")))?;
    let info = reader.metadata();
    check_start_offset(settings.start_offset_ns, info.duration_ns(), &settings.bag)?;
    let in_bag: Vec<String> = reader.topics().iter().map(|t| t.name.clone()).collect();
    let mut selection = select_topics(&settings.topics, &in_bag, &settings.bag)?;
    if !selection.missing.is_empty() {
        log::warn!(
            "replay: skipping {} (not in the bag {}, which has {})",
            selection.missing.join(", "),
            settings.bag,
            in_bag.join(", ")
        );
    }
    if leave_out_bag_clock(&mut selection, settings.publish_clock)? {
        log::info!(
            "replay: not playing the bag's /clock: publish_clock:=true publishes /clock from the \
             bag's time line instead (publish_clock:=false plays the bag's own)"
        );
    }
    if !settings.wait_for.is_empty() && !selection.play.contains(&settings.wait_for) {
        let reason = format!("{} is not a played topic", settings.wait_for);
        return Err(bad_parameter("wait_for_subscriber", reason).into());
    }
    let node = lidar_har::join(setup)?;
    let mut publishers: HashMap<String, Publisher> = HashMap::new();
    let mut reliable = Vec::new();
    let mut static_transforms = None;
    for topic in reader.topics() {
        if selection.play.contains(&topic.name) {
            if topic.name == topics::TF_STATIC.name && topic.type_name == TFMessage::TYPE_NAME {
                static_transforms = Some(StaticTransforms::default());
            }
            let qos = qos_for(&topic.name, &topic.offered_qos);
            let publisher = node.publisher(&topic.name, &topic.type_name, qos)?;
            publishers.insert(topic.name.clone(), publisher);
            if qos.reliability == Reliability::Reliable {
                reliable.push(topic.name.clone());
            }
        }
    }
    let writers_created = Instant::now();
    let clock = if settings.publish_clock {
        Some(node.publisher_for(&topics::CLOCK)?)
    } else {
        None
    };
    if let Some(publisher) = publishers.get(&settings.wait_for) {
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
    let (bag_start, bag_end) = (info.start_ns, info.end_ns);
    let mut played = 0u64;
    let mut cut_short = None;
    loop {
        let begin = bag_start.saturating_add(settings.start_offset_ns);
        let mut pacing = Pacing::new(begin, Instant::now(), settings.rate);
        for message in reader.messages()? {
            let message = match message {
                Ok(message) => message,
                // A killed recorder (a power cut) leaves a file cut short: the reader gives
                // every complete message first, so the pass ends here, warned about once.
                Err(e @ BagError::Truncated { .. }) => {
                    if cut_short.is_none() {
                        log::warn!("replay: {e}; playing the bag up to there");
                    }
                    cut_short.get_or_insert(e);
                    continue;
                }
                Err(e) => return Err(anyhow::Error::new(e).context("reading the bag")),
            };
            if message.log_time_ns < begin {
                continue;
            }
            let Some(publisher) = publishers.get(&*message.topic) else {
                continue;
            };
            if settings.rate > 0.0 {
                let due = pacing.due(message.log_time_ns, Instant::now(), &message.topic);
                if !shutdown.sleep_until(due) {
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
            let data = match &mut static_transforms {
                Some(merged) if *message.topic == *topics::TF_STATIC.name => {
                    merged.merge_recorded(message.data)
                }
                _ => message.data,
            };
            publisher.publish(&data)?;
            played += 1;
        }
        if !settings.looping || shutdown.requested() {
            break;
        }
        if settings.rate > 0.0 && !shutdown.sleep_until(pacing.pass_end(bag_end, Instant::now())) {
            break;
        }
    }
    log::info!("replay: played {played} messages from {}", settings.bag);
    if !shutdown.requested() && !settings.acked_timeout.is_zero() {
        let reliable = reliable.iter().filter_map(|topic| publishers.get(topic));
        wait_for_all_acked(reliable, writers_created, settings.acked_timeout, shutdown);
    }
    match cut_short {
        // Played to its end, a bag cut short fails the replay, as it fails `lidar-har run`,
        // but only once what there was has been played and acknowledged. A `loop` ends only
        // by a signal, with status 0 as always.
        Some(e) if !settings.looping => Err(anyhow::Error::new(e).context("reading the bag")),
        _ => Ok(()),
    }
}

/// The static transforms played so far, one per child frame, in the order the child frames
/// were first played: what the replay publishes on /tf_static, as tf2's
/// StaticTransformBroadcaster publishes its own. On a robot each static broadcaster is a
/// latched writer of its own, and a late subscriber gets every one's last message; the replay
/// plays them all through one writer of depth 1, so publishing each recorded message alone
/// left a subscriber that joined after RustDDS's cache cleaning (every 6 s) with only the
/// newest one or two: rviz2 opened later, or a restarted localiser, lost base_link -> laser.
/// The set persists across `loop` passes; which messages are played is unchanged (one before
/// `start_offset` is not, as with rosbag2's player).
#[derive(Debug, Default)]
struct StaticTransforms {
    merged: TFMessage,
}

impl StaticTransforms {
    /// Adds `message`'s transforms to the set, each replacing the one of its child frame
    /// (a later transform of a child frame wins), and returns the whole set.
    fn merge(&mut self, message: TFMessage) -> &TFMessage {
        for transform in message.transforms {
            let known = self
                .merged
                .transforms
                .iter_mut()
                .find(|t| t.child_frame_id == transform.child_frame_id);
            match known {
                Some(known) => *known = transform,
                None => self.merged.transforms.push(transform),
            }
        }
        &self.merged
    }

    /// [`Self::merge`] on a recorded /tf_static payload, returning the CDR of the whole set;
    /// one that cannot be read as a TFMessage is played as it was recorded, with a warning.
    fn merge_recorded(&mut self, cdr: Vec<u8>) -> Vec<u8> {
        let encoded = lidar_har_msgs::decode::<TFMessage>(&cdr)
            .and_then(|message| lidar_har_msgs::encode(self.merge(message)));
        match encoded {
            Ok(merged) => merged,
            Err(e) => {
                log::warn!(
                    "replay: {}: {e}; playing this message as recorded, not merged with the \
                     static transforms played before",
                    topics::TF_STATIC.name
                );
                cdr
            }
        }
    }
}

/// Bag time between two messages beyond which the replay plays on at once instead of
/// waiting: a damaged stamp (a sqlite3 row at -9e18 ns) or a recorder paused for hours.
const MAX_WAITED_GAP_NS: i64 = 3_600_000_000_000;

/// The least bag time a pass of `loop` lasts: one second, so that a selection of topics
/// that spans no bag time (a single /map) is not published again and again at once.
const MIN_PASS_NS: i64 = 1_000_000_000;

/// When each message is due on the wall clock: its bag time since an anchor, scaled by the
/// rate. The anchor moves to a message that comes more than [`MAX_WAITED_GAP_NS`] after the
/// one before it, so that nothing waits for ever and no arithmetic overflows.
struct Pacing {
    rate: f64,
    anchor_ns: i64,
    anchor_at: Instant,
    previous_ns: i64,
    start: Instant,
}

impl Pacing {
    /// Bag time `begin_ns` is due at `start`.
    fn new(begin_ns: i64, start: Instant, rate: f64) -> Self {
        Self {
            rate,
            anchor_ns: begin_ns,
            anchor_at: start,
            previous_ns: begin_ns,
            start,
        }
    }

    /// When a pass of `loop` that played its messages ends: at the bag's end `end_ns` (the
    /// last message of any topic, played or not), paced as a message would be, and at least
    /// [`MIN_PASS_NS`] of bag time after the pass started.
    fn pass_end(&mut self, end_ns: i64, now: Instant) -> Instant {
        let at_bag_end = self.due(end_ns, now, "the end of the bag");
        let shortest = Duration::from_secs_f64(MIN_PASS_NS as f64 / 1e9 / self.rate);
        at_bag_end.max(self.start + shortest)
    }

    fn due(&mut self, log_time_ns: i64, now: Instant, topic: &str) -> Instant {
        let gap_ns = log_time_ns.saturating_sub(self.previous_ns);
        self.previous_ns = log_time_ns;
        let since_anchor_s = log_time_ns.saturating_sub(self.anchor_ns) as f64 / 1e9;
        let due = Duration::try_from_secs_f64(since_anchor_s / self.rate)
            .ok()
            .and_then(|after| self.anchor_at.checked_add(after));
        match due {
            Some(due) if gap_ns <= MAX_WAITED_GAP_NS => due,
            _ => {
                log::warn!(
                    "replay: {topic} at {log_time_ns} ns comes {:.3e} s of bag time after the \
                     message before it: playing on at once",
                    gap_ns as f64 / 1e9
                );
                self.anchor_ns = log_time_ns;
                self.anchor_at = now;
                now
            }
        }
    }
}

/// At the end, waits for each reliable writer in `reliable` to have had a subscriber, up to
/// `timeout` after the writers were `created`, then, up to `timeout` again in all, for the
/// subscribers to acknowledge everything. RustDDS's wait for acknowledgements returns at once
/// while no reader has matched: a short replay exited before discovery had matched a
/// subscriber that was already running, which never got the transient-local /map. A replay
/// without subscribers waits at most `timeout`, and not at all once it has played as long.
/// SIGINT or SIGTERM ends either wait within a fraction of a second.
fn wait_for_all_acked<'a>(
    reliable: impl Iterator<Item = &'a Publisher> + Clone,
    created: Instant,
    timeout: Duration,
    shutdown: &Shutdown,
) {
    let matching_deadline = created + timeout;
    for publisher in reliable.clone() {
        while !publisher.has_matched() && Instant::now() < matching_deadline {
            let next_look = Instant::now() + Duration::from_millis(20);
            if !shutdown.sleep_until(next_look.min(matching_deadline)) {
                return;
            }
        }
    }
    let deadline = Instant::now() + timeout;
    for publisher in reliable {
        // In slices, so that a signal stops the wait within one.
        let acknowledged = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match publisher.wait_for_acknowledgments(left.min(ACK_WAIT_SLICE)) {
                Ok(true) => break true,
                Ok(false) if left <= ACK_WAIT_SLICE => break false,
                Ok(false) if shutdown.requested() => return,
                Ok(false) => {}
                Err(e) => {
                    log::warn!("replay: {e}");
                    return;
                }
            }
        };
        if !acknowledged {
            log::warn!(
                "replay: {}: not every subscriber acknowledged within {timeout:?}",
                publisher.topic()
            );
        }
    }
}

/// Longest single wait for acknowledgements between looks at the shutdown flag.
const ACK_WAIT_SLICE: Duration = Duration::from_millis(100);

#[cfg(test)]
mod tests {
    use lidar_har_msgs::geometry_msgs::TransformStamped;
    use lidar_har_msgs::std_msgs::Header;

    use super::*;

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn messages_are_due_at_their_bag_time_over_the_rate() {
        let start = Instant::now();
        let mut pacing = Pacing::new(1_000_000_000, start, 2.0);
        let due = pacing.due(1_000_000_000, start, "/scan");
        assert_eq!(due, start);
        let due = pacing.due(3_000_000_000, start, "/scan");
        assert_eq!(due, start + Duration::from_secs(1));
    }

    #[test]
    fn a_damaged_stamp_is_played_at_once_and_the_next_ones_keep_their_pace() {
        let start = Instant::now();
        // The bag's start is the damaged row at the start of time.
        let mut pacing = Pacing::new(i64::MIN, start, 1.0);
        assert_eq!(pacing.due(i64::MIN, start, "/scan"), start);
        let later = start + Duration::from_millis(5);
        assert_eq!(pacing.due(100_000_000_000, later, "/scan"), later);
        let due = pacing.due(100_050_000_000, later, "/scan");
        assert_eq!(due, later + Duration::from_millis(50));
        // A stamp at the end of time neither waits nor overflows.
        assert_eq!(pacing.due(i64::MAX, later, "/scan"), later);
    }

    #[test]
    fn a_loop_pass_lasts_until_the_bags_end_over_the_rate() {
        // Only /map, at the start of a 4 s bag, is played: the pass still lasts 4 s of bag time.
        let start = Instant::now();
        let mut pacing = Pacing::new(0, start, 2.0);
        assert_eq!(pacing.due(0, start, "/map"), start);
        let end = pacing.pass_end(4_000_000_000, start);
        assert_eq!(end, start + Duration::from_secs(2));
    }

    #[test]
    fn a_loop_pass_of_no_bag_time_lasts_a_second_of_it() {
        // A bag of one message used to be played again and again at once (a core spinning).
        let start = Instant::now();
        let mut pacing = Pacing::new(5, start, 4.0);
        pacing.due(5, start, "/map");
        assert_eq!(
            pacing.pass_end(5, start),
            start + Duration::from_millis(250)
        );
        // A bag's end an hour of bag time after the last message played is not waited for
        // (as a gap between messages), but the pass still lasts a second of bag time.
        let mut pacing = Pacing::new(0, start, 1.0);
        pacing.due(0, start, "/map");
        let later = start + Duration::from_millis(10);
        let end = pacing.pass_end(2 * MAX_WAITED_GAP_NS, later);
        assert_eq!(end, start + Duration::from_secs(1));
    }

    #[test]
    fn a_start_offset_past_the_bags_end_is_an_error_naming_it_and_the_bags_length() {
        // Used to play no message and exit 0 without a word.
        let err = check_start_offset(100_000_000_000, 5_000_000_000, "my_bag")
            .unwrap_err()
            .to_string();
        for needle in ["`start_offset`", "100 s", "my_bag", "5.000 s long"] {
            assert!(err.contains(needle), "{needle} missing from: {err}");
        }
        // Up to the last message something is played.
        check_start_offset(0, 5_000_000_000, "b").unwrap();
        check_start_offset(5_000_000_000, 5_000_000_000, "b").unwrap();
        check_start_offset(0, 0, "empty").unwrap();
    }

    /// The bag's /clock and the replay's own used to be published together: simulated time
    /// flipped between 1.7e9 s and 0.2 s.
    #[test]
    fn the_bags_clock_is_not_played_when_the_replay_publishes_its_own() {
        let bag = names(&["/scan", "/clock", "/map"]);
        let mut s = select_topics(&[], &bag, "b").unwrap();
        assert!(leave_out_bag_clock(&mut s, true).unwrap());
        assert_eq!(s.play, names(&["/scan", "/map"]));
        let mut s = select_topics(&[], &bag, "b").unwrap();
        assert!(!leave_out_bag_clock(&mut s, false).unwrap());
        assert_eq!(s.play, bag);
        let mut s = select_topics(&names(&["/scan"]), &bag, "b").unwrap();
        assert!(!leave_out_bag_clock(&mut s, true).unwrap());
        assert_eq!(s.play, names(&["/scan"]));
        let mut s = select_topics(&names(&["/clock"]), &bag, "b").unwrap();
        let err = leave_out_bag_clock(&mut s, true).unwrap_err().to_string();
        assert!(
            err.contains("`publish_clock`") && err.contains("publish_clock:=false"),
            "{err}"
        );
    }

    fn transform(parent: &str, child: &str, x: f64) -> TransformStamped {
        let mut t = TransformStamped {
            header: Header::new(Time::from_nanos(0), parent),
            child_frame_id: child.into(),
            transform: Default::default(),
        };
        t.transform.translation.x = x;
        t
    }

    fn children(message: &TFMessage) -> Vec<(&str, &str, f64)> {
        let frames = message.transforms.iter().map(|t| {
            let x = t.transform.translation.x;
            (&*t.header.frame_id, &*t.child_frame_id, x)
        });
        frames.collect()
    }

    /// Each recorded /tf_static message used to be published alone through one writer of
    /// depth 1: a late subscriber lost the transforms of all but the newest.
    #[test]
    fn static_transforms_are_merged_by_child_frame_in_first_seen_order() {
        let mut merged = StaticTransforms::default();
        let one = |t| TFMessage {
            transforms: vec![t],
        };
        let set = merged.merge(one(transform("base_link", "laser", 1.0)));
        assert_eq!(children(set), [("base_link", "laser", 1.0)]);
        // A message of several transforms, one of them twice: the later one wins.
        let several = TFMessage {
            transforms: vec![
                transform("base_link", "imu", 2.0),
                transform("map", "odom", 3.0),
                transform("base_link", "imu", 4.0),
            ],
        };
        let set = merged.merge(several);
        let want = [
            ("base_link", "laser", 1.0),
            ("base_link", "imu", 4.0),
            ("map", "odom", 3.0),
        ];
        assert_eq!(children(set), want);
        // A later transform of a child frame replaces it where it was first seen, even under
        // another parent.
        let set = merged.merge(one(transform("base_footprint", "laser", 5.0)));
        let want = [
            ("base_footprint", "laser", 5.0),
            ("base_link", "imu", 4.0),
            ("map", "odom", 3.0),
        ];
        assert_eq!(children(set), want);
        // An empty message publishes the set again, unchanged.
        assert_eq!(children(merged.merge(TFMessage::default())), want);
    }

    #[test]
    fn a_recorded_static_transform_payload_is_merged_and_a_bad_one_played_as_recorded() {
        let mut merged = StaticTransforms::default();
        let laser = TFMessage {
            transforms: vec![transform("base_link", "laser", 1.0)],
        };
        let imu = TFMessage {
            transforms: vec![transform("base_link", "imu", 2.0)],
        };
        merged.merge_recorded(lidar_har_msgs::encode(&laser).unwrap());
        let cdr = merged.merge_recorded(lidar_har_msgs::encode(&imu).unwrap());
        let set: TFMessage = lidar_har_msgs::decode(&cdr).unwrap();
        assert_eq!(
            children(&set),
            [("base_link", "laser", 1.0), ("base_link", "imu", 2.0)]
        );
        let bad = vec![0, 1, 0, 0, 9];
        assert_eq!(merged.merge_recorded(bad.clone()), bad);
        assert_eq!(merged.merged, set, "a bad payload changes nothing");
    }

    /// /scan used to be offered best effort, the contract's subscription QoS: a reliable
    /// subscriber (rclcpp's default) got nothing. Other contract topics keep their QoS.
    #[test]
    fn scan_is_offered_reliable_like_the_driver_and_other_topics_as_the_contract() {
        // Recorded best effort, as the simulator records it.
        let recorded = [OfferedQos::from(topics::SCAN.qos)];
        let scan = qos_for(topics::SCAN.name, &recorded);
        assert_eq!(scan.reliability, Reliability::Reliable);
        assert_eq!(
            (scan.durability, scan.history),
            (topics::SCAN.qos.durability, topics::SCAN.qos.history)
        );
        for spec in [topics::MAP, topics::ODOM, topics::TF_STATIC] {
            assert_eq!(qos_for(spec.name, &[]), spec.qos, "{}", spec.name);
        }
    }

    #[test]
    fn no_requested_topics_plays_the_whole_bag() {
        let bag = names(&["/scan", "/map"]);
        let s = select_topics(&[], &bag, "b").unwrap();
        assert_eq!(s.play, bag);
        assert!(s.missing.is_empty());
    }

    #[test]
    fn requested_topics_the_bag_lacks_are_skipped() {
        // What replay.launch.py asks for, on the real recording that has only /scan.
        let launch = names(&["/scan", "/odom", "/map", "/tf", "/tf_static"]);
        let s = select_topics(&launch, &names(&["/scan"]), "b").unwrap();
        assert_eq!(s.play, names(&["/scan"]));
        assert_eq!(s.missing, names(&["/odom", "/map", "/tf", "/tf_static"]));
    }

    #[test]
    fn no_requested_topic_in_the_bag_is_an_error_naming_them_and_the_bags_topics() {
        let err = select_topics(&names(&["/nope", "/odom"]), &names(&["/scan"]), "my_bag")
            .unwrap_err()
            .to_string();
        for needle in ["`topics`", "/nope", "/odom", "my_bag", "/scan"] {
            assert!(err.contains(needle), "{needle} missing from: {err}");
        }
    }
}
