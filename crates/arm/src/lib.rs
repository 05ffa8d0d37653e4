//! longreach-arm: URDF arms as rapier3d-f64 multibodies, plus independent rigid-body
//! dynamics for checks and gravity feed-forward.
//!
//! - [`urdf`]: URDF file -> validated [`ArmSpec`] (fixed joints merged, unsupported
//!   content listed in [`ArmSpec::warnings`]).
//! - [`multibody`]: [`ArmModel`] (immutable) / [`ArmData`] (mutable) and [`step`].
//! - [`dynamics`]: recursive Newton-Euler on the spec: [`gravity_torques`],
//!   [`energy`], mass matrix, inverse and forward dynamics.
//! - [`generate`]: [`chain_urdf`], uniform planar chains for benchmarks.
//! - [`transmission`]: rope pairs, relays, routing matrix `R`, motors.
//! - [`relay`]: relay-pulley friction: ropes split into spans, relay pulley states.
//! - [`system`]: [`DrivenArm`] / [`DrivenState`]: links + ropes + motors + servos,
//!   integrated implicitly (trapezoidal rule, exact-hold ropes, Newton); see docs/arm.md.
//! - [`fast`]: allocation-free kinematics, Newton-Euler and mass matrix for the step.
//! - [`command`]: joint references (hold, step, trapezoid, sine, series).
//! - [`scenario`]: arm scenario files -> [`DrivenArm`]; [`run`]: time series and metrics.

pub mod command;
pub mod dynamics;
pub mod error;
pub mod fast;
pub mod generate;
pub mod multibody;
pub mod relay;
pub mod run;
pub mod scenario;
pub mod spec;
pub mod system;
pub mod transmission;
pub mod urdf;

pub use command::Command;
pub use dynamics::{energy, gravity_torques, Energy};
pub use error::ArmError;
pub use generate::{anchor_chain, chain_urdf};
pub use multibody::{step, ArmData, ArmModel, ModelOptions};
pub use spec::{ArmSpec, Element, Frame, Inertial, JointKind, JointSpec, LinkSpec, SpecError};
pub use system::{DrivenArm, DrivenState, StaticPair, SystemEnergy, RELAY_NEWTON_TOLERANCE};
pub use transmission::{MotorMode, MotorSpec, PairSpec, Relay, RoutingMatrix, TensionerKind};
pub use urdf::{load_urdf, parse_urdf, UrdfError};
