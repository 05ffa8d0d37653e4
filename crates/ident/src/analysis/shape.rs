//! Shape-free refinement of an effect's law: the function at the heart of an effect
//! (stiffness against tension, creep rate against tension, friction against hub load or
//! sliding speed; [`longreach_drive::effects::Shape`]) fitted as a piecewise-linear
//! table over the range the data visits, in place of the catalog's formula.
//!
//! * **Knots**: 0, then halfway between `top i/K` and the quantile `i/K` (`i = 1..K`)
//!   of the argument's values over every run simulated with the parametric fit (`top`
//!   the largest, the last knot): the knots follow the data, and the stretch below its
//!   bulk keeps knots too (a stiffness law's shape there sets the strain everywhere
//!   above).
//! * **Start**: the parametric law's values at the knots ([`Effect::curve`]), so the
//!   table starts where the catalog's formula ended; each larger number of knots starts
//!   from the previous table's fit (its values at the new knots, its other parameters),
//!   and again from the catalog law when that fit stalls on the smaller table's curve
//!   (`STALLED`).
//! * **Fit**: every free parameter of the model together with the table's values, by
//!   least squares on the simulation from the parametric fit's values
//!   ([`fit_model_deferred`], the model's own values); a law that never falls is
//!   fitted through its non-negative rises from knot to knot. Only the table kept gets
//!   its 95% intervals ([`with_intervals`]: the same as if every fit had computed them,
//!   bit for bit, without their Jacobians at the optima thrown away).
//! * **How many knots**: the number the data chooses by the Bayesian information
//!   criterion among `K` in [`KNOT_COUNTS`], tried in turn while it improves (a
//!   sweep's from 4 knots up, then down from the catalog law: [`SWEEP_FIRST_KNOTS`]);
//!   the refinement is kept only when its BIC beats the parametric law's by
//!   [`MIN_SCORE`].
//! * **Band**: the 95% band of each knot's value from the fit's covariance (the sum
//!   of the rises below it for a non-decreasing law), `1.96` standard errors.

use longreach_drive::effects::{DataKind, Effect, Shape};
use rayon::prelude::*;
use serde::Serialize;

use super::diagnose::MIN_SCORE;
use super::fit::{fit_model_deferred, fit_model_from, with_intervals, Fitted, Start};
use super::prepare::Prepared;
use crate::error::IdentError;
use crate::model::{Model, Owner, ShapeUse};

/// A larger table whose fit ends with at least this share of the smaller table's
/// squared error has stalled on the smaller one's curve and is fitted again from the
/// catalog law ([`refine_shape`]).
const STALLED: f64 = 0.999;

/// Numbers of knots after the one at 0 that the refinement tries.
pub const KNOT_COUNTS: [usize; 3] = [2, 4, 7];

/// Index in [`KNOT_COUNTS`] of the count a sweep's refinement tries first (4 knots):
/// it goes up from there while the criterion improves, and down to the counts below
/// (from the catalog law) only while the smallest table tried is the best. A sweep's
/// simulations are the dearest of the rig's data, and a 2-knot table of a saturating
/// law crawls: on a 5-run sweep of one, the 2-knot fit took 51 simulations for its 4
/// values, then 26 for 4 knots from there and 58 for 7; from the catalog law, the 4
/// knots take 32 and the 2 are not fitted (7 knots chosen either way, the same NRMSE
/// to 4 digits).
pub const SWEEP_FIRST_KNOTS: usize = 1;

/// One number of knots tried.
#[derive(Debug, Clone, Serialize)]
pub struct KnotChoice {
    /// Knots after the one at 0.
    pub knots: usize,
    /// NRMSE of the fit.
    pub nrmse: f64,
    /// Bayesian information criterion `n ln(SSR/n) + p ln n`.
    pub bic: f64,
}

/// The outcome of a shape-free refinement.
#[derive(Debug, Clone, Serialize)]
pub struct ShapeRefinement {
    /// The effect whose law was refined, with its joints when it is restricted to some
    /// (`joint_friction@j5`: a table per joint).
    pub effect: String,
    /// What the law takes (`tension_n`, ...).
    pub argument: String,
    /// What it gives (`stiffness_factor`, ...).
    pub value: String,
    /// Unit of the value.
    pub unit: String,
    /// Knots of the chosen table.
    pub knots: Vec<f64>,
    /// Its values at the knots (run 0's for a per-run value).
    pub values: Vec<f64>,
    /// Their 95% band, `[lower, upper]` per knot.
    pub band_95: Vec<[f64; 2]>,
    /// The catalog law with its fitted parameter values, at the knots.
    pub catalog: Vec<f64>,
    /// The catalog law over a fine grid `(argument, value)` for plots, and the table's.
    pub curve: Vec<[f64; 3]>,
    /// Every number of knots tried.
    pub tried: Vec<KnotChoice>,
    /// NRMSE with the catalog law (the parametric fit).
    pub nrmse_parametric: f64,
    /// NRMSE with the chosen table.
    pub nrmse: f64,
    /// BIC improvement over the parametric fit (positive: the table is better).
    pub score: f64,
    /// Whether the table replaces the parametric law (score above [`MIN_SCORE`]).
    pub kept: bool,
}

/// The quantile `q` of sorted `v`.
fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let i = (q * (v.len() - 1) as f64).round() as usize;
    v[i.min(v.len() - 1)]
}

/// `K` knots after 0, each halfway between the evenly spaced position `top i / K` and
/// the quantile `i / K` of `sorted` (the largest value, `top`, last): the knots follow
/// the data without leaving the stretch below its bulk bare (a law's shape there sets
/// the strain at every higher tension).
fn place_knots(sorted: &[f64], k: usize, log_knots: bool) -> Vec<f64> {
    let top = quantile(sorted, 1.0);
    if log_knots {
        // 0, then geometric from LOG_KNOTS_DECADES below the top up to it
        let lo = top * 10f64.powf(-Shape::LOG_KNOTS_DECADES);
        return std::iter::once(0.0)
            .chain((0..k).map(|i| {
                if i + 1 == k {
                    top
                } else {
                    lo * (top / lo).powf(i as f64 / (k - 1).max(1) as f64)
                }
            }))
            .collect();
    }
    let mut knots: Vec<f64> = (0..=k)
        .map(|i| {
            let a = i as f64 / k as f64;
            0.5 * (top * a + quantile(sorted, a).min(top))
        })
        .collect();
    knots[0] = 0.0;
    knots[k] = top;
    if knots.windows(2).any(|w| w[1] - w[0] < top / (4 * k) as f64) {
        knots = (0..=k).map(|i| top * i as f64 / k as f64).collect();
    }
    knots
}

/// The BIC of a fit with `p` free parameters over `n` samples.
pub(super) fn bic(ssr: f64, p: usize, n: f64) -> f64 {
    n * (ssr.max(f64::MIN_POSITIVE) / n).ln() + p as f64 * n.ln()
}

/// Effect number `e` of `fitted`, its shape and the sorted values its argument takes
/// over every run (at the effect's joints when it is restricted to some): what a table
/// of its law is placed over. `None` when the effect has no shape, already holds one or
/// the plant gives no values of its argument.
#[allow(clippy::type_complexity)]
fn table_start<'f>(
    prep: &Prepared<'_>,
    fitted: &'f Fitted,
    e: usize,
) -> Result<Option<(&'f crate::model::EffectUse, Shape, Vec<f64>)>, IdentError> {
    let Some(u) = fitted.model.effects.get(e) else {
        return Ok(None);
    };
    let Some(shape) = u.effect.shape() else {
        return Ok(None);
    };
    if u.shape.is_some() {
        return Ok(None);
    }
    let mut samples: Vec<f64> = (0..prep.runs.len())
        .into_par_iter()
        .map(|r| {
            let params = fitted.model.plant_params(r)?;
            prep.plant
                .argument_samples(&params, r, shape.argument, u.at.as_deref())
        })
        .collect::<Result<Vec<_>, IdentError>>()?
        .concat();
    samples.retain(|x| x.is_finite() && *x >= 0.0);
    samples.sort_by(f64::total_cmp);
    if samples.is_empty() || quantile(&samples, 1.0) <= 0.0 {
        return Ok(None);
    }
    Ok(Some((u, shape, samples)))
}

/// The catalog law with values `values0` at `knots`, as a table's start: within the
/// shape's range, its value at 0 where the shape fixes it, never falling where the
/// shape says so.
fn catalog_at(effect: &dyn Effect, shape: &Shape, values0: &[f64], knots: &[f64]) -> Vec<f64> {
    let mut y: Vec<f64> = knots
        .iter()
        .map(|&x| {
            effect
                .curve(values0, x)
                .clamp(shape.max_value * 1e-6, shape.max_value)
        })
        .collect();
    if let Some(z) = shape.value_at_zero {
        y[0] = z;
    }
    if shape.non_decreasing {
        for i in 1..y.len() {
            y[i] = y[i].max(y[i - 1]);
        }
    }
    y
}

/// Refines the law of effect number `e` of the fitted model `fitted` in its shape-free
/// form (module docs). `None` when the effect has no shape, already holds one or the
/// plant gives no values of its argument. The returned [`Fitted`] is the model with the
/// table when the refinement is kept, otherwise `fitted` unchanged.
pub fn refine_shape(
    prep: &Prepared<'_>,
    fitted: &Fitted,
    e: usize,
) -> Result<Option<(ShapeRefinement, Fitted)>, IdentError> {
    let Some((u, shape, samples)) = table_start(prep, fitted, e)? else {
        return Ok(None);
    };
    let effect: &'static dyn Effect = u.effect;
    let n_runs = prep.runs.len();
    let values0: Vec<f64> = u.params.iter().map(|p| p.value).collect();
    let n = prep.n_samples() as f64;
    let p_parametric = fitted.model.fit_specs(n_runs).len();
    let bic_parametric = bic(fitted.ssr, p_parametric, n);
    let tables: Vec<(Vec<f64>, Vec<f64>)> = KNOT_COUNTS
        .iter()
        .map(|&k| {
            let knots = place_knots(&samples, k, shape.log_knots);
            let y = catalog_at(effect, &shape, &values0, &knots);
            (knots, y)
        })
        .collect();
    // (a sweep starts at the middle count, and tries the smallest only when the middle
    // one beats the largest: `SWEEP_FIRST_KNOTS`)
    let sweep = prep.kind == DataKind::SineSweep;
    let first = if sweep { SWEEP_FIRST_KNOTS } else { 0 };
    // The model with a table at `knots` holding the catalog law's values `y0` there (a
    // fit's start), and the BIC of a fit.
    let from_catalog = |knots: &[f64], y0: &[f64]| -> Result<Model, IdentError> {
        Ok(fitted
            .model
            .with_shape(e, ShapeUse::new(effect, shape, knots, y0, true)?))
    };
    let scored = |f: &Fitted| bic(f.ssr, f.model.fit_specs(n_runs).len(), n);
    let mut fits: Vec<(usize, f64, Fitted)> = Vec::new();
    for (knots, y0) in &tables[first..] {
        // From the previous number of knots' fit where there is one: its table at the
        // new knots and its other values (the larger table starts where the smaller
        // one ended, not from the catalog law again).
        let (base, y) = match fits.last() {
            Some((_, _, last)) => {
                let prev = last.model.effects[e]
                    .shape
                    .as_ref()
                    .and_then(|sh| sh.table_for(0).ok());
                match prev {
                    // (a value the smaller table left on its lower bound, a knot the
                    // data barely see, starts from the catalog law there instead, as
                    // the first table does: a log-scale value frozen on its bound
                    // stalled the larger fit)
                    Some(t) => (
                        &last.model,
                        knots
                            .iter()
                            .zip(y0)
                            .map(|(&x, &c)| {
                                let v = t.eval(x);
                                if v <= ShapeUse::value_lower_bound(&shape) * (1.0 + 1e-6) {
                                    c
                                } else {
                                    v
                                }
                            })
                            .collect(),
                    ),
                    None => (&fitted.model, y0.clone()),
                }
            }
            None => (&fitted.model, y0.clone()),
        };
        let sh = ShapeUse::new(effect, shape, knots, &y, true)?;
        let model = base.with_shape(e, sh);
        let mut f = fit_model_deferred(prep, &model)?;
        // A larger table that ends where the smaller one did (its least squares stayed
        // on the smaller table's curve, a stationary point it cannot leave: a convex
        // stiffening hidden in a relaxation, 4 knots at exactly the 2 knots' 1.11x the
        // floor) is fitted again from the catalog law at its knots, the better kept.
        if fits.last().is_some_and(|l| f.ssr >= STALLED * l.2.ssr) {
            // (a second start that fails leaves the first's fit)
            if let Ok(again) = fit_model_deferred(prep, &from_catalog(knots, y0)?) {
                if again.ssr < f.ssr {
                    f = again;
                }
            }
        }

        let b = scored(&f);
        // more knots only while the criterion improves; a larger table that fits worse
        // than the smaller one (it holds nearly the smaller's law: its fit stopped
        // short) does not end the search
        let worse = fits.last().is_some_and(|l| b >= l.1 && f.ssr < l.2.ssr);
        fits.push((knots.len() - 1, b, f));
        if worse {
            break;
        }
    }
    // The counts below the first tried, from the catalog law, while the smallest table
    // fitted so far is the best (fewer knots only while the criterion improves).
    for (knots, y0) in tables[..first].iter().rev() {
        let best = (0..fits.len()).min_by(|&a, &b| fits[a].1.total_cmp(&fits[b].1));
        if best != Some(0) {
            break;
        }
        let f = fit_model_deferred(prep, &from_catalog(knots, y0)?)?;
        fits.insert(0, (knots.len() - 1, scored(&f), f));
    }
    let Some((tried, best_bic, best_fit)) = best_of(fits) else {
        return Ok(None);
    };
    // (the intervals of the table kept only: the others' are never read)
    let best_fit = with_intervals(prep, best_fit)?;
    let score = bic_parametric - best_bic;
    let Some(refinement) = record(&best_fit, e, &values0, tried, fitted.nrmse, score, n_runs)?
    else {
        return Ok(None);
    };
    let kept = refinement.kept;
    Ok(Some((
        refinement,
        if kept { best_fit } else { fitted.clone() },
    )))
}

/// Of the fits of every number of knots tried (`(knots, BIC, fit)`), what was tried
/// and the best by BIC (its BIC and fit). `None` when nothing was fitted.
fn best_of(mut fits: Vec<(usize, f64, Fitted)>) -> Option<(Vec<KnotChoice>, f64, Fitted)> {
    let tried = fits
        .iter()
        .map(|(k, b, f)| KnotChoice {
            knots: *k,
            nrmse: f.nrmse,
            bic: *b,
        })
        .collect();
    let best = (0..fits.len()).min_by(|&a, &b| fits[a].1.total_cmp(&fits[b].1))?;
    let (_, bic, fit) = fits.swap_remove(best);
    Some((tried, bic, fit))
}

/// What the refinement of effect number `e` found, from `best` (the fit holding its
/// chosen table): the table and its band against the catalog law with values
/// `values0`, kept when `score` (its BIC improvement) is above [`MIN_SCORE`]. `None`
/// when `best` holds no table for the effect.
fn record(
    best: &Fitted,
    e: usize,
    values0: &[f64],
    tried: Vec<KnotChoice>,
    nrmse_parametric: f64,
    score: f64,
    n_runs: usize,
) -> Result<Option<ShapeRefinement>, IdentError> {
    let u = &best.model.effects[e];
    let Some(sh) = u.shape.clone() else {
        return Ok(None);
    };
    let (effect, shape) = (u.effect, &sh.shape);
    let knots = sh.knots.clone();
    let values = sh.values_for(0);
    let band_95 = band(best, e, &sh, &values, n_runs);
    let catalog: Vec<f64> = knots.iter().map(|&x| effect.curve(values0, x)).collect();
    let table = sh.table_for(0).map_err(crate::model::ModelError::from)?;
    let top = *knots.last().unwrap_or(&0.0);
    let curve = (0..=40)
        .map(|i| {
            let x = top * i as f64 / 40.0;
            [x, effect.curve(values0, x), table.eval(x)]
        })
        .collect();
    Ok(Some(ShapeRefinement {
        effect: u.label(),
        argument: shape.argument.name().to_string(),
        value: shape.value.to_string(),
        unit: shape.unit.to_string(),
        knots,
        values,
        band_95,
        catalog,
        curve,
        tried,
        nrmse_parametric,
        nrmse: best.nrmse,
        score,
        kept: score > MIN_SCORE,
    }))
}

/// Refines the laws of effects `uses` of `fitted` (the uses of one effect split per
/// joint, [`super::split_per_joint`]) together: every use with a shape gets a table of
/// `K` knots over its own joints' motion (K in [`KNOT_COUNTS`], in turn while the BIC
/// improves), each from its catalog law, all fitted at once with the model's other
/// free values. Together, not one after the other: a table fitted first leaves values
/// on their bounds (the value at rest of a friction table, which the data barely see)
/// that stall every later fit. `None` when no use has a shape to refine. The records
/// share one score, the BIC improvement of all the tables over `fitted`; the returned
/// [`Fitted`] holds them when kept.
pub fn refine_shapes_together(
    prep: &Prepared<'_>,
    fitted: &Fitted,
    uses: std::ops::Range<usize>,
) -> Result<Option<(Vec<ShapeRefinement>, Fitted)>, IdentError> {
    let mut starts = Vec::new();
    for e in uses {
        if let Some((u, shape, samples)) = table_start(prep, fitted, e)? {
            let values0: Vec<f64> = u.params.iter().map(|p| p.value).collect();
            starts.push((e, u.effect, shape, samples, values0));
        }
    }
    if starts.is_empty() {
        return Ok(None);
    }
    let n_runs = prep.runs.len();
    let n = prep.n_samples() as f64;
    let bic_parametric = bic(fitted.ssr, fitted.model.fit_specs(n_runs).len(), n);
    let mut fits: Vec<(usize, f64, Fitted)> = Vec::new();
    for &k in &KNOT_COUNTS {
        let mut model = fitted.model.clone();
        for (e, effect, shape, samples, values0) in &starts {
            let knots = place_knots(samples, k, shape.log_knots);
            let y = catalog_at(*effect, shape, values0, &knots);
            model = model.with_shape(*e, ShapeUse::new(*effect, *shape, &knots, &y, true)?);
        }
        let f = fit_model_from(prep, &model, Start::Own)?;
        let b = bic(f.ssr, f.model.fit_specs(n_runs).len(), n);
        let worse = fits.last().is_some_and(|l| b >= l.1);
        fits.push((k, b, f));
        if worse {
            break;
        }
    }
    let Some((tried, best_bic, best_fit)) = best_of(fits) else {
        return Ok(None);
    };
    let score = bic_parametric - best_bic;
    let mut records = Vec::new();
    for (e, _, _, _, values0) in &starts {
        if let Some(r) = record(
            &best_fit,
            *e,
            values0,
            tried.clone(),
            fitted.nrmse,
            score,
            n_runs,
        )? {
            records.push(r);
        }
    }
    Ok(Some((records, best_fit)))
}

/// The 95% band of every knot's value: `1.96` standard errors of the value (for a
/// non-decreasing law the sum of the rises below it, with their correlations).
fn band(f: &Fitted, e: usize, sh: &ShapeUse, values: &[f64], n_runs: usize) -> Vec<[f64; 2]> {
    let Some(r) = &f.fit else {
        return values.iter().map(|&v| [v, v]).collect();
    };
    let slots = f.model.free_slots(n_runs);
    // index in the fit of each of the table's parameters (global ones only)
    let idx: Vec<Option<usize>> = (0..sh.params.len())
        .map(|j| {
            slots
                .iter()
                .position(|s| s.owner == Owner::Shape(e) && s.index == j && s.run.is_none())
        })
        .collect();
    let fixed_first = sh.shape.value_at_zero.is_some();
    values
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            // the table parameters value i depends on
            let deps: Vec<usize> = if sh.shape.non_decreasing {
                let first = if fixed_first { 0 } else { 1 };
                (0..i + first).filter(|&j| j < idx.len()).collect()
            } else if fixed_first {
                if i == 0 {
                    Vec::new()
                } else {
                    vec![i - 1]
                }
            } else {
                vec![i]
            };
            let mut var = 0.0;
            for &a in &deps {
                for &b in &deps {
                    if let (Some(ia), Some(ib)) = (idx[a], idx[b]) {
                        let c = if ia == ib { 1.0 } else { r.correlation[ia][ib] };
                        var += c * r.std_errors[ia] * r.std_errors[ib];
                    }
                }
            }
            let half = if var.is_finite() {
                1.96 * var.max(0.0).sqrt()
            } else {
                f64::INFINITY
            };
            [(v - half).max(0.0), v + half]
        })
        .collect()
}
