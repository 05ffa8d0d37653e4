//! Malformed datasets give errors naming file, line and column/field; datasets written
//! with the writers read back unchanged.

use std::f64::consts::PI;
use std::fs;
use std::path::{Path, PathBuf};

use longreach_ident::dataset::{DatasetError, KINDS};
use longreach_ident::{
    CyclicDataset, CyclicRun, CyclicSpecimen, Dataset, DatasetKind, Frf, RelaxationDataset,
    RelaxationRun, RelaxationSpecimen, RigSpec, SweepDataset, SweepRun, Tensioner,
};

/// A small stepped sine: 1 Hz for 4 s then 2 Hz for 3 s at 100 Hz, settle 1 s.
fn small_sweep() -> SweepDataset {
    let dt = 0.01;
    let (mut t, mut f, mut cmd, mut out, mut t1, mut t2) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    let mut phase: f64 = 0.0;
    for i in 0..700 {
        let fi = if i < 400 { 1.0 } else { 2.0 };
        t.push(i as f64 * dt);
        f.push(fi);
        cmd.push(0.05 * phase.sin());
        out.push(0.04 * (phase - 0.3).sin());
        t1.push(49.0 + 3.0 * phase.sin());
        t2.push(49.0 - 3.0 * phase.sin());
        phase += 2.0 * PI * fi * dt;
    }
    SweepDataset {
        rig: RigSpec {
            rope: "dyneema2".into(),
            rope_length_m: 15.2,
            input_radius_m: 0.025,
            output_radius_m: 0.025,
            output_inertia_kg_m2: 0.0284,
            output_damping_n_m_s: 0.05,
            relay_pulleys: 3,
            relay_radius_m: 0.025,
            tensioner: Tensioner::ConstantForce,
        },
        runs: vec![SweepRun {
            name: "run_01".into(),
            file: "run_01.csv".into(),
            frf: Some(Frf {
                file: "frf_01.csv".into(),
                frequency_hz: vec![1.0, 2.0],
                gain_db: vec![-1.9382, -1.9382],
                phase_deg: vec![-17.19, -17.19],
            }),
            mean_tension_n: 49.0,
            amplitude_rad: 0.05,
            settle_s: 1.0,
            time_s: t,
            frequency_hz: f,
            command_rad: cmd.clone(),
            input_angle_rad: cmd,
            output_angle_rad: out,
            tension_in_1_n: Some(t1),
            tension_in_2_n: Some(t2),
            tension_out_1_n: None,
            tension_out_2_n: None,
        }],
    }
}

/// Writes the small sweep into a fresh folder `<tmp>/ds` and returns it.
fn written_sweep(tmp: &tempfile::TempDir) -> PathBuf {
    let dir = tmp.path().join("ds");
    small_sweep().write(&dir, "small").unwrap();
    dir
}

/// Replaces 1-based line `line` of `path` with `f(old line)`.
fn edit_line(path: &Path, line: usize, f: impl Fn(&str) -> String) {
    let text = fs::read_to_string(path).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    lines[line - 1] = f(&lines[line - 1]);
    fs::write(path, lines.join("\n") + "\n").unwrap();
}

/// Replaces cell `col` (0-based) of 1-based line `line` of a CSV file.
fn edit_cell(path: &Path, line: usize, col: usize, text: &str) {
    edit_line(path, line, |l| {
        let mut cells: Vec<&str> = l.split(',').collect();
        cells[col] = text;
        cells.join(",")
    });
}

fn line_of(path: &Path, needle: &str) -> usize {
    fs::read_to_string(path)
        .unwrap()
        .lines()
        .position(|l| l.contains(needle))
        .unwrap_or_else(|| panic!("{needle} not in {}", path.display()))
        + 1
}

fn load_err(dir: &Path) -> (DatasetError, String) {
    let e = Dataset::load(dir).expect_err("malformed dataset must not load");
    let msg = e.to_string();
    println!("{msg}");
    (e, msg)
}

fn assert_mentions(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "message lacks {p:?}: {msg}");
    }
}

#[test]
fn missing_column() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    let csv = dir.join("run_01.csv");
    edit_line(&csv, 1, |l| {
        l.replace("output_angle_rad", "output_angle_deg")
    });
    let (e, msg) = load_err(&dir);
    assert!(matches!(e, DatasetError::MissingColumn { .. }));
    assert_mentions(
        &msg,
        &[
            "run_01.csv",
            "line 1",
            "`output_angle_rad`",
            "output_angle_deg",
            "time_s",
        ],
    );
}

#[test]
fn non_numeric_cell() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    edit_cell(&dir.join("run_01.csv"), 5, 2, "abc");
    let (e, msg) = load_err(&dir);
    assert!(matches!(e, DatasetError::NotANumber { line: 5, .. }));
    assert_mentions(&msg, &["run_01.csv", "line 5", "command_rad", "\"abc\""]);
}

#[test]
fn nan_cell() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    edit_cell(&dir.join("run_01.csv"), 7, 3, "NaN");
    let (e, msg) = load_err(&dir);
    assert!(matches!(e, DatasetError::NonFinite { line: 7, .. }));
    assert_mentions(&msg, &["run_01.csv", "line 7", "input_angle_rad", "NaN"]);
}

#[test]
fn nan_in_optional_column_and_frf() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    edit_cell(&dir.join("run_01.csv"), 9, 6, "inf");
    let (_, msg) = load_err(&dir);
    assert_mentions(&msg, &["run_01.csv", "line 9", "tension_in_2_n", "inf"]);

    let dir = tmp.path().join("ds2");
    small_sweep().write(&dir, "small").unwrap();
    edit_cell(&dir.join("frf_01.csv"), 3, 1, "x");
    let (_, msg) = load_err(&dir);
    assert_mentions(&msg, &["frf_01.csv", "line 3", "gain_db", "\"x\""]);
}

#[test]
fn decreasing_time() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    edit_cell(&dir.join("run_01.csv"), 10, 0, "0.01");
    let (e, msg) = load_err(&dir);
    assert!(matches!(
        e,
        DatasetError::TimeNotIncreasing { line: 10, .. }
    ));
    assert_mentions(&msg, &["run_01.csv", "line 10", "time_s"]);
}

#[test]
fn irregular_sampling() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    // line 12 holds sample 10 (t = 0.10): move it to 0.1001, still increasing
    edit_cell(&dir.join("run_01.csv"), 12, 0, "0.1001");
    let (e, msg) = load_err(&dir);
    assert!(matches!(
        e,
        DatasetError::IrregularSampling { line: 12, .. }
    ));
    assert_mentions(&msg, &["run_01.csv", "line 12", "time_s", "irregular"]);
}

#[test]
fn ragged_row() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    edit_line(&dir.join("run_01.csv"), 20, |l| format!("{l},1.0"));
    let (_, msg) = load_err(&dir);
    assert_mentions(&msg, &["run_01.csv", "line 20", "cells"]);
}

#[test]
fn unknown_kind() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    let toml = dir.join("dataset.toml");
    let line = line_of(&toml, "kind =");
    edit_line(&toml, line, |_| "kind = \"sweep\"".into());
    let (e, msg) = load_err(&dir);
    assert!(matches!(e, DatasetError::UnknownKind { .. }));
    assert_mentions(
        &msg,
        &[
            "dataset.toml",
            &format!("line {line}"),
            "`kind`",
            "\"sweep\"",
        ],
    );
    for k in KINDS {
        assert!(msg.contains(k), "valid kinds listed: {msg}");
    }
}

#[test]
fn unsupported_format() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    let toml = dir.join("dataset.toml");
    let line = line_of(&toml, "format =");
    edit_line(&toml, line, |_| {
        "format = \"longreach-measurement/2\"".into()
    });
    let (e, msg) = load_err(&dir);
    assert!(matches!(e, DatasetError::UnsupportedFormat { .. }));
    assert_mentions(
        &msg,
        &[
            "dataset.toml",
            &format!("line {line}"),
            "`format`",
            "longreach-measurement/1",
        ],
    );
}

#[test]
fn missing_run_file() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    let toml = dir.join("dataset.toml");
    let line = line_of(&toml, "file = \"run_01.csv\"");
    edit_line(&toml, line, |_| "file = \"nope.csv\"".into());
    let (e, msg) = load_err(&dir);
    assert!(matches!(e, DatasetError::RunFileMissing { .. }));
    assert_mentions(
        &msg,
        &[
            "dataset.toml",
            &format!("line {line}"),
            "run[1].file",
            "nope.csv",
        ],
    );
}

#[test]
fn wrong_type_in_toml() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    let toml = dir.join("dataset.toml");
    let line = line_of(&toml, "rope_length_m");
    edit_line(&toml, line, |_| "rope_length_m = \"long\"".into());
    let (e, msg) = load_err(&dir);
    assert!(matches!(e, DatasetError::Toml { .. }));
    assert_mentions(
        &msg,
        &[
            "dataset.toml",
            &format!("line {line}"),
            "rig.rope_length_m",
            "expected f64",
        ],
    );

    // a wrong type inside a [[run]] table names the run
    let dir = tmp.path().join("ds2");
    small_sweep().write(&dir, "small").unwrap();
    let toml = dir.join("dataset.toml");
    let line = line_of(&toml, "settle_s");
    edit_line(&toml, line, |_| "settle_s = true".into());
    let (_, msg) = load_err(&dir);
    assert_mentions(
        &msg,
        &[
            "dataset.toml",
            &format!("line {line}"),
            "run[1].settle_s",
            "expected f64",
        ],
    );
}

#[test]
fn missing_toml_field() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    let toml = dir.join("dataset.toml");
    let line = line_of(&toml, "output_inertia_kg_m2");
    edit_line(&toml, line, |_| String::new());
    let (_, msg) = load_err(&dir);
    let header = line_of(&toml, "[rig]");
    assert_mentions(
        &msg,
        &[
            "dataset.toml",
            &format!("line {header}"),
            "rig.output_inertia_kg_m2",
            "missing",
        ],
    );
}

#[test]
fn invalid_values() {
    for (key, value, field) in [
        ("mean_tension_n", "-5.0", "run[1].mean_tension_n"),
        ("amplitude_rad", "0.0", "run[1].amplitude_rad"),
        ("output_radius_m", "0.0", "rig.output_radius_m"),
        ("output_inertia_kg_m2", "-0.1", "rig.output_inertia_kg_m2"),
        ("rope_length_m", "nan", "rig.rope_length_m"),
        ("tensioner", "\"spring\"", "rig.tensioner"),
    ] {
        let tmp = tempfile::tempdir().unwrap();
        let dir = written_sweep(&tmp);
        let toml = dir.join("dataset.toml");
        let line = line_of(&toml, key);
        edit_line(&toml, line, |_| format!("{key} = {value}"));
        let (e, msg) = load_err(&dir);
        assert!(matches!(e, DatasetError::InvalidValue { .. }), "{key}");
        assert_mentions(&msg, &["dataset.toml", &format!("line {line}"), field]);
    }
}

#[test]
fn no_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("relax");
    fs::create_dir(&dir).unwrap();
    fs::write(
        dir.join("dataset.toml"),
        "format = \"longreach-measurement/1\"\nkind = \"relaxation\"\n[specimen]\nrope = \"x\"\nlength_m = 0.1\nstrain = 0.01\n",
    )
    .unwrap();
    let (e, msg) = load_err(&dir);
    assert!(matches!(e, DatasetError::NoRuns { .. }));
    assert_mentions(&msg, &["dataset.toml", "line 1", "`run`"]);
}

#[test]
fn step_too_short() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ds");
    let mut s = small_sweep();
    s.runs[0].settle_s = 2.5; // 1 Hz step: 4 s - 2.5 s = 1.5 cycles
    s.write(&dir, "small").unwrap();
    let d = Dataset::load(&dir).unwrap();
    let DatasetKind::SineSweep(s) = d.kind else {
        panic!()
    };
    let e = s.runs[0].segments().expect_err("1.5 cycles are too few");
    let msg = e.to_string();
    assert_mentions(
        &msg,
        &["run_01.csv", "line 2", "frequency_hz", "1.500 cycles"],
    );
}

#[test]
fn unknown_keys_and_columns_are_ignored() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = written_sweep(&tmp);
    let toml = dir.join("dataset.toml");
    let mut text = fs::read_to_string(&toml).unwrap();
    text = text.replace("[rig]\n", "[rig]\ncolour = \"blue\"\n");
    text.push_str("\n[extra]\nnote = 3\n");
    fs::write(&toml, text).unwrap();
    let csv = dir.join("run_01.csv");
    let text = fs::read_to_string(&csv).unwrap();
    let with_extra: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                format!("{l},temperature_c\n")
            } else {
                format!("{l},{}\n", 20 + i)
            }
        })
        .collect();
    fs::write(&csv, with_extra).unwrap();
    let d = Dataset::load(&dir).unwrap();
    assert_eq!(d.kind, DatasetKind::SineSweep(small_sweep()));
}

#[test]
fn sweep_round_trip_and_replace() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ds");
    let s = small_sweep();
    s.write(&dir, "small sweep").unwrap();
    let d = Dataset::load(&dir).unwrap();
    assert_eq!(d.title, "small sweep");
    assert_eq!(d.dir, dir);
    assert_eq!(d.kind, DatasetKind::SineSweep(s.clone()));
    // writing again replaces the folder (a stale file disappears)
    fs::write(dir.join("stale.txt"), "x").unwrap();
    let mut s2 = s.clone();
    s2.runs[0].mean_tension_n = 147.0;
    s2.write(&dir, "again").unwrap();
    assert!(!dir.join("stale.txt").exists());
    let d = Dataset::load(dir.join("dataset.toml")).unwrap();
    assert_eq!(d.kind, DatasetKind::SineSweep(s2));
    // nothing but the dataset is left in the parent folder
    let names: Vec<_> = fs::read_dir(tmp.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("ds")]);
}

#[test]
fn failed_writes_leave_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("ds");
    // mismatched lengths: refused before writing
    let mut s = small_sweep();
    s.runs[0].output_angle_rad.pop();
    let e = s.write(&dir, "bad").unwrap_err();
    assert!(e.to_string().contains("output_angle_rad"), "{e}");
    // decreasing time: caught when reading back, after writing to the temporary folder
    let mut s = small_sweep();
    s.runs[0].time_s[5] = 0.0;
    let e = s.write(&dir, "bad").unwrap_err();
    assert!(matches!(e, DatasetError::WriteCheck { .. }), "{e}");
    assert!(e.to_string().contains("time_s"), "{e}");
    assert_eq!(
        fs::read_dir(tmp.path()).unwrap().count(),
        0,
        "no target and no temporary folder left"
    );
    // an existing dataset survives a failed overwrite
    small_sweep().write(&dir, "good").unwrap();
    assert!(s.write(&dir, "bad").is_err());
    assert_eq!(Dataset::load(&dir).unwrap().title, "good");
}

#[test]
fn relaxation_and_cyclic_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let t: Vec<f64> = (0..50)
        .map(|i| 0.1 * i as f64 + 0.01 * (i % 3) as f64)
        .collect();
    let relax = RelaxationDataset {
        specimen: RelaxationSpecimen {
            rope: "zylon2".into(),
            length_m: 0.1,
            strain: 0.015,
        },
        runs: vec![
            RelaxationRun {
                name: "a".into(),
                file: "a.csv".into(),
                time_s: t.clone(),
                tension_n: t.iter().map(|x| 1000.0 / (1.0 + x)).collect(),
                strain: None,
            },
            RelaxationRun {
                name: "b".into(),
                file: "b.csv".into(),
                time_s: t.clone(),
                tension_n: t.iter().map(|x| 900.0 - x).collect(),
                strain: Some(0.02),
            },
        ],
    };
    relax.write(tmp.path().join("relax"), "r").unwrap();
    assert_eq!(
        Dataset::load(tmp.path().join("relax")).unwrap().kind,
        DatasetKind::Relaxation(relax)
    );

    // a run's own strain must be positive, like the specimen's
    let toml = tmp.path().join("relax").join("dataset.toml");
    let line = line_of(&toml, "strain = 0.02");
    edit_line(&toml, line, |_| "strain = -0.02".into());
    let (e, msg) = load_err(&tmp.path().join("relax"));
    assert!(matches!(e, DatasetError::InvalidValue { .. }));
    assert_mentions(
        &msg,
        &["dataset.toml", &format!("line {line}"), "strain", "> 0"],
    );

    let cyclic = CyclicDataset {
        specimen: CyclicSpecimen {
            rope: "kevlar2".into(),
            length_m: 0.1,
        },
        runs: vec![CyclicRun {
            name: "cyclic".into(),
            file: "cyclic.csv".into(),
            time_s: t.clone(),
            strain: t.iter().map(|x| 0.01 * x.sin()).collect(),
            tension_n: t.iter().map(|x| 500.0 * x.sin().max(0.0)).collect(),
        }],
    };
    cyclic.write(tmp.path().join("cyc"), "c").unwrap();
    let d = Dataset::load(tmp.path().join("cyc")).unwrap();
    assert_eq!(d.kind.name(), "cyclic");
    assert_eq!(d.kind, DatasetKind::Cyclic(cyclic));
}

#[test]
fn not_found() {
    let e = Dataset::load("/nonexistent/longreach/dataset").unwrap_err();
    assert!(matches!(e, DatasetError::NotFound { .. }));
    assert!(e.to_string().contains("/nonexistent/longreach/dataset"));
}
