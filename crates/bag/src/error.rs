//! Errors of the bag reader and writer. Each names the path it concerns and what is wrong.
//!
//! Every message is complete on its own: the underlying error's text is part of it, and that
//! error is kept in a `cause` field, not exposed as `source()`. Callers print bag errors both
//! with `{}` (log lines) and as a chain with `{:#}` (the `lidar-har` binary); a cause that were
//! both in the text and the chain would be printed twice.

use std::path::PathBuf;

/// Why a bag could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    #[error("{path}: no such file or directory")]
    NotFound { path: PathBuf },
    #[error("{path}: not a rosbag2 bag: {reason}")]
    NotABag { path: PathBuf, reason: String },
    #[error("{path}: {action}: {cause}")]
    Io {
        path: PathBuf,
        action: &'static str,
        cause: std::io::Error,
    },
    #[error("{path}: malformed metadata.yaml: {message}")]
    Metadata { path: PathBuf, message: String },
    #[error(
        "{path}: metadata.yaml version {version} is not supported (this reader knows versions 1 to 9)"
    )]
    UnsupportedVersion { path: PathBuf, version: u32 },
    #[error("{path}: unknown storage identifier `{storage_id}` (supported: mcap, sqlite3)")]
    UnknownStorage { path: PathBuf, storage_id: String },
    #[error("{path}: compression `{format}` ({mode}) is not supported")]
    UnsupportedCompression {
        path: PathBuf,
        format: String,
        mode: String,
    },
    /// Compression mode MESSAGE: the message's data is not a zstd frame.
    #[error(
        "{path}: message on `{topic}` at {log_time_ns} ns: its data does not zstd-decompress (compression mode MESSAGE): {cause}"
    )]
    MessageDecompression {
        path: PathBuf,
        topic: String,
        log_time_ns: i64,
        cause: std::io::Error,
    },
    #[error("{path}: {}", McapCause(.cause))]
    Mcap {
        path: PathBuf,
        cause: mcap::McapError,
    },
    /// The file ends inside a record (cut short, or a chunk still open when the recorder was
    /// killed); `reason` says which. Every complete message before it was read.
    #[error(
        "{path}: MCAP file is truncated (e.g. the recorder was killed) after {messages_read} complete messages: {reason}"
    )]
    Truncated {
        path: PathBuf,
        messages_read: u64,
        reason: String,
    },
    #[error("{path}: sqlite3 storage: {cause}")]
    Sqlite {
        path: PathBuf,
        cause: rusqlite::Error,
    },
    #[error("{path}: topic `{topic}` has no schema (message definition); every channel needs one")]
    MissingSchema { path: PathBuf, topic: String },
    /// rosbag2 records a topic with one type, and a message carries only its topic's name:
    /// the messages of the two types could not be told apart.
    #[error(
        "{path}: topic `{topic}` has two types, `{first_type}` and `{second_type}` (rosbag2 records one type per topic; their messages cannot be told apart)"
    )]
    TopicWithTwoTypes {
        path: PathBuf,
        topic: String,
        first_type: String,
        second_type: String,
    },
    #[error("{path}: message refers to unknown channel/topic id {id}")]
    UnknownTopicId { path: PathBuf, id: i64 },
    #[error("{path}: message on `{topic}` at {log_time} ns has log time out of range")]
    BadTime {
        path: PathBuf,
        topic: String,
        log_time: u64,
    },
    #[error("topic `{topic}` has type `{found}`, not `{expected}`")]
    WrongType {
        topic: String,
        expected: &'static str,
        found: String,
    },
    #[error("topic `{topic}` is not in this bag")]
    UnknownTopic { topic: String },
    #[error("message on `{topic}` at {log_time_ns} ns: {cause}")]
    Decode {
        topic: String,
        log_time_ns: i64,
        cause: lidar_har_msgs::CdrError,
    },
    #[error("{path}: cannot write: {message}")]
    Write { path: PathBuf, message: String },
}

pub type Result<T, E = BagError> = std::result::Result<T, E>;

/// What went wrong in the `mcap` crate: the file's content, or an I/O error, whose own text
/// (a full disk) that crate's message leaves out.
struct McapCause<'a>(&'a mcap::McapError);

impl std::fmt::Display for McapCause<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            mcap::McapError::Io(e) => write!(f, "I/O error: {e}"),
            other => write!(f, "invalid MCAP: {other}"),
        }
    }
}

pub(crate) fn io_error(
    path: impl Into<PathBuf>,
    action: &'static str,
) -> impl FnOnce(std::io::Error) -> BagError {
    let path = path.into();
    move |cause| BagError::Io {
        path,
        action,
        cause,
    }
}

pub(crate) fn sqlite_error(path: impl Into<PathBuf>) -> impl FnOnce(rusqlite::Error) -> BagError {
    let path = path.into();
    move |cause| BagError::Sqlite { path, cause }
}

pub(crate) fn mcap_error(path: impl Into<PathBuf>) -> impl FnOnce(mcap::McapError) -> BagError {
    let path = path.into();
    move |cause| BagError::Mcap { path, cause }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A full disk while the output bag was written had read "invalid MCAP: I/O error from
    /// writing, or reading a compression stream", without what the system said.
    #[test]
    fn an_mcap_io_error_says_what_the_system_said() {
        let disk_full = BagError::Mcap {
            path: "out/out_0.mcap".into(),
            cause: mcap::McapError::Io(std::io::Error::from_raw_os_error(28)),
        };
        let text = disk_full.to_string();
        assert!(
            text.starts_with("out/out_0.mcap: I/O error: No space left on device"),
            "{text}"
        );
        assert!(!text.contains("invalid MCAP"), "{text}");
        let corrupt = BagError::Mcap {
            path: "in.mcap".into(),
            cause: mcap::McapError::BadMagic,
        };
        assert!(
            corrupt.to_string().starts_with("in.mcap: invalid MCAP: "),
            "{corrupt}"
        );
    }
}
