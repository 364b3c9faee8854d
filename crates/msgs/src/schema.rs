//! Message definitions (.msg texts), the full schema text rosbag2 writes into MCAP files,
//! and a small .msg parser used to keep the texts, the mirrors and `msg/` in sync.

use std::collections::BTreeMap;

use crate::RosMessage;

/// A message type's own .msg text and the definitions of the message types its fields use.
#[derive(Debug)]
pub struct MessageDefinition {
    /// The full type name, e.g. `nav_msgs/msg/Odometry`.
    pub type_name: &'static str,
    /// The type's .msg text (fields, constants, comments), as in its ROS package.
    pub text: &'static str,
    /// The message types its fields use directly, in field order.
    pub dependencies: &'static [&'static MessageDefinition],
    /// The RIHS01 type description hash (`RIHS01_` and 64 hex digits) that ROS 2 Iron and
    /// later compute from the type's fields (not its constants or comments): rosbag2 records
    /// it per topic, and rmw implementations announce it with their endpoints. A constant, since the
    /// definitions are; `tests/tests/bag_python.rs` recomputes every one from
    /// [`Self::schema_text`] with rosbags' `hash_rihs01`.
    pub type_hash: &'static str,
}

/// The line rosbag2 puts between the definitions of a schema.
const SEPARATOR: &str =
    "================================================================================";

impl MessageDefinition {
    /// The type's .msg text followed, for every dependency (recursively, each once, depth
    /// first), by a line of 80 `=`, `MSG: pkg/Type` and its .msg text: the `ros2msg` schema
    /// encoding of rosbag2's MCAP storage.
    pub fn schema_text(&self) -> String {
        let mut out = self.text.trim_end().to_owned();
        let mut seen = vec![self.type_name];
        append_dependencies(self, &mut seen, &mut out);
        out.push('\n');
        out
    }

    /// `pkg/Type`, the form rosbag2 writes after `MSG:` (without the `msg/` part).
    pub fn short_name(&self) -> String {
        self.type_name.replacen("/msg/", "/", 1)
    }

    /// The package part of the type name, e.g. `nav_msgs`.
    pub fn package(&self) -> &'static str {
        self.type_name.split('/').next().unwrap_or(self.type_name)
    }
}

fn append_dependencies(def: &MessageDefinition, seen: &mut Vec<&'static str>, out: &mut String) {
    for dep in def.dependencies {
        if seen.contains(&dep.type_name) {
            continue;
        }
        seen.push(dep.type_name);
        out.push('\n');
        out.push_str(SEPARATOR);
        out.push_str("\nMSG: ");
        out.push_str(&dep.short_name());
        out.push('\n');
        out.push_str(dep.text.trim_end());
        append_dependencies(dep, seen, out);
    }
}

/// Every message type this crate mirrors, including those only used as fields.
pub const ALL: &[&MessageDefinition] = {
    use crate::{
        builtin_interfaces as bi, diagnostic_msgs as dm, geometry_msgs as gm, lidar_har_msgs as lh,
        nav_msgs as nm, rcl_interfaces as rc, rosgraph_msgs as rg, sensor_msgs as sm,
        std_msgs as st, tf2_msgs as tf, visualization_msgs as vm,
    };
    &[
        &bi::Time::DEFINITION,
        &bi::Duration::DEFINITION,
        &st::Header::DEFINITION,
        &st::ColorRGBA::DEFINITION,
        &gm::Point::DEFINITION,
        &gm::Point32::DEFINITION,
        &gm::Quaternion::DEFINITION,
        &gm::Vector3::DEFINITION,
        &gm::Pose::DEFINITION,
        &gm::PoseStamped::DEFINITION,
        &gm::PoseWithCovariance::DEFINITION,
        &gm::PoseWithCovarianceStamped::DEFINITION,
        &gm::Twist::DEFINITION,
        &gm::TwistWithCovariance::DEFINITION,
        &gm::Transform::DEFINITION,
        &gm::TransformStamped::DEFINITION,
        &sm::LaserScan::DEFINITION,
        &sm::CompressedImage::DEFINITION,
        &nm::Odometry::DEFINITION,
        &nm::OccupancyGrid::DEFINITION,
        &nm::MapMetaData::DEFINITION,
        &tf::TFMessage::DEFINITION,
        &rg::Clock::DEFINITION,
        &vm::Marker::DEFINITION,
        &vm::MarkerArray::DEFINITION,
        &vm::UVCoordinate::DEFINITION,
        &vm::MeshFile::DEFINITION,
        &dm::DiagnosticArray::DEFINITION,
        &dm::DiagnosticStatus::DEFINITION,
        &dm::KeyValue::DEFINITION,
        &rc::Log::DEFINITION,
        &lh::Activity::DEFINITION,
        &lh::FallAlert::DEFINITION,
        &lh::HumanObservation::DEFINITION,
    ]
};

/// The definition of a mirrored type by name: `pkg/msg/Type` (or `pkg/Type`).
pub fn definition(type_name: &str) -> Option<&'static MessageDefinition> {
    ALL.iter()
        .copied()
        .find(|def| def.type_name == type_name || def.short_name() == type_name)
}

/// The RIHS01 hash of our definition of `type_name` where `schema_text` (a `ros2msg` schema,
/// as a bag stores it) declares the same fields as ours, in the type and in each dependency:
/// the hash covers field names and types only, so comments, constants, default values and the
/// order of the dependency sections do not matter. `None` for a type we do not mirror, or for
/// a schema of other fields (Foxy's Marker, say), whose hash ours is not.
pub fn type_hash_of(type_name: &str, schema_text: &str) -> Option<&'static str> {
    let ours = definition(type_name)?;
    let same = schema_fields(ours.type_name, &ours.schema_text())?
        == schema_fields(ours.type_name, schema_text)?;
    same.then_some(ours.type_hash)
}

/// Each section of a schema: full type name -> its fields (type, name) in order.
type SchemaFields = BTreeMap<String, Vec<(String, String)>>;

/// The fields of every section of a `ros2msg` schema whose first section is `type_name`;
/// `None` where a section does not parse (an IDL schema, a separator without `MSG:` line).
fn schema_fields(type_name: &str, schema_text: &str) -> Option<SchemaFields> {
    let mut sections = SchemaFields::new();
    let mut section = (type_name.to_owned(), String::new());
    let mut lines = schema_text.lines();
    while let Some(line) = lines.next() {
        let trimmed = line.trim();
        if !trimmed.is_empty() && trimmed.chars().all(|c| c == '=') {
            let name = lines.next()?.trim().strip_prefix("MSG:")?.trim();
            let next = (field_message_type(name, "")?, String::new());
            let (done, text) = std::mem::replace(&mut section, next);
            sections.insert(done.clone(), section_fields(&done, &text)?);
        } else {
            section.1.push_str(line);
            section.1.push('\n');
        }
    }
    let fields = section_fields(&section.0, &section.1)?;
    sections.insert(section.0, fields);
    Some(sections)
}

/// The fields of the .msg text of `type_name`, message types written `pkg/msg/Type` (then
/// any array suffix) whichever way the text writes them.
fn section_fields(type_name: &str, text: &str) -> Option<Vec<(String, String)>> {
    let package = type_name.split('/').next().unwrap_or(type_name);
    let items = parse_msg(text).ok()?;
    Some(
        items
            .into_iter()
            .filter_map(|item| match item {
                MsgItem::Field { ty, name } => {
                    let ty = match field_message_type(&ty, package) {
                        Some(full) => format!("{full}{}", &ty[element_type(&ty).len()..]),
                        None => ty,
                    };
                    Some((ty, name))
                }
                MsgItem::Constant { .. } => None,
            })
            .collect(),
    )
}

/// One line of a .msg file that declares something.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MsgItem {
    /// `type name` or `type name default`: a field (its default value is not kept).
    Field { ty: String, name: String },
    /// `type NAME=value`: a constant, with its value as written.
    Constant {
        ty: String,
        name: String,
        value: String,
    },
}

/// A line of a .msg text that is neither a field nor a constant.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line}: cannot parse '{text}' as a field or a constant")]
pub struct MsgParseError {
    pub line: usize,
    pub text: String,
}

/// Parses the fields and constants of a .msg text, in order; comments and blank lines are
/// skipped. Only what ROS 2 .msg files use is understood: `type name [default]`,
/// `type NAME=value`, types with `[]`, `[N]`, `[<=N]` and bounded strings.
pub fn parse_msg(text: &str) -> Result<Vec<MsgItem>, MsgParseError> {
    let mut items = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let code = raw.split('#').next().unwrap_or("").trim();
        if code.is_empty() {
            continue;
        }
        let error = || MsgParseError {
            line: index + 1,
            text: raw.to_owned(),
        };
        let (ty, rest) = code.split_once(char::is_whitespace).ok_or_else(error)?;
        let rest = rest.trim();
        let item = match rest.split_once('=') {
            Some((name, value)) => MsgItem::Constant {
                ty: ty.to_owned(),
                name: name.trim().to_owned(),
                value: value.trim().to_owned(),
            },
            None => {
                let name = rest.split_whitespace().next().ok_or_else(error)?;
                MsgItem::Field {
                    ty: ty.to_owned(),
                    name: name.to_owned(),
                }
            }
        };
        let name = match &item {
            MsgItem::Field { name, .. } | MsgItem::Constant { name, .. } => name,
        };
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(error());
        }
        items.push(item);
    }
    Ok(items)
}

/// The ROS primitive types (the element type of a field, without array brackets).
const PRIMITIVES: &[&str] = &[
    "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
    "uint64", "float32", "float64", "string", "wstring",
];

/// The element type of a field type: `geometry_msgs/Point[]` -> `geometry_msgs/Point`,
/// `string<=5` -> `string`.
pub fn element_type(ty: &str) -> &str {
    let ty = ty.split('[').next().unwrap_or(ty);
    ty.split("<=").next().unwrap_or(ty)
}

/// The full name (`pkg/msg/Type`) of a field's message type, or `None` for a primitive;
/// a name without package is resolved in `package` (and `Header` is `std_msgs/Header`).
pub fn field_message_type(ty: &str, package: &str) -> Option<String> {
    let element = element_type(ty);
    if PRIMITIVES.contains(&element) {
        return None;
    }
    Some(match element.split_once('/') {
        Some((pkg, name)) => format!("{pkg}/msg/{}", name.rsplit('/').next().unwrap_or(name)),
        None if element == "Header" => "std_msgs/msg/Header".to_owned(),
        None => format!("{package}/msg/{element}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_definition_parses_and_lists_exactly_the_types_its_fields_use() {
        for def in ALL {
            let items = parse_msg(def.text).unwrap_or_else(|e| panic!("{}: {e}", def.type_name));
            let mut used: Vec<String> = Vec::new();
            for item in &items {
                if let MsgItem::Field { ty, .. } = item
                    && let Some(full) = field_message_type(ty, def.package())
                    && !used.contains(&full)
                {
                    used.push(full);
                }
            }
            let declared: Vec<&str> = def.dependencies.iter().map(|d| d.type_name).collect();
            assert_eq!(
                used, declared,
                "{}: dependencies differ from its fields",
                def.type_name
            );
        }
    }

    #[test]
    fn every_type_is_listed_once_and_every_dependency_is_listed() {
        for (i, def) in ALL.iter().enumerate() {
            assert!(
                ALL[..i]
                    .iter()
                    .all(|other| other.type_name != def.type_name),
                "{} listed twice",
                def.type_name
            );
            for dep in def.dependencies {
                assert!(
                    definition(dep.type_name).is_some(),
                    "{} not in ALL",
                    dep.type_name
                );
            }
        }
    }

    #[test]
    fn schema_text_has_rosbag2_layout_with_each_dependency_once() {
        let text = crate::nav_msgs::Odometry::DEFINITION.schema_text();
        assert!(text.starts_with("std_msgs/Header header\n"), "{text}");
        let sections: Vec<&str> = text.split(&format!("\n{SEPARATOR}\n")).collect();
        let names: Vec<&str> = sections[1..]
            .iter()
            .map(|s| s.lines().next().unwrap_or_default())
            .collect();
        assert_eq!(
            names,
            [
                "MSG: std_msgs/Header",
                "MSG: builtin_interfaces/Time",
                "MSG: geometry_msgs/PoseWithCovariance",
                "MSG: geometry_msgs/Pose",
                "MSG: geometry_msgs/Point",
                "MSG: geometry_msgs/Quaternion",
                "MSG: geometry_msgs/TwistWithCovariance",
                "MSG: geometry_msgs/Twist",
                "MSG: geometry_msgs/Vector3",
            ]
        );
        assert!(text.ends_with("float64 z\n"));
    }

    /// A hash rosbag2 records is `RIHS01_` and 64 lowercase hex digits; two types never share
    /// one (the type name is hashed too). Their values are checked by `bag_python.rs`.
    #[test]
    fn every_type_has_a_rihs01_hash_of_its_own() {
        for (i, def) in ALL.iter().enumerate() {
            let hex = def.type_hash.strip_prefix("RIHS01_").unwrap_or_default();
            assert!(
                hex.len() == 64 && hex.chars().all(|c| matches!(c, '0'..='9' | 'a'..='f')),
                "{}: `{}` is not a RIHS01 hash",
                def.type_name,
                def.type_hash
            );
            assert!(
                ALL[..i]
                    .iter()
                    .all(|other| other.type_hash != def.type_hash),
                "{}: hash shared with another type",
                def.type_name
            );
        }
    }

    /// Our hash goes with a schema of our fields however it is written (rosbag2 keeps the
    /// comments, rosbags writes `MSG: pkg/msg/Type`, bare names in the package), never with
    /// other fields.
    #[test]
    fn a_known_type_hash_goes_only_with_a_schema_of_its_fields() {
        use crate::visualization_msgs::Marker;
        let ours = Marker::DEFINITION.schema_text();
        assert_eq!(
            type_hash_of("visualization_msgs/msg/Marker", &ours),
            Some(Marker::DEFINITION.type_hash)
        );
        let rewritten = format!("# a comment\nint32 NEW=12\n{}", ours)
            .replace("MSG: std_msgs/Header", "MSG: std_msgs/msg/Header")
            .replace("std_msgs/Header header", "Header header  # stamped");
        assert_eq!(
            type_hash_of("visualization_msgs/Marker", &rewritten),
            Some(Marker::DEFINITION.type_hash),
            "{rewritten}"
        );
        let foxy = ours.replace("bool mesh_use_embedded_materials\n", "");
        assert_ne!(foxy, ours);
        assert_eq!(type_hash_of("visualization_msgs/msg/Marker", &foxy), None);
        let point = crate::geometry_msgs::Point::DEFINITION.schema_text();
        assert_eq!(
            type_hash_of(
                "geometry_msgs/msg/Point",
                &point.replace("float64 z", "float32 z")
            ),
            None
        );
        assert_eq!(type_hash_of("std_msgs/msg/String", "string data\n"), None);
        assert_eq!(
            type_hash_of("geometry_msgs/msg/Point", "struct Point { double x; };"),
            None,
            "an IDL schema is not ours"
        );
    }

    #[test]
    fn a_type_without_dependencies_is_its_own_text() {
        let text = crate::geometry_msgs::Point::DEFINITION.schema_text();
        assert_eq!(text, "float64 x\nfloat64 y\nfloat64 z\n");
    }

    #[test]
    fn lookup_by_full_and_short_name() {
        assert_eq!(
            definition("sensor_msgs/msg/LaserScan").map(|d| d.type_name),
            Some("sensor_msgs/msg/LaserScan")
        );
        assert_eq!(
            definition("std_msgs/Header").map(|d| d.type_name),
            Some("std_msgs/msg/Header")
        );
        assert!(definition("sensor_msgs/msg/Image").is_none());
    }

    #[test]
    fn parser_reads_fields_constants_defaults_and_rejects_garbage() {
        let items = parse_msg(
            "# comment\nuint8 A=3 # c\n\nfloat64 x 0\ngeometry_msgs/Point[] pts\nstring<=4 s\n",
        )
        .unwrap();
        assert_eq!(
            items,
            [
                MsgItem::Constant {
                    ty: "uint8".into(),
                    name: "A".into(),
                    value: "3".into()
                },
                MsgItem::Field {
                    ty: "float64".into(),
                    name: "x".into()
                },
                MsgItem::Field {
                    ty: "geometry_msgs/Point[]".into(),
                    name: "pts".into()
                },
                MsgItem::Field {
                    ty: "string<=4".into(),
                    name: "s".into()
                },
            ]
        );
        assert_eq!(parse_msg("float64\n").unwrap_err().line, 1);
        assert_eq!(
            parse_msg("int32 ok\nfloat64 bad-name\n").unwrap_err().line,
            2
        );
        assert_eq!(
            field_message_type("Header", "x"),
            Some("std_msgs/msg/Header".into())
        );
        assert_eq!(
            field_message_type("UVCoordinate[]", "visualization_msgs"),
            Some("visualization_msgs/msg/UVCoordinate".into())
        );
        assert_eq!(field_message_type("float32[36]", "x"), None);
    }
}
