//! MCAP storage in rosbag2's profile: writing (chunked, flushed regularly so a killed writer
//! leaves a readable file) and streaming reading (indexed in log-time order when the file has
//! a summary, linear in file order when it does not, e.g. after the recorder was killed).

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mcap::records::{self, MessageHeader, Record, op};
use mcap::sans_io::indexed_reader::{IndexedReadEvent, IndexedReader, IndexedReaderOptions};
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
use mcap::{McapError, Summary};

use crate::error::{BagError, Result, io_error, mcap_error};
use crate::mcap_records::{
    ChunkRecords, check_summary_section, decompress_chunk, parse_checked, parse_metadata,
};
use crate::metadata::BagMetadata;
use crate::qos;
use crate::reader::{BagMessage, MessageFilter, RecordedVersion, TopicInfo, stored_definition};
use crate::source::StorageSource;
use crate::writer::{Compression, StorageSink, WriterTopic};

/// The MCAP profile and message encoding of rosbag2.
pub(crate) const PROFILE: &str = "ros2";
pub(crate) const MESSAGE_ENCODING: &str = "cdr";
/// The name of the Metadata record in which rosbag2 notes what wrote the file.
const ROSBAG2_RECORD: &str = "rosbag2";

/// Records (and decompressed chunks) larger than this are refused rather than allocated:
/// no real bag has a single 256 MiB message, and garbage lengths must not exhaust memory.
const RECORD_LENGTH_LIMIT: usize = 256 << 20;
const READ_BUFFER: usize = 256 << 10;

/// The largest message the writer takes, so that the reader can read back every file it
/// writes: a larger message is written in a chunk of its own, and the chunk record (its
/// header, the message record's, and compression's worst-case growth, which is under
/// 1/255 of the data for zstd and lz4) must stay within [`RECORD_LENGTH_LIMIT`].
const MESSAGE_LENGTH_LIMIT: usize = RECORD_LENGTH_LIMIT - RECORD_LENGTH_LIMIT / 128;
/// The largest chunk size the writer takes: a chunk holds up to twice it (it is closed at the
/// first message after it is full), which must stay within [`RECORD_LENGTH_LIMIT`].
const CHUNK_SIZE_LIMIT: u64 = (RECORD_LENGTH_LIMIT / 4) as u64;

pub(crate) struct McapSink {
    path: PathBuf,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    sequences: HashMap<u16, u32>,
    chunk_size: u64,
    /// The metadata version, which decides the form of the QoS in channel metadata.
    metadata_version: u32,
    /// [`MESSAGE_LENGTH_LIMIT`]; smaller in tests.
    max_message_len: usize,
}

impl McapSink {
    pub(crate) fn create(
        path: &Path,
        compression: Compression,
        chunk_size: u64,
        metadata_version: u32,
    ) -> Result<Self> {
        if chunk_size > CHUNK_SIZE_LIMIT {
            return Err(BagError::Write {
                path: path.to_path_buf(),
                message: format!(
                    "chunk size {chunk_size} bytes is over the {CHUNK_SIZE_LIMIT} bytes a chunk \
                     may be for the reader to read it back"
                ),
            });
        }
        let file = File::create_new(path).map_err(io_error(path, "cannot create"))?;
        let options = mcap::WriteOptions::new()
            .profile(PROFILE)
            .library(concat!("lidar-har-bag/", env!("CARGO_PKG_VERSION")))
            .compression(match compression {
                Compression::None => None,
                Compression::Zstd => Some(mcap::Compression::Zstd),
                Compression::Lz4 => Some(mcap::Compression::Lz4),
            })
            .compression_threads(0)
            .chunk_size(Some(chunk_size));
        let writer = options
            .create(BufWriter::new(file))
            .map_err(mcap_error(path))?;
        Ok(Self {
            path: path.to_path_buf(),
            writer: Some(writer),
            sequences: HashMap::new(),
            chunk_size,
            metadata_version,
            max_message_len: MESSAGE_LENGTH_LIMIT,
        })
    }

    fn writer(&mut self) -> Result<&mut mcap::Writer<BufWriter<File>>> {
        self.writer.as_mut().ok_or_else(|| BagError::Write {
            path: self.path.clone(),
            message: "the bag is already finished".into(),
        })
    }
}

impl StorageSink for McapSink {
    fn add_topic(&mut self, topic: &WriterTopic) -> Result<i64> {
        let path = self.path.clone();
        let qos = qos::to_yaml_string(&topic.qos, self.metadata_version);
        let writer = self.writer()?;
        let schema_id = writer
            .add_schema(
                &topic.type_name,
                &topic.schema_encoding,
                topic.schema_text.as_bytes(),
            )
            .map_err(mcap_error(&path))?;
        // Both keys on every channel, the hash empty where unknown, as rosbag2 Iron and later
        // write them (rosbag2_storage_mcap `create_topic`); earlier readers ignore the hash.
        let metadata = BTreeMap::from([
            ("offered_qos_profiles".to_string(), qos),
            (
                "topic_type_hash".to_string(),
                topic.type_description_hash.clone(),
            ),
        ]);
        let channel = writer
            .add_channel(
                schema_id,
                &topic.name,
                &topic.serialization_format,
                &metadata,
            )
            .map_err(mcap_error(&path))?;
        Ok(i64::from(channel))
    }

    fn write(
        &mut self,
        topic: &WriterTopic,
        log_time_ns: i64,
        publish_time_ns: i64,
        data: &[u8],
    ) -> Result<()> {
        let path = self.path.clone();
        if data.len() > self.max_message_len {
            return Err(BagError::Write {
                path,
                message: format!(
                    "`{}`: a message of {} bytes at {log_time_ns} ns is over the {} bytes an \
                     MCAP message may be for lidar-har to read it back (sqlite3 storage takes it)",
                    topic.name,
                    data.len(),
                    self.max_message_len
                ),
            });
        }
        let channel_id = u16::try_from(topic.storage_id).map_err(|_| BagError::UnknownTopicId {
            path: path.clone(),
            id: topic.storage_id,
        })?;
        if data.len() as u64 > self.chunk_size {
            // In a chunk of its own: with the messages before it the chunk could pass the limit.
            self.writer()?.flush().map_err(mcap_error(&path))?;
        }
        let time = |ns: i64, what: &str| {
            u64::try_from(ns).map_err(|_| BagError::Write {
                path: path.clone(),
                message: format!("negative {what} time {ns} ns"),
            })
        };
        let (log_time, publish_time) =
            (time(log_time_ns, "log")?, time(publish_time_ns, "publish")?);
        let sequence = self.sequences.entry(channel_id).or_insert(0);
        *sequence = sequence.wrapping_add(1);
        let header = MessageHeader {
            channel_id,
            sequence: *sequence,
            log_time,
            publish_time,
        };
        self.writer()?
            .write_to_known_channel(&header, data)
            .map_err(mcap_error(path))
    }

    fn flush(&mut self) -> Result<()> {
        let path = self.path.clone();
        self.writer()?.flush().map_err(mcap_error(path))
    }

    fn finish(&mut self, metadata: &BagMetadata) -> Result<()> {
        let mut writer = self.writer.take().ok_or_else(|| BagError::Write {
            path: self.path.clone(),
            message: "the bag is already finished".into(),
        })?;
        let path = self.path.clone();
        let mut record = BTreeMap::new();
        record.insert(
            "serialized_metadata".to_string(),
            metadata.to_serialized_metadata(),
        );
        record.insert("ROS_DISTRO".to_string(), metadata.ros_distro.clone());
        writer
            .write_metadata(&records::Metadata {
                name: ROSBAG2_RECORD.to_string(),
                metadata: record,
            })
            .map_err(mcap_error(&path))?;
        writer.finish().map_err(mcap_error(&path))?;
        let file = writer.into_inner().into_inner().map_err(|e| BagError::Io {
            path: path.clone(),
            action: "cannot flush",
            cause: e.into_error(),
        })?;
        file.sync_all().map_err(io_error(&path, "cannot sync"))
    }
}

/// Something an MCAP can be read from more than once: a file, or bytes in memory.
#[derive(Clone)]
pub(crate) enum McapInput {
    File(StorageSource),
    Bytes(Arc<[u8]>),
}

trait ReadSeek: Read + Seek {}
impl<T: Read + Seek> ReadSeek for T {}

impl McapInput {
    fn path(&self) -> PathBuf {
        match self {
            McapInput::File(source) => source.path.clone(),
            McapInput::Bytes(_) => PathBuf::from("<memory>"),
        }
    }

    fn open(&self) -> Result<(Box<dyn ReadSeek + Send>, u64)> {
        match self {
            McapInput::File(source) => {
                let path = &source.path;
                let file = File::open(&source.bytes).map_err(io_error(path, "cannot open"))?;
                let len = file
                    .metadata()
                    .map_err(io_error(path, "cannot stat"))?
                    .len();
                Ok((Box::new(BufReader::with_capacity(READ_BUFFER, file)), len))
            }
            McapInput::Bytes(bytes) => Ok((
                Box::new(std::io::Cursor::new(bytes.clone())),
                bytes.len() as u64,
            )),
        }
    }
}

/// What opening an MCAP learnt: its topics, and how to stream its messages.
pub(crate) struct McapFile {
    input: McapInput,
    layout: Layout,
    pub(crate) topics: Vec<TopicInfo>,
    /// (first, last) log time, when there are messages.
    pub(crate) time_bounds: Option<(i64, i64)>,
    /// Why the file cannot be read to its end (cut short or damaged), naming it: counts and
    /// time bounds cover the part before, and its message stream ends with the error.
    pub(crate) damage: Option<String>,
    /// What the file's `rosbag2` Metadata records say of the rosbag2 that wrote it
    /// ([`recorded_in`]).
    pub(crate) recorded: Option<RecordedVersion>,
}

/// How the messages of an MCAP are read.
enum Layout {
    /// A finished file: in log-time order, through its summary's chunk indexes.
    Indexed(Box<Summary>),
    /// A file without a summary (cut short, or unchunked): in file order, from start to end.
    Linear,
    /// A file shorter than its magic, which holds no record at all: why, as the reason of a
    /// truncation. rosbag2 opens the next split file before it writes into it, so a recorder
    /// killed just after a split leaves it empty; but any empty file looks so, hence a bag
    /// is refused unless another of its files opens (`BagReader`).
    CutInMagic(String),
}

impl McapFile {
    pub(crate) fn open(input: McapInput) -> Result<Self> {
        let path = input.path();
        let (mut reader, len) = input.open()?;
        let mut magic = [0u8; 8];
        let got = read_fully(&mut reader, &mut magic).map_err(io_error(&path, "cannot read"))?;
        if magic[..got] != mcap::MAGIC[..got] {
            return Err(BagError::NotABag {
                path,
                reason: "not an MCAP file (bad magic bytes)".into(),
            });
        }
        if got < mcap::MAGIC.len() {
            let reason = match got {
                0 => "the file is empty".to_string(),
                _ => format!("the file ends inside its magic (after {got} bytes of 8)"),
            };
            let damage = BagError::Truncated {
                path,
                messages_read: 0,
                reason: reason.clone(),
            };
            return Ok(Self {
                input,
                layout: Layout::CutInMagic(reason),
                topics: Vec::new(),
                time_bounds: None,
                damage: Some(damage.to_string()),
                recorded: None,
            });
        }
        reader
            .seek(SeekFrom::Start(0))
            .map_err(io_error(&path, "cannot seek"))?;
        match read_summary(&mut reader, len) {
            // The indexed reader only sees messages inside indexed chunks: use it when every
            // message is in one (a chunked file, or one without messages).
            Ok(Some(summary))
                if !summary.chunk_indexes.is_empty()
                    || summary.stats.as_ref().is_some_and(|s| s.message_count == 0) =>
            {
                let recorded = indexed_rosbag2_records(&mut reader, len, &summary);
                Ok(Self {
                    recorded,
                    ..Self::from_summary(input, summary)?
                })
            }
            _ => Self::from_linear_scan(input),
        }
    }

    fn from_summary(input: McapInput, summary: Summary) -> Result<Self> {
        let path = input.path();
        let (counts, time_bounds, damaged) = match &summary.stats {
            // The per-channel counts are optional inside the record (an empty map means "not
            // available", as some writers leave it), and a writer that skips a channel with
            // messages gives no usable count either: counted then, as without statistics.
            Some(stats)
                if stats
                    .channel_message_counts
                    .values()
                    .try_fold(0u64, |sum, &n| sum.checked_add(n))
                    == Some(stats.message_count) =>
            {
                let bounds = if stats.message_count > 0 {
                    Some((
                        to_i64(&path, "", stats.message_start_time)?,
                        to_i64(&path, "", stats.message_end_time)?,
                    ))
                } else {
                    None
                };
                (stats.channel_message_counts.clone(), bounds, None)
            }
            _ => count_messages(&input, &summary)?,
        };
        let mut ids: Vec<_> = summary.channels.keys().copied().collect();
        ids.sort_unstable();
        let mut topics = Vec::new();
        for id in ids {
            let channel = &summary.channels[&id];
            let schema = channel
                .schema
                .as_ref()
                .map(|s| (s.name.clone(), s.encoding.clone(), s.data.to_vec()));
            topics.push(topic_info(
                &path,
                id,
                &channel.topic,
                &channel.message_encoding,
                &channel.metadata,
                schema,
            )?);
            if let Some(topic) = topics.last_mut() {
                topic.message_count = counts.get(&id).copied().unwrap_or(0);
            }
        }
        Ok(Self {
            input,
            layout: Layout::Indexed(Box::new(summary)),
            topics,
            time_bounds,
            damage: damaged,
            recorded: None,
        })
    }

    /// Reads a file without a summary from start to end: channels, counts and time bounds.
    /// A file that ends early or is damaged (a chunk whose CRC fails or that does not
    /// decompress, a malformed record) is accepted here, counted up to that point: its
    /// message stream stops at the same point and reports the error, so one bad chunk costs
    /// the rest of its file, not the bag.
    fn from_linear_scan(input: McapInput) -> Result<Self> {
        let mut stream = LinearMessages::new(&input, &MessageFilter::new())?;
        let mut counts: HashMap<u16, u64> = HashMap::new();
        let mut time_bounds: Option<(i64, i64)> = None;
        let mut damage = None;
        while let Some(item) = stream.next_raw() {
            match item {
                Ok((channel_id, log_time, _, _)) => {
                    *counts.entry(channel_id).or_insert(0) += 1;
                    time_bounds = Some(match time_bounds {
                        None => (log_time, log_time),
                        Some((lo, hi)) => (lo.min(log_time), hi.max(log_time)),
                    });
                }
                Err(e) => {
                    damage = Some(e.to_string());
                    break;
                }
            }
        }
        let mut topics = std::mem::take(&mut stream.topics);
        for topic in &mut topics {
            topic.message_count = counts.get(&(topic.storage_id as u16)).copied().unwrap_or(0);
        }
        Ok(Self {
            input,
            layout: Layout::Linear,
            topics,
            time_bounds,
            damage,
            recorded: RecordedVersion::most_telling(std::mem::take(&mut stream.recorded)),
        })
    }

    /// Why the file holds no record (it is empty or ends inside its magic), if so.
    pub(crate) fn cut_in_magic(&self) -> Option<&str> {
        match &self.layout {
            Layout::CutInMagic(reason) => Some(reason),
            _ => None,
        }
    }

    /// Streams the messages `filter` selects in log-time order when the file has a summary,
    /// reading only the chunks whose time span meets its range, else in file order, reading
    /// every record. Memory stays bounded by the chunks in flight. A file cut in its magic has
    /// no messages to stream: its truncation is the error.
    pub(crate) fn messages(&self, filter: &MessageFilter) -> Result<McapMessages> {
        match &self.layout {
            // `mcap`'s indexed reader turns the topics into the channel ids that carry them and
            // takes an empty set for no filter at all: a file with none of the topics (a split
            // file written before a topic first appeared) would yield every message.
            Layout::Indexed(_)
                if filter.topic_set().is_some_and(|wanted| {
                    !self.topics.iter().any(|t| wanted.contains(&t.name))
                }) =>
            {
                Ok(McapMessages::Empty)
            }
            Layout::Indexed(summary) => Ok(McapMessages::Indexed(IndexedMessages::new(
                &self.input,
                summary,
                filter,
            )?)),
            Layout::Linear => Ok(McapMessages::Linear(LinearMessages::new(
                &self.input,
                filter,
            )?)),
            Layout::CutInMagic(reason) => Err(BagError::Truncated {
                path: self.input.path(),
                messages_read: 0,
                reason: reason.clone(),
            }),
        }
    }
}

fn owned(record: Option<Record<'_>>) -> Option<Record<'static>> {
    record.map(Record::into_owned)
}

fn read_fully(reader: &mut dyn Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match reader.read(&mut buf[filled..])? {
            0 => break,
            n => filled += n,
        }
    }
    Ok(filled)
}

fn read_summary(
    reader: &mut dyn ReadSeek,
    len: u64,
) -> std::result::Result<Option<Summary>, McapError> {
    check_summary_section(reader, len, RECORD_LENGTH_LIMIT)?;
    reader.seek(SeekFrom::Start(0))?;
    let mut summary_reader = SummaryReader::new_with_options(
        SummaryReaderOptions::default()
            .with_file_size(len)
            .with_record_length_limit(RECORD_LENGTH_LIMIT),
    );
    while let Some(event) = summary_reader.next_event() {
        match event? {
            SummaryReadEvent::ReadRequest(n) => {
                let read = reader.read(summary_reader.insert(n))?;
                summary_reader.notify_read(read);
            }
            SummaryReadEvent::SeekRequest(to) => {
                let pos = reader.seek(to)?;
                summary_reader.notify_seeked(pos);
            }
        }
    }
    Ok(summary_reader.finish())
}

/// What the `rosbag2` Metadata records of a file with a summary say, read through the
/// summary's metadata indexes (one small read each). A record that cannot be read says nothing.
fn indexed_rosbag2_records(
    reader: &mut dyn ReadSeek,
    len: u64,
    summary: &Summary,
) -> Option<RecordedVersion> {
    let read_record = |reader: &mut dyn ReadSeek, index: &records::MetadataIndex| {
        let length = usize::try_from(index.length)
            .ok()
            .filter(|&length| length <= RECORD_LENGTH_LIMIT)
            .filter(|_| {
                index
                    .offset
                    .checked_add(index.length)
                    .is_some_and(|end| end <= len)
            })?;
        reader.seek(SeekFrom::Start(index.offset)).ok()?;
        let mut record = vec![0u8; length];
        reader.read_exact(&mut record).ok()?;
        let mut records = ChunkRecords::new(record);
        let (opcode, body) = records.next_record()?.ok()?;
        (opcode == op::METADATA)
            .then(|| parse_metadata(records.body(body)))
            .flatten()
            .as_ref()
            .and_then(recorded_in)
    };
    RecordedVersion::most_telling(
        summary
            .metadata_indexes
            .iter()
            .filter(|index| index.name == ROSBAG2_RECORD)
            .filter_map(|index| read_record(reader, index)),
    )
}

/// What a `rosbag2` Metadata record says of the rosbag2 that wrote its file: the `version` of
/// its `serialized_metadata` (the metadata without its root key; rosbag2 writes it at each
/// `update_metadata` call of its writer from Iron on, and `BagWriter` when it finishes), else
/// its `ROS_DISTRO` (which rosbag2 Iron from 0.22.2 on writes in a record of its own when it
/// opens a file for writing, so a file a killed recorder left still names it).
fn recorded_in(record: &records::Metadata) -> Option<RecordedVersion> {
    #[derive(serde::Deserialize)]
    struct Versioned {
        version: u32,
    }
    if record.name != ROSBAG2_RECORD {
        return None;
    }
    let version = record
        .metadata
        .get("serialized_metadata")
        .and_then(|text| serde_yaml_ng::from_str::<Versioned>(text).ok())
        .map(|metadata| RecordedVersion::StorageFile(metadata.version));
    version.or_else(|| {
        record
            .metadata
            .get("ROS_DISTRO")
            .filter(|distro| !distro.is_empty())
            .map(|distro| RecordedVersion::Distribution(distro.clone()))
    })
}

/// Message counts per channel, the (first, last) log time when there are messages, and
/// why reading stopped early (at a damaged chunk), if it did.
type Counts = (BTreeMap<u16, u64>, Option<(i64, i64)>, Option<String>);

/// Per-channel counts and time bounds of a file whose summary has no Statistics record (the
/// record is optional: e.g. Python's `mcap` writer with `use_statistics=False`) or one without
/// per-channel counts, by reading every chunk once. Chunk indexes alone would give the time span but not the counts. A chunk
/// that cannot be read ends the count there, not the opening: the message stream stops at the
/// same chunk and reports why.
fn count_messages(input: &McapInput, summary: &Summary) -> Result<Counts> {
    let path = input.path();
    let mut stream = IndexedMessages::new(input, summary, &MessageFilter::new())?;
    let mut counts = BTreeMap::new();
    let mut bounds: Option<(u64, u64)> = None;
    let mut damaged = None;
    while let Some(item) =
        stream.next_with(|_, _, header, _| Ok((header.channel_id, header.log_time)))
    {
        let (channel_id, log_time) = match item {
            Ok(item) => item,
            Err(e) => {
                damaged = Some(e.to_string());
                break;
            }
        };
        *counts.entry(channel_id).or_insert(0) += 1;
        bounds = Some(match bounds {
            None => (log_time, log_time),
            Some((lo, hi)) => (lo.min(log_time), hi.max(log_time)),
        });
    }
    let bounds = match bounds {
        Some((lo, hi)) => Some((to_i64(&path, "", lo)?, to_i64(&path, "", hi)?)),
        None => None,
    };
    Ok((counts, bounds, damaged))
}

/// A message of a file read in file order: channel id, log time, publish time, bytes.
type RawMessage = (u16, i64, i64, Vec<u8>);

/// A message's publish (send) time; its log time where the publish time is past an `i64`,
/// which no clock gives (the log time is what orders and selects messages).
fn publish_time_ns(header: &MessageHeader, log_time_ns: i64) -> i64 {
    i64::try_from(header.publish_time).unwrap_or(log_time_ns)
}

fn to_i64(path: &Path, topic: &str, log_time: u64) -> Result<i64> {
    i64::try_from(log_time).map_err(|_| BagError::BadTime {
        path: path.to_path_buf(),
        topic: topic.to_string(),
        log_time,
    })
}

/// A rosbag2 topic from an MCAP channel; refuses a channel without a schema record (rosbag2
/// writes one for every channel, empty where it has no definition).
fn topic_info(
    path: &Path,
    channel_id: u16,
    topic: &str,
    message_encoding: &str,
    metadata: &BTreeMap<String, String>,
    schema: Option<(String, String, Vec<u8>)>,
) -> Result<TopicInfo> {
    let Some((type_name, encoding, data)) = schema else {
        return Err(BagError::MissingSchema {
            path: path.to_path_buf(),
            topic: topic.to_string(),
        });
    };
    let offered_qos = match metadata.get("offered_qos_profiles") {
        Some(text) => qos::parse_str(text).map_err(|message| BagError::Metadata {
            path: path.to_path_buf(),
            message: format!("channel `{topic}`: offered_qos_profiles: {message}"),
        })?,
        None => Vec::new(),
    };
    let (schema_encoding, schema_text) =
        match stored_definition(&encoding, &String::from_utf8_lossy(&data)) {
            Some((encoding, text)) => (encoding, Some(text)),
            None => (String::new(), None),
        };
    Ok(TopicInfo {
        name: topic.to_string(),
        type_name,
        serialization_format: message_encoding.to_string(),
        offered_qos,
        schema_text,
        schema_encoding,
        type_description_hash: metadata.get("topic_type_hash").cloned().unwrap_or_default(),
        message_count: 0,
        storage_id: i64::from(channel_id),
    })
}

/// Messages of one MCAP file.
pub(crate) enum McapMessages {
    Indexed(IndexedMessages),
    Linear(LinearMessages),
    /// A complete file without any of the topics asked for.
    Empty,
}

impl Iterator for McapMessages {
    type Item = Result<BagMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        match self {
            McapMessages::Indexed(m) => m.next(),
            McapMessages::Linear(m) => m.next(),
            McapMessages::Empty => None,
        }
    }
}

/// Log-time-ordered reading through the summary's chunk indexes.
pub(crate) struct IndexedMessages {
    path: PathBuf,
    file: Box<dyn ReadSeek + Send>,
    reader: IndexedReader,
    channels: HashMap<u16, Arc<str>>,
    chunk: Vec<u8>,
    failed: bool,
    /// Keeps a temporary copy that `file` reads alive (last: dropped after `file`).
    _input: McapInput,
}

impl IndexedMessages {
    /// The messages `filter` selects. `mcap` leaves out the chunks whose indexed time span
    /// misses the range unread and drops the messages outside it from the chunks it reads.
    /// MCAP log times are unsigned: a range starting before 0 starts at 0, and one ending at
    /// or before 0 is empty (the caller reads nothing for a range with its end at or before
    /// its start, which `mcap` would refuse).
    fn new(input: &McapInput, summary: &Summary, filter: &MessageFilter) -> Result<Self> {
        let path = input.path();
        let (file, _) = input.open()?;
        let mut options = IndexedReaderOptions::new().with_record_length_limit(RECORD_LENGTH_LIMIT);
        if let Some(topics) = filter.topic_set() {
            options = options.include_topics(topics.iter().cloned());
        }
        if let Some(start) = filter.start_ns().and_then(|ns| u64::try_from(ns).ok()) {
            options = options.starting_at(start);
        }
        if let Some(end) = filter.end_ns() {
            options = options.ending_before(u64::try_from(end).unwrap_or(0));
        }
        let reader =
            IndexedReader::new_with_options(summary, options).map_err(mcap_error(&path))?;
        let channels = summary
            .channels
            .iter()
            .map(|(id, c)| (*id, Arc::from(c.topic.as_str())))
            .collect();
        Ok(Self {
            path,
            file,
            reader,
            channels,
            chunk: Vec::new(),
            failed: false,
            _input: input.clone(),
        })
    }

    /// Reads on to the next message and hands its header and bytes to `take` (with the path
    /// and the channels' topics, for error messages and names).
    fn next_with<T>(
        &mut self,
        take: impl FnOnce(&Path, &HashMap<u16, Arc<str>>, &MessageHeader, &[u8]) -> Result<T>,
    ) -> Option<Result<T>> {
        if self.failed {
            return None;
        }
        let result = loop {
            let event = match self.reader.next_event()? {
                Ok(event) => event,
                Err(e) => {
                    break Err(BagError::Mcap {
                        path: self.path.clone(),
                        cause: e,
                    });
                }
            };
            match event {
                IndexedReadEvent::ReadChunkRequest { offset, length } => {
                    self.chunk.resize(length, 0);
                    let read = self
                        .file
                        .seek(SeekFrom::Start(offset))
                        .and_then(|_| self.file.read_exact(&mut self.chunk));
                    if let Err(e) = read {
                        let truncated = e.kind() == std::io::ErrorKind::UnexpectedEof;
                        break Err(if truncated {
                            BagError::Mcap {
                                path: self.path.clone(),
                                cause: McapError::BadIndex,
                            }
                        } else {
                            BagError::Io {
                                path: self.path.clone(),
                                action: "cannot read",
                                cause: e,
                            }
                        });
                    }
                    if let Err(e) = self.reader.insert_chunk_record_data(offset, &self.chunk) {
                        break Err(BagError::Mcap {
                            path: self.path.clone(),
                            cause: e,
                        });
                    }
                }
                IndexedReadEvent::Message { header, data } => {
                    break take(&self.path, &self.channels, &header, data);
                }
            }
        };
        self.failed = result.is_err();
        Some(result)
    }
}

impl Iterator for IndexedMessages {
    type Item = Result<BagMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        self.next_with(|path, channels, header, data| {
            let Some(topic) = channels.get(&header.channel_id) else {
                return Err(BagError::UnknownTopicId {
                    path: path.to_path_buf(),
                    id: i64::from(header.channel_id),
                });
            };
            to_i64(path, topic, header.log_time).map(|log_time_ns| BagMessage {
                topic: topic.clone(),
                log_time_ns,
                publish_time_ns: publish_time_ns(header, log_time_ns),
                data: data.to_vec(),
            })
        })
    }
}

/// File-order reading of every record, for files without a summary. Each chunk is read whole
/// and its CRC checked before any of its messages is yielded, so a chunk cut short yields
/// nothing corrupt.
pub(crate) struct LinearMessages {
    path: PathBuf,
    file: Box<dyn ReadSeek + Send>,
    /// The file's size: a record longer than this was never finished.
    file_len: u64,
    /// Boxed: `mcap`'s reader state is large, and this path serves only unfinished files.
    reader: Box<LinearReader>,
    schemas: HashMap<u16, (String, String, Vec<u8>)>,
    channels: HashMap<u16, Arc<str>>,
    pub(crate) topics: Vec<TopicInfo>,
    /// Which messages [`Iterator::next`] yields; [`Self::next_raw`] yields all.
    filter: MessageFilter,
    messages_read: u64,
    /// The records of the chunk being read, checked and decompressed by `mcap_records`.
    chunk: Option<ChunkRecords>,
    /// What the `rosbag2` Metadata records read so far say ([`recorded_in`]).
    recorded: Vec<RecordedVersion>,
    done: bool,
    /// Keeps a temporary copy that `file` reads alive (last: dropped after `file`).
    _input: McapInput,
}

impl LinearMessages {
    fn new(input: &McapInput, filter: &MessageFilter) -> Result<Self> {
        let path = input.path();
        let (file, file_len) = input.open()?;
        let reader = Box::new(LinearReader::new_with_options(
            LinearReaderOptions::default()
                .with_emit_chunks(true)
                .with_record_length_limit(RECORD_LENGTH_LIMIT),
        ));
        Ok(Self {
            path,
            file,
            file_len,
            reader,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            topics: Vec::new(),
            filter: filter.clone(),
            messages_read: 0,
            chunk: None,
            recorded: Vec::new(),
            done: false,
            _input: input.clone(),
        })
    }

    /// Ends the scan with `cause`. A file that ends inside a record is truncated, not invalid:
    /// it ends before a record's end, or a record claims more bytes than the whole file has
    /// (`mcap`'s writer leaves `u64::MAX` as the length of the chunk it is writing until the
    /// chunk is complete, so that is what a killed recorder leaves).
    fn fail(&mut self, cause: McapError) -> BagError {
        self.done = true;
        let reason = match cause {
            McapError::UnexpectedEof => "the file ends before its summary and footer".to_string(),
            McapError::RecordTooLarge { opcode, len } if opcode == op::CHUNK && len == u64::MAX => {
                "the last chunk was still being written (its length is the writer's placeholder)"
                    .to_string()
            }
            McapError::RecordTooLarge { opcode, len } if len > self.file_len => format!(
                "the last record (opcode {opcode:#04x}) claims {len} bytes, more than the {}-byte file",
                self.file_len
            ),
            cause => {
                return BagError::Mcap {
                    path: self.path.clone(),
                    cause,
                };
            }
        };
        BagError::Truncated {
            path: self.path.clone(),
            messages_read: self.messages_read,
            reason,
        }
    }

    /// The next message, whatever its topic.
    fn next_raw(&mut self) -> Option<Result<RawMessage>> {
        loop {
            if self.done {
                return None;
            }
            if let Some(mut chunk) = self.chunk.take() {
                let (opcode, range) = match chunk.next_record() {
                    None => continue,
                    Some(Ok(record)) => record,
                    Some(Err(e)) => return Some(Err(self.fail(e))),
                };
                let parsed = parse_checked(opcode, chunk.body(range)).map(owned);
                self.chunk = Some(chunk);
                let outcome = self.on_record(parsed);
                match outcome {
                    Some(message) => return Some(message),
                    None => continue,
                }
            }
            let event = match self.reader.next_event() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Ok(event)) => event,
                Some(Err(e)) => return Some(Err(self.fail(e))),
            };
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    match self.file.read(self.reader.insert(need)) {
                        Ok(n) => self.reader.notify_read(n),
                        Err(e) => {
                            self.done = true;
                            return Some(Err(BagError::Io {
                                path: self.path.clone(),
                                action: "cannot read",
                                cause: e,
                            }));
                        }
                    }
                }
                LinearReadEvent::Record { opcode, data } if opcode == op::METADATA => {
                    self.recorded
                        .extend(parse_metadata(data).as_ref().and_then(recorded_in));
                }
                LinearReadEvent::Record { opcode, data } => {
                    // Owning the parsed record ends the borrow of the reader's buffer; records
                    // the scan skips are never copied.
                    let parsed = parse_checked(opcode, data).map(owned);
                    if let Some(message) = self.on_record(parsed) {
                        return Some(message);
                    }
                }
            }
        }
    }

    /// Takes in one parsed record of the file or of a chunk; `Some` for a message or an error.
    fn on_record(
        &mut self,
        parsed: std::result::Result<Option<Record<'static>>, McapError>,
    ) -> Option<Result<RawMessage>> {
        let record = match parsed {
            Ok(Some(record)) => record,
            Ok(None) => return None,
            Err(e) => return Some(Err(self.fail(e))),
        };
        match record {
            Record::Chunk { header, data } => {
                match decompress_chunk(&header, data, RECORD_LENGTH_LIMIT) {
                    Ok(records) => self.chunk = Some(ChunkRecords::new(records)),
                    Err(e) => return Some(Err(self.fail(e))),
                }
            }
            Record::Schema { header, data } => {
                self.schemas
                    .insert(header.id, (header.name, header.encoding, data.into_owned()));
            }
            Record::Channel(channel) => {
                if self.channels.contains_key(&channel.id) {
                    return None;
                }
                let schema = self.schemas.get(&channel.schema_id).cloned();
                let info = match topic_info(
                    &self.path,
                    channel.id,
                    &channel.topic,
                    &channel.message_encoding,
                    &channel.metadata,
                    schema,
                ) {
                    Ok(info) => info,
                    Err(e) => {
                        self.done = true;
                        return Some(Err(e));
                    }
                };
                self.channels
                    .insert(channel.id, Arc::from(channel.topic.as_str()));
                self.topics.push(info);
            }
            Record::Message { header, data } => {
                if !self.channels.contains_key(&header.channel_id) {
                    self.done = true;
                    return Some(Err(BagError::UnknownTopicId {
                        path: self.path.clone(),
                        id: i64::from(header.channel_id),
                    }));
                }
                let log_time = match to_i64(&self.path, "", header.log_time) {
                    Ok(t) => t,
                    Err(e) => {
                        self.done = true;
                        return Some(Err(e));
                    }
                };
                self.messages_read += 1;
                return Some(Ok((
                    header.channel_id,
                    log_time,
                    publish_time_ns(&header, log_time),
                    data.into_owned(),
                )));
            }
            _ => {}
        }
        None
    }
}

impl Iterator for LinearMessages {
    type Item = Result<BagMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let (channel_id, log_time_ns, publish_time_ns, data) = match self.next_raw()? {
                Ok(raw) => raw,
                Err(e) => return Some(Err(e)),
            };
            let Some(topic) = self.channels.get(&channel_id) else {
                continue;
            };
            if !self.filter.includes(topic, log_time_ns) {
                continue;
            }
            return Some(Ok(BagMessage {
                topic: topic.clone(),
                log_time_ns,
                publish_time_ns,
                data,
            }));
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::path::Path;

    use crate::{BagError, BagReader, MessageFilter};

    /// An MCAP in rosbag2's profile with `per_topic` messages on each of `topics`, interleaved,
    /// log times 1000, 1001, ... in file order. Small chunks, so there are several.
    fn write_mcap(
        path: &Path,
        topics: &[&str],
        per_topic: u64,
        statistics: bool,
        compression: Option<mcap::Compression>,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        {
            let mut writer = mcap::WriteOptions::new()
                .profile(super::PROFILE)
                .emit_statistics(statistics)
                .compression(compression)
                .chunk_size(Some(256))
                .create(std::io::Cursor::new(&mut out))
                .unwrap();
            let schema = writer
                .add_schema("std_msgs/msg/String", "ros2msg", b"string data")
                .unwrap();
            let channels: Vec<u16> = topics
                .iter()
                .map(|t| {
                    writer
                        .add_channel(schema, t, "cdr", &BTreeMap::new())
                        .unwrap()
                })
                .collect();
            let mut log_time = 1000;
            for i in 0..per_topic {
                for &channel_id in &channels {
                    let header = mcap::records::MessageHeader {
                        channel_id,
                        sequence: i as u32,
                        log_time,
                        publish_time: log_time,
                    };
                    writer
                        .write_to_known_channel(&header, &[0, 1, 0, 0, 2, 0, 0, 0, b'x', 0])
                        .unwrap();
                    log_time += 1;
                }
            }
            writer.finish().unwrap();
        }
        std::fs::write(path, &out).unwrap();
        out
    }

    /// A message over the reader's record limit used to be written, and the file then read
    /// as "invalid MCAP" from that chunk on, by `bag convert` too. The writer refuses it
    /// (limit 4 KiB here), naming the topic and size; a message larger than a chunk is written
    /// in a chunk of its own, so the messages before it cannot take that chunk over the limit.
    #[test]
    fn a_message_the_reader_could_not_read_back_is_refused() {
        use crate::writer::{Compression, StorageSink, WriterTopic};

        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("big_0.mcap");
        assert!(
            super::McapSink::create(&path, Compression::None, super::CHUNK_SIZE_LIMIT + 1, 9)
                .err()
                .is_some_and(|e| e.to_string().contains("chunk size"))
        );
        let mut sink = super::McapSink::create(&path, Compression::None, 256, 9).unwrap();
        sink.max_message_len = 4096;
        let topic = WriterTopic::string_added_to(&mut sink, "/map");
        let err = sink
            .write(&topic, 7, 7, &[0; 4097])
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("`/map`") && err.contains("4097 bytes") && err.contains("4096 bytes"),
            "{err}"
        );
        // The first chunk closes after the schema, channel and first message; the second
        // still has room when the large message comes.
        sink.write(&topic, 0, 0, &[1; 200]).unwrap();
        sink.write(&topic, 1, 1, &[1; 100]).unwrap();
        sink.write(&topic, 2, 2, &[2; 4096]).unwrap();
        sink.write(&topic, 3, 3, &[3; 10]).unwrap();
        sink.finish(
            &crate::metadata::BagMetadata::parse(
                "rosbag2_bagfile_information: {version: 9, storage_identifier: mcap}",
                &path,
            )
            .unwrap(),
        )
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let big = summary
            .chunk_indexes
            .iter()
            .find(|c| c.message_start_time <= 2 && 2 <= c.message_end_time)
            .unwrap();
        assert_eq!((big.message_start_time, big.message_end_time), (2, 2));
        assert!(big.uncompressed_size < 4096 + 64, "{big:?}");
        let reader = BagReader::open(&path).unwrap();
        assert_eq!(reader.messages().unwrap().count(), 4);
    }

    /// rosbag2 split bags where a topic first appears after the first split: the earlier
    /// files have no channel for it, and `mcap`'s reader would take the empty channel set
    /// it makes of the topic filter for no filter at all.
    #[test]
    fn a_split_file_without_the_requested_topic_yields_none_of_its_messages() {
        let tmp = tempfile::tempdir().unwrap();
        write_mcap(&tmp.path().join("split_0.mcap"), &["/a"], 20, true, None);
        write_mcap(
            &tmp.path().join("split_1.mcap"),
            &["/a", "/b"],
            10,
            true,
            None,
        );
        let reader = BagReader::open(tmp.path()).unwrap();
        let on_b: Vec<_> = reader
            .messages_on(&["/b"])
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let topics: Vec<&str> = on_b.iter().map(|m| &*m.topic).collect();
        assert_eq!(topics, vec!["/b"; 10]);
        let on_a = reader.messages_on(&["/a"]).unwrap().count();
        assert_eq!(on_a, 30);
    }

    /// `ros2 bag record` opens the next split file before writing into it: killed just after
    /// a split, it leaves that file empty, or holding only part of the magic. The file opens as
    /// truncated with no messages, and the bag's other file is read whole. A single file whose
    /// bytes are not the start of the magic is still no MCAP.
    #[test]
    fn a_split_file_cut_in_its_magic_opens_as_truncated_and_empty() {
        let tmp = tempfile::tempdir().unwrap();
        write_mcap(&tmp.path().join("split_0.mcap"), &["/a"], 20, true, None);
        for (cut, says) in [(0, "is empty"), (3, "inside its magic")] {
            std::fs::write(tmp.path().join("split_1.mcap"), &mcap::MAGIC[..cut]).unwrap();
            let reader = BagReader::open(tmp.path()).unwrap_or_else(|e| panic!("open: {e}"));
            let info = reader.metadata();
            assert!(info.truncated, "cut at {cut}");
            assert_eq!(info.message_count, 20);
            let (times, errors) = read_all(tmp.path());
            assert_eq!(times, (1000..1020).collect::<Vec<_>>());
            let [error] = &errors[..] else {
                panic!("one error expected: {errors:?}");
            };
            let text = error.to_string();
            assert!(
                matches!(
                    error,
                    BagError::Truncated {
                        messages_read: 0,
                        ..
                    }
                ) && text.contains("split_1.mcap")
                    && text.contains(says),
                "{text}"
            );
        }
        let not_mcap = tmp.path().join("notes.mcap");
        std::fs::write(&not_mcap, b"\x89MCAx").unwrap();
        let error = BagReader::open(&not_mcap).err().unwrap();
        assert!(matches!(error, BagError::NotABag { .. }), "{error}");
    }

    /// `bytes`, written without statistics, with a Statistics record whose map of counts per
    /// channel is empty, which the MCAP specification reads as "not available" (Python's
    /// `mcap` writer can leave it so). Inserted before the summary offsets, whose offsets
    /// into the summary stay right; the footer's offset and summary CRC are updated.
    fn with_statistics_without_channel_counts(bytes: &[u8], message_count: u64) -> Vec<u8> {
        let summary = mcap::Summary::read(bytes).unwrap().unwrap();
        let footer = bytes.len() - (1 + 8 + 8 + 8 + 4 + 8);
        let field = |at: usize| {
            u64::from_le_bytes(bytes[footer + at..footer + at + 8].try_into().unwrap()) as usize
        };
        let (summary_start, offsets_start) = (field(9), field(17));
        assert!(summary_start > 0 && offsets_start > 0);
        let chunks = &summary.chunk_indexes;
        let mut body = message_count.to_le_bytes().to_vec();
        body.extend((summary.schemas.len() as u16).to_le_bytes());
        body.extend((summary.channels.len() as u32).to_le_bytes());
        body.extend([0; 8]); // attachments, metadata
        body.extend((chunks.len() as u32).to_le_bytes());
        let start = chunks.iter().map(|c| c.message_start_time).min().unwrap();
        body.extend(start.to_le_bytes());
        let end = chunks.iter().map(|c| c.message_end_time).max().unwrap();
        body.extend(end.to_le_bytes());
        body.extend(0u32.to_le_bytes()); // channel_message_counts: no entries
        let mut record = vec![mcap::records::op::STATISTICS];
        record.extend((body.len() as u64).to_le_bytes());
        record.extend(body);
        let mut out = [&bytes[..offsets_start], &record, &bytes[offsets_start..]].concat();
        let footer = footer + record.len();
        let moved = (offsets_start + record.len()) as u64;
        out[footer + 17..footer + 25].copy_from_slice(&moved.to_le_bytes());
        let crc = crc32fast::hash(&out[summary_start..footer + 25]);
        out[footer + 25..footer + 29].copy_from_slice(&crc.to_le_bytes());
        let stats = mcap::Summary::read(&out).unwrap().unwrap().stats.unwrap();
        assert!(stats.channel_message_counts.is_empty() && stats.message_count > 0);
        out
    }

    /// Counts "not available" are not zero: a topic counted 0 is a topic without messages
    /// (`lidar-har run` took /map and /odom for absent). They are counted from the chunks.
    #[test]
    fn statistics_without_counts_per_channel_are_counted_from_the_chunks() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("rec_0.mcap");
        let bytes = write_mcap(&path, &["/a", "/b"], 30, false, None);
        std::fs::write(&path, with_statistics_without_channel_counts(&bytes, 60)).unwrap();
        let reader = BagReader::open(&path).unwrap_or_else(|e| panic!("open: {e}"));
        let counts: Vec<(&str, u64)> = reader
            .topics()
            .iter()
            .map(|t| (t.name.as_str(), t.message_count))
            .collect();
        assert_eq!(counts, vec![("/a", 30), ("/b", 30)]);
        let info = reader.metadata();
        assert_eq!(info.message_count, 60);
        assert_eq!((info.start_ns, info.end_ns), (1000, 1059));
        assert!(!info.truncated);
    }

    /// The bytes up to the end of the file's last chunk (a file without its summary, as a
    /// killed recorder leaves it), with one byte flipped inside that chunk's records; and the
    /// log time of the chunk's first message.
    fn damage_last_chunk(bytes: &[u8], cut: bool) -> (Vec<u8>, i64) {
        let summary = mcap::Summary::read(bytes).unwrap().unwrap();
        let last = summary
            .chunk_indexes
            .iter()
            .max_by_key(|c| c.chunk_start_offset)
            .unwrap();
        let end = (last.chunk_start_offset + last.chunk_length) as usize;
        let mut damaged = if cut {
            bytes[..end].to_vec()
        } else {
            bytes.to_vec()
        };
        damaged[end - 3] ^= 0x40;
        (damaged, last.message_start_time as i64)
    }

    /// Reads every item of the bag at `dir`: the messages (log times) and the errors.
    fn read_all(dir: &Path) -> (Vec<i64>, Vec<BagError>) {
        let reader = BagReader::open(dir).unwrap_or_else(|e| panic!("open: {e}"));
        let (mut times, mut errors) = (Vec::new(), Vec::new());
        for item in reader.messages().unwrap() {
            match item {
                Ok(m) => times.push(m.log_time_ns),
                Err(e) => errors.push(e),
            }
        }
        (times, errors)
    }

    /// A split bag whose second file was cut after its last chunk (no summary) and has one
    /// byte wrong in that chunk: the bag opens, every message of the good file and of the good
    /// chunks comes, then the error naming the file and the failed CRC.
    #[test]
    fn a_corrupt_chunk_in_a_file_without_summary_ends_that_file_only() {
        let tmp = tempfile::tempdir().unwrap();
        write_mcap(&tmp.path().join("split_0.mcap"), &["/a"], 20, true, None);
        let second = tmp.path().join("split_1.mcap");
        let bytes = write_mcap(&second, &["/a", "/b"], 40, true, None);
        let (damaged, bad_from) = damage_last_chunk(&bytes, true);
        std::fs::write(&second, damaged).unwrap();

        let reader = BagReader::open(tmp.path()).unwrap_or_else(|e| panic!("open: {e}"));
        let info = reader.metadata();
        assert!(info.truncated, "the damage is reported by metadata()");
        assert!(
            info.damaged.len() == 1
                && info.damaged[0].contains("split_1.mcap")
                && info.damaged[0].contains("CRC"),
            "the file and why: {:?}",
            info.damaged
        );
        let (times, errors) = read_all(tmp.path());
        // The first file's 20 messages and the second's before its last chunk, in order.
        let expected: Vec<i64> = (1000..1020).chain(1000..bad_from).collect();
        let mut sorted = times.clone();
        sorted.sort_unstable();
        let mut expected_sorted = expected.clone();
        expected_sorted.sort_unstable();
        assert_eq!(sorted, expected_sorted);
        assert_eq!(info.message_count, expected.len() as u64);
        let [error] = &errors[..] else {
            panic!("one error expected: {errors:?}");
        };
        let text = error.to_string();
        assert!(
            text.contains("split_1.mcap") && text.contains("CRC"),
            "{text}"
        );
    }

    /// The same damage, in a zstd chunk, of a complete file whose summary has no Statistics
    /// record (its counts come from reading every chunk when it is opened).
    #[test]
    fn a_corrupt_chunk_in_a_file_without_statistics_ends_that_file_only() {
        let tmp = tempfile::tempdir().unwrap();
        write_mcap(&tmp.path().join("split_0.mcap"), &["/a"], 20, true, None);
        let second = tmp.path().join("split_1.mcap");
        let bytes = write_mcap(
            &second,
            &["/a", "/b"],
            40,
            false,
            Some(mcap::Compression::Zstd),
        );
        let (damaged, bad_from) = damage_last_chunk(&bytes, false);
        std::fs::write(&second, damaged).unwrap();

        let reader = BagReader::open(tmp.path()).unwrap_or_else(|e| panic!("open: {e}"));
        let info = reader.metadata();
        assert!(info.truncated, "the damage is reported by metadata()");
        assert!(
            info.damaged.len() == 1
                && info.damaged[0].contains("split_1.mcap")
                && info.damaged[0].contains("decompression"),
            "the file and why: {:?}",
            info.damaged
        );
        let (times, errors) = read_all(tmp.path());
        let mut expected: Vec<i64> = (1000..1020).chain(1000..bad_from).collect();
        expected.sort_unstable();
        assert_eq!(times, expected, "log-time order");
        assert_eq!(info.message_count, expected.len() as u64);
        let [error] = &errors[..] else {
            panic!("one error expected: {errors:?}");
        };
        let text = error.to_string();
        assert!(
            text.contains("split_1.mcap") && text.contains("decompression"),
            "{text}"
        );
    }

    /// (log time, error text) of what a read of `filter` on the bag at `path` yields.
    fn read_range(path: &Path, filter: &MessageFilter) -> (Vec<i64>, Vec<String>) {
        let reader = BagReader::open(path).unwrap_or_else(|e| panic!("open: {e}"));
        let (mut times, mut errors) = (Vec::new(), Vec::new());
        for item in reader.messages_matching(filter).unwrap() {
            match item {
                Ok(m) => times.push(m.log_time_ns),
                Err(e) => errors.push(e.to_string()),
            }
        }
        (times, errors)
    }

    /// Through the summary, a time range reads only the chunks whose indexed span meets it:
    /// the first chunk, made undecompressable, fails a read of the whole file but not one
    /// that starts after it (which would fail too if it read that chunk and dropped its
    /// messages). A range ending inside the file ends there, a topic filter with it.
    #[test]
    fn a_time_range_skips_the_chunks_before_it_unread() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("rec_0.mcap");
        let mut bytes = write_mcap(
            &path,
            &["/a", "/b"],
            40,
            true,
            Some(mcap::Compression::Zstd),
        );
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert!(summary.chunk_indexes.len() > 4, "several chunks");
        let first = summary
            .chunk_indexes
            .iter()
            .min_by_key(|c| c.chunk_start_offset)
            .unwrap();
        let end = (first.chunk_start_offset + first.chunk_length) as usize;
        bytes[end - 3] ^= 0x40;
        std::fs::write(&path, &bytes).unwrap();
        let after = first.message_end_time as i64 + 1;

        let (times, errors) = read_range(&path, &MessageFilter::new());
        assert!(times.is_empty(), "{times:?}");
        assert!(
            errors.len() == 1 && errors[0].contains("rec_0.mcap"),
            "{errors:?}"
        );
        let from = MessageFilter::new().starting_at(after);
        let (times, errors) = read_range(&path, &from);
        assert!(errors.is_empty(), "{errors:?}");
        assert_eq!(times, (after..1080).collect::<Vec<_>>());
        let (times, errors) = read_range(&path, &from.topics(&["/b"]).ending_before(1050));
        assert!(errors.is_empty(), "{errors:?}");
        // `/b` is written second at each step: odd log times.
        let odd: Vec<i64> = (after..1050).filter(|t| t % 2 == 1).collect();
        assert_eq!(times, odd);
    }

    /// A file without a summary (cut short) has no index: its messages are read from the
    /// start, those in the range come, in file order, then its truncation error, also when
    /// the range holds none of its messages.
    #[test]
    fn a_time_range_of_a_file_cut_short_ends_with_its_truncation() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("rec_0.mcap");
        let bytes = write_mcap(&path, &["/a", "/b"], 40, true, None);
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        let last = summary
            .chunk_indexes
            .iter()
            .max_by_key(|c| c.chunk_start_offset)
            .unwrap();
        let complete = last.message_start_time as i64;
        std::fs::write(&path, &bytes[..last.chunk_start_offset as usize + 20]).unwrap();
        assert!(complete > 1030, "the cut is in the last chunk ({complete})");

        let range = MessageFilter::new().starting_at(1010).ending_before(1030);
        let (times, errors) = read_range(&path, &range);
        assert_eq!(times, (1010..1030).collect::<Vec<_>>());
        let [error] = &errors[..] else {
            panic!("one error expected: {errors:?}");
        };
        assert!(error.contains("rec_0.mcap"), "{error}");
        let reader = BagReader::open(&path).unwrap();
        let error = reader
            .messages_matching(&MessageFilter::new().starting_at(complete))
            .unwrap()
            .map(|m| m.map(|m| m.log_time_ns))
            .collect::<Vec<_>>();
        assert!(
            matches!(
                &error[..],
                [Err(BagError::Truncated { messages_read, .. })]
                    if *messages_read == (complete - 1000) as u64
            ),
            "{error:?}"
        );
    }
}
