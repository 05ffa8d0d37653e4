//! Loading a dataset ([`Dataset::load`]): the `dataset.toml` header and tables (with
//! errors located by line and field), the CSV files, and the checks on time.

use std::fs;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::error::csv_error;
use super::types::mean_interval;
use super::{
    ArmChannel, ArmMovesDataset, ArmQuantity, ArmRun, CyclicDataset, CyclicRun, CyclicSpecimen,
    Dataset, DatasetError, DatasetKind, Frf, RelaxationDataset, RelaxationRun, RelaxationSpecimen,
    RigSpec, SweepDataset, SweepRun, Tensioner, CYCLIC_COLUMNS, DATASET_TOML, FORMAT, FRF_COLUMNS,
    RELAXATION_COLUMNS, SAMPLING_TOLERANCE_REL, SWEEP_COLUMNS, SWEEP_TENSION_COLUMNS,
};

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
    run: Vec<RawRelaxationRun>,
}

#[derive(Deserialize)]
struct RawRelaxationRun {
    file: Spanned<String>,
    strain: Option<Spanned<f64>>,
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

#[derive(Deserialize)]
struct RawArmMoves {
    arm: RawArmSection,
    #[serde(default)]
    run: Vec<RawArmRun>,
}

#[derive(Deserialize)]
struct RawArmSection {
    scenario: Spanned<String>,
}

#[derive(Deserialize)]
struct RawArmRun {
    file: Spanned<String>,
    payload_kg: Option<Spanned<f64>>,
    title: Option<String>,
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
            "arm_moves" => DatasetKind::ArmMoves(load_arm_moves(&doc, &dir)?),
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
        // Every test frequency below the Nyquist rate of the samples (fixed rate,
        // checked above): a faster one cannot be measured, so no result would hold.
        let nyquist_hz = 0.5 / mean_interval(&table.required[0]);
        for (i, &f) in table.required[1].iter().enumerate() {
            if f <= 0.0 || f >= nyquist_hz {
                return Err(DatasetError::BadCell {
                    file: path,
                    line: table.lines[i],
                    column: "frequency_hz".into(),
                    value: f,
                    requirement: format!(
                        "must be > 0 and below the Nyquist rate {nyquist_hz} Hz of the samples"
                    ),
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
        let strain = match &rr.strain {
            Some(s) => Some(doc.positive(s, "strain")?),
            None => None,
        };
        runs.push(RelaxationRun {
            name: file_stem(&file),
            file,
            time_s,
            tension_n,
            strain,
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

fn load_arm_moves(doc: &TomlDoc, dir: &Path) -> Result<ArmMovesDataset, DatasetError> {
    let raw: RawArmMoves = doc.parse(doc.src)?;
    let sc = &raw.arm.scenario;
    let scenario = sc.get_ref().clone();
    if scenario.trim().is_empty() {
        return Err(doc.invalid(
            sc.span(),
            "scenario",
            "\"\"".into(),
            "must name an arm scenario file (the `longreach run` format)",
        ));
    }
    let scenario_path = dir.join(&scenario);
    let line = doc.line_of(sc.span().start);
    let arm =
        longreach_arm::scenario::load(&scenario_path).map_err(|e| DatasetError::Scenario {
            file: doc.path.to_path_buf(),
            line,
            message: e.to_string(),
        })?;
    let joints: Vec<String> = arm
        .arm
        .pairs()
        .iter()
        .map(|p| arm.arm.spec().joints[p.spec.joint].name.clone())
        .collect();
    let rope = arm
        .arm
        .pairs()
        .first()
        .map(|p| p.spec.rope_name.clone())
        .unwrap_or_default();
    doc.check_runs(&raw.run)?;
    let mut runs = Vec::with_capacity(raw.run.len());
    for rr in &raw.run {
        let payload_kg = match &rr.payload_kg {
            Some(p) => Some(doc.non_negative(p, "payload_kg")?),
            None => None,
        };
        let (file, path) = doc.run_file(dir, &rr.file, "file")?;
        runs.push(read_arm_run(
            &path,
            file,
            &joints,
            payload_kg,
            rr.title.clone(),
        )?);
    }
    Ok(ArmMovesDataset {
        scenario,
        scenario_path,
        joints,
        flex_links: arm.flex_link_names(),
        rope,
        runs,
    })
}

/// The joint a per-joint column of an arm run names (`command_J_rad`, `motor_J_rad`,
/// `joint_J_rad`, `tension_J_1_n`, `tension_J_2_n`), if it is one.
fn column_joint(column: &str) -> Option<&str> {
    let j = ["command_", "motor_", "joint_"]
        .iter()
        .find_map(|p| column.strip_prefix(p).and_then(|r| r.strip_suffix("_rad")))
        .or_else(|| {
            let r = column.strip_prefix("tension_")?;
            r.strip_suffix("_1_n").or_else(|| r.strip_suffix("_2_n"))
        })?;
    (!j.is_empty()).then_some(j)
}

/// Reads one run file of an arm dataset: every per-joint column must name a driven
/// joint, every driven joint needs its command and motor columns.
fn read_arm_run(
    path: &Path,
    file: String,
    joints: &[String],
    payload_kg: Option<f64>,
    title: Option<String>,
) -> Result<ArmRun, DatasetError> {
    let headers = csv_headers(path)?;
    for (i, h) in headers.iter().enumerate() {
        if headers[..i].contains(h) {
            return Err(DatasetError::DuplicateColumn {
                file: path.to_path_buf(),
                column: h.clone(),
            });
        }
        if let Some(j) = column_joint(h) {
            if !joints.iter().any(|d| d == j) {
                return Err(DatasetError::UndrivenJoint {
                    file: path.to_path_buf(),
                    column: h.clone(),
                    joint: j.to_string(),
                    driven: joints.to_vec(),
                });
            }
        }
    }
    let mut required = vec!["time_s".to_string()];
    required.extend(joints.iter().map(|j| format!("command_{j}_rad")));
    required.extend(joints.iter().map(|j| ArmQuantity::Motor.column(j)));
    let mut optional: Vec<(String, ArmQuantity, Option<usize>)> = Vec::new();
    for (k, j) in joints.iter().enumerate() {
        for q in [
            ArmQuantity::Joint,
            ArmQuantity::Tension1,
            ArmQuantity::Tension2,
        ] {
            optional.push((q.column(j), q, Some(k)));
        }
    }
    for a in 0..3u8 {
        optional.push((ArmQuantity::Tip(a).column(""), ArmQuantity::Tip(a), None));
    }
    for a in 0..3u8 {
        optional.push((
            ArmQuantity::TipAcc(a).column(""),
            ArmQuantity::TipAcc(a),
            None,
        ));
    }
    let req: Vec<&str> = required.iter().map(String::as_str).collect();
    let opt: Vec<&str> = optional.iter().map(|o| o.0.as_str()).collect();
    let table = read_csv(path, &req, &opt)?;
    check_time(path, &table.required[0], &table.lines, true)?;
    let n = joints.len();
    let mut req_cols = table.required.into_iter();
    let time_s = req_cols.next().unwrap_or_default();
    let command_rad: Vec<Vec<f64>> = req_cols.by_ref().take(n).collect();
    let mut channels: Vec<ArmChannel> = req_cols
        .zip(joints.iter().enumerate())
        .map(|(values, (k, j))| ArmChannel {
            name: ArmQuantity::Motor.column(j),
            quantity: ArmQuantity::Motor,
            joint: Some(k),
            values,
        })
        .collect();
    for ((name, quantity, joint), values) in optional.into_iter().zip(table.optional) {
        if let Some(values) = values {
            channels.push(ArmChannel {
                name,
                quantity,
                joint,
                values,
            });
        }
    }
    Ok(ArmRun {
        name: file_stem(&file),
        file,
        title,
        payload_kg,
        time_s,
        command_rad,
        channels,
    })
}

/// The header row of a CSV file.
fn csv_headers(path: &Path) -> Result<Vec<String>, DatasetError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| csv_error(path, &e))?;
    Ok(reader
        .headers()
        .map_err(|e| csv_error(path, &e))?
        .iter()
        .map(str::to_string)
        .collect())
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
