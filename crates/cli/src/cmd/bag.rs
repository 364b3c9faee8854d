//! `lidar-har bag`: inspect (`info`) and convert (`convert`) rosbag2 bags, MCAP and sqlite3.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use lidar_har_bag::{
    BagInfo, BagReader, BagWriter, Compression, MetadataVersion, StorageId, WriterOptions,
};
use lidar_har_msgs::RosMessage;
use lidar_har_msgs::visualization_msgs::{Marker, MarkerArray};
use lidar_har_pipeline::bag_run::StopRequest;

#[derive(clap::Subcommand)]
pub enum BagCommand {
    /// Show storage, files, duration, start/end time and topics (type, count, QoS) of a bag,
    /// like `ros2 bag info`.
    Info {
        /// A rosbag2 directory (with metadata.yaml or without) or a bare storage file (.mcap,
        /// .db3, or either compressed by rosbag2, .zstd).
        bag: PathBuf,
    },
    /// Copy every message of a bag into a new bag, changing storage and/or compression.
    Convert {
        /// The bag to read (directory or bare storage file, as for `info`).
        src: PathBuf,
        /// The bag directory to create (must not already hold a bag).
        dst: PathBuf,
        /// Storage of the new bag.
        #[arg(long, default_value = "mcap", value_parser = parse_storage)]
        storage: StorageId,
        /// Chunk compression of the new bag (MCAP only).
        #[arg(long, default_value = "none", value_parser = parse_compression)]
        compression: Compression,
        /// rosbag2 metadata version of the new bag: 9 (read by Jazzy and later) or 8 (read by
        /// Humble, Iron and later; use it for a Humble robot). Default: 8 when the source's
        /// metadata.yaml is version 8 or older (Humble writes 5, Iron 8), else 9.
        #[arg(long, value_parser = parse_metadata_version)]
        rosbag2_version: Option<MetadataVersion>,
    },
}

fn parse_storage(s: &str) -> Result<StorageId, String> {
    s.parse()
}

fn parse_compression(s: &str) -> Result<Compression, String> {
    s.parse()
}

fn parse_metadata_version(s: &str) -> Result<MetadataVersion, String> {
    s.parse()
}

/// The metadata version `convert` writes without `--rosbag2-version`: a source that the
/// distributions before Jazzy read (version 8 or older) stays readable by them.
fn default_metadata_version(source_version: Option<u32>) -> MetadataVersion {
    match source_version {
        Some(version) if version < 9 => MetadataVersion::V8,
        _ => MetadataVersion::default(),
    }
}

/// Runs a bag command; `stop` (a signal) ends a conversion early, its new bag finished.
pub fn run(command: BagCommand, stop: &StopRequest) -> anyhow::Result<()> {
    match command {
        BagCommand::Info { bag } => info(&bag),
        BagCommand::Convert {
            src,
            dst,
            storage,
            compression,
            rosbag2_version,
        } => convert(&src, &dst, storage, compression, rosbag2_version, stop),
    }
}

fn info(path: &Path) -> anyhow::Result<()> {
    let reader =
        BagReader::open(path).with_context(|| format!("cannot open bag {}", path.display()))?;
    let info = reader.metadata();
    let size: u64 = info
        .files
        .iter()
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| m.len())
        .sum();
    let files: Vec<String> = info
        .files
        .iter()
        .map(|f| {
            f.file_name().map_or_else(
                || f.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            )
        })
        .collect();
    outln!("Files:             {}", files.join("\n                   "));
    outln!("Bag size:          {}", human_size(size));
    outln!("Storage id:        {}", info.storage);
    if let Some(version) = info.metadata_version {
        outln!("Metadata version:  {version}");
    }
    if !info.ros_distro.is_empty() {
        outln!("ROS Distro:        {}", info.ros_distro);
    }
    outln!("Duration:          {}", seconds(info.duration_ns()));
    outln!("Start:             {}", timestamp(info.start_ns));
    outln!("End:               {}", timestamp(info.end_ns));
    outln!("Messages:          {}", info.message_count);
    if info.truncated {
        outln!(
            "Warning:           a storage file cannot be read to its end (cut short by a killed recorder, or damaged); counts cover the part before"
        );
    }
    if let Some(note) = missing_metadata_note(path, &info) {
        outln!("Metadata:          {note}");
    }
    let width = reader
        .topics()
        .iter()
        .map(|t| t.name.len())
        .max()
        .unwrap_or(0);
    for (i, topic) in reader.topics().iter().enumerate() {
        let qos: Vec<String> = topic.offered_qos.iter().map(|q| q.describe()).collect();
        outln!(
            "{}Topic: {:width$} | Type: {} | Count: {} | Serialization Format: {} | QoS: {}",
            if i == 0 {
                "Topic information: "
            } else {
                "                   "
            },
            topic.name,
            topic.type_name,
            topic.message_count,
            topic.serialization_format,
            if qos.is_empty() {
                "(none recorded)".to_string()
            } else {
                qos.join(", ")
            },
        );
    }
    Ok(())
}

/// What `info` says of a bag directory without metadata.yaml (a killed recorder leaves
/// none): this reader does without it, but `ros2 bag play` does not.
fn missing_metadata_note(path: &Path, info: &BagInfo) -> Option<String> {
    (path.is_dir() && info.metadata_version.is_none()).then(|| {
        format!(
            "none (metadata.yaml missing; a killed recorder leaves none): `ros2 bag play` needs \
             it; `lidar-har bag convert {0} NEW_DIR` writes a copy with one (or `ros2 bag reindex \
             {0}` writes it in place)",
            path.display()
        )
    })
}

fn convert(
    src: &Path,
    dst: &Path,
    storage: StorageId,
    compression: Compression,
    metadata_version: Option<MetadataVersion>,
    stop: &StopRequest,
) -> anyhow::Result<()> {
    let reader =
        BagReader::open(src).with_context(|| format!("cannot open bag {}", src.display()))?;
    let mut options = WriterOptions {
        storage,
        compression,
        metadata_version: metadata_version
            .unwrap_or_else(|| default_metadata_version(reader.bag_metadata().map(|m| m.version))),
        ..WriterOptions::default()
    };
    if let Some(metadata) = reader.bag_metadata() {
        if !metadata.ros_distro.is_empty() {
            options.ros_distro = metadata.ros_distro.clone();
        }
        options.custom_data = metadata.custom_data.clone().unwrap_or_default();
    }
    // Every topic checked before the new bag is created: a refusal leaves nothing behind.
    let mut topics = Vec::new();
    let mut substituted = std::collections::HashSet::new();
    for topic in reader.topics() {
        let mut topic = topic.clone();
        if topic.schema_text.is_none() {
            // Older sqlite3 bags (Foxy/Humble) store no definitions: use ours where we know the type.
            let Some(definition) = lidar_har_msgs::schema::definition(&topic.type_name) else {
                bail!(
                    "{}: topic `{}` ({}) has no stored message definition and the type is unknown to lidar-har",
                    src.display(),
                    topic.name,
                    topic.type_name
                );
            };
            topic.schema_text = Some(definition.schema_text());
            substituted.insert(topic.name.clone());
        }
        topics.push(topic);
    }
    check_messages_decode(&reader, &substituted, src)?;
    // From here a stop is honoured at the first message, the new bag finished.
    stop.arm();
    let mut writer = BagWriter::create(dst, options)
        .with_context(|| format!("cannot create bag {}", dst.display()))?;
    let mut handles = std::collections::HashMap::new();
    for topic in &topics {
        let handle = writer
            .add_topic_like(topic)
            .with_context(|| format!("cannot add topic {}", topic.name))?;
        handles.insert(topic.name.clone(), handle);
    }
    let (mut count, mut negative_times) = (0u64, 0u64);
    let mut stopped = None;
    for message in reader.messages()? {
        // Before the message: what stops the copy (a signal) may also have made it unreadable.
        if let Some(reason) = stop.reason() {
            stopped = Some(reason.to_string());
            break;
        }
        let message = match message {
            Ok(message) => message,
            Err(e) => {
                stopped = Some(e.to_string());
                break;
            }
        };
        let Some(&handle) = handles.get(&*message.topic) else {
            bail!(
                "{}: message on unlisted topic `{}`",
                src.display(),
                message.topic
            );
        };
        // A damaged sqlite3 row can hold one; it sorts first, and stopping at it would leave
        // the new bag empty.
        if message.log_time_ns < 0 {
            negative_times += 1;
            continue;
        }
        writer.write(handle, message.log_time_ns, &message.data)?;
        count += 1;
    }
    let summary = writer.finish()?;
    if let Some(why) = stopped {
        // What was copied is kept, and said to be all there is: converting a bag cut short
        // is how its complete messages are salvaged.
        bail!(
            "reading {} stopped after {count} messages: {why}; {} holds those {count} messages \
             and no more",
            src.display(),
            dst.display()
        );
    }
    if negative_times > 0 {
        errln!(
            "lidar-har: warning: {}: {negative_times} messages with a negative log time left out",
            src.display()
        );
    }
    outln!(
        "Converted {count} messages on {} topics: {} ({}) -> {} ({storage}, metadata version {})",
        handles.len(),
        src.display(),
        reader.storage(),
        summary.dir.display(),
        summary.metadata.version
    );
    Ok(())
}

/// The mirrored types whose layout has changed since Foxy and Galactic: their Marker lacks
/// the texture and mesh fields (docs/msgs.md); every other type is the same in all of them.
const TYPES_CHANGED_SINCE_FOXY: [&str; 2] = [Marker::TYPE_NAME, MarkerArray::TYPE_NAME];

/// Decodes `data` as one of [`TYPES_CHANGED_SINCE_FOXY`], `type_name`.
fn decode_changed_type(type_name: &str, data: &[u8]) -> Result<(), lidar_har_msgs::CdrError> {
    if type_name == Marker::TYPE_NAME {
        lidar_har_msgs::decode::<Marker>(data).map(drop)
    } else {
        lidar_har_msgs::decode::<MarkerArray>(data).map(drop)
    }
}

/// Checks that the messages of `topics`, given lidar-har's definition of their type for want
/// of a stored one, are of that layout, where the type has had another: written under a
/// definition they are not of, no reader could decode them. A topic most of whose messages
/// do not decode is of the other layout; a few that do not are damaged, which the copy keeps
/// as they are, as it keeps those of every other type.
fn check_messages_decode(
    reader: &BagReader,
    topics: &std::collections::HashSet<String>,
    src: &Path,
) -> anyhow::Result<()> {
    let changed: Vec<&str> = reader
        .topics()
        .iter()
        .filter(|t| topics.contains(&t.name) && TYPES_CHANGED_SINCE_FOXY.contains(&&*t.type_name))
        .map(|t| t.name.as_str())
        .collect();
    if changed.is_empty() {
        return Ok(());
    }
    // Per topic: messages that decode, messages that do not, and the first error.
    let mut tally: std::collections::HashMap<&str, (u64, u64, Option<String>)> =
        std::collections::HashMap::new();
    for message in reader.messages_on(&changed)? {
        let Ok(message) = message else { break };
        let Some(topic) = reader.topic(&message.topic) else {
            continue;
        };
        let entry = tally.entry(topic.name.as_str()).or_default();
        match decode_changed_type(&topic.type_name, &message.data) {
            Err(e) => {
                entry.1 += 1;
                entry.2.get_or_insert_with(|| e.to_string());
            }
            Ok(()) => entry.0 += 1,
        }
    }
    for (topic, (decoded, failed, error)) in tally {
        if failed > decoded {
            let type_name = reader.topic(topic).map_or("", |t| t.type_name.as_str());
            bail!(
                "{}: topic `{topic}` ({type_name}) has no stored message definition, and {failed} \
                 of its {} messages do not decode with lidar-har's, which is ROS 2 Humble's and \
                 later's ({}): Foxy's and Galactic's lack fields Humble's has, and cannot be \
                 converted",
                src.display(),
                decoded + failed,
                error.unwrap_or_default(),
            );
        }
    }
    Ok(())
}

fn human_size(bytes: u64) -> String {
    const UNITS: [&str; 4] = ["B", "KiB", "MiB", "GiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    format!("{value:.1} {}", UNITS[unit])
}

fn seconds(ns: i64) -> String {
    format!(
        "{}.{:09}s",
        ns.div_euclid(1_000_000_000),
        ns.rem_euclid(1_000_000_000)
    )
}

/// `YYYY-MM-DD hh:mm:ss.nnnnnnnnn UTC (seconds.nanoseconds)`.
fn timestamp(ns: i64) -> String {
    let secs = ns.div_euclid(1_000_000_000);
    let nanos = ns.rem_euclid(1_000_000_000);
    let days = secs.div_euclid(86_400);
    let of_day = secs.rem_euclid(86_400);
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02}.{nanos:09} UTC ({secs}.{nanos:09})",
        of_day / 3600,
        of_day % 3600 / 60,
        of_day % 60
    )
}

/// Proleptic Gregorian date of a day count since 1970-01-01 (Howard Hinnant's algorithm).
fn civil_from_days(days: i64) -> (i64, i64, i64) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_times() {
        assert_eq!(
            timestamp(0),
            "1970-01-01 00:00:00.000000000 UTC (0.000000000)"
        );
        assert!(timestamp(1_403_201_183_687_882_605).starts_with("2014-06-19 18:06:23.687882605"));
        assert_eq!(seconds(125_989_004_529), "125.989004529s");
        assert_eq!(human_size(2048), "2.0 KiB");
    }

    /// A Humble (5) or Iron (8) source converted without `--rosbag2-version` stays readable
    /// by them: it used to become version 9, which their `ros2 bag info` cannot parse.
    #[test]
    fn converting_a_bag_older_than_jazzy_keeps_a_version_they_read() {
        assert_eq!(default_metadata_version(Some(5)), MetadataVersion::V8);
        assert_eq!(default_metadata_version(Some(8)), MetadataVersion::V8);
        assert_eq!(default_metadata_version(Some(9)), MetadataVersion::V9);
        assert_eq!(default_metadata_version(None), MetadataVersion::V9);
        assert!(
            parse_metadata_version("5")
                .unwrap_err()
                .contains("expected 8, read by Humble")
        );
    }

    /// `info` on a directory without metadata.yaml said nothing of it, and `ros2 bag play`
    /// then refused the bag that looked fine.
    #[test]
    fn info_says_a_directory_without_metadata_yaml_needs_one_to_play() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("rec");
        let mut writer = BagWriter::create(&dir, WriterOptions::default()).unwrap();
        writer
            .add_topic_for::<Marker>("/m", lidar_har_msgs::qos::QosProfile::reliable(1))
            .unwrap();
        writer.finish().unwrap();
        let with = BagReader::open(&dir).unwrap();
        assert_eq!(missing_metadata_note(&dir, &with.metadata()), None);
        std::fs::remove_file(dir.join("metadata.yaml")).unwrap();
        let without = BagReader::open(&dir).unwrap();
        let note = missing_metadata_note(&dir, &without.metadata()).unwrap();
        assert!(
            note.contains("`ros2 bag play` needs it")
                && note.contains(&format!("lidar-har bag convert {}", dir.display()))
                && note.contains("ros2 bag reindex"),
            "{note}"
        );
        let bare_file = dir.join("rec_0.mcap");
        let bare = BagReader::open(&bare_file).unwrap();
        assert_eq!(missing_metadata_note(&bare_file, &bare.metadata()), None);
    }
}
