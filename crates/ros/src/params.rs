//! Node parameters: declarations with typed defaults, values from `--params-file` YAML files
//! and `-p name:=value` overrides, checked against the declared type.
//!
//! Values are typed the way ROS 2 types them: the YAML scalar decides (`3` is an integer,
//! `3.0` a double, `true` a bool, anything else a string); an integer is accepted where a
//! double is declared.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;

use serde_yaml_ng::Value;

use crate::RosError;

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

    /// Parses the right-hand side of `-p name:=value` as a YAML scalar or flow sequence.
    pub fn parse_cli(text: &str) -> Result<Self, String> {
        let value: Value = serde_yaml_ng::from_str(text)
            .map_err(|e| format!("`{text}` is not a YAML value: {e}"))?;
        match value {
            // `-p name:=` (empty) and `~` are strings in rcl, not null.
            Value::Null => Ok(Self::String(text.to_string())),
            other => Self::from_yaml(&other),
        }
    }

    /// Converts a YAML value of a parameter file or command line.
    pub fn from_yaml(value: &Value) -> Result<Self, String> {
        match value {
            Value::Bool(b) => Ok(Self::Bool(*b)),
            Value::Number(n) => {
                if let Some(i) = n.as_i64() {
                    Ok(Self::Integer(i))
                } else if let Some(f) = n.as_f64() {
                    Ok(Self::Double(f))
                } else {
                    Err(format!(
                        "number {n} does not fit a 64-bit integer or double"
                    ))
                }
            }
            Value::String(s) => Ok(Self::String(s.clone())),
            Value::Sequence(items) => Self::from_sequence(items),
            Value::Null => Err("empty value (null) is not a parameter value".into()),
            Value::Mapping(_) => Err("a mapping is not a parameter value".into()),
            Value::Tagged(t) => Self::from_yaml(&t.value),
        }
    }

    fn from_sequence(items: &[Value]) -> Result<Self, String> {
        let scalars = items
            .iter()
            .map(Self::from_yaml)
            .collect::<Result<Vec<_>, _>>()?;
        let all = |pred: fn(&ParamValue) -> bool| scalars.iter().all(pred);
        if scalars.is_empty() {
            // An empty list carries no element type; rcl rejects it too.
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
        } else if all(|v| matches!(v, Self::Integer(_) | Self::Double(_))) {
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
            Err("a list must hold values of one type (bools, numbers or strings)".into())
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

/// The resolved start-up parameters of a node.
#[derive(Debug, Clone, Default)]
pub struct Parameters {
    values: BTreeMap<String, ParamValue>,
}

impl Parameters {
    /// Defaults of `decls`, overridden by parameter files (in order), then by `-p` overrides.
    pub fn resolve(
        decls: &[ParamDecl],
        node_fqn: &str,
        files: &[std::path::PathBuf],
        overrides: &[(String, ParamValue)],
    ) -> Result<Self, RosError> {
        let mut values: BTreeMap<String, ParamValue> = decls
            .iter()
            .map(|d| (d.name.clone(), d.default.clone()))
            .collect();
        let mut set =
            |name: &str, value: ParamValue, source: &str, strict: bool| -> Result<(), RosError> {
                let Some(declared) = values.get(name) else {
                    if strict {
                        return Err(RosError::Parameter {
                            name: name.to_string(),
                            reason: format!(
                                "unknown parameter (from {source}); this node declares: {}",
                                decl_names(decls)
                            ),
                        });
                    }
                    return Ok(());
                };
                let given_type = value.type_name();
                let coerced = declared
                    .coerce_like(value)
                    .ok_or_else(|| RosError::Parameter {
                        name: name.to_string(),
                        reason: format!(
                            "expected {} but {source} gives {given_type}",
                            declared.type_name()
                        ),
                    })?;
                values.insert(name.to_string(), coerced);
                Ok(())
            };
        for file in files {
            for entry in read_params_file(file, node_fqn)? {
                let source = format!("parameter file {}", file.display());
                set(&entry.name, entry.value, &source, !entry.wildcard)?;
            }
        }
        for (name, value) in overrides {
            set(name, value.clone(), "-p on the command line", true)?;
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

/// One value of a parameter file that applies to a node.
#[derive(Debug, Clone, PartialEq)]
pub struct FileParam {
    pub name: String,
    pub value: ParamValue,
    /// From a `/**` section shared by all nodes: names the node does not declare are ignored.
    pub wildcard: bool,
}

/// Reads a ROS 2 parameter file (`node_name: ros__parameters: {...}`) and returns the values
/// that apply to the node `node_fqn` (`/ns/name`): sections `/**`, `/**/name`, `name`,
/// `/ns/name` or `ns/name`, in file order. Nested mappings become dotted names, as in rcl.
pub fn read_params_file(path: &Path, node_fqn: &str) -> Result<Vec<FileParam>, RosError> {
    let err = |reason: String| RosError::ParamsFile {
        path: path.to_path_buf(),
        reason,
    };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    parse_params_yaml(&text, node_fqn).map_err(err)
}

/// [`read_params_file`] on text.
pub fn parse_params_yaml(text: &str, node_fqn: &str) -> Result<Vec<FileParam>, String> {
    let root: Value = serde_yaml_ng::from_str(text).map_err(|e| format!("not YAML: {e}"))?;
    let Value::Mapping(sections) = root else {
        return Err("expected a mapping of node names at the top level".into());
    };
    let base = node_fqn.rsplit('/').next().unwrap_or(node_fqn);
    let mut out = Vec::new();
    for (key, section) in &sections {
        let Some(key) = key.as_str() else {
            return Err(format!("top-level key {key:?} is not a node name"));
        };
        let wildcard = key == "/**";
        let applies = wildcard
            || key == base
            || key == node_fqn
            || format!("/{key}") == node_fqn
            || key.strip_prefix("/**/").is_some_and(|k| k == base);
        if !applies {
            continue;
        }
        let params = section
            .as_mapping()
            .and_then(|m| m.get("ros__parameters"))
            .ok_or_else(|| format!("section `{key}` has no `ros__parameters` mapping"))?;
        flatten(params, "", wildcard, &mut out).map_err(|e| format!("section `{key}`: {e}"))?;
    }
    Ok(out)
}

fn flatten(
    value: &Value,
    prefix: &str,
    wildcard: bool,
    out: &mut Vec<FileParam>,
) -> Result<(), String> {
    let Value::Mapping(map) = value else {
        return Err(format!(
            "`{}` must be a mapping of parameter names",
            prefix.trim_end_matches('.')
        ));
    };
    for (k, v) in map {
        let key = match k {
            Value::String(s) => s.clone(),
            other => serde_yaml_ng::to_string(other)
                .map_err(|e| e.to_string())?
                .trim()
                .to_string(),
        };
        let name = format!("{prefix}{key}");
        if v.is_mapping() {
            flatten(v, &format!("{name}."), wildcard, out)?;
        } else {
            let value = ParamValue::from_yaml(v).map_err(|e| format!("parameter `{name}`: {e}"))?;
            out.push(FileParam {
                name,
                value,
                wildcard,
            });
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

    #[test]
    fn cli_values_are_typed_like_yaml() {
        assert_eq!(ParamValue::parse_cli("3").unwrap(), ParamValue::Integer(3));
        assert_eq!(
            ParamValue::parse_cli("3.5").unwrap(),
            ParamValue::Double(3.5)
        );
        assert_eq!(
            ParamValue::parse_cli("true").unwrap(),
            ParamValue::Bool(true)
        );
        assert_eq!(
            ParamValue::parse_cli("hello").unwrap(),
            ParamValue::String("hello".into())
        );
        assert_eq!(
            ParamValue::parse_cli("[1, 2.5]").unwrap(),
            ParamValue::DoubleArray(vec![1.0, 2.5])
        );
        assert_eq!(
            ParamValue::parse_cli("[/scan, /odom]").unwrap(),
            ParamValue::StringArray(vec!["/scan".into(), "/odom".into()])
        );
        assert!(ParamValue::parse_cli("[1, abc]").is_err());
        assert!(ParamValue::parse_cli("[]").is_err());
        assert_eq!(
            ParamValue::parse_cli("").unwrap(),
            ParamValue::String(String::new())
        );
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
other:
  ros__parameters:
    rate: 9.0
"#;
        let got = parse_params_yaml(yaml, "/replay").unwrap();
        let names: Vec<_> = got.iter().map(|p| (p.name.as_str(), p.wildcard)).collect();
        assert_eq!(
            names,
            vec![
                ("use_sim_time", true),
                ("rate", true),
                ("loop", false),
                ("nested.a", false)
            ]
        );
        let in_ns = parse_params_yaml(yaml, "/other_ns/replay").unwrap();
        assert!(
            in_ns
                .iter()
                .any(|p| p.name == "loop" && p.value == ParamValue::Bool(false))
        );
    }

    #[test]
    fn params_file_errors_name_the_problem() {
        assert!(
            parse_params_yaml("replay: {rate: 1}", "/replay")
                .unwrap_err()
                .contains("ros__parameters")
        );
        assert!(
            parse_params_yaml("- a", "/replay")
                .unwrap_err()
                .contains("top level")
        );
        assert!(
            parse_params_yaml("replay: {ros__parameters: {x: null}}", "/replay")
                .unwrap_err()
                .contains("`x`")
        );
        assert!(parse_params_yaml(":\n  - [", "/replay").is_err());
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
