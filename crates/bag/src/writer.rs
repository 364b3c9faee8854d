//! Writing rosbag2 directories: `metadata.yaml` plus one storage file (`<dir>_0.mcap` or
//! `<dir>_0.db3`). Data is flushed at the first write after each flush interval (and on
//! `flush()`), and `metadata.yaml` rewritten at each flush, so a process killed mid-recording
//! leaves a bag that reads back up to its last flush.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use lidar_har_msgs::RosMessage;
use lidar_har_msgs::qos::QosProfile;
use lidar_har_msgs::topics::TopicSpec;

use crate::error::{BagError, Result, io_error};
use crate::mcap_storage::McapSink;
use crate::metadata::{
    BagMetadata, FileInformation, Nanoseconds, NanosecondsSinceEpoch, TopicMetadata, TopicWithCount,
};
use crate::qos::{self, OfferedQos};
use crate::reader::{ROS2MSG, RecordedVersion, TopicInfo, stored_definition};
use crate::sqlite_storage::SqliteSink;

/// Storage plugin of a bag, as named in `metadata.yaml`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StorageId {
    #[default]
    Mcap,
    Sqlite3,
}

impl StorageId {
    pub fn as_str(self) -> &'static str {
        match self {
            StorageId::Mcap => "mcap",
            StorageId::Sqlite3 => "sqlite3",
        }
    }

    pub(crate) fn extension(self) -> &'static str {
        match self {
            StorageId::Mcap => "mcap",
            StorageId::Sqlite3 => "db3",
        }
    }
}

impl std::fmt::Display for StorageId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for StorageId {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "mcap" => Ok(StorageId::Mcap),
            "sqlite3" => Ok(StorageId::Sqlite3),
            other => Err(format!(
                "unknown storage `{other}` (expected mcap or sqlite3)"
            )),
        }
    }
}

/// Chunk compression of MCAP storage (sqlite3 storage is never compressed by this writer).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    #[default]
    None,
    Zstd,
    Lz4,
}

impl std::str::FromStr for Compression {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "none" | "" => Ok(Compression::None),
            "zstd" => Ok(Compression::Zstd),
            "lz4" => Ok(Compression::Lz4),
            other => Err(format!(
                "unknown compression `{other}` (expected none, zstd or lz4)"
            )),
        }
    }
}

/// The rosbag2 metadata version a bag is written in. It decides the form of the offered QoS
/// profiles, in `metadata.yaml` and in the storage file's own copy (MCAP channel metadata,
/// sqlite `topics` rows), and that form decides which ROS 2 distributions read the bag:
/// rosbag2 before Jazzy reads `offered_qos_profiles` as a string of integer enums only, and
/// stops at a list (`Exception on parsing info file: ... bad conversion`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MetadataVersion {
    /// Version 8, rosbag2 Iron's: QoS as a YAML string with integer enums. Humble (which
    /// writes version 5) reads it too: its reader takes the keys of the versions it knows and
    /// ignores the others. Jazzy and later read it.
    V8,
    /// Version 9, rosbag2 Jazzy's and later: QoS as a YAML list with string enums.
    #[default]
    V9,
}

impl MetadataVersion {
    pub fn number(self) -> u32 {
        match self {
            MetadataVersion::V8 => 8,
            MetadataVersion::V9 => 9,
        }
    }

    /// The first ROS 2 distribution whose rosbag2 writes this version: the `ros_distro` a bag
    /// of this version is labelled with when none is given, so that the label never names a
    /// distribution that cannot read the bag (`jazzy` on a version-8 bag said it was Jazzy's
    /// format; a Humble recording kept at 8 by `bag convert` keeps `humble`, which reads it).
    pub fn distribution(self) -> &'static str {
        match self {
            MetadataVersion::V8 => "iron",
            MetadataVersion::V9 => "jazzy",
        }
    }

    /// The version of a bag made from a source bag that records `source`
    /// ([`BagReader::recorded_version`](crate::BagReader::recorded_version)) when none is
    /// asked for: a source that the distributions before Jazzy wrote gives 8, which they read,
    /// since their `ros2 bag info` and `play` cannot parse 9 (ros2/rosbag2#2013). That is a
    /// recorded version of 8 or older (Humble writes 5, Iron 8), or, where no version is
    /// recorded, a distribution before Jazzy (Humble, Iron and older) or a sqlite3 layout only
    /// they write. Anything else (version 9, Jazzy or later, nothing recorded) gives 9.
    pub fn like_source(source: Option<&RecordedVersion>) -> Self {
        let before_jazzy = match source {
            Some(
                RecordedVersion::MetadataYaml(version) | RecordedVersion::StorageFile(version),
            ) => *version < 9,
            Some(RecordedVersion::Distribution(name)) => DISTRIBUTIONS_BEFORE_JAZZY
                .iter()
                .any(|before| name.eq_ignore_ascii_case(before)),
            Some(RecordedVersion::SqliteLayoutBeforeJazzy) => true,
            None => false,
        };
        if before_jazzy {
            MetadataVersion::V8
        } else {
            MetadataVersion::default()
        }
    }
}

/// The `ROS_DISTRO` names of the ROS 2 distributions before Jazzy.
const DISTRIBUTIONS_BEFORE_JAZZY: [&str; 9] = [
    "ardent", "bouncy", "crystal", "dashing", "eloquent", "foxy", "galactic", "humble", "iron",
];

impl std::str::FromStr for MetadataVersion {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "8" => Ok(MetadataVersion::V8),
            "9" => Ok(MetadataVersion::V9),
            other => Err(format!(
                "unsupported rosbag2 metadata version `{other}` (expected 8, read by Humble, Iron \
                 and later, or 9, read by Jazzy and later)"
            )),
        }
    }
}

/// How a bag is written.
#[derive(Debug, Clone)]
pub struct WriterOptions {
    pub storage: StorageId,
    pub compression: Compression,
    /// Target uncompressed MCAP chunk size in bytes; a full chunk is written out at once.
    pub chunk_size: u64,
    /// At the first write this long after the last flush, the current chunk (or sqlite
    /// transaction) is written out and `metadata.yaml` rewritten: bounds what a kill loses
    /// while messages keep coming. Only writes check it; during a pause call `flush()`.
    pub flush_interval: Duration,
    /// `ros_distro` recorded in the metadata (informative only: `metadata_version` decides
    /// the format); `None` names the distribution of `metadata_version`
    /// ([`MetadataVersion::distribution`]).
    pub ros_distro: Option<String>,
    pub custom_data: BTreeMap<String, String>,
    /// Version 9 by default; version 8 for a bag that ROS 2 Humble or Iron must read.
    pub metadata_version: MetadataVersion,
}

impl WriterOptions {
    /// The `ros_distro` the bag is labelled with.
    pub fn ros_distro(&self) -> &str {
        self.ros_distro
            .as_deref()
            .unwrap_or_else(|| self.metadata_version.distribution())
    }
}

impl Default for WriterOptions {
    fn default() -> Self {
        Self {
            storage: StorageId::Mcap,
            compression: Compression::None,
            chunk_size: 1 << 20,
            flush_interval: Duration::from_millis(500),
            ros_distro: None,
            custom_data: BTreeMap::new(),
            metadata_version: MetadataVersion::default(),
        }
    }
}

/// Checks a topic name as rcl checks a fully qualified one (`rcl_validate_topic_name`, then
/// `rmw_validate_full_topic_name`): `ros2 bag play` creates a publisher per topic, and rcl
/// refuses any other name.
pub fn validate_topic_name(name: &str) -> std::result::Result<(), String> {
    const RULE: &str = "a ROS 2 topic name is '/' then name tokens separated by single '/', \
                        each of ASCII letters, digits and '_' and not starting with a digit \
                        (rcl_validate_topic_name)";
    // rmw's limit (RMW_TOPIC_MAX_NAME_LENGTH), which leaves room for the DDS prefix.
    const MAX_LEN: usize = 247;
    let problem = match name.strip_prefix('/') {
        _ if name.len() > MAX_LEN => format!("is longer than {MAX_LEN} characters"),
        None => "does not start with '/'".to_string(),
        Some(tokens) if tokens.is_empty() || tokens.ends_with('/') => "ends with '/'".to_string(),
        Some(tokens) if tokens.split('/').any(str::is_empty) => "contains `//`".to_string(),
        Some(tokens) => {
            if let Some(c) = tokens
                .chars()
                .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '/'))
            {
                format!("contains {c:?}")
            } else if let Some(token) = tokens
                .split('/')
                .find(|t| t.starts_with(|c: char| c.is_ascii_digit()))
            {
                format!("has a token `{token}` that starts with a digit")
            } else {
                return Ok(());
            }
        }
    };
    Err(format!("topic `{name}` {problem}: {RULE}"))
}

/// A topic added to a [`BagWriter`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TopicHandle(usize);

/// A topic as the storage back-ends need it.
#[derive(Debug, Clone)]
pub(crate) struct WriterTopic {
    pub name: String,
    pub type_name: String,
    pub serialization_format: String,
    /// The definition's encoding and text as stored: both empty for a topic without one, as
    /// rosbag2 stores it.
    pub schema_encoding: String,
    pub schema_text: String,
    pub qos: Vec<OfferedQos>,
    pub type_description_hash: String,
    pub storage_id: i64,
    pub message_count: u64,
}

#[cfg(test)]
impl WriterTopic {
    /// A `std_msgs/msg/String` topic `name` added to `sink`, for the storages' own tests.
    pub(crate) fn string_added_to(sink: &mut dyn StorageSink, name: &str) -> Self {
        let mut topic = WriterTopic {
            name: name.into(),
            type_name: "std_msgs/msg/String".into(),
            serialization_format: "cdr".into(),
            schema_encoding: ROS2MSG.into(),
            schema_text: "string data\n".into(),
            qos: Vec::new(),
            type_description_hash: String::new(),
            storage_id: 0,
            message_count: 0,
        };
        topic.storage_id = sink.add_topic(&topic).unwrap();
        topic
    }
}

/// What a storage back-end does; the writer keeps topics, counts and metadata.
pub(crate) trait StorageSink {
    fn add_topic(&mut self, topic: &WriterTopic) -> Result<i64>;
    fn write(
        &mut self,
        topic: &WriterTopic,
        log_time_ns: i64,
        publish_time_ns: i64,
        data: &[u8],
    ) -> Result<()>;
    fn flush(&mut self) -> Result<()>;
    fn finish(&mut self, metadata: &BagMetadata) -> Result<()>;
}

/// What a finished bag holds.
#[derive(Debug, Clone)]
pub struct BagSummary {
    pub dir: PathBuf,
    pub metadata: BagMetadata,
}

/// Where a writer is: a `finish` that failed leaves an incomplete storage file, which later
/// calls (and `Drop`) must not report as finished.
enum State {
    Open,
    Finished(Box<BagSummary>),
    /// The text of the error the failed `finish` returned.
    FinishFailed(String),
}

/// Writes one rosbag2 directory. Dropping it finishes the bag (best effort, errors ignored);
/// call [`BagWriter::finish`] to see errors.
pub struct BagWriter {
    dir: PathBuf,
    file_name: String,
    options: WriterOptions,
    sink: Box<dyn StorageSink + Send>,
    topics: Vec<WriterTopic>,
    time_bounds: Option<(i64, i64)>,
    last_flush: Instant,
    state: State,
}

impl BagWriter {
    /// Creates the bag directory `dir` (which must not already hold a bag) and its storage file.
    pub fn create(dir: impl AsRef<Path>, options: WriterOptions) -> Result<Self> {
        let dir = dir.as_ref().to_path_buf();
        if options.storage == StorageId::Sqlite3 && options.compression != Compression::None {
            return Err(BagError::Write {
                path: dir,
                message: "compression is only supported with MCAP storage".into(),
            });
        }
        if dir.join("metadata.yaml").exists() {
            return Err(BagError::Write {
                path: dir,
                message: "a bag already exists there".into(),
            });
        }
        // A recorder killed before it wrote metadata.yaml leaves only these; our reader reads
        // them as a bag, and a metadata.yaml of ours would hide them.
        if let Some(file) = crate::reader::storage_file_in(&dir) {
            return Err(BagError::Write {
                path: dir,
                message: format!(
                    "it holds a bag's storage file, {}, without metadata.yaml: readers take the \
                     folder for that bag, which a new metadata.yaml would hide; write to a \
                     folder holding no bag",
                    file.display()
                ),
            });
        }
        std::fs::create_dir_all(&dir).map_err(io_error(&dir, "cannot create the bag directory"))?;
        let stem = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .filter(|n| !n.is_empty() && n != "..")
            .unwrap_or_else(|| "bag".to_string());
        let file_name = format!("{stem}_0.{}", options.storage.extension());
        let file_path = dir.join(&file_name);
        let sink: Box<dyn StorageSink + Send> = match options.storage {
            StorageId::Mcap => Box::new(McapSink::create(
                &file_path,
                options.compression,
                options.chunk_size,
                options.metadata_version.number(),
            )?),
            StorageId::Sqlite3 => Box::new(SqliteSink::create(
                &file_path,
                options.ros_distro(),
                options.metadata_version.number(),
            )?),
        };
        let writer = Self {
            dir,
            file_name,
            options,
            sink,
            topics: Vec::new(),
            time_bounds: None,
            last_flush: Instant::now(),
            state: State::Open,
        };
        writer.metadata().write(&writer.dir)?;
        Ok(writer)
    }

    /// The bag directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Adds a topic with its type, `ros2msg` schema text (the .msg and its dependencies) and QoS.
    /// A blank schema is stored as an empty definition, as rosbag2 stores a type it has no
    /// definition of (readers that decode by the stored definition cannot decode its messages).
    /// Its type hash is ours where the type is one we mirror and the schema has our fields
    /// ([`lidar_har_msgs::schema::type_hash_of`]), else empty, as rosbag2 records an unknown one.
    pub fn add_topic(
        &mut self,
        name: &str,
        type_name: &str,
        schema_text: &str,
        qos: QosProfile,
    ) -> Result<TopicHandle> {
        validate_topic_name(name).map_err(|message| self.refusal(message))?;
        // A blank text is no definition, stored as rosbag2 stores one it did not find.
        let encoding = if schema_text.trim().is_empty() {
            ""
        } else {
            ROS2MSG
        };
        self.add_topic_with(
            name,
            type_name,
            (encoding, schema_text),
            vec![OfferedQos::from(qos)],
            lidar_har_msgs::schema::type_hash_of(type_name, schema_text).unwrap_or_default(),
        )
    }

    /// Adds a topic for message type `M`, taking its type name, schema and hash from the type.
    pub fn add_topic_for<M: RosMessage>(
        &mut self,
        name: &str,
        qos: QosProfile,
    ) -> Result<TopicHandle> {
        validate_topic_name(name).map_err(|message| self.refusal(message))?;
        self.add_topic_with(
            name,
            M::TYPE_NAME,
            (ROS2MSG, &M::schema_text()),
            vec![OfferedQos::from(qos)],
            M::DEFINITION.type_hash,
        )
    }

    /// Adds a topic of the contract (`lidar_har_msgs::topics`) with its type, schema, type
    /// hash and QoS.
    pub fn add_contract_topic(&mut self, topic: &TopicSpec) -> Result<TopicHandle> {
        validate_topic_name(topic.name).map_err(|message| self.refusal(message))?;
        self.add_topic_with(
            topic.name,
            topic.type_name,
            (ROS2MSG, &topic.definition.schema_text()),
            vec![OfferedQos::from(topic.qos)],
            topic.definition.type_hash,
        )
    }

    /// Adds a topic copied from another bag: keeps its name, QoS list, type hash and stored
    /// definition as they were (an `ros2idl` one, or none; a name rcl would refuse, which
    /// another tool recorded), as rosbag2's convert copies them.
    pub fn add_topic_like(&mut self, topic: &TopicInfo) -> Result<TopicHandle> {
        self.add_topic_with(
            &topic.name,
            &topic.type_name,
            (
                &topic.schema_encoding,
                topic.schema_text.as_deref().unwrap_or_default(),
            ),
            topic.offered_qos.clone(),
            &topic.type_description_hash,
        )
    }

    /// Whether a topic of this name and type can be copied ([`BagWriter::add_topic_like`]):
    /// an absolute name and a `pkg/msg/Type` type. A bag converter checks its topics with this
    /// before it creates the new bag, so that a refusal leaves nothing behind. Topics of our
    /// own (`add_topic`, `add_topic_for`) must also have a name rcl takes
    /// ([`validate_topic_name`]).
    pub fn check_topic(name: &str, type_name: &str) -> std::result::Result<(), String> {
        if !name.starts_with('/') || name.len() < 2 {
            return Err(format!("topic `{name}` is not an absolute topic name"));
        }
        if type_name.split('/').count() != 3 {
            return Err(format!(
                "topic `{name}`: type `{type_name}` is not of the form `pkg/msg/Type`"
            ));
        }
        Ok(())
    }

    fn refusal(&self, message: String) -> BagError {
        BagError::Write {
            path: self.dir.clone(),
            message,
        }
    }

    /// `definition`: encoding and text, stored as rosbag2 stores them: as none where the
    /// encoding is empty or `unknown`.
    fn add_topic_with(
        &mut self,
        name: &str,
        type_name: &str,
        definition: (&str, &str),
        qos: Vec<OfferedQos>,
        type_description_hash: &str,
    ) -> Result<TopicHandle> {
        let problem = if let Some(closed) = self.closed() {
            Some(closed)
        } else if self.topics.iter().any(|t| t.name == name) {
            Some(format!("topic `{name}` added twice"))
        } else {
            Self::check_topic(name, type_name).err()
        };
        if let Some(message) = problem {
            return Err(self.refusal(message));
        }
        let (schema_encoding, schema_text) =
            stored_definition(definition.0, definition.1).unwrap_or_default();
        let mut topic = WriterTopic {
            name: name.to_string(),
            type_name: type_name.to_string(),
            serialization_format: crate::mcap_storage::MESSAGE_ENCODING.to_string(),
            schema_encoding,
            schema_text,
            qos,
            type_description_hash: type_description_hash.to_string(),
            storage_id: 0,
            message_count: 0,
        };
        topic.storage_id = self.sink.add_topic(&topic)?;
        self.topics.push(topic);
        self.metadata().write(&self.dir)?;
        Ok(TopicHandle(self.topics.len() - 1))
    }

    /// Writes one serialised (CDR, with encapsulation header) message received at
    /// `log_time_ns`, and sent then too.
    pub fn write(&mut self, topic: TopicHandle, log_time_ns: i64, cdr: &[u8]) -> Result<()> {
        self.write_sent_at(topic, log_time_ns, log_time_ns, cdr)
    }

    /// Writes one serialised message received at `log_time_ns` and sent at `publish_time_ns`
    /// (rosbag2's receive and send timestamps, MCAP `log_time` and `publish_time`; sqlite3
    /// keeps only the first, as rosbag2's does). `bag convert` keeps both so.
    pub fn write_sent_at(
        &mut self,
        topic: TopicHandle,
        log_time_ns: i64,
        publish_time_ns: i64,
        cdr: &[u8],
    ) -> Result<()> {
        if let Some(message) = self.closed() {
            return Err(BagError::Write {
                path: self.dir.clone(),
                message,
            });
        }
        let Some(entry) = self.topics.get_mut(topic.0) else {
            return Err(BagError::UnknownTopicId {
                path: self.dir.clone(),
                id: topic.0 as i64,
            });
        };
        if log_time_ns < 0 {
            return Err(BagError::Write {
                path: self.dir.clone(),
                message: format!("`{}`: negative log time {log_time_ns} ns", entry.name),
            });
        }
        if publish_time_ns < 0 {
            return Err(BagError::Write {
                path: self.dir.clone(),
                message: format!(
                    "`{}`: negative publish time {publish_time_ns} ns",
                    entry.name
                ),
            });
        }
        self.sink.write(entry, log_time_ns, publish_time_ns, cdr)?;
        entry.message_count += 1;
        self.time_bounds = Some(match self.time_bounds {
            None => (log_time_ns, log_time_ns),
            Some((lo, hi)) => (lo.min(log_time_ns), hi.max(log_time_ns)),
        });
        if self.last_flush.elapsed() >= self.options.flush_interval {
            self.flush()?;
        }
        Ok(())
    }

    /// Serialises `msg` and writes it; refuses a message type other than the topic's.
    pub fn write_message<M: RosMessage>(
        &mut self,
        topic: TopicHandle,
        log_time_ns: i64,
        msg: &M,
    ) -> Result<()> {
        let Some(entry) = self.topics.get(topic.0) else {
            return Err(BagError::UnknownTopicId {
                path: self.dir.clone(),
                id: topic.0 as i64,
            });
        };
        if entry.type_name != M::TYPE_NAME {
            return Err(BagError::WrongType {
                topic: entry.name.clone(),
                expected: M::TYPE_NAME,
                found: entry.type_name.clone(),
            });
        }
        let cdr = lidar_har_msgs::encode(msg).map_err(|cause| BagError::Decode {
            topic: entry.name.clone(),
            log_time_ns,
            cause,
        })?;
        self.write(topic, log_time_ns, &cdr)
    }

    /// Writes buffered messages to disk and rewrites `metadata.yaml`: after this returns,
    /// a kill loses nothing written so far.
    pub fn flush(&mut self) -> Result<()> {
        if matches!(self.state, State::Finished(_)) {
            return Ok(());
        }
        if let Some(message) = self.closed() {
            return Err(BagError::Write {
                path: self.dir.clone(),
                message,
            });
        }
        self.sink.flush()?;
        self.metadata().write(&self.dir)?;
        self.last_flush = Instant::now();
        Ok(())
    }

    /// Completes the storage file (MCAP summary, statistics and `rosbag2` record; sqlite
    /// metadata row) and writes the final `metadata.yaml`. Calling it again returns the same
    /// summary, or an error again when it failed; signal handlers in binaries can call it from
    /// their shutdown path.
    pub fn finish(&mut self) -> Result<BagSummary> {
        if let State::Finished(summary) = &self.state {
            return Ok(BagSummary::clone(summary));
        }
        if let Some(message) = self.closed() {
            return Err(BagError::Write {
                path: self.dir.clone(),
                message,
            });
        }
        let metadata = self.metadata();
        let done = self
            .sink
            .finish(&metadata)
            .and_then(|()| metadata.write(&self.dir));
        if let Err(e) = done {
            self.state = State::FinishFailed(e.to_string());
            return Err(e);
        }
        let summary = BagSummary {
            dir: self.dir.clone(),
            metadata,
        };
        self.state = State::Finished(Box::new(summary.clone()));
        Ok(summary)
    }

    /// Why nothing more can be written, once the bag is finished or finishing it failed.
    fn closed(&self) -> Option<String> {
        match &self.state {
            State::Open => None,
            State::Finished(_) => Some("the bag is already finished".to_string()),
            State::FinishFailed(error) => Some(format!(
                "finishing the bag failed earlier, its storage file is incomplete ({error})"
            )),
        }
    }

    fn metadata(&self) -> BagMetadata {
        let (start, end) = self.time_bounds.unwrap_or((0, 0));
        let message_count = self.topics.iter().map(|t| t.message_count).sum();
        let version = self.options.metadata_version.number();
        BagMetadata {
            version,
            storage_identifier: self.options.storage.as_str().to_string(),
            duration: Nanoseconds {
                nanoseconds: end - start,
            },
            starting_time: NanosecondsSinceEpoch {
                nanoseconds_since_epoch: start,
            },
            message_count,
            topics_with_message_count: self
                .topics
                .iter()
                .map(|t| TopicWithCount {
                    topic_metadata: TopicMetadata {
                        name: t.name.clone(),
                        type_name: t.type_name.clone(),
                        serialization_format: t.serialization_format.clone(),
                        offered_qos_profiles: qos::to_metadata_value(&t.qos, version),
                        type_description_hash: t.type_description_hash.clone(),
                    },
                    message_count: t.message_count,
                })
                .collect(),
            compression_format: String::new(),
            compression_mode: String::new(),
            relative_file_paths: vec![self.file_name.clone()],
            files: vec![FileInformation {
                path: self.file_name.clone(),
                starting_time: NanosecondsSinceEpoch {
                    nanoseconds_since_epoch: start,
                },
                duration: Nanoseconds {
                    nanoseconds: end - start,
                },
                message_count,
            }],
            custom_data: Some(self.options.custom_data.clone()),
            ros_distro: self.options.ros_distro().to_string(),
        }
    }
}

impl Drop for BagWriter {
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

#[cfg(test)]
mod tests {
    use lidar_har_msgs::qos::QosProfile;
    use serde_yaml_ng::Value;

    use super::*;
    use crate::BagReader;

    /// A folder holding a recording cut short (storage files, no metadata.yaml) is a bag to
    /// the reader: writing there hid it behind a metadata.yaml listing only the new file.
    #[test]
    fn a_folder_holding_storage_files_without_metadata_is_not_written_over() {
        let tmp = tempfile::tempdir().unwrap();
        for storage in ["rec_0.db3", "rec_0.mcap", "rec_0.mcap.zstd"] {
            let dir = tmp.path().join(storage.replace('.', "_"));
            std::fs::create_dir(&dir).unwrap();
            std::fs::write(dir.join(storage), b"recorded").unwrap();
            std::fs::write(dir.join("summary.json"), b"{}").unwrap();
            let err = BagWriter::create(&dir, WriterOptions::default())
                .err()
                .expect("refused");
            assert!(err.to_string().contains(storage), "{storage}: {err}");
            assert!(!dir.join("metadata.yaml").exists(), "{storage}");
        }
        // Other files (a run's summary.json, a picture) are no bag.
        let dir = tmp.path().join("other");
        std::fs::create_dir(&dir).unwrap();
        std::fs::write(dir.join("summary.json"), b"{}").unwrap();
        BagWriter::create(&dir, WriterOptions::default()).expect("written");
    }

    /// A Humble (5) or Iron (8) source gives, unasked, a bag they read: `run` and `bag
    /// convert` used to write version 9, which their `ros2 bag info` cannot parse.
    #[test]
    fn a_bag_made_from_one_older_than_jazzy_is_of_a_version_they_read() {
        use RecordedVersion::*;
        let like = |recorded: RecordedVersion| MetadataVersion::like_source(Some(&recorded));
        assert_eq!(like(MetadataYaml(5)), MetadataVersion::V8);
        assert_eq!(like(MetadataYaml(8)), MetadataVersion::V8);
        assert_eq!(like(MetadataYaml(9)), MetadataVersion::V9);
        assert_eq!(like(StorageFile(8)), MetadataVersion::V8);
        assert_eq!(like(StorageFile(9)), MetadataVersion::V9);
        assert_eq!(like(Distribution("humble".into())), MetadataVersion::V8);
        assert_eq!(like(Distribution("iron".into())), MetadataVersion::V8);
        assert_eq!(like(Distribution("foxy".into())), MetadataVersion::V8);
        assert_eq!(like(Distribution("jazzy".into())), MetadataVersion::V9);
        assert_eq!(like(Distribution("rolling".into())), MetadataVersion::V9);
        assert_eq!(like(SqliteLayoutBeforeJazzy), MetadataVersion::V8);
        assert_eq!(MetadataVersion::like_source(None), MetadataVersion::V9);
    }

    /// A version-8 bag labelled `jazzy` (as every bag was) named a distribution whose rosbag2
    /// writes 9; the label now follows the format unless one is given.
    #[test]
    fn a_bag_is_labelled_with_a_distribution_that_writes_its_version() {
        let tmp = tempfile::tempdir().unwrap();
        let cases = [
            (MetadataVersion::V8, None, "iron"),
            (MetadataVersion::V9, None, "jazzy"),
            (MetadataVersion::V8, Some("humble"), "humble"),
        ];
        for (version, given, expected) in cases {
            for storage in [StorageId::Mcap, StorageId::Sqlite3] {
                let dir = tmp
                    .path()
                    .join(format!("{}_{storage}_{expected}", version.number()));
                let options = WriterOptions {
                    storage,
                    metadata_version: version,
                    ros_distro: given.map(str::to_string),
                    ..WriterOptions::default()
                };
                BagWriter::create(&dir, options).unwrap().finish().unwrap();
                let reader = BagReader::open(&dir).unwrap();
                assert_eq!(
                    reader.metadata().ros_distro,
                    expected,
                    "{storage} {version:?}"
                );
                if storage == StorageId::Sqlite3 {
                    let file = dir.join(format!(
                        "{}_0.db3",
                        dir.file_name().unwrap().to_str().unwrap()
                    ));
                    let in_schema: String = rusqlite::Connection::open(file)
                        .unwrap()
                        .query_row("SELECT ros_distro FROM schema", [], |row| row.get(0))
                        .unwrap();
                    assert_eq!(in_schema, expected, "{version:?}");
                }
            }
        }
    }

    /// The value of `key` in the metadata of the MCAP channel of `topic` in `file`.
    fn mcap_channel_metadata(file: &Path, topic: &str, key: &str) -> String {
        let bytes = std::fs::read(file).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let channel = summary
            .channels
            .values()
            .find(|c| c.topic == topic)
            .unwrap();
        channel.metadata[key].clone()
    }

    /// The type hash each storage file keeps for `topic`: MCAP channel metadata
    /// `topic_type_hash`; sqlite `topics` and `message_definitions` (both, which must agree).
    fn storage_type_hash(file: &Path, storage: StorageId, topic: &str) -> String {
        match storage {
            StorageId::Mcap => mcap_channel_metadata(file, topic, "topic_type_hash"),
            StorageId::Sqlite3 => {
                let (in_topics, in_definitions): (String, String) =
                    rusqlite::Connection::open(file)
                        .unwrap()
                        .query_row(
                            "SELECT t.type_description_hash, d.type_description_hash
                             FROM topics t JOIN message_definitions d ON d.topic_type = t.type
                             WHERE t.name = ?1",
                            [topic],
                            |row| Ok((row.get(0)?, row.get(1)?)),
                        )
                        .unwrap();
                assert_eq!(in_topics, in_definitions, "{topic}");
                in_topics
            }
        }
    }

    /// Every hash was written empty: rosbag2 Iron and later record a topic's RIHS01 type hash
    /// in metadata.yaml (metadata version 7 and later) and in the storage file. A type we
    /// mirror gets ours, whichever way it is added; an unknown one stays empty.
    #[test]
    fn a_known_type_is_recorded_with_its_hash_in_metadata_and_storage() {
        use lidar_har_msgs::lidar_har_msgs::FallAlert;
        use lidar_har_msgs::sensor_msgs::LaserScan;
        let tmp = tempfile::tempdir().unwrap();
        for version in [MetadataVersion::V8, MetadataVersion::V9] {
            for storage in [StorageId::Mcap, StorageId::Sqlite3] {
                let name = format!("v{}_{storage}", version.number());
                let dir = tmp.path().join(&name);
                let options = WriterOptions {
                    storage,
                    metadata_version: version,
                    ..WriterOptions::default()
                };
                let mut writer = BagWriter::create(&dir, options).unwrap();
                writer
                    .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
                    .unwrap();
                writer
                    .add_topic(
                        "/fall",
                        FallAlert::TYPE_NAME,
                        &FallAlert::schema_text(),
                        QosProfile::reliable(10),
                    )
                    .unwrap();
                writer
                    .add_topic(
                        "/chatter",
                        "std_msgs/msg/String",
                        "string data\n",
                        QosProfile::reliable(10),
                    )
                    .unwrap();
                writer.finish().unwrap();
                let yaml: Value = serde_yaml_ng::from_str(
                    &std::fs::read_to_string(dir.join("metadata.yaml")).unwrap(),
                )
                .unwrap();
                let listed = &yaml["rosbag2_bagfile_information"]["topics_with_message_count"];
                let file = dir.join(format!("{name}_0.{}", storage.extension()));
                let reader = BagReader::open(&dir).unwrap();
                for (i, (topic, hash)) in [
                    ("/scan", LaserScan::DEFINITION.type_hash),
                    ("/fall", FallAlert::DEFINITION.type_hash),
                    ("/chatter", ""),
                ]
                .into_iter()
                .enumerate()
                {
                    let in_metadata = &listed[i]["topic_metadata"]["type_description_hash"];
                    assert_eq!(in_metadata.as_str(), Some(hash), "{name} {topic}");
                    assert_eq!(
                        storage_type_hash(&file, storage, topic),
                        hash,
                        "{name} {topic}"
                    );
                    assert_eq!(
                        reader.topic(topic).unwrap().type_description_hash,
                        hash,
                        "{name} {topic}"
                    );
                }
            }
        }
        assert!(
            LaserScan::DEFINITION
                .type_hash
                .starts_with("RIHS01_64c19139")
        );
    }

    /// Writes `/map` (latched) and `/scan` (sensor data) in `storage` at `version`.
    fn write_map_and_scan(dir: &Path, storage: StorageId, version: MetadataVersion) {
        let options = WriterOptions {
            storage,
            metadata_version: version,
            ..WriterOptions::default()
        };
        let mut writer = BagWriter::create(dir, options).unwrap();
        let map = writer
            .add_topic(
                "/map",
                "std_msgs/msg/String",
                "string data\n",
                QosProfile::latched(1),
            )
            .unwrap();
        writer
            .add_topic(
                "/scan",
                "std_msgs/msg/String",
                "string data\n",
                QosProfile::sensor_data(),
            )
            .unwrap();
        writer.write(map, 5, &[0, 1, 0, 0, 1, 0, 0, 0, 0]).unwrap();
        writer.finish().unwrap();
    }

    /// The QoS text each storage file keeps for `topic`, as rosbag2 reads it there.
    fn storage_qos(file: &Path, storage: StorageId, topic: &str) -> String {
        match storage {
            StorageId::Mcap => mcap_channel_metadata(file, topic, "offered_qos_profiles"),
            StorageId::Sqlite3 => rusqlite::Connection::open(file)
                .unwrap()
                .query_row(
                    "SELECT offered_qos_profiles FROM topics WHERE name = ?1",
                    [topic],
                    |row| row.get(0),
                )
                .unwrap(),
        }
    }

    /// rosbag2 before Jazzy reads `offered_qos_profiles` with yaml-cpp's `as<std::string>()`
    /// and each enum with `as<int>()`: a version-9 list (or string enums in the storage file)
    /// stops `ros2 bag info` and `play` on Humble. Version 8 keeps that form everywhere, and
    /// `/map` stays transient local.
    #[test]
    fn version_8_writes_qos_as_humble_reads_it_in_metadata_and_storage() {
        let tmp = tempfile::tempdir().unwrap();
        for storage in [StorageId::Mcap, StorageId::Sqlite3] {
            let dir = tmp.path().join(format!("v8_{storage}"));
            write_map_and_scan(&dir, storage, MetadataVersion::V8);
            let yaml: Value = serde_yaml_ng::from_str(
                &std::fs::read_to_string(dir.join("metadata.yaml")).unwrap(),
            )
            .unwrap();
            let info = &yaml["rosbag2_bagfile_information"];
            assert_eq!(info["version"], Value::from(8), "{storage}");
            let file = dir.join(format!("v8_{storage}_0.{}", storage.extension()));
            for (i, topic) in ["/map", "/scan"].into_iter().enumerate() {
                let in_metadata =
                    info["topics_with_message_count"][i]["topic_metadata"]["offered_qos_profiles"]
                        .as_str()
                        .unwrap_or_else(|| panic!("{storage} {topic}: not a string"))
                        .to_string();
                for text in [in_metadata, storage_qos(&file, storage, topic)] {
                    let profiles: Value = serde_yaml_ng::from_str(&text).unwrap();
                    for key in ["history", "reliability", "durability", "liveliness"] {
                        assert!(
                            profiles[0][key].is_u64(),
                            "{storage} {topic}: `{key}` is not an integer in {text}"
                        );
                    }
                    let (reliability, durability) = if topic == "/map" { (1, 1) } else { (2, 2) };
                    assert_eq!(profiles[0]["reliability"], Value::from(reliability));
                    assert_eq!(profiles[0]["durability"], Value::from(durability), "{text}");
                }
            }
            let reader = BagReader::open(&dir).unwrap();
            assert_eq!(reader.metadata().metadata_version, Some(8));
            assert_eq!(
                reader.topic("/map").unwrap().offered_qos[0].to_profile(),
                Some(QosProfile::latched(1))
            );
            assert_eq!(reader.messages().unwrap().count(), 1);
        }
        let dir = tmp.path().join("v9");
        write_map_and_scan(&dir, StorageId::Mcap, MetadataVersion::V9);
        let text = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
        assert!(text.contains("version: 9") && text.contains("durability: transient_local"));
        assert!(
            storage_qos(&dir.join("v9_0.mcap"), StorageId::Mcap, "/map")
                .contains("transient_local")
        );
    }

    /// The stored definition of each topic of `file`: `(type, encoding, text)`, as the MCAP
    /// schema records or the sqlite3 `message_definitions` rows hold them.
    fn stored_definitions(file: &Path, storage: StorageId) -> Vec<(String, String, String)> {
        let mut definitions: Vec<(String, String, String)> = match storage {
            StorageId::Mcap => {
                let bytes = std::fs::read(file).unwrap();
                let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
                summary
                    .schemas
                    .values()
                    .map(|s| {
                        let text = String::from_utf8(s.data.to_vec()).unwrap();
                        (s.name.clone(), s.encoding.clone(), text)
                    })
                    .collect()
            }
            StorageId::Sqlite3 => rusqlite::Connection::open(file)
                .unwrap()
                .prepare(
                    "SELECT topic_type, encoding, encoded_message_definition
                     FROM message_definitions",
                )
                .unwrap()
                .query_map([], |row| Ok((row.get(0)?, row.get(1)?, row.get(2)?)))
                .unwrap()
                .collect::<rusqlite::Result<_>>()
                .unwrap(),
        };
        definitions.sort();
        definitions
    }

    /// rosbag2 records a type whose package the recorder cannot find with an empty definition
    /// (encoding and text empty; `unknown` is taken as empty too), and a type defined only in
    /// .idl as `ros2idl`. The writer refused both ("has no schema text"), so `bag convert`
    /// refused such a recording; each is now copied as rosbag2 stores it, in either storage.
    /// A `ros2msg` one with a blank text (a type without fields) stays a `ros2msg` one: taken
    /// for none, its copy lost the encoding decoders read it by.
    #[test]
    fn definitions_other_than_ros2msg_are_copied_as_rosbag2_stores_them() {
        const IDL: &str = "module acme_msgs { module msg { struct Widget { string name; }; }; };\n";
        let stored = [
            ("/empty", "acme_msgs/msg/Empty", "", ""),
            ("/unknown", "acme_msgs/msg/Unknown", "unknown", ""),
            ("/idl", "acme_msgs/msg/Widget", "ros2idl", IDL),
            // A type without fields: a ros2msg definition all the same (std_msgs/msg/Empty).
            ("/blank", "std_msgs/msg/Empty", ROS2MSG, " \n"),
        ];
        let tmp = tempfile::tempdir().unwrap();
        let source = tmp.path().join("source.mcap");
        {
            let file = std::io::BufWriter::new(std::fs::File::create(&source).unwrap());
            let mut writer = mcap::WriteOptions::new()
                .profile(crate::mcap_storage::PROFILE)
                .create(file)
                .unwrap();
            for (sequence, (topic, type_name, encoding, text)) in stored.iter().enumerate() {
                let schema = writer
                    .add_schema(type_name, encoding, text.as_bytes())
                    .unwrap();
                let channel_id = writer
                    .add_channel(schema, topic, "cdr", &BTreeMap::new())
                    .unwrap();
                let header = mcap::records::MessageHeader {
                    channel_id,
                    sequence: sequence as u32,
                    log_time: 1000,
                    publish_time: 1000,
                };
                writer
                    .write_to_known_channel(&header, &[0, 1, 0, 0])
                    .unwrap();
            }
            writer.finish().unwrap();
        }
        let as_read = |reader: &BagReader| -> Vec<(String, String, Option<String>)> {
            let mut topics: Vec<_> = reader
                .topics()
                .iter()
                .map(|t| {
                    let ros2msg = (t.name == "/blank").then_some(" \n");
                    assert_eq!(t.ros2msg_schema(), ros2msg, "{}", t.name);
                    (
                        t.name.clone(),
                        t.schema_encoding.clone(),
                        t.schema_text.clone(),
                    )
                })
                .collect();
            topics.sort();
            topics
        };
        let expected = vec![
            (
                "/blank".to_string(),
                ROS2MSG.to_string(),
                Some(" \n".to_string()),
            ),
            ("/empty".to_string(), String::new(), None),
            (
                "/idl".to_string(),
                "ros2idl".to_string(),
                Some(IDL.to_string()),
            ),
            ("/unknown".to_string(), String::new(), None),
        ];
        let reader = BagReader::open(&source).unwrap();
        assert_eq!(as_read(&reader), expected);
        for storage in [StorageId::Mcap, StorageId::Sqlite3] {
            let dir = tmp.path().join(format!("copy_{storage}"));
            let options = WriterOptions {
                storage,
                ..WriterOptions::default()
            };
            let mut writer = BagWriter::create(&dir, options).unwrap();
            for topic in reader.topics() {
                let handle = writer.add_topic_like(topic).unwrap();
                writer.write(handle, 1000, &[0, 1, 0, 0]).unwrap();
            }
            writer.finish().unwrap();
            let copy = BagReader::open(&dir).unwrap();
            assert_eq!(as_read(&copy), expected, "{storage}");
            let file = dir.join(format!("copy_{storage}_0.{}", storage.extension()));
            // MCAP: an empty schema record, as rosbag2 writes it. sqlite3: no row, which
            // rosbags reads, where it fails on rosbag2's row with an empty encoding.
            let empty = |type_name: &str| (type_name.to_string(), String::new(), String::new());
            let idl = (
                "acme_msgs/msg/Widget".to_string(),
                "ros2idl".to_string(),
                IDL.to_string(),
            );
            let blank = (
                "std_msgs/msg/Empty".to_string(),
                ROS2MSG.to_string(),
                " \n".to_string(),
            );
            let expected_stored = match storage {
                StorageId::Mcap => vec![
                    empty("acme_msgs/msg/Empty"),
                    empty("acme_msgs/msg/Unknown"),
                    idl,
                    blank,
                ],
                StorageId::Sqlite3 => vec![idl, blank],
            };
            assert_eq!(
                stored_definitions(&file, storage),
                expected_stored,
                "{storage}"
            );
            assert_eq!(copy.messages().unwrap().count(), stored.len(), "{storage}");
        }
    }

    /// `ros2 bag play` creates a publisher per topic, and rcl refuses a name outside its
    /// rules: the writer took `/a b`, `/héllo` and `/x//y`, making bags that cannot be played.
    #[test]
    fn topic_names_that_rcl_refuses_are_refused_naming_the_topic_and_the_rule() {
        for topic in lidar_har_msgs::topics::ALL {
            assert_eq!(validate_topic_name(topic.name), Ok(()), "{}", topic.name);
        }
        for name in ["/a", "/_private/x_1", "/A9/b_c/D"] {
            assert_eq!(validate_topic_name(name), Ok(()), "{name}");
        }
        let long = format!("/{}", "a".repeat(300));
        let refused = [
            ("/a b", "contains ' '"),
            ("/héllo", "contains 'é'"),
            ("/ünï/çødé", "contains 'ü'"),
            ("/x//y", "contains `//`"),
            ("/x-y", "contains '-'"),
            ("/x/1y", "has a token `1y` that starts with a digit"),
            ("/x/", "ends with '/'"),
            ("/", "ends with '/'"),
            ("scan", "does not start with '/'"),
            ("~/scan", "does not start with '/'"),
            (&long, "is longer than 247 characters"),
        ];
        let tmp = tempfile::tempdir().unwrap();
        for storage in [StorageId::Mcap, StorageId::Sqlite3] {
            let options = WriterOptions {
                storage,
                ..WriterOptions::default()
            };
            let mut writer = BagWriter::create(tmp.path().join(storage.as_str()), options).unwrap();
            for (name, problem) in refused {
                let error = writer
                    .add_topic(
                        name,
                        "std_msgs/msg/String",
                        "string data\n",
                        QosProfile::reliable(1),
                    )
                    .unwrap_err()
                    .to_string();
                assert!(
                    error.contains(&format!("topic `{name}` {problem}"))
                        && error.contains("rcl_validate_topic_name"),
                    "{storage} {name}: {error}"
                );
            }
            writer
                .add_topic(
                    "/a_1/b",
                    "std_msgs/msg/String",
                    "string data\n",
                    QosProfile::reliable(1),
                )
                .unwrap();
            // A recorded name is copied as it is (another tool recorded it), as rosbag2's
            // convert copies it.
            let recorded = TopicInfo {
                name: "/front-scan".into(),
                type_name: "sensor_msgs/msg/LaserScan".into(),
                serialization_format: "cdr".into(),
                offered_qos: Vec::new(),
                schema_text: None,
                schema_encoding: String::new(),
                type_description_hash: String::new(),
                message_count: 0,
                storage_id: 0,
            };
            writer.add_topic_like(&recorded).unwrap();
            assert_eq!(
                writer
                    .finish()
                    .unwrap()
                    .metadata
                    .topics_with_message_count
                    .len(),
                2
            );
        }
    }
}
