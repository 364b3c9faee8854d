//! Write bags in every storage/compression, read them back: same bytes, same order, metadata
//! that says what was written; and the error cases of reading.

use lidar_har_bag::{BagError, BagReader, BagWriter, Compression, StorageId, WriterOptions};
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::qos::QosProfile;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;

fn scan(i: u32) -> LaserScan {
    let mut ranges: Vec<f32> = (0..360)
        .map(|b| 0.5 + (b as f32 + i as f32) * 0.01)
        .collect();
    ranges[0] = f32::INFINITY;
    ranges[1] = f32::NAN;
    ranges[2] = f32::NEG_INFINITY;
    LaserScan {
        header: Header {
            stamp: Time {
                sec: 100 + i as i32,
                nanosec: 5,
            },
            frame_id: "laser".into(),
        },
        angle_min: -3.0,
        angle_max: 3.0,
        angle_increment: 0.0175,
        time_increment: 0.0,
        scan_time: 0.05,
        range_min: 0.1,
        range_max: 12.0,
        ranges,
        intensities: vec![],
    }
}

fn write_bag(
    dir: &std::path::Path,
    storage: StorageId,
    compression: Compression,
    n: u32,
) -> Vec<Vec<u8>> {
    let options = WriterOptions {
        storage,
        compression,
        chunk_size: 16 * 1024,
        ..WriterOptions::default()
    };
    let mut writer = BagWriter::create(dir, options).unwrap();
    let scan_topic = writer
        .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
        .unwrap();
    let other = writer
        .add_topic(
            "/raw",
            "std_msgs/msg/String",
            "string data\n",
            QosProfile::latched(1),
        )
        .unwrap();
    let mut written = Vec::new();
    for i in 0..n {
        let bytes = lidar_har_msgs::encode(&scan(i)).unwrap();
        writer
            .write(
                scan_topic,
                1_000_000_000 + i64::from(i) * 50_000_000,
                &bytes,
            )
            .unwrap();
        written.push(bytes);
    }
    writer
        .write(
            other,
            1_000_000_001,
            &[0, 1, 0, 0, 3, 0, 0, 0, b'h', b'i', 0],
        )
        .unwrap();
    let summary = writer.finish().unwrap();
    assert_eq!(summary.metadata.message_count, u64::from(n) + 1);
    assert_eq!(
        writer.finish().unwrap().metadata,
        summary.metadata,
        "finish is idempotent"
    );
    written
}

fn check_bag(dir: &std::path::Path, storage: StorageId, written: &[Vec<u8>]) {
    let reader = BagReader::open(dir).unwrap();
    assert_eq!(reader.storage(), storage);
    let info = reader.metadata();
    assert_eq!(info.message_count, written.len() as u64 + 1);
    assert_eq!(info.start_ns, 1_000_000_000);
    assert_eq!(
        info.end_ns,
        1_000_000_000 + (written.len() as i64 - 1) * 50_000_000
    );
    assert!(!info.truncated);
    let scan_topic = reader.topic("/scan").unwrap();
    assert_eq!(scan_topic.type_name, "sensor_msgs/msg/LaserScan");
    assert_eq!(scan_topic.message_count, written.len() as u64);
    assert_eq!(
        scan_topic.offered_qos[0].to_profile(),
        Some(QosProfile::sensor_data())
    );
    assert!(
        scan_topic
            .schema_text
            .as_deref()
            .unwrap()
            .contains("MSG: std_msgs/Header")
    );
    assert_eq!(
        reader.topic("/raw").unwrap().offered_qos[0].to_profile(),
        Some(QosProfile::latched(1))
    );

    let all: Vec<_> = reader
        .messages()
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(all.len(), written.len() + 1);
    assert!(
        all.windows(2).all(|w| w[0].log_time_ns <= w[1].log_time_ns),
        "log-time order"
    );
    assert_eq!(
        &*all[1].topic, "/raw",
        "the /raw message sorts between the first two scans"
    );
    let scans: Vec<_> = reader
        .messages_on(&["/scan"])
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(scans.len(), written.len());
    for (i, (message, bytes)) in scans.iter().zip(written).enumerate() {
        assert_eq!(&message.data, bytes);
        let decoded: LaserScan = reader.decode(message).unwrap();
        let expected = scan(i as u32);
        assert_eq!(decoded.ranges.len(), expected.ranges.len());
        for (a, b) in decoded.ranges.iter().zip(&expected.ranges) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }
}

#[test]
fn round_trip_every_storage_and_compression() {
    let tmp = tempfile::tempdir().unwrap();
    for (storage, compression) in [
        (StorageId::Mcap, Compression::None),
        (StorageId::Mcap, Compression::Zstd),
        (StorageId::Mcap, Compression::Lz4),
        (StorageId::Sqlite3, Compression::None),
    ] {
        let dir = tmp.path().join(format!("bag_{storage}_{compression:?}"));
        let written = write_bag(&dir, storage, compression, 200);
        let ext = if storage == StorageId::Mcap {
            "mcap"
        } else {
            "db3"
        };
        assert!(
            dir.join(format!("bag_{storage}_{compression:?}_0.{ext}"))
                .is_file()
        );
        check_bag(&dir, storage, &written);
    }
}

#[test]
fn bare_mcap_and_directory_without_metadata() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("b");
    let written = write_bag(&dir, StorageId::Mcap, Compression::Zstd, 30);
    let file = dir.join("b_0.mcap");
    let reader = BagReader::open(&file).unwrap();
    assert_eq!(reader.metadata().metadata_version, None);
    assert_eq!(reader.metadata().message_count, 31);
    std::fs::remove_file(dir.join("metadata.yaml")).unwrap();
    let reader = BagReader::open(&dir).unwrap();
    let got: Vec<_> = reader
        .messages_on(&["/scan"])
        .unwrap()
        .map(|m| m.unwrap().data)
        .collect();
    assert_eq!(got, written);
}

#[test]
fn wrong_type_and_wrong_length_are_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("b");
    write_bag(&dir, StorageId::Mcap, Compression::None, 3);
    let reader = BagReader::open(&dir).unwrap();
    let raw = reader
        .messages_on(&["/raw"])
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    let err = reader.decode::<LaserScan>(&raw).unwrap_err();
    assert!(matches!(err, BagError::WrongType { .. }), "{err}");
    let mut scan_msg = reader
        .messages_on(&["/scan"])
        .unwrap()
        .next()
        .unwrap()
        .unwrap();
    scan_msg.data.truncate(scan_msg.data.len() - 7);
    let err = reader.decode::<LaserScan>(&scan_msg).unwrap_err();
    assert!(matches!(err, BagError::Decode { .. }), "{err}");
    assert!(err.to_string().contains("/scan"), "{err}");
    assert!(matches!(
        reader.messages_on(&["/nope"]),
        Err(BagError::UnknownTopic { .. })
    ));
}

#[test]
fn bad_inputs_give_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = BagReader::open(tmp.path().join("missing")).err().unwrap();
    assert!(matches!(missing, BagError::NotFound { .. }), "{missing}");
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let err = BagReader::open(&empty).err().unwrap();
    assert!(err.to_string().contains("no metadata.yaml"), "{err}");
    let text = tmp.path().join("notes.txt");
    std::fs::write(&text, "hello").unwrap();
    let err = BagReader::open(&text).err().unwrap();
    assert!(err.to_string().contains("not an MCAP"), "{err}");

    let dir = tmp.path().join("b");
    write_bag(&dir, StorageId::Mcap, Compression::None, 3);
    let metadata = std::fs::read_to_string(dir.join("metadata.yaml")).unwrap();
    std::fs::write(
        dir.join("metadata.yaml"),
        metadata.replace("storage_identifier: mcap", "storage_identifier: rosbag_v1"),
    )
    .unwrap();
    let err = BagReader::open(&dir).err().unwrap();
    assert!(matches!(err, BagError::UnknownStorage { .. }), "{err}");
    std::fs::write(
        dir.join("metadata.yaml"),
        metadata.replace("message_count:", "message_count: ["),
    )
    .unwrap();
    let err = BagReader::open(&dir).err().unwrap();
    assert!(matches!(err, BagError::Metadata { .. }), "{err}");

    let sq = tmp.path().join("s");
    write_bag(&sq, StorageId::Sqlite3, Compression::None, 3);
    let db = sq.join("s_0.db3");
    let mut bytes = std::fs::read(&db).unwrap();
    for b in bytes.iter_mut().take(100) {
        *b = 0x5a;
    }
    std::fs::write(&db, bytes).unwrap();
    let err = BagReader::open(&sq).err().unwrap();
    assert!(
        matches!(err, BagError::Sqlite { .. }) && err.to_string().contains("s_0.db3"),
        "{err}"
    );
}

#[test]
fn truncated_mcap_yields_complete_messages_then_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("t");
    let written = write_bag(&dir, StorageId::Mcap, Compression::Zstd, 300);
    let file = dir.join("t_0.mcap");
    let bytes = std::fs::read(&file).unwrap();
    for cut in [bytes.len() / 2, bytes.len() - 100, 9, 50] {
        std::fs::write(&file, &bytes[..cut]).unwrap();
        let reader = match BagReader::open(&dir) {
            Ok(reader) => reader,
            Err(e) => panic!("cut at {cut}: {e}"),
        };
        assert!(reader.metadata().truncated, "cut at {cut}");
        let mut got = Vec::new();
        let mut error = None;
        for message in reader.messages().unwrap() {
            match message {
                Ok(m) if &*m.topic == "/scan" => got.push(m.data),
                Ok(_) => {}
                Err(e) => error = Some(e),
            }
        }
        let error = error.expect("truncation reported");
        assert!(matches!(error, BagError::Truncated { .. }), "{error}");
        assert_eq!(
            &written[..got.len()],
            &got[..],
            "cut at {cut}: a prefix, nothing corrupt"
        );
        if cut > bytes.len() / 2 {
            assert!(got.len() > 100, "cut at {cut}: only {} messages", got.len());
        }
    }
}

/// `{:#}` of anyhow: the error, then each `source()`, joined by ": ".
fn chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut next = error.source();
    while let Some(cause) = next {
        text = format!("{text}: {cause}");
        next = cause.source();
    }
    text
}

#[test]
fn a_printed_error_chain_says_the_cause_once() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("t");
    write_bag(&dir, StorageId::Mcap, Compression::None, 30);
    let file = dir.join("t_0.mcap");
    let bytes = std::fs::read(&file).unwrap();
    std::fs::write(&file, &bytes[..bytes.len() / 2]).unwrap();
    let reader = BagReader::open(&dir).unwrap();
    let error = reader.messages().unwrap().find_map(Result::err).unwrap();
    let text = chain(&error);
    assert_eq!(text, error.to_string(), "no cause repeated: {text}");
    assert!(
        text.contains("t_0.mcap") && text.contains("truncated") && text.contains("footer"),
        "{text}"
    );

    std::fs::write(dir.join("metadata.yaml"), b"version: \xff").unwrap();
    let error = BagReader::open(&dir).err().unwrap();
    let text = chain(&error);
    assert!(
        text.contains("metadata.yaml: cannot read: ") && text.matches("UTF-8").count() == 1,
        "{text}"
    );
}

/// A split bag (several storage files, here without metadata.yaml) where one file was cut
/// before its first complete chunk: every message of the good file comes out, then the error.
#[test]
fn a_cut_file_of_a_split_bag_loses_no_message_of_the_others() {
    let tmp = tempfile::tempdir().unwrap();
    let good = tmp.path().join("good");
    let written = write_bag(&good, StorageId::Mcap, Compression::Zstd, 30);
    let good_bytes = std::fs::read(good.join("good_0.mcap")).unwrap();
    let cut_bytes = &good_bytes[..200];
    for (first, second) in [(&good_bytes[..], cut_bytes), (cut_bytes, &good_bytes[..])] {
        let split = tmp.path().join("split");
        let _ = std::fs::remove_dir_all(&split);
        std::fs::create_dir(&split).unwrap();
        std::fs::write(split.join("split_0.mcap"), first).unwrap();
        std::fs::write(split.join("split_1.mcap"), second).unwrap();
        let cut_name = if first.len() == 200 {
            "split_0.mcap"
        } else {
            "split_1.mcap"
        };

        let reader = BagReader::open(&split).unwrap();
        assert!(reader.metadata().truncated);
        // Which file, and why: a bag of many split files needs it to know which to repair.
        let damaged = reader.metadata().damaged;
        assert!(
            damaged.len() == 1 && damaged[0].contains(cut_name) && damaged[0].contains("truncated"),
            "{damaged:?}"
        );
        assert_eq!(reader.metadata().message_count, 31);
        let items: Vec<_> = reader.messages().unwrap().collect();
        assert_eq!(items.len(), 32, "31 messages and one error");
        let scans: Vec<_> = items[..31]
            .iter()
            .map(|m| m.as_ref().unwrap())
            .filter(|m| &*m.topic == "/scan")
            .map(|m| m.data.clone())
            .collect();
        assert_eq!(scans, written);
        let Err(error) = &items[31] else {
            panic!("the last item is the error");
        };
        assert!(
            matches!(
                error,
                BagError::Truncated {
                    messages_read: 0,
                    ..
                }
            ) && error.to_string().contains(cut_name),
            "{error}"
        );
    }
}

/// A valid MCAP whose summary has chunk indexes but no Statistics record (optional in the
/// specification): counts and time span come from reading it.
#[test]
fn an_mcap_without_statistics_has_its_counts_and_time_span() {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("nostats.mcap");
    {
        let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
        let mut writer = mcap::WriteOptions::new()
            .profile("ros2")
            .emit_statistics(false)
            .chunk_size(Some(64))
            .create(file)
            .unwrap();
        let schema = writer
            .add_schema("std_msgs/msg/String", "ros2msg", b"string data")
            .unwrap();
        let chatter = writer
            .add_channel(schema, "/chatter", "cdr", &Default::default())
            .unwrap();
        let other = writer
            .add_channel(schema, "/other", "cdr", &Default::default())
            .unwrap();
        for i in 0..10u64 {
            let channel_id = if i % 3 == 0 { other } else { chatter };
            let header = mcap::records::MessageHeader {
                channel_id,
                sequence: i as u32,
                log_time: 5_000 + i * 7,
                publish_time: 5_000 + i * 7,
            };
            writer
                .write_to_known_channel(&header, &[0, 1, 0, 0, 2, 0, 0, 0, b'x', 0])
                .unwrap();
        }
        writer.finish().unwrap();
    }
    let summary = mcap::Summary::read(&std::fs::read(&path).unwrap())
        .unwrap()
        .unwrap();
    assert!(summary.stats.is_none() && summary.chunk_indexes.len() > 1);
    let reader = BagReader::open(&path).unwrap();
    let info = reader.metadata();
    assert_eq!(info.message_count, 10);
    assert_eq!((info.start_ns, info.end_ns), (5_000, 5_063));
    assert!(!info.truncated);
    assert_eq!(reader.topic("/chatter").unwrap().message_count, 6);
    assert_eq!(reader.topic("/other").unwrap().message_count, 4);
    let times: Vec<_> = reader
        .messages()
        .unwrap()
        .map(|m| m.unwrap().log_time_ns)
        .collect();
    assert_eq!(times, (0..10).map(|i| 5_000 + i * 7).collect::<Vec<_>>());
}

/// metadata.yaml versions 1 to 3 listed storage files with the bag directory's name in front;
/// rosbag2 resolves them from the parent directory (and `rosbags` by file name alone).
#[test]
fn old_metadata_lists_files_with_the_bag_directory_in_front() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("old");
    let written = write_bag(&dir, StorageId::Sqlite3, Compression::None, 5);
    let mut metadata = lidar_har_bag::metadata::BagMetadata::read(&dir).unwrap();
    metadata.version = 3;
    metadata.relative_file_paths = vec!["old/old_0.db3".into()];
    metadata.files.clear();
    metadata.write(&dir).unwrap();
    check_bag(&dir, StorageId::Sqlite3, &written);

    let renamed = tmp.path().join("renamed");
    std::fs::rename(&dir, &renamed).unwrap();
    check_bag(&renamed, StorageId::Sqlite3, &written);

    metadata.version = 4;
    metadata.write(&renamed).unwrap();
    let err = BagReader::open(&renamed).err().unwrap();
    assert!(
        matches!(err, BagError::NotFound { .. }) && err.to_string().contains("old/old_0.db3"),
        "from version 4 on the path is relative to the bag directory: {err}"
    );
}

/// A `finish` that failed leaves an incomplete bag: calling it again (as `Drop` does) must not
/// report success, and nothing more can be written.
#[test]
fn finish_after_a_failed_finish_is_an_error() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("f");
    let mut writer = BagWriter::create(&dir, WriterOptions::default()).unwrap();
    let topic = writer
        .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
        .unwrap();
    writer.write_message(topic, 1, &scan(0)).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let first = writer.finish().unwrap_err();
    assert!(first.to_string().contains("metadata.yaml"), "{first}");
    std::fs::create_dir(&dir).unwrap();
    let second = writer.finish().unwrap_err();
    assert!(second.to_string().contains("failed earlier"), "{second}");
    assert!(writer.write_message(topic, 2, &scan(1)).is_err());
    assert!(writer.flush().is_err());
}

/// A sqlite3 row stamped near the start of time (a damaged bag) beside normal ones: the time
/// span saturates instead of overflowing, and every message is still read.
#[test]
fn a_stamp_at_the_edge_of_time_does_not_overflow_the_time_span() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("b");
    write_bag(&dir, StorageId::Sqlite3, Compression::None, 3);
    let db = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|x| x == "db3"))
        .unwrap();
    let connection = rusqlite::Connection::open(&db).unwrap();
    let changed = connection
        .execute(
            "UPDATE messages SET timestamp = ?1 WHERE id = (SELECT MIN(id) FROM messages)",
            [i64::MIN],
        )
        .unwrap();
    assert_eq!(changed, 1);
    drop(connection);
    let reader = BagReader::open(&dir).unwrap();
    let info = reader.metadata();
    assert_eq!(info.start_ns, i64::MIN);
    assert_eq!(info.duration_ns(), i64::MAX);
    let read = reader.messages().unwrap().filter(|m| m.is_ok()).count() as u64;
    assert_eq!(read, info.message_count);
}
