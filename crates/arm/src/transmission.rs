//! Rope transmissions of an arm: one antagonistic rope pair per driven joint, routed
//! from a motor pulley at the base over relay pulleys at the proximal joints.
//!
//! # Routing matrix
//!
//! Pair `p` drives joint `j(p)` with a joint pulley of radius `r_j` and passes the
//! proximal joints `k` over relay pulleys of radius `r_k` that the rope wraps with
//! crossing sign `s_k = +-1`. Row `p` of the routing matrix `R` (pairs x joints) is
//! `R[p][j(p)] = r_j`, `R[p][k] = s_k r_k`, zero elsewhere. With motor angle
//! `theta_p` on a pulley of radius `r_m`, the differential stretch of the pair is
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

use longreach_drive::RelayFriction;
use longreach_rope::{RopeLaw, RopeParams, RopeStepper};

use crate::relay::CompiledRelays;

/// How the pre-tension of a pair is held.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TensionerKind {
    /// Rope ends fixed after pre-tensioning to the preload at the initial pose.
    Fixed,
    /// A carriage pulled with `2 * preload` holds `f+ + f- = 2 * preload` (per rope).
    ConstantForce,
}

/// One relay pulley on the route of a pair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Relay {
    /// Index of the joint the relay pulley turns with.
    pub joint: usize,
    /// Radius, m.
    pub radius_m: f64,
    /// Crossing sign `+1` (rope wraps the relay the same way as the joint pulley) or `-1`.
    pub sign: f64,
}

/// How the motor of a pair is driven.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotorMode {
    /// The motor angle follows the command exactly (an ideal stiff drive, like the
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
    /// Relay pulleys at proximal joints.
    pub route: Vec<Relay>,
    /// Rope length motor pulley to joint pulley, m.
    pub length_m: f64,
    /// Lengths of the spans between successive pulleys, m (sum = `length_m`).
    pub span_lengths_m: Vec<f64>,
    /// Pre-tension per rope, N.
    pub preload_n: f64,
    /// Tension each rope was pre-stretched to (sets Flory's ratchet), N.
    pub prestretch_n: f64,
    /// Tensioner.
    pub tensioner: TensionerKind,
    /// Motor.
    pub motor: MotorSpec,
    /// Names of the rope-law effects applied (from the drive effect registry).
    pub effects: Vec<String>,
    /// Friction and inertia of the relay pulleys (`None`: ideal relays, one tension per
    /// rope). With friction every rope is split into spans at its relays
    /// ([`crate::relay`]).
    pub relay_friction: Option<RelayFriction>,
}

impl PairSpec {
    /// The routing-matrix row of this pair (length = number of joints).
    pub fn routing_row(&self, ndofs: usize) -> Vec<f64> {
        let mut row = vec![0.0; ndofs];
        row[self.joint] = self.joint_radius_m;
        for r in &self.route {
            row[r.joint] += r.sign * r.radius_m;
        }
        row
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

/// A pair compiled for one time step.
#[derive(Debug, Clone)]
pub struct CompiledPair {
    /// Its definition.
    pub spec: PairSpec,
    /// Its rope law compiled for the step.
    pub stepper: RopeStepper,
    /// Routing row (length = joints).
    pub row: Vec<f64>,
    /// Non-zero columns of the row.
    pub nz: Vec<usize>,
    /// `1 / length_m`.
    pub inv_length: f64,
    /// Ropes in parallel as a float.
    pub n: f64,
    /// Spans and relay pulleys when the pair has relay friction.
    pub relays: Option<CompiledRelays>,
}

/// Joints between the base and `joint` (exclusive), base first.
pub fn proximal_joints(spec: &crate::ArmSpec, joint: usize) -> Vec<usize> {
    let mut out = Vec::new();
    let mut link = spec.joints[joint].parent_link;
    while link > 0 {
        out.push(link - 1);
        link = spec.joints[link - 1].parent_link;
    }
    out.reverse();
    out
}

/// The default route of the pair driving `joint`: a relay at every proximal joint `k`
/// with radius `joint_radii_m[k]` (the pulley radius of that joint) and sign +1.
pub fn default_route(spec: &crate::ArmSpec, joint: usize, joint_radii_m: &[f64]) -> Vec<Relay> {
    proximal_joints(spec, joint)
        .into_iter()
        .map(|k| Relay {
            joint: k,
            radius_m: joint_radii_m[k],
            sign: 1.0,
        })
        .collect()
}

/// Span lengths of the rope driving `joint`, from the URDF geometry: the motor pulley
/// to the first joint (`motor_offset_m`), then joint origin to joint origin along the
/// chain up to the driven joint, m.
pub fn span_lengths_m(spec: &crate::ArmSpec, joint: usize, motor_offset_m: f64) -> Vec<f64> {
    let mut spans = vec![motor_offset_m];
    let chain: Vec<usize> = proximal_joints(spec, joint)
        .into_iter()
        .chain(std::iter::once(joint))
        .collect();
    for w in chain.windows(2) {
        spans.push(
            spec.joints[w[1]]
                .parent_from_joint
                .translation
                .vector
                .norm(),
        );
    }
    spans
}

/// One rope pair per joint of `spec`: every pulley (joint, motor, relays) of radius
/// `radius_m`, relays at every proximal joint (sign +1), span lengths from the
/// geometry with the motor `motor_offset_m` before the first joint. For benchmarks,
/// tests and quick studies.
pub fn uniform_pairs(
    spec: &crate::ArmSpec,
    rope_name: &str,
    rope: &RopeParams,
    law: &RopeLaw,
    radius_m: f64,
    preload_n: f64,
    tensioner: TensionerKind,
    motor: MotorSpec,
    motor_offset_m: f64,
) -> Vec<PairSpec> {
    let radii = vec![radius_m; spec.ndofs()];
    (0..spec.ndofs())
        .map(|j| {
            let spans = span_lengths_m(spec, j, motor_offset_m);
            PairSpec {
                joint: j,
                rope_name: rope_name.to_string(),
                rope: rope.clone(),
                law: law.clone(),
                ropes_in_parallel: 1,
                joint_radius_m: radius_m,
                motor_radius_m: radius_m,
                route: default_route(spec, j, &radii),
                length_m: spans.iter().sum(),
                span_lengths_m: spans,
                preload_n,
                prestretch_n: 0.0,
                tensioner,
                motor,
                effects: vec![],
                relay_friction: None,
            }
        })
        .collect()
}
