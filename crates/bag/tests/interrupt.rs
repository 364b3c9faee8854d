//! A real child process records a bag and is interrupted: SIGKILL loses nothing flushed and
//! leaves nothing corrupt (MCAP, and sqlite3 with more unflushed than SQLite's page cache);
//! SIGTERM (handled the way the project's binaries do) leaves a complete bag. The child is
//! this test binary itself, re-run with `BAG_CHILD_DIR` set.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use lidar_har_bag::{
    BagError, BagReader, BagWriter, Compression, StorageId, TopicHandle, WriterOptions,
};
use lidar_har_msgs::builtin_interfaces::Time;
use lidar_har_msgs::qos::QosProfile;
use lidar_har_msgs::sensor_msgs::LaserScan;
use lidar_har_msgs::std_msgs::Header;

const CHILD_DIR: &str = "BAG_CHILD_DIR";

fn scan(i: u32) -> LaserScan {
    LaserScan {
        header: Header {
            stamp: Time {
                sec: i as i32,
                nanosec: 0,
            },
            frame_id: "laser".into(),
        },
        angle_increment: 0.00872,
        range_max: 12.0,
        ranges: (0..720)
            .map(|b| {
                if b % 7 == 0 {
                    f32::INFINITY
                } else {
                    (i + b) as f32 * 0.001
                }
            })
            .collect(),
        ..LaserScan::default()
    }
}

/// The child: records scans until SIGTERM/SIGINT (then finishes the bag) or until killed.
/// Prints `flushed N` each time N messages are safely on disk.
#[test]
fn child_writer() {
    let Some(dir) = std::env::var_os(CHILD_DIR) else {
        return;
    };
    let stop = Arc::new(AtomicBool::new(false));
    signal_hook::flag::register(signal_hook::consts::SIGTERM, stop.clone()).unwrap();
    signal_hook::flag::register(signal_hook::consts::SIGINT, stop.clone()).unwrap();
    let options = WriterOptions {
        compression: Compression::Zstd,
        chunk_size: 64 * 1024,
        flush_interval: Duration::from_secs(3600),
        ..WriterOptions::default()
    };
    let (mut writer, topic) = scan_writer(&dir, options);
    let mut i = 0u32;
    while !stop.load(Ordering::Relaxed) && i < 1_000_000 {
        writer
            .write_message(topic, 1_000 + i64::from(i) * 50_000_000, &scan(i))
            .unwrap();
        i += 1;
        if i.is_multiple_of(25) {
            writer.flush().unwrap();
            println!("flushed {i}");
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    let summary = writer.finish().unwrap();
    println!("finished {}", summary.metadata.message_count);
}

/// A child's bag in `dir`, with its /scan topic.
fn scan_writer(dir: &std::ffi::OsStr, options: WriterOptions) -> (BagWriter, TopicHandle) {
    let mut writer = BagWriter::create(Path::new(dir), options).unwrap();
    let topic = writer
        .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
        .unwrap();
    (writer, topic)
}

/// The sqlite3 child: flushes `SQLITE_FLUSHED` scans of about 6 KB, then writes 1000 more
/// without flushing (printing `pending N` every 100) and waits to be killed: 6 MB in the open
/// transaction, three times SQLite's default page cache of 2 MB, so its pages would be
/// spilled into the file if the writer let SQLite do so.
#[test]
fn child_sqlite_writer() {
    let Some(dir) = std::env::var_os(CHILD_DIR) else {
        return;
    };
    let options = WriterOptions {
        storage: StorageId::Sqlite3,
        flush_interval: Duration::from_secs(3600),
        ..WriterOptions::default()
    };
    let (mut writer, topic) = scan_writer(&dir, options);
    // Ends the harness's `test child_sqlite_writer ... ` line: the awaited lines start clean.
    println!();
    let big_scan = |i: u32| LaserScan {
        intensities: vec![1.0; 720],
        ..scan(i)
    };
    for i in 0..SQLITE_FLUSHED + 1000 {
        writer
            .write_message(topic, 1_000 + i64::from(i) * 50_000_000, &big_scan(i))
            .unwrap();
        if i + 1 == SQLITE_FLUSHED {
            writer.flush().unwrap();
            println!("flushed {}", i + 1);
        } else if i >= SQLITE_FLUSHED && (i + 1 - SQLITE_FLUSHED).is_multiple_of(100) {
            println!("pending {}", i + 1 - SQLITE_FLUSHED);
        }
    }
    std::thread::sleep(CHILD_DEADLINE);
}

const SQLITE_FLUSHED: u32 = 100;

/// How long the child may take to print its next awaited line.
const CHILD_DEADLINE: Duration = Duration::from_secs(60);

/// The child writer and its stdout lines, read on a thread so that waiting for a line can
/// time out; the child is killed when this is dropped (a failing test included), so a hung
/// child neither blocks the test nor outlives it.
struct ChildWriter {
    child: Child,
    lines: Receiver<String>,
}

impl ChildWriter {
    /// Runs the test `test` (`child_writer` or `child_sqlite_writer`) as the child.
    fn spawn(test: &str, dir: &Path) -> Self {
        let mut child = Command::new(std::env::current_exe().unwrap())
            .args(["--exact", test, "--nocapture", "--test-threads=1"])
            .env(CHILD_DIR, dir)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let stdout = child.stdout.take().unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Self { child, lines }
    }

    /// The first line for which `parse` gives a value, within [`CHILD_DEADLINE`]; panics
    /// (the child is then killed) if it does not come in time or the child ends first.
    fn find_line<T>(&self, what: &str, mut parse: impl FnMut(&str) -> Option<T>) -> T {
        let deadline = Instant::now() + CHILD_DEADLINE;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    if let Some(value) = parse(&line) {
                        return value;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    panic!("child too slow: no {what} within {CHILD_DEADLINE:?}")
                }
                Err(RecvTimeoutError::Disconnected) => panic!("child ended before {what}"),
            }
        }
    }

    /// Reads the child's `flushed N` lines until N reaches `at_least`; returns that N.
    fn wait_for_flushes(&self, at_least: u32) -> u32 {
        self.find_line(&format!("`flushed N` with N >= {at_least}"), |line| {
            line.strip_prefix("flushed ")
                .and_then(|n| n.trim().parse::<u32>().ok())
                .filter(|n| *n >= at_least)
        })
    }

    /// Waits for the child to exit, killing it if it has not within [`CHILD_DEADLINE`].
    fn wait(&mut self) -> std::process::ExitStatus {
        let deadline = Instant::now() + CHILD_DEADLINE;
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                return status;
            }
            assert!(
                Instant::now() < deadline,
                "child did not exit within {CHILD_DEADLINE:?}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for ChildWriter {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

fn read_back(dir: &Path) -> (Vec<LaserScan>, Option<BagError>) {
    let reader = BagReader::open(dir).unwrap();
    let mut scans = Vec::new();
    let mut error = None;
    for message in reader.messages().unwrap() {
        match message {
            Ok(m) => scans.push(reader.decode::<LaserScan>(&m).unwrap()),
            Err(e) => error = Some(e),
        }
    }
    (scans, error)
}

#[test]
fn sigkill_loses_nothing_flushed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("killed");
    let mut child = ChildWriter::spawn("child_writer", &dir);
    let flushed = child.wait_for_flushes(300);
    child.child.kill().unwrap(); // SIGKILL: no handler runs
    child.wait();

    let (scans, error) = read_back(&dir);
    assert!(
        scans.len() >= flushed as usize,
        "{} read back, {flushed} flushed",
        scans.len()
    );
    for (i, got) in scans.iter().enumerate() {
        let expected = scan(i as u32);
        assert_eq!(got.header, expected.header, "message {i}");
        assert!(
            got.ranges
                .iter()
                .zip(&expected.ranges)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "message {i}"
        );
    }
    // The writer was killed mid-file: no summary, and normally half a chunk at the end.
    let reader = BagReader::open(&dir).unwrap();
    assert!(reader.metadata().truncated);
    if let Some(error) = error {
        assert!(matches!(error, BagError::Truncated { .. }), "{error}");
    }
    // metadata.yaml was kept up to date at each flush.
    let listed = reader.bag_metadata().unwrap().message_count;
    assert!(
        listed >= u64::from(flushed) && listed <= scans.len() as u64,
        "metadata.yaml lists {listed}"
    );
}

/// SIGKILL of a sqlite3 recorder whose open transaction is larger than SQLite's page cache:
/// the bag opens and every flushed message reads back (the uncommitted ones are lost).
#[test]
fn sigkill_of_a_sqlite3_writer_loses_nothing_flushed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("killed");
    let mut child = ChildWriter::spawn("child_sqlite_writer", &dir);
    let flushed = child.wait_for_flushes(SQLITE_FLUSHED);
    child.find_line("`pending 1000`", |line| {
        (line == "pending 1000").then_some(())
    });
    child.child.kill().unwrap(); // SIGKILL, mid-transaction
    child.wait();
    // Killed with the transaction open, and none of its pages in the file: the journal is
    // not hot, so any read-only reader (rosbag2's too) opens the file as it is.
    let journal = std::fs::read(dir.join("killed_0.db3-journal")).unwrap();
    assert_eq!(journal.first(), Some(&0), "the journal is not hot");

    let (scans, error) = read_back(&dir);
    assert!(error.is_none(), "{error:?}");
    assert_eq!(scans.len(), flushed as usize);
    for (i, got) in scans.iter().enumerate() {
        assert_eq!(got.header, scan(i as u32).header, "message {i}");
        assert_eq!(got.intensities.len(), 720, "message {i}");
    }
    let reader = BagReader::open(&dir).unwrap();
    assert_eq!(
        reader.bag_metadata().unwrap().message_count,
        u64::from(flushed)
    );
}

#[test]
fn sigterm_finishes_the_bag() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("terminated");
    let mut child = ChildWriter::spawn("child_writer", &dir);
    child.wait_for_flushes(100);
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let finished: u64 = child.find_line("`finished N` after SIGTERM", |l| {
        l.strip_prefix("finished ")
            .and_then(|n| n.trim().parse().ok())
    });
    assert!(child.wait().success());

    let (scans, error) = read_back(&dir);
    assert!(error.is_none(), "{error:?}");
    assert_eq!(scans.len() as u64, finished);
    let reader = BagReader::open(&dir).unwrap();
    assert!(
        !reader.metadata().truncated,
        "a complete MCAP with its summary"
    );
    assert_eq!(reader.bag_metadata().unwrap().message_count, finished);
    assert_eq!(reader.metadata().message_count, finished);
}

/// Where the last chunk written by `mcap`'s writer still has its placeholder length: the chunk
/// opcode followed by `u64::MAX`, as the file stands while a chunk is being written.
fn open_chunk_at(bytes: &[u8]) -> Option<usize> {
    let mut placeholder = vec![0x06];
    placeholder.extend_from_slice(&u64::MAX.to_le_bytes());
    bytes
        .windows(placeholder.len())
        .rposition(|w| w == placeholder)
}

/// The file exactly as a recorder killed while writing a chunk leaves it (a copy of its bytes
/// taken with the chunk open), for each compression: every flushed message comes back, then a
/// `Truncated` error naming the file.
#[test]
fn a_chunk_left_open_by_a_killed_writer_reads_as_truncated() {
    let tmp = tempfile::tempdir().unwrap();
    for compression in [Compression::None, Compression::Zstd, Compression::Lz4] {
        let dir = tmp.path().join(format!("rec_{compression:?}"));
        let options = WriterOptions {
            compression,
            chunk_size: 64 << 20,
            flush_interval: Duration::from_secs(3600),
            ..WriterOptions::default()
        };
        let mut writer = BagWriter::create(&dir, options).unwrap();
        let topic = writer
            .add_topic_for::<LaserScan>("/scan", QosProfile::sensor_data())
            .unwrap();
        let file = dir.join(format!("rec_{compression:?}_0.mcap"));
        let flushed = 40u32;
        let mut snapshot = None;
        for i in 0..2000u32 {
            writer
                .write_message(topic, 1_000 + i64::from(i) * 50_000_000, &scan(i))
                .unwrap();
            if i + 1 == flushed {
                writer.flush().unwrap();
            }
            if i >= flushed {
                let bytes = std::fs::read(&file).unwrap();
                if open_chunk_at(&bytes).is_some() {
                    snapshot = Some(bytes);
                    break;
                }
            }
        }
        let snapshot = snapshot.expect("the open chunk reached the file");
        let metadata = std::fs::read(dir.join("metadata.yaml")).unwrap();
        drop(writer);

        let killed = tmp.path().join(format!("killed_{compression:?}"));
        std::fs::create_dir(&killed).unwrap();
        std::fs::write(killed.join("metadata.yaml"), metadata).unwrap();
        let killed_file = killed.join(file.file_name().unwrap());
        std::fs::write(&killed_file, &snapshot).unwrap();

        let reader = BagReader::open(&killed).unwrap();
        let info = reader.metadata();
        assert!(info.truncated, "{compression:?}");
        assert_eq!(info.message_count, u64::from(flushed), "{compression:?}");
        assert_eq!(info.start_ns, 1_000);
        let (scans, error) = read_back(&killed);
        assert_eq!(scans.len(), flushed as usize, "{compression:?}");
        for (i, got) in scans.iter().enumerate() {
            assert_eq!(
                got.header,
                scan(i as u32).header,
                "{compression:?} message {i}"
            );
        }
        let error = error.expect("the truncation is reported");
        assert!(
            matches!(
                error,
                BagError::Truncated {
                    messages_read: 40,
                    ..
                }
            ),
            "{error}"
        );
        let text = error.to_string();
        assert!(
            text.contains(&killed_file.display().to_string()) && text.contains("truncated"),
            "{text}"
        );
    }
}
