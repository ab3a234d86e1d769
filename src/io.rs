//! Atomic file output: nothing half-written is ever left under a final name.

use std::path::{Path, PathBuf};

/// Why an output could not be written; `path` untouched in every case. The
/// message holds the system's reason (`cause`, not a `source`: the edges
/// print an error's sources after it, which would say it twice).
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error("cannot create {}: {cause}", dir.display())]
    CreateDir { dir: PathBuf, cause: std::io::Error },
    #[error("writing {}: {message}", path.display())]
    Write { path: PathBuf, message: String },
    #[error("cannot move {} to {}: {cause}", from.display(), to.display())]
    Rename { from: PathBuf, to: PathBuf, cause: std::io::Error },
    #[error("encoding {}: {message}", path.display())]
    Encode { path: PathBuf, message: String },
}

/// Write through `write` into a temporary file beside `path`, then rename it
/// over `path`. On failure the temporary file is removed and `path` is untouched.
pub fn write_atomically<E: std::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), WriteError> {
    let tmp = temporary_beside(path);
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|cause| WriteError::CreateDir { dir: dir.to_path_buf(), cause })?;
    }
    if let Err(e) = write(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(WriteError::Write { path: path.to_path_buf(), message: e.to_string() });
    }
    std::fs::rename(&tmp, path).map_err(|cause| {
        let _ = std::fs::remove_file(&tmp);
        WriteError::Rename { from: tmp.clone(), to: path.to_path_buf(), cause }
    })
}

/// Write bytes atomically.
pub fn write_bytes_atomically(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_atomically(path, |tmp| std::fs::write(tmp, bytes))
}

const TEMPORARY_PREFIX: &str = ".filterjit.tmp-";

fn temporary_beside(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    // Keep the extension last: some writers pick the format from it.
    path.with_file_name(format!("{TEMPORARY_PREFIX}{}-{name}", std::process::id()))
}

/// Remove temporary files a killed process left in `dir` (never a final file).
pub fn remove_stale_temporaries(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        if entry.file_name().to_string_lossy().starts_with(TEMPORARY_PREFIX) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}
