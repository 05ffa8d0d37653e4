//! Fitting a model's free parameters to a dataset: the starting values (a grid, for
//! sweeps scored and refined on the analytic frequency response), least squares on the
//! time-domain simulation, and the screening of a model at its starting values alone.

use longreach_drive::effects::DataKind;
use num_complex::Complex64;
use rayon::prelude::*;

use super::compare::dft;
use super::prepare::Prepared;
use crate::dataset::DatasetKind;
use crate::error::IdentError;
use crate::fitting::{fit, FitOptions, FitResult, ResidualError, Residuals};
use crate::model::Model;
use crate::sim;

struct Problem<'p, 'a> {
    prep: &'p Prepared<'a>,
    model: &'p Model,
}

impl Residuals for Problem<'_, '_> {
    fn residuals(&self, params: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        let m = self.model.with_values(params, self.prep.runs.len());
        let sims = self.prep.simulate(&m)?;
        *out = self.prep.residuals_of(&sims);
        Ok(())
    }

    fn error_groups(&self) -> Option<Vec<usize>> {
        self.prep.error_groups()
    }

    fn refined_residuals(&self, params: &[f64], out: &mut Vec<f64>) -> Result<bool, ResidualError> {
        let m = self.model.with_values(params, self.prep.runs.len());
        let Some(sims) = self.prep.simulate_refined(&m) else {
            return Ok(false);
        };
        *out = self.prep.residuals_of(&sims?);
        Ok(true)
    }
}

/// Outcome of fitting a model.
#[derive(Debug, Clone)]
pub struct Fitted {
    /// The model with its fitted values.
    pub model: Model,
    /// The optimiser's result (`None` when nothing was fitted).
    pub fit: Option<FitResult>,
    /// Overall NRMSE before the fit (at the starting values).
    pub nrmse_before: f64,
    /// Overall NRMSE after.
    pub nrmse: f64,
    /// Noise floor on the NRMSE scale.
    pub noise_floor: f64,
    /// Sum of squared residuals after.
    pub ssr: f64,
    /// The simulated channel of every run after the fit.
    pub sims: Vec<Vec<f64>>,
}

/// Measured frequency response of every (run, test frequency) of a sweep.
fn measured_frf(prep: &Prepared<'_>) -> Vec<(usize, f64, Complex64)> {
    let DatasetKind::SineSweep(sw) = &prep.ds.kind else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for (r, run) in prep.runs.iter().enumerate() {
        let input = sim::drive_input(&sw.runs[r]);
        for &(f, a, b) in &run.segments {
            let x = dft(&input[a..b], run.dt_s, f);
            let y = dft(&run.measured[a..b], run.dt_s, f);
            if x.norm() > 0.0 && y.norm() > 0.0 {
                out.push((r, f, y / x));
            }
        }
    }
    out
}

/// Log-ratio residuals of the analytic small-signal response (eqs. 12-13, each rope
/// law's tangent at the run's mean tension) against the measured one.
struct FrfProblem<'p, 'a> {
    prep: &'p Prepared<'a>,
    model: &'p Model,
    points: Vec<(usize, f64, Complex64)>,
}

impl FrfProblem<'_, '_> {
    fn eval(&self, x: &[f64], out: &mut Vec<f64>) -> Result<(), IdentError> {
        let m = self.model.with_values(x, self.prep.runs.len());
        let params = (0..self.prep.runs.len())
            .map(|r| m.plant_params(r))
            .collect::<Result<Vec<_>, _>>()?;
        out.clear();
        for &(r, f, h) in &self.points {
            let model_h = self
                .prep
                .plant
                .small_signal_response(&params[r], r, f)
                .ok_or(IdentError::NotASweep {
                    kind: self.prep.ds.kind.name(),
                })?;
            let d = (model_h / h).ln();
            out.push(d.re);
            out.push(d.im);
        }
        Ok(())
    }
}

impl Residuals for FrfProblem<'_, '_> {
    fn residuals(&self, params: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        Ok(self.eval(params, out)?)
    }
}

/// Starting values: a grid over the free parameters (9 points each for sweeps, 5
/// otherwise, plus the starting value; log-spaced where the parameter is, at most 3
/// parameters gridded: the effect's and `k1_scale`), scored by the analytic response
/// for sweeps (then refined by least squares on it) and by the simulation for the other
/// kinds. Deterministic.
///
/// Sweeps: a gridded parameter the analytic response cannot see (every cost of the grid
/// is the same along its axis: `relay_friction` acts on the rig, and dry friction has no
/// amplitude-independent transfer function) would start at the first point of its
/// axis, whatever the data. With `scan_hidden`, such parameters are instead scanned on
/// the time-domain simulation, one at a time along their grid axis (the others at the
/// analytic start, the hidden ones at their starting values until scanned), and the
/// best point is kept.
fn starting_values(
    prep: &Prepared<'_>,
    model: &Model,
    scan_hidden: bool,
) -> Result<Vec<Vec<f64>>, IdentError> {
    let specs = model.fit_specs(prep.runs.len());
    let mut x0: Vec<f64> = specs.iter().map(|s| s.initial).collect();
    let slots = model.free_slots(prep.runs.len());
    let gridded: Vec<usize> = (0..specs.len())
        .filter(|&i| {
            matches!(slots[i].owner, crate::model::Owner::Effect(_))
                || (prep.kind == DataKind::SineSweep
                    && slots[i].owner == crate::model::Owner::Base
                    && model.base[slots[i].index].role
                        == crate::model::Role::Base(crate::model::BaseParam::K1Scale))
        })
        .take(3)
        .collect();
    if gridded.is_empty() {
        return Ok(vec![x0]);
    }
    let sweep = prep.kind == DataKind::SineSweep;
    let npts = if sweep { 9 } else { 5 };
    let axis = |i: usize| -> Vec<f64> {
        let s = &specs[i];
        let (lo, hi) = (
            s.lower,
            s.upper.min(if s.log_scale {
                s.lower * 1e6
            } else {
                f64::INFINITY
            }),
        );
        let mut v: Vec<f64> = (0..npts)
            .map(|k| {
                let a = (k as f64 + 0.5) / npts as f64;
                if s.log_scale && lo > 0.0 {
                    (lo.ln() + a * (hi.ln() - lo.ln())).exp()
                } else {
                    lo + a * (hi - lo)
                }
            })
            .collect();
        v.push(s.initial);
        v
    };
    let axes: Vec<Vec<f64>> = gridded.iter().map(|&i| axis(i)).collect();
    let total: usize = axes.iter().map(|a| a.len()).product();
    let points: Vec<Vec<f64>> = (0..total)
        .map(|mut k| {
            let mut x = x0.clone();
            for (g, a) in gridded.iter().zip(&axes) {
                x[*g] = a[k % a.len()];
                k /= a.len();
            }
            x
        })
        .collect();
    if sweep {
        let problem = FrfProblem {
            prep,
            model,
            points: measured_frf(prep),
        };
        let costs: Vec<f64> = points
            .par_iter()
            .map(|x| {
                let mut r = Vec::new();
                match problem.eval(x, &mut r) {
                    Ok(()) => r.iter().map(|v| v * v).sum::<f64>(),
                    Err(_) => f64::INFINITY,
                }
            })
            .collect();
        let best = (0..total)
            .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
            .unwrap_or(0);
        x0 = points[best].clone();
        let mut s2 = specs.clone();
        for (s, &v) in s2.iter_mut().zip(&x0) {
            s.initial = crate::fitting::strictly_inside(v, s.lower, s.upper);
        }
        if let Ok(r) = fit(
            &problem,
            &s2,
            &FitOptions {
                tolerance: 1e-8,
                gtol: 1e-10,
                patience: 60,
                diff_step: 1e-6,
                max_evaluations: usize::MAX,
            },
        ) {
            if r.ssr <= costs[best] {
                x0 = r.values;
            }
        }
        // Gridded parameters the analytic response cannot see: the cost of every grid
        // point equals that of the point with this coordinate at its first value.
        let hidden: Vec<usize> = (0..gridded.len())
            .filter(|&g| {
                let stride: usize = axes[..g].iter().map(|a| a.len()).product();
                let len = axes[g].len();
                (0..total).all(|k| {
                    let digit = (k / stride) % len;
                    costs[k].to_bits() == costs[k - digit * stride].to_bits()
                })
            })
            .collect();
        if scan_hidden && !hidden.is_empty() {
            let sim_cost = |x: &Vec<f64>| -> f64 {
                let m = model.with_values(x, prep.runs.len());
                prep.simulate(&m)
                    .map(|s| prep.ssr(&s))
                    .unwrap_or(f64::INFINITY)
            };
            for &g in &hidden {
                x0[gridded[g]] = specs[gridded[g]].initial;
            }
            let mut best_cost = f64::INFINITY;
            for &g in &hidden {
                let line: Vec<Vec<f64>> = axes[g]
                    .iter()
                    .map(|&v| {
                        let mut x = x0.clone();
                        x[gridded[g]] = v;
                        x
                    })
                    .collect();
                let line_costs: Vec<f64> = line.par_iter().map(sim_cost).collect();
                if let Some(k) = (0..line.len())
                    .min_by(|&a, &b| line_costs[a].total_cmp(&line_costs[b]).then(a.cmp(&b)))
                {
                    if line_costs[k] < best_cost {
                        best_cost = line_costs[k];
                        x0 = line[k].clone();
                    }
                }
            }
        }
    } else {
        // Two settings of the base constants: the baseline's fitted ones (in `points`)
        // and the catalog's (a strong effect pulls the baseline's constants far from
        // where the model with the effect has its optimum).
        let law = &model.law;
        let catalog: Vec<Option<f64>> = specs
            .iter()
            .enumerate()
            .map(|(i, s)| {
                if !matches!(slots[i].owner, crate::model::Owner::Base) {
                    return None;
                }
                let v = match s.name.as_str() {
                    "k1" => Some(law.k1_n),
                    "c2" => law.c2_n_s,
                    "k3" => law.kelvin.first().map(|k| k.k_n),
                    "c3" => law.kelvin.first().map(|k| k.c_n_s),
                    _ => None,
                };
                v.map(|v| v.clamp(s.lower, s.upper))
            })
            .collect();
        let alt: Vec<Vec<f64>> = points
            .iter()
            .map(|x| {
                x.iter()
                    .zip(&catalog)
                    .map(|(&v, c)| c.unwrap_or(v))
                    .collect()
            })
            .collect();
        let mut all = points;
        if alt[0] != all[0] {
            all.extend(alt);
        }
        let costs: Vec<f64> = all
            .par_iter()
            .map(|x| {
                let m = model.with_values(x, prep.runs.len());
                prep.simulate(&m)
                    .map(|s| prep.ssr(&s))
                    .unwrap_or(f64::INFINITY)
            })
            .collect();
        let mut order: Vec<usize> = (0..all.len()).filter(|&k| costs[k].is_finite()).collect();
        order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)));
        // Multi-start: the best grid point with the baseline's constants, the same
        // effect values with the catalog's, the best grid point with the catalog's,
        // then the best points whose effect values differ from those taken (another
        // basin: e.g. a second retardation time on either side of the rope's own); 4 at
        // most.
        let mut out: Vec<Vec<f64>> = Vec::new();
        let mut taken_gridded: Vec<Vec<f64>> = Vec::new();
        if let Some(&k) = order.iter().find(|&&k| k < total) {
            out.push(all[k].clone());
            // the same effect values with the catalog's constants
            if all.len() > total {
                out.push(all[k + total].clone());
            }
        }
        if let Some(&k) = order.iter().find(|&&k| k >= total) {
            if !out.contains(&all[k]) {
                out.push(all[k].clone());
            }
        }
        for x in &out {
            let g: Vec<f64> = gridded.iter().map(|&i| x[i]).collect();
            if !taken_gridded.contains(&g) {
                taken_gridded.push(g);
            }
        }
        for &k in &order {
            if out.len() >= 4 {
                break;
            }
            let g: Vec<f64> = gridded.iter().map(|&i| all[k][i]).collect();
            if !taken_gridded.contains(&g) {
                taken_gridded.push(g);
                out.push(all[k].clone());
            }
        }
        if out.is_empty() {
            out.push(x0);
        }
        return Ok(out);
    }
    Ok(vec![x0])
}

/// Scores `model` at its starting values without the time-domain refinement: the
/// starting grid (for sweeps refined on the analytic response) and one simulation per
/// start; the best start is returned with `fit = None`. [`diagnose`](fn@super::diagnose)
/// uses it for the candidates when the baseline already fits to the noise floor: no
/// candidate can be decisive then, and the time-domain fits (of a non-linear law above
/// all) are the dearest part of a diagnosis.
pub fn screen_model(prep: &Prepared<'_>, model: &Model) -> Result<Fitted, IdentError> {
    let starts = starting_values(prep, model, false)?;
    let scored: Vec<Result<(Model, Vec<Vec<f64>>, f64), IdentError>> = starts
        .par_iter()
        .map(|x| {
            let m = model.with_values(x, prep.runs.len());
            let sims = prep.simulate(&m)?;
            let ssr = prep.ssr(&sims);
            Ok((m, sims, ssr))
        })
        .collect();
    let (fitted_model, sims, ssr) = scored
        .into_iter()
        .filter_map(Result::ok)
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .ok_or(IdentError::NoStartSimulated {
            starts: starts.len(),
        })?;
    let (nrmse, noise_floor) = prep.overall(&sims);
    Ok(Fitted {
        model: fitted_model,
        fit: None,
        nrmse_before: nrmse,
        nrmse,
        noise_floor,
        ssr,
        sims,
    })
}

/// Where a fit starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// The search of [`starting_values`] (a grid; for sweeps refined on the analytic
    /// response), or the model's own values where they simulate closer to the data.
    Search,
    /// The model's own values: a refinement of a model already fitted (the analytic
    /// response of a sweep only sees the tangent of a non-linear law at each run's mean
    /// tension, which a rope swinging from slack to twice its mean tension near
    /// resonance does not follow).
    Own,
}

/// Most simulations of every run of a sweep that the least squares of a model with a
/// non-linear rope law may spend, Jacobians included, per free parameter plus one: a
/// rope step then solves the head spring's law (one exponential per iteration), 3-4x
/// the linear rig's cost. 20 lets the refined tables of example_sweep_stiffening
/// converge (at 6, when a step cost 25x the linear one, they stopped at 8.5x the noise
/// floor).
pub const DEAR_EVALUATIONS_PER_PARAM: usize = 20;

/// Fits the free parameters of `model` to the dataset, from the search of starting
/// values ([`Start::Search`]).
pub fn fit_model(prep: &Prepared<'_>, model: &Model) -> Result<Fitted, IdentError> {
    fit_model_from(prep, model, Start::Search)
}

/// Fits the free parameters of `model` to the dataset from `start`.
pub fn fit_model_from(
    prep: &Prepared<'_>,
    model: &Model,
    start: Start,
) -> Result<Fitted, IdentError> {
    let sims0 = prep.simulate(model)?;
    let (nrmse_before, noise_floor) = prep.overall(&sims0);
    let own: Vec<f64> = model
        .fit_specs(prep.runs.len())
        .iter()
        .map(|s| s.initial)
        .collect();
    let mut starts = match start {
        Start::Own => vec![own.clone()],
        Start::Search => starting_values(prep, model, true)?,
    };
    if starts.len() == 1 && starts[0] != own {
        // a searched start that simulates farther from the data than the model's own
        // values gives way to them
        let searched = prep.simulate(&model.with_values(&starts[0], prep.runs.len()));
        if searched.is_ok_and(|s| prep.ssr(&s) > prep.ssr(&sims0)) {
            starts[0] = own;
        }
    }
    let mut best: Option<(Model, Option<FitResult>, f64)> = None;
    for start in &starts {
        let model_start = model.with_values(start, prep.runs.len());
        let model = &model_start;
        let specs = model.fit_specs(prep.runs.len());
        let dear = prep.kind == DataKind::SineSweep
            && model.law_for_run(0).is_ok_and(|(l, _)| !l.is_linear());
        let (fitted_model, fit_res) = if specs.is_empty() {
            (model.clone(), None)
        } else {
            let opts = FitOptions {
                tolerance: 1e-5,
                gtol: 1e-7,
                patience: 25,
                diff_step: 1e-5,
                max_evaluations: if dear {
                    DEAR_EVALUATIONS_PER_PARAM * (specs.len() + 1)
                } else {
                    usize::MAX
                },
            };
            let problem = Problem { prep, model };
            match fit(&problem, &specs, &opts) {
                Ok(r) => (model.with_values(&r.values, prep.runs.len()), Some(r)),
                Err(e) if best.is_none() && starts.len() == 1 => return Err(e.into()),
                Err(_) => continue,
            }
        };
        let ssr = fit_res.as_ref().map_or(f64::INFINITY, |r| r.ssr);
        if best.as_ref().is_none_or(|b| ssr < b.2) {
            best = Some((fitted_model, fit_res, ssr));
        }
    }
    let (fitted_model, fit_res, _) = best.ok_or(IdentError::NoStartFitted {
        starts: starts.len(),
    })?;
    let sims = prep.simulate(&fitted_model)?;
    let (nrmse, _) = prep.overall(&sims);
    let ssr = prep.ssr(&sims);
    Ok(Fitted {
        model: fitted_model,
        fit: fit_res,
        nrmse_before,
        nrmse,
        noise_floor,
        ssr,
        sims,
    })
}
