//! Reading rosbag2 bags: a directory with `metadata.yaml` (MCAP or sqlite3 storage, one or
//! more files) or a bare `.mcap` file. Messages stream in log-time order in constant memory.

use std::collections::{BTreeSet, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use lidar_har_msgs::RosMessage;

use crate::error::{BagError, Result};
use crate::mcap_storage::{McapFile, McapInput, McapMessages};
use crate::metadata::BagMetadata;
use crate::qos::OfferedQos;
use crate::sqlite_storage::{SqliteFile, SqliteMessages};
use crate::writer::StorageId;

/// A topic of a bag.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicInfo {
    pub name: String,
    /// e.g. `sensor_msgs/msg/LaserScan`.
    pub type_name: String,
    /// `cdr` for every ROS 2 bag.
    pub serialization_format: String,
    pub offered_qos: Vec<OfferedQos>,
    /// The `ros2msg` schema (the .msg and its dependencies), when the bag stores it.
    pub schema_text: Option<String>,
    pub type_description_hash: String,
    pub message_count: u64,
    /// Channel id (MCAP) or `topics.id` (sqlite3) in the storage file.
    pub(crate) storage_id: i64,
}

/// One serialised message: CDR bytes with their encapsulation header.
#[derive(Debug, Clone, PartialEq)]
pub struct BagMessage {
    pub topic: Arc<str>,
    pub log_time_ns: i64,
    pub data: Vec<u8>,
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
    /// record). Counts cover the part before; reading the messages ends with the error.
    pub truncated: bool,
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
}

/// An opened bag.
pub struct BagReader {
    path: PathBuf,
    storage: StorageId,
    files: Vec<(PathBuf, StorageFile)>,
    topics: Vec<TopicInfo>,
    metadata: Option<BagMetadata>,
}

impl BagReader {
    /// Opens a rosbag2 directory or a bare `.mcap` file.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref().to_path_buf();
        if !path.exists() {
            return Err(BagError::NotFound { path });
        }
        if path.is_file() {
            let file = McapFile::open(McapInput::File(path.clone()))?;
            return Ok(Self::from_mcap_files(
                path.clone(),
                vec![(path, file)],
                None,
            ));
        }
        let metadata_path = path.join("metadata.yaml");
        if !metadata_path.is_file() {
            let mcaps = list_mcap_files(&path)?;
            if mcaps.is_empty() {
                return Err(BagError::NotABag {
                    path,
                    reason: "no metadata.yaml and no .mcap file in it".into(),
                });
            }
            let files = mcaps
                .into_iter()
                .map(|file| McapFile::open(McapInput::File(file.clone())).map(|m| (file, m)))
                .collect::<Result<Vec<_>>>()?;
            return Ok(Self::from_mcap_files(path, files, None));
        }
        let metadata = BagMetadata::read(&path)?;
        if !metadata.compression_format.is_empty() {
            return Err(BagError::UnsupportedCompression {
                path: metadata_path,
                format: metadata.compression_format.clone(),
                mode: metadata.compression_mode.clone(),
            });
        }
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
        let mut files = Vec::new();
        for name in relative {
            let file_path = storage_file_path(&path, metadata.version, &name);
            if !file_path.is_file() {
                return Err(BagError::NotFound { path: file_path });
            }
            let file = match storage {
                StorageId::Mcap => StorageFile::Mcap(Box::new(McapFile::open(McapInput::File(
                    file_path.clone(),
                ))?)),
                StorageId::Sqlite3 => StorageFile::Sqlite(SqliteFile::open(&file_path)?),
            };
            files.push((file_path, file));
        }
        let mut reader = Self {
            path,
            storage,
            files,
            topics: Vec::new(),
            metadata: Some(metadata),
        };
        reader.topics = reader.merge_topics()?;
        Ok(reader)
    }

    /// Opens MCAP bytes held in memory as a bare `.mcap` (for fuzzing and embedded data).
    pub fn from_mcap_bytes(bytes: impl Into<Arc<[u8]>>) -> Result<Self> {
        let file = McapFile::open(McapInput::Bytes(bytes.into()))?;
        Ok(Self::from_mcap_files(
            PathBuf::from("<memory>"),
            vec![(PathBuf::from("<memory>"), file)],
            None,
        ))
    }

    fn from_mcap_files(
        path: PathBuf,
        files: Vec<(PathBuf, McapFile)>,
        metadata: Option<BagMetadata>,
    ) -> Self {
        let files: Vec<_> = files
            .into_iter()
            .map(|(p, f)| (p, StorageFile::Mcap(Box::new(f))))
            .collect();
        let mut reader = Self {
            path,
            storage: StorageId::Mcap,
            files,
            topics: Vec::new(),
            metadata,
        };
        reader.topics = reader.merge_topics().unwrap_or_default();
        reader
    }

    /// Topics of all storage files, counts summed; QoS and hashes completed from metadata.yaml.
    fn merge_topics(&self) -> Result<Vec<TopicInfo>> {
        let mut topics: Vec<TopicInfo> = Vec::new();
        for (_, file) in &self.files {
            let file_topics = match file {
                StorageFile::Mcap(m) => &m.topics,
                StorageFile::Sqlite(s) => &s.topics,
            };
            for topic in file_topics {
                match topics.iter_mut().find(|t| t.name == topic.name) {
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
        let mut truncated = false;
        for (_, file) in &self.files {
            let (file_bounds, file_truncated) = match file {
                StorageFile::Mcap(m) => (m.time_bounds, m.truncated),
                StorageFile::Sqlite(s) => (s.time_bounds, false),
            };
            truncated |= file_truncated;
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
            truncated,
        }
    }

    /// Every message in log-time order (file order inside a storage file cut short).
    pub fn messages(&self) -> Result<Messages> {
        self.messages_filtered(None)
    }

    /// Messages of the named topics only; an unknown topic name is an error.
    pub fn messages_on(&self, topics: &[&str]) -> Result<Messages> {
        for name in topics {
            if self.topic(name).is_none() {
                return Err(BagError::UnknownTopic {
                    topic: name.to_string(),
                });
            }
        }
        let set: BTreeSet<String> = topics.iter().map(|t| t.to_string()).collect();
        self.messages_filtered(Some(&set))
    }

    fn messages_filtered(&self, topics: Option<&BTreeSet<String>>) -> Result<Messages> {
        let mut sources = Vec::new();
        for (_, file) in &self.files {
            sources.push(match file {
                StorageFile::Mcap(m) => Source::Mcap(m.messages(topics)?),
                StorageFile::Sqlite(s) => Source::Sqlite(s.messages(topics)?),
            });
        }
        let heads = sources.iter().map(|_| None).collect();
        Ok(Messages {
            sources,
            heads,
            primed: false,
            errors: VecDeque::new(),
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

fn list_mcap_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir).map_err(crate::error::io_error(dir, "cannot list"))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "mcap"))
        .collect();
    files.sort();
    Ok(files)
}

enum Source {
    Mcap(McapMessages),
    Sqlite(SqliteMessages),
}

impl Iterator for Source {
    type Item = Result<BagMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        match self {
            Source::Mcap(m) => m.next(),
            Source::Sqlite(m) => m.next(),
        }
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
