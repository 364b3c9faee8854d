//! `replay`: plays a rosbag2 directory (MCAP or sqlite3) onto ROS 2 topics, like
//! `ros2 bag play`, with each topic's contract QoS (transient-local topics such as /map stay
//! available to late subscribers; /scan reliable, as the driver offers it), and /clock from
//! the bag's time line for `use_sim_time`, at a fixed rate as `ros2 bag play --clock` does.
//!
//! Parameters: `bag` (required), `rate` (1.0; 0 = as fast as possible), `loop`,
//! `start_offset` (s into the bag, up to its length), `playback_duration` (s of bag time
//! played from `start_offset`, the messages logged in `[offset, offset + duration]`, each
//! `loop` pass as long; negative, the default, plays to the bag's end, as
//! `ros2 bag play --playback-duration`), `topics` (only these; empty = all;
//! those the bag lacks are skipped with a warning, none present is an error), `publish_clock`
//! (then the bag's own /clock is not played), `clock_frequency` (/clock publications a second
//! of wall time, 40 as `ros2 bag play --clock`), `wait_for_subscriber` (a topic to wait on
//! before playing, up to `wait_timeout` s),
//! `wait_for_all_acked` (s to wait at the end for reliable subscribers to acknowledge
//! everything, so the last messages are not lost when the process exits, and, while the
//! replay has run for less than that, for a subscriber to match each reliable topic first;
//! 0 = don't wait).
//!
//! With `loop`, each pass lasts the whole bag (from `start_offset` to its last message, of any
//! topic, or `playback_duration` if that ends sooner) and at least a second of bag time,
//! both over the rate: a selection of topics that spans no bag time (`topics:=[/map]`) used
//! to be published again and again without a pause.
//! Each pass starts /clock again at `start_offset`, as rosbag2's player jumps its clock back.
//!
//! Each pass reads the bag from `start_offset` on, as `ros2 bag play --start-offset` seeks
//! to it: an MCAP with a summary reads only its chunks from there, a sqlite3 file asks for
//! the rows from there in its query (an MCAP cut short, without an index, is still read from
//! its start, dropping what comes before). The part before the offset used to be read and
//! decompressed at the start of each pass. A message before `start_offset` is not played,
//! a /tf_static one included, as with rosbag2's player (ros2/rosbag2#1482: by design).
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
use lidar_har_bag::{BagError, BagReader, MessageFilter, OfferedQos, PROCESS_ENDING, qos};
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
            "playback_duration",
            V::Double(-1.0),
            "seconds of bag time to play from start_offset; negative plays to the bag's end",
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
            "clock_frequency",
            V::Double(DEFAULT_CLOCK_HZ),
            "Hz (wall time) at which /clock is published, with publish_clock",
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
/// `clock_frequency`'s default: `ros2 bag play --clock` without a value.
const DEFAULT_CLOCK_HZ: f64 = 40.0;
/// `clock_frequency`'s range: from one /clock every 10 s to one a millisecond.
const CLOCK_HZ: std::ops::RangeInclusive<f64> = 0.1..=1000.0;

struct Settings {
    bag: String,
    rate: f64,
    looping: bool,
    start_offset_ns: i64,
    /// `None`: to the bag's end.
    playback_duration_ns: Option<i64>,
    topics: Vec<String>,
    publish_clock: bool,
    clock_period: Duration,
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
        // As `ros2 bag play --playback-duration`: negative (its default, -1) is no limit.
        let rule = format!("finite: negative (to the bag's end) or in (0, {MAX_OFFSET_S}] s");
        let duration = p.f64_checked("playback_duration", &rule, |v| {
            v < 0.0 || (v > 0.0 && v <= MAX_OFFSET_S)
        })?;
        let rule = format!("Hz in {}..={}", CLOCK_HZ.start(), CLOCK_HZ.end());
        let clock_hz = p.f64_checked("clock_frequency", &rule, |v| CLOCK_HZ.contains(&v))?;
        Ok(Self {
            bag,
            rate,
            looping: p.bool("loop")?,
            start_offset_ns: i64::try_from(offset.as_nanos()).unwrap_or(i64::MAX),
            playback_duration_ns: (duration > 0.0).then(|| (duration * 1e9).round() as i64),
            topics: p.string_array("topics")?,
            publish_clock: p.bool("publish_clock")?,
            clock_period: Duration::from_secs_f64(1.0 / clock_hz),
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

/// The contract's offer for a known topic, whatever the bag recorded (/scan reliable, as its
/// driver offers it, where older simulator bags recorded it best effort), else the one
/// rosbag2's player would offer for what the bag says its publishers offered.
fn qos_for(topic: &str, offered: &[OfferedQos]) -> QosProfile {
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
    let setup = NodeSetup::new("replay").parameters(decls()).prepare()?;
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
    let mut clock = if settings.publish_clock {
        let publisher = node.publisher_for(&topics::CLOCK)?;
        Some((
            publisher,
            ClockTicks::new(settings.clock_period, Instant::now()),
        ))
    } else {
        None
    };
    let (bag_start, bag_end) = (info.start_ns, info.end_ns);
    let begin = bag_start.saturating_add(settings.start_offset_ns);
    // Where a pass ends: `playback_duration` after the offset, at most the bag's end.
    let pass_end_ns = settings.playback_duration_ns.map_or(bag_end, |duration| {
        begin.saturating_add(duration).min(bag_end)
    });
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
            // /clock holds at the start meanwhile.
            let next_look = Instant::now() + Duration::from_millis(20);
            if !sleep_until_ticking(next_look, shutdown, &mut clock, |_| begin)? {
                return Ok(());
            }
        }
    }
    let mut played = 0u64;
    let mut cut_short = None;
    // Each pass reads the played topics from `begin` on, as `ros2 bag play --start-offset`
    // seeks: an MCAP with a summary reads only the chunks from there, sqlite3 asks for the
    // range (and topics) in its query. Reading the part before the offset took over a second
    // a pass, 19 s into a 20 s zstd bag of images (0.014 s now: docs/bag.md).
    let mut to_play = MessageFilter::new()
        .topics(&selection.play)
        .starting_at(begin);
    // The end itself is played, as rosbag2's player stops only at a message after it.
    if let Some(duration) = settings.playback_duration_ns {
        to_play = to_play.ending_before(begin.saturating_add(duration).saturating_add(1));
    }
    loop {
        let mut pacing = Pacing::new(begin, settings.rate);
        if let Some((_, ticks)) = &mut clock {
            ticks.restart();
        }
        for message in reader.messages_matching(&to_play)? {
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
            let Some(publisher) = publishers.get(&*message.topic) else {
                continue;
            };
            let due = pacing.due(message.log_time_ns, Instant::now(), &message.topic);
            if !sleep_until_ticking(due, shutdown, &mut clock, |now| pacing.bag_time_at(now))? {
                log::info!("replay: stopped by signal after {played} messages");
                return Ok(());
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
        let pass_end = pacing.pass_end(pass_end_ns, Instant::now());
        if !sleep_until_ticking(pass_end, shutdown, &mut clock, |now| {
            pacing.bag_time_at(now)
        })? {
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
/// rate (with rate 0, at once). The pass's start, `start_offset` into the bag, is anchored
/// when its first message is played, not when the pass starts reading: the wall time until
/// then (reading the first chunk; before the replay sought `start_offset`, reading through
/// the whole part of the bag before it) used to count as played, and the first seconds
/// after the offset came out in a burst (23 scans in 0.14 s, 17 s into a 20 s bag with
/// images). The anchor moves to a message that comes more than
/// [`MAX_WAITED_GAP_NS`] after the one before it, so that nothing waits for ever and no
/// arithmetic overflows.
struct Pacing {
    rate: f64,
    begin_ns: i64,
    /// None until the pass plays its first message (or ends without one).
    anchor: Option<Anchor>,
    previous_ns: i64,
}

/// Bag time `ns` is due at wall time `at`; the pass started at `pass_started`.
#[derive(Clone, Copy)]
struct Anchor {
    ns: i64,
    at: Instant,
    pass_started: Instant,
}

impl Pacing {
    /// A pass starting at bag time `begin_ns`, due when its first message is played.
    fn new(begin_ns: i64, rate: f64) -> Self {
        Self {
            rate,
            begin_ns,
            anchor: None,
            previous_ns: begin_ns,
        }
    }

    /// The anchor, `begin_ns` at `now` the first time it is asked for.
    fn anchor(&mut self, now: Instant) -> Anchor {
        *self.anchor.get_or_insert(Anchor {
            ns: self.begin_ns,
            at: now,
            pass_started: now,
        })
    }

    /// When a pass of `loop` that played its messages ends: at the bag's end `end_ns` (the
    /// last message of any topic, played or not), paced as a message would be, and at least
    /// [`MIN_PASS_NS`] of bag time after the pass started; with rate 0, at once.
    fn pass_end(&mut self, end_ns: i64, now: Instant) -> Instant {
        if self.rate == 0.0 {
            return now;
        }
        let started = self.anchor(now).pass_started;
        let at_bag_end = self.due(end_ns, now, "the end of the bag");
        let shortest = Duration::from_secs_f64(MIN_PASS_NS as f64 / 1e9 / self.rate);
        at_bag_end.max(started + shortest)
    }

    fn due(&mut self, log_time_ns: i64, now: Instant, topic: &str) -> Instant {
        let anchor = self.anchor(now);
        let gap_ns = log_time_ns.saturating_sub(self.previous_ns);
        self.previous_ns = log_time_ns;
        if self.rate == 0.0 {
            return now;
        }
        let since_anchor_s = log_time_ns.saturating_sub(anchor.ns) as f64 / 1e9;
        let due = Duration::try_from_secs_f64(since_anchor_s / self.rate)
            .ok()
            .and_then(|after| anchor.at.checked_add(after));
        match due {
            Some(due) if gap_ns <= MAX_WAITED_GAP_NS => due,
            _ => {
                log::warn!(
                    "replay: {topic} at {log_time_ns} ns comes {:.3e} s of bag time after the \
                     message before it: playing on at once",
                    gap_ns as f64 / 1e9
                );
                self.anchor = Some(Anchor {
                    ns: log_time_ns,
                    at: now,
                    ..anchor
                });
                now
            }
        }
    }

    /// The bag time at wall time `now`, what /clock says: the pass's start until its first
    /// message is played, then on at the rate, between messages too, as rosbag2's player
    /// clock; with rate 0, the time of the last message played.
    fn bag_time_at(&self, now: Instant) -> i64 {
        match self.anchor {
            Some(anchor) if self.rate > 0.0 => {
                let since = now.saturating_duration_since(anchor.at).as_secs_f64();
                // `as` saturates: a replay running for centuries stops at the end of time.
                anchor.ns.saturating_add((since * self.rate * 1e9) as i64)
            }
            _ => self.previous_ns,
        }
    }
}

/// When /clock is due: at a fixed wall rate, as `ros2 bag play --clock` publishes it from a
/// timer, whatever the messages do. It used to be published with each message, with its
/// time: once per message of a stamp (five times in a row on a bag of five topics), and
/// never in a gap between messages, the `loop` pass-end wait or the `wait_for_subscriber`
/// wait, so that `use_sim_time` timers stopped there.
struct ClockTicks {
    period: Duration,
    next: Instant,
    /// The latest time published in this pass: /clock never goes back within one, even
    /// where the pacing does (a message stamped before the one played before it).
    latest_ns: i64,
}

impl ClockTicks {
    /// The first tick is at `now`.
    fn new(period: Duration, now: Instant) -> Self {
        Self {
            period,
            next: now,
            latest_ns: i64::MIN,
        }
    }

    /// The time to publish if a tick has come by `now`, `bag_ns` or the latest one of the
    /// pass if later. A tick missed (a long write) is not caught up with a burst: the next
    /// one is a period on.
    fn take(&mut self, now: Instant, bag_ns: i64) -> Option<i64> {
        if now < self.next {
            return None;
        }
        self.next += self.period;
        if self.next <= now {
            self.next = now + self.period;
        }
        self.latest_ns = self.latest_ns.max(bag_ns);
        Some(self.latest_ns)
    }

    /// A `loop` pass starts: /clock goes back to its start, as rosbag2's player jumps its
    /// clock back to the start at each pass.
    fn restart(&mut self) {
        self.latest_ns = i64::MIN;
    }
}

/// Sleeps until `deadline` (not at all if it has passed), publishing /clock on the way at
/// each of its ticks, with the bag time `bag_time` gives for the moment. False when a
/// signal came.
fn sleep_until_ticking(
    deadline: Instant,
    shutdown: &Shutdown,
    clock: &mut Option<(Publisher, ClockTicks)>,
    bag_time: impl Fn(Instant) -> i64,
) -> Result<bool, RosError> {
    loop {
        let mut wake = deadline;
        if let Some((publisher, ticks)) = clock {
            let now = Instant::now();
            if let Some(ns) = ticks.take(now, bag_time(now)) {
                publisher.publish_msg(&Clock {
                    clock: Time::from_nanos(ns),
                })?;
            }
            wake = wake.min(ticks.next);
        }
        if !shutdown.sleep_until(wake) {
            return Ok(false);
        }
        if wake >= deadline {
            return Ok(true);
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
        let mut pacing = Pacing::new(1_000_000_000, 2.0);
        let due = pacing.due(1_000_000_000, start, "/scan");
        assert_eq!(due, start);
        let due = pacing.due(3_000_000_000, start, "/scan");
        assert_eq!(due, start + Duration::from_secs(1));
    }

    #[test]
    fn a_damaged_stamp_is_played_at_once_and_the_next_ones_keep_their_pace() {
        let start = Instant::now();
        // The bag's start is the damaged row at the start of time.
        let mut pacing = Pacing::new(i64::MIN, 1.0);
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
        let mut pacing = Pacing::new(0, 2.0);
        assert_eq!(pacing.due(0, start, "/map"), start);
        let end = pacing.pass_end(4_000_000_000, start);
        assert_eq!(end, start + Duration::from_secs(2));
    }

    #[test]
    fn a_loop_pass_of_no_bag_time_lasts_a_second_of_it() {
        // A bag of one message used to be played again and again at once (a core spinning).
        let start = Instant::now();
        let mut pacing = Pacing::new(5, 4.0);
        pacing.due(5, start, "/map");
        assert_eq!(
            pacing.pass_end(5, start),
            start + Duration::from_millis(250)
        );
        // A bag's end an hour of bag time after the last message played is not waited for
        // (as a gap between messages), but the pass still lasts a second of bag time.
        let mut pacing = Pacing::new(0, 1.0);
        pacing.due(0, start, "/map");
        let later = start + Duration::from_millis(10);
        let end = pacing.pass_end(2 * MAX_WAITED_GAP_NS, later);
        assert_eq!(end, start + Duration::from_secs(1));
    }

    /// 17 s into a 20 s bag with images, reading through the part before the offset took
    /// about a second, which used to count as played: 2.2 s of scans came out in 0.14 s.
    #[test]
    fn the_pace_starts_at_the_first_message_played_not_when_the_pass_starts_reading() {
        let begin = 17_000_000_000;
        let mut pacing = Pacing::new(begin, 1.0);
        let read_through = Instant::now() + Duration::from_millis(1200);
        assert_eq!(
            pacing.bag_time_at(read_through),
            begin,
            "/clock holds at the start"
        );
        // The first message, 50 ms after the offset, waits those 50 ms; the next ones keep
        // their recorded spacing from there.
        let first = pacing.due(begin + 50_000_000, read_through, "/scan");
        assert_eq!(first, read_through + Duration::from_millis(50));
        for i in 1..=22 {
            let due = pacing.due(begin + 50_000_000 + i * 100_000_000, first, "/scan");
            assert_eq!(
                due,
                first + Duration::from_millis(100 * i as u64),
                "scan {i}"
            );
        }
    }

    /// What [`sleep_until_ticking`] publishes on /clock while a pass plays `stamps` (bag ns,
    /// in order) from `begin` at `rate`, in simulated wall time from `start`: (wall time,
    /// bag time) of each /clock.
    fn clock_of_a_pass(
        stamps: &[i64],
        begin: i64,
        rate: f64,
        ticks: &mut ClockTicks,
        start: Instant,
    ) -> Vec<(Instant, i64)> {
        let mut pacing = Pacing::new(begin, rate);
        let mut clock = Vec::new();
        let mut now = start;
        let mut sleep_until = |deadline: Instant, pacing: &Pacing, now: &mut Instant| loop {
            if let Some(ns) = ticks.take(*now, pacing.bag_time_at(*now)) {
                clock.push((*now, ns));
            }
            let wake = deadline.min(ticks.next);
            *now = (*now).max(wake);
            if wake >= deadline {
                break;
            }
        };
        for &stamp in stamps {
            let due = pacing.due(stamp, now, "/scan");
            sleep_until(due, &pacing, &mut now);
        }
        let end = pacing.pass_end(*stamps.last().unwrap(), now);
        sleep_until(end, &pacing, &mut now);
        clock
    }

    /// /clock used to be published with each message: the same time once per topic of a
    /// stamp, and nothing in a gap between messages.
    #[test]
    fn clock_ticks_at_its_rate_moves_on_in_gaps_and_never_repeats_within_a_pass() {
        let begin = 1_000_000_000_000;
        // Five topics sharing a 20 Hz time line for 1 s, a 2 s gap, then 1 s more.
        let mut stamps = Vec::new();
        for i in (0..20).chain(60..80) {
            stamps.extend([begin + i * 50_000_000; 5]);
        }
        let start = Instant::now();
        let mut ticks = ClockTicks::new(Duration::from_millis(25), start);
        let clock = clock_of_a_pass(&stamps, begin, 1.0, &mut ticks, start);
        // 3.95 s of bag time at 1x, ticking at 40 Hz.
        assert!((150..=165).contains(&clock.len()), "{} /clock", clock.len());
        assert_eq!(clock[0].1, begin);
        for pair in clock.windows(2) {
            assert!(
                pair[1].1 > pair[0].1,
                "/clock repeated or went back: {pair:?}"
            );
        }
        let in_gap = clock
            .iter()
            .filter(|(_, ns)| (begin + 1_000_000_000..begin + 3_000_000_000).contains(ns));
        assert!(in_gap.count() >= 70, "/clock stopped in the gap");
        // At 4x the bag takes a quarter of the wall time, and /clock keeps its wall rate.
        let start = Instant::now();
        let mut ticks = ClockTicks::new(Duration::from_millis(25), start);
        let clock = clock_of_a_pass(&stamps, begin, 4.0, &mut ticks, start);
        assert!(
            (36..=45).contains(&clock.len()),
            "{} /clock at 4x",
            clock.len()
        );
        let (first, last) = (clock[0], clock[clock.len() - 1]);
        let wall = last.0 - first.0;
        let bag_s = (last.1 - first.1) as f64 / 1e9;
        assert!(
            (bag_s / wall.as_secs_f64() - 4.0).abs() < 0.01,
            "{bag_s} s in {wall:?}"
        );
    }

    #[test]
    fn clock_goes_back_to_the_start_only_at_a_new_loop_pass() {
        let begin = 5_000_000_000;
        let stamps = [begin, begin + 500_000_000];
        let start = Instant::now();
        let mut ticks = ClockTicks::new(Duration::from_millis(25), start);
        let first = clock_of_a_pass(&stamps, begin, 1.0, &mut ticks, start);
        // The pass lasts a second of bag time (MIN_PASS_NS), /clock up to its end.
        assert!(first.last().unwrap().1 >= begin + 950_000_000, "{first:?}");
        ticks.restart();
        let again = first.last().unwrap().0;
        let second = clock_of_a_pass(&stamps, begin, 1.0, &mut ticks, again);
        // Its first tick, within a period of its start, is back at the pass's start.
        let back = second[0].1;
        assert!((begin..=begin + 25_000_000).contains(&back), "{back}");
        // Within a pass it never goes back, even where the pacing does (a message stamped
        // before the one played before it moves the anchor back).
        let mut ticks = ClockTicks::new(Duration::from_millis(25), start);
        let unsorted = [begin, begin + 400_000_000, begin - 3_000_000_000];
        let clock = clock_of_a_pass(&unsorted, begin, 1.0, &mut ticks, start);
        for pair in clock.windows(2) {
            assert!(pair[1].1 >= pair[0].1, "/clock went back: {pair:?}");
        }
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
        // Recorded best effort, as the simulator recorded it before session 54.
        let recorded = [OfferedQos::from(topics::SCAN.subscribed)];
        let scan = qos_for(topics::SCAN.name, &recorded);
        assert_eq!(scan.reliability, Reliability::Reliable);
        assert_eq!(scan, topics::SCAN.qos);
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
