//! [`IdentError`]: what can go wrong preparing, simulating, fitting, comparing and
//! diagnosing a dataset, or making a synthetic one.
//!
//! Each variant carries the failure as a typed value (the dataset's, the model's, the
//! drive's, the fitter's, ...); the message is the one the CLI prints, the cause's own
//! message with, where it helps, the run it happened in.

use longreach_drive::DriveError;

use crate::dataset::DatasetError;
use crate::fitting::FitError;
use crate::metrics::MetricsError;
use crate::model::ModelError;
use crate::sensors::SensorError;

/// Everything the identification loop ([`crate::analysis`], [`crate::synth`]) can fail
/// on.
#[derive(Debug, thiserror::Error)]
pub enum IdentError {
    /// The dataset cannot be used as it is (e.g. a frequency step too short to analyse).
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The model gives no valid rope law or rig for a run (an unknown base parameter,
    /// an effect refusing its values, an invalid law).
    #[error(transparent)]
    Model(#[from] ModelError),
    /// Simulating the model on one run of the dataset failed.
    #[error("run {run}: {source}")]
    Simulation {
        /// The run's name (file stem).
        run: String,
        /// The simulator's complaint.
        #[source]
        source: DriveError,
    },
    /// The drive crate refused a synthetic test (its input signal or its simulation).
    #[error(transparent)]
    Drive(DriveError),
    /// A sensor model refused its settings (e.g. a negative noise level).
    #[error(transparent)]
    Sensor(#[from] SensorError),
    /// An error metric could not be computed.
    #[error(transparent)]
    Metrics(#[from] MetricsError),
    /// The least-squares fit failed.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// An effect named to be left out of a diagnosis is not registered.
    #[error("{name}: no registered effect has that name\n  fix: give one of {known}")]
    UnknownEffect {
        /// The name given.
        name: String,
        /// The registered effects, comma-separated.
        known: String,
    },
    /// No start of the starting grid could be simulated (screening a model).
    #[error("every start failed to simulate")]
    NoStartSimulated {
        /// Starts tried.
        starts: usize,
    },
    /// The fit failed from every start of the starting grid.
    #[error("every fit from the starting grid failed")]
    NoStartFitted {
        /// Starts tried.
        starts: usize,
    },
    /// A computation made ahead of the decision that needs it was abandoned once the
    /// decision went the other way (internal: its result is never used or reported).
    #[error("abandoned: made ahead of a decision that went the other way")]
    Abandoned,
    /// A run's measured channel does not vary over its analysed samples: an error
    /// cannot be normalised by it (NRMSE, intervals), so no result would be a number.
    #[error("{dir}: run {run}: the measured {channel} does not vary over its {samples} analysed samples, so the model's error cannot be normalised (NRMSE and intervals would not be numbers); fix: check that the run file holds the measurement (docs/measurements.md), or leave out a run without motion")]
    NoVariation {
        /// The dataset folder.
        dir: String,
        /// The run's name.
        run: String,
        /// The channel (`output_angle_rad`, `tension_n`, a tension column).
        channel: &'static str,
        /// Analysed samples.
        samples: usize,
    },
    /// A further measured channel (a sweep's rope tension) shows no noise to weight it
    /// by: its second differences are zero at most samples.
    #[error("{dir}: run {run}: column {channel}: its noise cannot be estimated (the second differences of the measurement are zero at most samples), so it cannot be weighted against the other channels; fix: record the channel at its sensor's full resolution, or leave the column out (docs/measurements.md)")]
    NoNoise {
        /// The dataset folder.
        dir: String,
        /// The run's name.
        run: String,
        /// The channel (column name).
        channel: &'static str,
    },
    /// The plant did not return a channel the run measured (a plant that does not
    /// simulate it).
    #[error("run {run}: the model's plant gives no {channel}, which the run measured")]
    MissingChannel {
        /// The run's name.
        run: String,
        /// The channel (column name).
        channel: &'static str,
    },
    /// A sweep-only computation (the analytic frequency response, the sweep's step) was
    /// asked of another kind of dataset.
    #[error("not a sweep (kind = \"{kind}\")")]
    NotASweep {
        /// The dataset's kind, as spelled in `dataset.toml`.
        kind: &'static str,
    },
    /// The arm scenario of an arm dataset does not build with the run's payload or the
    /// model's numbers.
    #[error("run {run}: the arm does not build: {message}")]
    ArmBuild {
        /// The run's name (file stem).
        run: String,
        /// The scenario's or the arm's complaint.
        message: String,
    },
    /// Simulating the arm on one run failed.
    #[error("run {run}: the arm simulation failed at t = {time_s:.4} s: {message}; check the recorded commands (a jump the servo cannot follow) or the model's values")]
    ArmSimulation {
        /// The run's name (file stem).
        run: String,
        /// Simulated time of the failure (s).
        time_s: f64,
        /// The arm's complaint.
        message: String,
    },
    /// The arm scenario of a synthetic arm dataset does not load, or the moves asked of
    /// it are not possible.
    #[error("arm synth: {message}")]
    ArmScenario {
        /// What is wrong, with the scenario's own file, line, field and fix.
        message: String,
    },
    /// An arm-only computation was asked of another kind of dataset.
    #[error("not an arm dataset (kind = \"{kind}\")")]
    NotAnArm {
        /// The dataset's kind, as spelled in `dataset.toml`.
        kind: &'static str,
    },
    /// A synthetic cyclic test's strain rate or sample interval is not positive.
    #[error("cyclic test: strain rate {strain_rate_per_s} 1/s and dt {dt_s} s must be > 0")]
    CyclicRates {
        /// Strain rate of the ramps (1/s).
        strain_rate_per_s: f64,
        /// Sample interval (s).
        dt_s: f64,
    },
    /// A synthetic relaxation run's strain is not a finite number > 0.
    #[error("relaxation run {run}: strain {strain} must be a finite number > 0 (--strain takes strains such as 0.015,0.008)")]
    RelaxationStrain {
        /// The run, counted from 1.
        run: usize,
        /// The strain given.
        strain: f64,
    },
    /// A synthetic cyclic run's strains are not `0 <= lower < upper`.
    #[error("cyclic run {run}: need 0 <= lower strain {lower} < upper strain {upper}")]
    CyclicStrains {
        /// The run, counted from 1.
        run: usize,
        /// Lower strain.
        lower: f64,
        /// Upper strain.
        upper: f64,
    },
}
