//! Named physical effects the paper's model leaves out (its Sec. V-VI), as plugins.
//!
//! An effect is a small object implementing [`Effect`]: a name, a paragraph of physics,
//! named parameters with units, bounds and defaults ([`EffectParam`]), the kinds of
//! measurement that can reveal it ([`DataKind`]), the [`Site`] where it acts, and hooks
//! with default methods that do nothing, in the spirit of rapier's `PhysicsHooks` and
//! MuJoCo's plugins:
//!
//! | hook | site | what it may do |
//! |---|---|---|
//! | [`Effect::on_law`] | rope law | change the constitutive law of every rope (span) it applies to |
//! | [`Effect::on_pair`] | span, relay pulley, motor | change a rope pair's spec (relays, motor, tensioner) |
//! | [`Effect::joint_force`] | joint | add a passive torque at a joint, with states of its own ([`JointForce`]) |
//! | [`Effect::sensor`] | sensor | transform what a sensor reports of a channel ([`SensorModel`]) |
//!
//! A plant applies them when it is built ([`Applied`]): the rig to its one pair and its
//! output shaft ([`crate::RigModel::with_effects`]), the arm to each transmission's pair
//! and each joint (crates/arm). The implicit step evaluates a joint force at every Newton
//! iteration, with its derivatives in the Newton matrix, and advances its states once
//! per step ([`crate::transmission::step`]).
//!
//! Every effect lives in its own file; [`REGISTRY`] lists them, one line each.
//! `longreach diagnose` iterates the registry: for every effect the model lacks it fits
//! model + effect and ranks the candidates. Nothing outside this module matches on an
//! effect's name.
//!
//! # Adding an effect (worked example)
//!
//! Suppose the output shaft of the rig (or a joint of an arm) drags in a lip seal: a
//! torque proportional to the rate but only beyond a breakaway rate, a `seal_drag`
//! effect at the joint site. It needs one file and one registry line:
//!
//! 1. Create `crates/drive/src/effects/seal_drag.rs`:
//!
//! ```ignore
//! //! Drag of a lip seal on a joint's shaft.
//! use std::sync::Arc;
//! use super::{DataKind, Effect, EffectParam, JointForce, JointTorque, Site, Target};
//! use crate::DriveError;
//!
//! /// See the module docs.
//! #[derive(Debug)]
//! pub struct SealDrag;
//!
//! const PARAMS: &[EffectParam] = &[EffectParam {
//!     name: "drag_n_m_s", unit: "N*m*s", default: 0.01, lower: 1e-5, upper: 10.0,
//!     log_scale: true, fitted: true,
//! }];
//!
//! /// The compiled torque law: `-d w` beyond 0.1 rad/s.
//! #[derive(Debug)]
//! struct Drag(f64);
//! impl JointForce for Drag {
//!     fn torque(&self, _q: f64, w: f64, _state: &[f64]) -> JointTorque {
//!         if w.abs() <= 0.1 { return JointTorque::default(); }
//!         JointTorque { torque_n_m: -self.0 * (w - 0.1 * w.signum()), d_angle_n_m: 0.0, d_rate_n_m_s: -self.0 }
//!     }
//! }
//!
//! impl Effect for SealDrag {
//!     fn name(&self) -> &'static str { "seal_drag" }
//!     fn doc(&self) -> &'static str { "A lip seal drags the shaft beyond a breakaway rate: ..." }
//!     fn params(&self) -> &'static [EffectParam] { PARAMS }
//!     fn site(&self) -> Site { Site::Joint }
//!     fn applies_to(&self, kind: DataKind) -> bool { kind == DataKind::SineSweep }
//!     fn present_in(&self, target: &Target<'_>) -> bool { target.holds_joint_effect(self) }
//!     fn joint_force(&self, v: &[f64]) -> Result<Option<Arc<dyn JointForce>>, DriveError> {
//!         Ok(Some(Arc::new(Drag(v[0]))))
//!     }
//! }
//! ```
//!
//! 2. Add `mod seal_drag;` below and `&seal_drag::SealDrag,` to [`REGISTRY`].
//!
//! That is all: `diagnose` now fits and ranks it, model files accept
//! `[[effect]] name = "seal_drag"`, `synth --effect seal_drag=0.05` hides it in
//! synthetic data, and the rig and every arm joint can carry it. The confusion-matrix
//! study (`crates/ident/tests/confusion.rs`) picks it up too; give it parameter values
//! the data can reveal. [`joint_friction`](JointFriction) is a complete example of a
//! joint-site effect, [`relay_friction`](RelayFrictionEffect) of a pair-site one.

mod extra_retardation;
mod internal_damping;
mod joint_friction;
mod nonlinear_creep;
mod nonlinear_stiffness;
mod plastic_ratchet;
mod relay_friction;
mod sensor_delay;

pub use crate::transmission::{JointForce, JointTorque};
pub use extra_retardation::ExtraRetardation;
pub use internal_damping::InternalDamping;
pub use joint_friction::{BearingFriction, JointFriction};
pub use nonlinear_creep::NonlinearCreepEffect;
pub use nonlinear_stiffness::NonlinearStiffness;
pub use plastic_ratchet::PlasticRatchet;
pub use relay_friction::RelayFrictionEffect;
pub use sensor_delay::{Delay, SensorDelay};

use std::sync::Arc;

use longreach_rope::RopeLaw;

use crate::transmission::PairSpec;
use crate::DriveError;

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

/// Where an effect acts in a plant.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Site {
    /// The constitutive law of every rope (and span) ([`Effect::on_law`]).
    RopeLaw,
    /// The spans of a rope pair ([`Effect::on_pair`]).
    Span,
    /// The relay pulleys of a rope pair ([`Effect::on_pair`]).
    RelayPulley,
    /// A joint: the rig's output shaft, an arm's joint ([`Effect::joint_force`]).
    Joint,
    /// A link of an arm (its compliance; no hook yet).
    Link,
    /// The motor of a rope pair ([`Effect::on_pair`]).
    Motor,
    /// A measured channel ([`Effect::sensor`]).
    Sensor,
}

impl Site {
    /// Lower-case name (reports).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::RopeLaw => "rope law",
            Self::Span => "span",
            Self::RelayPulley => "relay pulley",
            Self::Joint => "joint",
            Self::Link => "link",
            Self::Motor => "motor",
            Self::Sensor => "sensor",
        }
    }
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
    /// Fitted when the effect is a candidate (false: a regularisation or a setting
    /// the data cannot pin down, kept at its default unless a model file frees it).
    pub fitted: bool,
}

/// What an effect may already be present in ([`Effect::present_in`]).
#[derive(Debug, Clone, Copy)]
pub struct Target<'a> {
    /// The rope law.
    pub law: &'a RopeLaw,
    /// The rope pair, when the data's plant has one.
    pub pair: Option<&'a PairSpec>,
    /// The effects already acting at the joints (their names, as in
    /// [`crate::transmission::JointLoad::effect`]).
    pub joint_effects: &'a [&'static str],
}

impl Target<'_> {
    /// True when `effect` already acts at a joint.
    pub fn holds_joint_effect(&self, effect: &dyn Effect) -> bool {
        self.joint_effects.contains(&effect.name())
    }
}

/// A physical effect that can be added to a model. Only the description is required;
/// every hook has a default that does nothing (module docs).
pub trait Effect: Sync + std::fmt::Debug {
    /// Name as in model files and reports (snake_case).
    fn name(&self) -> &'static str;
    /// A paragraph of physics: what the effect is, what it does to the data.
    fn doc(&self) -> &'static str;
    /// Parameters, in the order the hooks take them.
    fn params(&self) -> &'static [EffectParam];
    /// Where the effect acts.
    fn site(&self) -> Site;
    /// True when a measurement of this kind can reveal the effect.
    fn applies_to(&self, kind: DataKind) -> bool;
    /// True when `target` already holds this effect (diagnose then skips it).
    fn present_in(&self, _target: &Target<'_>) -> bool {
        false
    }
    /// Rope-law site: adds the effect with parameter values `values` to a rope law.
    fn on_law(&self, _values: &[f64], _law: &mut RopeLaw) -> Result<(), DriveError> {
        Ok(())
    }
    /// Span, relay-pulley or motor site: adds the effect to a rope pair's spec.
    fn on_pair(&self, _values: &[f64], _pair: &mut PairSpec) -> Result<(), DriveError> {
        Ok(())
    }
    /// Joint site: the passive torque the effect adds at a joint (`None`: none).
    fn joint_force(&self, _values: &[f64]) -> Result<Option<Arc<dyn JointForce>>, DriveError> {
        Ok(None)
    }
    /// Sensor site: how the effect changes what a sensor reports (`None`: it does not).
    fn sensor(&self, _values: &[f64]) -> Result<Option<Arc<dyn SensorModel>>, DriveError> {
        Ok(None)
    }
}

/// What a sensor-site effect does to a measured channel: the plant simulates the true
/// quantity, the sensor model turns it into what the sensor reports, and that is what
/// is compared with the measurement.
pub trait SensorModel: Send + Sync + std::fmt::Debug {
    /// Whether it acts on the channel called `channel` (a dataset column name, e.g.
    /// `output_angle_rad`).
    fn acts_on(&self, channel: &str) -> bool;
    /// Turns the true values of the channel, sampled at `time_s`, into the reported ones,
    /// in place.
    fn apply(&self, time_s: &[f64], values: &mut [f64]);
    /// Its small-signal response at `frequency_hz` (reported over true), when it is
    /// linear and has one: fits start from the plant's closed-form response times it.
    fn response(&self, _frequency_hz: f64) -> Option<num_complex::Complex64> {
        None
    }
}

/// Every registered effect, one line each.
pub static REGISTRY: &[&dyn Effect] = &[
    &nonlinear_stiffness::NonlinearStiffness,
    &internal_damping::InternalDamping,
    &extra_retardation::ExtraRetardation,
    &nonlinear_creep::NonlinearCreepEffect,
    &plastic_ratchet::PlasticRatchet,
    &relay_friction::RelayFrictionEffect,
    &joint_friction::JointFriction,
    &sensor_delay::SensorDelay,
];

/// The registered effect called `name`.
pub fn find(name: &str) -> Option<&'static dyn Effect> {
    REGISTRY.iter().copied().find(|e| e.name() == name)
}

/// Names of every registered effect (for error messages).
pub fn names() -> Vec<&'static str> {
    REGISTRY.iter().map(|e| e.name()).collect()
}

/// True when `a` and `b` are the same registered effect.
pub fn same(a: &dyn Effect, b: &dyn Effect) -> bool {
    a.name() == b.name()
}

/// Checks that `values` has one finite value per parameter, within bounds.
pub fn check(effect: &dyn Effect, values: &[f64]) -> Result<(), DriveError> {
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

/// An effect with its parameter values (checked), as a plant applies it when it is
/// built.
#[derive(Debug, Clone)]
pub struct Applied {
    /// The registered effect.
    pub effect: &'static dyn Effect,
    /// One value per parameter, within bounds.
    pub values: Vec<f64>,
}

impl Applied {
    /// Checks `values` against the effect's parameters.
    pub fn new(effect: &'static dyn Effect, values: Vec<f64>) -> Result<Self, DriveError> {
        check(effect, &values)?;
        Ok(Self { effect, values })
    }

    /// The effect at its default parameters.
    pub fn default_of(effect: &'static dyn Effect) -> Self {
        Self {
            effect,
            values: effect.params().iter().map(|p| p.default).collect(),
        }
    }

    /// Applies the rope-law and pair hooks to a rope pair.
    pub fn apply_to_pair(&self, pair: &mut PairSpec) -> Result<(), DriveError> {
        self.effect.on_law(&self.values, &mut pair.law)?;
        self.effect.on_pair(&self.values, pair)?;
        pair.law.validate()?;
        Ok(())
    }

    /// Applies the rope-law hook to a rope law alone (a specimen).
    pub fn apply_to_law(&self, law: &mut RopeLaw) -> Result<(), DriveError> {
        self.effect.on_law(&self.values, law)?;
        law.validate()?;
        Ok(())
    }

    /// The passive torque the effect adds at a joint, if any.
    pub fn joint_force(&self) -> Result<Option<Arc<dyn JointForce>>, DriveError> {
        self.effect.joint_force(&self.values)
    }

    /// What the effect does to a sensor, if anything.
    pub fn sensor(&self) -> Result<Option<Arc<dyn SensorModel>>, DriveError> {
        self.effect.sensor(&self.values)
    }
}
