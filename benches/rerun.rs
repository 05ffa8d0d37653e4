//! Cost of `--rerun` (target: a run < 20% slower with an `.rrd` at the default 60
//! frames per simulated second):
//!
//! - `rerun_cli_*`: the whole command as a user runs it, `longreach run SCENARIO --out
//!   DIR` with and without `--rerun save:FILE` (process start, scenario, run, tables,
//!   CSV and JSON; the recording closes while the outputs are written), for the fast
//!   arm and the realistic arm with relay friction;
//! - `rerun_arm_*`: the same arm run in process (the scenario's 10 s, and 2 s), whole
//!   recording from start to closed file;
//! - `rerun_arm_parts`: the fixed part of a recording (open + close, static scene +
//!   blueprint);
//! - `rerun_bode_147n`: the rig's stepped sine with and without recording.
//!
//! Run: `cargo bench --bench rerun` (`-- rerun_cli` for the whole command only).

use std::hint::black_box;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use longreach_arm::scenario::ArmScenario;
use longreach_viz::{arm::ArmLogger, Recorder, Target, DEFAULT_HZ};

fn scenario(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios")
        .join(name)
}

/// One arm run of `duration_s`, logged to `rec`.
fn arm_run(sc: &ArmScenario, duration_s: f64, rec: &Recorder) -> usize {
    let mut viewer = ArmLogger::new(rec, &sc.arm);
    let (_, m) = longreach_arm::run::run_observed(
        &sc.arm,
        duration_s,
        sc.sim.output_every,
        sc.sim.residual_window_s,
        &mut |_, _| {},
        &mut |st| viewer.observe(st),
    )
    .expect("run");
    viewer.finish();
    m.steps
}

/// A recording into `dir/file` at the default rate.
fn open(dir: &Path, file: &str) -> Recorder {
    let target = Target::Save(Some(dir.join(file)));
    Recorder::start("bench", &target, dir, DEFAULT_HZ).expect("rec")
}

/// The arm run of `duration_s` without logging and with an `.rrd` at 60 Hz, whole
/// recording from start to closed file.
fn bench_arm_run(c: &mut Criterion, sc: &ArmScenario, dir: &Path, duration_s: f64, samples: usize) {
    let mut g = c.benchmark_group(format!("rerun_arm_{duration_s}s"));
    g.sample_size(samples);
    g.bench_function("off", |b| {
        b.iter(|| black_box(arm_run(sc, duration_s, &Recorder::off())))
    });
    g.bench_function("save_60hz", |b| {
        b.iter(|| {
            let rec = open(dir, "arm.rrd");
            let n = arm_run(sc, duration_s, &rec);
            rec.finish();
            black_box(n)
        })
    });
    g.finish();
}

fn bench_arm(c: &mut Criterion) {
    let sc = longreach_arm::scenario::load(&scenario("arm_dyneema2_distal_step.toml"))
        .expect("scenario");
    let dir = tempfile::tempdir().expect("tempdir");
    bench_arm_run(c, &sc, dir.path(), 2.0, 20);

    // Where the cost of a recording goes: an empty recording (open + close) and the
    // static scene with the blueprint alone.
    let mut g = c.benchmark_group("rerun_arm_parts");
    g.sample_size(20);
    g.bench_function("open_close", |b| {
        b.iter(|| black_box(open(dir.path(), "empty.rrd").finish()))
    });
    g.bench_function("static_scene", |b| {
        b.iter(|| {
            let rec = open(dir.path(), "static.rrd");
            let viewer = ArmLogger::new(&rec, &sc.arm);
            let n = viewer.finish();
            black_box((n, rec.finish()))
        })
    });
    g.finish();

    // The scenario as shipped (10 s).
    bench_arm_run(c, &sc, dir.path(), 10.0, 10);
}

fn bench_bode(c: &mut Criterion) {
    let text = std::fs::read_to_string(scenario("bode_stainless1.toml"))
        .expect("scenario")
        .replace(
            "mean_tensions_n = [49.0, 98.0, 147.0, 196.0, 245.0, 294.0, 343.0, 392.0]",
            "mean_tensions_n = [147.0]",
        );
    let sc = longreach_scenario::BodeScenario::from_str(&text, "bode_stainless1.toml")
        .expect("scenario");
    let dir = tempfile::tempdir().expect("tempdir");
    let mut g = c.benchmark_group("rerun_bode_147n");
    g.sample_size(10);
    g.bench_function("off", |b| b.iter(|| black_box(sc.run_one(0).expect("run"))));
    g.bench_function("save_60hz", |b| {
        b.iter(|| {
            let rec = open(dir.path(), "bode.rrd");
            let (run, trace) = sc.run_one_traced(0).expect("run");
            let t = longreach_viz::rig::decimate(&trace, DEFAULT_HZ);
            longreach_viz::rig::log_bode(
                &rec,
                &sc.rigs[0],
                &[(run.mean_tension_n, &t, &run.points)],
            );
            rec.finish();
            black_box(run)
        })
    });
    g.finish();
}

/// `longreach run SCENARIO --out DIR [--rerun save:FILE]`, the binary built with this
/// bench; panics when the command fails.
fn cli_run(name: &str, dir: &Path, rerun: bool) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_longreach"));
    cmd.arg("run")
        .arg(scenario(name))
        .arg("--out")
        .arg(dir.join("out"));
    if rerun {
        cmd.arg("--rerun")
            .arg(format!("save:{}", dir.join("run.rrd").display()));
    }
    let out = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output()
        .expect("longreach");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn bench_cli(c: &mut Criterion) {
    for name in [
        "arm_dyneema2_distal_step.toml",
        "arm_dyneema2_base_step_relay_friction.toml",
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut g = c.benchmark_group(format!("rerun_cli_{}", name.trim_end_matches(".toml")));
        g.sample_size(20).measurement_time(Duration::from_secs(10));
        g.bench_function("off", |b| b.iter(|| cli_run(name, dir.path(), false)));
        g.bench_function("save_60hz", |b| b.iter(|| cli_run(name, dir.path(), true)));
        g.finish();
    }
}

criterion_group!(benches, bench_cli, bench_arm, bench_bode);
criterion_main!(benches);
