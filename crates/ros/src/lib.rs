//! ROS 2 transport of lidar_har: a small byte-level publish/subscribe interface (topic, type
//! name, QoS, CDR bytes) over two backends, so that `lidar_har_msgs`' codec is the only place
//! that knows message layouts.
//!
//! - default: `ros2-client` (pure-Rust DDS/RTPS with ROS 2 naming: topic `rt/scan`, type
//!   `sensor_msgs::msg::dds_::LaserScan_`). Builds and runs everywhere, talks to ROS 2 nodes.
//! - feature `r2r`: rcl through `r2r` (`publish_raw` / `subscribe_raw`); needs a sourced ROS 2.
//!
//! It also handles what ros2-client leaves to the application: `--ros-args` (remapping, node
//! name and namespace, `-p`, `--params-file`), `ROS_DOMAIN_ID`, and typed parameters that
//! `ros2 param get/set` can reach. Time stamps come from [`Node::now`], which follows /clock
//! when the `use_sim_time` parameter is true.

pub mod args;
mod dds;
pub mod json;
mod param_services;
pub mod params;
#[cfg(feature = "r2r")]
mod rcl;
mod rosout;
mod yaml;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use lidar_har_msgs::qos::{Durability, QosProfile, Reliability};
use lidar_har_msgs::topics::{self, TopicSpec};
use lidar_har_msgs::{CdrError, RosMessage};

pub use args::{RosArgs, utf8_args};
pub use params::{ParamDecl, ParamSource, ParamValue, Parameters, node_parameters};
pub use rosout::{LogEntry, Rosout, logger_name};

/// Everything that can go wrong in the transport, each naming what it is about.
#[derive(Debug, thiserror::Error)]
pub enum RosError {
    #[error("bad ROS argument {0}")]
    Args(String),
    #[error("parameter `{name}`: {reason}")]
    Parameter { name: String, reason: String },
    #[error("parameter file {path}: {reason}")]
    ParamsFile { path: PathBuf, reason: String },
    #[error("bad name `{name}`: {reason}")]
    Name { name: String, reason: String },
    #[error("type name `{0}` is not of the form `package/msg/Type`")]
    TypeName(String),
    #[error("DDS: {0}")]
    Dds(String),
    #[error("topic {topic}: {reason}")]
    Topic { topic: String, reason: String },
    #[error("service {service}: {reason}")]
    Service { service: String, reason: String },
    #[error(transparent)]
    Cdr(#[from] CdrError),
}

/// Which middleware a node uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// Pure-Rust DDS (`ros2-client`).
    Dds,
    /// rcl through `r2r`.
    #[cfg(feature = "r2r")]
    Rcl,
}

impl Default for Backend {
    /// rcl when built with `r2r` (a ROS 2 installation is present), pure-Rust DDS otherwise.
    fn default() -> Self {
        #[cfg(feature = "r2r")]
        return Self::Rcl;
        #[cfg(not(feature = "r2r"))]
        Self::Dds
    }
}

/// How to start a node: its default name, the parameters it declares, and the command line
/// (whose `--ros-args` sections are applied; the rest is left to the program).
#[derive(Debug, Clone)]
pub struct NodeSetup {
    pub name: String,
    pub namespace: String,
    pub parameters: Vec<ParamDecl>,
    pub args: Vec<String>,
    pub backend: Backend,
    /// Serve `ros2 param` (default): every node does; a tool that joins the graph only to
    /// look at it (`lidar-har topic`) does without.
    pub parameter_services: bool,
}

impl NodeSetup {
    /// A node named `name` in `/`, reading this process's command line.
    pub fn new(name: &str) -> Self {
        Self {
            name: name.to_string(),
            namespace: "/".to_string(),
            parameters: Vec::new(),
            // Lossy, not a panic: a node's `run` has refused a line that is not UTF-8.
            args: std::env::args_os()
                .skip(1)
                .map(|arg| arg.to_string_lossy().into_owned())
                .collect(),
            backend: Backend::default(),
            parameter_services: true,
        }
    }

    /// No `ros2 param` services (see [`NodeSetup::parameter_services`]).
    pub fn without_parameter_services(mut self) -> Self {
        self.parameter_services = false;
        self
    }

    pub fn parameters(mut self, decls: Vec<ParamDecl>) -> Self {
        self.parameters = decls;
        self
    }

    pub fn args<I: IntoIterator<Item = S>, S: Into<String>>(mut self, args: I) -> Self {
        self.args = args.into_iter().map(Into::into).collect();
        self
    }

    /// Parses the command line and resolves the parameters (defaults, then parameter files
    /// and `-p` as rclcpp combines them, see [`Parameters::resolve_sources`]). Bad arguments
    /// or parameters are errors naming them.
    pub fn prepare(self) -> Result<PreparedNode, RosError> {
        let ros_args = RosArgs::parse(self.args.clone())?;
        let name = ros_args.node_name(&self.name).to_string();
        let namespace = ros_args.namespace(&name, &self.namespace).to_string();
        let fqn = args::expand_name(&name, &namespace, &name);
        // The arguments' names are checked as they are parsed; these catch the program's own.
        let bad_name = |reason| RosError::Name {
            name: fqn.clone(),
            reason,
        };
        args::validate_node_name(&name).map_err(bad_name)?;
        args::validate_namespace(&namespace).map_err(bad_name)?;
        // The parameter services are named after the node's full name by ros2-client's rules
        // once DDS has started: a name it refuses must be refused here, before the node joins
        // the graph (its spinner panicked on `__` in a token, before `validate_token`
        // refused it).
        ros2_client::Name::new(&fqn, "get_parameters")
            .map_err(|e| bad_name(format!("ros2-client refuses it: {e}")))?;
        let decls = params::node_parameters(self.parameters.clone());
        let params = Parameters::resolve_sources(&decls, &fqn, &ros_args.params_for(&fqn))?;
        Ok(PreparedNode {
            setup: self,
            name,
            namespace,
            ros_args,
            params,
        })
    }
}

/// A received message: its CDR bytes (with encapsulation header) and when it was published.
#[derive(Debug, Clone)]
pub struct Sample {
    pub bytes: Vec<u8>,
    /// The publisher's source time stamp in nanoseconds since the Unix epoch, when the
    /// middleware carries one.
    pub source_time_ns: Option<i64>,
}

impl Sample {
    pub fn decode<M: RosMessage>(&self) -> Result<M, RosError> {
        Ok(lidar_har_msgs::decode(&self.bytes)?)
    }
}

/// A topic seen on the network.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct TopicInfo {
    /// ROS name, e.g. `/scan`.
    pub name: String,
    /// ROS type, e.g. `sensor_msgs/msg/LaserScan`.
    pub type_name: String,
}

/// What a discovered publisher offers of the QoS policies that decide whether a subscriber
/// matches it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OfferedQos {
    pub reliability: Reliability,
    /// Transient-local stands for anything at least as durable (transient, persistent).
    pub durability: Durability,
}

trait NodeBackend: Send + Sync {
    fn publisher(
        &self,
        topic: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<Box<dyn PublisherBackend>, RosError>;
    fn subscriber(
        &self,
        topic: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<Box<dyn SubscriberBackend>, RosError>;
    /// Blocks until some subscriber may have data, or `timeout` passes.
    fn wait(&self, timeout: Duration) -> Result<(), RosError>;
    fn now_ns(&self) -> i64;
    fn parameter(&self, name: &str) -> Option<ParamValue>;
    fn topics(&self) -> Vec<TopicInfo>;
    fn publishers_qos(&self, topic: &str) -> Vec<OfferedQos>;
    /// Where the node's log records go on /rosout, where the backend publishes them itself.
    fn rosout(&self) -> Option<Rosout> {
        None
    }
    /// A `std_srvs/srv/Empty` server at the resolved name `service`.
    fn empty_service(&self, service: &str) -> Result<Box<dyn EmptyServiceBackend>, RosError> {
        Err(RosError::Service {
            service: service.to_string(),
            reason: "services are not offered by this transport".into(),
        })
    }
}

trait EmptyServiceBackend: Send + Sync {
    /// Takes the next waiting request, if any, and returns the handle to answer it with.
    fn try_take(&self) -> Result<Option<RequestId>, RosError>;
    fn respond(&self, request: RequestId) -> Result<(), RosError>;
}

/// A request taken from a service, to be answered once it is acted on.
struct RequestId(ros2_client::RmwRequestId);

trait PublisherBackend: Send + Sync {
    fn publish(&self, cdr: &[u8]) -> Result<(), RosError>;
    fn subscription_count(&self) -> usize;
    /// Whether any subscriber has matched, one that has left since included (r2r tells only
    /// how many are matched now).
    fn has_matched(&self) -> bool {
        self.subscription_count() > 0
    }
    fn wait_for_acknowledgments(&self, timeout: Duration) -> Result<bool, RosError>;
}

trait SubscriberBackend: Send + Sync {
    fn try_take(&self) -> Result<Option<Sample>, RosError>;
}

/// A ROS 2 node.
pub struct Node {
    name: String,
    namespace: String,
    ros_args: RosArgs,
    params: Parameters,
    backend: Box<dyn NodeBackend>,
}

/// A node whose arguments and parameters are checked, before it joins the ROS graph: a
/// program can check what its parameters name (a file, a device) first, so that a bad one
/// fails before any DDS traffic (a participant dropped while it registered its endpoints
/// logged a dozen ERROR lines of the DDS stack before the one-line error).
pub struct PreparedNode {
    setup: NodeSetup,
    name: String,
    namespace: String,
    ros_args: RosArgs,
    params: Parameters,
}

impl PreparedNode {
    /// Parameter values at start-up.
    pub fn params(&self) -> &Parameters {
        &self.params
    }

    /// `topic` after namespace expansion and `-r` remapping, as [`Node::resolve_topic`].
    fn resolve_topic(&self, topic: &str) -> String {
        args::resolve_name(topic, &self.ros_args.remaps, &self.namespace, &self.name)
    }

    /// The topics the DDS backend opens itself, resolved as any of the node's topics: rcl
    /// resolves rclcpp's /clock subscription (TimeSource) and its /rosout publisher with the
    /// node's `-r` rules too, so `-r /clock:=/robot1/clock` moves them as it moves the
    /// replay's /clock (they used to stay at /clock and /rosout).
    fn own_topics(&self) -> dds::OwnTopics {
        dds::OwnTopics {
            clock: self.resolve_topic(topics::CLOCK.name),
            rosout: self.resolve_topic(topics::ROSOUT.name),
        }
    }

    /// Joins the ROS graph.
    pub fn join(self) -> Result<Node, RosError> {
        let own_topics = self.own_topics();
        let Self {
            setup,
            name,
            namespace,
            ros_args,
            params,
        } = self;
        let backend: Box<dyn NodeBackend> = match setup.backend {
            Backend::Dds => Box::new(dds::DdsNode::new(
                &name,
                &namespace,
                &params,
                &params::node_parameters(setup.parameters.clone()),
                setup.parameter_services,
                (!ros_args.disable_rosout_logs).then_some(own_topics.rosout),
                &own_topics.clock,
            )?),
            #[cfg(feature = "r2r")]
            Backend::Rcl => Box::new(rcl::RclNode::new(&name, &namespace, &setup.args)?),
        };
        Ok(Node {
            name,
            namespace,
            ros_args,
            params,
            backend,
        })
    }
}

impl Node {
    /// [`NodeSetup::prepare`], then [`PreparedNode::join`].
    pub fn new(setup: NodeSetup) -> Result<Self, RosError> {
        setup.prepare()?.join()
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// Command-line arguments outside `--ros-args`: the program's own.
    pub fn program_args(&self) -> &[String] {
        &self.ros_args.rest
    }

    /// Parameter values at start-up.
    pub fn params(&self) -> &Parameters {
        &self.params
    }

    /// The value of a parameter that the node serves to `ros2 param get`: with the DDS backend,
    /// which refuses every `ros2 param set`, its start-up value.
    pub fn parameter(&self, name: &str) -> Option<ParamValue> {
        self.backend
            .parameter(name)
            .or_else(|| self.params.get(name).cloned())
    }

    /// Where to publish the node's log records on /rosout, as rclcpp does: none with
    /// `--disable-rosout-logs`, nor with the rcl backend (whose rosout rcl's logging feeds;
    /// the `log` crate's records are not passed to it).
    pub fn rosout(&self) -> Option<Rosout> {
        self.backend.rosout()
    }

    /// `topic` after namespace expansion and `-r` remapping.
    pub fn resolve_topic(&self, topic: &str) -> String {
        args::resolve_name(topic, &self.ros_args.remaps, &self.namespace, &self.name)
    }

    /// `service` after namespace expansion and the `-r` rules that apply to services.
    pub fn resolve_service(&self, service: &str) -> String {
        args::resolve_name(
            service,
            &self.ros_args.service_remaps,
            &self.namespace,
            &self.name,
        )
    }

    /// Serves `service` (relative names are in the node's namespace, as rclcpp's) with the
    /// type `std_srvs/srv/Empty`: a trigger, answered from the node's own loop by
    /// [`EmptyService::answer`]. Only the default transport offers services.
    pub fn empty_service(&self, service: &str) -> Result<EmptyService, RosError> {
        let resolved = self.resolve_service(service);
        Ok(EmptyService {
            backend: self.backend.empty_service(&resolved)?,
            name: resolved,
        })
    }

    /// Now, in nanoseconds since the epoch: /clock time when `use_sim_time` is true (zero
    /// until the first /clock message), the system clock otherwise.
    pub fn now(&self) -> i64 {
        self.backend.now_ns()
    }

    pub fn publisher(
        &self,
        topic: &str,
        type_name: &str,
        qos: QosProfile,
    ) -> Result<Publisher, RosError> {
        let resolved = self.resolve_topic(topic);
        let inner = self.backend.publisher(&resolved, type_name, &qos)?;
        Ok(Publisher {
            topic: resolved,
            type_name: type_name.to_string(),
            inner,
        })
    }

    pub fn subscriber(
        &self,
        topic: &str,
        type_name: &str,
        qos: QosProfile,
    ) -> Result<Subscriber, RosError> {
        let resolved = self.resolve_topic(topic);
        let inner = self.backend.subscriber(&resolved, type_name, &qos)?;
        Ok(Subscriber {
            topic: resolved,
            type_name: type_name.to_string(),
            inner,
        })
    }

    /// A publisher for a topic of the contract (its name, type and QoS).
    pub fn publisher_for(&self, spec: &TopicSpec) -> Result<Publisher, RosError> {
        self.publisher(spec.name, spec.type_name, spec.qos)
    }

    /// A subscriber for a topic of the contract (its name, type and subscription QoS).
    pub fn subscriber_for(&self, spec: &TopicSpec) -> Result<Subscriber, RosError> {
        self.subscriber(spec.name, spec.type_name, spec.subscribed)
    }

    /// Blocks until one of this node's subscribers may have data, or `timeout` passes. Take
    /// from every subscriber until empty before waiting again.
    pub fn wait(&self, timeout: Duration) -> Result<(), RosError> {
        self.backend.wait(timeout)
    }

    /// The QoS of each publisher of `topic` (a fully qualified name) discovered so far.
    pub fn publishers_qos(&self, topic: &str) -> Vec<OfferedQos> {
        self.backend.publishers_qos(topic)
    }

    /// Topics discovered on the network so far, sorted.
    pub fn topics(&self) -> Vec<TopicInfo> {
        let mut topics = self.backend.topics();
        topics.sort();
        topics.dedup();
        topics
    }
}

/// Publishes CDR bytes on one topic.
pub struct Publisher {
    topic: String,
    type_name: String,
    inner: Box<dyn PublisherBackend>,
}

impl Publisher {
    /// Publishes one message: CDR bytes beginning with the 4-byte encapsulation header.
    pub fn publish(&self, cdr: &[u8]) -> Result<(), RosError> {
        self.inner.publish(cdr)
    }

    /// Encodes and publishes a message of this topic's type.
    pub fn publish_msg<M: RosMessage>(&self, msg: &M) -> Result<(), RosError> {
        if M::TYPE_NAME != self.type_name {
            return Err(RosError::Topic {
                topic: self.topic.clone(),
                reason: format!("publishes {}, not {}", self.type_name, M::TYPE_NAME),
            });
        }
        self.publish(&lidar_har_msgs::encode(msg)?)
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// Subscribers matched so far.
    pub fn subscription_count(&self) -> usize {
        self.inner.subscription_count()
    }

    /// Whether any subscriber has matched so far, including one that has left since (with
    /// r2r: one is matched now).
    pub fn has_matched(&self) -> bool {
        self.inner.has_matched()
    }

    /// Blocks until every matched reliable subscriber has acknowledged all that was
    /// published, or `timeout` passes; true when they have (at once for best-effort topics).
    /// A process that exits right after publishing would otherwise lose what was still
    /// being sent or repaired.
    pub fn wait_for_acknowledgments(&self, timeout: Duration) -> Result<bool, RosError> {
        self.inner.wait_for_acknowledgments(timeout)
    }
}

/// Receives CDR bytes from one topic.
pub struct Subscriber {
    topic: String,
    type_name: String,
    inner: Box<dyn SubscriberBackend>,
}

impl Subscriber {
    /// The next received message, if any, without blocking.
    pub fn try_take(&self) -> Result<Option<Sample>, RosError> {
        self.inner.try_take()
    }

    /// The next message, waiting at most `timeout` on `node` (the node that made this
    /// subscriber).
    pub fn take_timeout(&self, node: &Node, timeout: Duration) -> Result<Option<Sample>, RosError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(sample) = self.try_take()? {
                return Ok(Some(sample));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            // Bounded slices: a notification that raced with the last take costs at most 20 ms.
            node.wait(left.min(Duration::from_millis(20)))?;
        }
    }

    /// The next message decoded as `M`, without blocking.
    pub fn try_take_msg<M: RosMessage>(&self) -> Result<Option<(M, Sample)>, RosError> {
        if M::TYPE_NAME != self.type_name {
            return Err(RosError::Topic {
                topic: self.topic.clone(),
                reason: format!("carries {}, not {}", self.type_name, M::TYPE_NAME),
            });
        }
        match self.try_take()? {
            Some(sample) => {
                let msg = sample.decode::<M>().map_err(|e| RosError::Topic {
                    topic: self.topic.clone(),
                    reason: e.to_string(),
                })?;
                Ok(Some((msg, sample)))
            }
            None => Ok(None),
        }
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }

    pub fn type_name(&self) -> &str {
        &self.type_name
    }
}

/// A `std_srvs/srv/Empty` service (see [`Node::empty_service`]).
pub struct EmptyService {
    name: String,
    backend: Box<dyn EmptyServiceBackend>,
}

impl EmptyService {
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Runs `act` for each waiting request and answers the request after it, so that a
    /// caller's response means the action has been taken. Returns how many were answered. A
    /// request that cannot be read or answered is logged and skipped: its caller times out.
    pub fn answer(&self, mut act: impl FnMut()) -> usize {
        let mut answered = 0;
        loop {
            match self.backend.try_take() {
                Ok(Some(request)) => {
                    act();
                    match self.backend.respond(request) {
                        Ok(()) => answered += 1,
                        Err(e) => log::warn!("{e}"),
                    }
                }
                Ok(None) => return answered,
                Err(e) => {
                    log::warn!("{e}");
                    return answered;
                }
            }
        }
    }
}

/// Splits `pkg/msg/Type` into its package and type.
fn split_type_name(type_name: &str) -> Result<(&str, &str), RosError> {
    match type_name.split('/').collect::<Vec<_>>().as_slice() {
        [pkg, "msg", ty] if !pkg.is_empty() && !ty.is_empty() => Ok((pkg, ty)),
        _ => Err(RosError::TypeName(type_name.to_string())),
    }
}

/// `pkg::msg::dds_::Type_` (the DDS type name) back to `pkg/msg/Type`.
pub fn ros_type_from_dds(dds: &str) -> Option<String> {
    let (pkg, rest) = dds.split_once("::msg::dds_::")?;
    Some(format!("{pkg}/msg/{}", rest.strip_suffix('_')?))
}

/// `rt/scan` (a DDS topic of a ROS topic) back to `/scan`.
pub fn ros_topic_from_dds(dds: &str) -> Option<String> {
    dds.strip_prefix("rt/").map(|t| format!("/{t}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn type_names_round_trip() {
        assert_eq!(
            split_type_name("sensor_msgs/msg/LaserScan").unwrap(),
            ("sensor_msgs", "LaserScan")
        );
        assert!(split_type_name("sensor_msgs/LaserScan").is_err());
        assert!(split_type_name("/msg/X").is_err());
        assert_eq!(
            ros_type_from_dds("sensor_msgs::msg::dds_::LaserScan_").as_deref(),
            Some("sensor_msgs/msg/LaserScan")
        );
        assert_eq!(
            ros_type_from_dds("rcl_interfaces::srv::dds_::GetParameters_Request_"),
            None
        );
        assert_eq!(
            ros_topic_from_dds("rt/human/activity").as_deref(),
            Some("/human/activity")
        );
        assert_eq!(ros_topic_from_dds("rq/node/get_parametersRequest"), None);
    }

    /// A name from the program itself breaking rmw's rules is refused before DDS starts
    /// (ros2-client alone accepts the namespace `/1robot`, then panics creating the node).
    #[test]
    fn a_bad_name_in_the_code_is_refused_before_dds() {
        for (name, namespace, bad) in [
            ("1node", "/", "`1node`"),
            ("node", "/1robot", "`/1robot`"),
            ("node", "/a/", "`/a/`"),
        ] {
            let mut setup = NodeSetup::new(name).args(Vec::<String>::new());
            setup.namespace = namespace.into();
            match Node::new(setup) {
                Err(e @ RosError::Name { .. }) => assert!(e.to_string().contains(bad), "{e}"),
                Err(other) => panic!("{namespace} {name}: {other}"),
                Ok(_) => panic!("{namespace} {name}: accepted"),
            }
        }
    }

    /// `-r` rules move the node's own /clock and /rosout as rcl moves rclcpp's (they stayed
    /// at /clock and /rosout while the replay's /clock publisher followed the rule); a
    /// relative rule resolves in the node's namespace, and a rule for another node is not
    /// applied.
    #[test]
    fn remapping_rules_apply_to_the_nodes_own_clock_and_rosout() {
        let own = |args: &[&str]| {
            NodeSetup::new("localiser")
                .args(args.iter().copied())
                .prepare()
                .unwrap()
                .own_topics()
        };
        let default = dds::OwnTopics {
            clock: "/clock".into(),
            rosout: "/rosout".into(),
        };
        assert_eq!(own(&[]), default);
        let remapped = dds::OwnTopics {
            clock: "/sim/clock".into(),
            rosout: "/robot1/rosout".into(),
        };
        let args = [
            "--ros-args",
            "-r",
            "/clock:=/sim/clock",
            "-r",
            "__ns:=/robot1",
        ];
        let args = [&args[..], &["-r", "/rosout:=rosout"]].concat();
        assert_eq!(own(&args), remapped);
        let other_node = ["--ros-args", "-r", "classifier:/clock:=/sim/clock"];
        assert_eq!(own(&other_node), default);
    }

    /// Names with `__` passed rmw's rules and then panicked in ros2-client's spinner (status
    /// 101, after DDS had started), from the code as from `-r __node:=` / `-r __ns:=`.
    #[test]
    fn a_name_ros2_client_refuses_is_refused_before_dds() {
        for (name, namespace, args) in [
            ("loc__2", "/", vec![]),
            ("node", "/robot__1", vec![]),
            ("node", "/", vec!["--ros-args", "-r", "__node:=loc__2"]),
            ("node", "/", vec!["--ros-args", "-r", "__ns:=/robot__1"]),
        ] {
            let mut setup = NodeSetup::new(name).args(args.clone());
            setup.namespace = namespace.into();
            match setup.prepare() {
                Err(e @ (RosError::Name { .. } | RosError::Args(_))) => {
                    assert!(e.to_string().contains("`__`"), "{e}")
                }
                Err(other) => panic!("{namespace} {name} {args:?}: {other}"),
                Ok(_) => panic!("{namespace} {name} {args:?}: accepted"),
            }
        }
        let setup = NodeSetup::new("_loc_2").args(["--ros-args", "-r", "__ns:=/_r1_/a_b"]);
        assert!(setup.prepare().is_ok());
    }
}
