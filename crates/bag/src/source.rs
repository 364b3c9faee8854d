//! Where the bytes of a bag's storage file are read from.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use crate::error::{Result, io_error};

/// A storage file of a bag, and the file its bytes are read from: the file itself, or a
/// private copy when the file cannot be read as it is (compressed by rosbag2, or a sqlite file
/// with a hot journal) and must not be changed. The copy's directory is deleted when the last
/// storage file or message stream holding it is dropped.
#[derive(Clone)]
pub(crate) struct StorageSource {
    /// The bag's file, named in errors.
    pub(crate) path: PathBuf,
    /// The file that is opened: `path`, or the copy.
    pub(crate) bytes: PathBuf,
    _copy: Option<Arc<CopyDir>>,
}

impl StorageSource {
    pub(crate) fn file(path: &Path) -> Self {
        Self {
            path: path.to_path_buf(),
            bytes: path.to_path_buf(),
            _copy: None,
        }
    }

    /// A copy of this source in a new directory under `$TMPDIR`, named `name` there, that
    /// `make` writes; `failed` says in an error what the copy was for and what else to do.
    pub(crate) fn copy(
        &self,
        name: &str,
        failed: &'static str,
        make: impl FnOnce(&Path) -> std::io::Result<()>,
    ) -> Result<Self> {
        let dir = CopyDir::new().map_err(io_error(&self.path, failed))?;
        let bytes = dir.0.join(name);
        make(&bytes).map_err(io_error(&self.path, failed))?;
        Ok(Self {
            path: self.path.clone(),
            bytes,
            _copy: Some(Arc::new(dir)),
        })
    }
}

/// The directories of this process's temporary copies. A copy is as large as its storage file
/// uncompressed, and a process ended by a signal runs no destructors: its signal handler calls
/// [`remove_temporary_copies`] first.
static COPIES: Mutex<Copies> = Mutex::new(Copies {
    dirs: Vec::new(),
    removed: false,
});

struct Copies {
    dirs: Vec<PathBuf>,
    /// The process is ending: a copy made now would be left behind.
    removed: bool,
}

fn copies() -> MutexGuard<'static, Copies> {
    COPIES.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Deletes the temporary copies of storage files (rosbag2 `.zstd` files decompressed, sqlite
/// files rolled back) that this process holds, and makes opening a file that needs one fail
/// from then on, a copy being written included: for a process about to end on a signal
/// (SIGINT, SIGTERM), which runs no destructors and would leave the copies in `$TMPDIR`, or
/// would otherwise finish decompressing a large file first.
pub fn remove_temporary_copies() {
    let mut copies = copies();
    copies.removed = true;
    for dir in copies.dirs.drain(..) {
        let _ = std::fs::remove_dir_all(dir);
    }
}

fn ending() -> bool {
    copies().removed
}

/// What a read says that failed because [`remove_temporary_copies`] was called meanwhile.
pub const PROCESS_ENDING: &str = "the process is ending (its temporary copies were removed)";

/// Copies `from` into `to` as `std::io::copy` does, but in pieces, and fails between two once
/// `ending` says so: a copy is as large as a storage file uncompressed, seconds to write.
pub(crate) fn copy_unless_ending(
    from: &mut impl std::io::Read,
    to: &mut impl std::io::Write,
    ending: impl Fn() -> bool,
) -> std::io::Result<u64> {
    let mut piece = vec![0u8; 1 << 20];
    let mut copied = 0u64;
    loop {
        if ending() {
            return Err(std::io::Error::other(PROCESS_ENDING));
        }
        let read = match from.read(&mut piece) {
            Ok(0) => return Ok(copied),
            Ok(read) => read,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        to.write_all(&piece[..read])?;
        copied += read as u64;
    }
}

/// [`copy_unless_ending`] until [`remove_temporary_copies`] is called.
pub(crate) fn copy_for_temporary(
    from: &mut impl std::io::Read,
    to: &mut impl std::io::Write,
) -> std::io::Result<u64> {
    copy_unless_ending(from, to, ending)
}

/// A directory of temporary copies, deleted when dropped.
struct CopyDir(PathBuf);

impl CopyDir {
    /// Made and listed under the lock, so that a signal cannot come between the two.
    fn new() -> std::io::Result<Self> {
        let mut copies = copies();
        if copies.removed {
            return Err(std::io::Error::other(PROCESS_ENDING));
        }
        let dir = tempfile::Builder::new()
            .prefix("lidar-har-bag-")
            .tempdir()?
            .keep();
        copies.dirs.push(dir.clone());
        Ok(Self(dir))
    }
}

impl Drop for CopyDir {
    fn drop(&mut self) {
        let mut copies = copies();
        copies.dirs.retain(|dir| *dir != self.0);
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    #[test]
    fn a_copy_stops_between_pieces_once_the_process_is_ending() {
        let looks = Cell::new(0);
        let ending = || {
            looks.set(looks.get() + 1);
            looks.get() > 3
        };
        let mut endless = std::io::repeat(7);
        let mut written = Vec::new();
        let err = copy_unless_ending(&mut endless, &mut written, ending).unwrap_err();
        assert!(err.to_string().contains("the process is ending"), "{err}");
        assert_eq!(written.len(), 3 << 20);
    }

    #[test]
    fn a_copy_left_alone_copies_everything() {
        let data: Vec<u8> = (0..3_000_000u32).map(|i| i as u8).collect();
        let mut written = Vec::new();
        let copied = copy_unless_ending(&mut data.as_slice(), &mut written, || false).unwrap();
        assert_eq!(copied, data.len() as u64);
        assert_eq!(written, data);
    }
}
