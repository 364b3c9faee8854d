//! Which ONNX Runtime library file to open, found the way `ort` finds it, and whether that file
//! is whole: the system loader maps a truncated library anyway and the process dies of SIGBUS
//! inside `dlopen`, with no message (an interrupted copy to the robot, a full disk, an
//! extraction cut short), so a library is checked before it is opened.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use crate::InferError;

/// What to hand to `ort::init_from`.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Library {
    /// A file that was found and checked, by an absolute path (which `ort` opens as it is).
    File(PathBuf),
    /// A bare file name not next to the executable: the system loader searches for it
    /// (`LD_LIBRARY_PATH`, `ld.so.cache`, the system's library directories; not the working
    /// directory) and picks the file, so it cannot be checked beforehand.
    ByLoader(PathBuf),
}

impl Library {
    pub(crate) fn path(&self) -> &Path {
        match self {
            Self::File(path) | Self::ByLoader(path) => path,
        }
    }
}

/// Finds `configured` as ort 2.0.0-rc.15 does (`load_dynamic::load_library`): an absolute
/// path as it is; a relative one in the executable's directory when it exists there, else as
/// `dlopen` takes it. `origin` says where `configured` came from, for the errors.
pub(crate) fn locate(configured: &Path, origin: &'static str) -> Result<Library, InferError> {
    if configured.is_absolute() {
        return checked(configured.to_path_buf(), origin);
    }
    // ort would panic here (`expect`) where this fails: refuse instead.
    let executable_dir = std::env::current_exe()
        .map_err(|e| e.to_string())
        .and_then(|exe| {
            exe.parent()
                .map(Path::to_path_buf)
                .ok_or_else(|| format!("{} has no parent directory", exe.display()))
        })
        .map_err(|why| InferError::RuntimeUnusable {
            path: configured.to_path_buf(),
            problem: format!(
                "a relative path is looked for next to the executable first, but its \
                 directory is unknown ({why}); set ORT_DYLIB_PATH to an absolute path"
            ),
        })?;
    locate_relative(configured, origin, &executable_dir)
}

/// [`locate`] for a relative `configured`, with the executable in `executable_dir`.
fn locate_relative(
    configured: &Path,
    origin: &'static str,
    executable_dir: &Path,
) -> Result<Library, InferError> {
    let next_to_executable = executable_dir.join(configured);
    if next_to_executable.exists() {
        return checked(next_to_executable, origin);
    }
    // dlopen(3): a name without a slash is searched for; one with a slash is a path, here
    // relative to the working directory.
    if !configured.as_os_str().as_encoded_bytes().contains(&b'/') {
        return Ok(Library::ByLoader(configured.to_path_buf()));
    }
    let in_working_directory =
        std::path::absolute(configured).map_err(|e| InferError::RuntimeUnusable {
            path: configured.to_path_buf(),
            problem: format!("cannot make it absolute: {e}"),
        })?;
    checked(in_working_directory, origin)
}

/// `path` when it is a file that looks whole; else an error naming it and the fix.
fn checked(path: PathBuf, origin: &'static str) -> Result<Library, InferError> {
    if path.is_dir() {
        return Err(InferError::RuntimeIsDirectory { path, origin });
    }
    if !path.is_file() {
        return Err(InferError::RuntimeMissing { path, origin });
    }
    match check_whole(&path) {
        Ok(()) => Ok(Library::File(path)),
        Err(message) => Err(InferError::RuntimeLoad { path, message }),
    }
}

const ELF_MAGIC: &[u8; 4] = b"\x7fELF";
const ELF_CLASS_64: u8 = 2;
const ELF64_HEADER_LEN: usize = 64;
const ELF64_PROGRAM_HEADER_LEN: usize = 56;
const PT_LOAD: u32 = 1;

/// Refuses a file that is not an ELF library or whose loadable segments (`PT_LOAD`) run past
/// its end. Reads the ELF header and the program headers, a few hundred bytes; no hashing.
///
/// Hand-parsed: five fields of the ELF64 layout. `object`, in Cargo.lock only as a build
/// tool's dependency (psm's), would become a new workspace dependency for them.
fn check_whole(path: &Path) -> Result<(), String> {
    // ELF is Linux's format; elsewhere the loader's own errors stand.
    if !cfg!(target_os = "linux") {
        return Ok(());
    }
    let unreadable = |e: std::io::Error| format!("cannot read it: {e}");
    let mut file = File::open(path).map_err(unreadable)?;
    let len = file.metadata().map_err(unreadable)?.len();
    let mut header = Vec::with_capacity(ELF64_HEADER_LEN);
    (&mut file)
        .take(ELF64_HEADER_LEN as u64)
        .read_to_end(&mut header)
        .map_err(unreadable)?;
    if !header.starts_with(ELF_MAGIC) {
        return Err("not a shared library: it does not start with the ELF magic number".into());
    }
    // dlopen refuses another class (32-bit) itself, before it maps anything.
    if header.get(4) != Some(&ELF_CLASS_64) {
        return Ok(());
    }
    let truncated = |what: &str, end: u64| {
        format!("truncated: its {what} end at {end} bytes, the file has {len}")
    };
    if header.len() < ELF64_HEADER_LEN {
        return Err(truncated("ELF header would", ELF64_HEADER_LEN as u64));
    }
    let big_endian = match header[5] {
        1 => false,
        2 => true,
        other => return Err(format!("not a shared library: ELF byte order {other}")),
    };
    let field = |bytes: &[u8], at: usize, width: usize| {
        let mut value = [0u8; 8];
        let source = &bytes[at..at + width];
        if big_endian {
            value[8 - width..].copy_from_slice(source);
            u64::from_be_bytes(value)
        } else {
            value[..width].copy_from_slice(source);
            u64::from_le_bytes(value)
        }
    };
    let table_offset = field(&header, 0x20, 8);
    let entry_len = field(&header, 0x36, 2);
    let entries = field(&header, 0x38, 2);
    if entries > 0 && entry_len != ELF64_PROGRAM_HEADER_LEN as u64 {
        return Err(format!(
            "not a shared library: program header entries of {entry_len} bytes (ELF64 has \
             {ELF64_PROGRAM_HEADER_LEN})"
        ));
    }
    // At most 65535 entries of 56 bytes: no overflow.
    let table_len = entries * entry_len;
    let table_end = table_offset.saturating_add(table_len);
    if table_end > len {
        return Err(truncated("program headers", table_end));
    }
    let mut table = vec![0u8; table_len as usize];
    file.seek(SeekFrom::Start(table_offset))
        .and_then(|_| file.read_exact(&mut table))
        .map_err(unreadable)?;
    let segments_end = table
        .chunks_exact(ELF64_PROGRAM_HEADER_LEN)
        .filter(|entry| field(entry, 0, 4) == u64::from(PT_LOAD))
        .map(|entry| field(entry, 8, 8).saturating_add(field(entry, 32, 8)))
        .max()
        .unwrap_or(0);
    if segments_end > len {
        return Err(truncated("ELF segments", segments_end));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime_library_path;

    /// An ELF64 little-endian header with one `PT_LOAD` segment of `segment_len` bytes from
    /// offset 0, padded to `file_len` bytes.
    fn elf_with_segment(segment_len: u64, file_len: usize) -> Vec<u8> {
        let mut bytes = vec![0u8; file_len.max(ELF64_HEADER_LEN + ELF64_PROGRAM_HEADER_LEN)];
        bytes[..4].copy_from_slice(ELF_MAGIC);
        bytes[4] = ELF_CLASS_64;
        bytes[5] = 1;
        bytes[0x20..0x28].copy_from_slice(&(ELF64_HEADER_LEN as u64).to_le_bytes());
        bytes[0x36..0x38].copy_from_slice(&(ELF64_PROGRAM_HEADER_LEN as u16).to_le_bytes());
        bytes[0x38..0x3a].copy_from_slice(&1u16.to_le_bytes());
        let entry = &mut bytes[ELF64_HEADER_LEN..];
        entry[..4].copy_from_slice(&PT_LOAD.to_le_bytes());
        entry[32..40].copy_from_slice(&segment_len.to_le_bytes());
        bytes.truncate(file_len);
        bytes
    }

    /// The installed library, when there is one (see `tests/model.rs`: required in CI).
    fn installed_library() -> Option<PathBuf> {
        let (path, _) = runtime_library_path();
        if path.is_file() {
            return Some(path);
        }
        assert!(
            std::env::var_os("LIDAR_HAR_REQUIRE_CHECKERS").is_none(),
            "{} missing: run scripts/setup.sh",
            path.display()
        );
        eprintln!("SKIP: {} missing (run scripts/setup.sh)", path.display());
        None
    }

    #[test]
    fn a_library_cut_short_is_refused_before_it_is_opened() {
        let dir = tempfile::tempdir().unwrap();
        let whole = dir.path().join("whole.so");
        std::fs::write(&whole, elf_with_segment(4096, 4096)).unwrap();
        assert!(matches!(locate(&whole, "test"), Ok(Library::File(p)) if p == whole));
        let cut = dir.path().join("cut.so");
        std::fs::write(&cut, elf_with_segment(4096, 4000)).unwrap();
        let e = locate(&cut, "test").unwrap_err();
        let text = e.to_string();
        assert!(e.is_runtime(), "{text}");
        assert!(
            text.contains(&cut.display().to_string())
                && text
                    .contains("truncated: its ELF segments end at 4096 bytes, the file has 4000")
                && text.contains("run scripts/setup.sh"),
            "{text}"
        );
        let headers_cut = dir.path().join("headers_cut.so");
        std::fs::write(&headers_cut, elf_with_segment(4096, 100)).unwrap();
        let text = locate(&headers_cut, "test").unwrap_err().to_string();
        assert!(
            text.contains("truncated: its program headers end at 120"),
            "{text}"
        );
        let not_elf = dir.path().join("not_elf.so");
        std::fs::write(&not_elf, b"<html>404</html>").unwrap();
        let text = locate(&not_elf, "test").unwrap_err().to_string();
        assert!(
            text.contains("does not start with the ELF magic number"),
            "{text}"
        );
    }

    /// The reviewer's case: half the real library, which killed the process in dlopen.
    #[test]
    fn half_of_the_installed_library_is_refused_naming_where_its_segments_end() {
        let Some(installed) = installed_library() else {
            return;
        };
        assert!(matches!(locate(&installed, "test"), Ok(Library::File(_))));
        let bytes = std::fs::read(&installed).unwrap();
        let dir = tempfile::tempdir().unwrap();
        for (name, len) in [
            ("half.so", bytes.len() / 2),
            ("tail_cut.so", bytes.len() - 4096),
        ] {
            let cut = dir.path().join(name);
            std::fs::write(&cut, &bytes[..len]).unwrap();
            let text = locate(&cut, "test").unwrap_err().to_string();
            assert!(
                text.contains(&cut.display().to_string())
                    && text.contains(&format!("the file has {len}"))
                    && text.contains("truncated: its ELF segments end at"),
                "{text}"
            );
        }
    }

    #[test]
    fn a_relative_path_is_looked_for_next_to_the_executable_first_as_ort_does() {
        let exe_dir = tempfile::tempdir().unwrap();
        std::fs::write(
            exe_dir.path().join("libonnxruntime.so"),
            elf_with_segment(128, 128),
        )
        .unwrap();
        std::fs::create_dir(exe_dir.path().join("lib")).unwrap();
        std::fs::write(
            exe_dir.path().join("lib/libonnxruntime.so"),
            elf_with_segment(128, 128),
        )
        .unwrap();
        for relative in ["libonnxruntime.so", "lib/libonnxruntime.so"] {
            let found = locate_relative(Path::new(relative), "test", exe_dir.path());
            assert!(
                matches!(&found, Ok(Library::File(p)) if *p == exe_dir.path().join(relative)),
                "{relative}: {found:?}"
            );
        }
    }

    #[test]
    fn a_bare_name_not_next_to_the_executable_goes_to_the_system_loader() {
        let exe_dir = tempfile::tempdir().unwrap();
        let found = locate_relative(Path::new("libonnxruntime.so.1"), "test", exe_dir.path());
        assert!(
            matches!(&found, Ok(Library::ByLoader(p)) if *p == Path::new("libonnxruntime.so.1")),
            "{found:?}"
        );
        // With a slash, dlopen takes it relative to the working directory.
        let e = locate_relative(
            Path::new("nowhere/libonnxruntime.so"),
            "test",
            exe_dir.path(),
        )
        .unwrap_err();
        let in_working_directory = std::env::current_dir()
            .unwrap()
            .join("nowhere/libonnxruntime.so");
        assert!(
            matches!(&e, InferError::RuntimeMissing { path, .. } if *path == in_working_directory),
            "{e}"
        );
    }

    #[test]
    fn a_directory_is_refused_asking_for_the_library_file_in_it() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("onnxruntime")).unwrap();
        let absolute = dir.path().join("onnxruntime");
        let relative = locate_relative(Path::new("onnxruntime"), "from ORT_DYLIB_PATH", dir.path());
        for e in [locate(&absolute, "from ORT_DYLIB_PATH"), relative] {
            let text = e.unwrap_err().to_string();
            assert!(
                text.contains(&format!(
                    "{} (from ORT_DYLIB_PATH) is a directory",
                    absolute.display()
                )) && text.contains("onnxruntime/libonnxruntime.so"),
                "{text}"
            );
        }
    }
}
