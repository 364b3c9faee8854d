//! Bounds-checked MCAP records for the linear scan of files without a summary (cut short,
//! corrupt, or written by a tool that skips the summary).
//!
//! Why not let `mcap` do it: on corrupt input its chunk reader can overflow an unsigned
//! subtraction (`mcap` 0.26, `sans_io/linear_reader.rs:745`) and its string parser reserves
//! whatever length prefix it reads (up to 4 GiB) before noticing the bytes are not there. Both
//! were found by the `mcap_read` fuzz target. So here every length is checked against the
//! bytes that are really present before `mcap::parse_record` sees a record, and chunks are
//! decompressed, CRC-checked and split into records by this module.

use std::borrow::Cow;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;

use mcap::McapError;
use mcap::records::{ChunkHeader, Record, op};

/// A record's opcode and length field.
const OPCODE_LEN_SIZE: usize = 1 + 8;

/// Parses the records the linear scan uses (schemas, channels, messages, chunks) after
/// checking every length inside them; other records are skipped (`None`).
pub(crate) fn parse_checked(opcode: u8, body: &[u8]) -> Result<Option<Record<'_>>, McapError> {
    if !matches!(opcode, op::SCHEMA | op::CHANNEL | op::CHUNK | op::MESSAGE) {
        return Ok(None);
    }
    check_lengths(opcode, body)?;
    mcap::parse_record(opcode, body).map(Some)
}

/// A Metadata record from its body, every length checked first as in [`parse_checked`];
/// `None` when it is malformed.
pub(crate) fn parse_metadata(body: &[u8]) -> Option<mcap::records::Metadata> {
    check_lengths(op::METADATA, body).ok()?;
    match mcap::parse_record(op::METADATA, body).ok()? {
        Record::Metadata(metadata) => Some(metadata),
        _ => None,
    }
}

/// Checks that every string and map inside a record fits in the record, for each record type
/// that has one (MCAP specification, "Records"); fixed-size records need no check.
fn check_lengths(opcode: u8, body: &[u8]) -> Result<(), McapError> {
    let mut f = Fields { bytes: body };
    match opcode {
        op::HEADER => {
            f.string()?; // profile
            f.string()?; // library
        }
        op::SCHEMA => {
            f.skip(2)?; // id
            f.string()?; // name
            f.string()?; // encoding
        }
        op::CHANNEL => {
            f.skip(2 + 2)?; // id, schema id
            f.string()?; // topic
            f.string()?; // message encoding
            f.string_map()?; // metadata
        }
        op::CHUNK => {
            f.skip(8 + 8 + 8 + 4)?; // start, end, uncompressed size, crc
            f.string()?; // compression
        }
        op::CHUNK_INDEX => {
            f.skip(8 * 4)?; // start, end, chunk offset, chunk length
            let offsets = f.u32()? as usize;
            f.skip(offsets)?; // message index offsets
            f.skip(8)?; // message index length
            f.string()?; // compression
        }
        op::ATTACHMENT => {
            f.skip(8 + 8)?; // log time, create time
            f.string()?; // name
            f.string()?; // media type
        }
        op::ATTACHMENT_INDEX => {
            f.skip(8 * 5)?; // offset, length, log time, create time, data size
            f.string()?; // name
            f.string()?; // media type
        }
        op::METADATA => {
            f.string()?; // name
            f.string_map()?; // metadata
        }
        op::METADATA_INDEX => {
            f.skip(8 + 8)?; // offset, length
            f.string()?; // name
        }
        _ => {}
    }
    Ok(())
}

/// Size of the footer record with the magic after it: opcode, length, summary start, summary
/// offset start, summary CRC, magic.
const FOOTER_WITH_MAGIC: u64 = 1 + 8 + 8 + 8 + 4 + 8;

/// Checks the lengths inside every record of the summary section before `mcap`'s summary
/// reader parses them; a file without a summary passes. `len` is the file's size.
pub(crate) fn check_summary_section(
    file: &mut (impl Read + Seek + ?Sized),
    len: u64,
    limit: usize,
) -> Result<(), McapError> {
    let Some(footer_start) = len.checked_sub(FOOTER_WITH_MAGIC) else {
        return Ok(());
    };
    file.seek(SeekFrom::Start(footer_start))?;
    let mut footer = [0u8; FOOTER_WITH_MAGIC as usize];
    file.read_exact(&mut footer)?;
    if footer[0] != op::FOOTER || footer[FOOTER_WITH_MAGIC as usize - 8..] != *mcap::MAGIC {
        return Ok(()); // no footer: `mcap` reports it, the linear scan takes over
    }
    let summary_start = u64::from_le_bytes(footer[9..17].try_into().unwrap_or_default());
    if summary_start == 0 {
        return Ok(());
    }
    let size = footer_start
        .checked_sub(summary_start)
        .and_then(|size| usize::try_from(size).ok())
        .filter(|&size| size <= limit)
        .ok_or(McapError::BadFooter)?;
    file.seek(SeekFrom::Start(summary_start))?;
    let mut section = vec![0u8; size];
    file.read_exact(&mut section)?;
    let mut records = ChunkRecords::new(section);
    while let Some(record) = records.next_record() {
        let (opcode, range) = record?;
        check_lengths(opcode, records.body(range))?;
    }
    Ok(())
}

/// The uncompressed records of a chunk, with its CRC checked (when the writer stored one).
pub(crate) fn decompress_chunk(
    header: &ChunkHeader,
    compressed: Cow<'_, [u8]>,
    limit: usize,
) -> Result<Vec<u8>, McapError> {
    let size = usize::try_from(header.uncompressed_size)
        .ok()
        .filter(|&size| size <= limit)
        .ok_or(McapError::ChunkTooLarge(header.uncompressed_size))?;
    let data = match header.compression.as_str() {
        "" => compressed.into_owned(),
        "zstd" => zstd::bulk::decompress(&compressed, size)
            .map_err(|e| McapError::DecompressionError(e.to_string()))?,
        "lz4" => {
            let mut out = Vec::with_capacity(size);
            lz4::Decoder::new(&*compressed)?
                .take(size as u64 + 1)
                .read_to_end(&mut out)
                .map_err(|e| McapError::DecompressionError(e.to_string()))?;
            out
        }
        other => return Err(McapError::UnsupportedCompression(other.to_string())),
    };
    if data.len() != size {
        return Err(McapError::DecompressionError(format!(
            "chunk holds {} bytes once decompressed, its header says {size}",
            data.len()
        )));
    }
    if header.uncompressed_crc != 0 {
        let calculated = crc32fast::hash(&data);
        if calculated != header.uncompressed_crc {
            return Err(McapError::BadChunkCrc {
                saved: header.uncompressed_crc,
                calculated,
            });
        }
    }
    Ok(data)
}

/// The records inside one decompressed chunk (or a summary section, or a record read alone),
/// in order.
pub(crate) struct ChunkRecords {
    data: Vec<u8>,
    next: usize,
}

impl ChunkRecords {
    pub(crate) fn new(data: Vec<u8>) -> Self {
        Self { data, next: 0 }
    }

    /// The next record's opcode and body range, or an error when its length runs past the
    /// end of the chunk.
    pub(crate) fn next_record(&mut self) -> Option<Result<(u8, Range<usize>), McapError>> {
        let rest = self.data.get(self.next..).filter(|rest| !rest.is_empty())?;
        let Some((head, _)) = rest.split_first_chunk::<OPCODE_LEN_SIZE>() else {
            self.next = self.data.len();
            return Some(Err(McapError::UnexpectedEoc));
        };
        let len = u64::from_le_bytes(head[1..].try_into().unwrap_or_default());
        let start = self.next + OPCODE_LEN_SIZE;
        let end = usize::try_from(len)
            .ok()
            .and_then(|len| start.checked_add(len))
            .filter(|&end| end <= self.data.len());
        let Some(end) = end else {
            self.next = self.data.len();
            return Some(Err(McapError::UnexpectedEoc));
        };
        self.next = end;
        Some(Ok((head[0], start..end)))
    }

    pub(crate) fn body(&self, range: Range<usize>) -> &[u8] {
        &self.data[range]
    }
}

/// A cursor over a record's fields that checks each length against what is left.
struct Fields<'a> {
    bytes: &'a [u8],
}

impl<'a> Fields<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], McapError> {
        if n > self.bytes.len() {
            return Err(McapError::UnexpectedEoc);
        }
        let (head, rest) = self.bytes.split_at(n);
        self.bytes = rest;
        Ok(head)
    }

    fn skip(&mut self, n: usize) -> Result<(), McapError> {
        self.take(n).map(|_| ())
    }

    fn u32(&mut self) -> Result<u32, McapError> {
        let bytes = self.take(4)?;
        Ok(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
    }

    fn string(&mut self) -> Result<(), McapError> {
        let len = self.u32()? as usize;
        self.skip(len)
    }

    /// A map of strings to strings, prefixed by its length in bytes.
    fn string_map(&mut self) -> Result<(), McapError> {
        let len = self.u32()? as usize;
        let mut map = Fields {
            bytes: self.take(len)?,
        };
        while !map.bytes.is_empty() {
            map.string()?;
            map.string()?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
        let mut out = vec![opcode];
        out.extend_from_slice(&(body.len() as u64).to_le_bytes());
        out.extend_from_slice(body);
        out
    }

    fn string(s: &str) -> Vec<u8> {
        let mut out = (s.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(s.as_bytes());
        out
    }

    fn schema_body(name_len_prefix: u32) -> Vec<u8> {
        let mut body = 1u16.to_le_bytes().to_vec();
        body.extend_from_slice(&name_len_prefix.to_le_bytes());
        body.extend_from_slice(b"std_msgs/msg/String");
        body.extend(string("ros2msg"));
        body.extend(string("string data"));
        body
    }

    #[test]
    fn a_well_formed_schema_parses() {
        let body = schema_body(19);
        match parse_checked(op::SCHEMA, &body) {
            Ok(Some(Record::Schema { header, data })) => {
                assert_eq!(header.name, "std_msgs/msg/String");
                assert_eq!(&*data, b"string data");
            }
            other => panic!("unexpected {other:?}"),
        }
    }

    #[test]
    fn a_string_length_past_the_record_is_refused_before_mcap_allocates_it() {
        let body = schema_body(0x6E00_0000);
        assert!(matches!(
            parse_checked(op::SCHEMA, &body),
            Err(McapError::UnexpectedEoc)
        ));
    }

    #[test]
    fn channel_metadata_longer_than_the_record_is_refused() {
        let mut body = vec![1, 0, 1, 0];
        body.extend(string("/scan"));
        body.extend(string("cdr"));
        body.extend_from_slice(&1000u32.to_le_bytes());
        body.extend(string("offered_qos_profiles"));
        assert!(parse_checked(op::CHANNEL, &body).is_err());
    }

    #[test]
    fn every_record_with_strings_is_checked() {
        let huge = 0x7FFF_FFFFu32.to_le_bytes();
        for (opcode, fixed) in [
            (op::HEADER, 0),
            (op::METADATA, 0),
            (op::METADATA_INDEX, 16),
            (op::ATTACHMENT_INDEX, 40),
            (op::ATTACHMENT, 16),
        ] {
            let mut body = vec![0u8; fixed];
            body.extend_from_slice(&huge);
            assert!(check_lengths(opcode, &body).is_err(), "opcode {opcode:#x}");
        }
        let mut chunk_index = vec![0u8; 32];
        chunk_index.extend_from_slice(&0u32.to_le_bytes());
        chunk_index.extend_from_slice(&[0; 8]);
        chunk_index.extend_from_slice(&huge);
        assert!(check_lengths(op::CHUNK_INDEX, &chunk_index).is_err());
    }

    #[test]
    fn a_summary_with_a_corrupt_schema_is_refused_and_a_good_one_passes() {
        let mut file = Vec::new();
        {
            let mut writer = mcap::Writer::new(std::io::Cursor::new(&mut file)).unwrap();
            let schema = writer
                .add_schema("std_msgs/msg/String", "ros2msg", b"string data")
                .unwrap();
            writer
                .add_channel(schema, "/chatter", "cdr", &Default::default())
                .unwrap();
            writer.finish().unwrap();
        }
        let len = file.len() as u64;
        check_summary_section(&mut std::io::Cursor::new(&file), len, 1 << 20).unwrap();
        // Make the summary's copy of the schema name claim 1.8 GB.
        let name = b"std_msgs/msg/String";
        let at = file.windows(name.len()).rposition(|w| w == name).unwrap();
        file[at - 4..at].copy_from_slice(&0x6E00_0000u32.to_le_bytes());
        assert!(check_summary_section(&mut std::io::Cursor::new(&file), len, 1 << 20).is_err());
    }

    #[test]
    fn records_other_than_the_ones_read_are_skipped_unparsed() {
        assert!(matches!(
            parse_checked(op::ATTACHMENT, &[0xFF; 3]),
            Ok(None)
        ));
    }

    #[test]
    fn a_chunk_record_running_past_the_chunk_end_is_an_error_not_an_overflow() {
        let mut data = record(op::MESSAGE, &[0; 22]);
        data.push(op::MESSAGE);
        data.extend_from_slice(&u64::MAX.to_le_bytes());
        let mut records = ChunkRecords::new(data);
        let first = records.next_record().map(|r| r.map(|(opcode, _)| opcode));
        assert!(matches!(first, Some(Ok(op::MESSAGE))));
        assert!(matches!(
            records.next_record(),
            Some(Err(McapError::UnexpectedEoc))
        ));
        assert!(records.next_record().is_none());
    }

    #[test]
    fn a_chunk_whose_size_disagrees_with_its_header_is_refused() {
        let data = record(op::MESSAGE, &[0; 22]);
        let header = ChunkHeader {
            message_start_time: 0,
            message_end_time: 0,
            uncompressed_size: data.len() as u64 + 5,
            uncompressed_crc: 0,
            compression: String::new(),
            compressed_size: data.len() as u64,
        };
        assert!(decompress_chunk(&header, Cow::Borrowed(&data), 1 << 20).is_err());
        let header = ChunkHeader {
            uncompressed_size: data.len() as u64,
            uncompressed_crc: crc32fast::hash(&data) ^ 1,
            ..header
        };
        assert!(matches!(
            decompress_chunk(&header, Cow::Borrowed(&data), 1 << 20),
            Err(McapError::BadChunkCrc { .. })
        ));
    }

    #[test]
    fn zstd_and_lz4_chunks_round_trip() {
        let data = record(op::MESSAGE, &[7; 300]);
        let zstd = zstd::bulk::compress(&data, 3).unwrap();
        let mut lz4 = lz4::EncoderBuilder::new().build(Vec::new()).unwrap();
        std::io::Write::write_all(&mut lz4, &data).unwrap();
        let (lz4, done) = lz4.finish();
        done.unwrap();
        for (compression, compressed) in [("zstd", zstd), ("lz4", lz4)] {
            let header = ChunkHeader {
                message_start_time: 0,
                message_end_time: 0,
                uncompressed_size: data.len() as u64,
                uncompressed_crc: crc32fast::hash(&data),
                compression: compression.into(),
                compressed_size: compressed.len() as u64,
            };
            assert_eq!(
                decompress_chunk(&header, Cow::Borrowed(&compressed), 1 << 20).unwrap(),
                data
            );
            assert!(decompress_chunk(&header, Cow::Borrowed(&compressed), 10).is_err());
        }
    }
}
