//! A node's log records on /rosout (`rcl_interfaces/msg/Log`), as rclcpp publishes every
//! record a node logs: `rqt_console`, Foxglove's log panel and `ros2 bag record /rosout` see
//! what the node says, not only its terminal.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::SystemTime;

use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::rcl_interfaces::Log;
use ros2_client::dds::rustdds::Timestamp;
use ros2_client::dds::rustdds::no_key::DataWriter;

use crate::dds::{RawAdapter, RawCdr};

/// One log record, owned: one logged before the node joined the graph waits in this form.
#[derive(Debug, Clone)]
pub struct LogEntry {
    pub time: SystemTime,
    pub level: log::Level,
    pub msg: String,
    pub file: String,
    pub function: String,
    pub line: u32,
}

impl From<&log::Record<'_>> for LogEntry {
    /// The record, timed now.
    fn from(record: &log::Record<'_>) -> Self {
        Self {
            time: SystemTime::now(),
            level: record.level(),
            msg: record.args().to_string(),
            file: record.file().unwrap_or_default().to_string(),
            function: record.module_path().unwrap_or_default().to_string(),
            line: record.line().unwrap_or_default(),
        }
    }
}

/// Where a node's log records are published, under its logger name: a /rosout writer of
/// rcl's QoS (reliable, transient local, keep last 1000, lifespan 10 s), which never waits
/// (docs/ros.md, "Nodes").
#[derive(Clone)]
pub struct Rosout {
    /// Our codec's CDR of `rcl_interfaces/msg/Log`, as every other topic's.
    writer: Arc<DataWriter<RawCdr, RawAdapter>>,
    logger_name: String,
    /// Records the writer refused (its send window full: a reader stopped acknowledging).
    dropped: Arc<AtomicU64>,
}

impl Rosout {
    pub(crate) fn new(writer: DataWriter<RawCdr, RawAdapter>, namespace: &str, name: &str) -> Self {
        Self {
            writer: Arc::new(writer),
            logger_name: logger_name(namespace, name),
            dropped: Arc::new(AtomicU64::new(0)),
        }
    }

    /// Publishes `entry`, stamped with its time on the system clock (as rcl stamps /rosout,
    /// whatever `use_sim_time` says). A record the writer refuses is dropped (it has been
    /// printed) and counted, with a warning through `log` at the first and every 1000th: a
    /// logger that forwards records here must not forward those it gets while publishing.
    pub fn publish(&self, entry: &LogEntry) {
        let log = Log {
            stamp: stamp(entry.time),
            level: level(entry.level),
            name: self.logger_name.clone(),
            msg: entry.msg.clone(),
            file: entry.file.clone(),
            function: entry.function.clone(),
            line: entry.line,
        };
        // A `Log` always encodes; were it not to, the record would be dropped like a refused one.
        let written = lidar_har_msgs::encode(&log).ok().and_then(|cdr| {
            let body = cdr.strip_prefix(&lidar_har_msgs::CDR_LE_HEADER)?;
            // With a source time, as the node's other samples (`topic echo`'s `source_time_ns`).
            let sent = Some(Timestamp::now());
            self.writer.write(RawCdr::little_endian(body), sent).ok()
        });
        if written.is_none() {
            let dropped = self.dropped.fetch_add(1, Ordering::Relaxed) + 1;
            if dropped % DROPPED_WARNING_EVERY == 1 {
                log::warn!(
                    "rosout: {dropped} log records not published: a /rosout reader has \
                     stopped acknowledging (they are printed here still)"
                );
            }
        }
    }
}

/// Refused records between two warnings.
const DROPPED_WARNING_EVERY: u64 = 1000;

/// rcl's logger name of a node: its namespace without the leading slash, then its name,
/// joined by dots (`/robot1` + `localiser` = `robot1.localiser`).
pub fn logger_name(namespace: &str, name: &str) -> String {
    let namespace = namespace.trim_matches('/');
    if namespace.is_empty() {
        name.to_string()
    } else {
        format!("{}.{name}", namespace.replace('/', "."))
    }
}

/// `time` as a `Time` since the Unix epoch; a time before it is 0, as ros2-client stamped it.
fn stamp(time: SystemTime) -> Time {
    time.duration_since(SystemTime::UNIX_EPOCH)
        .ok()
        .and_then(|since| i64::try_from(since.as_nanos()).ok())
        .map_or(Time::default(), Time::from_nanos)
}

/// The `Log` level of a record (`rcl_interfaces/msg/Log`'s constants; `trace` is a debug).
fn level(level: log::Level) -> u8 {
    match level {
        log::Level::Error => Log::ERROR,
        log::Level::Warn => Log::WARN,
        log::Level::Info => Log::INFO,
        log::Level::Debug | log::Level::Trace => Log::DEBUG,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logger_names_are_rcls() {
        assert_eq!(logger_name("/", "localiser"), "localiser");
        assert_eq!(logger_name("/robot1", "localiser"), "robot1.localiser");
        assert_eq!(logger_name("/a/b", "replay"), "a.b.replay");
    }

    #[test]
    fn stamps_are_wall_clock_times_and_zero_before_the_epoch() {
        let time = SystemTime::UNIX_EPOCH + std::time::Duration::from_nanos(1_700_000_000_250);
        assert_eq!(
            stamp(time),
            Time {
                sec: 1700,
                nanosec: 250
            }
        );
        let before = SystemTime::UNIX_EPOCH - std::time::Duration::from_secs(1);
        assert_eq!(stamp(before), Time::default());
    }

    #[test]
    fn levels_are_rcl_interfaces_constants() {
        let levels = [
            log::Level::Error,
            log::Level::Warn,
            log::Level::Info,
            log::Level::Debug,
            log::Level::Trace,
        ]
        .map(level);
        assert_eq!(levels, [40, 30, 20, 10, 10]);
    }
}
