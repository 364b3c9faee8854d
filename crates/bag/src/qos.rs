//! Offered QoS profiles as rosbag2 stores them, in both of its forms: metadata version 8 and
//! older keep a YAML *string* with integer enums, version 9 a YAML *list* with string enums.

use lidar_har_msgs::qos::{Durability, History, QosProfile, Reliability};
use serde::{Deserialize, Serialize};
use serde_yaml_ng::Value;

/// A ROS duration as rosbag2 writes it in QoS profiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct QosDuration {
    pub sec: i64,
    pub nsec: u64,
}

/// One offered QoS profile of a topic, with rmw's enum values (0 = system default).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OfferedQos {
    /// rmw history: 0 system default, 1 keep last, 2 keep all, 3 unknown.
    pub history: u8,
    pub depth: u32,
    /// rmw reliability: 0 system default, 1 reliable, 2 best effort, 3 unknown, 4 best available.
    pub reliability: u8,
    /// rmw durability: 0 system default, 1 transient local, 2 volatile, 3 unknown, 4 best available.
    pub durability: u8,
    pub deadline: QosDuration,
    pub lifespan: QosDuration,
    /// rmw liveliness: 0 system default, 1 automatic, 3 manual by topic, 4 unknown, 5 best available.
    pub liveliness: u8,
    pub liveliness_lease_duration: QosDuration,
    pub avoid_ros_namespace_conventions: bool,
}

const HISTORY_NAMES: &[&str] = &["system_default", "keep_last", "keep_all", "unknown"];
const RELIABILITY_NAMES: &[&str] = &[
    "system_default",
    "reliable",
    "best_effort",
    "unknown",
    "best_available",
];
const DURABILITY_NAMES: &[&str] = &[
    "system_default",
    "transient_local",
    "volatile",
    "unknown",
    "best_available",
];
const LIVELINESS_NAMES: &[&str] = &[
    "system_default",
    "automatic",
    "manual_by_node",
    "manual_by_topic",
    "unknown",
    "best_available",
];

impl From<QosProfile> for OfferedQos {
    fn from(qos: QosProfile) -> Self {
        let (history, depth) = match qos.history {
            History::KeepLast(depth) => (1, depth),
            History::KeepAll => (2, 0),
        };
        Self {
            history,
            depth,
            reliability: match qos.reliability {
                Reliability::Reliable => 1,
                Reliability::BestEffort => 2,
            },
            durability: match qos.durability {
                Durability::TransientLocal => 1,
                Durability::Volatile => 2,
            },
            deadline: QosDuration::default(),
            lifespan: QosDuration::default(),
            liveliness: 1,
            liveliness_lease_duration: QosDuration::default(),
            avoid_ros_namespace_conventions: false,
        }
    }
}

impl OfferedQos {
    /// The project's [`QosProfile`] this profile corresponds to, if its enums are concrete.
    pub fn to_profile(&self) -> Option<QosProfile> {
        let history = match self.history {
            1 => History::KeepLast(self.depth),
            2 => History::KeepAll,
            _ => return None,
        };
        Some(QosProfile {
            reliability: self.concrete_reliability()?,
            durability: self.concrete_durability()?,
            history,
        })
    }

    fn concrete_reliability(&self) -> Option<Reliability> {
        match self.reliability {
            1 => Some(Reliability::Reliable),
            2 => Some(Reliability::BestEffort),
            _ => None,
        }
    }

    fn concrete_durability(&self) -> Option<Durability> {
        match self.durability {
            1 => Some(Durability::TransientLocal),
            2 => Some(Durability::Volatile),
            _ => None,
        }
    }

    /// The history as a publisher could be created with it. rosbag2 records offers from DDS
    /// discovery, which does not carry the history: its recordings say `unknown` with depth 0.
    fn concrete_history(&self) -> Option<History> {
        match (self.history, self.depth) {
            (1, depth) if depth > 0 => Some(History::KeepLast(depth)),
            (2, _) => Some(History::KeepAll),
            _ => None,
        }
    }

    /// Short human-readable form, as `ros2 bag info` shows it.
    pub fn describe(&self) -> String {
        let name = |names: &[&str], v: u8| {
            names
                .get(usize::from(v))
                .copied()
                .unwrap_or("unknown")
                .to_string()
        };
        format!(
            "{} {} {}{}",
            name(RELIABILITY_NAMES, self.reliability),
            name(DURABILITY_NAMES, self.durability),
            name(HISTORY_NAMES, self.history),
            if self.history == 1 {
                format!(" {}", self.depth)
            } else {
                String::new()
            }
        )
    }

    fn to_value(self, string_enums: bool) -> Value {
        let enum_value = |names: &[&str], v: u8| {
            if string_enums {
                Value::from(names.get(usize::from(v)).copied().unwrap_or("unknown"))
            } else {
                Value::from(v)
            }
        };
        let duration = |d: QosDuration| serde_yaml_ng::to_value(d).unwrap_or(Value::Null);
        let mut map = serde_yaml_ng::Mapping::new();
        map.insert("history".into(), enum_value(HISTORY_NAMES, self.history));
        map.insert("depth".into(), Value::from(self.depth));
        map.insert(
            "reliability".into(),
            enum_value(RELIABILITY_NAMES, self.reliability),
        );
        map.insert(
            "durability".into(),
            enum_value(DURABILITY_NAMES, self.durability),
        );
        map.insert("deadline".into(), duration(self.deadline));
        map.insert("lifespan".into(), duration(self.lifespan));
        map.insert(
            "liveliness".into(),
            enum_value(LIVELINESS_NAMES, self.liveliness),
        );
        map.insert(
            "liveliness_lease_duration".into(),
            duration(self.liveliness_lease_duration),
        );
        map.insert(
            "avoid_ros_namespace_conventions".into(),
            Value::from(self.avoid_ros_namespace_conventions),
        );
        Value::Mapping(map)
    }

    fn from_value(value: &Value) -> Result<Self, String> {
        let map = value
            .as_mapping()
            .ok_or_else(|| format!("a QoS profile must be a mapping, found {value:?}"))?;
        let field = |key: &str| map.get(key);
        let enum_field = |key: &str, names: &[&str]| -> Result<u8, String> {
            match field(key) {
                None => Ok(0),
                Some(Value::Number(n)) => n
                    .as_u64()
                    .and_then(|n| u8::try_from(n).ok())
                    .ok_or_else(|| format!("`{key}`: bad value {n}")),
                Some(Value::String(s)) => Ok(names
                    .iter()
                    .position(|name| name.eq_ignore_ascii_case(s))
                    .and_then(|i| u8::try_from(i).ok())
                    .unwrap_or(3)),
                Some(other) => Err(format!(
                    "`{key}`: expected an integer or a name, found {other:?}"
                )),
            }
        };
        let duration = |key: &str| -> Result<QosDuration, String> {
            match field(key) {
                None => Ok(QosDuration::default()),
                Some(v) => {
                    serde_yaml_ng::from_value(v.clone()).map_err(|e| format!("`{key}`: {e}"))
                }
            }
        };
        let depth = match field("depth") {
            None => 0,
            Some(v) => v
                .as_u64()
                .and_then(|d| u32::try_from(d).ok())
                .ok_or_else(|| format!("`depth`: bad value {v:?}"))?,
        };
        Ok(Self {
            history: enum_field("history", HISTORY_NAMES)?,
            depth,
            reliability: enum_field("reliability", RELIABILITY_NAMES)?,
            durability: enum_field("durability", DURABILITY_NAMES)?,
            deadline: duration("deadline")?,
            lifespan: duration("lifespan")?,
            liveliness: enum_field("liveliness", LIVELINESS_NAMES)?,
            liveliness_lease_duration: duration("liveliness_lease_duration")?,
            avoid_ros_namespace_conventions: field("avoid_ros_namespace_conventions")
                .and_then(Value::as_bool)
                .unwrap_or(false),
        })
    }
}

/// The history rosbag2's player gives a topic whose recorded offers do not say one
/// (`rmw_qos_profile_default.depth`).
const PLAYBACK_DEFAULT_DEPTH: u32 = 10;

/// What a replay offers on a topic in place of the publishers recorded on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlaybackQos {
    pub profile: QosProfile,
    /// The recorded offers differ in reliability or durability, so `profile` is the default
    /// offer, which a subscriber that matched only some of the recorded publishers may not
    /// match: worth telling the user, as rosbag2 does.
    pub offers_disagree: bool,
}

/// The profile to replay a topic with, chosen as rosbag2's player does
/// (`Rosbag2QoS::adapt_offer_to_recorded_offers`): one publisher stands in for all the recorded
/// ones, so it keeps their reliability and durability, which decide which subscribers match
/// (a transient-local topic stays latched), when they all agree on them. Otherwise, or when the
/// recording does not say them, it is reliable, volatile, keep last 10, rosbag2's default.
/// The history does not affect matching: the deepest one recorded is kept (what any recorded
/// publisher kept for a late subscriber), else keep last 10.
pub fn playback_qos(offers: &[OfferedQos]) -> PlaybackQos {
    let default = PlaybackQos {
        profile: QosProfile::reliable(PLAYBACK_DEFAULT_DEPTH),
        offers_disagree: false,
    };
    let Some(first) = offers.first() else {
        return default;
    };
    if offers
        .iter()
        .any(|offer| (offer.reliability, offer.durability) != (first.reliability, first.durability))
    {
        return PlaybackQos {
            offers_disagree: true,
            ..default
        };
    }
    let (Some(reliability), Some(durability)) =
        (first.concrete_reliability(), first.concrete_durability())
    else {
        return default;
    };
    let history = offers
        .iter()
        .filter_map(OfferedQos::concrete_history)
        .max_by_key(|history| match history {
            History::KeepAll => u64::MAX,
            History::KeepLast(depth) => u64::from(*depth),
        })
        .unwrap_or(History::KeepLast(PLAYBACK_DEFAULT_DEPTH));
    PlaybackQos {
        profile: QosProfile {
            reliability,
            durability,
            history,
        },
        offers_disagree: false,
    }
}

/// The version-9 form: a YAML list with string enums (metadata.yaml `offered_qos_profiles`).
pub fn to_v9_list(profiles: &[OfferedQos]) -> Value {
    Value::Sequence(profiles.iter().map(|p| p.to_value(true)).collect())
}

/// metadata.yaml's `offered_qos_profiles` for metadata `version`: the list of version 9, or
/// the string of [`to_yaml_string`] for older versions.
pub fn to_metadata_value(profiles: &[OfferedQos], version: u32) -> Value {
    if version >= 9 {
        to_v9_list(profiles)
    } else {
        Value::String(to_yaml_string(profiles, version))
    }
}

/// The YAML string rosbag2 stores in MCAP channel metadata and sqlite `topics` rows:
/// string enums for version 9, integer enums for version 8 and older. Empty for no profiles.
pub fn to_yaml_string(profiles: &[OfferedQos], version: u32) -> String {
    if profiles.is_empty() {
        return String::new();
    }
    let list = Value::Sequence(profiles.iter().map(|p| p.to_value(version >= 9)).collect());
    serde_yaml_ng::to_string(&list)
        .map(|s| s.trim_end().to_string())
        .unwrap_or_default()
}

/// Parses `offered_qos_profiles` in either form: a YAML list, or a string holding one
/// (with integer or string enums). An empty string or null means no profiles.
pub fn parse(value: &Value) -> Result<Vec<OfferedQos>, String> {
    match value {
        Value::Null => Ok(Vec::new()),
        Value::String(text) if text.trim().is_empty() => Ok(Vec::new()),
        Value::String(text) => {
            let inner: Value = serde_yaml_ng::from_str(text)
                .map_err(|e| format!("offered_qos_profiles is not valid YAML: {e}"))?;
            match inner {
                Value::String(_) => {
                    Err("offered_qos_profiles string does not hold a list".to_string())
                }
                other => parse(&other),
            }
        }
        Value::Sequence(items) => items.iter().map(OfferedQos::from_value).collect(),
        other => Err(format!(
            "offered_qos_profiles must be a list or a string, found {other:?}"
        )),
    }
}

/// Parses the string form (MCAP channel metadata, sqlite `topics.offered_qos_profiles`).
pub fn parse_str(text: &str) -> Result<Vec<OfferedQos>, String> {
    parse(&Value::String(text.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_forms_round_trip() {
        let profiles = vec![
            OfferedQos::from(QosProfile::sensor_data()),
            OfferedQos::from(QosProfile::latched(1)),
        ];
        let v8 = to_yaml_string(&profiles, 8);
        assert!(v8.contains("reliability: 2"), "{v8}");
        assert_eq!(parse_str(&v8).unwrap(), profiles);
        let v9 = to_yaml_string(&profiles, 9);
        assert!(v9.contains("reliability: best_effort"), "{v9}");
        assert_eq!(parse_str(&v9).unwrap(), profiles);
        assert_eq!(parse(&to_v9_list(&profiles)).unwrap(), profiles);
        assert_eq!(profiles[0].to_profile(), Some(QosProfile::sensor_data()));
        assert_eq!(profiles[1].to_profile(), Some(QosProfile::latched(1)));
    }

    /// What `ros2 bag record` on Humble writes (integer enums; 3 is "unknown"): discovery
    /// does not tell the history.
    const HUMBLE_LATCHED: &str = "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 1\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false";

    /// The same from Jazzy (string enums), for a best-effort sensor topic.
    const JAZZY_SENSOR: &str = "- history: unknown\n  depth: 0\n  reliability: best_effort\n  durability: volatile\n  deadline:\n    sec: 9223372036\n    nsec: 854775807\n  lifespan:\n    sec: 9223372036\n    nsec: 854775807\n  liveliness: automatic\n  liveliness_lease_duration:\n    sec: 9223372036\n    nsec: 854775807\n  avoid_ros_namespace_conventions: false";

    fn playback(text: &str) -> PlaybackQos {
        playback_qos(&parse_str(text).unwrap())
    }

    /// A latched topic recorded by rosbag2 was replayed volatile, so transient-local
    /// subscribers (RViz's RobotModel on /robot_description) got nothing.
    #[test]
    fn a_rosbag2_recording_is_replayed_with_its_reliability_and_durability() {
        let agreed = |profile| PlaybackQos {
            profile,
            offers_disagree: false,
        };
        assert_eq!(playback(HUMBLE_LATCHED), agreed(QosProfile::latched(10)));
        let two_publishers = format!("{HUMBLE_LATCHED}\n{HUMBLE_LATCHED}");
        assert_eq!(playback(&two_publishers), agreed(QosProfile::latched(10)));
        let best_effort_10 = QosProfile {
            history: History::KeepLast(10),
            ..QosProfile::sensor_data()
        };
        assert_eq!(playback(JAZZY_SENSOR), agreed(best_effort_10));
    }

    /// Bags written by this crate record the history; the deepest of those recorded is kept.
    #[test]
    fn a_recorded_history_is_kept() {
        let agreed = |offers: &[QosProfile]| {
            let offers: Vec<OfferedQos> = offers.iter().copied().map(OfferedQos::from).collect();
            playback_qos(&offers)
        };
        let latched_1 = QosProfile::latched(1);
        assert_eq!(agreed(&[latched_1]).profile, latched_1);
        let latched_3 = QosProfile::latched(3);
        assert_eq!(agreed(&[latched_1, latched_3]).profile, latched_3);
        let keep_all = QosProfile {
            history: History::KeepAll,
            ..latched_1
        };
        assert_eq!(agreed(&[latched_3, keep_all]).profile, keep_all);
        let unknown_history = parse_str(HUMBLE_LATCHED).unwrap()[0];
        let offers = [unknown_history, OfferedQos::from(latched_3)];
        assert_eq!(playback_qos(&offers).profile, latched_3);
    }

    /// As rosbag2: no single offer suits subscribers of every recorded publisher, so the
    /// default is offered, and the caller is told.
    #[test]
    fn disagreeing_or_unknown_offers_are_replayed_reliable_volatile_keep_last_10() {
        let mixed = format!("{HUMBLE_LATCHED}\n{JAZZY_SENSOR}");
        let expected = PlaybackQos {
            profile: QosProfile::reliable(10),
            offers_disagree: true,
        };
        assert_eq!(playback(&mixed), expected);
        let volatile = HUMBLE_LATCHED.replace("durability: 1", "durability: 2");
        let mixed_durability = format!("{HUMBLE_LATCHED}\n{volatile}");
        assert_eq!(playback(&mixed_durability), expected);

        let default = PlaybackQos {
            profile: QosProfile::reliable(10),
            offers_disagree: false,
        };
        let unknown = JAZZY_SENSOR.replace("best_effort", "unknown");
        assert_eq!(playback(&unknown), default);
        let system_default = HUMBLE_LATCHED.replace("durability: 1", "durability: 0");
        assert_eq!(playback(&system_default), default);
        assert_eq!(playback_qos(&[]), default);
    }

    #[test]
    fn empty_and_bad_input() {
        assert!(parse_str("").unwrap().is_empty());
        assert!(parse_str("[]").unwrap().is_empty());
        assert!(
            parse_str("- history: [1, 2]")
                .unwrap_err()
                .contains("history")
        );
        assert!(parse_str("::: not yaml [").is_err());
    }
}
