//! Fit, compare and diagnose: a model simulated on the measured input of every run,
//! its error, where it fails, and which registered effect is missing.

use longreach_drive::effects::{DataKind, REGISTRY};
use num_complex::Complex64;
use rayon::prelude::*;
use serde::Serialize;

use crate::dataset::{Dataset, DatasetKind};
use crate::fitting::{fit, FitOptions, FitResult, Residuals};
use crate::metrics;
use crate::model::{data_kind, Model};
use crate::sensors::ENCODER_RESOLUTION_RAD;
use crate::sim;

/// One run prepared for comparison: the compared channel and the analysed samples.
#[derive(Debug, Clone)]
pub struct RunData {
    /// Run name (file stem).
    pub name: String,
    /// Sample times [s].
    pub time_s: Vec<f64>,
    /// The compared measured channel (output angle [rad] or tension [N]), all samples.
    pub measured: Vec<f64>,
    /// Indices of the analysed samples (analysis windows of sweeps; all otherwise).
    pub idx: Vec<usize>,
    /// Frequency steps of a sweep: `(frequency_hz, analysis start, analysis end)`.
    pub segments: Vec<(f64, usize, usize)>,
    /// Sample interval [s].
    pub dt_s: f64,
    /// Mean tension of a sweep run [N].
    pub mean_tension_n: Option<f64>,
    /// Input amplitude of a sweep run [rad].
    pub amplitude_rad: Option<f64>,
    /// Noise standard deviation of the compared channel (the noise floor) [rad or N].
    pub noise_sigma: f64,
}

impl RunData {
    /// A run whose measured channel is a rope tension (relaxation and cyclic tests):
    /// every sample analysed, noise from the second differences.
    fn tension_run(name: &str, time_s: &[f64], tension_n: &[f64]) -> Self {
        Self {
            name: name.to_string(),
            time_s: time_s.to_vec(),
            measured: tension_n.to_vec(),
            idx: (0..time_s.len()).collect(),
            segments: Vec::new(),
            dt_s: dt_of(time_s),
            mean_tension_n: None,
            amplitude_rad: None,
            noise_sigma: noise_sigma_second_difference(tension_n),
        }
    }
}

/// A dataset prepared for simulation and comparison.
#[derive(Debug, Clone)]
pub struct Prepared<'a> {
    /// The dataset.
    pub ds: &'a Dataset,
    /// Its kind.
    pub kind: DataKind,
    /// Its runs.
    pub runs: Vec<RunData>,
    /// Simulation sub-steps per sample of sweeps ([`sim::SWEEP_SUBSTEPS`] by default).
    pub substeps: usize,
}

/// Noise standard deviation of a smooth signal from its second differences:
/// `d_i = x_i - (x_{i-1} + x_{i+1})/2` is `N(0, 1.5 sigma^2)` for white Gaussian noise
/// on a signal whose curvature over two samples is small, so
/// `sigma = median |d_i| / (0.6745 sqrt 1.5)` (the median absolute deviation: robust
/// to the few samples where the signal itself bends sharply, such as the step of a
/// relaxation test at t = 0 or a decay faster than the sampling; a mean of squares
/// would count those as noise and raise the floor).
pub fn noise_sigma_second_difference(x: &[f64]) -> f64 {
    if x.len() < 3 {
        return 0.0;
    }
    let mut d: Vec<f64> = x
        .windows(3)
        .map(|w| (w[1] - 0.5 * (w[0] + w[2])).abs())
        .collect();
    let mid = d.len() / 2;
    let (_, median, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    // 0.67449 = Phi^-1(3/4): the median of |N(0, 1)|
    *median / (0.674_489_750_196_081_7 * 1.5f64.sqrt())
}

impl<'a> Prepared<'a> {
    /// Prepares `ds`: analysis windows and noise floors.
    pub fn new(ds: &'a Dataset) -> Result<Self, String> {
        let runs = match &ds.kind {
            DatasetKind::SineSweep(sw) => sw
                .runs
                .iter()
                .map(|r| {
                    let segs = r.segments().map_err(|e| e.to_string())?;
                    let idx = segs
                        .iter()
                        .flat_map(|g| g.analysis_start_index..g.analysis_end_index)
                        .collect();
                    Ok(RunData {
                        name: r.name.clone(),
                        time_s: r.time_s.clone(),
                        measured: r.output_angle_rad.clone(),
                        idx,
                        segments: segs
                            .iter()
                            .map(|g| (g.frequency_hz, g.analysis_start_index, g.analysis_end_index))
                            .collect(),
                        dt_s: r.dt_s(),
                        mean_tension_n: Some(r.mean_tension_n),
                        amplitude_rad: Some(r.amplitude_rad),
                        // Encoder quantisation: uniform error of one count.
                        noise_sigma: ENCODER_RESOLUTION_RAD / 12f64.sqrt(),
                    })
                })
                .collect::<Result<Vec<_>, String>>()?,
            DatasetKind::Relaxation(rx) => rx
                .runs
                .iter()
                .map(|r| RunData::tension_run(&r.name, &r.time_s, &r.tension_n))
                .collect(),
            DatasetKind::Cyclic(cy) => cy
                .runs
                .iter()
                .map(|r| RunData::tension_run(&r.name, &r.time_s, &r.tension_n))
                .collect(),
        };
        Ok(Self {
            ds,
            kind: data_kind(ds),
            runs,
            substeps: sim::SWEEP_SUBSTEPS,
        })
    }

    /// Simulates `model` on every run (in parallel, results in run order); returns the
    /// compared channel at every sample.
    pub fn simulate(&self, model: &Model) -> Result<Vec<Vec<f64>>, String> {
        (0..self.runs.len())
            .into_par_iter()
            .map(|r| self.simulate_run(model, r))
            .collect()
    }

    /// Simulates `model` on run `r`.
    pub fn simulate_run(&self, model: &Model, r: usize) -> Result<Vec<f64>, String> {
        let (law, damping) = model.law_for_run(r)?;
        let out = match &self.ds.kind {
            DatasetKind::SineSweep(sw) => {
                let run = &sw.runs[r];
                let mut spec = sim::drive_rig(&sw.rig, law, run.mean_tension_n);
                if let Some(c) = damping {
                    spec.output_damping_n_m_s = c;
                }
                let effects = model.plant_effects_for_run(r)?;
                sim::simulate_sweep(
                    spec,
                    &effects,
                    sim::drive_input(run),
                    run.dt_s(),
                    self.substeps,
                )
                .map(|s| s.output_rad)
            }
            DatasetKind::Relaxation(rx) => {
                sim::simulate_relaxation(&law, rx.specimen.strain, &rx.runs[r].time_s)
            }
            DatasetKind::Cyclic(cy) => {
                sim::simulate_cyclic(&law, &cy.runs[r].time_s, &cy.runs[r].strain)
            }
        };
        out.map_err(|e| format!("run {}: {e}", self.runs[r].name))
    }

    /// Residuals (model - measured) over the analysed samples of every run, concatenated.
    pub fn residuals_of(&self, sims: &[Vec<f64>]) -> Vec<f64> {
        let mut out = Vec::new();
        for (run, y) in self.runs.iter().zip(sims) {
            out.extend(run.idx.iter().map(|&i| y[i] - run.measured[i]));
        }
        out
    }

    /// Per-run `(SSE, SST, n)` over the analysed samples.
    pub fn sums(&self, sims: &[Vec<f64>]) -> Vec<(f64, f64, usize)> {
        self.runs
            .iter()
            .zip(sims)
            .map(|(run, y)| {
                let n = run.idx.len();
                let mean = run.idx.iter().map(|&i| run.measured[i]).sum::<f64>() / n.max(1) as f64;
                let sse = run
                    .idx
                    .iter()
                    .map(|&i| (y[i] - run.measured[i]).powi(2))
                    .sum();
                let sst = run
                    .idx
                    .iter()
                    .map(|&i| (run.measured[i] - mean).powi(2))
                    .sum();
                (sse, sst, n)
            })
            .collect()
    }

    /// Overall NRMSE `sqrt(sum SSE / sum SST)` and the noise floor on the same scale.
    pub fn overall(&self, sims: &[Vec<f64>]) -> (f64, f64) {
        let sums = self.sums(sims);
        let sse: f64 = sums.iter().map(|s| s.0).sum();
        let sst: f64 = sums.iter().map(|s| s.1).sum();
        let floor: f64 = self
            .runs
            .iter()
            .zip(&sums)
            .map(|(r, s)| r.noise_sigma.powi(2) * s.2 as f64)
            .sum();
        ((sse / sst).sqrt(), (floor / sst).sqrt())
    }

    /// Total analysed samples.
    pub fn n_samples(&self) -> usize {
        self.runs.iter().map(|r| r.idx.len()).sum()
    }
}

fn dt_of(t: &[f64]) -> f64 {
    if t.len() < 2 {
        1.0
    } else {
        (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
    }
}

struct Problem<'p, 'a> {
    prep: &'p Prepared<'a>,
    model: &'p Model,
}

impl Residuals for Problem<'_, '_> {
    fn residuals(&self, params: &[f64], out: &mut Vec<f64>) -> Result<(), String> {
        let m = self.model.with_values(params, self.prep.runs.len());
        let sims = self.prep.simulate(&m)?;
        *out = self.prep.residuals_of(&sims);
        Ok(())
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
    fn eval(&self, x: &[f64], out: &mut Vec<f64>) -> Result<(), String> {
        let DatasetKind::SineSweep(sw) = &self.prep.ds.kind else {
            return Err("not a sweep".into());
        };
        let m = self.model.with_values(x, self.prep.runs.len());
        let specs: Vec<longreach_drive::RigSpec> = (0..self.prep.runs.len())
            .map(|r| {
                let (law, damping) = m.law_for_run(r)?;
                let mut spec = sim::drive_rig(&sw.rig, law, sw.runs[r].mean_tension_n);
                if let Some(c) = damping {
                    spec.output_damping_n_m_s = c;
                }
                Ok(spec)
            })
            .collect::<Result<_, String>>()?;
        out.clear();
        for &(r, f, h) in &self.points {
            let d = (longreach_drive::rig_transfer(&specs[r], f) / h).ln();
            out.push(d.re);
            out.push(d.im);
        }
        Ok(())
    }
}

impl Residuals for FrfProblem<'_, '_> {
    fn residuals(&self, params: &[f64], out: &mut Vec<f64>) -> Result<(), String> {
        self.eval(params, out)
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
) -> Result<Vec<Vec<f64>>, String> {
    let specs = model.fit_specs(prep.runs.len());
    let mut x0: Vec<f64> = specs.iter().map(|s| s.initial).collect();
    let slots = model.free_slots(prep.runs.len());
    let gridded: Vec<usize> = (0..specs.len())
        .filter(|&i| {
            matches!(slots[i].owner, crate::model::Owner::Effect(_))
                || (prep.kind == DataKind::SineSweep && specs[i].name == "k1_scale")
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
            let span = s.upper - s.lower;
            s.initial = v.clamp(s.lower + 1e-6 * span, s.upper - 1e-6 * span);
        }
        if let Ok(r) = fit(
            &problem,
            &s2,
            &FitOptions {
                tolerance: 1e-8,
                gtol: 1e-10,
                patience: 60,
                diff_step: 1e-6,
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
                    .map(|s| prep.residuals_of(&s).iter().map(|v| v * v).sum::<f64>())
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
                    .map(|s| prep.residuals_of(&s).iter().map(|v| v * v).sum::<f64>())
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
/// start; the best start is returned with `fit = None`. [`diagnose`] uses it for the
/// candidates when the baseline already fits to the noise floor: no candidate can be
/// decisive then, and the time-domain fits (of a non-linear law above all) are the
/// dearest part of a diagnosis.
pub fn screen_model(prep: &Prepared<'_>, model: &Model) -> Result<Fitted, String> {
    let starts = starting_values(prep, model, false)?;
    let scored: Vec<Result<(Model, Vec<Vec<f64>>, f64), String>> = starts
        .par_iter()
        .map(|x| {
            let m = model.with_values(x, prep.runs.len());
            let sims = prep.simulate(&m)?;
            let ssr = prep.residuals_of(&sims).iter().map(|e| e * e).sum();
            Ok((m, sims, ssr))
        })
        .collect();
    let (fitted_model, sims, ssr) = scored
        .into_iter()
        .filter_map(Result::ok)
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .ok_or_else(|| "every start failed to simulate".to_string())?;
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

/// Fits the free parameters of `model` to the dataset.
pub fn fit_model(prep: &Prepared<'_>, model: &Model) -> Result<Fitted, String> {
    let sims0 = prep.simulate(model)?;
    let (nrmse_before, noise_floor) = prep.overall(&sims0);
    let starts = starting_values(prep, model, true)?;
    let mut best: Option<(Model, Option<FitResult>, f64)> = None;
    for start in &starts {
        let model_start = model.with_values(start, prep.runs.len());
        let model = &model_start;
        let specs = model.fit_specs(prep.runs.len());
        let expensive = prep.kind == DataKind::SineSweep
            && model.law_for_run(0).is_ok_and(|(l, _)| !l.is_linear());
        let (fitted_model, fit_res) = if specs.is_empty() {
            (model.clone(), None)
        } else {
            let opts = FitOptions {
                tolerance: 1e-5,
                gtol: 1e-7,
                // A non-linear rope law makes every rig simulation ~50x dearer; the
                // analytic-response start is already close, so fewer refinement steps.
                patience: if expensive { 3 } else { 25 },
                diff_step: 1e-5,
            };
            let problem = Problem { prep, model };
            match fit(&problem, &specs, &opts) {
                Ok(r) => (model.with_values(&r.values, prep.runs.len()), Some(r)),
                Err(e) if best.is_none() && starts.len() == 1 => return Err(e.to_string()),
                Err(_) => continue,
            }
        };
        let ssr = fit_res.as_ref().map_or(f64::INFINITY, |r| r.ssr);
        if best.as_ref().is_none_or(|b| ssr < b.2) {
            best = Some((fitted_model, fit_res, ssr));
        }
    }
    let (fitted_model, fit_res, _) =
        best.ok_or_else(|| "every fit from the starting grid failed".to_string())?;
    let sims = prep.simulate(&fitted_model)?;
    let (nrmse, _) = prep.overall(&sims);
    let ssr = prep.residuals_of(&sims).iter().map(|e| e * e).sum();
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

/// NRMSE of one run.
#[derive(Debug, Clone, Serialize)]
pub struct RunError {
    /// Run name.
    pub run: String,
    /// Mean tension [N] (sweeps).
    pub mean_tension_n: Option<f64>,
    /// Input amplitude [rad] (sweeps).
    pub amplitude_rad: Option<f64>,
    /// NRMSE of the compared channel.
    pub nrmse: f64,
    /// Noise floor of this run on the NRMSE scale.
    pub noise_floor_nrmse: f64,
    /// Share of the dataset's squared error.
    pub share: f64,
}

/// Measured vs model frequency response at one test frequency of one run.
#[derive(Debug, Clone, Serialize)]
pub struct FrequencyError {
    /// Run name.
    pub run: String,
    /// Test frequency [Hz].
    pub frequency_hz: f64,
    /// Measured gain [dB].
    pub gain_measured_db: f64,
    /// Model gain [dB].
    pub gain_model_db: f64,
    /// Model minus measured [dB].
    pub gain_error_db: f64,
    /// Measured phase [deg].
    pub phase_measured_deg: f64,
    /// Model phase [deg].
    pub phase_model_deg: f64,
    /// Model minus measured, wrapped to (-180, 180] [deg].
    pub phase_error_deg: f64,
    /// Share of the dataset's squared error in this step's analysis window.
    pub share: f64,
}

/// A place where the error concentrates.
#[derive(Debug, Clone, Serialize)]
pub struct Where {
    /// Run name.
    pub run: String,
    /// Test frequency [Hz] (sweeps), null otherwise.
    pub frequency_hz: Option<f64>,
    /// Start of the window [s].
    pub start_s: f64,
    /// End of the window [s].
    pub end_s: f64,
    /// Share of the dataset's squared error.
    pub share: f64,
}

/// Residual checks.
#[derive(Debug, Clone, Serialize)]
pub struct ResidualChecks {
    /// Ljung-Box Q of the residual (decimated to at most 4000 samples, 20 lags).
    pub ljung_box_q: f64,
    /// Its p-value (small: the residual is not white).
    pub ljung_box_p: f64,
    /// Correlation of the residual with the input angle (sweeps) or time (others).
    pub corr_input: f64,
    /// Correlation of the residual with the sign of the measured velocity.
    pub corr_velocity_sign: f64,
    /// Correlation of each run's RMS error with its mean tension (sweeps, >= 3 runs).
    pub corr_mean_tension: Option<f64>,
    /// Largest residual amplitude at 2f over the measured output at f (sweeps).
    pub harmonic_2f: f64,
    /// Same at 3f.
    pub harmonic_3f: f64,
    /// Correlation of the residual with time (drift).
    pub corr_time: f64,
}

/// Resonance of one run, measured and model.
#[derive(Debug, Clone, Serialize)]
pub struct RunResonance {
    /// Run name.
    pub run: String,
    /// Mean tension [N].
    pub mean_tension_n: f64,
    /// Input amplitude [rad].
    pub amplitude_rad: f64,
    /// Measured resonance [Hz] (peak of the gain, interpolated).
    pub measured_hz: Option<f64>,
    /// Model resonance [Hz].
    pub model_hz: Option<f64>,
    /// Measured peak gain [dB].
    pub measured_peak_db: Option<f64>,
    /// Model peak gain [dB].
    pub model_peak_db: Option<f64>,
}

/// Everything `compare` reports.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// Dataset title.
    pub dataset: String,
    /// Dataset kind.
    pub kind: String,
    /// Model parameters.
    pub params: std::collections::BTreeMap<String, f64>,
    /// Effects in the model.
    pub effects: Vec<String>,
    /// Overall NRMSE.
    pub nrmse: f64,
    /// Noise floor on the NRMSE scale.
    pub noise_floor_nrmse: f64,
    /// Per run.
    pub runs: Vec<RunError>,
    /// Per test frequency (sweeps).
    pub frequency: Vec<FrequencyError>,
    /// Where the squared error concentrates (largest share first).
    #[serde(rename = "where")]
    pub where_: Vec<Where>,
    /// Worst 2-second windows (largest share first).
    pub worst_windows: Vec<Where>,
    /// Residual checks.
    pub residual: ResidualChecks,
    /// Resonances (sweeps).
    pub resonance: Vec<RunResonance>,
}

/// Compares a (fitted) model with the dataset; `sims` are its simulations.
pub fn compare(
    prep: &Prepared<'_>,
    model: &Model,
    sims: &[Vec<f64>],
) -> Result<Comparison, String> {
    let e = |x: metrics::MetricsError| x.to_string();
    let sums = prep.sums(sims);
    let total_sse: f64 = sums.iter().map(|s| s.0).sum::<f64>().max(f64::MIN_POSITIVE);
    let (nrmse, floor) = prep.overall(sims);
    let runs: Vec<RunError> = prep
        .runs
        .iter()
        .zip(&sums)
        .map(|(r, s)| RunError {
            run: r.name.clone(),
            mean_tension_n: r.mean_tension_n,
            amplitude_rad: r.amplitude_rad,
            nrmse: (s.0 / s.1).sqrt(),
            noise_floor_nrmse: r.noise_sigma * (s.2 as f64 / s.1).sqrt(),
            share: s.0 / total_sse,
        })
        .collect();
    let mut frequency = Vec::new();
    let mut places = Vec::new();
    let mut resonance = Vec::new();
    let mut h2: f64 = 0.0;
    let mut h3: f64 = 0.0;
    let inputs: Vec<&[f64]> = match &prep.ds.kind {
        DatasetKind::SineSweep(sw) => sw.runs.iter().map(sim::drive_input).collect(),
        _ => Vec::new(),
    };
    for (ri, (run, y)) in prep.runs.iter().zip(sims).enumerate() {
        if run.segments.is_empty() {
            // time windows of 10% of the run
            let n = run.measured.len();
            let w = (n / 10).max(1);
            let mut a = 0;
            while a < n {
                let b = (a + w).min(n);
                let sse: f64 = (a..b).map(|i| (y[i] - run.measured[i]).powi(2)).sum();
                places.push(Where {
                    run: run.name.clone(),
                    frequency_hz: None,
                    start_s: run.time_s[a],
                    end_s: run.time_s[b - 1],
                    share: sse / total_sse,
                });
                a = b;
            }
            continue;
        }
        let input = inputs[ri];
        let mut meas_pts = Vec::new();
        let mut model_pts = Vec::new();
        for &(f, a, b) in &run.segments {
            let x = dft(&input[a..b], run.dt_s, f);
            let ym = dft(&run.measured[a..b], run.dt_s, f);
            let yy = dft(&y[a..b], run.dt_s, f);
            let (hm, hy) = (ym / x, yy / x);
            let sse: f64 = (a..b).map(|i| (y[i] - run.measured[i]).powi(2)).sum();
            let gm = 20.0 * hm.norm().log10();
            let gy = 20.0 * hy.norm().log10();
            let pm = hm.arg().to_degrees();
            let py = hy.arg().to_degrees();
            frequency.push(FrequencyError {
                run: run.name.clone(),
                frequency_hz: f,
                gain_measured_db: gm,
                gain_model_db: gy,
                gain_error_db: gy - gm,
                phase_measured_deg: pm,
                phase_model_deg: py,
                phase_error_deg: metrics::wrap_phase_deg(py - pm),
                share: sse / total_sse,
            });
            places.push(Where {
                run: run.name.clone(),
                frequency_hz: Some(f),
                start_s: run.time_s[a],
                end_s: run.time_s[b - 1],
                share: sse / total_sse,
            });
            meas_pts.push((f, gm));
            model_pts.push((f, gy));
            if 3.0 * f < 0.5 / run.dt_s {
                let res: Vec<f64> = (a..b).map(|i| y[i] - run.measured[i]).collect();
                if let Ok(h) = metrics::harmonic_ratios(&res, &run.measured[a..b], run.dt_s, f) {
                    h2 = h2.max(h.second_ratio);
                    h3 = h3.max(h.third_ratio);
                }
            }
        }
        let (mf, mp) = peak(&meas_pts).unzip();
        let (yf, yp) = peak(&model_pts).unzip();
        resonance.push(RunResonance {
            run: run.name.clone(),
            mean_tension_n: run.mean_tension_n.unwrap_or(f64::NAN),
            amplitude_rad: run.amplitude_rad.unwrap_or(f64::NAN),
            measured_hz: mf,
            model_hz: yf,
            measured_peak_db: mp,
            model_peak_db: yp,
        });
    }
    places.sort_by(|a, b| b.share.total_cmp(&a.share));
    // worst windows of 2 s across runs
    let mut windows = Vec::new();
    for (run, y) in prep.runs.iter().zip(sims) {
        let err: Vec<f64> = (0..run.measured.len())
            .map(|i| y[i] - run.measured[i])
            .collect();
        let all: f64 = err.iter().map(|v| v * v).sum();
        let scale = all / total_sse.max(f64::MIN_POSITIVE);
        let ws = metrics::worst_windows(
            &err,
            run.dt_s,
            2.0_f64
                .min(run.time_s.last().copied().unwrap_or(1.0) / 5.0)
                .max(run.dt_s),
            3,
        )
        .map_err(e)?;
        for w in ws {
            windows.push(Where {
                run: run.name.clone(),
                frequency_hz: None,
                start_s: run.time_s[w.start_index],
                end_s: run.time_s[w.end_index - 1],
                share: w.share * scale,
            });
        }
    }
    windows.sort_by(|a, b| b.share.total_cmp(&a.share));
    windows.truncate(5);
    // residual checks over the analysed samples
    let res = prep.residuals_of(sims);
    let mut inp = Vec::new();
    let mut vel = Vec::new();
    let mut time = Vec::new();
    for (ri, run) in prep.runs.iter().enumerate() {
        for &i in &run.idx {
            let x = if inputs.is_empty() {
                run.time_s[i]
            } else {
                inputs[ri][i]
            };
            inp.push(x);
            let (a, b) = (i.saturating_sub(1), (i + 1).min(run.measured.len() - 1));
            vel.push(run.measured[b] - run.measured[a]);
            time.push(run.time_s[i]);
        }
    }
    let step = (res.len() / 4000).max(1);
    let dec: Vec<f64> = res.iter().step_by(step).copied().collect();
    let lb = metrics::ljung_box(&dec, 20.min(dec.len().saturating_sub(3)).max(1), 0).ok();
    let corr = |x: &[f64]| metrics::pearson(&res, x).unwrap_or(0.0);
    let corr_mean_tension = if prep.runs.len() >= 3 && prep.kind == DataKind::SineSweep {
        let t: Vec<f64> = prep
            .runs
            .iter()
            .map(|r| r.mean_tension_n.unwrap_or(0.0))
            .collect();
        let rmse: Vec<f64> = sums.iter().map(|s| (s.0 / s.2 as f64).sqrt()).collect();
        metrics::pearson(&t, &rmse).ok()
    } else {
        None
    };
    let residual = ResidualChecks {
        ljung_box_q: lb.map_or(f64::NAN, |l| l.q),
        ljung_box_p: lb.map_or(f64::NAN, |l| l.p_value),
        corr_input: corr(&inp),
        corr_velocity_sign: corr(&metrics::signum_series(&vel)),
        corr_mean_tension,
        harmonic_2f: h2,
        harmonic_3f: h3,
        corr_time: corr(&time),
    };
    Ok(Comparison {
        dataset: prep.ds.title.clone(),
        kind: prep.ds.kind.name().to_string(),
        params: model.named_values().into_iter().collect(),
        effects: model
            .effects
            .iter()
            .map(|u| u.effect.name().to_string())
            .collect(),
        nrmse,
        noise_floor_nrmse: floor,
        runs,
        frequency,
        where_: places.into_iter().take(10).collect(),
        worst_windows: windows,
        residual,
        resonance,
    })
}

/// Sine-phase single-bin DFT (see [`metrics::single_bin_dft`]) without allocation checks.
fn dft(x: &[f64], dt_s: f64, f: f64) -> Complex64 {
    metrics::single_bin_dft(x, dt_s, f).unwrap_or_default()
}

/// Peak of a gain curve `(f, dB)`: the largest point refined by a parabola in
/// `(ln f, dB)` through its neighbours. `None` at an end of the range.
fn peak(pts: &[(f64, f64)]) -> Option<(f64, f64)> {
    let (k, _) = pts
        .iter()
        .enumerate()
        .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1))?;
    if k == 0 || k + 1 >= pts.len() {
        return None;
    }
    let (x0, x1, x2) = (pts[k - 1].0.ln(), pts[k].0.ln(), pts[k + 1].0.ln());
    let (y0, y1, y2) = (pts[k - 1].1, pts[k].1, pts[k + 1].1);
    let d1 = (y1 - y0) / (x1 - x0);
    let d2 = (y2 - y1) / (x2 - x1);
    let a = (d2 - d1) / (x2 - x0);
    if a >= 0.0 {
        return Some((pts[k].0, y1));
    }
    let b = d1 - a * (x0 + x1);
    let xm = (-b / (2.0 * a)).clamp(x0, x2);
    let ym = y1 + (xm - x1) * (b + a * (xm + x1));
    Some((xm.exp(), ym))
}

/// One candidate effect of a diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// Effect name.
    pub effect: String,
    /// NRMSE of baseline + effect, fitted (or screened, see `screened`).
    pub nrmse: f64,
    /// Score: BIC improvement over the baseline, `n ln(SSR_b / SSR_c) - dk ln n`.
    pub score: f64,
    /// Share of the baseline's excess squared error (above the noise floor) explained.
    pub explained: f64,
    /// Fitted parameters (baseline's and the effect's).
    pub params: std::collections::BTreeMap<String, f64>,
    /// True for the winner when the evidence is decisive.
    pub decisive: bool,
    /// True when the candidate was only screened ([`screen_model`]: its starting values,
    /// one simulation) because the baseline already fits to the noise floor.
    pub screened: bool,
    /// Why the fit failed, if it did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The baseline part of a diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct BaselineSummary {
    /// NRMSE after fitting.
    pub nrmse: f64,
    /// Noise floor on the NRMSE scale.
    pub noise_floor_nrmse: f64,
    /// Fitted parameters.
    pub params: std::collections::BTreeMap<String, f64>,
    /// Their standard errors.
    pub std_errors: std::collections::BTreeMap<String, f64>,
}

/// The result of `diagnose`.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// Dataset title.
    pub dataset: String,
    /// Baseline.
    pub baseline: BaselineSummary,
    /// Where the baseline fails.
    #[serde(rename = "where")]
    pub where_: Vec<Where>,
    /// Candidates, best first.
    pub candidates: Vec<Candidate>,
    /// The missing effect when decisive.
    pub missing_effect: Option<String>,
    /// The verdict in words.
    pub explanation: String,
    /// The baseline's comparison (residual checks, resonances).
    pub comparison: Comparison,
    /// NRMSE of the model with the winning effect (null when none).
    pub nrmse_after: Option<f64>,
}

/// Fraction of the baseline's excess squared error a decisive winner must explain.
pub const MIN_EXPLAINED: f64 = 0.5;
/// Baseline NRMSE above this multiple of the noise floor is a failure worth diagnosing
/// (the squared error 10% above the floor: beyond the floor estimate's own scatter,
/// ~2% for a few thousand samples, and the sweep simulation's time-step error, ~2% of
/// the floor's squared error at 2.5 ms; see `docs/models.md`).
pub const FLOOR_MARGIN: f64 = 1.05;
/// Least score (BIC improvement over the baseline) of a decisive winner: "very strong"
/// evidence on the scale of Kass and Raftery (1995), `2 ln B > 10`.
pub const MIN_SCORE: f64 = 10.0;
/// Least score lead of a decisive winner over the second candidate beyond one
/// parameter's BIC penalty `ln n` (n: analysed samples): two effects that fit equally
/// well differ by their parameter counts alone, `ln n` per parameter; the data must
/// favour the winner "very strongly" over the next explanation, not only over the
/// baseline.
pub const MIN_SCORE_GAP: f64 = 10.0;

/// Fits the baseline and every applicable registered effect; ranks and decides.
/// Returns the diagnosis and the winning model (if any).
pub fn diagnose(
    prep: &Prepared<'_>,
    model: &Model,
) -> Result<(Diagnosis, Fitted, Option<Fitted>), String> {
    let base = fit_model(prep, model)?;
    let cmp = compare(prep, &base.model, &base.sims)?;
    let n = prep.n_samples() as f64;
    let k_base = base.model.fit_specs(prep.runs.len()).len();
    let ssr_floor = prep
        .runs
        .iter()
        .map(|r| r.noise_sigma.powi(2) * r.idx.len() as f64)
        .sum::<f64>();
    let effects: Vec<_> = REGISTRY
        .iter()
        .copied()
        .filter(|e| e.applies_to(prep.kind) && !base.model.has_effect(*e))
        .collect();
    // At the noise floor no candidate can be decisive: screen them (starting values,
    // one simulation each) instead of fitting them in the time domain.
    let at_floor = base.nrmse <= FLOOR_MARGIN * base.noise_floor;
    let fits: Vec<(String, Result<Fitted, String>)> = effects
        .par_iter()
        .map(|e| {
            let m = base.model.with_effect(*e);
            let f = if at_floor {
                screen_model(prep, &m)
            } else {
                fit_model(prep, &m)
            };
            (e.name().to_string(), f)
        })
        .collect();
    let excess = (base.ssr - ssr_floor).max(0.0);
    let mut cands: Vec<(Candidate, Option<Fitted>)> = fits
        .into_iter()
        .map(|(name, r)| match r {
            Ok(f) => {
                let dk = f
                    .model
                    .fit_specs(prep.runs.len())
                    .len()
                    .saturating_sub(k_base) as f64;
                let ssr_c = f.ssr.min(base.ssr);
                let score = n * (base.ssr / ssr_c.max(f64::MIN_POSITIVE)).ln() - dk * n.ln();
                let explained = if excess > 0.0 {
                    (base.ssr - ssr_c) / excess
                } else {
                    0.0
                };
                (
                    Candidate {
                        effect: name,
                        nrmse: f.nrmse,
                        score,
                        explained: explained.min(1.5),
                        params: f.model.named_values().into_iter().collect(),
                        decisive: false,
                        screened: at_floor,
                        error: None,
                    },
                    Some(f),
                )
            }
            Err(err) => (
                Candidate {
                    effect: name,
                    nrmse: f64::NAN,
                    score: f64::NEG_INFINITY,
                    explained: 0.0,
                    params: Default::default(),
                    decisive: false,
                    screened: at_floor,
                    error: Some(err),
                },
                None,
            ),
        })
        .collect();
    cands.sort_by(|a, b| {
        b.0.score
            .total_cmp(&a.0.score)
            .then(a.0.effect.cmp(&b.0.effect))
    });
    let decisive = !at_floor
        && cands.first().is_some_and(|(best, fit)| {
            let gap = cands
                .get(1)
                .map_or(f64::INFINITY, |(second, _)| best.score - second.score);
            // The winner reaches the floor, or leaves at most half the excess the
            // second leaves: a lead in score between two candidates that both stop far
            // above the floor may be a fit that stopped early, not evidence.
            let best_ssr = fit.as_ref().map_or(f64::INFINITY, |f| f.ssr);
            let reaches_floor = best_ssr <= FLOOR_MARGIN * FLOOR_MARGIN * ssr_floor;
            let second_left = cands
                .get(1)
                .and_then(|(_, f)| f.as_ref())
                .map_or(base.ssr, |f| f.ssr.min(base.ssr));
            let separated = second_left - ssr_floor >= 2.0 * (best_ssr - ssr_floor).max(0.0);
            best.explained >= MIN_EXPLAINED
                && best.score > MIN_SCORE
                && gap >= MIN_SCORE_GAP + n.ln()
                && (reaches_floor || separated)
        });
    let mut winner = None;
    if decisive {
        cands[0].0.decisive = true;
        winner = cands[0].1.take();
    }
    let missing = decisive.then(|| cands[0].0.effect.clone());
    let explanation = explain(
        prep,
        &base,
        &cmp,
        &cands.iter().map(|c| c.0.clone()).collect::<Vec<_>>(),
        missing.as_deref(),
        at_floor,
    );
    let diag = Diagnosis {
        dataset: prep.ds.title.clone(),
        baseline: BaselineSummary {
            nrmse: base.nrmse,
            noise_floor_nrmse: base.noise_floor,
            params: base.model.named_values().into_iter().collect(),
            std_errors: base
                .fit
                .as_ref()
                .map(|f| {
                    f.names
                        .iter()
                        .cloned()
                        .zip(f.std_errors.iter().copied())
                        .collect()
                })
                .unwrap_or_default(),
        },
        where_: cmp.where_.clone(),
        candidates: cands.iter().map(|c| c.0.clone()).collect(),
        missing_effect: missing,
        nrmse_after: winner.as_ref().map(|w: &Fitted| w.nrmse),
        explanation,
        comparison: cmp,
    };
    Ok((diag, base, winner))
}

fn explain(
    prep: &Prepared<'_>,
    base: &Fitted,
    cmp: &Comparison,
    cands: &[Candidate],
    missing: Option<&str>,
    at_floor: bool,
) -> String {
    let mut s = String::new();
    let ratio = base.nrmse / base.noise_floor.max(f64::MIN_POSITIVE);
    if at_floor {
        s.push_str(&format!(
            "The baseline fits to the noise floor (NRMSE {:.4}, {:.2}x the floor {:.4} of the sensors): no missing effect is needed; none found (the candidates were screened at their starting values, not fitted).",
            base.nrmse, ratio, base.noise_floor
        ));
        return s;
    }
    s.push_str(&format!(
        "The baseline misses the data: NRMSE {:.4} is {:.1}x the noise floor {:.4}. ",
        base.nrmse, ratio, base.noise_floor
    ));
    if let Some(w) = cmp.where_.first() {
        match w.frequency_hz {
            Some(f) => s.push_str(&format!(
                "The largest share of the error ({:.0}%) is in run {} at {:.2} Hz. ",
                100.0 * w.share,
                w.run,
                f
            )),
            None => s.push_str(&format!(
                "The largest share of the error ({:.0}%) is in run {} between {:.1} and {:.1} s. ",
                100.0 * w.share,
                w.run,
                w.start_s,
                w.end_s
            )),
        }
    }
    // Evidence from the data, by kind.
    if prep.kind == DataKind::SineSweep {
        let mut res: Vec<&RunResonance> = cmp
            .resonance
            .iter()
            .filter(|r| r.measured_hz.is_some() && r.model_hz.is_some())
            .collect();
        res.sort_by(|a, b| a.mean_tension_n.total_cmp(&b.mean_tension_n));
        if let (Some(lo), Some(hi)) = (res.first(), res.last()) {
            if hi.mean_tension_n > lo.mean_tension_n {
                let (ml, mh) = (lo.measured_hz.unwrap_or(0.0), hi.measured_hz.unwrap_or(0.0));
                let (yl, yh) = (lo.model_hz.unwrap_or(0.0), hi.model_hz.unwrap_or(0.0));
                s.push_str(&format!(
                    "The measured resonance moves from {ml:.2} to {mh:.2} Hz between {:.0} and {:.0} N while the model goes from {yl:.2} to {yh:.2} Hz",
                    lo.mean_tension_n, hi.mean_tension_n
                ));
                let moved = (mh / ml).ln() - (yh / yl).ln();
                if moved > 0.03 {
                    s.push_str(": the rope's stiffness depends on its tension. ");
                } else {
                    s.push_str(". ");
                }
                let dpk: f64 = res
                    .iter()
                    .map(|r| r.model_peak_db.unwrap_or(0.0) - r.measured_peak_db.unwrap_or(0.0))
                    .sum::<f64>()
                    / res.len() as f64;
                if dpk.abs() > 1.0 {
                    s.push_str(&format!(
                        "The model's resonance peak is {:.1} dB {} than measured on average{}. ",
                        dpk.abs(),
                        if dpk > 0.0 { "higher" } else { "lower" },
                        if dpk > 0.0 {
                            ": the rope dissipates more than the model"
                        } else {
                            ""
                        }
                    ));
                }
            }
        }
    } else {
        let r = &cmp.residual;
        s.push_str(&format!(
            "The residual correlates with time at {:.2} (drift) and is {}white (Ljung-Box p = {:.2e}). ",
            r.corr_time,
            if r.ljung_box_p < 0.05 { "not " } else { "" },
            r.ljung_box_p
        ));
    }
    match (missing, cands.first()) {
        (Some(m), Some(best)) => {
            let after = best.nrmse;
            s.push_str(&format!(
                "Adding {m} explains {:.0}% of the excess error and brings the NRMSE from {:.4} to {:.4} ({:.1}x lower); ",
                100.0 * best.explained.min(1.0),
                base.nrmse,
                after,
                base.nrmse / after.max(f64::MIN_POSITIVE)
            ));
            if let Some(second) = cands.get(1) {
                s.push_str(&format!(
                    "the next best, {}, explains {:.0}%.",
                    second.effect,
                    100.0 * second.explained.clamp(0.0, 1.0)
                ));
            }
        }
        (_, best) => {
            if let Some(b) = best {
                s.push_str(&format!(
                    "No registered effect explains the failure decisively (best: {}, explaining {:.0}% of the excess error). ",
                    b.effect,
                    100.0 * b.explained.clamp(0.0, 1.0)
                ));
                if let Some(second) = cands.get(1) {
                    if b.explained >= MIN_EXPLAINED && second.explained >= MIN_EXPLAINED {
                        s.push_str(&format!(
                            "{} and {} both explain it (scores {:.1} and {:.1}): these data cannot tell them apart (a test of another kind or frequency range can; see docs/models.md). ",
                            b.effect, second.effect, b.score, second.score
                        ));
                    }
                }
            } else {
                s.push_str("No registered effect applies to this kind of data. ");
            }
            s.push_str(&signature(cmp));
        }
    }
    s
}

/// A description of the residual's signature.
fn signature(cmp: &Comparison) -> String {
    let mut parts = Vec::new();
    let r = &cmp.residual;
    if cmp.frequency.len() >= 4 {
        // phase error vs frequency: proportional growth means a pure delay
        let (f, p): (Vec<f64>, Vec<f64>) = cmp
            .frequency
            .iter()
            .map(|x| (x.frequency_hz, x.phase_error_deg))
            .unzip();
        if let Ok(c) = metrics::pearson(&f, &p) {
            if c.abs() > 0.8 {
                parts.push(format!("phase error grows with frequency (correlation {c:.2}): a delay or missing dissipation"));
            }
        }
    }
    if let Some(c) = r.corr_mean_tension {
        if c.abs() > 0.7 {
            parts.push(format!(
                "error {} with mean tension (correlation {c:.2})",
                if c > 0.0 { "grows" } else { "falls" }
            ));
        }
    }
    if r.corr_velocity_sign.abs() > 0.2 {
        parts.push(format!(
            "residual follows the sign of the velocity ({:.2}): friction",
            r.corr_velocity_sign
        ));
    }
    if r.harmonic_2f > 0.02 || r.harmonic_3f > 0.02 {
        parts.push(format!(
            "harmonics in the residual (2f: {:.1}%, 3f: {:.1}%): a non-linearity",
            100.0 * r.harmonic_2f,
            100.0 * r.harmonic_3f
        ));
    }
    if r.corr_time.abs() > 0.3 {
        parts.push(format!("drift over time (correlation {:.2})", r.corr_time));
    }
    let amp: Vec<&RunError> = cmp
        .runs
        .iter()
        .filter(|x| x.amplitude_rad.is_some())
        .collect();
    if amp.len() >= 2 {
        let mut by = amp.clone();
        by.sort_by(|a, b| {
            a.amplitude_rad
                .unwrap_or(0.0)
                .total_cmp(&b.amplitude_rad.unwrap_or(0.0))
        });
        let (lo, hi) = (by[0], by[by.len() - 1]);
        if hi.amplitude_rad > lo.amplitude_rad && (hi.nrmse / lo.nrmse.max(1e-12)).ln().abs() > 0.7
        {
            parts.push(format!("the error depends on the amplitude (NRMSE {:.3} at {:.3} rad vs {:.3} at {:.3} rad)", lo.nrmse, lo.amplitude_rad.unwrap_or(0.0), hi.nrmse, hi.amplitude_rad.unwrap_or(0.0)));
        }
    }
    if parts.is_empty() {
        "Residual signature: no clear pattern (white-ish, no harmonics, no drift).".into()
    } else {
        format!("Residual signature: {}.", parts.join("; "))
    }
}
