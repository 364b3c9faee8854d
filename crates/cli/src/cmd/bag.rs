//! `lidar-har bag`: inspect (`info`) and convert (`convert`) rosbag2 bags, MCAP and sqlite3.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use lidar_har_bag::{
    BagInfo, BagReader, BagWriter, Compression, MessageFilter, MetadataVersion, RecordedVersion,
    StorageId, TopicInfo, WriterOptions,
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
    /// Copy the messages of a bag into a new bag, changing storage and/or compression; with
    /// --start-offset, --duration or --topics, only a clip of it.
    ///
    /// The new bag lists every topic of the source (or of --topics), also one none of whose
    /// messages falls in the clip, as rosbag2's convert does; a warning names those: a /map or
    /// /tf_static recorded once, at the start, is not in a clip that starts later.
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
        /// Humble, Iron and later; use it for a Humble robot). Default: 8 when the source was
        /// written before Jazzy (metadata.yaml version 8 or older: Humble writes 5, Iron 8; or,
        /// without metadata.yaml, what its storage files record), else 9.
        #[arg(long, value_parser = super::parse_metadata_version)]
        rosbag2_version: Option<MetadataVersion>,
        /// Copy from this many seconds into the source, counted from its first message, as
        /// `ros2 bag play --start-offset` plays (at most the source's length).
        #[arg(
            long = "start-offset",
            value_name = "SECONDS",
            default_value = "0",
            allow_negative_numbers = true,
            value_parser = parse_seconds
        )]
        start_offset_ns: i64,
        /// Copy this many seconds from the start offset (default: to the end of the source);
        /// a message logged exactly at its end is left out.
        #[arg(
            long = "duration",
            value_name = "SECONDS",
            allow_negative_numbers = true,
            value_parser = parse_duration
        )]
        duration_ns: Option<i64>,
        /// Copy only these topics (default: all); the new bag lists only them. The list takes
        /// every word after it: give it after SRC and DST.
        #[arg(long, num_args = 1.., value_name = "TOPIC")]
        topics: Vec<String>,
    },
}

/// The part of the source `convert` copies.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
struct Clip {
    /// From the source's first message.
    start_offset_ns: i64,
    /// `None`: to the source's end.
    duration_ns: Option<i64>,
    /// Empty: every topic.
    topics: Vec<String>,
}

impl Clip {
    /// Whether a time range is cut (not the whole length of the source).
    fn is_time_bounded(&self) -> bool {
        self.start_offset_ns > 0 || self.duration_ns.is_some()
    }

    /// Where the messages of a topic that the clip leaves out all lie.
    fn outside(&self) -> &'static str {
        match (self.start_offset_ns > 0, self.duration_ns.is_some()) {
            (true, false) => "their only messages are before --start-offset",
            (false, true) => "their only messages are after --duration",
            _ => "their only messages are before --start-offset or after --duration",
        }
    }
}

/// `--start-offset`/`--duration`: a finite number of seconds >= 0, in nanoseconds (the
/// conversion saturates, at 292 years).
fn parse_seconds(s: &str) -> Result<i64, String> {
    let seconds: f64 = s
        .trim()
        .parse()
        .map_err(|_| "not a number of seconds".to_string())?;
    if !(seconds.is_finite() && seconds >= 0.0) {
        return Err("must be a finite number of seconds, 0 or more".to_string());
    }
    Ok((seconds * 1e9).round() as i64)
}

/// `--duration`: as [`parse_seconds`], but more than 0: a clip of no time would be empty, as
/// the `replay` node refuses `playback_duration:=0`.
fn parse_duration(s: &str) -> Result<i64, String> {
    match parse_seconds(s)? {
        0 => Err("must be more than 0 seconds: the clip would be empty".to_string()),
        ns => Ok(ns),
    }
}

fn parse_storage(s: &str) -> Result<StorageId, String> {
    s.parse()
}

fn parse_compression(s: &str) -> Result<Compression, String> {
    s.parse()
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
            start_offset_ns,
            duration_ns,
            topics,
        } => {
            let clip = Clip {
                start_offset_ns,
                duration_ns,
                topics,
            };
            convert(
                &src,
                &dst,
                storage,
                compression,
                rosbag2_version,
                &clip,
                stop,
            )
        }
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
    if let Some(line) = recorded_version_line(reader.recorded_version().as_ref()) {
        outln!("{line}");
    }
    if !info.ros_distro.is_empty() {
        outln!("ROS Distro:        {}", info.ros_distro);
    }
    outln!("Duration:          {}", seconds(info.duration_ns()));
    outln!("Start:             {}", timestamp(info.start_ns));
    outln!("End:               {}", timestamp(info.end_ns));
    outln!("Messages:          {}", info.message_count);
    for warning in damage_warnings(&info) {
        outln!("Warning:           {warning}");
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

/// `info`'s warning for each storage file that cannot be read to its end, naming it and why:
/// in a bag of many split files, the one to repair.
fn damage_warnings(info: &BagInfo) -> Vec<String> {
    info.damaged
        .iter()
        .map(|why| {
            format!(
                "a storage file cannot be read to its end (cut short by a killed recorder, or \
                 damaged); counts cover the part before: {why}"
            )
        })
        .collect()
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

/// The `info` line of the metadata version (or, where none is recorded, the distribution) the
/// bag records: without metadata.yaml, what its storage files say, which `convert` and `run`
/// follow.
fn recorded_version_line(recorded: Option<&RecordedVersion>) -> Option<String> {
    match recorded? {
        RecordedVersion::MetadataYaml(version) => Some(format!("Metadata version:  {version}")),
        RecordedVersion::StorageFile(version) => Some(format!(
            "Metadata version:  {version} (from the storage file)"
        )),
        RecordedVersion::Distribution(distro) => Some(format!(
            "ROS Distro:        {distro} (from the storage file)"
        )),
        RecordedVersion::SqliteLayoutBeforeJazzy => None,
    }
}

fn convert(
    src: &Path,
    dst: &Path,
    storage: StorageId,
    compression: Compression,
    metadata_version: Option<MetadataVersion>,
    clip: &Clip,
    stop: &StopRequest,
) -> anyhow::Result<()> {
    let reader =
        BagReader::open(src).with_context(|| format!("cannot open bag {}", src.display()))?;
    let filter = clip_filter(&reader, clip, src)?;
    let mut options = WriterOptions {
        storage,
        compression,
        metadata_version: metadata_version
            .unwrap_or_else(|| MetadataVersion::like_source(reader.recorded_version().as_ref())),
        ..WriterOptions::default()
    };
    if let Some(metadata) = reader.bag_metadata() {
        // The source's label is kept where it names a distribution of the format written (a
        // Humble recording kept at 8); else the format's own names it (asked for 9: jazzy).
        let source = RecordedVersion::Distribution(metadata.ros_distro.clone());
        if !metadata.ros_distro.is_empty()
            && MetadataVersion::like_source(Some(&source)) == options.metadata_version
        {
            options.ros_distro = Some(metadata.ros_distro.clone());
        }
        options.custom_data = metadata.custom_data.clone().unwrap_or_default();
    }
    // Every topic checked before the new bag is created: a refusal leaves nothing behind.
    let mut topics = Vec::new();
    let mut substituted = std::collections::HashSet::new();
    let mut warnings = Vec::new();
    for topic in reader.topics() {
        if !clip.topics.is_empty() && !clip.topics.contains(&topic.name) {
            continue;
        }
        BagWriter::check_topic(&topic.name, &topic.type_name)
            .map_err(|problem| anyhow::anyhow!("{}: {problem}", src.display()))?;
        // Copied as recorded, as rosbag2's convert copies it (a ROS 1 name such as
        // `/front-scan` that rosbags-convert kept, say), but said.
        if let Err(problem) = lidar_har_bag::validate_topic_name(&topic.name) {
            warnings.push(format!(
                "{}: {problem}; copied as recorded, but `ros2 bag play` cannot publish it \
                 (leave it out with --topics)",
                src.display()
            ));
        }
        let mut topic = topic.clone();
        if topic.ros2msg_schema().is_none() {
            // Older sqlite3 bags (Foxy/Humble) store no definitions, and rosbag2 stores an
            // empty one for a type whose package the recorder lacked: ours where we know the
            // type; else the topic is copied with what is stored, as rosbag2's convert does.
            if let Some(definition) = lidar_har_msgs::schema::definition(&topic.type_name) {
                topic.schema_text = Some(definition.schema_text());
                topic.schema_encoding = "ros2msg".to_string();
                substituted.insert(topic.name.clone());
            } else {
                warnings.push(no_ros2msg_warning(&topic, src));
            }
        }
        // A source that records no type hash (Humble's, or one of ours made before we wrote
        // them) gets ours where the type and its fields are ours; a recorded one is kept.
        if topic.type_description_hash.is_empty()
            && let Some(schema) = topic.ros2msg_schema()
            && let Some(hash) = lidar_har_msgs::schema::type_hash_of(&topic.type_name, schema)
        {
            topic.type_description_hash = hash.to_string();
        }
        topics.push(topic);
    }
    check_messages_decode(&reader, &substituted, src)?;
    for warning in warnings {
        errln!("lidar-har: warning: {warning}");
    }
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
    let mut copied_on: std::collections::HashMap<String, u64> = std::collections::HashMap::new();
    let mut stopped = None;
    for message in reader.messages_matching(&filter)? {
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
        writer.write_sent_at(
            handle,
            message.log_time_ns,
            message.publish_time_ns,
            &message.data,
        )?;
        count += 1;
        *copied_on.entry(message.topic.to_string()).or_default() += 1;
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
    if let Some(warning) = clip_warning(&topics, &copied_on, clip) {
        errln!("lidar-har: warning: {warning}");
    }
    let length_ns = reader.metadata().duration_ns();
    let part = if clip.is_time_bounded() {
        let end_ns = clip.duration_ns.map_or(length_ns, |d| {
            clip.start_offset_ns.saturating_add(d).min(length_ns)
        });
        format!(
            ", {:.3} s to {:.3} s of the source's {:.3} s",
            clip.start_offset_ns as f64 / 1e9,
            end_ns as f64 / 1e9,
            length_ns as f64 / 1e9
        )
    } else {
        String::new()
    };
    outln!(
        "Converted {count} messages on {} topics: {} ({}) -> {} ({storage}, metadata version \
         {}){part}",
        handles.len(),
        src.display(),
        reader.storage(),
        summary.dir.display(),
        summary.metadata.version
    );
    Ok(())
}

/// The warning for a topic copied without a `ros2msg` definition (a type lidar-har does not
/// know): the copy is right, but tools that decode by the stored definition cannot decode it.
fn no_ros2msg_warning(topic: &TopicInfo, src: &Path) -> String {
    let stored = if topic.schema_text.is_some() {
        format!("only an `{}` one", topic.schema_encoding)
    } else {
        "none".to_string()
    };
    format!(
        "{}: topic `{}` ({}) has no ros2msg message definition (the bag stores {stored}), and \
         the type is not one lidar-har knows: copied with the definition as stored, as rosbag2's \
         convert does; rosbags and Foxglove need the type's definition from elsewhere to decode it",
        src.display(),
        topic.name,
        topic.type_name
    )
}

/// The read that gives `clip`'s messages, checked against the source before anything is
/// written: an offset past its end or a topic it lacks is refused, naming what it has.
fn clip_filter(reader: &BagReader, clip: &Clip, src: &Path) -> anyhow::Result<MessageFilter> {
    let mut filter = MessageFilter::new();
    if !clip.topics.is_empty() {
        for name in &clip.topics {
            if reader.topic(name).is_none() {
                let in_bag: Vec<&str> = reader.topics().iter().map(|t| t.name.as_str()).collect();
                bail!(
                    "--topics: `{name}` is not in the bag {}, which has {}",
                    src.display(),
                    if in_bag.is_empty() {
                        "no topic".to_string()
                    } else {
                        in_bag.join(", ")
                    }
                );
            }
        }
        filter = filter.topics(&clip.topics);
    }
    let info = reader.metadata();
    if clip.start_offset_ns > info.duration_ns() {
        bail!(
            "--start-offset {} s is past the end of the bag {}, which is {:.3} s long: the clip \
             would be empty",
            clip.start_offset_ns as f64 / 1e9,
            src.display(),
            info.duration_ns() as f64 / 1e9
        );
    }
    // No bound where the clip sets none, so that a whole copy reads what it always read (a
    // damaged sqlite3 row with a negative log time included, then left out with a warning).
    let start_ns = info.start_ns.saturating_add(clip.start_offset_ns);
    if clip.start_offset_ns > 0 {
        filter = filter.starting_at(start_ns);
    }
    if let Some(end_ns) = clip.duration_ns.and_then(|d| start_ns.checked_add(d)) {
        filter = filter.ending_before(end_ns);
    }
    Ok(filter)
}

/// Names the topics of `topics` that have messages in the source but none in a clip cut in
/// time (`copied_on`: messages copied per topic): a map or static transforms recorded once,
/// at the start of a recording, are left out of a clip that starts later.
fn clip_warning(
    topics: &[TopicInfo],
    copied_on: &std::collections::HashMap<String, u64>,
    clip: &Clip,
) -> Option<String> {
    if !clip.is_time_bounded() {
        return None;
    }
    let mut left_out: Vec<&str> = topics
        .iter()
        .filter(|t| t.message_count > 0 && !copied_on.contains_key(&t.name))
        .map(|t| t.name.as_str())
        .collect();
    if left_out.is_empty() {
        return None;
    }
    left_out.sort_unstable();
    Some(format!(
        "{}: no message in the clip ({}); the new bag lists them without messages",
        left_out.join(", "),
        clip.outside()
    ))
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
    use lidar_har_msgs::nav_msgs::{OccupancyGrid, Odometry};
    use lidar_har_msgs::qos::QosProfile;
    use lidar_har_msgs::sensor_msgs::LaserScan;
    use lidar_har_msgs::tf2_msgs::TFMessage;

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

    /// `lidar-har bag ...` as the binary parses it.
    #[derive(clap::Parser)]
    struct Cli {
        #[command(subcommand)]
        bag: BagCommand,
    }

    /// Runs `lidar-har bag convert SRC DST ARGS...` as the command line would.
    fn convert_with(src: &Path, dst: &Path, args: &[&str]) -> anyhow::Result<()> {
        use clap::Parser;
        let mut line = vec![
            "bag",
            "convert",
            src.to_str().unwrap(),
            dst.to_str().unwrap(),
        ];
        line.extend_from_slice(args);
        let cli = Cli::try_parse_from(line).map_err(|e| anyhow::anyhow!("{e}"))?;
        run(cli.bag, &StopRequest::default())
    }

    /// Start of [`recording`].
    const T0: i64 = 1_700_000_000_000_000_000;

    /// A 9.9 s recording shaped like a robot's: /map and /tf_static once at its start (as
    /// map_server and robot_state_publisher latch them), /scan at 10 Hz from the start, /odom
    /// at 5 Hz from 0.05 s. Each message's bytes say its topic and time.
    fn recording(dir: &Path, storage: StorageId) {
        let options = WriterOptions {
            storage,
            ..WriterOptions::default()
        };
        let mut writer = BagWriter::create(dir, options).unwrap();
        let map = writer
            .add_topic_for::<OccupancyGrid>("/map", QosProfile::latched(1))
            .unwrap();
        let tf_static = writer
            .add_topic_for::<TFMessage>("/tf_static", QosProfile::latched(1))
            .unwrap();
        let scan = writer
            .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
            .unwrap();
        let odom = writer
            .add_topic_for::<Odometry>("/odom", QosProfile::reliable(10))
            .unwrap();
        let mut write = |handle, name: &str, t: i64| {
            let data = format!("\0\u{1}\0\0{name}@{t}");
            writer.write(handle, t, data.as_bytes()).unwrap();
        };
        write(map, "/map", T0);
        write(tf_static, "/tf_static", T0);
        for k in 0..100 {
            write(scan, "/scan", T0 + k * 100_000_000);
            if k % 2 == 0 {
                write(odom, "/odom", T0 + 50_000_000 + k * 100_000_000);
            }
        }
        writer.finish().unwrap();
    }

    /// Every message of `bag`: topic, log time, bytes.
    fn messages_of(bag: &Path) -> Vec<(String, i64, Vec<u8>)> {
        let reader = BagReader::open(bag).unwrap();
        reader
            .messages()
            .unwrap()
            .map(|m| {
                let m = m.unwrap();
                (m.topic.to_string(), m.log_time_ns, m.data)
            })
            .collect()
    }

    /// A Humble recording converted to version 9 used to keep its `humble` label, naming a
    /// distribution that writes another format; kept at 8 it keeps it.
    #[test]
    fn a_converted_bag_keeps_its_label_only_where_it_names_the_format_written() {
        let tmp = tempfile::tempdir().unwrap();
        let src = tmp.path().join("humble");
        let options = WriterOptions {
            metadata_version: MetadataVersion::V8,
            ros_distro: Some("humble".into()),
            ..WriterOptions::default()
        };
        BagWriter::create(&src, options).unwrap().finish().unwrap();
        for (n, (args, expected)) in [
            (&[][..], "humble"),
            (&["--rosbag2-version", "8"][..], "humble"),
            (&["--rosbag2-version", "9"][..], "jazzy"),
        ]
        .into_iter()
        .enumerate()
        {
            let dst = tmp.path().join(format!("out{n}"));
            convert_with(&src, &dst, args).unwrap();
            let label = BagReader::open(&dst).unwrap().metadata().ros_distro;
            assert_eq!(label, expected, "{args:?}");
        }
    }

    /// `bag convert` could only copy a whole bag: a minute of a long recording meant copying
    /// all of it, then cutting it with another tool.
    #[test]
    fn a_clip_holds_exactly_the_messages_of_its_range_in_both_storages() {
        for storage in [StorageId::Mcap, StorageId::Sqlite3] {
            let tmp = tempfile::tempdir().unwrap();
            let src = tmp.path().join("rec");
            recording(&src, storage);
            let every = messages_of(&src);
            for (args, start_s, end_s) in [
                // Bounds on messages: /scan at 2.0 s is in, /scan at 5.0 s is out.
                (
                    &["--start-offset", "2", "--duration", "3"][..],
                    2.0,
                    Some(5.0),
                ),
                (&["--start-offset", "2.05"][..], 2.05, None),
                (&["--duration", "0.05"][..], 0.0, Some(0.05)),
                // Up to the source's length: its last message only.
                (&["--start-offset", "9.9"][..], 9.9, None),
            ] {
                let dst = tmp.path().join(format!("clip_{start_s}_{end_s:?}"));
                let storage_arg = storage.to_string();
                let args = [args, &["--storage", &storage_arg]].concat();
                convert_with(&src, &dst, &args).unwrap();
                let start = T0 + (start_s * 1e9_f64).round() as i64;
                let end = end_s.map_or(i64::MAX, |e: f64| T0 + (e * 1e9).round() as i64);
                let expected: Vec<_> = every
                    .iter()
                    .filter(|(_, t, _)| (start..end).contains(t))
                    .cloned()
                    .collect();
                assert_eq!(messages_of(&dst), expected, "{storage} {args:?}");
                let clip = BagReader::open(&dst).unwrap();
                assert_eq!(clip.storage(), storage);
                // As rosbag2's rewrite does: every topic of the source, with its QoS, also
                // those the range leaves without a message.
                let source = BagReader::open(&src).unwrap();
                for topic in source.topics() {
                    let copy = clip.topic(&topic.name).unwrap();
                    assert_eq!(copy.offered_qos, topic.offered_qos, "{}", topic.name);
                    let in_range = expected.iter().filter(|m| m.0 == topic.name).count();
                    assert_eq!(copy.message_count, in_range as u64, "{}", topic.name);
                }
            }
        }
    }

    /// A clip starting after the one /map and /tf_static message has neither, which
    /// `lidar-har run` over it needs (--map or a learned background instead); nothing said so.
    #[test]
    fn a_clip_that_leaves_a_topic_without_messages_names_it() {
        let tmp = tempfile::tempdir().unwrap();
        let src = tmp.path().join("rec");
        recording(&src, StorageId::Mcap);
        let source = BagReader::open(&src).unwrap();
        let warning_for = |args: &[&str], clip: &Clip| {
            let dst = tmp.path().join(format!("clip{}", args.join("_")));
            convert_with(&src, &dst, args).unwrap();
            let copied_on = BagReader::open(&dst)
                .unwrap()
                .topics()
                .iter()
                .filter(|t| t.message_count > 0)
                .map(|t| (t.name.clone(), t.message_count))
                .collect();
            clip_warning(source.topics(), &copied_on, clip)
        };
        let late = Clip {
            start_offset_ns: 1_000_000_000,
            ..Clip::default()
        };
        assert_eq!(
            warning_for(&["--start-offset", "1"], &late).as_deref(),
            Some(
                "/map, /tf_static: no message in the clip (their only messages are before \
                 --start-offset); the new bag lists them without messages"
            )
        );
        let short = Clip {
            duration_ns: Some(50_000_000),
            ..Clip::default()
        };
        let warning = warning_for(&["--duration", "0.05"], &short).unwrap();
        assert!(
            warning.starts_with("/odom: no message in the clip (their only messages are after"),
            "{warning}"
        );
        let whole = Clip::default();
        assert_eq!(warning_for(&[], &whole), None);
        let both = Clip {
            start_offset_ns: 2_000_000_000,
            duration_ns: Some(1_000_000_000),
            ..Clip::default()
        };
        assert!(
            warning_for(&["--start-offset", "2", "--duration", "1"], &both)
                .unwrap()
                .contains("before --start-offset or after --duration")
        );
    }

    #[test]
    fn topics_selects_the_topics_of_the_clip_and_refuses_one_the_bag_lacks() {
        let tmp = tempfile::tempdir().unwrap();
        let src = tmp.path().join("rec");
        recording(&src, StorageId::Sqlite3);
        let dst = tmp.path().join("scans");
        convert_with(
            &src,
            &dst,
            &["--duration", "1", "--topics", "/scan", "/odom"],
        )
        .unwrap();
        let clip = BagReader::open(&dst).unwrap();
        let names: Vec<&str> = clip.topics().iter().map(|t| t.name.as_str()).collect();
        assert_eq!(names.len(), 2, "{names:?}");
        assert_eq!(clip.topic("/scan").unwrap().message_count, 10);
        assert_eq!(clip.topic("/odom").unwrap().message_count, 5);

        let refused = tmp.path().join("refused");
        let err = convert_with(&src, &refused, &["--topics", "/scan", "/laser"])
            .unwrap_err()
            .to_string();
        for needle in [
            "--topics",
            "`/laser`",
            "rec",
            "/map, /tf_static, /scan, /odom",
        ] {
            assert!(err.contains(needle), "{needle} missing from: {err}");
        }
        assert!(
            !refused.exists(),
            "a refused clip created {}",
            refused.display()
        );
    }

    #[test]
    fn a_negative_non_finite_or_empty_time_is_refused_naming_the_option() {
        let tmp = tempfile::tempdir().unwrap();
        let src = tmp.path().join("rec");
        recording(&src, StorageId::Mcap);
        let dst = tmp.path().join("clip");
        for option in ["--start-offset", "--duration"] {
            let attached = format!("{option}=-inf");
            let mut lines: Vec<Vec<&str>> = ["-1", "-0.5", "-1e3", "nan", "inf", "ten", ""]
                .into_iter()
                .map(|value| vec![option, value])
                .collect();
            if option == "--duration" {
                // It wrote an empty bag and succeeded.
                lines.extend([vec![option, "0"], vec![option, "0.0000000001"]]);
            }
            lines.push(vec![&attached]);
            lines.push(vec![option]);
            for line in lines {
                let err = convert_with(&src, &dst, &line).unwrap_err().to_string();
                assert!(
                    err.contains(&format!("'{option} <SECONDS>'")),
                    "{line:?}: {err}"
                );
            }
        }
        assert!(!dst.exists());
        assert_eq!(parse_seconds("1.5"), Ok(1_500_000_000));
        assert_eq!(parse_seconds("0.1"), Ok(100_000_000));
        assert_eq!(parse_seconds("1e300"), Ok(i64::MAX));
    }

    /// A Humble source records no type hash; rosbag2 Iron and later read one per topic.
    /// `bag convert` gives ours where the type and its fields are ours, keeps a recorded one
    /// (even one we would not compute) and leaves an unknown type's empty.
    #[test]
    fn convert_keeps_a_recorded_type_hash_and_gives_ours_where_none_is() {
        let tmp = tempfile::tempdir().unwrap();
        let template = tmp.path().join("template");
        recording(&template, StorageId::Mcap);
        let template = BagReader::open(&template).unwrap();
        let recorded = format!("RIHS01_{}", "ab".repeat(32));
        let src = tmp.path().join("humble");
        let mut writer = BagWriter::create(&src, WriterOptions::default()).unwrap();
        for (name, hash) in [("/scan", ""), ("/odom", recorded.as_str())] {
            let mut topic = template.topic(name).unwrap().clone();
            topic.type_description_hash = hash.to_string();
            writer.add_topic_like(&topic).unwrap();
        }
        writer
            .add_topic(
                "/chatter",
                "std_msgs/msg/String",
                "string data\n",
                QosProfile::reliable(1),
            )
            .unwrap();
        writer.finish().unwrap();
        assert_eq!(
            BagReader::open(&src)
                .unwrap()
                .topic("/scan")
                .unwrap()
                .type_description_hash,
            ""
        );
        for storage in ["mcap", "sqlite3"] {
            let dst = tmp.path().join(storage);
            convert_with(&src, &dst, &["--storage", storage]).unwrap();
            let converted = BagReader::open(&dst).unwrap();
            let hash_of = |name| converted.topic(name).unwrap().type_description_hash.clone();
            assert_eq!(
                hash_of("/scan"),
                LaserScan::DEFINITION.type_hash,
                "{storage}"
            );
            assert_eq!(hash_of("/odom"), recorded, "{storage}");
            assert_eq!(hash_of("/chatter"), "", "{storage}");
        }
    }

    /// Like the `replay` node's `start_offset`: past the end, nothing would be copied.
    #[test]
    fn a_start_offset_past_the_end_is_an_error_naming_it_and_the_bags_length() {
        let tmp = tempfile::tempdir().unwrap();
        let src = tmp.path().join("rec");
        recording(&src, StorageId::Mcap);
        let dst = tmp.path().join("clip");
        let err = convert_with(&src, &dst, &["--start-offset", "20"])
            .unwrap_err()
            .to_string();
        for needle in ["--start-offset 20 s", "rec", "9.900 s long"] {
            assert!(err.contains(needle), "{needle} missing from: {err}");
        }
        assert!(!dst.exists());
        // Just past the last message is past the end too.
        assert!(convert_with(&src, &dst, &["--start-offset", "9.9000001"]).is_err());
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
        assert_eq!(
            recorded_version_line(with.recorded_version().as_ref()).unwrap(),
            "Metadata version:  9"
        );
        std::fs::remove_file(dir.join("metadata.yaml")).unwrap();
        let without = BagReader::open(&dir).unwrap();
        assert_eq!(
            recorded_version_line(without.recorded_version().as_ref()).unwrap(),
            "Metadata version:  9 (from the storage file)"
        );
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

    /// rosbag2 records a type whose package the recorder lacks with an empty definition, and
    /// one defined only in .idl as `ros2idl`; `convert` refused the whole recording for either
    /// (and for a `ros2msg` one with an empty text, after creating DST). Such a topic is now
    /// copied with what is stored, as rosbag2's convert copies it; a type of ours gets ours.
    #[test]
    fn a_topic_without_a_ros2msg_definition_is_copied_as_stored() {
        const IDL: &str = "module acme_msgs { module msg { struct Gadget { string name; }; }; };\n";
        let tmp = tempfile::tempdir().unwrap();
        for storage in [StorageId::Mcap, StorageId::Sqlite3] {
            let src = tmp.path().join(format!("src_{storage}"));
            let options = WriterOptions {
                storage,
                ..WriterOptions::default()
            };
            let mut writer = BagWriter::create(&src, options).unwrap();
            let qos = QosProfile::reliable(10);
            let scan = writer
                .add_topic("/scan", LaserScan::TYPE_NAME, "", qos)
                .unwrap();
            let widget = writer
                .add_topic("/widget", "acme_msgs/msg/Widget", "", qos)
                .unwrap();
            writer.flush().unwrap();
            let mut gadget_topic = BagReader::open(&src)
                .unwrap()
                .topic("/widget")
                .unwrap()
                .clone();
            gadget_topic.name = "/gadget".to_string();
            gadget_topic.type_name = "acme_msgs/msg/Gadget".to_string();
            gadget_topic.schema_encoding = "ros2idl".to_string();
            gadget_topic.schema_text = Some(IDL.to_string());
            let gadget = writer.add_topic_like(&gadget_topic).unwrap();
            for (i, handle) in [scan, widget, gadget].into_iter().enumerate() {
                writer
                    .write(handle, T0 + i as i64, &[0, 1, 0, 0, i as u8])
                    .unwrap();
            }
            writer.finish().unwrap();

            for (i, args) in [&[][..], &["--storage", "sqlite3"], &["--duration", "1"]]
                .into_iter()
                .enumerate()
            {
                let dst = tmp.path().join(format!("dst_{storage}_{i}"));
                convert_with(&src, &dst, args)
                    .unwrap_or_else(|e| panic!("{storage} {args:?}: {e:#}"));
                assert_eq!(messages_of(&dst), messages_of(&src), "{storage} {args:?}");
                let copy = BagReader::open(&dst).unwrap();
                let widget = copy.topic("/widget").unwrap();
                assert_eq!(
                    (
                        widget.schema_encoding.as_str(),
                        widget.schema_text.as_deref()
                    ),
                    ("", None)
                );
                let gadget = copy.topic("/gadget").unwrap();
                assert_eq!(
                    (
                        gadget.schema_encoding.as_str(),
                        gadget.schema_text.as_deref()
                    ),
                    ("ros2idl", Some(IDL))
                );
                assert_eq!(
                    copy.topic("/scan").unwrap().ros2msg_schema(),
                    Some(LaserScan::schema_text().as_str()),
                    "{storage} {args:?}: ours, for a type of ours"
                );
            }
        }
        let widget = BagReader::open(tmp.path().join("src_mcap"))
            .unwrap()
            .topic("/widget")
            .unwrap()
            .clone();
        let warning = no_ros2msg_warning(&widget, Path::new("src"));
        assert!(
            warning.contains("topic `/widget` (acme_msgs/msg/Widget) has no ros2msg message definition (the bag stores none)")
                && warning.contains("as rosbag2's convert does"),
            "{warning}"
        );
    }

    /// A name rcl refuses that another tool recorded (`/front-scan`, kept by rosbags-convert
    /// from a ROS 1 bag) is copied as recorded, as rosbag2's convert copies it; refusing it
    /// refused the whole recording.
    #[test]
    fn a_recorded_topic_name_rcl_refuses_is_copied_as_recorded() {
        let tmp = tempfile::tempdir().unwrap();
        let src = tmp.path().join("src");
        let mut writer = BagWriter::create(&src, WriterOptions::default()).unwrap();
        let scan = writer
            .add_topic_for::<LaserScan>("/scan", QosProfile::reliable(10))
            .unwrap();
        writer.flush().unwrap();
        let mut front = BagReader::open(&src)
            .unwrap()
            .topic("/scan")
            .unwrap()
            .clone();
        front.name = "/front-scan".to_string();
        let front = writer.add_topic_like(&front).unwrap();
        for (i, handle) in [scan, front].into_iter().enumerate() {
            writer.write(handle, T0 + i as i64, &[0, 1, 0, 0]).unwrap();
        }
        writer.finish().unwrap();
        let dst = tmp.path().join("dst");
        convert_with(&src, &dst, &[]).unwrap();
        assert_eq!(messages_of(&dst), messages_of(&src));
        assert!(
            BagReader::open(&dst)
                .unwrap()
                .topic("/front-scan")
                .is_some()
        );
    }

    /// `info` said that "a storage file" was damaged, but not which of a split bag's files nor
    /// why, which `convert` says.
    #[test]
    fn info_names_the_damaged_storage_file_and_why() {
        let tmp = tempfile::tempdir().unwrap();
        let whole = tmp.path().join("whole");
        recording(&whole, StorageId::Mcap);
        let bytes = std::fs::read(whole.join("whole_0.mcap")).unwrap();
        let split = tmp.path().join("split");
        std::fs::create_dir(&split).unwrap();
        std::fs::write(split.join("split_0.mcap"), &bytes).unwrap();
        std::fs::write(split.join("split_1.mcap"), &bytes[..200]).unwrap();
        let info = BagReader::open(&split).unwrap().metadata();
        let warnings = damage_warnings(&info);
        assert!(
            warnings.len() == 1
                && warnings[0].contains("split_1.mcap")
                && warnings[0].contains("truncated")
                && !warnings[0].contains("split_0.mcap"),
            "{warnings:?}"
        );
        assert_eq!(
            damage_warnings(&BagReader::open(&whole).unwrap().metadata()),
            Vec::<String>::new()
        );
    }

    /// rosbag2's MCAP plugin stores the send time as `publish_time`; `convert` wrote the log
    /// time in its place. It is kept into MCAP; sqlite3 has no column for it.
    #[test]
    fn convert_keeps_the_send_time_where_the_storage_has_one() {
        let tmp = tempfile::tempdir().unwrap();
        let src = tmp.path().join("sent");
        let mut writer = BagWriter::create(&src, WriterOptions::default()).unwrap();
        let scan = writer
            .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
            .unwrap();
        for k in 0..5 {
            let t = T0 + k * 100_000_000;
            writer
                .write_sent_at(scan, t, t - 3_000_000, &[0, 1, 0, 0])
                .unwrap();
        }
        writer.finish().unwrap();
        let times = |bag: &Path| -> Vec<(i64, i64)> {
            BagReader::open(bag)
                .unwrap()
                .messages()
                .unwrap()
                .map(|m| m.map(|m| (m.log_time_ns, m.publish_time_ns)).unwrap())
                .collect()
        };
        let sent: Vec<(i64, i64)> = (0..5)
            .map(|k| T0 + k * 100_000_000)
            .map(|t| (t, t - 3_000_000))
            .collect();
        assert_eq!(times(&src), sent);
        convert_with(&src, &tmp.path().join("mcap"), &[]).unwrap();
        assert_eq!(times(&tmp.path().join("mcap")), sent);
        convert_with(&src, &tmp.path().join("db3"), &["--storage", "sqlite3"]).unwrap();
        let received: Vec<(i64, i64)> = sent.iter().map(|&(t, _)| (t, t)).collect();
        assert_eq!(times(&tmp.path().join("db3")), received);
    }
}
