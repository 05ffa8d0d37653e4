//! Scenario files of longreach (TOML, serde): parsing, validation with errors that name
//! the file, line, field and fix, and compilation into runnable models.

pub mod atomic;
pub mod batch;
pub mod bode;
mod error;
pub mod limits;
pub mod locate;
pub mod rig;
pub mod spec;

pub use bode::{BodeRun, BodeScenario};
pub use error::ScenarioError;
