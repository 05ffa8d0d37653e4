//! Writing result files atomically (through `longreach_scenario::atomic`, the one
//! helper): a failed run leaves nothing half-written, and nothing of the user's is
//! replaced by surprise.

use std::path::Path;

use anyhow::Result;
use longreach_scenario::atomic;

/// Writes `bytes` to `path` through a temporary file, fsync and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    Ok(atomic::write_file(path, bytes)?)
}

/// Runs `write` on a temporary path beside `path`, then flushes and renames it into
/// place; the temporary is removed on any error.
pub fn write_atomic_with(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    Ok(atomic::write_file_with(path, |p| {
        write(p)
            .map_err(|e| -> Box<dyn std::error::Error + Send + Sync> { format!("{e:#}").into() })
    })?)
}

/// Creates the output folder `dir` (or accepts it when it exists as a folder), with a
/// message that names the flag and the fix.
pub fn output_dir(dir: &Path, flag: &str) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        anyhow::bail!(
            "{flag} {}: it exists and is not a folder\n  fix: give a folder path for {flag} (the file is left as it is)",
            dir.display()
        );
    }
    std::fs::create_dir_all(dir).map_err(|e| {
        anyhow::anyhow!(
            "{flag} {}: cannot create the folder: {e}\n  fix: check that its parent is writable",
            dir.display()
        )
    })
}

/// Checks, before the work, that the file of `flag` can be written at `path`: its
/// folder exists and the path is not itself a folder. A fit or a diagnosis that runs
/// for a minute must not end on a path it cannot write, its result lost.
pub fn check_output_file(path: &Path, flag: &str) -> Result<()> {
    if path.is_dir() {
        anyhow::bail!(
            "{flag} {}: it is an existing folder\n  fix: give a file name (e.g. inside that folder)",
            path.display()
        );
    }
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !folder.is_dir() {
        anyhow::bail!(
            "{flag} {}: the folder {} does not exist\n  fix: create it first (mkdir -p {}) or give another path; nothing was run",
            path.display(),
            folder.display(),
            folder.display()
        );
    }
    Ok(())
}
