//! sqlite3 storage (`.db3`) in the layout of rosbag2 Iron/Jazzy (schema version 4): tables
//! `schema`, `metadata`, `topics` (with `offered_qos_profiles` and `type_description_hash`),
//! `message_definitions` and `messages`. Older files (Foxy/Humble, fewer tables/columns) read too.

use std::collections::{BTreeSet, HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rusqlite::{Connection, OpenFlags, OptionalExtension, ffi, params};

use crate::error::{BagError, Result, sqlite_error};
use crate::metadata::BagMetadata;
use crate::qos;
use crate::reader::{BagMessage, MessageFilter, RecordedVersion, TopicInfo, stored_definition};
use crate::source::{StorageSource, copy_for_temporary};
use crate::writer::{StorageSink, WriterTopic};

const SCHEMA_VERSION: i64 = 4;
/// Rows fetched per query while streaming.
const BATCH: i64 = 512;
/// Message bytes a fetched batch may hold: a batch ends at the first row that brings it to
/// this (a single larger message is a batch of its own), so 512 large messages (images, point
/// clouds, maps) are never held at once.
const BATCH_BYTES: usize = 8 << 20;

const CREATE_TABLES: &str = "
CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);
CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);
CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
  serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL, type_description_hash TEXT NOT NULL);
CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT NULL, encoding TEXT NOT NULL,
  encoded_message_definition TEXT NOT NULL, type_description_hash TEXT NOT NULL);
CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB NOT NULL);
CREATE INDEX timestamp_idx ON messages (timestamp ASC);
";

/// Message bytes an open transaction may hold before it is committed without a flush: it is
/// held in memory (see [`SqliteSink`]), and a writer whose flushes are far apart must not grow
/// without bound. Large, because each commit syncs the file: committing every MiB made a bulk
/// write (`bag convert`) three times slower.
const TRANSACTION_LIMIT: u64 = 64 << 20;

/// Writes a `.db3` in one open transaction, committed at each flush. The transaction's pages
/// stay in memory until it commits (cache spill is off): SQLite would otherwise write them
/// into the file once they outgrow its page cache (2 MB), after making the rollback journal
/// hot, and a writer killed then leaves a file that a read-only reader cannot open until the
/// journal is rolled back.
pub(crate) struct SqliteSink {
    path: PathBuf,
    conn: Option<Connection>,
    defined_types: BTreeSet<String>,
    /// Message bytes written since the last commit.
    pending: u64,
    /// [`TRANSACTION_LIMIT`]; smaller in tests.
    commit_after: u64,
    /// The metadata version, which decides the form of the QoS in `topics` rows.
    metadata_version: u32,
}

impl SqliteSink {
    pub(crate) fn create(path: &Path, ros_distro: &str, metadata_version: u32) -> Result<Self> {
        if path.exists() {
            return Err(BagError::Write {
                path: path.to_path_buf(),
                message: "file already exists".into(),
            });
        }
        let err = sqlite_error(path);
        let conn = Connection::open(path).map_err(sqlite_error(path))?;
        conn.execute_batch("PRAGMA cache_spill = OFF")
            .map_err(sqlite_error(path))?;
        conn.execute_batch(CREATE_TABLES)
            .map_err(sqlite_error(path))?;
        conn.execute(
            "INSERT INTO schema(schema_version, ros_distro) VALUES (?1, ?2)",
            params![SCHEMA_VERSION, ros_distro],
        )
        .map_err(sqlite_error(path))?;
        conn.execute_batch("BEGIN").map_err(err)?;
        Ok(Self {
            path: path.to_path_buf(),
            conn: Some(conn),
            defined_types: BTreeSet::new(),
            pending: 0,
            commit_after: TRANSACTION_LIMIT,
            metadata_version,
        })
    }

    fn conn(&self) -> Result<&Connection> {
        self.conn.as_ref().ok_or_else(|| BagError::Write {
            path: self.path.clone(),
            message: "the bag is already finished".into(),
        })
    }
}

impl StorageSink for SqliteSink {
    fn add_topic(&mut self, topic: &WriterTopic) -> Result<i64> {
        let path = self.path.clone();
        let conn = self.conn()?;
        conn.execute(
            "INSERT INTO topics(name, type, serialization_format, offered_qos_profiles, type_description_hash)
             VALUES (?1, ?2, ?3, ?4, ?5)",
            params![
                topic.name,
                topic.type_name,
                topic.serialization_format,
                qos::to_yaml_string(&topic.qos, self.metadata_version),
                topic.type_description_hash
            ],
        )
        .map_err(sqlite_error(&path))?;
        let id = conn.last_insert_rowid();
        // No row for a type without a definition: rosbag2 writes one with an empty encoding,
        // which rosbags (0.11) cannot read (`KeyError: ''`); without a row, rosbag2 and
        // rosbags both read the type as having none, as in a Humble bag.
        if !topic.schema_encoding.is_empty() && !self.defined_types.contains(&topic.type_name) {
            conn.execute(
                "INSERT INTO message_definitions(topic_type, encoding, encoded_message_definition, type_description_hash)
                 VALUES (?1, ?2, ?3, ?4)",
                params![
                    topic.type_name,
                    topic.schema_encoding,
                    topic.schema_text,
                    topic.type_description_hash
                ],
            )
            .map_err(sqlite_error(&path))?;
            self.defined_types.insert(topic.type_name.clone());
        }
        Ok(id)
    }

    /// sqlite3 has no column for the send time: rosbag2's sqlite3 plugin drops it too.
    fn write(
        &mut self,
        topic: &WriterTopic,
        log_time_ns: i64,
        _publish_time_ns: i64,
        data: &[u8],
    ) -> Result<()> {
        let path = self.path.clone();
        let conn = self.conn()?;
        let mut insert = conn
            .prepare_cached("INSERT INTO messages(topic_id, timestamp, data) VALUES (?1, ?2, ?3)")
            .map_err(sqlite_error(&path))?;
        insert
            .execute(params![topic.storage_id, log_time_ns, data])
            .map_err(sqlite_error(&path))?;
        drop(insert);
        self.pending += data.len() as u64;
        if self.pending >= self.commit_after {
            self.flush()?;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        let path = self.path.clone();
        self.conn()?
            .execute_batch("COMMIT; BEGIN")
            .map_err(sqlite_error(path))?;
        self.pending = 0;
        Ok(())
    }

    fn finish(&mut self, metadata: &BagMetadata) -> Result<()> {
        let conn = self.conn.take().ok_or_else(|| BagError::Write {
            path: self.path.clone(),
            message: "the bag is already finished".into(),
        })?;
        let path = self.path.clone();
        conn.execute(
            "INSERT INTO metadata(metadata_version, metadata) VALUES (?1, ?2)",
            params![metadata.version, metadata.to_serialized_metadata()],
        )
        .map_err(sqlite_error(&path))?;
        conn.execute_batch("COMMIT").map_err(sqlite_error(&path))?;
        conn.close()
            .map_err(|(_, e)| BagError::Sqlite { path, cause: e })
    }
}

/// An opened `.db3` file: its topics, and how to stream its messages.
pub(crate) struct SqliteFile {
    /// The file, and the copy its messages are read from when it needed one.
    source: StorageSource,
    pub(crate) topics: Vec<TopicInfo>,
    pub(crate) time_bounds: Option<(i64, i64)>,
    /// What the file records of the rosbag2 that wrote it ([`recorded_version`]).
    pub(crate) recorded: Option<RecordedVersion>,
}

fn open_read_only(db: &Path) -> rusqlite::Result<Connection> {
    Connection::open_with_flags(
        db,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
}

/// SQLite's rollback journal of the database at `db`.
fn journal_of(db: &Path) -> PathBuf {
    let mut name = db.as_os_str().to_owned();
    name.push("-journal");
    PathBuf::from(name)
}

/// Reads the schema, which is when SQLite takes its lock and looks for a hot journal.
fn probe(conn: &Connection) -> rusqlite::Result<()> {
    conn.query_row("SELECT count(*) FROM sqlite_master", [], |_| Ok(()))
}

/// Opens `source` for reading without changing it. A writer killed in the middle of a commit,
/// or one that let SQLite spill a transaction larger than its page cache into the file (as
/// other writers may), leaves a hot rollback journal: the file holds pages of a transaction
/// that never committed until the journal is rolled back, which a read-only connection cannot
/// do (`SQLITE_READONLY_ROLLBACK`). Rolling it back in place would change the user's bag,
/// which rosbag2's read-only reader does not do either; so the file and its journal are copied
/// to a temporary directory and SQLite rolls the copy back, as it would the file itself on
/// opening it for writing: every committed message, nothing of the unfinished transaction.
fn open_for_reading(source: StorageSource) -> Result<(Connection, StorageSource)> {
    let path = &source.path;
    let conn = open_read_only(&source.bytes).map_err(sqlite_error(path))?;
    match probe(&conn) {
        Ok(()) => return Ok((conn, source)),
        Err(e)
            if e.sqlite_error()
                .is_some_and(|e| e.extended_code == ffi::SQLITE_READONLY_ROLLBACK) => {}
        Err(e) => return Err(sqlite_error(path)(e)),
    }
    drop(conn);
    let copy = roll_back_on_copy(&source)?;
    let conn = open_read_only(&copy.bytes).map_err(sqlite_error(path))?;
    probe(&conn).map_err(sqlite_error(path))?;
    Ok((conn, copy))
}

/// Copies `source` and its hot journal to a new temporary directory and rolls the copy back.
fn roll_back_on_copy(source: &StorageSource) -> Result<StorageSource> {
    const CANNOT_COPY: &str = "has a hot rollback journal beside it (`-journal`, left by a \
        writer killed in a transaction); copying the two aside to roll it back there failed \
        (opening the file for writing once, e.g. with the sqlite3 tool, rolls it back in place)";
    let name = source.path.file_name().unwrap_or("bag.db3".as_ref());
    let copy = source.copy(&name.to_string_lossy(), CANNOT_COPY, |db| {
        for (from, to) in [
            (source.bytes.clone(), db.to_path_buf()),
            (journal_of(&source.bytes), journal_of(db)),
        ] {
            // Copied into new files (not `fs::copy`, which keeps a read-only file's mode):
            // the roll-back writes to them.
            copy_for_temporary(
                &mut std::fs::File::open(&from)?,
                &mut std::fs::File::create_new(&to)?,
            )?;
        }
        Ok(())
    })?;
    let path = &source.path;
    let conn = Connection::open_with_flags(
        &copy.bytes,
        OpenFlags::SQLITE_OPEN_READ_WRITE | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(sqlite_error(path))?;
    probe(&conn).map_err(sqlite_error(path))?;
    conn.close().map_err(|(_, e)| sqlite_error(path)(e))?;
    Ok(copy)
}

/// What the file records of the rosbag2 that wrote it: the `metadata_version` of the last row
/// of the `metadata` table (rosbag2 reads the last one too), else the `ros_distro` of the
/// `schema` table, else whether its layout is one only rosbag2 before Jazzy writes (see
/// [`RecordedVersion`]). One-row queries. A table that cannot be read records nothing: this
/// only picks a default, and must not make a bag whose messages read unreadable.
fn recorded_version(conn: &Connection) -> Option<RecordedVersion> {
    let has_table = |name: &str| {
        conn.query_row(
            "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?1",
            [name],
            |_| Ok(()),
        )
        .optional()
        .is_ok_and(|found| found.is_some())
    };
    if has_table("metadata") {
        let version = conn
            .query_row(
                "SELECT metadata_version FROM metadata ORDER BY id DESC LIMIT 1",
                [],
                |row| row.get::<_, i64>(0),
            )
            .ok()
            .and_then(|version| u32::try_from(version).ok());
        if let Some(version) = version {
            return Some(RecordedVersion::StorageFile(version));
        }
    }
    if !has_table("schema") {
        return Some(RecordedVersion::SqliteLayoutBeforeJazzy);
    }
    let (schema_version, ros_distro) = conn
        .query_row("SELECT schema_version, ros_distro FROM schema", [], |row| {
            Ok((row.get::<_, i64>(0)?, row.get::<_, String>(1)?))
        })
        .ok()?;
    if !ros_distro.is_empty() {
        Some(RecordedVersion::Distribution(ros_distro))
    } else if schema_version <= 3 {
        Some(RecordedVersion::SqliteLayoutBeforeJazzy)
    } else {
        None
    }
}

fn has_column(conn: &Connection, table: &str, column: &str) -> rusqlite::Result<bool> {
    let mut stmt = conn.prepare(&format!("SELECT name FROM pragma_table_info('{table}')"))?;
    let names = stmt
        .query_map([], |row| row.get::<_, String>(0))?
        .collect::<rusqlite::Result<Vec<_>>>()?;
    Ok(names.iter().any(|n| n == column))
}

impl SqliteFile {
    pub(crate) fn open(source: StorageSource) -> Result<Self> {
        let (conn, source) = open_for_reading(source)?;
        let path = source.path.clone();
        let err = |e| BagError::Sqlite {
            path: path.to_path_buf(),
            cause: e,
        };
        let has_qos = has_column(&conn, "topics", "offered_qos_profiles").map_err(err)?;
        let has_hash = has_column(&conn, "topics", "type_description_hash").map_err(err)?;
        let has_definitions =
            has_column(&conn, "message_definitions", "encoded_message_definition").map_err(err)?;
        let sql = format!(
            "SELECT id, name, type, serialization_format, {}, {} FROM topics ORDER BY id",
            if has_qos {
                "offered_qos_profiles"
            } else {
                "''"
            },
            if has_hash {
                "type_description_hash"
            } else {
                "''"
            },
        );
        let mut stmt = conn.prepare(&sql).map_err(err)?;
        let rows = stmt
            .query_map([], |row| {
                Ok((
                    row.get::<_, i64>(0)?,
                    row.get::<_, String>(1)?,
                    row.get::<_, String>(2)?,
                    row.get::<_, String>(3)?,
                    row.get::<_, String>(4)?,
                    row.get::<_, String>(5)?,
                ))
            })
            .map_err(err)?
            .collect::<rusqlite::Result<Vec<_>>>()
            .map_err(err)?;
        let mut counts: HashMap<i64, u64> = HashMap::new();
        {
            let mut stmt = conn
                .prepare("SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id")
                .map_err(err)?;
            let mut rows = stmt.query([]).map_err(err)?;
            while let Some(row) = rows.next().map_err(err)? {
                counts.insert(
                    row.get(0).map_err(err)?,
                    row.get::<_, i64>(1).map_err(err)?.max(0) as u64,
                );
            }
        }
        let mut topics = Vec::new();
        for (id, name, type_name, serialization_format, qos_text, hash) in rows {
            let offered_qos = qos::parse_str(&qos_text).map_err(|message| BagError::Metadata {
                path: path.to_path_buf(),
                message: format!("topics row `{name}`: offered_qos_profiles: {message}"),
            })?;
            // rosbag2 stores one definition per type; a `ros2msg` one is preferred where
            // another tool has added more.
            let definition = if has_definitions {
                conn.query_row(
                    "SELECT encoding, encoded_message_definition FROM message_definitions
                     WHERE topic_type = ?1 ORDER BY encoding = 'ros2msg' DESC, rowid LIMIT 1",
                    [&type_name],
                    |row| Ok((row.get::<_, String>(0)?, row.get::<_, String>(1)?)),
                )
                .optional()
                .map_err(err)?
                .and_then(|(encoding, text)| stored_definition(&encoding, &text))
            } else {
                None
            };
            let (schema_encoding, schema_text) = match definition {
                Some((encoding, text)) => (encoding, Some(text)),
                None => (String::new(), None),
            };
            topics.push(TopicInfo {
                name,
                type_name,
                serialization_format,
                offered_qos,
                schema_text,
                schema_encoding,
                type_description_hash: hash,
                message_count: counts.get(&id).copied().unwrap_or(0),
                storage_id: id,
            });
        }
        let time_bounds = conn
            .query_row(
                "SELECT MIN(timestamp), MAX(timestamp) FROM messages",
                [],
                |row| Ok((row.get::<_, Option<i64>>(0)?, row.get::<_, Option<i64>>(1)?)),
            )
            .map_err(err)?;
        let time_bounds = match time_bounds {
            (Some(lo), Some(hi)) => Some((lo, hi)),
            _ => None,
        };
        Ok(Self {
            recorded: recorded_version(&conn),
            source,
            topics,
            time_bounds,
        })
    }

    /// Streams the messages `filter` selects in timestamp order, a batch of rows at a time
    /// (keyset pagination on the `timestamp_idx` index), each batch bounded by [`BATCH`] rows
    /// and [`BATCH_BYTES`] message bytes, so memory stays bounded whatever the file's size.
    /// The time range, and a topic filter that leaves some topic out, are applied in the
    /// query: the rows before the range, and the other topics' rows, are not read. rosbag2
    /// and [`SqliteSink`] create `timestamp_idx`; in a file without it SQLite scans the table
    /// for each batch, with the same result.
    pub(crate) fn messages(&self, filter: &MessageFilter) -> Result<SqliteMessages> {
        let conn = open_read_only(&self.source.bytes).map_err(sqlite_error(&self.source.path))?;
        let wanted: HashMap<i64, Arc<str>> = self
            .topics
            .iter()
            .filter(|t| filter.topic_set().is_none_or(|f| f.contains(&t.name)))
            .map(|t| (t.storage_id, Arc::from(t.name.as_str())))
            .collect();
        // Literal integers (ids and times), like rosbag2's own queries.
        let mut conditions = Vec::new();
        // Without a filter, a row of a topic id that `topics` lacks is reported, not skipped.
        if wanted.len() < self.topics.len() {
            let ids: Vec<String> = wanted.keys().map(i64::to_string).collect();
            conditions.push(format!("topic_id IN ({})", ids.join(", ")));
        }
        if let Some(start) = filter.start_ns() {
            conditions.push(format!("timestamp >= {start}"));
        }
        if let Some(end) = filter.end_ns() {
            conditions.push(format!("timestamp < {end}"));
        }
        if conditions.is_empty() {
            conditions.push("1".to_string());
        }
        let selected = conditions.join(" AND ");
        Ok(SqliteMessages {
            path: self.source.path.clone(),
            conn,
            topics: wanted,
            select_first: format!(
                "SELECT id, topic_id, timestamp, data FROM messages WHERE {selected}
                 ORDER BY timestamp, id LIMIT ?1"
            ),
            select_after: format!(
                "SELECT id, topic_id, timestamp, data FROM messages
                 WHERE (timestamp > ?1 OR (timestamp = ?1 AND id > ?2)) AND {selected}
                 ORDER BY timestamp, id LIMIT ?3"
            ),
            after: None,
            batch: VecDeque::new(),
            batch_bytes: BATCH_BYTES,
            done: false,
            _source: self.source.clone(),
        })
    }
}

pub(crate) struct SqliteMessages {
    path: PathBuf,
    conn: Connection,
    /// The topics read, by storage id; the query returns no other (known) topic's rows.
    topics: HashMap<i64, Arc<str>>,
    /// The first batch's query, with the topic filter and time range.
    select_first: String,
    /// The query of the batches after the first: rows after [`Self::after`].
    select_after: String,
    /// (timestamp, id) of the last row fetched.
    after: Option<(i64, i64)>,
    /// (topic_id, timestamp, data) of the rows fetched and not yet returned.
    batch: VecDeque<(i64, i64, Vec<u8>)>,
    /// [`BATCH_BYTES`]; smaller in tests.
    batch_bytes: usize,
    done: bool,
    /// Keeps a rolled-back copy alive while its messages are read (last: dropped after `conn`).
    _source: StorageSource,
}

impl SqliteMessages {
    /// Fetches the next batch. SQLite reads a row's blob only when it is asked for, so the rows
    /// after the one that fills the byte budget are not read.
    fn fetch(&mut self) -> rusqlite::Result<()> {
        let mut stmt;
        let mut rows = match self.after {
            None => {
                stmt = self.conn.prepare_cached(&self.select_first)?;
                stmt.query(params![BATCH])?
            }
            Some((timestamp, id)) => {
                stmt = self.conn.prepare_cached(&self.select_after)?;
                stmt.query(params![timestamp, id, BATCH])?
            }
        };
        let mut bytes = 0;
        while bytes < self.batch_bytes
            && let Some(row) = rows.next()?
        {
            let data: Vec<u8> = row.get(3)?;
            bytes += data.len();
            let (id, timestamp) = (row.get(0)?, row.get(2)?);
            self.after = Some((timestamp, id));
            self.batch.push_back((row.get(1)?, timestamp, data));
        }
        Ok(())
    }
}

impl Iterator for SqliteMessages {
    type Item = Result<BagMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if self.batch.is_empty() {
            if let Err(e) = self.fetch() {
                self.done = true;
                return Some(Err(BagError::Sqlite {
                    path: self.path.clone(),
                    cause: e,
                }));
            }
            if self.batch.is_empty() {
                self.done = true;
                return None;
            }
        }
        let (topic_id, timestamp, data) = self.batch.pop_front()?;
        let Some(topic) = self.topics.get(&topic_id) else {
            self.done = true;
            return Some(Err(BagError::UnknownTopicId {
                path: self.path.clone(),
                id: topic_id,
            }));
        };
        Some(Ok(BagMessage {
            topic: topic.clone(),
            log_time_ns: timestamp,
            publish_time_ns: timestamp,
            data,
        }))
    }
}

#[cfg(test)]
mod tests {
    use rusqlite::{Connection, params};

    use super::{SqliteFile, SqliteSink};
    use crate::reader::MessageFilter;
    use crate::reader::tests::write_bag;
    use crate::source::StorageSource;
    use crate::writer::{StorageSink, WriterTopic};
    use crate::{BagReader, StorageId};

    /// Message `i`: 6 KB of bytes that differ from message to message.
    fn payload(i: u32) -> Vec<u8> {
        (0..6000u32).map(|b| (b ^ i) as u8).collect()
    }

    /// The open transaction is held in memory until it commits; without a flush it is
    /// committed once it holds the limit (64 MiB; 64 KiB here) of message bytes.
    #[test]
    fn the_open_transaction_is_committed_once_it_holds_the_limit() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("rec_0.db3");
        let mut sink = SqliteSink::create(&path, "jazzy", 9).unwrap();
        sink.commit_after = 64 << 10;
        let topic = WriterTopic::string_added_to(&mut sink, "/raw");
        for i in 0..100 {
            sink.write(
                &topic,
                1000 + i64::from(i),
                1000 + i64::from(i),
                &payload(i),
            )
            .unwrap();
        }
        let file = SqliteFile::open(StorageSource::file(&path)).unwrap();
        let on_disk: Vec<Vec<u8>> = file
            .messages(&MessageFilter::new())
            .unwrap()
            .map(|m| m.unwrap().data)
            .collect();
        let per_commit = (64 << 10) / 6000 + 1;
        assert!(
            on_disk.len() >= 100 - per_commit,
            "{} of 100 committed without a flush",
            on_disk.len()
        );
        assert_eq!(
            on_disk,
            (0..on_disk.len() as u32).map(payload).collect::<Vec<_>>()
        );
    }

    /// A batch ends at the row that brings its message bytes to the budget (8 MiB; 100 kB
    /// here), so large messages are not held 512 at a time; a topic filter is applied in the
    /// query, so the rows of the topics not read are not fetched. Messages keep their order
    /// (timestamp, then id) across batches, rows of equal timestamps included.
    #[test]
    fn batches_are_bounded_by_bytes_and_hold_only_the_topics_read() {
        const BUDGET: usize = 100_000;
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("rec_0.db3");
        let mut sink = SqliteSink::create(&path, "jazzy", 9).unwrap();
        let image = WriterTopic::string_added_to(&mut sink, "/image");
        let scan = WriterTopic::string_added_to(&mut sink, "/scan");
        // 40 kB images and 6 kB scans, two of each on every timestamp.
        let image_data = |i: u32| payload(i).repeat(7)[..40_000].to_vec();
        let mut written = Vec::new();
        for i in 0..10 {
            let timestamp = 1000 + i64::from(i / 2);
            for (topic, data) in [(&image, image_data(i)), (&scan, payload(i))] {
                sink.write(topic, timestamp, timestamp, &data).unwrap();
                written.push((topic.name.clone(), timestamp, data));
            }
        }
        sink.flush().unwrap();
        let file = SqliteFile::open(StorageSource::file(&path)).unwrap();
        let read = |messages: super::SqliteMessages| -> Vec<(String, i64, Vec<u8>)> {
            messages
                .map(|m| m.unwrap())
                .map(|m| (m.topic.to_string(), m.log_time_ns, m.data))
                .collect()
        };

        let mut all = file.messages(&MessageFilter::new()).unwrap();
        all.batch_bytes = BUDGET;
        let first = all.next().unwrap().unwrap();
        let held = first.data.len() + all.batch.iter().map(|r| r.2.len()).sum::<usize>();
        assert!(
            held < BUDGET + 40_000,
            "the first batch held {held} bytes in {} rows",
            all.batch.len() + 1
        );
        let mut all_read = vec![(first.topic.to_string(), first.log_time_ns, first.data)];
        all_read.extend(read(all));
        assert!(all_read == written, "every message, in order");

        let mut scans = file
            .messages(&MessageFilter::new().topics(&["/scan"]))
            .unwrap();
        scans.batch_bytes = BUDGET;
        let first = scans.next().unwrap().unwrap();
        assert!(
            scans.batch.iter().all(|r| r.0 == scan.storage_id),
            "the batch holds only /scan rows"
        );
        let mut scans_read = vec![(first.topic.to_string(), first.log_time_ns, first.data)];
        scans_read.extend(read(scans));
        let written_scans: Vec<_> = written.into_iter().filter(|m| m.0 == "/scan").collect();
        assert!(scans_read == written_scans, "every /scan message, in order");
    }

    /// A writer killed in the middle of a commit (or one whose transaction outgrew SQLite's
    /// page cache) leaves a hot rollback journal, which a read-only connection cannot roll
    /// back. The reader rolls it back on a private copy: every committed message, none of the
    /// uncommitted ones, and the bag's files are left as they were.
    #[test]
    fn a_hot_journal_is_rolled_back_on_a_copy_and_the_bag_is_not_changed() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("rec");
        let written: Vec<Vec<u8>> = (0..50).map(payload).collect();
        // Another writer's transaction, larger than its page cache: its pages spill into the
        // file and the journal becomes hot. A copy of both now is what a kill would leave.
        let db = write_bag(&dir, StorageId::Sqlite3, 1000, &written);
        let conn = Connection::open(&db).unwrap();
        conn.execute_batch("PRAGMA cache_size = 8; BEGIN").unwrap();
        for i in 0..200 {
            conn.execute(
                "INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?1, ?2)",
                params![i, payload(9)],
            )
            .unwrap();
        }
        let killed = tmp.path().join("killed");
        std::fs::create_dir(&killed).unwrap();
        for name in ["metadata.yaml", "rec_0.db3", "rec_0.db3-journal"] {
            std::fs::copy(dir.join(name), killed.join(name)).unwrap();
        }
        conn.execute_batch("ROLLBACK").unwrap();
        let files = || {
            ["rec_0.db3", "rec_0.db3-journal"].map(|name| std::fs::read(killed.join(name)).unwrap())
        };
        let files_before = files();
        assert_ne!(files_before[1][0], 0, "the journal is hot");

        let reader = BagReader::open(&killed).unwrap_or_else(|e| panic!("open: {e}"));
        let read: Vec<Vec<u8>> = reader
            .messages()
            .unwrap()
            .map(|m| m.unwrap_or_else(|e| panic!("read: {e}")).data)
            .collect();
        assert_eq!(read, written);
        drop(reader);
        assert!(files() == files_before, "the bag's files are unchanged");
    }

    /// A time range is asked for in the query, with the topic filter, across byte-bounded
    /// batches: the first batch already starts at the range (the rows before it are not
    /// fetched), and rows of equal timestamps keep their order. The writer creates rosbag2's
    /// `timestamp_idx`, which SQLite searches for the range; a file without it (an older or
    /// foreign writer's) gives the same messages from a scan.
    #[test]
    fn a_time_range_is_read_in_the_query_with_or_without_timestamp_idx() {
        let tmp = tempfile::tempdir().unwrap();
        let path = tmp.path().join("rec_0.db3");
        let mut sink = SqliteSink::create(&path, "jazzy", 9).unwrap();
        let image = WriterTopic::string_added_to(&mut sink, "/image");
        let scan = WriterTopic::string_added_to(&mut sink, "/scan");
        // 40 rows of 6 kB, two topics on each timestamp, written out of timestamp order.
        let mut written = Vec::new();
        for i in (0..20).rev().chain(20..40) {
            let timestamp = 1000 + i64::from(i / 2);
            for (topic, data) in [(&image, payload(2 * i)), (&scan, payload(2 * i + 1))] {
                sink.write(topic, timestamp, timestamp, &data).unwrap();
                written.push((topic.name.clone(), timestamp, data));
            }
        }
        sink.flush().unwrap();
        let conn = Connection::open(&path).unwrap();
        let index: String = conn
            .query_row(
                "SELECT sql FROM sqlite_master WHERE name = 'timestamp_idx'",
                [],
                |row| row.get(0),
            )
            .unwrap();
        assert!(index.contains("messages (timestamp ASC)"), "{index}");
        // In timestamp order, rows of a timestamp in the order they were written.
        written.sort_by_key(|(_, timestamp, _)| *timestamp);
        let in_range = |topic: Option<&str>| -> Vec<(String, i64, Vec<u8>)> {
            let wanted = |t: &(String, i64, Vec<u8>)| {
                (1005..1015).contains(&t.1) && topic.is_none_or(|name| t.0 == name)
            };
            written.iter().filter(|t| wanted(t)).cloned().collect()
        };
        let range = MessageFilter::new().starting_at(1005).ending_before(1015);
        for with_index in [true, false] {
            if !with_index {
                conn.execute_batch("DROP INDEX timestamp_idx").unwrap();
            }
            let file = SqliteFile::open(StorageSource::file(&path)).unwrap();
            for topic in [None, Some("/scan")] {
                let filter = match topic {
                    Some(name) => range.clone().topics(&[name]),
                    None => range.clone(),
                };
                let mut messages = file.messages(&filter).unwrap();
                messages.batch_bytes = 20_000;
                let first = messages.next().unwrap().unwrap();
                assert!(
                    first.log_time_ns == 1005
                        && messages.batch.iter().all(|r| (1005..1015).contains(&r.1)),
                    "the first batch holds rows of the range only"
                );
                let mut read = vec![(first.topic.to_string(), first.log_time_ns, first.data)];
                read.extend(messages.map(|m| {
                    let m = m.unwrap();
                    (m.topic.to_string(), m.log_time_ns, m.data)
                }));
                assert!(
                    read == in_range(topic),
                    "{topic:?}, index {with_index}: {:?}",
                    read.iter().map(|r| (&r.0, r.1)).collect::<Vec<_>>()
                );
            }
        }
    }
}
