//! `metadata.yaml` (`rosbag2_bagfile_information`), versions 1 to 9: every key that appeared
//! after version 1 has a default, and `offered_qos_profiles` is read in both of its forms.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_yaml_ng::Value;

use crate::error::{BagError, Result, io_error};
use crate::qos::{self, OfferedQos};

/// The newest metadata version this crate reads, and the one it writes by default (rosbag2
/// Jazzy; see [`crate::MetadataVersion`]).
pub const METADATA_VERSION: u32 = 9;

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Nanoseconds {
    pub nanoseconds: i64,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NanosecondsSinceEpoch {
    pub nanoseconds_since_epoch: i64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TopicMetadata {
    pub name: String,
    #[serde(rename = "type")]
    pub type_name: String,
    #[serde(default = "cdr")]
    pub serialization_format: String,
    /// A YAML string (versions 4 to 8) or a list (version 9); see [`crate::qos::parse`].
    #[serde(default)]
    pub offered_qos_profiles: Value,
    /// The type's RIHS01 hash (metadata version 7 and later; rosbag2 Iron writes 8), empty
    /// where the writer does not know it.
    #[serde(default)]
    pub type_description_hash: String,
}

fn cdr() -> String {
    "cdr".to_string()
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TopicWithCount {
    pub topic_metadata: TopicMetadata,
    pub message_count: u64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FileInformation {
    pub path: String,
    pub starting_time: NanosecondsSinceEpoch,
    pub duration: Nanoseconds,
    pub message_count: u64,
}

/// The content of `rosbag2_bagfile_information`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BagMetadata {
    pub version: u32,
    pub storage_identifier: String,
    #[serde(default)]
    pub duration: Nanoseconds,
    #[serde(default)]
    pub starting_time: NanosecondsSinceEpoch,
    #[serde(default)]
    pub message_count: u64,
    #[serde(default)]
    pub topics_with_message_count: Vec<TopicWithCount>,
    #[serde(default)]
    pub compression_format: String,
    #[serde(default)]
    pub compression_mode: String,
    #[serde(default)]
    pub relative_file_paths: Vec<String>,
    #[serde(default)]
    pub files: Vec<FileInformation>,
    #[serde(default)]
    pub custom_data: Option<BTreeMap<String, String>>,
    #[serde(default)]
    pub ros_distro: String,
}

#[derive(Debug, Serialize, Deserialize)]
struct MetadataFile {
    rosbag2_bagfile_information: BagMetadata,
}

impl BagMetadata {
    /// Reads and checks `<dir>/metadata.yaml`.
    pub fn read(dir: &Path) -> Result<Self> {
        let path = dir.join("metadata.yaml");
        let text = std::fs::read_to_string(&path).map_err(io_error(&path, "cannot read"))?;
        Self::parse(&text, &path)
    }

    /// Parses the text of a metadata.yaml; `path` is only used in error messages.
    pub fn parse(text: &str, path: &Path) -> Result<Self> {
        let file: MetadataFile = serde_yaml_ng::from_str(text).map_err(|e| BagError::Metadata {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let metadata = file.rosbag2_bagfile_information;
        if metadata.version == 0 || metadata.version > METADATA_VERSION {
            return Err(BagError::UnsupportedVersion {
                path: path.to_path_buf(),
                version: metadata.version,
            });
        }
        for topic in &metadata.topics_with_message_count {
            qos::parse(&topic.topic_metadata.offered_qos_profiles).map_err(|message| {
                BagError::Metadata {
                    path: path.to_path_buf(),
                    message: format!(
                        "topics_with_message_count: topic `{}`: offered_qos_profiles: {message}",
                        topic.topic_metadata.name
                    ),
                }
            })?;
        }
        Ok(metadata)
    }

    /// The YAML text of this metadata, as rosbag2 writes it (`rosbag2_bagfile_information:` root).
    pub fn to_yaml(&self) -> String {
        let file = MetadataFile {
            rosbag2_bagfile_information: self.clone(),
        };
        serde_yaml_ng::to_string(&file).unwrap_or_default()
    }

    /// The YAML text without the root key, as the MCAP `rosbag2` metadata record holds it.
    pub fn to_serialized_metadata(&self) -> String {
        serde_yaml_ng::to_string(self).unwrap_or_default()
    }

    /// Writes `<dir>/metadata.yaml` atomically (temporary file, then rename), so a reader never
    /// sees a half-written file even when the writer is killed.
    pub fn write(&self, dir: &Path) -> Result<()> {
        let path = dir.join("metadata.yaml");
        let tmp = dir.join(".metadata.yaml.tmp");
        std::fs::write(&tmp, self.to_yaml()).map_err(io_error(&tmp, "cannot write"))?;
        std::fs::rename(&tmp, &path).map_err(io_error(&path, "cannot replace"))
    }

    /// The offered QoS of a topic listed in this metadata (already validated by [`Self::parse`]).
    pub fn offered_qos(topic: &TopicMetadata) -> Vec<OfferedQos> {
        qos::parse(&topic.offered_qos_profiles).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V4: &str = "rosbag2_bagfile_information:
  version: 4
  storage_identifier: sqlite3
  relative_file_paths: [a_0.db3]
  duration: {nanoseconds: 5}
  starting_time: {nanoseconds_since_epoch: 10}
  message_count: 2
  topics_with_message_count:
    - message_count: 2
      topic_metadata:
        name: /scan
        type: sensor_msgs/msg/LaserScan
        serialization_format: cdr
        offered_qos_profiles: \"- history: 3\\n  depth: 0\\n  reliability: 2\\n  durability: 2\\n\"
  compression_format: \"\"
  compression_mode: \"\"
";

    #[test]
    fn reads_version_4_with_string_qos() {
        let m = BagMetadata::parse(V4, Path::new("m.yaml")).unwrap();
        assert_eq!(m.version, 4);
        assert_eq!(m.starting_time.nanoseconds_since_epoch, 10);
        assert!(m.files.is_empty());
        let qos = BagMetadata::offered_qos(&m.topics_with_message_count[0].topic_metadata);
        assert_eq!(qos[0].reliability, 2);
    }

    #[test]
    fn round_trips_version_9() {
        let mut m = BagMetadata::parse(V4, Path::new("m.yaml")).unwrap();
        m.version = 9;
        m.topics_with_message_count[0]
            .topic_metadata
            .offered_qos_profiles = qos::to_v9_list(&[OfferedQos::from(
            lidar_har_msgs::qos::QosProfile::sensor_data(),
        )]);
        let again = BagMetadata::parse(&m.to_yaml(), Path::new("m.yaml")).unwrap();
        assert_eq!(again, m);
    }

    #[test]
    fn malformed_names_the_key() {
        let broken = V4.replace("nanoseconds: 5", "nanoseconds: five");
        let err = BagMetadata::parse(&broken, Path::new("bag/metadata.yaml"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("bag/metadata.yaml") && err.contains("duration"),
            "{err}"
        );
        let newer = V4.replace("version: 4", "version: 12");
        assert!(matches!(
            BagMetadata::parse(&newer, Path::new("m")),
            Err(BagError::UnsupportedVersion { version: 12, .. })
        ));
        let missing = V4.replace("  storage_identifier: sqlite3\n", "");
        let err = BagMetadata::parse(&missing, Path::new("m"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("storage_identifier"), "{err}");
    }
}
