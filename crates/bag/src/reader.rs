//! Reading rosbag2 bags: a directory with `metadata.yaml` (MCAP or sqlite3 storage, one or
//! more files, compressed or not), a directory of storage files without it, or a bare storage
//! file. Messages stream in log-time order in constant memory.

use std::collections::{BTreeSet, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use lidar_har_msgs::RosMessage;

use crate::compression::{self, MessageCompression};
use crate::error::{BagError, Result};
use crate::mcap_storage::{McapFile, McapInput, McapMessages};
use crate::metadata::BagMetadata;
use crate::qos::OfferedQos;
use crate::sqlite_storage::{SqliteFile, SqliteMessages};
use crate::writer::StorageId;

/// The encoding of a definition in .msg form, the one lidar-har writes.
pub(crate) const ROS2MSG: &str = "ros2msg";

/// A stored definition as rosbag2 keeps it, `(encoding, text)`: none where the encoding is
/// empty or `unknown`, which is how rosbag2 stores a type it found no definition for
/// (rosbag2_cpp `SequentialWriter::create_topic`). A `ros2msg` one may be empty: a type
/// without fields (`std_msgs/msg/Empty`), which decoders read by that encoding.
pub(crate) fn stored_definition(encoding: &str, text: &str) -> Option<(String, String)> {
    (!encoding.is_empty() && encoding != "unknown")
        .then(|| (encoding.to_string(), text.to_string()))
}

/// A topic of a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    pub name: String,
    /// e.g. `sensor_msgs/msg/LaserScan`.
    pub type_name: String,
    /// `cdr` for every ROS 2 bag.
    pub serialization_format: String,
    pub offered_qos: Vec<OfferedQos>,
    /// The message definition the bag stores for the type, in [`Self::schema_encoding`];
    /// `None` where it stores none (an empty or `unknown` encoding): rosbag2 (Iron and later)
    /// records a type whose package the recorder could not find so, and Foxy's and Humble's
    /// sqlite3 bags store no definitions at all.
    pub schema_text: Option<String>,
    /// `ros2msg` (the .msg and its dependencies) or `ros2idl` (rosbag2 stores a type defined
    /// only in .idl so); empty where `schema_text` is `None`.
    pub schema_encoding: String,
    pub type_description_hash: String,
    pub message_count: u64,
    /// Channel id (MCAP) or `topics.id` (sqlite3) in the storage file.
    pub(crate) storage_id: i64,
}

impl TopicInfo {
    /// The stored `ros2msg` definition, which is what rosbags, Foxglove and lidar-har's
    /// writer need; `None` for a topic stored without one or with an IDL one.
    pub fn ros2msg_schema(&self) -> Option<&str> {
        self.schema_text
            .as_deref()
            .filter(|_| self.schema_encoding == ROS2MSG)
    }
}

/// One serialised message: CDR bytes with their encapsulation header.
#[derive(Debug, Clone, PartialEq)]
pub struct BagMessage {
    pub topic: Arc<str>,
    /// When the recorder received it (rosbag2's `recv_timestamp`); messages are ordered by it.
    pub log_time_ns: i64,
    /// When the publisher sent it (rosbag2's `send_timestamp`), where the storage records it
    /// (MCAP `publish_time`); the log time where it does not (sqlite3), as rosbag2 reads it.
    pub publish_time_ns: i64,
    pub data: Vec<u8>,
}

/// Which messages a read returns ([`BagReader::messages_matching`]): those of the topics
/// named (all by default) logged in `[start, end)` (the whole bag by default), in nanoseconds.
/// Each storage skips what is outside the range without reading it where it can: an MCAP
/// file with a summary reads (and decompresses) only the chunks whose indexed time span
/// meets the range; sqlite3 asks for the range in its query, which rosbag2's `timestamp_idx`
/// index answers without reading the rows before it (a file without the index is scanned,
/// with the same result); an MCAP file without a summary (cut short) has no index, so its
/// messages are read and those outside are dropped.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MessageFilter {
    topics: Option<BTreeSet<String>>,
    start_ns: Option<i64>,
    end_ns: Option<i64>,
}

impl MessageFilter {
    /// Every message of the bag.
    pub fn new() -> Self {
        Self::default()
    }

    /// Only messages on `topics` (none if it is empty).
    pub fn topics(mut self, topics: &[impl AsRef<str>]) -> Self {
        self.topics = Some(topics.iter().map(|t| t.as_ref().to_string()).collect());
        self
    }

    /// Only messages logged at or after `start_ns`.
    pub fn starting_at(mut self, start_ns: i64) -> Self {
        self.start_ns = Some(start_ns);
        self
    }

    /// Only messages logged before `end_ns`.
    pub fn ending_before(mut self, end_ns: i64) -> Self {
        self.end_ns = Some(end_ns);
        self
    }

    /// The topics asked for, `None` for all.
    pub(crate) fn topic_set(&self) -> Option<&BTreeSet<String>> {
        self.topics.as_ref()
    }

    /// The first log time in the range, if bounded below.
    pub(crate) fn start_ns(&self) -> Option<i64> {
        self.start_ns
    }

    /// The first log time after the range, if bounded above.
    pub(crate) fn end_ns(&self) -> Option<i64> {
        self.end_ns
    }

    /// Whether a message of `topic` logged at `log_time_ns` is selected.
    pub(crate) fn includes(&self, topic: &str, log_time_ns: i64) -> bool {
        self.topics.as_ref().is_none_or(|t| t.contains(topic))
            && self.start_ns.is_none_or(|start| log_time_ns >= start)
            && self.end_ns.is_none_or(|end| log_time_ns < end)
    }

    /// Whether no log time is in the range.
    fn is_empty_range(&self) -> bool {
        matches!((self.start_ns, self.end_ns), (Some(start), Some(end)) if start >= end)
    }
}

/// What a bag records of the rosbag2 that wrote it ([`BagReader::recorded_version`]), which
/// decides the metadata version of a bag made from it
/// ([`MetadataVersion::like_source`](crate::MetadataVersion::like_source)).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RecordedVersion {
    /// `version` of metadata.yaml.
    MetadataYaml(u32),
    /// The version of a storage file's own copy of the metadata, where metadata.yaml is missing
    /// (a killed recorder): sqlite3's `metadata` table (its last row; rosbag2 Iron from 0.22.2
    /// on, and Jazzy and later, write one at each `update_metadata` call of their writer, at a
    /// split or close at least) or the `serialized_metadata` of MCAP's `rosbag2` Metadata
    /// record (written at those calls, from Iron on; `BagWriter` writes it when it finishes).
    StorageFile(u32),
    /// No version recorded, only the `ROS_DISTRO` of the writer, as the storage file names it:
    /// sqlite3's `schema.ros_distro` (rosbag2 Humble from 0.15.4 on and later distributions
    /// write it when they create a file) or the `ROS_DISTRO` of MCAP's `rosbag2` Metadata record
    /// (rosbag2 Iron from 0.22.2 on writes it when it opens a file for writing).
    Distribution(String),
    /// Nothing named, but a sqlite3 layout that only rosbag2 before Jazzy writes: no `schema`
    /// table (Foxy, Galactic, Humble before 0.15.4), or schema version 3 (Humble from 0.15.4
    /// on; Iron and later write 4) with an empty `ros_distro` (`ROS_DISTRO` was unset).
    SqliteLayoutBeforeJazzy,
}

impl RecordedVersion {
    /// The most telling of `recorded` (a version number over a distribution over a layout),
    /// the first of equals.
    pub(crate) fn most_telling(
        recorded: impl IntoIterator<Item = RecordedVersion>,
    ) -> Option<RecordedVersion> {
        recorded.into_iter().min_by_key(|r| match r {
            RecordedVersion::MetadataYaml(_) => 0,
            RecordedVersion::StorageFile(_) => 1,
            RecordedVersion::Distribution(_) => 2,
            RecordedVersion::SqliteLayoutBeforeJazzy => 3,
        })
    }
}

/// What `ros2 bag info` shows about a bag.
#[derive(Debug, Clone)]
pub struct BagInfo {
    pub path: PathBuf,
    pub storage: StorageId,
    pub files: Vec<PathBuf>,
    pub start_ns: i64,
    pub end_ns: i64,
    pub message_count: u64,
    /// `metadata.yaml` version, `None` for a bare `.mcap` file.
    pub metadata_version: Option<u32>,
    pub ros_distro: String,
    /// True when a storage file cannot be read to its end: cut short (a recorder was killed)
    /// or damaged (an MCAP chunk that fails its CRC or does not decompress, a malformed
    /// record), or, in a bag of several files, one cannot be opened at all. Counts cover the
    /// part before; reading the messages ends with the error. `damaged` says which and why.
    pub truncated: bool,
    /// For each storage file that cannot be read to its end, why: the error its read ends
    /// with, which names the file.
    pub damaged: Vec<String>,
}

impl BagInfo {
    /// Saturates: the stamps of a damaged bag may span more than an `i64`.
    pub fn duration_ns(&self) -> i64 {
        self.end_ns.saturating_sub(self.start_ns)
    }
}

enum StorageFile {
    Mcap(Box<McapFile>),
    Sqlite(SqliteFile),
    /// A file of a bag of several that could not be opened, with the error. Like an error
    /// while reading a file, that ends this file only: it is opened again when messages are
    /// read, and its stream is the error.
    Unreadable(String),
}

impl StorageFile {
    /// Whether the file opened as storage with records in it (which may be none of messages).
    fn has_records(&self) -> bool {
        match self {
            StorageFile::Mcap(m) => m.cut_in_magic().is_none(),
            StorageFile::Sqlite(_) => true,
            StorageFile::Unreadable(_) => false,
        }
    }

    /// What the file records of the rosbag2 that wrote it.
    fn recorded_version(&self) -> Option<&RecordedVersion> {
        match self {
            StorageFile::Mcap(m) => m.recorded.as_ref(),
            StorageFile::Sqlite(s) => s.recorded.as_ref(),
            StorageFile::Unreadable(_) => None,
        }
    }

    /// The refusal of a bag of this file alone, when it opened cut in its magic.
    fn cut_in_magic(&self, path: &Path) -> Option<BagError> {
        let StorageFile::Mcap(m) = self else {
            return None;
        };
        m.cut_in_magic().map(|reason| BagError::NotABag {
            path: path.to_path_buf(),
            reason: reason.to_string(),
        })
    }
}

/// An opened bag.
pub struct BagReader {
    path: PathBuf,
    storage: StorageId,
    files: Vec<(PathBuf, StorageFile)>,
    topics: Vec<TopicInfo>,
    metadata: Option<BagMetadata>,
    message_compression: MessageCompression,
}

impl BagReader {
    /// Opens a rosbag2 directory, or a bare storage file (`.mcap`, `.db3`, or one of them
    /// compressed whole by rosbag2, `.zstd`).
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        if !path.exists() {
            return Err(BagError::NotFound { path });
        }
        if path.is_file() {
            // A file named for neither storage is tried as MCAP, whose magic tells.
            let storage = storage_of(&path).unwrap_or(StorageId::Mcap);
            return Self::from_files(
                path.clone(),
                storage,
                vec![path],
                None,
                MessageCompression::ByMagic,
            );
        }
        let metadata_path = path.join("metadata.yaml");
        if !metadata_path.is_file() {
            let (storage, files) = list_storage_files(&path)?;
            return Self::from_files(path, storage, files, None, MessageCompression::ByMagic);
        }
        let metadata = BagMetadata::read(&path)?;
        let message_compression = compression::message_compression(&metadata, &metadata_path)?;
        let storage = match metadata.storage_identifier.as_str() {
            "mcap" => StorageId::Mcap,
            "sqlite3" => StorageId::Sqlite3,
            other => {
                return Err(BagError::UnknownStorage {
                    path: metadata_path,
                    storage_id: other.to_string(),
                });
            }
        };
        let relative: Vec<String> = if metadata.relative_file_paths.is_empty() {
            metadata.files.iter().map(|f| f.path.clone()).collect()
        } else {
            metadata.relative_file_paths.clone()
        };
        if relative.is_empty() {
            return Err(BagError::Metadata {
                path: metadata_path,
                message: "relative_file_paths: no storage file listed".into(),
            });
        }
        let files = relative
            .iter()
            .map(|name| storage_file_path(&path, metadata.version, name))
            .collect();
        Self::from_files(path, storage, files, Some(metadata), message_compression)
    }

    /// Opens MCAP bytes held in memory as a bare `.mcap` (for fuzzing and embedded data).
    pub fn from_mcap_bytes(bytes: impl Into<Arc<[u8]>>) -> Result<Self> {
        let file = StorageFile::Mcap(Box::new(McapFile::open(McapInput::Bytes(bytes.into()))?));
        let path = PathBuf::from("<memory>");
        if let Some(error) = file.cut_in_magic(&path) {
            return Err(error);
        }
        let files = vec![(path.clone(), file)];
        Self::new(
            path,
            StorageId::Mcap,
            files,
            None,
            MessageCompression::ByMagic,
        )
    }

    /// Opens the storage files of a bag. A file that cannot be opened ends that file only (see
    /// [`StorageFile::Unreadable`]), and an MCAP cut in its magic is a truncated split file,
    /// unless no file opens with records: any empty file looks cut in its magic, so a bag of
    /// one file that is not a bag is refused, with the (first) file's error.
    fn from_files(
        path: PathBuf,
        storage: StorageId,
        file_paths: Vec<PathBuf>,
        metadata: Option<BagMetadata>,
        message_compression: MessageCompression,
    ) -> Result<Self> {
        let mut first_error = None;
        let mut files = Vec::new();
        for file_path in file_paths {
            let file = open_storage_file(storage, &file_path).unwrap_or_else(|e| {
                let reason = e.to_string();
                first_error.get_or_insert(e);
                StorageFile::Unreadable(reason)
            });
            if let Some(error) = file.cut_in_magic(&file_path) {
                first_error.get_or_insert(error);
            }
            files.push((file_path, file));
        }
        if let Some(error) = first_error
            && !files.iter().any(|(_, file)| file.has_records())
        {
            return Err(error);
        }
        Self::new(path, storage, files, metadata, message_compression)
    }

    fn new(
        path: PathBuf,
        storage: StorageId,
        files: Vec<(PathBuf, StorageFile)>,
        metadata: Option<BagMetadata>,
        message_compression: MessageCompression,
    ) -> Result<Self> {
        let mut reader = Self {
            path,
            storage,
            files,
            topics: Vec::new(),
            metadata,
            message_compression,
        };
        reader.topics = reader.merge_topics()?;
        Ok(reader)
    }

    /// Topics of all storage files, counts summed; QoS and hashes completed from metadata.yaml.
    /// A topic that comes with two types (two MCAP channels or sqlite `topics` rows, in one
    /// file or in two) is refused: its messages would all be taken for the first type's.
    fn merge_topics(&self) -> Result<Vec<TopicInfo>> {
        let mut topics: Vec<TopicInfo> = Vec::new();
        for (_, file) in &self.files {
            let file_topics: &[TopicInfo] = match file {
                StorageFile::Mcap(m) => &m.topics,
                StorageFile::Sqlite(s) => &s.topics,
                StorageFile::Unreadable(_) => &[],
            };
            for topic in file_topics {
                match topics.iter_mut().find(|t| t.name == topic.name) {
                    Some(existing) if existing.type_name != topic.type_name => {
                        return Err(BagError::TopicWithTwoTypes {
                            path: self.path.clone(),
                            topic: topic.name.clone(),
                            first_type: existing.type_name.clone(),
                            second_type: topic.type_name.clone(),
                        });
                    }
                    Some(existing) => existing.message_count += topic.message_count,
                    None => topics.push(topic.clone()),
                }
            }
        }
        if let Some(metadata) = &self.metadata {
            for listed in &metadata.topics_with_message_count {
                let meta = &listed.topic_metadata;
                if let Some(topic) = topics.iter_mut().find(|t| t.name == meta.name) {
                    if topic.offered_qos.is_empty() {
                        topic.offered_qos = BagMetadata::offered_qos(meta);
                    }
                    if topic.type_description_hash.is_empty() {
                        topic.type_description_hash = meta.type_description_hash.clone();
                    }
                }
            }
        }
        Ok(topics)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn storage(&self) -> StorageId {
        self.storage
    }

    /// The parsed `metadata.yaml`, `None` for a bare `.mcap`.
    pub fn bag_metadata(&self) -> Option<&BagMetadata> {
        self.metadata.as_ref()
    }

    /// What the bag records of the rosbag2 metadata version it was written in: metadata.yaml's
    /// `version`; without metadata.yaml (a killed recorder, a bare file), what its storage
    /// files record (see [`RecordedVersion`]); `None` when they record nothing. Read when the
    /// files are opened (a few rows of small sqlite tables, one small MCAP record found
    /// through the summary's metadata index, or seen by the scan of a file without summary).
    pub fn recorded_version(&self) -> Option<RecordedVersion> {
        match &self.metadata {
            Some(metadata) => Some(RecordedVersion::MetadataYaml(metadata.version)),
            None => RecordedVersion::most_telling(
                self.files
                    .iter()
                    .filter_map(|(_, file)| file.recorded_version().cloned()),
            ),
        }
    }

    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    pub fn topic(&self, name: &str) -> Option<&TopicInfo> {
        self.topics.iter().find(|t| t.name == name)
    }

    /// Storage, files, time span and counts, taken from the storage files themselves (not
    /// only from metadata.yaml, which a killed recorder leaves behind its data).
    pub fn metadata(&self) -> BagInfo {
        let mut bounds: Option<(i64, i64)> = None;
        let mut damaged = Vec::new();
        for (_, file) in &self.files {
            let (file_bounds, damage) = match file {
                StorageFile::Mcap(m) => (m.time_bounds, m.damage.as_ref()),
                StorageFile::Sqlite(s) => (s.time_bounds, None),
                StorageFile::Unreadable(reason) => (None, Some(reason)),
            };
            damaged.extend(damage.cloned());
            if let Some((lo, hi)) = file_bounds {
                bounds = Some(bounds.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
            }
        }
        let (start_ns, end_ns) = bounds.unwrap_or((0, 0));
        BagInfo {
            path: self.path.clone(),
            storage: self.storage,
            files: self.files.iter().map(|(p, _)| p.clone()).collect(),
            start_ns,
            end_ns,
            message_count: self.topics.iter().map(|t| t.message_count).sum(),
            metadata_version: self.metadata.as_ref().map(|m| m.version),
            ros_distro: self
                .metadata
                .as_ref()
                .map(|m| m.ros_distro.clone())
                .unwrap_or_default(),
            truncated: !damaged.is_empty(),
            damaged,
        }
    }

    /// Every message in log-time order (file order inside a storage file cut short).
    pub fn messages(&self) -> Result<Messages> {
        self.messages_matching(&MessageFilter::new())
    }

    /// Messages of the named topics only; an unknown topic name is an error.
    pub fn messages_on(&self, topics: &[&str]) -> Result<Messages> {
        self.messages_matching(&MessageFilter::new().topics(topics))
    }

    /// The messages `filter` selects, in the order of [`Self::messages`]; a topic it names
    /// that the bag lacks is an error. What lies outside its time range is skipped without
    /// being read where the storage allows (see [`MessageFilter`]), so a read that starts
    /// late in a large bag costs what it reads, not what comes before. An error (a file cut
    /// short, a damaged chunk) comes when the read reaches it: one in a part skipped unread
    /// does not come. An empty range reads nothing.
    pub fn messages_matching(&self, filter: &MessageFilter) -> Result<Messages> {
        if let Some(wanted) = &filter.topics {
            for name in wanted {
                if self.topic(name).is_none() {
                    return Err(BagError::UnknownTopic {
                        topic: name.to_string(),
                    });
                }
            }
        }
        let sources: Vec<Source> = if filter.is_empty_range() {
            Vec::new()
        } else {
            self.files
                .iter()
                .map(|(path, file)| Source {
                    path: path.clone(),
                    stream: self
                        .stream(path, file, filter)
                        .unwrap_or_else(|e| Stream::Failed(Some(e))),
                    compression: self.message_compression,
                })
                .collect()
        };
        let heads = sources.iter().map(|_| None).collect();
        Ok(Messages {
            sources,
            heads,
            primed: false,
            errors: VecDeque::new(),
        })
    }

    /// The messages of one storage file; one that could not be opened is opened again.
    fn stream(&self, path: &Path, file: &StorageFile, filter: &MessageFilter) -> Result<Stream> {
        Ok(match file {
            StorageFile::Mcap(m) => Stream::Mcap(m.messages(filter)?),
            StorageFile::Sqlite(s) => Stream::Sqlite(s.messages(filter)?),
            StorageFile::Unreadable(_) => {
                let file = open_storage_file(self.storage, path)?;
                return self.stream(path, &file, filter);
            }
        })
    }

    /// Decodes `message` as `M`, checking first that its topic has type `M`.
    pub fn decode<M: RosMessage>(&self, message: &BagMessage) -> Result<M> {
        let Some(topic) = self.topic(&message.topic) else {
            return Err(BagError::UnknownTopic {
                topic: message.topic.to_string(),
            });
        };
        if topic.type_name != M::TYPE_NAME {
            return Err(BagError::WrongType {
                topic: topic.name.clone(),
                expected: M::TYPE_NAME,
                found: topic.type_name.clone(),
            });
        }
        lidar_har_msgs::decode::<M>(&message.data).map_err(|cause| BagError::Decode {
            topic: topic.name.clone(),
            log_time_ns: message.log_time_ns,
            cause,
        })
    }
}

/// Where a storage file listed in `relative_file_paths` is. Versions 1 to 3 listed it with the
/// bag directory's name in front (`old/old_0.db3`), and rosbag2_cpp resolves those from the
/// directory's parent; from version 4 on the name is relative to the bag directory. When the
/// old form does not lead to a file (the directory was renamed, or opened as `.`), the file
/// name alone is looked up in the bag directory, as `rosbags` does.
fn storage_file_path(dir: &Path, version: u32, listed: &str) -> PathBuf {
    let in_dir = dir.join(listed);
    if version >= 4 {
        return in_dir;
    }
    let from_parent = dir.parent().map(|parent| parent.join(listed));
    let by_name = Path::new(listed).file_name().map(|name| dir.join(name));
    [from_parent, by_name]
        .into_iter()
        .flatten()
        .find(|candidate| candidate.is_file())
        .unwrap_or(in_dir)
}

/// Opens a storage file of `storage`; one that rosbag2 compressed whole is read from a
/// decompressed copy.
fn open_storage_file(storage: StorageId, path: &Path) -> Result<StorageFile> {
    if !path.is_file() {
        return Err(BagError::NotFound {
            path: path.to_path_buf(),
        });
    }
    let source = compression::open_source(path)?;
    Ok(match storage {
        StorageId::Mcap => StorageFile::Mcap(Box::new(McapFile::open(McapInput::File(source))?)),
        StorageId::Sqlite3 => StorageFile::Sqlite(SqliteFile::open(source)?),
    })
}

/// The storage a file's name says it holds: `.mcap` or `.db3`, also compressed whole (`.zstd`).
fn storage_of(path: &Path) -> Option<StorageId> {
    let name = compression::compressed_file_name(path).map_or(path, Path::new);
    let extension = name.extension()?;
    [StorageId::Mcap, StorageId::Sqlite3]
        .into_iter()
        .find(|storage| extension == storage.extension())
}

/// The storage files directly in `dir`, with the storage each one's name says, unordered.
fn storage_files(dir: &Path) -> std::io::Result<impl Iterator<Item = (StorageId, PathBuf)>> {
    Ok(std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .filter_map(|p| Some((storage_of(&p)?, p))))
}

/// A storage file directly in `dir` (none when it cannot be listed, or does not exist).
pub(crate) fn storage_file_in(dir: &Path) -> Option<PathBuf> {
    storage_files(dir).ok()?.next().map(|(_, path)| path)
}

/// The storage files of a directory without metadata.yaml (rosbag2 writes it when recording
/// ends, so a killed recorder leaves none), in split order. A file compressed whole is left out
/// while the file it was made from is still there: rosbag2 deletes that file once the
/// compressed one is complete, so its compression was cut short.
fn list_storage_files(dir: &Path) -> Result<(StorageId, Vec<PathBuf>)> {
    let mut files: Vec<(StorageId, PathBuf)> = storage_files(dir)
        .map_err(crate::error::io_error(dir, "cannot list"))?
        .collect();
    files.retain(|(_, p)| {
        compression::compressed_file_name(p).is_none_or(|name| !dir.join(name).exists())
    });
    let Some(&(storage, _)) = files.first() else {
        return Err(BagError::NotABag {
            path: dir.to_path_buf(),
            reason: "no metadata.yaml and no storage file (.mcap, .db3, or either .zstd) in it"
                .into(),
        });
    };
    if files.iter().any(|(other, _)| *other != storage) {
        return Err(BagError::NotABag {
            path: dir.to_path_buf(),
            reason: "no metadata.yaml, and both .mcap and .db3 files in it: which of them \
                     make up the bag is unknown"
                .into(),
        });
    }
    let mut paths: Vec<PathBuf> = files.into_iter().map(|(_, p)| p).collect();
    paths.sort_by_cached_key(|p| split_order(p));
    Ok((storage, paths))
}

/// Sorts rosbag2's split files `<name>_<N>.<ext>` by name, then by the number N (`_10` after
/// `_9`); other names come first among those with the same name.
fn split_order(path: &Path) -> (String, Option<u64>, PathBuf) {
    let name = compression::compressed_file_name(path).map_or(path, Path::new);
    let stem = name.file_stem().unwrap_or_default().to_string_lossy();
    let split = stem
        .rsplit_once('_')
        .and_then(|(prefix, n)| Some((prefix.to_string(), Some(n.parse().ok()?))));
    let (prefix, index) = split.unwrap_or_else(|| (stem.to_string(), None));
    (prefix, index, path.to_path_buf())
}

/// The messages of one storage file, ending at its first error.
struct Source {
    /// The file, named in errors of message decompression.
    path: PathBuf,
    stream: Stream,
    compression: MessageCompression,
}

enum Stream {
    Mcap(McapMessages),
    Sqlite(SqliteMessages),
    /// A file whose messages cannot be read at all: why, once.
    Failed(Option<BagError>),
}

impl Iterator for Source {
    type Item = Result<BagMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        let item = match &mut self.stream {
            Stream::Mcap(m) => m.next(),
            Stream::Sqlite(m) => m.next(),
            Stream::Failed(error) => error.take().map(Err),
        }?;
        Some(match item {
            Ok(message) if self.compression.applies_to(&message.data) => {
                compression::decompress_message(&self.path, message)
            }
            item => item,
        })
    }
}

/// Messages of a bag, merged across its storage files by log time. An error in one file (e.g.
/// a truncated one, after its complete messages) ends that file only: the other files' messages
/// still come, and the errors follow the last message, one item each, as they occurred. Callers
/// that stop at the first error therefore lose no message of a good file.
pub struct Messages {
    sources: Vec<Source>,
    heads: Vec<Option<BagMessage>>,
    primed: bool,
    errors: VecDeque<BagError>,
}

impl Iterator for Messages {
    type Item = Result<BagMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        if !self.primed {
            self.primed = true;
            for i in 0..self.sources.len() {
                self.refill(i);
            }
        }
        let earliest = self
            .heads
            .iter()
            .enumerate()
            .filter_map(|(i, h)| h.as_ref().map(|m| (m.log_time_ns, i)))
            .min()
            .map(|(_, i)| i);
        let Some(earliest) = earliest else {
            return self.errors.pop_front().map(Err);
        };
        let message = self.heads[earliest].take()?;
        self.refill(earliest);
        Some(Ok(message))
    }
}

impl Messages {
    /// Reads the next message of file `i`; an error ends that file and waits its turn.
    fn refill(&mut self, i: usize) {
        self.heads[i] = match self.sources[i].next() {
            Some(Ok(m)) => Some(m),
            Some(Err(e)) => {
                self.errors.push_back(e);
                None
            }
            None => None,
        };
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use std::path::{Path, PathBuf};

    use lidar_har_msgs::qos::QosProfile;

    use crate::metadata::BagMetadata;
    use crate::{
        BagError, BagReader, BagWriter, Compression, MessageFilter, StorageId, WriterOptions,
    };

    /// A bag at `dir` of one storage file with `data` on `/raw`, one message a nanosecond from
    /// `t0`; returns the file.
    pub(crate) fn write_bag(dir: &Path, storage: StorageId, t0: i64, data: &[Vec<u8>]) -> PathBuf {
        let options = WriterOptions {
            storage,
            ..WriterOptions::default()
        };
        let mut writer = BagWriter::create(dir, options).unwrap();
        let topic = writer
            .add_topic(
                "/raw",
                "std_msgs/msg/String",
                "string data\n",
                QosProfile::sensor_data(),
            )
            .unwrap();
        for (i, data) in data.iter().enumerate() {
            writer.write(topic, t0 + i as i64, data).unwrap();
        }
        writer.finish().unwrap();
        let name = dir.file_name().unwrap().to_string_lossy();
        dir.join(format!("{name}_0.{}", storage.extension()))
    }

    /// Message `i`: CDR of a `std_msgs/String`, different for each `i`.
    fn payload(i: u32) -> Vec<u8> {
        let text = format!("message {i}");
        let mut cdr = vec![0, 1, 0, 0];
        cdr.extend((text.len() as u32 + 1).to_le_bytes());
        cdr.extend(text.as_bytes());
        cdr.push(0);
        cdr
    }

    /// Every message (log time, data) of the bag at `path`, and the errors after them.
    fn read_all(path: &Path) -> (Vec<(i64, Vec<u8>)>, Vec<BagError>) {
        let reader = BagReader::open(path).unwrap_or_else(|e| panic!("open: {e}"));
        let (mut messages, mut errors) = (Vec::new(), Vec::new());
        for item in reader.messages().unwrap() {
            match item {
                Ok(m) => messages.push((m.log_time_ns, m.data)),
                Err(e) => errors.push(e),
            }
        }
        (messages, errors)
    }

    fn zstd_file_name(path: &Path) -> PathBuf {
        let mut name = path.as_os_str().to_owned();
        name.push(".zstd");
        PathBuf::from(name)
    }

    /// Replaces the file at `path` by `<path>.zstd`, as rosbag2's mode FILE does; returns it.
    fn zstd_file(path: &Path) -> PathBuf {
        let compressed = zstd_file_name(path);
        let bytes = std::fs::read(path).unwrap();
        std::fs::write(&compressed, zstd::encode_all(&bytes[..], 3).unwrap()).unwrap();
        std::fs::remove_file(path).unwrap();
        compressed
    }

    /// Compresses the bag's one storage `file` whole, as rosbag2's FILE mode does, and lists
    /// the compressed file in its metadata.yaml; returns it.
    fn compress_whole(bag: &Path, file: &Path) -> PathBuf {
        let compressed = zstd_file(file);
        let mut metadata = BagMetadata::read(bag).unwrap();
        let listed = compressed.file_name().unwrap().to_string_lossy();
        metadata.relative_file_paths = vec![listed.to_string()];
        metadata.files[0].path = listed.to_string();
        metadata.compression_format = "zstd".into();
        metadata.compression_mode = "FILE".into();
        metadata.write(bag).unwrap();
        compressed
    }

    /// A killed recorder leaves no metadata.yaml; with sqlite3 storage (Humble's default) its
    /// files are `.db3`. They are read in split order (`_10` after `_9`), and so is one given
    /// on its own.
    #[test]
    fn db3_files_without_metadata_are_read_in_split_order() {
        let tmp = tempfile::tempdir().unwrap();
        let rec = tmp.path().join("rec");
        std::fs::create_dir(&rec).unwrap();
        for split in 0..11u32 {
            let dir = tmp.path().join(format!("w{split}"));
            let data = [payload(split)];
            let file = write_bag(&dir, StorageId::Sqlite3, 1000 + i64::from(split), &data);
            std::fs::rename(file, rec.join(format!("rec_{split}.db3"))).unwrap();
        }
        let reader = BagReader::open(&rec).unwrap_or_else(|e| panic!("open: {e}"));
        let info = reader.metadata();
        assert_eq!(info.storage, StorageId::Sqlite3);
        let names: Vec<String> = info
            .files
            .iter()
            .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        let expected: Vec<String> = (0..11).map(|i| format!("rec_{i}.db3")).collect();
        assert_eq!(names, expected);
        let (messages, errors) = read_all(&rec);
        assert!(errors.is_empty(), "{errors:?}");
        let expected: Vec<_> = (0..11).map(|i| (1000 + i64::from(i), payload(i))).collect();
        assert_eq!(messages, expected);

        let (messages, errors) = read_all(&rec.join("rec_10.db3"));
        assert!(errors.is_empty(), "{errors:?}");
        assert_eq!(messages, vec![(1010, payload(10))]);
    }

    /// `--compression-mode file`: each storage file is replaced by `<file>.zstd`, listed so in
    /// metadata.yaml. It is read from a decompressed copy, with metadata.yaml or without (a
    /// killed recorder), where it is read beside the file being recorded, uncompressed.
    #[test]
    fn files_compressed_whole_are_read_decompressed() {
        for storage in [StorageId::Mcap, StorageId::Sqlite3] {
            let tmp = tempfile::tempdir().unwrap();
            let bag = tmp.path().join("bag");
            let written: Vec<Vec<u8>> = (0..30).map(payload).collect();
            let file = write_bag(&bag, storage, 1000, &written);
            let compressed = compress_whole(&bag, &file);
            let expected: Vec<_> = (1000..).zip(written.iter().cloned()).collect();
            let (messages, errors) = read_all(&bag);
            assert!(errors.is_empty(), "{storage}: {errors:?}");
            assert_eq!(messages, expected, "{storage}");
            let reader = BagReader::open(&bag).unwrap();
            assert_eq!(reader.metadata().files, vec![compressed.clone()]);

            std::fs::remove_file(bag.join("metadata.yaml")).unwrap();
            let last = write_bag(&tmp.path().join("last"), storage, 2000, &[payload(99)]);
            let last_in_bag = bag.join(format!("bag_1.{}", storage.extension()));
            std::fs::rename(last, &last_in_bag).unwrap();
            // Its compression, cut short by the kill: rosbag2 deletes the file compressed
            // only once the compressed file is complete.
            let cut = zstd::encode_all(&std::fs::read(&last_in_bag).unwrap()[..], 3).unwrap();
            std::fs::write(zstd_file_name(&last_in_bag), &cut[..cut.len() / 2]).unwrap();
            let (messages, errors) = read_all(&bag);
            assert!(errors.is_empty(), "{storage}: {errors:?}");
            assert_eq!(messages.len(), 31, "{storage}");
            assert_eq!(&messages[..30], &expected[..], "{storage}");
            let reader = BagReader::open(&bag).unwrap();
            assert_eq!(reader.metadata().files, vec![compressed, last_in_bag]);
        }
    }

    /// `--compression-mode message`: each message's data is one zstd frame. A frame that does
    /// not decompress ends its file with an error naming it; another format is refused.
    #[test]
    fn messages_compressed_one_by_one_are_decompressed() {
        let tmp = tempfile::tempdir().unwrap();
        let bag = tmp.path().join("bag");
        let written: Vec<Vec<u8>> = (0..30).map(payload).collect();
        let mut stored: Vec<Vec<u8>> = written
            .iter()
            .map(|data| zstd::bulk::compress(data, 3).unwrap())
            .collect();
        stored[20] = b"not zstd".to_vec();
        write_bag(&bag, StorageId::Mcap, 1000, &stored);
        let mut metadata = BagMetadata::read(&bag).unwrap();
        metadata.compression_format = "zstd".into();
        metadata.compression_mode = "message".into();
        metadata.write(&bag).unwrap();

        let (messages, errors) = read_all(&bag);
        let expected: Vec<_> = (1000..).zip(written[..20].iter().cloned()).collect();
        assert_eq!(messages, expected);
        let [error] = &errors[..] else {
            panic!("one error expected: {errors:?}");
        };
        let text = error.to_string();
        assert!(
            matches!(error, BagError::MessageDecompression { .. })
                && text.contains("bag_0.mcap")
                && text.contains("1020 ns"),
            "{text}"
        );

        metadata.compression_format = "lz4".into();
        metadata.write(&bag).unwrap();
        let error = BagReader::open(&bag).err().unwrap();
        assert!(
            matches!(error, BagError::UnsupportedCompression { .. })
                && error.to_string().contains("lz4"),
            "{error}"
        );
    }

    /// An empty file looks like an MCAP split file cut in its magic, which is a truncation
    /// beside a file with records; alone (as a bare file, the only file of a directory, or
    /// the only one listed in metadata.yaml) it is no bag.
    #[test]
    fn a_bag_of_files_cut_in_their_magic_only_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let bag = tmp.path().join("bag");
        write_bag(&bag, StorageId::Mcap, 1000, &[payload(0)]);
        let mut metadata = BagMetadata::read(&bag).unwrap();
        std::fs::remove_file(bag.join("bag_0.mcap")).unwrap();
        let notes = tmp.path().join("notes.txt");
        std::fs::write(&notes, b"").unwrap();
        for (cut, says) in [(0, "the file is empty"), (5, "ends inside its magic")] {
            std::fs::write(bag.join("bag_1.mcap"), &mcap::MAGIC[..cut]).unwrap();
            std::fs::write(bag.join("bag_2.mcap"), b"").unwrap();
            metadata.relative_file_paths = vec!["bag_1.mcap".into(), "bag_2.mcap".into()];
            metadata.write(&bag).unwrap();
            let with_metadata = BagReader::open(&bag).err();
            std::fs::remove_file(bag.join("metadata.yaml")).unwrap();
            let without = BagReader::open(&bag).err();
            let bare = BagReader::open(bag.join("bag_1.mcap")).err();
            for error in [with_metadata, without, bare] {
                let error = error.expect("refused");
                let text = error.to_string();
                assert!(
                    matches!(error, BagError::NotABag { .. })
                        && text.contains("bag_1.mcap")
                        && text.contains(says),
                    "{text}"
                );
            }
        }
        let error = BagReader::open(&notes).err().expect("refused");
        assert!(
            matches!(error, BagError::NotABag { .. }) && error.to_string().contains("notes.txt"),
            "{error}"
        );
        let error = BagReader::from_mcap_bytes(&mcap::MAGIC[..3])
            .err()
            .expect("refused");
        assert!(matches!(error, BagError::NotABag { .. }), "{error}");
    }

    /// A killed recorder in mode MESSAGE leaves no metadata.yaml to say that messages are
    /// compressed: one whose data starts with zstd's magic (CDR data starts with 0) is.
    #[test]
    fn compressed_messages_without_metadata_are_known_by_their_magic() {
        let tmp = tempfile::tempdir().unwrap();
        let bag = tmp.path().join("bag");
        let written: Vec<Vec<u8>> = (0..10).map(payload).collect();
        let stored: Vec<Vec<u8>> = written
            .iter()
            .enumerate()
            .map(|(i, data)| match i % 2 {
                0 => zstd::bulk::compress(data, 3).unwrap(),
                _ => data.clone(),
            })
            .collect();
        let file = write_bag(&bag, StorageId::Mcap, 1000, &stored);
        std::fs::remove_file(bag.join("metadata.yaml")).unwrap();
        let expected: Vec<_> = (1000..).zip(written).collect();
        for path in [&bag, &file] {
            let (messages, errors) = read_all(path);
            assert!(errors.is_empty(), "{errors:?}");
            assert_eq!(messages, expected, "{}", path.display());
        }
    }

    /// A file of a bag of several that cannot be opened at all ends that file only, as an
    /// error while reading it does; a bag of that file alone is refused with its error.
    #[test]
    fn a_file_that_cannot_be_opened_ends_that_file_only() {
        let tmp = tempfile::tempdir().unwrap();
        let bag = tmp.path().join("bag");
        let written: Vec<Vec<u8>> = (0..10).map(payload).collect();
        write_bag(&bag, StorageId::Sqlite3, 1000, &written);
        std::fs::write(bag.join("bag_1.db3"), vec![0x5a; 4096]).unwrap();
        let mut metadata = BagMetadata::read(&bag).unwrap();
        metadata.relative_file_paths.push("bag_1.db3".into());
        metadata.write(&bag).unwrap();

        let reader = BagReader::open(&bag).unwrap_or_else(|e| panic!("open: {e}"));
        assert!(reader.metadata().truncated);
        let damaged = reader.metadata().damaged;
        assert!(
            damaged.len() == 1
                && damaged[0].contains("bag_1.db3")
                && damaged[0].contains("sqlite3 storage"),
            "{damaged:?}"
        );
        assert_eq!(reader.metadata().message_count, 10);
        let (messages, errors) = read_all(&bag);
        assert_eq!(messages.len(), 10);
        let [error] = &errors[..] else {
            panic!("one error expected: {errors:?}");
        };
        assert!(
            matches!(error, BagError::Sqlite { .. }) && error.to_string().contains("bag_1.db3"),
            "{error}"
        );

        metadata.relative_file_paths = vec!["bag_1.db3".into()];
        metadata.write(&bag).unwrap();
        let error = BagReader::open(&bag).err().unwrap();
        assert!(matches!(error, BagError::Sqlite { .. }), "{error}");
    }

    /// Checks that `error` refuses the bag at `path` because `topic` has the types
    /// `std_msgs/msg/String` and `std_msgs/msg/Int32`, in that order.
    fn assert_refused_for_two_types(error: Option<BagError>, path: &Path, topic: &str) {
        let error = error.expect("refused");
        let text = error.to_string();
        assert!(
            matches!(error, BagError::TopicWithTwoTypes { .. })
                && text.starts_with(&format!("{}: ", path.display()))
                && text.contains(&format!("topic `{topic}`"))
                && text.contains("`std_msgs/msg/String` and `std_msgs/msg/Int32`"),
            "{text}"
        );
    }

    /// An MCAP with two channels on `/x`, of `std_msgs/String` then `std_msgs/Int32`, a message
    /// on each; returns its bytes.
    fn write_mcap_with_two_types(path: &Path) -> Vec<u8> {
        let mut bytes = Vec::new();
        {
            let mut writer = mcap::WriteOptions::new()
                .profile("ros2")
                .create(std::io::Cursor::new(&mut bytes))
                .unwrap();
            let types = [
                ("std_msgs/msg/String", "string data", payload(0)),
                (
                    "std_msgs/msg/Int32",
                    "int32 data",
                    vec![0, 1, 0, 0, 7, 0, 0, 0],
                ),
            ];
            for (sequence, (type_name, definition, data)) in (0..).zip(types) {
                let schema = writer
                    .add_schema(type_name, "ros2msg", definition.as_bytes())
                    .unwrap();
                let channel_id = writer
                    .add_channel(schema, "/x", "cdr", &Default::default())
                    .unwrap();
                let header = mcap::records::MessageHeader {
                    channel_id,
                    sequence,
                    log_time: 1000 + u64::from(sequence),
                    publish_time: 1000 + u64::from(sequence),
                };
                writer.write_to_known_channel(&header, &data).unwrap();
            }
            writer.finish().unwrap();
        }
        std::fs::write(path, &bytes).unwrap();
        bytes
    }

    /// MCAP allows channels of one topic name with different schemas, but messages carry only
    /// the name: the Int32 messages were read as Strings (`bag convert` wrote them under the
    /// String schema, `replay` published them on a String publisher).
    #[test]
    fn an_mcap_topic_with_two_types_is_refused_naming_both() {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("dup.mcap");
        let bytes = write_mcap_with_two_types(&file);
        assert_refused_for_two_types(BagReader::open(&file).err(), &file, "/x");
        let in_memory = BagReader::from_mcap_bytes(bytes).err();
        assert_refused_for_two_types(in_memory, Path::new("<memory>"), "/x");
    }

    /// A sqlite3 `topics` table does not keep names unique; split files may come from two
    /// recordings. Split files that repeat a topic with its type are one topic, as before.
    #[test]
    fn a_sqlite3_topic_with_two_types_is_refused_naming_both() {
        let tmp = tempfile::tempdir().unwrap();
        let bag = tmp.path().join("bag");
        let first = write_bag(&bag, StorageId::Sqlite3, 1000, &[payload(0)]);
        let second = bag.join("bag_1.db3");
        let other = write_bag(
            &tmp.path().join("o"),
            StorageId::Sqlite3,
            2000,
            &[payload(1)],
        );
        std::fs::rename(other, &second).unwrap();
        let mut metadata = BagMetadata::read(&bag).unwrap();
        metadata.relative_file_paths.push("bag_1.db3".into());
        metadata.write(&bag).unwrap();
        let reader = BagReader::open(&bag).unwrap_or_else(|e| panic!("open: {e}"));
        assert_eq!(reader.topics().len(), 1);
        assert_eq!(reader.metadata().message_count, 2);

        let db = rusqlite::Connection::open(&second).unwrap();
        db.execute("UPDATE topics SET type = 'std_msgs/msg/Int32'", [])
            .unwrap();
        drop(db);
        assert_refused_for_two_types(BagReader::open(&bag).err(), &bag, "/raw");
        std::fs::remove_file(&second).unwrap();

        let db = rusqlite::Connection::open(&first).unwrap();
        db.execute(
            "INSERT INTO topics(name, type, serialization_format, offered_qos_profiles, \
             type_description_hash) VALUES ('/raw', 'std_msgs/msg/Int32', 'cdr', '', '')",
            [],
        )
        .unwrap();
        drop(db);
        assert_refused_for_two_types(BagReader::open(&first).err(), &first, "/raw");
    }

    /// A bag at `dir` of one storage file with `n` messages alternating on `/a` (even `i`) and
    /// `/b` (odd `i`), message `i` at `t0 + 10 i` ns with `payload(i)`; small MCAP chunks, so
    /// that a range starts and ends inside some. Returns the file.
    fn write_two_topics(
        dir: &Path,
        storage: StorageId,
        compression: Compression,
        t0: i64,
        n: u32,
    ) -> PathBuf {
        let options = WriterOptions {
            storage,
            compression,
            chunk_size: 256,
            ..WriterOptions::default()
        };
        let mut writer = BagWriter::create(dir, options).unwrap();
        let mut add = |name| {
            let qos = QosProfile::sensor_data();
            writer.add_topic(name, "std_msgs/msg/String", "string data\n", qos)
        };
        let topics = [add("/a").unwrap(), add("/b").unwrap()];
        for i in 0..n {
            let topic = topics[i as usize % 2];
            writer
                .write(topic, t0 + 10 * i64::from(i), &payload(i))
                .unwrap();
        }
        writer.finish().unwrap();
        let name = dir.file_name().unwrap().to_string_lossy();
        dir.join(format!("{name}_0.{}", storage.extension()))
    }

    /// (topic, log time) of every message `filter` selects in the bag at `path`, and the
    /// errors after them; checks that each message's data is the payload written at its time.
    fn read_matching(
        path: &Path,
        filter: &MessageFilter,
        t0: i64,
    ) -> (Vec<(String, i64)>, Vec<BagError>) {
        let reader = BagReader::open(path).unwrap_or_else(|e| panic!("open: {e}"));
        let (mut messages, mut errors) = (Vec::new(), Vec::new());
        for item in reader.messages_matching(filter).unwrap() {
            match item {
                Ok(m) => {
                    let i = u32::try_from((m.log_time_ns - t0) / 10).unwrap();
                    assert_eq!(
                        m.data,
                        payload(i),
                        "data of the message at {}",
                        m.log_time_ns
                    );
                    messages.push((m.topic.to_string(), m.log_time_ns));
                }
                Err(e) => errors.push(e),
            }
        }
        (messages, errors)
    }

    /// (topic, log time) of the messages [`write_two_topics`] wrote from `t0` (the `n`
    /// first) logged in `[start, end)`, on `/b` only if `only_b`.
    fn expected(t0: i64, n: i64, start: i64, end: i64, only_b: bool) -> Vec<(String, i64)> {
        (0..n)
            .filter(|i| !only_b || i % 2 == 1)
            .map(|i| (["/a", "/b"][i as usize % 2].to_string(), t0 + 10 * i))
            .filter(|(_, t)| (start..end).contains(t))
            .collect()
    }

    /// A read bounded by log time returns exactly the messages in `[start, end)`, in order,
    /// with a topic filter or without: MCAP (plain and zstd chunks, read through the
    /// summary), sqlite3, and rosbag2's FILE and MESSAGE compression. An empty range, one
    /// before or after the bag, gives nothing and no error.
    #[test]
    fn a_time_range_reads_exactly_its_messages_in_every_storage() {
        let tmp = tempfile::tempdir().unwrap();
        let cases = [
            ("mcap", StorageId::Mcap, Compression::None),
            ("mcap_zstd", StorageId::Mcap, Compression::Zstd),
            ("sqlite", StorageId::Sqlite3, Compression::None),
            ("mcap_file_mode", StorageId::Mcap, Compression::None),
            ("sqlite_file_mode", StorageId::Sqlite3, Compression::None),
        ];
        for (name, storage, compression) in cases {
            let bag = tmp.path().join(name);
            let file = write_two_topics(&bag, storage, compression, 1000, 100);
            if name.ends_with("file_mode") {
                compress_whole(&bag, &file);
            }
            let ranges = [(1500, 1700), (1505, 1691), (1990, 2000), (-5, 1010)];
            for (start, end) in ranges {
                let all = MessageFilter::new().starting_at(start).ending_before(end);
                let (messages, errors) = read_matching(&bag, &all, 1000);
                assert!(errors.is_empty(), "{name}: {errors:?}");
                let want = expected(1000, 100, start, end, false);
                assert!(!want.is_empty());
                assert_eq!(messages, want, "{name} [{start}, {end})");
                let (on_b, errors) = read_matching(&bag, &all.topics(&["/b"]), 1000);
                assert!(errors.is_empty(), "{name}: {errors:?}");
                assert_eq!(on_b, expected(1000, 100, start, end, true), "{name} /b");
            }
            let from = MessageFilter::new().starting_at(1985);
            let (messages, _) = read_matching(&bag, &from, 1000);
            assert_eq!(
                messages,
                expected(1000, 100, 1985, i64::MAX, false),
                "{name}"
            );
            let nothing = [
                MessageFilter::new().starting_at(1700).ending_before(1700),
                MessageFilter::new().starting_at(1700).ending_before(1500),
                MessageFilter::new().ending_before(1000),
                MessageFilter::new().ending_before(-3),
                MessageFilter::new().starting_at(1991),
                MessageFilter::new().starting_at(i64::MAX).topics(&["/a"]),
            ];
            for filter in nothing {
                let (messages, errors) = read_matching(&bag, &filter, 1000);
                assert!(
                    messages.is_empty() && errors.is_empty(),
                    "{name} {filter:?}"
                );
            }
            let unknown = BagReader::open(&bag)
                .unwrap()
                .messages_matching(&from.topics(&["/nope"]))
                .err();
            assert!(
                matches!(unknown, Some(BagError::UnknownTopic { .. })),
                "{unknown:?}"
            );
        }

        // MESSAGE mode: each message's data is a zstd frame, decompressed as it is read.
        let bag = tmp.path().join("message_mode");
        let written: Vec<Vec<u8>> = (0..50).map(payload).collect();
        let stored: Vec<Vec<u8>> = written
            .iter()
            .map(|data| zstd::bulk::compress(data, 3).unwrap())
            .collect();
        write_bag(&bag, StorageId::Mcap, 1000, &stored);
        let mut metadata = BagMetadata::read(&bag).unwrap();
        metadata.compression_format = "zstd".into();
        metadata.compression_mode = "MESSAGE".into();
        metadata.write(&bag).unwrap();
        let reader = BagReader::open(&bag).unwrap();
        let filter = MessageFilter::new().starting_at(1020).ending_before(1025);
        let read: Vec<(i64, Vec<u8>)> = reader
            .messages_matching(&filter)
            .unwrap()
            .map(|m| m.map(|m| (m.log_time_ns, m.data)).unwrap())
            .collect();
        let want: Vec<(i64, Vec<u8>)> = (1020..).zip(written[20..25].iter().cloned()).collect();
        assert_eq!(read, want);
    }

    /// The files of a split bag are merged by log time within the range too, for both
    /// storages; a file without the topic asked for (one before the topic first appears)
    /// gives none of its messages.
    #[test]
    fn a_time_range_of_a_split_bag_is_merged_in_order() {
        for storage in [StorageId::Mcap, StorageId::Sqlite3] {
            let tmp = tempfile::tempdir().unwrap();
            let bag = tmp.path().join("split");
            std::fs::create_dir(&bag).unwrap();
            // Messages 0..60 in the first file, 60..100 in the second; a third holds /raw only.
            let ext = storage.extension();
            let first =
                write_two_topics(&tmp.path().join("w0"), storage, Compression::None, 1000, 60);
            std::fs::rename(first, bag.join(format!("split_0.{ext}"))).unwrap();
            let second = write_two_topics(
                &tmp.path().join("w1"),
                storage,
                Compression::None,
                1000,
                100,
            );
            std::fs::rename(second, bag.join(format!("split_1.{ext}"))).unwrap();
            let raw = write_bag(&tmp.path().join("w2"), storage, 1600, &[payload(60)]);
            std::fs::rename(raw, bag.join(format!("split_2.{ext}"))).unwrap();
            let filter = MessageFilter::new().starting_at(1450).ending_before(1650);
            let (messages, errors) =
                read_matching(&bag, &filter.clone().topics(&["/a", "/b"]), 1000);
            assert!(errors.is_empty(), "{storage}: {errors:?}");
            // Messages 45..60 come from both files, merged; 60..65 from the second only.
            let mut want = expected(1000, 60, 1450, 1650, false);
            want.extend(expected(1000, 100, 1450, 1650, false));
            want.sort_by_key(|(_, t)| *t);
            assert_eq!(messages, want, "{storage}");
            let (on_b, _) = read_matching(&bag, &filter.topics(&["/b"]), 1000);
            assert!(
                on_b.iter().all(|(topic, _)| topic == "/b"),
                "{storage}: {on_b:?}"
            );
            assert_eq!(on_b.len(), want.iter().filter(|(t, _)| t == "/b").count());
        }
    }

    /// A killed recorder leaves no metadata.yaml, but its sqlite3 file records what wrote it:
    /// Humble's `schema` row (version 3, `humble`) without a `metadata` table, Iron's
    /// `metadata` row of version 8, Jazzy's of 9, or a layout older than both tables. `run` and
    /// `bag convert` wrote version 9 over all of them, which Humble's and Iron's `ros2 bag
    /// info` cannot parse. metadata.yaml, where there is one, wins.
    #[test]
    fn a_sqlite3_file_without_metadata_yaml_tells_which_rosbag2_wrote_it() {
        use crate::MetadataVersion::{V8, V9};
        use crate::{MetadataVersion, RecordedVersion::*};
        let tmp = tempfile::tempdir().unwrap();
        let recorded = |name: &str, sql: &str, keep_metadata_yaml: bool| {
            let bag = tmp.path().join(name);
            let file = write_bag(&bag, StorageId::Sqlite3, 1000, &[payload(0)]);
            rusqlite::Connection::open(&file)
                .unwrap()
                .execute_batch(sql)
                .unwrap();
            if !keep_metadata_yaml {
                std::fs::remove_file(bag.join("metadata.yaml")).unwrap();
            }
            let recorded = BagReader::open(&bag).unwrap().recorded_version();
            let version = MetadataVersion::like_source(recorded.as_ref());
            (recorded.unwrap(), version)
        };
        let humble = "UPDATE schema SET schema_version = 3, ros_distro = 'humble';
                      DROP TABLE metadata;";
        let iron =
            "UPDATE schema SET ros_distro = 'iron'; UPDATE metadata SET metadata_version = 8;";
        let jazzy = "UPDATE schema SET ros_distro = 'jazzy';";
        assert_eq!(
            recorded("humble", humble, false),
            (Distribution("humble".into()), V8)
        );
        assert_eq!(recorded("iron", iron, false), (StorageFile(8), V8));
        assert_eq!(recorded("jazzy", jazzy, false), (StorageFile(9), V9));
        let iron_unclosed = "UPDATE schema SET ros_distro = 'iron'; DELETE FROM metadata;";
        assert_eq!(
            recorded("iron_unclosed", iron_unclosed, false),
            (Distribution("iron".into()), V8)
        );
        let jazzy_unclosed = "UPDATE schema SET ros_distro = 'jazzy'; DELETE FROM metadata;";
        assert_eq!(
            recorded("jazzy_unclosed", jazzy_unclosed, false),
            (Distribution("jazzy".into()), V9)
        );
        let foxy = "DROP TABLE schema; DROP TABLE metadata;";
        assert_eq!(recorded("foxy", foxy, false), (SqliteLayoutBeforeJazzy, V8));
        let humble_unnamed = "UPDATE schema SET schema_version = 3, ros_distro = '';
                              DROP TABLE metadata;";
        assert_eq!(
            recorded("humble_unnamed", humble_unnamed, false),
            (SqliteLayoutBeforeJazzy, V8)
        );
        assert_eq!(
            recorded("humble_listed", humble, true),
            (MetadataYaml(9), V9)
        );
    }

    /// rosbag2 Iron (from 0.22.2) notes its `ROS_DISTRO` in a `rosbag2` Metadata record when it
    /// opens an MCAP for writing, so a file its killed recorder left (no summary, no
    /// metadata.yaml) says it too; a finished file's record is found through the summary's
    /// metadata index. The `serialized_metadata` a finished file holds (as `BagWriter` writes
    /// it) tells the version itself.
    #[test]
    fn an_mcap_without_metadata_yaml_tells_which_rosbag2_wrote_it() {
        use crate::MetadataVersion::{V8, V9};
        use crate::{MetadataVersion, RecordedVersion::*};
        let tmp = tempfile::tempdir().unwrap();
        for distro in ["humble", "iron"] {
            let mut bytes = Vec::new();
            {
                let mut writer = mcap::WriteOptions::new()
                    .profile("ros2")
                    .create(std::io::Cursor::new(&mut bytes))
                    .unwrap();
                writer
                    .write_metadata(&mcap::records::Metadata {
                        name: "rosbag2".into(),
                        metadata: [("ROS_DISTRO".to_string(), distro.to_string())].into(),
                    })
                    .unwrap();
                let schema = writer
                    .add_schema("std_msgs/msg/String", "ros2msg", b"string data")
                    .unwrap();
                let channel_id = writer
                    .add_channel(schema, "/raw", "cdr", &Default::default())
                    .unwrap();
                let header = mcap::records::MessageHeader {
                    channel_id,
                    sequence: 1,
                    log_time: 1000,
                    publish_time: 1000,
                };
                writer.write_to_known_channel(&header, &payload(0)).unwrap();
                writer.finish().unwrap();
            }
            for cut_short in [false, true] {
                let file = tmp.path().join(format!("{distro}_{cut_short}.mcap"));
                let kept = if cut_short {
                    bytes.len() - 20
                } else {
                    bytes.len()
                };
                std::fs::write(&file, &bytes[..kept]).unwrap();
                let reader = BagReader::open(&file).unwrap();
                assert_eq!(reader.metadata().truncated, cut_short, "{}", file.display());
                let recorded = reader.recorded_version();
                assert_eq!(
                    recorded,
                    Some(Distribution(distro.into())),
                    "{}",
                    file.display()
                );
                assert_eq!(MetadataVersion::like_source(recorded.as_ref()), V8);
            }
        }
        let bag = tmp.path().join("ours");
        write_bag(&bag, StorageId::Mcap, 1000, &[payload(0)]);
        std::fs::remove_file(bag.join("metadata.yaml")).unwrap();
        let recorded = BagReader::open(&bag).unwrap().recorded_version();
        assert_eq!(recorded, Some(StorageFile(9)));
        assert_eq!(MetadataVersion::like_source(recorded.as_ref()), V9);
    }

    /// Without metadata.yaml nothing says whether `.mcap` or `.db3` files make up the bag.
    #[test]
    fn a_directory_of_both_storages_without_metadata_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let bag = tmp.path().join("bag");
        write_bag(&bag, StorageId::Mcap, 1000, &[payload(0)]);
        let other = write_bag(
            &tmp.path().join("o"),
            StorageId::Sqlite3,
            1000,
            &[payload(0)],
        );
        std::fs::rename(other, bag.join("bag_1.db3")).unwrap();
        std::fs::remove_file(bag.join("metadata.yaml")).unwrap();
        let error = BagReader::open(&bag).err().unwrap();
        assert!(error.to_string().contains(".mcap and .db3"), "{error}");
    }
}
