//! `--rerun` and `--rerun-hz`, shared by the commands that can stream to Rerun.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Result};
use clap::Args;
use longreach_viz::{Closing, Recorder, Target, DEFAULT_HZ};

/// Streaming to the Rerun viewer.
#[derive(Debug, Clone, Args)]
pub struct RerunArgs {
    /// Stream the run to Rerun: `save:FILE.rrd` (the default when given alone:
    /// `<input stem>.rrd`), `spawn` (start a viewer) or `connect[:HOST:PORT]`.
    /// Give it after the input file, or as `--rerun=TARGET`.
    #[arg(long, value_name = "TARGET", num_args = 0..=1, default_missing_value = "save")]
    pub rerun: Option<String>,
    /// Frames of simulated time logged per simulated second.
    #[arg(long, value_name = "HZ", default_value_t = DEFAULT_HZ)]
    pub rerun_hz: f64,
}

impl RerunArgs {
    /// The recorder asked for (off without `--rerun`); `default_file` names a bare
    /// `save`. Errors (bad target, unwritable file, bad rate) come before any run.
    pub fn recorder(&self, name: &str, default_file: &Path) -> Result<Recorder> {
        let Some(given) = &self.rerun else {
            return Ok(Recorder::off());
        };
        let target: Target = given.parse().map_err(|e| {
            if Path::new(given).exists() {
                anyhow!(
                    "{e}\n`--rerun` took `{given}` as its target: write the input file before `--rerun`, or use `--rerun=save`"
                )
            } else {
                anyhow!("{e}")
            }
        })?;
        Ok(Recorder::start(name, &target, default_file, self.rerun_hz)?)
    }
}

/// `<dir>/<stem of input><suffix>.rrd` (dir = `.` when None).
pub fn default_rrd(dir: Option<&Path>, input: &Path, suffix: &str) -> PathBuf {
    let stem = input
        .file_stem()
        .map_or_else(|| "longreach".into(), |s| s.to_string_lossy().into_owned());
    dir.unwrap_or(Path::new("."))
        .join(format!("{stem}{suffix}.rrd"))
}

/// Finishes a recording and says where it went.
pub fn finish(rec: Recorder) {
    said(rec.finish());
}

/// Says where a recording closed in the background went, once it is closed.
pub fn finished(closing: Closing) {
    said(closing.wait());
}

fn said(path: Option<PathBuf>) {
    if let Some(path) = path {
        println!(
            "wrote Rerun recording {} (open it with `rerun {}`; viewer version {})",
            path.display(),
            path.display(),
            longreach_viz::SDK_VERSION
        );
    }
}
