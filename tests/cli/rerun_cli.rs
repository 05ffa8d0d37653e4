//! `--rerun` from the command line: recordings read back with Rerun's own Python SDK
//! (`tools/rrd_summary.py`, rerun-sdk 0.36.3, installed by `.ci/run`), results
//! unchanged by logging, unreachable viewers reported once without stopping the run.
//!
//! Without the Python SDK the read-back checks are skipped with a message, unless
//! `LONGREACH_REQUIRE_RERUN=1` (as in CI), which makes its absence a failure.

use std::path::Path;
use std::process::{Command, Output};

use serde_json::Value;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn longreach(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_longreach"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "stdout:\n{}\nstderr:\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The recording's contents as `tools/rrd_summary.py` reports them, or `None` when
/// the Python SDK is missing (and not required).
fn read_back(rrd: &Path) -> Option<Value> {
    let o = Command::new("python3")
        .arg(format!("{ROOT}/tools/rrd_summary.py"))
        .arg(rrd)
        .output();
    let required = std::env::var("LONGREACH_REQUIRE_RERUN").is_ok_and(|v| v == "1");
    match o {
        Ok(o) if o.status.success() => Some(serde_json::from_slice(&o.stdout).unwrap()),
        Ok(o) if !required && String::from_utf8_lossy(&o.stderr).contains("No module named") => {
            eprintln!("SKIPPED read-back: `pip install rerun-sdk==0.36.3` to check recordings");
            None
        }
        Err(e) if !required => {
            eprintln!("SKIPPED read-back: no python3 ({e})");
            None
        }
        Ok(o) => panic!(
            "reading {} back failed:\n{}",
            rrd.display(),
            String::from_utf8_lossy(&o.stderr)
        ),
        Err(e) => panic!("python3: {e}"),
    }
}

fn entity<'a>(summary: &'a Value, path: &str) -> &'a Value {
    let e = &summary["entities"][path];
    assert!(
        e.is_object(),
        "no entity {path}; have {:?}",
        summary["entities"]
            .as_object()
            .unwrap()
            .keys()
            .collect::<Vec<_>>()
    );
    e
}

/// `(time, value)` of a single series.
fn scalars(e: &Value) -> Vec<(f64, f64)> {
    instance(e, 0)
}

/// `(time, value)` of instance `i` of a group of series.
fn instance(e: &Value, i: usize) -> Vec<(f64, f64)> {
    e["scalars"]
        .as_array()
        .unwrap()
        .iter()
        .map(|tv| {
            (
                tv[0].as_f64().unwrap(),
                tv[1][i].as_f64().unwrap_or(f64::NAN),
            )
        })
        .collect()
}

/// Instance of the series named `name` in a group.
fn named(e: &Value, name: &str) -> usize {
    let names = e["names"].as_array().unwrap();
    names
        .iter()
        .position(|n| n == name)
        .unwrap_or_else(|| panic!("no series {name} in {names:?}"))
}

#[test]
fn an_arm_run_is_recorded_with_every_entity_and_logging_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = format!("{ROOT}/scenarios/arm_dyneema2_distal_step.toml");
    let plain = dir.path().join("plain");
    let logged = dir.path().join("logged");
    let rrd = dir.path().join("arm.rrd");
    ok(&longreach(&[
        "run",
        &scenario,
        "--out",
        plain.to_str().unwrap(),
    ]));
    let out = ok(&longreach(&[
        "run",
        &scenario,
        "--out",
        logged.to_str().unwrap(),
        "--rerun",
        &format!("save:{}", rrd.display()),
        "--rerun-hz",
        "20",
    ]));
    assert!(out.contains("wrote Rerun recording"), "{out}");
    // Logging only reads the states: the results are bitwise the same.
    let a = std::fs::read(plain.join("timeseries.csv")).unwrap();
    let b = std::fs::read(logged.join("timeseries.csv")).unwrap();
    assert!(a == b, "time series differ with logging on");
    assert_eq!(
        std::fs::read(plain.join("metrics.json")).unwrap(),
        std::fs::read(logged.join("metrics.json")).unwrap()
    );
    assert!(std::fs::metadata(&rrd).unwrap().len() > 10_000);
    let Some(s) = read_back(&rrd) else { return };
    assert_eq!(s["sdk_version"], "0.36.3");
    assert!(
        s["blueprints"].as_u64().unwrap() >= 1,
        "no default blueprint"
    );
    // 10 s at 20 Hz: t = 0 plus 200 frames.
    let frames = 201;
    let joints = entity(&s, "/series/joints/angle_rad");
    assert_eq!(joints["rows"], frames);
    assert_eq!(
        joints["names"].as_array().unwrap().len(),
        10,
        "q and ref of 5 joints"
    );
    let tensions = entity(&s, "/series/tensions/tension_n");
    assert_eq!(tensions["rows"], frames);
    named(tensions, "j1 +");
    named(tensions, "j5 -");
    assert_eq!(entity(&s, "/series/motors/torque_n_m")["rows"], frames);
    assert_eq!(entity(&s, "/series/motors/angle_rad")["rows"], frames);
    assert_eq!(entity(&s, "/series/tip/error_m")["rows"], frames);
    assert_eq!(entity(&s, "/world/ropes")["rows"], frames);
    let link5 = entity(&s, "/world/arm/link5");
    assert_eq!(link5["rows"], frames);
    // Its visuals and the pulleys on its joint axis: one static row.
    assert_eq!(link5["static_rows"], 1);
    for kind in ["Transform3D", "Cylinders3D"] {
        assert!(
            link5["components"]
                .as_array()
                .unwrap()
                .iter()
                .any(|c| c.as_str().unwrap().starts_with(kind)),
            "{kind} in {}",
            link5["components"]
        );
    }
    assert_eq!(entity(&s, "/world/motors")["static"], true);
    // Rigid links: drawn by their poses only, no bent centre lines or tip markers.
    let ents = s["entities"].as_object().unwrap();
    assert!(!ents.contains_key("/world/tip"));
    assert!(!ents.keys().any(|k| k.ends_with("/beam")));
    // Values: the recorded joint angle equals the CSV's at the same times (the CSV
    // keeps every 10th step with 10 significant digits).
    let csv = String::from_utf8(b).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|c| *c == "q_j5_rad").unwrap();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    let rec = instance(joints, named(joints, "j5 q"));
    let mut checked = 0;
    for (t, v) in &rec {
        if let Some(r) = rows.iter().find(|r| (r[0] - t).abs() < 1e-9) {
            assert!(
                (r[col] - v).abs() <= 1e-9 * v.abs().max(1e-3),
                "t = {t}: {v} vs CSV {}",
                r[col]
            );
            checked += 1;
        }
    }
    assert!(checked >= 200, "only {checked} frames matched CSV rows");
    // The distal step moves j5: its recorded angle ends near the command.
    let qref = instance(joints, named(joints, "j5 ref"));
    let (last_q, last_ref) = (rec.last().unwrap().1, qref.last().unwrap().1);
    assert!(
        (last_q - last_ref).abs() < 0.01 * last_ref.abs().max(0.01),
        "{last_q} vs {last_ref}"
    );
}

/// `(time, value)` of a geometry list of the summary (`translations`, `strips`, ...).
fn geometry<'a>(e: &'a Value, key: &str) -> Vec<(f64, &'a Value)> {
    e[key]
        .as_array()
        .unwrap_or_else(|| panic!("no {key} in {e}"))
        .iter()
        .filter(|tv| !tv[0].is_null())
        .map(|tv| (tv[0].as_f64().unwrap(), &tv[1]))
        .collect()
}

fn vec3(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    [0, 1, 2].map(|i| a[i].as_f64().unwrap())
}

/// `p` turned by the unit quaternion `[x, y, z, w]`, then moved by `t`.
fn transform(t: [f64; 3], q: [f64; 4], p: [f64; 3]) -> [f64; 3] {
    let (u, w) = ([q[0], q[1], q[2]], q[3]);
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let c1 = cross(u, p);
    let c2 = cross(u, c1);
    [0, 1, 2].map(|i| t[i] + p[i] + 2.0 * w * c1[i] + 2.0 * c2[i])
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt()
}

#[test]
fn a_flexible_arm_is_drawn_bent_with_its_tip_at_the_deflected_end() {
    let dir = tempfile::tempdir().unwrap();
    // The flexible base step, 2 s of it.
    let scenario = dir.path().join("flex.toml");
    let text = std::fs::read_to_string(format!("{ROOT}/scenarios/flex_dyneema2_base_step.toml"))
        .unwrap()
        .replace("duration_s = 10.0", "duration_s = 2.0")
        .replace("\"../robots/", &format!("\"{ROOT}/robots/"));
    assert!(text.contains("duration_s = 2.0") && text.contains(ROOT));
    std::fs::write(&scenario, text).unwrap();
    let json = dir.path().join("m.json");
    let rrd = dir.path().join("flex.rrd");
    ok(&longreach(&[
        "run",
        scenario.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--rerun",
        &format!("save:{}", rrd.display()),
        "--rerun-hz",
        "20",
    ]));
    let m: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let expected = m["tip_deflection_m"].as_f64().unwrap();
    assert!(expected > 0.01, "the links sag: {expected} m at the tip");
    let Some(s) = read_back(&rrd) else { return };
    // 2 s at 20 Hz: t = 0 plus 40 frames, each with the bent links and the tip.
    let frames = 41;
    let deflection = scalars(entity(&s, "/series/tip/deflection_m"));
    assert_eq!(deflection.len(), frames);
    let (t_end, d_end) = *deflection.last().unwrap();
    assert!((t_end - 2.0).abs() < 1e-9);
    // The recorded deflection at the end is the run's own (tip vs straight links).
    assert!(
        (d_end - expected).abs() < 1e-9 * expected,
        "{d_end} vs {expected}"
    );
    let tips = geometry(entity(&s, "/world/tip"), "points");
    assert_eq!(tips.len(), frames);
    let pts = tips.last().unwrap().1.as_array().unwrap();
    assert_eq!(pts.len(), 2, "deflected tip, then the straight one");
    let (tip, straight) = (vec3(&pts[0]), vec3(&pts[1]));
    // Points are f32: 11 m to a micrometre.
    assert!(
        (dist(tip, straight) - expected).abs() < 5e-6,
        "drawn tips {} m apart, deflection {expected} m",
        dist(tip, straight)
    );
    // The last link's centre line ends at the deflected tip (in its link frame, posed
    // by the link's transform); it starts at its joint.
    let link5 = entity(&s, "/world/arm/link5");
    let beams = geometry(entity(&s, "/world/arm/link5/beam"), "strips");
    assert_eq!(beams.len(), frames);
    let strip = beams.last().unwrap().1[0].as_array().unwrap();
    assert_eq!(strip.len(), 17);
    assert!(dist(vec3(&strip[0]), [0.0; 3]) == 0.0, "{:?}", strip[0]);
    let end = vec3(strip.last().unwrap());
    let t = vec3(&geometry(link5, "translations").last().unwrap().1[0]);
    let q = geometry(link5, "quaternions").last().unwrap().1[0]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect::<Vec<_>>();
    let drawn_end = transform(t, [q[0], q[1], q[2], q[3]], end);
    assert!(
        dist(drawn_end, tip) < 5e-6,
        "beam ends {} m from the tip",
        dist(drawn_end, tip)
    );
    // Every link bends: a centre line for each.
    for l in 1..=5 {
        assert_eq!(
            entity(&s, &format!("/world/arm/link{l}/beam"))["rows"],
            frames
        );
    }
}

#[test]
fn modes_are_drawn_oscillating_at_their_frequency_and_scale() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = format!("{ROOT}/scenarios/flex_dyneema2_base_step.toml");
    let json = dir.path().join("m.json");
    let rrd = dir.path().join("m.rrd");
    let out = ok(&longreach(&[
        "modes",
        &scenario,
        "--top",
        "5",
        "--json",
        json.to_str().unwrap(),
        "--rerun",
        &format!("save:{}", rrd.display()),
    ]));
    assert!(out.contains("wrote Rerun recording"), "{out}");
    let j: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let Some(s) = read_back(&rrd) else { return };
    let ents = s["entities"].as_object().unwrap();
    // The five lowest modes, no more.
    assert!(ents.contains_key("/modes/mode_05/series/joints_rad"));
    assert!(!ents.contains_key("/modes/mode_06/series/joints_rad"));
    let mut bending_checked = false;
    for (i, md) in j["modes"].as_array().unwrap().iter().take(5).enumerate() {
        let root = format!("/modes/mode_{:02}", i + 1);
        let period = 1.0 / md["damped_hz"].as_f64().unwrap();
        // Two periods of 32 frames, on the mode's own time: back to the full amplitude
        // after one period of the damped frequency, through the pose at a quarter.
        let tip = scalars(entity(&s, &format!("{root}/series/tip_m")));
        assert_eq!(tip.len(), 65, "{root}");
        let amp = tip[0].1;
        assert!(amp > 1e-4 && amp <= 0.05 * 11.1, "{root}: tip {amp} m");
        for (frame, share) in [(32, 1.0), (64, 2.0), (16, 0.5), (8, 0.25)] {
            let t = tip[frame].0;
            assert!(
                (t - share * period).abs() < 1e-9, // nanoseconds in the file
                "{root} frame {frame} at {t} s, period {period} s"
            );
        }
        assert!((tip[32].1 - amp).abs() < 1e-9 * amp, "{root}");
        assert!((tip[64].1 - amp).abs() < 1e-9 * amp, "{root}");
        assert!(
            tip[8].1 < 1e-9,
            "{root}: {} m at a quarter period",
            tip[8].1
        );
        let joints = entity(&s, &format!("{root}/series/joints_rad"));
        assert_eq!(
            joints["names"],
            serde_json::json!(["j1", "j2", "j3", "j4", "j5"])
        );
        let want: Vec<f64> = md["joints_rad"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a["angle"].as_f64().unwrap())
            .collect();
        let big = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if big > 1e-6 {
            // The joints move along the mode's shape (one scale for all), in its
            // phase, and swing to the opposite side after half a period.
            let jb = (0..want.len())
                .max_by(|&a, &b| want[a].abs().total_cmp(&want[b].abs()))
                .unwrap();
            let scale = instance(joints, jb)[0].1 / want[jb];
            assert!(scale > 0.0, "{root}: drawn in the mode's phase");
            for (k, w) in want.iter().enumerate() {
                let v = instance(joints, k);
                assert!(
                    (v[0].1 - scale * w).abs() <= 1e-9 * scale * big,
                    "{root} j{}: {} vs {}",
                    k + 1,
                    v[0].1,
                    scale * w
                );
                assert!((v[16].1 + v[0].1).abs() <= 1e-9 * scale * big);
                assert!((v[32].1 - v[0].1).abs() <= 1e-9 * scale * big);
            }
        } else {
            // A bending mode: the joints hold; the bent links' ends swing in the
            // proportions of the mode's link-end deflections.
            bending_checked = true;
            let mut ratios = Vec::new();
            for e in md["link_ends_m"].as_array().unwrap() {
                let want = e["in_plane"]
                    .as_f64()
                    .unwrap()
                    .hypot(e["out_of_plane"].as_f64().unwrap());
                let link = e["link"].as_str().unwrap();
                let beams = geometry(entity(&s, &format!("{root}/arm/{link}/beam")), "strips");
                assert_eq!(beams.len(), 65);
                let end = |k: usize| vec3(beams[k].1[0].as_array().unwrap().last().unwrap());
                ratios.push((dist(end(0), end(16)), 2.0 * want));
            }
            let (d0, w0) = ratios
                .iter()
                .copied()
                .fold((0.0, 0.0), |m, r| if r.1 > m.1 { r } else { m });
            for (d, w) in ratios {
                if w > 0.01 * w0 {
                    assert!(
                        (d / d0 - w / w0).abs() < 1e-4,
                        "{root}: link end swings {d} of {d0}, mode {w} of {w0}"
                    );
                }
            }
        }
        assert_eq!(entity(&s, &format!("{root}/arm/link3"))["rows"], 65);
        let text = entity(&s, &format!("{root}/info"))["text"]
            .as_str()
            .unwrap()
            .to_string();
        let f_n = md["natural_hz"].as_f64().unwrap();
        assert!(text.contains(&format!("{f_n:.4} Hz")), "{text}");
        assert!(
            text.contains(&format!("{:.4}", md["damping_ratio"].as_f64().unwrap())),
            "{text}"
        );
    }
    assert!(bending_checked, "mode 5 bends the links (2.81 Hz)");
}

#[test]
fn modes_that_fail_leave_no_recording() {
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("m.rrd");
    // Relay friction has no linearisation: modes refuses it.
    let o = longreach(&[
        "modes",
        &format!("{ROOT}/scenarios/arm_dyneema2_base_step_relay_friction.toml"),
        "--rerun",
        &format!("save:{}", rrd.display()),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("relay friction"));
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn a_bode_run_records_gain_and_phase_per_frequency() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("b.toml");
    let text = std::fs::read_to_string(format!("{ROOT}/scenarios/bode_stainless1.toml"))
        .unwrap()
        .replace(
            "mean_tensions_n = [49.0, 98.0, 147.0, 196.0, 245.0, 294.0, 343.0, 392.0]",
            "mean_tensions_n = [147.0, 294.0]",
        )
        .replace(
            "frequencies_hz = [0.1, 0.2, 0.4, 0.7, 1.0, 1.4, 1.8, 2.1, 2.4, 2.7, 3.0, 3.3, 3.6, 4.0, 4.5, 5.0, 6.0]",
            "frequencies_hz = [1.0, 3.0, 5.0]",
        );
    assert!(text.contains("[147.0, 294.0]") && text.contains("[1.0, 3.0, 5.0]"));
    std::fs::write(&scenario, text).unwrap();
    let json = dir.path().join("b.json");
    let rrd = dir.path().join("b.rrd");
    ok(&longreach(&[
        "bode",
        scenario.to_str().unwrap(),
        "--quiet",
        "--json",
        json.to_str().unwrap(),
        &format!("--rerun=save:{}", rrd.display()),
    ]));
    // Logging (the runs handed to the logging thread as they finish) changes nothing.
    let plain = dir.path().join("plain.json");
    ok(&longreach(&[
        "bode",
        scenario.to_str().unwrap(),
        "--quiet",
        "--json",
        plain.to_str().unwrap(),
    ]));
    let j_text = std::fs::read_to_string(&json).unwrap();
    assert_eq!(j_text, std::fs::read_to_string(&plain).unwrap());
    let Some(s) = read_back(&rrd) else { return };
    let j: Value = serde_json::from_str(&j_text).unwrap();
    // Gain and phase: one entity each for every run, a line per run and model, a row
    // per test frequency.
    let gain = entity(&s, "/bode/gain_db");
    let phase = entity(&s, "/bode/phase_deg");
    let names = serde_json::json!([
        "T147N simulated",
        "T147N analytic",
        "T294N simulated",
        "T294N analytic"
    ]);
    assert_eq!(gain["names"], names);
    assert_eq!(phase["names"], names);
    assert_eq!(gain["rows"], 3, "one row per test frequency");
    for (r, run) in j["runs"].as_array().unwrap().iter().enumerate() {
        let points = run["points"].as_array().unwrap();
        assert_eq!(points.len(), 3);
        for (k, key) in [(0, "simulated"), (1, "analytic")] {
            let g = instance(gain, 2 * r + k);
            let ph = instance(phase, 2 * r + k);
            for (i, p) in points.iter().enumerate() {
                assert!((p["frequency_hz"].as_f64().unwrap() * 1e3 - g[i].0).abs() < 0.5);
                let (pg, pp) = (
                    p[format!("{key}_gain_db")].as_f64().unwrap(),
                    p[format!("{key}_phase_deg")].as_f64().unwrap(),
                );
                assert!((pg - g[i].1).abs() < 1e-12, "run {r} {key} gain");
                assert!((pp - ph[i].1).abs() < 1e-12, "run {r} {key} phase");
            }
        }
    }
    // The rig's series per run: two groups with named instances, a row per logged
    // frame; the ropes' colours on every frame (their geometry static).
    for (run, mean_n) in [("T147N", 147.0), ("T294N", 294.0)] {
        let angles = entity(&s, &format!("/rig/{run}/series/angles_rad"));
        assert!(angles["rows"].as_u64().unwrap() > 100);
        assert_eq!(
            angles["names"],
            serde_json::json!([format!("{run} input"), format!("{run} output")])
        );
        let tensions = entity(&s, &format!("/rig/{run}/series/tensions_n"));
        assert_eq!(
            tensions["names"],
            serde_json::json!([format!("{run} rope 1"), format!("{run} rope 2")])
        );
        for e in ["series/tensions_n", "ropes"] {
            let e = format!("/rig/{run}/{e}");
            assert_eq!(entity(&s, &e)["rows"], angles["rows"], "{e}");
        }
        // Both ropes start at the mean tension, and both pulleys at rest.
        for i in 0..2 {
            let (t, f) = instance(tensions, i)[0];
            assert!(
                t == 0.0 && (f - mean_n).abs() < 1e-9,
                "{run} rope {}: {f} N at {t} s",
                i + 1
            );
            assert_eq!(instance(angles, i)[0], (0.0, 0.0));
        }
    }
}

#[test]
fn compare_records_measured_model_and_residual_per_run() {
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("c.rrd");
    let data = format!("{ROOT}/data/examples/example_relax_control");
    ok(&longreach(&[
        "compare",
        &data,
        "--rerun",
        &format!("save:{}", rrd.display()),
    ]));
    let Some(s) = read_back(&rrd) else { return };
    let ents = s["entities"].as_object().unwrap();
    let measured: Vec<&String> = ents
        .keys()
        .filter(|k| k.starts_with("/compare/") && k.ends_with("/measured"))
        .collect();
    assert!(
        !measured.is_empty(),
        "{:?}",
        ents.keys().collect::<Vec<_>>()
    );
    for m in measured {
        let run = m.trim_end_matches("/measured");
        let meas = scalars(&ents[m]);
        let model = scalars(&ents[&format!("{run}/model")]);
        let resid = scalars(&ents[&format!("{run}/residual")]);
        assert_eq!(meas.len(), model.len());
        assert!(meas.len() > 100);
        for k in [0, meas.len() / 2, meas.len() - 1] {
            assert!((meas[k].1 - model[k].1 - resid[k].1).abs() < 1e-9);
        }
    }
}

/// Columns of a CSV file with a header: name -> values.
fn csv_columns(path: &str) -> std::collections::HashMap<String, Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); header.len()];
    for l in lines.filter(|l| !l.trim().is_empty()) {
        for (c, x) in cols.iter_mut().zip(l.split(',')) {
            c.push(x.trim().parse().unwrap());
        }
    }
    header.into_iter().zip(cols).collect()
}

/// Angle of a rotation about y from its quaternion `[x, y, z, w]`.
fn pitch(q: &Value) -> f64 {
    let q: Vec<f64> = q
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!(q[0].abs() < 1e-6 && q[2].abs() < 1e-6, "not about y: {q:?}");
    2.0 * q[1].atan2(q[3])
}

#[test]
fn compare_on_an_arm_dataset_records_both_arms_and_every_channel() {
    let dir = tempfile::tempdir().unwrap();
    let rrd = dir.path().join("a.rrd");
    let json = dir.path().join("a.json");
    let data = format!("{ROOT}/data/examples/example_arm_control");
    let plain = dir.path().join("plain.json");
    let o = longreach(&[
        "compare",
        &data,
        "--json",
        json.to_str().unwrap(),
        "--rerun",
        &format!("save:{}", rrd.display()),
    ]);
    let out = ok(&o);
    assert!(out.contains("wrote Rerun recording"), "{out}");
    assert!(!String::from_utf8_lossy(&o.stderr).contains("does not draw"));
    // Drawing only reads the simulated states: the comparison is the same without it.
    ok(&longreach(&[
        "compare",
        &data,
        "--json",
        plain.to_str().unwrap(),
    ]));
    let j_text = std::fs::read_to_string(&json).unwrap();
    assert_eq!(j_text, std::fs::read_to_string(&plain).unwrap());
    let Some(s) = read_back(&rrd) else { return };
    let j: Value = serde_json::from_str(&j_text).unwrap();
    let channels = j["channels"].as_array().unwrap();
    // 4 runs x 23 channels (5 motors, 5 joints, 10 tensions, the tip's 3 axes).
    let runs = ["move_01", "move_02", "move_03", "move_04"];
    assert_eq!(channels.len(), 4 * 23);
    for run in runs {
        let csv = csv_columns(&format!("{data}/{run}.csv"));
        let samples = csv["time_s"].len();
        assert_eq!(samples, 401);
        for ch in channels.iter().filter(|c| c["run"] == run) {
            let name = ch["channel"].as_str().unwrap();
            let root = format!("/compare/{run}/{name}");
            let measured = scalars(entity(&s, &format!("{root}/measured")));
            let model = scalars(entity(&s, &format!("{root}/model")));
            let residual = scalars(entity(&s, &format!("{root}/residual")));
            assert_eq!(measured.len(), samples, "{root}");
            assert_eq!(model.len(), samples, "{root}");
            // The measured series is the dataset's column, at its times.
            for (k, (t, v)) in measured.iter().enumerate() {
                assert!((t - csv["time_s"][k]).abs() < 1e-9, "{root} t");
                // The same decimal text parsed to the same f64 (then sent as f64).
                assert!(v.to_bits() == csv[name][k].to_bits(), "{root} sample {k}");
                assert!((v - model[k].1 - residual[k].1).abs() < 1e-12);
            }
            // The model series is what compare measured against: its RMS error.
            let rms = (measured
                .iter()
                .zip(&model)
                .map(|(a, b)| (a.1 - b.1).powi(2))
                .sum::<f64>()
                / samples as f64)
                .sqrt();
            let want = ch["rms_error"].as_f64().unwrap();
            assert!(
                (rms - want).abs() <= 1e-9 * want.max(1e-12),
                "{root}: {rms} vs {want}"
            );
        }
        // Both arms, posed at every sample: the measured one from its joint encoders
        // (longreach5 pitches every joint about y: link 5's angle is their sum), the
        // model one from the simulated states, 2.75 m beside it.
        let measured5 = entity(&s, &format!("/world/{run}/measured/link5"));
        let model5 = entity(&s, &format!("/world/{run}/model/link5"));
        assert_eq!(measured5["rows"], samples);
        assert_eq!(model5["rows"], samples);
        let q = geometry(measured5, "quaternions");
        let model_q = geometry(model5, "quaternions");
        let model_joints: Vec<Vec<(f64, f64)>> = (1..=5)
            .map(|j| scalars(entity(&s, &format!("/compare/{run}/joint_j{j}_rad/model"))))
            .collect();
        for k in [0, samples / 4, samples / 2, samples - 1] {
            let sum: f64 = (1..=5).map(|j| csv[&format!("joint_j{j}_rad")][k]).sum();
            let drawn = pitch(&q[k].1[0]);
            assert!(
                (drawn - sum).abs() < 1e-6,
                "{run} sample {k}: {drawn} vs {sum}"
            );
            let model_sum: f64 = model_joints.iter().map(|m| m[k].1).sum();
            let drawn = pitch(&model_q[k].1[0]);
            assert!(
                (drawn - model_sum).abs() < 1e-6,
                "{run} model sample {k}: {drawn} vs {model_sum}"
            );
        }
        // The measured tip, where the dataset has it (f32 points).
        let tips = geometry(entity(&s, &format!("/world/{run}/measured/tip")), "points");
        assert_eq!(tips.len(), samples);
        for (k, (_, p)) in tips.iter().enumerate() {
            let p = vec3(&p[0]);
            for (a, axis) in ["x", "y", "z"].iter().enumerate() {
                let want = csv[&format!("tip_{axis}_m")][k];
                assert!((p[a] - want).abs() < 2e-6, "{run} tip {axis} sample {k}");
            }
        }
        assert_eq!(
            entity(&s, &format!("/world/{run}/model/tip"))["rows"],
            samples
        );
        let offset = entity(&s, &format!("/world/{run}/model"));
        let t = vec3(geometry_static(offset, "translations")[0]);
        assert!((t[1] - 0.25 * 11.0).abs() < 0.01 && t[0] == 0.0, "{t:?}");
        assert_eq!(
            entity(&s, &format!("/world/{run}/measured/tip_path"))["static"],
            true
        );
    }
}

#[test]
fn diagnose_on_an_arm_dataset_records_the_arms_the_winner_and_the_ranking() {
    // A short synthetic arm dataset with joint friction hidden (1.5 s at 50 Hz: the
    // diagnosis takes seconds, not the minutes of the examples).
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("friction");
    ok(&longreach(&[
        "synth",
        "--arm",
        &format!("{ROOT}/scenarios/arm_dyneema2_distal_step.toml"),
        "--move",
        "j5:0.1",
        "--duration-s",
        "1.5",
        "--sample-hz",
        "50",
        "--effect",
        "joint_friction",
        "--out",
        data.to_str().unwrap(),
    ]));
    let rrd = dir.path().join("d.rrd");
    let rep = dir.path().join("rep");
    let out = ok(&longreach(&[
        "diagnose",
        data.to_str().unwrap(),
        "--rerun",
        &format!("save:{}", rrd.display()),
        "--report",
        rep.to_str().unwrap(),
    ]));
    assert!(out.contains("missing effect: joint_friction"), "{out}");
    // The report's arm part: what the sensors show, and every joint measured with the
    // baseline and the named model.
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(
        md.contains("## The arm") && md.contains("Against the model with joint_friction"),
        "{md}"
    );
    assert!(rep.join("arm_diagnosis_move_01.png").is_file());
    let Some(s) = read_back(&rrd) else { return };
    let ranking = entity(&s, "/diagnose/ranking")["text"].as_str().unwrap();
    assert!(ranking.contains("| 1 | joint_friction |"), "{ranking}");
    let csv = csv_columns(data.join("move_01.csv").to_str().unwrap());
    let samples = csv["time_s"].len();
    assert_eq!(samples, 76);
    let root = "/compare/move_01/joint_j5_rad";
    let measured = scalars(entity(&s, &format!("{root}/measured")));
    let model = scalars(entity(&s, &format!("{root}/model")));
    let after = scalars(entity(&s, &format!("{root}/with_effect")));
    assert_eq!(measured.len(), samples);
    assert_eq!(after.len(), samples);
    for (k, (_, v)) in measured.iter().enumerate() {
        assert!(
            v.to_bits() == csv["joint_j5_rad"][k].to_bits(),
            "sample {k}"
        );
    }
    let rms = |m: &[(f64, f64)]| {
        (measured
            .iter()
            .zip(m)
            .map(|(a, b)| (a.1 - b.1).powi(2))
            .sum::<f64>()
            / samples as f64)
            .sqrt()
    };
    // The friction the baseline misses shows on the moved joint: the winner's channel
    // is much closer to the measurement.
    let (base, with) = (rms(&model), rms(&after));
    assert!(
        with < 0.5 * base,
        "joint j5: {with} rad rms with the effect, {base} without"
    );
    assert_eq!(entity(&s, "/world/move_01/model/link5")["rows"], samples);
    assert_eq!(entity(&s, "/world/move_01/measured/link5")["rows"], samples);
    // Not the stacked channel the fit compares.
    let ents = s["entities"].as_object().unwrap();
    assert!(!ents.contains_key("/compare/move_01/measured"));
}

/// The static values of a geometry list of the summary.
fn geometry_static<'a>(e: &'a Value, key: &str) -> Vec<&'a Value> {
    e[key]
        .as_array()
        .unwrap_or_else(|| panic!("no {key} in {e}"))
        .iter()
        .filter(|tv| tv[0].is_null())
        .map(|tv| &tv[1][0])
        .collect()
}

#[test]
fn an_unreachable_viewer_is_reported_once_and_the_run_goes_on() {
    let scenario = format!("{ROOT}/scenarios/arm5_elastic_stainless1.toml");
    // No viewer listens on port 1.
    let o = longreach(&["run", &scenario, "--rerun", "connect:127.0.0.1:1"]);
    let stdout = ok(&o);
    assert!(stdout.contains("tip position error"), "{stdout}");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(stderr.matches("rerun:").count(), 1, "{stderr}");
    assert!(stderr.contains("127.0.0.1:1"), "{stderr}");
    // `spawn` with no viewer on PATH: a clear message with the install command.
    let o = Command::new(env!("CARGO_BIN_EXE_longreach"))
        .args(["run", &scenario, "--rerun", "spawn"])
        .env("PATH", "/nonexistent")
        .output()
        .unwrap();
    ok(&o);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(stderr.matches("rerun:").count(), 1, "{stderr}");
    assert!(stderr.contains("pip install rerun-sdk==0.36.3"), "{stderr}");
}

#[test]
fn bad_targets_and_rates_fail_before_the_run() {
    let scenario = format!("{ROOT}/scenarios/arm5_elastic_stainless1.toml");
    for (args, expect) in [
        (vec!["--rerun", "viewer"], "save:FILE.rrd"),
        (vec!["--rerun", "connect:host"], "needs a port"),
        (
            vec!["--rerun", "save:/nonexistent-dir/x.rrd"],
            "folder exists",
        ),
        (vec!["--rerun", "--rerun-hz", "0"], "--rerun-hz"),
    ] {
        let mut all = vec!["run", scenario.as_str()];
        all.extend(args.iter().copied());
        let o = longreach(&all);
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(stderr.contains(expect), "{args:?}: {stderr}");
        assert!(
            !String::from_utf8_lossy(&o.stdout).contains("steps of"),
            "ran anyway"
        );
    }
    // A file given as the target: the message says how to write it.
    let o = longreach(&["run", &scenario, "--rerun", &scenario]);
    assert_eq!(o.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("before `--rerun`"), "{stderr}");
}

#[test]
fn a_batch_records_the_selected_scenarios_only() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("quick");
    let batch = format!("{ROOT}/scenarios/batch_quick.toml");
    let o = longreach(&[
        "batch",
        &batch,
        "-j",
        "2",
        "--out",
        out.to_str().unwrap(),
        "--rerun-select",
        "1,4",
    ]);
    ok(&o);
    let rec = out.join("rerun");
    let mut names: Vec<String> = std::fs::read_dir(&rec)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["1.rrd", "4.rrd"]);
    // A selection outside the batch fails before running.
    let o = longreach(&[
        "batch",
        &batch,
        "--out",
        out.to_str().unwrap(),
        "--rerun-select",
        "99",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--dry-run"));
    let Some(s) = read_back(&rec.join("4.rrd")) else {
        return;
    };
    // Scenario 4 is a Bode run at one mean tension: its gain, simulated and analytic.
    let gain = entity(&s, "/bode/gain_db");
    let names = gain["names"].as_array().unwrap();
    assert_eq!(names.len(), 2, "{names:?}");
    assert!(
        names[0].as_str().unwrap().ends_with(" simulated"),
        "{names:?}"
    );
    assert!(gain["rows"].as_u64().unwrap() > 0);
}
