//! Where a recording goes, and the stream that sends it there.

use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use rerun::{RecordingStream, RecordingStreamBuilder};

use crate::rrd_file::RrdFile;
use crate::VizError;

/// Version of the Rerun SDK compiled in; a viewer must have the same version.
pub const SDK_VERSION: &str = "0.36.3";

/// Default logging rate of simulated time, frames per simulated second.
pub const DEFAULT_HZ: f64 = 60.0;

/// Default viewer address for `connect`.
const DEFAULT_ADDR: &str = "127.0.0.1:9876";

/// Where `--rerun` sends the recording.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// Write an `.rrd` file (`save:FILE`); `None` = the command's default name.
    Save(Option<PathBuf>),
    /// Start a viewer (`rerun` on PATH) and stream to it.
    Spawn,
    /// Stream to a running viewer at `HOST:PORT` (or a full `rerun+http://` URL).
    Connect(String),
}

impl FromStr for Target {
    type Err = VizError;

    fn from_str(s: &str) -> Result<Self, VizError> {
        let bad = |reason: &str| VizError::BadTarget {
            given: s.to_string(),
            reason: reason.to_string(),
        };
        let s_trim = s.trim();
        match s_trim {
            "" | "save" => return Ok(Self::Save(None)),
            "spawn" => return Ok(Self::Spawn),
            "connect" => return Ok(Self::Connect(DEFAULT_ADDR.to_string())),
            _ => {}
        }
        if let Some(file) = s_trim.strip_prefix("save:") {
            if file.is_empty() {
                return Err(bad("no file name after `save:`"));
            }
            return Ok(Self::Save(Some(PathBuf::from(file))));
        }
        if let Some(addr) = s_trim.strip_prefix("connect:") {
            if addr.is_empty() {
                return Err(bad("no address after `connect:`"));
            }
            if !addr.contains("://") && !addr.contains(':') {
                return Err(bad(
                    "the address needs a port, e.g. `connect:127.0.0.1:9876`",
                ));
            }
            return Ok(Self::Connect(addr.to_string()));
        }
        if s_trim.ends_with(".rrd") {
            return Ok(Self::Save(Some(PathBuf::from(s_trim))));
        }
        Err(bad("unknown target"))
    }
}

impl Target {
    /// The `rerun+http://.../proxy` URL of a `Connect` address.
    fn url(addr: &str) -> String {
        if addr.contains("://") {
            addr.to_string()
        } else {
            format!("rerun+http://{addr}/proxy")
        }
    }
}

/// The recording stream of one command, with its failure reported once.
#[derive(Debug)]
pub struct Recorder {
    sink: Sink,
    target: Target,
    /// `(temporary, final)` paths of a file recording.
    file: Option<(PathBuf, PathBuf)>,
    hz: f64,
}

/// The logging half of a [`Recorder`]: the stream and the say-it-once flag. Cheap to
/// clone and usable from another thread (the arm logger draws on one of its own);
/// every clone shares the flag, so a failure is still reported once.
#[derive(Debug, Clone)]
pub struct Sink {
    stream: RecordingStream,
    warned: Arc<AtomicBool>,
}

impl Sink {
    /// True when something is being recorded.
    pub fn is_enabled(&self) -> bool {
        self.stream.is_enabled()
    }

    /// The stream (for the loggers of this crate).
    pub(crate) fn stream(&self) -> &RecordingStream {
        &self.stream
    }

    /// Marks a failure as reported; true when one was reported before.
    fn warn_once(&self) -> bool {
        self.warned.swap(true, Ordering::Relaxed)
    }

    /// Reports a logging failure once; later failures are silent.
    pub(crate) fn report<E: std::fmt::Display>(&self, what: &str, result: Result<(), E>) {
        if let Err(e) = result {
            if !self.warn_once() {
                eprintln!(
                    "rerun: {what} failed ({e}); the run goes on, the recording may be incomplete"
                );
            }
        }
    }
}

impl Recorder {
    /// Opens the recording `name` of application `longreach` at `target`, logging at
    /// `hz` frames per simulated second. `default_file` names the `.rrd` when the
    /// target is a bare `save`. A viewer that cannot be started or reached gives a
    /// recorder that logs nothing and says why once (the run goes on); a file that
    /// cannot be created is an error.
    pub fn start(
        name: &str,
        target: &Target,
        default_file: &Path,
        hz: f64,
    ) -> Result<Self, VizError> {
        if !(hz.is_finite() && hz > 0.0) {
            return Err(VizError::BadRate(hz));
        }
        let builder = RecordingStreamBuilder::new("longreach").recording_name(name);
        let mut file = None;
        let warned = Arc::new(AtomicBool::new(false));
        let rec = match target {
            Target::Save(path) => {
                let final_path = path.clone().unwrap_or_else(|| default_file.to_path_buf());
                let tmp = temp_beside(&final_path);
                let bad_file = |reason: String| VizError::File {
                    path: final_path.clone(),
                    reason,
                };
                let sink = RrdFile::create(&tmp, Arc::clone(&warned)).map_err(bad_file)?;
                let rec = builder.buffered().map_err(|e| bad_file(e.to_string()))?;
                rec.set_sink(Box::new(sink));
                file = Some((tmp, final_path));
                rec
            }
            Target::Spawn => match builder.spawn() {
                Ok(rec) => rec,
                Err(e) => {
                    eprintln!(
                        "rerun: could not start a viewer ({e}); install one with `pip install rerun-sdk=={SDK_VERSION}` \
                         (or `cargo install rerun-cli@{SDK_VERSION} --locked`) so that `rerun` is on PATH, \
                         or use `--rerun save:FILE.rrd`; the run goes on without Rerun"
                    );
                    return Ok(Self::disabled(target.clone(), hz, true));
                }
            },
            Target::Connect(addr) => match builder.connect_grpc_opts(Target::url(addr)) {
                Ok(rec) => rec,
                Err(e) => {
                    eprintln!(
                        "rerun: cannot connect to a viewer at {addr} ({e}); start one with `rerun` or use \
                         `--rerun save:FILE.rrd`; the run goes on without Rerun"
                    );
                    return Ok(Self::disabled(target.clone(), hz, true));
                }
            },
        };
        Ok(Self {
            sink: Sink {
                stream: rec,
                warned,
            },
            target: target.clone(),
            file,
            hz,
        })
    }

    /// A recorder that logs nothing (no `--rerun`).
    pub fn off() -> Self {
        Self::disabled(Target::Save(None), DEFAULT_HZ, false)
    }

    fn disabled(target: Target, hz: f64, warned: bool) -> Self {
        Self {
            sink: Sink {
                stream: RecordingStream::disabled(),
                warned: Arc::new(AtomicBool::new(warned)),
            },
            target,
            file: None,
            hz,
        }
    }

    /// True when something is being recorded.
    pub fn is_enabled(&self) -> bool {
        self.sink.is_enabled()
    }

    /// Logging rate, frames per simulated second.
    pub fn hz(&self) -> f64 {
        self.hz
    }

    /// The stream and the say-it-once flag, to log from (also from another thread).
    pub fn sink(&self) -> &Sink {
        &self.sink
    }

    /// The stream (for the loggers of this crate).
    pub(crate) fn stream(&self) -> &RecordingStream {
        self.sink.stream()
    }

    /// Reports a logging failure once; later failures are silent.
    pub(crate) fn report<E: std::fmt::Display>(&self, what: &str, result: Result<(), E>) {
        self.sink.report(what, result);
    }

    /// [`Recorder::finish`] on a thread of its own, so that a command can write its
    /// other outputs while Rerun encodes the last frames and writes the file's footer
    /// (a fixed few milliseconds per recording); wait on the result before exiting.
    pub fn finish_in_background(self) -> Closing {
        let slot = std::sync::Arc::new(std::sync::Mutex::new(Some(self)));
        let theirs = std::sync::Arc::clone(&slot);
        let spawned = std::thread::Builder::new()
            .name("rerun-close".into())
            .spawn(move || {
                let rec = theirs.lock().ok().and_then(|mut r| r.take());
                rec.and_then(Recorder::finish)
            });
        match spawned {
            Ok(handle) => Closing(Some(handle), None),
            // No thread: close here.
            Err(_) => {
                let rec = slot.lock().ok().and_then(|mut r| r.take());
                Closing(None, rec.and_then(Recorder::finish))
            }
        }
    }

    /// Closes a recording that has nothing to show because the command failed before
    /// logging (e.g. `modes` on an arm it cannot linearise): a file is removed instead
    /// of left half-named; a viewer's stream is closed as by [`Recorder::finish`].
    pub fn discard(mut self) {
        match self.file.take() {
            Some((tmp, _)) if self.sink.is_enabled() => {
                self.sink.stream.disconnect();
                let _ = std::fs::remove_file(&tmp);
            }
            _ => {
                self.finish();
            }
        }
    }

    /// Flushes everything; for a file, moves the finished recording to its name and
    /// returns that path. A viewer that did not answer is reported once.
    pub fn finish(mut self) -> Option<PathBuf> {
        if !self.sink.is_enabled() {
            return None;
        }
        let flushed = self.sink.stream.flush_with_timeout(Duration::from_secs(5));
        if let Err(e) = &flushed {
            let addr = match &self.target {
                Target::Connect(a) => Some(a.clone()),
                Target::Spawn => Some("the spawned viewer".to_string()),
                Target::Save(_) => None,
            };
            if let Some(addr) = addr {
                // Disconnecting (or dropping) would wait for the viewer forever: leave
                // the stream to the process exit instead.
                let warned = self.sink.warn_once();
                std::mem::forget(self);
                if !warned {
                    eprintln!(
                        "rerun: the viewer at {addr} did not take the recording ({e}); is it running \
                         (`rerun`, version {SDK_VERSION})? The simulation results are unaffected"
                    );
                }
                return None;
            } else {
                self.report("writing the recording", Err::<(), _>(e.to_string()));
            }
        }
        self.sink.stream.disconnect();
        let (tmp, final_path) = self.file.take()?;
        // Renaming over an earlier recording makes ext4 (auto_da_alloc) allocate the
        // new file's blocks at once: 26 ms for a 12 MB Bode recording, measured. The
        // old one is removed first (a failure to remove shows in the rename's error).
        let _ = std::fs::remove_file(&final_path);
        match std::fs::rename(&tmp, &final_path) {
            Ok(()) => Some(final_path),
            Err(e) => {
                eprintln!(
                    "rerun: could not move {} to {}: {e}",
                    tmp.display(),
                    final_path.display()
                );
                None
            }
        }
    }
}

/// A recorder dropped without [`Recorder::finish`] or [`Recorder::discard`] belongs to a
/// command that failed after it started (a bad dataset, a non-finite result): its file
/// is removed, never left half-written beside the name it would have had.
impl Drop for Recorder {
    fn drop(&mut self) {
        if let Some((tmp, _)) = self.file.take() {
            self.sink.stream.disconnect();
            let _ = std::fs::remove_file(&tmp);
        }
    }
}

/// A recording being closed on a thread of its own ([`Recorder::finish_in_background`]).
/// [`Closing::wait`] (or dropping it) waits until the file is complete and renamed.
#[derive(Debug)]
pub struct Closing(
    Option<std::thread::JoinHandle<Option<PathBuf>>>,
    Option<PathBuf>,
);

impl Closing {
    /// Waits for the recording to be closed; what [`Recorder::finish`] returns.
    pub fn wait(mut self) -> Option<PathBuf> {
        self.join()
    }

    fn join(&mut self) -> Option<PathBuf> {
        match self.0.take() {
            Some(handle) => handle.join().unwrap_or_else(|_| {
                eprintln!("rerun: closing the recording failed (its thread panicked)");
                None
            }),
            None => self.1.take(),
        }
    }
}

impl Drop for Closing {
    fn drop(&mut self) {
        self.join();
    }
}

/// `dir/.name.partial` beside `path`.
fn temp_beside(path: &Path) -> PathBuf {
    let name = path.file_name().map_or_else(
        || "recording.rrd".into(),
        |n| n.to_string_lossy().into_owned(),
    );
    path.with_file_name(format!(".{name}.partial"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_parse_and_bad_ones_say_what_to_write() {
        assert_eq!("".parse::<Target>().unwrap(), Target::Save(None));
        assert_eq!(
            "save:out/a.rrd".parse::<Target>().unwrap(),
            Target::Save(Some("out/a.rrd".into()))
        );
        assert_eq!(
            "b.rrd".parse::<Target>().unwrap(),
            Target::Save(Some("b.rrd".into()))
        );
        assert_eq!("spawn".parse::<Target>().unwrap(), Target::Spawn);
        assert_eq!(
            "connect".parse::<Target>().unwrap(),
            Target::Connect("127.0.0.1:9876".into())
        );
        assert_eq!(
            "connect:10.0.0.2:9000".parse::<Target>().unwrap(),
            Target::Connect("10.0.0.2:9000".into())
        );
        assert_eq!(
            Target::url("10.0.0.2:9000"),
            "rerun+http://10.0.0.2:9000/proxy"
        );
        for bad in ["sav:x", "connect:host", "save:", "viewer"] {
            let e = bad.parse::<Target>().unwrap_err().to_string();
            assert!(e.contains(bad) && e.contains("save:FILE.rrd"), "{e}");
        }
    }

    #[test]
    fn a_missing_folder_is_an_error_before_the_run_and_a_bad_rate_too() {
        let e = Recorder::start(
            "t",
            &Target::Save(Some("/nonexistent-dir/x.rrd".into())),
            Path::new("x.rrd"),
            60.0,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("/nonexistent-dir/x.rrd") && e.contains("folder"),
            "{e}"
        );
        let e = Recorder::start("t", &Target::Save(None), Path::new("x.rrd"), 0.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("--rerun-hz"), "{e}");
    }

    #[test]
    fn a_recorder_dropped_unfinished_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("failed.rrd");
        let r =
            Recorder::start("t", &Target::Save(Some(path.clone())), Path::new("x"), 30.0).unwrap();
        r.report("test", Ok::<(), String>(()));
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "its .partial"
        );
        drop(r);
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert!(left.is_empty(), "left behind: {left:?}");
    }

    #[test]
    fn an_unreachable_viewer_does_not_fail_and_the_file_is_renamed_when_done() {
        // Nothing listens on port 1: the recorder starts (connection is lazy) and
        // finishing reports once instead of failing.
        let r = Recorder::start(
            "t",
            &Target::Connect("127.0.0.1:1".into()),
            Path::new("x"),
            60.0,
        )
        .unwrap();
        assert_eq!(r.finish(), None);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.rrd");
        let r =
            Recorder::start("t", &Target::Save(Some(path.clone())), Path::new("x"), 30.0).unwrap();
        assert!(r.is_enabled());
        assert!((r.hz() - 30.0).abs() < 1e-12);
        assert!(!path.exists(), "written beside its name until finished");
        assert_eq!(r.finish(), Some(path.clone()));
        assert!(std::fs::metadata(&path).unwrap().len() > 0);
        // Closed in the background: complete and renamed once waited for, or dropped.
        for (k, wait) in [(0, true), (1, false)] {
            let path = dir.path().join(format!("bg{k}.rrd"));
            let r = Recorder::start("t", &Target::Save(Some(path.clone())), Path::new("x"), 30.0)
                .unwrap();
            r.report("test", Ok::<(), String>(()));
            let closing = r.finish_in_background();
            if wait {
                assert_eq!(closing.wait(), Some(path.clone()));
            } else {
                drop(closing);
            }
            assert!(std::fs::metadata(&path).unwrap().len() > 0, "{k}");
            assert!(!temp_beside(&path).exists(), "{k}");
        }
    }
}
