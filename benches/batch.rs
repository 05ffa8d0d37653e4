//! Batch runner benchmarks: throughput on 1 and 2 rayon threads (target: >= 1.9x on 2
//! cores), and the per-scenario overhead beyond the simulation (target: < 1 ms).
//!
//! Run: `cargo bench --bench batch`.

use std::hint::black_box;
use std::path::{Path, PathBuf};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use longreach_scenario::batch::{
    builtin_kinds, run_one, run_scenarios, Batch, Header, Journal, Row, RunOptions,
};
use longreach_scenario::BodeScenario;

fn scenarios_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios")
}

/// 24 rig scenarios of ~10 ms each (5 frequencies x 6 s at dt = 1 ms): 4 ropes x 6
/// damping values.
const THROUGHPUT: &str = r#"
base = "bode_dyneema2.toml"
[set]
"sweep.mean_tensions_n" = [98.0]
"sweep.frequencies_hz" = [1.0, 1.5, 2.0, 2.5, 3.5]
"sweep.settle_s" = 4.0
"sweep.min_cycles" = 1
"sweep.min_hold_s" = 2.0
"simulation.dt_s" = 0.001
[[axis]]
path = "rig.rope"
values = ["dyneema2", "vectran2", "zylon2", "kevlar2"]
[[axis]]
path = "rig.output_damping_n_m_s"
values = [0.02, 0.04, 0.06, 0.08, 0.1, 0.12]
"#;

/// A trivially short run (one 5 Hz cycle at dt = 10 ms, no settling): the time per
/// scenario is almost all batch overhead (expand, TOML text, parse, validate, row).
const TRIVIAL: &str = r#"
base = "bode_dyneema2.toml"
[set]
"sweep.mean_tensions_n" = [98.0]
"sweep.frequencies_hz" = [5.0]
"sweep.settle_s" = 0.0
"sweep.min_cycles" = 1
"sweep.min_hold_s" = 0.0
"simulation.dt_s" = 0.01
[[axis]]
path = "rig.output_damping_n_m_s"
values = [0.02, 0.04, 0.06, 0.08, 0.1, 0.12, 0.14, 0.16, 0.18, 0.2]
[[axis]]
path = "rig.rope"
values = ["dyneema2", "vectran2", "zylon2", "kevlar2", "stainless1"]
"#;

fn batch(text: &str) -> Batch {
    Batch::from_str(
        text,
        "bench.toml",
        "bench",
        &scenarios_dir(),
        &builtin_kinds(),
    )
    .expect("bench batch")
}

fn run_all(b: &Batch, threads: usize) -> usize {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("pool");
    let todo: Vec<usize> = (0..b.len()).collect();
    let mut n = 0;
    pool.install(|| {
        run_scenarios(b, &todo, &RunOptions::default(), |row: Row| {
            n += usize::from(black_box(row).index < usize::MAX);
            Ok::<(), ()>(())
        })
    })
    .expect("run");
    n
}

fn bench_throughput(c: &mut Criterion) {
    let b = batch(THROUGHPUT);
    let mut group = c.benchmark_group("batch_throughput");
    group.sample_size(10);
    group.throughput(Throughput::Elements(b.len() as u64));
    for threads in [1, 2] {
        group.bench_function(format!("{threads}_threads"), |bench| {
            bench.iter(|| run_all(&b, threads));
        });
    }
    group.finish();
}

fn bench_overhead(c: &mut Criterion) {
    let b = batch(TRIVIAL);
    let mut group = c.benchmark_group("batch_overhead");
    // The simulation alone: every scenario parsed beforehand, run directly.
    let parsed: Vec<BodeScenario> = (0..b.len())
        .map(|i| BodeScenario::from_str(&b.scenario(i).text, "bench").expect("scenario"))
        .collect();
    group.throughput(Throughput::Elements(b.len() as u64));
    group.bench_function("simulation_only", |bench| {
        bench.iter(|| {
            for s in &parsed {
                black_box(s.run_all().expect("run"));
            }
        });
    });
    // The batch pipeline (expand, TOML text, parse, validate, run, metrics, channel) on
    // one thread: minus simulation_only, the overhead per scenario.
    group.bench_function("pipeline_1_thread", |bench| {
        bench.iter(|| run_all(&b, 1));
    });
    group.throughput(Throughput::Elements(1));
    group.bench_function("expand_one", |bench| {
        bench.iter(|| black_box(b.scenario(black_box(17))));
    });
    group.bench_function("run_one", |bench| {
        bench.iter(|| black_box(run_one(&b, black_box(17), &RunOptions::default())));
    });
    group.throughput(Throughput::Elements(b.len() as u64));
    // The whole pipeline on one thread, with the journal, per scenario.
    let dir = tempfile::tempdir().expect("tempdir");
    group.bench_function("pipeline_with_journal_1_thread", |bench| {
        bench.iter(|| {
            let out = dir.path().join("run");
            let _ = std::fs::remove_dir_all(&out);
            let header = Header {
                longreach_batch_journal: 1,
                batch: b.name.clone(),
                fingerprint: b.fingerprint.clone(),
                total: b.len(),
                shard: None,
                axes: b.axis_names(),
            };
            let (mut journal, _) = Journal::open(&out, &header, false).expect("journal");
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .expect("pool");
            let todo: Vec<usize> = (0..b.len()).collect();
            pool.install(|| {
                run_scenarios(&b, &todo, &RunOptions::default(), |row: Row| {
                    journal.append(&row)
                })
            })
            .expect("run");
            journal.sync().expect("sync");
        });
    });
    group.finish();
}

criterion_group!(benches, bench_throughput, bench_overhead);
criterion_main!(benches);
