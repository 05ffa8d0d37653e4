//! Errors of the Rerun logging: each says what, where and what to do.

use std::path::PathBuf;

/// What can go wrong before a run starts (a viewer that cannot be reached is not an
/// error: the run goes on and the recorder says so once).
#[derive(Debug, thiserror::Error)]
pub enum VizError {
    /// `--rerun` was given something that is not a target.
    #[error(
        "--rerun `{given}`: {reason}; use `save:FILE.rrd` (the default), `spawn`, `connect` or `connect:HOST:PORT`"
    )]
    BadTarget {
        /// What the user wrote.
        given: String,
        /// What is wrong with it.
        reason: String,
    },
    /// `--rerun-hz` out of range.
    #[error("--rerun-hz {0}: must be a finite rate > 0 Hz (default 60)")]
    BadRate(f64),
    /// The recording file cannot be created.
    #[error("--rerun save:{path}: cannot create the recording: {reason}; check that the folder exists and is writable")]
    File {
        /// The recording path.
        path: PathBuf,
        /// The OS/SDK message.
        reason: String,
    },
}
