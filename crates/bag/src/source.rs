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
/// from then on: for a process about to end on a signal (SIGINT, SIGTERM), which runs no
/// destructors and would leave the copies in `$TMPDIR`.
pub fn remove_temporary_copies() {
    let mut copies = copies();
    copies.removed = true;
    for dir in copies.dirs.drain(..) {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// A directory of temporary copies, deleted when dropped.
struct CopyDir(PathBuf);

impl CopyDir {
    /// Made and listed under the lock, so that a signal cannot come between the two.
    fn new() -> std::io::Result<Self> {
        let mut copies = copies();
        if copies.removed {
            return Err(std::io::Error::other(
                "the process is ending (its temporary copies were removed)",
            ));
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
