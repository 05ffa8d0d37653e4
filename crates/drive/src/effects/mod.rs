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
//! | [`Effect::on_payload`] | link | change the arm's payload ([`Payload`]) before its dynamics are built |
//! | [`Effect::sensor`] | sensor | transform what a sensor reports of a channel ([`SensorModel`]) |
//!
//! A plant applies them when it is built ([`Applied`]): the rig to its one pair and its
//! output shaft ([`crate::RigModel::with_effects`]), the arm to each transmission's pair,
//! each joint and its payload (crates/arm). A hook an effect does not override costs
//! nothing at run time: the hooks run once, when the plant is built. The implicit step evaluates a joint force at every Newton
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
//! joint-site effect, [`relay_friction`](RelayFrictionEffect) of a pair-site one,
//! [`motor_friction`](MotorFrictionEffect) of a motor-site one (through `on_pair`, on the
//! pair's motor) and [`payload_mass`](PayloadMass) of a link-site one (`on_payload`).

mod extra_retardation;
mod internal_damping;
mod joint_friction;
mod link_flexibility;
mod motor_friction;
mod nonlinear_creep;
mod nonlinear_stiffness;
mod payload_mass;
mod plastic_ratchet;
mod relay_friction;
mod sensor_delay;

pub use crate::transmission::{JointForce, JointTorque};
pub use extra_retardation::ExtraRetardation;
pub use internal_damping::InternalDamping;
pub use joint_friction::{BearingFriction, JointFriction};
pub use link_flexibility::LinkFlexibility;
pub use motor_friction::MotorFrictionEffect;
pub use nonlinear_creep::NonlinearCreepEffect;
pub use nonlinear_stiffness::NonlinearStiffness;
pub use payload_mass::PayloadMass;
pub use plastic_ratchet::PlasticRatchet;
pub use relay_friction::RelayFrictionEffect;
pub use sensor_delay::{Delay, SensorDelay};

use std::sync::Arc;

use longreach_rope::{RopeLaw, Table};

use crate::transmission::PairSpec;
use crate::DriveError;

/// The bending of a flexible link of an arm, as an effect at the link site sees it
/// ([`Effect::on_link`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkBending {
    /// Bending stiffness `E I`, N*m^2.
    pub ei_n_m2: f64,
    /// Structural damping ratio of its bending modes.
    pub damping_ratio: f64,
}

/// The kind of measurement an effect is looked for in (the `kind` of a dataset).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DataKind {
    /// Stepped-sine sweep of the cable-pulley rig.
    SineSweep,
    /// Tension relaxation at constant strain.
    Relaxation,
    /// Cyclic load-strain test.
    Cyclic,
    /// Moves of a long-reach arm measured through its own sensors.
    ArmMoves,
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
    /// A link of an arm: the payload it carries ([`Effect::on_payload`]), its bending
    /// ([`Effect::on_link`]).
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
    /// The function of one variable at the heart of the effect, when it has one: what
    /// its shape-free form tabulates ([`Shape`]). `None`: the effect has no such form.
    fn shape(&self) -> Option<Shape> {
        None
    }
    /// The parametric law's function (the one [`Self::shape`] describes) at parameter
    /// values `values` and argument `x`: the shape-free fit starts from it, reports plot
    /// it against the fitted table.
    fn curve(&self, _values: &[f64], _x: f64) -> f64 {
        f64::NAN
    }
    /// Rope-law site: adds the effect with parameter values (and shape-free law) `args`
    /// to a rope law.
    fn on_law(&self, _args: Args<'_>, _law: &mut RopeLaw) -> Result<(), DriveError> {
        Ok(())
    }
    /// Span, relay-pulley or motor site: adds the effect to a rope pair's spec.
    fn on_pair(&self, _args: Args<'_>, _pair: &mut PairSpec) -> Result<(), DriveError> {
        Ok(())
    }
    /// Joint site: the passive torque the effect adds at a joint (`None`: none).
    fn joint_force(&self, _args: Args<'_>) -> Result<Option<Arc<dyn JointForce>>, DriveError> {
        Ok(None)
    }
    /// Link site: changes the payload an arm carries (added to its link's inertial before
    /// anything is built from the arm: dynamics, gravity feed-forward, statics).
    fn on_payload(&self, _args: Args<'_>, _payload: &mut Payload) -> Result<(), DriveError> {
        Ok(())
    }
    /// Link site: changes the bending of a flexible link; `true` when it did.
    fn on_link(&self, _args: Args<'_>, _link: &mut LinkBending) -> Result<bool, DriveError> {
        Ok(false)
    }
    /// Sensor site: how the effect changes what a sensor reports (`None`: it does not).
    fn sensor(&self, _args: Args<'_>) -> Result<Option<Arc<dyn SensorModel>>, DriveError> {
        Ok(None)
    }
}

/// What an effect's hooks receive: its parameter values, and, for its shape-free form,
/// the table of its function ([`Effect::shape`]) that replaces the parameters
/// [`Shape::replaces`] names.
#[derive(Debug, Clone, Copy)]
pub struct Args<'a> {
    /// One value per parameter ([`Effect::params`]).
    pub values: &'a [f64],
    /// The shape-free law, when the effect is used in that form.
    pub table: Option<&'a Table>,
}

impl<'a> Args<'a> {
    /// The parametric form with `values`.
    pub fn values(values: &'a [f64]) -> Self {
        Self {
            values,
            table: None,
        }
    }
}

/// Which quantity of a plant an effect's function takes (where the shape-free table's
/// knots are placed: over the range the data visits).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Argument {
    /// The tension of a rope (or span), N.
    TensionN,
    /// The hub load of a relay pulley (the sum of the tensions on either side), N.
    HubLoadN,
    /// The rate of a joint (its absolute value), rad/s.
    JointRateRadS,
}

impl Argument {
    /// Name and unit, as in model files.
    pub fn name(self) -> &'static str {
        match self {
            Self::TensionN => "tension_n",
            Self::HubLoadN => "hub_load_n",
            Self::JointRateRadS => "rate_rad_s",
        }
    }
}

/// The function of one variable at the heart of an effect, for its shape-free form: a
/// table of values at knots over the range the data visits, fitted in place of the
/// parametric law ([`Effect::curve`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shape {
    /// What the function takes.
    pub argument: Argument,
    /// What it gives (a name for reports and model files) and its unit.
    pub value: &'static str,
    /// Unit of the value.
    pub unit: &'static str,
    /// The value at argument 0 when it is fixed (a scale held by another parameter),
    /// `None` when it is fitted.
    pub value_at_zero: Option<f64>,
    /// The values never fall from knot to knot (a stiffening, a creep that speeds up
    /// with load); otherwise only positive.
    pub non_decreasing: bool,
    /// Largest value a knot may take.
    pub max_value: f64,
    /// The law changes over decades of its argument (friction against sliding speed:
    /// a Stribeck drop sits at a few hundredths of the largest speed, a viscous rise
    /// at its top): the knots after 0 are spaced geometrically, from
    /// [`Shape::LOG_KNOTS_DECADES`] below the largest value the data visit up to it;
    /// otherwise they follow the data's distribution.
    pub log_knots: bool,
    /// The parameters the table replaces (held at their values, not fitted).
    pub replaces: &'static [&'static str],
}

impl Shape {
    /// Decades below the largest argument value where the first knot after 0 of a
    /// [`Shape::log_knots`] table sits.
    pub const LOG_KNOTS_DECADES: f64 = 2.5;
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

/// The payload of an arm as link-site effects see it ([`Effect::on_payload`]): a point
/// mass at the point the arm's scenario names (its `[payload]` link and offset, the tip
/// frame's origin without one). The arm adds it to that link's inertial when it is built.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Payload {
    /// Mass, kg (the scenario's, 0 without one); must stay >= 0.
    pub mass_kg: f64,
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
    &link_flexibility::LinkFlexibility,
    &sensor_delay::SensorDelay,
    &motor_friction::MotorFrictionEffect,
    &payload_mass::PayloadMass,
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

/// Whether `effect` acts on a flexible link's bending (its [`Effect::on_link`] hook,
/// probed with its default values): such an effect acts on links, not on the payload.
pub fn bends_links(effect: &'static dyn Effect) -> bool {
    let values = effect.params().iter().map(|p| p.default).collect();
    let mut probe = LinkBending {
        ei_n_m2: 1.0,
        damping_ratio: 0.0,
    };
    Applied::new(effect, values)
        .and_then(|a| a.apply_to_link(&mut probe))
        .unwrap_or(false)
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

/// An effect with its parameter values (checked), and its shape-free law when used in
/// that form, as a plant applies it when it is built.
#[derive(Debug, Clone)]
pub struct Applied {
    /// The registered effect.
    pub effect: &'static dyn Effect,
    /// One value per parameter, within bounds.
    pub values: Vec<f64>,
    /// The shape-free law ([`Effect::shape`]), replacing the parametric function.
    pub table: Option<Table>,
}

impl Applied {
    /// Checks `values` against the effect's parameters.
    pub fn new(effect: &'static dyn Effect, values: Vec<f64>) -> Result<Self, DriveError> {
        check(effect, &values)?;
        Ok(Self {
            effect,
            values,
            table: None,
        })
    }

    /// [`Self::new`] in the shape-free form `table` (checked against the effect's
    /// [`Shape`]).
    pub fn shaped(
        effect: &'static dyn Effect,
        values: Vec<f64>,
        table: Table,
    ) -> Result<Self, DriveError> {
        let shape = effect.shape().ok_or_else(|| DriveError::BadParameter {
            field: format!("{}.shape", effect.name()),
            value: f64::NAN,
            reason: "this effect has no shape-free form".into(),
        })?;
        check_table(effect.name(), &shape, &table)?;
        let mut a = Self::new(effect, values)?;
        a.table = Some(table);
        Ok(a)
    }

    /// The effect at its default parameters.
    pub fn default_of(effect: &'static dyn Effect) -> Self {
        Self {
            effect,
            values: effect.params().iter().map(|p| p.default).collect(),
            table: None,
        }
    }

    /// What the hooks receive.
    pub fn args(&self) -> Args<'_> {
        Args {
            values: &self.values,
            table: self.table.as_ref(),
        }
    }

    /// Applies the rope-law and pair hooks to a rope pair.
    pub fn apply_to_pair(&self, pair: &mut PairSpec) -> Result<(), DriveError> {
        self.effect.on_law(self.args(), &mut pair.law)?;
        self.effect.on_pair(self.args(), pair)?;
        pair.law.validate()?;
        Ok(())
    }

    /// Applies the rope-law hook to a rope law alone (a specimen).
    pub fn apply_to_law(&self, law: &mut RopeLaw) -> Result<(), DriveError> {
        self.effect.on_law(self.args(), law)?;
        law.validate()?;
        Ok(())
    }

    /// The passive torque the effect adds at a joint, if any.
    pub fn joint_force(&self) -> Result<Option<Arc<dyn JointForce>>, DriveError> {
        self.effect.joint_force(self.args())
    }

    /// Applies the link-site hook to an arm's payload; the mass must stay >= 0.
    pub fn apply_to_payload(&self, payload: &mut Payload) -> Result<(), DriveError> {
        self.effect.on_payload(self.args(), payload)?;
        if !(payload.mass_kg.is_finite() && payload.mass_kg >= 0.0) {
            return Err(DriveError::BadParameter {
                field: format!("{}.payload.mass_kg", self.effect.name()),
                value: payload.mass_kg,
                reason: "leaves a payload below 0 kg: the correction of a known payload \
                         cannot take away more than its mass"
                    .into(),
            });
        }
        Ok(())
    }

    /// Applies the link hook to a flexible link's bending; `true` when the effect acts
    /// there.
    pub fn apply_to_link(&self, link: &mut LinkBending) -> Result<bool, DriveError> {
        self.effect.on_link(self.args(), link)
    }

    /// What the effect does to a sensor, if anything.
    pub fn sensor(&self) -> Result<Option<Arc<dyn SensorModel>>, DriveError> {
        self.effect.sensor(self.args())
    }
}

/// Checks a shape-free table against the effect's [`Shape`]: positive values, within
/// the largest, never falling when the shape says so, the value at 0 when it is fixed.
pub fn check_table(effect: &str, shape: &Shape, table: &Table) -> Result<(), DriveError> {
    let bad = |reason: String, value: f64| DriveError::BadParameter {
        field: format!("{effect}.shape.{}", shape.value),
        value,
        reason,
    };
    for &v in table.y() {
        if !(v > 0.0 && v <= shape.max_value) {
            return Err(bad(
                format!(
                    "every value must lie in (0, {}] {}",
                    shape.max_value, shape.unit
                ),
                v,
            ));
        }
    }
    if shape.non_decreasing && !table.non_decreasing() {
        return Err(bad(
            "the values must not fall from knot to knot".into(),
            f64::NAN,
        ));
    }
    if let Some(v0) = shape.value_at_zero {
        if (table.y()[0] - v0).abs() > 1e-12 * v0.abs().max(1.0) {
            return Err(bad(
                format!("the value at 0 is fixed at {v0}"),
                table.y()[0],
            ));
        }
    }
    Ok(())
}
