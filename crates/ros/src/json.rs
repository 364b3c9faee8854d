//! Messages of known types as JSON, for `lidar-har topic echo` and tests: the serde mirrors of
//! `lidar_har_msgs` decoded from CDR, then serialised field by field, shortened as `ros2 topic
//! echo` shortens them ([`Truncation`]). The shortening is done as the message is serialised,
//! never on a finished JSON tree: an echoed 10 MB map used to cost a `Value` per cell (about
//! 100 bytes each, a gigabyte) to print 128 of them. JSON has no infinity or NaN, which
//! LaserScan ranges use with distinct meanings (REP 117: +inf nothing within range, -inf too
//! close, NaN no measurement): they are written as the strings "inf", "-inf" and "nan".

use lidar_har_msgs::{
    RosMessage, diagnostic_msgs, geometry_msgs, lidar_har_msgs as har, nav_msgs, rcl_interfaces,
    rosgraph_msgs, sensor_msgs, tf2_msgs, visualization_msgs,
};
use serde::ser::{self, Serialize, Serializer};

use crate::RosError;

/// How much of a message is written, as `ros2 topic echo`'s `--truncate-length`,
/// `--full-length`, `--no-arr` and `--no-str` (rosidl_runtime_py's `message_to_ordereddict`),
/// kept valid JSON: the marker of a cut array is a last element, the string `"..."`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Truncation {
    /// An array (sequence, fixed-size array or bytes) longer than this keeps its first
    /// `length` elements, then `"..."`; a longer string keeps its first `length` characters,
    /// then `...`. `None`: everything (`--full-length`).
    pub length: Option<usize>,
    /// Every array is written as its length instead: `"<sequence length: N>"` (a fixed-size
    /// array `"<array length: N>"`; ros2 also names the element type, which the serde
    /// mirrors do not carry).
    pub no_arr: bool,
    /// Every string is written as its length instead: `"<string length: <N>>"`, as ros2.
    pub no_str: bool,
}

impl Truncation {
    /// Everything, as `--full-length`.
    pub const FULL: Self = Self {
        length: None,
        no_arr: false,
        no_str: false,
    };
}

/// What ends an array cut at [`Truncation::length`], as in ros2's output.
pub const ELLIPSIS: &str = "...";

/// `value` serialised shortened by a [`Truncation`], with non-finite floats as strings: for
/// `serde_json::to_writer` (nothing is held but the message) or `serde_json::to_value`.
pub struct Truncated<'a, T: ?Sized> {
    value: &'a T,
    how: Truncation,
}

impl<'a, T: ?Sized> Truncated<'a, T> {
    pub fn new(value: &'a T, how: Truncation) -> Self {
        Self { value, how }
    }
}

impl<T: Serialize + ?Sized> Serialize for Truncated<'_, T> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        self.value.serialize(Shortening {
            inner: serializer,
            how: self.how,
        })
    }
}

/// A serializer that hands everything to `inner`, arrays and strings shortened and floats
/// made JSON-safe, and wraps every nested value so that the same holds at any depth.
struct Shortening<S> {
    inner: S,
    how: Truncation,
}

impl<S: Serializer> Shortening<S> {
    fn wrap<'a, T: ?Sized>(&self, value: &'a T) -> Truncated<'a, T> {
        Truncated::new(value, self.how)
    }
}

macro_rules! forward {
    ($($method:ident($ty:ty)),* $(,)?) => {
        $(fn $method(self, v: $ty) -> Result<S::Ok, S::Error> {
            self.inner.$method(v)
        })*
    };
}

impl<S: Serializer> Serializer for Shortening<S> {
    type Ok = S::Ok;
    type Error = S::Error;
    type SerializeSeq = Elements<S>;
    type SerializeTuple = Elements<S>;
    type SerializeTupleStruct = Fields<S::SerializeTupleStruct>;
    type SerializeTupleVariant = Fields<S::SerializeTupleVariant>;
    type SerializeMap = Fields<S::SerializeMap>;
    type SerializeStruct = Fields<S::SerializeStruct>;
    type SerializeStructVariant = Fields<S::SerializeStructVariant>;

    forward!(
        serialize_bool(bool),
        serialize_i8(i8),
        serialize_i16(i16),
        serialize_i32(i32),
        serialize_i64(i64),
        serialize_i128(i128),
        serialize_u8(u8),
        serialize_u16(u16),
        serialize_u32(u32),
        serialize_u64(u64),
        serialize_u128(u128),
        serialize_char(char),
        serialize_unit_struct(&'static str),
    );

    /// Widened, as ros2 prints a float32 (a Python float).
    fn serialize_f32(self, v: f32) -> Result<S::Ok, S::Error> {
        self.serialize_f64(f64::from(v))
    }

    fn serialize_f64(self, v: f64) -> Result<S::Ok, S::Error> {
        match v {
            v if v.is_finite() => self.inner.serialize_f64(v),
            v if v.is_nan() => self.inner.serialize_str("nan"),
            v if v > 0.0 => self.inner.serialize_str("inf"),
            _ => self.inner.serialize_str("-inf"),
        }
    }

    fn serialize_str(self, v: &str) -> Result<S::Ok, S::Error> {
        if self.how.no_str {
            return self
                .inner
                .serialize_str(&format!("<string length: <{}>>", v.chars().count()));
        }
        // The byte offset of the character after the first `length`: there only when longer.
        match self.how.length.and_then(|n| v.char_indices().nth(n)) {
            Some((cut, _)) => self
                .inner
                .serialize_str(&format!("{}{ELLIPSIS}", &v[..cut])),
            None => self.inner.serialize_str(v),
        }
    }

    /// As an array of numbers (serde_json's own choice), shortened as one.
    fn serialize_bytes(self, v: &[u8]) -> Result<S::Ok, S::Error> {
        let mut elements = self.serialize_seq(Some(v.len()))?;
        for byte in v {
            ser::SerializeSeq::serialize_element(&mut elements, byte)?;
        }
        ser::SerializeSeq::end(elements)
    }

    fn serialize_none(self) -> Result<S::Ok, S::Error> {
        self.inner.serialize_none()
    }

    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<S::Ok, S::Error> {
        let value = self.wrap(value);
        self.inner.serialize_some(&value)
    }

    fn serialize_unit(self) -> Result<S::Ok, S::Error> {
        self.inner.serialize_unit()
    }

    fn serialize_unit_variant(
        self,
        name: &'static str,
        index: u32,
        variant: &'static str,
    ) -> Result<S::Ok, S::Error> {
        self.inner.serialize_unit_variant(name, index, variant)
    }

    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        name: &'static str,
        value: &T,
    ) -> Result<S::Ok, S::Error> {
        let value = self.wrap(value);
        self.inner.serialize_newtype_struct(name, &value)
    }

    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        name: &'static str,
        index: u32,
        variant: &'static str,
        value: &T,
    ) -> Result<S::Ok, S::Error> {
        let value = self.wrap(value);
        self.inner
            .serialize_newtype_variant(name, index, variant, &value)
    }

    fn serialize_seq(self, len: Option<usize>) -> Result<Elements<S>, S::Error> {
        Elements::start(self, len, "sequence")
    }

    /// A fixed-size array (`float64[36] covariance`): serde writes arrays as tuples.
    fn serialize_tuple(self, len: usize) -> Result<Elements<S>, S::Error> {
        Elements::start(self, Some(len), "array")
    }

    fn serialize_tuple_struct(
        self,
        name: &'static str,
        len: usize,
    ) -> Result<Self::SerializeTupleStruct, S::Error> {
        Fields::new(self.inner.serialize_tuple_struct(name, len), self.how)
    }

    fn serialize_tuple_variant(
        self,
        name: &'static str,
        index: u32,
        variant: &'static str,
        len: usize,
    ) -> Result<Self::SerializeTupleVariant, S::Error> {
        let fields = self
            .inner
            .serialize_tuple_variant(name, index, variant, len);
        Fields::new(fields, self.how)
    }

    fn serialize_map(self, len: Option<usize>) -> Result<Self::SerializeMap, S::Error> {
        Fields::new(self.inner.serialize_map(len), self.how)
    }

    fn serialize_struct(
        self,
        name: &'static str,
        len: usize,
    ) -> Result<Self::SerializeStruct, S::Error> {
        Fields::new(self.inner.serialize_struct(name, len), self.how)
    }

    fn serialize_struct_variant(
        self,
        name: &'static str,
        index: u32,
        variant: &'static str,
        len: usize,
    ) -> Result<Self::SerializeStructVariant, S::Error> {
        let fields = self
            .inner
            .serialize_struct_variant(name, index, variant, len);
        Fields::new(fields, self.how)
    }

    fn is_human_readable(&self) -> bool {
        self.inner.is_human_readable()
    }
}

/// An array being written. Elements past the cut are skipped unserialised, so the memory and
/// time spent follow what is printed, not the message.
enum Elements<S: Serializer> {
    /// Its first elements, then [`ELLIPSIS`] when there were more.
    Kept {
        seq: S::SerializeSeq,
        how: Truncation,
        seen: usize,
    },
    /// `--no-arr`: only counted, then written as `"<{kind} length: {seen}>"`.
    Counted {
        inner: S,
        kind: &'static str,
        seen: usize,
    },
}

impl<S: Serializer> Elements<S> {
    fn start(to: Shortening<S>, len: Option<usize>, kind: &'static str) -> Result<Self, S::Error> {
        let how = to.how;
        if how.no_arr {
            return Ok(Self::Counted {
                inner: to.inner,
                kind,
                seen: 0,
            });
        }
        let written = match (len, how.length) {
            (Some(len), Some(n)) if len > n => Some(n + 1),
            _ => len,
        };
        Ok(Self::Kept {
            seq: to.inner.serialize_seq(written)?,
            how,
            seen: 0,
        })
    }

    fn element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), S::Error> {
        match self {
            Self::Kept { seq, how, seen } => {
                if how.length.is_none_or(|n| *seen < n) {
                    ser::SerializeSeq::serialize_element(seq, &Truncated::new(value, *how))?;
                }
                *seen += 1;
            }
            Self::Counted { seen, .. } => *seen += 1,
        }
        Ok(())
    }

    fn finish(self) -> Result<S::Ok, S::Error> {
        match self {
            Self::Kept { mut seq, how, seen } => {
                if how.length.is_some_and(|n| seen > n) {
                    ser::SerializeSeq::serialize_element(&mut seq, ELLIPSIS)?;
                }
                ser::SerializeSeq::end(seq)
            }
            Self::Counted { inner, kind, seen } => {
                inner.serialize_str(&format!("<{kind} length: {seen}>"))
            }
        }
    }
}

impl<S: Serializer> ser::SerializeSeq for Elements<S> {
    type Ok = S::Ok;
    type Error = S::Error;

    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), S::Error> {
        self.element(value)
    }

    fn end(self) -> Result<S::Ok, S::Error> {
        self.finish()
    }
}

impl<S: Serializer> ser::SerializeTuple for Elements<S> {
    type Ok = S::Ok;
    type Error = S::Error;

    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), S::Error> {
        self.element(value)
    }

    fn end(self) -> Result<S::Ok, S::Error> {
        self.finish()
    }
}

/// A struct, map or variant being written, its values shortened (keys never are, as ros2).
struct Fields<C> {
    inner: C,
    how: Truncation,
}

impl<C> Fields<C> {
    fn new<E>(inner: Result<C, E>, how: Truncation) -> Result<Self, E> {
        Ok(Self { inner: inner?, how })
    }
}

macro_rules! fields {
    ($trait:ident $(, $key:ident: $key_ty:ty)?) => {
        impl<C: ser::$trait> ser::$trait for Fields<C> {
            type Ok = C::Ok;
            type Error = C::Error;

            fn serialize_field<T: Serialize + ?Sized>(
                &mut self,
                $($key: $key_ty,)?
                value: &T,
            ) -> Result<(), C::Error> {
                let value = Truncated::new(value, self.how);
                self.inner.serialize_field($($key,)? &value)
            }

            fn end(self) -> Result<C::Ok, C::Error> {
                self.inner.end()
            }
        }
    };
}

fields!(SerializeTupleStruct);
fields!(SerializeTupleVariant);
fields!(SerializeStruct, key: &'static str);
fields!(SerializeStructVariant, key: &'static str);

impl<C: ser::SerializeMap> ser::SerializeMap for Fields<C> {
    type Ok = C::Ok;
    type Error = C::Error;

    fn serialize_key<T: Serialize + ?Sized>(&mut self, key: &T) -> Result<(), C::Error> {
        self.inner.serialize_key(key)
    }

    fn serialize_value<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), C::Error> {
        self.inner.serialize_value(&Truncated::new(value, self.how))
    }

    fn end(self) -> Result<C::Ok, C::Error> {
        self.inner.end()
    }
}

macro_rules! messages {
    ($($variant:ident: $ty:ty),* $(,)?) => {
        /// A message of a type this project mirrors, decoded; serialised as that message.
        pub enum Message {
            $($variant(Box<$ty>),)*
        }

        impl Serialize for Message {
            fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
                match self {
                    $(Self::$variant(msg) => msg.serialize(serializer),)*
                }
            }
        }

        /// `bytes` decoded as `type_name`; `None` for a type this project does not mirror.
        pub fn decode(type_name: &str, bytes: &[u8]) -> Option<Result<Message, RosError>> {
            $(if type_name == <$ty as RosMessage>::TYPE_NAME {
                let msg = lidar_har_msgs::decode::<$ty>(bytes);
                return Some(msg.map(|m| Message::$variant(Box::new(m))).map_err(RosError::from));
            })*
            None
        }
    };
}

messages!(
    LaserScan: sensor_msgs::LaserScan,
    Odometry: nav_msgs::Odometry,
    OccupancyGrid: nav_msgs::OccupancyGrid,
    TfMessage: tf2_msgs::TFMessage,
    Clock: rosgraph_msgs::Clock,
    PoseStamped: geometry_msgs::PoseStamped,
    PoseWithCovarianceStamped: geometry_msgs::PoseWithCovarianceStamped,
    Activity: har::Activity,
    FallAlert: har::FallAlert,
    HumanObservation: har::HumanObservation,
    MarkerArray: visualization_msgs::MarkerArray,
    DiagnosticArray: diagnostic_msgs::DiagnosticArray,
    Log: rcl_interfaces::Log,
);

/// `bytes` decoded as `type_name` and turned whole into JSON; `None` for a type this project
/// does not mirror.
pub fn decode_to_json(
    type_name: &str,
    bytes: &[u8],
) -> Option<Result<serde_json::Value, RosError>> {
    let msg = match decode(type_name, bytes)? {
        Ok(msg) => msg,
        Err(e) => return Some(Err(e)),
    };
    let json = serde_json::to_value(Truncated::new(&msg, Truncation::FULL));
    Some(json.map_err(|e| RosError::Topic {
        topic: type_name.into(),
        reason: e.to_string(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_types_decode_unknown_are_none_garbage_is_an_error() {
        let activity = har::Activity {
            activity: 3,
            label: "lying_down".into(),
            confidence: 0.5,
            ..Default::default()
        };
        let bytes = lidar_har_msgs::encode(&activity).unwrap();
        let json = decode_to_json("lidar_har_msgs/msg/Activity", &bytes)
            .unwrap()
            .unwrap();
        assert_eq!(json["label"], "lying_down");
        assert_eq!(json["activity"], 3);
        assert!(decode_to_json("foo_msgs/msg/Bar", &bytes).is_none());
        assert!(
            decode_to_json("lidar_har_msgs/msg/Activity", &bytes[..6])
                .unwrap()
                .is_err()
        );
        assert!(
            decode_to_json("lidar_har_msgs/msg/Activity", &[])
                .unwrap()
                .is_err()
        );
    }

    /// /rosout's records are read field by field (`topic echo /rosout`); they were printed
    /// as hex.
    #[test]
    fn log_records_decode() {
        let record = rcl_interfaces::Log {
            level: rcl_interfaces::Log::WARN,
            name: "robot1.replay".into(),
            msg: "no /missing in the bag".into(),
            line: 42,
            ..Default::default()
        };
        let bytes = lidar_har_msgs::encode(&record).unwrap();
        let json = decode_to_json("rcl_interfaces/msg/Log", &bytes)
            .unwrap()
            .unwrap();
        assert_eq!(json["name"], "robot1.replay");
        assert_eq!(json["msg"], "no /missing in the bag");
        assert_eq!((&json["level"], &json["line"]), (&30.into(), &42.into()));
    }

    #[test]
    fn non_finite_ranges_keep_their_meaning() {
        let scan = sensor_msgs::LaserScan {
            angle_increment: 0.1,
            range_max: 12.0,
            ranges: vec![1.5, f32::INFINITY, f32::NEG_INFINITY, f32::NAN],
            ..Default::default()
        };
        let bytes = lidar_har_msgs::encode(&scan).unwrap();
        let json = decode_to_json("sensor_msgs/msg/LaserScan", &bytes)
            .unwrap()
            .unwrap();
        assert_eq!(
            json["ranges"],
            serde_json::json!([1.5, "inf", "-inf", "nan"])
        );
        // Finite values are written as before: f32 widened to f64.
        assert_eq!(json["angle_increment"], f64::from(0.1f32));
        assert_eq!(json["range_max"], 12.0);
        assert_eq!(json["header"]["stamp"]["sec"], 0);
        assert_eq!(json["intensities"], serde_json::json!([]));
    }

    fn cut_at(length: usize) -> Truncation {
        Truncation {
            length: Some(length),
            ..Truncation::FULL
        }
    }

    fn truncated<T: Serialize>(value: &T, how: Truncation) -> serde_json::Value {
        serde_json::to_value(Truncated::new(value, how)).unwrap()
    }

    /// As ros2: an array longer than the length keeps that many elements then "..."; one of
    /// exactly the length is whole. The message used to be printed whole, always.
    #[test]
    fn arrays_longer_than_the_length_keep_their_first_elements_then_an_ellipsis() {
        let grid = |cells: usize| nav_msgs::OccupancyGrid {
            data: (0..cells).map(|i| (i % 100) as i8).collect(),
            ..Default::default()
        };
        let json = truncated(&grid(300), cut_at(128));
        let data = json["data"].as_array().unwrap();
        assert_eq!(data.len(), 129);
        assert_eq!(
            data[..128],
            truncated(&grid(128), Truncation::FULL)["data"]
                .as_array()
                .unwrap()[..]
        );
        assert_eq!(data[128], ELLIPSIS);
        assert_eq!(
            truncated(&grid(128), cut_at(128)),
            truncated(&grid(128), Truncation::FULL)
        );
        assert_eq!(
            json["info"],
            truncated(&grid(300), Truncation::FULL)["info"]
        );
        assert_eq!(
            truncated(&grid(3), cut_at(0))["data"],
            serde_json::json!(["..."])
        );
        assert_eq!(
            truncated(&grid(0), cut_at(0))["data"],
            serde_json::json!([])
        );
        // Fixed-size arrays too (`float64[36] covariance`), and non-finite floats still named.
        let mut pose = geometry_msgs::PoseWithCovarianceStamped::default();
        pose.pose.covariance[1] = f64::INFINITY;
        let covariance = &truncated(&pose, cut_at(2))["pose"]["covariance"];
        assert_eq!(covariance, &serde_json::json!([0.0, "inf", "..."]));
    }

    /// Arrays in the elements of a cut array are cut as well, bytes (`uint8[]`) are an array
    /// like any other, and strings keep their first characters then `...`, as ros2.
    #[test]
    fn nested_arrays_bytes_and_strings_are_cut_at_every_depth() {
        let marker = |text: &str| visualization_msgs::Marker {
            points: vec![geometry_msgs::Point::default(); 5],
            text: text.into(),
            texture: sensor_msgs::CompressedImage {
                data: vec![7; 5],
                ..Default::default()
            },
            ..Default::default()
        };
        let markers = visualization_msgs::MarkerArray {
            markers: vec![marker("fall"), marker("ééé"), marker("x")],
        };
        let json = truncated(&markers, cut_at(2));
        let cut = json["markers"].as_array().unwrap();
        assert_eq!(cut.len(), 3);
        assert_eq!(cut[2], ELLIPSIS);
        let point = serde_json::json!({"x": 0.0, "y": 0.0, "z": 0.0});
        for m in &cut[..2] {
            assert_eq!(m["points"], serde_json::json!([point, point, "..."]));
            assert_eq!(m["texture"]["data"], serde_json::json!([7, 7, "..."]));
            assert_eq!(m["colors"], serde_json::json!([]));
        }
        // Characters, not bytes: "é" is two.
        assert_eq!(cut[0]["text"], "fa...");
        assert_eq!(cut[1]["text"], "éé...");
        assert_eq!(truncated(&"ab", cut_at(2)), "ab");

        // What serde writes as bytes (serde_bytes) is shortened as an array of numbers.
        struct Blob;
        impl Serialize for Blob {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.serialize_bytes(&[1, 2, 3, 4])
            }
        }
        assert_eq!(
            truncated(&Blob, cut_at(2)),
            serde_json::json!([1, 2, "..."])
        );
        assert_eq!(
            truncated(&Blob, Truncation::FULL),
            serde_json::json!([1, 2, 3, 4])
        );
    }

    #[test]
    fn no_arr_and_no_str_write_lengths_instead() {
        let mut scan = sensor_msgs::LaserScan {
            ranges: vec![1.0; 300],
            ..Default::default()
        };
        scan.header.frame_id = "laser".into();
        let how = Truncation {
            no_arr: true,
            no_str: true,
            ..Truncation::FULL
        };
        let json = truncated(&scan, how);
        assert_eq!(json["ranges"], "<sequence length: 300>");
        assert_eq!(json["intensities"], "<sequence length: 0>");
        assert_eq!(json["header"]["frame_id"], "<string length: <5>>");
        assert_eq!(json["range_max"], 0.0);
        let pose = geometry_msgs::PoseWithCovarianceStamped::default();
        let json = truncated(&pose, how);
        assert_eq!(json["pose"]["covariance"], "<array length: 36>");
    }

    /// The memory follows what is printed: elements past the cut are never serialised (a
    /// 10 MB map cost a gigabyte of `Value`s when the whole message was converted first).
    #[test]
    fn elements_past_the_cut_are_never_serialised() {
        use std::cell::Cell;
        struct Counted<'a>(&'a Cell<usize>);
        impl Serialize for Counted<'_> {
            fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                self.0.set(self.0.get() + 1);
                s.serialize_u8(1)
            }
        }
        let calls = Cell::new(0);
        let many: Vec<Counted> = (0..10_000).map(|_| Counted(&calls)).collect();
        let mut line = Vec::new();
        serde_json::to_writer(&mut line, &Truncated::new(&many, cut_at(3))).unwrap();
        assert_eq!(String::from_utf8(line).unwrap(), r#"[1,1,1,"..."]"#);
        assert_eq!(calls.get(), 3);
    }

    /// Written straight to the output (`topic echo`) or built as a `Value`: the same JSON.
    #[test]
    fn writing_and_building_give_the_same_json() {
        let scan = sensor_msgs::LaserScan {
            ranges: vec![1.5, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 2.0],
            ..Default::default()
        };
        let bytes = lidar_har_msgs::encode(&scan).unwrap();
        let msg = decode("sensor_msgs/msg/LaserScan", &bytes)
            .unwrap()
            .unwrap();
        for how in [Truncation::FULL, cut_at(3)] {
            let written = serde_json::to_string(&Truncated::new(&msg, how)).unwrap();
            let built = serde_json::to_value(Truncated::new(&msg, how)).unwrap();
            assert_eq!(
                serde_json::from_str::<serde_json::Value>(&written).unwrap(),
                built
            );
        }
        let full = decode_to_json("sensor_msgs/msg/LaserScan", &bytes)
            .unwrap()
            .unwrap();
        assert_eq!(full, truncated(&msg, Truncation::FULL));
    }
}
