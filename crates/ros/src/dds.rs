//! The default backend: ros2-client (RustDDS) with raw CDR bytes.
//!
//! ros2-client's typed publishers serialise serde values; we already have CDR bytes from our
//! codec. So the ros2-client `Node` provides the ROS side (node in the graph, rosout, ROS
//! topic and type naming) and our data readers and writers are RustDDS ones on its
//! participant, with a serializer adapter that passes bytes through unchanged. The node runs
//! no ros2-client spinner: `ros2 param` is served by [`crate::param_services`] and /clock read
//! by [`SimClock`].

use std::collections::HashMap;
use std::net::Ipv4Addr;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use lidar_har_msgs::qos::{Durability, History, QosProfile, Reliability};
use lidar_har_msgs::rosgraph_msgs::Clock;
use lidar_har_msgs::topics;
use ros2_client::dds::rustdds;
use ros2_client::{MessageTypeName, Name, NodeName, NodeOptions};
use rustdds::mio1;
use rustdds::no_key::{
    self, DataWriter, Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter,
};
use rustdds::{
    DataWriterStatus, QosPolicies, RepresentationIdentifier, StatusEvented, Timestamp, Topic,
};

use crate::args::DiscoveryRange;
use crate::param_services::{ParameterServices, ServedParameters};
use crate::params::{ParamDecl, ParamValue, Parameters};
use crate::{
    EmptyServiceBackend, NodeBackend, OfferedQos, PublisherBackend, RequestId, RosError, Rosout,
    Sample, SubscriberBackend, TopicInfo, split_type_name,
};

/// CDR bytes after the encapsulation header, with the header's representation identifier.
pub(crate) struct RawCdr {
    representation: RepresentationIdentifier,
    body: Vec<u8>,
}

/// Why bytes could not be handed to or taken from DDS.
#[derive(Debug, thiserror::Error)]
pub(crate) enum RawCdrError {
    #[error("encapsulation {0:02x?} is not plain CDR")]
    Encapsulation([u8; 2]),
}

/// Serialiser and deserialiser adapter passing CDR bytes through unchanged.
pub(crate) struct RawAdapter;

impl SerializerAdapter<RawCdr> for RawAdapter {
    type Error = RawCdrError;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    fn to_bytes(value: &RawCdr) -> Result<rustdds::bytes::Bytes, RawCdrError> {
        // The writer adds the CDR_LE header itself; only little-endian payloads are offered.
        if value.representation != RepresentationIdentifier::CDR_LE {
            return Err(RawCdrError::Encapsulation(value.representation.to_bytes()));
        }
        Ok(rustdds::bytes::Bytes::copy_from_slice(&value.body))
    }
}

impl DeserializerAdapter<RawCdr> for RawAdapter {
    type Error = RawCdrError;
    type Decoded = RawCdr;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &[
            RepresentationIdentifier::CDR_LE,
            RepresentationIdentifier::CDR_BE,
        ]
    }

    fn transform_decoded(decoded: RawCdr) -> RawCdr {
        decoded
    }
}

#[derive(Clone)]
pub(crate) struct RawDecoder;

impl Decode<'_, RawCdr> for RawDecoder {
    type Error = RawCdrError;

    fn decode_bytes(
        self,
        input: &[u8],
        encoding: RepresentationIdentifier,
    ) -> Result<RawCdr, RawCdrError> {
        Ok(RawCdr {
            representation: encoding,
            body: input.to_vec(),
        })
    }
}

impl DefaultDecoder<RawCdr> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

/// The QoS of a topic and of our readers of it.
fn qos_policies(qos: &QosProfile) -> QosPolicies {
    QosPolicies::from(&ros2_profile(qos, ros2_client::qos::WhenFull::DEFAULT))
}

fn ros2_profile(
    qos: &QosProfile,
    when_full: ros2_client::qos::WhenFull,
) -> ros2_client::QosProfile {
    use ros2_client::qos as r;
    let reliability = match qos.reliability {
        Reliability::Reliable => r::Reliability::Reliable { when_full },
        Reliability::BestEffort => r::Reliability::BestEffort,
    };
    let durability = match qos.durability {
        Durability::Volatile => r::Durability::Volatile,
        Durability::TransientLocal => r::Durability::TransientLocal,
    };
    let history = match qos.history {
        // DDS holds the depth as an i32: a larger one (a bag's metadata may say anything)
        // would wrap negative, announced so to peers, and keep everything.
        History::KeepLast(depth) => r::History::KeepLast {
            depth: depth.clamp(1, i32::MAX as u32) as usize,
        },
        History::KeepAll => r::History::KeepAll,
    };
    r::QosProfile::publisher_default()
        .reliability(reliability)
        .durability(durability)
        .history(history)
}

/// How long a write to a transient-local keep-last topic waits for its send window (see
/// [`writer_qos_policies`]): longer than RustDDS's slow heartbeat (1 s), after which a reader
/// that is there acknowledges.
const LATCHED_WRITE_WAIT: Duration = Duration::from_secs(2);

/// The QoS of our writers: [`qos_policies`], and what a write does when RustDDS's reliable
/// send window is full, which it is, but for the small windows of transient-local writers
/// (below), only when a matched reader has stopped acknowledging (a stopped process, a
/// network that lets discovery through but not data).
///
/// - Keep-last, volatile: the write fails at once ([`DdsPublisher::publish`] drops the
///   sample, with a warning). Keep-last writers of Cyclone DDS and Fast DDS never block: a
///   reader that falls behind loses old samples. RustDDS 0.15 blocks instead, for the
///   reliability's `max_blocking_time` (100 ms by default), once 8192 samples are
///   unacknowledged (its window, sized by ResourceLimits, not by the history), then fails:
///   that used to end the node. The window stays at 8192: one the size of the history
///   would hold up every reader of the topic as soon as one of them fell a few samples
///   behind.
/// - Keep-last, transient-local: ResourceLimits of the history's depth, so that RustDDS's
///   cache cleaning (every 6 s) keeps about `depth` samples for late joiners while no reader
///   is matched; it kept every sample, so a late joiner got them all and a replayed /map in
///   a loop grew the process by a map a pass. RustDDS 0.15 takes the send window from
///   ResourceLimits too, so the window is then `depth` samples (1 for /tf_static and /map:
///   stop-and-wait), and a write waits for a matched reader's acknowledgement of the sample
///   `depth` before it. That acknowledgement does not always come at once: a reader that has
///   just matched (the discovery race), or a loaded machine, may answer only after RustDDS's
///   next heartbeat, up to about 1 s later. A write that gave up after 100 ms never reached
///   the writer cache, so a second /tf_static written beside a starting subscriber was lost
///   for that subscriber and for every late joiner. Such writes wait up to
///   [`LATCHED_WRITE_WAIT`] (2 s); latched writes are rare, so a reader that stopped
///   acknowledging costs 2 s a latched sample, and the sample is then dropped with a warning
///   every time ([`DdsPublisher::publish`]).
/// - Keep-all: RustDDS's default wait (100 ms), then the sample is dropped with a warning.
fn writer_qos_policies(qos: &QosProfile) -> QosPolicies {
    use ros2_client::qos::WhenFull;
    let when_full = match (qos.history, qos.durability) {
        (History::KeepLast(_), Durability::Volatile) => WhenFull::Fail,
        (History::KeepLast(_), Durability::TransientLocal) => WhenFull::Wait(LATCHED_WRITE_WAIT),
        (History::KeepAll, _) => WhenFull::DEFAULT,
    };
    let policies = QosPolicies::from(&ros2_profile(qos, when_full));
    match (qos.history, qos.durability) {
        (History::KeepLast(depth), Durability::TransientLocal) => {
            let depth = i32::try_from(depth.max(1)).unwrap_or(i32::MAX);
            let limits = rustdds::QosPolicyBuilder::new()
                .resource_limits(rustdds::policy::ResourceLimits {
                    max_samples: depth,
                    max_instances: 1,
                    max_samples_per_instance: depth,
                })
                .build();
            policies.modify_by(&limits)
        }
        _ => policies,
    }
}

/// The contract's /rosout QoS (rcl's `rcl_qos_profile_rosout_default`: reliable, transient
/// local, keep last 1000; ResourceLimits as [`writer_qos_policies`] sets them) with rcl's
/// lifespan of 10 s; a write never waits, so a console that stops acknowledging cannot stall
/// the node's logging. ros2-client's own /rosout writer keeps 1 record: a console opened a
/// moment late missed every record but the last.
fn rosout_qos_policies() -> QosPolicies {
    let never_wait = rustdds::QosPolicyBuilder::new()
        .reliability(rustdds::policy::Reliability::Reliable {
            max_blocking_time: rustdds::Duration::ZERO,
        })
        .lifespan(rustdds::policy::Lifespan {
            duration: rustdds::Duration::from_secs(10),
        })
        .build();
    writer_qos_policies(&topics::ROSOUT.qos).modify_by(&never_wait)
}

/// A participant on `ROS_DOMAIN_ID`, announcing itself and listening for multicast only on
/// the interfaces the discovery range allows. RustDDS filters what it announces and where it
/// sends multicast, not what its unicast sockets accept: a peer elsewhere that learns our
/// addresses some other way can still reach them (docs/ros.md).
fn participant_from_env() -> Result<rustdds::DomainParticipant, RosError> {
    let builder = rustdds::DomainParticipantBuilder::new(crate::args::domain_id_from_env()?);
    let builder = match crate::args::discovery_range_from_env()? {
        DiscoveryRange::Subnet => builder,
        DiscoveryRange::Localhost => builder.with_only_networks([Ipv4Addr::LOCALHOST]),
        DiscoveryRange::Off => builder
            .with_only_networks(std::iter::empty::<Ipv4Addr>())
            .same_host_loopback(false),
    };
    if std::env::var("ROS_STATIC_PEERS").is_ok_and(|peers| !peers.trim().is_empty()) {
        log::warn!("ROS_STATIC_PEERS is not supported by the pure-Rust transport: ignored");
    }
    builder.build().map_err(dds_err)
}

fn dds_err(e: impl std::fmt::Display) -> RosError {
    RosError::Dds(e.to_string())
}

/// Fields drop in this order: every reader and writer (the parameter services', ours, then
/// the node's) before the participant, whose event loop must still run to remove them.
pub(crate) struct DdsNode {
    /// `ros2 param`, answered by a thread of ours: the node runs no ros2-client spinner
    /// (see [`crate::param_services`]).
    _parameter_services: Option<ParameterServices>,
    /// Where the node's log records go, unless `--disable-rosout-logs`.
    rosout: Option<Rosout>,
    served: Arc<ServedParameters>,
    /// /clock when `use_sim_time` is true, as `rosgraph_msgs/msg/Clock` (ros2-client 0.12's
    /// spinner read it as `builtin_interfaces/msg/Time`, which ROS 2's publishers do not
    /// match).
    sim_clock: Option<SimClock>,
    /// Locked only to create servers (ros2-client's `create_server` takes it mutably).
    node: Mutex<ros2_client::Node>,
    topics: Mutex<HashMap<String, Topic>>,
    publisher: rustdds::Publisher,
    subscriber: rustdds::Subscriber,
    poll: Mutex<(mio1::Poll, mio1::Events)>,
    registry: mio1::Registry,
    next_token: Mutex<usize>,
    context: ros2_client::Context,
}

/// The newest time received on /clock.
struct SimClock {
    reader: DdsSubscriber,
    latest_ns: Mutex<i64>,
}

impl SimClock {
    /// The newest /clock time, 0 before the first one (as rclcpp's ROS time).
    fn now_ns(&self) -> i64 {
        let Ok(mut latest) = self.latest_ns.lock() else {
            return 0;
        };
        loop {
            match self.reader.try_take() {
                Ok(Some(sample)) => match sample.decode::<Clock>() {
                    Ok(clock) => *latest = clock.clock.to_nanos(),
                    Err(e) => log::warn!("/clock: {e}"),
                },
                Ok(None) => break,
                Err(e) => {
                    log::warn!("/clock: {e}");
                    break;
                }
            }
        }
        *latest
    }
}

/// The resolved names of the topics the node opens itself, as rcl names rclcpp's.
#[derive(Debug, PartialEq)]
pub(crate) struct OwnTopics {
    /// Read when `use_sim_time` is true.
    pub(crate) clock: String,
    pub(crate) rosout: String,
}

impl DdsNode {
    /// `rosout`: where the node's log records go (none with `--disable-rosout-logs`);
    /// `clock`: what it reads as /clock when `use_sim_time` is true.
    pub(crate) fn new(
        name: &str,
        namespace: &str,
        params: &Parameters,
        decls: &[ParamDecl],
        parameter_services: bool,
        rosout: Option<String>,
        clock: &str,
    ) -> Result<Self, RosError> {
        let use_sim_time = params.bool("use_sim_time")?;
        let context = ros2_client::Context::from_domain_participant(participant_from_env()?)
            .map_err(dds_err)?;
        let node_name = NodeName::new(namespace, name).map_err(|e| RosError::Name {
            name: format!("{namespace}/{name}"),
            reason: format!("{e:?}"),
        })?;
        // ros2-client's parameter services are its spinner's, which the node does not run:
        // ours (below) replace them; so does our /rosout writer its own.
        let options = NodeOptions::new()
            .enable_rosout(false)
            .start_parameter_services(false);
        let mut node = context.new_node(node_name, options).map_err(dds_err)?;
        let served = Arc::new(ServedParameters::new(params, decls));
        let parameter_services = if parameter_services {
            Some(ParameterServices::start(&mut node, served.clone())?)
        } else {
            None
        };
        let participant = context.domain_participant();
        let publisher = participant
            .create_publisher(&QosPolicies::qos_none())
            .map_err(dds_err)?;
        let subscriber = participant
            .create_subscriber(&QosPolicies::qos_none())
            .map_err(dds_err)?;
        let poll = mio1::Poll::new().map_err(dds_err)?;
        let registry = poll.registry().try_clone().map_err(dds_err)?;
        let mut this = Self {
            _parameter_services: parameter_services,
            rosout: None,
            served,
            sim_clock: None,
            node: Mutex::new(node),
            topics: Mutex::new(HashMap::new()),
            publisher,
            subscriber,
            poll: Mutex::new((poll, mio1::Events::with_capacity(64))),
            registry,
            next_token: Mutex::new(0),
            context,
        };
        if let Some(rosout) = rosout {
            let policies = rosout_qos_policies();
            // Its drops are warned about sparingly, as a volatile topic's: one warning per
            // dropped record would double what the node prints.
            let writer = this.writer(
                &rosout,
                topics::ROSOUT.type_name,
                &policies,
                policies.clone(),
                false,
            )?;
            this.rosout = Some(Rosout::new(writer, namespace, name));
        }
        if use_sim_time {
            let spec = &topics::CLOCK;
            this.sim_clock = Some(SimClock {
                // Not registered with the node's poll: /clock alone need not wake `wait`.
                reader: this.reader(clock, spec.type_name, &spec.subscribed)?,
                latest_ns: Mutex::new(0),
            });
        }
        Ok(this)
    }

    /// A writer of CDR bytes on `topic`; `latched`: each dropped sample is warned about.
    fn writer(
        &self,
        topic: &str,
        type_name: &str,
        topic_policies: &QosPolicies,
        writer_policies: QosPolicies,
        latched: bool,
    ) -> Result<DdsPublisher, RosError> {
        let t = self.topic(topic, type_name, topic_policies)?;
        let writer = self
            .publisher
            .create_datawriter_no_key::<RawCdr, RawAdapter>(&t, Some(writer_policies))
            .map_err(|e| RosError::Topic {
                topic: topic.into(),
                reason: e.to_string(),
            })?;
        Ok(DdsPublisher {
            topic: topic.to_string(),
            writer,
            matched: AtomicUsize::new(0),
            matched_ever: AtomicUsize::new(0),
            dropped: AtomicU64::new(0),
            latched,
        })
    }

    fn reader(
        &self,
        topic: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<DdsSubscriber, RosError> {
        let policies = qos_policies(qos);
        let t = self.topic(topic, type_name, &policies)?;
        let reader = self
            .subscriber
            .create_simple_datareader_no_key::<RawCdr, RawAdapter>(&t, Some(policies))
            .map_err(|e| RosError::Topic {
                topic: topic.into(),
                reason: e.to_string(),
            })?;
        Ok(DdsSubscriber {
            topic: topic.to_string(),
            reader,
            skipped: AtomicU64::new(0),
        })
    }

    fn topic(&self, name: &str, type_name: &str, qos: &QosPolicies) -> Result<Topic, RosError> {
        let mut topics = self.topics.lock().map_err(dds_err)?;
        if let Some(t) = topics.get(name) {
            return Ok(t.clone());
        }
        let (pkg, ty) = split_type_name(type_name)?;
        let ros_name = Name::parse(name).map_err(|e| RosError::Name {
            name: name.into(),
            reason: format!("{e:?}"),
        })?;
        let profile = ros2_client::QosProfile::from(qos);
        let topic = self
            .node
            .lock()
            .map_err(lock_poisoned)?
            .create_topic(&ros_name, MessageTypeName::new(pkg, ty), &profile)
            .map_err(dds_err)?;
        topics.insert(name.to_string(), topic.clone());
        Ok(topic)
    }
}

fn lock_poisoned<T>(_: T) -> RosError {
    RosError::Dds("internal lock poisoned".into())
}

impl NodeBackend for DdsNode {
    fn publisher(
        &self,
        topic: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<Box<dyn PublisherBackend>, RosError> {
        let latched = qos.durability == Durability::TransientLocal;
        let writer_policies = writer_qos_policies(qos);
        let writer = self.writer(
            topic,
            type_name,
            &qos_policies(qos),
            writer_policies,
            latched,
        )?;
        Ok(Box::new(writer))
    }

    fn subscriber(
        &self,
        topic: &str,
        type_name: &str,
        qos: &QosProfile,
    ) -> Result<Box<dyn SubscriberBackend>, RosError> {
        let mut subscriber = self.reader(topic, type_name, qos)?;
        let token = {
            let mut next = self.next_token.lock().map_err(lock_poisoned)?;
            *next += 1;
            *next
        };
        mio1::event::Source::register(
            &mut subscriber.reader,
            &self.registry,
            mio1::Token(token),
            mio1::Interest::READABLE,
        )
        .map_err(dds_err)?;
        Ok(Box::new(subscriber))
    }

    fn wait(&self, timeout: Duration) -> Result<(), RosError> {
        let mut guard = self.poll.lock().map_err(lock_poisoned)?;
        let (poll, events) = &mut *guard;
        match poll.poll(events, Some(timeout)) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => Ok(()),
            Err(e) => Err(dds_err(e)),
        }
    }

    fn now_ns(&self) -> i64 {
        match &self.sim_clock {
            Some(clock) => clock.now_ns(),
            None => crate::rosout::nanos_since_epoch(std::time::SystemTime::now()).unwrap_or(0),
        }
    }

    fn parameter(&self, name: &str) -> Option<ParamValue> {
        self.served.get(name).cloned()
    }

    fn topics(&self) -> Vec<TopicInfo> {
        self.context
            .discovered_topics()
            .into_iter()
            .filter_map(|t| {
                Some(TopicInfo {
                    name: crate::ros_topic_from_dds(&t.name)?,
                    type_name: crate::ros_type_from_dds(&t.type_name)?,
                })
            })
            .collect()
    }

    fn publishers_qos(&self, topic: &str) -> Vec<OfferedQos> {
        self.context
            .domain_participant()
            .discovered_writers()
            .into_iter()
            .map(|w| w.publication_topic_data)
            .filter(|p| crate::ros_topic_from_dds(&p.topic_name).as_deref() == Some(topic))
            .map(|p| offered_qos(p.reliability, p.durability))
            .collect()
    }

    fn rosout(&self) -> Option<Rosout> {
        self.rosout.clone()
    }

    fn empty_service(&self, service: &str) -> Result<Box<dyn EmptyServiceBackend>, RosError> {
        let server = crate::param_services::server(
            &mut *self.node.lock().map_err(lock_poisoned)?,
            service,
            &ros2_client::ServiceTypeName::new("std_srvs", "Empty"),
        )?;
        Ok(Box::new(DdsEmptyService {
            service: service.to_string(),
            server,
        }))
    }
}

/// `std_srvs/srv/Empty`'s request and response alike: an IDL structure has at least one
/// member, so ROS 2 gives an empty one this byte.
#[derive(Debug, Default, Clone, serde::Serialize, serde::Deserialize)]
struct EmptyMessage {
    structure_needs_at_least_one_member: u8,
}

impl ros2_client::Message for EmptyMessage {}

struct DdsEmptyService {
    service: String,
    server: ros2_client::Server<EmptyMessage, EmptyMessage>,
}

impl DdsEmptyService {
    fn error(&self, what: &str, e: impl std::fmt::Debug) -> RosError {
        RosError::Service {
            service: self.service.clone(),
            reason: format!("{what}: {e:?}"),
        }
    }
}

impl EmptyServiceBackend for DdsEmptyService {
    fn try_take(&self) -> Result<Option<RequestId>, RosError> {
        self.server
            .receive_request()
            .map(|request| request.map(|(id, _)| RequestId(id)))
            .map_err(|e| self.error("a request that cannot be read", e))
    }

    fn respond(&self, RequestId(id): RequestId) -> Result<(), RosError> {
        self.server
            .send_response(id, EmptyMessage::default())
            .map_err(|e| self.error("the response could not be sent", e))
    }
}

/// A discovered writer's QoS; a policy it does not announce has the DDS default of a
/// writer: reliable, volatile.
fn offered_qos(
    reliability: Option<rustdds::policy::Reliability>,
    durability: Option<rustdds::policy::Durability>,
) -> OfferedQos {
    OfferedQos {
        reliability: match reliability {
            Some(rustdds::policy::Reliability::BestEffort) => Reliability::BestEffort,
            _ => Reliability::Reliable,
        },
        durability: match durability {
            None | Some(rustdds::policy::Durability::Volatile) => Durability::Volatile,
            Some(_) => Durability::TransientLocal,
        },
    }
}

pub(crate) struct DdsPublisher {
    topic: String,
    writer: DataWriter<RawCdr, RawAdapter>,
    /// Matched readers, from the writer's status events (RustDDS has no direct query).
    matched: AtomicUsize,
    /// Readers matched at any time, also from the status events.
    matched_ever: AtomicUsize,
    /// Samples dropped because the reliable send window was full (see
    /// [`writer_qos_policies`]).
    dropped: AtomicU64,
    /// Transient-local: a dropped sample is lost for late joiners too, so each is reported.
    latched: bool,
}

impl DdsPublisher {
    /// Takes in the writer's status events so far.
    fn update_matched(&self) {
        while let Some(status) = self.writer.try_recv_status() {
            if let DataWriterStatus::PublicationMatched { total, current, .. } = status {
                let count = |c: i32| usize::try_from(c).unwrap_or(0);
                self.matched
                    .store(count(current.count()), Ordering::Relaxed);
                self.matched_ever
                    .store(count(total.count()), Ordering::Relaxed);
            }
        }
    }
}

impl PublisherBackend for DdsPublisher {
    fn publish(&self, cdr: &[u8]) -> Result<(), RosError> {
        let bad = |reason: String| RosError::Topic {
            topic: self.topic.clone(),
            reason,
        };
        let Some((header, body)) = cdr.split_first_chunk::<4>() else {
            return Err(bad(format!(
                "{} bytes are shorter than the CDR encapsulation header",
                cdr.len()
            )));
        };
        let representation =
            RepresentationIdentifier::from_bytes(&header[..2]).map_err(|e| bad(e.to_string()))?;
        let written = self.writer.write(
            RawCdr {
                representation,
                body: body.to_vec(),
            },
            Some(Timestamp::now()),
        );
        match written {
            Ok(()) => Ok(()),
            // A matched reader has stopped acknowledging: the sample is lost for every reader,
            // as a keep-last writer of another DDS loses old samples for a slow reader.
            // A latched sample (after a 2 s wait, if keep-last) is reported every time: it
            // never reached the writer cache, so late joiners will not get it either. It is
            // not an error: that would end the node (a replay, a map publisher) for every
            // other subscriber because one of them is stopped, and would not bring the
            // sample back.
            Err(rustdds::dds::WriteError::WouldBlock { .. }) => {
                let dropped = self.dropped.fetch_add(1, Ordering::Relaxed) + 1;
                if self.latched {
                    log::warn!(
                        "{}: latched sample dropped: a subscriber has not acknowledged the \
                         samples before it; late subscribers will not get it either \
                         ({dropped} dropped so far)",
                        self.topic
                    );
                } else if dropped.is_power_of_two() {
                    log::warn!(
                        "{}: sample dropped: a subscriber has not acknowledged the samples \
                         before it ({dropped} dropped so far)",
                        self.topic
                    );
                }
                Ok(())
            }
            Err(e) => Err(bad(format!("write failed: {e}"))),
        }
    }

    fn subscription_count(&self) -> usize {
        self.update_matched();
        self.matched.load(Ordering::Relaxed)
    }

    fn has_matched(&self) -> bool {
        self.update_matched();
        self.matched_ever.load(Ordering::Relaxed) > 0
    }

    fn wait_for_acknowledgments(&self, timeout: Duration) -> Result<bool, RosError> {
        self.writer
            .wait_for_acknowledgments(timeout)
            .map_err(|e| RosError::Topic {
                topic: self.topic.clone(),
                reason: format!("waiting for acknowledgements: {e}"),
            })
    }
}

struct DdsSubscriber {
    topic: String,
    reader: no_key::SimpleDataReader<RawCdr, RawAdapter>,
    /// Samples that could not be read (see [`take_readable`]).
    skipped: AtomicU64,
}

/// RTPS time (seconds and 2^-32 fractions since the epoch) in nanoseconds; `None` for the
/// reserved "invalid" and "infinite" values, which are no time (they read as the year 2106).
fn timestamp_ns(t: Timestamp) -> Option<i64> {
    if t == Timestamp::INVALID || t == Timestamp::INFINITE {
        return None;
    }
    let ticks = t.to_ticks();
    let seconds = (ticks >> 32) as i64;
    let nanos = ((ticks & 0xFFFF_FFFF) * 1_000_000_000) >> 32;
    Some(seconds * 1_000_000_000 + nanos as i64)
}

/// The next sample that `take` gives, passing over those it cannot read: a sample whose
/// encapsulation is not plain CDR (any peer can send one, `00 11` or XCDR2) is logged, at
/// the 1st, 2nd, 4th, 8th... of `topic`, counted in `skipped`, and the next one taken. It
/// used to be an error, which ended the node. Other errors (the DDS stack's threads gone)
/// are errors.
fn take_readable<T>(
    topic: &str,
    skipped: &AtomicU64,
    mut take: impl FnMut() -> rustdds::dds::ReadResult<Option<T>>,
) -> Result<Option<T>, RosError> {
    loop {
        match take() {
            Ok(taken) => return Ok(taken),
            Err(rustdds::dds::ReadError::Deserialization { reason }) => {
                let n = skipped.fetch_add(1, Ordering::Relaxed) + 1;
                if n.is_power_of_two() {
                    log::warn!(
                        "{topic}: skipped a sample that cannot be read: {reason} ({n} so far)"
                    );
                }
            }
            Err(e) => {
                return Err(RosError::Topic {
                    topic: topic.to_string(),
                    reason: e.to_string(),
                });
            }
        }
    }
}

impl SubscriberBackend for DdsSubscriber {
    fn try_take(&self) -> Result<Option<Sample>, RosError> {
        self.reader.drain_read_notifications();
        let taken = take_readable(&self.topic, &self.skipped, || self.reader.try_take_one())?;
        Ok(taken.map(|change| {
            let source_time_ns = change.source_timestamp().and_then(timestamp_ns);
            let raw = change.into_value();
            let mut bytes = Vec::with_capacity(raw.body.len() + 4);
            bytes.extend_from_slice(&raw.representation.to_bytes());
            bytes.extend_from_slice(&[0, 0]);
            bytes.extend_from_slice(&raw.body);
            Sample {
                bytes,
                source_time_ns,
            }
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unannounced_policy_is_the_dds_default_of_a_writer() {
        use rustdds::policy::{Durability as D, Reliability as R};
        let reliable = R::Reliable {
            max_blocking_time: rustdds::Duration::ZERO,
        };
        let qos = |r, d| {
            let q = offered_qos(r, d);
            (q.reliability, q.durability)
        };
        assert_eq!(
            qos(None, None),
            (Reliability::Reliable, Durability::Volatile)
        );
        assert_eq!(
            qos(Some(R::BestEffort), Some(D::TransientLocal)),
            (Reliability::BestEffort, Durability::TransientLocal)
        );
        assert_eq!(
            qos(Some(reliable), Some(D::Persistent)),
            (Reliability::Reliable, Durability::TransientLocal)
        );
    }

    /// A sample whose encapsulation is not plain CDR (any peer can send one) is skipped and
    /// the next one taken: it used to be an error that ended the localiser and the
    /// classifier. Other errors stay errors.
    #[test]
    fn an_unreadable_sample_is_skipped_and_the_next_one_taken() {
        use rustdds::dds::ReadError;
        let unreadable = || ReadError::Deserialization {
            reason: "Unknown representation id [0, 17]".into(),
        };
        let mut queue = vec![Ok(Some(3)), Err(unreadable()), Err(unreadable())];
        let skipped = AtomicU64::new(0);
        let taken = take_readable("/scan", &skipped, || queue.pop().unwrap());
        assert_eq!(taken.unwrap(), Some(3));
        assert_eq!(skipped.load(Ordering::Relaxed), 2);
        let mut queue = vec![Ok(None::<u8>), Err(unreadable())];
        let taken = take_readable("/scan", &skipped, || queue.pop().unwrap());
        assert_eq!(taken.unwrap(), None);
        assert_eq!(skipped.load(Ordering::Relaxed), 3);
        let broken = take_readable::<u8>("/scan", &skipped, || {
            Err(ReadError::Poisoned {
                reason: "gone".into(),
            })
        });
        let err = broken.unwrap_err().to_string();
        assert!(err.contains("/scan") && err.contains("gone"), "{err}");
    }

    /// Keep-last writers do not wait for a full send window (a reader that stopped
    /// acknowledging used to end the node 100 ms into the first write it held up), but for
    /// transient-local ones, whose window is their depth (below): they wait 2 s.
    #[test]
    fn keep_last_writers_do_not_wait_for_a_stalled_reader() {
        use rustdds::policy::Reliability as R;
        let blocking = |qos: QosProfile| match writer_qos_policies(&qos).reliability() {
            Some(R::Reliable { max_blocking_time }) => Some(max_blocking_time),
            _ => None,
        };
        let zero = Some(rustdds::Duration::ZERO);
        assert_eq!(blocking(QosProfile::reliable(10)), zero);
        assert_eq!(blocking(topics::HUMAN_ACTIVITY.qos), zero);
        assert_eq!(blocking(QosProfile::sensor_data()), None);
        let waits = Some(rustdds::Duration::from_millis(100));
        // Longer than RustDDS's slow heartbeat: a window of 1 waits for the previous
        // sample's acknowledgement, which a reader that has just matched may send only then.
        let latched = Some(rustdds::Duration::from_secs(2));
        assert_eq!(blocking(QosProfile::latched(1)), latched);
        assert_eq!(blocking(topics::TF_STATIC.qos), latched);
        assert_eq!(blocking(topics::FALL_ALERT.qos), latched);
        let keep_all = QosProfile {
            history: History::KeepAll,
            ..QosProfile::reliable(1)
        };
        assert_eq!(blocking(keep_all), waits);
        // Readers and topics as before.
        assert_eq!(
            qos_policies(&QosProfile::reliable(10)).reliable_max_blocking_time(),
            waits
        );
    }

    /// A transient-local keep-last writer keeps its depth for late joiners: RustDDS kept
    /// every sample while no reader was matched (a late subscriber got 25 fall alerts of a
    /// depth of 10), unless ResourceLimits bound it. Other writers and readers get none.
    #[test]
    fn transient_local_writers_are_bounded_by_their_depth() {
        let limits = |qos: QosProfile| writer_qos_policies(&qos).resource_limits();
        let bound = |d| {
            Some(rustdds::policy::ResourceLimits {
                max_samples: d,
                max_instances: 1,
                max_samples_per_instance: d,
            })
        };
        assert_eq!(limits(topics::FALL_ALERT.qos), bound(10));
        assert_eq!(limits(topics::MAP.qos), bound(1));
        assert_eq!(limits(QosProfile::reliable(10)), None);
        assert_eq!(limits(QosProfile::sensor_data()), None);
        assert_eq!(
            qos_policies(&topics::FALL_ALERT.qos).resource_limits(),
            None
        );
        let history = writer_qos_policies(&topics::FALL_ALERT.qos).history();
        assert_eq!(
            history,
            Some(rustdds::policy::History::KeepLast { depth: 10 })
        );
    }

    #[test]
    fn rtps_time_converts_to_nanoseconds() {
        let t = Timestamp::from_ticks((5u64 << 32) | (1u64 << 31));
        assert_eq!(timestamp_ns(t), Some(5_500_000_000));
        assert_eq!(timestamp_ns(Timestamp::INVALID), None);
        assert_eq!(timestamp_ns(Timestamp::INFINITE), None);
    }

    #[test]
    fn a_history_deeper_than_dds_can_hold_is_its_deepest() {
        let qos = QosProfile {
            history: History::KeepLast(u32::MAX),
            ..QosProfile::reliable(1)
        };
        assert_eq!(
            qos_policies(&qos).history(),
            Some(rustdds::policy::History::KeepLast { depth: i32::MAX })
        );
    }
}
