//! Keeps three things in step: the .msg texts (for our own types, the files of the ROS 2
//! interface package in `msg/`), the serde mirrors, and the constants.
//!
//! The mirrors' fields are read with a small serde `Serializer` that records the shape of a
//! value (struct names, field names in order, primitive types, array lengths) and compared
//! with the fields parsed from the .msg text: a field added, renamed, retyped or moved in
//! one place only fails here.

mod common;

use std::fmt;
use std::path::Path;

use common::sample;
use lidar_har_msgs::schema::{self, MsgItem, element_type, parse_msg};
use lidar_har_msgs::{RosMessage, lidar_har_msgs as lh};
use serde::Serialize;
use serde::ser::{self, Impossible};

/// What serde sees of a value.
#[derive(Debug, Clone, PartialEq)]
enum Shape {
    Primitive(&'static str),
    /// A variable-length sequence and the shape of its first element, if any.
    Sequence(Option<Box<Shape>>),
    /// A fixed-length array (serde tuple).
    Array(usize, Option<Box<Shape>>),
    Struct(&'static str, Vec<(&'static str, Shape)>),
}

#[derive(Debug)]
struct Unsupported(String);
impl fmt::Display for Unsupported {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for Unsupported {}
impl ser::Error for Unsupported {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        Unsupported(msg.to_string())
    }
}

struct ShapeOf;

macro_rules! primitive {
    ($($method:ident: $ty:ty => $name:literal),* $(,)?) => {
        $(fn $method(self, _: $ty) -> Result<Shape, Unsupported> { Ok(Shape::Primitive($name)) })*
    };
}

macro_rules! unsupported {
    ($what:expr) => {
        Err(Unsupported(format!("a ROS message has no {}", $what)))
    };
}

impl ser::Serializer for ShapeOf {
    type Ok = Shape;
    type Error = Unsupported;
    type SerializeSeq = Elements;
    type SerializeTuple = Elements;
    type SerializeTupleStruct = Impossible<Shape, Unsupported>;
    type SerializeTupleVariant = Impossible<Shape, Unsupported>;
    type SerializeMap = Impossible<Shape, Unsupported>;
    type SerializeStruct = Fields;
    type SerializeStructVariant = Impossible<Shape, Unsupported>;

    primitive! {
        serialize_bool: bool => "bool", serialize_i8: i8 => "int8", serialize_u8: u8 => "uint8",
        serialize_i16: i16 => "int16", serialize_u16: u16 => "uint16", serialize_i32: i32 => "int32",
        serialize_u32: u32 => "uint32", serialize_i64: i64 => "int64", serialize_u64: u64 => "uint64",
        serialize_f32: f32 => "float32", serialize_f64: f64 => "float64", serialize_str: &str => "string",
    }
    fn serialize_char(self, _: char) -> Result<Shape, Unsupported> {
        unsupported!("Rust char")
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<Shape, Unsupported> {
        Ok(Shape::Sequence(Some(Box::new(Shape::Primitive("uint8")))))
    }
    fn serialize_none(self) -> Result<Shape, Unsupported> {
        unsupported!("Option")
    }
    fn serialize_some<T: ?Sized + Serialize>(self, _: &T) -> Result<Shape, Unsupported> {
        unsupported!("Option")
    }
    fn serialize_unit(self) -> Result<Shape, Unsupported> {
        unsupported!("unit")
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<Shape, Unsupported> {
        unsupported!("unit struct")
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
    ) -> Result<Shape, Unsupported> {
        unsupported!("enum")
    }
    fn serialize_newtype_struct<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        _: &T,
    ) -> Result<Shape, Unsupported> {
        unsupported!("newtype")
    }
    fn serialize_newtype_variant<T: ?Sized + Serialize>(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: &T,
    ) -> Result<Shape, Unsupported> {
        unsupported!("enum")
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Elements, Unsupported> {
        Ok(Elements {
            fixed_len: None,
            count: 0,
            first: None,
        })
    }
    fn serialize_tuple(self, len: usize) -> Result<Elements, Unsupported> {
        Ok(Elements {
            fixed_len: Some(len),
            count: 0,
            first: None,
        })
    }
    fn serialize_tuple_struct(
        self,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeTupleStruct, Unsupported> {
        unsupported!("tuple struct")
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeTupleVariant, Unsupported> {
        unsupported!("enum")
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Self::SerializeMap, Unsupported> {
        unsupported!("map")
    }
    fn serialize_struct(self, name: &'static str, _: usize) -> Result<Fields, Unsupported> {
        Ok(Fields {
            name,
            fields: Vec::new(),
        })
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Self::SerializeStructVariant, Unsupported> {
        unsupported!("enum")
    }
}

struct Elements {
    fixed_len: Option<usize>,
    count: usize,
    first: Option<Box<Shape>>,
}

impl Elements {
    fn push<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Unsupported> {
        let shape = value.serialize(ShapeOf)?;
        if self.first.is_none() {
            self.first = Some(Box::new(shape));
        }
        self.count += 1;
        Ok(())
    }
    fn finish(self) -> Shape {
        match self.fixed_len {
            Some(len) => Shape::Array(len, self.first),
            None => Shape::Sequence(self.first),
        }
    }
}

impl ser::SerializeSeq for Elements {
    type Ok = Shape;
    type Error = Unsupported;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Unsupported> {
        self.push(value)
    }
    fn end(self) -> Result<Shape, Unsupported> {
        Ok(self.finish())
    }
}

impl ser::SerializeTuple for Elements {
    type Ok = Shape;
    type Error = Unsupported;
    fn serialize_element<T: ?Sized + Serialize>(&mut self, value: &T) -> Result<(), Unsupported> {
        self.push(value)
    }
    fn end(self) -> Result<Shape, Unsupported> {
        Ok(self.finish())
    }
}

struct Fields {
    name: &'static str,
    fields: Vec<(&'static str, Shape)>,
}

impl ser::SerializeStruct for Fields {
    type Ok = Shape;
    type Error = Unsupported;
    fn serialize_field<T: ?Sized + Serialize>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), Unsupported> {
        self.fields.push((key, value.serialize(ShapeOf)?));
        Ok(())
    }
    fn end(self) -> Result<Shape, Unsupported> {
        Ok(Shape::Struct(self.name, self.fields))
    }
}

/// The serde shape a .msg field type must have; `Err` says why `shape` does not fit.
fn check_field(ty: &str, shape: &Shape) -> Result<(), String> {
    let element = element_type(ty);
    let suffix = &ty[element.len()..];
    let element_shape = match (suffix, shape) {
        ("", _) => Some(shape),
        (s, Shape::Sequence(first)) if s == "[]" || s.starts_with("[<=") => first.as_deref(),
        (s, Shape::Array(len, first)) if s == format!("[{len}]") => first.as_deref(),
        (s, _) if s.starts_with("<=") => Some(shape), // bounded string
        _ => return Err(format!("{ty} is not {shape:?}")),
    };
    let Some(element_shape) = element_shape else {
        return Ok(()); // empty sequence: nothing to compare the element with
    };
    let expected_primitive = match element {
        "byte" | "char" => Some("uint8"),
        "bool" | "int8" | "uint8" | "int16" | "uint16" | "int32" | "uint32" | "int64"
        | "uint64" | "float32" | "float64" | "string" => Some(element),
        _ => None,
    };
    match (expected_primitive, element_shape) {
        (Some(p), Shape::Primitive(q)) if p == *q => Ok(()),
        (None, Shape::Struct(name, _)) if element.rsplit('/').next() == Some(*name) => Ok(()),
        _ => Err(format!("element of {ty} is {element_shape:?}")),
    }
}

/// Compares a value's serde shape with the fields of its .msg text.
fn check_layout<M: RosMessage>(value: &M) -> Result<(), String> {
    let shape = value.serialize(ShapeOf).map_err(|e| e.to_string())?;
    let Shape::Struct(name, fields) = shape else {
        return Err(format!("not a struct: {shape:?}"));
    };
    let type_short = M::TYPE_NAME.rsplit('/').next().unwrap_or_default();
    if name != type_short {
        return Err(format!(
            "Rust struct is named {name}, the type {type_short}"
        ));
    }
    let items = parse_msg(M::DEFINITION.text).map_err(|e| e.to_string())?;
    let msg_fields: Vec<(&str, &str)> = items
        .iter()
        .filter_map(|item| match item {
            MsgItem::Field { ty, name } => Some((ty.as_str(), name.as_str())),
            MsgItem::Constant { .. } => None,
        })
        .collect();
    let rust_names: Vec<&str> = fields.iter().map(|(n, _)| *n).collect();
    let msg_names: Vec<&str> = msg_fields.iter().map(|(_, n)| *n).collect();
    if rust_names != msg_names {
        return Err(format!(
            "fields differ:\n  Rust: {rust_names:?}\n  .msg: {msg_names:?}"
        ));
    }
    for ((ty, field), (_, shape)) in msg_fields.iter().zip(&fields) {
        check_field(ty, shape).map_err(|e| format!("field {field}: {e}"))?;
    }
    Ok(())
}

fn layout<M: RosMessage>() -> Option<String> {
    check_layout(&sample::<M>())
        .err()
        .map(|e| format!("{}: {e}", M::TYPE_NAME))
}

macro_rules! layout_of {
    ($ty:ty) => {
        layout::<$ty>()
    };
}

#[test]
fn every_mirror_has_the_fields_of_its_msg_text_in_order_with_matching_types() {
    let failures: Vec<String> = for_every_type!(layout_of).into_iter().flatten().collect();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_layout_check_notices_a_reordered_or_missing_field() {
    #[derive(Serialize, serde::Deserialize)]
    struct Activity {
        header: lidar_har_msgs::std_msgs::Header,
        label: String,
        activity: u8,
        confidence: f32,
        probabilities: Vec<f32>,
    }
    impl RosMessage for Activity {
        const TYPE_NAME: &'static str = lh::Activity::TYPE_NAME;
        const DEFINITION: lidar_har_msgs::MessageDefinition = lh::Activity::DEFINITION;
    }
    let swapped = Activity {
        header: Default::default(),
        label: String::new(),
        activity: 0,
        confidence: 0.0,
        probabilities: vec![],
    };
    let error = check_layout(&swapped).unwrap_err();
    assert!(error.contains("fields differ"), "{error}");

    #[derive(Serialize, serde::Deserialize)]
    struct Point {
        x: f64,
        y: f32,
        z: f64,
    }
    impl RosMessage for Point {
        const TYPE_NAME: &'static str = lidar_har_msgs::geometry_msgs::Point::TYPE_NAME;
        const DEFINITION: lidar_har_msgs::MessageDefinition =
            lidar_har_msgs::geometry_msgs::Point::DEFINITION;
    }
    let error = check_layout(&Point {
        x: 0.0,
        y: 0.0,
        z: 0.0,
    })
    .unwrap_err();
    assert!(error.contains("field y"), "{error}");
}

/// The interface package's .msg files, by type name.
fn package_msg_files() -> Vec<(String, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../msg/msg");
    let mut files: Vec<(String, String)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.expect("readable msg/msg").path())
        .filter(|path| path.extension().is_some_and(|e| e == "msg"))
        .map(|path| {
            let stem = path
                .file_stem()
                .and_then(|s| s.to_str())
                .expect("UTF-8 file name")
                .to_owned();
            let text = std::fs::read_to_string(&path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            (format!("lidar_har_msgs/msg/{stem}"), text)
        })
        .collect();
    files.sort();
    files
}

#[test]
fn every_msg_file_of_the_interface_package_is_mirrored_with_its_exact_text() {
    let files = package_msg_files();
    let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "lidar_har_msgs/msg/Activity",
            "lidar_har_msgs/msg/FallAlert",
            "lidar_har_msgs/msg/HumanObservation"
        ]
    );
    for (name, text) in &files {
        let def = schema::definition(name).unwrap_or_else(|| panic!("{name} has no Rust mirror"));
        assert_eq!(def.text, text, "{name}: schema text is not the .msg file");
    }
    let cmake = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../msg/CMakeLists.txt"),
    )
    .unwrap();
    for (name, _) in &files {
        let file = format!(
            "\"msg/{}.msg\"",
            name.rsplit('/').next().unwrap_or_default()
        );
        assert!(
            cmake.contains(&file),
            "CMakeLists.txt does not generate {file}"
        );
    }
}

/// The constants of a .msg text as (name, type, value).
fn msg_constants(text: &str) -> Vec<(String, String, i64)> {
    parse_msg(text)
        .unwrap()
        .into_iter()
        .filter_map(|item| match item {
            MsgItem::Constant { ty, name, value } => Some((
                name,
                ty,
                value
                    .parse()
                    .unwrap_or_else(|_| panic!("constant value {value} is not an integer")),
            )),
            MsgItem::Field { .. } => None,
        })
        .collect()
}

fn assert_constants(def: &lidar_har_msgs::MessageDefinition, rust: &[(&str, &str, i64)]) {
    let rust: Vec<(String, String, i64)> = rust
        .iter()
        .map(|(n, t, v)| (n.to_string(), t.to_string(), *v))
        .collect();
    assert_eq!(
        msg_constants(def.text),
        rust,
        "{}: constants of the .msg and of the mirror differ",
        def.type_name
    );
}

#[test]
fn constants_of_the_mirrors_equal_those_of_the_msg_texts() {
    use lh::{Activity as A, FallAlert as F};
    use lidar_har_msgs::diagnostic_msgs::DiagnosticStatus as D;
    use lidar_har_msgs::rcl_interfaces::Log as L;
    use lidar_har_msgs::visualization_msgs::Marker as M;
    let u = |v: u8| i64::from(v);
    assert_constants(
        &A::DEFINITION,
        &[
            ("CRAWLING", "uint8", u(A::CRAWLING)),
            ("FALLING_DOWN", "uint8", u(A::FALLING_DOWN)),
            ("GETTING_UP", "uint8", u(A::GETTING_UP)),
            ("LYING_DOWN", "uint8", u(A::LYING_DOWN)),
            ("RUNNING", "uint8", u(A::RUNNING)),
            ("SITTING_ON_FLOOR", "uint8", u(A::SITTING_ON_FLOOR)),
            ("STANDING", "uint8", u(A::STANDING)),
            ("WALKING", "uint8", u(A::WALKING)),
            ("WALKING_UNSTEADILY", "uint8", u(A::WALKING_UNSTEADILY)),
            ("NUM_CLASSES", "uint8", u(A::NUM_CLASSES)),
        ],
    );
    assert_constants(
        &F::DEFINITION,
        &[
            ("FALL_DETECTED", "uint8", u(F::FALL_DETECTED)),
            ("PERSON_DOWN", "uint8", u(F::PERSON_DOWN)),
        ],
    );
    assert_constants(
        &D::DEFINITION,
        &[
            ("OK", "byte", u(D::OK)),
            ("WARN", "byte", u(D::WARN)),
            ("ERROR", "byte", u(D::ERROR)),
            ("STALE", "byte", u(D::STALE)),
        ],
    );
    assert_constants(
        &L::DEFINITION,
        &[
            ("DEBUG", "uint8", u(L::DEBUG)),
            ("INFO", "uint8", u(L::INFO)),
            ("WARN", "uint8", u(L::WARN)),
            ("ERROR", "uint8", u(L::ERROR)),
            ("FATAL", "uint8", u(L::FATAL)),
        ],
    );
    let i = i64::from;
    assert_constants(
        &M::DEFINITION,
        &[
            ("ARROW", "int32", i(M::ARROW)),
            ("CUBE", "int32", i(M::CUBE)),
            ("SPHERE", "int32", i(M::SPHERE)),
            ("CYLINDER", "int32", i(M::CYLINDER)),
            ("LINE_STRIP", "int32", i(M::LINE_STRIP)),
            ("LINE_LIST", "int32", i(M::LINE_LIST)),
            ("CUBE_LIST", "int32", i(M::CUBE_LIST)),
            ("SPHERE_LIST", "int32", i(M::SPHERE_LIST)),
            ("POINTS", "int32", i(M::POINTS)),
            ("TEXT_VIEW_FACING", "int32", i(M::TEXT_VIEW_FACING)),
            ("MESH_RESOURCE", "int32", i(M::MESH_RESOURCE)),
            ("TRIANGLE_LIST", "int32", i(M::TRIANGLE_LIST)),
            ("ADD", "int32", i(M::ADD)),
            ("MODIFY", "int32", i(M::MODIFY)),
            ("DELETE", "int32", i(M::DELETE)),
            ("DELETEALL", "int32", i(M::DELETEALL)),
        ],
    );
    // Types without constants have none in their text either.
    for def in schema::ALL {
        if ![
            A::TYPE_NAME,
            F::TYPE_NAME,
            D::TYPE_NAME,
            L::TYPE_NAME,
            M::TYPE_NAME,
        ]
        .contains(&def.type_name)
        {
            assert!(
                msg_constants(def.text).is_empty(),
                "{} has constants the mirror lacks",
                def.type_name
            );
        }
    }
}

#[test]
fn activity_labels_follow_the_class_constants() {
    assert_eq!(
        lh::Activity::LABELS.len(),
        usize::from(lh::Activity::NUM_CLASSES)
    );
    assert_eq!(
        lh::Activity::label_of(lh::Activity::SITTING_ON_FLOOR),
        Some("sitting_on_floor")
    );
    assert_eq!(
        lh::Activity::label_of(lh::Activity::WALKING_UNSTEADILY),
        Some("walking_unsteadily")
    );
    assert_eq!(lh::Activity::label_of(9), None);
    // The sample (from the golden values) has as many probabilities as classes.
    assert_eq!(
        sample::<lh::Activity>().probabilities.len(),
        usize::from(lh::Activity::NUM_CLASSES)
    );
}
