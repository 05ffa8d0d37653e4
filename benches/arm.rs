//! Driven-arm step cost (one core, dt = 1 ms): the realistic longreach5 arm with
//! four-element ropes, without and with relay friction (issue 4: >= 200x real time, i.e.
//! <= 5 us/step, with relay friction on), the MuJoCo anchor arm5 with elastic ropes (compare with
//! `../shared/anchors/mujoco/run.sh` in the same session), longreach5 with flexible links
//! (two assumed modes per link and direction: issue 19 asks <= 3x the rigid step), and
//! the cost against the
//! number of links (3, 6, 12).
//!
//! Run: `cargo bench --bench arm` (the figures and the MuJoCo ratio are in docs/arm.md).

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

criterion_group!(benches, arm_benches);
criterion_main!(benches);
