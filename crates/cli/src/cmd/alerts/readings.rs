//! What the classifier stage gave the fall alerts on every scan of every episode
//! (`lidar-har alerts --save-readings`), replayed with other `fall_alert` settings
//! (`--readings`). Simulating and running the model is nearly all of a run's time; replaying
//! the alert logic over the same readings takes seconds, and gives exactly what a full run
//! with those settings gives.
//!
//! The file is zstd-compressed JSON lines: a [`Header`], then one [`EpisodeLog`] per episode.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Lines, Write};
use std::path::{Path, PathBuf};

use anyhow::Context;
use glam::DVec2;
use lidar_har_core::activity::Activity;
use lidar_har_core::classifier::LaneSchedule;
use lidar_har_core::fall::FallInput;
use lidar_har_pipeline::classifier::{self, ClassifierOutput};
use lidar_har_sim::scripts::ScriptKind;
use serde::{Deserialize, Serialize};

const FORMAT: &str = "lidar-har alerts readings";
const VERSION: u32 = 1;

/// The file's first line: what the readings were recorded with. Everything but the
/// `fall_alert` settings is fixed by it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    format: String,
    version: u32,
    pub model: String,
    pub scenes: Vec<String>,
    pub seed: u64,
    pub episode_seconds: f64,
    /// Episodes with falls ran on for it past their end, so it is the one to score them by.
    pub latency_target_s: f64,
    /// The model's training window and its staggered states (lanes), which shaped every
    /// prediction.
    pub window: usize,
    pub lane_period_scans: usize,
    pub lanes: usize,
}

impl Header {
    pub fn new(
        model: String,
        scenes: Vec<String>,
        seed: u64,
        episode_seconds: f64,
        latency_target_s: f64,
        window: usize,
        schedule: LaneSchedule,
    ) -> Self {
        Self {
            format: FORMAT.into(),
            version: VERSION,
            model,
            scenes,
            seed,
            episode_seconds,
            latency_target_s,
            window,
            lane_period_scans: schedule.period,
            lanes: schedule.lanes,
        }
    }
}

/// One simulated episode as the alerts saw it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeLog {
    pub id: usize,
    pub kind: ScriptKind,
    pub scene: String,
    /// The simulator's clock at the episode's start: episode time counts from here.
    pub start_ns: u64,
    /// The episode's end in episode time, half a scan after its last scan; the frames after
    /// it are the run-on.
    pub end_s: f64,
    pub frames: Vec<Frame>,
}

impl EpisodeLog {
    pub fn start_s(&self) -> f64 {
        self.start_ns as f64 * 1e-9
    }
}

/// One scan of an episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Frame {
    pub stamp_ns: u64,
    /// The person's true activity; `None` in a scene without a person.
    pub truth: Option<Activity>,
    /// `None` when nobody was tracked (the localiser node publishes no observation then).
    pub reading: Option<Reading>,
}

impl Frame {
    /// In episode time, as the ground truth and the alerts are.
    pub fn stamp_s(&self, start_s: f64) -> f64 {
        self.stamp_ns as f64 * 1e-9 - start_s
    }

    /// Whether the localiser saw the person.
    pub fn seen(&self) -> bool {
        self.reading.is_some_and(|r| r.visible)
    }
}

/// What the classifier stage had for the tracked person on one scan.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// Seen in this scan (else predicted through an occlusion).
    pub visible: bool,
    /// The model had enough history to be published.
    pub ready: bool,
    /// Map frame.
    pub position: [f64; 2],
    pub probabilities: [f32; Activity::COUNT],
    pub body_length_m: Option<f64>,
}

impl Reading {
    pub fn of(out: &ClassifierOutput) -> Self {
        Self {
            visible: out.visible,
            ready: out.prediction.ready,
            position: out.position.to_array(),
            probabilities: out.prediction.probabilities,
            body_length_m: out.body_length_m,
        }
    }

    pub fn publishable(&self) -> bool {
        classifier::publishable(self.visible, self.ready)
    }

    pub fn position(&self) -> DVec2 {
        DVec2::from_array(self.position)
    }

    /// What the classifier stage gives the fall alerts for this scan, at `stamp_s` on the
    /// stage's alert clock ([`classifier::StreamClock`]).
    pub fn fall_input(&self, stamp_s: f64) -> FallInput {
        classifier::fall_input(
            stamp_s,
            self.visible,
            self.ready,
            self.position(),
            self.probabilities,
            self.body_length_m,
        )
    }
}

type Encoder = zstd::stream::write::Encoder<'static, BufWriter<File>>;

/// Writes a readings file episode by episode.
pub struct ReadingsWriter {
    path: PathBuf,
    out: Encoder,
}

impl ReadingsWriter {
    pub fn create(path: &Path, header: &Header) -> anyhow::Result<Self> {
        let file = File::create(path)
            .with_context(|| format!("--save-readings {}: cannot create it", path.display()))?;
        let out = Encoder::new(BufWriter::new(file), 3)?;
        let mut writer = Self {
            path: path.to_owned(),
            out,
        };
        // On disk at once: a run stopped during its first episode leaves a file `--readings`
        // knows as a recording with no episode, not an empty one it cannot tell from any other.
        writer.line(header)?;
        writer.flush()?;
        Ok(writer)
    }

    /// Each episode is flushed as its own block: a run cut short keeps what it recorded, and
    /// `--readings` scores those episodes (and says the file is cut short).
    pub fn write(&mut self, episode: &EpisodeLog) -> anyhow::Result<()> {
        self.line(episode)?;
        self.flush()
    }

    fn flush(&mut self) -> anyhow::Result<()> {
        self.out
            .flush()
            .with_context(|| format!("--save-readings {}: writing", self.path.display()))
    }

    fn line(&mut self, value: &impl Serialize) -> anyhow::Result<()> {
        serde_json::to_writer(&mut self.out, value)
            .map_err(anyhow::Error::from)
            .and_then(|()| Ok(self.out.write_all(b"\n")?))
            .with_context(|| format!("--save-readings {}: writing", self.path.display()))
    }

    /// Removes the file of a run that failed: its readings would replay as a result.
    pub fn discard(self) -> anyhow::Result<()> {
        drop(self.out);
        std::fs::remove_file(&self.path)
            .with_context(|| format!("--save-readings {}: removing it", self.path.display()))
    }

    pub fn finish(self) -> anyhow::Result<()> {
        let path = self.path;
        self.out
            .finish()
            .and_then(|mut file| file.flush())
            .with_context(|| format!("--save-readings {}: writing", path.display()))
    }
}

/// Reads a readings file: the header at once, the episodes one at a time.
pub struct ReadingsReader {
    path: PathBuf,
    header: Header,
    lines: Lines<BufReader<zstd::stream::read::Decoder<'static, BufReader<File>>>>,
    line: usize,
    /// A damaged stream goes on failing: the first error ends the episodes.
    failed: bool,
}

impl ReadingsReader {
    pub fn open(path: &Path) -> anyhow::Result<Self> {
        let name = path.display();
        let file =
            File::open(path).with_context(|| format!("--readings {name}: cannot open it"))?;
        let decoder = zstd::stream::read::Decoder::new(file)
            .with_context(|| format!("--readings {name}: cannot read it"))?;
        let mut lines = BufReader::new(decoder).lines();
        let not_readings = || {
            format!(
                "--readings {name}: not a readings file (write one with `lidar-har alerts \
                 --save-readings FILE`)"
            )
        };
        let first = lines
            .next()
            .context("empty")
            .and_then(|line| Ok(line?))
            .with_context(not_readings)?;
        let header: Header = serde_json::from_str(&first).with_context(not_readings)?;
        anyhow::ensure!(header.format == FORMAT, not_readings());
        anyhow::ensure!(
            header.version == VERSION,
            "--readings {name}: format version {}, this lidar-har reads {VERSION}: record it \
             again",
            header.version
        );
        Ok(Self {
            path: path.to_owned(),
            header,
            lines,
            line: 1,
            failed: false,
        })
    }

    pub fn header(&self) -> &Header {
        &self.header
    }
}

impl Iterator for ReadingsReader {
    type Item = anyhow::Result<EpisodeLog>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        let line = self.lines.next()?;
        self.line += 1;
        let (name, number) = (self.path.display(), self.line);
        let episode = line
            .map_err(anyhow::Error::from)
            .and_then(|line| Ok(serde_json::from_str(&line)?))
            .with_context(|| {
                format!(
                    "--readings {name}: line {number}: cut short or damaged (a recording that \
                     was interrupted?)"
                )
            });
        self.failed = episode.is_err();
        Some(episode)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn episode(id: usize) -> EpisodeLog {
        let reading = Reading {
            visible: true,
            ready: true,
            position: [1.25, -0.1],
            probabilities: [0.1, 0.2, 0.3, 0.05, 0.05, 0.1, 0.1, 0.05, 0.05],
            body_length_m: Some(0.3),
        };
        EpisodeLog {
            id,
            kind: ScriptKind::WithFalls,
            scene: "living_room".into(),
            start_ns: 1_700_000_000_123_456_789,
            end_s: 20.025,
            frames: vec![
                Frame {
                    stamp_ns: 1_700_000_000_123_456_789,
                    truth: Some(Activity::Walking),
                    reading: None,
                },
                Frame {
                    stamp_ns: 1_700_000_000_173_456_789,
                    truth: Some(Activity::FallingDown),
                    reading: Some(reading),
                },
            ],
        }
    }

    fn header() -> Header {
        let schedule = LaneSchedule {
            period: 24,
            lanes: 2,
            lanes_between: 0,
        };
        Header::new(
            "m.onnx".into(),
            vec!["a".into()],
            3,
            60.0,
            1.0,
            20,
            schedule,
        )
    }

    #[test]
    fn episodes_come_back_exactly_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.zst");
        let mut writer = ReadingsWriter::create(&path, &header()).unwrap();
        writer.write(&episode(0)).unwrap();
        writer.write(&episode(1)).unwrap();
        writer.finish().unwrap();

        let reader = ReadingsReader::open(&path).unwrap();
        assert_eq!(reader.header(), &header());
        let episodes: Vec<EpisodeLog> = reader.map(Result::unwrap).collect();
        assert_eq!(episodes, vec![episode(0), episode(1)]);
    }

    #[test]
    fn a_recording_stopped_in_its_first_episode_reads_as_one_without_episodes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.zst");
        // What is on disk while the first episode runs: a process killed now leaves this.
        let writer = ReadingsWriter::create(&path, &header()).unwrap();
        let on_disk = dir.path().join("killed.zst");
        std::fs::copy(&path, &on_disk).unwrap();
        drop(writer);

        let mut read = ReadingsReader::open(&on_disk).unwrap();
        assert_eq!(read.header(), &header());
        assert!(
            read.next().is_none_or(|episode| episode.is_err()),
            "no episode was written"
        );
    }

    #[test]
    fn a_reading_gives_the_alerts_a_position_only_when_seen_and_ready() {
        let reading = episode(0).frames[1].reading.unwrap();
        let input = reading.fall_input(1.5);
        assert_eq!(input.stamp_s, 1.5);
        assert_eq!(input.position, Some(DVec2::new(1.25, -0.1)));
        for (visible, ready) in [(false, true), (true, false)] {
            let input = Reading {
                visible,
                ready,
                ..reading
            }
            .fall_input(0.0);
            assert_eq!(input.position, None);
        }
    }

    #[test]
    fn a_cut_short_file_gives_the_episodes_before_the_cut_then_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.zst");
        let mut writer = ReadingsWriter::create(&path, &header()).unwrap();
        for id in 0..3 {
            writer.write(&episode(id)).unwrap();
        }
        writer.finish().unwrap();
        let whole = std::fs::read(&path).unwrap();
        let cut = dir.path().join("cut.zst");
        std::fs::write(&cut, &whole[..whole.len() - 1]).unwrap();

        let mut read = ReadingsReader::open(&cut).unwrap();
        let mut episodes = Vec::new();
        let err = loop {
            match read.next() {
                Some(Ok(episode)) => episodes.push(episode),
                Some(Err(e)) => break format!("{e:#}"),
                None => panic!("the cut went unnoticed"),
            }
        };
        assert!(read.next().is_none(), "the first error ends the episodes");
        assert_eq!(
            episodes[..],
            [episode(0), episode(1), episode(2)][..episodes.len()]
        );
        assert!(
            err.contains("cut.zst") && err.contains("cut short"),
            "{err}"
        );
    }

    #[test]
    fn other_files_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("none.zst");
        let err = format!("{:#}", ReadingsReader::open(&missing).err().unwrap());
        assert!(
            err.contains("none.zst") && err.contains("cannot open"),
            "{err}"
        );

        let plain = dir.path().join("report.json");
        std::fs::write(&plain, "{\"falls\": 3}\n").unwrap();
        let err = format!("{:#}", ReadingsReader::open(&plain).err().unwrap());
        assert!(
            err.contains("report.json") && err.contains("not a readings file"),
            "{err}"
        );

        let json = dir.path().join("other.zst");
        std::fs::write(&json, zstd::encode_all(&b"{\"a\": 1}\n"[..], 3).unwrap()).unwrap();
        let err = format!("{:#}", ReadingsReader::open(&json).err().unwrap());
        assert!(err.contains("not a readings file"), "{err}");
    }
}
