//! [`DatasetError`], what can go wrong reading or writing a dataset, and the helpers
//! that build it.

use std::path::{Path, PathBuf};

use super::{FORMAT, KINDS};

const FORMAT_HINT: &str = "the format longreach-measurement/1 is described in docs/measurements.md";

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
    #[error("{file}: line {line}: column `time_s`: irregular sampling, interval {interval_s} s differs from the mean interval {dt_s} s by more than {tolerance_rel} (relative); sine sweeps and arm moves need a fixed sampling rate -- resample the data")]
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
    /// The arm scenario of an `arm_moves` dataset cannot be used (its own error says
    /// where and what to do).
    #[error(
        "{file}: line {line}: field `arm.scenario`: the arm scenario does not load: {message}"
    )]
    Scenario {
        /// The `dataset.toml` file.
        file: PathBuf,
        /// 1-based line of `scenario = ...`.
        line: usize,
        /// The scenario reader's message (file, line, field and fix of the scenario).
        message: String,
    },
    /// A column of an arm run names a joint the arm scenario does not drive.
    #[error("{file}: line 1: column `{column}` names joint `{joint}`, which the arm scenario does not drive (driven joints: {driven}); rename the column after a driven joint or drop it", driven = .driven.join(", "))]
    UndrivenJoint {
        /// The CSV file.
        file: PathBuf,
        /// The column.
        column: String,
        /// The joint it names.
        joint: String,
        /// The joints the scenario drives.
        driven: Vec<String>,
    },
    /// A column appears twice in the header of a run file.
    #[error("{file}: line 1: column `{column}` appears twice; keep one")]
    DuplicateColumn {
        /// The CSV file.
        file: PathBuf,
        /// The column.
        column: String,
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
    /// The output folder could not be written, or is not ours to replace.
    #[error(transparent)]
    Write(#[from] longreach_scenario::atomic::WriteError),
}

fn fmt_line(line: Option<usize>) -> String {
    match line {
        Some(l) => l.to_string(),
        None => "?".to_string(),
    }
}

/// A CSV reader's or writer's error about `path` as a [`DatasetError`].
pub(super) fn csv_error(path: &Path, e: &csv::Error) -> DatasetError {
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
