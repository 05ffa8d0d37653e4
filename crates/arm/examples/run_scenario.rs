//! Runs an arm scenario and prints its metrics as JSON (the library path of
//! `longreach run`): `cargo run --release -p longreach-arm --example run_scenario -- FILE`.

fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: run_scenario SCENARIO.toml");
        std::process::exit(2);
    };
    let sc = match longreach_arm::scenario::load(std::path::Path::new(&path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let t0 = std::time::Instant::now();
    match longreach_arm::run::run(
        &sc.arm,
        sc.sim.duration_s,
        sc.sim.output_every,
        sc.sim.residual_window_s,
        &mut |_, _| {},
    ) {
        Ok((_, m)) => {
            let wall = t0.elapsed().as_secs_f64();
            println!("{path}: {:.2} us/step", 1e6 * wall / m.steps.max(1) as f64);
            for j in &m.joints {
                println!(
                    "  {} move {:.3} settle {:?} over {:?} resid {:.3e} err {:.3e}",
                    j.joint,
                    j.move_rad,
                    j.settling_time_s,
                    j.overshoot_pct,
                    j.residual_vibration_rad,
                    j.final_error_rad
                );
            }
            for p in &m.pairs {
                println!(
                    "  pair {} peak {:.1} min {:.1} slack {} sf {:.2} static sf {:.2}",
                    p.joint,
                    p.peak_tension_n,
                    p.min_tension_n,
                    p.slack_events,
                    p.safety_factor,
                    p.static_safety_factor
                );
            }
            println!(
                "  tip error {:.3e} m, {:.2} iterations/step",
                m.tip_error_m, m.mean_iterations
            );
        }
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    }
}
