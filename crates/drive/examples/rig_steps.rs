//! Steps the paper's rig with Dyneema2 four-element ropes (for profiling):
//! `cargo run --release -p longreach-drive --example rig_steps -- 1000000`; a second
//! argument gives the relay pulleys that friction coefficient (inertia 2e-5 kg*m^2, or
//! `RIG_RELAY_INERTIA`); `RIG_DT_S` sets the step (1 ms), `RIG_STIFFENING_PER_N` a
//! stiffening head spring (`nonlinear_stiffness`'s b, 1/N; 0). Prints the time and the
//! Newton iterations per step (at 2.5 ms, a sweep dataset's step, 0.003 with 1e-7 or
//! 2e-5 kg*m^2: 2.4 iterations, 2.9 us, where the ideal rig takes 0.15-0.19 us on
//! the AMD EPYC family 23 machine).

use longreach_drive::{RelayFriction, RigModel, RigSpec};
use longreach_rope::{Catalog, LawKind, RopeLaw};

fn main() {
    let n: u64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1_000_000);
    let params = Catalog::builtin().get("dyneema2").unwrap().clone();
    let mut law = RopeLaw::from_params(&params, LawKind::FourElement).unwrap();
    law.stiffening_per_n = std::env::var("RIG_STIFFENING_PER_N")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.0);
    let mut spec = RigSpec::paper("dyneema2", law, 0.05, 147.0);
    spec.relay_friction = std::env::args()
        .nth(2)
        .and_then(|a| a.parse().ok())
        .map(|coefficient| RelayFriction {
            coefficient,
            inertia_kg_m2: std::env::var("RIG_RELAY_INERTIA")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(2e-5),
            slip_rate_rad_s: RelayFriction::DEFAULT_SLIP_RATE_RAD_S,
            coefficient_table: None,
        });
    let dt_s: f64 = std::env::var("RIG_DT_S")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1e-3);
    let model = RigModel::new(spec, dt_s).unwrap();
    let mut st = model.rest_state();
    let amp = 4.5f64.to_radians();
    let t0 = std::time::Instant::now();
    let mut iterations = 0u64;
    for i in 1..=n {
        let theta = amp * (std::f64::consts::TAU * 2.0 * i as f64 * dt_s).sin();
        model.step(&mut st, theta).unwrap();
        iterations += u64::from(st.plant().iterations);
    }
    let el = t0.elapsed();
    println!(
        "{n} steps, {:.1} ns/step, {:.2} Newton iterations/step, phi = {}",
        el.as_nanos() as f64 / n as f64,
        iterations as f64 / n as f64,
        st.output_rad()
    );
}
