//! The transmission core: rope pairs (spans, relay pulleys with inertia and friction,
//! tensioner, motor), their unknowns, residuals, Jacobians, commit and energy, and the
//! implicit step that integrates them with the joints they drive. The paper's rig (one
//! joint, [`crate::RigModel`]) and the long-reach arm (crates/arm, every joint, routed
//! over the proximal joints) are both a [`step::JointSide`] plus a [`step::Drivetrain`].
//!
//! # Routing
//!
//! Pair `p` drives joint `j(p)` with a joint pulley of radius `r_j` and passes relay
//! pulleys of radius `r_k`: mounted at the proximal joints `k` (crossing sign `s_k = +-1`)
//! or fixed to the base. Row `p` of the routing matrix `R` (pairs x joints) is
//! `R[p][j(p)] = r_j`, `R[p][k] = s_k r_k` for the mounted relays, zero elsewhere. With
//! motor angle `theta_p` on a pulley of radius `r_m`, the differential stretch of the
//! pair is
//!
//! ```text
//! u_p = r_m theta_p - R[p] . q          (rope + is stretched by x_p + u_p, rope - by x_p - u_p)
//! ```
//!
//! where `x_p` is the common stretch held by the tensioner. With `n_p` parallel ropes
//! on each side carrying `f+`, `f-` each, the pair force is `phi_p = n_p (f+ - f-)`; the
//! ropes load the joints with `tau = R^T phi` (the distal pairs load every proximal
//! joint they pass) and the motor with `-r_m phi_p` (tendon duality: the same `R` maps
//! joint velocities to rope velocities and rope forces to joint torques).
//!
//! # Equations of one step
//!
//! ```text
//! joints:     M(q) qdd + C(q, qd) qd + g(q) + D qd = R^T phi + tau_loads(q, qd)
//! motor p:    J_m thdd_p + b_m thd_p = tau_servo,p - r_m phi_p      (servo; kinematic: theta = reference)
//! ropes:      f+- = rope law of strain (x_p +- u_p) / L_p           (crates/rope, exact hold)
//! tensioner:  f+ + f- = 2 T_p                                      (constant force; fixed: x constant)
//! relays:     J psi'' + tau_f + r (f_l - f_l+1) = 0                 (with relay friction, [`relay`])
//! ```
//!
//! # Layout
//!
//! - [`spec`]: what defines a pair ([`PairSpec`], [`MotorSpec`], [`Tensioner`],
//!   [`Relay`]) and the routing matrix;
//! - [`pair`]: a pair compiled for the step ([`CompiledPair`]): static split, state at
//!   rest, energy, span tensions;
//! - `ideal` and [`relay`]: a pair's block of the Newton system without and with relay
//!   friction (the relay module split into model, friction law, factorisation,
//!   assembly and safeguards);
//! - `servo`: the motor's row;
//! - [`state`]: the mutable [`PlantState`];
//! - [`load`]: passive torques at the joints ([`JointForce`], [`JointLoad`]), what
//!   effects at the joint site add;
//! - [`step`]: the joints' interface ([`JointSide`]) and the implicit step
//!   ([`Drivetrain::step`]) in named stages;
//! - `free`: coordinates of the joint side no pair touches (bending modes), eliminated
//!   once per Newton matrix ([`Drivetrain::with_free_coords`]).

mod free;
pub(crate) mod ideal;
pub mod load;
pub mod pair;
pub mod relay;
mod servo;
pub mod spec;
pub mod state;
pub mod step;

pub use load::{JointForce, JointLoad, JointTorque};
pub use pair::{CompiledPair, PairAtRest, StaticPair};
pub use relay::{CompiledRelays, RelayFriction, RelayRule, RelayState, RelayTorque};
pub use spec::{MotorFriction, MotorMode, MotorSpec, PairSpec, Relay, RoutingMatrix, Tensioner};
pub use state::PlantState;
pub use step::{
    Drivetrain, DrivetrainEnergy, JointSide, MotorInputs, FREE_BASE_STEPS, MAX_KEPT_STEPS,
    NEWTON_TOLERANCE, RELAY_NEWTON_TOLERANCE,
};
