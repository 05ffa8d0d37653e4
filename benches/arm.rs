//! Driven-arm step cost (one core, dt = 1 ms): the realistic longreach5 arm with
//! four-element ropes, without and with relay friction (issue 4: >= 200x real time, i.e.
//! <= 5 us/step, with relay friction on), the MuJoCo anchor arm5 with elastic ropes (compare with
//! `../shared/anchors/mujoco/run.sh` in the same session), longreach5 with flexible links
//! (two assumed modes per link and direction: issue 19 asks <= 3x the rigid step), and
//! the cost against the
//! number of links (3, 6, 12).
//!
//! Issue 18 item 6: one 10 s run of longreach5 (a trapezoidal base move, 10 000 steps,
//! target <= 30 ms), and the unit of the measurement loop's work on an arm: one
//! evaluation of a fit, the model simulated on the four 8 s runs of
//! `data/examples/example_arm_joint_friction` (every channel, in parallel over the runs)
//! and on one of them alone.
//!
//! Run: `cargo bench --bench arm` (the figures and the MuJoCo ratio are in docs/arm.md;
//! the loop's in docs/models.md and the README's Performance section).

use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use longreach_arm::DrivenArm;
use longreach_rope::LawKind;

fn scenario(name: &str) -> DrivenArm {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios")
        .join(name);
    longreach_arm::scenario::load(&path)
        .unwrap_or_else(|e| panic!("{e}"))
        .arm
}

fn bench_arm(c: &mut Criterion, label: &str, arm: &DrivenArm) {
    let mut st = arm.initial_state();
    c.bench_function(label, |b| {
        b.iter(|| {
            if st.time_s > 10.0 {
                st = arm.initial_state();
            }
            arm.step(&mut st).unwrap();
        })
    });
}

fn chain(n: usize, kind: LawKind) -> DrivenArm {
    longreach_arm::anchor_chain(n, kind, 1e-3).unwrap_or_else(|e| panic!("{e}"))
}

/// longreach5 with dyneema2 four-element ropes and relay friction on every pair
/// (`scenarios/arm_dyneema2_base_step_relay_friction.toml`).
fn longreach5_relay_friction() -> DrivenArm {
    scenario("arm_dyneema2_base_step_relay_friction.toml")
}

/// One whole 10 s run of longreach5 from its initial state (`[sim] duration_s`,
/// `dt_s = 1 ms`): the base's trapezoidal move.
fn longreach5_ten_seconds(c: &mut Criterion) {
    let sc = longreach_arm::scenario::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/arm_dyneema2_base_trapezoid.toml"),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let steps = (sc.sim.duration_s / sc.arm.dt_s()).round() as usize;
    assert_eq!(steps, 10_000);
    let mut g = c.benchmark_group("arm_run");
    g.sample_size(20);
    g.bench_function(
        "longreach5 four-element, one 10 s run (10 000 steps)",
        |b| {
            b.iter(|| {
                let mut st = sc.arm.initial_state();
                for _ in 0..steps {
                    sc.arm.step(&mut st).unwrap();
                }
                st.q_rad[0]
            })
        },
    );
    g.finish();
}

/// One evaluation of a fit on the arm example: the baseline simulated on every run.
fn arm_fit_evaluation(c: &mut Criterion) {
    use longreach_ident::analysis::Prepared;
    use longreach_ident::model::Model;
    use longreach_ident::Dataset;
    let dir =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("data/examples/example_arm_joint_friction");
    let ds = Dataset::load(&dir).unwrap_or_else(|e| panic!("{e}"));
    let model = Model::baseline(&ds).unwrap_or_else(|e| panic!("{e}"));
    let prep = Prepared::new(&ds).unwrap_or_else(|e| panic!("{e}"));
    let mut g = c.benchmark_group("arm_loop");
    g.sample_size(10);
    g.bench_function(
        "example_arm_joint_friction, one run (8 s, 8000 steps, 28 channels)",
        |b| b.iter(|| prep.simulate_channels(&model, 0).unwrap()),
    );
    g.bench_function(
        "example_arm_joint_friction, four runs in parallel (one fit evaluation)",
        |b| b.iter(|| prep.simulate(&model).unwrap()),
    );
    g.finish();
}

fn arm_benches(c: &mut Criterion) {
    bench_arm(
        c,
        "longreach5_dyneema2_four_element_servo_step",
        &scenario("arm_dyneema2_base_step.toml"),
    );
    bench_arm(
        c,
        "longreach5 four-element, flexible links (2 modes per direction)",
        &scenario("flex_dyneema2_base_step.toml"),
    );
    bench_arm(
        c,
        "longreach5 four-element, relay friction on",
        &longreach5_relay_friction(),
    );
    bench_arm(
        c,
        "arm5_elastic_stainless1_kinematic",
        &scenario("arm5_elastic_stainless1.toml"),
    );
    for n in [3, 6, 12] {
        bench_arm(c, &format!("chain{n}_elastic"), &chain(n, LawKind::Elastic));
    }
}

criterion_group!(
    benches,
    longreach5_ten_seconds,
    arm_fit_evaluation,
    arm_benches
);
criterion_main!(benches);
