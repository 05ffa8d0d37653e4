//! Errors of the transmission and rig: each says what, where and what to do.

use longreach_rope::RopeError;

/// Everything that can go wrong building or running a rig.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DriveError {
    /// A rope law is invalid.
    #[error(transparent)]
    Rope(#[from] RopeError),
    /// A rig or signal parameter is outside its valid range.
    #[error("`{field}` = {value}: {reason}")]
    BadParameter {
        /// Field name as in the scenario/dataset files.
        field: String,
        /// Value given.
        value: f64,
        /// What is wrong and what to do.
        reason: String,
    },
    /// The simulation produced a non-finite or runaway state.
    #[error(
        "numerical blow-up at t = {time_s:.6} s: {what}; reduce dt_s or check the rig constants"
    )]
    BlowUp {
        /// Simulation time.
        time_s: f64,
        /// What went wrong.
        what: String,
    },
    /// A transmission (rope pair, motor, route) is not usable.
    #[error("{field}: {reason}")]
    BadTransmission {
        /// Which field (e.g. `transmission[2] (joint j3).motor.inertia_kg_m2`).
        field: String,
        /// What is wrong and what to do.
        reason: String,
    },
    /// A recorded input series is unusable.
    #[error("input series: {0}")]
    BadSeries(String),
}

/// Checks `value` is finite and > 0.
pub(crate) fn positive(field: &str, value: f64) -> Result<f64, DriveError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(DriveError::BadParameter {
            field: field.to_string(),
            value,
            reason: "must be a finite number > 0".to_string(),
        })
    }
}

/// Checks `value` is finite and >= 0.
pub(crate) fn non_negative(field: &str, value: f64) -> Result<f64, DriveError> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(DriveError::BadParameter {
            field: field.to_string(),
            value,
            reason: "must be a finite number >= 0".to_string(),
        })
    }
}
