//! ROS 2 command-line arguments (`--ros-args ... [--]`), parsed the way rcl parses them, and
//! ROS name resolution with remapping. ros2-client does neither, so the nodes do it here.

use std::path::PathBuf;

use crate::RosError;
use crate::params::ParamValue;

/// What `--ros-args` sections of a command line say.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RosArgs {
    /// `-r [node:]from:=to` topic remappings, in order (first match wins, as in rcl).
    pub remaps: Vec<Remap>,
    /// `-r __node:=name` (or `__name:=`).
    pub node_name: Option<String>,
    /// `-r __ns:=/namespace`.
    pub namespace: Option<String>,
    /// `-p name:=value`, in order (later ones win).
    pub params: Vec<(String, ParamValue)>,
    /// `--params-file FILE`, in order.
    pub params_files: Vec<PathBuf>,
    /// Arguments outside `--ros-args` sections (the program's own).
    pub rest: Vec<String>,
}

/// One `-r` remapping rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Remap {
    /// Applies only to the node of this name (`node:from:=to`), or to every node.
    pub node: Option<String>,
    pub from: String,
    pub to: String,
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
                        let (name, text) = rule
                            .split_once(":=")
                            .ok_or_else(|| bad(&rule, "a parameter must be `name:=value`"))?;
                        if name.is_empty() {
                            return Err(bad(&rule, "empty parameter name"));
                        }
                        // `node:name:=value` applies to one node only; we keep the last part.
                        let name = name.rsplit(':').next().unwrap_or(name);
                        let parsed =
                            ParamValue::parse_cli(text).map_err(|e| RosError::Parameter {
                                name: name.to_string(),
                                reason: e,
                            })?;
                        out.params.push((name.to_string(), parsed));
                    }
                    "--params-file" => out.params_files.push(PathBuf::from(value("a file")?)),
                    // Accepted and ignored: logging and security settings of rcl.
                    "--log-level" | "--log-config-file" | "-e" | "--enclave" => {
                        value("a value")?;
                    }
                    "--enable-rosout-logs"
                    | "--disable-rosout-logs"
                    | "--enable-stdout-logs"
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
        // `node:from` restricts the rule to one node; `from` may itself not contain ':'.
        let (node, from) = match lhs.split_once(':') {
            Some((node, from)) => (Some(node.to_string()), from),
            None => (None, lhs),
        };
        if from.is_empty() || to.is_empty() {
            return Err(bad("both sides must be non-empty"));
        }
        match from {
            "__node" | "__name" => self.node_name = Some(to.to_string()),
            "__ns" => {
                if !to.starts_with('/') {
                    return Err(bad("a namespace must be absolute (start with '/')"));
                }
                self.namespace = Some(to.to_string());
            }
            _ => self.remaps.push(Remap {
                node,
                from: from.to_string(),
                to: to.to_string(),
            }),
        }
        Ok(())
    }
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

/// Applies the first matching remap rule to the expanded `name`.
pub fn resolve_topic(name: &str, remaps: &[Remap], namespace: &str, node_name: &str) -> String {
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
        assert_eq!(a.node_name.as_deref(), Some("loc2"));
        assert_eq!(a.namespace.as_deref(), Some("/r1"));
        assert_eq!(
            a.params,
            vec![("rate".to_string(), ParamValue::Double(2.5))]
        );
        assert_eq!(a.params_files, vec![PathBuf::from("p.yaml")]);
    }

    #[test]
    fn bad_arguments_are_named() {
        for (args, needle) in [
            (vec!["--ros-args", "-r"], "-r"),
            (vec!["--ros-args", "-r", "scan"], "from:=to"),
            (vec!["--ros-args", "-r", "__ns:=relative"], "absolute"),
            (vec!["--ros-args", "-p", "rate"], "name:=value"),
            (vec!["--ros-args", "--frobnicate"], "--frobnicate"),
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
        assert_eq!(resolve_topic("/scan", &remaps, "/", "loc"), "/base_scan");
        assert_eq!(
            resolve_topic("scan", &remaps, "/r1", "loc"),
            "/r1/base_scan"
        );
        assert_eq!(resolve_topic("/scan", &remaps, "/r1", "loc"), "/scan");
        assert_eq!(resolve_topic("/odom", &remaps, "/", "loc"), "/odom");
        assert_eq!(resolve_topic("/odom", &remaps, "/", "other"), "/x");
        assert_eq!(resolve_topic("~/debug", &[], "/r1", "loc"), "/r1/loc/debug");
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
