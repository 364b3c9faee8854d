//! `scripts/setup.sh` repairs what an interrupted run left behind. It runs offline here: the
//! ONNX Runtime library comes from a small wheel the test makes (`LIDAR_HAR_ORT_WHEEL`), the
//! virtual environment's pip from Python's own `ensurepip`, and a stand-in `cargo` answers for
//! cargo-fuzz. Before, a library cut short by a full disk or a Ctrl-C was taken as installed
//! ("already at", then every model command died of SIGBUS), a missing link too, and a
//! virtual environment without pip was never remade.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use lidar_har_e2e::{repo_root, skip_or_fail};

const ORT_VERSION: &str = "1.31.1";

/// A copy of the scripts setup.sh needs, in a directory of its own (setup.sh installs beside
/// itself), with a stand-in `cargo` and a wheel holding `library`.
struct Checkout {
    dir: tempfile::TempDir,
    wheel: PathBuf,
    bin: PathBuf,
}

impl Checkout {
    fn new(library: &[u8]) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let scripts = dir.path().join("scripts");
        std::fs::create_dir(&scripts).unwrap();
        for file in ["setup.sh", "requirements-checkers.txt"] {
            std::fs::copy(repo_root().join("scripts").join(file), scripts.join(file)).unwrap();
        }
        let bin = dir.path().join("bin");
        std::fs::create_dir(&bin).unwrap();
        let cargo = bin.join("cargo");
        std::fs::write(&cargo, "#!/bin/sh\necho 'cargo-fuzz 0.0.0 (stand-in)'\n").unwrap();
        std::fs::set_permissions(&cargo, std::fs::Permissions::from_mode(0o755)).unwrap();
        let wheel = dir.path().join("onnxruntime-test.whl");
        let payload = dir.path().join("payload");
        std::fs::write(&payload, library).unwrap();
        let zipped = Command::new("python3")
            .args(["-c", "import sys, zipfile\nwith zipfile.ZipFile(sys.argv[1], 'w') as z: z.write(sys.argv[2], sys.argv[3])"])
            .arg(&wheel)
            .arg(&payload)
            .arg(format!("onnxruntime/capi/libonnxruntime.so.{ORT_VERSION}"))
            .output()
            .unwrap();
        assert!(zipped.status.success(), "{zipped:?}");
        Self { dir, wheel, bin }
    }

    /// Replaces the stand-in `cargo` with one that has no cargo-fuzz and whose
    /// `cargo install` runs `install` (a shell command).
    fn without_cargo_fuzz(&self, install: &str) {
        let script = format!(
            "#!/bin/sh\ncase \"$1\" in\n  install) {install} ;;\n  *) echo \"error: no such command: $1\" >&2; exit 101 ;;\nesac\n"
        );
        std::fs::write(self.bin.join("cargo"), script).unwrap();
    }

    fn path(&self, relative: &str) -> PathBuf {
        self.dir.path().join(relative)
    }

    fn library(&self) -> PathBuf {
        self.path(&format!(
            ".deps/onnxruntime/libonnxruntime.so.{ORT_VERSION}"
        ))
    }

    fn link(&self) -> PathBuf {
        self.path(".deps/onnxruntime/libonnxruntime.so")
    }

    /// `setup.sh --no-python` with the test's wheel; its output, both streams in one text.
    fn setup(&self, wheel: &Path) -> (Output, String) {
        let path = format!(
            "{}:{}",
            self.bin.display(),
            std::env::var("PATH").unwrap_or_default()
        );
        let out = Command::new("bash")
            .arg(self.path("scripts/setup.sh"))
            .arg("--no-python")
            .env("PATH", path)
            .env("LIDAR_HAR_ORT_WHEEL", wheel)
            .env("PIP_NO_INDEX", "1")
            .output()
            .unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        (out, text)
    }

    fn setup_succeeds(&self) -> String {
        let (out, text) = self.setup(&self.wheel);
        assert!(out.status.success(), "setup.sh failed:\n{text}");
        text
    }
}

fn python_can_make_environments() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import venv, ensurepip"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        skip_or_fail(
            "python3 with the venv and ensurepip modules is missing",
            "apt-get install python3-venv (scripts/setup.sh does as root)",
        );
    }
    ok
}

#[test]
fn setup_repairs_what_an_interrupted_run_left_behind() {
    if !python_can_make_environments() {
        return;
    }
    let library: Vec<u8> = (0..200_000u32).map(|i| (i * 7 + i / 251) as u8).collect();
    let checkout = Checkout::new(&library);
    // `python3 -m venv` stopped before it installed pip.
    let made = Command::new("python3")
        .args(["-m", "venv", "--without-pip"])
        .arg(checkout.path(".venv"))
        .output()
        .unwrap();
    assert!(made.status.success(), "{made:?}");

    let text = checkout.setup_succeeds();
    assert!(text.contains("creating the virtual environment"), "{text}");
    let pip = Command::new(checkout.path(".venv/bin/python"))
        .args(["-m", "pip", "--version"])
        .output()
        .unwrap();
    assert!(pip.status.success(), "the environment was not given pip");
    assert_eq!(std::fs::read(checkout.library()).unwrap(), library);
    assert_eq!(
        std::fs::read_link(checkout.link()).unwrap(),
        Path::new(&format!("libonnxruntime.so.{ORT_VERSION}"))
    );

    // Installed: a rerun changes nothing.
    let text = checkout.setup_succeeds();
    assert!(text.contains("already at"), "{text}");
    assert!(!text.contains("creating the virtual environment"), "{text}");

    // A library cut short (a full disk, Ctrl-C during extraction).
    std::fs::write(checkout.library(), &library[..1000]).unwrap();
    let text = checkout.setup_succeeds();
    assert!(!text.contains("already at"), "{text}");
    assert_eq!(std::fs::read(checkout.library()).unwrap(), library);

    // Stopped between extracting the library and linking it.
    std::fs::remove_file(checkout.link()).unwrap();
    let text = checkout.setup_succeeds();
    assert!(!text.contains("already at"), "{text}");
    assert_eq!(std::fs::read(checkout.link()).unwrap(), library);

    // A repair that cannot be made fails, naming what is wrong, and claims nothing.
    std::fs::write(checkout.library(), b"truncated").unwrap();
    let missing = checkout.path("no-such.whl");
    let (out, text) = checkout.setup(&missing);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(
        text.contains(&format!("LIDAR_HAR_ORT_WHEEL={}", missing.display())),
        "{text}"
    );
    let (out, text) = checkout.setup(&missing);
    assert_eq!(
        out.status.code(),
        Some(1),
        "a failed repair was taken as done: {text}"
    );

    // Installed by a set-up before checksums: fetched again where a wheel can be had, kept
    // with a warning where none can (an offline robot), never refused.
    std::fs::write(checkout.library(), &library).unwrap();
    std::fs::remove_file(checkout.path(".deps/onnxruntime/installed.sha256")).unwrap();
    let (out, text) = checkout.setup(&missing);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("unverified"), "{text}");
    assert_eq!(std::fs::read(checkout.library()).unwrap(), library);
    let text = checkout.setup_succeeds();
    assert!(text.contains("taking the ONNX Runtime library"), "{text}");
    let text = checkout.setup_succeeds();
    assert!(text.contains("already at"), "verified now: {text}");
}

/// cargo-fuzz only serves scripts/fuzz.sh: an offline machine (no crates.io) is warned, with
/// what will not work and how to get it, and the set-up goes on. Before, it failed there on
/// every run, after the library was in place. Where crates.io answers, it is installed (CI).
#[test]
fn setup_without_crates_io_warns_that_fuzzing_needs_cargo_fuzz_and_goes_on() {
    if !python_can_make_environments() {
        return;
    }
    let checkout = Checkout::new(b"library");
    checkout.without_cargo_fuzz("echo 'error: failed to query crates.io (offline)' >&2; exit 101");
    let text = checkout.setup_succeeds();
    assert!(
        text.contains("warning: cargo install cargo-fuzz failed"),
        "{text}"
    );
    assert!(text.contains("scripts/fuzz.sh"), "{text}");
    assert!(text.contains("cargo install cargo-fuzz --locked"), "{text}");
    assert!(text.contains("without cargo-fuzz"), "{text}");
    assert_eq!(std::fs::read(checkout.library()).unwrap(), b"library");

    let installed = checkout.path("cargo-fuzz-installed");
    checkout.without_cargo_fuzz(&format!("touch '{}'", installed.display()));
    let text = checkout.setup_succeeds();
    assert!(installed.exists(), "cargo install was not run: {text}");
    assert!(!text.contains("cargo-fuzz failed"), "{text}");
}

/// `--help` prints the whole usage, down to the offline wheel (it stopped before it).
#[test]
fn setup_help_names_the_offline_wheel() {
    let out = Command::new("bash")
        .arg(repo_root().join("scripts/setup.sh"))
        .arg("--help")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{out:?}");
    assert!(text.contains("--no-python"), "{text}");
    assert!(text.contains("LIDAR_HAR_ORT_WHEEL"), "{text}");
    assert!(!text.contains("set -euo"), "{text}");
}
