//! A dataset prepared for simulation and comparison: the compared channels, analysed
//! samples and noise floors of every run, and a model simulated on the runs.
//!
//! Every channel a run measured enters: the primary one (a sweep's output angle, a
//! specimen's tension, an arm's [`crate::plant::ARM_STACKED`]) and, for sweeps, the rope
//! tensions the run recorded ([`RunData::channels`]). As the arm plant stacks its
//! channels, each channel's residual is divided by its own noise standard deviation
//! and the results are concatenated, so the stacked residual is dimensionless and white
//! noise gives every channel the same weight per sample; the stack is then multiplied
//! by the primary channel's noise (the primary's weight is exactly 1), which keeps a
//! dataset with the primary channel alone bit for bit where it was, and keeps sums of
//! squares, RMS errors and the noise floor in the primary's unit (the floor's SSR is
//! `sigma_primary^2` per stacked residual).

use longreach_drive::effects::DataKind;
use rayon::prelude::*;

use crate::dataset::{Dataset, DatasetKind};
use crate::error::IdentError;
pub use crate::metrics::noise_sigma_second_difference;
use crate::model::{data_kind, Model};
use crate::plant::{arm_plant_for, plant_for, Channels, Plant};
use crate::sensors::ENCODER_RESOLUTION_RAD;
use crate::sim;

/// A further measured channel of a run (a sweep's rope tension), compared with the
/// plant's channel of the same name over the run's analysed samples.
#[derive(Debug, Clone)]
pub struct ChannelData {
    /// Column name (`tension_in_1_n`, ...).
    pub name: &'static str,
    /// Measured values, all samples.
    pub values: Vec<f64>,
    /// Noise standard deviation (second differences of the measurement) [N].
    pub noise_sigma: f64,
}

/// One run prepared for comparison: the compared channels and the analysed samples.
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
    /// The further measured channels, in the order they are stacked after the primary
    /// one (a sweep's tensions: `tension_in_1_n`, `tension_in_2_n`, `tension_out_1_n`,
    /// `tension_out_2_n`, those recorded); empty for the other kinds. A caller may clear
    /// them to compare the primary channel alone.
    pub channels: Vec<ChannelData>,
}

impl RunData {
    /// Weight of stacked channel `k` (0: the primary, `k >= 1`: `channels[k - 1]`):
    /// the primary's noise over the channel's.
    pub fn weight(&self, k: usize) -> f64 {
        if k == 0 {
            1.0
        } else {
            self.noise_sigma / self.channels[k - 1].noise_sigma
        }
    }

    /// Name of stacked channel `k`.
    pub fn channel_name(&self, k: usize, primary: &'static str) -> &'static str {
        if k == 0 {
            primary
        } else {
            self.channels[k - 1].name
        }
    }

    /// Measured values of stacked channel `k`.
    pub fn channel_values(&self, k: usize) -> &[f64] {
        if k == 0 {
            &self.measured
        } else {
            &self.channels[k - 1].values
        }
    }

    /// Noise standard deviation of stacked channel `k`, in its own unit.
    pub fn channel_sigma(&self, k: usize) -> f64 {
        if k == 0 {
            self.noise_sigma
        } else {
            self.channels[k - 1].noise_sigma
        }
    }

    /// Number of stacked channels (the primary and [`Self::channels`]).
    pub fn n_channels(&self) -> usize {
        1 + self.channels.len()
    }
}

/// Per-channel sums of one run ([`Prepared::channel_sums`]), in the channel's own unit.
#[derive(Debug, Clone, Copy)]
pub struct ChannelSums {
    /// Column name.
    pub name: &'static str,
    /// Sum of squared errors over the analysed samples.
    pub sse: f64,
    /// Sum of squares about the measured mean over the analysed samples.
    pub sst: f64,
    /// Analysed samples.
    pub n: usize,
    /// Noise standard deviation.
    pub noise_sigma: f64,
}

impl ChannelSums {
    /// NRMSE `sqrt(SSE/SST)`.
    pub fn nrmse(&self) -> f64 {
        (self.sse / self.sst).sqrt()
    }

    /// The noise floor on the NRMSE scale, `sigma sqrt(n/SST)`.
    pub fn floor_nrmse(&self) -> f64 {
        self.noise_sigma * (self.n as f64 / self.sst).sqrt()
    }
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
            channels: Vec::new(),
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
    /// Sub-steps per sample of the plant's sweeps.
    pub substeps: usize,
    /// Refinement of an arm plant's steps ([`Self::with_arm_refinement`]; 1: steps of
    /// at most [`crate::plant::ARM_MAX_STEP_S`]).
    pub arm_refinement: usize,
    /// Runs simulated so far through [`Self::simulate_channels`] (every simulation of
    /// fit, compare and diagnose but the sweeps' refined ones): the work of a diagnosis,
    /// whatever the machine's load.
    simulations: std::sync::atomic::AtomicUsize,
    /// When set, every simulation asked of this instance fails with
    /// [`IdentError::Abandoned`] ([`Self::abandonable`]).
    abandon: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl<'a> Prepared<'a> {
    /// Prepares `ds`: analysis windows and noise floors.
    pub fn new(ds: &'a Dataset) -> Result<Self, IdentError> {
        Self::with_substeps(ds, sim::SWEEP_SUBSTEPS)
    }

    /// Prepares `ds` with its sweeps simulated at `substeps` sub-steps per sample
    /// (studies of the simulation's step error; [`Self::new`] uses
    /// [`sim::SWEEP_SUBSTEPS`]).
    pub fn with_substeps(ds: &'a Dataset, substeps: usize) -> Result<Self, IdentError> {
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
                        channels: sweep_tensions(r),
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
                        channels: Vec::new(),
                    }
                })
                .collect(),
        };
        for run in &runs {
            let n = run.idx.len();
            for k in 0..run.n_channels() {
                let values = run.channel_values(k);
                let first = run.idx.first().map(|&i| values[i]);
                // Exactly constant (bit for bit): any variation at all gives a number.
                let varies = first
                    .is_some_and(|f| run.idx.iter().any(|&i| values[i].to_bits() != f.to_bits()));
                if !varies {
                    return Err(IdentError::NoVariation {
                        dir: ds.dir.display().to_string(),
                        run: run.name.clone(),
                        channel: run.channel_name(k, primary_name(&ds.kind)),
                        samples: n,
                    });
                }
                // A further channel is weighted by its noise: it must show some.
                let sigma = run.channel_sigma(k);
                if k > 0 && !(sigma > 0.0 && sigma.is_finite()) {
                    return Err(IdentError::NoNoise {
                        dir: ds.dir.display().to_string(),
                        run: run.name.clone(),
                        channel: run.channel_name(k, primary_name(&ds.kind)),
                    });
                }
            }
        }
        Ok(Self {
            ds,
            kind: data_kind(ds),
            runs,
            plant: plant_for(ds, substeps),
            substeps,
            arm_refinement: 1,
            simulations: std::sync::atomic::AtomicUsize::new(0),
            abandon: None,
        })
    }

    /// The same data prepared again (the same plant, step, refinement and runs, as
    /// this instance holds them: a caller may have left a run's channels out), for work
    /// made ahead of a decision: once `abandon` is set, every simulation asked of it
    /// fails with [`IdentError::Abandoned`], so what runs there stops within one
    /// simulation of a run.
    pub(crate) fn abandonable(
        &self,
        abandon: std::sync::Arc<std::sync::atomic::AtomicBool>,
    ) -> Result<Prepared<'a>, IdentError> {
        let mut p = self.reprepared(self.substeps, self.arm_refinement)?;
        p.abandon = Some(abandon);
        Ok(p)
    }

    /// This data prepared again at the refinement `refinement` of its plant's coarsest
    /// step (an arm's steps of at most [`crate::plant::ARM_MAX_STEP_S`] divided into
    /// `refinement`, a sweep's [`sim::SWEEP_SUBSTEPS`] x `refinement` sub-steps per
    /// sample; relaxation and cyclic tests unchanged), with the runs as this instance
    /// holds them (a caller may have left a run's channels out: prepared from the
    /// dataset again, they came back, and simulations cached in one instance did not
    /// match the other's runs).
    pub fn at_refinement(&self, refinement: usize) -> Result<Prepared<'a>, IdentError> {
        let refinement = refinement.max(1);
        match self.kind {
            DataKind::SineSweep => self.reprepared(sim::SWEEP_SUBSTEPS * refinement, 1),
            DataKind::ArmMoves => self.reprepared(self.substeps, refinement),
            _ => self.reprepared(self.substeps, self.arm_refinement),
        }
    }

    /// This data prepared again at `substeps` and `arm_refinement`, with the runs as
    /// this instance holds them ([`Self::at_refinement`]).
    fn reprepared(
        &self,
        substeps: usize,
        arm_refinement: usize,
    ) -> Result<Prepared<'a>, IdentError> {
        let mut p = Self::with_substeps(self.ds, substeps)?;
        if arm_refinement != p.arm_refinement {
            p = p.with_arm_refinement(arm_refinement);
        }
        p.runs = self.runs.clone();
        Ok(p)
    }

    /// The refinement of the plant's coarsest step this instance simulates at
    /// ([`Self::at_refinement`]): an arm's [`Self::arm_refinement`], a sweep's sub-steps
    /// over [`sim::SWEEP_SUBSTEPS`] (at least 1); 1 for the specimens' tests.
    pub fn refinement(&self) -> usize {
        match self.kind {
            DataKind::ArmMoves => self.arm_refinement,
            DataKind::SineSweep => (self.substeps / sim::SWEEP_SUBSTEPS).max(1),
            _ => 1,
        }
    }

    /// The longest simulation step of any run, s (an arm's or a sweep's; `None` for the
    /// specimens' tests, whose simulation has no step error to speak of).
    pub fn step_s(&self) -> Option<f64> {
        match &self.ds.kind {
            DatasetKind::ArmMoves(am) => {
                Some(crate::plant::longest_step_s(am, self.arm_refinement))
            }
            DatasetKind::SineSweep(sw) => Some(
                sw.runs
                    .iter()
                    .map(|r| r.dt_s() / self.substeps.max(1) as f64)
                    .fold(0.0, f64::max),
            ),
            _ => None,
        }
    }

    /// [`IdentError::Abandoned`] once this instance's work was abandoned.
    fn check_abandoned(&self) -> Result<(), IdentError> {
        match &self.abandon {
            Some(a) if a.load(std::sync::atomic::Ordering::Relaxed) => Err(IdentError::Abandoned),
            _ => Ok(()),
        }
    }

    /// The same data with an arm's simulation steps divided into `refinement` (the
    /// step [`super::choose_arm_step`] chose); no change for other kinds.
    pub fn with_arm_refinement(mut self, refinement: usize) -> Self {
        self.arm_refinement = refinement.max(1);
        self.plant = arm_plant_for(self.ds, self.substeps, self.arm_refinement);
        self
    }

    /// The same data at the plant's coarsest step (refinement 1: an arm's steps of at
    /// most [`crate::plant::ARM_MAX_STEP_S`], a sweep's [`sim::SWEEP_SUBSTEPS`]
    /// sub-steps per sample) when this one is finer, where a diagnosis searches
    /// ([`super::diagnose`]); `None` otherwise.
    pub fn coarse_twin(&self) -> Result<Option<Prepared<'a>>, IdentError> {
        if self.refinement() <= 1 {
            return Ok(None);
        }
        Ok(Some(self.at_refinement(1)?))
    }

    /// Simulates `model` on every run (in parallel, results in run order); returns, for
    /// each run, its stacked channels' simulated values concatenated: the primary
    /// channel at every sample (`y[..n]`, n samples), then each of
    /// [`RunData::channels`] (`y[k n..(k + 1) n]` for stacked channel `k`).
    pub fn simulate(&self, model: &Model) -> Result<Vec<Vec<f64>>, IdentError> {
        (0..self.runs.len())
            .into_par_iter()
            .map(|r| self.simulate_run(model, r))
            .collect()
    }

    /// Simulates `model` on run `r`: its stacked channels concatenated, as in
    /// [`Self::simulate`].
    pub fn simulate_run(&self, model: &Model, r: usize) -> Result<Vec<f64>, IdentError> {
        self.check_abandoned()?;
        let params = model.plant_params(r)?;
        self.stacked(r, self.plant.simulate(&params, r)?)
    }

    /// [`Self::simulate_run`], and the knot opening the highest segment in which that
    /// simulation evaluated a shape-free law's table
    /// ([`crate::plant::Plant::simulate_bounded`]).
    pub(crate) fn simulate_run_bounded(
        &self,
        model: &Model,
        r: usize,
    ) -> Result<(Vec<f64>, Option<f64>), IdentError> {
        self.check_abandoned()?;
        let params = model.plant_params(r)?;
        let (channels, bound) = self.plant.simulate_bounded(&params, r)?;
        Ok((self.stacked(r, channels)?, bound))
    }

    /// The residuals of run `r` alone (`y` its stacked channels): its part of
    /// [`Self::residuals_of`], appended to `out`.
    pub(crate) fn run_residuals_into(&self, r: usize, y: &[f64], out: &mut Vec<f64>) {
        run_residuals(&self.runs[r], y, out);
    }

    /// Number of residuals of run `r` ([`Self::residuals_of`] puts them one run after
    /// another).
    pub(crate) fn run_residual_count(&self, r: usize) -> usize {
        self.runs[r].idx.len() * self.runs[r].n_channels()
    }

    /// The plant's channels of run `r` in the order of its stacked channels,
    /// concatenated.
    fn stacked(&self, r: usize, channels: Channels) -> Result<Vec<f64>, IdentError> {
        let run = &self.runs[r];
        if run.channels.is_empty() {
            return Ok(channels.into_primary());
        }
        let mut out = channels.primary().to_vec();
        for c in &run.channels {
            let y = channels.get(c.name).ok_or(IdentError::MissingChannel {
                run: run.name.clone(),
                channel: c.name,
            })?;
            out.extend_from_slice(y);
        }
        Ok(out)
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
        self.check_abandoned()?;
        self.simulations
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.plant.simulate(params, r)
    }

    /// Runs simulated so far (one per run and model; see the field).
    pub fn simulations(&self) -> usize {
        self.simulations.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Residuals over the analysed samples of every run, concatenated: run by run, each
    /// stacked channel's `(model - measured) * weight` ([`RunData::weight`]: the
    /// primary's unit, 1 for the primary) in turn. `sims` as from [`Self::simulate`].
    pub fn residuals_of(&self, sims: &[Vec<f64>]) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.n_samples());
        for (run, y) in self.runs.iter().zip(sims) {
            run_residuals(run, y, &mut out);
        }
        out
    }

    /// [`Self::ssr`] of run `r` alone, `y` its stacked channels as
    /// [`Self::simulate_run`] returns them.
    pub fn run_ssr(&self, r: usize, y: &[f64]) -> f64 {
        let mut out = Vec::new();
        run_residuals(&self.runs[r], y, &mut out);
        out.iter().map(|e| e * e).sum()
    }

    /// Residuals of the primary channel alone (model - measured), over the analysed
    /// samples of every run: what the residual checks and signatures look at (time
    /// series of the output angle). `sims` may hold the primary alone or every stacked
    /// channel.
    pub fn primary_residuals_of(&self, sims: &[Vec<f64>]) -> Vec<f64> {
        let mut out = Vec::new();
        for (run, y) in self.runs.iter().zip(sims) {
            out.extend(run.idx.iter().map(|&i| y[i] - run.measured[i]));
        }
        out
    }

    /// Squared stacked residual of sample `i` of run `r` (`y` its simulated channels,
    /// as from [`Self::simulate`]): every stacked channel's, weighted.
    pub fn squared_error(&self, r: usize, y: &[f64], i: usize) -> f64 {
        let run = &self.runs[r];
        let n = run.measured.len();
        let mut sq = (y[i] - run.measured[i]).powi(2);
        for (k, c) in run.channels.iter().enumerate() {
            sq += ((y[(k + 1) * n + i] - c.values[i]) * run.weight(k + 1)).powi(2);
        }
        sq
    }

    /// Sum of squared residuals ([`Self::residuals_of`]) of the simulated channels `sims`.
    pub fn ssr(&self, sims: &[Vec<f64>]) -> f64 {
        self.residuals_of(sims).iter().map(|e| e * e).sum()
    }

    /// SSR that noise alone leaves: `sigma_primary^2` per stacked residual.
    pub fn floor_ssr(&self) -> f64 {
        self.runs
            .iter()
            .map(|r| r.noise_sigma.powi(2) * (r.idx.len() * r.n_channels()) as f64)
            .sum()
    }

    /// [`Self::floor_ssr`] of the primary channel alone.
    pub fn primary_floor_ssr(&self) -> f64 {
        self.runs
            .iter()
            .map(|r| r.noise_sigma.powi(2) * r.idx.len() as f64)
            .sum()
    }

    /// The error group of every residual of [`Self::residuals_of`], for the fits'
    /// uncertainties ([`crate::fitting::Residuals::error_groups`]): a sweep's analysed
    /// samples grouped by test frequency, over all runs and channels (the encoder's
    /// quantisation error is coherent over a frequency step, and runs that see the same
    /// signal, such as a linear rope at several mean tensions, see the same error; a
    /// step's tensions belong with its angles). An arm's residuals are grouped by
    /// channel, over all runs ([`Self::arm_error_groups`]). `None` for relaxation and
    /// cyclic tests, whose tension noise is independent from sample to sample.
    pub fn error_groups(&self) -> Option<Vec<usize>> {
        if self.kind == DataKind::ArmMoves {
            return self.arm_error_groups();
        }
        if self.kind != DataKind::SineSweep {
            return None;
        }
        let mut freqs: Vec<f64> = Vec::new();
        let mut out = Vec::with_capacity(self.n_samples());
        for run in &self.runs {
            for _ in 0..run.n_channels() {
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
        }
        Some(out)
    }

    /// The error group of every residual of an arm dataset: its channel (by name),
    /// whatever the run. An encoder that holds still reads one value for as long as it
    /// holds, so its quantisation error is one number over the whole hold, and a joint
    /// held at the initial pose in several runs reads the same value in each: a
    /// channel's errors may be correlated over its samples and across runs. Different
    /// channels measure with sensors of their own (a motor's encoder, a joint's, a
    /// tension cell, the tip tracker), so their errors are independent. (Coverage
    /// study, docs/models.md: independent errors held a hidden payload's mass in 62%
    /// of the intervals, a group per channel and run in 82%, these groups in the
    /// figures given there.)
    fn arm_error_groups(&self) -> Option<Vec<usize>> {
        let DatasetKind::ArmMoves(am) = &self.ds.kind else {
            return None;
        };
        let mut names: Vec<&str> = Vec::new();
        let mut out = Vec::with_capacity(self.n_samples());
        for (run, data) in am.runs.iter().zip(&self.runs) {
            let samples = run.time_s.len();
            // (every sample of the stacked channel is analysed)
            debug_assert_eq!(data.idx.len(), samples * run.channels.len());
            for c in &run.channels {
                let id = names.iter().position(|n| *n == c.name).unwrap_or_else(|| {
                    names.push(&c.name);
                    names.len() - 1
                });
                out.extend(std::iter::repeat_n(id, samples));
            }
        }
        Some(out)
    }

    /// Simulates `model` on every run at half the time step of [`Self::simulate`] (a
    /// sweep's sub-steps, an arm's refinement doubled), for the step-error correction
    /// of the fits' intervals ([`crate::fitting::Residuals::refined_residuals`]); `None`
    /// for data kinds whose simulation has no step error to speak of (relaxation in
    /// closed form or by the exact-hold rope step).
    pub fn simulate_refined(&self, model: &Model) -> Option<Result<Vec<Vec<f64>>, IdentError>> {
        let plant = match self.kind {
            DataKind::SineSweep => plant_for(self.ds, 2 * self.substeps),
            DataKind::ArmMoves => arm_plant_for(self.ds, self.substeps, 2 * self.arm_refinement),
            _ => return None,
        };
        Some(
            (0..self.runs.len())
                .into_par_iter()
                .map(|r| self.stacked(r, plant.simulate(&model.plant_params(r)?, r)?))
                .collect(),
        )
    }

    /// Per-run, per-stacked-channel sums over the analysed samples, each channel in its
    /// own unit.
    pub fn channel_sums(&self, sims: &[Vec<f64>]) -> Vec<Vec<ChannelSums>> {
        let primary = primary_name(&self.ds.kind);
        self.runs
            .iter()
            .zip(sims)
            .map(|(run, y)| {
                let len = run.measured.len();
                (0..run.n_channels())
                    .map(|k| {
                        let (m, y) = (run.channel_values(k), &y[k * len..]);
                        let n = run.idx.len();
                        let mean = run.idx.iter().map(|&i| m[i]).sum::<f64>() / n.max(1) as f64;
                        ChannelSums {
                            name: run.channel_name(k, primary),
                            sse: run.idx.iter().map(|&i| (y[i] - m[i]).powi(2)).sum(),
                            sst: run.idx.iter().map(|&i| (m[i] - mean).powi(2)).sum(),
                            n,
                            noise_sigma: run.channel_sigma(k),
                        }
                    })
                    .collect()
            })
            .collect()
    }

    /// Per-run `(SSE, SST, n)` over the analysed samples of every stacked channel, in
    /// the primary's unit (each channel's sums times its weight squared; `n` counts
    /// every stacked residual). For a run with the primary channel alone, its sums.
    pub fn sums(&self, sims: &[Vec<f64>]) -> Vec<(f64, f64, usize)> {
        self.runs
            .iter()
            .zip(self.channel_sums(sims))
            .map(|(run, ch)| {
                ch.iter()
                    .enumerate()
                    .fold((0.0, 0.0, 0), |(sse, sst, n), (k, c)| {
                        if k == 0 {
                            (c.sse, c.sst, c.n)
                        } else {
                            let w2 = run.weight(k).powi(2);
                            (sse + c.sse * w2, sst + c.sst * w2, n + c.n)
                        }
                    })
            })
            .collect()
    }

    /// Overall NRMSE `sqrt(sum SSE / sum SST)` and the noise floor on the same scale,
    /// over every stacked channel ([`Self::sums`]).
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

    /// Total stacked residuals: analysed samples times stacked channels, over the runs
    /// (the length of [`Self::residuals_of`]).
    pub fn n_samples(&self) -> usize {
        (0..self.runs.len())
            .map(|r| self.run_residual_count(r))
            .sum()
    }

    /// Whether any run stacks a channel besides the primary one.
    pub fn has_channels(&self) -> bool {
        self.runs.iter().any(|r| !r.channels.is_empty())
    }
}

/// Name of a dataset kind's primary channel.
pub fn primary_name(kind: &DatasetKind) -> &'static str {
    match kind {
        DatasetKind::SineSweep(_) => "output_angle_rad",
        DatasetKind::ArmMoves(_) => crate::plant::ARM_STACKED,
        _ => "tension_n",
    }
}

/// The rope tensions a sweep run recorded, each with its noise from the second
/// differences of the whole run ([`noise_sigma_second_difference`]), in the order the
/// rig plant returns them.
fn sweep_tensions(r: &crate::dataset::SweepRun) -> Vec<ChannelData> {
    [
        ("tension_in_1_n", &r.tension_in_1_n),
        ("tension_in_2_n", &r.tension_in_2_n),
        ("tension_out_1_n", &r.tension_out_1_n),
        ("tension_out_2_n", &r.tension_out_2_n),
    ]
    .into_iter()
    .filter_map(|(name, v)| {
        v.as_ref().map(|v| ChannelData {
            name,
            values: v.clone(),
            noise_sigma: noise_sigma_second_difference(v),
        })
    })
    .collect()
}

fn dt_of(t: &[f64]) -> f64 {
    if t.len() < 2 {
        1.0
    } else {
        (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
    }
}

/// The residuals of one run, appended to `out` as [`Prepared::residuals_of`] lists
/// them: each stacked channel's `(model - measured) * weight` in turn.
fn run_residuals(run: &RunData, y: &[f64], out: &mut Vec<f64>) {
    let n = run.measured.len();
    for k in 0..run.n_channels() {
        let (w, m, y) = (run.weight(k), run.channel_values(k), &y[k * n..]);
        if k == 0 {
            out.extend(run.idx.iter().map(|&i| y[i] - m[i]));
        } else {
            out.extend(run.idx.iter().map(|&i| (y[i] - m[i]) * w));
        }
    }
}
