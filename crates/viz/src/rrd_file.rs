//! The `.rrd` writer of `--rerun save:FILE`: Rerun's own encoder (same format, same
//! footer manifest as `rerun::sink::FileSink`), with the chunks stored uncompressed.
//!
//! Rerun's `FileSink` always LZ4-compresses each chunk on a writer thread of its own.
//! Measured on the 10 s fast arm (callgrind, docs/rerun.md#cost), compression was a
//! third of the writer's instructions, and the writer's work is what a recorded run
//! waits for when the file is closed; the file is about twice as large without it
//! (about 1 MB per 10 s of the fast arm at 60 Hz). This sink encodes on the thread
//! that forwards Rerun's chunks (the recording stream's own), so there is no extra
//! hop, and writes through a buffer. Dropping it writes the footer.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rerun::external::re_log_encoding::{CrateVersion, Encoder, EncodingOptions};
use rerun::log::LogMsg;
use rerun::sink::{LogSink, SinkFlushError};

use crate::SDK_VERSION;

type FileEncoder = Encoder<BufWriter<File>>;

/// An uncompressed `.rrd` file sink; failures are reported once through `warned`.
pub(crate) struct RrdFile {
    path: PathBuf,
    encoder: Mutex<Option<FileEncoder>>,
    warned: Arc<AtomicBool>,
}

impl RrdFile {
    /// Creates `path` and writes the stream header.
    pub(crate) fn create(path: &Path, warned: Arc<AtomicBool>) -> Result<Self, String> {
        let file = File::create(path).map_err(|e| e.to_string())?;
        let encoder = Encoder::new_eager(
            CrateVersion::parse(SDK_VERSION),
            EncodingOptions::PROTOBUF_UNCOMPRESSED,
            BufWriter::with_capacity(1 << 16, file),
        )
        .map_err(|e| e.to_string())?;
        Ok(Self {
            path: path.to_path_buf(),
            encoder: Mutex::new(Some(encoder)),
            warned,
        })
    }

    /// Runs `f` on the encoder; the first failure is printed, later ones are silent.
    fn with_encoder<E: std::fmt::Display>(
        &self,
        what: &str,
        f: impl FnOnce(&mut FileEncoder) -> Result<(), E>,
    ) -> Result<(), String> {
        let mut guard = self
            .encoder
            .lock()
            .map_err(|_| "the encoder's lock is poisoned".to_string())?;
        let Some(encoder) = guard.as_mut() else {
            return Ok(());
        };
        f(encoder).map_err(|e| {
            let message = format!("{what} {}: {e}", self.path.display());
            if !self.warned.swap(true, Ordering::Relaxed) {
                eprintln!("rerun: {message}; the run goes on, the recording may be incomplete");
            }
            message
        })
    }
}

impl LogSink for RrdFile {
    fn send(&self, msg: LogMsg) {
        let _ = self.with_encoder("writing", |e| e.append(&msg).map(|_| ()));
    }

    fn flush_blocking(&self, _timeout: Duration) -> Result<(), SinkFlushError> {
        self.with_encoder("flushing", FileEncoder::flush_blocking)
            .map_err(|message| SinkFlushError::Failed { message })
    }

    fn defers_finalization_to_shutdown(&self) -> bool {
        true
    }
}

impl Drop for RrdFile {
    /// Writes the footer (the manifest of every chunk) and flushes the file.
    fn drop(&mut self) {
        let _ = self.with_encoder("closing", |e| {
            e.finish()?;
            e.flush_blocking()
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[cfg(target_os = "linux")]
    fn a_write_that_fails_is_an_error_reported_once() {
        // /dev/full accepts the open and fails every write (ENOSPC); the header sits in
        // the buffer until the first flush.
        let warned = Arc::new(AtomicBool::new(false));
        let sink = RrdFile::create(Path::new("/dev/full"), Arc::clone(&warned)).unwrap();
        let first = sink.flush_blocking(Duration::from_secs(1)).unwrap_err();
        assert!(first.to_string().contains("/dev/full"), "{first}");
        assert!(warned.load(Ordering::Relaxed));
        // Later failures are errors too, and the flag stays set (said once).
        assert!(sink.flush_blocking(Duration::from_secs(1)).is_err());
        assert!(warned.load(Ordering::Relaxed));
    }

    #[test]
    fn a_file_that_cannot_be_created_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing").join("a.rrd");
        let e = RrdFile::create(&path, Arc::new(AtomicBool::new(false)))
            .err()
            .unwrap();
        assert!(!e.is_empty());
    }
}
