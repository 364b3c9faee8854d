//! ROS 2 command-line arguments (`--ros-args ... [--]`), parsed the way rcl parses them, and
//! ROS name resolution with remapping. ros2-client does neither, so the nodes do it here.

use std::path::PathBuf;

use crate::RosError;
use crate::params::{CLI_SECTION, GivenValue, ParamSource, section_applies};

/// What `--ros-args` sections of a command line say.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RosArgs {
    /// `-r [node:]from:=to` topic remappings, in order (first match wins, as in rcl).
    pub remaps: Vec<Remap>,
    /// The rules that apply to service names: those without `rostopic://`, in order.
    pub service_remaps: Vec<Remap>,
    /// `-r [node:]__node:=name` (or `__name:=`), in order; see [`RosArgs::node_name`].
    pub node_names: Vec<NodeRule>,
    /// `-r [node:]__ns:=/namespace`, in order; see [`RosArgs::namespace`].
    pub namespaces: Vec<NodeRule>,
    /// `-p [node:]name:=value` and `--params-file FILE`, in command-line order, the order rcl
    /// merges them in; see [`RosArgs::params_for`].
    pub params: Vec<ParamArg>,
    /// Arguments outside `--ros-args` sections (the program's own).
    pub rest: Vec<String>,
    /// `--disable-rosout-logs` (the last of it and `--enable-rosout-logs` wins, as in rcl):
    /// the node's log records are not published on /rosout.
    pub disable_rosout_logs: bool,
    /// `--log-level [logger:=]severity`, in order; see [`RosArgs::log_level_for`].
    pub log_levels: Vec<LogLevelRule>,
}

/// A `--log-level` rule: the severity of one logger (`localiser:=debug`), or of every logger
/// without a rule of its own (`debug`).
#[derive(Debug, Clone, PartialEq)]
pub struct LogLevelRule {
    pub logger: Option<String>,
    pub severity: Severity,
}

/// rcutils' log severities, as `--log-level` names them (in any case).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Severity {
    Unset,
    Debug,
    Info,
    Warn,
    Error,
    Fatal,
}

impl std::str::FromStr for Severity {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "unset" => Ok(Self::Unset),
            "debug" => Ok(Self::Debug),
            "info" => Ok(Self::Info),
            "warn" => Ok(Self::Warn),
            "error" => Ok(Self::Error),
            "fatal" => Ok(Self::Fatal),
            _ => Err(format!(
                "unknown severity `{s}` (expected debug, info, warn, error, fatal or unset)"
            )),
        }
    }
}

/// One `-r` remapping rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Remap {
    /// Applies only to the node of this name (`node:from:=to`), or to every node.
    pub node: Option<String>,
    pub from: String,
    pub to: String,
}

/// A `-r __node:=` or `-r __ns:=` rule: the node's new name or namespace.
#[derive(Debug, Clone, PartialEq)]
pub struct NodeRule {
    /// Applies only to the node of this name (`node:__node:=...`), or to every node.
    pub node: Option<String>,
    pub to: String,
}

/// A `-p` or `--params-file` argument.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamArg {
    Override(ParamOverride),
    File(PathBuf),
}

/// One `-p` parameter override.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamOverride {
    /// Applies only to the node of this name (`node:name:=value`), or to every node.
    pub node: Option<String>,
    pub name: String,
    pub value: GivenValue,
}

/// A command line as text: an argument that is not UTF-8 (a path in another encoding) is an
/// error naming it, where `std::env::args` would panic.
pub fn utf8_args(
    args: impl IntoIterator<Item = std::ffi::OsString>,
) -> Result<Vec<String>, RosError> {
    args.into_iter()
        .map(|arg| {
            arg.into_string().map_err(|arg| {
                RosError::Args(format!(
                    "`{}`: not UTF-8, which ROS arguments must be",
                    arg.to_string_lossy()
                ))
            })
        })
        .collect()
}

impl RosArgs {
    /// Parses a command line without the program name.
    pub fn parse<I, S>(args: I) -> Result<Self, RosError>
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        let mut out = Self::default();
        let mut args = args.into_iter().map(Into::into);
        let bad = |arg: &str, reason: &str| RosError::Args(format!("`{arg}`: {reason}"));
        while let Some(arg) = args.next() {
            if arg != "--ros-args" {
                out.rest.push(arg);
                continue;
            }
            while let Some(flag) = args.next() {
                let mut value = |what: &str| {
                    args.next()
                        .ok_or_else(|| bad(&flag, &format!("needs {what}")))
                };
                match flag.as_str() {
                    "--" => break,
                    "--ros-args" => {}
                    "-r" | "--remap" => {
                        let rule = value("a remapping `from:=to`")?;
                        out.add_remap(&rule)?;
                    }
                    "-p" | "--param" => {
                        let rule = value("`name:=value`")?;
                        out.params.push(ParamArg::Override(parse_param(&rule)?));
                    }
                    "--params-file" => out
                        .params
                        .push(ParamArg::File(PathBuf::from(value("a file")?))),
                    "--log-level" => {
                        let rule = value("a severity, or `logger:=severity`")?;
                        out.log_levels.push(parse_log_level(&rule)?);
                    }
                    // Accepted and ignored: logging and security settings of rcl. The nodes
                    // log to stderr and /rosout, so Jazzy's `--log-file-name` names nothing
                    // here.
                    "--log-config-file" | "--log-file-name" | "-e" | "--enclave" => {
                        value("a value")?;
                    }
                    "--enable-rosout-logs" => out.disable_rosout_logs = false,
                    "--disable-rosout-logs" => out.disable_rosout_logs = true,
                    "--enable-stdout-logs"
                    | "--disable-stdout-logs"
                    | "--enable-external-lib-logs"
                    | "--disable-external-lib-logs" => {}
                    other => return Err(bad(other, "unknown ROS argument")),
                }
            }
        }
        Ok(out)
    }

    fn add_remap(&mut self, rule: &str) -> Result<(), RosError> {
        let bad = |reason: &str| RosError::Args(format!("remapping `{rule}`: {reason}"));
        let (lhs, to) = rule
            .split_once(":=")
            .ok_or_else(|| bad("must be `from:=to`"))?;
        let (node, from) = split_remap_node_prefix(lhs).map_err(|e| bad(&e))?;
        // rcl's `rostopic://` and `rosservice://` restrict a rule to topics or to services;
        // the rest of the match side is a name as in a rule without them.
        let (kind, from) = match (from.strip_prefix(TOPIC_URL), from.strip_prefix(SERVICE_URL)) {
            (Some(name), _) => (Some(RuleKind::Topic), name),
            (_, Some(name)) => (Some(RuleKind::Service), name),
            (None, None) => (None, from),
        };
        if from.is_empty() || to.is_empty() {
            return Err(bad("both sides must be non-empty"));
        }
        let node = node.map(String::from);
        let to = to.to_string();
        let special = matches!(from, "__node" | "__name" | "__ns");
        if special && kind.is_some() {
            // rcl expects a name after the URL scheme, and `__node` is none.
            return Err(bad(&format!(
                "`{from}` is not a topic or service name (`{from}:=...` takes no \
                 rostopic:// or rosservice://)"
            )));
        }
        let topic_rule = !special;
        if topic_rule {
            // rcl parses both sides of a topic rule when it parses the arguments: a name the
            // middleware would refuse fails here, as a bad argument, before any DDS traffic.
            validate_topic_name(from).map_err(|e| bad(&e))?;
            validate_topic_name(&to).map_err(|e| bad(&e))?;
        }
        match from {
            "__node" | "__name" => {
                validate_node_name(&to).map_err(|e| bad(&e))?;
                self.node_names.push(NodeRule { node, to });
            }
            "__ns" => {
                validate_namespace(&to).map_err(|e| bad(&e))?;
                self.namespaces.push(NodeRule { node, to });
            }
            _ => {
                let rule = Remap {
                    node,
                    from: from.to_string(),
                    to,
                };
                if kind != Some(RuleKind::Topic) {
                    self.service_remaps.push(rule.clone());
                }
                if kind != Some(RuleKind::Service) {
                    self.remaps.push(rule);
                }
            }
        }
        Ok(())
    }

    /// The name of the node whose code names it `name`: the first `__node` rule for it, else
    /// `name`. As in rcl, a rule's `node:` prefix is compared with the name in the code.
    pub fn node_name<'a>(&'a self, name: &'a str) -> &'a str {
        first_rule_for(&self.node_names, name).unwrap_or(name)
    }

    /// The namespace of the node named `name` (its name after [`RosArgs::node_name`]): the
    /// first `__ns` rule for it, else `default`. rcl compares a `__ns` rule's `node:` prefix
    /// with the name after the `__node` rules (`rcl_node_init`), so does this.
    pub fn namespace<'a>(&'a self, name: &str, default: &'a str) -> &'a str {
        first_rule_for(&self.namespaces, name).unwrap_or(default)
    }

    /// The severity `--log-level` sets for the logger `logger` (a node's is its name,
    /// prefixed by its namespace with dots: `robot1.localiser`), as rcutils resolves it: the
    /// last rule naming the logger, else the nearest ancestor's (`robot1` for
    /// `robot1.localiser`), else the last without a name; a rule of `unset` passes to the
    /// next.
    pub fn log_level_for(&self, logger: &str) -> Option<Severity> {
        let last_rule = |name: Option<&str>| {
            self.log_levels
                .iter()
                .rev()
                .find(|rule| rule.logger.as_deref() == name)
                .map(|rule| rule.severity)
                .filter(|severity| *severity != Severity::Unset)
        };
        let mut name = Some(logger);
        while let Some(current) = name {
            if let Some(severity) = last_rule(Some(current)) {
                return Some(severity);
            }
            name = current.rsplit_once('.').map(|(parent, _)| parent);
        }
        last_rule(None)
    }

    /// The parameter files and the `-p` overrides for the node `node_fqn` (`/ns/name`), in
    /// command-line order: every file, the overrides without a node prefix, and those whose
    /// prefix names it. rcl keeps `node:name:=value` as a parameter of the node `node`, which
    /// rclcpp matches with the fully qualified name like a parameter file's section:
    /// `localiser:` is `/localiser`, not `/robot1/localiser`.
    pub fn params_for(&self, node_fqn: &str) -> Vec<ParamSource> {
        self.params
            .iter()
            .filter_map(|arg| match arg {
                ParamArg::File(path) => Some(ParamSource::File(path.clone())),
                ParamArg::Override(p) => {
                    let section = p.node.as_deref().unwrap_or(CLI_SECTION);
                    section_applies(section, node_fqn).then(|| ParamSource::Value {
                        section: section.to_string(),
                        name: p.name.clone(),
                        value: p.value.clone(),
                    })
                }
            })
            .collect()
    }
}

fn first_rule_for<'a>(rules: &'a [NodeRule], node_name: &str) -> Option<&'a str> {
    rules
        .iter()
        .find(|r| r.node.as_deref().is_none_or(|n| n == node_name))
        .map(|r| r.to.as_str())
}

/// `[node:]name:=value` of `-p`, the value typed as rcl types it.
/// `severity` or `logger:=severity`, as rcl reads `--log-level`.
fn parse_log_level(rule: &str) -> Result<LogLevelRule, RosError> {
    let bad = |reason: String| RosError::Args(format!("--log-level `{rule}`: {reason}"));
    let (logger, severity) = match rule.split_once(":=") {
        Some(("", _)) => return Err(bad("empty logger name".into())),
        Some((logger, severity)) => (Some(logger.to_string()), severity),
        None => (None, rule),
    };
    Ok(LogLevelRule {
        logger,
        severity: severity.parse().map_err(bad)?,
    })
}

fn parse_param(rule: &str) -> Result<ParamOverride, RosError> {
    let bad = |reason: &str| RosError::Args(format!("`{rule}`: {reason}"));
    let (lhs, text) = rule
        .split_once(":=")
        .ok_or_else(|| bad("a parameter must be `name:=value`"))?;
    let (node, name) = split_node_prefix(lhs).map_err(|e| bad(&e))?;
    if name.is_empty() {
        return Err(bad("empty parameter name"));
    }
    if name.contains(':') {
        return Err(bad(
            "a parameter name cannot contain ':' (one `node:` prefix at most)",
        ));
    }
    let value = GivenValue::parse_cli(text).map_err(|reason| RosError::Parameter {
        name: name.to_string(),
        reason,
    })?;
    Ok(ParamOverride {
        node: node.map(String::from),
        name: name.to_string(),
        value,
    })
}

/// Splits the `node:` prefix off the left side of a `-r` or `-p` rule. rcl takes one name
/// token before the first ':' as the node the rule is for; one that is no valid node name
/// could never match, so it is refused here.
fn split_node_prefix(lhs: &str) -> Result<(Option<&str>, &str), String> {
    match lhs.split_once(':') {
        Some((node, rest)) => {
            validate_node_name(node).map_err(|e| format!("node prefix: {e}"))?;
            Ok((Some(node), rest))
        }
        None => Ok((None, lhs)),
    }
}

/// The URL schemes rcl's lexer reads at the start of a rule's match side.
const TOPIC_URL: &str = "rostopic://";
const SERVICE_URL: &str = "rosservice://";

/// What a `rostopic://` or `rosservice://` rule is restricted to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RuleKind {
    Topic,
    Service,
}

/// [`split_node_prefix`] for a `-r` rule, whose match side may begin with `rostopic://` or
/// `rosservice://` (after the node prefix, if any): rcl reads either as one lexeme, so their
/// ':' is no node prefix's (`rostopic://scan:=/r1/scan`, `localiser:rostopic://scan:=x`).
fn split_remap_node_prefix(lhs: &str) -> Result<(Option<&str>, &str), String> {
    if lhs.starts_with(TOPIC_URL) || lhs.starts_with(SERVICE_URL) {
        return Ok((None, lhs));
    }
    split_node_prefix(lhs)
}

/// rmw's longest node name (`RMW_NODE_NAME_MAX_NAME_LENGTH`).
const NODE_NAME_MAX_LEN: usize = 255;

/// Checks a node name by rmw's rules (`rmw_validate_node_name`): letters, digits and '_',
/// not starting with a digit, at most 255 characters; and without `__` (see
/// [`validate_token`]). The middleware refuses any other name
/// only once the node is being created; checking it with the arguments refuses it as a bad
/// argument, before any DDS traffic.
pub fn validate_node_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("a node name must not be empty".into());
    }
    validate_token(name).map_err(|e| format!("node name `{name}` {e}"))?;
    if name.len() > NODE_NAME_MAX_LEN {
        return Err(format!(
            "node name `{name}` is longer than {NODE_NAME_MAX_LEN} characters"
        ));
    }
    Ok(())
}

/// Checks a namespace by rmw's rules (`rmw_validate_namespace`): absolute, tokens as node
/// names (letters, digits and '_', not starting with a digit, no `__`) between single '/',
/// and no trailing '/' except for the root namespace `/`.
pub fn validate_namespace(namespace: &str) -> Result<(), String> {
    let bad = |e: &str| Err(format!("namespace `{namespace}` {e}"));
    let Some(tokens) = namespace.strip_prefix('/') else {
        return bad("must be absolute (start with '/')");
    };
    if tokens.is_empty() {
        return Ok(());
    }
    if tokens.ends_with('/') {
        return bad("must not end with '/' (only the root namespace `/` does)");
    }
    validate_tokens(tokens).or_else(|e| bad(&e))
}

/// Checks a topic name as rcl parses one side of a `-r` rule (and rmw validates a topic
/// name): relative, absolute (`/...`) or private (`~/...`), then name tokens (see
/// [`validate_node_name`]) between single '/', without a trailing '/'. rcl has no wildcards
/// or back-references in rules yet, and neither does this.
pub fn validate_topic_name(name: &str) -> Result<(), String> {
    let bad = |e: &str| Err(format!("topic name `{name}` {e}"));
    let tokens = name
        .strip_prefix("~/")
        .or_else(|| name.strip_prefix('/'))
        .unwrap_or(name);
    if tokens.is_empty() {
        return bad("has no name token");
    }
    if tokens.ends_with('/') {
        return bad("must not end with '/'");
    }
    validate_tokens(tokens).or_else(|e| bad(&e))
}

/// The name tokens of a namespace or topic name, between single '/'.
fn validate_tokens(tokens: &str) -> Result<(), String> {
    for token in tokens.split('/') {
        if token.is_empty() {
            return Err("must not contain `//` (an empty token)".into());
        }
        validate_token(token).map_err(|e| format!("has a token `{token}` that {e}"))?;
    }
    Ok(())
}

/// A name token of a node name, namespace or topic: rmw's rules (see [`validate_rmw_token`])
/// and no `__`. rcl's remapping rules cannot hold one (its lexer reads no name token with
/// `__` in it), and ros2-client refuses such names: its parameter services, named after the
/// node, panicked on a node name with `__` once DDS had started.
fn validate_token(token: &str) -> Result<(), String> {
    validate_rmw_token(token)?;
    if token.contains("__") {
        return Err("contains `__`, which rcl's remapping rules and ros2-client refuse".into());
    }
    Ok(())
}

/// A name token of rmw: only letters, digits and '_', not starting with a digit. Parameter
/// file sections are checked by this alone, as rcl checks them: a section with `__` is valid
/// there (for nodes of other client libraries), it just matches none of ours.
pub(crate) fn validate_rmw_token(token: &str) -> Result<(), String> {
    if let Some(c) = token
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_'))
    {
        return Err(format!(
            "contains {c:?}: only letters, digits and '_' are allowed"
        ));
    }
    if token.starts_with(|c: char| c.is_ascii_digit()) {
        return Err("starts with a digit".into());
    }
    Ok(())
}

/// Expands a topic name to a fully qualified one: relative names go into `namespace`, `~` is
/// the node's own name.
pub fn expand_name(name: &str, namespace: &str, node_name: &str) -> String {
    let ns = namespace.trim_end_matches('/');
    if let Some(rest) = name.strip_prefix('~') {
        format!("{ns}/{node_name}{rest}")
    } else if name.starts_with('/') {
        name.to_string()
    } else {
        format!("{ns}/{name}")
    }
}

/// Applies the first matching remap rule to the expanded topic or service `name`.
pub fn resolve_name(name: &str, remaps: &[Remap], namespace: &str, node_name: &str) -> String {
    let expanded = expand_name(name, namespace, node_name);
    remaps
        .iter()
        .filter(|r| r.node.as_deref().is_none_or(|n| n == node_name))
        .find(|r| expand_name(&r.from, namespace, node_name) == expanded)
        .map(|r| expand_name(&r.to, namespace, node_name))
        .unwrap_or(expanded)
}

/// `ROS_DOMAIN_ID` as a DDS domain: unset or empty means 0; otherwise 0..=232 (the largest
/// domain whose ports fit in 16 bits with the default port mapping).
pub fn domain_id_from_env() -> Result<u16, RosError> {
    parse_domain_id(std::env::var("ROS_DOMAIN_ID").ok().as_deref())
}

fn parse_domain_id(value: Option<&str>) -> Result<u16, RosError> {
    match value.map(str::trim) {
        None | Some("") => Ok(0),
        Some(text) => match text.parse::<u16>() {
            Ok(id) if id <= 232 => Ok(id),
            _ => Err(RosError::Args(format!(
                "ROS_DOMAIN_ID `{text}` is not a domain id (an integer 0..=232)"
            ))),
        },
    }
}

/// How far a node looks for others, as rcl reads it from the environment (Jazzy).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DiscoveryRange {
    /// No discovery at all, not even on this machine.
    Off,
    /// Only nodes on this machine: DDS traffic through the loopback interface alone.
    Localhost,
    /// Whatever multicast reaches (the default, and `SYSTEM_DEFAULT`): every interface.
    Subnet,
}

/// The discovery range from `ROS_LOCALHOST_ONLY` and `ROS_AUTOMATIC_DISCOVERY_RANGE`.
pub fn discovery_range_from_env() -> Result<DiscoveryRange, RosError> {
    let var = |name| std::env::var(name).ok();
    parse_discovery_range(
        var("ROS_LOCALHOST_ONLY").as_deref(),
        var("ROS_AUTOMATIC_DISCOVERY_RANGE").as_deref(),
    )
}

/// As rcl does: `ROS_LOCALHOST_ONLY=1` (Humble's switch, deprecated since Jazzy) wins over the
/// range, and any other value of it leaves the range to decide; an unknown range is an error.
fn parse_discovery_range(
    localhost_only: Option<&str>,
    range: Option<&str>,
) -> Result<DiscoveryRange, RosError> {
    if localhost_only == Some("1") {
        return Ok(DiscoveryRange::Localhost);
    }
    match range.unwrap_or("") {
        "" | "SUBNET" | "SYSTEM_DEFAULT" => Ok(DiscoveryRange::Subnet),
        "LOCALHOST" => Ok(DiscoveryRange::Localhost),
        "OFF" => Ok(DiscoveryRange::Off),
        other => Err(RosError::Args(format!(
            "ROS_AUTOMATIC_DISCOVERY_RANGE `{other}` is not a discovery range \
             (OFF, LOCALHOST, SUBNET or SYSTEM_DEFAULT)"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ParamValue;

    #[test]
    fn an_argument_that_is_not_utf8_is_an_error_naming_it() {
        use std::os::unix::ffi::OsStringExt;
        let line = |bag: Vec<u8>| {
            utf8_args([
                "--ros-args".into(),
                "-p".into(),
                std::ffi::OsString::from_vec(bag),
            ])
        };
        assert_eq!(
            line(b"bag:=/data".to_vec()).unwrap(),
            ["--ros-args", "-p", "bag:=/data"]
        );
        let err = line(b"bag:=caf\xe9".to_vec()).unwrap_err().to_string();
        assert!(err.contains("`bag:=caf\u{fffd}`: not UTF-8"), "{err}");
    }

    #[test]
    fn parses_remaps_node_ns_params_and_files() {
        let a = RosArgs::parse([
            "--bag",
            "x",
            "--ros-args",
            "-r",
            "scan:=/robot/scan",
            "-r",
            "__node:=loc2",
            "-r",
            "__ns:=/r1",
            "-p",
            "rate:=2.5",
            "--params-file",
            "p.yaml",
            "--log-level",
            "debug",
            "--log-file-name",
            "replay_log",
            "--",
            "tail",
        ])
        .unwrap();
        assert_eq!(a.rest, vec!["--bag", "x", "tail"]);
        assert_eq!(
            a.remaps,
            vec![Remap {
                node: None,
                from: "scan".into(),
                to: "/robot/scan".into()
            }]
        );
        assert_eq!(a.node_name("replay"), "loc2");
        assert_eq!(a.namespace("loc2", "/"), "/r1");
        assert_eq!(
            a.params_for("/r1/loc2"),
            vec![
                ParamSource::value("rate", ParamValue::Double(2.5)),
                ParamSource::File("p.yaml".into())
            ]
        );
    }

    /// `--log-level` was accepted and ignored: a launch file asking a node for debug output
    /// got the default.
    #[test]
    fn log_levels_apply_as_rcl_applies_them() {
        let parse = |args: &[&str]| RosArgs::parse(args.iter().copied()).unwrap();
        assert_eq!(parse(&["--ros-args"]).log_level_for("localiser"), None);
        let bare = parse(&["--ros-args", "--log-level", "DEBUG"]);
        assert_eq!(bare.log_level_for("localiser"), Some(Severity::Debug));
        let named = parse(&[
            "--ros-args",
            "--log-level",
            "localiser:=error",
            "--log-level",
            "warn",
            "--log-level",
            "classifier:=debug",
        ]);
        assert_eq!(named.log_level_for("localiser"), Some(Severity::Error));
        assert_eq!(named.log_level_for("classifier"), Some(Severity::Debug));
        assert_eq!(named.log_level_for("replay"), Some(Severity::Warn));
        let unset = parse(&["--ros-args", "--log-level", "info", "--log-level", "unset"]);
        assert_eq!(unset.log_level_for("replay"), None);
        // rcutils: a logger without a level of its own takes its nearest ancestor's, and an
        // `unset` logger level passes to it.
        let tree = parse(&[
            "--ros-args",
            "--log-level",
            "debug",
            "--log-level",
            "robot1:=warn",
            "--log-level",
            "robot1.replay:=unset",
            "--log-level",
            "localiser:=unset",
        ]);
        assert_eq!(tree.log_level_for("robot1.replay"), Some(Severity::Warn));
        assert_eq!(tree.log_level_for("robot1.a.b"), Some(Severity::Warn));
        assert_eq!(tree.log_level_for("localiser"), Some(Severity::Debug));
        assert_eq!(tree.log_level_for("robot10.replay"), Some(Severity::Debug));
        for bad in ["loud", "localiser:=", ":=debug"] {
            let err = RosArgs::parse(["--ros-args", "--log-level", bad]).unwrap_err();
            assert!(
                err.to_string().contains(&format!("--log-level `{bad}`")),
                "{err}"
            );
        }
    }

    #[test]
    fn rosout_logs_follow_the_last_switch() {
        let parse = |args: &[&str]| RosArgs::parse(args.iter().copied()).unwrap();
        assert!(!parse(&["--ros-args"]).disable_rosout_logs);
        assert!(parse(&["--ros-args", "--disable-rosout-logs"]).disable_rosout_logs);
        let both = [
            "--ros-args",
            "--disable-rosout-logs",
            "--enable-rosout-logs",
        ];
        assert!(!parse(&both).disable_rosout_logs);
    }

    /// rcl applies `-p` and `--params-file` in command-line order; `-p` used to win always.
    #[test]
    fn params_and_files_keep_their_command_line_order() {
        let a = RosArgs::parse([
            "--ros-args",
            "--params-file",
            "a.yaml",
            "-p",
            "rate:=2",
            "--params-file",
            "b.yaml",
            "-p",
            "other:rate:=3",
        ])
        .unwrap();
        assert_eq!(
            a.params_for("/replay"),
            vec![
                ParamSource::File("a.yaml".into()),
                ParamSource::value("rate", ParamValue::Integer(2)),
                ParamSource::File("b.yaml".into()),
            ]
        );
    }

    #[test]
    fn node_prefixed_rules_apply_to_their_node_only() {
        let a = RosArgs::parse([
            "--ros-args",
            "-p",
            "localiser:moving:=false",
            "-p",
            "rate:=2",
            "-p",
            "replay:rate:=3",
            "-r",
            "localiser:__node:=loc2",
            "-r",
            "__node:=first",
            "-r",
            "__node:=second",
            "-r",
            "localiser:__ns:=/not_after_rename",
            "-r",
            "loc2:__ns:=/r1",
            "-r",
            "classifier:__ns:=/c",
        ])
        .unwrap();
        // `__node`: the first rule for the name in the code; `__ns`: the first for the name
        // after `__node` (rcl_node_init).
        assert_eq!(a.node_name("localiser"), "loc2");
        assert_eq!(a.node_name("classifier"), "first");
        assert_eq!(a.namespace("loc2", "/"), "/r1");
        assert_eq!(a.namespace("first", "/"), "/");
        assert_eq!(a.namespace("classifier", "/x"), "/c");
        let rate = |section: &str, v| ParamSource::Value {
            section: section.into(),
            name: "rate".into(),
            value: ParamValue::Integer(v).into(),
        };
        let moving = ParamSource::Value {
            section: "localiser".into(),
            name: "moving".into(),
            value: ParamValue::Bool(false).into(),
        };
        assert_eq!(a.params_for("/localiser"), vec![moving, rate("/**", 2)]);
        // A `node:` prefix is matched with the whole name, as a parameter file's section.
        assert_eq!(a.params_for("/r1/localiser"), vec![rate("/**", 2)]);
        assert_eq!(
            a.params_for("/replay"),
            vec![rate("/**", 2), rate("replay", 3)]
        );
    }

    #[test]
    fn bad_node_names_and_namespaces_are_argument_errors() {
        let long = format!("__node:={}", "n".repeat(256));
        for (rule, needle) in [
            ("__node:=bad-name", "'-'"),
            ("__node:=1node", "digit"),
            (long.as_str(), "255"),
            ("__ns:=/robot-1", "'-'"),
            ("__ns:=/robot1/", "end with '/'"),
            ("__ns:=/1robot", "digit"),
            ("__ns:=/a//b", "//"),
            ("bad-node:scan:=x", "node prefix"),
            // ros2-client refused these only once DDS had started: a panic, status 101.
            ("__node:=a__b", "`__`"),
            ("__ns:=/a__b", "`__`"),
            ("__ns:=/r1/__x", "`__`"),
            ("a__b:scan:=x", "`__`"),
        ] {
            let err = RosArgs::parse(["--ros-args", "-r", rule]).unwrap_err();
            let text = err.to_string();
            assert!(
                matches!(err, RosError::Args(_)) && text.contains(rule) && text.contains(needle),
                "{rule}: {text}"
            );
        }
        for rule in ["bad-node:rate:=1", "a:b:rate:=1", "a__b:rate:=1"] {
            let err = RosArgs::parse(["--ros-args", "-p", rule]).unwrap_err();
            assert!(matches!(err, RosError::Args(_)), "{rule}: {err}");
            assert!(err.to_string().contains(rule), "{rule}: {err}");
        }
        for good in ["__ns:=/", "__ns:=/a/b_2", "__node:=_x9", "n1:__node:=n2"] {
            RosArgs::parse(["--ros-args", "-r", good]).unwrap();
        }
    }

    /// Both sides of a topic rule are checked as rcl parses them; a bad name used to be
    /// accepted and fail once DDS had started (or never, on the side that never matched).
    #[test]
    fn bad_topic_names_in_remappings_are_argument_errors() {
        for (rule, needle) in [
            ("/scan:=/robot-1/scan", "'-'"),
            ("/robot-1/scan:=/scan", "'-'"),
            ("/scan:=/a//b", "//"),
            ("/scan:=/a/", "end with '/'"),
            ("/**:=/x", "'*'"),
            ("a:b:c:=d", "':'"),
            ("scan:=a:b", "':'"),
            ("scan:=~", "'~'"),
            ("~x:=/y", "'~'"),
            ("/1scan:=/x", "digit"),
            ("/:=/x", "no name token"),
            ("/scan:=/a__b/scan", "`__`"),
            ("/a/b__:=/x", "`__`"),
        ] {
            let err = RosArgs::parse(["--ros-args", "-r", rule]).unwrap_err();
            let text = err.to_string();
            assert!(
                matches!(err, RosError::Args(_)) && text.contains(rule) && text.contains(needle),
                "{rule}: {text}"
            );
        }
        for good in ["scan:=/r1/scan", "~/x:=/y", "n:/a/b_2:=c", "/scan:=~/s"] {
            RosArgs::parse(["--ros-args", "-r", good]).unwrap();
        }
    }

    /// rcl's `rostopic://` and `rosservice://` rules: the ':' of the scheme used to be taken
    /// for a node prefix's (`-r rostopic://scan:=/robot1/scan` exited with status 2).
    #[test]
    fn rostopic_and_rosservice_rules_are_read_as_rcl_reads_them() {
        let a = RosArgs::parse([
            "--ros-args",
            "-r",
            "rostopic://scan:=/robot1/scan",
            "-r",
            "localiser:rostopic:///odom:=odom2",
            "-r",
            "rosservice://~/get_parameters:=/x",
            "-r",
            "classifier:rosservice://reset:=reset2",
        ])
        .unwrap();
        assert_eq!(
            a.remaps,
            vec![
                Remap {
                    node: None,
                    from: "scan".into(),
                    to: "/robot1/scan".into()
                },
                Remap {
                    node: Some("localiser".into()),
                    from: "/odom".into(),
                    to: "odom2".into()
                },
            ]
        );
        assert_eq!(
            resolve_name("/scan", &a.remaps, "/", "localiser"),
            "/robot1/scan"
        );
        assert_eq!(resolve_name("/odom", &a.remaps, "/", "localiser"), "/odom2");
        // The rosservice:// rules move services only.
        assert_eq!(
            resolve_name("reset", &a.service_remaps, "/", "classifier"),
            "/reset2"
        );
        assert_eq!(resolve_name("scan", &a.service_remaps, "/", "x"), "/scan");
        // A node named `rostopic`: only `://` makes the scheme.
        let a = RosArgs::parse(["--ros-args", "-r", "rostopic:scan:=x"]).unwrap();
        assert_eq!(a.remaps[0].node.as_deref(), Some("rostopic"));
        // The names after the scheme are checked as in any rule; the scheme belongs to the
        // match side only, and `__node`/`__ns` take none.
        for (rule, needle) in [
            ("rostopic://bad-name:=x", "'-'"),
            ("rosservice://x:=/a//b", "//"),
            ("rostopic://scan:=rostopic://x", "':'"),
            ("rostopic://:=x", "non-empty"),
            ("rostopic://__node:=x", "not a topic or service name"),
            ("rosservice://__ns:=/x", "not a topic or service name"),
            ("bad-node:rostopic://scan:=x", "node prefix"),
        ] {
            let err = RosArgs::parse(["--ros-args", "-r", rule]).unwrap_err();
            let text = err.to_string();
            assert!(
                matches!(err, RosError::Args(_)) && text.contains(rule) && text.contains(needle),
                "{rule}: {text}"
            );
        }
    }

    #[test]
    fn bad_arguments_are_named() {
        for (args, needle) in [
            (vec!["--ros-args", "-r"], "-r"),
            (vec!["--ros-args", "-r", "scan"], "from:=to"),
            (vec!["--ros-args", "-r", "__ns:=relative"], "absolute"),
            (vec!["--ros-args", "-p", "rate"], "name:=value"),
            (vec!["--ros-args", "--frobnicate"], "--frobnicate"),
            (vec!["--ros-args", "--log-file-name"], "--log-file-name"),
            (vec!["--ros-args", "-p", "rate:=[1, x]"], "rate"),
        ] {
            let err = RosArgs::parse(args.clone()).unwrap_err().to_string();
            assert!(err.contains(needle), "{args:?}: {err}");
        }
    }

    #[test]
    fn topic_resolution_follows_rcl() {
        let remaps = vec![
            Remap {
                node: None,
                from: "scan".into(),
                to: "base_scan".into(),
            },
            Remap {
                node: Some("other".into()),
                from: "/odom".into(),
                to: "/x".into(),
            },
        ];
        assert_eq!(resolve_name("/scan", &remaps, "/", "loc"), "/base_scan");
        assert_eq!(resolve_name("scan", &remaps, "/r1", "loc"), "/r1/base_scan");
        assert_eq!(resolve_name("/scan", &remaps, "/r1", "loc"), "/scan");
        assert_eq!(resolve_name("/odom", &remaps, "/", "loc"), "/odom");
        assert_eq!(resolve_name("/odom", &remaps, "/", "other"), "/x");
        assert_eq!(resolve_name("~/debug", &[], "/r1", "loc"), "/r1/loc/debug");
    }

    /// A rule without a scheme moves topics and services alike, as in rcl (the RPLIDAR
    /// driver's `stop_motor` service under `-r stop_motor:=lidar/stop_motor`).
    #[test]
    fn a_rule_without_a_scheme_applies_to_services_too() {
        let a = RosArgs::parse(["--ros-args", "-r", "stop_motor:=lidar/stop_motor"]).unwrap();
        assert_eq!(a.service_remaps, a.remaps);
        assert_eq!(
            resolve_name("stop_motor", &a.service_remaps, "/r1", "rplidar_driver"),
            "/r1/lidar/stop_motor"
        );
    }

    #[test]
    fn discovery_ranges_as_rcl_reads_them() {
        use DiscoveryRange::*;
        let range = |only, range| parse_discovery_range(only, range).unwrap();
        assert_eq!(range(None, None), Subnet);
        assert_eq!(range(Some("0"), Some("")), Subnet);
        assert_eq!(range(None, Some("SYSTEM_DEFAULT")), Subnet);
        assert_eq!(range(None, Some("LOCALHOST")), Localhost);
        assert_eq!(range(None, Some("OFF")), Off);
        assert_eq!(range(Some("1"), None), Localhost);
        assert_eq!(range(Some("1"), Some("OFF")), Localhost);
        assert_eq!(range(Some("0"), Some("LOCALHOST")), Localhost);
        let e = parse_discovery_range(None, Some("localhost"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("ROS_AUTOMATIC_DISCOVERY_RANGE `localhost`") && e.contains("LOCALHOST"),
            "{e}"
        );
    }

    #[test]
    fn domain_ids() {
        assert_eq!(parse_domain_id(None).unwrap(), 0);
        assert_eq!(parse_domain_id(Some(" 42 ")).unwrap(), 42);
        assert!(
            parse_domain_id(Some("233"))
                .unwrap_err()
                .to_string()
                .contains("ROS_DOMAIN_ID")
        );
        assert!(parse_domain_id(Some("-1")).is_err());
        assert!(parse_domain_id(Some("abc")).is_err());
    }
}
