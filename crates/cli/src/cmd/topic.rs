//! `lidar-har topic list|echo|hz`: see and read ROS 2 topics over DDS without ROS 2
//! installed (the pure-Rust transport of `lidar-har-ros`), as JSON lines that tests and
//! scripts parse, and measure a topic's rate as `ros2 topic hz` does.

mod hz;

use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use lidar_har_msgs::qos::{Durability, QosProfile, Reliability};
use lidar_har_msgs::topics;
use lidar_har_ros::json::{Truncated, Truncation};
use lidar_har_ros::{Node, NodeSetup, OfferedQos, RosError, Subscriber, args, json};

#[derive(clap::Subcommand)]
pub enum TopicCommand {
    /// List the topics discovered on the network (ROS_DOMAIN_ID applies), one per line.
    List {
        /// How long to listen for discovery, in seconds (at most a day).
        #[arg(long, default_value_t = 2.0)]
        wait: f64,
        /// Also print each topic's type.
        #[arg(short = 't', long)]
        show_types: bool,
    },
    /// Print the messages of a topic as JSON lines.
    Echo {
        /// Topic name, e.g. /human/activity (a relative name is in `/`).
        topic: String,
        /// Message type (e.g. lidar_har_msgs/msg/Activity); found by discovery when omitted.
        #[arg(long = "type")]
        type_name: Option<String>,
        /// Stop after this many messages.
        #[arg(long)]
        count: Option<u64>,
        /// Stop after this many seconds, at most a day (also bounds the wait for discovery).
        #[arg(long)]
        timeout: Option<f64>,
        /// Exit non-zero when fewer than --count messages arrived before --timeout.
        #[arg(long)]
        require_count: bool,
        /// Arrays longer than this are printed as their first N elements then the string
        /// "...", strings as their first N characters then "..." (as ros2 topic echo).
        #[arg(short = 'l', long, default_value_t = 128)]
        truncate_length: usize,
        /// Print arrays and strings whole, however long (--truncate-length is ignored).
        #[arg(short = 'f', long)]
        full_length: bool,
        /// Print every array as its length ("<sequence length: N>") instead of its elements.
        #[arg(long)]
        no_arr: bool,
        /// Print every string as its length ("<string length: <N>>") instead of its text.
        #[arg(long)]
        no_str: bool,
    },
    /// Print a topic's rate once a second, as `ros2 topic hz` does (e.g. the Lidar's scan
    /// rate, which the classifier wants within 25 % of its model's).
    Hz {
        /// Topic name, e.g. /scan (a relative name is in `/`).
        topic: String,
        /// Message type; found by discovery when omitted.
        #[arg(long = "type")]
        type_name: Option<String>,
        /// How many of the latest periods the rate is taken over (1 to 1,000,000).
        #[arg(short = 'w', long, default_value_t = 10_000,
              value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
        window: u32,
        /// Stop after this many seconds, at most a day (default: at Ctrl-C).
        #[arg(long)]
        timeout: Option<f64>,
    },
}

pub fn run(command: TopicCommand) -> anyhow::Result<()> {
    match command {
        TopicCommand::List { wait, show_types } => list(seconds(wait, "--wait")?, show_types),
        TopicCommand::Echo {
            topic,
            type_name,
            count,
            timeout,
            require_count,
            truncate_length,
            full_length,
            no_arr,
            no_str,
        } => {
            let timeout = timeout.map(|t| seconds(t, "--timeout")).transpose()?;
            let truncation = Truncation {
                length: (!full_length).then_some(truncate_length),
                no_arr,
                no_str,
            };
            echo(&topic, type_name, count, timeout, require_count, truncation)
        }
        TopicCommand::Hz {
            topic,
            type_name,
            window,
            timeout,
        } => {
            let timeout = timeout.map(|t| seconds(t, "--timeout")).transpose()?;
            rate(&topic, type_name, window, timeout)
        }
    }
}

/// The longest `--wait` or `--timeout`, seconds (a day).
const MAX_SECONDS: f64 = 86_400.0;

fn seconds(value: f64, flag: &str) -> anyhow::Result<Duration> {
    if !(0.0..=MAX_SECONDS).contains(&value) {
        bail!("{flag} {value}: must be a number of seconds from 0 to {MAX_SECONDS} (a day)");
    }
    Ok(Duration::from_secs_f64(value))
}

/// The tool's node name, unique per process: several `topic echo` may run at once.
fn cli_node_name() -> String {
    format!("lidar_har_cli_{}", std::process::id())
}

fn cli_node() -> anyhow::Result<Node> {
    // A tool, not a node: nothing for `ros2 param` to read.
    Node::new(
        NodeSetup::new(&cli_node_name())
            .args(Vec::<String>::new())
            .without_parameter_services(),
    )
    .context("cannot join the ROS 2 graph")
}

fn list(wait: Duration, show_types: bool) -> anyhow::Result<()> {
    let node = cli_node()?;
    std::thread::sleep(wait);
    for t in node.topics() {
        if show_types {
            outln!("{} [{}]", t.name, t.type_name);
        } else {
            outln!("{}", t.name);
        }
    }
    Ok(())
}

/// `topic` as given on the command line, checked and expanded as ros2 does it: relative to
/// `/` (`scan` is /scan), `~/x` in the tool's node.
fn topic_name(topic: &str) -> Result<String, RosError> {
    args::validate_topic_name(topic).map_err(|reason| RosError::Name {
        name: topic.to_string(),
        reason,
    })?;
    Ok(args::expand_name(topic, "/", &cli_node_name()))
}

/// How long `echo` waits for the topic's publishers to be discovered, to match their QoS.
const PUBLISHER_DISCOVERY: Duration = Duration::from_secs(2);

/// The QoS to read a topic with, chosen as `ros2 topic echo` does from the publishers found
/// (`choose_qos` in ros2cli): reliable only if every one offers it, transient-local only if
/// every one does (so a latched message of any of them is still received), best effort and
/// volatile otherwise, which every publisher matches. Without publishers, `fallback`.
fn echo_qos(fallback: QosProfile, publishers: &[OfferedQos]) -> QosProfile {
    if publishers.is_empty() {
        return fallback;
    }
    let all = |pred: fn(&OfferedQos) -> bool| publishers.iter().all(pred);
    QosProfile {
        reliability: if all(|p| p.reliability == Reliability::Reliable) {
            Reliability::Reliable
        } else {
            Reliability::BestEffort
        },
        durability: if all(|p| p.durability == Durability::TransientLocal) {
            Durability::TransientLocal
        } else {
            Durability::Volatile
        },
        history: fallback.history,
    }
}

/// The publishers of `topic` discovered within [`PUBLISHER_DISCOVERY`] (or until `deadline`).
fn discover_publishers(node: &Node, topic: &str, deadline: Option<Instant>) -> Vec<OfferedQos> {
    let until = Instant::now() + PUBLISHER_DISCOVERY;
    let until = deadline.map_or(until, |d| d.min(until));
    loop {
        let publishers = node.publishers_qos(topic);
        if !publishers.is_empty() || Instant::now() >= until {
            return publishers;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A subscription of the tool to one topic, with the QoS `ros2 topic echo` would choose.
struct TopicReader {
    node: Node,
    sub: Subscriber,
    /// The topic's full name.
    topic: String,
    type_name: String,
}

impl TopicReader {
    /// Subscribes to `topic` as `type_name`, else the contract's type, else the type
    /// discovered on the network (waiting up to `deadline` for it).
    fn open(
        topic: &str,
        type_name: Option<String>,
        deadline: Option<Instant>,
    ) -> anyhow::Result<Self> {
        let topic = topic_name(topic)?;
        let node = cli_node()?;
        let contract = topics::find(&topic);
        let type_name = match (type_name, contract) {
            (Some(t), _) => t,
            (None, Some(spec)) => spec.type_name.to_string(),
            (None, None) => discover_type(&node, &topic, deadline)?,
        };
        // Without publishers to go by: the contract's QoS, else best effort, which every
        // publisher matches.
        let fallback = contract.map_or(QosProfile::sensor_data(), |spec| spec.subscribed);
        let qos = echo_qos(fallback, &discover_publishers(&node, &topic, deadline));
        let sub = node.subscriber(&topic, &type_name, qos)?;
        Ok(Self {
            node,
            sub,
            topic,
            type_name,
        })
    }
}

fn echo(
    topic: &str,
    type_name: Option<String>,
    count: Option<u64>,
    timeout: Option<Duration>,
    require_count: bool,
    truncation: Truncation,
) -> anyhow::Result<()> {
    let deadline = timeout.map(|t| Instant::now() + t);
    let TopicReader {
        node,
        sub,
        topic,
        type_name,
    } = TopicReader::open(topic, type_name, deadline)?;
    let topic = &topic;
    let stop = stop_flag()?;
    let mut received = 0u64;
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    while count.is_none_or(|c| received < c) {
        // After a signal, the messages that have already arrived are still printed (a
        // publisher that has finished may count them as delivered); none is waited for.
        let sample = if stop.load(std::sync::atomic::Ordering::Relaxed) {
            match sub.try_take()? {
                Some(sample) => sample,
                None => break,
            }
        } else {
            let left = match deadline {
                Some(d) => d.saturating_duration_since(Instant::now()),
                None => Duration::from_millis(200),
            };
            if left.is_zero() {
                break;
            }
            match sub.take_timeout(&node, left.min(Duration::from_millis(200)))? {
                Some(sample) => sample,
                None => continue,
            }
        };
        received += 1;
        let msg = EchoedMessage::new(&type_name, &sample.bytes);
        // An error is printed whole: cut, it could hide why.
        let how = match msg {
            EchoedMessage::DecodeError { .. } => Truncation::FULL,
            _ => truncation,
        };
        let line = EchoLine {
            topic,
            type_name: &type_name,
            source_time_ns: sample.source_time_ns,
            msg: Truncated::new(&msg, how),
        };
        // Straight to the output: no JSON tree of the message is built.
        let written = serde_json::to_writer(&mut out, &line).map_err(std::io::Error::from);
        match written
            .and_then(|()| writeln!(out))
            .and_then(|()| out.flush())
        {
            Ok(()) => {}
            // The reader has gone (`| head -n 3`): the echo is over, as after `--count`.
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
            Err(e) => return Err(e.into()),
        }
    }
    if require_count
        && let Some(c) = count
        && received < c
    {
        bail!("{topic}: received {received} of {c} messages before the timeout");
    }
    Ok(())
}

/// How often `hz` prints the rate, as `ros2 topic hz`.
const HZ_REPORT_PERIOD: Duration = Duration::from_secs(1);

/// `topic hz`: messages are timed as they arrive, as `ros2 topic hz` times them. The
/// publishers' source timestamps would be steadier on a loaded machine, but two publishers'
/// clocks disagree (a reviewer's two 10 Hz publishers 0.3 s apart read "no new messages").
fn rate(
    topic: &str,
    type_name: Option<String>,
    window: u32,
    timeout: Option<Duration>,
) -> anyhow::Result<()> {
    let start = Instant::now();
    let deadline = timeout.map(|t| start + t);
    let TopicReader { node, sub, .. } = TopicReader::open(topic, type_name, deadline)?;
    let stop = stop_flag()?;
    let mut rates = hz::RateWindow::new(window as usize);
    let mut new_messages = false;
    let mut next_report = Instant::now() + HZ_REPORT_PERIOD;
    let mut out = std::io::stdout().lock();
    while !stop.load(std::sync::atomic::Ordering::Relaxed)
        && deadline.is_none_or(|d| Instant::now() < d)
    {
        let wait = next_report.saturating_duration_since(Instant::now());
        if sub
            .take_timeout(&node, wait.min(Duration::from_millis(200)))?
            .is_some()
        {
            rates.add(start.elapsed().as_nanos() as i64);
            new_messages = true;
        }
        let now = Instant::now();
        if now < next_report {
            continue;
        }
        // Once a second even under a flood of messages; a late report is not made up for.
        next_report = (next_report + HZ_REPORT_PERIOD).max(now);
        let report = match rates.stats() {
            Some(stats) if new_messages => stats.to_string(),
            _ => "no new messages".to_string(),
        };
        new_messages = false;
        match writeln!(out, "{report}").and_then(|()| out.flush()) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
            Err(e) => return Err(e.into()),
        }
    }
    Ok(())
}

fn discover_type(node: &Node, topic: &str, deadline: Option<Instant>) -> anyhow::Result<String> {
    let deadline = deadline.unwrap_or_else(|| Instant::now() + Duration::from_secs(5));
    loop {
        if let Some(t) = node.topics().into_iter().find(|t| t.name == topic) {
            return Ok(t.type_name);
        }
        if Instant::now() >= deadline {
            bail!("topic {topic} not found on the network; give its type with --type");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Set by SIGINT/SIGTERM, which end `echo` and `hz` cleanly (stdout flushed, exit 0).
fn stop_flag() -> anyhow::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, flag.clone())
            .context("cannot install signal handler")?;
    }
    Ok(flag)
}

/// One line of `echo`'s output.
#[derive(serde::Serialize)]
struct EchoLine<'a> {
    topic: &'a str,
    #[serde(rename = "type")]
    type_name: &'a str,
    source_time_ns: Option<i64>,
    msg: Truncated<'a, EchoedMessage>,
}

/// A message as printed: decoded field by field for the types of `lidar_har_msgs`, otherwise
/// its CDR bytes in hex (a string, cut at --truncate-length as any other).
#[derive(serde::Serialize)]
#[serde(untagged)]
enum EchoedMessage {
    Decoded(json::Message),
    DecodeError { decode_error: String },
    Unknown { cdr_hex: String },
}

impl EchoedMessage {
    fn new(type_name: &str, bytes: &[u8]) -> Self {
        match json::decode(type_name, bytes) {
            Some(Ok(msg)) => Self::Decoded(msg),
            Some(Err(e)) => Self::DecodeError {
                decode_error: e.to_string(),
            },
            None => Self::Unknown {
                cdr_hex: bytes.iter().map(|b| format!("{b:02x}")).collect(),
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topic_names_are_expanded_in_the_root_namespace_and_checked() {
        assert_eq!(topic_name("scan").unwrap(), "/scan");
        assert_eq!(topic_name("human/activity").unwrap(), "/human/activity");
        assert_eq!(topic_name("/robot1/map").unwrap(), "/robot1/map");
        for bad in ["/scan/", "/bad-name", "//scan", ""] {
            let err = topic_name(bad).unwrap_err();
            assert!(matches!(err, RosError::Name { .. }), "{bad}: {err}");
        }
    }

    /// As `ros2 topic echo`: the echo used to read every topic outside the contract best
    /// effort and volatile (missing a latched /robot1/map) and every contract topic with the
    /// contract's QoS (never matching a best-effort publisher of a reliable topic).
    #[test]
    fn echo_qos_follows_the_publishers() {
        use Durability::{TransientLocal, Volatile};
        use Reliability::{BestEffort, Reliable};
        let offered = |reliability, durability| OfferedQos {
            reliability,
            durability,
        };
        let latched = offered(Reliable, TransientLocal);
        let chosen = |fallback: QosProfile, publishers: &[OfferedQos]| {
            let q = echo_qos(fallback, publishers);
            assert_eq!(q.history, fallback.history);
            (q.reliability, q.durability)
        };
        let sensor = QosProfile::sensor_data();
        assert_eq!(chosen(sensor, &[latched]), (Reliable, TransientLocal));
        assert_eq!(
            chosen(sensor, &[latched, offered(Reliable, Volatile)]),
            (Reliable, Volatile)
        );
        let reliable = QosProfile::reliable(10);
        assert_eq!(
            chosen(reliable, &[offered(BestEffort, Volatile)]),
            (BestEffort, Volatile)
        );
        assert_eq!(
            chosen(reliable, &[latched, offered(BestEffort, TransientLocal)]),
            (BestEffort, TransientLocal)
        );
        // None found: the fallback.
        let map = topics::MAP.qos;
        assert_eq!(chosen(map, &[]), (map.reliability, map.durability));
    }

    #[test]
    fn waits_are_refused_outside_zero_to_a_day_naming_the_flag() {
        assert_eq!(seconds(1.5, "--wait").unwrap(), Duration::from_millis(1500));
        assert_eq!(seconds(MAX_SECONDS, "--wait").unwrap().as_secs(), 86_400);
        for bad in [-1.0, f64::NAN, f64::INFINITY, 1e20, MAX_SECONDS + 1.0] {
            let e = seconds(bad, "--timeout").unwrap_err().to_string();
            assert!(e.starts_with("--timeout "), "{e}");
        }
    }

    /// `--window` is bounded: a window of `usize::MAX` periods overflowed, and memory grows
    /// with it.
    #[test]
    fn the_hz_window_is_refused_outside_one_to_a_million() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(subcommand)]
            topic: TopicCommand,
        }
        let parse = |window: &str| {
            <Cli as clap::Parser>::try_parse_from(["lidar-har", "hz", "/scan", "-w", window])
        };
        for bad in ["0", "1000001", "18446744073709551615", "-3"] {
            assert!(parse(bad).is_err(), "--window {bad} accepted");
        }
        assert!(parse("1").is_ok() && parse("1000000").is_ok());
    }

    /// ros2's options and default (128); a line stays one JSON object whatever is cut.
    #[test]
    fn echo_cuts_long_arrays_and_strings_by_default_as_ros2() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(subcommand)]
            topic: TopicCommand,
        }
        let parsed = |args: &[&str]| {
            let argv = ["lidar-har", "echo", "/map"].iter().chain(args);
            match <Cli as clap::Parser>::try_parse_from(argv).unwrap().topic {
                TopicCommand::Echo {
                    truncate_length,
                    full_length,
                    no_arr,
                    no_str,
                    ..
                } => (truncate_length, full_length, no_arr, no_str),
                _ => unreachable!("echo parsed as another command"),
            }
        };
        assert_eq!(parsed(&[]), (128, false, false, false));
        assert_eq!(parsed(&["-l", "5", "-f"]), (5, true, false, false));
        assert_eq!(parsed(&["--no-arr", "--no-str"]), (128, false, true, true));

        let grid = lidar_har_msgs::nav_msgs::OccupancyGrid {
            data: vec![100; 300],
            ..Default::default()
        };
        let bytes = lidar_har_msgs::encode(&grid).unwrap();
        let line = |type_name: &str, truncation| {
            let msg = EchoedMessage::new(type_name, &bytes);
            let line = EchoLine {
                topic: "/map",
                type_name,
                source_time_ns: Some(7),
                msg: Truncated::new(&msg, truncation),
            };
            let text = serde_json::to_string(&line).unwrap();
            assert!(text.starts_with(r#"{"topic":"/map","type":"#), "{text}");
            serde_json::from_str::<serde_json::Value>(&text).unwrap()
        };
        let cut = Truncation {
            length: Some(128),
            ..Truncation::FULL
        };
        let map = line("nav_msgs/msg/OccupancyGrid", cut);
        assert_eq!(map["source_time_ns"], 7);
        let data = map["msg"]["data"].as_array().unwrap();
        assert_eq!(
            (data.len(), &data[127], &data[128]),
            (129, &100.into(), &"...".into())
        );
        let whole = line("nav_msgs/msg/OccupancyGrid", Truncation::FULL);
        assert_eq!(whole["msg"]["data"].as_array().unwrap().len(), 300);
        // A type without a mirror: its hex is a string like any other.
        let hex = line("foo_msgs/msg/Bar", cut)["msg"]["cdr_hex"].clone();
        assert_eq!(hex.as_str().unwrap().len(), 128 + 3);
        let garbage = EchoedMessage::new("nav_msgs/msg/OccupancyGrid", &bytes[..3]);
        assert!(matches!(garbage, EchoedMessage::DecodeError { .. }));
    }
}
