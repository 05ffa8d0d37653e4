//! Passive torques at the joints: what an effect at the joint site adds to a plant
//! ([`crate::effects::Effect::joint_force`]), with states of its own (in the spirit of
//! MuJoCo's plugins and rapier's physics hooks). Every method but the torque has a
//! default.

use std::sync::Arc;

/// A passive torque at one joint, compiled from an effect's parameter values; the
/// implicit step evaluates it at every Newton iteration at the trial angle and rate
/// (its derivatives enter the Newton matrix) and advances its state once per step.
pub trait JointForce: Send + Sync + std::fmt::Debug {
    /// Torque on the joint (N*m, positive along the joint's rate) at angle `angle_rad`
    /// and rate `rate_rad_s`, with the effect's state at the start of the step, and its
    /// derivatives.
    fn torque(&self, angle_rad: f64, rate_rad_s: f64, state: &[f64]) -> JointTorque;

    /// Number of state variables the effect keeps.
    fn state_len(&self) -> usize {
        0
    }

    /// Its state at the start of a run.
    fn initial_state(&self) -> Vec<f64> {
        Vec::new()
    }

    /// Advances the state over a converged step from `start` to `end` (angle, rate)
    /// of `dt_s`.
    fn advance(&self, _start: (f64, f64), _end: (f64, f64), _dt_s: f64, _state: &mut [f64]) {}

    /// Energy the effect stores at `angle_rad` with `state`, J (0 for a dissipative
    /// one).
    fn energy_j(&self, _angle_rad: f64, _state: &[f64]) -> f64 {
        0.0
    }
}

/// A joint torque and its derivatives.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct JointTorque {
    /// Torque, N*m.
    pub torque_n_m: f64,
    /// d torque / d angle, N*m/rad.
    pub d_angle_n_m: f64,
    /// d torque / d rate, N*m*s/rad.
    pub d_rate_n_m_s: f64,
}

/// A passive torque at one joint, as the implicit step holds it.
#[derive(Debug, Clone)]
pub struct JointLoad {
    /// The joint it acts on.
    pub joint: usize,
    /// The name of the registered effect it comes from (reports).
    pub effect: &'static str,
    /// The torque law, compiled with its parameter values.
    pub force: Arc<dyn JointForce>,
}
