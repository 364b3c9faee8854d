//! Node parameters: declarations with typed defaults, values from `--params-file` YAML files
//! and `-p name:=value` overrides, checked against the declared type.
//!
//! Values are typed the way rcl types them: the YAML scalar decides (`3` is an integer,
//! `3.0` a double, `true` or unquoted `yes`/`off` a bool, anything else a string, see
//! [`crate::yaml`]); an integer is accepted where a double is declared.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use crate::RosError;
use crate::yaml::{self, Yaml};

/// A parameter value, as `rcl_interfaces/msg/ParameterValue` types it.
#[derive(Debug, Clone, PartialEq)]
pub enum ParamValue {
    Bool(bool),
    Integer(i64),
    Double(f64),
    String(String),
    BoolArray(Vec<bool>),
    IntegerArray(Vec<i64>),
    DoubleArray(Vec<f64>),
    StringArray(Vec<String>),
}

impl ParamValue {
    /// The ROS type name, for messages.
    pub fn type_name(&self) -> &'static str {
        match self {
            Self::Bool(_) => "bool",
            Self::Integer(_) => "integer",
            Self::Double(_) => "double",
            Self::String(_) => "string",
            Self::BoolArray(_) => "bool array",
            Self::IntegerArray(_) => "integer array",
            Self::DoubleArray(_) => "double array",
            Self::StringArray(_) => "string array",
        }
    }

    /// Converts a YAML value of a parameter file or command line.
    fn from_yaml(value: &Yaml) -> Result<Self, String> {
        match value {
            Yaml::Bool(b) => Ok(Self::Bool(*b)),
            Yaml::Int(i) => Ok(Self::Integer(*i)),
            Yaml::Float(f) => Ok(Self::Double(*f)),
            Yaml::Str(s) => Ok(Self::String(s.to_string())),
            Yaml::Seq(items) => Self::from_sequence(items),
            Yaml::Null => Err("empty value (null) is not a parameter value".into()),
            Yaml::Map(_) => Err("a mapping is not a parameter value".into()),
        }
    }

    fn from_sequence(items: &[Yaml]) -> Result<Self, String> {
        let scalars = items
            .iter()
            .map(Self::from_yaml)
            .collect::<Result<Vec<_>, _>>()?;
        let all = |pred: fn(&ParamValue) -> bool| scalars.iter().all(pred);
        if scalars.is_empty() {
            // Only a declaration can type an empty list (see `GivenValue`); within a list
            // (`[[]]`) nothing can.
            return Err("an empty list has no element type".into());
        }
        if all(|v| matches!(v, Self::Bool(_))) {
            Ok(Self::BoolArray(
                scalars.iter().filter_map(|v| v.as_bool()).collect(),
            ))
        } else if all(|v| matches!(v, Self::Integer(_))) {
            Ok(Self::IntegerArray(
                scalars.iter().filter_map(|v| v.as_i64()).collect(),
            ))
        } else if all(|v| matches!(v, Self::Double(_))) {
            Ok(Self::DoubleArray(
                scalars.iter().filter_map(|v| v.as_f64()).collect(),
            ))
        } else if all(|v| matches!(v, Self::String(_))) {
            Ok(Self::StringArray(
                scalars
                    .iter()
                    .filter_map(|v| v.as_str().map(String::from))
                    .collect(),
            ))
        } else {
            // rcl refuses `[1, 2.5]` too ("Sequence should be of same type"): write `1.0`.
            Err("a list must hold values of one type (bools, integers, doubles or strings)".into())
        }
    }

    /// `value` converted to the type of `self` (the declared default), when ROS allows it.
    fn coerce_like(&self, value: ParamValue) -> Option<ParamValue> {
        match (self, value) {
            (Self::Double(_), Self::Integer(i)) => Some(Self::Double(i as f64)),
            (Self::DoubleArray(_), Self::IntegerArray(v)) => {
                Some(Self::DoubleArray(v.into_iter().map(|i| i as f64).collect()))
            }
            (declared, v) if std::mem::discriminant(declared) == std::mem::discriminant(&v) => {
                Some(v)
            }
            _ => None,
        }
    }

    /// An empty array of the type of `self` (the declared default), if it is an array.
    fn empty_like(&self) -> Option<ParamValue> {
        match self {
            Self::BoolArray(_) => Some(Self::BoolArray(Vec::new())),
            Self::IntegerArray(_) => Some(Self::IntegerArray(Vec::new())),
            Self::DoubleArray(_) => Some(Self::DoubleArray(Vec::new())),
            Self::StringArray(_) => Some(Self::StringArray(Vec::new())),
            Self::Bool(_) | Self::Integer(_) | Self::Double(_) | Self::String(_) => None,
        }
    }

    pub fn as_bool(&self) -> Option<bool> {
        match self {
            Self::Bool(b) => Some(*b),
            _ => None,
        }
    }

    pub fn as_i64(&self) -> Option<i64> {
        match self {
            Self::Integer(i) => Some(*i),
            _ => None,
        }
    }

    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Self::Double(f) => Some(*f),
            Self::Integer(i) => Some(*i as f64),
            _ => None,
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match self {
            Self::String(s) => Some(s),
            _ => None,
        }
    }

    pub fn as_string_array(&self) -> Option<&[String]> {
        match self {
            Self::StringArray(v) => Some(v),
            _ => None,
        }
    }
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Bool(b) => write!(f, "{b}"),
            Self::Integer(i) => write!(f, "{i}"),
            Self::Double(d) => write!(f, "{d}"),
            Self::String(s) => write!(f, "{s:?}"),
            Self::BoolArray(v) => write!(f, "{v:?}"),
            Self::IntegerArray(v) => write!(f, "{v:?}"),
            Self::DoubleArray(v) => write!(f, "{v:?}"),
            Self::StringArray(v) => write!(f, "{v:?}"),
        }
    }
}

/// A value as a parameter file or `-p` gives it, before the node's declaration types it. rcl
/// reads `[]` as an array of no element type, which rclcpp then refuses for any parameter
/// (ros2/rclcpp#1955: "No parameter value set"); here a parameter declared as an array takes
/// it as an empty array of its type, so that `topics: []` ("empty = all") can be given. For a
/// parameter the node does not declare it is still refused, as in rclcpp.
#[derive(Debug, Clone, PartialEq)]
pub enum GivenValue {
    Typed(ParamValue),
    EmptyList,
}

impl From<ParamValue> for GivenValue {
    fn from(value: ParamValue) -> Self {
        Self::Typed(value)
    }
}

impl GivenValue {
    /// Parses the right-hand side of `-p name:=value` as a YAML scalar or flow sequence.
    pub fn parse_cli(text: &str) -> Result<Self, String> {
        if text.trim().is_empty() {
            // rcl refuses it too (`rcl_parse_yaml_value`: no value), and the node with it.
            return Err("no value after `:=` (for an empty string write `:=''`)".into());
        }
        let value = yaml::parse(text).map_err(|e| format!("`{text}` is not a YAML value: {e}"))?;
        match value {
            // rcl types `~` and `null` by their text, as the strings "~" and "null".
            Yaml::Null => Ok(Self::Typed(ParamValue::String(text.to_string()))),
            other => Self::from_yaml(&other),
        }
    }

    /// Converts a YAML value of a parameter file or command line.
    fn from_yaml(value: &Yaml) -> Result<Self, String> {
        match value {
            Yaml::Seq(items) if items.is_empty() => Ok(Self::EmptyList),
            other => ParamValue::from_yaml(other).map(Self::Typed),
        }
    }

    /// The type given, for messages.
    fn type_name(&self) -> &'static str {
        match self {
            Self::Typed(value) => value.type_name(),
            Self::EmptyList => "an empty list",
        }
    }

    /// `self` as a value of the type of `declared` (the declared default), when ROS allows it;
    /// an empty list is an empty array of any array type.
    fn typed_like(self, declared: &ParamValue) -> Option<ParamValue> {
        match self {
            Self::Typed(value) => declared.coerce_like(value),
            Self::EmptyList => declared.empty_like(),
        }
    }
}

/// A parameter a node declares: its name, default (which fixes its type) and what it means.
#[derive(Debug, Clone)]
pub struct ParamDecl {
    pub name: String,
    pub default: ParamValue,
    pub description: String,
}

impl ParamDecl {
    pub fn new(name: &str, default: ParamValue, description: &str) -> Self {
        Self {
            name: name.to_string(),
            default,
            description: description.to_string(),
        }
    }
}

/// Every parameter a node declares: its own `decls`, then `use_sim_time`, which every ROS 2
/// node has, unless `decls` declares it itself (for its own description). The node and its
/// `--help` both list them from here, so the help cannot leave one out.
pub fn node_parameters(mut decls: Vec<ParamDecl>) -> Vec<ParamDecl> {
    if !decls.iter().any(|d| d.name == "use_sim_time") {
        decls.push(ParamDecl::new(
            "use_sim_time",
            ParamValue::Bool(false),
            "the node clock (Node::now) follows /clock; outputs keep their inputs' stamps \
             either way",
        ));
    }
    decls
}

/// Where a node's start-up values come from, in command-line order (see
/// [`crate::RosArgs::params_for`] and [`Parameters::resolve_sources`] for how they combine).
#[derive(Debug, Clone, PartialEq)]
pub enum ParamSource {
    /// A parameter file: its sections for the node.
    File(PathBuf),
    /// A `-p [node:]name:=value` for the node: `section` is the rule's node prefix as
    /// written, or [`CLI_SECTION`] without one, the section rcl files it under.
    Value {
        section: String,
        name: String,
        value: GivenValue,
    },
}

impl ParamSource {
    /// A `-p name:=value` without a node prefix.
    pub fn value(name: &str, value: impl Into<GivenValue>) -> Self {
        Self::Value {
            section: CLI_SECTION.to_string(),
            name: name.to_string(),
            value: value.into(),
        }
    }
}

/// The section rcl gives a `-p name:=value` without a node prefix: the same as a parameter
/// file's `/**:`, so the two overwrite each other's values.
pub const CLI_SECTION: &str = "/**";

/// One parameter of a merged section: its value and where the value came from.
struct MergedParam {
    name: String,
    value: GivenValue,
    source: String,
    /// Whether a name the node does not declare is an error (see [`Section::is_wildcard`]).
    strict: bool,
}

/// The resolved start-up parameters of a node.
#[derive(Debug, Clone, Default)]
pub struct Parameters {
    values: BTreeMap<String, ParamValue>,
}

impl Parameters {
    /// Defaults of `decls`, overridden by the parameter `files` (in order), then by the
    /// `overrides`: [`Parameters::resolve_sources`] for callers without a command line.
    pub fn resolve(
        decls: &[ParamDecl],
        node_fqn: &str,
        files: &[PathBuf],
        overrides: &[(String, ParamValue)],
    ) -> Result<Self, RosError> {
        let sources: Vec<ParamSource> = files
            .iter()
            .map(|path| ParamSource::File(path.clone()))
            .chain(
                overrides
                    .iter()
                    .map(|(name, value)| ParamSource::value(name, value.clone())),
            )
            .collect();
        Self::resolve_sources(decls, node_fqn, &sources)
    }

    /// Defaults of `decls`, overridden by `sources` as rcl and rclcpp (Humble on) combine
    /// them: rcl merges every source, in order, into one table of sections keyed by the
    /// section's name as written (a `-p` without a node prefix is in `/**`), a later value
    /// replacing an earlier one of its section in place; rclcpp then applies the sections that
    /// match the node in the order each name first appeared, a later section winning. So
    /// `--params-file a.yaml -p x:=1 --params-file b.yaml`, both files with a `localiser:`
    /// section setting x, gives 1: the section `localiser` (b's value) comes before `/**`.
    pub fn resolve_sources(
        decls: &[ParamDecl],
        node_fqn: &str,
        sources: &[ParamSource],
    ) -> Result<Self, RosError> {
        let mut sections: Vec<(String, Vec<MergedParam>)> = Vec::new();
        let mut merge = |section: &str, param: MergedParam| {
            let index = match sections.iter().position(|(name, _)| name == section) {
                Some(index) => index,
                None => {
                    sections.push((section.to_string(), Vec::new()));
                    sections.len() - 1
                }
            };
            let params = &mut sections[index].1;
            match params.iter_mut().find(|p| p.name == param.name) {
                Some(old) => *old = param,
                None => params.push(param),
            }
        };
        for source in sources {
            let path = match source {
                ParamSource::File(path) => path,
                ParamSource::Value {
                    section,
                    name,
                    value,
                } => {
                    let param = MergedParam {
                        name: name.clone(),
                        value: value.clone(),
                        source: "-p on the command line".into(),
                        strict: true,
                    };
                    merge(section, param);
                    continue;
                }
            };
            let file = ParamsFile::read(path)?;
            let source = format!("parameter file {}", path.display());
            let matching = file.sections_for(node_fqn);
            if matching.is_empty() {
                // rclcpp ignores such a file without a word: a classic trap (a section named
                // `localiser` is for /localiser, not /robot1/localiser).
                log::warn!(
                    "{source} has no section for the node {node_fqn}, so none of its values \
                     apply; its sections: {}",
                    file.section_names()
                );
            }
            for section in matching {
                for (name, value) in &section.params {
                    let param = MergedParam {
                        name: name.clone(),
                        value: value.clone(),
                        source: source.clone(),
                        strict: !section.is_wildcard(),
                    };
                    merge(&section.name, param);
                }
            }
        }
        let mut values: BTreeMap<String, ParamValue> = decls
            .iter()
            .map(|d| (d.name.clone(), d.default.clone()))
            .collect();
        for param in sections.into_iter().flat_map(|(_, params)| params) {
            let MergedParam {
                name,
                value,
                source,
                strict,
            } = param;
            let Some(declared) = values.get(&name) else {
                if strict {
                    return Err(RosError::Parameter {
                        reason: format!(
                            "unknown parameter (from {source}); this node declares: {}",
                            decl_names(decls)
                        ),
                        name,
                    });
                }
                if value == GivenValue::EmptyList {
                    // rclcpp refuses it for every node the section applies to.
                    return Err(RosError::Parameter {
                        reason: format!(
                            "{source} gives an empty list, which has no element type: only \
                             a node that declares `{name}` as an array can take it, and this \
                             one does not"
                        ),
                        name,
                    });
                }
                continue;
            };
            let given_type = value.type_name();
            let coerced = value
                .typed_like(declared)
                .ok_or_else(|| RosError::Parameter {
                    name: name.clone(),
                    reason: format!(
                        "expected {} but {source} gives {given_type}",
                        declared.type_name()
                    ),
                })?;
            values.insert(name, coerced);
        }
        Ok(Self { values })
    }

    pub fn get(&self, name: &str) -> Option<&ParamValue> {
        self.values.get(name)
    }

    pub fn iter(&self) -> impl Iterator<Item = (&str, &ParamValue)> {
        self.values.iter().map(|(k, v)| (k.as_str(), v))
    }

    fn typed<T>(
        &self,
        name: &str,
        want: &str,
        f: impl Fn(&ParamValue) -> Option<T>,
    ) -> Result<T, RosError> {
        let value = self.values.get(name).ok_or_else(|| RosError::Parameter {
            name: name.to_string(),
            reason: "not declared by this node".into(),
        })?;
        f(value).ok_or_else(|| RosError::Parameter {
            name: name.to_string(),
            reason: format!("expected {want}, found {}", value.type_name()),
        })
    }

    pub fn bool(&self, name: &str) -> Result<bool, RosError> {
        self.typed(name, "bool", ParamValue::as_bool)
    }

    pub fn i64(&self, name: &str) -> Result<i64, RosError> {
        self.typed(name, "integer", ParamValue::as_i64)
    }

    pub fn f64(&self, name: &str) -> Result<f64, RosError> {
        self.typed(name, "double", ParamValue::as_f64)
    }

    pub fn string(&self, name: &str) -> Result<String, RosError> {
        self.typed(name, "string", |v| v.as_str().map(String::from))
    }

    pub fn string_array(&self, name: &str) -> Result<Vec<String>, RosError> {
        self.typed(name, "string array", |v| {
            v.as_string_array().map(<[String]>::to_vec)
        })
    }

    /// A finite double checked by `valid`; the error names the parameter and the rule.
    pub fn f64_checked(
        &self,
        name: &str,
        rule: &str,
        valid: impl Fn(f64) -> bool,
    ) -> Result<f64, RosError> {
        let v = self.f64(name)?;
        if v.is_finite() && valid(v) {
            Ok(v)
        } else {
            Err(RosError::Parameter {
                name: name.to_string(),
                reason: format!("{v:?} is invalid: must be {rule}"),
            })
        }
    }
}

fn decl_names(decls: &[ParamDecl]) -> String {
    decls
        .iter()
        .map(|d| d.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A parameter file (`node_name: ros__parameters: {...}`), parsed whole as rcl parses it.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamsFile {
    /// In file order.
    pub sections: Vec<Section>,
}

/// The parameters a file gives to the nodes its name matches.
#[derive(Debug, Clone, PartialEq)]
pub struct Section {
    /// A node name or pattern (see [`section_applies`]): rcl joins the mapping keys above
    /// `ros__parameters` with '/', so `robot1: {localiser: {ros__parameters: ...}}` is the
    /// section `robot1/localiser`.
    pub name: String,
    /// In file order; nested mappings become dotted names, as in rcl.
    pub params: Vec<(String, GivenValue)>,
}

impl Section {
    /// A section for several nodes (its name has a `*`), such as `/**`: names a node does not
    /// declare are left to the other nodes instead of being errors.
    pub fn is_wildcard(&self) -> bool {
        self.name.contains('*')
    }
}

/// The key under a node's name that holds its parameters.
const PARAMS_KEY: &str = "ros__parameters";

/// A namespace key that names no node itself: the nodes below it are in `/`.
const ROOT_NAMESPACE: &str = "/";

impl ParamsFile {
    /// Reads and parses the file at `path`; errors name it.
    pub fn read(path: &Path) -> Result<Self, RosError> {
        let err = |reason: String| RosError::ParamsFile {
            path: path.to_path_buf(),
            reason,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
        Self::parse(&text).map_err(err)
    }

    /// [`ParamsFile::read`] on text.
    pub fn parse(text: &str) -> Result<Self, String> {
        let root = yaml::parse(text).map_err(|e| format!("not YAML: {e}"))?;
        let Yaml::Map(entries) = root else {
            return Err("expected a mapping of node names at the top level".into());
        };
        let mut sections = Vec::new();
        collect_sections("", &entries, &mut sections)?;
        Ok(Self { sections })
    }

    /// The sections that apply to the node `node_fqn` (`/ns/name`), in file order.
    pub fn sections_for(&self, node_fqn: &str) -> Vec<&Section> {
        self.sections
            .iter()
            .filter(|s| section_applies(&s.name, node_fqn))
            .collect()
    }

    /// The names of all sections, for messages.
    pub fn section_names(&self) -> String {
        if self.sections.is_empty() {
            return "none".into();
        }
        self.sections
            .iter()
            .map(|s| format!("`{}`", s.name))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// Whether the parameter file section `name` (or a `-p` rule's node prefix) applies to the
/// node `node_fqn` (`/ns/name`), as rclcpp decides (`parameter_map_from`): a leading '/' is
/// added when missing, then the name must match the whole fully qualified name, where a
/// token `*` stands for any one name token and `**` for any number of them, none included.
/// So `localiser` is `/localiser` only; `/*/localiser`, `/robot1/*` and `/**/localiser` are
/// patterns.
pub fn section_applies(name: &str, node_fqn: &str) -> bool {
    fn tokens(name: &str) -> Vec<&str> {
        name.strip_prefix('/').unwrap_or(name).split('/').collect()
    }
    tokens_match(&tokens(name), &tokens(node_fqn))
}

fn tokens_match(pattern: &[&str], tokens: &[&str]) -> bool {
    match pattern.split_first() {
        None => tokens.is_empty(),
        Some((&"**", rest)) => (0..=tokens.len()).any(|skip| tokens_match(rest, &tokens[skip..])),
        Some((&first, rest)) => tokens.split_first().is_some_and(|(&token, tokens)| {
            (first == "*" || first == token) && tokens_match(rest, tokens)
        }),
    }
}

/// The sections under the node name `prefix` (empty at the top level).
fn collect_sections(
    prefix: &str,
    entries: &[(Yaml, Yaml)],
    out: &mut Vec<Section>,
) -> Result<(), String> {
    for (key, value) in entries {
        let key = key_text(key)?;
        if key == PARAMS_KEY {
            if prefix.is_empty() || prefix == ROOT_NAMESPACE {
                return Err(format!("`{PARAMS_KEY}` must be under a node name"));
            }
            let mut params = Vec::new();
            flatten(value, "", &mut params).map_err(|e| format!("section `{prefix}`: {e}"))?;
            out.push(Section {
                name: prefix.to_string(),
                params,
            });
            continue;
        }
        let Yaml::Map(children) = value else {
            return Err(if prefix.is_empty() {
                format!("section `{key}` must be a mapping holding `{PARAMS_KEY}`")
            } else {
                format!(
                    "section `{prefix}`: `{key}` is neither `{PARAMS_KEY}` nor a node name \
                     (a node's parameters go under `{PARAMS_KEY}:`)"
                )
            });
        };
        let name = match prefix {
            "" => key,
            // The root namespace as a key of its own (`/: {talker: ...}`), as rcl reads it.
            "/" => format!("/{key}"),
            _ => format!("{prefix}/{key}"),
        };
        if name != ROOT_NAMESPACE {
            validate_section_name(&name)?;
        }
        collect_sections(&name, children, out)?;
    }
    Ok(())
}

/// rcl refuses a node name or namespace in a parameter file that rmw would refuse: one that
/// could never match a node is a typo (`robot-1:`), not a section to skip in silence.
fn validate_section_name(name: &str) -> Result<(), String> {
    let tokens = name.strip_prefix('/').unwrap_or(name);
    for token in tokens.split('/') {
        if token.is_empty() {
            return Err(format!("section `{name}` has an empty name token"));
        }
        if !matches!(token, "*" | "**") {
            crate::args::validate_rmw_token(token).map_err(|e| {
                format!("section `{name}` is no node name: its token `{token}` {e}")
            })?;
        }
    }
    Ok(())
}

fn key_text(key: &Yaml) -> Result<String, String> {
    match key {
        Yaml::Str(s) => Ok(s.to_string()),
        Yaml::Int(i) => Ok(i.to_string()),
        Yaml::Float(f) => Ok(f.to_string()),
        Yaml::Bool(b) => Ok(b.to_string()),
        Yaml::Null | Yaml::Seq(_) | Yaml::Map(_) => Err(format!("key {key:?} is not a name")),
    }
}

fn flatten(value: &Yaml, prefix: &str, out: &mut Vec<(String, GivenValue)>) -> Result<(), String> {
    let Yaml::Map(entries) = value else {
        let what = match prefix.strip_suffix('.') {
            Some(name) => name,
            None => PARAMS_KEY,
        };
        return Err(format!("`{what}` must be a mapping of parameter names"));
    };
    for (key, value) in entries {
        let name = format!("{prefix}{}", key_text(key)?);
        if let Yaml::Map(_) = value {
            flatten(value, &format!("{name}."), out)?;
        } else {
            let value =
                GivenValue::from_yaml(value).map_err(|e| format!("parameter `{name}`: {e}"))?;
            out.push((name, value));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decls() -> Vec<ParamDecl> {
        vec![
            ParamDecl::new("rate", ParamValue::Double(1.0), ""),
            ParamDecl::new("loop", ParamValue::Bool(false), ""),
            ParamDecl::new("bag", ParamValue::String(String::new()), ""),
            ParamDecl::new("topics", ParamValue::StringArray(vec![]), ""),
        ]
    }

    /// A `-p` value, typed by its text alone.
    fn cli(text: &str) -> Result<ParamValue, String> {
        match GivenValue::parse_cli(text)? {
            GivenValue::Typed(value) => Ok(value),
            GivenValue::EmptyList => Err("an empty list has no type of its own".into()),
        }
    }

    fn names(decls: &[ParamDecl]) -> Vec<&str> {
        decls.iter().map(|d| d.name.as_str()).collect()
    }

    #[test]
    fn every_node_declares_use_sim_time_once_keeping_its_own_description() {
        let all = node_parameters(decls());
        assert_eq!(
            names(&all),
            ["rate", "loop", "bag", "topics", "use_sim_time"]
        );
        // No node stamps its outputs with the node clock: `--help` used to say "stamp with
        // /clock instead of the system clock".
        let sim_time = &all[4].description;
        assert!(
            sim_time.contains("follows /clock") && sim_time.contains("keep their inputs' stamps"),
            "{sim_time}"
        );
        let own = ParamDecl::new("use_sim_time", ParamValue::Bool(false), "mine");
        let all = node_parameters(vec![own]);
        assert_eq!(names(&all), ["use_sim_time"]);
        assert_eq!(all[0].description, "mine");
    }

    #[test]
    fn cli_values_are_typed_like_yaml() {
        assert_eq!(cli("3").unwrap(), ParamValue::Integer(3));
        assert_eq!(cli("3.5").unwrap(), ParamValue::Double(3.5));
        assert_eq!(cli("true").unwrap(), ParamValue::Bool(true));
        assert_eq!(cli("hello").unwrap(), ParamValue::String("hello".into()));
        assert_eq!(
            cli("[1.0, 2.5]").unwrap(),
            ParamValue::DoubleArray(vec![1.0, 2.5])
        );
        // As rcl: one type per list ("Sequence should be of same type").
        assert!(cli("[1, 2.5]").is_err());
        assert_eq!(
            cli("[/scan, /odom]").unwrap(),
            ParamValue::StringArray(vec!["/scan".into(), "/odom".into()])
        );
        assert!(cli("[1, abc]").is_err());
        assert_eq!(GivenValue::parse_cli("[]").unwrap(), GivenValue::EmptyList);
        assert!(cli("[[]]").is_err());
        assert_eq!(cli("~").unwrap(), ParamValue::String("~".into()));
        assert_eq!(cli("''").unwrap(), ParamValue::String(String::new()));
    }

    /// rcl refuses `-p name:=` (no value), and so the node; it used to be the empty string.
    #[test]
    fn an_empty_cli_value_is_refused_as_rcl_refuses_it() {
        for text in ["", " "] {
            let err = cli(text).unwrap_err();
            assert!(
                err.contains("no value") && err.contains(":=''"),
                "{text:?}: {err}"
            );
        }
    }

    #[test]
    fn cli_values_take_rcl_booleans_unquoted_only() {
        for (text, want) in [("off", false), ("yes", true), ("On", true), ("N", false)] {
            assert_eq!(cli(text).unwrap(), ParamValue::Bool(want));
        }
        assert_eq!(cli("'off'").unwrap(), ParamValue::String("off".into()));
        assert_eq!(
            cli("[yes, no]").unwrap(),
            ParamValue::BoolArray(vec![true, false])
        );
        assert!(cli("[on, 'off']").is_err());
        // The documented way to give one of those words as a string; it used to be a bool.
        assert_eq!(cli("!!str on").unwrap(), ParamValue::String("on".into()));
    }

    /// (section, node, applies), as rclcpp's `parameter_map_from` decides.
    const SECTION_CASES: &[(&str, &str, bool)] = &[
        ("replay", "/replay", true),
        ("/replay", "/replay", true),
        ("replay", "/other_ns/replay", false),
        ("localiser", "/robot1/localiser", false),
        ("robot1/localiser", "/robot1/localiser", true),
        ("/robot1/localiser", "/robot1/localiser", true),
        ("/robot1/localiser", "/robot2/localiser", false),
        ("robot1/localiser", "/localiser", false),
        ("/**", "/replay", true),
        ("/**", "/a/b/replay", true),
        ("/**/localiser", "/localiser", true),
        ("/**/localiser", "/a/b/localiser", true),
        ("/**/localiser", "/a/classifier", false),
        ("/*/localiser", "/robot1/localiser", true),
        ("/*/localiser", "/localiser", false),
        ("/*/localiser", "/a/b/localiser", false),
        ("/robot1/*", "/robot1/localiser", true),
        ("/robot1/*", "/robot2/localiser", false),
        ("/robot1/*", "/robot1/sub/localiser", false),
        ("/robot1/**", "/robot1/sub/localiser", true),
        ("/a/**/b", "/a/b", true),
        ("/a/**/b", "/a/x/y/b", true),
        ("/a/**/b", "/a/x/c", false),
        ("localiser/", "/localiser", false),
    ];

    #[test]
    fn sections_apply_to_the_whole_fully_qualified_name() {
        for &(section, node, applies) in SECTION_CASES {
            assert_eq!(
                section_applies(section, node),
                applies,
                "section `{section}` for node {node}"
            );
        }
    }

    #[test]
    fn params_file_sections_wildcards_and_nesting() {
        let yaml = r#"
/**:
  ros__parameters:
    use_sim_time: true
    rate: 2
replay:
  ros__parameters:
    loop: true
    nested: {a: 1}
/other_ns/replay:
  ros__parameters:
    loop: false
robot1:
  ros__parameters:
    rate: 3.0
  localiser:
    ros__parameters:
      moving: off
      frame: 'off'
/robot2:
  localiser:
    ros__parameters:
      moving: on
"#;
        let file = ParamsFile::parse(yaml).unwrap();
        let applied = |node: &str| -> Vec<(String, bool, Vec<String>)> {
            file.sections_for(node)
                .into_iter()
                .map(|s| {
                    let names = s.params.iter().map(|(n, _)| n.clone()).collect();
                    (s.name.clone(), s.is_wildcard(), names)
                })
                .collect()
        };
        let strings = |names: &[&str]| names.iter().map(|n| n.to_string()).collect::<Vec<_>>();
        assert_eq!(
            applied("/replay"),
            vec![
                ("/**".into(), true, strings(&["use_sim_time", "rate"])),
                ("replay".into(), false, strings(&["loop", "nested.a"])),
            ]
        );
        // `replay` is /replay only: a node in a namespace gets its own section alone.
        assert_eq!(
            applied("/other_ns/replay"),
            vec![
                ("/**".into(), true, strings(&["use_sim_time", "rate"])),
                ("/other_ns/replay".into(), false, strings(&["loop"])),
            ]
        );
        // Nested keys are joined into the node's name; each robot gets its own section.
        let robot1 = file.sections_for("/robot1/localiser");
        assert_eq!(robot1.len(), 2);
        assert_eq!(robot1[1].name, "robot1/localiser");
        assert_eq!(
            robot1[1].params,
            vec![
                ("moving".to_string(), ParamValue::Bool(false).into()),
                ("frame".to_string(), ParamValue::String("off".into()).into()),
            ]
        );
        let robot2 = file.sections_for("/robot2/localiser");
        assert_eq!(robot2.len(), 2);
        assert_eq!(
            robot2[1].params,
            vec![("moving".to_string(), ParamValue::Bool(true).into())]
        );
        assert_eq!(file.sections_for("/robot1")[1].name, "robot1");
        assert_eq!(file.sections_for("/localiser").len(), 1);
    }

    #[test]
    fn params_file_errors_name_the_problem() {
        for (yaml, needle) in [
            ("replay: {rate: 1}", "ros__parameters"),
            ("replay: 1", "ros__parameters"),
            ("ros__parameters: {rate: 1}", "under a node name"),
            ("- a", "top level"),
            (
                "replay: {ros__parameters: 3}",
                "`ros__parameters` must be a mapping",
            ),
            ("replay: {ros__parameters: {x: null}}", "`x`"),
            // Every section is checked, as rcl parses the whole file.
            ("other: {ros__parameters: {y: [1, a]}}", "`y`"),
            ("other: {ros__parameters: {y: [1, 2.5]}}", "one type"),
            // A section no node could have, as rcl refuses it.
            ("robot-1: {n: {ros__parameters: {a: 1}}}", "'-'"),
            ("/ns/: {n: {ros__parameters: {a: 1}}}", "empty name token"),
            ("ns: {1n: {ros__parameters: {a: 1}}}", "digit"),
            ("/: {ros__parameters: {a: 1}}", "under a node name"),
            // rcl's own test files: a partial wildcard, a node key starting with '/'.
            ("/f*oo: {ros__parameters: {a: 1}}", "'*'"),
            ("/**/node*: {ros__parameters: {a: 1}}", "'*'"),
            ("/foo: {/*: {ros__parameters: {a: 1}}}", "empty name token"),
        ] {
            let err = ParamsFile::parse(yaml).unwrap_err();
            assert!(err.contains(needle), "{yaml}: {err}");
        }
        assert!(ParamsFile::parse(":\n  - [").is_err());
    }

    /// Section names rcl accepts (its test files root_ns.yaml and wildcards.yaml): `*` and
    /// `**` as any whole token. `/:` above a node used to be refused (an empty name token).
    #[test]
    fn section_names_rcl_accepts_are_accepted() {
        let file = ParamsFile::parse("/:\n  my_node:\n    ros__parameters:\n      a: 1\n").unwrap();
        assert_eq!(file.sections[0].name, "/my_node");
        assert_eq!(file.sections_for("/my_node").len(), 1);
        for name in [
            "/*",
            "/**/some_node1",
            "/*/some_node2",
            "/foo1/**",
            "/foo2/*",
            "/foo7/*/some_node7",
            "/foo10/**/bar/bar1/bar2/**",
        ] {
            ParamsFile::parse(&format!("{name}: {{ros__parameters: {{a: 1}}}}"))
                .unwrap_or_else(|e| panic!("{name}: {e}"));
        }
    }

    /// Keeps the warnings logged while the tests run (the crate's only logger in tests).
    struct Warnings(std::sync::Mutex<Vec<String>>);

    impl log::Log for Warnings {
        fn enabled(&self, metadata: &log::Metadata) -> bool {
            metadata.level() <= log::Level::Warn
        }

        fn log(&self, record: &log::Record) {
            if self.enabled(record.metadata())
                && let Ok(mut warnings) = self.0.lock()
            {
                warnings.push(record.args().to_string());
            }
        }

        fn flush(&self) {}
    }

    static WARNINGS: Warnings = Warnings(std::sync::Mutex::new(Vec::new()));

    #[test]
    fn a_params_file_with_no_section_for_the_node_is_warned_about() {
        let _ = log::set_logger(&WARNINGS);
        log::set_max_level(log::LevelFilter::Warn);
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("robots.yaml");
        std::fs::write(
            &file,
            "localiser:\n  ros__parameters:\n    rate: 2.0\n\
             robot2:\n  replay:\n    ros__parameters:\n      rate: 3.0\n",
        )
        .unwrap();
        let warned = |node: &str| {
            Parameters::resolve(&decls(), node, std::slice::from_ref(&file), &[]).unwrap();
            let warnings = WARNINGS.0.lock().unwrap();
            warnings
                .iter()
                .find(|w| w.contains(&file.display().to_string()) && w.contains(node))
                .cloned()
        };
        let warning = warned("/robot1/replay").expect("no warning for /robot1/replay");
        assert!(
            warning.contains("`localiser`, `robot2/replay`"),
            "{warning}"
        );
        assert_eq!(warned("/robot2/replay"), None);
    }

    #[test]
    fn resolve_orders_file_then_cli_and_checks_types() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("p.yaml");
        std::fs::write(&file, "/**:\n  ros__parameters:\n    rate: 2\n    unrelated: 1\nreplay:\n  ros__parameters:\n    bag: a.bag\n").unwrap();
        let p = Parameters::resolve(
            &decls(),
            "/replay",
            std::slice::from_ref(&file),
            &[("loop".into(), ParamValue::Bool(true))],
        )
        .unwrap();
        assert_eq!(p.f64("rate").unwrap(), 2.0);
        assert_eq!(p.string("bag").unwrap(), "a.bag");
        assert!(p.bool("loop").unwrap());
        assert!(p.string_array("topics").unwrap().is_empty());

        let err = Parameters::resolve(
            &decls(),
            "/replay",
            &[],
            &[("rate".into(), ParamValue::String("fast".into()))],
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("rate") && err.contains("expected double"),
            "{err}"
        );
        let err = Parameters::resolve(
            &decls(),
            "/replay",
            &[],
            &[("speed".into(), ParamValue::Integer(1))],
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("speed") && err.contains("unknown"), "{err}");
        let missing = dir.path().join("missing.yaml");
        let err = Parameters::resolve(&decls(), "/replay", &[missing], &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("missing.yaml"), "{err}");
    }

    /// An empty list takes its type from the declaration: replay's `topics: []` ("empty =
    /// all") in a params file after replay.launch.py's own `/**` list, or as `-p topics:=[]`,
    /// is an empty string array; both used to be refused ("an empty list has no element
    /// type"), so every topic could not be asked for under the launch file. A scalar, or a
    /// parameter the node does not declare (as rclcpp, which refuses `[]` for any), refuses
    /// it naming the parameter; a section for another node does not matter.
    #[test]
    fn an_empty_list_takes_the_type_of_a_declared_array() {
        let dir = tempfile::tempdir().unwrap();
        let file = |name: &str, text: &str| {
            let path = dir.path().join(name);
            std::fs::write(&path, text).unwrap();
            path
        };
        let own = file(
            "own.yaml",
            "/**:\n  ros__parameters:\n    topics: [/scan, /odom]\n",
        );
        let all = file(
            "all.yaml",
            "localiser:\n  ros__parameters:\n    unrelated: []\n\
             replay:\n  ros__parameters:\n    topics: []\n",
        );
        let launch = file("args.yaml", "/replay:\n  ros__parameters:\n    rate: 2.0\n");
        let resolve = |decls: &[ParamDecl], args: &[&str]| {
            let args = crate::RosArgs::parse(args.iter().copied())?;
            Parameters::resolve_sources(decls, "/replay", &args.params_for("/replay"))
        };
        let (own, all, launch) = (
            own.to_str().unwrap(),
            all.to_str().unwrap(),
            launch.to_str().unwrap(),
        );
        let layered = ["--ros-args", "--params-file", own, "--params-file", all];
        let p = resolve(
            &decls(),
            &[&layered[..], &["--params-file", launch]].concat(),
        )
        .unwrap();
        assert_eq!(p.get("topics"), Some(&ParamValue::StringArray(vec![])));
        assert_eq!(p.f64("rate").unwrap(), 2.0);
        let cli = ["--ros-args", "--params-file", own, "-p", "topics:=[]"];
        let p = resolve(&decls(), &cli).unwrap();
        assert_eq!(p.get("topics"), Some(&ParamValue::StringArray(vec![])));
        let ids = [ParamDecl::new("ids", ParamValue::IntegerArray(vec![1]), "")];
        let p = resolve(&ids, &["--ros-args", "-p", "ids:=[]"]).unwrap();
        assert_eq!(p.get("ids"), Some(&ParamValue::IntegerArray(vec![])));

        let err = resolve(&decls(), &["--ros-args", "-p", "rate:=[]"]).unwrap_err();
        let err = err.to_string();
        assert!(
            err.contains("`rate`")
                && err.contains("expected double")
                && err.contains("an empty list"),
            "{err}"
        );
        let shared = file("shared.yaml", "/**:\n  ros__parameters:\n    other: []\n");
        let err = resolve(
            &decls(),
            &["--ros-args", "--params-file", shared.to_str().unwrap()],
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("`other`") && err.contains("shared.yaml") && err.contains("empty list"),
            "{err}"
        );
    }

    /// A parameter file after a `-p` wins over it, as in rcl; `-p` used to win always.
    #[test]
    fn sources_apply_in_order_whatever_their_kind() {
        let dir = tempfile::tempdir().unwrap();
        let file = ParamSource::File(dir.path().join("p.yaml"));
        std::fs::write(
            dir.path().join("p.yaml"),
            "/**:\n  ros__parameters:\n    rate: 2.0\n",
        )
        .unwrap();
        let cli = ParamSource::value("rate", ParamValue::Double(5.0));
        let rate = |sources: &[ParamSource]| {
            Parameters::resolve_sources(&decls(), "/replay", sources)
                .unwrap()
                .f64("rate")
                .unwrap()
        };
        assert_eq!(rate(&[cli.clone(), file.clone()]), 2.0);
        assert_eq!(rate(&[file, cli]), 5.0);
    }

    /// rclcpp applies the merged sections in the order of each name's first appearance: a
    /// `localiser:` section set again by a later file still comes before the `-p` between
    /// them (`/**`). Sources used to be applied in command-line order (`moving` true).
    #[test]
    fn sections_merge_by_name_and_apply_in_order_of_first_appearance() {
        let dir = tempfile::tempdir().unwrap();
        let file = |name: &str, text: &str| {
            let path = dir.path().join(name);
            std::fs::write(&path, text).unwrap();
            ParamSource::File(path)
        };
        let robot = file(
            "robot.yaml",
            "localiser:\n  ros__parameters:\n    moving: true\n",
        );
        let overrides = file(
            "override.yaml",
            "localiser:\n  ros__parameters:\n    moving: true\n    rate: 3.0\n",
        );
        let all_nodes = file("all.yaml", "/**:\n  ros__parameters:\n    moving: true\n");
        let decls = vec![
            ParamDecl::new("moving", ParamValue::Bool(false), ""),
            ParamDecl::new("rate", ParamValue::Double(1.0), ""),
        ];
        let cli = |name: &str, value| ParamSource::value(name, value);
        let prefixed = |section: &str, value: ParamValue| ParamSource::Value {
            section: section.into(),
            name: "moving".into(),
            value: value.into(),
        };
        let resolve = |sources: &[ParamSource]| {
            Parameters::resolve_sources(&decls, "/localiser", sources).unwrap()
        };
        let moving = |sources: &[ParamSource]| resolve(sources).bool("moving").unwrap();
        let no = ParamValue::Bool(false);
        assert!(!moving(&[
            robot.clone(),
            cli("moving", no.clone()),
            overrides.clone()
        ]));
        // The later file's other values still apply.
        let p = resolve(&[robot.clone(), cli("moving", no.clone()), overrides.clone()]);
        assert_eq!(p.f64("rate").unwrap(), 3.0);
        // A `-p localiser:` is the section `localiser`: the later file replaces its value.
        assert!(moving(&[
            prefixed("localiser", no.clone()),
            overrides.clone()
        ]));
        assert!(!moving(&[
            overrides.clone(),
            prefixed("localiser", no.clone())
        ]));
        // `/localiser` is another section than `localiser`, as rcl keys them as written: the
        // one that appeared first applies first, however late its last value came.
        assert!(moving(&[
            prefixed("/localiser", no.clone()),
            robot.clone(),
            prefixed("/localiser", no.clone())
        ]));
        assert!(!moving(&[
            robot.clone(),
            prefixed("/localiser", no.clone()),
            robot.clone()
        ]));
        // A file's `/**` and a `-p` without prefix share the section `/**`: a last `-p` loses
        // to a `localiser:` section when a file opened `/**` before it.
        assert!(moving(&[
            all_nodes.clone(),
            robot.clone(),
            cli("moving", no.clone())
        ]));
        assert!(!moving(&[robot, all_nodes, cli("moving", no.clone())]));
        // Only the value that is applied is checked: one replaced in its section is not.
        let p = resolve(&[
            cli("rate", ParamValue::String("fast".into())),
            cli("rate", ParamValue::Double(2.0)),
        ]);
        assert_eq!(p.f64("rate").unwrap(), 2.0);
    }

    #[test]
    fn checked_doubles_reject_nan_and_rule_breakers() {
        let p = Parameters::resolve(
            &decls(),
            "/replay",
            &[],
            &[("rate".into(), ParamValue::Double(f64::NAN))],
        )
        .unwrap();
        let err = p
            .f64_checked("rate", "> 0", |v| v > 0.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("rate") && err.contains("> 0"), "{err}");
        let p = Parameters::resolve(
            &decls(),
            "/replay",
            &[],
            &[("rate".into(), ParamValue::Integer(-1))],
        )
        .unwrap();
        assert!(p.f64_checked("rate", "> 0", |v| v > 0.0).is_err());
    }
}
