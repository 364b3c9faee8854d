//! Helpers shared by the end-to-end tests: where the repository, the shared data, the
//! project's binaries and the external Python checkers are, and running a process with a
//! deadline.
//!
//! Where something a test needs is missing, the test skips with a message, unless
//! `LIDAR_HAR_REQUIRE_CHECKERS` is set (scripts/test.sh and CI set it): there it fails,
//! naming what is missing and how to get it, so nothing passes without running.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant, SystemTime};

/// The repository root.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// Whether a missing prerequisite fails the test instead of skipping it
/// (`LIDAR_HAR_REQUIRE_CHECKERS` is set, as in scripts/test.sh and CI).
pub fn prerequisites_required() -> bool {
    std::env::var_os("LIDAR_HAR_REQUIRE_CHECKERS").is_some()
}

/// Reports that `missing` is not there and how to get it (`remedy`): a panic where
/// prerequisites are required, else a `SKIP:` line on stderr (the caller then returns).
pub fn skip_or_fail(missing: &str, remedy: &str) {
    if prerequisites_required() {
        panic!(
            "{missing}; {remedy} (LIDAR_HAR_REQUIRE_CHECKERS is set, so this fails instead of skipping)"
        );
    }
    eprintln!("SKIP: {missing}; {remedy}");
}

/// `../shared/data/real` beside the repository, if present. Without it the tests that need
/// it skip with a message, so a clone without `../shared` still passes, unless
/// prerequisites are required (CI), where its absence fails.
pub fn shared_real_data() -> Option<PathBuf> {
    let dir = repo_root().join("../shared/data/real");
    if dir.is_dir() {
        return Some(dir);
    }
    skip_or_fail(
        &format!(
            "{} not found (the shared real recordings are not beside this clone)",
            dir.display()
        ),
        "put the project's shared folder beside the repository as ../shared, with \
         data/real/leg_tracker_demo_stationary (see its data/real/README.md)",
    );
    None
}

/// A binary of this workspace, built by `cargo build --workspace --bins` (scripts/test.sh does).
///
/// Fails when it is missing, or older than a source file it was built from (as listed in the
/// dep-info file cargo writes beside it): `cargo test` does not rebuild it, and testing a
/// stale binary tests code that no longer exists. Comparing with the test executable's own
/// time would misfire: scripts/test.sh builds the binaries first, then `cargo test` links
/// every test executable after them.
pub fn workspace_bin(name: &str) -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join("target"));
    let profile = if cfg!(debug_assertions) {
        "debug"
    } else {
        "release"
    };
    let path = target.join(profile).join(name);
    assert!(
        path.is_file(),
        "{} is not built: run `cargo build --workspace --bins` first (scripts/test.sh does)",
        path.display()
    );
    if let Some(source) = newer_source(&path) {
        panic!(
            "{} is older than {}, changed since it was built: run `cargo build --workspace --bins` \
             first (scripts/test.sh does)",
            path.display(),
            source.display()
        );
    }
    path
}

/// A source file listed in `binary`'s dep-info file (`binary.d`) modified after `binary`.
fn newer_source(binary: &Path) -> Option<PathBuf> {
    let built = modified(binary)?;
    let dep_info = std::fs::read_to_string(binary.with_extension("d")).ok()?;
    dep_info_sources(&dep_info)
        .into_iter()
        .find(|source| modified(source).is_some_and(|t| t > built))
}

fn modified(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).and_then(|m| m.modified()).ok()
}

/// The prerequisites of a Makefile-style dep-info text (`target: dep dep ...`, a space in a
/// path written `\ `).
fn dep_info_sources(text: &str) -> Vec<PathBuf> {
    let mut sources = Vec::new();
    for line in text.lines() {
        let Some((_, deps)) = line.split_once(": ") else {
            continue;
        };
        let mut current = String::new();
        let mut chars = deps.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '\\' if chars.peek() == Some(&' ') => current.push(chars.next().unwrap()),
                ' ' => {
                    if !current.is_empty() {
                        sources.push(PathBuf::from(std::mem::take(&mut current)));
                    }
                }
                c => current.push(c),
            }
        }
        if !current.is_empty() {
            sources.push(PathBuf::from(current));
        }
    }
    sources
}

/// `lidar-har`, in the test's working directory (`tests/`) unless the caller sets another:
/// relative paths such as the default `models/activity.onnx` resolve from there.
pub fn lidar_har() -> Command {
    Command::new(workspace_bin("lidar-har"))
}

/// Runs `cmd` to completion with stdout and stderr captured, killing it and failing the test
/// if it runs past `limit` (a process that hangs must not hang the suite).
pub fn output_within(cmd: &mut Command, limit: Duration) -> Output {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}"));
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut pipe) = pipe {
                let _ = pipe.read_to_end(&mut bytes);
            }
            bytes
        })
    };
    let stdout = drain(child.stdout.take().map(|p| Box::new(p) as _));
    let stderr = drain(child.stderr.take().map(|p| Box::new(p) as _));
    let deadline = Instant::now() + limit;
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for the child") {
            break status;
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            let (out, err) = (stdout.join().unwrap(), stderr.join().unwrap());
            panic!(
                "{cmd:?} ran past its {limit:?} limit and was killed\n--- stdout\n{}\n--- stderr\n{}",
                String::from_utf8_lossy(&out),
                String::from_utf8_lossy(&err)
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Output {
        status,
        stdout: stdout.join().unwrap(),
        stderr: stderr.join().unwrap(),
    }
}

/// The Python of `.venv` with the external checkers (rosbags, mcap, cyclonedds).
///
/// Returns `None` (with a message) when it is missing, unless prerequisites are required
/// (CI): there a missing checker is a failure, not a skip.
pub fn checker_python() -> Option<Command> {
    let python = repo_root().join(".venv/bin/python");
    if python.is_file() {
        let mut cmd = Command::new(python);
        cmd.current_dir(repo_root());
        return Some(cmd);
    }
    skip_or_fail(
        &format!("{} missing", python.display()),
        "run scripts/setup.sh for the external checkers",
    );
    None
}

/// Whether the ONNX Runtime library loads from where the binaries look for it, the rule of
/// `lidar_har_infer::runtime_library_path`: `ORT_DYLIB_PATH` when set and not empty, else
/// `.deps/onnxruntime/libonnxruntime.so`. The file must exist. Skips or fails like
/// [`checker_python`] when it does not.
pub fn runtime_available() -> bool {
    let path = match std::env::var_os("ORT_DYLIB_PATH") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => repo_root().join(".deps/onnxruntime/libonnxruntime.so"),
    };
    if path.is_file() {
        return true;
    }
    skip_or_fail(
        &format!("ONNX Runtime library {} missing", path.display()),
        "run scripts/setup.sh (and leave ORT_DYLIB_PATH unset or point it at the library)",
    );
    false
}

/// Copies the bag at `src` into a new bag at `dst`, leaving out the topics `dropped` and
/// passing each message's bytes through `edit(topic, bytes)`: inputs a test breaks on purpose.
pub fn copy_bag(src: &Path, dst: &Path, dropped: &[&str], edit: impl Fn(&str, Vec<u8>) -> Vec<u8>) {
    copy_messages(src, dst, dropped, |message| {
        message.data = edit(&message.topic, std::mem::take(&mut message.data));
        true
    });
}

/// Copies the bag at `src` into a new bag at `dst` with the topics `emptied` declared but
/// holding no message, as `ros2 bag record -a` leaves a topic nobody published on.
pub fn copy_bag_emptying(src: &Path, dst: &Path, emptied: &[&str]) {
    copy_messages(src, dst, &[], |message| !emptied.contains(&&*message.topic));
}

/// Copies the bag at `src` into a new bag at `dst` with the messages on `topic` received
/// (logged) `delay_ns` after they were, their stamps kept: a publisher whose messages come
/// late.
pub fn copy_bag_delaying(src: &Path, dst: &Path, topic: &str, delay_ns: i64) {
    copy_messages(src, dst, &[], |message| {
        if *message.topic == *topic {
            message.log_time_ns += delay_ns;
        }
        true
    });
}

/// The copy the above make: every message of the kept topics through `edit` (false leaves
/// the message out), then written in order of (edited) log time, a moved message before
/// those already logged at its new time.
fn copy_messages(
    src: &Path,
    dst: &Path,
    dropped: &[&str],
    mut edit: impl FnMut(&mut lidar_har_bag::BagMessage) -> bool,
) {
    let reader = lidar_har_bag::BagReader::open(src).expect("the bag to copy opens");
    let mut writer = lidar_har_bag::BagWriter::create(dst, lidar_har_bag::WriterOptions::default())
        .expect("the copy can be created");
    let kept: Vec<_> = reader
        .topics()
        .iter()
        .filter(|t| !dropped.contains(&t.name.as_str()))
        .map(|t| {
            (
                t.name.clone(),
                writer.add_topic_like(t).expect("topic added"),
            )
        })
        .collect();
    let mut messages = Vec::new();
    for message in reader.messages().expect("the bag to copy reads") {
        let mut message = message.expect("a message of the bag to copy");
        if kept.iter().any(|(name, _)| *name == *message.topic) && edit(&mut message) {
            messages.push(message);
        }
    }
    messages.sort_by_key(|m| m.log_time_ns);
    for message in messages {
        let (_, handle) = kept
            .iter()
            .find(|(name, _)| *name == *message.topic)
            .expect("a kept topic");
        writer
            .write(*handle, message.log_time_ns, &message.data)
            .expect("message copied");
    }
    writer.finish().expect("the copy is finished");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dep_info_lists_every_source_with_escaped_spaces() {
        let text = "/t/bin: /a/x.rs /a/my\\ dir/y.rs\n\n/a/x.rs:\n";
        assert_eq!(
            dep_info_sources(text),
            [PathBuf::from("/a/x.rs"), PathBuf::from("/a/my dir/y.rs")]
        );
    }

    #[test]
    fn output_within_kills_a_process_past_its_limit() {
        let started = Instant::now();
        let result = std::panic::catch_unwind(|| {
            output_within(Command::new("sleep").arg("30"), Duration::from_millis(300))
        });
        assert!(result.is_err(), "must fail past the limit");
        assert!(started.elapsed() < Duration::from_secs(10));
        let out = output_within(
            Command::new("sh").args(["-c", "echo hi; echo err >&2; exit 3"]),
            Duration::from_secs(10),
        );
        assert_eq!(out.status.code(), Some(3));
        assert_eq!(out.stdout, b"hi\n");
        assert_eq!(out.stderr, b"err\n");
    }
}
