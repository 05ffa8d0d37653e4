//! Writing a dataset ([`SweepDataset::write`], [`RelaxationDataset::write`],
//! [`CyclicDataset::write`]): every file goes into a temporary folder next to the
//! target, is read back with [`Dataset::load`], and only then is the folder renamed
//! into place.

use std::fs;
use std::path::Path;

use serde::Serialize;

use super::error::csv_error;
use super::{
    CyclicDataset, Dataset, DatasetError, RelaxationDataset, SweepDataset, DATASET_TOML, FORMAT,
    SWEEP_TENSION_COLUMNS,
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
