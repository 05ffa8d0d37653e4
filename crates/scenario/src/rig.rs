//! The `[rig]` table: the paper's cable-pulley rig, with the same keys as the
//! measurement format (`docs/measurements.md`), plus the rope law and pre-stretch.

use serde::Deserialize;

use longreach_drive::{DriveError, RelayFriction, RigSpec, Tensioner};
use longreach_rope::LawKind;

use crate::error::ScenarioError;
use crate::spec::{field_error, resolve_rope, RopeRef};

fn default_relay_pulleys() -> u32 {
    3
}
fn default_relay_radius_m() -> f64 {
    0.025
}
fn default_tensioner() -> Tensioner {
    Tensioner::ConstantForce
}
fn default_prestretch_n() -> f64 {
    490.0
}
fn default_slip_rate_rad_s() -> f64 {
    RelayFriction::DEFAULT_SLIP_RATE_RAD_S
}

/// `[rig.relay_friction]`: bearing friction and inertia of every relay pulley
/// ([`RelayFriction`]); each rope is then simulated as `relay_pulleys + 1` spans.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RelayFrictionSection {
    /// Friction torque per unit pulley radius per newton of hub load [-].
    pub coefficient: f64,
    /// Inertia of one relay pulley [kg*m^2].
    pub inertia_kg_m2: f64,
    /// Regularisation rate of the Coulomb friction [rad/s] (optional).
    #[serde(default = "default_slip_rate_rad_s")]
    pub slip_rate_rad_s: f64,
}

/// `[rig]` as written in a file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigSection {
    /// Catalog name or inline rope table.
    pub rope: RopeRef,
    /// `elastic`, `four_element` or `flory`; default: the paper's law for the rope.
    #[serde(default)]
    pub law: Option<LawKind>,
    /// L [m].
    pub rope_length_m: f64,
    /// r1 [m].
    pub input_radius_m: f64,
    /// r2 [m].
    pub output_radius_m: f64,
    /// I [kg*m^2].
    pub output_inertia_kg_m2: f64,
    /// C [N*m*s].
    pub output_damping_n_m_s: f64,
    /// Idler pulleys per rope (ideal unless `relay_friction` is given).
    #[serde(default = "default_relay_pulleys")]
    pub relay_pulleys: u32,
    /// Their radius [m].
    #[serde(default = "default_relay_radius_m")]
    pub relay_radius_m: f64,
    /// Friction and inertia of the relay pulleys (optional; absent: ideal pulleys).
    #[serde(default)]
    pub relay_friction: Option<RelayFrictionSection>,
    /// `constant_force` (default) or `fixed`.
    #[serde(default = "default_tensioner")]
    pub tensioner: Tensioner,
    /// Pre-stretch tension [N] (sets Flory's ratchet), default 490 N as in the paper.
    #[serde(default = "default_prestretch_n")]
    pub prestretch_n: f64,
}

impl RigSection {
    /// Builds the rig at `mean_tension_n`, validating every field against `text`.
    pub fn to_spec(
        &self,
        text: &str,
        file: &str,
        mean_tension_n: f64,
        tension_field: &str,
    ) -> Result<RigSpec, ScenarioError> {
        let (name, _, law) = resolve_rope(text, file, "rig.rope", &self.rope, self.law)?;
        let spec = RigSpec {
            rope_name: name,
            law,
            rope_length_m: self.rope_length_m,
            input_radius_m: self.input_radius_m,
            output_radius_m: self.output_radius_m,
            output_inertia_kg_m2: self.output_inertia_kg_m2,
            output_damping_n_m_s: self.output_damping_n_m_s,
            relay_pulleys: self.relay_pulleys,
            relay_radius_m: self.relay_radius_m,
            relay_friction: self.relay_friction.map(|r| RelayFriction {
                coefficient: r.coefficient,
                inertia_kg_m2: r.inertia_kg_m2,
                slip_rate_rad_s: r.slip_rate_rad_s,
                coefficient_table: None,
            }),
            tensioner: self.tensioner,
            mean_tension_n,
            prestretch_n: self.prestretch_n,
        };
        spec.validate().map_err(|e| match e {
            DriveError::BadParameter {
                field,
                value,
                reason,
            } => {
                let path = if field == "mean_tension_n" {
                    tension_field.to_string()
                } else {
                    format!("rig.{field}")
                };
                let fix = if field.starts_with("relay_friction") {
                    "[rig.relay_friction] takes coefficient in [0, 1) (bearings: 0.001-0.05), \
                     inertia_kg_m2 >= 0 (a 25 mm aluminium pulley: ~2e-5) and optionally \
                     slip_rate_rad_s > 0"
                } else {
                    "give a physical value in SI units (metres, kilograms, newtons, seconds)"
                };
                field_error(text, file, &path, format!("{value} {reason}"), fix)
            }
            other => field_error(
                text,
                file,
                "rig",
                other.to_string(),
                "check the rope constants",
            ),
        })?;
        Ok(spec)
    }
}
