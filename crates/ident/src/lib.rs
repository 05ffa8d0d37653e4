//! Identification tools for the longreach project: measurement datasets
//! (`longreach-measurement/1`), error metrics and residual checks, bounded nonlinear
//! least squares with uncertainties, and sensor models for synthetic data; on top of
//! them the measurement loop: models ([`model`]), their simulation on a dataset
//! ([`sim`]), fit, compare and diagnose ([`analysis`]) and synthetic datasets
//! ([`synth`]), which report failures as an [`IdentError`].

pub mod dataset;
pub mod error;
pub mod fitting;
pub mod metrics;
pub mod sensors;

pub use dataset::{
    ArmChannel, ArmMovesDataset, ArmQuantity, ArmRun, CyclicDataset, CyclicRun, CyclicSpecimen,
    Dataset, DatasetError, DatasetKind, Frf, RelaxationDataset, RelaxationRun, RelaxationSpecimen,
    RigSpec, Segment, SweepDataset, SweepRun, Tensioner, WindowAlignment,
};
pub use error::IdentError;
pub use fitting::{
    add_intervals, fit, fit_joining, FitError, FitOptions, FitResult, ParamSpec, ResidualError,
    Residuals,
};
pub use metrics::MetricsError;
pub use sensors::{Encoder, GaussianNoise, SensorError, ENCODER_RESOLUTION_RAD};
pub mod analysis;
pub mod arm_scenario;
pub mod model;
pub mod plant;
pub mod sim;
pub mod synth;
