//! rosbag2 compression (`ros2 bag record --compression-format zstd`), which wraps storage
//! files rather than being part of them: in mode FILE each closed split file is replaced by a
//! zstd stream of it (`<name>_<N>.mcap.zstd`), in mode MESSAGE each message's data is one zstd
//! frame inside an ordinary storage file (`rosbag2_compression_zstd`).

use std::ffi::OsStr;
use std::fs::File;
use std::io::Read;
use std::path::Path;

use crate::error::{BagError, Result};
use crate::metadata::BagMetadata;
use crate::reader::BagMessage;
use crate::source::{StorageSource, copy_for_temporary};

/// The extension rosbag2 adds to a file it compressed (mode FILE).
const COMPRESSED_EXTENSION: &str = "zstd";

/// Decompressed message data larger than this is refused, as MCAP records are: no real message
/// is that large, and a corrupt frame must not exhaust memory.
const MESSAGE_LIMIT: u64 = 256 << 20;

/// The first bytes of a zstd frame. CDR data starts with its encapsulation header, whose
/// first byte is 0, so message data starting so is compressed.
const ZSTD_MAGIC: [u8; 4] = [0x28, 0xB5, 0x2F, 0xFD];

/// Which messages' data is a zstd frame (mode MESSAGE).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum MessageCompression {
    None,
    All,
    /// Those that start with [`ZSTD_MAGIC`]: without metadata.yaml (a killed recorder leaves
    /// none, whatever its mode) nothing says whether the messages are compressed.
    ByMagic,
}

impl MessageCompression {
    pub(crate) fn applies_to(self, data: &[u8]) -> bool {
        match self {
            MessageCompression::None => false,
            MessageCompression::All => true,
            MessageCompression::ByMagic => data.starts_with(&ZSTD_MAGIC),
        }
    }
}

/// Whether each message's data is compressed (mode MESSAGE), from metadata.yaml. Files
/// compressed whole are known by their name, as in a directory without metadata.yaml. The mode
/// is read without regard to case and ignored without a format, as rosbag2 does; another format
/// or an unknown mode is refused.
pub(crate) fn message_compression(
    metadata: &BagMetadata,
    metadata_path: &Path,
) -> Result<MessageCompression> {
    if metadata.compression_format.is_empty() {
        return Ok(MessageCompression::None);
    }
    let mode = metadata.compression_mode.to_ascii_uppercase();
    match (metadata.compression_format.as_str(), mode.as_str()) {
        ("zstd", "MESSAGE") => Ok(MessageCompression::All),
        ("zstd", "FILE" | "NONE" | "") => Ok(MessageCompression::None),
        _ => Err(BagError::UnsupportedCompression {
            path: metadata_path.to_path_buf(),
            format: metadata.compression_format.clone(),
            mode: metadata.compression_mode.clone(),
        }),
    }
}

/// The name of the storage file that `path` holds compressed (`rec_0.mcap` for
/// `rec_0.mcap.zstd`), or `None` for a file that is not compressed whole.
pub(crate) fn compressed_file_name(path: &Path) -> Option<&OsStr> {
    let compressed = path.extension()? == COMPRESSED_EXTENSION;
    compressed.then(|| path.file_stem()).flatten()
}

/// The file at `path` as read: a file compressed whole is decompressed into a temporary copy
/// (named as before compression), since MCAP and SQLite need to seek in it.
pub(crate) fn open_source(path: &Path) -> Result<StorageSource> {
    let file = StorageSource::file(path);
    let Some(name) = compressed_file_name(path) else {
        return Ok(file);
    };
    file.copy(
        &name.to_string_lossy(),
        "cannot zstd-decompress (rosbag2 file compression) into a temporary file",
        |to| {
            let mut decoder = zstd::stream::read::Decoder::new(File::open(path)?)?;
            copy_for_temporary(&mut decoder, &mut File::create_new(to)?)?;
            Ok(())
        },
    )
}

/// `message` with its data decompressed (mode MESSAGE); `path` is its storage file.
pub(crate) fn decompress_message(path: &Path, mut message: BagMessage) -> Result<BagMessage> {
    let mut data = Vec::new();
    let decoded = zstd::stream::read::Decoder::with_buffer(&message.data[..])
        .and_then(|decoder| decoder.take(MESSAGE_LIMIT + 1).read_to_end(&mut data));
    let cause = match decoded {
        Ok(len) if len as u64 <= MESSAGE_LIMIT => {
            message.data = data;
            return Ok(message);
        }
        Ok(_) => std::io::Error::other(format!("more than {} MiB", MESSAGE_LIMIT >> 20)),
        Err(cause) => cause,
    };
    Err(BagError::MessageDecompression {
        path: path.to_path_buf(),
        topic: message.topic.to_string(),
        log_time_ns: message.log_time_ns,
        cause,
    })
}
