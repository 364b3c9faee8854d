//! sqlite3 storage (`.db3`) in the layout of rosbag2 Iron/Jazzy (schema version 4): tables
//! `schema`, `metadata`, `topics` (with `offered_qos_profiles` and `type_description_hash`),
//! `message_definitions` and `messages`. Older files (Foxy/Humble, fewer tables/columns) read too.

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rusqlite::{Connection, OpenFlags, OptionalExtension, params};

use crate::error::{BagError, Result, sqlite_error};
use crate::metadata::{BagMetadata, METADATA_VERSION};
use crate::qos;
use crate::reader::{BagMessage, TopicInfo};
use crate::writer::{StorageSink, WriterTopic};

const SCHEMA_VERSION: i64 = 4;
/// Rows fetched per query while streaming; bounds reader memory.
const BATCH: i64 = 512;

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

pub(crate) struct SqliteSink {
    path: PathBuf,
    conn: Option<Connection>,
    defined_types: BTreeSet<String>,
}

impl SqliteSink {
    pub(crate) fn create(path: &Path, ros_distro: &str) -> Result<Self> {
        if path.exists() {
            return Err(BagError::Write {
                path: path.to_path_buf(),
                message: "file already exists".into(),
            });
        }
        let err = sqlite_error(path);
        let conn = Connection::open(path).map_err(sqlite_error(path))?;
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
                qos::to_yaml_string(&topic.qos, METADATA_VERSION),
                topic.type_description_hash
            ],
        )
        .map_err(sqlite_error(&path))?;
        let id = conn.last_insert_rowid();
        if !self.defined_types.contains(&topic.type_name) {
            conn.execute(
                "INSERT INTO message_definitions(topic_type, encoding, encoded_message_definition, type_description_hash)
                 VALUES (?1, 'ros2msg', ?2, ?3)",
                params![topic.type_name, topic.schema_text, topic.type_description_hash],
            )
            .map_err(sqlite_error(&path))?;
            self.defined_types.insert(topic.type_name.clone());
        }
        Ok(id)
    }

    fn write(&mut self, storage_id: i64, log_time_ns: i64, data: &[u8]) -> Result<()> {
        let path = self.path.clone();
        let conn = self.conn()?;
        let mut insert = conn
            .prepare_cached("INSERT INTO messages(topic_id, timestamp, data) VALUES (?1, ?2, ?3)")
            .map_err(sqlite_error(&path))?;
        insert
            .execute(params![storage_id, log_time_ns, data])
            .map_err(sqlite_error(&path))?;
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        let path = self.path.clone();
        self.conn()?
            .execute_batch("COMMIT; BEGIN")
            .map_err(sqlite_error(path))
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
    path: PathBuf,
    pub(crate) topics: Vec<TopicInfo>,
    pub(crate) time_bounds: Option<(i64, i64)>,
}

fn open_read_only(path: &Path) -> Result<Connection> {
    Connection::open_with_flags(
        path,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(sqlite_error(path))
}

fn has_column(conn: &Connection, table: &str, column: &str) -> rusqlite::Result<bool> {
    let mut stmt = conn.prepare(&format!("SELECT name FROM pragma_table_info('{table}')"))?;
    let names = stmt
        .query_map([], |row| row.get::<_, String>(0))?
        .collect::<rusqlite::Result<Vec<_>>>()?;
    Ok(names.iter().any(|n| n == column))
}

impl SqliteFile {
    pub(crate) fn open(path: &Path) -> Result<Self> {
        let conn = open_read_only(path)?;
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
            let schema_text = if has_definitions {
                conn.query_row(
                    "SELECT encoded_message_definition FROM message_definitions WHERE topic_type = ?1 AND encoding = 'ros2msg'",
                    [&type_name],
                    |row| row.get::<_, String>(0),
                )
                .optional()
                .map_err(err)?
                .filter(|s| !s.is_empty())
            } else {
                None
            };
            topics.push(TopicInfo {
                name,
                type_name,
                serialization_format,
                offered_qos,
                schema_text,
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
            path: path.to_path_buf(),
            topics,
            time_bounds,
        })
    }

    /// Streams messages in timestamp order, a batch of rows at a time (keyset pagination on
    /// the `timestamp_idx` index), so memory stays constant whatever the file's size.
    pub(crate) fn messages(&self, topics: Option<&BTreeSet<String>>) -> Result<SqliteMessages> {
        let conn = open_read_only(&self.path)?;
        let wanted = self
            .topics
            .iter()
            .filter(|t| topics.is_none_or(|f| f.contains(&t.name)))
            .map(|t| (t.storage_id, Arc::from(t.name.as_str())))
            .collect();
        Ok(SqliteMessages {
            path: self.path.clone(),
            conn,
            topics: wanted,
            all_topics: self.topics.iter().map(|t| t.storage_id).collect(),
            after: None,
            batch: std::collections::VecDeque::new(),
            done: false,
        })
    }
}

pub(crate) struct SqliteMessages {
    path: PathBuf,
    conn: Connection,
    topics: HashMap<i64, Arc<str>>,
    all_topics: BTreeSet<i64>,
    /// (timestamp, id) of the last row fetched.
    after: Option<(i64, i64)>,
    batch: std::collections::VecDeque<(i64, i64, i64, Vec<u8>)>,
    done: bool,
}

impl SqliteMessages {
    fn fetch(&mut self) -> rusqlite::Result<()> {
        let (sql, ts, id) = match self.after {
            None => ("SELECT id, topic_id, timestamp, data FROM messages ORDER BY timestamp, id LIMIT ?1", 0, 0),
            Some((ts, id)) => (
                "SELECT id, topic_id, timestamp, data FROM messages
                 WHERE timestamp > ?1 OR (timestamp = ?1 AND id > ?2) ORDER BY timestamp, id LIMIT ?3",
                ts,
                id,
            ),
        };
        let mut stmt = self.conn.prepare_cached(sql)?;
        let mut rows = if self.after.is_some() {
            stmt.query(params![ts, id, BATCH])?
        } else {
            stmt.query(params![BATCH])?
        };
        while let Some(row) = rows.next()? {
            self.batch
                .push_back((row.get(0)?, row.get(1)?, row.get(2)?, row.get(3)?));
        }
        Ok(())
    }
}

impl Iterator for SqliteMessages {
    type Item = Result<BagMessage>;
    fn next(&mut self) -> Option<Self::Item> {
        loop {
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
            let (id, topic_id, timestamp, data) = self.batch.pop_front()?;
            self.after = Some((timestamp, id));
            if let Some(topic) = self.topics.get(&topic_id) {
                return Some(Ok(BagMessage {
                    topic: topic.clone(),
                    log_time_ns: timestamp,
                    data,
                }));
            }
            if !self.all_topics.contains(&topic_id) {
                self.done = true;
                return Some(Err(BagError::UnknownTopicId {
                    path: self.path.clone(),
                    id: topic_id,
                }));
            }
        }
    }
}
