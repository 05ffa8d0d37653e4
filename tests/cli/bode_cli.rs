//! `longreach bode` from the command line: outputs and error messages.

use std::path::Path;
use std::process::Command;

const GOOD: &str = r#"title = "small"
[rig]
rope = "dyneema2"
rope_length_m = 15.2
input_radius_m = 0.025
output_radius_m = 0.025
output_inertia_kg_m2 = 0.0284
output_damping_n_m_s = 0.05
[sweep]
mean_tensions_n = [49.0, 147.0]
amplitude_deg = 4.5
frequencies_hz = [1.0, 2.1, 2.4, 3.0]
settle_s = 8.0
[simulation]
dt_s = 0.001
"#;

fn longreach(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_longreach"))
        .args(args)
        .output()
        .unwrap()
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

#[test]
fn bode_writes_table_csv_json_and_png() {
    let dir = tempfile::tempdir().unwrap();
    let scen = write(dir.path(), "s.toml", GOOD);
    let json = dir.path().join("out.json");
    let csv = dir.path().join("out.csv");
    let png = dir.path().join("out.png");
    let out = longreach(&[
        "bode",
        &scen,
        "--json",
        json.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("resonance analytic [Hz]") && stdout.contains("2.304"),
        "{stdout}"
    );
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(v["rope"], "dyneema2");
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    assert_eq!(runs[0]["mean_tension_n"], 49.0);
    let res = runs[1]["resonance_hz"]["analytic"].as_f64().unwrap();
    assert!((res - 2.304).abs() < 0.002, "{res}");
    assert!(runs[1]["resonance_hz"]["simulated"].as_f64().is_some());
    assert!(runs[1]["peak_gain_db"]["analytic"].as_f64().unwrap() > 17.0);
    let p = &runs[1]["points"][2];
    for key in [
        "frequency_hz",
        "analytic_gain_db",
        "analytic_phase_deg",
        "simulated_gain_db",
        "simulated_phase_deg",
        "min_tension_n",
    ] {
        assert!(p[key].as_f64().is_some(), "missing {key}");
    }
    assert!(
        (p["simulated_gain_db"].as_f64().unwrap() - p["analytic_gain_db"].as_f64().unwrap()).abs()
            < 0.1
    );
    assert_eq!(runs[0]["slack"], true);
    assert_eq!(runs[0]["points"][2]["min_tension_n"], 0.0);
    let csv_text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(csv_text.lines().count(), 1 + 2 * 4);
    assert!(csv_text.starts_with("mean_tension_n,frequency_hz,analytic_gain_db"));
    let png_bytes = std::fs::read(&png).unwrap();
    assert_eq!(&png_bytes[1..4], b"PNG");
}

/// Each bad file fails with exit code 2 and a message naming the file, the line, the
/// field and the fix; nothing is written.
#[test]
fn bad_scenarios_name_file_line_field_and_fix() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, String, &str, &str); 5] = [
        (
            "unknown_rope.toml",
            GOOD.replace("rope = \"dyneema2\"", "rope = \"nylon6\""),
            "rig.rope",
            "catalog name",
        ),
        (
            "negative_length.toml",
            GOOD.replace("rope_length_m = 15.2", "rope_length_m = -15.2"),
            "rig.rope_length_m",
            "SI units",
        ),
        (
            "missing_field.toml",
            GOOD.replace("output_inertia_kg_m2 = 0.0284\n", ""),
            "output_inertia_kg_m2",
            "add `output_inertia_kg_m2",
        ),
        (
            "wrong_type.toml",
            GOOD.replace(
                "output_damping_n_m_s = 0.05",
                "output_damping_n_m_s = \"low\"",
            ),
            "output_damping_n_m_s",
            "expected type",
        ),
        (
            "bad_tension.toml",
            GOOD.replace("[49.0, 147.0]", "[49.0, -147.0]"),
            "sweep.mean_tensions_n.1",
            "SI units",
        ),
    ];
    for (name, text, field, fix) in cases {
        let path = write(dir.path(), name, &text);
        let json = dir.path().join(format!("{name}.json"));
        let out = longreach(&["bode", &path, "--json", json.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{name}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(name), "{name}: no file in: {err}");
        assert!(err.contains(field), "{name}: no field in: {err}");
        assert!(
            err.contains("fix:") && err.contains(fix),
            "{name}: no fix in: {err}"
        );
        let line_no = text
            .lines()
            .position(|l| {
                field
                    .rsplit('.')
                    .find(|p| p.parse::<usize>().is_err())
                    .is_some_and(|k| l.contains(k))
            })
            .map(|i| i + 1);
        if let Some(line_no) = line_no {
            if name != "missing_field.toml" {
                assert!(
                    err.contains(&format!("{name}:{line_no}")),
                    "{name}: no line {line_no} in: {err}"
                );
            }
        }
        assert!(!json.exists(), "{name}: output written despite the error");
    }
}
