//! Batches of long-reach arm scenarios (`longreach run` kind): the arm plugs into the
//! batch runner, and a row's metrics equal a direct run of the same scenario.

use std::path::PathBuf;
use std::process::Command;

fn scenarios() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios")
}

#[test]
fn arm_batch_rows_equal_direct_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let base = scenarios().join("arm_dyneema2_base_step.toml");
    let batch = tmp.path().join("arm.toml");
    std::fs::write(
        &batch,
        format!(
            "base = {:?}\n[set]\n\"sim.duration_s\" = 1.0\n\
             [[axis]]\npath = \"transmission_defaults.rope\"\nvalues = [\"dyneema2\", \"zylon2\"]\n",
            base.display().to_string()
        ),
    )
    .unwrap();
    let out = tmp.path().join("out");
    let csv = run_batch(&batch, &out, &["--keep-outputs"]);
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header[..3],
        ["index", "transmission_defaults.rope", "tip_error_m"]
    );
    let peak = header
        .iter()
        .position(|h| *h == "j1_peak_tension_n")
        .unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 2);
    // The zylon2 scenario written by hand, run directly.
    let text = std::fs::read_to_string(&base)
        .unwrap()
        .replace("duration_s = 10.0", "duration_s = 1.0")
        .replacen("rope = \"dyneema2\"", "rope = \"zylon2\"", 1);
    assert!(text.contains("duration_s = 1.0"));
    let sc = longreach_arm::scenario::parse(&text, "by hand", &scenarios()).unwrap();
    let (_, m) = longreach_arm::run::run(
        &sc.arm,
        sc.sim.duration_s,
        sc.sim.output_every,
        sc.sim.residual_window_s,
        &mut |_, _| {},
    )
    .unwrap();
    let row = &rows[1];
    assert_eq!(row[1], "zylon2");
    assert_eq!(
        row[2].parse::<f64>().unwrap().to_bits(),
        m.tip_error_m.to_bits()
    );
    let j1 = m.pairs.iter().find(|p| p.joint == "j1").unwrap();
    assert_eq!(
        row[peak].parse::<f64>().unwrap().to_bits(),
        j1.peak_tension_n.to_bits()
    );
    // Different ropes give different tensions (the axis reached the model).
    assert_ne!(rows[0][2], rows[1][2]);
    assert_eq!(row[row.len() - 2], "ok");
    // The kept scenario runs from its own folder (`longreach run`) and gives the row.
    let kept = out.join("scenarios").join("1.toml");
    let run_out = tmp.path().join("run1");
    let o = Command::new(env!("CARGO_BIN_EXE_longreach"))
        .args([
            "run",
            kept.to_str().unwrap(),
            "--out",
            run_out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run_out.join("metrics.json")).unwrap())
            .unwrap();
    assert_eq!(
        metrics["tip_error_m"].as_f64().unwrap().to_bits(),
        m.tip_error_m.to_bits(),
        "{metrics}"
    );
}

/// The shipped rope x preload x payload study (scenarios/batch_arm_ropes_preloads_payloads.toml)
/// through the CLI: 8 rows, and every metric that a payload should worsen does.
#[test]
fn arm_rope_preload_payload_study_is_monotone_in_payload() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let batch = scenarios().join("batch_arm_ropes_preloads_payloads.toml");
    let csv = run_batch(&batch, &out, &[]);
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
    };
    let (payload, sag, settle, peak) = (
        col("payload.mass_kg"),
        col("tip_error_m"),
        col("j1_settling_time_s"),
        col("j1_peak_tension_n"),
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 8);
    let num = |r: &[&str], c: usize| -> f64 {
        r[c].parse()
            .unwrap_or_else(|_| panic!("column {} = '{}' in {r:?}", header[c], r[c]))
    };
    // index = 4 rope + 2 preload + payload: rows 2k and 2k + 1 differ only by payload.
    for k in 0..4 {
        let (light, heavy) = (&rows[2 * k], &rows[2 * k + 1]);
        assert!(num(light, payload).abs() < 1e-12, "{light:?}");
        assert!((num(heavy, payload) - 6.0).abs() < 1e-12, "{heavy:?}");
        println!(
            "{} preload {}: tip sag {:.3} -> {:.3} mm, j1 settling {:.3} -> {:.3} s, peak {:.0} -> {:.0} N",
            light[1],
            light[2],
            1e3 * num(light, sag),
            1e3 * num(heavy, sag),
            num(light, settle),
            num(heavy, settle),
            num(light, peak),
            num(heavy, peak)
        );
        assert!(
            num(heavy, sag) > num(light, sag),
            "sag {light:?} vs {heavy:?}"
        );
        assert!(
            num(heavy, settle) >= num(light, settle),
            "settling {light:?} vs {heavy:?}"
        );
        assert!(
            num(heavy, peak) > num(light, peak),
            "peak {light:?} vs {heavy:?}"
        );
    }
}

/// Runs `longreach batch BATCH --out OUT EXTRA..`, demands success, returns results.csv.
fn run_batch(batch: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_longreach"))
        .args([
            "batch",
            batch.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .args(extra)
        .output()
        .unwrap();
    assert_eq!(
        o.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    std::fs::read_to_string(out.join("results.csv")).unwrap()
}
