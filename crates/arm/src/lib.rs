//! longreach-arm: URDF arms as rapier3d-f64 multibodies, plus independent rigid-body
//! dynamics for checks and gravity feed-forward.
//!
//! - [`urdf`]: URDF file -> validated [`ArmSpec`] (fixed joints merged, unsupported
//!   content listed in [`ArmSpec::warnings`]).
//! - [`multibody`]: [`ArmModel`] (immutable) / [`ArmData`] (mutable) and [`step`].
//! - [`dynamics`]: recursive Newton-Euler on the spec: [`gravity_torques`],
//!   [`energy`], mass matrix, inverse and forward dynamics.
//! - [`generate`]: [`chain_urdf`], uniform planar chains for benchmarks.
//! - [`transmission`]: routes and span lengths of the rope pairs from the URDF chain
//!   (the pairs themselves are the transmission core's, `longreach_drive::transmission`).
//! - [`system`]: [`DrivenArm`] / [`DrivenState`]: links + ropes + motors + servos,
//!   integrated implicitly by the transmission core's step; see docs/arm.md.
//! - [`fast`]: allocation-free kinematics, Newton-Euler and mass matrix for the step.
//! - [`command`]: joint references (hold, step, trapezoid, sine, series).
//! - [`scenario`]: arm scenario files -> [`DrivenArm`]; [`run`]: time series and metrics.

pub mod command;
pub mod dynamics;
pub mod error;
pub mod fast;
pub mod flex;
pub mod generate;
pub mod modes;
pub mod multibody;
pub mod run;
pub mod scenario;
pub mod spec;
pub mod system;
pub mod transmission;
pub mod urdf;

pub use command::Command;
pub use dynamics::{energy, gravity_torques, Energy};
pub use error::ArmError;
pub use flex::{tube_ei_n_m2, FlexDynamics, FlexLinkSpec};
pub use generate::{anchor_chain, chain_urdf};
pub use multibody::{step, ArmData, ArmModel, ModelOptions};
pub use spec::{ArmSpec, Element, Frame, Inertial, JointKind, JointSpec, LinkSpec, SpecError};
pub use system::{
    ArmScratch, DrivenArm, DrivenState, StaticPair, SystemEnergy, RELAY_NEWTON_TOLERANCE,
};
pub use transmission::{MotorMode, MotorSpec, PairSpec, Relay, RoutingMatrix, Tensioner};
pub use urdf::{load_urdf, parse_urdf, UrdfError};
