//! Named physical effects the paper's model leaves out (its Sec. V-VI), as plugins.
//!
//! An effect is a small object implementing [`Effect`]: a name, a paragraph of physics,
//! named parameters with units, bounds and defaults ([`EffectParam`]), the kinds of
//! measurement that can reveal it ([`DataKind`]), and [`Effect::apply`], which adds the
//! effect to a rope law (and, when it acts on the transmission, to a rig). Every effect
//! lives in its own file; [`REGISTRY`] lists them, one line each. `longreach diagnose`
//! iterates the registry: for every effect the model lacks it fits model + effect and
//! ranks the candidates.
//!
//! # Adding an effect (worked example)
//!
//! Suppose the ropes lose part of their pre-load because the rope ends slip in their
//! clamps: a `preload_loss` effect scaling the tensioner force. It needs one file and
//! one registry line:
//!
//! 1. Create `crates/drive/src/effects/preload_loss.rs`:
//!
//! ```ignore
//! //! Loss of pre-load: the tensioner delivers only a fraction of its setting.
//! use super::{DataKind, Effect, EffectParam};
//! use crate::{DriveError, RigSpec};
//! use longreach_rope::RopeLaw;
//!
//! /// See the module docs.
//! #[derive(Debug)]
//! pub struct PreloadLoss;
//!
//! const PARAMS: &[EffectParam] = &[EffectParam {
//!     name: "fraction_lost", unit: "1", default: 0.1, lower: 0.0, upper: 0.9, log_scale: false,
//! }];
//!
//! impl Effect for PreloadLoss {
//!     fn name(&self) -> &'static str { "preload_loss" }
//!     fn doc(&self) -> &'static str { "Clamp slip lowers the mean tension: ..." }
//!     fn params(&self) -> &'static [EffectParam] { PARAMS }
//!     fn applies_to(&self, kind: DataKind) -> bool { kind == DataKind::SineSweep }
//!     fn present_in(&self, _law: &RopeLaw, _rig: Option<&RigSpec>) -> bool { false }
//!     fn apply(&self, v: &[f64], _law: &mut RopeLaw, rig: Option<&mut RigSpec>) -> Result<(), DriveError> {
//!         if let Some(rig) = rig { rig.mean_tension_n *= 1.0 - v[0]; }
//!         Ok(())
//!     }
//! }
//! ```
//!
//! 2. Add `mod preload_loss;` below and `&preload_loss::PreloadLoss,` to [`REGISTRY`].
//!
//! That is all: `diagnose` now fits and ranks it, model files accept
//! `[[effect]] name = "preload_loss"`, and `synth --effect preload_loss=0.2` hides it in
//! synthetic data. The confusion-matrix test (`crates/ident/tests/confusion.rs`) picks
//! it up too; give it parameter values the data can reveal.

mod extra_retardation;
mod hooks;
mod internal_damping;
mod nonlinear_creep;
mod nonlinear_stiffness;
mod plastic_ratchet;
mod relay_friction;

pub use extra_retardation::ExtraRetardation;
pub use hooks::{JointForce, JointTorque};
pub use internal_damping::InternalDamping;
pub use nonlinear_creep::NonlinearCreepEffect;
pub use nonlinear_stiffness::NonlinearStiffness;
pub use plastic_ratchet::PlasticRatchet;
pub use relay_friction::RelayFrictionEffect;

use longreach_rope::RopeLaw;

use crate::{DriveError, RigSpec};

/// The kind of measurement an effect is looked for in (the `kind` of a dataset).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DataKind {
    /// Stepped-sine sweep of the cable-pulley rig.
    SineSweep,
    /// Tension relaxation at constant strain.
    Relaxation,
    /// Cyclic load-strain test.
    Cyclic,
}

/// One parameter of an effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectParam {
    /// Name, as in model files (`[effect.params]`).
    pub name: &'static str,
    /// Unit (SI).
    pub unit: &'static str,
    /// Starting value of a fit, and the value `synth` hides when none is given.
    pub default: f64,
    /// Lower bound.
    pub lower: f64,
    /// Upper bound.
    pub upper: f64,
    /// Fit on `ln(value)` (positive parameters spanning decades).
    pub log_scale: bool,
}

/// A physical effect that can be added to a model.
pub trait Effect: Sync + std::fmt::Debug {
    /// Name as in model files and reports (snake_case).
    fn name(&self) -> &'static str;
    /// A paragraph of physics: what the effect is, what it does to the data.
    fn doc(&self) -> &'static str;
    /// Parameters, in the order `apply` takes them.
    fn params(&self) -> &'static [EffectParam];
    /// True when a measurement of this kind can reveal the effect.
    fn applies_to(&self, kind: DataKind) -> bool;
    /// True when `law` (or, for effects acting on the transmission, `rig` when given)
    /// already holds this effect (diagnose then skips it).
    fn present_in(&self, law: &RopeLaw, rig: Option<&RigSpec>) -> bool;
    /// Adds the effect with parameter values `values` to the rope law and, when it acts
    /// on the transmission, to the rig.
    fn apply(
        &self,
        values: &[f64],
        law: &mut RopeLaw,
        rig: Option<&mut RigSpec>,
    ) -> Result<(), DriveError>;
}

/// Every registered effect, one line each.
pub static REGISTRY: &[&dyn Effect] = &[
    &nonlinear_stiffness::NonlinearStiffness,
    &internal_damping::InternalDamping,
    &extra_retardation::ExtraRetardation,
    &nonlinear_creep::NonlinearCreepEffect,
    &plastic_ratchet::PlasticRatchet,
    &relay_friction::RelayFrictionEffect,
];

/// The registered effect called `name`.
pub fn find(name: &str) -> Option<&'static dyn Effect> {
    REGISTRY.iter().copied().find(|e| e.name() == name)
}

/// Names of every registered effect (for error messages).
pub fn names() -> Vec<&'static str> {
    REGISTRY.iter().map(|e| e.name()).collect()
}

/// Checks that `values` has one finite value per parameter, within bounds.
pub(crate) fn check(effect: &dyn Effect, values: &[f64]) -> Result<(), DriveError> {
    let params = effect.params();
    if values.len() != params.len() {
        return Err(DriveError::BadParameter {
            field: effect.name().to_string(),
            value: values.len() as f64,
            reason: format!(
                "takes {} parameter(s): {}",
                params.len(),
                params.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
            ),
        });
    }
    for (p, &v) in params.iter().zip(values) {
        if !(v.is_finite() && v >= p.lower && v <= p.upper) {
            return Err(DriveError::BadParameter {
                field: format!("{}.{}", effect.name(), p.name),
                value: v,
                reason: format!("must lie in [{}, {}] {}", p.lower, p.upper, p.unit),
            });
        }
    }
    Ok(())
}
