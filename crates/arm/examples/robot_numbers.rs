//! Prints the design numbers of a URDF arm: bodies after fixed-joint merging (mass,
//! centre of mass, inertia about the joint axis), tip position and the static gravity
//! torques in the horizontal pose q = 0 (computed by `gravity_torques`).
//!
//! `cargo run -p longreach-arm --example robot_numbers -- robots/longreach5/longreach5.urdf`

use longreach_arm::dynamics::{mass_matrix, tip_position_m};
use longreach_arm::{gravity_torques, load_urdf};

fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: robot_numbers <file.urdf>");
        std::process::exit(2);
    };
    let spec = match load_urdf(&path) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    for w in &spec.warnings {
        println!("warning: {w}");
    }
    let n = spec.ndofs();
    let q = vec![0.0; n];
    println!("| body | merged links | mass (kg) | COM x, y, z in link frame (m) | inertia about joint axis at COM (kg*m^2) |");
    println!("|---|---|---|---|---|");
    for (i, link) in spec.links.iter().enumerate().skip(1) {
        let a = spec.joints[i - 1].axis.into_inner();
        let c = link.inertial.com_m;
        println!(
            "| {} | {} | {:.4} | {:.4}, {:.4}, {:.4} | {:.4} |",
            link.name,
            link.merged_links.join(", "),
            link.inertial.mass_kg,
            c.x,
            c.y,
            c.z,
            a.dot(&(link.inertial.inertia_kg_m2 * a))
        );
    }
    println!("moving mass {:.4} kg", spec.moving_mass_kg());
    let g = gravity_torques(&spec, &q).expect("gravity torques");
    let m = mass_matrix(&spec, &q).expect("mass matrix");
    let tip = tip_position_m(&spec, &q).expect("tip");
    println!(
        "tip frame '{}' at q = 0: ({:.4}, {:.4}, {:.4}) m",
        spec.tip.name, tip.x, tip.y, tip.z
    );
    println!("| joint | gravity torque at q = 0 (N*m) | M[j][j] at q = 0 (kg*m^2) |");
    println!("|---|---|---|");
    for (j, joint) in spec.joints.iter().enumerate() {
        println!("| {} | {:.2} | {:.3} |", joint.name, g[j], m[(j, j)]);
    }
}
