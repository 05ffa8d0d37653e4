//! Writing result files atomically: a failed run leaves nothing half-written.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// A temporary path beside `path` with the same extension (some writers need it).
pub fn temp_beside(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    let ext = path
        .extension()
        .map_or_else(String::new, |e| format!(".{}", e.to_string_lossy()));
    path.with_file_name(format!(".{name}.{}.partial{ext}", std::process::id()))
}

/// Writes `bytes` to `path` through a temporary file and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_beside(path);
    std::fs::write(&tmp, bytes).with_context(|| {
        format!(
            "cannot write {} (does its directory exist?)",
            path.display()
        )
    })?;
    std::fs::rename(&tmp, path)
        .with_context(|| format!("cannot move the result into {}", path.display()))
}

/// Runs `write` on a temporary path beside `path`, then renames it into place.
pub fn write_atomic_with(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let tmp = temp_beside(path);
    match write(&tmp) {
        Ok(()) => std::fs::rename(&tmp, path)
            .with_context(|| format!("cannot move the result into {}", path.display())),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}
