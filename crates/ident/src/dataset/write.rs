//! Writing a dataset ([`SweepDataset::write`], [`RelaxationDataset::write`],
//! [`CyclicDataset::write`], [`ArmMovesDataset::write`]): every file goes into a temporary folder next to the
//! target, is read back with [`Dataset::load`], and only then is the folder renamed
//! into place.

use std::fs;
use std::path::{Path, PathBuf};

use serde::Serialize;

use super::error::csv_error;
use super::{
    ArmMovesDataset, CyclicDataset, Dataset, DatasetError, RelaxationDataset, SweepDataset,
    DATASET_TOML, FORMAT, SWEEP_TENSION_COLUMNS,
};

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
struct OutSpecimenDataset<'a, S: Serialize, R: Serialize> {
    format: &'a str,
    kind: &'a str,
    title: &'a str,
    specimen: S,
    run: Vec<R>,
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

#[derive(Serialize)]
struct OutRelaxationRun<'a> {
    file: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    strain: Option<f64>,
}

/// Collects the files of a dataset to write and checks them.
struct Writer<'a> {
    dir: &'a Path,
    files: Vec<(String, Vec<(&'a str, &'a [f64])>)>,
    /// Text files written as they are (an arm dataset's copy of its scenario).
    texts: Vec<(String, String)>,
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
    /// [`Dataset::load`], then moves it to `dir`. An existing `dir` is replaced only
    /// when it is empty or a dataset (it has a `dataset.toml` in our format); anything
    /// else (a folder of the user's, a file) is refused and left untouched.
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
        longreach_scenario::atomic::replace_dir(dir, is_dataset_dir, NOT_OURS_FIX, |tmp| {
            fs::write(tmp.join(DATASET_TOML), toml_text)
                .map_err(io(&tmp.join(DATASET_TOML), "write"))?;
            for (name, text) in &self.texts {
                let path = tmp.join(name);
                fs::write(&path, text).map_err(io(&path, "write"))?;
            }
            for (name, columns) in &self.files {
                let path = tmp.join(name);
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
            Dataset::load(tmp).map_err(|e| DatasetError::WriteCheck {
                dir: dir.to_path_buf(),
                source: Box::new(e),
            })?;
            Ok(())
        })
    }
}

const NOT_OURS_FIX: &str = "choose a new folder for --out (or an existing dataset to replace); longreach never deletes a folder it did not write";

/// Checks that `dir` may receive a dataset (it is missing, empty, or a dataset) before
/// anything is computed for it; the writers check again when they write.
pub fn check_target(dir: &Path) -> Result<(), DatasetError> {
    longreach_scenario::atomic::check_dir_target(dir, is_dataset_dir, NOT_OURS_FIX)?;
    Ok(())
}

/// True when `dir` holds a `dataset.toml` that declares our format (a dataset we may
/// replace).
fn is_dataset_dir(dir: &Path) -> bool {
    fs::read_to_string(dir.join(DATASET_TOML)).is_ok_and(|text| {
        toml::from_str::<toml::Table>(&text)
            .ok()
            .and_then(|t| {
                t.get("format")
                    .and_then(|f| f.as_str())
                    .map(|f| f == FORMAT)
            })
            .unwrap_or(false)
    })
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
            texts: Vec::new(),
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
            texts: Vec::new(),
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
                .map(|r| OutRelaxationRun {
                    file: &r.file,
                    strain: r.strain,
                })
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
            texts: Vec::new(),
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

#[derive(Serialize)]
struct OutArmMoves<'a> {
    format: &'a str,
    kind: &'a str,
    title: &'a str,
    arm: OutArm<'a>,
    run: Vec<OutArmRun<'a>>,
}

#[derive(Serialize)]
struct OutArm<'a> {
    scenario: &'a str,
}

#[derive(Serialize)]
struct OutArmRun<'a> {
    file: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    payload_kg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    title: Option<&'a str>,
}

impl ArmMovesDataset {
    /// Writes this dataset to folder `dir`, atomically (see [`SweepDataset::write`]).
    ///
    /// When [`Self::scenario`] is a plain file name (`arm.toml`), the scenario at
    /// [`Self::scenario_path`] is copied into the dataset under that name, its URDF path
    /// made relative to `dir` and its commands dropped (the runs hold the commands): the
    /// dataset then carries the arm it was measured on. Any other `scenario` is written
    /// as it is and must resolve from `dir`.
    pub fn write(&self, dir: impl AsRef<Path>, title: &str) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let names: Vec<Vec<String>> = self
            .runs
            .iter()
            .map(|r| {
                self.joints
                    .iter()
                    .map(|j| format!("command_{j}_rad"))
                    .chain(r.channels.iter().map(|c| c.name.clone()))
                    .collect()
            })
            .collect();
        let mut w = Writer {
            dir,
            files: Vec::new(),
            texts: Vec::new(),
        };
        for (run, names) in self.runs.iter().zip(&names) {
            if run.command_rad.len() != self.joints.len() {
                return Err(w.invalid(format!(
                    "{}: {} command columns for {} driven joints",
                    run.file,
                    run.command_rad.len(),
                    self.joints.len()
                )));
            }
            let data = run
                .command_rad
                .iter()
                .chain(run.channels.iter().map(|c| &c.values));
            let mut cols: Vec<(&str, &[f64])> = vec![("time_s", &run.time_s)];
            cols.extend(
                names
                    .iter()
                    .map(String::as_str)
                    .zip(data.map(Vec::as_slice)),
            );
            w.add(&run.file, cols)?;
        }
        let plain = Path::new(&self.scenario)
            .file_name()
            .is_some_and(|f| f == std::ffi::OsStr::new(&self.scenario));
        if plain {
            let text = scenario_copy(&self.scenario_path, dir).map_err(|what| w.invalid(what))?;
            w.texts.push((self.scenario.clone(), text));
        }
        let out = OutArmMoves {
            format: FORMAT,
            kind: "arm_moves",
            title,
            arm: OutArm {
                scenario: &self.scenario,
            },
            run: self
                .runs
                .iter()
                .map(|r| OutArmRun {
                    file: &r.file,
                    payload_kg: r.payload_kg,
                    title: r.title.as_deref(),
                })
                .collect(),
        };
        w.commit(&toml_text(dir, &out)?)
    }
}

/// The arm scenario at `path` as a file of the dataset folder `dir`: its URDF path
/// relative to `dir`, every `command` removed.
fn scenario_copy(path: &Path, dir: &Path) -> Result<String, String> {
    let text = fs::read_to_string(path)
        .map_err(|e| format!("cannot read the arm scenario {}: {e}", path.display()))?;
    let mut doc: toml::Table = text
        .parse()
        .map_err(|e| format!("the arm scenario {} is not TOML: {e}", path.display()))?;
    rebase_urdf(&mut doc, path.parent().unwrap_or(Path::new(".")), dir)?;
    let drop_command = |t: &mut toml::Table| {
        t.remove("command");
    };
    if let Some(ts) = doc.get_mut("transmission").and_then(|t| t.as_array_mut()) {
        for t in ts.iter_mut().filter_map(|t| t.as_table_mut()) {
            drop_command(t);
        }
    }
    if let Some(d) = doc
        .get_mut("transmission_defaults")
        .and_then(|t| t.as_table_mut())
    {
        drop_command(d);
    }
    let body = toml::to_string(&doc).map_err(|e| format!("cannot encode the scenario: {e}"))?;
    Ok(format!(
        "# The arm these moves were measured on: a copy of {} (URDF path relative to this\n\
         # folder; [sim] and the commands are not used, the runs hold the commands).\n\n{body}",
        path.file_name().unwrap_or_default().to_string_lossy()
    ))
}

/// The URDF path of the arm scenario `doc` (read from the folder `base`) made relative
/// to the folder `dir` (which may not exist yet: its parent is created).
pub(crate) fn rebase_urdf(doc: &mut toml::Table, base: &Path, dir: &Path) -> Result<(), String> {
    let abs = |p: &Path| -> Result<PathBuf, String> {
        let p = if p.is_absolute() {
            p.to_path_buf()
        } else {
            std::env::current_dir()
                .map_err(|e| format!("no current folder: {e}"))?
                .join(p)
        };
        Ok(p.canonicalize().unwrap_or(p))
    };
    if let Some(urdf) = doc
        .get_mut("arm")
        .and_then(|a| a.as_table_mut())
        .and_then(|a| a.get_mut("urdf"))
    {
        let given = urdf.as_str().unwrap_or_default().to_string();
        let urdf_abs = abs(&base.join(&given))?;
        // The dataset folder may not exist yet: its parent does (or will, created first).
        let parent = dir.parent().filter(|p| !p.as_os_str().is_empty());
        let parent_abs = match parent {
            Some(p) => {
                fs::create_dir_all(p).map_err(|e| format!("{}: {e}", p.display()))?;
                abs(p)?
            }
            None => abs(Path::new("."))?,
        };
        let dir_abs = parent_abs.join(dir.file_name().unwrap_or_default());
        let rel = relative_path(&dir_abs, &urdf_abs);
        *urdf = toml::Value::String(rel.to_string_lossy().replace('\\', "/"));
    }
    Ok(())
}

/// `to` relative to the folder `from` (both absolute).
fn relative_path(from: &Path, to: &Path) -> PathBuf {
    let a: Vec<_> = from.components().collect();
    let b: Vec<_> = to.components().collect();
    let common = a.iter().zip(&b).take_while(|(x, y)| x == y).count();
    let mut out = PathBuf::new();
    for _ in common..a.len() {
        out.push("..");
    }
    for c in &b[common..] {
        out.push(c);
    }
    out
}
