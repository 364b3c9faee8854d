//! A node's log records on /rosout (`rcl_interfaces/msg/Log`), as rclcpp publishes every
//! record a node logs: `rqt_console`, Foxglove's log panel and `ros2 bag record /rosout` see
//! what the node says, not only its terminal.

use std::sync::Arc;
use std::time::SystemTime;

use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::rcl_interfaces::Log;

use crate::PublisherBackend;
use crate::dds::DdsPublisher;

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
    /// Our codec's CDR of `rcl_interfaces/msg/Log`, through the writer every topic has: a
    /// record it refuses (a reader stopped acknowledging) is dropped and warned about there.
    writer: Arc<DdsPublisher>,
    logger_name: String,
}

impl Rosout {
    pub(crate) fn new(writer: DdsPublisher, namespace: &str, name: &str) -> Self {
        Self {
            writer: Arc::new(writer),
            logger_name: logger_name(namespace, name),
        }
    }

    /// Publishes `entry`, stamped with its time on the system clock (as rcl stamps /rosout,
    /// whatever `use_sim_time` says). A record that cannot be written is dropped (it has
    /// been printed); a refused one is warned about through `log`, so a logger that forwards
    /// records here must not forward those it gets while publishing.
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
        if let Ok(cdr) = lidar_har_msgs::encode(&log) {
            let _ = self.writer.publish(&cdr);
        }
    }
}

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
    nanos_since_epoch(time).map_or(Time::default(), Time::from_nanos)
}

/// Nanoseconds from the Unix epoch to `time`; none before it (or past 2262).
pub(crate) fn nanos_since_epoch(time: SystemTime) -> Option<i64> {
    time.duration_since(SystemTime::UNIX_EPOCH)
        .ok()
        .and_then(|since| i64::try_from(since.as_nanos()).ok())
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
