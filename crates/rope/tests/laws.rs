//! Rope laws against closed forms and the paper's relations.
#![allow(clippy::float_cmp)] // exact equality is the point: held strains must not move by one ulp

use longreach_rope::{
    relaxation_tension_n, Catalog, KelvinElement, LawKind, NonlinearCreep, RopeError, RopeLaw,
    RopeStepper, Table,
};

fn four_element_ropes() -> Vec<(String, RopeLaw)> {
    let catalog = Catalog::builtin();
    catalog
        .ropes()
        .filter(|r| r.has_four_element())
        .map(|r| {
            (
                r.name.clone(),
                RopeLaw::from_params(r, LawKind::FourElement).unwrap(),
            )
        })
        .collect()
}

fn relaxation_max_rel_error(law: &RopeLaw, dt_s: f64, duration_s: f64) -> f64 {
    let strain = 0.015;
    let stepper = RopeStepper::new(law.clone(), dt_s).unwrap();
    let mut state = stepper.instant_strain_state(strain);
    let n = (duration_s / dt_s).round() as usize;
    let kel = law.kelvin[0];
    let c2 = law.c2_n_s.unwrap();
    let mut worst = 0.0_f64;
    for i in 1..=n {
        let p = stepper.prepare(&state);
        let f = stepper.commit(&p, &mut state, strain);
        let exact = relaxation_tension_n(law.k1_n, c2, kel.k_n, kel.c_n_s, strain, i as f64 * dt_s);
        worst = worst.max(((f - exact) / exact).abs());
    }
    worst
}

#[test]
fn catalog_holds_the_papers_five_ropes() {
    let c = Catalog::builtin();
    let names: Vec<&str> = c.names().collect();
    assert_eq!(
        names,
        ["dyneema2", "kevlar2", "stainless1", "vectran2", "zylon2"]
    );
    let d = c.get("Dyneema2").unwrap();
    assert_eq!(d.k1_n, 7.29e4);
    assert_eq!(d.c2_n_s, Some(1.65e7));
    assert_eq!(c.get("stainless1").unwrap().k1_n, 1.37e5);
    assert!(!c.get("stainless1").unwrap().has_four_element());
}

#[test]
fn unknown_rope_names_the_known_ones() {
    let err = Catalog::builtin().get("nylon").unwrap_err().to_string();
    assert!(
        err.contains("nylon") && err.contains("dyneema2") && err.contains("inline"),
        "{err}"
    );
}

#[test]
fn bad_catalog_text_names_the_file_and_key() {
    let err = Catalog::from_toml_str("[x]\ntensile_strength_n = 1.0\nk1 = -3.0\n", "my.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("my.toml") && err.contains("k1") && err.contains("-3"),
        "{err}"
    );
    let err = Catalog::from_toml_str("[x]\ntensile_strength_n = 1.0\nk1 = \"a\"\n", "my.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("my.toml") && err.contains("line 3"), "{err}");
    let err = Catalog::from_toml_str("[x]\ntensile_strength_n = 1.0\nk1 = 1.0\nc2 = 1.0\n", "f")
        .unwrap_err()
        .to_string();
    assert!(err.contains("k3, c2, c3"), "{err}");
}

#[test]
fn four_element_law_needs_its_constants() {
    let steel = Catalog::builtin().get("stainless1").unwrap().clone();
    let err = RopeLaw::from_params(&steel, LawKind::FourElement).unwrap_err();
    assert!(matches!(err, RopeError::MissingConstant { .. }));
    assert!(err.to_string().contains("elastic"));
    assert!(RopeStepper::new(RopeLaw::elastic(1.0), 0.0).is_err());
    assert!(RopeStepper::new(RopeLaw::elastic(1.0), f64::NAN).is_err());
}

/// Eq. 6 against the simulated relaxation of every catalog rope over 550 s (Fig. 6).
#[test]
fn relaxation_matches_eq6_for_every_rope() {
    for (name, law) in four_element_ropes() {
        let err = relaxation_max_rel_error(&law, 1e-4, 550.0);
        assert!(err < 1e-6, "{name}: max relative error {err:e}");
    }
}

/// Stable and accurate at every step from 1e-5 s to 1e-2 s: the error falls as dt^2
/// and stays small at the largest step.
#[test]
fn relaxation_is_accurate_at_every_step_size() {
    for (name, law) in four_element_ropes() {
        let mut prev = f64::INFINITY;
        for dt in [1e-2, 1e-3, 1e-4] {
            let err = relaxation_max_rel_error(&law, dt, 20.0);
            assert!(err < 2e-4, "{name}: dt {dt}: {err:e}");
            assert!(
                err < prev / 50.0 || err < 1e-11,
                "{name}: dt {dt}: {err:e} vs {prev:e}"
            );
            prev = err;
        }
        // The smallest step of the range: bounded and finite over a short run.
        let err = relaxation_max_rel_error(&law, 1e-5, 2.0);
        assert!(err < 1e-9, "{name}: dt 1e-5: {err:e}");
    }
}

/// The oscillating tension of a rope under a sine strain equals the strain amplitude
/// times the dynamic modulus 1/J(iw), J = 1/k1 + 1/(iw c2) + 1/(k3 + iw c3)
/// (the rope term of eq. 12), once the step response to the mean strain (eq. 6) is
/// taken away.
#[test]
fn sine_response_matches_the_complex_compliance() {
    for (name, law) in four_element_ropes() {
        let dt = 1e-3;
        let (mean, amp, freq_hz) = (0.01, 5e-4, 2.0);
        let w = 2.0 * std::f64::consts::PI * freq_hz;
        let stepper = RopeStepper::new(law.clone(), dt).unwrap();
        let mut state = stepper.instant_strain_state(mean);
        let kel = law.kelvin[0];
        let c2 = law.c2_n_s.unwrap();
        let (mut re, mut im) = (0.0, 0.0);
        let (start, cycles) = (20.0, 20.0);
        let n_end = ((start + cycles / freq_hz) / dt).round() as usize;
        let n_start = (start / dt).round() as usize;
        for i in 1..=n_end {
            let t = i as f64 * dt;
            let p = stepper.prepare(&state);
            let f = stepper.commit(&p, &mut state, mean + amp * (w * t).sin());
            let osc = f - relaxation_tension_n(law.k1_n, c2, kel.k_n, kel.c_n_s, mean, t);
            if i > n_start {
                re += osc * (w * t).sin();
                im += osc * (w * t).cos();
            }
        }
        let n = (n_end - n_start) as f64;
        let (re, im) = (2.0 * re / n, 2.0 * im / n);
        // Exact steady state: J(iw) inverse.
        let j_re = 1.0 / law.k1_n + kel.k_n / (kel.k_n.powi(2) + (w * kel.c_n_s).powi(2));
        let j_im = -1.0 / (w * c2) - w * kel.c_n_s / (kel.k_n.powi(2) + (w * kel.c_n_s).powi(2));
        let norm = j_re * j_re + j_im * j_im;
        let (m_re, m_im) = (j_re / norm, -j_im / norm);
        let gain = (re * re + im * im).sqrt() / amp;
        let phase = im.atan2(re);
        let gain_exact = (m_re * m_re + m_im * m_im).sqrt();
        let phase_exact = m_im.atan2(m_re);
        assert!(
            ((gain - gain_exact) / gain_exact).abs() < 2e-4,
            "{name}: {gain} vs {gain_exact}"
        );
        assert!(
            (phase - phase_exact).abs() < 2e-4,
            "{name}: {phase} vs {phase_exact}"
        );
    }
}

/// Flory (eqs. 1-2): loading to a peak leaves ep = f_peak/kp; unloading and reloading
/// below the peak leaves ep unchanged; loading past the peak makes it grow again.
#[test]
fn flory_ratchet_follows_eqs_1_and_2() {
    let d = Catalog::builtin().get("dyneema2").unwrap().clone();
    let kp = d.kp_n.unwrap();
    // Fast loading with the viscous elements removed: eq. 1 holds exactly.
    let law = RopeLaw {
        kp_n: Some(kp),
        ..RopeLaw::elastic(d.k1_n)
    };
    let stepper = RopeStepper::new(law, 1e-3).unwrap();
    let mut s = stepper.rest_state(0.0, 0.0);
    let ramp = |from: f64, to: f64| -> Vec<f64> {
        (1..=200)
            .map(|i| from + (to - from) * i as f64 / 200.0)
            .collect()
    };
    let e_peak = 0.02;
    let f = stepper
        .run_strain_history(&mut s, &ramp(0.0, e_peak))
        .unwrap();
    let f_peak = *f.last().unwrap();
    // eq. 1-2: e_peak = f/k1 + f/kp
    let expect = e_peak / (1.0 / d.k1_n + 1.0 / kp);
    assert!(
        ((f_peak - expect) / expect).abs() < 1e-12,
        "{f_peak} vs {expect}"
    );
    assert!(((s.ep - f_peak / kp) / s.ep).abs() < 1e-12);
    let ep_after_first = s.ep;
    // Unload to slack: the plastic strain stays.
    let f = stepper
        .run_strain_history(&mut s, &ramp(e_peak, 0.0))
        .unwrap();
    assert_eq!(*f.last().unwrap(), 0.0);
    assert_eq!(s.ep, ep_after_first);
    // Slack until the strain passes ep, then the k1 slope alone (the ratchet is locked).
    let e_reload = ep_after_first + 0.8 * f_peak / d.k1_n;
    let f = stepper
        .run_strain_history(&mut s, &ramp(0.0, e_reload))
        .unwrap();
    assert_eq!(s.ep, ep_after_first, "ep grew below the previous peak");
    let f_reload = *f.last().unwrap();
    assert!(
        ((f_reload - 0.8 * f_peak) / f_peak).abs() < 1e-12,
        "{f_reload}"
    );
    // Past the previous peak the ratchet slides again: ep = new peak / kp.
    let f = stepper
        .run_strain_history(&mut s, &ramp(e_reload, 0.03))
        .unwrap();
    let f_new = *f.last().unwrap();
    assert!(f_new > f_peak);
    assert!(((s.ep - f_new / kp) / s.ep).abs() < 1e-12);
}

/// The full Flory law (with its dashpots) cycled below the pre-stretch never grows ep.
#[test]
fn flory_below_prestretch_keeps_plastic_strain() {
    let d = Catalog::builtin().get("zylon2").unwrap().clone();
    let law = RopeLaw::from_params(&d, LawKind::Flory).unwrap();
    let stepper = RopeStepper::new(law, 1e-3).unwrap();
    let mut s = stepper.rest_state(200.0, 490.0);
    let ep0 = s.ep;
    assert!((ep0 - 490.0 / d.kp_n.unwrap()).abs() < 1e-15);
    let base = s.strain;
    let strains: Vec<f64> = (1..20_000)
        .map(|i| base + 0.002 * (i as f64 * 2e-3 * std::f64::consts::PI).sin())
        .collect();
    let f = stepper.run_strain_history(&mut s, &strains).unwrap();
    let peak = f.iter().cloned().fold(0.0, f64::max);
    assert!(peak < 490.0 && peak > 250.0, "peak {peak}");
    assert_eq!(s.ep, ep0);
}

/// Slack: a rope never pushes; while slack the creep dashpot and the ratchet hold and a
/// Kelvin element relaxes through its own dashpot (exp(-k3 t / c3)).
#[test]
fn slack_rope_never_pushes_and_its_elements_behave() {
    let d = Catalog::builtin().get("vectran2").unwrap().clone();
    let law = RopeLaw::from_params(&d, LawKind::Flory).unwrap();
    let dt = 1e-3;
    let stepper = RopeStepper::new(law, dt).unwrap();
    let mut s = stepper.rest_state(300.0, 490.0);
    let natural = s.natural_strain();
    // Shorten the path well below the natural length: slack on the first step.
    let p = stepper.prepare(&s);
    let f = stepper.commit(&p, &mut s, natural - 0.01);
    assert_eq!(f, 0.0);
    let (e2, ep, e3_0) = (s.e2, s.ep, s.e3[0]);
    let n = 2000;
    let f = stepper
        .run_strain_history(&mut s, &vec![natural - 0.01; n])
        .unwrap();
    assert!(f.iter().all(|&x| x == 0.0));
    assert_eq!(s.e2, e2);
    assert_eq!(s.ep, ep);
    let expect = e3_0 * (-(d.k3_n.unwrap() / d.c3_n_s.unwrap()) * n as f64 * dt).exp();
    assert!(
        ((s.e3[0] - expect) / expect).abs() < 1e-12,
        "{} vs {expect}",
        s.e3[0]
    );
    // Tension comes back exactly when the strain exceeds the natural length the rope
    // will have at the end of the next step (its Kelvin element keeps relaxing).
    let p = stepper.prepare(&s);
    let a = (-(d.k3_n.unwrap() / d.c3_n_s.unwrap()) * dt).exp();
    let natural_next = s.e2 + a * s.e3[0] + s.ep;
    assert!((p.slack_strain() - natural_next).abs() < 1e-18);
    assert_eq!(stepper.tension(&p, natural_next - 1e-12).0, 0.0);
    assert!(stepper.tension(&p, natural_next + 1e-6).0 > 0.0);
}

/// Tension-dependent stiffness: with no dashpots the stepped tension equals the closed
/// form f = (exp(k1 b e) - 1) / b of the tangent law k1 (1 + b f).
#[test]
fn stiffening_spring_matches_its_closed_form() {
    let law = RopeLaw {
        stiffening_per_n: 2e-3,
        ..RopeLaw::elastic(7e4)
    };
    let stepper = RopeStepper::new(law.clone(), 1e-3).unwrap();
    let mut s = stepper.rest_state(0.0, 0.0);
    for i in 1..100 {
        let e = i as f64 * 1e-4;
        let p = stepper.prepare(&s);
        let f = stepper.commit(&p, &mut s, e);
        let exact = (7e4 * 2e-3 * e).exp_m1() / 2e-3;
        assert!(((f - exact) / exact).abs() < 1e-12, "{f} vs {exact}");
        assert!((law.head_strain(f) - e).abs() < 1e-15);
    }
}

/// Stress-dependent creep (exponent 1) at constant strain: df/dt = -(k1/c2) f (1 + f/fc),
/// whose solution is f = fc f0 q / (fc + f0 (1 - q)), q = exp(-k1 t / c2).
#[test]
fn nonlinear_creep_matches_its_closed_form() {
    let (k1, c2, fc) = (7e4, 2e5, 500.0);
    let law = RopeLaw {
        c2_n_s: Some(c2),
        creep: Some(NonlinearCreep {
            tension_n: fc,
            exponent: 1.0,
        }),
        ..RopeLaw::elastic(k1)
    };
    let dt = 1e-4;
    let stepper = RopeStepper::new(law, dt).unwrap();
    let e0 = 0.01;
    let mut s = stepper.instant_strain_state(e0);
    let f0 = k1 * e0;
    let f = stepper
        .run_strain_history(&mut s, &vec![e0; 50_000])
        .unwrap();
    for (i, &fi) in f.iter().enumerate().step_by(997) {
        let q = (-k1 / c2 * (i + 1) as f64 * dt).exp();
        let exact = fc * f0 * q / (fc + f0 * (1.0 - q));
        assert!(
            ((fi - exact) / exact).abs() < 1e-6,
            "step {i}: {fi} vs {exact}"
        );
    }
}

/// A step of a rope that creeps non-linearly is solved by Newton on the step's residual
/// (`RopeStepper::solve_nonlinear`). Checked against the residual written out here and
/// solved by bisection to the last bit, for a law of an elastic head, a power-law creep
/// dashpot (exponent 5.5) and the ratchet, over a history that loads the rope past its
/// yield, swings it, slackens it and loads it again: every tension within 1e-12 of the
/// root and every slope (d tension / d strain) within 1e-6 of the residual's inverse
/// slope at the root (the solver returns the last iterate's, one converged Newton step
/// away). Its convergence test reads Newton's contraction off two steps;
/// a test that stopped early would miss the first bound.
#[test]
fn a_nonlinear_creep_step_is_solved_to_its_root() {
    let (k1, c2, fc, n, kp) = (7e4, 2e5, 300.0, 5.5, 3e5);
    let law = RopeLaw {
        c2_n_s: Some(c2),
        creep: Some(NonlinearCreep {
            tension_n: fc,
            exponent: n,
        }),
        kp_n: Some(kp),
        ..RopeLaw::elastic(k1)
    };
    let h = 1e-3;
    let stepper = RopeStepper::new(law.clone(), h).unwrap();
    let rate = |f: f64| f / c2 * (1.0 + (f / fc).powf(n));
    let slope = |f: f64| (1.0 + (n + 1.0) * (f / fc).powf(n)) / c2;
    let mut s = stepper.rest_state(100.0, 0.0);
    let mut strains = Vec::new();
    for i in 0..4000 {
        let t = i as f64 * h;
        // up to ~600 N (the ratchet slides), a swing, slack at 2.4 s, loaded again
        strains.push(
            s.strain + 0.008 * (t / 1.0).min(1.0) + 0.002 * (9.0 * t).sin()
                - 0.012 * ((t - 2.0).max(0.0) / 0.4).min(1.0)
                + 0.014 * ((t - 3.0).max(0.0) / 0.5).min(1.0),
        );
    }
    let (mut slid, mut slack, mut checked) = (false, false, 0);
    for &e in &strains {
        let p = stepper.prepare(&s);
        let (f, k) = stepper.tension(&p, e);
        let (f0, e2, ep0) = (s.tension_n, s.e2, s.ep);
        let yield_n = kp * ep0;
        let g = |f: f64| {
            let ep = if f > yield_n { f / kp } else { ep0 };
            f / k1 + e2 + 0.5 * h * (rate(f0) + rate(f)) + ep - e
        };
        if g(0.0) >= 0.0 {
            assert_eq!(f, 0.0, "slack at strain {e}");
            slack = true;
        } else {
            let (mut lo, mut hi) = (0.0_f64, 1e6_f64);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if g(mid) > 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            assert!(
                (f - lo).abs() <= 1e-12 * (1.0 + lo),
                "tension {f} against the root {lo}"
            );
            let dg = 1.0 / k1 + 0.5 * h * slope(lo) + if lo > yield_n { 1.0 / kp } else { 0.0 };
            // (at the ratchet's kink the slope is either side's)
            if (lo - yield_n).abs() > 1e-6 * lo {
                assert!(
                    (k * dg - 1.0).abs() < 1e-6,
                    "slope {k} against {}",
                    1.0 / dg
                );
            }
            slid |= lo > yield_n;
            checked += 1;
        }
        stepper.commit_with_tension(&p, &mut s, e, f);
    }
    assert!(
        slid && slack && checked > 2000,
        "slid {slid}, slack {slack}, {checked} taut steps"
    );
}

/// An added Kelvin element (extra retardation) relaxes like the generalised eq. 6:
/// checked against a fine-step run of the same law (halving dt changes the result by
/// the expected dt^2 factor), and its static strain is f/k for each element.
#[test]
fn extra_kelvin_element_settles_to_its_static_strain() {
    let mut law = RopeLaw::four_element(7.29e4, 1.65e7, 9.02e5, 1.57e6);
    law.kelvin.push(KelvinElement {
        k_n: 3e5,
        c_n_s: 3e4,
    });
    let stepper = RopeStepper::new(law.clone(), 1e-3).unwrap();
    let s = stepper.rest_state(400.0, 0.0);
    assert!((s.strain - law.settled_strain(400.0)).abs() < 1e-15);
    assert!((s.e3[1] - 400.0 / 3e5).abs() < 1e-18);
    // Holding that strain, the only motion left is creep: tension decays at f/c2 * k_eff.
    let mut s2 = s;
    let f = stepper
        .run_strain_history(&mut s2, &[s.strain; 10])
        .unwrap();
    assert!(f[9] < 400.0 && f[9] > 399.9, "{}", f[9]);
}

/// Stored spring energy of an elastic rope: L * k1 e^2 / 2.
#[test]
fn stored_energy_of_elastic_rope() {
    let stepper = RopeStepper::new(RopeLaw::elastic(1.37e5), 1e-3).unwrap();
    let mut s = stepper.rest_state(0.0, 0.0);
    stepper.run_strain_history(&mut s, &[0.004]).unwrap();
    let e = stepper.stored_energy_j(&s, 15.2);
    assert!((e - 15.2 * 0.5 * 1.37e5 * 0.004 * 0.004).abs() < 1e-12);
}

/// The shape-free head spring: a table of stiffness factors `g(f)` whose two knots lie
/// on `1 + b f` is the parametric law `k1 (1 + b f)` below its last knot, so the stepped
/// four-element rope follows the parametric one to round-off; beyond it the stiffness
/// stays `k1 g(f_last)`; the stored energy is the integral of f de1.
#[test]
fn a_stiffness_table_on_the_linear_law_is_that_law() {
    let p = Catalog::builtin().get("dyneema2").unwrap().clone();
    let base = RopeLaw::from_params(&p, LawKind::FourElement).unwrap();
    let b = 2e-3;
    let parametric = RopeLaw {
        stiffening_per_n: b,
        ..base.clone()
    };
    let tabled = RopeLaw {
        stiffness_table: Some(Table::new(&[0.0, 800.0], &[1.0, 1.0 + b * 800.0]).unwrap()),
        ..base
    };
    let (sa, sb) = (
        RopeStepper::new(parametric.clone(), 1e-3).unwrap(),
        RopeStepper::new(tabled.clone(), 1e-3).unwrap(),
    );
    let (mut xa, mut xb) = (sa.rest_state(100.0, 0.0), sb.rest_state(100.0, 0.0));
    let mut worst = 0.0f64;
    let e0 = xa.strain;
    for i in 0..3000 {
        let e = e0 + 2e-3 * (i as f64 * 6e-3).sin();
        let (pa, pb) = (sa.prepare(&xa), sb.prepare(&xb));
        let fa = sa.commit(&pa, &mut xa, e);
        let fb = sb.commit(&pb, &mut xb, e);
        assert!(fa < 800.0);
        worst = worst.max((fa - fb).abs() / fa.max(1.0));
    }
    assert!(worst < 1e-10, "{worst}");
    // Energy: the head's, against a quadrature of f de1 along the table's law.
    let f = 300.0;
    let e1 = tabled.head_strain(f);
    let n = 20_000;
    let mut w = 0.0;
    for k in 0..n {
        let (fa, fb) = (f * k as f64 / n as f64, f * (k + 1) as f64 / n as f64);
        w += 0.5 * (fa + fb) * (tabled.head_strain(fb) - tabled.head_strain(fa));
    }
    let st = longreach_rope::RopeState {
        e1,
        ..Default::default()
    };
    let energy = sb.stored_energy_j(&st, 1.0);
    assert!((energy - w).abs() < 1e-6 * w, "{energy} vs {w}");
    assert!((tabled.head_tension(e1) - f).abs() < 1e-9 * f);
    // Beyond the last knot the stiffness is the last factor's.
    assert!((tabled.head_stiffness(2000.0) - tabled.k1_n * (1.0 + b * 800.0)).abs() < 1e-6);
}

/// The shape-free creep: a table of creep factors `h(f)` on `1 + f/fc` is the creep law
/// with exponent 1, below its last knot.
#[test]
fn a_creep_table_on_the_linear_law_is_that_law() {
    let (k1, c2, fc) = (7e4, 2e5, 500.0);
    let parametric = RopeLaw {
        c2_n_s: Some(c2),
        creep: Some(NonlinearCreep {
            tension_n: fc,
            exponent: 1.0,
        }),
        ..RopeLaw::elastic(k1)
    };
    let tabled = RopeLaw {
        creep: None,
        creep_table: Some(Table::new(&[0.0, 2000.0], &[1.0, 1.0 + 2000.0 / fc]).unwrap()),
        ..parametric.clone()
    };
    let (sa, sb) = (
        RopeStepper::new(parametric, 1e-3).unwrap(),
        RopeStepper::new(tabled, 1e-3).unwrap(),
    );
    let mut xa = sa.instant_strain_state(0.015);
    let mut xb = sb.instant_strain_state(0.015);
    let a = sa.run_strain_history(&mut xa, &[0.015; 2000]).unwrap();
    let b = sb.run_strain_history(&mut xb, &[0.015; 2000]).unwrap();
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs() / x)
        .fold(0.0f64, f64::max);
    assert!(worst < 1e-10, "{worst}");
    // Both at once are refused, naming the field.
    let both = RopeLaw {
        creep: Some(NonlinearCreep {
            tension_n: fc,
            exponent: 1.0,
        }),
        ..RopeLaw {
            creep_table: Some(Table::new(&[0.0, 1.0], &[1.0, 1.0]).unwrap()),
            ..RopeLaw::elastic(k1)
        }
    };
    let e = both.validate().unwrap_err().to_string();
    assert!(e.contains("creep"), "{e}");
}
