//! A dataset prepared for simulation and comparison: the compared channel, analysed
//! samples and noise floor of every run, and a model simulated on the runs.

use longreach_drive::effects::DataKind;
use rayon::prelude::*;

use crate::dataset::{Dataset, DatasetKind};
use crate::error::IdentError;
pub use crate::metrics::noise_sigma_second_difference;
use crate::model::{data_kind, Model};
use crate::plant::{plant_for, Channels, Plant};
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
#[derive(Debug)]
pub struct Prepared<'a> {
    /// The dataset.
    pub ds: &'a Dataset,
    /// Its kind.
    pub kind: DataKind,
    /// Its runs.
    pub runs: Vec<RunData>,
    /// The plant that reproduces it (sweeps simulated at [`sim::SWEEP_SUBSTEPS`]
    /// sub-steps per sample).
    pub plant: Box<dyn Plant + 'a>,
    /// Runs simulated so far through [`Self::simulate_channels`] (every simulation of
    /// fit, compare and diagnose but the sweeps' refined ones): the work of a diagnosis,
    /// whatever the machine's load.
    simulations: std::sync::atomic::AtomicUsize,
}

impl<'a> Prepared<'a> {
    /// Prepares `ds`: analysis windows and noise floors.
    pub fn new(ds: &'a Dataset) -> Result<Self, IdentError> {
        let runs = match &ds.kind {
            DatasetKind::SineSweep(sw) => sw
                .runs
                .iter()
                .map(|r| {
                    let segs = r.segments()?;
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
                .collect::<Result<Vec<_>, IdentError>>()?,
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
            // Every channel at once, each over its noise (`plant::ARM_STACKED`); the
            // samples' times repeat once per channel.
            DatasetKind::ArmMoves(am) => am
                .runs
                .iter()
                .map(|r| {
                    let w = crate::plant::stacking(r);
                    let measured = crate::plant::stack(&w, |k| r.channels[k].values.as_slice());
                    RunData {
                        name: r.name.clone(),
                        time_s: (0..w.len())
                            .flat_map(|_| r.time_s.iter().copied())
                            .collect(),
                        idx: (0..measured.len()).collect(),
                        measured,
                        segments: Vec::new(),
                        dt_s: r.dt_s(),
                        mean_tension_n: None,
                        amplitude_rad: None,
                        noise_sigma: 1.0,
                    }
                })
                .collect(),
        };
        for run in &runs {
            let n = run.idx.len();
            let first = run.idx.first().map(|&i| run.measured[i]);
            // Exactly constant (bit for bit): any variation at all gives a number.
            let varies = first.is_some_and(|f| {
                run.idx
                    .iter()
                    .any(|&i| run.measured[i].to_bits() != f.to_bits())
            });
            if !varies {
                return Err(IdentError::NoVariation {
                    dir: ds.dir.display().to_string(),
                    run: run.name.clone(),
                    channel: match &ds.kind {
                        DatasetKind::SineSweep(_) => "output_angle_rad",
                        _ => "tension_n",
                    },
                    samples: n,
                });
            }
        }
        Ok(Self {
            ds,
            kind: data_kind(ds),
            runs,
            plant: plant_for(ds, sim::SWEEP_SUBSTEPS),
            simulations: std::sync::atomic::AtomicUsize::new(0),
        })
    }

    /// Simulates `model` on every run (in parallel, results in run order); returns the
    /// compared channel at every sample.
    pub fn simulate(&self, model: &Model) -> Result<Vec<Vec<f64>>, IdentError> {
        (0..self.runs.len())
            .into_par_iter()
            .map(|r| self.simulate_run(model, r))
            .collect()
    }

    /// Simulates `model` on run `r`: the compared channel.
    pub fn simulate_run(&self, model: &Model, r: usize) -> Result<Vec<f64>, IdentError> {
        Ok(self.simulate_channels(model, r)?.into_primary())
    }

    /// Simulates `model` on run `r`: every channel the run measured.
    pub fn simulate_channels(&self, model: &Model, r: usize) -> Result<Channels, IdentError> {
        self.simulate_params(&model.plant_params(r)?, r)
    }

    /// Simulates run `r` with the plant numbers `params` (counted as
    /// [`Self::simulate_channels`] is).
    pub(crate) fn simulate_params(
        &self,
        params: &crate::model::PlantParams,
        r: usize,
    ) -> Result<Channels, IdentError> {
        self.simulations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.plant.simulate(params, r)
    }

    /// Runs simulated so far (one per run and model; see the field).
    pub fn simulations(&self) -> usize {
        self.simulations.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Residuals (model - measured) over the analysed samples of every run, concatenated.
    pub fn residuals_of(&self, sims: &[Vec<f64>]) -> Vec<f64> {
        let mut out = Vec::new();
        for (run, y) in self.runs.iter().zip(sims) {
            out.extend(run.idx.iter().map(|&i| y[i] - run.measured[i]));
        }
        out
    }

    /// Sum of squared residuals ([`Self::residuals_of`]) of the simulated channels `sims`.
    pub fn ssr(&self, sims: &[Vec<f64>]) -> f64 {
        self.residuals_of(sims).iter().map(|e| e * e).sum()
    }

    /// The error group of every residual of [`Self::residuals_of`], for the fits'
    /// uncertainties ([`crate::fitting::Residuals::error_groups`]): a sweep's analysed
    /// samples grouped by test frequency, over all runs (the encoder's quantisation error
    /// is coherent over a frequency step, and runs that see the same signal, such as a
    /// linear rope at several mean tensions, see the same error). `None` for relaxation
    /// and cyclic tests, whose tension noise is independent from sample to sample.
    pub fn error_groups(&self) -> Option<Vec<usize>> {
        if self.kind != DataKind::SineSweep {
            return None;
        }
        let mut freqs: Vec<f64> = Vec::new();
        let mut out = Vec::with_capacity(self.n_samples());
        for run in &self.runs {
            for &(f, a, b) in &run.segments {
                let id = freqs
                    .iter()
                    .position(|g| g.to_bits() == f.to_bits())
                    .unwrap_or_else(|| {
                        freqs.push(f);
                        freqs.len() - 1
                    });
                out.extend(std::iter::repeat_n(id, b - a));
            }
        }
        Some(out)
    }

    /// Simulates `model` on every run at half the time step of [`Self::simulate`], for
    /// the step-error correction of the fits' intervals
    /// ([`crate::fitting::Residuals::refined_residuals`]); `None` for data kinds whose
    /// simulation has no step error to speak of (relaxation in closed form or by the
    /// exact-hold rope step).
    pub fn simulate_refined(&self, model: &Model) -> Option<Result<Vec<Vec<f64>>, IdentError>> {
        if self.kind != DataKind::SineSweep {
            return None;
        }
        let plant = plant_for(self.ds, 2 * sim::SWEEP_SUBSTEPS);
        Some(
            (0..self.runs.len())
                .into_par_iter()
                .map(|r| Ok(plant.simulate(&model.plant_params(r)?, r)?.into_primary()))
                .collect(),
        )
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
