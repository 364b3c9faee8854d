//! The `ros2 param` services of a node on the default backend (`get_parameters`,
//! `get_parameter_types`, `list_parameters`, `set_parameters`, `set_parameters_atomically`,
//! `describe_parameters`), answered from the node's start-up [`Parameters`].
//!
//! ros2-client 0.12 serves them from its `Node::spinner`, which also subscribes /clock with
//! the type `builtin_interfaces/msg/Time`: beside any ROS 2 /clock publisher
//! (`rosgraph_msgs/msg/Clock`: Gazebo, `ros2 bag play --clock`, our replay) the topic then had
//! two types, which `ros2 topic echo` refuses and `ros2 bag record` leaves out. So the nodes
//! run no spinner: the six servers are ros2-client's, created on the node (which announces
//! them in the graph), and a thread of ours answers them. They use the spinner's mapping,
//! `ServiceMapping::Enhanced` (rmw_fastrtps's, the default RMW: no header in the payload);
//! clients on rmw_cyclonedds frame requests otherwise and are not understood, as before.
//!
//! The nodes read their parameters once, at start-up, so every set is refused with the
//! restart that would apply it, and `describe` says `read_only: true`.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::thread::JoinHandle;

use ros2_client::dds::rustdds::mio1;
use ros2_client::parameters::raw;
use ros2_client::rcl_interfaces::{
    DescribeParametersRequest, DescribeParametersResponse, GetParameterTypesRequest,
    GetParameterTypesResponse, GetParametersRequest, GetParametersResponse, ListParametersRequest,
    ListParametersResponse, ListParametersResult, SetParametersAtomicallyResponse,
    SetParametersRequest, SetParametersResponse,
};
use ros2_client::{
    Message, Name, ParameterValue as Ros2Value, Server, ServiceMapping, ServiceTypeName,
};

use crate::RosError;
use crate::params::{ParamDecl, ParamValue, Parameters};

/// The parameters a node serves: start-up value and description of each, by name.
pub(crate) struct ServedParameters {
    params: BTreeMap<String, (ParamValue, String)>,
}

impl ServedParameters {
    /// `params`' values, described by `decls` (a name without a declaration gets none).
    pub(crate) fn new(params: &Parameters, decls: &[ParamDecl]) -> Self {
        let description = |name: &str| {
            decls
                .iter()
                .find(|d| d.name == name)
                .map_or_else(String::new, |d| d.description.clone())
        };
        Self {
            params: params
                .iter()
                .map(|(name, value)| (name.to_string(), (value.clone(), description(name))))
                .collect(),
        }
    }

    pub(crate) fn get(&self, name: &str) -> Option<&ParamValue> {
        self.params.get(name).map(|(value, _)| value)
    }

    /// As rclcpp: the values in the order asked, or none at all if a name is not declared.
    fn values(&self, names: &[String]) -> Vec<raw::ParameterValue> {
        names
            .iter()
            .map(|name| self.get(name).map(to_raw))
            .collect::<Option<Vec<_>>>()
            .unwrap_or_default()
    }

    /// As rclcpp: the `ParameterType` of each name, or none at all if a name is not declared
    /// (its service catches `ParameterNotDeclaredException` and answers an empty list).
    fn types(&self, names: &[String]) -> Vec<u8> {
        names
            .iter()
            .map(|name| self.get(name).map(|v| to_raw(v).ptype))
            .collect::<Option<Vec<_>>>()
            .unwrap_or_default()
    }

    /// As rclcpp's `list_parameters`: without prefixes every name with fewer than `depth`
    /// dots (`depth` 0: any number, what `ros2 param list` asks); else the names equal to a
    /// prefix or under `prefix.` with fewer than `depth` dots after it (Jazzy's rclcpp,
    /// ros2/rclcpp#2300: depth 1 is the prefix's children). `prefixes` of the result
    /// are the distinct namespaces (up to the last dot) of the names listed.
    fn list(&self, prefixes: &[String], depth: u64) -> ListParametersResult {
        let within_depth = |s: &str| depth == 0 || (s.matches('.').count() as u64) < depth;
        let mut result = ListParametersResult {
            names: Vec::new(),
            prefixes: Vec::new(),
        };
        for name in self.params.keys() {
            let all = prefixes.is_empty() && within_depth(name);
            let under_a_prefix = prefixes.iter().any(|prefix| {
                name == prefix
                    || name
                        .strip_prefix(prefix.as_str())
                        .and_then(|rest| rest.strip_prefix('.'))
                        .is_some_and(within_depth)
            });
            if all || under_a_prefix {
                result.names.push(name.clone());
                if let Some((namespace, _)) = name.rsplit_once('.')
                    && !result.prefixes.iter().any(|p| p == namespace)
                {
                    result.prefixes.push(namespace.to_string());
                }
            }
        }
        result
    }

    /// Why setting `param` is refused: every parameter is read at start-up.
    fn refusal(&self, param: &raw::Parameter) -> String {
        if self.get(&param.name).is_none() {
            // rclcpp's words for it.
            return format!(
                "parameter '{}' cannot be set because it was not declared",
                param.name
            );
        }
        read_only_reason(&param.name, &param.value)
    }

    /// One refusal per parameter, as `set_parameters` answers.
    fn set(&self, params: &[raw::Parameter]) -> Vec<raw::SetParametersResult> {
        params
            .iter()
            .map(|p| raw::SetParametersResult {
                successful: false,
                reason: self.refusal(p),
            })
            .collect()
    }

    /// One result for all, as `set_parameters_atomically` answers: refused, naming each.
    fn set_atomically(&self, params: &[raw::Parameter]) -> raw::SetParametersResult {
        raw::SetParametersResult {
            successful: params.is_empty(),
            reason: params
                .iter()
                .map(|p| self.refusal(p))
                .collect::<Vec<_>>()
                .join("; "),
        }
    }

    /// As rclcpp: the descriptors in the order asked, or none if a name is not declared.
    fn describe(&self, names: &[String]) -> Vec<raw::ParameterDescriptor> {
        names
            .iter()
            .map(|name| {
                let (value, description) = self.params.get(name)?;
                Some(raw::ParameterDescriptor {
                    name: name.clone(),
                    r#type: to_raw(value).ptype,
                    description: description.clone(),
                    additional_constraints: String::new(),
                    read_only: true,
                    dynamic_typing: false,
                    floating_point_range: Vec::new(),
                    integer_range: Vec::new(),
                })
            })
            .collect::<Option<Vec<_>>>()
            .unwrap_or_default()
    }
}

/// The reason a `ros2 param set NAME VALUE` is refused: the nodes read their parameters once,
/// at start-up (a set that succeeded used to change the value served and nothing else).
fn read_only_reason(name: &str, value: &raw::ParameterValue) -> String {
    let value = from_raw(value).map_or_else(|| "VALUE".into(), |v| v.to_string());
    format!(
        "read-only: {name} is read at start-up; restart the node with --ros-args -p {name}:={value}"
    )
}

fn to_raw(v: &ParamValue) -> raw::ParameterValue {
    raw::ParameterValue::from(match v.clone() {
        ParamValue::Bool(b) => Ros2Value::Boolean(b),
        ParamValue::Integer(i) => Ros2Value::Integer(i),
        ParamValue::Double(d) => Ros2Value::Double(d),
        ParamValue::String(s) => Ros2Value::String(s),
        ParamValue::BoolArray(v) => Ros2Value::BooleanArray(v),
        ParamValue::IntegerArray(v) => Ros2Value::IntegerArray(v),
        ParamValue::DoubleArray(v) => Ros2Value::DoubleArray(v),
        ParamValue::StringArray(v) => Ros2Value::StringArray(v),
    })
}

/// `None` for a value no node parameter can have (not set, a byte array).
fn from_raw(v: &raw::ParameterValue) -> Option<ParamValue> {
    Some(match Ros2Value::from(v.clone()) {
        Ros2Value::NotSet | Ros2Value::ByteArray(_) => return None,
        Ros2Value::Boolean(b) => ParamValue::Bool(b),
        Ros2Value::Integer(i) => ParamValue::Integer(i),
        Ros2Value::Double(d) => ParamValue::Double(d),
        Ros2Value::String(s) => ParamValue::String(s),
        Ros2Value::BooleanArray(v) => ParamValue::BoolArray(v),
        Ros2Value::IntegerArray(v) => ParamValue::IntegerArray(v),
        Ros2Value::DoubleArray(v) => ParamValue::DoubleArray(v),
        Ros2Value::StringArray(v) => ParamValue::StringArray(v),
    })
}

/// The six servers.
struct Servers {
    get: Server<GetParametersRequest, GetParametersResponse>,
    get_types: Server<GetParameterTypesRequest, GetParameterTypesResponse>,
    list: Server<ListParametersRequest, ListParametersResponse>,
    set: Server<SetParametersRequest, SetParametersResponse>,
    // SetParametersAtomically's request is a `Parameter[]` too, the same CDR.
    set_atomically: Server<SetParametersRequest, SetParametersAtomicallyResponse>,
    describe: Server<DescribeParametersRequest, DescribeParametersResponse>,
}

impl Servers {
    fn create(node: &mut ros2_client::Node) -> Result<Self, RosError> {
        let fqn = node.fully_qualified_name();
        Ok(Self {
            get: server(
                node,
                &format!("{fqn}/get_parameters"),
                &rcl("GetParameters"),
            )?,
            get_types: server(
                node,
                &format!("{fqn}/get_parameter_types"),
                &rcl("GetParameterTypes"),
            )?,
            list: server(
                node,
                &format!("{fqn}/list_parameters"),
                &rcl("ListParameters"),
            )?,
            set: server(
                node,
                &format!("{fqn}/set_parameters"),
                &rcl("SetParameters"),
            )?,
            set_atomically: server(
                node,
                &format!("{fqn}/set_parameters_atomically"),
                &rcl("SetParametersAtomically"),
            )?,
            describe: server(
                node,
                &format!("{fqn}/describe_parameters"),
                &rcl("DescribeParameters"),
            )?,
        })
    }

    fn register(&mut self, registry: &mio1::Registry, token: mio1::Token) -> std::io::Result<()> {
        use mio1::event::Source;
        let interest = mio1::Interest::READABLE;
        self.get.register(registry, token, interest)?;
        self.get_types.register(registry, token, interest)?;
        self.list.register(registry, token, interest)?;
        self.set.register(registry, token, interest)?;
        self.set_atomically.register(registry, token, interest)?;
        self.describe.register(registry, token, interest)
    }

    /// Answers every request that has come, on each service.
    fn answer(&self, served: &ServedParameters) {
        answer(&self.get, "get_parameters", |r| GetParametersResponse {
            values: served.values(&r.names),
        });
        answer(&self.get_types, "get_parameter_types", |r| {
            GetParameterTypesResponse {
                values: served.types(&r.names),
            }
        });
        answer(&self.list, "list_parameters", |r| ListParametersResponse {
            result: served.list(&r.prefixes, r.depth),
        });
        answer(&self.set, "set_parameters", |r| SetParametersResponse {
            results: served.set(&r.parameter),
        });
        answer(&self.set_atomically, "set_parameters_atomically", |r| {
            SetParametersAtomicallyResponse {
                result: served.set_atomically(&r.parameter),
            }
        });
        answer(&self.describe, "describe_parameters", |r| {
            DescribeParametersResponse {
                values: served.describe(&r.names),
            }
        });
    }
}

/// rclcpp's service QoS (`rmw_qos_profile_services_default`): reliable, volatile, keep 10.
fn service_qos() -> ros2_client::QosProfile {
    ros2_client::QosProfile::publisher_default()
        .durability(ros2_client::qos::Durability::Volatile)
        .history(ros2_client::qos::History::KeepLast { depth: 10 })
}

fn rcl(type_name: &str) -> ServiceTypeName {
    ServiceTypeName::new("rcl_interfaces", type_name)
}

/// A server of the absolute `service` on `node`, framed as rmw_fastrtps (ROS 2's default
/// RMW) frames requests and replies, with rclcpp's service QoS.
pub(crate) fn server<Req: Message + Clone + 'static, Resp: Message + 'static>(
    node: &mut ros2_client::Node,
    service: &str,
    service_type: &ServiceTypeName,
) -> Result<Server<Req, Resp>, RosError> {
    let name = Name::parse(service).map_err(|e| RosError::Name {
        name: service.into(),
        reason: format!("{e:?}"),
    })?;
    node.create_server(
        ServiceMapping::Enhanced,
        &name,
        service_type,
        service_qos(),
        service_qos(),
    )
    .map_err(|e| RosError::Service {
        service: service.into(),
        reason: e.to_string(),
    })
}

/// Answers the requests `server` has, each with `respond`'s response.
fn answer<Req: Message + 'static, Resp: Message + 'static>(
    server: &Server<Req, Resp>,
    service: &str,
    respond: impl Fn(Req) -> Resp,
) {
    loop {
        match server.receive_request() {
            Ok(Some((id, request))) => {
                if let Err(e) = server.send_response(id, respond(request)) {
                    log::warn!("{service}: the response could not be sent: {e:?}");
                }
            }
            Ok(None) => return,
            // The request is consumed either way (RustDDS moves its read position on).
            Err(e) => log::warn!("{service}: a request that cannot be read: {e:?}"),
        }
    }
}

const REQUEST: mio1::Token = mio1::Token(0);
const STOP: mio1::Token = mio1::Token(1);

/// The thread answering the services. Dropped before the node's participant, it stops the
/// thread and waits for it, so that the servers' readers and writers go first (dropped after
/// the participant had stopped, each was an ERROR line of the DDS stack).
pub(crate) struct ParameterServices {
    stop: mio1::Waker,
    thread: Option<JoinHandle<()>>,
}

impl ParameterServices {
    /// Creates the services on `node` and starts answering them from `served`.
    pub(crate) fn start(
        node: &mut ros2_client::Node,
        served: Arc<ServedParameters>,
    ) -> Result<Self, RosError> {
        let dds = |e: std::io::Error| RosError::Dds(format!("parameter services: {e}"));
        let mut servers = Servers::create(node)?;
        let mut poll = mio1::Poll::new().map_err(dds)?;
        servers.register(poll.registry(), REQUEST).map_err(dds)?;
        let stop = mio1::Waker::new(poll.registry(), STOP).map_err(dds)?;
        let thread = std::thread::Builder::new()
            .name("ros2-param".into())
            .spawn(move || serve(&mut poll, &servers, &served))
            .map_err(dds)?;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }
}

fn serve(poll: &mut mio1::Poll, servers: &Servers, served: &ServedParameters) {
    let mut events = mio1::Events::with_capacity(16);
    loop {
        // Requests that came before the servers were registered raise no event.
        servers.answer(served);
        match poll.poll(&mut events, None) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => {
                log::warn!("parameter services stopped: {e}");
                return;
            }
        }
        if events.iter().any(|event| event.token() == STOP) {
            return;
        }
    }
}

impl Drop for ParameterServices {
    fn drop(&mut self) {
        if let Err(e) = self.stop.wake() {
            log::warn!("parameter services: cannot stop them: {e}");
            return;
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn served() -> ServedParameters {
        let decls = [
            ParamDecl::new("rate", ParamValue::Double(1.0), "playback speed"),
            ParamDecl::new("topics", ParamValue::StringArray(vec![]), "topics"),
            ParamDecl::new("qos.depth", ParamValue::Integer(5), "queue"),
            ParamDecl::new("qos.deep.x", ParamValue::Bool(true), "deep"),
        ];
        let decls = crate::params::node_parameters(decls.to_vec());
        let params = Parameters::resolve(
            &decls,
            "/replay",
            &[],
            &[("rate".into(), ParamValue::Double(2.0))],
        )
        .unwrap();
        ServedParameters::new(&params, &decls)
    }

    fn strings(names: &[&str]) -> Vec<String> {
        names.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn list_answers_as_rclcpp_does() {
        let p = served();
        // `ros2 param list`: no prefixes, depth 0 (recursive).
        let all = p.list(&[], 0);
        let everything = ["qos.deep.x", "qos.depth", "rate", "topics", "use_sim_time"];
        assert_eq!(all.names, everything);
        assert_eq!(all.prefixes, ["qos.deep", "qos"]);
        assert_eq!(p.list(&[], 1).names, ["rate", "topics", "use_sim_time"]);
        let qos = strings(&["qos"]);
        assert_eq!(p.list(&qos, 0).names, ["qos.deep.x", "qos.depth"]);
        // Depth counts from the prefix (rclcpp since ros2/rclcpp#2300, Jazzy): depth 1 is the
        // prefix's children; Humble's counted the dot after the prefix too.
        assert_eq!(p.list(&qos, 1).names, ["qos.depth"]);
        assert_eq!(p.list(&qos, 2).names, ["qos.deep.x", "qos.depth"]);
        // A prefix matches whole dotted levels only.
        assert_eq!(p.list(&strings(&["qo"]), 0).names, Vec::<String>::new());
        assert_eq!(p.list(&strings(&["rate"]), 0).names, ["rate"]);
    }

    #[test]
    fn get_serves_start_up_values_and_nothing_for_an_undeclared_name() {
        let p = served();
        let values = p.values(&strings(&["rate", "topics"]));
        assert_eq!(values[0].ptype, raw::ParameterType::DOUBLE);
        assert_eq!(values[0].double_value, 2.0);
        assert_eq!(values[1].ptype, raw::ParameterType::STRING_ARRAY);
        assert!(p.values(&strings(&["rate", "nope"])).is_empty());
        assert_eq!(
            p.types(&strings(&["qos.depth", "rate"])),
            [raw::ParameterType::INTEGER, raw::ParameterType::DOUBLE]
        );
        assert!(p.types(&strings(&["qos.depth", "nope"])).is_empty());
    }

    #[test]
    fn describe_says_read_only_with_the_declared_description() {
        let d = served().describe(&strings(&["rate"]));
        assert_eq!(d.len(), 1);
        assert!(d[0].read_only, "the spinner said read_only: false");
        assert_eq!(d[0].description, "playback speed");
        assert_eq!(d[0].r#type, raw::ParameterType::DOUBLE);
        assert!(served().describe(&strings(&["nope"])).is_empty());
    }

    #[test]
    fn ros2_param_set_is_refused_naming_the_restart_that_would_apply_it() {
        let p = served();
        let param = |name: &str, value: Ros2Value| raw::Parameter {
            name: name.into(),
            value: value.into(),
        };
        let results = p.set(&[
            param("rate", Ros2Value::Double(2.5)),
            param("topics", Ros2Value::StringArray(strings(&["/scan"]))),
            // The spinner let a set of use_sim_time through.
            param("use_sim_time", Ros2Value::Boolean(true)),
            param("nope", Ros2Value::Integer(1)),
        ]);
        assert!(results.iter().all(|r| !r.successful));
        assert_eq!(
            results[0].reason,
            "read-only: rate is read at start-up; restart the node with --ros-args -p rate:=2.5"
        );
        assert!(
            results[1].reason.ends_with(r#"-p topics:=["/scan"]"#),
            "{}",
            results[1].reason
        );
        assert!(results[2].reason.starts_with("read-only: use_sim_time"));
        assert_eq!(
            results[3].reason,
            "parameter 'nope' cannot be set because it was not declared"
        );
        let atomic = p.set_atomically(&[param("rate", Ros2Value::Double(3.0))]);
        assert!(!atomic.successful);
        assert!(atomic.reason.ends_with("-p rate:=3"), "{}", atomic.reason);
    }
}
