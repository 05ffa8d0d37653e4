//! Behaviour of the rapier model: damping, torque reset, limits, input errors, blow-up.

use crate::common;

use longreach_arm::{load_urdf, parse_urdf, step, ArmError, ArmModel, ArmSpec, ModelOptions};

fn rig() -> ArmSpec {
    load_urdf(common::robot_path("rig/rig.urdf")).expect("rig.urdf loads")
}

/// The rig's free decay follows I phi'' + C phi' = 0: qd(t) = qd0 exp(-C t / I). With
/// rapier's default DoF damping (0.1 instead of C = 0.05) the rate would double.
#[test]
fn rig_velocity_decays_with_the_urdf_damping() {
    let spec = rig();
    let (c, i): (f64, f64) = (0.05, 0.0284);
    let model = ArmModel::new(spec).unwrap();
    let mut data = model.make_data();
    data.set_state(&model, &[0.0], &[2.0]).unwrap();
    let dt = 1e-3;
    for _ in 0..1000 {
        step(&model, &mut data, &[0.0], dt).unwrap();
    }
    let expected = 2.0 * (-c * 1.0 / i).exp();
    let got = data.qd_rad_s()[0];
    let rel = (got - expected) / expected;
    println!("rig decay after 1 s: qd = {got:.6} rad/s, closed form {expected:.6}, rel {rel:.2e}");
    // Implicit Euler damping: (1 + dt C / I)^-n vs exp(-n dt C / I): 0.15% here.
    assert!(rel.abs() < 5e-3, "{rel}");
}

/// Torques act for the step they are given in, not after (rapier keeps user torques
/// unless reset).
#[test]
fn torques_do_not_persist_between_steps() {
    let mut spec = rig();
    spec.joints[0].damping_n_m_s_per_rad = 0.0;
    let model = ArmModel::new(spec).unwrap();
    let mut data = model.make_data();
    let dt = 1e-3;
    step(&model, &mut data, &[1.0], dt).unwrap();
    let qd1 = data.qd_rad_s()[0];
    assert!((qd1 - dt * 1.0 / 0.0284).abs() < 1e-12, "{qd1}");
    for _ in 0..100 {
        step(&model, &mut data, &[0.0], dt).unwrap();
    }
    assert!((data.qd_rad_s()[0] - qd1).abs() < 1e-12);
    assert!((data.q_rad()[0] - qd1 * dt * 101.0).abs() < 1e-12);
    assert!((data.time_s() - 0.101).abs() < 1e-12);
}

/// A pendulum released towards a +-0.3 rad limit stops near it.
#[test]
fn revolute_limits_are_enforced() {
    let text = r#"<robot name="lim">
      <link name="base"/>
      <link name="bar"><inertial><origin xyz="0.5 0 0"/><mass value="1"/>
        <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.08" iyz="0" izz="0.08"/></inertial></link>
      <joint name="hinge" type="revolute"><parent link="base"/><child link="bar"/>
        <axis xyz="0 1 0"/><limit lower="-0.3" upper="0.3" effort="10" velocity="1"/></joint>
    </robot>"#;
    let spec = parse_urdf(text, "lim").unwrap();
    for enforce in [true, false] {
        let model = ArmModel::with_options(
            spec.clone(),
            ModelOptions {
                enforce_limits: enforce,
                ..ModelOptions::default()
            },
        )
        .unwrap();
        let mut data = model.make_data();
        let mut max_q = 0.0_f64;
        for _ in 0..1000 {
            step(&model, &mut data, &[0.0], 1e-3).unwrap();
            max_q = max_q.max(data.q_rad()[0]);
        }
        println!("limits enforced: {enforce}: max q = {max_q:.4} rad");
        if enforce {
            assert!(max_q < 0.3 + 0.02, "{max_q}");
        } else {
            assert!(max_q > 1.0, "{max_q}");
        }
    }
}

#[test]
fn step_rejects_bad_input_and_reports_blow_up() {
    let spec = rig();
    let model = ArmModel::new(spec.clone()).unwrap();
    let mut data = model.make_data();
    let e = step(&model, &mut data, &[1.0, 2.0], 1e-3).unwrap_err();
    assert!(
        matches!(
            e,
            ArmError::WrongLength {
                expected: 1,
                got: 2,
                ..
            }
        ),
        "{e}"
    );
    let e = step(&model, &mut data, &[f64::NAN], 1e-3).unwrap_err();
    assert!(matches!(e, ArmError::NonFinite { .. }), "{e}");
    for dt in [0.0, -1e-3, f64::INFINITY] {
        let e = step(&model, &mut data, &[0.0], dt).unwrap_err();
        assert!(matches!(e, ArmError::BadTimeStep { .. }), "{e}");
    }
    let other = ArmModel::new(spec).unwrap();
    let e = step(&other, &mut data, &[0.0], 1e-3).unwrap_err();
    assert!(matches!(e, ArmError::ModelMismatch { .. }), "{e}");
    assert!(
        data.time_s().abs() < 1e-300,
        "rejected steps must not advance time"
    );
    // A torque whose acceleration overflows f64.
    let e = step(&model, &mut data, &[1e308], 1e-3).unwrap_err();
    assert!(matches!(e, ArmError::BlowUp { .. }), "{e}");
    println!("{e}");
}

#[test]
fn zero_substeps_is_rejected() {
    let e = ArmModel::with_options(
        rig(),
        ModelOptions {
            substeps: 0,
            ..ModelOptions::default()
        },
    )
    .unwrap_err();
    assert!(e.to_string().contains("substeps"), "{e}");
}
