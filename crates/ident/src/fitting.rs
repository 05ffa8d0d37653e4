//! Bounded nonlinear least squares with parameter uncertainties.
//!
//! [`fit`] minimises `SSR = sum_i r_i(x)^2` over the parameters `x` of a [`Residuals`]
//! problem with the Levenberg-Marquardt method (crate `levenberg-marquardt`, a MINPACK
//! port) and a forward-difference Jacobian.
//!
//! # Bounds by transformation
//!
//! The optimiser works on unbounded internal variables `u`; each parameter maps to
//! `y` (`y = ln x` if [`ParamSpec::log_scale`], else `y = x`) by
//!
//! * both bounds finite: `y = lo + (hi - lo) (1 + tanh(u - 1)) / 2` (a logistic map),
//! * lower bound only:   `y = lo + d0 (sqrt(u^2 + 1) - 1)`, with `d0 = y0 - lo`
//!   (MINUIT's one-sided map, scaled so the start is at `u = sqrt 3`),
//! * upper bound only:   `y = hi - d0 (sqrt(u^2 + 1) - 1)`, with `d0 = hi - y0`,
//! * no bounds:          `y = y0 + s (u - 1)`, with `s = |y0|` (or 1 if `y0 = 0`),
//!
//! where `lo`, `hi` are the bounds in `y` (a log-scale parameter with lower bound 0
//! has `lo = -inf`). Every internal variable is thus of order 1, and the
//! forward-difference step is `h = diff_step * max(|u|, 1)`. The offsets keep the
//! start away from `u = 0`: MINPACK's first trust region is `100 ||D u||` (D: Jacobian
//! column norms), which collapses to an unscaled `100` at `u = 0` and then gives
//! microscopic first steps that pass the `ftol` test (a premature "convergence", seen
//! on the paper's relaxation fit started at the centre of its log bounds).
//!
//! # Points where the model fails
//!
//! A model may fail to evaluate (a solver that does not converge, a blow-up) at a
//! point the optimiser tries. At the starting values that is an error. At a trial
//! point of the optimiser it is a rejected step: the residuals returned are the last
//! evaluated ones times 1000, which MINPACK counts as a step that made the fit worse
//! (norm at least 10x the current one), so it shrinks its trust region and tries
//! closer. In a forward-difference Jacobian (and in the uncertainties' one) a column
//! whose forward point fails is taken backward. The rejected trials are counted in
//! [`FitResult::termination`]. Before, one failed trial ended the whole fit with an
//! error, e.g. the relay-pulley solve of `relay_friction` at one point near the
//! optimum (a candidate of `diagnose` then had no score at all).
//!
//! # Uncertainties
//!
//! At the optimum the Jacobian `J = d r / d x` is computed again, in the parameters
//! themselves (forward differences with step `diff_step * |x_j|`, backward at an upper
//! bound), and
//!
//! `Cov = sigma^2 (J^T J)^-1`, `sigma^2 = SSR / (n - p)`,
//!
//! giving `std_errors_j = sqrt(Cov_jj)` and correlations `Cov_jk / (s_j s_k)`. This is
//! the usual local (linearised, unconstrained) estimate: it assumes independent
//! residuals of equal variance and means little for a parameter stuck at a bound.
//!
//! # Determinism
//!
//! The `p + 1` residual vectors of a Jacobian are evaluated in parallel with rayon, each
//! into its own buffer, and combined in a fixed order: the result does not depend on the
//! number of threads.

use std::cell::{Cell, RefCell};

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt, TerminationReason};
use nalgebra034 as na;
use rayon::prelude::*;

/// Why a [`Residuals`] problem cannot be evaluated at some parameters: any error type
/// that can cross threads (the analysis' problems return an
/// [`IdentError`](crate::IdentError)). [`fit`] reports its message, with the parameter
/// values, as [`FitError::Model`].
pub type ResidualError = Box<dyn std::error::Error + Send + Sync>;

/// A least-squares problem: residuals `r(x)` for parameters `x`.
///
/// `Sync` because the fitter evaluates several parameter vectors at once on different
/// threads; an implementation must give the same residuals for the same parameters
/// whatever the thread.
pub trait Residuals: Sync {
    /// Writes the residuals (model - measurement, possibly weighted) for `params` (in the
    /// order of the [`ParamSpec`]s) into `out`, replacing its content. Must produce the
    /// same number of residuals for every call. Return `Err` if the model cannot be
    /// evaluated for these parameters.
    fn residuals(&self, params: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError>;
}

/// One parameter to fit.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamSpec {
    /// Name (for messages and results).
    pub name: String,
    /// Unit (for messages), e.g. `N`, `N*s`.
    pub unit: String,
    /// Starting value; must lie strictly inside finite bounds.
    pub initial: f64,
    /// Lower bound (`f64::NEG_INFINITY` for none).
    pub lower: f64,
    /// Upper bound (`f64::INFINITY` for none).
    pub upper: f64,
    /// Work on `ln x` (for positive scale parameters spanning decades); needs
    /// `lower >= 0` and `initial > 0`.
    pub log_scale: bool,
}

impl ParamSpec {
    /// An unbounded, linear-scale parameter.
    pub fn new(name: &str, unit: &str, initial: f64) -> Self {
        ParamSpec {
            name: name.to_string(),
            unit: unit.to_string(),
            initial,
            lower: f64::NEG_INFINITY,
            upper: f64::INFINITY,
            log_scale: false,
        }
    }

    /// A positive parameter fitted on a log scale, bounded to `[lower, upper]` (use
    /// `0.0` / `f64::INFINITY` for no bound).
    pub fn positive(name: &str, unit: &str, initial: f64, lower: f64, upper: f64) -> Self {
        ParamSpec {
            lower,
            upper,
            log_scale: true,
            ..ParamSpec::new(name, unit, initial)
        }
    }

    /// Sets the bounds.
    pub fn with_bounds(mut self, lower: f64, upper: f64) -> Self {
        self.lower = lower;
        self.upper = upper;
        self
    }
}

/// Options of [`fit`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// Relative tolerance on the SSR reduction and on the parameter step (MINPACK
    /// `ftol` = `xtol`).
    pub tolerance: f64,
    /// Tolerance on the cosine between residual vector and Jacobian columns (`gtol`).
    pub gtol: f64,
    /// The fit stops after `patience * (p + 1)` residual evaluations of the optimiser
    /// (result then has `converged = false`).
    pub patience: usize,
    /// Relative forward-difference step. The default `sqrt(eps) ~ 1.5e-8` suits smooth
    /// closed forms; raise it (1e-6..1e-4) for residuals from a simulation whose error
    /// control makes them noisy at small scales.
    pub diff_step: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            tolerance: 1e-10,
            gtol: 1e-10,
            patience: 200,
            diff_step: f64::EPSILON.sqrt(),
        }
    }
}

/// The outcome of [`fit`].
#[derive(Debug, Clone, PartialEq)]
pub struct FitResult {
    /// Parameter names, in the order of the specs.
    pub names: Vec<String>,
    /// Fitted values.
    pub values: Vec<f64>,
    /// Standard errors `sqrt(Cov_jj)` (`f64::INFINITY` if `J^T J` is singular: the
    /// parameter is not identifiable from these data).
    pub std_errors: Vec<f64>,
    /// Correlation matrix of the estimates (row-major, p x p; NaN if singular).
    pub correlation: Vec<Vec<f64>>,
    /// Sum of squared residuals at the optimum.
    pub ssr: f64,
    /// Number of residuals n.
    pub n_residuals: usize,
    /// Optimiser iterations (Jacobian evaluations).
    pub iterations: usize,
    /// Residual-vector evaluations in total (including Jacobians).
    pub evaluations: usize,
    /// True if the optimiser met a convergence criterion.
    pub converged: bool,
    /// Why the optimiser stopped (human-readable).
    pub termination: String,
}

impl FitResult {
    /// RMS of the residuals at the optimum, `sqrt(SSR / n)` (eq. 7 of the paper for
    /// tension residuals).
    pub fn rms(&self) -> f64 {
        (self.ssr / self.n_residuals as f64).sqrt()
    }

    /// `(value, std_error)` of the parameter called `name`.
    pub fn get(&self, name: &str) -> Option<(f64, f64)> {
        let i = self.names.iter().position(|n| n == name)?;
        Some((self.values[i], self.std_errors[i]))
    }
}

/// Why a fit failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// A parameter spec is unusable.
    #[error("parameter `{name}`: {problem}; fix the parameter spec")]
    InvalidSpec {
        /// Parameter name.
        name: String,
        /// What is wrong.
        problem: String,
    },
    /// No parameters were given.
    #[error("no parameters to fit; pass at least one ParamSpec")]
    NoParameters,
    /// Fewer residuals than parameters + 1.
    #[error("{n} residuals for {p} parameters: at least p + 1 residuals are needed to fit and estimate uncertainties; use more data or fewer parameters")]
    TooFewResiduals {
        /// Residuals.
        n: usize,
        /// Parameters.
        p: usize,
    },
    /// The model returned an error.
    #[error("the model failed at {params}: {message}")]
    Model {
        /// The model's message.
        message: String,
        /// The parameter values, formatted `name = value unit, ...`.
        params: String,
    },
    /// A residual is NaN or infinite.
    #[error("residual {index} is {value} (not finite) at {params}; the model blew up for these parameters -- tighten the bounds or check the model")]
    NonFinite {
        /// Index of the first bad residual.
        index: usize,
        /// Its value.
        value: f64,
        /// The parameter values.
        params: String,
    },
    /// The number of residuals changed between calls.
    #[error("the model returned {got} residuals at {params}, but {expected} before; the residual count must not depend on the parameters")]
    ResidualCount {
        /// Count of the first evaluation.
        expected: usize,
        /// Count now.
        got: usize,
        /// The parameter values.
        params: String,
    },
    /// The optimiser stopped on a numerical problem.
    #[error("the optimiser failed ({reason}) near {params}; check the model for discontinuities or rescale the parameters")]
    Numerical {
        /// The optimiser's reason.
        reason: String,
        /// The last parameter values.
        params: String,
    },
}

/// Maps internal variable `u` to a parameter and back (see the module docs).
#[derive(Debug, Clone, Copy)]
enum Map {
    Free { y0: f64, s: f64 },
    Lower { lo: f64, d0: f64 },
    Upper { hi: f64, d0: f64 },
    Both { lo: f64, hi: f64 },
}

#[derive(Debug, Clone, Copy)]
struct Transform {
    map: Map,
    log: bool,
}

impl Transform {
    fn new(p: &ParamSpec) -> Result<(Transform, f64), FitError> {
        let bad = |problem: String| FitError::InvalidSpec {
            name: p.name.clone(),
            problem,
        };
        if !p.initial.is_finite() {
            return Err(bad(format!("initial value {} is not finite", p.initial)));
        }
        if p.lower.is_nan() || p.upper.is_nan() || p.lower >= p.upper {
            return Err(bad(format!(
                "bounds [{}, {}] are empty or NaN (need lower < upper)",
                p.lower, p.upper
            )));
        }
        if !(p.initial > p.lower && p.initial < p.upper) {
            return Err(bad(format!(
                "initial value {} is not strictly inside the bounds ({}, {})",
                p.initial, p.lower, p.upper
            )));
        }
        let (y0, lo, hi) = if p.log_scale {
            if p.lower < 0.0 || p.initial <= 0.0 {
                return Err(bad(format!(
                    "log_scale needs lower >= 0 and initial > 0 (lower = {}, initial = {})",
                    p.lower, p.initial
                )));
            }
            let lo = if p.lower > 0.0 {
                p.lower.ln()
            } else {
                f64::NEG_INFINITY
            };
            (p.initial.ln(), lo, p.upper.ln())
        } else {
            (p.initial, p.lower, p.upper)
        };
        let (map, u0) = match (lo.is_finite(), hi.is_finite()) {
            (false, false) => {
                let s = if y0 != 0.0 { y0.abs() } else { 1.0 };
                (Map::Free { y0, s }, 1.0)
            }
            (true, false) => (Map::Lower { lo, d0: y0 - lo }, 3f64.sqrt()),
            (false, true) => (Map::Upper { hi, d0: hi - y0 }, 3f64.sqrt()),
            (true, true) => (
                Map::Both { lo, hi },
                1.0 + (2.0 * (y0 - lo) / (hi - lo) - 1.0).atanh(),
            ),
        };
        Ok((
            Transform {
                map,
                log: p.log_scale,
            },
            u0,
        ))
    }

    fn param_at(&self, u: f64) -> f64 {
        let y = match self.map {
            Map::Free { y0, s } => y0 + s * (u - 1.0),
            Map::Lower { lo, d0 } => lo + d0 * ((u * u + 1.0).sqrt() - 1.0),
            Map::Upper { hi, d0 } => hi - d0 * ((u * u + 1.0).sqrt() - 1.0),
            Map::Both { lo, hi } => lo + (hi - lo) * 0.5 * (1.0 + (u - 1.0).tanh()),
        };
        if self.log {
            y.exp()
        } else {
            y
        }
    }
}

fn format_params(specs: &[ParamSpec], x: &[f64]) -> String {
    specs
        .iter()
        .zip(x)
        .map(|(s, v)| {
            if s.unit.is_empty() {
                format!("{} = {v:e}", s.name)
            } else {
                format!("{} = {v:e} {}", s.name, s.unit)
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Evaluates the residuals at `x` and checks them.
fn evaluate(
    problem: &dyn Residuals,
    specs: &[ParamSpec],
    x: &[f64],
    expected: Option<usize>,
) -> Result<Vec<f64>, FitError> {
    let mut out = Vec::with_capacity(expected.unwrap_or(0));
    problem
        .residuals(x, &mut out)
        .map_err(|e| FitError::Model {
            message: e.to_string(),
            params: format_params(specs, x),
        })?;
    if let Some(n) = expected {
        if out.len() != n {
            return Err(FitError::ResidualCount {
                expected: n,
                got: out.len(),
                params: format_params(specs, x),
            });
        }
    }
    if let Some(index) = out.iter().position(|r| !r.is_finite()) {
        return Err(FitError::NonFinite {
            index,
            value: out[index],
            params: format_params(specs, x),
        });
    }
    Ok(out)
}

/// One-sided differences: the residuals at `x` and, for every column `j`, the slope
/// `(r(point(j, h_j)) - r(x)) / h_j` with `h_j = steps[j]`, all evaluated in parallel
/// and combined in a fixed order. A column whose point the model cannot evaluate is
/// taken the other way (`-h_j`); an error only when both fail (or `x` does). Returns
/// `(r(x), columns, evaluations beyond p + 1)`.
#[allow(clippy::type_complexity)]
fn differences(
    problem: &dyn Residuals,
    specs: &[ParamSpec],
    x: &[f64],
    point: &(dyn Fn(usize, f64) -> Vec<f64> + Sync),
    steps: &[f64],
    n: usize,
) -> Result<(Vec<f64>, Vec<Vec<f64>>, usize), FitError> {
    let p = steps.len();
    let points: Vec<Vec<f64>> = std::iter::once(x.to_vec())
        .chain((0..p).map(|j| point(j, steps[j])))
        .collect();
    let mut results: Vec<Result<Vec<f64>, FitError>> = points
        .par_iter()
        .map(|x| evaluate(problem, specs, x, Some(n)))
        .collect();
    let r0 = results.remove(0)?;
    let mut extra = 0;
    let mut cols = Vec::with_capacity(p);
    for (j, r) in results.into_iter().enumerate() {
        let (r, h) = match r {
            Ok(r) => (r, steps[j]),
            Err(e) => {
                extra += 1;
                match evaluate(problem, specs, &point(j, -steps[j]), Some(n)) {
                    Ok(r) => (r, -steps[j]),
                    Err(_) => return Err(e),
                }
            }
        };
        cols.push(r.iter().zip(&r0).map(|(a, b)| (a - b) / h).collect());
    }
    Ok((r0, cols, extra))
}

struct Problem<'a> {
    residuals: &'a dyn Residuals,
    specs: &'a [ParamSpec],
    transforms: Vec<Transform>,
    u: na::DVector<f64>,
    n: usize,
    diff_step: f64,
    error: RefCell<Option<FitError>>,
    jacobians: Cell<usize>,
    evaluations: Cell<usize>,
    /// Residuals of the last point that evaluated (see "Points where the model fails").
    last_good: RefCell<na::DVector<f64>>,
    /// Trial points where the model failed, and the first failure.
    rejected: Cell<usize>,
    first_rejection: RefCell<Option<FitError>>,
}

impl Problem<'_> {
    fn params_of(&self, u: &[f64]) -> Vec<f64> {
        self.transforms
            .iter()
            .zip(u)
            .map(|(t, &u)| t.param_at(u))
            .collect()
    }

    fn fail(&self, e: FitError) {
        let mut slot = self.error.borrow_mut();
        if slot.is_none() {
            *slot = Some(e);
        }
    }
}

impl LeastSquaresProblem<f64, na::Dyn, na::Dyn> for Problem<'_> {
    type ResidualStorage = na::storage::Owned<f64, na::Dyn>;
    type JacobianStorage = na::storage::Owned<f64, na::Dyn, na::Dyn>;
    type ParameterStorage = na::storage::Owned<f64, na::Dyn>;

    fn set_params(&mut self, u: &na::DVector<f64>) {
        self.u.copy_from(u);
    }

    fn params(&self) -> na::DVector<f64> {
        self.u.clone()
    }

    fn residuals(&self) -> Option<na::DVector<f64>> {
        self.evaluations.set(self.evaluations.get() + 1);
        let x = self.params_of(self.u.as_slice());
        match evaluate(self.residuals, self.specs, &x, Some(self.n)) {
            Ok(r) => {
                let r = na::DVector::from_vec(r);
                self.last_good.borrow_mut().copy_from(&r);
                Some(r)
            }
            Err(e) => {
                // A trial point: a step to reject (module docs).
                self.rejected.set(self.rejected.get() + 1);
                self.first_rejection.borrow_mut().get_or_insert(e);
                Some(&*self.last_good.borrow() * 1e3)
            }
        }
    }

    fn jacobian(&self) -> Option<na::DMatrix<f64>> {
        self.jacobians.set(self.jacobians.get() + 1);
        let p = self.u.len();
        self.evaluations.set(self.evaluations.get() + p + 1);
        let u0 = self.u.as_slice();
        let steps: Vec<f64> = u0
            .iter()
            .map(|u| self.diff_step * u.abs().max(1.0))
            .collect();
        let transforms = &self.transforms;
        let point = |j: usize, h: f64| -> Vec<f64> {
            transforms
                .iter()
                .enumerate()
                .map(|(k, t)| t.param_at(u0[k] + if k == j { h } else { 0.0 }))
                .collect()
        };
        match differences(
            self.residuals,
            self.specs,
            &self.params_of(u0),
            &point,
            &steps,
            self.n,
        ) {
            Ok((_, cols, extra)) => {
                self.evaluations.set(self.evaluations.get() + extra);
                Some(na::DMatrix::from_fn(self.n, p, |i, j| cols[j][i]))
            }
            Err(e) => {
                self.fail(e);
                None
            }
        }
    }
}

/// Fits the parameters `params` of `problem` by bounded Levenberg-Marquardt and
/// estimates their uncertainties (see the module documentation for the method).
///
/// Errors: invalid specs, fewer than `p + 1` residuals, a model error, non-finite
/// residuals (naming the parameter values), a numerical failure of the optimiser.
/// Running out of evaluations is not an error: the result has `converged = false`.
pub fn fit(
    problem: &dyn Residuals,
    params: &[ParamSpec],
    opts: &FitOptions,
) -> Result<FitResult, FitError> {
    if params.is_empty() {
        return Err(FitError::NoParameters);
    }
    if !(opts.diff_step > 0.0
        && opts.diff_step < 0.1
        && opts.tolerance >= 0.0
        && opts.gtol >= 0.0
        && opts.patience > 0)
    {
        return Err(FitError::InvalidSpec {
            name: "(options)".into(),
            problem: format!(
                "need 0 < diff_step < 0.1, tolerances >= 0 and patience > 0, got {opts:?}"
            ),
        });
    }
    let mut transforms = Vec::with_capacity(params.len());
    let mut u0 = Vec::with_capacity(params.len());
    for p in params {
        let (t, u) = Transform::new(p)?;
        transforms.push(t);
        u0.push(u);
    }
    let p = params.len();
    let x0: Vec<f64> = transforms
        .iter()
        .zip(&u0)
        .map(|(t, &u)| t.param_at(u))
        .collect();
    let r0 = evaluate(problem, params, &x0, None)?;
    let n = r0.len();
    if n <= p {
        return Err(FitError::TooFewResiduals { n, p });
    }
    let target = Problem {
        residuals: problem,
        specs: params,
        transforms,
        u: na::DVector::from_vec(u0),
        n,
        diff_step: opts.diff_step,
        error: RefCell::new(None),
        jacobians: Cell::new(0),
        evaluations: Cell::new(1),
        last_good: RefCell::new(na::DVector::from_vec(r0)),
        rejected: Cell::new(0),
        first_rejection: RefCell::new(None),
    };
    let lm = LevenbergMarquardt::new()
        .with_ftol(opts.tolerance)
        .with_xtol(opts.tolerance)
        .with_gtol(opts.gtol)
        .with_patience(opts.patience);
    let (target, report) = lm.minimize(target);
    if let Some(e) = target.error.borrow_mut().take() {
        return Err(e);
    }
    let x = target.params_of(target.u.as_slice());
    let converged = match &report.termination {
        TerminationReason::ResidualsZero
        | TerminationReason::Orthogonal
        | TerminationReason::Converged { .. }
        | TerminationReason::NoImprovementPossible(_) => true,
        TerminationReason::LostPatience => false,
        other => {
            return Err(FitError::Numerical {
                reason: format!("{other:?}"),
                params: format_params(params, &x),
            })
        }
    };
    let mut termination = format!("{:?}", report.termination);
    if let Some(e) = target.first_rejection.borrow().as_ref() {
        termination.push_str(&format!(
            "; {} trial point(s) rejected where the model failed, first: {e}",
            target.rejected.get()
        ));
    }
    let (ssr, std_errors, correlation, extra_evals) =
        uncertainties(problem, params, &x, n, opts.diff_step)?;
    Ok(FitResult {
        names: params.iter().map(|s| s.name.clone()).collect(),
        values: x,
        std_errors,
        correlation,
        ssr,
        n_residuals: n,
        iterations: target.jacobians.get(),
        evaluations: target.evaluations.get() + extra_evals,
        converged,
        termination,
    })
}

/// SSR, standard errors and correlation matrix at `x` (see the module docs).
fn uncertainties(
    problem: &dyn Residuals,
    specs: &[ParamSpec],
    x: &[f64],
    n: usize,
    diff_step: f64,
) -> Result<(f64, Vec<f64>, Vec<Vec<f64>>, usize), FitError> {
    let p = x.len();
    // scale of each parameter: differences are taken relative to it
    let scale: Vec<f64> = x
        .iter()
        .zip(specs)
        .map(|(&v, s)| {
            if v != 0.0 {
                v.abs()
            } else if s.initial != 0.0 {
                s.initial.abs()
            } else {
                1.0
            }
        })
        .collect();
    let steps: Vec<f64> = (0..p)
        .map(|j| {
            let h = diff_step * scale[j];
            if x[j] + h > specs[j].upper {
                -h
            } else {
                h
            }
        })
        .collect();
    let point = |j: usize, h: f64| {
        let mut v = x.to_vec();
        v[j] += h;
        v
    };
    let (r0, cols, extra) = differences(problem, specs, x, &point, &steps, n)?;
    let ssr: f64 = r0.iter().map(|v| v * v).sum();
    // Jacobian w.r.t. relative changes x_j (1 + d_j): J_s = J diag(scale)
    let js = na::DMatrix::from_fn(n, p, |i, j| cols[j][i] * scale[j]);
    let jtj = js.transpose() * &js;
    let sigma2 = ssr / (n - p) as f64;
    let inv = na::Cholesky::new(jtj).map(|c| c.inverse());
    let (std_errors, correlation) = match inv {
        Some(inv) if inv.iter().all(|v| v.is_finite()) => {
            let se: Vec<f64> = (0..p)
                .map(|j| (sigma2 * inv[(j, j)]).sqrt() * scale[j])
                .collect();
            let corr = (0..p)
                .map(|i| {
                    (0..p)
                        .map(|k| inv[(i, k)] / (inv[(i, i)] * inv[(k, k)]).sqrt())
                        .collect()
                })
                .collect();
            (se, corr)
        }
        _ => (vec![f64::INFINITY; p], vec![vec![f64::NAN; p]; p]),
    };
    Ok((ssr, std_errors, correlation, p + 1 + extra))
}
