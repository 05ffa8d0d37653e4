//! What defines a rope pair: rope, pulleys, route, tensioner and motor (SI units), and
//! the routing matrix of a set of pairs.

use longreach_rope::{RopeLaw, RopeParams};
use serde::{Deserialize, Serialize};

use super::relay::RelayFriction;
use crate::error::DriveError;

/// How the pre-tension of a pair is held.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Tensioner {
    /// A carriage pulled with `2 * preload` holds `f+ + f- = 2 * preload` (per rope) at
    /// all times while each rope's own tension is free (the paper's rig).
    ConstantForce,
    /// Rope ends fixed after pre-tensioning to the preload at the initial pose.
    Fixed,
}

/// One relay (idler) pulley on the route of a pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Relay {
    /// The joint whose axis the pulley turns about: it is mounted on that joint's
    /// proximal link, so a rotation of the joint changes the wrap on its distal side
    /// (`G`, module docs). `None`: fixed to the base (the idlers of the paper's rig).
    pub joint: Option<usize>,
    /// Radius, m.
    pub radius_m: f64,
    /// Crossing sign `+1` (the rope wraps the relay the same way as the joint pulley)
    /// or `-1`; no effect on a relay fixed to the base.
    pub sign: f64,
}

/// How the motor of a pair is driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotorMode {
    /// The motor angle follows its reference exactly (an ideal stiff drive, like the
    /// paper's rig input or MuJoCo's huge-armature motors).
    Kinematic,
    /// A torque-controlled motor with a PD position servo, gravity feed-forward and
    /// torque saturation.
    Servo {
        /// Proportional gain, N*m/rad (motor side).
        kp_n_m_per_rad: f64,
        /// Derivative gain, N*m*s/rad.
        kd_n_m_s_per_rad: f64,
        /// Torque saturation, N*m (infinite for none).
        torque_limit_n_m: f64,
        /// Feed forward the static torque that holds the reference pose.
        gravity_feedforward: bool,
    },
}

/// The motor of a pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorSpec {
    /// Rotor plus pulley inertia on the motor axis, kg*m^2.
    pub inertia_kg_m2: f64,
    /// Viscous loss, N*m*s/rad.
    pub damping_n_m_s: f64,
    /// Kinematic or servo.
    pub mode: MotorMode,
    /// Friction on the motor side (gearbox, bearings, seals) that the servo must
    /// overcome; `None`: none (the step takes exactly the path it took before the field
    /// existed). A kinematic motor follows its reference whatever it costs, so friction
    /// there changes nothing.
    pub friction: Option<MotorFriction>,
}

/// Coulomb plus viscous friction on a motor's axis: the torque
/// `F_c tanh(w / w_s) + b w` opposes its rate `w` (the `motor_friction` effect).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorFriction {
    /// Dry (Coulomb) torque `F_c`, N*m.
    pub coulomb_n_m: f64,
    /// Viscous torque per rate `b`, N*m*s/rad (on top of [`MotorSpec::damping_n_m_s`]).
    pub viscous_n_m_s: f64,
    /// Rate `w_s` over which the dry torque is regularised (tanh), rad/s.
    pub slip_rate_rad_s: f64,
}

impl MotorFriction {
    /// Default regularisation rate, rad/s: far below a motor's rates in a move, wide
    /// enough for the implicit step's Newton iteration.
    pub const DEFAULT_SLIP_RATE_RAD_S: f64 = 1e-2;

    /// The friction torque resisting the rate `rate_rad_s` (positive along the rate, so
    /// it enters the motor equation as `J a + b_m w + F = tau - r_m phi`) and its
    /// derivative with respect to the rate.
    #[inline]
    pub fn resisting(&self, rate_rad_s: f64) -> (f64, f64) {
        let x = rate_rad_s / self.slip_rate_rad_s;
        // tanh rounds to +-1 beyond 22 slip rates: skip it there (bitwise the same).
        let s = if x.abs() >= 22.0 {
            x.signum()
        } else {
            x.tanh()
        };
        (
            self.coulomb_n_m * s + self.viscous_n_m_s * rate_rad_s,
            self.coulomb_n_m * (1.0 - s * s) / self.slip_rate_rad_s + self.viscous_n_m_s,
        )
    }

    /// Checks that every value is finite, the torques >= 0 and the slip rate > 0.
    pub fn validate(&self) -> Result<(), DriveError> {
        for (field, v, ok) in [
            ("coulomb_n_m", self.coulomb_n_m, self.coulomb_n_m >= 0.0),
            (
                "viscous_n_m_s",
                self.viscous_n_m_s,
                self.viscous_n_m_s >= 0.0,
            ),
            (
                "slip_rate_rad_s",
                self.slip_rate_rad_s,
                self.slip_rate_rad_s > 0.0,
            ),
        ] {
            if !(v.is_finite() && ok) {
                return Err(DriveError::BadParameter {
                    field: format!("motor_friction.{field}"),
                    value: v,
                    reason: "torques must be finite and >= 0, the slip rate > 0".into(),
                });
            }
        }
        Ok(())
    }
}

impl MotorSpec {
    /// A motor that follows its reference exactly.
    pub fn kinematic() -> Self {
        Self {
            inertia_kg_m2: 0.0,
            damping_n_m_s: 0.0,
            mode: MotorMode::Kinematic,
            friction: None,
        }
    }

    /// True for a servo (its angle is an unknown of the step).
    pub fn is_servo(&self) -> bool {
        matches!(self.mode, MotorMode::Servo { .. })
    }
}

/// One antagonistic rope pair driving one joint.
#[derive(Debug, Clone)]
pub struct PairSpec {
    /// Index of the driven joint.
    pub joint: usize,
    /// Rope name (catalog or inline), for reports.
    pub rope_name: String,
    /// Catalog data (tensile strength for the safety factor).
    pub rope: RopeParams,
    /// Law of each rope (per unit strain).
    pub law: RopeLaw,
    /// Ropes in parallel on each side of the pair.
    pub ropes_in_parallel: u32,
    /// Joint pulley radius, m.
    pub joint_radius_m: f64,
    /// Motor pulley radius, m.
    pub motor_radius_m: f64,
    /// Relay pulleys between the motor and the joint, in the order the rope meets them
    /// from the motor (those fixed to the base first, then by joint).
    pub route: Vec<Relay>,
    /// Rope length motor pulley to joint pulley, m.
    pub length_m: f64,
    /// Lengths of the spans between successive pulleys of the route, motor side first
    /// (`route.len() + 1` values), m; used when the relays have friction (each span is
    /// then a rope of its own). Scaled to sum to `length_m`; empty or of another length:
    /// equal spans.
    pub span_lengths_m: Vec<f64>,
    /// Pre-tension per rope, N.
    pub preload_n: f64,
    /// Tension each rope was pre-stretched to (sets Flory's ratchet), N.
    pub prestretch_n: f64,
    /// Tensioner.
    pub tensioner: Tensioner,
    /// Motor.
    pub motor: MotorSpec,
    /// Names of the registered effects applied to the pair (for reports).
    pub effects: Vec<String>,
    /// Friction and inertia of the relay pulleys (`None`: ideal relays, one tension per
    /// rope). With friction every rope is split into spans at its relays
    /// ([`super::relay`]).
    pub relay_friction: Option<RelayFriction>,
}

impl PairSpec {
    /// The routing-matrix row of this pair (length = number of joints): the joint
    /// pulley's radius at the driven joint, `sign * radius` at the joint of every relay
    /// mounted on one.
    pub fn routing_row(&self, ndofs: usize) -> Vec<f64> {
        let mut row = vec![0.0; ndofs];
        row[self.joint] = self.joint_radius_m;
        for r in &self.route {
            if let Some(k) = r.joint {
                row[k] += r.sign * r.radius_m;
            }
        }
        row
    }

    /// Checks every field for an arm of `ndofs` joints; `field` names the pair in
    /// messages (e.g. `transmission[2] (joint j3)`).
    pub fn validate(&self, ndofs: usize, field: &str) -> Result<(), DriveError> {
        let bad = |f: &str, reason: String| DriveError::BadTransmission {
            field: format!("{field}.{f}"),
            reason,
        };
        if self.joint >= ndofs {
            return Err(bad(
                "joint",
                format!("joint index {} out of range", self.joint),
            ));
        }
        for (what, v) in [
            ("joint_radius_m", self.joint_radius_m),
            ("motor_radius_m", self.motor_radius_m),
            ("length_m", self.length_m),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(what, format!("{v} must be finite and > 0")));
            }
        }
        for (what, v) in [
            ("preload_n", self.preload_n),
            ("prestretch_n", self.prestretch_n),
            ("motor.inertia_kg_m2", self.motor.inertia_kg_m2),
            ("motor.damping_n_m_s", self.motor.damping_n_m_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(what, format!("{v} must be finite and >= 0")));
            }
        }
        if self.ropes_in_parallel == 0 {
            return Err(bad("ropes_in_parallel", "must be at least 1".into()));
        }
        if self.tensioner == Tensioner::ConstantForce && self.preload_n <= 0.0 {
            return Err(bad(
                "preload_n",
                "a constant-force tensioner needs a preload > 0".into(),
            ));
        }
        if let MotorMode::Servo {
            kp_n_m_per_rad,
            kd_n_m_s_per_rad,
            torque_limit_n_m,
            ..
        } = self.motor.mode
        {
            if self.motor.inertia_kg_m2 <= 0.0 {
                return Err(bad(
                    "motor.inertia_kg_m2",
                    "a servo motor needs an inertia > 0 (or use mode = \"kinematic\")".into(),
                ));
            }
            for (what, v) in [
                ("motor.kp_n_m_per_rad", kp_n_m_per_rad),
                ("motor.kd_n_m_s_per_rad", kd_n_m_s_per_rad),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(bad(what, format!("{v} must be finite and >= 0")));
                }
            }
            if torque_limit_n_m.is_nan() || torque_limit_n_m <= 0.0 {
                return Err(bad(
                    "motor.torque_limit_n_m",
                    format!("{torque_limit_n_m} must be > 0"),
                ));
            }
        }
        for r in &self.route {
            if let Some(k) = r.joint {
                if k >= self.joint {
                    return Err(bad(
                        "route",
                        format!(
                            "relay at joint index {k} is not proximal to the driven joint {}",
                            self.joint
                        ),
                    ));
                }
            }
            if !(r.radius_m.is_finite() && r.radius_m > 0.0) || (r.sign.abs() - 1.0).abs() > 1e-12 {
                return Err(bad(
                    "route",
                    format!(
                        "relay radius {} m / sign {}: need radius > 0 and sign +1 or -1",
                        r.radius_m, r.sign
                    ),
                ));
            }
        }
        if let Some(mf) = &self.motor.friction {
            mf.validate()
                .map_err(|e| bad("motor.friction", e.to_string()))?;
        }
        if let Some(rf) = &self.relay_friction {
            rf.validate().map_err(|e| {
                bad(
                    "relay_friction",
                    format!("{e}; typical: coefficient 0.001-0.05, inertia 1e-5-1e-2 kg*m^2"),
                )
            })?;
        }
        self.law
            .validate()
            .map_err(|e| bad("rope", e.to_string()))?;
        Ok(())
    }
}

/// Routing matrix `R` (pairs x joints), row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct RoutingMatrix {
    /// Pairs (rows).
    pub rows: usize,
    /// Joints (columns).
    pub cols: usize,
    /// Entries, m.
    pub data: Vec<f64>,
}

impl RoutingMatrix {
    /// Builds `R` from the pairs.
    pub fn new(pairs: &[PairSpec], ndofs: usize) -> Self {
        let mut data = Vec::with_capacity(pairs.len() * ndofs);
        for p in pairs {
            data.extend(p.routing_row(ndofs));
        }
        Self {
            rows: pairs.len(),
            cols: ndofs,
            data,
        }
    }

    /// Row `p`.
    pub fn row(&self, p: usize) -> &[f64] {
        &self.data[p * self.cols..(p + 1) * self.cols]
    }

    /// `R q`, m (per pair).
    pub fn apply(&self, q: &[f64]) -> Vec<f64> {
        (0..self.rows)
            .map(|p| self.row(p).iter().zip(q).map(|(a, b)| a * b).sum())
            .collect()
    }

    /// `R^T phi`, N*m (per joint).
    pub fn transpose_apply(&self, phi: &[f64]) -> Vec<f64> {
        let mut tau = vec![0.0; self.cols];
        for (p, f) in phi.iter().enumerate() {
            for (t, r) in tau.iter_mut().zip(self.row(p)) {
                *t += r * f;
            }
        }
        tau
    }
}
