//! `longreach run` from the command line: outputs, metrics and error messages.

use std::process::Command;

fn longreach(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_longreach"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn run_writes_time_series_and_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenarios/arm_stainless1_base_step.toml"
    );
    let out = dir.path().join("out");
    let json = dir.path().join("m.json");
    let o = longreach(&[
        "run",
        scenario,
        "--out",
        out.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("settling 2% (s)") && stdout.contains("safety factor"),
        "{stdout}"
    );
    let csv = std::fs::read_to_string(out.join("timeseries.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    for col in [
        "time_s",
        "q_j1_rad",
        "motor_j5_rad",
        "tension_j3_neg_n",
        "tip_z_m",
    ] {
        assert!(
            header.split(',').any(|c| c == col),
            "{col} missing in {header}"
        );
    }
    // 10 s at dt = 1 ms every 10 steps: 1001 rows plus the header.
    assert_eq!(csv.lines().count(), 1002);
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let j1 = &m["joints"][0];
    assert!((j1["move_rad"].as_f64().unwrap() - 0.1).abs() < 1e-12);
    let settle = j1["settling_time_s"].as_f64().unwrap();
    assert!(settle > 0.1 && settle < 5.0, "{settle}");
    // The design keeps every rope below a third of its strength.
    for p in m["pairs"].as_array().unwrap() {
        assert!(p["safety_factor"].as_f64().unwrap() > 3.0, "{p}");
    }
}

#[test]
fn bad_scenario_names_file_line_field_and_fix() {
    let dir = tempfile::tempdir().unwrap();
    let robots = concat!(env!("CARGO_MANIFEST_DIR"), "/robots/arm5/arm5.urdf");
    let text = format!(
        "[arm]\nurdf = \"{robots}\"\n[sim]\ndt_s = 0.001\nduration_s = 1.0\n[[transmission]]\njoint = \"q1\"\nrope = \"dyneema2\"\njoint_radius_m = 0.02\npreload_n = 100.0\nmotor = {{ mode = \"servo\", inertia_kg_m2 = 0.1 }}\ncommand = {{ kind = \"jump\" }}\n"
    );
    let path = dir.path().join("bad.toml");
    std::fs::write(&path, text).unwrap();
    let o = longreach(&["run", path.to_str().unwrap()]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("bad.toml:12"), "{err}");
    assert!(err.contains("transmission.0.command.kind"), "{err}");
    assert!(
        err.contains("unknown command kind 'jump'") && err.contains("fix:"),
        "{err}"
    );
}
