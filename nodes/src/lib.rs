//! Shared plumbing of the lidar_har node binaries: start-up, exit codes, signals and stamps.
//! The nodes themselves stay thin: parameters in, library crates do the work, topics out.

use std::cell::Cell;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use lidar_har_ros::args::Severity;
use lidar_har_ros::{Backend, LogEntry, Node, ParamDecl, PreparedNode, RosArgs, RosError, Rosout};

/// What the nodes log without `RUST_LOG`: their own info, only warnings from the DDS stack
/// (whose info level describes every discovery packet).
const DEFAULT_LOG_FILTER: &str = "info,rustdds=warn,ros2_client=warn";

/// The module of RustDDS that warns about every UDP datagram over 1500 bytes
/// (`try_send_to_locator: Message size = 3012`), such as each 720-beam scan: one warning per
/// scan from the driver and the replay. Such datagrams are normal (the IP layer fragments
/// them), so [`NodeLogger`] drops these warnings, whatever `RUST_LOG` says, and keeps the
/// module's others (failed sends, a send buffer smaller than asked for).
const UDP_SENDER_TARGET: &str = "rustdds::network::udp_sender";

/// The module of RustDDS that warns about each write that found the reliable send window
/// full (`Write timed out (reliable send window full): topic=...`): one per sample while a
/// subscriber has stopped acknowledging. The transport drops such samples and warns itself,
/// sparingly (`lidar_har_ros`), so [`NodeLogger`] drops these.
const DATAWRITER_TARGET: &str = "rustdds::dds::with_key::datawriter";

/// The module of ros2-client that compares `ROS_DISTRO` with the distribution it was built
/// for, at every start: a warning when `ROS_DISTRO` is unset (the documented case of no ROS 2
/// installation), an ERROR advising `--features humble` under Humble, a feature this
/// workspace does not have. [`NodeLogger`] drops its records; [`join`] says what another
/// distribution means for the node instead ([`ros_distro_note`]).
const DISTRO_CHECK_TARGET: &str = "ros2_client::distributions";

/// The distribution ros2-client is built for (its default feature).
const TRANSPORT_DISTRO: &str = "jazzy";

/// env_logger without RustDDS's datagram size and full send window warnings, and without
/// ros2-client's `ROS_DISTRO` check; what it prints of the node's own records also goes to
/// /rosout ([`forward_to_rosout`]).
struct NodeLogger(env_logger::Logger);

fn is_datagram_size_warning(record: &log::Record) -> bool {
    record.level() == log::Level::Warn
        && record.target() == UDP_SENDER_TARGET
        && record.args().to_string().contains(": Message size = ")
}

fn is_send_window_warning(record: &log::Record) -> bool {
    record.level() == log::Level::Warn
        && record.target() == DATAWRITER_TARGET
        && record
            .args()
            .to_string()
            .starts_with("Write timed out (reliable send window full)")
}

fn is_ros_distro_check(record: &log::Record) -> bool {
    record.target() == DISTRO_CHECK_TARGET
}

impl log::Log for NodeLogger {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        self.0.enabled(metadata)
    }

    fn log(&self, record: &log::Record) {
        if !is_datagram_size_warning(record)
            && !is_send_window_warning(record)
            && !is_ros_distro_check(record)
        {
            self.0.log(record);
            if self.0.matches(record) && !is_transport_record(record) {
                forward_to_rosout(record);
            }
        }
    }

    fn flush(&self) {
        self.0.flush();
    }
}

/// Records of the DDS stack: rclcpp leaves its middleware's logs off /rosout too, and one
/// written while publishing there would be published in turn.
fn is_transport_record(record: &log::Record) -> bool {
    ["rustdds", "ros2_client"]
        .iter()
        .any(|transport| record.target().starts_with(transport))
}

/// Where [`NodeLogger`] sends the node's records on /rosout.
enum RosoutForward {
    /// The node has not joined the graph yet: the first [`EARLY_RECORDS`] wait for it (what
    /// it found while starting, such as a bag's missing topics).
    Waiting(Vec<LogEntry>),
    Joined(Rosout),
    /// `--disable-rosout-logs`, the rcl backend, or a program that is no node.
    Off,
}

/// Records kept until the node joins.
const EARLY_RECORDS: usize = 100;

static ROSOUT: Mutex<RosoutForward> = Mutex::new(RosoutForward::Waiting(Vec::new()));

thread_local! {
    /// Set while this thread publishes a record: a record logged on the way is not forwarded.
    static FORWARDING: Cell<bool> = const { Cell::new(false) };
}

fn forward_to_rosout(record: &log::Record) {
    if FORWARDING.replace(true) {
        return;
    }
    if let Ok(mut forward) = ROSOUT.lock() {
        match &mut *forward {
            RosoutForward::Waiting(early) if early.len() < EARLY_RECORDS => {
                early.push(LogEntry::from(record));
            }
            RosoutForward::Joined(rosout) => rosout.publish(&LogEntry::from(record)),
            RosoutForward::Waiting(_) | RosoutForward::Off => {}
        }
    }
    FORWARDING.set(false);
}

/// From now on the node's records go to `rosout`, those logged before it joined first; or,
/// with none, nowhere.
fn start_rosout(rosout: Option<Rosout>) {
    let Ok(mut forward) = ROSOUT.lock() else {
        return;
    };
    let early = match std::mem::replace(&mut *forward, RosoutForward::Off) {
        RosoutForward::Waiting(early) => early,
        RosoutForward::Joined(_) | RosoutForward::Off => Vec::new(),
    };
    if let Some(rosout) = rosout {
        FORWARDING.set(true);
        for entry in &early {
            rosout.publish(entry);
        }
        FORWARDING.set(false);
        *forward = RosoutForward::Joined(rosout);
    }
}

/// Logs to stderr through [`NodeLogger`]: `RUST_LOG` where it is set, else
/// [`DEFAULT_LOG_FILTER`] with `level` (from `--log-level`) as the level of every module it
/// names no level for. `RUST_LOG` wins: the launch files pass their `log_level` argument,
/// `info` by default, to every node, and a `RUST_LOG=debug ros2 launch ...` must still work.
fn init_logging(level: Option<log::LevelFilter>) {
    let env = env_logger::Env::default().default_filter_or(DEFAULT_LOG_FILTER);
    let mut builder = env_logger::Builder::from_env(env);
    if let Some(level) = unless_rust_log(level, std::env::var_os("RUST_LOG").as_deref()) {
        builder.filter_level(level);
    }
    let logger = builder.build();
    let max_level = logger.filter();
    if log::set_boxed_logger(Box::new(NodeLogger(logger))).is_ok() {
        log::set_max_level(max_level);
    }
}

/// What the pure-Rust transport means under `ros_distro` (`ROS_DISTRO`), where it informs:
/// a distribution other than Jazzy (docs/ros.md, "ROS 2 distributions").
fn ros_distro_note(ros_distro: Option<&str>) -> Option<String> {
    let distro = ros_distro.filter(|d| !d.is_empty() && *d != TRANSPORT_DISTRO)?;
    Some(format!(
        "ROS_DISTRO is {distro}, and this node's transport (ros2-client) speaks Jazzy's graph \
         information: its topics work with {distro}'s nodes and `ros2 topic`, but `ros2 node \
         list` and `ros2 param` may not see it (docs/ros.md, \"ROS 2 distributions\")"
    ))
}

/// Joins the ROS graph, first saying what `ROS_DISTRO` means for the pure-Rust transport
/// where it informs ([`ros_distro_note`]); the rcl backend is the installation's own.
pub fn join(setup: PreparedNode) -> Result<Node, RosError> {
    if Backend::default() == Backend::Dds
        && let Some(note) = ros_distro_note(std::env::var("ROS_DISTRO").ok().as_deref())
    {
        log::warn!("{note}");
    }
    let node = setup.join()?;
    start_rosout(node.rosout());
    Ok(node)
}

/// What a node is, for its `--help`: its name, one line on what it does, its parameters.
pub struct NodeInfo {
    pub name: &'static str,
    pub about: &'static str,
    /// The node's own parameters; `use_sim_time` is added as the node adds it.
    pub parameters: fn() -> Vec<ParamDecl>,
}

impl NodeInfo {
    /// The text `--help` prints.
    pub fn usage(&self) -> String {
        let mut text = format!(
            "{}: {}\n\nUsage: {} [--ros-args [-p NAME:=VALUE]... [--params-file FILE]... \
             [-r FROM:=TO]...]\n\nParameters:\n",
            self.name, self.about, self.name
        );
        for p in lidar_har_ros::node_parameters((self.parameters)()) {
            text.push_str(&format!(
                "  {} ({}, default {}): {}\n",
                p.name,
                p.default.type_name(),
                p.default,
                p.description
            ));
        }
        text
    }
}

/// What the program's own arguments (those outside `--ros-args`) ask for.
#[derive(Debug)]
enum ProgramArgs {
    Run,
    Help,
}

/// The nodes take no arguments of their own but `--help`: anything else is a mistake (most
/// often a parameter without `--ros-args -p`), refused before any DDS traffic starts.
fn program_args(args: &[String]) -> Result<ProgramArgs, RosError> {
    let rest = RosArgs::parse(args.iter().cloned())?.rest;
    match rest.first().map(String::as_str) {
        None => Ok(ProgramArgs::Run),
        Some("-h" | "--help") => Ok(ProgramArgs::Help),
        Some(other) => Err(RosError::Args(format!(
            "`{other}`: not an option of this node; parameters go after --ros-args \
             (`--ros-args -p name:=value`), and --help lists them"
        ))),
    }
}

/// `level` where `rust_log` (`RUST_LOG`) is unset or empty ([`init_logging`]).
fn unless_rust_log(
    level: Option<log::LevelFilter>,
    rust_log: Option<&std::ffi::OsStr>,
) -> Option<log::LevelFilter> {
    level.filter(|_| rust_log.is_none_or(|v| v.is_empty()))
}

/// The level `--log-level` gives the records of the node `default_name` (after `__node` and
/// `__ns` remapping, by rcl's logger name: `robot1.localiser`); a command line that does not
/// parse gives none here and is refused by the node's set-up.
fn log_level(args: &[String], default_name: &str) -> Option<log::LevelFilter> {
    let ros_args = RosArgs::parse(args.iter().cloned()).ok()?;
    let name = ros_args.node_name(default_name);
    let namespace = ros_args.namespace(name, "/");
    let level = match ros_args.log_level_for(&lidar_har_ros::logger_name(namespace, name))? {
        Severity::Unset => return None,
        Severity::Debug => log::LevelFilter::Debug,
        Severity::Info => log::LevelFilter::Info,
        Severity::Warn => log::LevelFilter::Warn,
        Severity::Error | Severity::Fatal => log::LevelFilter::Error,
    };
    Some(level)
}

/// Runs a node's body: logs to stderr ([`init_logging`]), and turns
/// an error into a one-line message and a non-zero exit code: 2 for a bad argument or
/// parameter, 1 otherwise. `--help` prints the node's usage instead.
pub fn run(node: &NodeInfo, body: impl FnOnce(&Shutdown) -> anyhow::Result<()>) -> ExitCode {
    let name = node.name;
    let args = match lidar_har_ros::utf8_args(std::env::args_os().skip(1)) {
        Ok(args) => args,
        Err(e) => {
            eprintln!("{name}: error: {e}");
            return ExitCode::from(2);
        }
    };
    match program_args(&args) {
        Ok(ProgramArgs::Run) => {}
        Ok(ProgramArgs::Help) => {
            print!("{}", node.usage());
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("{name}: error: {e}");
            return ExitCode::from(2);
        }
    }
    init_logging(log_level(&args, name));
    let shutdown = match Shutdown::install() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{name}: error: cannot install signal handlers: {e}");
            return ExitCode::FAILURE;
        }
    };
    match body(&shutdown) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("{name}: error: {err:#}");
            let bad_input = err.chain().any(|cause| {
                matches!(
                    cause.downcast_ref::<RosError>(),
                    Some(
                        RosError::Parameter { .. }
                            | RosError::ParamsFile { .. }
                            | RosError::Args(_)
                    )
                )
            });
            if bad_input {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

/// Set by SIGINT or SIGTERM; nodes poll it between messages and leave their loop cleanly.
/// The signal also deletes the bag reader's temporary copies at once (see
/// [`lidar_har_bag::remove_temporary_copies`]), which stops a decompression under way. A
/// second SIGINT or SIGTERM ends the process at once, by that signal (the shell sees 130 or
/// 143), as the `lidar-har` tool does: a node whose clean stop is held up (a DDS stack that
/// hangs) used to ignore every further signal but SIGKILL. The same signal again within
/// [`REPEAT_GRACE`] of the first is the same request, not a second: one sender may deliver
/// it twice (coreutils `timeout` signals the child and its process group; `ros2 launch
/// --noninteractive` under a terminal resends the terminal's Ctrl-C), and 1 stop in 12 of a
/// replay under `timeout -s INT` skipped its clean stop (status 130).
#[derive(Clone)]
pub struct Shutdown(Arc<AtomicI32>);

/// How long a repeat of the first signal counts as the same request (see [`Shutdown`]).
const REPEAT_GRACE: Duration = Duration::from_secs(1);

/// Whether a signal after the first ends the process at once: another kind of signal does
/// (`ros2 launch` escalates SIGINT to SIGTERM), the same one only once `grace_over`.
fn repeat_ends_at_once(first: i32, this: i32, grace_over: bool) -> bool {
    this != first || grace_over
}

impl Shutdown {
    fn install() -> std::io::Result<Self> {
        // The first signal's number, 0 before any.
        let first = Arc::new(AtomicI32::new(0));
        let grace_over = Arc::new(AtomicBool::new(false));
        let handled = [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM];
        // Before the handlers: a first signal between the two would start no grace, and no
        // repeat could then end a stop that hangs.
        let mut signals = signal_hook::iterator::Signals::new(handled)?;
        for signal in handled {
            let (first, grace_over) = (first.clone(), grace_over.clone());
            // In the handler itself, not in a thread reading `Signals` (which may take two
            // quick signals of one kind for one): the first signal is recorded, a later one
            // that counts as a second takes the signal's default action. One atomic
            // exchange, so that of two signals handled at once on two threads, one is the
            // second.
            let action = move || {
                if let Err(earlier) =
                    first.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst)
                    && repeat_ends_at_once(earlier, signal, grace_over.load(Ordering::SeqCst))
                {
                    let _ = signal_hook::low_level::emulate_default_handler(signal);
                }
            };
            // SAFETY: the action only reads and exchanges atomics and emulates the default
            // action, which is async-signal-safe (it is what
            // `flag::register_conditional_default` runs).
            unsafe { signal_hook::low_level::register(signal, action) }?;
        }
        std::thread::spawn(move || {
            if signals.forever().next().is_some() {
                lidar_har_bag::remove_temporary_copies();
                std::thread::sleep(REPEAT_GRACE);
                grace_over.store(true, Ordering::SeqCst);
            }
        });
        Ok(Self(first))
    }

    pub fn requested(&self) -> bool {
        self.0.load(Ordering::Relaxed) != 0
    }

    /// Sleeps until `deadline` in short steps; false when shutdown was requested meanwhile.
    pub fn sleep_until(&self, deadline: Instant) -> bool {
        loop {
            if self.requested() {
                return false;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return true;
            }
            std::thread::sleep(left.min(Duration::from_millis(50)));
        }
    }
}

/// Publishers of a node's output topics, by topic name.
pub struct Outputs {
    publishers: std::collections::HashMap<&'static str, lidar_har_ros::Publisher>,
}

impl Outputs {
    /// A publisher (contract name, type and QoS) for each of `specs`.
    pub fn new(
        node: &lidar_har_ros::Node,
        specs: &[lidar_har_msgs::topics::TopicSpec],
    ) -> Result<Self, RosError> {
        let publishers = specs
            .iter()
            .map(|s| Ok((s.name, node.publisher_for(s)?)))
            .collect::<Result<_, RosError>>()?;
        Ok(Self { publishers })
    }

    /// Publishes what a pipeline stage produced, in order.
    pub fn publish(&self, outgoing: &[lidar_har_pipeline::Outgoing]) -> Result<(), RosError> {
        for out in outgoing {
            match self.publishers.get(out.topic.name) {
                Some(publisher) => publisher.publish(&out.cdr)?,
                None => log::warn!(
                    "no publisher for {} (not an output of this node)",
                    out.topic.name
                ),
            }
        }
        Ok(())
    }
}

/// A configuration file parameter: the path, or `None` when empty (use the defaults).
pub fn optional_path(
    params: &lidar_har_ros::Parameters,
    name: &str,
) -> Result<Option<std::path::PathBuf>, RosError> {
    let value = params.string(name)?;
    Ok(if value.is_empty() {
        None
    } else {
        Some(value.into())
    })
}

/// A bad parameter whose value could not be used, with the reason.
pub fn bad_parameter(name: &str, reason: impl std::fmt::Display) -> RosError {
    RosError::Parameter {
        name: name.to_string(),
        reason: format!("{reason:#}"),
    }
}

/// A parameter in seconds within `range` (finite), as a `Duration`: checked first because
/// `Duration::from_secs_f64` panics on values it cannot hold.
pub fn seconds(
    params: &lidar_har_ros::Parameters,
    name: &str,
    range: std::ops::RangeInclusive<f64>,
) -> Result<Duration, RosError> {
    let rule = format!("seconds in {}..={}", range.start(), range.end());
    let v = params.f64_checked(name, &rule, |v| range.contains(&v))?;
    Duration::try_from_secs_f64(v).map_err(|e| bad_parameter(name, format!("{v}: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use lidar_har_ros::{ParamDecl, ParamValue, Parameters};

    #[test]
    fn a_repeat_of_the_first_signal_within_the_grace_is_the_same_request() {
        use signal_hook::consts::{SIGINT, SIGTERM};
        // `timeout -s INT` delivers one SIGINT twice: one clean stop.
        assert!(!repeat_ends_at_once(SIGINT, SIGINT, false));
        // Ctrl-C again after the grace, or SIGTERM after SIGINT (as `ros2 launch`
        // escalates), ends the process at once.
        assert!(repeat_ends_at_once(SIGINT, SIGINT, true));
        assert!(repeat_ends_at_once(SIGINT, SIGTERM, false));
        assert!(repeat_ends_at_once(SIGTERM, SIGINT, false));
    }

    fn params(value: f64) -> Parameters {
        let decls = [ParamDecl::new("period", ParamValue::Double(1.0), "s")];
        Parameters::resolve(
            &decls,
            "/test",
            &[],
            &[("period".into(), ParamValue::Double(value))],
        )
        .unwrap()
    }

    fn args(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn nodes_take_only_ros_args_and_help() {
        let run = |list: &[&str]| matches!(program_args(&args(list)), Ok(ProgramArgs::Run));
        let help = |list: &[&str]| matches!(program_args(&args(list)), Ok(ProgramArgs::Help));
        assert!(run(&[]));
        assert!(run(&["--ros-args", "-p", "rate:=2.0", "--"]));
        assert!(help(&["--help"]) && help(&["-h"]));
        for stray in [
            &["rate:=2.0"][..],
            &["--ros-args", "-p", "a:=1", "--", "extra"],
        ] {
            let err = program_args(&args(stray)).unwrap_err().to_string();
            assert!(
                err.contains("not an option") && err.contains("--ros-args"),
                "{err}"
            );
        }
        assert!(program_args(&args(&["--ros-args", "-p"])).is_err());
    }

    #[test]
    fn bad_node_names_and_namespaces_are_bad_arguments() {
        // Refused here, before DDS starts, with status 2 (used to be 1, from the DDS stack).
        for rule in [
            "__node:=bad-name",
            "__ns:=/robot-1",
            "__ns:=/robot1/",
            "__ns:=/1robot",
        ] {
            let err = program_args(&args(&["--ros-args", "-r", rule])).unwrap_err();
            assert!(
                matches!(err, RosError::Args(_)) && err.to_string().contains(rule),
                "{rule}: {err}"
            );
        }
    }

    #[test]
    fn usage_lists_every_parameter_with_type_and_default() {
        let info = NodeInfo {
            name: "demo_node",
            about: "does a thing",
            parameters: || {
                vec![
                    ParamDecl::new("rate", ParamValue::Double(1.0), "speed"),
                    ParamDecl::new("bag", ParamValue::String(String::new()), "the bag"),
                ]
            },
        };
        let usage = info.usage();
        assert!(usage.starts_with("demo_node: does a thing"), "{usage}");
        assert!(usage.contains("rate (double, default 1"), "{usage}");
        assert!(
            usage.contains("bag (string, default \"\"): the bag"),
            "{usage}"
        );
        // Declared by every node without being in its own list; --help used to leave it out.
        assert!(
            usage.contains("  use_sim_time (bool, default false)"),
            "{usage}"
        );
    }

    /// Whether `filter` picks a warning from `target` saying `message`.
    fn picks_warning(filter: fn(&log::Record) -> bool, target: &str, message: &str) -> bool {
        filter(
            &log::Record::builder()
                .level(log::Level::Warn)
                .target(target)
                .args(format_args!("{message}"))
                .build(),
        )
    }

    #[test]
    fn rustdds_datagram_size_warnings_are_dropped_and_its_other_warnings_kept() {
        let dropped = |target, message| picks_warning(is_datagram_size_warning, target, message);
        // One per full-size scan, from the driver and the replay.
        assert!(dropped(
            UDP_SENDER_TARGET,
            "try_send_to_locator: Message size = 3012"
        ));
        assert!(dropped(
            UDP_SENDER_TARGET,
            "send_to_locator: Message size = 1600"
        ));
        assert!(!dropped(
            UDP_SENDER_TARGET,
            "raw_send: Unicast to 127.0.0.1:7412 : Os { code: 101 } len=3012"
        ));
        assert!(!dropped(
            "rustdds::other",
            "try_send_to_locator: Message size = 3012"
        ));
    }

    #[test]
    fn rustdds_full_send_window_warnings_are_dropped() {
        let dropped = |target, message| picks_warning(is_send_window_warning, target, message);
        // One per sample while a subscriber has stopped acknowledging.
        assert!(dropped(
            DATAWRITER_TARGET,
            "Write timed out (reliable send window full): topic=\"rt/odom\"  timeout=Some(0ns)"
        ));
        assert!(!dropped(DATAWRITER_TARGET, "write: some other trouble"));
        assert!(!dropped(
            "rustdds::other",
            "Write timed out (reliable send window full): topic=\"rt/odom\""
        ));
    }

    /// What a [`NodeLogger`] that lets every level through writes of `records` (level,
    /// target, message).
    fn node_logger_output(records: &[(log::Level, &str, &str)]) -> String {
        #[derive(Clone, Default)]
        struct Buffer(Arc<std::sync::Mutex<Vec<u8>>>);
        impl std::io::Write for Buffer {
            fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
                self.0.lock().unwrap().extend_from_slice(bytes);
                Ok(bytes.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let buffer = Buffer::default();
        let logger = NodeLogger(
            env_logger::Builder::new()
                .filter_level(log::LevelFilter::Trace)
                .target(env_logger::Target::Pipe(Box::new(buffer.clone())))
                .build(),
        );
        for (level, target, message) in records {
            log::Log::log(
                &logger,
                &log::Record::builder()
                    .level(*level)
                    .target(target)
                    .args(format_args!("{message}"))
                    .build(),
            );
        }
        String::from_utf8(buffer.0.lock().unwrap().clone()).unwrap()
    }

    /// `--log-level` was accepted and ignored.
    #[test]
    fn log_level_is_the_one_rcl_gives_the_nodes_logger() {
        let level = |args: &[&str]| {
            let args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
            log_level(&args, "replay")
        };
        assert_eq!(level(&["--ros-args"]), None);
        let debug = level(&["--ros-args", "--log-level", "debug"]);
        assert_eq!(debug, Some(log::LevelFilter::Debug));
        let in_robot1 = ["--ros-args", "-r", "__ns:=/robot1", "--log-level"];
        let named = [&in_robot1[..], &["robot1.replay:=fatal"]].concat();
        assert_eq!(level(&named), Some(log::LevelFilter::Error));
        let other = [&in_robot1[..], &["replay:=error"]].concat();
        assert_eq!(level(&other), None, "another logger's rule");
        assert_eq!(level(&["--ros-args", "--log-level", "loud"]), None);
    }

    /// The launch files pass `--log-level info` to every node: it used to silence a
    /// `RUST_LOG=debug ros2 launch ...`.
    #[test]
    fn rust_log_wins_over_log_level() {
        let debug = Some(log::LevelFilter::Debug);
        assert_eq!(unless_rust_log(debug, None), debug);
        assert_eq!(unless_rust_log(debug, Some("".as_ref())), debug);
        assert_eq!(unless_rust_log(debug, Some("warn".as_ref())), None);
    }

    /// The DDS stack's records stay off /rosout: one logged while a record is published
    /// there would be published in turn.
    #[test]
    fn only_the_nodes_own_records_go_to_rosout() {
        let transport =
            |target| is_transport_record(&log::Record::builder().target(target).build());
        assert!(transport("rustdds::network::udp_sender"));
        assert!(transport("ros2_client::context"));
        assert!(!transport("replay"));
        assert!(!transport("lidar_har_pipeline::localiser"));
    }

    /// ros2-client's check logged a warning at every start without ROS 2, and under Humble an
    /// ERROR advising a feature this workspace does not have.
    #[test]
    fn ros2_clients_ros_distro_check_is_dropped_at_every_level() {
        let written = node_logger_output(&[
            (
                log::Level::Warn,
                DISTRO_CHECK_TARGET,
                "ROS_DISTRO is not set; ros2-client was built for 'jazzy'.",
            ),
            (
                log::Level::Error,
                DISTRO_CHECK_TARGET,
                "ROS_DISTRO='humble' but ros2-client was built for 'jazzy'. rebuild with \
                 --features humble.",
            ),
            (
                log::Level::Info,
                DISTRO_CHECK_TARGET,
                "ROS_DISTRO='jazzy' matches the ros2-client build.",
            ),
            (log::Level::Warn, "ros2_client::context", "kept"),
        ]);
        assert!(
            !written.contains("ROS_DISTRO") && written.contains("kept"),
            "{written}"
        );
    }

    #[test]
    fn ros_distro_is_noted_only_when_it_is_not_jazzy() {
        for quiet in [None, Some(""), Some("jazzy")] {
            assert_eq!(ros_distro_note(quiet), None, "{quiet:?}");
        }
        let note = ros_distro_note(Some("humble")).unwrap();
        assert!(
            note.starts_with("ROS_DISTRO is humble")
                && note.contains("topics work")
                && note.contains("`ros2 node list` and `ros2 param` may not see it")
                && !note.contains("--features"),
            "{note}"
        );
    }

    /// The launch files (`launch/*.py`) with their text; at least the three shipped.
    fn launch_files() -> Vec<(std::path::PathBuf, String)> {
        let launch = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../launch");
        let files: Vec<_> = std::fs::read_dir(&launch)
            .unwrap()
            .map(|entry| entry.unwrap().path())
            .filter(|path| path.extension().is_some_and(|e| e == "py"))
            .map(|path| {
                let text = std::fs::read_to_string(&path).unwrap();
                (path, text)
            })
            .collect();
        assert!(
            files.len() >= 3,
            "launch files not found in {}",
            launch.display()
        );
        files
    }

    /// Every lidar_har node a launch file starts takes the `log_level` launch argument as
    /// `--log-level`, as ROS 2 packages' launch files offer it.
    #[test]
    fn the_launch_files_pass_log_level_to_every_node_of_the_package() {
        for (path, text) in launch_files() {
            let nodes = text.matches("Node(package=\"lidar_har\"").count();
            let passed = text
                .matches("ros_arguments=[\"--log-level\", arg(\"log_level\")]")
                .count();
            assert_eq!(passed, nodes, "{}", path.display());
            if nodes > 0 {
                assert!(text.contains("DeclareLaunchArgument(\"log_level\""));
            }
        }
    }

    /// launch_ros reads a parameter value given as a bare launch argument as YAML:
    /// `bag:=2024_01_01` reached the replay as the integer 20240101 (status 2). Every launch
    /// argument passed as a parameter goes through `ParameterValue(..., value_type=...)`.
    #[test]
    fn the_launch_files_type_every_launch_argument_they_pass_as_a_parameter() {
        for (path, text) in launch_files() {
            for (n, line) in text.lines().enumerate() {
                // `"name": arg("x")` or `"name": LaunchConfiguration("x")` in a parameters map.
                let untyped = line.split_once("\": ").is_some_and(|(_, value)| {
                    value.starts_with("arg(") || value.starts_with("LaunchConfiguration(")
                });
                assert!(!untyped, "{}:{}: untyped: {line}", path.display(), n + 1);
            }
        }
    }

    /// The items of a launch file's `parameters=[...]` list as written, comments left out.
    fn parameter_items(node: &str) -> Vec<String> {
        let Some((_, list)) = node.split_once("parameters=[") else {
            return Vec::new();
        };
        let (mut items, mut item, mut depth) = (Vec::new(), String::new(), 0);
        let (mut in_string, mut in_comment) = (false, false);
        for c in list.chars() {
            match c {
                '\n' if in_comment => in_comment = false,
                _ if in_comment => continue,
                '"' => in_string = !in_string,
                '#' if !in_string => {
                    in_comment = true;
                    continue;
                }
                '(' | '[' | '{' if !in_string => depth += 1,
                ')' | '}' if !in_string => depth -= 1,
                ']' if !in_string && depth == 0 => break,
                ']' if !in_string => depth -= 1,
                ',' if !in_string && depth == 0 => {
                    items.push(std::mem::take(&mut item).trim().to_string());
                    continue;
                }
                _ => {}
            }
            item.push(c);
        }
        items.push(item.trim().to_string());
        items.retain(|item| !item.is_empty());
        items
    }

    /// The parameter names an item gives: every `"name":` in it.
    fn parameter_names(item: &str) -> Vec<String> {
        item.split('"')
            .collect::<Vec<_>>()
            .windows(2)
            .filter(|pair| pair[1].starts_with(':'))
            .map(|pair| pair[0].to_string())
            .collect()
    }

    /// How `own_values_file` in the launch files writes its one section.
    const OWN_VALUES_SECTION: &str = "yaml.safe_dump({\"/**\": {\"ros__parameters\": params}}";

    /// The launch arguments win over `params_file`, and `params_file` over the launch file's
    /// own values, whatever sections the file has for a node (docs/ros.md, launch files),
    /// under rcl's and rclcpp's rule, which [`Parameters::resolve`] copies: all parameter files
    /// merge into one table of sections in the order each name first appears, then the
    /// sections apply in that order. launch_ros writes each dict to a file with one section,
    /// the node's full name when it has a namespace and `/**` without one; the launch files'
    /// `own_values_file` writes `/**`. Modelled in argument order, the last value winning,
    /// this test passed while the launch arguments lost to a file with a `replay:` section (or
    /// `/**:` before `rplidar_driver:`). A file that names the node `/NAME` and has another
    /// section for it after that one still wins: the launch arguments are in `/NAME` then.
    #[test]
    fn the_launch_arguments_win_over_the_params_file_and_it_over_the_launch_files_values() {
        let dir = std::env::temp_dir().join(format!("lidar_har_launch_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let write = |file: &str, sections: &[&str], names: &[String], value: &str| {
            let mut yaml = String::new();
            for section in sections {
                yaml += &format!("{section}:\n  ros__parameters:\n");
                for name in names {
                    yaml += &format!("    {name}: {value}\n");
                }
            }
            let path = dir.join(file);
            std::fs::write(&path, yaml).unwrap();
            path
        };
        let mut checked = 0;
        for (path, text) in launch_files() {
            for node in text.split("Node(").skip(1) {
                let Some(name) = node
                    .strip_prefix("package=\"lidar_har\"")
                    .and_then(|rest| rest.split_once("name=\""))
                    .and_then(|(_, rest)| rest.split_once('"'))
                    .map(|(name, _)| name)
                else {
                    continue;
                };
                let items = parameter_items(node);
                let Some(user) = items.iter().position(|i| i == "arg(\"params_file\")") else {
                    continue;
                };
                let where_ = format!("{}: {name}", path.display());
                let dict_section = if node.contains("namespace=\"\"") {
                    format!("/{name}")
                } else {
                    "/**".to_string()
                };
                let names: Vec<String> = items.iter().flat_map(|i| parameter_names(i)).collect();
                let winners: Vec<String> = items[user + 1..]
                    .iter()
                    .flat_map(|i| parameter_names(i))
                    .collect();
                for item in &items[user + 1..] {
                    // Only launch arguments win over the file, and the bag's clock: a value of
                    // the launch file's own there (the replay's `topics`) would override the file's.
                    for value in item.split("\": ").skip(1) {
                        assert!(
                            value.starts_with("ParameterValue(arg(")
                                || item == "{\"use_sim_time\": True}",
                            "{where_}: a value of the launch file's own after params_file: {item}"
                        );
                    }
                }
                // And every launch argument after it: one before it would lose to the file.
                for item in &items[..user] {
                    assert!(
                        !item.contains("arg("),
                        "{where_}: a launch argument before params_file: {item}"
                    );
                }
                // Each item but params_file: its section, its names and the value it gives.
                let sources: Vec<_> = items
                    .iter()
                    .enumerate()
                    .map(|(i, item)| {
                        if i == user {
                            return None;
                        }
                        let section = if item.starts_with("own_values_file(") {
                            assert!(
                                text.contains(OWN_VALUES_SECTION),
                                "{where_}: own_values_file no longer writes `/**`: update this test"
                            );
                            "/**".to_string()
                        } else {
                            assert!(item.starts_with('{'), "{where_}: unknown item {item}");
                            dict_section.clone()
                        };
                        let value = if i < user {
                            "launch_file"
                        } else {
                            "launch_argument"
                        };
                        Some((section, parameter_names(item), value))
                    })
                    .collect();
                let decls: Vec<ParamDecl> = names
                    .iter()
                    .map(|n| ParamDecl::new(n, ParamValue::String("default".into()), ""))
                    .collect();
                let fqn = format!("/{name}");
                let spellings = [name, "/**", "/*", fqn.as_str()];
                let mut layouts: Vec<Vec<&str>> = spellings.iter().map(|s| vec![*s]).collect();
                for first in spellings {
                    for second in spellings {
                        if first != second && first != fqn {
                            layouts.push(vec![first, second]);
                        }
                    }
                }
                for layout in layouts {
                    let files: Vec<_> = sources
                        .iter()
                        .enumerate()
                        .map(|(i, source)| match source {
                            None => write("user.yaml", &layout, &names, "params_file"),
                            Some((section, item_names, value)) => {
                                write(&format!("item{i}.yaml"), &[section], item_names, value)
                            }
                        })
                        .collect();
                    let resolved = Parameters::resolve(&decls, &fqn, &files, &[]).unwrap();
                    for n in &names {
                        let expected = if winners.contains(n) {
                            "launch_argument"
                        } else {
                            "params_file"
                        };
                        assert_eq!(
                            resolved.string(n).unwrap(),
                            expected,
                            "{where_}: `{n}` with params_file sections {layout:?}"
                        );
                    }
                }
                checked += 1;
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
        // replay, localiser and classifier in replay.launch.py; the driver, localiser and
        // classifier in robot.launch.py.
        assert!(checked >= 6, "{checked} nodes with a params_file checked");
    }

    #[test]
    fn seconds_in_range_become_a_duration() {
        let d = seconds(&params(0.25), "period", 0.0..=5.0).unwrap();
        assert_eq!(d, Duration::from_millis(250));
    }

    #[test]
    fn seconds_out_of_range_or_not_finite_are_errors_naming_the_parameter() {
        // 1e300 used to pass a `> 0` check and then panic in Duration::from_secs_f64.
        for bad in [1e300, f64::INFINITY, f64::NAN, -1.0, 5.5] {
            let err = seconds(&params(bad), "period", 0.0..=5.0)
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("`period`") && err.contains("0..=5"),
                "{bad}: {err}"
            );
        }
    }

    /// The launch files give each node its params file: a node with no section there would
    /// run on its defaults, with a warning at every launch.
    #[test]
    fn the_launch_params_files_have_a_section_for_every_node_they_start() {
        let config = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../config");
        for (file, nodes) in [
            (
                "robot.yaml",
                ["/rplidar_driver", "/localiser", "/classifier"],
            ),
            ("replay.yaml", ["/replay", "/localiser", "/classifier"]),
        ] {
            let params = lidar_har_ros::params::ParamsFile::read(&config.join(file)).unwrap();
            for node in nodes {
                assert!(!params.sections_for(node).is_empty(), "{file}: {node}");
            }
        }
    }
}
