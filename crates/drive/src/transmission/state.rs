//! The mutable state of a plant driven by rope pairs (joints, motors, tensioners,
//! ropes, relay pulleys, effect states) and the solver memory it carries from step to
//! step.

use longreach_rope::{PreparedStep, RopeState};

use super::free::FreeFactor;
use super::relay::assembly::RelayScratch;
use super::relay::RelayState;

/// Everything that changes while a plant of [`super::step`] runs: joint angles and
/// rates, motor angles, tensioner stretches, rope and relay states, the servos'
/// saturation set and the states of effects, plus the solver's memory.
///
/// `S` is the joint side's own scratch ([`super::step::JointSide::Scratch`]).
///
/// # What carries over from one step to the next
///
/// Besides the physical state, two things do, and both are part of this struct (so a
/// cloned state continues bit for bit like the original):
/// - [`Self::servo_saturation`], the active set of each servo's torque limit (held
///   through a step's Newton solve, corrected at its convergence, and the next step's
///   starting guess);
/// - the solver's memory (private): the factor of the last Newton matrix, which the next
///   step's chord iterations may reuse for up to three steps, and the contraction rate
///   last measured on it. Start a new run from the plant's initial state, never by
///   editing the physical fields of a used state (the kept matrix would belong to
///   another state; it is refreshed within a step when its updates do not contract,
///   so the result stays converged, but not bitwise that of a fresh start).
#[derive(Debug, Clone)]
pub struct PlantState<S> {
    /// Time, s.
    pub time_s: f64,
    /// Joint angles, rad.
    pub q_rad: Vec<f64>,
    /// Joint rates, rad/s.
    pub qd_rad_s: Vec<f64>,
    /// Joint accelerations, rad/s^2.
    pub qdd_rad_s2: Vec<f64>,
    /// Joint references at `time_s`, rad (set by the plant from its commands).
    pub q_ref_rad: Vec<f64>,
    /// Motor angles (per pair), rad.
    pub motor_rad: Vec<f64>,
    /// Motor rates, rad/s.
    pub motor_rate_rad_s: Vec<f64>,
    /// Motor accelerations, rad/s^2.
    pub motor_accel_rad_s2: Vec<f64>,
    /// Motor references, rad.
    pub motor_ref_rad: Vec<f64>,
    /// Servo torques of the last step, N*m.
    pub motor_torque_n_m: Vec<f64>,
    /// Saturation of each servo's torque at the end of the last step: -1, 0 or +1.
    pub servo_saturation: Vec<i8>,
    /// Common stretch of each pair held by its tensioner, m.
    pub carriage_m: Vec<f64>,
    /// Rope states `[+, -]` of each pair (one rope of the `n` in parallel); for a pair
    /// with relay friction, the motor-side span (every span is in `relays`).
    pub ropes: Vec<[RopeState; 2]>,
    /// Spans and relay pulleys of each pair with relay friction (empty otherwise).
    pub relays: Vec<RelayState>,
    /// States of the effects acting at the joints ([`super::step::JointLoad`]), in load
    /// order.
    pub effect_state: Vec<f64>,
    /// Newton iterations of the last step.
    pub iterations: u32,
    pub(crate) solver: Solver,
    /// The joint side's own buffers and caches ([`super::step::JointSide::Scratch`]).
    pub joint_scratch: S,
}

/// The implicit step's memory and buffers (see [`PlantState`]).
#[derive(Debug, Clone)]
pub(crate) struct Solver {
    /// Base of the Newton matrix (`4 M/h^2 + 2 D/h` at the step's first assembly).
    pub mbase: Vec<f64>,
    /// The Newton matrix, then its factor (kept for chord iterations).
    pub kq: Vec<f64>,
    /// Right-hand side, then the joint update.
    pub rhs: Vec<f64>,
    /// End-of-step joint angles, rates and accelerations of the trial state.
    pub q1: Vec<f64>,
    pub v1: Vec<f64>,
    pub a1: Vec<f64>,
    /// Per ideal pair: b11 b12 b21 b22 w0 w1 r0 r1 (its 2 x 2 border, [`super::ideal`]).
    pub local: Vec<[f64; 8]>,
    /// Prepared rope steps of every ideal pair.
    pub prep: Vec<[PreparedStep; 2]>,
    /// Unclamped servo torque at the last evaluation, N*m.
    pub raw: Vec<f64>,
    /// End-of-step motor angles and tensioner stretches of the trial state.
    pub th1: Vec<f64>,
    pub x1: Vec<f64>,
    /// Servo torques of the trial state, N*m.
    pub torque: Vec<f64>,
    /// Per pair with relay friction: its local block (and kept factor).
    pub relay: Vec<Option<RelayScratch>>,
    /// The factor of the free coordinates' block and its Schur complement on the
    /// joints ([`super::Drivetrain::with_free_coords`]); `None` without free
    /// coordinates.
    pub free: Option<FreeFactor>,
    /// Pivots of the joint LU (plants with relay friction).
    pub perm: Vec<usize>,
    /// The trial state before the last full Newton update and that update (joints,
    /// motors, tensioners), for the line search of the globalised iterations.
    pub q1_back: Vec<f64>,
    pub th1_back: Vec<f64>,
    pub x1_back: Vec<f64>,
    pub dq: Vec<f64>,
    pub dth: Vec<f64>,
    pub dx: Vec<f64>,
    /// The Newton matrix of the last step (factors in `kq`, `perm` and the relay
    /// scratch) may start the next step's chord iterations.
    pub kept: bool,
    /// Steps started since the Newton matrix was last assembled.
    pub age: u32,
    /// Last measured contraction of a chord iteration (update over the update before
    /// it) and the matrix age it was measured at: the error estimate of a step's first
    /// chord iteration, which has no update before it in the step.
    pub chord_rate: f64,
    pub chord_rate_age: u32,
}
