//! Wall time per step of the driven arm (no criterion; the criterion version is
//! `benches/arm.rs` of the root package):
//! `cargo run --release -p longreach-arm --example driven_step_cost [FILTER] [STEPS]`
//! (only the models whose label contains FILTER, e.g. `relay`, or is FILTER after an
//! `=`; STEPS per repetition, default 20000: a short run suits callgrind).

use std::path::Path;
use std::time::Instant;

use longreach_arm::{anchor_chain, DrivenArm};
use longreach_rope::LawKind;

/// CPU time of this thread, ns (first field of /proc/thread-self/schedstat; 0 when
/// unavailable).
fn cpu_ns() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok()))
        .unwrap_or(0.0)
}

fn time(label: &str, arm: &DrivenArm) {
    let mut args = std::env::args().skip(1);
    let filter = args.next().unwrap_or_default();
    let wanted = match filter.strip_prefix('=') {
        Some(exact) => label == exact,
        None => label.contains(&filter),
    };
    if !wanted {
        return;
    }
    let steps: usize = args
        .next()
        .map_or(20_000, |s| s.parse().expect("STEPS: a count"));
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
    time(
        "longreach5 dyneema2 four-element servo, relay friction on",
        &load("arm_dyneema2_base_step_relay_friction.toml"),
    );
    time(
        "longreach5 dyneema2 four-element servo, flexible links (2 modes per direction)",
        &load("flex_dyneema2_base_step.toml"),
    );
    for n in [3, 6, 12] {
        let arm = anchor_chain(n, LawKind::Elastic, 1e-3).unwrap_or_else(|e| panic!("{e}"));
        time(&format!("chain{n} elastic"), &arm);
    }
}
