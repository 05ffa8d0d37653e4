//! Reader and writer for measurement datasets in the format `longreach-measurement/1`.
//!
//! A dataset is a folder holding one `dataset.toml` and the CSV files it names
//! (format description: `docs/measurements.md`). Four kinds exist:
//!
//! * `sine_sweep`: the paper's cable-pulley rig (Sec. IV, Fig. 7/8), stepped-sine runs,
//! * `relaxation`: tension relaxation at constant strain (Sec. III, eq. 6),
//! * `cyclic`: load-strain test (Sec. II),
//! * `arm_moves`: moves of a long-reach arm (an arm scenario, `crates/arm`) measured
//!   through its own sensors (motor encoders, optionally joint encoders, rope tensions,
//!   the tip).
//!
//! The reader ignores keys and columns it does not know and refuses, with an error naming
//! the file, the line and the column or field, anything it cannot use. Every error
//! message ends with what to do about it.
//!
//! Writing ([`SweepDataset::write`], [`RelaxationDataset::write`],
//! [`CyclicDataset::write`]) is atomic: all files go into a temporary folder next to the
//! target (`longreach_scenario::atomic::replace_dir`: every file flushed to disk), are
//! read back and checked with the same reader, and only then is the folder renamed into
//! place. An existing target is replaced only when it is empty or a dataset (its
//! `dataset.toml` declares our format): a folder of the user's, or a file, is refused
//! and left untouched.
//!
//! The code is split by job: `types.rs` holds what a loaded dataset is ([`Dataset`],
//! [`SweepRun`] and its frequency [`Segment`]s, ...), `error.rs` the [`DatasetError`]
//! every reader and writer returns, `read.rs` the loading ([`Dataset::load`]: the
//! `dataset.toml` header and tables, the CSV files, the time checks) and `write.rs` the
//! atomic writers.

mod error;
mod read;
mod types;
mod write;

pub use error::DatasetError;
pub use types::{
    ArmChannel, ArmMovesDataset, ArmQuantity, ArmRun, CyclicDataset, CyclicRun, CyclicSpecimen,
    Dataset, DatasetKind, Frf, RelaxationDataset, RelaxationRun, RelaxationSpecimen, RigSpec,
    Segment, SweepDataset, SweepRun, Tensioner, WindowAlignment,
};
pub use write::check_target;
pub(crate) use write::rebase_urdf;

/// The only format string this reader understands (`format = ...` in `dataset.toml`).
pub const FORMAT: &str = "longreach-measurement/1";

/// Name of the description file inside a dataset folder.
pub const DATASET_TOML: &str = "dataset.toml";

/// The dataset kinds this reader understands, as spelled in `kind = ...`.
pub const KINDS: [&str; 4] = ["sine_sweep", "relaxation", "cyclic", "arm_moves"];

/// Relative tolerance on the sampling interval of a series that needs a fixed rate:
/// every interval must equal the mean interval within `SAMPLING_TOLERANCE_REL * dt`.
pub const SAMPLING_TOLERANCE_REL: f64 = 1e-6;

/// Encoder resolution of the angle columns of arm datasets (motor and joint), rad.
pub const ARM_ENCODER_RESOLUTION_RAD: f64 = 1e-4;

/// Required columns of a sine-sweep run file.
pub const SWEEP_COLUMNS: [&str; 5] = [
    "time_s",
    "frequency_hz",
    "command_rad",
    "input_angle_rad",
    "output_angle_rad",
];
/// Optional tension columns of a sine-sweep run file.
pub const SWEEP_TENSION_COLUMNS: [&str; 4] = [
    "tension_in_1_n",
    "tension_in_2_n",
    "tension_out_1_n",
    "tension_out_2_n",
];
/// Columns of a frequency-response file (`frf_file`).
pub const FRF_COLUMNS: [&str; 3] = ["frequency_hz", "gain_db", "phase_deg"];
/// Columns of a relaxation run file.
pub const RELAXATION_COLUMNS: [&str; 2] = ["time_s", "tension_n"];
/// Columns of a cyclic run file.
pub const CYCLIC_COLUMNS: [&str; 3] = ["time_s", "strain", "tension_n"];
