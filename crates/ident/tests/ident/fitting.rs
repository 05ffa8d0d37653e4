//! Bounded least squares: known answers, the paper's relaxation fit (eq. 6, 7), errors,
//! and independence from the thread count.

use longreach_ident::fitting::Clipped;
use longreach_ident::{
    add_intervals, fit, Dataset, DatasetKind, FitError, FitOptions, GaussianNoise, ParamSpec,
    ResidualError, Residuals,
};

/// y = a exp(-t / tau) + noise
struct Decay {
    t: Vec<f64>,
    y: Vec<f64>,
}

impl Decay {
    fn new(a: f64, tau: f64, sigma: f64, seed: u64) -> Self {
        let mut noise = GaussianNoise::new(sigma, seed).unwrap();
        let t: Vec<f64> = (0..501).map(|i| 0.02 * i as f64).collect();
        let y = t
            .iter()
            .map(|t| a * (-t / tau).exp() + noise.sample())
            .collect();
        Decay { t, y }
    }
}

impl Residuals for Decay {
    fn residuals(&self, p: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        out.clear();
        out.extend(
            self.t
                .iter()
                .zip(&self.y)
                .map(|(t, y)| p[0] * (-t / p[1]).exp() - y),
        );
        Ok(())
    }
}

fn decay_specs() -> Vec<ParamSpec> {
    vec![
        ParamSpec::positive("a", "", 0.7, 0.0, f64::INFINITY),
        ParamSpec::positive("tau", "s", 0.4, 1e-3, 100.0),
    ]
}

/// A fit made without intervals and given them afterwards ([`add_intervals`]) ends as
/// the fit that computed them: the same standard errors, intervals, correlations and
/// evaluation count, bit for bit (here with `a` near its bound, clipped).
#[test]
fn intervals_added_after_a_fit_are_those_it_would_have_had() {
    let problem = Decay::new(2.0, 1.5, 0.01, 7);
    let mut specs = decay_specs();
    // an upper bound just above the optimum: a's interval is clipped there
    specs[0].upper = 1.999;
    let now = fit(&problem, &specs, &FitOptions::default()).unwrap();
    let mut later = fit(
        &problem,
        &specs,
        &FitOptions {
            intervals: false,
            ..FitOptions::default()
        },
    )
    .unwrap();
    assert!(later.std_errors.iter().all(|s| s.is_nan()), "{later:?}");
    assert_eq!(later.interval_method, "none");
    add_intervals(&problem, &mut later).unwrap();
    assert!(later.deferred.is_none());
    assert!(now.std_errors.iter().all(|s| s.is_finite() && *s > 0.0));
    assert!(
        now.interval_clipped.iter().any(|c| *c != Clipped::No),
        "{now:?}"
    );
    assert_eq!(format!("{now:?}"), format!("{later:?}"));
    // a fit that has them is left as it is
    let mut again = later.clone();
    add_intervals(&problem, &mut again).unwrap();
    assert_eq!(again, later);
}

#[test]
fn exponential_decay_within_std_error() {
    let (a, tau, sigma) = (2.0, 1.5, 0.01);
    let problem = Decay::new(a, tau, sigma, 42);
    let r = fit(&problem, &decay_specs(), &FitOptions::default()).unwrap();
    assert!(r.converged, "{}", r.termination);
    let (fa, sa) = r.get("a").unwrap();
    let (ft, st) = r.get("tau").unwrap();
    println!(
        "a = {fa} +- {sa}, tau = {ft} +- {st}, rms = {}, iterations = {}",
        r.rms(),
        r.iterations
    );
    for s in [sa, st] {
        assert!(s.is_finite() && s > 0.0);
    }
    assert!((fa - a).abs() < 3.0 * sa, "a = {fa} +- {sa}");
    assert!((ft - tau).abs() < 3.0 * st, "tau = {ft} +- {st}");
    // the std errors have the size linear theory gives: sigma / sqrt(sum (dy/da)^2) for a
    // alone is a lower bound, and they are not absurdly large
    let lower_a = sigma
        / problem
            .t
            .iter()
            .map(|t| (-t / tau).exp().powi(2))
            .sum::<f64>()
            .sqrt();
    assert!(
        sa >= lower_a * 0.99 && sa < 5.0 * lower_a,
        "{sa} vs {lower_a}"
    );
    // sigma^2 = SSR / (n - p) estimates the noise variance
    let s2 = r.ssr / (r.n_residuals - 2) as f64;
    assert!((s2.sqrt() - sigma).abs() < 0.1 * sigma);
    assert_eq!(r.n_residuals, 501);
    // correlation of the estimates from the analytic Jacobian: for two parameters
    // rho = -J_a.J_tau / (|J_a| |J_tau|)
    let (ja, jt): (Vec<f64>, Vec<f64>) = problem
        .t
        .iter()
        .map(|t| ((-t / ft).exp(), fa * t / (ft * ft) * (-t / ft).exp()))
        .unzip();
    let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
    let rho = -dot(&ja, &jt) / (dot(&ja, &ja) * dot(&jt, &jt)).sqrt();
    assert!(
        (r.correlation[0][1] - rho).abs() < 1e-4,
        "{} vs {rho}",
        r.correlation[0][1]
    );
    assert!((r.correlation[1][0] - rho).abs() < 1e-4);
    assert!((r.correlation[0][0] - 1.0).abs() < 1e-12);
}

#[test]
fn active_bound_is_respected() {
    let problem = Decay::new(2.0, 1.5, 0.01, 1);
    let specs = vec![
        ParamSpec::new("a", "", 1.0).with_bounds(0.0, 10.0),
        ParamSpec::new("tau", "s", 0.5).with_bounds(0.1, 1.0),
    ];
    let r = fit(&problem, &specs, &FitOptions::default()).unwrap();
    assert!(r.values[1] <= 1.0 && r.values[1] > 0.999, "{:?}", r.values);
}

#[test]
fn unbounded_linear_parameters() {
    // a straight line: exact linear least squares to compare with
    struct Line(Vec<f64>, Vec<f64>);
    impl Residuals for Line {
        fn residuals(&self, p: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
            out.clear();
            out.extend(self.0.iter().zip(&self.1).map(|(x, y)| p[0] + p[1] * x - y));
            Ok(())
        }
    }
    let x: Vec<f64> = (0..20).map(|i| i as f64).collect();
    let y: Vec<f64> = x
        .iter()
        .map(|x| 3.0 - 0.5 * x + if (*x as i32) % 2 == 0 { 0.1 } else { -0.1 })
        .collect();
    let r = fit(
        &Line(x.clone(), y.clone()),
        &[ParamSpec::new("c", "", 0.0), ParamSpec::new("m", "", 1.0)],
        &FitOptions::default(),
    )
    .unwrap();
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxx: f64 = x.iter().map(|x| (x - mx).powi(2)).sum();
    let m = x
        .iter()
        .zip(&y)
        .map(|(x, y)| (x - mx) * (y - my))
        .sum::<f64>()
        / sxx;
    let c = my - m * mx;
    assert!(
        (r.values[0] - c).abs() < 1e-7 && (r.values[1] - m).abs() < 1e-8,
        "{:?} vs {c} {m}",
        r.values
    );
    // textbook standard error of the slope: sqrt(s^2 / Sxx)
    let s2 = r.ssr / (n - 2.0);
    assert!((r.std_errors[1] - (s2 / sxx).sqrt()).abs() < 1e-5 * (s2 / sxx).sqrt());
}

/// Eq. 6 of the paper: tension relaxation of the four-element model at strain eps0.
fn relaxation_n(t: f64, eps0: f64, k1: f64, k3: f64, c2: f64, c3: f64) -> f64 {
    let a = c2 * k1 + c2 * k3 + c3 * k1;
    let b = (a * a - 4.0 * c2 * c3 * k1 * k3).sqrt();
    let c = c2 * k1 - c2 * k3 + c3 * k1;
    let d = 2.0 * c2 * c3;
    eps0 * k1 / (2.0 * b)
        * ((-(a + b) * t / d).exp() * (c + b) - (-(a - b) * t / d).exp() * (c - b))
}

struct Relaxation {
    eps0: f64,
    t: Vec<f64>,
    f: Vec<f64>,
}

impl Residuals for Relaxation {
    fn residuals(&self, p: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        out.clear();
        out.extend(
            self.t
                .iter()
                .zip(&self.f)
                .map(|(&t, f)| relaxation_n(t, self.eps0, p[0], p[1], p[2], p[3]) - f),
        );
        Ok(())
    }
}

#[test]
fn relaxation_fit_recovers_catalog_dyneema2() {
    let path = format!(
        "{}/../../data/examples/example_relax_control",
        env!("CARGO_MANIFEST_DIR")
    );
    let DatasetKind::Relaxation(d) = Dataset::load(path).unwrap().kind else {
        panic!("expected relaxation");
    };
    assert!((d.specimen.length_m - 0.1).abs() < 1e-12);
    let problem = Relaxation {
        eps0: d.specimen.strain,
        t: d.runs[0].time_s.clone(),
        f: d.runs[0].tension_n.clone(),
    };
    // catalog dyneema2 (robots/ropes.toml, paper Table VI)
    let truth = [
        ("k1", 7.29e4),
        ("k3", 9.02e5),
        ("c2", 1.65e7),
        ("c3", 1.57e6),
    ];
    // start well away from it
    let start = [1.4, 0.6, 1.8, 0.5];
    let specs: Vec<ParamSpec> = truth
        .iter()
        .zip(start)
        .map(|(&(name, v), s)| {
            ParamSpec::positive(
                name,
                if name.starts_with('k') { "N" } else { "N*s" },
                v * s,
                v / 100.0,
                v * 100.0,
            )
        })
        .collect();
    let r = fit(&problem, &specs, &FitOptions::default()).unwrap();
    assert!(r.converged, "{}", r.termination);
    for (i, &(name, v)) in truth.iter().enumerate() {
        let rel = r.values[i] / v - 1.0;
        let z = (r.values[i] - v) / r.std_errors[i];
        println!(
            "{name} = {:.5e} +- {:.2e} (catalog {v:.3e}, {:+.3}%, {z:+.2} std errors)",
            r.values[i],
            r.std_errors[i],
            100.0 * rel
        );
        assert!(r.std_errors[i].is_finite() && r.std_errors[i] > 0.0);
        assert!(r.std_errors[i] < 0.05 * v);
        // k1, k3, c2 within 5%. c3 (set by the fast decay, time constant ~1.6 s, 16
        // samples) comes out 6% low on these data, 2.6 std errors: still a better fit
        // than the catalog values (checked below), so the data, not the fitter, put it
        // there; allow 10% and 3 std errors for it.
        let tol = if name == "c3" { 0.10 } else { 0.05 };
        assert!(rel.abs() < tol, "{name}: {} vs {v}", r.values[i]);
        assert!(z.abs() < 3.0, "{name}: {z} std errors off");
    }
    // eq. 7 RMS at the noise level. Noise estimated independently from the late part
    // (t > 100 s, where the tension changes by < 0.03 N per sample): std of successive
    // differences / sqrt 2.
    let late: Vec<f64> = problem.f[1000..].to_vec();
    let diffs: Vec<f64> = late.windows(2).map(|w| w[1] - w[0]).collect();
    let md = diffs.iter().sum::<f64>() / diffs.len() as f64;
    let noise =
        (diffs.iter().map(|d| (d - md).powi(2)).sum::<f64>() / diffs.len() as f64 / 2.0).sqrt();
    let rms = r.rms();
    println!(
        "RMS (eq. 7) = {rms:.4} N, noise estimate {noise:.4} N, iterations = {}, evaluations = {}",
        r.iterations, r.evaluations
    );
    assert!((rms / noise - 1.0).abs() < 0.05, "{rms} vs {noise}");
    // the catalog values fit these data no better than the optimum found
    let mut out = Vec::new();
    problem.residuals(&truth.map(|t| t.1), &mut out).unwrap();
    let catalog_rms = (out.iter().map(|e| e * e).sum::<f64>() / out.len() as f64).sqrt();
    println!("RMS at the catalog values = {catalog_rms:.4} N");
    assert!(rms <= catalog_rms, "{rms} vs {catalog_rms}");
    // started at the catalog values, the fit ends at the same optimum
    let specs2: Vec<ParamSpec> = specs
        .iter()
        .zip(truth)
        .map(|(s, t)| ParamSpec {
            initial: t.1,
            ..s.clone()
        })
        .collect();
    let r2 = fit(&problem, &specs2, &FitOptions::default()).unwrap();
    println!(
        "from catalog: {} after {} iterations, rms {}",
        r2.termination,
        r2.iterations,
        r2.rms()
    );
    for i in 0..4 {
        assert!(
            (r2.values[i] - r.values[i]).abs() < 0.01 * r.std_errors[i],
            "{:?} vs {:?}",
            r2.values,
            r.values
        );
    }
}

#[test]
fn nan_residuals_name_the_parameters() {
    struct Bad;
    impl Residuals for Bad {
        fn residuals(&self, p: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
            out.clear();
            out.extend([p[0] - 1.0, p[1], if p[0] > 0.5 { f64::NAN } else { 0.0 }]);
            Ok(())
        }
    }
    let specs = [
        ParamSpec::new("k1", "N", 0.9),
        ParamSpec::new("c2", "N*s", 2.0),
    ];
    let e = fit(&Bad, &specs, &FitOptions::default()).unwrap_err();
    assert!(matches!(e, FitError::NonFinite { index: 2, .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains("k1 = 9e-1 N") && msg.contains("c2 = 2e0 N*s"),
        "{msg}"
    );
}

#[test]
fn model_errors_and_bad_specs() {
    struct Fails;
    impl Residuals for Fails {
        fn residuals(&self, _: &[f64], _: &mut Vec<f64>) -> Result<(), ResidualError> {
            Err("rope went slack beyond recovery".into())
        }
    }
    let e = fit(
        &Fails,
        &[ParamSpec::new("k", "N", 1.0)],
        &FitOptions::default(),
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("rope went slack") && e.to_string().contains("k = 1e0 N"),
        "{e}"
    );

    let problem = Decay::new(2.0, 1.5, 0.01, 1);
    let outside = [ParamSpec::positive("a", "", 5.0, 0.0, 3.0)];
    assert!(matches!(
        fit(&problem, &outside, &FitOptions::default()),
        Err(FitError::InvalidSpec { .. })
    ));
    let negative_log = [ParamSpec::positive("a", "", -1.0, 0.0, 3.0)];
    assert!(matches!(
        fit(&problem, &negative_log, &FitOptions::default()),
        Err(FitError::InvalidSpec { .. })
    ));
    assert!(matches!(
        fit(&problem, &[], &FitOptions::default()),
        Err(FitError::NoParameters)
    ));

    struct Short;
    impl Residuals for Short {
        fn residuals(&self, p: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
            out.clear();
            out.push(p[0]);
            Ok(())
        }
    }
    assert!(matches!(
        fit(
            &Short,
            &[ParamSpec::new("x", "", 1.0)],
            &FitOptions::default()
        ),
        Err(FitError::TooFewResiduals { n: 1, p: 1 })
    ));
}

#[test]
fn result_does_not_depend_on_thread_count() {
    let problem = Decay::new(2.0, 1.5, 0.01, 9);
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| fit(&problem, &decay_specs(), &FitOptions::default()).unwrap())
    };
    let one = run(1);
    let four = run(4);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&one.values), bits(&four.values));
    assert_eq!(bits(&one.std_errors), bits(&four.std_errors));
    assert_eq!(one.ssr.to_bits(), four.ssr.to_bits());
    assert_eq!(one.iterations, four.iterations);
}

/// A model that cannot be evaluated past x = 2 (a solver that does not converge there)
/// while its residuals keep falling towards x = 2.5: the trial points past 2 are
/// rejected steps, not the end of the fit, and the fit stops at the edge of the region
/// where the model works (its Jacobian taken backward there).
#[test]
fn failed_trial_points_are_rejected_steps() {
    struct Edge;
    impl Residuals for Edge {
        fn residuals(&self, p: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
            if p[0] > 2.0 {
                return Err(format!("solver did not converge at x = {}", p[0]).into());
            }
            out.clear();
            out.extend([p[0] - 2.5, 0.5 * (p[0] - 2.5), 0.1]);
            Ok(())
        }
    }
    let r = fit(
        &Edge,
        &[ParamSpec::new("x", "m", 0.5)],
        &FitOptions::default(),
    )
    .unwrap();
    assert!(
        r.values[0] <= 2.0 && r.values[0] > 1.999,
        "x = {} ({})",
        r.values[0],
        r.termination
    );
    assert!(r.termination.contains("rejected"), "{}", r.termination);
    assert!(r.std_errors[0].is_finite(), "{:?}", r.std_errors);
    // At the start a failure is still an error.
    let e = fit(
        &Edge,
        &[ParamSpec::new("x", "m", 2.2)],
        &FitOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("did not converge"), "{e}");
}

/// A residual problem that counts its evaluations.
struct Counted<'a> {
    inner: &'a Decay,
    calls: std::sync::atomic::AtomicUsize,
}

impl Residuals for Counted<'_> {
    fn residuals(&self, p: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        self.calls
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.inner.residuals(p, out)
    }
}

/// The evaluation budget of a dear fit counts the Jacobians' evaluations: the optimiser
/// stops at an accepted point below it (better than the start, not converged), and
/// without the budget the same problem converges.
#[test]
fn evaluation_budget_counts_jacobians_and_stops_at_an_accepted_point() {
    let decay = Decay::new(2.0, 1.5, 0.01, 7);
    let specs = decay_specs();
    let start_ssr = {
        let mut r = Vec::new();
        decay.residuals(&[0.7, 0.4], &mut r).unwrap();
        r.iter().map(|v| v * v).sum::<f64>()
    };
    let p = specs.len();
    let budget = 2 * (p + 1) + 2;
    let counted = Counted {
        inner: &decay,
        calls: 0.into(),
    };
    let opts = FitOptions {
        max_evaluations: budget,
        probation_jacobians: None,
        ..FitOptions::default()
    };
    let r = fit(&counted, &specs, &opts).unwrap();
    // the optimiser's own evaluations (the uncertainties' Jacobian at the end adds p + 1
    // and is not part of the budget)
    let optimiser = r.evaluations - (p + 1);
    assert!(optimiser <= budget, "{optimiser} > {budget}");
    assert!(!r.converged, "{}", r.termination);
    assert!(r.ssr < start_ssr, "{} vs start {start_ssr}", r.ssr);
    let free = fit(&decay, &specs, &FitOptions::default()).unwrap();
    assert!(free.converged && free.evaluations > optimiser + p + 1);
    assert!(free.ssr < r.ssr);
}

/// The rises of a table that never falls (`y = 1 + r1 min(x, 1) + r2 max(x - 1, 0)`),
/// one started 200 times below its true value: on `[0, inf)` (the one-sided map, as a
/// sweep's refinement fits them, `analysis::fit::fit_specs`) the fit converges in a
/// few Jacobians; between 0 and a bound far above (`[0, 100]`, a stiffness factor's
/// largest value) the logistic map's tail moves the small rise by factors, a trust
/// region at a time, and the same fit takes several times the evaluations.
#[test]
fn a_rise_far_below_its_bound_converges_on_the_one_sided_map() {
    struct Rises(Vec<f64>, Vec<f64>);
    impl Residuals for Rises {
        fn residuals(&self, p: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
            out.clear();
            out.extend(
                self.0
                    .iter()
                    .zip(&self.1)
                    .map(|(x, y)| 1.0 + p[0] * x.min(1.0) + p[1] * (x - 1.0).max(0.0) - y),
            );
            Ok(())
        }
    }
    let x: Vec<f64> = (0..41).map(|i| 0.05 * i as f64).collect();
    let (r1, r2) = (0.5, 0.02);
    let y: Vec<f64> = x
        .iter()
        .map(|x| 1.0 + r1 * x.min(1.0) + r2 * (x - 1.0).max(0.0))
        .collect();
    let problem = Rises(x, y);
    let specs = |upper: f64| {
        vec![
            ParamSpec::new("r1", "1", 0.3).with_bounds(0.0, upper),
            ParamSpec::new("r2", "1", 1e-4).with_bounds(0.0, upper),
        ]
    };
    let opts = FitOptions::default();
    let one_sided = fit(&problem, &specs(f64::INFINITY), &opts).unwrap();
    let logistic = fit(&problem, &specs(100.0), &opts).unwrap();
    println!(
        "one-sided: {} evaluations {:?}; logistic: {} evaluations {:?}",
        one_sided.evaluations, one_sided.values, logistic.evaluations, logistic.values
    );
    assert!(one_sided.converged, "{}", one_sided.termination);
    assert!((one_sided.values[0] - r1).abs() < 1e-6 && (one_sided.values[1] - r2).abs() < 1e-6);
    assert!(
        logistic.evaluations >= 2 * one_sided.evaluations,
        "one-sided {} evaluations, logistic {}",
        one_sided.evaluations,
        logistic.evaluations
    );
}
