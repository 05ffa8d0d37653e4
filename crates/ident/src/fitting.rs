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
//! # Uncertainties and 95% intervals
//!
//! At the optimum the Jacobian `J = d r / d x` is computed again, in the parameters
//! themselves (forward differences with step `diff_step * |x_j|`, backward at an upper
//! bound). With `A = J^T J`, the covariance of the estimates is
//!
//! * **independent errors** (the default): `Cov = sigma^2 A^-1`,
//!   `sigma^2 = SSR / (n - p)`, the usual local (linearised) estimate for independent
//!   residuals of equal variance; the interval uses Student's t with `n - p` degrees of
//!   freedom;
//! * **grouped errors** ([`Residuals::error_groups`]: the residuals fall into `G`
//!   groups whose errors may be correlated within a group, not between groups): the
//!   delete-one-group jackknife, linearised. Leaving group `g` out moves the estimate by
//!   `d_g = (A - A_g)^-1 s_g` (one Gauss-Newton step; `A_g = J_g^T J_g`, score
//!   `s_g = J_g^T r_g`), and `Cov = (G - 1)/G sum_g (d_g - d_mean)(d_g - d_mean)^T`;
//!   the interval uses t with `G - 1` degrees of freedom. This is the cluster-robust
//!   sandwich with the jackknife's leverage correction (CR3), which stays honest when a
//!   few groups carry most of the information about a parameter (a sweep's frequency
//!   steps near the resonance) and whatever the errors' structure inside a group (an
//!   encoder's quantisation error is coherent over a frequency step and, in runs that
//!   see the same signal, the same in every run). It needs `G >= p + 2`; with fewer
//!   groups the independent-error estimate is used (and [`FitResult::interval_method`]
//!   says so). A group whose removal leaves a parameter undetermined makes its error
//!   infinite.
//!
//! `std_errors` and `correlation` come from that covariance. The 95% interval
//! ([`FitResult::interval_95`]) of parameter `j` is `centre_j -/+ t se_j`, where
//! `centre = x + shift` ([`FitResult::interval_shift`]) estimates the exact model's
//! optimum:
//!
//! * the Gauss-Newton step `-A^-1 J^T r` (the distance to the optimum the optimiser
//!   stopped short of: ~0 for a converged fit; beyond the bound for a parameter held at
//!   its bound);
//! * for a model whose evaluation has a step ([`Residuals::refined_residuals`]: a
//!   simulation), the shift of the optimum to the exact model's, by Richardson
//!   extrapolation of a second-order method: the residuals' own error is
//!   `e = 4/3 (r(h) - r(h/2))` and the optimum moves by `A^-1 J^T e`. For sweeps at
//!   2.5 ms this is ~30 standard errors of `k1_scale` (the trapezoidal rule's period
//!   error, `(w h)^2 / 12` at the resonance), far larger than the noise's share; for
//!   an arm at its chosen 0.25 ms, ~5 standard errors of a joint friction's viscous
//!   coefficient.
//!
//! The interval is thus one for the parameter of the system the data come from, and it
//! may exclude the fitted value (which is the optimum of the model as evaluated, the
//! one `compare` reproduces) when the shift exceeds `t se`: a sweep's `k1_scale`. An
//! interval widened to include the fitted value as well would hold the truth far more
//! often than 95% on one side.
//!
//! A log-scale parameter's interval is symmetric in `ln x` (standard error of `ln x`:
//! `se / x`) and centred at `ln x + shift / x` (the shift, like the standard error, is
//! for a relative change of `x`). An interval that reaches past a bound is clipped there, flagged
//! ([`Clipped`]) and made to reach the fitted value (a parameter held at its bound whose
//! optimum lies beyond it gets the interval from the bound to the fitted value at
//! least). A parameter the data do not determine (its column of `J` zero, or explained
//! by the others' to `1 - R^2 < 1e-10`: pivoted Cholesky of `A` scaled to unit
//! diagonal) gets an infinite standard error and its bounds; the others are estimated
//! without it, and [`FitResult::interval_method`] names it. The columns of `J` are
//! scaled to unit norm for all of this (sensitivities span decades).
//!
//! # Several starts
//!
//! A caller that fits one problem from several starts (the analysis' multi-start on a
//! grid) passes the optima already found to [`fit_joining`]: a start whose accepted
//! point comes within [`JOIN_RADIUS`] (relative) or [`JOIN_STD_ERRORS`] standard errors
//! of one of them in every parameter, at an SSR not
//! below it by more than the fit's relative `tolerance`, has joined that basin and stops
//! there (no result): finishing would reach the same optimum within the fit's own
//! tolerances. Each basin is then paid for once. The standard errors of that test are
//! the intervals' own, or, for a problem that asks for it
//! ([`Residuals::joins_on_independent_errors`]: an arm's, whose grouped errors are
//! several times the independent ones), the independent-error ones.
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

    /// The group of every residual (one id per residual, in order; ids need not be
    /// contiguous) when errors may be correlated within a group but not between groups,
    /// e.g. a sweep's frequency steps. `None` (the default): independent errors of equal
    /// variance. Selects the uncertainty estimate (module docs).
    fn error_groups(&self) -> Option<Vec<usize>> {
        None
    }

    /// Whether a start joins a known optimum ([`fit_joining`]) within
    /// [`JOIN_STD_ERRORS`] of that optimum's independent-error standard errors rather
    /// than of the grouped ones its intervals use (default false: the same standard
    /// errors). An arm's grouped standard errors are several times the independent ones,
    /// and starts that joined within a tenth of them stopped in basins they would have
    /// left (the arm confusion study's `extra_retardation` fell from 4/4 to 3/4).
    fn joins_on_independent_errors(&self) -> bool {
        false
    }

    /// For a model evaluated with a step (a simulation), second-order accurate in it:
    /// writes the residuals at `params` evaluated with half the step into `out` and
    /// returns `Ok(true)`. The default, `Ok(false)`, says the evaluation is exact. Used
    /// once, at the optimum, to correct the 95% intervals for the step's error (module
    /// docs).
    fn refined_residuals(
        &self,
        _params: &[f64],
        _out: &mut Vec<f64>,
    ) -> Result<bool, ResidualError> {
        Ok(false)
    }

    /// The residuals at `params`, which differ from `base` in parameter `j` alone (a
    /// forward difference), when the problem can take some of them from
    /// `base_residuals`, its residuals at `base`: a block that parameter cannot change
    /// there (a run whose simulation never reaches the stretch of a table that value
    /// moves) need not be evaluated again. Writes every residual, [`Self::residuals`]'s
    /// at `params` to the bit, into `out` and returns `Ok(true)`; `Ok(false)` (the
    /// default): the caller evaluates [`Self::residuals`].
    fn residuals_beside(
        &self,
        _base: &[f64],
        _base_residuals: &[f64],
        _j: usize,
        _params: &[f64],
        _out: &mut Vec<f64>,
    ) -> Result<bool, ResidualError> {
        Ok(false)
    }
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
    /// Most residual-vector evaluations of the optimiser, its Jacobians' included (each
    /// costs `p + 1`): the budget of a fit whose every evaluation is a dear simulation.
    /// The optimiser stops at its last accepted point before a Jacobian would exceed it
    /// (result then has `converged = false`). `usize::MAX`: no budget but `patience`.
    pub max_evaluations: usize,
    /// A later start's probation ([`fit_joining`] with optima already found): after this
    /// many Jacobians, a fit whose SSR is not below every optimum found stops, as one
    /// that joined a basin does. `None`: every start runs to its end.
    pub probation_jacobians: Option<usize>,
    /// Whether the result carries standard errors and intervals (one more Jacobian at
    /// the optimum). `false`: a search whose values are only a screen (NaN standard
    /// errors and intervals, `interval_method` "none").
    pub intervals: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            tolerance: 1e-10,
            gtol: 1e-10,
            patience: 200,
            diff_step: f64::EPSILON.sqrt(),
            max_evaluations: usize::MAX,
            probation_jacobians: None,
            intervals: true,
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
    /// The standard errors a later start's joining test uses ([`fit_joining`]):
    /// `std_errors`, or the independent-error ones where the problem says so
    /// ([`Residuals::joins_on_independent_errors`]).
    pub join_std_errors: Vec<f64>,
    /// Correlation matrix of the estimates (row-major, p x p; NaN if singular).
    pub correlation: Vec<Vec<f64>>,
    /// 95% interval `(lower, upper)` of every parameter (module docs: centred at
    /// `values + interval_shift`, symmetric in `ln x` for a log-scale parameter, clipped
    /// at the bounds).
    pub interval_95: Vec<(f64, f64)>,
    /// Whether each interval was clipped at a bound (the parameter is at or near it).
    pub interval_clipped: Vec<Clipped>,
    /// Where each interval is centred, relative to the fitted value: the estimated
    /// distance to the exact model's optimum (Gauss-Newton step plus the step-error
    /// correction, module docs).
    pub interval_shift: Vec<f64>,
    /// How the intervals were computed, e.g. `independent errors, t(68011) = 1.960`.
    pub interval_method: String,
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
    /// A fit made without intervals ([`FitOptions::intervals`] false): what
    /// [`add_intervals`] needs to give it the intervals it would have had.
    pub deferred: Option<Deferred>,
}

/// What a fit made without intervals keeps for [`add_intervals`]: its specs and the
/// relative step of its differences.
#[derive(Debug, Clone, PartialEq)]
pub struct Deferred {
    specs: Vec<ParamSpec>,
    diff_step: f64,
}

/// Gives a fit made without intervals ([`FitOptions::intervals`] false) the standard
/// errors and intervals that the fit with them would have had, bit for bit: the same
/// differences at the same optimum (`problem` the fit's own, or one that evaluates the
/// same residuals). Nothing to do for a fit that has them.
///
/// For a search whose fits are mostly thrown away (the shape refinement's tables of
/// every number of knots, of which one is kept), the Jacobian and the half-step
/// evaluation at every discarded optimum are saved.
pub fn add_intervals(problem: &dyn Residuals, result: &mut FitResult) -> Result<(), FitError> {
    let Some(Deferred { specs, diff_step }) = result.deferred.take() else {
        return Ok(());
    };
    let u = uncertainties(
        problem,
        &specs,
        &result.values,
        result.n_residuals,
        diff_step,
    )?;
    result.std_errors = u.std_errors;
    result.join_std_errors = u.join_std_errors;
    result.correlation = u.correlation;
    result.interval_95 = u.interval_95;
    result.interval_clipped = u.clipped;
    result.interval_shift = u.shift;
    result.interval_method = u.method;
    result.ssr = u.ssr;
    result.evaluations += u.evaluations;
    Ok(())
}

/// `v` moved strictly inside `[lower, upper]` (by a millionth of the span, or of `v`'s
/// size when a bound is infinite), as a fit's start must be.
pub fn strictly_inside(v: f64, lower: f64, upper: f64) -> f64 {
    let span = upper - lower;
    let eps = if span.is_finite() {
        1e-6 * span
    } else {
        1e-6 * v.abs().max(1e-3)
    };
    v.clamp(lower + eps, (upper - eps).max(lower + eps))
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

    /// The 95% interval of every parameter by name, `[lower, upper]`.
    pub fn intervals_by_name(&self) -> std::collections::BTreeMap<String, [f64; 2]> {
        self.names
            .iter()
            .zip(&self.interval_95)
            .map(|(n, &(lo, hi))| (n.clone(), [lo, hi]))
            .collect()
    }

    /// The parameters whose interval was clipped at a bound, by name: `"lower"`,
    /// `"upper"` or `"both"`.
    pub fn clipped_by_name(&self) -> std::collections::BTreeMap<String, String> {
        self.names
            .iter()
            .zip(&self.interval_clipped)
            .filter_map(|(n, c)| c.as_str().map(|s| (n.clone(), s.to_string())))
            .collect()
    }

    /// A short note on parameter `i`'s interval for tables: clipped at a bound, or
    /// centred away from the fitted value by more than half a standard error (module
    /// docs); empty otherwise.
    pub fn interval_note(&self, i: usize) -> String {
        let mut notes = Vec::new();
        if let Some(c) = self.interval_clipped.get(i).and_then(|c| c.as_str()) {
            notes.push(Clipped::note_for(c));
        }
        let (shift, se) = (self.interval_shift[i], self.std_errors[i]);
        if shift.abs() > 0.5 * se {
            let centre = self.values[i] + shift;
            let centre = if (1e-3..1e5).contains(&centre.abs()) {
                format!("{centre:.6}")
            } else {
                format!("{centre:.5e}")
            };
            notes.push(format!(
                "centred at {centre} (exact model, {:+.1} std errors)",
                shift / se
            ));
        }
        notes.join("; ")
    }
}

/// Whether a 95% interval reached past a parameter's bound and was clipped there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Clipped {
    /// Inside both bounds.
    #[default]
    No,
    /// Clipped at the lower bound.
    Lower,
    /// Clipped at the upper bound.
    Upper,
    /// Clipped at both (e.g. an infinite standard error).
    Both,
}

impl Clipped {
    /// What a table says of an interval clipped as `name` ([`Self::as_str`]).
    pub fn note_for(name: &str) -> String {
        match name {
            "both" => "not determined by these data: the interval is the bounds".into(),
            side => format!("clipped at the {side} bound"),
        }
    }

    /// `None`, `"lower"`, `"upper"` or `"both"` (for tables and JSON).
    pub fn as_str(self) -> Option<&'static str> {
        match self {
            Clipped::No => None,
            Clipped::Lower => Some("lower"),
            Clipped::Upper => Some("upper"),
            Clipped::Both => Some("both"),
        }
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
    /// [`Residuals::error_groups`] gave a group for a different number of residuals.
    #[error("the model gave error groups for {got} residuals but returns {expected}; give one group id per residual")]
    ErrorGroups {
        /// Residuals.
        expected: usize,
        /// Group ids.
        got: usize,
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
    evaluate_beside(problem, specs, x, expected, None)
}

/// [`evaluate`]; with `beside = Some((base, base_residuals, j))`, `x` differs from
/// `base` in parameter `j` alone and the problem may take the residuals it cannot
/// change from `base_residuals` ([`Residuals::residuals_beside`]).
fn evaluate_beside(
    problem: &dyn Residuals,
    specs: &[ParamSpec],
    x: &[f64],
    expected: Option<usize>,
    beside: Option<(&[f64], &[f64], usize)>,
) -> Result<Vec<f64>, FitError> {
    let mut out = Vec::with_capacity(expected.unwrap_or(0));
    let model_error = |e: ResidualError| FitError::Model {
        message: e.to_string(),
        params: format_params(specs, x),
    };
    let done = match beside {
        Some((base, r0, j)) => problem
            .residuals_beside(base, r0, j, x, &mut out)
            .map_err(model_error)?,
        None => false,
    };
    if !done {
        problem.residuals(x, &mut out).map_err(model_error)?;
    }
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
/// `(r(point(j, h_j)) - r(x)) / h_j` with `h_j = steps[j]`: `r(x)` first (usually
/// known: the point the optimiser accepted last), then the columns' points in parallel,
/// each taking from `r(x)` the residuals it cannot change when the problem knows them
/// ([`Residuals::residuals_beside`]; the same bits), combined in a fixed order. A
/// column whose point the model cannot evaluate is
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
    // (the centre first: the columns may take from it what they cannot change)
    let r0 = evaluate(problem, specs, x, Some(n))?;
    let results: Vec<Result<Vec<f64>, FitError>> = (0..p)
        .into_par_iter()
        .map(|j| {
            let xj = point(j, steps[j]);
            evaluate_beside(problem, specs, &xj, Some(n), Some((x, &r0, j)))
        })
        .collect();
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

/// Relative distance (in `ln x` for a log-scale parameter) within which a fit's
/// iterate has joined an optimum already found ([`fit_joining`]).
pub const JOIN_RADIUS: f64 = 0.01;

/// Distance in standard errors of the optimum within which a parameter has joined it
/// too (a parameter the data hardly determine, e.g. one going to zero on a log scale).
pub const JOIN_STD_ERRORS: f64 = 0.1;

/// True when `a` is within [`JOIN_RADIUS`] of `b` (relative, or in `ln x` for a
/// log-scale parameter), or within [`JOIN_STD_ERRORS`] of `b`'s standard error `se`.
fn near(s: &ParamSpec, a: f64, b: f64, se: f64) -> bool {
    if (a - b).abs() <= JOIN_STD_ERRORS * se {
        return true;
    }
    if s.log_scale && a > 0.0 && b > 0.0 {
        (a.ln() - b.ln()).abs() <= JOIN_RADIUS
    } else {
        (a - b).abs() <= JOIN_RADIUS * a.abs().max(b.abs())
    }
}

struct Problem<'a> {
    residuals: &'a dyn Residuals,
    tolerance: f64,
    specs: &'a [ParamSpec],
    transforms: Vec<Transform>,
    u: na::DVector<f64>,
    n: usize,
    diff_step: f64,
    error: RefCell<Option<FitError>>,
    jacobians: Cell<usize>,
    evaluations: Cell<usize>,
    /// [`FitOptions::max_evaluations`], and whether a Jacobian was refused by it.
    max_evaluations: usize,
    budget_spent: Cell<bool>,
    /// Optima of earlier fits of the same problem that this fit stops at when it comes
    /// near one ([`fit_joining`]), and whether it did.
    known: &'a [FitResult],
    joined: Cell<bool>,
    /// [`FitOptions::probation_jacobians`].
    probation_jacobians: Option<usize>,
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
        let p = self.u.len();
        if self.evaluations.get().saturating_add(p + 1) > self.max_evaluations {
            // the budget is spent: stop at this accepted point
            self.budget_spent.set(true);
            return None;
        }
        let u0 = self.u.as_slice();
        if !self.known.is_empty() {
            let x = self.params_of(u0);
            let joins = |ssr: f64| {
                self.known.iter().any(|k| {
                    ssr >= k.ssr * (1.0 - self.tolerance)
                        && (0..x.len())
                            .all(|j| near(&self.specs[j], x[j], k.values[j], k.join_std_errors[j]))
                })
            };
            // the point is the last one accepted, and the Jacobian's base point: its
            // residuals are at hand (cached by the analysis' problems), not counted again
            if let Ok(r) = evaluate(self.residuals, self.specs, &x, Some(self.n)) {
                let ssr: f64 = r.iter().map(|v| v * v).sum();
                // on probation: still above every optimum found after its Jacobians
                let lags = self.probation_jacobians.is_some_and(|k| {
                    self.jacobians.get() >= k && self.known.iter().all(|o| ssr > o.ssr)
                });
                if joins(ssr) || lags {
                    self.joined.set(true);
                    return None;
                }
            }
        }
        self.jacobians.set(self.jacobians.get() + 1);
        self.evaluations.set(self.evaluations.get() + p + 1);
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
    fit_joining(problem, params, opts, &[])?.ok_or_else(|| FitError::Numerical {
        reason: "joined an optimum though none was given".into(),
        params: format_params(params, &[]),
    })
}

/// [`fit`] of one start among several: `known` holds the results of the other starts'
/// fits of the same problem. At each point it accepts (before its Jacobian) the fit
/// stops and returns `Ok(None)` when the point is near a known optimum in every
/// parameter (within [`JOIN_RADIUS`], relative or in `ln x` for a log-scale one, or
/// within [`JOIN_STD_ERRORS`] of its standard error) and its SSR is not below that optimum's by more than
/// [`FitOptions::tolerance`] (relative): it has joined that optimum's basin, where it
/// would converge to the same values within the fit's own tolerances. A multi-start fit
/// thus pays for each basin once.
pub fn fit_joining(
    problem: &dyn Residuals,
    params: &[ParamSpec],
    opts: &FitOptions,
    known: &[FitResult],
) -> Result<Option<FitResult>, FitError> {
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
        tolerance: opts.tolerance,
        known,
        joined: Cell::new(false),
        probation_jacobians: opts.probation_jacobians,
        specs: params,
        transforms,
        u: na::DVector::from_vec(u0),
        n,
        diff_step: opts.diff_step,
        error: RefCell::new(None),
        jacobians: Cell::new(0),
        evaluations: Cell::new(1),
        max_evaluations: opts.max_evaluations,
        budget_spent: Cell::new(false),
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
    if target.joined.get() {
        return Ok(None);
    }
    let converged = match &report.termination {
        TerminationReason::ResidualsZero
        | TerminationReason::Orthogonal
        | TerminationReason::Converged { .. }
        | TerminationReason::NoImprovementPossible(_) => true,
        TerminationReason::LostPatience => false,
        TerminationReason::User("jacobian") if target.budget_spent.get() => false,
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
    let u = if opts.intervals {
        uncertainties(problem, params, &x, n, opts.diff_step)?
    } else {
        let r = evaluate(problem, params, &x, Some(n))?;
        let p = x.len();
        Uncertainties {
            ssr: r.iter().map(|v| v * v).sum(),
            std_errors: vec![f64::NAN; p],
            join_std_errors: vec![f64::NAN; p],
            correlation: Vec::new(),
            interval_95: vec![(f64::NAN, f64::NAN); p],
            clipped: vec![Clipped::No; p],
            shift: vec![0.0; p],
            method: "none".into(),
            evaluations: 0,
        }
    };
    Ok(Some(FitResult {
        names: params.iter().map(|s| s.name.clone()).collect(),
        values: x,
        std_errors: u.std_errors,
        join_std_errors: u.join_std_errors,
        correlation: u.correlation,
        interval_95: u.interval_95,
        interval_clipped: u.clipped,
        interval_shift: u.shift,
        interval_method: u.method,
        ssr: u.ssr,
        n_residuals: n,
        iterations: target.jacobians.get(),
        evaluations: target.evaluations.get() + u.evaluations,
        converged,
        termination,
        deferred: (!opts.intervals).then(|| Deferred {
            specs: params.to_vec(),
            diff_step: opts.diff_step,
        }),
    }))
}

/// What [`uncertainties`] finds at the optimum.
struct Uncertainties {
    ssr: f64,
    std_errors: Vec<f64>,
    join_std_errors: Vec<f64>,
    correlation: Vec<Vec<f64>>,
    interval_95: Vec<(f64, f64)>,
    clipped: Vec<Clipped>,
    shift: Vec<f64>,
    method: String,
    evaluations: usize,
}

/// The two-sided 95% quantile of Student's t with `df` degrees of freedom.
fn t_quantile_95(df: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    StudentsT::new(0.0, 1.0, df.max(1.0)).map_or(1.959_963_984_540_054, |t| t.inverse_cdf(0.975))
}

/// The parameters the data determine: pivoted Cholesky of `A = J^T J` scaled to unit
/// diagonal, taking the column with the largest remaining diagonal (`1 - R^2` of that
/// column on those taken) while it exceeds 1e-10; a zero column is never taken. In the
/// parameters' order.
fn identifiable(a: &na::DMatrix<f64>) -> Vec<usize> {
    let p = a.nrows();
    let d: Vec<f64> = (0..p).map(|j| a[(j, j)]).collect();
    let ok: Vec<bool> = d.iter().map(|v| v.is_finite() && *v > 0.0).collect();
    // correlation-scaled copy
    let mut m = na::DMatrix::from_fn(p, p, |i, j| {
        if ok[i] && ok[j] {
            a[(i, j)] / (d[i] * d[j]).sqrt()
        } else {
            0.0
        }
    });
    let mut taken = Vec::new();
    while let Some((j, rest)) = (0..p)
        .filter(|j| ok[*j] && !taken.contains(j))
        .map(|j| (j, m[(j, j)]))
        .max_by(|x, y| x.1.total_cmp(&y.1))
        .filter(|(_, rest)| *rest > 1e-10)
    {
        // eliminate column j from the remaining ones (Schur complement)
        let col: Vec<f64> = (0..p).map(|i| m[(i, j)]).collect();
        for r in 0..p {
            for c in 0..p {
                m[(r, c)] -= col[r] * col[c] / rest;
            }
        }
        taken.push(j);
    }
    taken.sort_unstable();
    taken
}

/// The linearised delete-one-group jackknife covariance (module docs) of the scaled
/// problem: `jac` n x p, residuals `r`, group of every residual. `None` with fewer than
/// `p + 2` groups; infinite where leaving a group out leaves the estimate undetermined.
fn jackknife_covariance(
    jac: &na::DMatrix<f64>,
    r: &[f64],
    groups: &[usize],
) -> Option<(na::DMatrix<f64>, usize)> {
    let p = jac.ncols();
    let mut ids: Vec<usize> = groups.to_vec();
    ids.sort_unstable();
    ids.dedup();
    let g = ids.len();
    if g < p + 2 {
        return None;
    }
    let mut a_g = vec![na::DMatrix::<f64>::zeros(p, p); g];
    let mut s_g = vec![na::DVector::<f64>::zeros(p); g];
    for (i, id) in groups.iter().enumerate() {
        let k = ids.binary_search(id).unwrap_or(0);
        let row = jac.row(i).transpose();
        a_g[k] += &row * row.transpose();
        s_g[k] += &row * r[i];
    }
    let a: na::DMatrix<f64> = a_g.iter().sum();
    let mut d = Vec::with_capacity(g);
    for (ak, sk) in a_g.iter().zip(&s_g) {
        match na::Cholesky::new(&a - ak) {
            Some(c) => d.push(c.solve(sk)),
            None => return Some((na::DMatrix::from_element(p, p, f64::INFINITY), g)),
        }
    }
    let mean: na::DVector<f64> = d.iter().sum::<na::DVector<f64>>() / g as f64;
    let mut cov = na::DMatrix::<f64>::zeros(p, p);
    for dk in &d {
        let c = dk - &mean;
        cov += &c * c.transpose();
    }
    Some((cov * ((g - 1) as f64 / g as f64), g))
}

/// SSR, covariance, standard errors, correlations and 95% intervals at `x` (see the
/// module docs).
fn uncertainties(
    problem: &dyn Residuals,
    specs: &[ParamSpec],
    x: &[f64],
    n: usize,
    diff_step: f64,
) -> Result<Uncertainties, FitError> {
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
    let mut evaluations = p + 1 + extra;
    let ssr: f64 = r0.iter().map(|v| v * v).sum();
    // Jacobian w.r.t. relative changes x_j (1 + d_j): J_s = J diag(scale)
    let js = na::DMatrix::from_fn(n, p, |i, j| cols[j][i] * scale[j]);
    // Parameters the data do not determine (a zero column, or one the others explain)
    // get an infinite error; the rest are estimated without them.
    let keep = identifiable(&(js.transpose() * &js));
    let dropped: Vec<&str> = (0..p)
        .filter(|j| !keep.contains(j))
        .map(|j| specs[j].name.as_str())
        .collect();
    let q = keep.len();
    // the kept columns, each scaled to unit norm (a plain change of units that keeps
    // J^T J well scaled when sensitivities span decades)
    let mut jk = js.select_columns(&keep);
    let norms: Vec<f64> = jk.column_iter().map(|c| c.norm()).collect();
    for (mut c, nrm) in jk.column_iter_mut().zip(&norms) {
        c /= *nrm;
    }
    let inv = na::Cholesky::new(jk.transpose() * &jk)
        .map(|c| c.inverse())
        .filter(|m| q > 0 && m.iter().all(|v| v.is_finite()));
    // The covariance of the relative changes of the kept parameters, and the degrees
    // of freedom of t.
    let groups = problem.error_groups();
    if let Some(g) = &groups {
        if g.len() != n {
            return Err(FitError::ErrorGroups {
                expected: n,
                got: g.len(),
            });
        }
    }
    let independent = |why: &str| {
        let df = (n - q.max(1)) as f64;
        (
            inv.as_ref().map(|m| m * (ssr / df)),
            df,
            format!(
                "independent errors{why}, t({}) = {:.3}",
                n - q.max(1),
                t_quantile_95(df)
            ),
        )
    };
    let (cov, df, mut method) = match (&groups, &inv) {
        (Some(g), Some(_)) => match jackknife_covariance(&jk, &r0, g) {
            Some((c, count)) => {
                let df = (count - 1) as f64;
                (
                    Some(c),
                    df,
                    format!(
                        "delete-one-group jackknife over {count} error groups, t({}) = {:.3}",
                        count - 1,
                        t_quantile_95(df)
                    ),
                )
            }
            None => independent(" (too few error groups for the jackknife)"),
        },
        _ => independent(""),
    };
    if !dropped.is_empty() {
        method.push_str(&format!(
            "; not identifiable from these data: {}",
            dropped.join(", ")
        ));
    }
    let mut std_errors = vec![f64::INFINITY; p];
    let mut correlation = vec![vec![f64::NAN; p]; p];
    if let Some(c) = &cov {
        if (0..q).all(|a| c[(a, a)].is_finite() && c[(a, a)] >= 0.0) {
            for (a, &i) in keep.iter().enumerate() {
                std_errors[i] = c[(a, a)].sqrt() / norms[a] * scale[i];
                for (b, &k) in keep.iter().enumerate() {
                    correlation[i][k] = c[(a, b)] / (c[(a, a)] * c[(b, b)]).sqrt();
                }
            }
        }
    }
    // The standard errors a later start's joining test uses: these, or the
    // independent-error ones (as `independent` computes them).
    let join_std_errors = if problem.joins_on_independent_errors() && groups.is_some() {
        let df = (n - q.max(1)) as f64;
        let mut se = vec![f64::INFINITY; p];
        if let Some(c) = inv.as_ref().map(|m| m * (ssr / df)) {
            if (0..q).all(|a| c[(a, a)].is_finite() && c[(a, a)] >= 0.0) {
                for (a, &i) in keep.iter().enumerate() {
                    se[i] = c[(a, a)].sqrt() / norms[a] * scale[i];
                }
            }
        }
        se
    } else {
        std_errors.clone()
    };
    // Where the intervals are centred: the Gauss-Newton step to the optimum, plus the
    // Richardson estimate of the exact model's optimum when the model has a step.
    let mut shift = vec![0.0; p];
    if let Some(inv) = &inv {
        let mut target: Vec<f64> = r0.iter().map(|v| -v).collect();
        let mut refined = Vec::with_capacity(n);
        // A model that fails at half its step leaves the intervals uncorrected (and
        // says so) rather than failing the fit.
        match problem.refined_residuals(x, &mut refined) {
            Ok(false) => {}
            Ok(true) if refined.len() == n && refined.iter().all(|v| v.is_finite()) => {
                evaluations += 1;
                // the residuals' own error e = 4/3 (r(h) - r(h/2)); the exact model's
                // residuals are r - e
                for ((t, a), b) in target.iter_mut().zip(&r0).zip(&refined) {
                    *t += 4.0 / 3.0 * (a - b);
                }
                method.push_str("; centred for the model's step error");
            }
            Ok(true) => {
                evaluations += 1;
                method.push_str(
                    "; not corrected for the model's step error (the refined evaluation gave non-finite or too few residuals)",
                );
            }
            Err(e) => {
                evaluations += 1;
                method.push_str(&format!(
                    "; not corrected for the model's step error (the refined evaluation failed: {e})"
                ));
            }
        }
        let step = inv * (jk.transpose() * na::DVector::from_vec(target));
        for (a, &j) in keep.iter().enumerate() {
            if step[a].is_finite() {
                shift[j] = step[a] / norms[a] * scale[j];
            }
        }
    }
    let t = t_quantile_95(df);
    let mut interval_95 = Vec::with_capacity(p);
    let mut clipped = Vec::with_capacity(p);
    for j in 0..p {
        let s = &specs[j];
        let (lo, hi) = interval(x[j], shift[j], t * std_errors[j], s);
        // NaN ends count as beyond the bound
        let below = lo.is_nan() || lo <= s.lower;
        let above = hi.is_nan() || hi >= s.upper;
        // Clipped into the bounds; a clipped interval also reaches the fitted value (a
        // parameter at or near its bound whose optimum lies beyond it: the interval
        // runs from the bound to the fitted value at least).
        let (mut lo, mut hi) = (lo.max(s.lower).min(s.upper), hi.min(s.upper).max(s.lower));
        if below || above {
            lo = lo.min(x[j]);
            hi = hi.max(x[j]);
        }
        interval_95.push((lo, hi));
        clipped.push(match (below, above) {
            (false, false) => Clipped::No,
            (true, false) => Clipped::Lower,
            (false, true) => Clipped::Upper,
            (true, true) => Clipped::Both,
        });
    }
    Ok(Uncertainties {
        ssr,
        std_errors,
        join_std_errors,
        correlation,
        interval_95,
        clipped,
        shift,
        method,
        evaluations,
    })
}

/// The unclipped interval of a parameter fitted at `x`, centred at `x + shift`, of
/// half-width `half` (in the parameter; for a log-scale one in `ln x`, as `half / x`,
/// and centred at `ln x + shift / x`: the shift, like the standard error, is computed
/// for a relative change of `x` (module docs), which is a change of `ln x`). NaN
/// half-widths give infinite ends.
///
/// (Until 2026-12-07 a log-scale interval was centred at `ln(x + shift)`: where the
/// step-error shift exceeded the value, the centre was `ln 0`, and the interval ran from
/// the bound to the fitted value. On MuJoCo's 2-run friction sweep every knot of
/// `joint_friction`'s 7-knot table but the first had `[0, value]`, "clipped at the
/// lower bound", none holding the 0.02 N*m the data were made with; centred in the
/// logarithm they reach both bounds, "not determined", which they are: the viscous
/// coefficient fitted beside the table is one direction of the data with them.)
fn interval(x: f64, shift: f64, half: f64, spec: &ParamSpec) -> (f64, f64) {
    let half = if half.is_nan() { f64::INFINITY } else { half };
    if spec.log_scale && x > 0.0 {
        let h = half / x;
        let lc = x.ln() + shift / x;
        ((lc - h).exp(), (lc + h).exp())
    } else {
        let c = x + shift;
        (c - half, c + half)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log_spec() -> ParamSpec {
        ParamSpec {
            lower: 1e-9,
            upper: 1e3,
            log_scale: true,
            ..ParamSpec::new("coulomb_n_m", "N*m", 0.02)
        }
    }

    /// A log-scale interval is centred at `ln x + shift / x` (the shift is for a
    /// relative change of `x`): a shift beyond the value keeps a positive centre, where
    /// `ln(x + shift)` had none; a small shift gives `ln(x + shift)` to second order.
    #[test]
    fn a_log_scale_interval_takes_its_shift_in_the_logarithm() {
        let s = log_spec();
        let (x, se) = (0.02, 0.001);
        let (lo, hi) = interval(x, -0.03, 1.96 * se, &s);
        let c = (x.ln() - 1.5).exp();
        assert!((lo - c * (-1.96 * se / x).exp()).abs() < 1e-15, "{lo}");
        assert!((hi - c * (1.96 * se / x).exp()).abs() < 1e-15, "{hi}");
        assert!(lo > 0.0 && hi < x, "[{lo}, {hi}]");
        let small = 1e-5;
        let (lo, hi) = interval(x, small, 0.0, &s);
        assert_eq!(lo.to_bits(), hi.to_bits());
        let r = small / x;
        assert!(
            (lo - (x + small)).abs() < 0.6 * x * r * r,
            "{lo} against {}",
            x + small
        );
        // A linear parameter: centred at x + shift.
        let lin = ParamSpec::new("k1_scale", "1", 1.0);
        assert_eq!(interval(1.0, -0.5, 0.25, &lin), (0.25, 0.75));
    }
}
