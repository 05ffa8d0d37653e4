//! Static design numbers of a scenario's transmission at its initial pose: pair force,
//! rope tensions and safety factors (tensile strength / largest static tension):
//! `cargo run --release -p longreach-arm --example transmission_design -- FILE`.

fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: transmission_design SCENARIO.toml");
        std::process::exit(2);
    };
    let sc = match longreach_arm::scenario::load(std::path::Path::new(&path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    let arm = &sc.arm;
    let g = longreach_arm::gravity_torques(arm.spec(), arm.initial_q_rad()).unwrap_or_default();
    println!("| joint | gravity torque (N*m) | r_joint (m) | ropes | L (m) | preload (N) | pair force (N) | f+ (N) | f- (N) | rope | static SF |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for (p, s) in arm
        .pairs()
        .iter()
        .zip(arm.static_pairs(arm.initial_q_rad()))
    {
        let j = p.spec.joint;
        println!(
            "| {} | {:.2} | {} | {} | {:.2} | {} | {:.1} | {:.1} | {:.1} | {} | {:.2} |",
            arm.spec().joints[j].name,
            g[j],
            p.spec.joint_radius_m,
            p.spec.ropes_in_parallel,
            p.spec.length_m,
            p.spec.preload_n,
            s.phi_n,
            s.f_pos_n,
            s.f_neg_n,
            p.spec.rope_name,
            p.spec.rope.tensile_strength_n / s.f_pos_n.max(s.f_neg_n)
        );
    }
}
