//! Rough cost per `step` of the rapier multibody (no ropes), release mode:
//!
//! `cargo run -p longreach-arm --release --example step_cost [-- arm5 1]`
//!
//! Prints ns/step for arm5 (1 and 4 substeps) and for uniform chains of 3, 6, 12, 24
//! links, plus the cost of the independent RNEA gravity torques. Two clocks: wall
//! time (best of 5 runs) and on-CPU time of this thread (Linux
//! `/proc/thread-self/schedstat`, less sensitive to other load on a shared machine).

use longreach_arm::{chain_urdf, gravity_torques, load_urdf, parse_urdf, step};
use longreach_arm::{ArmModel, ArmSpec, ModelOptions};
use std::time::Instant;

/// Nanoseconds this thread has spent on a CPU (Linux), if available.
fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// (best wall ns/step, on-CPU ns/step).
fn ns_per_step(spec: &ArmSpec, substeps: usize, steps: usize) -> (f64, f64) {
    let model = ArmModel::with_options(
        spec.clone(),
        ModelOptions {
            substeps,
            ..ModelOptions::default()
        },
    )
    .expect("valid model");
    let n = model.ndofs();
    let mut data = model.make_data();
    let q0: Vec<f64> = (0..n).map(|j| 0.2 * (j as f64 + 1.0).sin()).collect();
    data.set_state(&model, &q0, &vec![0.0; n]).expect("state");
    let tau = vec![0.0; n];
    // Warm-up.
    for _ in 0..200 {
        step(&model, &mut data, &tau, 1e-3).expect("step");
    }
    let mut best = f64::INFINITY;
    let cpu0 = thread_cpu_ns();
    for _ in 0..5 {
        let t = Instant::now();
        for _ in 0..steps {
            step(&model, &mut data, &tau, 1e-3).expect("step");
        }
        best = best.min(t.elapsed().as_nanos() as f64 / steps as f64);
    }
    let cpu = match (cpu0, thread_cpu_ns()) {
        (Some(a), Some(b)) => (b - a) as f64 / (5 * steps) as f64,
        _ => f64::NAN,
    };
    (best, cpu)
}

fn ns_gravity(spec: &ArmSpec, reps: usize) -> f64 {
    let n = spec.ndofs();
    let q: Vec<f64> = (0..n).map(|j| 0.1 * j as f64).collect();
    let mut sink = 0.0;
    let t = Instant::now();
    for _ in 0..reps {
        sink += gravity_torques(spec, &q).expect("g")[0];
    }
    let ns = t.elapsed().as_nanos() as f64 / reps as f64;
    std::hint::black_box(sink);
    ns
}

fn main() {
    // Optional filters: `step_cost arm5 1` runs only arm5 with 1 substep (for perf).
    let only = std::env::args().nth(1);
    let only_substeps: Option<usize> = std::env::args().nth(2).and_then(|s| s.parse().ok());
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../robots/arm5/arm5.urdf");
    let arm5 = load_urdf(path).expect("arm5.urdf");
    let mut cases: Vec<(String, ArmSpec, usize)> =
        vec![("arm5".into(), arm5.clone(), 1), ("arm5".into(), arm5, 4)];
    for n in [3usize, 6, 12, 24] {
        let spec = parse_urdf(&chain_urdf(n, 2.0, 10.0), "chain").expect("chain");
        cases.push((format!("chain{n}"), spec, 1));
    }
    println!(
        "{:<8} {:>8} {:>14} {:>14} {:>14}",
        "arm", "substeps", "wall ns/step", "cpu ns/step", "ns/gravity_tq"
    );
    for (name, spec, substeps) in cases {
        if only.as_deref().is_some_and(|o| o != name)
            || only_substeps.is_some_and(|s| s != substeps)
        {
            continue;
        }
        let steps = 20_000;
        let (wall, cpu) = ns_per_step(&spec, substeps, steps);
        let g = ns_gravity(&spec, 100_000);
        println!("{name:<8} {substeps:>8} {wall:>14.0} {cpu:>14.0} {g:>14.0}");
    }
}
