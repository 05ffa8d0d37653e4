//! The rig plant in the time domain, against closed forms and against itself.

use longreach_drive::sweep::run;
use longreach_drive::{DriveError, InputSignal, RigModel, RigSpec, SteppedSine, Tensioner};
use longreach_rope::{Catalog, LawKind, RopeLaw};

fn spec(rope: &str, damping: f64, tension: f64) -> RigSpec {
    let p = Catalog::builtin().get(rope).unwrap().clone();
    RigSpec::paper(
        rope,
        RopeLaw::from_params(&p, LawKind::default_for(&p)).unwrap(),
        damping,
        tension,
    )
}

/// Elastic ropes, both taut: I phi'' + C phi' + K r2^2 phi = K r1 r2 theta with
/// K = 2 k1 / L: the step response of a damped oscillator.
#[test]
fn step_response_matches_the_damped_oscillator() {
    let s = spec("stainless1", 0.05, 300.0);
    let dt = 1e-4;
    let model = RigModel::new(s.clone(), dt).unwrap();
    let amp = 0.02;
    let input = InputSignal::Step {
        amplitude_rad: amp,
        start_s: 0.5 * dt,
        duration_s: 3.0,
    };
    let trace = run(&model, &input).unwrap();
    let k = 2.0 * s.law.k1_n / s.rope_length_m;
    let w0 = (k * s.output_radius_m.powi(2) / s.output_inertia_kg_m2).sqrt();
    let zeta = s.output_damping_n_m_s / (2.0 * s.output_inertia_kg_m2 * w0);
    let wd = w0 * (1.0 - zeta * zeta).sqrt();
    let gain = s.input_radius_m / s.output_radius_m * amp;
    let mut worst = 0.0_f64;
    for (t, phi) in trace.time_s.iter().zip(&trace.output_rad).skip(1) {
        // The sampled step ramps over the first step: a step at dt/2 to second order.
        let tt = t - 0.5 * dt;
        let exact = gain
            * (1.0
                - (-zeta * w0 * tt).exp()
                    * ((wd * tt).cos() + zeta / (1.0 - zeta * zeta).sqrt() * (wd * tt).sin()));
        worst = worst.max((phi - exact).abs());
    }
    assert!(worst < 2e-4 * gain, "worst error {worst:e} rad of {gain}");
    // Both ropes stayed taut and the tensioner held their sum.
    let t_sum_err = trace
        .tension_1_n
        .iter()
        .zip(&trace.tension_2_n)
        .map(|(a, b)| (a + b - 600.0).abs())
        .fold(0.0, f64::max);
    assert!(t_sum_err < 1e-9, "{t_sum_err}");
}

/// A stepped sine given as a recorded series (sampled on the step grid) drives the
/// rig exactly as the stepped sine itself.
#[test]
fn recorded_series_reproduces_the_signal_it_samples() {
    let model = RigModel::new(spec("dyneema2", 0.05, 147.0), 1e-3).unwrap();
    let sine = InputSignal::stepped_sine(SteppedSine {
        amplitude_rad: 0.05,
        frequencies_hz: vec![0.5, 2.0, 3.0],
        settle_s: 2.0,
        min_cycles: 2,
        min_hold_s: 1.0,
    })
    .unwrap();
    let a = run(&model, &sine).unwrap();
    let series = InputSignal::series(a.time_s.clone(), a.input_rad.clone()).unwrap();
    let b = run(&model, &series).unwrap();
    assert_eq!(a.output_rad.len(), b.output_rad.len());
    let worst = a
        .output_rad
        .iter()
        .zip(&b.output_rad)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-10, "{worst:e}");
    // Bad series are refused with the sample named.
    let err = InputSignal::series(vec![0.0, 1.0, 1.0], vec![0.0; 3]).unwrap_err();
    assert!(err.to_string().contains("sample 2"), "{err}");
}

/// A recorded series is interpolated between the two samples around `t` and held
/// past its ends, on a uniformly sampled series (looked up in one guess) as on an
/// irregular one (bisection): every value equals the interpolation between the samples
/// found by a linear scan, at sample times, between them, at the ends and beyond.
#[test]
fn a_series_interpolates_between_the_samples_around_each_time() {
    let uniform: Vec<f64> = (0..801).map(|i| 0.25 + f64::from(i) * 0.01).collect();
    let irregular: Vec<f64> = (0..400).map(|i| f64::from(i).powf(1.5) * 1e-3).collect();
    for time_s in [uniform, irregular] {
        let angle_rad: Vec<f64> = time_s.iter().map(|t| (3.0 * t).sin() + t).collect();
        let series = InputSignal::series(time_s.clone(), angle_rad.clone()).unwrap();
        let (t0, t1) = (time_s[0], time_s[time_s.len() - 1]);
        let n = 5000;
        let probes = (0..=n)
            .map(|k| t0 - 0.5 + (t1 - t0 + 1.0) * f64::from(k) / f64::from(n))
            .chain(time_s.iter().copied());
        for t in probes {
            let expected = match time_s.iter().rposition(|&x| x <= t) {
                None => angle_rad[0],
                Some(i) if i + 1 == time_s.len() => angle_rad[i],
                Some(i) => {
                    let w = (t - time_s[i]) / (time_s[i + 1] - time_s[i]);
                    angle_rad[i] + w * (angle_rad[i + 1] - angle_rad[i])
                }
            };
            let got = series.angle_rad(t);
            assert_eq!(
                got.to_bits(),
                expected.to_bits(),
                "t = {t}: {got} against {expected}"
            );
        }
    }
}

/// While both ropes are taut a fixed and a constant-force tensioner give the same
/// motion for linear ropes (different solver paths); once a rope goes slack the
/// constant-force tensioner clips the rope torque at 2 r2 T, the fixed one does not.
#[test]
fn tensioners_agree_while_taut_and_differ_when_slack() {
    let taut = |tensioner: Tensioner, amp: f64| {
        let mut s = spec("dyneema2", 0.05, 49.0);
        s.tensioner = tensioner;
        let model = RigModel::new(s, 1e-3).unwrap();
        let input = InputSignal::stepped_sine(SteppedSine {
            amplitude_rad: amp,
            frequencies_hz: vec![2.3],
            settle_s: 4.0,
            min_cycles: 4,
            min_hold_s: 0.0,
        })
        .unwrap();
        run(&model, &input).unwrap()
    };
    let (a, b) = (
        taut(Tensioner::ConstantForce, 0.005),
        taut(Tensioner::Fixed, 0.005),
    );
    assert!(a.tension_1_n.iter().chain(&a.tension_2_n).all(|&t| t > 0.0));
    let worst = a
        .output_rad
        .iter()
        .zip(&b.output_rad)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-9, "{worst:e}");
    // Large amplitude at resonance: ropes go slack.
    let (c, d) = (
        taut(Tensioner::ConstantForce, 0.08),
        taut(Tensioner::Fixed, 0.08),
    );
    let max_t = |t: &longreach_drive::RigTrace| t.tension_1_n.iter().copied().fold(0.0, f64::max);
    assert!(c.tension_2_n.contains(&0.0));
    assert!(
        (max_t(&c) - 98.0).abs() < 1e-6,
        "constant force: {}",
        max_t(&c)
    );
    assert!(max_t(&d) > 110.0, "fixed: {}", max_t(&d));
}

#[test]
fn blow_up_is_reported_with_the_time() {
    let model = RigModel::new(spec("dyneema2", 0.05, 147.0), 1e-3).unwrap();
    let mut st = model.rest_state();
    model.step(&mut st, 0.01).unwrap();
    let err = model.step(&mut st, f64::NAN).unwrap_err();
    assert!(matches!(err, DriveError::BlowUp { .. }), "{err}");
    assert!(err.to_string().contains("t = 0.002"), "{err}");
}

#[test]
fn bad_rig_fields_are_named() {
    let mut s = spec("dyneema2", 0.05, 147.0);
    s.output_inertia_kg_m2 = 0.0;
    let err = RigModel::new(s, 1e-3).unwrap_err().to_string();
    assert!(err.contains("output_inertia_kg_m2"), "{err}");
    let err = RigModel::new(spec("dyneema2", 0.05, 147.0), 0.5)
        .unwrap_err()
        .to_string();
    assert!(err.contains("dt_s"), "{err}");
}
