//! Cost of `--rerun`: the same arm run (the scenario's 10 s, and 2 s) with and without
//! logging to an `.rrd` file at the default 60 frames per simulated second, whole
//! recording from start to closed file (target: < 20% slower); the fixed part of a
//! recording (open + close, static scene + blueprint); and the rig's stepped sine
//! with and without recording.
//!
//! Run: `cargo bench --bench rerun`.

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use longreach_viz::{arm::ArmLogger, Recorder, Target, DEFAULT_HZ};

fn scenario(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios")
        .join(name)
}

/// One arm run of `duration_s`, logged to `rec`.
fn arm_run(sc: &longreach_arm::scenario::ArmScenario, duration_s: f64, rec: &Recorder) -> usize {
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

fn bench_arm(c: &mut Criterion) {
    let sc = longreach_arm::scenario::load(&scenario("arm_dyneema2_distal_step.toml"))
        .expect("scenario");
    let dir = tempfile::tempdir().expect("tempdir");
    let mut g = c.benchmark_group("rerun_arm_2s");
    g.sample_size(20);
    g.bench_function("off", |b| {
        b.iter(|| black_box(arm_run(&sc, 2.0, &Recorder::off())))
    });
    g.bench_function("save_60hz", |b| {
        b.iter(|| {
            let target = Target::Save(Some(dir.path().join("arm.rrd")));
            let rec = Recorder::start("bench", &target, dir.path(), DEFAULT_HZ).expect("rec");
            let n = arm_run(&sc, 2.0, &rec);
            rec.finish();
            black_box(n)
        })
    });
    g.finish();

    // Where the cost of a recording goes: an empty recording (open + close), the
    // static scene and blueprint alone, and a 10 s run where the fixed part amortises.
    let mut g = c.benchmark_group("rerun_arm_parts");
    g.sample_size(20);
    g.bench_function("open_close", |b| {
        b.iter(|| {
            let target = Target::Save(Some(dir.path().join("empty.rrd")));
            let rec = Recorder::start("bench", &target, dir.path(), DEFAULT_HZ).expect("rec");
            black_box(rec.finish())
        })
    });
    g.bench_function("static_scene", |b| {
        b.iter(|| {
            let target = Target::Save(Some(dir.path().join("static.rrd")));
            let rec = Recorder::start("bench", &target, dir.path(), DEFAULT_HZ).expect("rec");
            let viewer = ArmLogger::new(&rec, &sc.arm);
            let n = viewer.finish();
            black_box((n, rec.finish()))
        })
    });
    g.finish();

    let mut g = c.benchmark_group("rerun_arm_10s");
    g.sample_size(10);
    g.bench_function("off", |b| {
        b.iter(|| black_box(arm_run(&sc, 10.0, &Recorder::off())))
    });
    g.bench_function("save_60hz", |b| {
        b.iter(|| {
            let target = Target::Save(Some(dir.path().join("arm10.rrd")));
            let rec = Recorder::start("bench", &target, dir.path(), DEFAULT_HZ).expect("rec");
            let n = arm_run(&sc, 10.0, &rec);
            rec.finish();
            black_box(n)
        })
    });
    g.finish();
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
            let target = Target::Save(Some(dir.path().join("bode.rrd")));
            let rec = Recorder::start("bench", &target, dir.path(), DEFAULT_HZ).expect("rec");
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

criterion_group!(benches, bench_arm, bench_bode);
criterion_main!(benches);
