//! Where the bytes of a bag's storage file are read from.

use std::path::{Path, PathBuf};
use std::sync::Arc;

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
    _copy: Option<Arc<tempfile::TempDir>>,
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
        let dir = tempfile::Builder::new()
            .prefix("lidar-har-bag-")
            .tempdir()
            .map_err(io_error(&self.path, failed))?;
        let bytes = dir.path().join(name);
        make(&bytes).map_err(io_error(&self.path, failed))?;
        Ok(Self {
            path: self.path.clone(),
            bytes,
            _copy: Some(Arc::new(dir)),
        })
    }
}
