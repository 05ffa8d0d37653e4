//! Wall time per step of the driven arm (no criterion; the criterion version is
//! `benches/arm.rs` of the root package):
//! `cargo run --release -p longreach-arm --example driven_step_cost`.

use std::path::Path;
use std::time::Instant;

use longreach_arm::transmission::{uniform_pairs, MotorMode, MotorSpec, TensionerKind};
use longreach_arm::{chain_urdf, parse_urdf, Command, DrivenArm};
use longreach_rope::{Catalog, LawKind, RopeLaw};

fn chain(n: usize) -> DrivenArm {
    let spec = parse_urdf(&chain_urdf(n, 10.0 / n as f64, 50.0 / n as f64), "chain").unwrap();
    let params = Catalog::builtin().get("stainless1").unwrap().clone();
    let law = RopeLaw::from_params(&params, LawKind::Elastic).unwrap();
    let motor = MotorSpec {
        inertia_kg_m2: 0.0,
        damping_n_m_s: 0.0,
        mode: MotorMode::Kinematic,
    };
    let pairs = uniform_pairs(
        &spec,
        "stainless1",
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

/// CPU time of this thread, ns (first field of /proc/thread-self/schedstat; 0 when
/// unavailable).
fn cpu_ns() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
        .unwrap_or(0.0)
}

fn time(label: &str, arm: &DrivenArm) {
    let steps = 20_000;
    for rep in 0..3 {
        let mut st = arm.initial_state();
        let t0 = Instant::now();
        let c0 = cpu_ns();
        let mut iters = 0u64;
        for _ in 0..steps {
            arm.step(&mut st).unwrap();
            iters += u64::from(st.iterations);
        }
        let ns = t0.elapsed().as_secs_f64() * 1e9 / steps as f64;
        let cpu = (cpu_ns() - c0) / steps as f64;
        println!(
            "{label} rep {rep}: {ns:.0} ns/step wall, {cpu:.0} ns/step cpu ({:.0}x real time), {:.2} Newton iterations/step",
            1e6 / cpu,
            iters as f64 / steps as f64
        );
    }
}

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios");
    let load = |n: &str| longreach_arm::scenario::load(&dir.join(n)).unwrap().arm;
    time(
        "longreach5 dyneema2 four-element servo",
        &load("arm_dyneema2_base_step.toml"),
    );
    time(
        "arm5 elastic stainless1 (MuJoCo anchor)",
        &load("arm5_elastic_stainless1.toml"),
    );
    for n in [3, 6, 12] {
        time(&format!("chain{n} elastic"), &chain(n));
    }
}
