//! The one way longreach writes a file or a folder: through a temporary beside the
//! target, flushed to disk (`fsync`) before it is renamed into place, and removed on
//! every error path. Nothing half-written is ever left where the user looks, and a
//! target that exists and is not ours is refused, never replaced.

use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// A failed write: the path, what was being done, and the cause.
#[derive(Debug)]
pub struct WriteError {
    /// The file or folder being written (the target, not the temporary).
    pub path: PathBuf,
    /// What failed ("write", "move into place", ...).
    pub action: &'static str,
    /// What to do about it.
    pub fix: String,
    /// The underlying error, when there is one.
    pub source: Option<io::Error>,
}

impl std::fmt::Display for WriteError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "cannot {} {}", self.action, self.path.display())?;
        if let Some(e) = &self.source {
            write!(f, ": {e}")?;
        }
        if !self.fix.is_empty() {
            write!(f, "\n  fix: {}", self.fix)?;
        }
        Ok(())
    }
}

// The message already quotes the cause: no `source()`, or `{:#}` would print it twice.
impl std::error::Error for WriteError {}

fn err(path: &Path, action: &'static str, fix: &str, source: io::Error) -> WriteError {
    WriteError {
        path: path.to_path_buf(),
        action,
        fix: fix.to_string(),
        source: Some(source),
    }
}

const FIX_DIR: &str = "check that the folder exists and is writable, and that the disk has room";

/// The temporary name beside `path`: hidden, with the process id, ending in
/// `.partial` and then the target's own extension (some writers go by it).
pub fn temp_beside(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "out".into(), |n| n.to_string_lossy().into_owned());
    let ext = path
        .extension()
        .map_or_else(String::new, |e| format!(".{}", e.to_string_lossy()));
    path.with_file_name(format!(".{name}.{}.partial{ext}", std::process::id()))
}

/// Refuses an output file path that is an existing folder (it would not be replaced
/// by a file, and a folder is never ours to remove).
pub fn check_file_target(path: &Path) -> Result<(), WriteError> {
    if path.is_dir() {
        return Err(WriteError {
            path: path.to_path_buf(),
            action: "write the file",
            fix: "it is an existing folder: give a file name (e.g. inside that folder)".into(),
            source: None,
        });
    }
    Ok(())
}

fn sync_dir(dir: &Path) {
    // Makes the rename itself durable; not every platform or file system allows it.
    if let Ok(d) = File::open(dir) {
        let _ = d.sync_all();
    }
}

fn parent_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Writes `bytes` to `path` atomically (see the module docs).
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_file_with(path, |tmp| -> io::Result<()> {
        let mut f = File::create(tmp)?;
        f.write_all(bytes)?;
        Ok(())
    })
}

/// Runs `write` on a temporary path beside `path`, flushes it to disk and renames it
/// into place; on any error the temporary is removed and `path` is left as it was.
pub fn write_file_with<E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), WriteError>
where
    E: Into<Box<dyn std::error::Error + Send + Sync>>,
{
    check_file_target(path)?;
    let tmp = temp_beside(path);
    let result = write(&tmp)
        .map_err(|e| {
            let e: Box<dyn std::error::Error + Send + Sync> = e.into();
            err(path, "write", FIX_DIR, io::Error::other(e.to_string()))
        })
        .and_then(|()| {
            File::open(&tmp)
                .and_then(|f| f.sync_all())
                .map_err(|e| err(path, "write", FIX_DIR, e))
        })
        .and_then(|()| {
            fs::rename(&tmp, path).map_err(|e| err(path, "move into place", FIX_DIR, e))
        });
    match result {
        Ok(()) => {
            sync_dir(&parent_of(path));
            Ok(())
        }
        Err(e) => {
            let _ = fs::remove_file(&tmp);
            Err(e)
        }
    }
}

/// Checks an output folder before anything is computed for it: `Ok(false)` when it
/// does not exist, `Ok(true)` when it is an empty folder or one for which `ours`
/// returns true (it may be replaced); anything else is refused with `fix_not_ours`.
pub fn check_dir_target(
    dir: &Path,
    ours: impl Fn(&Path) -> bool,
    fix_not_ours: &str,
) -> Result<bool, WriteError> {
    let refuse = |what: &str| WriteError {
        path: dir.to_path_buf(),
        action: "write into",
        fix: format!("{what}; {fix_not_ours}"),
        source: None,
    };
    match fs::symlink_metadata(dir) {
        Ok(m) if m.is_dir() => {
            let empty = fs::read_dir(dir).is_ok_and(|mut r| r.next().is_none());
            if !empty && !ours(dir) {
                return Err(refuse("it is an existing folder that is not ours"));
            }
            Ok(true)
        }
        Ok(_) => Err(refuse("it exists and is not a folder")),
        Err(_) => Ok(false),
    }
}

/// Fills a fresh temporary folder beside `dir` with `fill`, flushes every file in it to
/// disk, and moves it into place. `dir` may be missing, or an existing folder for which
/// `ours` returns true (it is then replaced, and only once the new one is complete);
/// anything else is refused with `fix_not_ours`, and nothing is touched.
pub fn replace_dir<E>(
    dir: &Path,
    ours: impl Fn(&Path) -> bool,
    fix_not_ours: &str,
    fill: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E>
where
    E: From<WriteError>,
{
    let existing = check_dir_target(dir, &ours, fix_not_ours)?;
    let refuse = |what: &str| WriteError {
        path: dir.to_path_buf(),
        action: "write into",
        fix: format!("{what}; {fix_not_ours}"),
        source: None,
    };
    let parent = parent_of(dir);
    let base = dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .ok_or_else(|| refuse("the path has no folder name"))?;
    fs::create_dir_all(&parent).map_err(|e| err(&parent, "create", FIX_DIR, e))?;
    let tmp = parent.join(format!(".{base}.{}.partial", std::process::id()));
    let aside = parent.join(format!(".{base}.{}.old", std::process::id()));
    let cleanup = |p: &Path| {
        let _ = fs::remove_dir_all(p);
    };
    cleanup(&tmp);
    fs::create_dir(&tmp).map_err(|e| err(dir, "create a temporary folder beside", FIX_DIR, e))?;
    if let Err(e) = fill(&tmp) {
        cleanup(&tmp);
        return Err(e);
    }
    let synced = fs::read_dir(&tmp).and_then(|entries| {
        for entry in entries {
            let entry = entry?;
            if entry.file_type()?.is_file() {
                File::open(entry.path())?.sync_all()?;
            }
        }
        Ok(())
    });
    if let Err(e) = synced {
        cleanup(&tmp);
        return Err(err(dir, "write", FIX_DIR, e).into());
    }
    sync_dir(&tmp);
    if existing {
        if let Err(e) = fs::rename(dir, &aside) {
            cleanup(&tmp);
            return Err(err(dir, "move aside the previous", FIX_DIR, e).into());
        }
    }
    if let Err(e) = fs::rename(&tmp, dir) {
        if existing {
            let _ = fs::rename(&aside, dir);
        }
        cleanup(&tmp);
        return Err(err(dir, "move into place", FIX_DIR, e).into());
    }
    sync_dir(&parent);
    if existing {
        // The previous folder was ours (checked above); a failure to remove it leaves
        // it hidden beside the new one, which is reported.
        fs::remove_dir_all(&aside)
            .map_err(|e| err(&aside, "remove the previous", "remove it by hand", e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_written_and_no_temporary_left() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.json");
        write_file(&p, b"{}").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"{}");
        let failed: Result<(), WriteError> =
            write_file_with(&p, |_| Err::<(), _>(io::Error::other("boom")));
        assert!(failed.is_err());
        assert_eq!(fs::read(&p).unwrap(), b"{}", "the old file is kept");
        let names: Vec<_> = fs::read_dir(d.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "no temporary left");
    }

    #[test]
    fn folder_not_ours_is_refused_and_kept() {
        let d = tempfile::tempdir().unwrap();
        let target = d.path().join("photos");
        fs::create_dir(&target).unwrap();
        fs::write(target.join("cat.jpg"), b"meow").unwrap();
        let r: Result<(), WriteError> = replace_dir(
            &target,
            |_| false,
            "choose another",
            |t| fs::write(t.join("x"), b"1").map_err(|e| err(t, "write", "", e)),
        );
        let e = r.unwrap_err().to_string();
        assert!(e.contains("not ours"), "{e}");
        assert_eq!(fs::read(target.join("cat.jpg")).unwrap(), b"meow");
        assert_eq!(fs::read_dir(d.path()).unwrap().count(), 1);
        // A file as the target is refused too.
        let file = d.path().join("notes.txt");
        fs::write(&file, b"keep").unwrap();
        let r: Result<(), WriteError> = replace_dir(&file, |_| true, "x", |_| Ok(()));
        assert!(r.is_err());
        assert_eq!(fs::read(&file).unwrap(), b"keep");
    }

    #[test]
    fn folder_ours_is_replaced_whole() {
        let d = tempfile::tempdir().unwrap();
        let target = d.path().join("ds");
        fs::create_dir(&target).unwrap();
        fs::write(target.join("old"), b"1").unwrap();
        replace_dir::<WriteError>(
            &target,
            |_| true,
            "",
            |t| fs::write(t.join("new"), b"2").map_err(|e| err(t, "write", "", e)),
        )
        .unwrap();
        assert!(!target.join("old").exists());
        assert!(target.join("new").exists());
        assert_eq!(fs::read_dir(d.path()).unwrap().count(), 1);
    }
}
