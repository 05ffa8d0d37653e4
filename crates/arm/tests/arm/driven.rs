//! The driven arm: links, rope pairs, motors and servos integrated together.

use crate::common;

use common::*;
use longreach_arm::{dynamics, Command, MotorMode, MotorSpec};
use nalgebra::Vector3;

#[test]
fn energy_is_conserved_without_damping_or_gravity() {
    // Free motors (no servo torque), elastic ropes, no damping, no gravity: links,
    // motors and rope springs exchange energy; the total must stay constant.
    let motor = MotorSpec {
        inertia_kg_m2: 0.01,
        damping_n_m_s: 0.0,
        mode: MotorMode::Servo {
            kp_n_m_per_rad: 0.0,
            kd_n_m_s_per_rad: 0.0,
            torque_limit_n_m: f64::INFINITY,
            gravity_feedforward: false,
        },
        friction: None,
    };
    let arm = arm5_driven_preload(motor, vec![Command::Hold; 5], 2000.0)
        .with_gravity(Vector3::zeros())
        .with_joint_damping(0.0);
    let mut st = arm.initial_state();
    // Kick: joint and motor velocities, and every rope pair stretched by turning its
    // motor 0.2 rad (u = 5 mm) at the start (the ropes' state follows on the first step).
    st.qd_rad_s = vec![0.3, -0.2, 0.4, -0.5, 0.6];
    st.motor_rate_rad_s = vec![5.0, -3.0, 2.0, 4.0, -6.0];
    let theta0 = st.motor_rad.clone();
    let mut q_free = st.clone();
    for (p, m) in q_free.motor_rad.iter_mut().enumerate() {
        *m = theta0[p] + 0.2;
    }
    st = q_free;
    for (p, pair) in arm.pairs().iter().enumerate() {
        for (side, sign) in [(0, 1.0), (1, -1.0)] {
            let r = &mut st.ropes[p][side];
            let rq: f64 = pair.row.iter().zip(&st.q_rad).map(|(a, b)| a * b).sum();
            let u = pair.spec.motor_radius_m * st.motor_rad[p] - rq;
            r.strain = (st.carriage_m[p] + sign * u) * pair.inv_length;
            r.e1 = r.strain;
            r.tension_n = pair.spec.law.k1_n * r.e1;
        }
    }
    let en0 = arm.energy(&st);
    let e0 = en0.total_j();
    let ke0 = en0.links_kinetic_j + en0.motors_kinetic_j;
    let (mut max_dev, mut min_ke, mut max_ke) = (0.0f64, f64::INFINITY, 0.0f64);
    for _ in 0..10_000 {
        arm.step(&mut st).unwrap();
        let en = arm.energy(&st);
        max_dev = max_dev.max((en.total_j() - e0).abs());
        let ke = en.links_kinetic_j + en.motors_kinetic_j;
        (min_ke, max_ke) = (min_ke.min(ke), max_ke.max(ke));
    }
    println!(
        "energy {e0:.6} J (kinetic {ke0:.6} J, swinging between {min_ke:.4} and {max_ke:.4} J): \
         max |dE| over 10 s = {max_dev:.3e} J = {:.2e} of the total, {:.2e} of the initial kinetic energy",
        max_dev / e0,
        max_dev / ke0
    );
    // The exchange is real (kinetic energy goes into the ropes and back) ...
    assert!(max_ke - min_ke > 0.1 * max_ke, "no exchange");
    // ... and the total is kept: < 0.1% of the total (measured 1.1e-4), and within 1%
    // of the kinetic energy alone (measured 1.4e-3: the trapezoidal rule is exactly
    // conservative on the linear ropes and motors; M(q) changing costs O(h^2)).
    assert!(max_dev < 1e-3 * e0, "drift {max_dev} J of {e0} J");
    assert!(max_dev < 1e-2 * ke0, "drift {max_dev} J vs kinetic {ke0} J");
}

#[test]
fn statics_rope_torques_equal_gravity_torques() {
    let arm = arm5_driven(servo(0.01, 200.0, 5.0), vec![Command::Hold; 5]);
    let mut st = arm.initial_state();
    let q = st.q_rad.clone();
    let g = dynamics::gravity_torques(arm.spec(), &q).unwrap();
    let tau = arm.rope_joint_torques(&st);
    for j in 0..5 {
        assert!(
            (tau[j] - g[j]).abs() <= 1e-6 * g[j].abs(),
            "{j}: {} vs {}",
            tau[j],
            g[j]
        );
    }
    // Hold for a second: stays put.
    for _ in 0..1000 {
        arm.step(&mut st).unwrap();
    }
    for j in 0..5 {
        assert!((st.q_rad[j] - q[j]).abs() < 1e-9, "{j}: {}", st.q_rad[j]);
    }
}

#[test]
fn coupling_distal_tensions_change_as_routing_predicts() {
    // Kinematic motors held at their initial angles, no gravity, fixed tensioners:
    // joint 1 is moved by its motor (trapezoid); every distal rope runs over the relay
    // at joint 1 (MuJoCo anchor: tendon coefficient -0.025 on q1 .. q_p), so its
    // stretch changes by -0.025 (dq1 + .. + dq_p) and, with elastic ropes, its tension
    // by k1/L_p times that. The coefficients below are the anchor's, not ours.
    let motor = kinematic();
    let mut cmds = vec![Command::Hold; 5];
    cmds[0] = trapezoid(0.2, 0.1, 0.2, 0.5);
    let arm = arm5_driven(motor, cmds)
        .with_gravity(Vector3::zeros())
        .with_routing_compensation(false);
    let mut st = arm.initial_state();
    let q0 = st.q_rad.clone();
    let f0: Vec<[f64; 2]> = st
        .ropes
        .iter()
        .map(|r| [r[0].tension_n, r[1].tension_n])
        .collect();
    let th0 = st.motor_rad.clone();
    for _ in 0..1500 {
        arm.step(&mut st).unwrap();
    }
    assert!((st.q_rad[0] - q0[0]).abs() > 0.05, "joint 1 did not move");
    let k1 = 1.37e5;
    for p in 1..5 {
        let l = 0.5 + 2.0 * p as f64;
        let dq: f64 = (0..=p).map(|k| 0.025 * (st.q_rad[k] - q0[k])).sum();
        let du = 0.025 * (st.motor_rad[p] - th0[p]) - dq;
        let pred = [f0[p][0] + k1 / l * du, f0[p][1] - k1 / l * du];
        for s in 0..2 {
            let got = st.ropes[p][s].tension_n;
            let change = pred[s] - f0[p][s];
            println!(
                "pair {p} rope {s}: tension {got:.6} N, predicted {:.6} N (change {change:.3} N)",
                pred[s]
            );
            assert!(
                (got - pred[s]).abs() < 1e-6 * change.abs().max(1.0),
                "pair {p} side {s}"
            );
        }
    }
    // Only joint 1 displaced (every other joint and motor where it was): each distal
    // pair's tensions change by exactly -+ k1/L_p * 0.025 * dq1.
    let st0 = arm.initial_state();
    let dq1 = 0.01;
    let mut q = st0.q_rad.clone();
    q[0] += dq1;
    let base = arm.tensions_at(&st0, &st0.q_rad, &st0.motor_rad, &st0.carriage_m);
    let moved = arm.tensions_at(&st0, &q, &st0.motor_rad, &st0.carriage_m);
    for p in 0..5 {
        let l = 0.5 + 2.0 * p as f64;
        let df = k1 / l * 0.025 * dq1;
        let got = [moved[p][0] - base[p][0], moved[p][1] - base[p][1]];
        println!(
            "pair {p}: dT+ = {:.6} N, dT- = {:.6} N, predicted -+{df:.6} N",
            got[0], got[1]
        );
        assert!(
            (got[0] + df).abs() < 1e-9 * df,
            "pair {p}: {} vs {}",
            got[0],
            -df
        );
        assert!(
            (got[1] - df).abs() < 1e-9 * df,
            "pair {p}: {} vs {}",
            got[1],
            df
        );
    }
}
