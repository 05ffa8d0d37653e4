//! Accuracy against cost of the Newton tolerance on the relay-friction scenario: the
//! joint angles of a solve at each tolerance against a 1e-13 solve over the whole 10 s
//! of `scenarios/arm_dyneema2_base_step_relay_friction.toml`, with the Newton
//! iterations per step (docs/arm.md, "Speed"):
//! `cargo run --release -p longreach-arm --example relay_tolerance [TOL ...]`.

use std::path::Path;

use longreach_arm::DrivenArm;

/// Joint angles after every step and the mean Newton iterations per step.
fn run(arm: &DrivenArm) -> (Vec<Vec<f64>>, f64) {
    let mut st = arm.initial_state();
    let steps = 10_000;
    let mut q = Vec::with_capacity(steps);
    let mut iterations = 0u64;
    for _ in 0..steps {
        arm.step(&mut st).unwrap_or_else(|e| panic!("{e}"));
        iterations += u64::from(st.iterations);
        q.push(st.q_rad.clone());
    }
    (q, iterations as f64 / steps as f64)
}

fn main() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenarios/arm_dyneema2_base_step_relay_friction.toml");
    let arm = longreach_arm::scenario::load(&path)
        .unwrap_or_else(|e| panic!("{e}"))
        .arm;
    let tolerances: Vec<f64> = std::env::args()
        .skip(1)
        .map(|a| a.parse().expect("TOL: a number"))
        .collect();
    let tolerances = if tolerances.is_empty() {
        vec![1e-8, 1e-9, 1e-10]
    } else {
        tolerances
    };
    let with = |tol: f64| {
        arm.clone()
            .with_newton_tolerance(tol)
            .expect("a tolerance > 0")
    };
    let (reference, it_ref) = run(&with(1e-13));
    println!("1e-13: {it_ref:.2} Newton iterations per step (reference)");
    for tol in tolerances {
        let (q, it) = run(&with(tol));
        let worst = q
            .iter()
            .zip(&reference)
            .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
            .fold(0.0f64, f64::max);
        println!("{tol:e}: {it:.2} Newton iterations per step, joint angles within {worst:.2e} rad of the reference over 10 s");
    }
}
