//! Driven-arm step cost (one core, dt = 1 ms): the realistic longreach5 arm with
//! four-element ropes, the MuJoCo anchor arm5 with elastic ropes (compare with
//! `../shared/anchors/mujoco/run.sh` in the same session), and the cost against the
//! number of links (3, 6, 12).
//!
//! Run: `cargo bench --bench arm` (the figures and the MuJoCo ratio are in docs/arm.md).

use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion};
use longreach_arm::transmission::{uniform_pairs, MotorMode, MotorSpec, TensionerKind};
use longreach_arm::{chain_urdf, parse_urdf, Command, DrivenArm};
use longreach_rope::{Catalog, LawKind, RopeLaw};

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
    let spec = parse_urdf(&chain_urdf(n, 10.0 / n as f64, 50.0 / n as f64), "chain").unwrap();
    let name = if kind == LawKind::Elastic {
        "stainless1"
    } else {
        "dyneema2"
    };
    let params = Catalog::builtin().get(name).unwrap().clone();
    let law = RopeLaw::from_params(&params, kind).unwrap();
    let motor = MotorSpec {
        inertia_kg_m2: 0.0,
        damping_n_m_s: 0.0,
        mode: MotorMode::Kinematic,
    };
    let pairs = uniform_pairs(
        &spec,
        name,
        &params,
        &law,
        0.025,
        20000.0,
        TensionerKind::Fixed,
        motor,
        0.5,
    );
    let mut cmds = vec![Command::Hold; n];
    cmds[n - 1] = Command::Step {
        to_rad: 0.0872664626,
        at_s: 0.0,
    };
    DrivenArm::new(spec, pairs, cmds, vec![0.0; n], 1e-3).unwrap()
}

fn arm_benches(c: &mut Criterion) {
    bench_arm(
        c,
        "longreach5_dyneema2_four_element_servo_step",
        &scenario("arm_dyneema2_base_step.toml"),
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
