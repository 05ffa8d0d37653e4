//! Relay pulleys with friction and inertia (`RigSpec::relay_friction`): against the
//! ideal rig, the capstan-like sliding ratio, Coulomb's decrement and energy.

use longreach_drive::effects::{self, DataKind};
use longreach_drive::sweep::{frequency_response, run};
use longreach_drive::transmission::RELAY_NEWTON_TOLERANCE;
use longreach_drive::{
    rig_resonance, InputSignal, RelayFriction, RigModel, RigSpec, RigTrace, SteppedSine, Tensioner,
};
use longreach_rope::{Catalog, LawKind, RopeLaw};

fn spec(rope: &str, law: Option<LawKind>, damping: f64, tension: f64) -> RigSpec {
    let p = Catalog::builtin().get(rope).unwrap().clone();
    let kind = law.unwrap_or_else(|| LawKind::default_for(&p));
    RigSpec::paper(
        rope,
        RopeLaw::from_params(&p, kind).unwrap(),
        damping,
        tension,
    )
}

fn friction(coefficient: f64, inertia_kg_m2: f64) -> Option<RelayFriction> {
    Some(RelayFriction {
        coefficient,
        inertia_kg_m2,
        slip_rate_rad_s: RelayFriction::DEFAULT_SLIP_RATE_RAD_S,
        coefficient_table: None,
    })
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Spans in series of the same law are one rope: without friction and inertia the
/// split rig follows the ideal one (exactly for linear laws, here to solver precision),
/// and every span carries the rope's tension.
#[test]
fn frictionless_massless_relays_are_the_ideal_rig() {
    for (rope, law) in [
        ("dyneema2", None),
        ("vectran2", Some(LawKind::Flory)),
        ("stainless1", None),
    ] {
        let ideal = spec(rope, law, 0.05, 147.0);
        let mut split = ideal.clone();
        split.relay_friction = friction(0.0, 0.0);
        let input = InputSignal::stepped_sine(SteppedSine {
            amplitude_rad: 0.06,
            frequencies_hz: vec![0.5, 2.3, 4.0],
            settle_s: 1.0,
            min_cycles: 2,
            min_hold_s: 1.0,
        })
        .unwrap();
        let a = run(&RigModel::new(ideal, 1e-3).unwrap(), &input).unwrap();
        let model = RigModel::new(split, 1e-3).unwrap();
        let b = run(&model, &input).unwrap();
        let amp = a.output_rad.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        let d_out = max_abs_diff(&a.output_rad, &b.output_rad);
        let d_t = max_abs_diff(&a.tension_1_n, &b.tension_1_n)
            .max(max_abs_diff(&a.tension_2_n, &b.tension_2_n));
        eprintln!("{rope}: output differs by {d_out:e} rad of {amp}, tensions by {d_t:e} N");
        assert!(
            d_out <= 1e-9 * amp,
            "{rope}: output differs by {d_out:e} of {amp}"
        );
        assert!(d_t <= 1e-9 * 147.0, "{rope}: tension differs by {d_t:e} N");
        // Every span of the split rig carries the same tension.
        let mut st = model.rest_state();
        for i in 1..=2000 {
            model
                .step(&mut st, input.angle_rad(i as f64 * 1e-3))
                .unwrap();
        }
        for rope_i in 0..2 {
            let t = st.span_tensions_n(rope_i);
            assert_eq!(t.len(), 4);
            let spread = t.iter().fold(0.0_f64, |m, x| m.max((x - t[0]).abs()));
            assert!(spread < 1e-9 * 147.0, "{rope}: spans {t:?}");
            assert!((st.tension_in_n(rope_i) - t[0]).abs() == 0.0);
            assert!((st.tension_n(rope_i) - t[3]).abs() == 0.0);
        }
    }
}

/// A slow steady pull: rope 1 slides over its pulleys towards the input pulley, so its
/// span tensions fall geometrically from the input to the output pulley with the ratio
/// (1 + c)/(1 - c) per pulley; rope 2 slides the other way and rises.
#[test]
fn steady_sliding_gives_the_closed_form_tension_ratio() {
    let c = 0.02;
    let mut s = spec("dyneema2", None, 0.05, 147.0);
    s.relay_friction = friction(c, 2e-5);
    let dt = 1e-3;
    let model = RigModel::new(s, dt).unwrap();
    let ratio = model.spec().relay_friction.unwrap().sliding_tension_ratio();
    assert!((ratio - 1.02 / 0.98).abs() < 1e-15);
    // theta = rate * (t - tau (1 - exp(-t/tau))): a smooth start into a constant rate.
    let (rate, tau) = (0.2, 0.5);
    let mut st = model.rest_state();
    let mut worst = 0.0_f64;
    for i in 1..=6000 {
        let t = i as f64 * dt;
        let theta = rate * (t - tau * (1.0 - (-t / tau).exp()));
        model.step(&mut st, theta).unwrap();
        if t >= 4.0 {
            let t1 = st.span_tensions_n(0);
            let t2 = st.span_tensions_n(1);
            for j in 0..3 {
                worst = worst.max((t1[j] / t1[j + 1] / ratio - 1.0).abs());
                worst = worst.max((t2[j + 1] / t2[j] / ratio - 1.0).abs());
            }
            // The carriage still holds the input-side tensions' sum.
            assert!((st.tension_in_n(0) + st.tension_in_n(1) - 294.0).abs() < 1e-6);
        }
    }
    let t1 = st.span_tensions_n(0);
    eprintln!("rope 1 spans {t1:?}, worst ratio error {worst:e}");
    assert!(worst < 1e-3, "worst relative ratio error {worst:e}");
    // A geometric sequence: input side / output side = ratio^3.
    assert!((t1[0] / t1[3] / ratio.powi(3) - 1.0).abs() < 3e-3);
}

/// Free oscillation after an input step, one relay pulley per rope, elastic ropes, no
/// shaft damping, fixed tensioner: the relay friction is the only loss. The energy never
/// rises, and the peaks fall linearly by Coulomb's decrement 4 F / k per cycle with
/// F = 2 c T (the pulley's friction force at hub load 2 T) and k = k1 / (L/2) (one span;
/// both ropes' series spans give the same total stiffness), not exponentially.
#[test]
fn free_oscillation_decays_like_coulomb_and_energy_never_rises() {
    let (c, tension) = (0.002, 300.0);
    let mut s = spec("stainless1", None, 0.0, tension);
    s.relay_pulleys = 1;
    s.tensioner = Tensioner::Fixed;
    s.relay_friction = friction(c, 2e-5);
    let dt = 5e-4;
    let model = RigModel::new(s.clone(), dt).unwrap();
    let mut st = model.rest_state();
    let step = 0.1;
    let mut phi = Vec::new();
    model.step(&mut st, step).unwrap();
    let e_start = model.energy_j(&st);
    let mut e_prev = e_start;
    let mut worst_rise = 0.0_f64;
    for _ in 0..(5.0 / dt) as usize {
        model.step(&mut st, step).unwrap();
        let e = model.energy_j(&st);
        worst_rise = worst_rise.max(e - e_prev);
        e_prev = e;
        phi.push(st.output_rad());
    }
    let lost = e_start - e_prev;
    eprintln!("energy lost {lost:e} J, worst rise in a step {worst_rise:e} J");
    assert!(lost > 0.0);
    // Backward Euler on the relays (`RelayRule`, every plant's rule) is
    // dissipative: measured 2.4e-13 J against 0.100 J lost. (The trapezoidal rule, the
    // arm's until 2026-11-27, gave 2.9e-10 J: at a reversal its friction torque, taken
    // at the end rate, can do a little positive work.)
    assert!(worst_rise <= 1e-9 * lost, "energy rose by {worst_rise:e} J");
    // Successive maxima of the output angle.
    let peaks: Vec<f64> = phi
        .windows(3)
        .filter(|w| w[1] > w[0] && w[1] >= w[2] && w[1] > step)
        .map(|w| w[1])
        .collect();
    let k_span = s.law.k1_n / (s.rope_length_m / 2.0);
    let force = 2.0 * c * tension;
    let expected = 4.0 * force / k_span / s.output_radius_m;
    let dec: Vec<f64> = peaks.windows(2).map(|w| w[0] - w[1]).collect();
    eprintln!("peaks {peaks:?}\ndecrements {dec:?}, Coulomb {expected}");
    assert!(dec.len() >= 5, "{peaks:?}");
    // Cycles while the amplitude is above 40% of the step: each decrement within 20%
    // of Coulomb's (an exponential decay would halve it as the amplitude halves).
    let mut used = 0;
    for (d, p) in dec.iter().zip(&peaks) {
        if p - step > 0.4 * step {
            assert!(
                (d / expected - 1.0).abs() < 0.2,
                "decrement {d} vs {expected}"
            );
            used += 1;
        }
    }
    assert!(used >= 4, "{used}");
}

fn peak_gain_db(model: &RigModel, amplitude_rad: f64, freqs: &[f64]) -> f64 {
    let sine = SteppedSine {
        amplitude_rad,
        frequencies_hz: freqs.to_vec(),
        settle_s: 4.0,
        min_cycles: 4,
        min_hold_s: 0.0,
    };
    let input = InputSignal::stepped_sine(sine.clone()).unwrap();
    let trace: RigTrace = run(model, &input).unwrap();
    frequency_response(model, &sine, &trace)
        .iter()
        .map(|p| p.simulated_gain_db)
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Dry friction lowers the resonance peak more at a small input amplitude than at a
/// large one (viscous damping lowers it by the same dB at every amplitude).
#[test]
fn friction_flattens_the_peak_more_at_small_amplitude() {
    let ideal = spec("dyneema2", None, 0.05, 147.0);
    let res = rig_resonance(&ideal, 0.5, 10.0).unwrap().frequency_hz;
    let freqs: Vec<f64> = (0..9).map(|i| res * (0.8 + 0.075 * i as f64)).collect();
    let mut rough = ideal.clone();
    rough.relay_friction = friction(0.002, 2e-5);
    let (m_ideal, m_rough) = (
        RigModel::new(ideal, 1e-3).unwrap(),
        RigModel::new(rough, 1e-3).unwrap(),
    );
    let (small, large) = (0.005, 0.04);
    let drop_small = peak_gain_db(&m_ideal, small, &freqs) - peak_gain_db(&m_rough, small, &freqs);
    let drop_large = peak_gain_db(&m_ideal, large, &freqs) - peak_gain_db(&m_rough, large, &freqs);
    eprintln!("peak drop: {drop_small:.2} dB at {small} rad, {drop_large:.2} dB at {large} rad");
    assert!(drop_large > 0.0, "{drop_large}");
    assert!(
        drop_small > drop_large + 3.0,
        "{drop_small} vs {drop_large}"
    );
}

#[test]
fn bad_relay_values_name_the_field() {
    let base = spec("dyneema2", None, 0.05, 147.0);
    let cases = [
        (friction(1.5, 2e-5), 3, "relay_friction.coefficient"),
        (friction(-0.1, 2e-5), 3, "relay_friction.coefficient"),
        (friction(0.01, f64::NAN), 3, "relay_friction.inertia_kg_m2"),
        (
            Some(RelayFriction {
                coefficient: 0.01,
                inertia_kg_m2: 2e-5,
                slip_rate_rad_s: 0.0,
                coefficient_table: None,
            }),
            3,
            "relay_friction.slip_rate_rad_s",
        ),
        (friction(0.01, 2e-5), 40, "relay_pulleys"),
    ];
    for (f, n, field) in cases {
        let mut s = base.clone();
        s.relay_friction = f;
        s.relay_pulleys = n;
        let err = RigModel::new(s, 1e-3).unwrap_err().to_string();
        assert!(err.contains(field), "{err}");
    }
    // A state of another rig is refused, not silently misread.
    let mut s = base.clone();
    s.relay_friction = friction(0.01, 2e-5);
    let model = RigModel::new(s, 1e-3).unwrap();
    let mut ideal_state = RigModel::new(base, 1e-3).unwrap().rest_state();
    let err = model.step(&mut ideal_state, 0.01).unwrap_err().to_string();
    assert!(err.contains("rest_state"), "{err}");
}

/// The registry's `relay_friction` effect acts at the relay pulleys: it sets the pair's
/// relay friction (the rig built with it has the friction), checks its bounds by name,
/// and is seen as present afterwards.
#[test]
fn the_effect_sets_the_rig() {
    let e = effects::find("relay_friction").unwrap();
    assert!(e.applies_to(DataKind::SineSweep) && !e.applies_to(DataKind::Relaxation));
    assert_eq!(e.site(), effects::Site::RelayPulley);
    let rig = spec("dyneema2", None, 0.05, 147.0);
    let mut pair = rig.pair_spec();
    let target = |p: &longreach_drive::transmission::PairSpec| {
        e.present_in(&effects::Target {
            law: &rig.law,
            pair: Some(p),
            joint_effects: &[],
        })
    };
    assert!(!target(&pair));
    let applied = effects::Applied::new(e, vec![0.03, 4e-5]).unwrap();
    applied.apply_to_pair(&mut pair).unwrap();
    assert_eq!(pair.law, rig.law);
    let f = pair.relay_friction.unwrap();
    assert_eq!((f.coefficient, f.inertia_kg_m2), (0.03, 4e-5));
    assert!(target(&pair));
    let model = RigModel::with_effects(rig.clone(), &[applied], 1e-3).unwrap();
    assert_eq!(model.spec().relay_friction, Some(f));
    assert_eq!(model.pair().relays.as_ref().map(|c| c.relays()), Some(3));
    let err = effects::Applied::new(e, vec![0.5, 4e-5]).unwrap_err();
    assert!(
        err.to_string().contains("relay_friction.coefficient"),
        "{err}"
    );
    for p in e.params() {
        assert!(p.lower < p.default && p.default < p.upper, "{}", p.name);
    }
}

/// The relay rig's implicit step converges on its angles' tolerance, the constant-force
/// tensioner's stretch to the rope length that tolerance stands for at the smallest
/// pulley (`CompiledPair::carriage_tolerance_m`, 2.5e-10 m on the rig's 25 mm
/// pulleys): dyneema2 with relay friction 0.02 and pulleys of 1e-4 kg*m^2, stepped at
/// 2.5 ms through a sine sweep across the rig's resonance. The tensioner still holds
/// the two motor-side spans at twice the mean tension (the equation the carriage
/// solves; within 2.3e-13 N, as before), and the step takes 2.46 Newton iterations on
/// average, where it took 3.07 when the carriage's update had to fall below the ideal
/// pair's `1e-15 (1 + L)` m.
#[test]
fn the_carriage_converges_with_the_relay_angles() {
    let mut s = spec("dyneema2", None, 0.05, 196.0);
    s.relay_friction = friction(0.02, 1e-4);
    let model = RigModel::new(s, 2.5e-3).unwrap();
    let tol = model.pair().carriage_tolerance_m(RELAY_NEWTON_TOLERANCE);
    assert!((tol - 2.5e-10).abs() < 1e-20, "tolerance {tol:e} m");
    let mut st = model.rest_state();
    let (mut iterations, mut worst) = (0u64, 0.0f64);
    let steps = 3200;
    // (0.5 to 4 Hz over 8 s, 0.06 rad)
    for i in 1..=steps {
        let t = i as f64 * 2.5e-3;
        let phase = 2.0 * std::f64::consts::PI * (0.5 * t + 3.5 * t * t / 16.0);
        model.step(&mut st, 0.06 * phase.sin()).unwrap();
        iterations += u64::from(st.plant().iterations);
        worst = worst.max((st.tension_in_n(0) + st.tension_in_n(1) - 2.0 * 196.0).abs());
    }
    let mean = iterations as f64 / steps as f64;
    eprintln!(
        "relay rig: {mean:.3} Newton iterations a step, tensioner residual up to {worst:e} N"
    );
    assert!(mean < 2.6, "{mean} iterations a step");
    assert!(worst < 1e-6, "the tensioner's equation left {worst:e} N");
}
