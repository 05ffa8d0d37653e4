//! The `joint_friction` effect at the rig's output shaft (a joint-site effect through
//! the transmission core's hooks): the energy the step loses equals the friction's work,
//! and a free oscillation decays by Coulomb's decrement.

use longreach_drive::effects::{self, Applied, BearingFriction, DataKind, JointFriction, Site};
use longreach_drive::{RigModel, RigSpec, Tensioner};
use longreach_rope::{Catalog, LawKind, RopeLaw};

fn stainless_rig() -> RigSpec {
    let p = Catalog::builtin().get("stainless1").unwrap().clone();
    let mut s = RigSpec::paper(
        "stainless1",
        RopeLaw::from_params(&p, LawKind::Elastic).unwrap(),
        0.0,
        300.0,
    );
    s.tensioner = Tensioner::Fixed;
    s
}

/// Free oscillation of the output pulley after an input step, elastic ropes, no shaft
/// damping, a fixed tensioner: the bearing's friction is the only loss. With the input
/// held, every other force of the step is conservative under the trapezoidal rule, so
/// the energy each step loses must equal the friction's discrete work
/// `(tau(w0) + tau(w1)) / 2 * dphi`, to round-off; and the peaks fall linearly by
/// Coulomb's `4 F / k` with `k = 2 r2^2 k1 / L`, not exponentially.
#[test]
fn friction_work_equals_the_energy_lost_and_peaks_fall_by_coulombs_decrement() {
    let (coulomb, viscous) = (0.05, 2e-4);
    let s = stainless_rig();
    let applied = Applied::new(
        &JointFriction,
        vec![coulomb, viscous, BearingFriction::DEFAULT_SLIP_RATE_RAD_S],
    )
    .unwrap();
    let law = BearingFriction {
        coulomb_n_m: coulomb,
        viscous_n_m_s: viscous,
        slip_rate_rad_s: BearingFriction::DEFAULT_SLIP_RATE_RAD_S,
        coulomb_table: None,
    };
    let dt = 5e-4;
    let model = RigModel::with_effects(s.clone(), &[applied], dt).unwrap();
    let mut st = model.rest_state();
    let step = 0.1;
    model.step(&mut st, step).unwrap();
    let e_start = model.energy_j(&st);
    let (mut work, mut worst_gap) = (0.0, 0.0f64);
    let mut phi = Vec::new();
    for _ in 0..(6.0 / dt) as usize {
        let (phi0, w0, e0) = (st.output_rad(), st.output_rate_rad_s(), model.energy_j(&st));
        model.step(&mut st, step).unwrap();
        let w = law.step_work_j(w0, st.output_rate_rad_s(), st.output_rad() - phi0);
        work += w;
        worst_gap = worst_gap.max((model.energy_j(&st) - e0 - w).abs());
        phi.push(st.output_rad());
    }
    let lost = e_start - model.energy_j(&st);
    eprintln!(
        "energy lost {lost:.6e} J, friction work {:.6e} J, worst step mismatch {worst_gap:.2e} J",
        -work
    );
    assert!(lost > 0.05, "{lost}");
    assert!((lost + work).abs() <= 1e-9 * lost, "{lost} vs {}", -work);
    assert!(worst_gap <= 1e-12 * lost.max(1.0), "{worst_gap}");
    // Successive maxima of the output angle above its new rest.
    let peaks: Vec<f64> = phi
        .windows(3)
        .filter(|w| w[1] > w[0] && w[1] >= w[2] && w[1] > step)
        .map(|w| w[1])
        .collect();
    let k_theta = 2.0 * s.output_radius_m.powi(2) * s.law.k1_n / s.rope_length_m;
    let expected = 4.0 * coulomb / k_theta;
    let dec: Vec<f64> = peaks.windows(2).map(|w| w[0] - w[1]).collect();
    eprintln!("decrements {dec:?}, Coulomb {expected}");
    let used: Vec<f64> = dec
        .iter()
        .zip(&peaks)
        .filter(|(_, p)| **p - step > 0.3 * step)
        .map(|(d, _)| *d)
        .collect();
    assert!(used.len() >= 4, "{peaks:?}");
    for d in used {
        // The viscous part adds a little: within 5% of the dry decrement.
        assert!(
            (d / expected - 1.0).abs() < 0.05,
            "decrement {d} vs {expected}"
        );
    }
}

/// The effect is at the joint site, on sweeps, present once added, and its compiled
/// torque is what the rig's step uses (no joint effect: the step is the ideal one).
#[test]
fn the_effect_acts_at_the_joint_and_is_seen_as_present() {
    let e = effects::find("joint_friction").unwrap();
    assert_eq!(e.site(), Site::Joint);
    assert!(e.applies_to(DataKind::SineSweep) && !e.applies_to(DataKind::Relaxation));
    let s = stainless_rig();
    let target = |joint_effects: &[&'static str]| {
        e.present_in(&effects::Target {
            law: &s.law,
            pair: None,
            joint_effects,
        })
    };
    assert!(!target(&[]));
    assert!(target(&["joint_friction"]));
    // Below the bounds: refused by name.
    let err = Applied::new(e, vec![-1.0, 0.0, 1e-2])
        .unwrap_err()
        .to_string();
    assert!(err.contains("joint_friction.coulomb_n_m"), "{err}");
    // A zero dry torque and zero viscous part leave the rig as it was.
    let none = Applied::new(e, vec![1e-6, 0.0, 1e-2]).unwrap();
    let mut s = s;
    s.output_damping_n_m_s = 0.05;
    let a = RigModel::new(s.clone(), 1e-3).unwrap();
    let b = RigModel::with_effects(s, &[none], 1e-3).unwrap();
    let (mut sa, mut sb) = (a.rest_state(), b.rest_state());
    let mut worst = 0.0f64;
    for i in 1..=2000 {
        let th = 0.05 * (i as f64 * 1e-3 * 12.0).sin();
        a.step(&mut sa, th).unwrap();
        b.step(&mut sb, th).unwrap();
        worst = worst.max((sa.output_rad() - sb.output_rad()).abs());
    }
    eprintln!("tiny friction: output within {worst:e} rad of the rig without");
    // 1e-6 N*m against rope torques of ~10 N*m.
    assert!(worst < 1e-6, "{worst}");
}
