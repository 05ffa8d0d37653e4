//! A rope pair compiled for one time step: its rope law's stepper, routing row, relay
//! chain; its static split of a load, its state at rest, its energy.

use longreach_rope::{RopeState, RopeStepper};

use super::relay::{CompiledRelays, RelayState};
use super::spec::{PairSpec, Tensioner};
use crate::error::DriveError;

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
    /// The smallest radius of its pulleys (motor, joint, relays), m.
    smallest_radius_m: f64,
}

/// What the static map gives for one pair at a pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticPair {
    /// Pair force `n (f+ - f-)`, N.
    pub phi_n: f64,
    /// Tension of each `+` rope, N.
    pub f_pos_n: f64,
    /// Tension of each `-` rope, N.
    pub f_neg_n: f64,
    /// Differential stretch `u`, m.
    pub u_m: f64,
    /// Common stretch `x`, m.
    pub x_m: f64,
    /// False when the tensioner cannot hold this load (constant force below |phi|/2n).
    pub holds: bool,
}

/// The state of one pair at rest ([`CompiledPair::at_rest`]).
#[derive(Debug, Clone)]
pub struct PairAtRest {
    /// Motor angle, rad.
    pub motor_rad: f64,
    /// Tensioner stretch, m.
    pub carriage_m: f64,
    /// Rope states `[+, -]` (the motor-side span with relay friction).
    pub ropes: [RopeState; 2],
    /// Spans and relays (empty without relay friction).
    pub relays: RelayState,
    /// Motor torque that holds the pair's static force, N*m.
    pub motor_torque_n_m: f64,
}

impl CompiledPair {
    /// Largest update of the constant-force tensioner's stretch, m, that a Newton
    /// iteration whose angles converge to `tol` rad counts as converged. With relay
    /// friction: the rope length `tol` stands for at the pair's smallest pulley (motor,
    /// joint or relay), the tolerance of the step's angles in the same length (a
    /// carriage error moves both ropes alike and leaves the joint torque unchanged to
    /// first order). Until 2026-12-07 the relay step took the ideal pair's `1e-15 (1 +
    /// L)` m: 1.6e-14 m on the rig's 15.2 m rope against the 2.5e-10 m of a relay or
    /// output angle on its 25 mm pulley, and the carriage's test failed in 72% of the
    /// relay rig's Newton iterations (a temporary count on a 5-run relay sweep). The
    /// ideal pair keeps `1e-15 (1 + L)`: its angles converge to 1e-12 rad, which is
    /// that length on a pulley of `1 + L` mm.
    pub fn carriage_tolerance_m(&self, tol: f64) -> f64 {
        match &self.relays {
            Some(_) => tol * self.smallest_radius_m,
            None => 1e-15 * (1.0 + self.spec.length_m),
        }
    }

    /// Compiles `spec` (validated with [`PairSpec::validate`]; `field` names the pair in
    /// messages) for a plant of `ndofs` joints and steps of `dt_s`.
    pub fn new(spec: PairSpec, ndofs: usize, dt_s: f64, field: &str) -> Result<Self, DriveError> {
        spec.validate(ndofs, field)?;
        let stepper =
            RopeStepper::new(spec.law.clone(), dt_s).map_err(|e| DriveError::BadTransmission {
                field: format!("{field}.rope"),
                reason: e.to_string(),
            })?;
        let row = spec.routing_row(ndofs);
        let nz = (0..ndofs).filter(|&k| row[k] != 0.0).collect();
        let relays = spec.relay_friction.map(|rf| CompiledRelays::new(&spec, rf));
        let smallest_radius_m = relays
            .iter()
            .flat_map(|c| &c.radius_m)
            .fold(spec.motor_radius_m.min(spec.joint_radius_m), |a, &r| {
                a.min(r)
            });
        Ok(Self {
            smallest_radius_m,
            stepper,
            row,
            nz,
            inv_length: 1.0 / spec.length_m,
            n: f64::from(spec.ropes_in_parallel),
            relays,
            spec,
        })
    }

    /// `R[p] . q`, m.
    #[inline]
    pub fn routed_m(&self, q: &[f64]) -> f64 {
        self.nz.iter().map(|&k| self.row[k] * q[k]).sum()
    }

    /// How the pair holds the pair force `phi_n` (N) statically: the tensions split
    /// about the preload (`T +- phi / 2n`; a rope that would push goes slack and the
    /// other carries it all; a constant-force tensioner saturates at `2T`), and the
    /// settled stretches of both ropes at those tensions.
    pub fn static_split(&self, phi_n: f64) -> StaticPair {
        let t = self.spec.preload_n;
        let half = phi_n / (2.0 * self.n);
        let (mut fp, mut fm) = (t + half, t - half);
        let mut holds = true;
        if fm < 0.0 {
            fm = 0.0;
            fp = phi_n / self.n;
        } else if fp < 0.0 {
            fp = 0.0;
            fm = -phi_n / self.n;
        }
        if self.spec.tensioner == Tensioner::ConstantForce && half.abs() > t {
            holds = false;
            fp = fp.min(2.0 * t);
            fm = fm.min(2.0 * t);
        }
        let l = self.spec.length_m;
        let sp = self.stepper.rest_state(fp, self.spec.prestretch_n).strain * l;
        let sm = self.stepper.rest_state(fm, self.spec.prestretch_n).strain * l;
        StaticPair {
            phi_n: self.n * (fp - fm),
            f_pos_n: fp,
            f_neg_n: fm,
            u_m: 0.5 * (sp - sm),
            x_m: 0.5 * (sp + sm),
            holds,
        }
    }

    /// The pair at rest holding `s` at joint angles `q`: motor angle, stretches, every
    /// rope (and span) settled at its static tension.
    pub fn at_rest(&self, s: &StaticPair, q: &[f64]) -> PairAtRest {
        let rq: f64 = self.row.iter().zip(q).map(|(a, b)| a * b).sum();
        let th = (rq + s.u_m) / self.spec.motor_radius_m;
        let mut rp = self.stepper.rest_state(s.f_pos_n, self.spec.prestretch_n);
        let mut rm = self.stepper.rest_state(s.f_neg_n, self.spec.prestretch_n);
        rp.strain = (s.x_m + s.u_m) * self.inv_length;
        rm.strain = (s.x_m - s.u_m) * self.inv_length;
        let mut ropes = [rp, rm];
        let mut relays = RelayState::default();
        if let Some(c) = &self.relays {
            relays = RelayState::at_rest(
                c,
                &self.stepper,
                self.spec.motor_radius_m,
                self.spec.prestretch_n,
                [s.f_pos_n, s.f_neg_n],
                q,
                th,
                s.x_m,
            );
            ropes = relays.spans[0];
        }
        PairAtRest {
            motor_rad: th,
            carriage_m: s.x_m,
            ropes,
            relays,
            motor_torque_n_m: self.spec.motor_radius_m * s.phi_n,
        }
    }

    /// Elastic energy of the pair's ropes (every rope in parallel counted), J.
    pub fn rope_energy_j(&self, ropes: &[RopeState; 2], relays: &RelayState) -> f64 {
        let mut e = 0.0;
        if let Some(c) = &self.relays {
            for (span, len) in relays.spans.iter().zip(&c.span_length_m) {
                for r in span {
                    e += self.n * self.stepper.stored_energy_j(r, *len);
                }
            }
        } else {
            for r in ropes {
                e += self.n * self.stepper.stored_energy_j(r, self.spec.length_m);
            }
        }
        e
    }

    /// Kinetic energy of the pair's relay pulleys (every rope in parallel counted), J.
    pub fn relay_energy_j(&self, relays: &RelayState) -> f64 {
        self.relays
            .as_ref()
            .map_or(0.0, |c| self.n * relays.kinetic_j(c))
    }

    /// Potential of a constant-force tensioner at stretch `carriage_m`, `-2 n T x`, J
    /// (0 for a fixed one).
    pub fn tensioner_energy_j(&self, carriage_m: f64) -> f64 {
        if self.spec.tensioner == Tensioner::ConstantForce {
            -2.0 * self.n * self.spec.preload_n * carriage_m
        } else {
            0.0
        }
    }

    /// Tensions `[+, -]` of every span (motor side first), N per rope; one entry for a
    /// pair without relay friction.
    pub fn span_tensions_n(&self, ropes: &[RopeState; 2], relays: &RelayState) -> Vec<[f64; 2]> {
        match self.relays {
            Some(_) => relays
                .spans
                .iter()
                .map(|s| [s[0].tension_n, s[1].tension_n])
                .collect(),
            None => vec![[ropes[0].tension_n, ropes[1].tension_n]],
        }
    }

    /// Adds the joint torques the pair's ropes exert (`n sum sigma f_i G_i`, or
    /// `R^T phi` for an ideal pair) to `tau`, N*m.
    pub fn add_joint_torques(&self, ropes: &[RopeState; 2], relays: &RelayState, tau: &mut [f64]) {
        match &self.relays {
            None => {
                let phi = self.n * (ropes[0].tension_n - ropes[1].tension_n);
                for (t, r) in tau.iter_mut().zip(&self.row) {
                    *t += r * phi;
                }
            }
            Some(c) => {
                let nc = c.cols.len();
                for (i, span) in relays.spans.iter().enumerate() {
                    let df = span[0].tension_n - span[1].tension_n;
                    for (a, &col) in c.cols.iter().enumerate() {
                        tau[col] += self.n * df * c.geometry_m[i * nc + a];
                    }
                }
            }
        }
    }
}
