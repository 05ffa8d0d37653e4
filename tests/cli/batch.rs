//! `longreach batch` and `longreach merge` end to end: determinism across thread counts,
//! resume after an interruption, shards merged back into the unsharded table, failing
//! scenarios as error rows, and malformed batch files rejected before anything runs.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use longreach_scenario::BodeScenario;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// A cheap stepped sine (3 frequencies, 1 s settle, dt 2 ms): ~10 ms per scenario.
const CHEAP: &str = r#"
[set]
"sweep.mean_tensions_n" = [98.0]
"sweep.frequencies_hz" = [1.5, 2.5, 3.5]
"sweep.settle_s" = 1.0
"sweep.min_cycles" = 1
"sweep.min_hold_s" = 0.5
"simulation.dt_s" = 0.002
"#;

/// Writes a batch file over scenarios/bode_dyneema2.toml with the cheap [set] and `body`.
fn batch_file(dir: &Path, name: &str, body: &str) -> PathBuf {
    let base = root().join("scenarios/bode_dyneema2.toml");
    let text = format!("base = {:?}\n{body}\n{CHEAP}", base.display().to_string());
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

fn longreach(args: &[&str], envs: &[(&str, &str)]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_longreach"));
    cmd.args(args);
    for var in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_STEP",
        "JOB_COMPLETION_INDEX",
        "LONGREACH_SHARD_COUNT",
    ] {
        cmd.env_remove(var);
    }
    cmd.envs(envs.iter().copied());
    cmd.output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn run_batch(file: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "batch",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    longreach(&args, &[])
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Asserts two files are bitwise equal, showing where they first differ.
fn assert_same_file(a: &Path, b: &Path) {
    let (x, y) = (read(a), read(b));
    if x != y {
        let at = x
            .iter()
            .zip(&y)
            .position(|(p, q)| p != q)
            .unwrap_or(x.len().min(y.len()));
        let show = |v: &[u8]| {
            String::from_utf8_lossy(&v[at.saturating_sub(80)..(at + 80).min(v.len())]).into_owned()
        };
        panic!(
            "{} ({} bytes) and {} ({} bytes) differ at byte {at}:\n{}\n---\n{}",
            a.display(),
            x.len(),
            b.display(),
            y.len(),
            show(&x),
            show(&y)
        );
    }
}

const STUDY: &str = r#"
seed = 7
samples = 2
[[axis]]
path = "rig.rope"
values = ["dyneema2", "vectran2", "zylon2"]
[[axis]]
path = "sweep.mean_tensions_n.0"
values = [98.0, 392.0]
[[random]]
path = "rig.output_damping_n_m_s"
uniform = [0.02, 0.1]
"#;

#[test]
fn table_is_bitwise_identical_for_one_and_two_threads() {
    let tmp = tempfile::tempdir().unwrap();
    let file = batch_file(tmp.path(), "study", STUDY);
    let (a, b) = (tmp.path().join("j1"), tmp.path().join("j2"));
    let oa = run_batch(&file, &a, &["-j", "1"]);
    let ob = run_batch(&file, &b, &["-j", "2"]);
    assert_eq!(oa.status.code(), Some(0), "{}", stderr(&oa));
    assert_eq!(ob.status.code(), Some(0), "{}", stderr(&ob));
    let csv = read(&a.join("results.csv"));
    assert_eq!(csv, read(&b.join("results.csv")));
    assert_same_file(&a.join("results.parquet"), &b.join("results.parquet"));
    // 3 ropes x 2 preloads x 2 samples, sorted by index, all ok.
    let text = String::from_utf8(csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 13);
    assert!(lines[0].starts_with(
        "index,rig.rope,sweep.mean_tensions_n.0,rig.output_damping_n_m_s,sample,analytic_resonance_hz"
    ));
    for (i, line) in lines[1..].iter().enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells[0], i.to_string());
        assert_eq!(cells[1], ["dyneema2", "vectran2", "zylon2"][i / 4]);
        assert_eq!(cells[2], ["98.0", "392.0"][(i / 2) % 2]);
        assert_eq!(cells[4], (i % 2).to_string());
        let damping: f64 = cells[3].parse().unwrap();
        assert!((0.02..0.1).contains(&damping), "{damping}");
        assert_eq!(cells[cells.len() - 2], "ok");
    }
    // Random draws differ between scenarios (seeded by index, not repeated).
    assert_ne!(lines[1].split(',').nth(3), lines[2].split(',').nth(3));
}

#[test]
fn row_metrics_equal_a_direct_run_of_the_same_scenario() {
    let tmp = tempfile::tempdir().unwrap();
    let file = batch_file(
        tmp.path(),
        "one",
        "[[axis]]\npath = \"rig.output_inertia_kg_m2\"\nvalues = [0.0284, 0.0568]\n",
    );
    let out = tmp.path().join("out");
    let o = run_batch(&file, &out, &["--keep-outputs"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = String::from_utf8(read(&out.join("results.csv"))).unwrap();
    let row: Vec<&str> = text.lines().nth(2).unwrap().split(',').collect();
    // --keep-outputs: each scenario's expanded TOML (runnable alone) and full output.
    let kept = String::from_utf8(read(&out.join("scenarios/1.toml"))).unwrap();
    let kept = BodeScenario::from_str(&kept, "kept").unwrap();
    assert!((kept.rigs[0].output_inertia_kg_m2 - 0.0568).abs() < 1e-15);
    let json: serde_json::Value =
        serde_json::from_slice(&read(&out.join("scenarios/1.json"))).unwrap();
    let kept_f = json[0]["analytic"]["frequency_hz"].as_f64().unwrap();
    // The same scenario written by hand: base with the cheap settings and I = 0.0568.
    let base = std::fs::read_to_string(root().join("scenarios/bode_dyneema2.toml")).unwrap();
    let mut by_hand = String::new();
    for line in base.lines() {
        let key = line.split('=').next().unwrap_or("").trim();
        let line = match key {
            "output_inertia_kg_m2" => "output_inertia_kg_m2 = 0.0568".to_string(),
            "mean_tensions_n" => "mean_tensions_n = [98.0]".into(),
            "frequencies_hz" => "frequencies_hz = [1.5, 2.5, 3.5]".into(),
            "settle_s" => "settle_s = 1.0".into(),
            "min_cycles" => "min_cycles = 1".into(),
            "min_hold_s" => "min_hold_s = 0.5".into(),
            "dt_s" => "dt_s = 0.002".into(),
            _ => line.to_string(),
        };
        by_hand.push_str(&line);
        by_hand.push('\n');
    }
    let run = BodeScenario::from_str(&by_hand, "by hand")
        .unwrap()
        .run_one(0)
        .unwrap();
    let analytic = run.analytic.unwrap();
    assert_eq!(row[1], "0.0568");
    assert!((kept_f - analytic.frequency_hz).abs() < 1e-12);
    assert_eq!(
        row[2].parse::<f64>().unwrap().to_bits(),
        analytic.frequency_hz.to_bits()
    );
    assert_eq!(
        row[4].parse::<f64>().unwrap().to_bits(),
        analytic.peak_gain_db.to_bits()
    );
    let min_t = run
        .points
        .iter()
        .map(|p| p.min_tension_n)
        .fold(f64::INFINITY, f64::min);
    assert_eq!(row[7].parse::<f64>().unwrap().to_bits(), min_t.to_bits());
    // Doubling the inertia lowers the resonance by about sqrt(2) (eq. 13: w^2 ~ k/I).
    let row0: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    let ratio = row0[2].parse::<f64>().unwrap() / analytic.frequency_hz;
    assert!((ratio - 2f64.sqrt()).abs() < 0.05, "{ratio}");
}

#[test]
fn resume_after_interruption_gives_the_same_table_without_redoing_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let file = batch_file(tmp.path(), "study", STUDY);
    let full = tmp.path().join("full");
    assert_eq!(run_batch(&file, &full, &["-j", "2"]).status.code(), Some(0));
    let want = String::from_utf8(read(&full.join("results.csv"))).unwrap();

    // An interrupted run: the journal holds the header, 5 rows and a torn 6th line;
    // no final tables. Row 0 carries a marker value so a recomputation would show.
    let part = tmp.path().join("part");
    std::fs::create_dir(&part).unwrap();
    let journal = String::from_utf8(read(&full.join("journal.jsonl"))).unwrap();
    let lines: Vec<&str> = journal.lines().collect();
    let mut kept: Vec<String> = lines[..6].iter().map(|l| l.to_string()).collect();
    let marked = kept
        .iter()
        .position(|l| l.contains("\"index\":0,"))
        .map(|i| {
            let l = &kept[i];
            let start = l.find("[\"min_tension_n\",{\"f\":\"").unwrap() + 23;
            let end = start + l[start..].find('"').unwrap();
            let original: f64 = l[start..end].parse().unwrap();
            kept[i] = format!("{}12345.5{}", &l[..start], &l[end..]);
            original
        });
    let mut text = kept.join("\n");
    text.push('\n');
    text.push_str(&lines[6][..lines[6].len() / 2]);
    std::fs::write(part.join("journal.jsonl"), text).unwrap();

    // Without --resume the journal is protected.
    let o = run_batch(&file, &part, &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--resume"), "{}", stderr(&o));

    let o = run_batch(&file, &part, &["--resume", "-j", "2"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("5 done before, 7 to run"),
        "{}",
        stderr(&o)
    );
    let got = String::from_utf8(read(&part.join("results.csv"))).unwrap();
    let want = match &marked {
        // Row 0 was kept from the journal: its marker shows it was not run again.
        Some(original) => want.replacen(&format!(",{original:?},ok"), ",12345.5,ok", 1),
        None => want,
    };
    assert_eq!(got, want);
    // The journal now has every row exactly once (plus the header).
    let journal = String::from_utf8(read(&part.join("journal.jsonl"))).unwrap();
    let mut indices: Vec<usize> = journal
        .lines()
        .skip(1)
        .map(|l| {
            let start = l.find("\"index\":").unwrap() + 8;
            l[start..].split(',').next().unwrap().parse().unwrap()
        })
        .collect();
    indices.sort_unstable();
    assert_eq!(indices, (0..12).collect::<Vec<_>>());

    // Resuming a finished run redoes nothing and rewrites the same table.
    let o = run_batch(&file, &part, &["--resume"]);
    assert!(
        stderr(&o).contains("12 done before, 0 to run"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        String::from_utf8(read(&part.join("results.csv"))).unwrap(),
        got
    );
}

#[test]
fn killed_run_resumes_to_the_identical_table() {
    let tmp = tempfile::tempdir().unwrap();
    let body = "[[axis]]\npath = \"rig.rope\"\nvalues = [\"dyneema2\", \"vectran2\", \"zylon2\", \"kevlar2\"]\n\
                [[axis]]\npath = \"rig.output_damping_n_m_s\"\nvalues = [0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.11]\n";
    let file = batch_file(tmp.path(), "kill", body);
    let full = tmp.path().join("full");
    assert_eq!(run_batch(&file, &full, &["-j", "2"]).status.code(), Some(0));
    let part = tmp.path().join("part");
    let mut child = Command::new(env!("CARGO_BIN_EXE_longreach"))
        .args([
            "batch",
            file.to_str().unwrap(),
            "--out",
            part.to_str().unwrap(),
            "-j",
            "1",
        ])
        .stderr(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Kill it once a few rows are journaled (if it finished first, resume has nothing to do).
    for _ in 0..2000 {
        let rows = std::fs::read_to_string(part.join("journal.jsonl"))
            .map_or(0, |t| t.lines().count().saturating_sub(1));
        if rows >= 3 || child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let _ = child.kill();
    let _ = child.wait();
    let o = run_batch(&file, &part, &["--resume", "-j", "2"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_same_file(&part.join("results.csv"), &full.join("results.csv"));
    assert_same_file(&part.join("results.parquet"), &full.join("results.parquet"));
}

#[test]
fn three_shards_merge_into_the_unsharded_table() {
    let tmp = tempfile::tempdir().unwrap();
    let file = batch_file(tmp.path(), "study", STUDY);
    let whole = tmp.path().join("whole");
    assert_eq!(run_batch(&file, &whole, &[]).status.code(), Some(0));
    let shards = tmp.path().join("shards");
    let s = shards.to_str().unwrap();
    let f = file.to_str().unwrap();
    // Shard 1 by flag, shard 2 as a Slurm array task, shard 3 as a Kubernetes Indexed Job.
    let o1 = longreach(&["batch", f, "--out", s, "--shard", "1/3"], &[]);
    let o2 = longreach(
        &["batch", f, "--out", s],
        &[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ],
    );
    for o in [&o1, &o2] {
        assert_eq!(o.status.code(), Some(0), "{}", stderr(o));
    }
    // Merging before the last shard ran names the missing shard.
    let early = longreach(&["merge", s], &[]);
    assert_eq!(early.status.code(), Some(2));
    assert!(
        stderr(&early).contains("shard 3/3 is missing"),
        "{}",
        stderr(&early)
    );
    let o3 = longreach(
        &["batch", f, "--out", s],
        &[
            ("JOB_COMPLETION_INDEX", "2"),
            ("LONGREACH_SHARD_COUNT", "3"),
        ],
    );
    assert_eq!(o3.status.code(), Some(0), "{}", stderr(&o3));
    let rows = |k: usize| {
        String::from_utf8(read(&shards.join(format!("shard-{k}-of-3/results.csv"))))
            .unwrap()
            .lines()
            .count()
            - 1
    };
    assert_eq!([rows(1), rows(2), rows(3)], [4, 4, 4]);
    let o = longreach(&["merge", s], &[]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert_same_file(&shards.join("results.csv"), &whole.join("results.csv"));
    assert_same_file(
        &shards.join("results.parquet"),
        &whole.join("results.parquet"),
    );
    // The same shard twice is refused.
    let one = shards.join("shard-1-of-3");
    let out2 = tmp.path().join("m2");
    let o = longreach(
        &[
            "merge",
            out2.to_str().unwrap(),
            one.to_str().unwrap(),
            one.to_str().unwrap(),
        ],
        &[],
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("both shard 1"), "{}", stderr(&o));
}

#[test]
fn a_failing_scenario_is_one_error_row_among_49_good_rows() {
    let tmp = tempfile::tempdir().unwrap();
    let mut lengths: Vec<String> = (0..50)
        .map(|i| format!("{:?}", 10.0 + 0.2 * i as f64))
        .collect();
    lengths[17] = "-1.0".into();
    let body = format!(
        "[[axis]]\npath = \"rig.rope_length_m\"\nvalues = [{}]\n",
        lengths.join(", ")
    );
    let file = batch_file(tmp.path(), "fifty", &body);
    let out = tmp.path().join("out");
    let o = run_batch(&file, &out, &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let text = String::from_utf8(read(&out.join("results.csv"))).unwrap();
    let rows: Vec<&str> = text.lines().skip(1).collect();
    assert_eq!(rows.len(), 50);
    let ok = rows.iter().filter(|r| r.ends_with(",ok,")).count();
    assert_eq!(ok, 49);
    let bad = rows[17];
    assert!(bad.starts_with("17,-1.0,,,,,,,invalid,"), "{bad}");
    assert!(bad.contains("rope_length_m"), "{bad}");
    // Longer ropes are softer: the analytic resonance falls along the axis.
    let f = |r: &str| r.split(',').nth(2).unwrap().parse::<f64>().unwrap();
    assert!(f(rows[0]) > f(rows[16]) && f(rows[18]) > f(rows[49]));
}

fn assert_rejected(body: &str, line: usize, needles: &[&str]) {
    let tmp = tempfile::tempdir().unwrap();
    let file = batch_file(tmp.path(), "bad", body);
    let out = tmp.path().join("out");
    let o = run_batch(&file, &out, &[]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains(&format!("bad.toml:{line}:")),
        "line {line}: {err}"
    );
    assert!(err.contains("fix:"), "{err}");
    for n in needles {
        assert!(err.contains(n), "{n}: {err}");
    }
    assert!(!out.exists(), "nothing may run: {err}");
}

#[test]
fn malformed_batch_files_fail_before_anything_runs() {
    // Line 1 is `base = ...`; the body starts on line 2.
    assert_rejected(
        "[[axis]]\npath = \"rig.rope_lenght_m\"\nvalues = [1.0]\n",
        3,
        &["`rig.rope_lenght_m` is not a field", "rope_length_m"],
    );
    assert_rejected(
        "[[axis]]\npath = \"rig.rope\"\nvalues = [\"dyneema2\",\n  3.5]\n",
        5,
        &["type mismatch", "expected string", "found float"],
    );
    assert_rejected(
        "[[axis]]\npath = \"rig.rope\"\nvalues = []\n",
        4,
        &["no values"],
    );
    assert_rejected(
        "[[axis]]\npath = \"rig.rope\"\nvalues = [\"dyneema2\", \"zylon2\"]\nzip = \"p\"\n\
         [[axis]]\npath = \"rig.output_inertia_kg_m2\"\nvalues = [0.1]\nzip = \"p\"\n",
        8,
        &["differ in length"],
    );
    assert_rejected(
        "[[axis]]\npath = \"rig.rope\"\nvalues = [\"dyneema2\"]\n[[axis]]\npath = \"rig\"\nvalues = [1]\n",
        6,
        &["overlaps"],
    );
    assert_rejected(
        "[[random]]\npath = \"rig.prestretch_n\"\nuniform = [1.0, 2.0]\n",
        2,
        &["seed"],
    );
    assert_rejected("axes = 3\n", 2, &["unknown field"]);
}

#[test]
fn dry_run_lists_cases_and_zips_in_order_without_running() {
    let tmp = tempfile::tempdir().unwrap();
    let body = "[[axis]]\npath = \"rig.output_inertia_kg_m2\"\nvalues = [1, 2]\nzip = \"payload\"\n\
                [[axis]]\npath = \"rig.output_damping_n_m_s\"\nvalues = [0.5, 0.7]\nzip = \"payload\"\n\
                [[case]]\n\"rig.rope\" = \"zylon2\"\n\
                [[case]]\n\"rig.rope\" = \"kevlar2\"\n\"rig.prestretch_n\" = 300.0\n";
    let file = batch_file(tmp.path(), "dry", body);
    let out = tmp.path().join("out");
    let o = run_batch(&file, &out, &["--dry-run"]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!out.exists());
    assert_eq!(
        String::from_utf8(o.stdout).unwrap(),
        "index,rig.output_inertia_kg_m2,rig.output_damping_n_m_s,rig.rope,rig.prestretch_n\n\
         0,1.0,0.5,zylon2,490.0\n\
         1,1.0,0.5,kevlar2,300.0\n\
         2,2.0,0.7,zylon2,490.0\n\
         3,2.0,0.7,kevlar2,300.0\n"
    );
}

#[test]
fn shipped_batch_files_expand_and_run() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, rows, header) in [
        (
            "batch_quick.toml",
            6,
            "index,rig.rope,sweep.mean_tensions_n.0",
        ),
        (
            "batch_ropes_preloads_payloads.toml",
            40,
            "index,rig.rope,sweep.mean_tensions_n.0,rig.output_inertia_kg_m2",
        ),
        (
            "batch_arm_ropes.toml",
            10,
            "index,transmission_defaults.rope,transmission_defaults.law,transmission.0.preload_n",
        ),
    ] {
        let file = root().join("scenarios").join(name);
        let listed = longreach(&["batch", file.to_str().unwrap(), "--dry-run"], &[]);
        assert_eq!(listed.status.code(), Some(0), "{name}: {}", stderr(&listed));
        let listed = String::from_utf8(listed.stdout).unwrap();
        assert_eq!(listed.lines().count(), rows + 1, "{name}");
        assert!(listed.starts_with(header), "{name}: {listed}");
        let out = tmp.path().join(name);
        let o = run_batch(&file, &out, &[]);
        assert_eq!(o.status.code(), Some(0), "{name}: {}", stderr(&o));
        let table = String::from_utf8(read(&out.join("results.csv"))).unwrap();
        let ok = table
            .lines()
            .skip(1)
            .filter(|l| l.ends_with(",ok,"))
            .count();
        assert_eq!(ok, rows, "{name}");
    }
}
