//! Fit, compare and diagnose: a model simulated on the measured input of every run,
//! its error, where it fails, and which registered effect is missing.
//!
//! Split by job:
//!
//! * `prepare.rs`: a dataset readied for the rest ([`Prepared`]: the compared channels
//!   (a sweep's output angle and the rope tensions it recorded, each weighted by its
//!   noise), analysed samples and noise floor of every run, [`RunData`]) and a model
//!   simulated on its runs ([`Prepared::simulate`]);
//! * `fit.rs`: a model's free parameters fitted to the data ([`fit_model`]: a starting
//!   grid, for sweeps refined on the analytic frequency response, then least squares on
//!   the simulation) or only screened at their starting values ([`screen_model`]);
//! * `compare.rs`: a model measured against the data ([`compare`]: the error per run and
//!   per test frequency, where it concentrates, residual checks, resonances);
//! * `arm/`: a model measured against an arm dataset ([`compare_arm`]: every channel
//!   of every run against its noise floor, where the error concentrates, the vibration
//!   figures of every move, and in `evidence.rs` what the sensors show in the arm's
//!   terms, [`arm_findings`]);
//! * `diagnose.rs`: the baseline and every applicable registered effect fitted, ranked,
//!   and the missing effect named when the evidence is decisive ([`diagnose`]);
//! * `joints.rs`: an arm effect's values split per joint (one use per moved joint) or
//!   per flexible link, kept by BIC ([`split_per_joint`]);
//! * `shape.rs`: an effect's law refined in its shape-free form (a table over the range
//!   the data visits, the number of knots chosen by BIC; [`refine_shape`]), and the
//!   laws of an effect split per joint refined together, a table per joint
//!   ([`refine_shapes_together`]);
//! * `step.rs`: the simulation step chosen from the data for the model simulated (the
//!   coarsest whose halving moves every channel by at most a quarter of its noise:
//!   [`choose_arm_step`], [`choose_sweep_step`]), an arm prepared at it
//!   ([`prepared_at_step`]), and the finer step a sweep's model needs where its step
//!   error shows ([`needed_sweep_step`]);
//! * `signature.rs`: the residual's signatures, each with the simplest term that would
//!   produce it, its size and the share of the excess error it removes ([`signatures`]).

mod arm;
mod compare;
mod diagnose;
mod fit;
mod joints;
mod prepare;
mod shape;
mod signature;
mod step;

pub use arm::{
    arm_dataset, arm_findings, compare_arm, describe_findings, residual_vibration, simulate_arm,
    simulate_arm_poses, ArmComparison, ArmFinding, ArmWhere, ChannelError, Figures, MoveFigures,
    ARM_WINDOW_S, FINDINGS_TOLD, OFFSET_COUNTS,
};
pub use compare::{
    compare, Comparison, FrequencyError, ResidualChecks, RunChannelError, RunError, RunResonance,
    Where,
};
pub use diagnose::{
    check_registered, diagnose, diagnose_with, diagnose_without, excess_by_channel,
    BaselineSummary, Candidate, DiagnoseOptions, Diagnosis, Lead, FLOOR_MARGIN, IDLE_SHARE,
    MIN_EXPLAINED, MIN_SCORE, MIN_SCORE_GAP, NAME_MARGIN, PAIR_CANDIDATES, REFINE_MARGIN,
    SCREEN_RATIO,
};
pub use fit::{
    fit_model, fit_model_deferred, fit_model_from, fit_model_from_starts, scan_added,
    scan_coordinates, screen_added, screen_jacobians, screen_model, screen_own, searched_starts,
    with_intervals, Fitted, Staged, Start, ARM_EVALUATIONS_PER_PARAM, DEAR_EVALUATIONS_PER_PARAM,
    RELAY_SCREEN_JACOBIANS, SCREEN_JACOBIANS,
};
pub use joints::{moved_joints, split_per_joint, splittable, JointSplit, JointValues};
pub use prepare::{
    noise_sigma_second_difference, primary_name, ChannelData, ChannelSums, Prepared, RunData,
};
pub use shape::{refine_shape, refine_shapes_together, KnotChoice, ShapeRefinement, KNOT_COUNTS};
pub use signature::{describe, signatures, Equivalent, Signature, SignatureKind};
pub use step::{
    choose_arm_step, choose_sweep_step, needed_sweep_step, prepared_at_step, SimulationStep,
    StepNeed, StepTrial, ARM_MAX_REFINEMENT, STEP_ERROR_SHARE, STEP_TOLERANCE_SIGMA,
    SWEEP_MAX_REFINEMENT,
};
