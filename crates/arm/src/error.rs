//! Errors of the dynamics and the simulation.

use crate::spec::SpecError;

/// Bad input to the dynamics functions or to [`crate::step`], or a numerical blow-up.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ArmError {
    /// A per-joint vector has the wrong length.
    #[error("{what}: expected {expected} values (one per joint of arm '{arm}'), got {got}")]
    WrongLength {
        /// Which argument.
        what: &'static str,
        /// Arm name.
        arm: String,
        /// Number of joints.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// An input value is NaN or infinite.
    #[error("{what}[{index}] = {value} is not finite")]
    NonFinite {
        /// Which argument.
        what: &'static str,
        /// Index in the vector.
        index: usize,
        /// The value.
        value: f64,
    },
    /// The time step is not usable.
    #[error("time step dt_s = {dt_s} must be finite and > 0")]
    BadTimeStep {
        /// The step given, s.
        dt_s: f64,
    },
    /// The simulation produced NaN/inf or rapier quarantined a body.
    #[error("numerical blow-up at t = {time_s} s: {detail}; reduce dt_s, raise the substeps, or check the applied torques")]
    BlowUp {
        /// Simulated time of the failed step, s.
        time_s: f64,
        /// What was found.
        detail: String,
    },
    /// An [`crate::ArmData`] was used with a model it was not made from.
    #[error("this ArmData was made for a model with {data_dofs} joints, not arm '{arm}' with {model_dofs}: make the data with ArmModel::make_data")]
    ModelMismatch {
        /// Arm name of the model.
        arm: String,
        /// Joints of the model.
        model_dofs: usize,
        /// Joints of the data.
        data_dofs: usize,
    },
    /// The mass matrix could not be factorised (should not happen for a valid spec).
    #[error("mass matrix of arm '{arm}' is singular at this configuration")]
    SingularMassMatrix {
        /// Arm name.
        arm: String,
    },
    /// The spec failed validation.
    #[error(transparent)]
    InvalidSpec(#[from] SpecError),
    /// A generated arm ([`crate::generate`]) could not be built from its arguments.
    #[error("generated arm '{arm}': {reason}")]
    Generated {
        /// Which generated arm.
        arm: String,
        /// What is wrong and what to do.
        reason: String,
    },
    /// A transmission (rope pair, motor, route) is not usable.
    #[error("{field}: {reason}")]
    BadTransmission {
        /// Which field (`transmission[i] (joint name).field`).
        field: String,
        /// What is wrong and what to do.
        reason: String,
    },
}

/// Checks a per-joint vector: length and finiteness.
pub(crate) fn check_joint_vector(
    arm: &str,
    ndofs: usize,
    what: &'static str,
    v: &[f64],
) -> Result<(), ArmError> {
    if v.len() != ndofs {
        return Err(ArmError::WrongLength {
            what,
            arm: arm.to_string(),
            expected: ndofs,
            got: v.len(),
        });
    }
    if let Some((index, &value)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        return Err(ArmError::NonFinite { what, index, value });
    }
    Ok(())
}
