//! Cable-pulley transmissions of longreach: the paper's 1-DoF rig (Figs. 7-8, eqs. 9-11)
//! as a time-stepped plant with a constant-force tensioner, the input histories that
//! drive it, its analytic transfer functions (eqs. 12-13) and its simulated frequency
//! response. No physics engine: ropes come from [`longreach_rope`].

pub mod effects;
mod error;
pub mod freq;
mod rig;
pub mod signal;
pub mod sweep;
pub mod tf;
pub mod transmission;

pub use error::DriveError;
pub use rig::{RigModel, RigSpec, RigState, MAX_RELAY_PULLEYS};
pub use signal::{InputSignal, SineStep, SteppedSine};
pub use sweep::{FrequencyPoint, RigTrace};
pub use tf::{golden_section_max, rig_resonance, rig_transfer, Resonance};
pub use transmission::{RelayFriction, RelayState, RelayTorque, Tensioner};
