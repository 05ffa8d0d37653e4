//! Reader and writer for measurement datasets in the format `longreach-measurement/1`.
//!
//! A dataset is a folder holding one `dataset.toml` and the CSV files it names
//! (format description: `formats/measurements.md` of the project). Three kinds exist:
//!
//! * `sine_sweep`: the paper's cable-pulley rig (Sec. IV, Fig. 7/8), stepped-sine runs,
//! * `relaxation`: tension relaxation at constant strain (Sec. III, eq. 6),
//! * `cyclic`: load-strain test (Sec. II).
//!
//! The reader ignores keys and columns it does not know and refuses, with an error naming
//! the file, the line and the column or field, anything it cannot use. Every error
//! message ends with what to do about it.
//!
//! Writing ([`SweepDataset::write`], [`RelaxationDataset::write`],
//! [`CyclicDataset::write`]) is atomic: all files go into a temporary folder next to the
//! target, are read back and checked with the same reader, and only then is the folder
//! renamed into place.

use std::fs;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use toml::Spanned;

/// The only format string this reader understands (`format = ...` in `dataset.toml`).
pub const FORMAT: &str = "longreach-measurement/1";

/// Name of the description file inside a dataset folder.
pub const DATASET_TOML: &str = "dataset.toml";

/// The dataset kinds this reader understands, as spelled in `kind = ...`.
pub const KINDS: [&str; 3] = ["sine_sweep", "relaxation", "cyclic"];

/// Relative tolerance on the sampling interval of a series that needs a fixed rate:
/// every interval must equal the mean interval within `SAMPLING_TOLERANCE_REL * dt`.
pub const SAMPLING_TOLERANCE_REL: f64 = 1e-6;

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

const FORMAT_HINT: &str =
    "the format longreach-measurement/1 is described in formats/measurements.md";

/// Everything that can go wrong reading or writing a dataset. Each message names the
/// file, the line (where there is one) and the field or column, and says what to do.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The dataset folder or its `dataset.toml` does not exist.
    #[error("dataset not found: {path} does not exist; pass a dataset folder or its dataset.toml")]
    NotFound {
        /// The path that was looked for.
        path: PathBuf,
    },
    /// A file could not be read, written or renamed.
    #[error("{path}: {action} failed: {source}; check that the path exists and is accessible")]
    Io {
        /// The file or folder concerned.
        path: PathBuf,
        /// What was being done (`read`, `write`, `rename`, ...).
        action: &'static str,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// `dataset.toml` is not valid TOML, or a field is missing or has the wrong type.
    #[error("{file}: line {line}: field `{field}`: {message}; fix dataset.toml ({FORMAT_HINT})", line = fmt_line(*.line), field = .field.as_deref().unwrap_or("?"))]
    Toml {
        /// The `dataset.toml` file.
        file: PathBuf,
        /// 1-based line where TOML located the problem, if it did.
        line: Option<usize>,
        /// Dotted field name (e.g. `run(2).mean_tension_n`), if it could be determined.
        field: Option<String>,
        /// The parser's message (includes the expected type for type errors).
        message: String,
    },
    /// `format = ...` is not the supported format.
    #[error("{file}: line {line}: field `format`: unsupported format \"{found}\"; this reader understands only \"{FORMAT}\" -- convert the dataset or use a newer longreach")]
    UnsupportedFormat {
        /// The `dataset.toml` file.
        file: PathBuf,
        /// 1-based line.
        line: usize,
        /// The format string found.
        found: String,
    },
    /// `kind = ...` is not one of [`KINDS`].
    #[error("{file}: line {line}: field `kind`: unknown kind \"{found}\"; valid kinds are {valid}", valid = KINDS.map(|k| format!("\"{k}\"")).join(", "))]
    UnknownKind {
        /// The `dataset.toml` file.
        file: PathBuf,
        /// 1-based line.
        line: usize,
        /// The kind found.
        found: String,
    },
    /// A field of `dataset.toml` has a value that cannot be used.
    #[error(
        "{file}: line {line}: field `{field}` = {value}: {requirement}; correct it in dataset.toml"
    )]
    InvalidValue {
        /// The `dataset.toml` file.
        file: PathBuf,
        /// 1-based line of the value.
        line: usize,
        /// Dotted field name.
        field: String,
        /// The value found, as text.
        value: String,
        /// What the value must satisfy.
        requirement: String,
    },
    /// The dataset lists no `[(run)]`.
    #[error("{file}: line {line}: field `run`: the dataset lists no runs; add at least one [[run]] table with a `file`")]
    NoRuns {
        /// The `dataset.toml` file.
        file: PathBuf,
        /// Always 1 (the whole document).
        line: usize,
    },
    /// A run file named in `dataset.toml` does not exist.
    #[error("{file}: line {line}: field `{field}`: run file {missing} does not exist; put the file next to dataset.toml or fix the name")]
    RunFileMissing {
        /// The `dataset.toml` file.
        file: PathBuf,
        /// 1-based line of the file name.
        line: usize,
        /// Dotted field name (`run(1).file`, `run(1).frf_file`).
        field: String,
        /// The path that was looked for.
        missing: PathBuf,
    },
    /// A required CSV column is missing.
    #[error("{file}: line 1: missing required column `{column}` (columns found: {found}); add the column to the header", found = .found.join(", "))]
    MissingColumn {
        /// The CSV file.
        file: PathBuf,
        /// The missing column.
        column: String,
        /// The columns present in the header.
        found: Vec<String>,
    },
    /// A CSV cell is not a number.
    #[error("{file}: line {line}: column `{column}`: \"{text}\" is not a number; every cell of this column must be a decimal number")]
    NotANumber {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line.
        line: u64,
        /// Column name.
        column: String,
        /// The cell text.
        text: String,
    },
    /// A CSV cell is NaN or infinite.
    #[error("{file}: line {line}: column `{column}`: \"{text}\" is not finite; replace it with a measured value or drop the row")]
    NonFinite {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line.
        line: u64,
        /// Column name.
        column: String,
        /// The cell text.
        text: String,
    },
    /// Time does not strictly increase.
    #[error("{file}: line {line}: column `time_s`: time {time_s} s does not increase (previous row: {previous_s} s); sort the rows by time and remove duplicates")]
    TimeNotIncreasing {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line.
        line: u64,
        /// Time of the previous row.
        previous_s: f64,
        /// Time of this row.
        time_s: f64,
    },
    /// A series that needs a fixed sampling rate is irregularly sampled.
    #[error("{file}: line {line}: column `time_s`: irregular sampling, interval {interval_s} s differs from the mean interval {dt_s} s by more than {tolerance_rel} (relative); a sine sweep needs a fixed sampling rate -- resample the data")]
    IrregularSampling {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line of the row ending the bad interval.
        line: u64,
        /// The interval found.
        interval_s: f64,
        /// The mean interval over the file.
        dt_s: f64,
        /// Relative tolerance applied.
        tolerance_rel: f64,
    },
    /// The CSV file is structurally broken (ragged rows, bad UTF-8, ...).
    #[error("{file}: line {line}: {message}; fix the CSV file (comma-separated, one header row, the same number of cells in every row)", line = fmt_line(.line.map(|l| l as usize)))]
    Csv {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line, if known.
        line: Option<u64>,
        /// The CSV parser's message.
        message: String,
    },
    /// The CSV file has too few data rows.
    #[error(
        "{file}: line {line}: {rows} data rows, at least {min} needed; the run is too short to use"
    )]
    TooFewRows {
        /// The CSV file.
        file: PathBuf,
        /// Last line of the file.
        line: u64,
        /// Data rows found.
        rows: usize,
        /// Data rows needed.
        min: usize,
    },
    /// A column value is out of its valid range (e.g. `frequency_hz <= 0`).
    #[error("{file}: line {line}: column `{column}`: {value} {requirement}; correct the data")]
    BadCell {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line.
        line: u64,
        /// Column name.
        column: String,
        /// The value found.
        value: f64,
        /// What it must satisfy.
        requirement: String,
    },
    /// A stepped-sine frequency step holds fewer than two whole cycles after `settle_s`.
    #[error("{file}: line {line}: column `frequency_hz`: the step at {frequency_hz} Hz (lines {line}..{last_line}) holds {cycles:.3} cycles after settle_s = {settle_s} s, at least 2 whole cycles are needed; hold each frequency longer or reduce settle_s")]
    StepTooShort {
        /// The CSV file.
        file: PathBuf,
        /// 1-based line of the first row of the step.
        line: u64,
        /// 1-based line of the last row of the step.
        last_line: u64,
        /// Frequency of the step.
        frequency_hz: f64,
        /// Cycles available after the settling time.
        cycles: f64,
        /// The run's settling time.
        settle_s: f64,
    },
    /// Data given to a writer is inconsistent.
    #[error("cannot write dataset {dir}: {what}; fix the data before writing")]
    InvalidData {
        /// The target folder.
        dir: PathBuf,
        /// What is wrong.
        what: String,
    },
    /// The written dataset did not read back (nothing was left at the target).
    #[error("cannot write dataset {dir}: the written files do not read back ({source}); nothing was written")]
    WriteCheck {
        /// The target folder.
        dir: PathBuf,
        /// The reader's complaint.
        #[source]
        source: Box<DatasetError>,
    },
}

fn fmt_line(line: Option<usize>) -> String {
    match line {
        Some(l) => l.to_string(),
        None => "?".to_string(),
    }
}

/// A loaded dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// The dataset folder.
    pub dir: PathBuf,
    /// `title` from `dataset.toml` (the folder name if absent).
    pub title: String,
    /// The kind-specific content.
    pub kind: DatasetKind,
}

/// The kind-specific content of a dataset.
#[derive(Debug, Clone, PartialEq)]
pub enum DatasetKind {
    /// `kind = "sine_sweep"`.
    SineSweep(SweepDataset),
    /// `kind = "relaxation"`.
    Relaxation(RelaxationDataset),
    /// `kind = "cyclic"`.
    Cyclic(CyclicDataset),
}

impl DatasetKind {
    /// The kind as spelled in `dataset.toml`.
    pub fn name(&self) -> &'static str {
        match self {
            DatasetKind::SineSweep(_) => KINDS[0],
            DatasetKind::Relaxation(_) => KINDS[1],
            DatasetKind::Cyclic(_) => KINDS[2],
        }
    }
}

/// How the rig keeps its ropes tensioned (`tensioner = ...`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tensioner {
    /// `"constant_force"`: the input pulley rides a carriage pulled with a constant force,
    /// so `tension_in_1 + tension_in_2 = 2 * mean_tension_n` at all times.
    ConstantForce,
}

impl Tensioner {
    /// Valid spellings in `dataset.toml`.
    pub const NAMES: [&'static str; 1] = ["constant_force"];

    /// The spelling in `dataset.toml`.
    pub fn name(self) -> &'static str {
        match self {
            Tensioner::ConstantForce => "constant_force",
        }
    }

    fn parse(s: &str) -> Option<Self> {
        match s {
            "constant_force" => Some(Tensioner::ConstantForce),
            _ => None,
        }
    }
}

/// The `[rig]` table of a sine-sweep dataset: the paper's cable-pulley rig (Sec. IV,
/// Fig. 8, Table VII).
#[derive(Debug, Clone, PartialEq)]
pub struct RigSpec {
    /// Rope name in the rope catalog.
    pub rope: String,
    /// L: length of each rope from input to output pulley (m).
    pub rope_length_m: f64,
    /// r1: input pulley radius (m).
    pub input_radius_m: f64,
    /// r2: output pulley radius (m).
    pub output_radius_m: f64,
    /// I: inertia about the output axis (kg m^2).
    pub output_inertia_kg_m2: f64,
    /// C: viscous resistance of the output shaft (N m s) (eq. 8); may be 0.
    pub output_damping_n_m_s: f64,
    /// Idler pulleys each rope runs over.
    pub relay_pulleys: u32,
    /// Radius of the relay pulleys (m).
    pub relay_radius_m: f64,
    /// Tensioner type.
    pub tensioner: Tensioner,
}

/// A sine-sweep dataset (`kind = "sine_sweep"`).
#[derive(Debug, Clone, PartialEq)]
pub struct SweepDataset {
    /// The rig.
    pub rig: RigSpec,
    /// The runs, in file order.
    pub runs: Vec<SweepRun>,
}

/// A frequency response computed by the rig software (`frf_file`): output angle over
/// input angle, one row per test frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct Frf {
    /// File name relative to the dataset folder.
    pub file: String,
    /// Test frequencies (Hz).
    pub frequency_hz: Vec<f64>,
    /// Gain (dB).
    pub gain_db: Vec<f64>,
    /// Phase (deg).
    pub phase_deg: Vec<f64>,
}

/// One stepped-sine run of the rig.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRun {
    /// File stem of `file` (e.g. `run_01`).
    pub name: String,
    /// Time-series file name relative to the dataset folder.
    pub file: String,
    /// The rig software's frequency response, if `frf_file` was given.
    pub frf: Option<Frf>,
    /// Tensioner setting (N).
    pub mean_tension_n: f64,
    /// Amplitude of the commanded input angle (rad).
    pub amplitude_rad: f64,
    /// Transient time at the start of each frequency step (s).
    pub settle_s: f64,
    /// Time since the run started (s), fixed rate.
    pub time_s: Vec<f64>,
    /// Commanded frequency of the current step (Hz).
    pub frequency_hz: Vec<f64>,
    /// Commanded input pulley angle (rad).
    pub command_rad: Vec<f64>,
    /// Measured input pulley angle (rad).
    pub input_angle_rad: Vec<f64>,
    /// Measured output pulley angle (rad).
    pub output_angle_rad: Vec<f64>,
    /// Rope 1 tension next to the input pulley (N).
    pub tension_in_1_n: Option<Vec<f64>>,
    /// Rope 2 tension next to the input pulley (N).
    pub tension_in_2_n: Option<Vec<f64>>,
    /// Rope 1 tension next to the output pulley (N).
    pub tension_out_1_n: Option<Vec<f64>>,
    /// Rope 2 tension next to the output pulley (N).
    pub tension_out_2_n: Option<Vec<f64>>,
}

/// One frequency step of a stepped-sine run (indices into the run's series).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Frequency of the step (Hz).
    pub frequency_hz: f64,
    /// First sample of the step.
    pub start_index: usize,
    /// One past the last sample of the step.
    pub end_index: usize,
    /// First sample of the part to analyse (at or after `settle_s` into the step).
    pub analysis_start_index: usize,
    /// One past the last sample of the part to analyse: `analysis_start_index..
    /// analysis_end_index` spans `cycles` whole cycles, to the nearest sample.
    pub analysis_end_index: usize,
    /// Whole cycles in the analysed part (>= 2).
    pub cycles: usize,
}

/// Where the analysed whole cycles of a frequency step are taken (see
/// [`SweepRun::segments_aligned`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WindowAlignment {
    /// Starting at the first sample at or after `settle_s` into the step. This is what
    /// the rig software that wrote the example `frf_file`s does (checked: it reproduces
    /// their gains within 0.001 dB and phases within 0.01 deg).
    AfterSettle,
    /// Ending at the last sample of the step (the latest, most settled cycles).
    EndOfStep,
}

impl SweepRun {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True if the run holds no samples (never the case for a loaded run).
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Sampling interval (s): mean interval over the run (the reader checked it is fixed).
    pub fn dt_s(&self) -> f64 {
        mean_interval(&self.time_s)
    }

    /// The distinct test frequencies in order of appearance (Hz).
    pub fn test_frequencies_hz(&self) -> Vec<f64> {
        let mut out: Vec<f64> = Vec::new();
        for &f in &self.frequency_hz {
            if out.last().is_none_or(|&last| !same_frequency(last, f)) {
                out.push(f);
            }
        }
        out
    }

    /// Splits the run into its frequency steps (runs of equal `frequency_hz`), with the
    /// analysed part placed as the rig software does ([`WindowAlignment::AfterSettle`]).
    pub fn segments(&self) -> Result<Vec<Segment>, DatasetError> {
        self.segments_aligned(WindowAlignment::AfterSettle)
    }

    /// Splits the run into its frequency steps (runs of equal `frequency_hz`).
    ///
    /// In each step the first `settle_s` seconds are transient (`ceil(settle_s / dt)`
    /// samples). Of the `m` samples after them, the analysed part is the largest whole
    /// number of cycles `n = floor(m dt f)` that fits, `round(n / (f dt))` samples long,
    /// placed as `alignment` says. Errors if a frequency is not positive or if `n < 2`.
    pub fn segments_aligned(
        &self,
        alignment: WindowAlignment,
    ) -> Result<Vec<Segment>, DatasetError> {
        let dt_s = self.dt_s();
        let file = PathBuf::from(&self.file);
        let mut out = Vec::new();
        let mut start = 0usize;
        let n = self.frequency_hz.len();
        while start < n {
            let f = self.frequency_hz[start];
            let mut end = start + 1;
            while end < n && same_frequency(self.frequency_hz[end], f) {
                end += 1;
            }
            if f <= 0.0 {
                return Err(DatasetError::BadCell {
                    file,
                    line: start as u64 + 2,
                    column: "frequency_hz".into(),
                    value: f,
                    requirement: "must be > 0 in a stepped sine".into(),
                });
            }
            // samples dropped for settling: up to the first sample at or after settle_s
            let settle_samples = ((self.settle_s / dt_s) - 1e-6).ceil().max(0.0) as usize;
            let available = (end - start).saturating_sub(settle_samples);
            let cycles_f = available as f64 * dt_s * f;
            let cycles = (cycles_f + 1e-6).floor();
            if cycles < 2.0 {
                return Err(DatasetError::StepTooShort {
                    file,
                    line: start as u64 + 2,
                    last_line: end as u64 + 1,
                    frequency_hz: f,
                    cycles: cycles_f,
                    settle_s: self.settle_s,
                });
            }
            let len = ((cycles / (f * dt_s)).round() as usize).min(available);
            let (a, b) = match alignment {
                WindowAlignment::AfterSettle => {
                    (start + settle_samples, start + settle_samples + len)
                }
                WindowAlignment::EndOfStep => (end - len, end),
            };
            out.push(Segment {
                frequency_hz: f,
                start_index: start,
                end_index: end,
                analysis_start_index: a,
                analysis_end_index: b,
                cycles: cycles as usize,
            });
            start = end;
        }
        Ok(out)
    }
}

/// The `[specimen]` of a relaxation test.
#[derive(Debug, Clone, PartialEq)]
pub struct RelaxationSpecimen {
    /// Rope name in the rope catalog.
    pub rope: String,
    /// Initial length after the pre-stretch process (m).
    pub length_m: f64,
    /// Strain applied at t = 0 and held (elongation / length) (-).
    pub strain: f64,
}

/// One relaxation run: tension over time at constant strain (paper Sec. III).
#[derive(Debug, Clone, PartialEq)]
pub struct RelaxationRun {
    /// File stem.
    pub name: String,
    /// File name relative to the dataset folder.
    pub file: String,
    /// Time since the strain was applied (s).
    pub time_s: Vec<f64>,
    /// Measured tension (N).
    pub tension_n: Vec<f64>,
}

/// A relaxation dataset (`kind = "relaxation"`).
#[derive(Debug, Clone, PartialEq)]
pub struct RelaxationDataset {
    /// The specimen.
    pub specimen: RelaxationSpecimen,
    /// The runs.
    pub runs: Vec<RelaxationRun>,
}

/// The `[specimen]` of a cyclic test.
#[derive(Debug, Clone, PartialEq)]
pub struct CyclicSpecimen {
    /// Rope name in the rope catalog.
    pub rope: String,
    /// Initial length (m).
    pub length_m: f64,
}

/// One cyclic load-strain run (paper Sec. II).
#[derive(Debug, Clone, PartialEq)]
pub struct CyclicRun {
    /// File stem.
    pub name: String,
    /// File name relative to the dataset folder.
    pub file: String,
    /// Time (s).
    pub time_s: Vec<f64>,
    /// Strain (elongation / length) (-).
    pub strain: Vec<f64>,
    /// Tension (N).
    pub tension_n: Vec<f64>,
}

/// A cyclic dataset (`kind = "cyclic"`).
#[derive(Debug, Clone, PartialEq)]
pub struct CyclicDataset {
    /// The specimen.
    pub specimen: CyclicSpecimen,
    /// The runs.
    pub runs: Vec<CyclicRun>,
}

// ---------------------------------------------------------------------------------------
// dataset.toml: raw serde structs (unknown keys are ignored by serde's default)

#[derive(Deserialize)]
struct RawHeader {
    format: Spanned<String>,
    kind: Spanned<String>,
    title: Option<String>,
}

#[derive(Deserialize)]
struct RawSweep {
    rig: RawRig,
    #[serde(default)]
    run: Vec<RawSweepRun>,
}

#[derive(Deserialize)]
struct RawRig {
    rope: String,
    rope_length_m: Spanned<f64>,
    input_radius_m: Spanned<f64>,
    output_radius_m: Spanned<f64>,
    output_inertia_kg_m2: Spanned<f64>,
    output_damping_n_m_s: Spanned<f64>,
    relay_pulleys: u32,
    relay_radius_m: Spanned<f64>,
    tensioner: Spanned<String>,
}

#[derive(Deserialize)]
struct RawSweepRun {
    file: Spanned<String>,
    frf_file: Option<Spanned<String>>,
    mean_tension_n: Spanned<f64>,
    amplitude_rad: Spanned<f64>,
    settle_s: Spanned<f64>,
}

#[derive(Deserialize)]
struct RawRelaxation {
    specimen: RawRelaxationSpecimen,
    #[serde(default)]
    run: Vec<RawFileRun>,
}

#[derive(Deserialize)]
struct RawRelaxationSpecimen {
    rope: String,
    length_m: Spanned<f64>,
    strain: Spanned<f64>,
}

#[derive(Deserialize)]
struct RawCyclic {
    specimen: RawCyclicSpecimen,
    #[serde(default)]
    run: Vec<RawFileRun>,
}

#[derive(Deserialize)]
struct RawCyclicSpecimen {
    rope: String,
    length_m: Spanned<f64>,
}

#[derive(Deserialize)]
struct RawFileRun {
    file: Spanned<String>,
}

/// Context for reporting problems in `dataset.toml`.
struct TomlDoc<'a> {
    path: &'a Path,
    src: &'a str,
}

impl TomlDoc<'_> {
    fn line_of(&self, offset: usize) -> usize {
        let offset = offset.min(self.src.len());
        self.src.as_bytes()[..offset]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
            + 1
    }

    /// Name of the table that contains byte `offset` (`rig`, `run[2]`, ...), from the
    /// last table header at or before that line.
    fn table_at(&self, offset: usize) -> Option<String> {
        let line = self.line_of(offset);
        let mut table = None;
        let mut runs = std::collections::BTreeMap::<String, usize>::new();
        for text in self.src.lines().take(line) {
            let t = text.trim();
            if let Some(name) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
                let name = name.trim().to_string();
                let count = runs.entry(name.clone()).or_insert(0);
                *count += 1;
                table = Some(format!("{name}[{count}]"));
            } else if let Some(name) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
                table = Some(name.trim().to_string());
            }
        }
        table
    }

    fn qualified(&self, offset: usize, key: &str) -> String {
        match self.table_at(offset) {
            Some(t) => format!("{t}.{key}"),
            None => key.to_string(),
        }
    }

    fn parse<'de, T: Deserialize<'de>>(&self, src: &'de str) -> Result<T, DatasetError> {
        toml::from_str(src).map_err(|e| self.toml_error(&e))
    }

    fn toml_error(&self, e: &toml::de::Error) -> DatasetError {
        let message = e.message().to_string();
        let (line, field) = match e.span() {
            Some(span) => {
                let line = self.line_of(span.start);
                let text = self.src.lines().nth(line - 1).unwrap_or("");
                let key = if let Some(rest) = message.strip_prefix("missing field `") {
                    rest.split('`').next().map(str::to_string)
                } else if !text.trim_start().starts_with('[') {
                    text.split('=')
                        .next()
                        .map(|k| k.trim().trim_matches('"').to_string())
                        .filter(|k| !k.is_empty())
                } else {
                    None
                };
                let field = match key {
                    Some(k) => Some(self.qualified(span.start, &k)),
                    None => self.table_at(span.start),
                };
                (Some(line), field)
            }
            None => (None, None),
        };
        DatasetError::Toml {
            file: self.path.to_path_buf(),
            line,
            field,
            message,
        }
    }

    fn invalid(
        &self,
        span: std::ops::Range<usize>,
        key: &str,
        value: String,
        req: &str,
    ) -> DatasetError {
        DatasetError::InvalidValue {
            file: self.path.to_path_buf(),
            line: self.line_of(span.start),
            field: self.qualified(span.start, key),
            value,
            requirement: req.to_string(),
        }
    }

    /// A finite value > 0.
    fn positive(&self, v: &Spanned<f64>, key: &str) -> Result<f64, DatasetError> {
        let x = *v.get_ref();
        if x.is_finite() && x > 0.0 {
            Ok(x)
        } else {
            Err(self.invalid(v.span(), key, x.to_string(), "must be a finite number > 0"))
        }
    }

    /// A finite value >= 0.
    fn non_negative(&self, v: &Spanned<f64>, key: &str) -> Result<f64, DatasetError> {
        let x = *v.get_ref();
        if x.is_finite() && x >= 0.0 {
            Ok(x)
        } else {
            Err(self.invalid(v.span(), key, x.to_string(), "must be a finite number >= 0"))
        }
    }

    /// A run file that exists in `dir`.
    fn run_file(
        &self,
        dir: &Path,
        v: &Spanned<String>,
        key: &str,
    ) -> Result<(String, PathBuf), DatasetError> {
        let name = v.get_ref().clone();
        if name.trim().is_empty() {
            return Err(self.invalid(v.span(), key, "\"\"".into(), "must name a CSV file"));
        }
        let path = dir.join(&name);
        if !path.is_file() {
            return Err(DatasetError::RunFileMissing {
                file: self.path.to_path_buf(),
                line: self.line_of(v.span().start),
                field: self.qualified(v.span().start, key),
                missing: path,
            });
        }
        Ok((name, path))
    }

    fn check_runs<T>(&self, runs: &[T]) -> Result<(), DatasetError> {
        if runs.is_empty() {
            Err(DatasetError::NoRuns {
                file: self.path.to_path_buf(),
                line: 1,
            })
        } else {
            Ok(())
        }
    }
}

/// True if two `frequency_hz` cells belong to the same step (equal within 1e-9 relative;
/// the column holds the commanded frequency, identical within a step).
fn same_frequency(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

fn file_stem(name: &str) -> String {
    Path::new(name)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| name.to_string())
}

impl Dataset {
    /// Loads a dataset from its folder or from its `dataset.toml`, checking everything
    /// the format requires (see [`DatasetError`] for what is refused).
    pub fn load(path: impl AsRef<Path>) -> Result<Dataset, DatasetError> {
        let path = path.as_ref();
        if !path.exists() {
            return Err(DatasetError::NotFound {
                path: path.to_path_buf(),
            });
        }
        let (dir, toml_path) = if path.is_dir() {
            (path.to_path_buf(), path.join(DATASET_TOML))
        } else {
            let dir = match path.parent() {
                Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
                _ => PathBuf::from("."),
            };
            (dir, path.to_path_buf())
        };
        if !toml_path.is_file() {
            return Err(DatasetError::NotFound { path: toml_path });
        }
        let src = fs::read_to_string(&toml_path).map_err(|source| DatasetError::Io {
            path: toml_path.clone(),
            action: "read",
            source,
        })?;
        let doc = TomlDoc {
            path: &toml_path,
            src: &src,
        };
        let header: RawHeader = doc.parse(&src)?;
        if header.format.get_ref() != FORMAT {
            return Err(DatasetError::UnsupportedFormat {
                file: toml_path.clone(),
                line: doc.line_of(header.format.span().start),
                found: header.format.get_ref().clone(),
            });
        }
        let title = header.title.unwrap_or_else(|| {
            dir.file_name()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        });
        let kind = match header.kind.get_ref().as_str() {
            "sine_sweep" => DatasetKind::SineSweep(load_sweep(&doc, &dir)?),
            "relaxation" => DatasetKind::Relaxation(load_relaxation(&doc, &dir)?),
            "cyclic" => DatasetKind::Cyclic(load_cyclic(&doc, &dir)?),
            other => {
                return Err(DatasetError::UnknownKind {
                    file: toml_path.clone(),
                    line: doc.line_of(header.kind.span().start),
                    found: other.to_string(),
                })
            }
        };
        Ok(Dataset { dir, title, kind })
    }
}

fn load_sweep(doc: &TomlDoc, dir: &Path) -> Result<SweepDataset, DatasetError> {
    let raw: RawSweep = doc.parse(doc.src)?;
    let r = &raw.rig;
    let tensioner = Tensioner::parse(r.tensioner.get_ref()).ok_or_else(|| {
        doc.invalid(
            r.tensioner.span(),
            "tensioner",
            format!("\"{}\"", r.tensioner.get_ref()),
            &format!(
                "unknown tensioner, valid: {}",
                Tensioner::NAMES.map(|n| format!("\"{n}\"")).join(", ")
            ),
        )
    })?;
    let rig = RigSpec {
        rope: r.rope.clone(),
        rope_length_m: doc.positive(&r.rope_length_m, "rope_length_m")?,
        input_radius_m: doc.positive(&r.input_radius_m, "input_radius_m")?,
        output_radius_m: doc.positive(&r.output_radius_m, "output_radius_m")?,
        output_inertia_kg_m2: doc.positive(&r.output_inertia_kg_m2, "output_inertia_kg_m2")?,
        output_damping_n_m_s: doc.non_negative(&r.output_damping_n_m_s, "output_damping_n_m_s")?,
        relay_pulleys: r.relay_pulleys,
        relay_radius_m: doc.positive(&r.relay_radius_m, "relay_radius_m")?,
        tensioner,
    };
    doc.check_runs(&raw.run)?;
    let mut runs = Vec::with_capacity(raw.run.len());
    for rr in &raw.run {
        let mean_tension_n = doc.positive(&rr.mean_tension_n, "mean_tension_n")?;
        let amplitude_rad = doc.positive(&rr.amplitude_rad, "amplitude_rad")?;
        let settle_s = doc.non_negative(&rr.settle_s, "settle_s")?;
        let (file, path) = doc.run_file(dir, &rr.file, "file")?;
        let frf_path = match &rr.frf_file {
            Some(f) => Some(doc.run_file(dir, f, "frf_file")?),
            None => None,
        };
        let mut table = read_csv(&path, &SWEEP_COLUMNS, &SWEEP_TENSION_COLUMNS)?;
        check_time(&path, &table.required[0], &table.lines, true)?;
        for (i, &f) in table.required[1].iter().enumerate() {
            if f <= 0.0 {
                return Err(DatasetError::BadCell {
                    file: path,
                    line: table.lines[i],
                    column: "frequency_hz".into(),
                    value: f,
                    requirement: "must be > 0".into(),
                });
            }
        }
        let frf = match frf_path {
            Some((frf_file, frf_path)) => {
                let t = read_csv(&frf_path, &FRF_COLUMNS, &[])?;
                let mut cols = t.required.into_iter();
                let frequency_hz = cols.next().unwrap_or_default();
                let gain_db = cols.next().unwrap_or_default();
                let phase_deg = cols.next().unwrap_or_default();
                Some(Frf {
                    file: frf_file,
                    frequency_hz,
                    gain_db,
                    phase_deg,
                })
            }
            None => None,
        };
        let mut req = table.required.drain(..);
        let mut opt = table.optional.drain(..);
        runs.push(SweepRun {
            name: file_stem(&file),
            file,
            frf,
            mean_tension_n,
            amplitude_rad,
            settle_s,
            time_s: req.next().unwrap_or_default(),
            frequency_hz: req.next().unwrap_or_default(),
            command_rad: req.next().unwrap_or_default(),
            input_angle_rad: req.next().unwrap_or_default(),
            output_angle_rad: req.next().unwrap_or_default(),
            tension_in_1_n: opt.next().flatten(),
            tension_in_2_n: opt.next().flatten(),
            tension_out_1_n: opt.next().flatten(),
            tension_out_2_n: opt.next().flatten(),
        });
    }
    Ok(SweepDataset { rig, runs })
}

fn load_relaxation(doc: &TomlDoc, dir: &Path) -> Result<RelaxationDataset, DatasetError> {
    let raw: RawRelaxation = doc.parse(doc.src)?;
    let specimen = RelaxationSpecimen {
        rope: raw.specimen.rope.clone(),
        length_m: doc.positive(&raw.specimen.length_m, "length_m")?,
        strain: doc.positive(&raw.specimen.strain, "strain")?,
    };
    doc.check_runs(&raw.run)?;
    let mut runs = Vec::new();
    for rr in &raw.run {
        let (file, path) = doc.run_file(dir, &rr.file, "file")?;
        let mut t = read_csv(&path, &RELAXATION_COLUMNS, &[])?;
        check_time(&path, &t.required[0], &t.lines, false)?;
        let tension_n = t.required.pop().unwrap_or_default();
        let time_s = t.required.pop().unwrap_or_default();
        runs.push(RelaxationRun {
            name: file_stem(&file),
            file,
            time_s,
            tension_n,
        });
    }
    Ok(RelaxationDataset { specimen, runs })
}

fn load_cyclic(doc: &TomlDoc, dir: &Path) -> Result<CyclicDataset, DatasetError> {
    let raw: RawCyclic = doc.parse(doc.src)?;
    let specimen = CyclicSpecimen {
        rope: raw.specimen.rope.clone(),
        length_m: doc.positive(&raw.specimen.length_m, "length_m")?,
    };
    doc.check_runs(&raw.run)?;
    let mut runs = Vec::new();
    for rr in &raw.run {
        let (file, path) = doc.run_file(dir, &rr.file, "file")?;
        let mut t = read_csv(&path, &CYCLIC_COLUMNS, &[])?;
        check_time(&path, &t.required[0], &t.lines, false)?;
        let tension_n = t.required.pop().unwrap_or_default();
        let strain = t.required.pop().unwrap_or_default();
        let time_s = t.required.pop().unwrap_or_default();
        runs.push(CyclicRun {
            name: file_stem(&file),
            file,
            time_s,
            strain,
            tension_n,
        });
    }
    Ok(CyclicDataset { specimen, runs })
}

// ---------------------------------------------------------------------------------------
// CSV

struct CsvTable {
    /// Required columns, in the order asked for.
    required: Vec<Vec<f64>>,
    /// Optional columns, in the order asked for (None if absent).
    optional: Vec<Option<Vec<f64>>>,
    /// 1-based line of each data row.
    lines: Vec<u64>,
}

fn csv_error(path: &Path, e: &csv::Error) -> DatasetError {
    if let csv::ErrorKind::Io(io) = e.kind() {
        return DatasetError::Io {
            path: path.to_path_buf(),
            action: "read",
            source: std::io::Error::new(io.kind(), io.to_string()),
        };
    }
    let line = e.position().map(|p| p.line());
    let message = match e.kind() {
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => {
            format!("row has {len} cells but the header has {expected_len}")
        }
        csv::ErrorKind::Utf8 { .. } => "the file is not valid UTF-8 text".to_string(),
        _ => e.to_string(),
    };
    DatasetError::Csv {
        file: path.to_path_buf(),
        line,
        message,
    }
}

/// Reads the named numeric columns of a CSV file (extra columns are ignored).
fn read_csv(path: &Path, required: &[&str], optional: &[&str]) -> Result<CsvTable, DatasetError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| csv_error(path, &e))?;
    let headers: Vec<String> = reader
        .headers()
        .map_err(|e| csv_error(path, &e))?
        .iter()
        .map(str::to_string)
        .collect();
    let find = |name: &str| headers.iter().position(|h| h == name);
    let mut req_idx = Vec::with_capacity(required.len());
    for name in required {
        match find(name) {
            Some(i) => req_idx.push(i),
            None => {
                return Err(DatasetError::MissingColumn {
                    file: path.to_path_buf(),
                    column: (*name).to_string(),
                    found: headers.clone(),
                })
            }
        }
    }
    let opt_idx: Vec<Option<usize>> = optional.iter().map(|n| find(n)).collect();
    let mut req_data: Vec<Vec<f64>> = vec![Vec::new(); required.len()];
    let mut opt_data: Vec<Option<Vec<f64>>> =
        opt_idx.iter().map(|i| i.map(|_| Vec::new())).collect();
    let mut lines = Vec::new();
    let mut record = csv::StringRecord::new();
    loop {
        match reader.read_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(csv_error(path, &e)),
        }
        let line = record.position().map(|p| p.line()).unwrap_or(0);
        let cell = |col: usize| -> Result<f64, DatasetError> {
            let text = record.get(col).unwrap_or("");
            match text.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                Ok(_) => Err(DatasetError::NonFinite {
                    file: path.to_path_buf(),
                    line,
                    column: headers[col].clone(),
                    text: text.to_string(),
                }),
                Err(_) => Err(DatasetError::NotANumber {
                    file: path.to_path_buf(),
                    line,
                    column: headers[col].clone(),
                    text: text.to_string(),
                }),
            }
        };
        for (k, &col) in req_idx.iter().enumerate() {
            req_data[k].push(cell(col)?);
        }
        for (k, col) in opt_idx.iter().enumerate() {
            if let (Some(col), Some(data)) = (col, opt_data[k].as_mut()) {
                data.push(cell(*col)?);
            }
        }
        lines.push(line);
    }
    if lines.is_empty() {
        return Err(DatasetError::TooFewRows {
            file: path.to_path_buf(),
            line: 1,
            rows: 0,
            min: 1,
        });
    }
    Ok(CsvTable {
        required: req_data,
        optional: opt_data,
        lines,
    })
}

fn mean_interval(time_s: &[f64]) -> f64 {
    match (time_s.first(), time_s.last()) {
        (Some(a), Some(b)) if time_s.len() >= 2 => (b - a) / (time_s.len() - 1) as f64,
        _ => f64::NAN,
    }
}

/// Checks that time strictly increases and, if `fixed_rate`, that it is regularly
/// sampled within [`SAMPLING_TOLERANCE_REL`].
fn check_time(
    path: &Path,
    time_s: &[f64],
    lines: &[u64],
    fixed_rate: bool,
) -> Result<(), DatasetError> {
    for i in 1..time_s.len() {
        if time_s[i] <= time_s[i - 1] {
            return Err(DatasetError::TimeNotIncreasing {
                file: path.to_path_buf(),
                line: lines[i],
                previous_s: time_s[i - 1],
                time_s: time_s[i],
            });
        }
    }
    if fixed_rate {
        if time_s.len() < 2 {
            return Err(DatasetError::TooFewRows {
                file: path.to_path_buf(),
                line: lines.last().copied().unwrap_or(1),
                rows: time_s.len(),
                min: 2,
            });
        }
        let dt_s = mean_interval(time_s);
        for i in 1..time_s.len() {
            let interval_s = time_s[i] - time_s[i - 1];
            // allow for the rounding of the times themselves (a few ulps of t)
            let tol = SAMPLING_TOLERANCE_REL * dt_s + 4.0 * f64::EPSILON * time_s[i].abs();
            if (interval_s - dt_s).abs() > tol {
                return Err(DatasetError::IrregularSampling {
                    file: path.to_path_buf(),
                    line: lines[i],
                    interval_s,
                    dt_s,
                    tolerance_rel: SAMPLING_TOLERANCE_REL,
                });
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Writing

#[derive(Serialize)]
struct OutSweep<'a> {
    format: &'a str,
    kind: &'a str,
    title: &'a str,
    rig: OutRig<'a>,
    run: Vec<OutSweepRun<'a>>,
}

#[derive(Serialize)]
struct OutRig<'a> {
    rope: &'a str,
    rope_length_m: f64,
    input_radius_m: f64,
    output_radius_m: f64,
    output_inertia_kg_m2: f64,
    output_damping_n_m_s: f64,
    relay_pulleys: u32,
    relay_radius_m: f64,
    tensioner: &'a str,
}

#[derive(Serialize)]
struct OutSweepRun<'a> {
    file: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    frf_file: Option<&'a str>,
    mean_tension_n: f64,
    amplitude_rad: f64,
    settle_s: f64,
}

#[derive(Serialize)]
struct OutSpecimenDataset<'a, S: Serialize> {
    format: &'a str,
    kind: &'a str,
    title: &'a str,
    specimen: S,
    run: Vec<OutFileRun<'a>>,
}

#[derive(Serialize)]
struct OutRelaxationSpecimen<'a> {
    rope: &'a str,
    length_m: f64,
    strain: f64,
}

#[derive(Serialize)]
struct OutCyclicSpecimen<'a> {
    rope: &'a str,
    length_m: f64,
}

#[derive(Serialize)]
struct OutFileRun<'a> {
    file: &'a str,
}

/// Collects the files of a dataset to write and checks them.
struct Writer<'a> {
    dir: &'a Path,
    files: Vec<(String, Vec<(&'a str, &'a [f64])>)>,
}

impl<'a> Writer<'a> {
    fn invalid(&self, what: String) -> DatasetError {
        DatasetError::InvalidData {
            dir: self.dir.to_path_buf(),
            what,
        }
    }

    fn add(&mut self, name: &str, columns: Vec<(&'a str, &'a [f64])>) -> Result<(), DatasetError> {
        let plain = Path::new(name)
            .file_name()
            .is_some_and(|f| f == std::ffi::OsStr::new(name));
        if !plain || name == DATASET_TOML || name.starts_with('.') {
            return Err(self.invalid(format!(
                "file name \"{name}\" must be a plain file name (no folders, not dataset.toml)"
            )));
        }
        if self.files.iter().any(|(n, _)| n == name) {
            return Err(self.invalid(format!("file name \"{name}\" is used twice")));
        }
        let len = columns.first().map_or(0, |c| c.1.len());
        if len == 0 {
            return Err(self.invalid(format!("{name}: no samples")));
        }
        for (col, data) in &columns {
            if data.len() != len {
                return Err(self.invalid(format!(
                    "{name}: column `{col}` has {} samples, `{}` has {len}",
                    data.len(),
                    columns[0].0
                )));
            }
            if let Some(i) = data.iter().position(|v| !v.is_finite()) {
                return Err(self.invalid(format!(
                    "{name}: column `{col}` sample {i} is {} (not finite)",
                    data[i]
                )));
            }
        }
        self.files.push((name.to_string(), columns));
        Ok(())
    }

    /// Writes everything to a temporary folder next to `dir`, reads it back with
    /// [`Dataset::load`], then renames it to `dir` (replacing an existing `dir`).
    fn commit(self, toml_text: &str) -> Result<(), DatasetError> {
        let dir = self.dir;
        let io = |path: &Path, action: &'static str| {
            let path = path.to_path_buf();
            move |source| DatasetError::Io {
                path,
                action,
                source,
            }
        };
        let parent = match dir.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let base = dir
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .ok_or_else(|| self.invalid("the target has no folder name".into()))?;
        fs::create_dir_all(&parent).map_err(io(&parent, "create folder"))?;
        let tmp = tempfile::Builder::new()
            .prefix(&format!(".{base}.tmp"))
            .tempdir_in(&parent)
            .map_err(io(&parent, "create temporary folder"))?;
        fs::write(tmp.path().join(DATASET_TOML), toml_text)
            .map_err(io(&tmp.path().join(DATASET_TOML), "write"))?;
        for (name, columns) in &self.files {
            let path = tmp.path().join(name);
            let mut w = csv::Writer::from_path(&path).map_err(|e| csv_error(&path, &e))?;
            w.write_record(columns.iter().map(|c| c.0))
                .map_err(|e| csv_error(&path, &e))?;
            let n = columns[0].1.len();
            let mut row: Vec<String> = Vec::with_capacity(columns.len());
            for i in 0..n {
                row.clear();
                row.extend(columns.iter().map(|c| c.1[i].to_string()));
                w.write_record(&row).map_err(|e| csv_error(&path, &e))?;
            }
            w.flush().map_err(io(&path, "write"))?;
        }
        Dataset::load(tmp.path()).map_err(|e| DatasetError::WriteCheck {
            dir: dir.to_path_buf(),
            source: Box::new(e),
        })?;
        // Swap into place; an existing target is moved aside first and removed afterwards.
        let tmp_path = tmp.keep();
        let old = if dir.exists() {
            let aside = parent.join(format!(".{base}.old.{}", std::process::id()));
            if let Err(e) = fs::rename(dir, &aside) {
                let _ = fs::remove_dir_all(&tmp_path);
                return Err(DatasetError::Io {
                    path: dir.to_path_buf(),
                    action: "move aside",
                    source: e,
                });
            }
            Some(aside)
        } else {
            None
        };
        if let Err(e) = fs::rename(&tmp_path, dir) {
            if let Some(aside) = &old {
                let _ = fs::rename(aside, dir);
            }
            let _ = fs::remove_dir_all(&tmp_path);
            return Err(DatasetError::Io {
                path: dir.to_path_buf(),
                action: "rename",
                source: e,
            });
        }
        if let Some(aside) = old {
            fs::remove_dir_all(&aside).map_err(io(&aside, "remove old dataset"))?;
        }
        Ok(())
    }
}

fn toml_text<T: Serialize>(dir: &Path, value: &T) -> Result<String, DatasetError> {
    toml::to_string(value).map_err(|e| DatasetError::InvalidData {
        dir: dir.to_path_buf(),
        what: format!("cannot encode dataset.toml: {e}"),
    })
}

impl SweepDataset {
    /// Writes this dataset to folder `dir` (`dataset.toml`, each run's `file` and, if
    /// present, its `frf.file`), atomically: nothing is left half-written on error, and
    /// an existing `dir` is replaced only once the new one has been written and read back.
    pub fn write(&self, dir: impl AsRef<Path>, title: &str) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let mut w = Writer {
            dir,
            files: Vec::new(),
        };
        for run in &self.runs {
            let mut cols: Vec<(&str, &[f64])> = vec![
                ("time_s", &run.time_s),
                ("frequency_hz", &run.frequency_hz),
                ("command_rad", &run.command_rad),
                ("input_angle_rad", &run.input_angle_rad),
                ("output_angle_rad", &run.output_angle_rad),
            ];
            let tensions = [
                &run.tension_in_1_n,
                &run.tension_in_2_n,
                &run.tension_out_1_n,
                &run.tension_out_2_n,
            ];
            for (name, data) in SWEEP_TENSION_COLUMNS.iter().zip(tensions) {
                if let Some(d) = data {
                    cols.push((name, d));
                }
            }
            w.add(&run.file, cols)?;
            if let Some(frf) = &run.frf {
                w.add(
                    &frf.file,
                    vec![
                        ("frequency_hz", &frf.frequency_hz),
                        ("gain_db", &frf.gain_db),
                        ("phase_deg", &frf.phase_deg),
                    ],
                )?;
            }
        }
        let r = &self.rig;
        let out = OutSweep {
            format: FORMAT,
            kind: "sine_sweep",
            title,
            rig: OutRig {
                rope: &r.rope,
                rope_length_m: r.rope_length_m,
                input_radius_m: r.input_radius_m,
                output_radius_m: r.output_radius_m,
                output_inertia_kg_m2: r.output_inertia_kg_m2,
                output_damping_n_m_s: r.output_damping_n_m_s,
                relay_pulleys: r.relay_pulleys,
                relay_radius_m: r.relay_radius_m,
                tensioner: r.tensioner.name(),
            },
            run: self
                .runs
                .iter()
                .map(|run| OutSweepRun {
                    file: &run.file,
                    frf_file: run.frf.as_ref().map(|f| f.file.as_str()),
                    mean_tension_n: run.mean_tension_n,
                    amplitude_rad: run.amplitude_rad,
                    settle_s: run.settle_s,
                })
                .collect(),
        };
        w.commit(&toml_text(dir, &out)?)
    }
}

impl RelaxationDataset {
    /// Writes this dataset to folder `dir`, atomically (see [`SweepDataset::write`]).
    pub fn write(&self, dir: impl AsRef<Path>, title: &str) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let mut w = Writer {
            dir,
            files: Vec::new(),
        };
        for run in &self.runs {
            w.add(
                &run.file,
                vec![("time_s", &run.time_s), ("tension_n", &run.tension_n)],
            )?;
        }
        let out = OutSpecimenDataset {
            format: FORMAT,
            kind: "relaxation",
            title,
            specimen: OutRelaxationSpecimen {
                rope: &self.specimen.rope,
                length_m: self.specimen.length_m,
                strain: self.specimen.strain,
            },
            run: self
                .runs
                .iter()
                .map(|r| OutFileRun { file: &r.file })
                .collect(),
        };
        w.commit(&toml_text(dir, &out)?)
    }
}

impl CyclicDataset {
    /// Writes this dataset to folder `dir`, atomically (see [`SweepDataset::write`]).
    pub fn write(&self, dir: impl AsRef<Path>, title: &str) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let mut w = Writer {
            dir,
            files: Vec::new(),
        };
        for run in &self.runs {
            w.add(
                &run.file,
                vec![
                    ("time_s", &run.time_s),
                    ("strain", &run.strain),
                    ("tension_n", &run.tension_n),
                ],
            )?;
        }
        let out = OutSpecimenDataset {
            format: FORMAT,
            kind: "cyclic",
            title,
            specimen: OutCyclicSpecimen {
                rope: &self.specimen.rope,
                length_m: self.specimen.length_m,
            },
            run: self
                .runs
                .iter()
                .map(|r| OutFileRun { file: &r.file })
                .collect(),
        };
        w.commit(&toml_text(dir, &out)?)
    }
}
