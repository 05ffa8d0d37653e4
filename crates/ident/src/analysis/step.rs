//! The simulation step chosen from the data: the coarsest step whose halving moves
//! every compared channel by at most [`STEP_TOLERANCE_SIGMA`] of its noise, for the
//! plants whose simulation has a step error (an arm's, [`choose_arm_step`]; the rig's
//! sweeps, [`choose_sweep_step`]).
//!
//! The step a model needs is its own. An arm is prepared at the step chosen with the
//! model given ([`prepared_at_step`]). A sweep starts at 2.5 ms, and `compare`, `fit`
//! and `diagnose` refine it where the model at hand shows its step error against what
//! it leaves over the floor ([`needed_sweep_step`]): the baseline of the independent
//! MuJoCo example moves by 4.8 sigma when its 2.5 ms step is halved, but it misses the
//! data by 28.5x the floor, and its named effect at the floor does not show the step.

use serde::Serialize;

use crate::dataset::DatasetKind;
use crate::model::Model;
use crate::IdentError;

use super::arm::simulate_arm;
use super::Prepared;

/// The step error `compare`, `fit` and `diagnose` accept, in noise standard
/// deviations: the largest over the compared channels of every run of the RMS change
/// of the channel (over its noise) when the step is halved. The step error falls at
/// least as the step (first order), so the error left is at most about twice that
/// change: 0.5 sigma, 12% on the noise floor in quadrature.
pub const STEP_TOLERANCE_SIGMA: f64 = 0.25;

pub use crate::plant::ARM_MAX_REFINEMENT;

/// The finest refinement of a sweep's step tried: [`crate::sim::SWEEP_SUBSTEPS`] x 8
/// sub-steps per sample (0.3125 ms at 200 Hz).
pub const SWEEP_MAX_REFINEMENT: usize = 8;

/// One halving of the simulation step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepTrial {
    /// Refinement of the plant's coarsest step (an arm's
    /// [`crate::plant::ARM_MAX_STEP_S`], a sweep's [`crate::sim::SWEEP_SUBSTEPS`]
    /// sub-steps per sample).
    pub refinement: usize,
    /// The longest step of any run at this refinement, s.
    pub step_s: f64,
    /// Largest RMS change of any channel of any run (over its noise) from this step to
    /// half of it.
    pub change_sigma: f64,
    /// The model's NRMSE against the data at this step (every channel over its noise).
    pub nrmse: f64,
}

/// The simulation step chosen from the data ([`choose_arm_step`], [`choose_sweep_step`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimulationStep {
    /// The refinement chosen: the coarsest whose halving changes every channel by at
    /// most [`STEP_TOLERANCE_SIGMA`], or the plant's finest (its halving measured too).
    pub refinement: usize,
    /// The longest step of any run at that refinement, s.
    pub step_s: f64,
    /// Whether the halving at the chosen step stayed within the tolerance (false: at
    /// the finest step its halving still moved a channel by more; its change is the
    /// last trial's).
    pub converged: bool,
    /// Every halving tried, coarsest first.
    pub trials: Vec<StepTrial>,
}

/// The halving loop of [`choose_arm_step`] and [`choose_sweep_step`]: `simulate(k)` at refinement `k` (1, 2, 4, ...),
/// `change(coarse, fine)` in noise standard deviations, `nrmse` of a simulation,
/// `step_s(k)` the longest step at `k`, `max_k` the finest refinement.
fn halvings<S>(
    max_k: usize,
    step_s: impl Fn(usize) -> f64,
    simulate: impl Fn(usize) -> Result<S, IdentError>,
    change: impl Fn(&S, &S) -> f64,
    nrmse: impl Fn(&S) -> f64,
) -> Result<SimulationStep, IdentError> {
    let mut trials = Vec::new();
    let mut k = 1;
    let mut coarse = simulate(k)?;
    loop {
        let fine = simulate(2 * k)?;
        let change_sigma = change(&coarse, &fine);
        trials.push(StepTrial {
            refinement: k,
            step_s: step_s(k),
            change_sigma,
            nrmse: nrmse(&coarse),
        });
        // (a change that is not a number is no convergence)
        let converged = change_sigma <= STEP_TOLERANCE_SIGMA;
        if converged || k >= max_k {
            return Ok(SimulationStep {
                refinement: k,
                step_s: step_s(k),
                converged,
                trials,
            });
        }
        k *= 2;
        coarse = fine;
    }
}

/// Chooses the arm's simulation step from the prepared data: `model` is simulated at
/// steps of at most [`crate::plant::ARM_MAX_STEP_S`] (1 ms), then at half of that, and
/// so on; the first step whose halving changes the channels by at most
/// [`STEP_TOLERANCE_SIGMA`] noise standard deviations is kept (so that the
/// simulation's own error stays below the sensors' noise), [`ARM_MAX_REFINEMENT`] at
/// most. Each trial records the model's NRMSE at its step: it stops moving where the
/// change does.
pub fn choose_arm_step(prep: &Prepared<'_>, model: &Model) -> Result<SimulationStep, IdentError> {
    let ds = prep.ds;
    let DatasetKind::ArmMoves(am) = &ds.kind else {
        return Err(IdentError::NotAnArm {
            kind: ds.kind.name(),
        });
    };
    halvings(
        ARM_MAX_REFINEMENT,
        |k| crate::plant::longest_step_s(am, k),
        |k| simulate_arm(ds, model, k),
        |coarse, fine| {
            // each channel of each run on its own (a channel that moves must not hide
            // among the many that barely do)
            let mut change_sigma = 0.0f64;
            for ((a, b), r) in coarse.iter().zip(fine).zip(&am.runs) {
                let n = r.time_s.len().max(1);
                for (x, y) in a.primary().chunks(n).zip(b.primary().chunks(n)) {
                    let ss: f64 = x.iter().zip(y).map(|(p, q)| (p - q).powi(2)).sum();
                    change_sigma = change_sigma.max((ss / n as f64).sqrt());
                }
            }
            change_sigma
        },
        // the prepared data's NRMSE (every channel over its noise, stacked)
        |sims| {
            let stacked: Vec<Vec<f64>> = sims.iter().map(|s| s.primary().to_vec()).collect();
            prep.overall(&stacked).0
        },
    )
}

/// Chooses a sweep's simulation step from the prepared data as [`choose_arm_step`]
/// chooses an arm's: `model` simulated at [`crate::sim::SWEEP_SUBSTEPS`] sub-steps per
/// sample, then at twice as many, and so on ([`SWEEP_MAX_REFINEMENT`] at most); the
/// change measured on every compared channel (the output angle and the tension
/// channels the dataset holds, each over its noise) over the analysed samples.
pub fn choose_sweep_step(prep: &Prepared<'_>, model: &Model) -> Result<SimulationStep, IdentError> {
    let DatasetKind::SineSweep(sw) = &prep.ds.kind else {
        return Err(IdentError::NotASweep {
            kind: prep.ds.kind.name(),
        });
    };
    let step_s = |k: usize| {
        sw.runs
            .iter()
            .map(|r| r.dt_s() / (crate::sim::SWEEP_SUBSTEPS * k) as f64)
            .fold(0.0, f64::max)
    };
    halvings(
        SWEEP_MAX_REFINEMENT,
        step_s,
        |k| prep.at_refinement(k)?.simulate(model),
        |coarse, fine| sweep_change(prep, coarse, fine),
        |sims| prep.overall(sims).0,
    )
}

/// The largest RMS change over the analysed samples of any compared channel of any
/// run of a sweep, over the channel's noise, from the simulations `coarse` to `fine`.
fn sweep_change(prep: &Prepared<'_>, coarse: &[Vec<f64>], fine: &[Vec<f64>]) -> f64 {
    let mut change_sigma = 0.0f64;
    for ((a, b), run) in coarse.iter().zip(fine).zip(&prep.runs) {
        let len = run.measured.len();
        let n = run.idx.len().max(1) as f64;
        for c in 0..run.n_channels() {
            let (a, b) = (&a[c * len..], &b[c * len..]);
            let ss: f64 = run.idx.iter().map(|&i| (a[i] - b[i]).powi(2)).sum();
            change_sigma = change_sigma.max((ss / n).sqrt() / run.channel_sigma(c));
        }
    }
    change_sigma
}

/// The share of a sweep model's excess squared error over the floor its simulation's
/// step error must reach for the step to be refined ([`needed_sweep_step`]): the step
/// error taken as 4/3 of its halving's change (second order), in noise standard
/// deviations squared, against `(NRMSE / floor)^2 - 1`. The baseline of
/// example_mujoco_friction moves by 4.8 sigma when its 2.5 ms step is halved, 3% of
/// its excess at 28.5x the floor: a finer step would cost 8x for nothing.
pub const STEP_ERROR_SHARE: f64 = 0.1;

/// A finer step a sweep's model needs ([`needed_sweep_step`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepNeed {
    /// The step chosen with the model ([`choose_sweep_step`]).
    pub step: SimulationStep,
    /// The step it was simulated at, s.
    pub from_step_s: f64,
    /// Its halving's change there, in noise standard deviations.
    pub change_sigma: f64,
    /// The step error there (4/3 of the change, squared) over the model's excess
    /// squared error over the floor.
    pub share: f64,
}

/// The step a sweep's `model` needs on `prep`'s data where its step error shows:
/// `None` when the model is at the floor (`ratio_to_floor`, its NRMSE over the floor,
/// at most [`super::FLOOR_MARGIN`]), when its step error at `refinement` is less than
/// [`STEP_ERROR_SHARE`] of its excess over the floor, or when the step chosen with it
/// ([`choose_sweep_step`]) is no finer than `refinement`. Other kinds: `None`.
pub fn needed_sweep_step(
    prep: &Prepared<'_>,
    model: &Model,
    ratio_to_floor: f64,
    refinement: usize,
) -> Result<Option<StepNeed>, IdentError> {
    if !matches!(prep.ds.kind, DatasetKind::SineSweep(_))
        || ratio_to_floor.is_nan()
        || ratio_to_floor <= super::FLOOR_MARGIN
    {
        return Ok(None);
    }
    let excess = ratio_to_floor.powi(2) - 1.0;
    // one halving at `refinement` first (a model far from the data stops here)
    let here = prep.at_refinement(refinement)?;
    let change_sigma = sweep_change(
        prep,
        &here.simulate(model)?,
        &prep.at_refinement(2 * refinement)?.simulate(model)?,
    );
    let share = (4.0 / 3.0 * change_sigma).powi(2) / excess;
    if change_sigma.is_nan() || share < STEP_ERROR_SHARE || change_sigma <= STEP_TOLERANCE_SIGMA {
        return Ok(None);
    }
    let step = choose_sweep_step(prep, model)?;
    if step.refinement <= refinement {
        return Ok(None);
    }
    Ok(Some(StepNeed {
        from_step_s: here.step_s().unwrap_or(f64::NAN),
        change_sigma,
        share,
        step,
    }))
}

/// `ds` prepared for `fit`, `compare` and `diagnose`: an arm's at the step
/// [`choose_arm_step`] chooses with `model` (returned too); a sweep at its coarsest
/// step (2.5 ms), which they refine where the model's step error shows against what it
/// leaves over the floor ([`needed_sweep_step`]); the specimens' tests as
/// [`Prepared::new`] prepares them.
pub fn prepared_at_step<'a>(
    ds: &'a crate::Dataset,
    model: &Model,
) -> Result<(Prepared<'a>, Option<SimulationStep>), IdentError> {
    let prep = Prepared::new(ds)?;
    if !matches!(ds.kind, DatasetKind::ArmMoves(_)) {
        return Ok((prep, None));
    }
    let step = choose_arm_step(&prep, model)?;
    Ok((prep.at_refinement(step.refinement)?, Some(step)))
}
