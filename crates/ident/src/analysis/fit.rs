//! Fitting a model's free parameters to a dataset: the starting values (a grid, for
//! sweeps scored and refined on the analytic frequency response), least squares on the
//! time-domain simulation, and the screening of a model at its starting values alone.

use longreach_drive::effects::{Argument, DataKind, Site};
use num_complex::Complex64;
use rayon::prelude::*;

use super::compare::dft;
use super::prepare::Prepared;
use crate::dataset::DatasetKind;
use crate::error::IdentError;
use crate::fitting::{
    fit, fit_joining, FitOptions, FitResult, ParamSpec, ResidualError, Residuals,
};
use crate::model::{Model, Owner};
use crate::sim;

/// Most bytes of simulated channels a [`SimCache`] keeps: for an arm dataset of four
/// 8 s runs, one model's simulation is 0.36 MB; for a 5-run sweep with its four tension
/// channels (23 250 samples a run), 4.65 MB. A staged fit retraces its screen's path
/// (the grid's points, the least squares' start and its first Jacobians: about 15
/// points), and the path must still be kept then: at 32 MB it was not, and a relay-rig
/// candidate on such a sweep made 40 of its 310 simulations of a run twice (each ~0.1 s).
const SIM_CACHE_BYTES: usize = 256 << 20;

/// The simulations of one model (one set of effects and fixed numbers) at the free
/// values `x` ([`Model::with_values`]) already made during one fit, by the bits of `x`:
/// the fit asks for the same point several times (the start it picked from the grid, the
/// optimiser's first evaluation, the point of every forward-difference Jacobian, which
/// is the last point it accepted, the optimum again for the uncertainties and the
/// result), and a simulation is deterministic, so a point simulated once is reused
/// bit for bit whatever the threads. Least recently used points go first past
/// [`SIM_CACHE_BYTES`]; errors are not kept.
///
/// It also knows which runs a free value cannot change ([`Self::unchanged_runs`]): a
/// per-run value changes its run alone, and a value of a shape-free table changes the
/// law above the knot before its own only (a rise at knot `k` moves every value from
/// `k` up; a value, the segments on either side of `k`): a run whose simulation never
/// evaluated the law above that knot is the same to the bit. The plant reports the
/// knot opening the highest segment in which each simulation evaluated a table, every
/// evaluation counted ([`crate::plant::Plant::simulate_bounded`]); the bounds of every
/// point simulated here are kept (a few numbers each).
struct SimCache<'p, 'a> {
    prep: &'p Prepared<'a>,
    model: &'p Model,
    entries: std::sync::Mutex<Vec<(Vec<u64>, std::sync::Arc<Vec<Vec<f64>>>)>>,
    /// The argument of the model's free tables, when they share one and act
    /// everywhere (not restricted to some of an arm's joints).
    argument: Option<Argument>,
    /// What each free value can change.
    reach: Vec<Reach>,
    /// Every run's bound on `argument` at the points simulated, by the bits of the point.
    bounds: std::sync::Mutex<Vec<(Vec<u64>, Vec<Option<f64>>)>>,
}

/// The key a [`SimCache`] keeps a point by: the bits of its free values.
fn point_key(x: &[f64]) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

/// The runs a free value can change ([`SimCache::unchanged_runs`]).
#[derive(Debug, Clone, Copy, PartialEq)]
enum Reach {
    /// Every run.
    All,
    /// Run `r` alone (a per-run value).
    Run(usize),
    /// The runs whose table argument went above this knot (a table's value).
    Above(f64),
}

impl<'p, 'a> SimCache<'p, 'a> {
    fn new(prep: &'p Prepared<'a>, model: &'p Model) -> Self {
        let slots = model.free_slots(prep.runs.len());
        let mut arguments = slots.iter().filter_map(|s| match s.owner {
            Owner::Shape(e) => model.effects[e]
                .shape
                .as_ref()
                .map(|sh| (model.effects[e].at.is_none()).then_some(sh.shape.argument)),
            _ => None,
        });
        let first = arguments.next().flatten();
        let argument = first.filter(|a| arguments.all(|b| b == Some(*a)));
        let reach = slots
            .iter()
            .map(|s| match (s.run, s.owner) {
                (Some(r), _) => Reach::Run(r),
                (None, Owner::Shape(e)) if argument.is_some() => {
                    let Some(sh) = model.effects[e].shape.as_ref() else {
                        return Reach::All;
                    };
                    // (the first parameter is knot 0's value unless the shape fixes it)
                    let k = s.index + usize::from(sh.shape.value_at_zero.is_some());
                    match k.checked_sub(1).and_then(|i| sh.knots.get(i)) {
                        Some(&below) if below > 0.0 => Reach::Above(below),
                        _ => Reach::All,
                    }
                }
                _ => Reach::All,
            })
            .collect();
        Self {
            prep,
            model,
            entries: std::sync::Mutex::new(Vec::new()),
            argument,
            reach,
            bounds: std::sync::Mutex::new(Vec::new()),
        }
    }

    /// The runs free value `j` cannot change at the free values `base` (per run, true
    /// where it cannot); `None` when it may change every run, or when `base` was not
    /// simulated here with bounds.
    fn unchanged_runs(&self, base: &[f64], j: usize) -> Option<Vec<bool>> {
        let n = self.prep.runs.len();
        match *self.reach.get(j)? {
            Reach::All => None,
            Reach::Run(r) => Some((0..n).map(|q| q != r).collect()),
            Reach::Above(knot) => {
                let key = point_key(base);
                let bounds = self.bounds.lock().unwrap_or_else(|e| e.into_inner());
                let (_, b) = bounds.iter().find(|(k, _)| *k == key)?;
                Some(b.iter().map(|b| b.is_some_and(|b| b < knot)).collect())
            }
        }
    }

    /// Records `sims` as the model's simulation at the free values `x` (simulated
    /// elsewhere on the same prepared data).
    fn seed(&self, x: &[f64], sims: std::sync::Arc<Vec<Vec<f64>>>) {
        let key = point_key(x);
        let mut entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        if !entries.iter().any(|(k, _)| *k == key) {
            entries.push((key, sims));
        }
    }

    /// The simulation at the free values `x` when it was made (or seeded) and is still
    /// kept; nothing is simulated.
    fn cached(&self, x: &[f64]) -> Option<std::sync::Arc<Vec<Vec<f64>>>> {
        let key = point_key(x);
        let entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        entries
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, s)| s.clone())
    }

    /// The compared channel of every run of the model at the free values `x`.
    fn simulate(&self, x: &[f64]) -> Result<std::sync::Arc<Vec<Vec<f64>>>, IdentError> {
        let key = point_key(x);
        {
            let mut entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
            if let Some(k) = entries.iter().position(|(k, _)| *k == key) {
                let hit = entries.remove(k);
                let sims = hit.1.clone();
                entries.push(hit);
                return Ok(sims);
            }
        }
        let model = self.model.with_values(x, self.prep.runs.len());
        let sims = std::sync::Arc::new(match self.argument {
            None => self.prep.simulate(&model)?,
            Some(_) => {
                let (sims, bounds): (Vec<Vec<f64>>, Vec<Option<f64>>) = (0..self.prep.runs.len())
                    .into_par_iter()
                    .map(|r| self.prep.simulate_run_bounded(&model, r))
                    .collect::<Result<Vec<_>, IdentError>>()?
                    .into_iter()
                    .unzip();
                let mut kept = self.bounds.lock().unwrap_or_else(|e| e.into_inner());
                if !kept.iter().any(|(k, _)| *k == key) {
                    kept.push((key.clone(), bounds));
                }
                sims
            }
        });
        let bytes = |s: &Vec<Vec<f64>>| 8 * s.iter().map(Vec::len).sum::<usize>();
        let mut entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        if !entries.iter().any(|(k, _)| *k == key) {
            entries.push((key, sims.clone()));
            let mut total: usize = entries.iter().map(|(_, s)| bytes(s)).sum();
            while total > SIM_CACHE_BYTES && entries.len() > 1 {
                total -= bytes(&entries.remove(0).1);
            }
        }
        Ok(sims)
    }

    /// The sum of squared residuals at `x`, infinite where the model fails.
    fn ssr(&self, x: &[f64]) -> f64 {
        self.simulate(x)
            .map_or(f64::INFINITY, |s| self.prep.ssr(&s))
    }

    /// [`Self::ssr`] over the runs `runs` alone (in order, simulated in parallel; not
    /// kept unless `runs` are all of them).
    fn ssr_on(&self, x: &[f64], runs: &[usize]) -> f64 {
        if runs.len() == self.prep.runs.len() {
            return self.ssr(x);
        }
        let model = self.model.with_values(x, self.prep.runs.len());
        let parts: Vec<f64> = runs
            .par_iter()
            .map(|&r| {
                self.prep
                    .simulate_run(&model, r)
                    .map_or(f64::INFINITY, |y| self.prep.run_ssr(r, &y))
            })
            .collect();
        parts.iter().sum()
    }
}

struct Problem<'c, 'p, 'a> {
    cache: &'c SimCache<'p, 'a>,
}

impl Residuals for Problem<'_, '_, '_> {
    fn residuals(&self, params: &[f64], out: &mut Vec<f64>) -> Result<(), ResidualError> {
        let sims = self.cache.simulate(params)?;
        *out = self.cache.prep.residuals_of(&sims);
        Ok(())
    }

    fn error_groups(&self) -> Option<Vec<usize>> {
        self.cache.prep.error_groups()
    }

    fn joins_on_independent_errors(&self) -> bool {
        // (an arm's starts join as they did before its errors were grouped)
        self.cache.prep.kind == DataKind::ArmMoves
    }

    fn residuals_beside(
        &self,
        base: &[f64],
        base_residuals: &[f64],
        j: usize,
        params: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<bool, ResidualError> {
        let cache = self.cache;
        let Some(unchanged) = cache.unchanged_runs(base, j).filter(|u| u.contains(&true)) else {
            return Ok(false);
        };
        let prep = cache.prep;
        let model = cache.model.with_values(params, prep.runs.len());
        let sims: Vec<Option<Vec<f64>>> = (0..prep.runs.len())
            .into_par_iter()
            .map(|r| {
                (!unchanged[r])
                    .then(|| prep.simulate_run(&model, r))
                    .transpose()
            })
            .collect::<Result<_, IdentError>>()?;
        out.clear();
        let mut at = 0;
        for (r, y) in sims.iter().enumerate() {
            let len = prep.run_residual_count(r);
            match y {
                Some(y) => prep.run_residuals_into(r, y, out),
                None => out.extend_from_slice(&base_residuals[at..at + len]),
            }
            at += len;
        }
        Ok(true)
    }

    fn refined_residuals(&self, params: &[f64], out: &mut Vec<f64>) -> Result<bool, ResidualError> {
        let prep = self.cache.prep;
        let m = self.cache.model.with_values(params, prep.runs.len());
        let Some(sims) = prep.simulate_refined(&m) else {
            return Ok(false);
        };
        *out = prep.residuals_of(&sims?);
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

/// The starting grid's values of a parameter: `npts` points spread over its bounds
/// (log-spaced on a log scale over at most six decades, see below), then its
/// starting value.
fn grid_axis(s: &ParamSpec, npts: usize) -> Vec<f64> {
    // A log-scale axis spans at most 6 decades: up from a positive lower bound, down
    // from the upper bound when the lower one is 0 (a friction's viscous coefficient
    // on [0, 1e3]: 1e-3 to 1e3; a linear axis there put every point but the start on
    // 0, and the hidden 0.1 was never tried), around the start when neither bounds it.
    let (lo, hi) = if !s.log_scale {
        (s.lower, s.upper)
    } else if s.lower > 0.0 {
        (s.lower, s.upper.min(s.lower * 1e6))
    } else if s.upper.is_finite() {
        (s.upper * 1e-6, s.upper)
    } else {
        (s.initial.abs() * 1e-3, s.initial.abs() * 1e3)
    };
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
}

/// Whether a free parameter is an effect's.
fn is_effect(slot: &crate::model::Slot) -> bool {
    matches!(slot.owner, crate::model::Owner::Effect(_))
}

/// Whether a free effect parameter holds a fitted value the starting grid should keep:
/// one of an effect before the model's last whose values are not all their defaults (a
/// model that already holds fitted effects, with a candidate added last). Its grid
/// axis would only multiply the grid (5-6 points per axis, simulated on arms) and take
/// the place of the new effect's own parameters among the 3 gridded: the candidates
/// screened on the written model of example_arm_joint_friction gridded its friction's
/// two values and one of theirs, 78 of the 84 s of `diagnose --model`.
fn already_fitted(model: &Model, slot: &crate::model::Slot) -> bool {
    let crate::model::Owner::Effect(e) = slot.owner else {
        return false;
    };
    let u = &model.effects[e];
    e + 1 < model.effects.len()
        && u.params
            .iter()
            .zip(u.effect.params())
            .any(|(p, d)| p.value.to_bits() != d.default.to_bits())
}

/// The free parameters (indices into the model's fit specs) the starting grid spans:
/// at most 3, the effect parameters not [`already_fitted`] first in the model's order,
/// and on a sweep the base's `k1_scale`.
/// `slots` are the model's free slots ([`Model::free_slots`]).
fn gridded_params(model: &Model, slots: &[crate::model::Slot], kind: DataKind) -> Vec<usize> {
    (0..slots.len())
        .filter(|&i| {
            (is_effect(&slots[i]) && !already_fitted(model, &slots[i]))
                || (kind == DataKind::SineSweep && is_k1_scale(model, &slots[i]))
        })
        .take(3)
        .collect()
}

/// Whether a free parameter is the base's `k1_scale`.
fn is_k1_scale(model: &Model, slot: &crate::model::Slot) -> bool {
    slot.owner == crate::model::Owner::Base
        && model.base[slot.index].role == crate::model::Role::Base(crate::model::BaseParam::K1Scale)
}

/// The model's values improved one coordinate at a time on the simulation: every
/// effect parameter and `k1_scale` scanned in turn along its starting grid's axis
/// ([`grid_axis`], 9 points) from the current point, the best point kept each time
/// (parallel simulations, deterministic). For a start that the analytic response
/// cannot place: a pair of effects each fitted alone made up for the other's absence.
pub fn scan_coordinates(prep: &Prepared<'_>, model: &Model) -> Result<Model, IdentError> {
    let n_runs = prep.runs.len();
    let specs = model.fit_specs(n_runs);
    let slots = model.free_slots(n_runs);
    let cache = SimCache::new(prep, model);
    let mut x: Vec<f64> = specs.iter().map(|s| s.initial).collect();
    let mut best = cache.ssr(&x);
    for i in 0..specs.len() {
        if !(is_effect(&slots[i]) || is_k1_scale(model, &slots[i])) {
            continue;
        }
        if let Some((cost, y)) = best_on_axis(&cache, &x, i, &grid_axis(&specs[i], 9)) {
            if cost < best {
                best = cost;
                x = y;
            }
        }
    }
    Ok(model.with_values(&x, n_runs))
}

/// Factor on either side of the current `k1_scale` at which [`scan_added`] weighs
/// each value of an added effect's parameter (then at the parabola's vertex through
/// the three, in log `k1_scale`, within [`K1_REPLACE_SPAN`] of the current).
const K1_REPLACE_STEP: f64 = 1.25;

/// Largest factor by which [`scan_added`] moves `k1_scale` from the first fit's.
const K1_REPLACE_SPAN: f64 = 2.0;

/// `model` with the effect `added` (an index into its effects) placed on the
/// simulation while the other effects hold their values: each of that effect's free
/// parameters in turn scanned along an axis of [`HIDDEN_SCAN_POINTS`] ([`grid_axis`])
/// from the current point, the best point kept each time; returned with its squared
/// error, and with the best point of every other value of those axes (the starts of
/// [`screen_added`]). Each value is weighed with `k1_scale` placed again (an effect
/// that stiffens or softens the rope moves the `k1_scale` the others were fitted
/// with): at the current one and [`K1_REPLACE_STEP`] on either side, then at the vertex
/// of the parabola through those three in log `k1_scale`. For a second effect that the
/// first's error masks: alone its fit makes up for the first's absence, and beside an
/// effect at the relay pulleys (which the analytic response does not see) its
/// starting grid has no minimum away from zero (a stiffening rope beside relay
/// friction, the extended study's pairs).
pub fn scan_added(prep: &Prepared<'_>, model: &Model, added: usize) -> (Model, f64, Vec<Model>) {
    let n_runs = prep.runs.len();
    let mut held = model.clone();
    for (e, u) in held.effects.iter_mut().enumerate() {
        if e != added {
            for p in &mut u.params {
                p.fit = false;
            }
        }
    }
    let specs = held.fit_specs(n_runs);
    let slots = held.free_slots(n_runs);
    let cache = SimCache::new(prep, &held);
    let mut x: Vec<f64> = specs.iter().map(|s| s.initial).collect();
    let mut best = cache.ssr(&x);
    let mut axis_points: Vec<Vec<f64>> = Vec::new();
    let k1 = (0..specs.len()).find(|&i| is_k1_scale(&held, &slots[i]));
    let own = (0..specs.len()).filter(|&i| slots[i].owner == Owner::Effect(added));
    for i in own {
        let values = grid_axis(&specs[i], HIDDEN_SCAN_POINTS);
        let at = |v: f64, w: Option<f64>| {
            let mut y = x.clone();
            y[i] = v;
            if let (Some(j), Some(w)) = (k1, w) {
                y[j] = w.clamp(specs[j].lower, specs[j].upper);
            }
            y
        };
        let k0 = k1.map(|j| x[j]);
        let factors = [1.0 / K1_REPLACE_STEP, 1.0, K1_REPLACE_STEP];
        // (each point with the index of its axis value)
        let mut line: Vec<(usize, Vec<f64>)> = values
            .iter()
            .enumerate()
            .flat_map(|(n, &v)| match k0 {
                Some(w) => factors.iter().map(|f| (n, at(v, Some(w * f)))).collect(),
                None => vec![(n, at(v, None))],
            })
            .collect();
        let mut costs: Vec<f64> = line.par_iter().map(|(_, y)| cache.ssr(y)).collect();
        if let Some(w) = k0 {
            // the vertex in u = log_step(k1 / k1_0), from the costs at u = -1, 0, 1
            let vertices: Vec<(usize, Vec<f64>)> = values
                .iter()
                .enumerate()
                .filter_map(|(n, &v)| {
                    let c = &costs[3 * n..3 * n + 3];
                    let curv = c[0] - 2.0 * c[1] + c[2];
                    if curv.is_nan() || curv <= 0.0 {
                        return None;
                    }
                    let span = K1_REPLACE_SPAN.ln() / K1_REPLACE_STEP.ln();
                    let u = (0.5 * (c[0] - c[2]) / curv).clamp(-span, span);
                    Some((n, at(v, Some(w * K1_REPLACE_STEP.powf(u)))))
                })
                .collect();
            costs.extend(
                vertices
                    .par_iter()
                    .map(|(_, y)| cache.ssr(y))
                    .collect::<Vec<_>>(),
            );
            line.extend(vertices);
        }
        // (the best point of each axis value: a start of `screen_added`; below, the
        // closest of all points moves the placing if it beats the current one)
        let per_value: Vec<usize> = (0..values.len())
            .filter_map(|n| {
                let of_n: Vec<usize> = (0..line.len()).filter(|&k| line[k].0 == n).collect();
                let c: Vec<f64> = of_n.iter().map(|&k| costs[k]).collect();
                argmin(&c)
                    .map(|m| of_n[m])
                    .filter(|&k| costs[k].is_finite())
            })
            .collect();
        axis_points.extend(per_value.iter().map(|&k| line[k].1.clone()));
        if let Some(k) = argmin(&costs).filter(|&k| costs[k] < best) {
            best = costs[k];
            x = line.swap_remove(k).1;
        }
    }
    // (the held effects free again, at their values)
    let freed = |y: &[f64]| {
        let mut out = held.with_values(y, n_runs);
        for (u, v) in out.effects.iter_mut().zip(&model.effects) {
            for (p, q) in u.params.iter_mut().zip(&v.params) {
                p.fit = q.fit;
            }
        }
        out
    };
    let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(p, q)| p.to_bits() == q.to_bits());
    let mut others: Vec<Model> = Vec::new();
    let mut kept: Vec<&Vec<f64>> = vec![&x];
    for y in &axis_points {
        if !kept.iter().any(|k| same(k, y)) {
            kept.push(y);
            others.push(freed(y));
        }
    }
    (freed(&x), best, others)
}

/// The effect last in `own` (the first fit's model with that effect added at its own
/// single fit's values, `own_ssr` its squared error) placed beside the others and
/// screened as a pair: [`scan_added`] places it from its defaults (`fresh`: the same
/// model with the effect at its defaults); the closer of that point and `own` is
/// screened ([`screen_own`], every value free), and so is the best point of every
/// other value of the placing's axes (on [`AXIS_SCREEN_JACOBIANS`]). Returns the
/// screened model that comes closest to the data and its squared error. Every axis value is a start because the held
/// values of the first effect, fitted without the second, bend the valley the second
/// lies in: on a relay-friction sweep of dyneema2 without tension channels the placing
/// kept a stiffening of 2.6e-5 (SSR 0.790, the relay alone 0.808; hidden 2e-3), while
/// its axis value 1.96e-3 (SSR 1.07 there) screened to 0.034.
pub fn screen_added(prep: &Prepared<'_>, own: &Model, own_ssr: f64, fresh: &Model) -> (Model, f64) {
    let (placed, placed_ssr, others) = scan_added(prep, fresh, fresh.effects.len() - 1);
    let mut starts = vec![if placed_ssr < own_ssr {
        placed
    } else {
        own.clone()
    }];
    starts.extend(others);
    let mut screened: Vec<(Model, f64)> = starts
        .par_iter()
        .enumerate()
        .map(|(k, m)| {
            screen_on(
                prep,
                m,
                if k == 0 {
                    SCREEN_JACOBIANS
                } else {
                    AXIS_SCREEN_JACOBIANS
                },
            )
        })
        .collect();
    let costs: Vec<f64> = screened.iter().map(|(_, c)| *c).collect();
    // (never empty: the placing's own point is the first start)
    screened.swap_remove(argmin(&costs).unwrap_or(0))
}

/// `model` screened from its own values: the first [`SCREEN_JACOBIANS`] Jacobians of
/// its least squares, and the squared error reached (at its values when the least
/// squares fails). Three on the relay rig too: there one Jacobian moved no pair of
/// relay friction with a second effect from its start (the extended study's pairs with
/// a stiffening rope), three took the stiffening ahead of the others.
pub fn screen_own(prep: &Prepared<'_>, model: &Model) -> (Model, f64) {
    screen_on(prep, model, SCREEN_JACOBIANS)
}

/// Jacobians of the screens [`screen_added`] starts from its axis' other values (the
/// placing's own point takes [`SCREEN_JACOBIANS`]): two moved the stiffening beside
/// relay friction from its axis value 1.96e-3 to SSR 0.047 on dyneema2 without
/// tensions (three: 0.034), one did not move it.
const AXIS_SCREEN_JACOBIANS: usize = 2;

/// [`screen_own`] on `jacobians` Jacobians.
fn screen_on(prep: &Prepared<'_>, model: &Model, jacobians: usize) -> (Model, f64) {
    let n_runs = prep.runs.len();
    let cache = SimCache::new(prep, model);
    let x0: Vec<f64> = model.fit_specs(n_runs).iter().map(|s| s.initial).collect();
    let values = screened_values(&cache, x0, jacobians);
    let ssr = cache.ssr(&values);
    (model.with_values(&values, n_runs), ssr)
}

/// The values the least squares of `cache`'s model reaches from `x0` in `jacobians`
/// Jacobians (a screen: no intervals), or `x0` when it fails.
fn screened_values(cache: &SimCache<'_, '_>, x0: Vec<f64>, jacobians: usize) -> Vec<f64> {
    let (prep, model) = (cache.prep, cache.model);
    let specs = fit_specs(prep, &model.with_values(&x0, prep.runs.len()));
    if specs.is_empty() {
        return x0;
    }
    let opts = FitOptions {
        max_evaluations: jacobians * (specs.len() + 2),
        intervals: false,
        ..fit_options(prep, model, specs.len())
    };
    match fit_joining(&Problem { cache }, &specs, &opts, &[]) {
        Ok(Some(r)) => r.values,
        _ => x0,
    }
}

/// The index of the least of `costs` (ties: the first); `None` when empty.
fn argmin(costs: &[f64]) -> Option<usize> {
    (0..costs.len()).min_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)))
}

/// `x` with coordinate `i` set to the value of `axis` that simulates closest to the
/// data (parallel simulations; ties: the first), and that cost.
fn best_on_axis(
    cache: &SimCache<'_, '_>,
    x: &[f64],
    i: usize,
    axis: &[f64],
) -> Option<(f64, Vec<f64>)> {
    best_on_axis_by(&|y: &[f64]| cache.ssr(y), x, i, axis)
}

/// [`best_on_axis`] with the cost `cost` of a point.
fn best_on_axis_by(
    cost: &(dyn Fn(&[f64]) -> f64 + Sync),
    x: &[f64],
    i: usize,
    axis: &[f64],
) -> Option<(f64, Vec<f64>)> {
    let mut line: Vec<Vec<f64>> = axis
        .iter()
        .map(|&v| {
            let mut y = x.to_vec();
            y[i] = v;
            y
        })
        .collect();
    let costs: Vec<f64> = line.par_iter().map(|y| cost(y)).collect();
    let k = argmin(&costs)?;
    Some((costs[k], line.swap_remove(k)))
}

/// Points of the axis along which a sweep's starting values scan a parameter the
/// analytic response cannot see, on the simulation, besides its starting value
/// ([`starting_values`]; the analytic grid has 9). On example_sweep_stiffening, 5
/// instead of 9 took `diagnose` from 14.2 to 11.6-12.5 s wall (25.4 to 20.3-21.8 s
/// CPU; `relay_friction`'s two axes and `joint_friction`'s), with the same verdict.
pub const HIDDEN_SCAN_POINTS: usize = 5;

/// Share of the squared error at a sweep's start that the runs a hidden scan weighs
/// its points on hold at least ([`scan_runs`]).
pub const HIDDEN_SCAN_SHARE: f64 = 0.5;

/// The runs a sweep's hidden scan ([`starting_values`]) weighs its points on, and the
/// cost there of the scan's start `x`: the fewest runs, largest squared error at `x`
/// first, that hold at least [`HIDDEN_SCAN_SHARE`] of it (all of them when `x` cannot
/// be simulated). The scan only chooses a start among a few points decades apart, and
/// a missing effect's hidden parameter moves the error most where the model misses
/// most; the least squares that follows weighs every run. On a 5-run sweep,
/// `relay_friction`'s scan of two axes on every run was 11 of its screen's 20
/// simulations of the relay rig (a quarter of the diagnosis' CPU); on the two runs
/// holding half the error, its start's and 10 points on two runs cost 5.
fn scan_runs(cache: &SimCache<'_, '_>, x: &[f64]) -> (Vec<usize>, f64) {
    let prep = cache.prep;
    let all: Vec<usize> = (0..prep.runs.len()).collect();
    let Ok(sims) = cache.simulate(x) else {
        return (all, f64::INFINITY);
    };
    let per_run: Vec<f64> = all.iter().map(|&r| prep.run_ssr(r, &sims[r])).collect();
    let total: f64 = per_run.iter().sum();
    let mut order = all;
    order.sort_by(|&a, &b| per_run[b].total_cmp(&per_run[a]).then(a.cmp(&b)));
    let mut held = 0.0;
    let mut runs = Vec::new();
    for r in order {
        runs.push(r);
        held += per_run[r];
        if held >= HIDDEN_SCAN_SHARE * total {
            break;
        }
    }
    runs.sort_unstable();
    // (summed as `SimCache::ssr_on` sums it: on every run, as `SimCache::ssr` does)
    let cost = if runs.len() == prep.runs.len() {
        prep.ssr(&sims)
    } else {
        runs.iter().map(|&r| per_run[r]).sum()
    };
    (runs, cost)
}

/// Distinct minima of a sweep's starting grid refined on the analytic response; they
/// and their refinements are weighed by one simulation each ([`starting_values`]).
pub const SWEEP_STARTS: usize = 4;

/// Relative distance on every coordinate within which a minimum of a sweep's starting
/// grid is its refinement (or another's): it is not weighed again by a simulation
/// ([`starting_values`]).
const GRID_JOINS: f64 = 1e-3;

/// Starting values: a grid over the free parameters (9 points each for sweeps, 5
/// otherwise, plus the starting value; log-spaced where the parameter is, at most 3
/// parameters gridded: the effect's and `k1_scale`), scored by the analytic response
/// for sweeps (its best distinct minima then refined by least squares on it, and the
/// minima and their refinements, distinct within [`GRID_JOINS`], weighed by one
/// simulation each) and by the simulation for the other kinds. Deterministic.
///
/// Sweeps: a gridded parameter the analytic response cannot see (every cost of the grid
/// is the same along its axis: `relay_friction` acts on the rig, and dry friction has no
/// amplitude-independent transfer function) would start at the first point of its
/// axis, whatever the data. With `scan_hidden`, such parameters are instead scanned on
/// the time-domain simulation, one at a time along an axis of [`HIDDEN_SCAN_POINTS`]
/// over the same range (the others at the
/// analytic start, the hidden ones at their starting values until scanned), and the
/// best point is kept.
fn starting_values(
    cache: &SimCache<'_, '_>,
    scan_hidden: bool,
) -> Result<Vec<Vec<f64>>, IdentError> {
    let (prep, model) = (cache.prep, cache.model);
    let specs = model.fit_specs(prep.runs.len());
    let mut x0: Vec<f64> = specs.iter().map(|s| s.initial).collect();
    let slots = model.free_slots(prep.runs.len());
    let gridded = gridded_params(model, &slots, prep.kind);
    if gridded.is_empty() {
        return Ok(vec![x0]);
    }
    let sweep = prep.kind == DataKind::SineSweep;
    let npts = if sweep { 9 } else { 5 };
    let axes: Vec<Vec<f64>> = gridded
        .iter()
        .map(|&i| grid_axis(&specs[i], npts))
        .collect();
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
        // The analytic response is a small-signal picture (each law's tangent at the
        // run's mean tension): where a law is non-linear, or a second effect is fitted
        // beside it, and the ropes swing far from their mean tension, its optimum may
        // sit in another basin than the simulation's. So the grid's best distinct
        // minima (points not next to a better one on every axis) are each refined on it,
        // and the start is the one that simulates closest to the data.
        let mut order: Vec<usize> = (0..total).filter(|&k| costs[k].is_finite()).collect();
        order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]).then(a.cmp(&b)));
        // each grid point's rank along every gridded axis (the axes end with the
        // starting value, out of order)
        let ranks: Vec<Vec<usize>> = axes
            .iter()
            .map(|a| {
                a.iter()
                    .map(|v| a.iter().filter(|w| w.total_cmp(v).is_lt()).count())
                    .collect()
            })
            .collect();
        let rank_of = |mut k: usize| -> Vec<usize> {
            axes.iter()
                .zip(&ranks)
                .map(|(a, r)| {
                    let d = k % a.len();
                    k /= a.len();
                    r[d]
                })
                .collect()
        };
        let mut picked: Vec<usize> = Vec::new();
        for &k in &order {
            if picked.len() >= SWEEP_STARTS {
                break;
            }
            let rk = rank_of(k);
            let apart = picked
                .iter()
                .all(|&p| rank_of(p).iter().zip(&rk).any(|(a, b)| a.abs_diff(*b) > 1));
            if apart {
                picked.push(k);
            }
        }
        if picked.is_empty() {
            picked.push(0);
        }
        let refined: Vec<Vec<f64>> = picked
            .par_iter()
            .map(|&k| {
                let mut s2 = specs.clone();
                for (s, &v) in s2.iter_mut().zip(&points[k]) {
                    s.initial = crate::fitting::strictly_inside(v, s.lower, s.upper);
                }
                match fit(
                    &problem,
                    &s2,
                    &FitOptions {
                        tolerance: 1e-8,
                        gtol: 1e-10,
                        patience: 60,
                        diff_step: 1e-6,
                        max_evaluations: usize::MAX,
                        probation_jacobians: None,
                        intervals: true,
                    },
                ) {
                    Ok(r) if r.ssr <= costs[k] => r.values,
                    _ => points[k].clone(),
                }
            })
            .collect();
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
        let scan = scan_hidden && !hidden.is_empty();
        // The scan below starts from the chosen start with the hidden parameters reset
        // to their starting values. Starts that are one point once reset need no
        // simulation to choose among them: the grid's distinct minima differ only
        // along hidden axes when the analytic response sees one gridded parameter, and
        // `relay_friction`'s four starts on example_sweep_stiffening were four
        // simulations for one start (29 points simulated then, with 9-point scans).
        let reset = |x: &[f64]| -> Vec<f64> {
            let mut y = x.to_vec();
            for &g in &hidden {
                y[gridded[g]] = specs[gridded[g]].initial;
            }
            y
        };
        // The grid's minima themselves join their refinements, where the refinement
        // moved them: the analytic response's optimum can lie far from the
        // simulation's where a run's ropes go slack at its resonance (its small-signal
        // picture then misplaces the peak). On a MuJoCo sweep of ropes stiffening as
        // the square root of their tension, every minimum of `nonlinear_stiffness`'s
        // grid refined to `k1_scale` 0.71, where the best grid point (1.0, 0.002) lies
        // next to the simulation's optimum (1.04, 0.0019, at the floor); the fit from
        // 0.71 stopped at 26x the floor.
        let near = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .all(|(u, v)| (u - v).abs() <= GRID_JOINS * u.abs().max(v.abs()))
        };
        // (refinements that met in one basin are one start: each was a simulation)
        let mut distinct: Vec<Vec<f64>> = Vec::new();
        let grid = picked.iter().map(|&k| points[k].clone());
        for x in refined.into_iter().chain(grid) {
            let x = if scan { reset(&x) } else { x };
            if !distinct.iter().any(|y| near(&x, y)) {
                distinct.push(x);
            }
        }
        x0 = if distinct.len() == 1 {
            distinct.swap_remove(0)
        } else {
            let sim_costs: Vec<f64> = distinct.par_iter().map(|x| cache.ssr(x)).collect();
            let b = (0..distinct.len())
                .min_by(|&a, &b| sim_costs[a].total_cmp(&sim_costs[b]).then(a.cmp(&b)))
                .unwrap_or(0);
            distinct.swap_remove(b)
        };
        if scan {
            // (every axis ends with the starting value: the point it scans from, whose
            // cost is known)
            let (runs, mut at_cost) = scan_runs(cache, &x0);
            let mut best_cost = f64::INFINITY;
            for &g in &hidden {
                let axis = grid_axis(&specs[gridded[g]], HIDDEN_SCAN_POINTS);
                let at = x0.clone();
                let known = at_cost;
                let cost = |y: &[f64]| {
                    if y.iter().zip(&at).all(|(a, b)| a.to_bits() == b.to_bits()) {
                        known
                    } else {
                        cache.ssr_on(y, &runs)
                    }
                };
                if let Some((cost, x)) = best_on_axis_by(&cost, &x0, gridded[g], &axis) {
                    if cost < best_cost {
                        best_cost = cost;
                        at_cost = cost;
                        x0 = x;
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
        let costs: Vec<f64> = all.par_iter().map(|x| cache.ssr(x)).collect();
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
    let cache = SimCache::new(prep, model);
    let starts = starting_values(&cache, false)?;
    let scored: Vec<Result<(Model, Vec<Vec<f64>>, f64), IdentError>> = starts
        .par_iter()
        .map(|x| {
            let m = model.with_values(x, prep.runs.len());
            let sims = cache.simulate(x)?.to_vec();
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

/// The starts the search of starting values gives `model` (for sweeps one, the grid on
/// the analytic response refined there; otherwise up to four, from the grid simulated),
/// as models at those values. Used where a caller weighs them against starts of its
/// own (the pair step of [`diagnose`](fn@super::diagnose)).
pub fn searched_starts(prep: &Prepared<'_>, model: &Model) -> Result<Vec<Model>, IdentError> {
    let cache = SimCache::new(prep, model);
    Ok(starting_values(&cache, true)?
        .iter()
        .map(|x| model.with_values(x, prep.runs.len()))
        .collect())
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

/// Most simulations of every run of an arm dataset that the least squares of one start
/// may spend, Jacobians included, per free parameter plus one. On
/// `example_arm_joint_friction` every start that converged took at most 21 (82
/// evaluations for 3 parameters); one start of `extra_retardation` crawled along the
/// valley of its two constants for 457 (88 Jacobians) without converging, a quarter of
/// the whole diagnosis, and ended worse than the other starts.
pub const ARM_EVALUATIONS_PER_PARAM: usize = 30;

/// Jacobians a later start of an arm fit may take while its SSR stays above every
/// optimum the earlier starts found ([`crate::fitting::FitOptions::probation_jacobians`]).
/// On `example_arm_joint_friction` the later starts cost 102 s of the candidates' 233 s
/// of CPU, and none of them ended below its candidate's first start but one
/// (`extra_retardation`'s second, whose first stopped on its budget unconverged).
pub const ARM_PROBATION_JACOBIANS: usize = 3;

/// Fits the free parameters of `model` to the dataset, from the search of starting
/// values ([`Start::Search`]).
pub fn fit_model(prep: &Prepared<'_>, model: &Model) -> Result<Fitted, IdentError> {
    fit_model_from(prep, model, Start::Search)
}

/// Fits the free parameters of `model` to the dataset from `start`.
///
/// A fit that ends with effect values on their bounds is tried once more from those
/// values at their effects' defaults when the model is closer to the data there (one
/// simulation): the map of a bounded parameter is flat at its bounds, so a least
/// squares that reaches one (or starts on it) does not leave it, whatever the data
/// say beyond. The better of the two fits is returned. Found on the arm's confusion
/// study: `extra_retardation` (3e5 N, 3e4 N*s) hidden, its fit ended with `c_n_s` on
/// its upper bound at 35x the floor; from the default it reaches the floor.
pub fn fit_model_from(
    prep: &Prepared<'_>,
    model: &Model,
    start: Start,
) -> Result<Fitted, IdentError> {
    fit_simulated(prep, model, start, None)
}

/// Fits the free parameters of `model` from each of `starts` (models of its structure,
/// with the same free parameters), in that order, and keeps the best fit: a start
/// whose least squares joins the basin of one fitted before stops there, and a start
/// equal to one fitted before is skipped ([`fit_once`]). For a fit whose starts'
/// squared errors do not tell which basin each is in: the exhaustive pair step of
/// [`diagnose_with`](fn@super::diagnose_with) (on a sweep holding a stiffening rope and
/// internal damping, the pair's own search start simulated farther from the data than
/// either single fit's, and only its least squares reached the floor).
pub fn fit_model_from_starts(
    prep: &Prepared<'_>,
    model: &Model,
    starts: &[Model],
) -> Result<Fitted, IdentError> {
    let n_runs = prep.runs.len();
    let xs: Vec<Vec<f64>> = starts
        .iter()
        .map(|m| m.fit_specs(n_runs).iter().map(|s| s.initial).collect())
        .collect();
    let first = fit_once(
        &SimCache::new(prep, model),
        Start::Search,
        None,
        Some(xs),
        Intervals::Now,
    )?;
    or_from_defaults(prep, first, Intervals::Now)
}

/// When a fit's 95% intervals are computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Intervals {
    /// At its optimum, as it ends.
    Now,
    /// Later, by [`with_intervals`], for the fit that is kept.
    Deferred,
}

/// [`fit_model_from`] from the model's own values ([`Start::Own`]) without the 95%
/// intervals: [`with_intervals`] gives the fit that is kept the intervals it would have
/// had, bit for bit. For a search whose fits are mostly thrown away: the shape
/// refinement fits a table of every number of knots and keeps one, and a fit's
/// intervals cost a Jacobian and a simulation at half the step (on
/// example_sweep_stiffening, the 2- and 4-knot tables' 8 simulations and 2 at half the
/// step: 4% of the diagnosis's CPU, its output the same to the byte).
pub fn fit_model_deferred(prep: &Prepared<'_>, model: &Model) -> Result<Fitted, IdentError> {
    let first = fit_once(
        &SimCache::new(prep, model),
        Start::Own,
        None,
        None,
        Intervals::Deferred,
    )?;
    or_from_defaults(prep, first, Intervals::Deferred)
}

/// `f` with the 95% intervals of its fit when they were deferred
/// ([`fit_model_deferred`]); unchanged otherwise. Its simulations at its values serve
/// the differences' centre.
pub fn with_intervals(prep: &Prepared<'_>, mut f: Fitted) -> Result<Fitted, IdentError> {
    let Some(r) = f.fit.as_mut().filter(|r| r.deferred.is_some()) else {
        return Ok(f);
    };
    let cache = SimCache::new(prep, &f.model);
    cache.seed(&r.values, std::sync::Arc::new(f.sims.clone()));
    crate::fitting::add_intervals(&Problem { cache: &cache }, r)?;
    Ok(f)
}

/// [`fit_model_from`] where `model` was already simulated on `prep` (`sims`, as
/// [`Prepared::simulate`] returns them): the fit starts from those instead of
/// simulating it again.
pub(crate) fn fit_simulated(
    prep: &Prepared<'_>,
    model: &Model,
    start: Start,
    sims: Option<Vec<Vec<f64>>>,
) -> Result<Fitted, IdentError> {
    let first = fit_once(
        &SimCache::new(prep, model),
        start,
        sims,
        None,
        Intervals::Now,
    )?;
    or_from_defaults(prep, first, Intervals::Now)
}

/// `first`, or its fit again from its values on bounds reset to their effects'
/// defaults when that is closer to the data ([`fit_model_from`]).
fn or_from_defaults(
    prep: &Prepared<'_>,
    first: Fitted,
    intervals: Intervals,
) -> Result<Fitted, IdentError> {
    let Some(reset) = first.model.with_bound_values_reset(prep.runs.len()) else {
        return Ok(first);
    };
    let Ok(reset_sims) = prep.simulate(&reset) else {
        return Ok(first);
    };
    if prep.ssr(&reset_sims) >= first.ssr {
        return Ok(first);
    }
    match fit_once(
        &SimCache::new(prep, &reset),
        Start::Own,
        Some(reset_sims),
        None,
        intervals,
    ) {
        Ok(again) if again.ssr < first.ssr => Ok(Fitted {
            nrmse_before: first.nrmse_before,
            ..again
        }),
        _ => Ok(first),
    }
}

/// Whether a fit of `model` on `prep` has a budget of evaluations
/// ([`DEAR_EVALUATIONS_PER_PARAM`]): a sweep's non-linear rope.
fn dear(prep: &Prepared<'_>, model: &Model) -> bool {
    prep.kind == DataKind::SineSweep && model.law_for_run(0).is_ok_and(|(l, _)| !l.is_linear())
}

/// The fit specs of `model`'s free values on `prep` ([`Model::fit_specs`]); in a fit
/// with a budget ([`dear`]) a table's rises ([`Model::is_rise`]) without their upper
/// bound, the shape's largest value, which the table's check still enforces.
///
/// Between two bounds the least squares works on a logistic map
/// ([`crate::fitting`]) whose tail near a bound is an exponential: the rises of a
/// stiffness factor (0.2 of a bound at 100) sit in that tail and move by factors, a
/// trust region at a time. On example_sweep_stiffening a rise started at 1e-4 took 15
/// Jacobians to climb to 0.02, one going to 0 took 8, and the refinement's tables (2,
/// 4, 7 knots) stopped on their budget after 86, 127 and 186 evaluations, the 4-knot
/// one at 2.3x the floor. With the lower bound only the map is quadratic at 0 and
/// linear beyond: 51, 37 and 52 evaluations, converged, the 4-knot table at 1.02x,
/// the 7-knot one at 0.99x (1.01x). Other fits keep the logistic map (relaxation and
/// cyclic tests run to convergence; arms have their own budget, not studied with it).
/// With the one-sided map on relaxations the extended study named two effects that
/// were not in the data: `extra_retardation` for a saturating creep at one strain
/// (creep rises one-sided too), and a stiffening beside that creep at two strains
/// (the pair step's creep and stiffness tables refined together). The one-sided map
/// is flat at 0: a rise that reaches 0 on the way stays there.
fn fit_specs(prep: &Prepared<'_>, model: &Model) -> Vec<ParamSpec> {
    let n_runs = prep.runs.len();
    let mut specs = model.fit_specs(n_runs);
    if dear(prep, model) {
        for (spec, slot) in specs.iter_mut().zip(model.free_slots(n_runs)) {
            if model.is_rise(&slot) {
                spec.upper = f64::INFINITY;
            }
        }
    }
    specs
}

/// The least squares' options of a fit of `model` with `p` free parameters on `prep`
/// from one of its starts ([`fit_once`]).
fn fit_options(prep: &Prepared<'_>, model: &Model, p: usize) -> FitOptions {
    let dear = dear(prep, model);
    FitOptions {
        tolerance: 1e-5,
        gtol: 1e-7,
        patience: 25,
        diff_step: 1e-5,
        max_evaluations: if dear {
            DEAR_EVALUATIONS_PER_PARAM * (p + 1)
        } else if prep.kind == DataKind::ArmMoves {
            ARM_EVALUATIONS_PER_PARAM * (p + 1)
        } else {
            usize::MAX
        },
        probation_jacobians: (prep.kind == DataKind::ArmMoves).then_some(ARM_PROBATION_JACOBIANS),
        intervals: true,
    }
}

/// `starts`, where a single searched start simulates farther from the data than the
/// model's own values `own` (SSR `own_ssr`), with those in its place.
fn or_own(
    cache: &SimCache<'_, '_>,
    mut starts: Vec<Vec<f64>>,
    own: Vec<f64>,
    own_ssr: f64,
) -> Vec<Vec<f64>> {
    if starts.len() == 1
        && starts[0] != own
        && cache
            .simulate(&starts[0])
            .is_ok_and(|s| cache.prep.ssr(&s) > own_ssr)
    {
        starts[0] = own;
    }
    starts
}

/// Jacobians of a candidate's first start in the first stage of a [`Staged`] fit.
pub const SCREEN_JACOBIANS: usize = 3;

/// [`SCREEN_JACOBIANS`] of a sweep's candidate simulated on the relay rig
/// ([`on_relay_rig`]), whose simulations cost 20-25 times the plain rig's (a relay
/// rig's run of a 5-run sweep ~70 ms, the plain rig's 3 ms, 12 ms with a non-linear
/// rope). On the 5-run stiffening sweep (README) the relay screen's second and third
/// Jacobians were 40 of its 75 simulations of a run, 2.5 of the diagnosis' 17.4 s of
/// CPU, for a candidate left ~400 times the squared error its screen is stopped at
/// (`diagnose` 10.3-11.1 s wall before, 9.3-9.5 s since, alternated in a slow hour).
/// Where the relays' friction is in the data its screen leads after one Jacobian: on
/// the 5-run relay-friction sweep NRMSE 0.209 (0.044 after three), the next screen
/// 1.007; the leader's whole fit then retraces that path through the same
/// simulations. Arms keep [`SCREEN_JACOBIANS`] (their relay candidate not studied
/// with fewer).
pub const RELAY_SCREEN_JACOBIANS: usize = 1;

/// Whether `model` is simulated on the relay rig (an effect at the relay pulleys or on
/// the spans splits each rope into spans): its simulations cost several times the
/// plain rig's.
pub(crate) fn on_relay_rig(model: &Model) -> bool {
    model
        .effects
        .iter()
        .any(|u| matches!(u.effect.site(), Site::RelayPulley | Site::Span))
}

/// The Jacobians of `model`'s screen on `prep` ([`Staged::screen`]):
/// [`RELAY_SCREEN_JACOBIANS`] for a sweep's candidate on the relay rig,
/// [`SCREEN_JACOBIANS`] otherwise.
pub fn screen_jacobians(prep: &Prepared<'_>, model: &Model) -> usize {
    if prep.kind == DataKind::SineSweep && on_relay_rig(model) {
        RELAY_SCREEN_JACOBIANS
    } else {
        SCREEN_JACOBIANS
    }
}

/// A model's fit ([`fit_model`]) in two stages that share its simulations, for a
/// diagnosis that fits many candidates and keeps few ([`super::diagnose`] on arms):
/// [`Self::screen`], the search of starting values and the first start's least squares
/// for [`SCREEN_JACOBIANS`] Jacobians, then, for the candidates kept, [`Self::fit`],
/// the whole fit. The second stage retraces the first start's path through the
/// simulations already made, and its result is [`fit_model`]'s to the bit.
pub struct Staged<'p, 'a> {
    cache: SimCache<'p, 'a>,
    starts: Option<Vec<Vec<f64>>>,
}

impl std::fmt::Debug for Staged<'_, '_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Staged")
            .field("screened", &self.starts.is_some())
            .finish_non_exhaustive()
    }
}

impl<'p, 'a> Staged<'p, 'a> {
    /// The fit of `model` (its free parameters from its values) on `prep`.
    pub fn new(prep: &'p Prepared<'a>, model: &'p Model) -> Self {
        Self {
            cache: SimCache::new(prep, model),
            starts: None,
        }
    }

    /// The first stage: the model at the values its first start reaches after
    /// [`screen_jacobians`] Jacobians (or at that start when its least squares fails),
    /// with `fit = None` (no intervals: a screen, not a fit).
    pub fn screen(&mut self) -> Result<Fitted, IdentError> {
        self.screen_reporting(&|_| {})
    }

    /// [`Self::screen`], telling `start` the squared error at the start of its least
    /// squares as soon as it is known: the screen's own can only be lower (the least
    /// squares accepts descents only, and keeps its start when it fails).
    pub(crate) fn screen_reporting(
        &mut self,
        start: &(dyn Fn(f64) + Sync),
    ) -> Result<Fitted, IdentError> {
        let (prep, model) = (self.cache.prep, self.cache.model);
        let n_runs = prep.runs.len();
        let own: Vec<f64> = model.fit_specs(n_runs).iter().map(|s| s.initial).collect();
        let sims0 = self.cache.simulate(&own)?;
        let (nrmse_before, noise_floor) = prep.overall(&sims0);
        let searched = starting_values(&self.cache, true)?;
        let x0 = or_own(&self.cache, searched.clone(), own, prep.ssr(&sims0)).swap_remove(0);
        if let Some(sims) = self.cache.cached(&x0) {
            start(prep.ssr(&sims));
        }
        // (the second stage chooses among them as `fit_once` does)
        self.starts = Some(searched);
        // the least squares of `fit_once`'s first start, stopped early: the same path
        let values = screened_values(&self.cache, x0, screen_jacobians(prep, model));
        let sims = self.cache.simulate(&values)?.to_vec();
        let (nrmse, _) = prep.overall(&sims);
        Ok(Fitted {
            model: model.with_values(&values, n_runs),
            fit: None,
            nrmse_before,
            nrmse,
            noise_floor,
            ssr: prep.ssr(&sims),
            sims,
        })
    }

    /// This stage (screened or not) on `prep`, another instance of the same prepared
    /// data ([`Prepared::abandonable`]), with the simulations and starts it holds: its
    /// fit there is its fit here, to the bit.
    pub(crate) fn rebound<'q>(&self, prep: &'q Prepared<'a>) -> Staged<'q, 'a>
    where
        'p: 'q,
    {
        fn copy<T: Clone>(m: &std::sync::Mutex<Vec<T>>) -> std::sync::Mutex<Vec<T>> {
            std::sync::Mutex::new(m.lock().unwrap_or_else(|e| e.into_inner()).clone())
        }
        let mut cache = SimCache::new(prep, self.cache.model);
        cache.entries = copy(&self.cache.entries);
        cache.bounds = copy(&self.cache.bounds);
        Staged {
            cache,
            starts: self.starts.clone(),
        }
    }

    /// The second stage: the whole fit, [`fit_model`]'s.
    pub fn fit(self) -> Result<Fitted, IdentError> {
        let first = fit_once(
            &self.cache,
            Start::Search,
            None,
            self.starts,
            Intervals::Now,
        )?;
        or_from_defaults(self.cache.prep, first, Intervals::Now)
    }
}

/// [`fit_simulated`] without the restart from the defaults, on `cache`'s model;
/// `searched`: the starts [`starting_values`] gives it, when already found;
/// `intervals`: when the fit's 95% intervals are computed ([`Intervals::Deferred`]
/// only from the model's own values: with several starts, a later start's joining
/// test reads the standard errors of the optima found before).
fn fit_once(
    cache: &SimCache<'_, '_>,
    start: Start,
    sims: Option<Vec<Vec<f64>>>,
    searched: Option<Vec<Vec<f64>>>,
    intervals: Intervals,
) -> Result<Fitted, IdentError> {
    let (prep, model) = (cache.prep, cache.model);
    let n_runs = prep.runs.len();
    let own: Vec<f64> = model.fit_specs(n_runs).iter().map(|s| s.initial).collect();
    // The model itself is the model at `own` unless a value sat on a bound (the specs
    // start strictly inside).
    let raw: Vec<f64> = model
        .free_slots(n_runs)
        .iter()
        .map(|s| {
            let p = model.param(s);
            s.run.map_or(p.value, |r| p.value_for(r))
        })
        .collect();
    let sims0 = match sims {
        Some(s) => {
            let s = std::sync::Arc::new(s);
            if raw == own {
                cache.seed(&own, s.clone());
            }
            s
        }
        None if raw == own => cache.simulate(&own)?,
        None => std::sync::Arc::new(prep.simulate(model)?),
    };
    let (nrmse_before, noise_floor) = prep.overall(&sims0);
    let starts = match (start, searched) {
        (Start::Own, _) => vec![own.clone()],
        (Start::Search, Some(found)) => found,
        (Start::Search, None) => starting_values(cache, true)?,
    };
    let starts = or_own(cache, starts, own, prep.ssr(&sims0));
    let mut best: Option<(Model, Option<FitResult>, f64)> = None;
    // Optima of the starts fitted so far (values, SSR; converged fits only): a later
    // start that comes near one stops there (`fit_joining`).
    let mut known: Vec<FitResult> = Vec::new();
    // Starts already fitted, as the fit starts them (strictly inside the bounds): two
    // grid points that differ only on a bound start the same fit.
    let mut started: Vec<Vec<u64>> = Vec::new();
    for start in &starts {
        let model_start = model.with_values(start, prep.runs.len());
        let model = &model_start;
        let specs = fit_specs(prep, model);
        let key: Vec<u64> = specs.iter().map(|s| s.initial.to_bits()).collect();
        if started.contains(&key) {
            continue;
        }
        started.push(key);
        let (fitted_model, fit_res) = if specs.is_empty() {
            (model.clone(), None)
        } else {
            let opts = FitOptions {
                intervals: intervals == Intervals::Now,
                ..fit_options(prep, model, specs.len())
            };
            let problem = Problem { cache };
            match fit_joining(&problem, &specs, &opts, &known) {
                // joined the basin of a start fitted before
                Ok(None) => continue,
                Ok(Some(r)) => {
                    if r.converged {
                        known.push(r.clone());
                    }
                    (model.with_values(&r.values, prep.runs.len()), Some(r))
                }
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
    let sims = match &fit_res {
        Some(r) => cache.simulate(&r.values)?.to_vec(),
        None => prep.simulate(&fitted_model)?,
    };
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{BaseParam, ParamDef, ShapeUse, Slot};
    use crate::{Dataset, DatasetKind, RelaxationDataset, RelaxationSpecimen};
    use longreach_drive::effects;

    /// The sweep baseline of dyneema2 with `k1_scale` free.
    fn sweep_base() -> Model {
        let ds = Dataset {
            dir: Default::default(),
            title: String::new(),
            kind: DatasetKind::Relaxation(RelaxationDataset {
                specimen: RelaxationSpecimen {
                    rope: "dyneema2".into(),
                    length_m: 0.1,
                    strain: 0.015,
                },
                runs: Vec::new(),
            }),
        };
        let mut m = Model::baseline(&ds).unwrap();
        m.base = vec![ParamDef::base(BaseParam::K1Scale, 1.0, 0.2, 5.0)];
        m
    }

    /// The shipped example `example_sweep_stiffening`.
    fn stiffening_example() -> Dataset {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../data/examples/example_sweep_stiffening");
        Dataset::load(&dir).unwrap()
    }

    /// (owner effect's name or "base", parameter index) of every gridded parameter.
    fn gridded_names(m: &Model) -> Vec<(String, usize)> {
        let slots: Vec<Slot> = m.free_slots(1);
        gridded_params(m, &slots, DataKind::SineSweep)
            .into_iter()
            .map(|i| match slots[i].owner {
                crate::model::Owner::Effect(e) => {
                    (m.effects[e].effect.name().to_string(), slots[i].index)
                }
                _ => ("base".to_string(), slots[i].index),
            })
            .collect()
    }

    /// A model that already holds a fitted effect (values off its defaults) grids the
    /// added candidate's parameters, not the fitted one's: before, joint friction's two
    /// fitted values took two of the 3 gridded places and a 2-parameter candidate had
    /// one of its own gridded. An effect still at its defaults (not yet fitted) is
    /// gridded, and the candidate alone grids its own.
    #[test]
    fn the_grid_spans_the_candidate_not_the_effects_already_fitted() {
        let friction = effects::find("joint_friction").unwrap();
        let retardation = effects::find("extra_retardation").unwrap();
        let mut held = sweep_base().with_effect(friction);
        held.effects[0].params[0].value = 0.7;
        held.effects[0].params[1].value = 0.05;
        let m = held.with_effect(retardation);
        assert_eq!(
            gridded_names(&m),
            [
                ("base".to_string(), 0),
                ("extra_retardation".to_string(), 0),
                ("extra_retardation".to_string(), 1)
            ]
        );
        // at its defaults the first effect is a candidate too: it comes first
        let fresh = sweep_base().with_effect(friction).with_effect(retardation);
        assert_eq!(
            gridded_names(&fresh),
            [
                ("base".to_string(), 0),
                ("joint_friction".to_string(), 0),
                ("joint_friction".to_string(), 1)
            ]
        );
        // the last effect is gridded even when its values are off their defaults
        let mut alone = sweep_base().with_effect(retardation);
        alone.effects[0].params[0].value *= 2.0;
        assert_eq!(gridded_names(&alone).len(), 3);
    }

    /// A hidden scan weighs its points on the fewest runs, largest error first, that
    /// hold at least half of the start's squared error, and the cost it gives the start
    /// is the one `ssr_on` gives any point: the runs' squared errors sum to the whole
    /// (the sum of `run_ssr` over every run is `Prepared::ssr`), the runs left out each
    /// hold less than any taken, and without the smallest taken the rest hold less than
    /// half.
    #[test]
    fn a_hidden_scan_weighs_the_runs_that_hold_half_the_error() {
        let ds = stiffening_example();
        let prep = Prepared::new(&ds).unwrap();
        let model = Model::baseline(&ds).unwrap();
        let cache = SimCache::new(&prep, &model);
        let x: Vec<f64> = model
            .fit_specs(prep.runs.len())
            .iter()
            .map(|s| s.initial)
            .collect();
        let sims = cache.simulate(&x).unwrap();
        let per_run: Vec<f64> = (0..prep.runs.len())
            .map(|r| prep.run_ssr(r, &sims[r]))
            .collect();
        let total: f64 = per_run.iter().sum();
        let whole = prep.ssr(&sims);
        assert!((total - whole).abs() <= 1e-12 * whole, "{total} vs {whole}");

        let (runs, cost) = scan_runs(&cache, &x);
        assert!(
            !runs.is_empty() && runs.len() < prep.runs.len(),
            "{runs:?} of {per_run:?}"
        );
        let held: f64 = runs.iter().map(|&r| per_run[r]).sum();
        assert!(held >= HIDDEN_SCAN_SHARE * total, "{runs:?} of {per_run:?}");
        let least = runs
            .iter()
            .map(|&r| per_run[r])
            .fold(f64::INFINITY, f64::min);
        assert!(
            held - least < HIDDEN_SCAN_SHARE * total,
            "{runs:?} of {per_run:?}"
        );
        for r in (0..prep.runs.len()).filter(|r| !runs.contains(r)) {
            assert!(per_run[r] <= least, "run {r} left out: {per_run:?}");
        }
        assert_eq!(cost.to_bits(), cache.ssr_on(&x, &runs).to_bits());
        assert_eq!(cost.to_bits(), held.to_bits());
    }

    /// The baseline of `ds` with `effect`'s law as a table of `values` over `knots`
    /// (its argument `argument`), every free value moved alone: the columns taken
    /// beside the centre equal the full evaluation to the bit, and the runs taken are
    /// those whose evaluations of the table stayed below the knot before the value's
    /// own (the plant's bound). Returns how many runs were taken.
    fn check_columns_beside(
        ds: &Dataset,
        effect: &'static dyn effects::Effect,
        knots: &[f64],
        values: &[f64],
        argument: Argument,
    ) -> usize {
        let prep = Prepared::new(ds).unwrap();
        let sh = ShapeUse::new(effect, effect.shape().unwrap(), knots, values, true).unwrap();
        let model = Model::baseline(ds)
            .unwrap()
            .with_effect(effect)
            .with_shape(0, sh);
        let cache = SimCache::new(&prep, &model);
        assert_eq!(cache.argument, Some(argument));
        let problem = Problem { cache: &cache };
        let specs = model.fit_specs(prep.runs.len());
        let x: Vec<f64> = specs.iter().map(|s| s.initial).collect();
        let mut r0 = Vec::new();
        problem.residuals(&x, &mut r0).unwrap();
        let bounds = cache.bounds.lock().unwrap()[0].1.clone();
        assert!(bounds.iter().all(Option::is_some), "{bounds:?}");
        let mut taken = 0;
        for (j, slot) in model.free_slots(prep.runs.len()).iter().enumerate() {
            let mut xj = x.clone();
            xj[j] += 1e-3 * xj[j].abs().max(1.0);
            let mut full = Vec::new();
            problem.residuals(&xj, &mut full).unwrap();
            let mut beside = Vec::new();
            let used = problem
                .residuals_beside(&x, &r0, j, &xj, &mut beside)
                .unwrap();
            // (a table whose value at 0 is fixed starts its values at knot 1)
            let below = match slot.owner {
                Owner::Shape(e) => {
                    let sh = model.effects[e].shape.as_ref().unwrap();
                    let k = slot.index + usize::from(sh.shape.value_at_zero.is_some());
                    k.checked_sub(1).map_or(0.0, |i| knots[i])
                }
                _ => 0.0,
            };
            let expected: Vec<bool> = bounds.iter().map(|b| b.unwrap() < below).collect();
            assert_eq!(used, expected.contains(&true), "value {j}: {bounds:?}");
            if used {
                taken += expected.iter().filter(|u| **u).count();
                assert_eq!(cache.unchanged_runs(&x, j), Some(expected));
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&beside), bits(&full), "value {j}");
            }
        }
        taken
    }

    /// A stiffness table's forward difference takes the runs whose rope tension never
    /// went above the knot before that value from the centre's residuals, and what it
    /// gives is the full evaluation's to the bit: those runs were the same. A run the
    /// value does change is simulated again (the top knot's rise moves the 590 N run).
    #[test]
    fn a_table_value_leaves_the_runs_below_its_knot_as_they_were() {
        let ds = stiffening_example();
        let taken = check_columns_beside(
            &ds,
            effects::find("nonlinear_stiffness").unwrap(),
            &[0.0, 150.0, 300.0, 450.0, 600.0],
            &[1.0, 1.3, 1.5, 1.6, 1.7],
            Argument::TensionN,
        );
        // the 100 N run below 150 N, the 100 and 296 N runs below 300 N, ...
        assert!(taken >= 3, "{taken} runs taken");
    }

    /// The same on the relay rig, whose inner spans no channel shows: a table of the
    /// relays' friction coefficient over their hub load, in a short synthetic sweep at
    /// 49 and 294 N (hub loads near 100 and 600 N). The relay step evaluates the table
    /// at every Newton iterate; the bound counts them all.
    #[test]
    fn a_relay_table_value_leaves_the_runs_below_its_knot_as_they_were() {
        let ds = stiffening_example();
        let relay_ds = crate::synth::short_relay_sweep(
            &Model::baseline(&ds).unwrap(),
            23,
            vec![(49.0, 4.5f64.to_radians()), (294.0, 4.5f64.to_radians())],
            vec![1.0, 2.4, 4.5],
            1.0,
        );
        let taken = check_columns_beside(
            &relay_ds,
            effects::find("relay_friction").unwrap(),
            &[0.0, 250.0, 450.0, 700.0, 1000.0],
            &[0.02, 0.02, 0.015, 0.01, 0.01],
            Argument::HubLoadN,
        );
        // the 49 N run below 250 N (values at 450, 700 and 1000 N), the 294 N run not
        assert!(taken >= 2, "{taken} runs taken");
    }
}
