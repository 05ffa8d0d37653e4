//! Joint friction on the arm: the URDF's `<dynamics friction>` is modelled as the
//! registered `joint_friction` effect at its joint (present whenever the URDF says so),
//! and its work equals the energy the arm loses, to round-off.

use crate::common;

use common::{rig_pair, robot_path};
use longreach_arm::transmission::{PairSpec, Tensioner};
use longreach_arm::{parse_urdf, Command, DrivenArm, DrivenState};
use longreach_drive::effects::{self, Applied, BearingFriction, JointFriction};
use longreach_rope::{Catalog, LawKind, RopeLaw};

/// The paper's rig as a one-joint arm (robots/rig/rig.urdf) with `dynamics` in place of
/// its own `<dynamics>` element.
fn rig_urdf(dynamics: &str) -> longreach_arm::ArmSpec {
    let text = std::fs::read_to_string(robot_path("rig/rig.urdf")).unwrap();
    let text = text.replace(r#"<dynamics damping="0.05"/>"#, dynamics);
    parse_urdf(&text, "rig.urdf (edited)").unwrap()
}

fn pair() -> PairSpec {
    let params = Catalog::builtin().get("stainless1").unwrap().clone();
    let law = RopeLaw::from_params(&params, LawKind::Elastic).unwrap();
    rig_pair("stainless1", law, 300.0, 0.0, Tensioner::Fixed)
}

/// The motor steps by 0.1 rad at t = 0.5 ms and holds: the pulley oscillates and the
/// bearing's dry friction stops it.
fn stepped(arm_joint_effects: Vec<(usize, Applied)>, dynamics: &str) -> DrivenArm {
    DrivenArm::with_joint_effects(
        rig_urdf(dynamics),
        vec![pair()],
        arm_joint_effects,
        vec![Command::Step {
            to_rad: 0.1,
            at_s: 5e-4,
        }],
        vec![0.0],
        1e-3,
    )
    .unwrap()
}

/// Runs 6 s; returns the energy lost after the first step, the friction's discrete work
/// over the same steps and the largest per-step mismatch, J, and the joint angles.
fn swing(arm: &DrivenArm, law: &BearingFriction) -> (f64, f64, f64, Vec<f64>) {
    let mut st: DrivenState = arm.initial_state();
    arm.step(&mut st).unwrap();
    let e_start = arm.energy(&st).total_j();
    let (mut work, mut gap) = (0.0, 0.0f64);
    let mut q = Vec::new();
    for _ in 0..6000 {
        let (q0, w0, e0) = (st.q_rad[0], st.qd_rad_s[0], arm.energy(&st).total_j());
        arm.step(&mut st).unwrap();
        let w = law.step_work_j(w0, st.qd_rad_s[0], st.q_rad[0] - q0);
        work += w;
        gap = gap.max((arm.energy(&st).total_j() - e0 - w).abs());
        q.push(st.q_rad[0]);
    }
    (e_start - arm.energy(&st).total_j(), -work, gap, q)
}

#[test]
fn urdf_friction_is_the_joint_friction_effect_and_its_work_is_the_energy_lost() {
    let coulomb = 0.05;
    // From the URDF: `friction` is the bearing's dry torque, `damping` stays the joint's
    // own viscous damping (here none).
    let from_urdf = stepped(
        vec![],
        &format!(r#"<dynamics damping="0" friction="{coulomb}"/>"#),
    );
    assert_eq!(from_urdf.loads().len(), 1);
    assert_eq!(from_urdf.loads()[0].effect, "joint_friction");
    let law = BearingFriction {
        coulomb_n_m: coulomb,
        viscous_n_m_s: 0.0,
        slip_rate_rad_s: BearingFriction::DEFAULT_SLIP_RATE_RAD_S,
        coulomb_table: None,
    };
    let (lost, work, gap, q) = swing(&from_urdf, &law);
    eprintln!("energy lost {lost:.6e} J, friction work {work:.6e} J, worst step {gap:.2e} J");
    // One joint, its inertia constant, no gravity torque, elastic ropes and a held
    // motor: the trapezoidal rule conserves everything but the friction.
    assert!(lost > 0.03, "{lost}");
    assert!((lost - work).abs() <= 1e-9 * lost, "{lost} vs {work}");
    assert!(gap <= 1e-12, "{gap}");
    // Coulomb's decrement 4 F / k, k = 2 r^2 k1 / L (fixed tensioner: both ropes).
    let k1 = pair().law.k1_n;
    let expected = 4.0 * coulomb / (2.0 * 0.025f64.powi(2) * k1 / 15.2);
    let peaks: Vec<f64> = q
        .windows(3)
        .filter(|w| w[1] > w[0] && w[1] >= w[2] && w[1] > 0.115)
        .map(|w| w[1])
        .collect();
    let dec: Vec<f64> = peaks.windows(2).map(|w| w[0] - w[1]).collect();
    eprintln!("decrements {dec:?}, Coulomb {expected}");
    assert!(dec.len() >= 4, "{peaks:?}");
    for d in &dec {
        assert!(
            (d / expected - 1.0).abs() < 0.02,
            "decrement {d} vs {expected}"
        );
    }
    // The same effect given explicitly replaces the URDF's: bitwise the same run.
    let explicit = stepped(
        vec![(0, JointFriction::dry(coulomb).unwrap())],
        r#"<dynamics damping="0" friction="0.2"/>"#,
    );
    assert_eq!(explicit.loads().len(), 1);
    let (lost2, ..) = swing(&explicit, &law);
    assert_eq!(lost.to_bits(), lost2.to_bits());
    // Without friction nothing is lost.
    let none = stepped(vec![], r#"<dynamics damping="0"/>"#);
    assert!(none.loads().is_empty());
    let (lost0, ..) = swing(&none, &law);
    assert!(lost0.abs() < 1e-10 * lost, "{lost0}");
}

/// An effect that does not act at a joint is refused there, naming the joint and site.
#[test]
fn an_effect_of_another_site_is_refused_at_a_joint() {
    let relay = effects::find("relay_friction").unwrap();
    let err = DrivenArm::with_joint_effects(
        rig_urdf(r#"<dynamics damping="0"/>"#),
        vec![pair()],
        vec![(0, Applied::default_of(relay))],
        vec![Command::Hold],
        vec![0.0],
        1e-3,
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("phi") && err.contains("relay pulley"), "{err}");
    // The compiled torque of the default effect opposes motion.
    let f = Applied::default_of(&JointFriction)
        .joint_force()
        .unwrap()
        .unwrap();
    assert!(f.torque(0.0, 1.0, &[]).torque_n_m < 0.0);
}
