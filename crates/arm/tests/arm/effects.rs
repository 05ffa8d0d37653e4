//! The arm's effect catalog, each effect against a closed form on a one-link arm, given
//! the way a user gives it: an arm-wide `[[effect]]` table of a `longreach run`
//! scenario (or a transmission's `effects`).
//!
//! One-link arms: `robots/rig/rig.urdf` (the paper's output pulley on a vertical axis:
//! no gravity torque, I = 0.0284 kg*m^2, r = 25 mm, elastic stainless1 ropes of 15.2 m,
//! so the ropes' torsional stiffness is `k_t = 2 r^2 k1 / L` = 11.27 N*m/rad) and a 1 m
//! boom on a horizontal axis (written below), which gravity loads.

use std::path::{Path, PathBuf};

use crate::common::robot_path;
use longreach_arm::scenario::parse;
use longreach_arm::spec::STANDARD_GRAVITY_M_S2;
use longreach_arm::{DrivenArm, DrivenState};

const STAINLESS_K1_N: f64 = 1.37e5;
const RIG_I_KG_M2: f64 = 0.0284;
const RIG_R_M: f64 = 0.025;
const RIG_L_M: f64 = 15.2;

fn k_t() -> f64 {
    2.0 * RIG_R_M * RIG_R_M * STAINLESS_K1_N / RIG_L_M
}

fn arm_of(text: &str) -> DrivenArm {
    parse(text, "effects test", Path::new("."))
        .unwrap_or_else(|e| panic!("{e}"))
        .arm
}

/// A one-link arm from `urdf` driven by one pair of elastic stainless1 ropes, with the
/// rest of its `[[transmission]]` table in `transmission` and `extra` appended
/// (effects, payload).
fn one_link(urdf: &Path, transmission: &str, extra: &str) -> String {
    format!(
        "[arm]\nurdf = \"{}\"\n[sim]\ndt_s = 0.001\nduration_s = 10.0\n[[transmission]]\n\
         rope = \"stainless1\"\nlaw = \"elastic\"\n{transmission}\n{extra}\n",
        urdf.display()
    )
}

/// The rig as a one-joint arm: elastic stainless1, fixed tensioner at 300 N, `motor`
/// (an inline table), `command`, and `extra` appended (effects, payload).
fn rig(motor: &str, command: &str, extra: &str) -> String {
    one_link(
        &robot_path("rig/rig.urdf"),
        &format!(
            "joint = \"phi\"\njoint_radius_m = 0.025\nlength_m = 15.2\npreload_n = 300.0\n\
             motor = {motor}\ncommand = {command}"
        ),
        extra,
    )
}

const KINEMATIC: &str = r#"{ mode = "kinematic" }"#;
const SMALL_STEP: &str = r#"{ kind = "step", to_rad = 0.1, at_s = 0.0005 }"#;

/// Steps `arm` `steps` times from rest; the joint and motor angles after each step.
fn trace(arm: &DrivenArm, steps: usize) -> (Vec<f64>, Vec<f64>) {
    let mut st: DrivenState = arm.initial_state();
    let (mut q, mut m) = (Vec::new(), Vec::new());
    for _ in 0..steps {
        arm.step(&mut st).unwrap();
        q.push(st.q_rad[0]);
        m.push(st.motor_rad[0]);
    }
    (q, m)
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Times at which `q - q_end` crosses zero upwards (linear interpolation), s.
fn upward_crossings(q: &[f64], q_end: f64, dt_s: f64) -> Vec<f64> {
    q.windows(2)
        .enumerate()
        .filter(|(_, w)| w[0] < q_end && w[1] >= q_end)
        .map(|(i, w)| dt_s * (i as f64 + 1.0 + (q_end - w[0]) / (w[1] - w[0])))
        .collect()
}

/// Peaks of `q` above `above`.
fn peaks(q: &[f64], above: f64) -> Vec<f64> {
    q.windows(3)
        .filter(|w| w[1] > w[0] && w[1] >= w[2] && w[1] > above)
        .map(|w| w[1])
        .collect()
}

#[test]
fn joint_friction_is_viscous_plus_a_tanh_dry_torque_at_every_joint() {
    // Viscous part: a free oscillation (held motor, no URDF damping) decays by the
    // logarithmic decrement 2 pi zeta / sqrt(1 - zeta^2), zeta = b / (2 sqrt(k_t I)).
    // The dry part at its lower bound (1e-6 N*m) takes 4 F / k_t = 3.5e-7 rad a cycle,
    // 3e-5 of the decrement here.
    let b = 0.02;
    let text = rig(
        KINEMATIC,
        SMALL_STEP,
        &format!("[[effect]]\nname = \"joint_friction\"\nparams = [1e-6, {b}, 0.01]\n"),
    );
    let arm = arm_of(&text).with_joint_damping(0.0);
    assert_eq!(arm.loads().len(), 1);
    let (q, _) = trace(&arm, 3000);
    let zeta = b / (2.0 * (k_t() * RIG_I_KG_M2).sqrt());
    let expected = 2.0 * std::f64::consts::PI * zeta / (1.0 - zeta * zeta).sqrt();
    // Peaks of the deviation from the held 0.1 rad.
    let dev: Vec<f64> = q.iter().map(|x| x - 0.1).collect();
    let p = peaks(&dev, 0.0);
    assert!(p.len() >= 6, "{p:?}");
    let decrements: Vec<f64> = p.windows(2).map(|w| (w[0] / w[1]).ln()).collect();
    let worst = decrements
        .iter()
        .fold(0.0f64, |a, d| a.max((d / expected - 1.0).abs()));
    println!("log decrements {decrements:?}, closed form {expected:.6}, worst {worst:.1e}");
    for d in &decrements {
        assert!((d / expected - 1.0).abs() < 1e-3, "{d} vs {expected}");
    }
    // Every joint of longreach5 gets it through one [[effect]] table, or the named ones.
    let l5 = std::fs::read_to_string(robot_path("../scenarios/arm_dyneema2_base_step.toml"))
        .unwrap()
        .replace("../robots/", &format!("{}/", robot_path("").display()));
    let every = arm_of(&format!(
        "{l5}\n[[effect]]\nname = \"joint_friction\"\nparams = [2.0, 0.5, 0.01]\n"
    ));
    let joints: Vec<usize> = every.loads().iter().map(|l| l.joint).collect();
    assert_eq!(joints, vec![0, 1, 2, 3, 4]);
    assert!(every.loads().iter().all(|l| l.effect == "joint_friction"));
    let named = arm_of(&format!(
        "{l5}\n[[effect]]\nname = \"joint_friction\"\njoints = [\"j2\", \"j5\"]\n"
    ));
    let joints: Vec<usize> = named.loads().iter().map(|l| l.joint).collect();
    assert_eq!(joints, vec![1, 4]);
    // The torque law: tanh over the slip rate, plus the viscous term.
    let f = every.loads()[0].force.torque(0.0, 0.01, &[]);
    let by_hand = -(2.0 * (1.0f64).tanh() + 0.5 * 0.01);
    assert!((f.torque_n_m - by_hand).abs() < 1e-15, "{f:?}");
}

#[test]
fn motor_friction_makes_a_servo_lag_a_ramp_by_its_torque_over_kp() {
    // Servo on the rig's motor (J = 1e-3 kg*m^2, kp = 100 N*m/rad, kd = 1 N*m*s/rad),
    // a ramp of 0.5 rad/s from 0.35 s to 6.1 s, the joint damped to zeta ~0.9 so that
    // every transient has died by 3 s. At a steady rate w the servo must give the
    // friction F_c tanh(w / w_s) + b w on top of what the ropes take: the motor lags by
    // that over kp, and the joint (r_m = r_j) by as much.
    let servo = r#"{ mode = "servo", inertia_kg_m2 = 1e-3, kp_n_m_per_rad = 100.0, kd_n_m_s_per_rad = 1.0 }"#;
    let ramp = r#"{ kind = "trapezoid", to_rad = 3.0, start_s = 0.1, max_velocity_rad_s = 0.5, max_accel_rad_s2 = 2.0 }"#;
    let (fc, b, ws) = (0.5f64, 0.2, 0.01);
    let with = arm_of(&rig(
        servo,
        ramp,
        &format!("[[effect]]\nname = \"motor_friction\"\nparams = [{fc}, {b}, {ws}]\n"),
    ))
    .with_joint_damping(1.0);
    let without = arm_of(&rig(servo, ramp, "")).with_joint_damping(1.0);
    assert!(with.pairs()[0].spec.motor.friction.is_some());
    let (q1, m1) = trace(&with, 3000);
    let (q0, m0) = trace(&without, 3000);
    let w = 0.5f64;
    let expected = (fc * (w / ws).tanh() + b * w) / 100.0;
    let (dm, dq) = (m0[2999] - m1[2999], q0[2999] - q1[2999]);
    println!(
        "motor lags {dm:.9} rad more, joint {dq:.9} rad; closed form {expected:.9} ({:.1e}, {:.1e})",
        dm / expected - 1.0,
        dq / expected - 1.0
    );
    assert!((dm / expected - 1.0).abs() < 1e-6, "{dm} vs {expected}");
    assert!((dq / expected - 1.0).abs() < 1e-6, "{dq} vs {expected}");
    // At zero friction the run is bitwise the plain arm's.
    let zero = arm_of(&rig(
        servo,
        ramp,
        "[[effect]]\nname = \"motor_friction\"\nparams = [0.0, 0.0, 0.01]\n",
    ))
    .with_joint_damping(1.0);
    let (qz, mz) = trace(&zero, 3000);
    assert_eq!(bits(&qz), bits(&q0));
    assert_eq!(bits(&mz), bits(&m0));
    // A kinematic motor follows its reference whatever the friction costs: no effect.
    let kin_with = arm_of(&rig(
        KINEMATIC,
        ramp,
        &format!("[[effect]]\nname = \"motor_friction\"\nparams = [{fc}, {b}, {ws}]\n"),
    ));
    let kin_without = arm_of(&rig(KINEMATIC, ramp, ""));
    let (a, am) = trace(&kin_with, 1000);
    let (c, cm) = trace(&kin_without, 1000);
    assert_eq!(bits(&a), bits(&c));
    assert_eq!(bits(&am), bits(&cm));
}

#[test]
fn payload_mass_lowers_the_rig_frequency_to_the_closed_form() {
    // A payload of unknown mass at a known point ([payload] mass 0, 0.3 m off the
    // vertical axis): the effect's m adds m l^2 to the pulley's inertia, and the held
    // pulley swings at w_d = sqrt(k_t / I - (c / 2I)^2) (URDF damping c = 0.05).
    let (m, l) = (0.5, 0.3);
    let place =
        format!("[payload]\nmass_kg = 0.0\nlink = \"output_pulley\"\noffset_m = [{l}, 0.0, 0.0]\n");
    let arm = arm_of(&rig(
        KINEMATIC,
        SMALL_STEP,
        &format!("{place}[[effect]]\nname = \"payload_mass\"\nparams = [{m}]\n"),
    ));
    let (q, _) = trace(&arm, 4000);
    let inertia = RIG_I_KG_M2 + m * l * l;
    let c = 0.05;
    let wd = (k_t() / inertia - (c / (2.0 * inertia)).powi(2)).sqrt();
    let t = upward_crossings(&q, 0.1, 1e-3);
    let periods: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let mean = periods.iter().sum::<f64>() / periods.len() as f64;
    let expected = 2.0 * std::f64::consts::PI / wd;
    println!(
        "period {mean:.6} s over {} cycles, closed form {expected:.6} s ({:.1e}; without the payload {:.6} s)",
        periods.len(),
        mean / expected - 1.0,
        2.0 * std::f64::consts::PI / (k_t() / RIG_I_KG_M2).sqrt()
    );
    assert!(periods.len() >= 5);
    // The trapezoidal rule's period error at 1 ms is (w h)^2 / 12 = 1.3e-5.
    assert!((mean / expected - 1.0).abs() < 2e-4, "{mean} vs {expected}");
    // At zero the run is bitwise the plain arm's, with and without a [payload].
    for payload in [
        "",
        "[payload]\nmass_kg = 0.7\nlink = \"output_pulley\"\noffset_m = [0.2, 0.0, 0.0]\n",
    ] {
        let plain = arm_of(&rig(KINEMATIC, SMALL_STEP, payload));
        let zero = arm_of(&rig(
            KINEMATIC,
            SMALL_STEP,
            &format!("{payload}[[effect]]\nname = \"payload_mass\"\nparams = [0.0]\n"),
        ));
        assert_eq!(bits(&trace(&plain, 500).0), bits(&trace(&zero, 500).0));
    }
}

/// A 1 m boom (1 kg, centre of mass at 0.5 m) on a horizontal axis, tip frame at 1 m,
/// in one file of the temporary folder shared by every run of these tests (written
/// under a name of this scenario `name` and process, then renamed over it: tests in
/// parallel never read a half-written file, and runs leave one file, not one each).
fn boom_urdf(name: &str) -> PathBuf {
    let dir = std::env::temp_dir();
    let path = dir.join("longreach_effects_boom.urdf");
    let part = dir.join(format!(
        "longreach_effects_boom.urdf.{name}.{}.part",
        std::process::id()
    ));
    std::fs::write(
        &part,
        r#"<?xml version="1.0"?>
<robot name="boom">
  <link name="base"/>
  <link name="boom">
    <inertial>
      <origin xyz="0.5 0 0"/>
      <mass value="1.0"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.084" iyz="0" izz="0.084"/>
    </inertial>
  </link>
  <link name="tip"/>
  <joint name="j1" type="continuous">
    <parent link="base"/><child link="boom"/>
    <axis xyz="0 1 0"/>
    <dynamics damping="1.0"/>
  </joint>
  <joint name="tip_fixed" type="fixed">
    <parent link="boom"/><child link="tip"/>
    <origin xyz="1.0 0 0"/>
  </joint>
</robot>
"#,
    )
    .unwrap();
    std::fs::rename(&part, &path).unwrap();
    path
}

/// The boom driven by one pair (r = 50 mm, 10 m of elastic stainless1 at 1000 N) from a
/// servo, held at q = 0; `extra` appended.
fn boom(name: &str, tensioner: &str, extra: &str) -> String {
    one_link(
        &boom_urdf(name),
        &format!(
            "joint = \"j1\"\njoint_radius_m = 0.05\nlength_m = 10.0\npreload_n = 1000.0\n\
             tensioner = \"{tensioner}\"\nmotor = {{ mode = \"servo\", inertia_kg_m2 = 0.01, \
             kp_n_m_per_rad = 500.0, kd_n_m_s_per_rad = 5.0 }}"
        ),
        extra,
    )
}

/// The boom is held still for 1 s: the largest joint angle, rad.
fn held(arm: &DrivenArm) -> f64 {
    let (q, _) = trace(arm, 1000);
    q.iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

#[test]
fn payload_mass_at_the_tip_loads_the_ropes_by_m_g_l_and_stretches_them_by_phi_over_k() {
    // No [payload]: the effect's 2 kg sit at the tip frame, 1 m from the axis. Held at
    // q = 0 the pair carries m g l / r more, and its ropes (fixed tensioner, each side
    // k1 / L) stretch by u = phi L / (2 k1): the motor's static angle moves by u / r_m.
    let m = 2.0;
    let with = arm_of(&boom(
        "payload",
        "fixed",
        &format!("[[effect]]\nname = \"payload_mass\"\nparams = [{m}]\n"),
    ));
    let without = arm_of(&boom("payload0", "fixed", ""));
    let (sw, s0) = (
        &with.static_pairs(&[0.0])[0],
        &without.static_pairs(&[0.0])[0],
    );
    let dphi = sw.phi_n - s0.phi_n;
    let expected_phi = m * STANDARD_GRAVITY_M_S2 * 1.0 / 0.05;
    let du = sw.u_m - s0.u_m;
    let expected_u = dphi * 10.0 / (2.0 * STAINLESS_K1_N);
    println!(
        "pair force {dphi:+.6} N (m g l / r = {expected_phi:.6}); stretch {du:+.9} m \
         (phi L / (2 k1) = {expected_u:+.9}; {:.1e})",
        du / expected_u - 1.0
    );
    assert!((dphi.abs() / expected_phi - 1.0).abs() < 1e-9, "{dphi}");
    assert!((du / expected_u - 1.0).abs() < 1e-9, "{du}");
    // A payload the servo is told of ([payload]): its references hold the weight too,
    // and the boom stays on its command.
    let known = arm_of(&boom(
        "payload_known",
        "fixed",
        "[payload]\nmass_kg = 2.0\nlink = \"tip\"\n",
    ));
    assert!(known.controller_spec().is_none());
    let worst = held(&known);
    assert!(worst < 1e-9, "{worst}");
}

#[test]
fn a_payload_the_servo_does_not_know_sags_the_arm_by_its_compliance() {
    // The effect's mass is unknown to the controller: the servo's references (gravity
    // feed-forward, static stretch) are the boom's without it. At rest the servo holds
    // its reference against the extra load with its stiffness kp (the motor gives way
    // by r_m dphi / kp) and the ropes stretch by dphi L / (2 k1): the boom sags by
    // dq = dtau (r_m^2 / kp + L / (2 k1)) / r^2, dtau = m g l (r = r_m = 0.05 m; to
    // first order in m: gravity's own stiffness m g l sin q vanishes at q = 0).
    let (m, r, kp, l_m) = (0.05, 0.05, 500.0, 10.0);
    let with = arm_of(&boom(
        "payload_unknown",
        "fixed",
        &format!("[[effect]]\nname = \"payload_mass\"\nparams = [{m}]\n"),
    ));
    let without = arm_of(&boom("payload_unknown0", "fixed", ""));
    assert!(with.controller_spec().is_some());
    let (st, s0) = (with.initial_state(), without.initial_state());
    let dq = st.q_rad[0] - s0.q_rad[0];
    let dtau = m * STANDARD_GRAVITY_M_S2 * 1.0;
    let expected = dtau * (r * r / kp + l_m / (2.0 * STAINLESS_K1_N)) / (r * r);
    let tip = |arm: &DrivenArm, q: &[f64]| arm.tip_m(q).unwrap().z;
    println!(
        "sag {dq:+.9} rad (closed form {expected:.9}, {:.1e}); tip {:+.6} mm",
        dq.abs() / expected - 1.0,
        1e3 * (tip(&with, &st.q_rad) - tip(&without, &s0.q_rad))
    );
    assert!(
        (dq.abs() / expected - 1.0).abs() < 1e-3,
        "{dq} vs {expected}"
    );
    // the tip goes down
    assert!(tip(&with, &st.q_rad) < tip(&without, &s0.q_rad) - 1e-4);
    // The servo holds the reference it computes for the boom without the payload, and
    // balances the real load there: kp (th_ref - th) + r_m phi_ref = r_m phi.
    assert_eq!(st.motor_ref_rad[0].to_bits(), s0.motor_ref_rad[0].to_bits());
    let phi = with.static_pairs(&st.q_rad)[0].phi_n;
    let phi_ref = without.static_pairs(&[0.0])[0].phi_n;
    let give = st.motor_rad[0] - st.motor_ref_rad[0];
    let expected_give = r * (phi_ref - phi) / kp;
    assert!(
        (give / expected_give - 1.0).abs() < 1e-9,
        "{give} vs {expected_give}"
    );
    // That is a rest: held 1 s, the boom does not move from its sag.
    let (q, _) = trace(&with, 1000);
    let worst = q.iter().fold(0.0f64, |a, x| a.max((x - st.q_rad[0]).abs()));
    println!("held within {worst:.1e} rad of the sag");
    assert!(worst < 1e-9, "{worst}");
}

#[test]
fn nonlinear_stiffness_on_the_arm_ropes_gives_the_closed_form_stretch() {
    // The boom with 2 kg at its tip and a constant-force tensioner (f+ + f- = 2 T), its
    // ropes stiffening (tangent k1 (1 + b f)): a rope at tension f is strained by
    // e(f) = ln(1 + b f) / (k1 b), and the pair holding phi stretches by
    // u = L (e(T + phi/2) - e(T - phi/2)) / 2 (linear ropes: phi L / (2 k1)).
    let b = 1e-3f64;
    let payload = "[payload]\nmass_kg = 2.0\nlink = \"tip\"\n";
    let stiff = arm_of(&boom(
        "stiff",
        "constant_force",
        &format!("{payload}[[effect]]\nname = \"nonlinear_stiffness\"\nparams = [{b}]\n"),
    ));
    let linear = arm_of(&boom("linear", "constant_force", payload));
    assert_eq!(
        stiff.pairs()[0].spec.law.stiffening_per_n.to_bits(),
        b.to_bits()
    );
    let s = &stiff.static_pairs(&[0.0])[0];
    let phi = s.phi_n;
    let e = |f: f64| (1.0 + b * f).ln() / (STAINLESS_K1_N * b);
    let u = 10.0 * (e(1000.0 + phi / 2.0) - e(1000.0 - phi / 2.0)) / 2.0;
    let u_linear = phi * 10.0 / (2.0 * STAINLESS_K1_N);
    let theta = stiff.initial_state().motor_rad[0];
    let theta_linear = linear.initial_state().motor_rad[0];
    println!(
        "phi {phi:.4} N: u {:.9} m (closed form {u:.9}, {:.1e}; linear {u_linear:.9}), motor \
         {theta:.9} rad (linear rope {theta_linear:.9}); held, worst {:.1e} rad",
        s.u_m,
        s.u_m / u - 1.0,
        held(&stiff)
    );
    // The boom's 1 kg at 0.5 m and the payload's 2 kg at 1 m on r = 0.05 m: 490.5 N.
    assert!((phi.abs() - 2.5 * STANDARD_GRAVITY_M_S2 / 0.05).abs() < 1e-9 * phi.abs());
    assert!((s.u_m / u - 1.0).abs() < 1e-9, "{} vs {u}", s.u_m);
    assert!((theta * 0.05 / u - 1.0).abs() < 1e-9, "{theta}");
    assert!((theta_linear * 0.05 / u_linear - 1.0).abs() < 1e-9);
    // The step's ropes are the same stiffening ropes: held, the boom stays put.
    let worst = held(&stiff);
    assert!(worst < 1e-9, "{worst}");
    // Every rope (and span) of every pair of an arm gets it from one [[effect]] table.
    let l5 = std::fs::read_to_string(robot_path(
        "../scenarios/arm_dyneema2_base_step_relay_friction.toml",
    ))
    .unwrap()
    .replace("../robots/", &format!("{}/", robot_path("").display()));
    let arm = arm_of(&format!(
        "{l5}\n[[effect]]\nname = \"nonlinear_stiffness\"\nparams = [{b}]\n"
    ));
    for p in arm.pairs() {
        let got = p.spec.law.stiffening_per_n;
        assert_eq!(got.to_bits(), b.to_bits(), "joint {}", p.spec.joint);
        assert!(p.spec.effects.iter().any(|e| e == "nonlinear_stiffness"));
        assert!(p.relays.is_some(), "joint {}", p.spec.joint);
    }
}

#[test]
fn arm_wide_effects_are_refused_where_they_cannot_act() {
    let cases = [
        // Given twice: in a transmission and arm-wide.
        (
            "[[effect]]\nname = \"joint_friction\"\n",
            "effects = [{ name = \"joint_friction\" }]",
            "given twice",
        ),
        // A payload at a transmission.
        ("", "effects = [{ name = \"payload_mass\" }]", "[[effect]]"),
        // A sensor has no place in an arm run.
        ("[[effect]]\nname = \"sensor_delay\"\n", "", "sensor"),
        // A payload that would weigh less than nothing.
        (
            "[[effect]]\nname = \"payload_mass\"\nparams = [-1.0]\n",
            "",
            "below 0 kg",
        ),
        // An unknown joint.
        (
            "[[effect]]\nname = \"joint_friction\"\njoints = [\"j9\"]\n",
            "",
            "no moving joint named 'j9'",
        ),
    ];
    for (arm_wide, in_transmission, needle) in cases {
        let text = rig(KINEMATIC, SMALL_STEP, arm_wide).replace(
            "preload_n = 300.0\n",
            &format!("preload_n = 300.0\n{in_transmission}\n"),
        );
        let err = parse(&text, "effects test", Path::new("."))
            .unwrap_err()
            .to_string();
        println!("{err}");
        assert!(err.contains(needle), "{needle}: {err}");
        assert!(err.contains("effects test:"), "{err}");
    }
}
