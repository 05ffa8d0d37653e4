//! Two independent plants agree: the paper's rig URDF driven through the arm path
//! (URDF -> links, routed rope pair, kinematic motor) gives the frequency response
//! of the rig plant of crates/drive (its own equations, its own integrator).

use crate::common;

use common::{rig_pair, robot_path};
use longreach_arm::transmission::Tensioner;
use longreach_arm::{load_urdf, Command, DrivenArm};
use longreach_drive::sweep::{frequency_response, run};
use longreach_drive::{InputSignal, RigModel, RigSpec, RigTrace, SteppedSine};
use longreach_rope::{Catalog, LawKind, RopeLaw};

fn compare(rope: &str, kind: LawKind, mean_tension_n: f64) {
    let params = Catalog::builtin().get(rope).unwrap().clone();
    let law = RopeLaw::from_params(&params, kind).unwrap();
    let dt = 1e-3;
    let sine = SteppedSine {
        amplitude_rad: 4.5f64.to_radians(),
        frequencies_hz: vec![0.5, 1.0, 1.8, 2.4, 3.0, 3.6, 4.5, 6.0],
        settle_s: 4.0,
        min_cycles: 2,
        min_hold_s: 1.0,
    };
    let input = InputSignal::stepped_sine(sine.clone()).unwrap();

    // Plant 1: the rig of crates/drive (C = 0.05 N*m*s, as rig.urdf's damping).
    let rig = RigModel::new(RigSpec::paper(rope, law.clone(), 0.05, mean_tension_n), dt).unwrap();
    let rig_trace = run(&rig, &input).unwrap();
    let rig_points = frequency_response(&rig, &sine, &rig_trace);

    // Plant 2: robots/rig/rig.urdf through the arm path.
    let spec = load_urdf(robot_path("rig/rig.urdf")).unwrap();
    let pair = rig_pair(rope, law, mean_tension_n, 490.0, Tensioner::ConstantForce);
    let arm = DrivenArm::new(
        spec,
        vec![pair],
        vec![Command::Signal(input.clone())],
        vec![0.0],
        dt,
    )
    .unwrap();
    let mut st = arm.initial_state();
    let mut trace = RigTrace::default();
    let steps = (input.duration_s() / dt).round() as usize;
    let push = |tr: &mut RigTrace, st: &longreach_arm::DrivenState| {
        tr.time_s.push(st.time_s);
        tr.input_rad.push(st.motor_rad[0]);
        tr.output_rad.push(st.q_rad[0]);
        tr.tension_1_n.push(st.ropes[0][0].tension_n);
        tr.tension_2_n.push(st.ropes[0][1].tension_n);
    };
    push(&mut trace, &st);
    for _ in 0..steps {
        arm.step(&mut st).unwrap();
        push(&mut trace, &st);
    }
    let arm_points = frequency_response(&rig, &sine, &trace);
    for (a, r) in arm_points.iter().zip(&rig_points) {
        let dg = a.simulated_gain_db - r.simulated_gain_db;
        let dp = a.simulated_phase_deg - r.simulated_phase_deg;
        println!(
            "{rope} {:4.1} Hz: arm {:8.3} dB {:8.2} deg, rig {:8.3} dB {:8.2} deg (diff {dg:.2e} dB, {dp:.2e} deg)",
            a.frequency_hz, a.simulated_gain_db, a.simulated_phase_deg, r.simulated_gain_db, r.simulated_phase_deg
        );
        assert!(
            dg.abs() < 0.2,
            "{rope} at {} Hz: gain differs by {dg} dB",
            a.frequency_hz
        );
        assert!(
            dp.abs() < 2.0,
            "{rope} at {} Hz: phase differs by {dp} deg",
            a.frequency_hz
        );
    }
}

#[test]
fn rig_urdf_through_arm_path_matches_rig_plant_dyneema() {
    compare("dyneema2", LawKind::FourElement, 196.0);
}

#[test]
fn rig_urdf_through_arm_path_matches_rig_plant_stainless() {
    compare("stainless1", LawKind::Elastic, 196.0);
}
