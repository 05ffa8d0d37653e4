//! The driven arm: links + rope pairs + motors + servos, integrated together in
//! reduced coordinates with an implicit, energy-consistent scheme.
//!
//! # Equations
//!
//! ```text
//! M(q) qdd + C(q, qd) qd + g(q) + D qd = R^T phi                 (arm, phi_p = n_p (f+ - f-))
//! J_m thdd_p + b_m thd_p = tau_servo,p - r_m phi_p                (motor p)
//! f+- = rope law of strain (x_p +- u_p) / L_p,  u_p = r_m th_p - R[p] . q
//! f+ + f- = 2 T_p                                                 (constant-force tensioner)
//! tau_servo = sat(kp (th_ref - th) + kd (thd_ref - thd) + r_m phi_static(q_ref))
//! ```
//!
//! # Integration (why not rapier's step)
//!
//! rapier's multibody step is semi-implicit Euler with explicit joint forces: with
//! ropes of 10^5..10^6 N/m on 25 mm pulleys it needs tiny steps and it loses energy
//! at first order. Here every unknown of the step is implicit, exactly like the rig
//! plant ([`longreach_drive::RigModel`]): the trapezoidal rule (Newmark average
//! acceleration: unconditionally stable, second order, no numerical damping) for the
//! joints and motors, the exact-hold step for each rope ([`RopeStepper`]), and Newton's
//! method on the end-of-step state. The Newton matrix is
//! `4 M(q0)/h^2 + 2 D/h + R^T K R` with the rope pairs' tangent stiffness `K`, the
//! motor and tensioner unknowns eliminated pair by pair (Schur complement of 2x2
//! blocks), so the linear solve is one `n x n` Cholesky. The residual is evaluated
//! exactly at the trial state by recursive Newton-Euler (`M(q1) a1 + C(q1, v1) v1 +
//! g(q1)`), so the converged step is the trapezoidal rule on the full nonlinear
//! equations; freezing `M` in the matrix only costs an extra iteration.

use crate::command::Command;
use crate::error::ArmError;
use crate::fast::{cholesky_in_place, cholesky_solve, FastDynamics, Kin};
use crate::relay::{self, Assembly, CompiledRelays, Local, MotorRow, RelayScratch, RelayState};
use crate::spec::ArmSpec;
use crate::transmission::{CompiledPair, MotorMode, PairSpec, RoutingMatrix, TensionerKind};
use longreach_rope::{PreparedStep, RopeState, RopeStepper};
use nalgebra::{DMatrix, Vector3};

/// A compiled driven arm (immutable; share it between runs).
#[derive(Debug, Clone)]
pub struct DrivenArm {
    /// The arm.
    pub spec: ArmSpec,
    dynamics: FastDynamics,
    /// The rope pairs, compiled for `dt_s`.
    pub pairs: Vec<CompiledPair>,
    /// Routing matrix (pairs x joints).
    pub routing: RoutingMatrix,
    /// Reference of every joint.
    pub commands: Vec<Command>,
    /// Initial joint angles, rad.
    pub initial_q_rad: Vec<f64>,
    /// Motor references include `R q_ref` of every joint a rope passes, so that a held
    /// distal joint stays put when a proximal joint moves (default true). Off, each
    /// motor reference only follows its own joint.
    pub compensate_routing: bool,
    dt_s: f64,
    damping: Vec<f64>,
    /// `phi = ff_map * g_driven`: inverse of `R^T` restricted to the driven joints.
    ff_map: Vec<f64>,
    /// Driven joint of each row of `ff_map`'s input.
    driven: Vec<usize>,
    /// Some pair has relay friction: the joint matrix is solved by LU.
    any_friction: bool,
    /// Relative tolerance on the Newton updates of the implicit step (angles, rad):
    /// the step ends when every update is below `tol (1 + |angle|)` (or, for the
    /// chord iterations, when the error left is estimated below a hundredth of it).
    /// Defaults: 1e-12 without relay friction, [`RELAY_NEWTON_TOLERANCE`] with.
    pub newton_tolerance: f64,
}

/// Default [`DrivenArm::newton_tolerance`] of an arm with relay friction, rad (2 nm of
/// rope on a 0.2 m pulley). On `arm_dyneema2_base_step_relay_friction.toml` (10 s) the
/// joint angles of a 1e-8, 1e-9 and 1e-10 solve stay within 2.2e-9, 1.1e-9 and 5.4e-11
/// rad of a 1e-13 solve, for 1.45, 1.50 and 1.75 Newton iterations per step (2.55 at
/// 1e-13; `cargo run --release -p longreach-arm --example relay_tolerance`). Before the
/// relays were solved alone ([`crate::relay`] `relax_relays`), 1e-9 gave 3.2e-9 rad for
/// 1.91 iterations and 1e-8 gave 2.3e-7 rad.
pub const RELAY_NEWTON_TOLERANCE: f64 = 1e-8;

/// Mutable state of a [`DrivenArm`] (and its scratch).
#[derive(Debug, Clone)]
pub struct DrivenState {
    /// Time, s.
    pub time_s: f64,
    /// Joint angles, rad.
    pub q_rad: Vec<f64>,
    /// Joint rates, rad/s.
    pub qd_rad_s: Vec<f64>,
    /// Joint accelerations, rad/s^2.
    pub qdd_rad_s2: Vec<f64>,
    /// Joint references at `time_s`, rad.
    pub q_ref_rad: Vec<f64>,
    /// Motor angles (per pair), rad.
    pub motor_rad: Vec<f64>,
    /// Motor rates, rad/s.
    pub motor_rate_rad_s: Vec<f64>,
    /// Motor accelerations, rad/s^2.
    pub motor_accel_rad_s2: Vec<f64>,
    /// Motor references, rad.
    pub motor_ref_rad: Vec<f64>,
    /// Servo torques of the last step, N*m.
    pub motor_torque_n_m: Vec<f64>,
    /// Common stretch of each pair held by its tensioner, m.
    pub carriage_m: Vec<f64>,
    /// Rope states `[+, -]` of each pair (one rope of the `n` in parallel); for a pair
    /// with relay friction, the motor-side span (every span is in `relays`).
    pub ropes: Vec<[RopeState; 2]>,
    /// Spans and relay pulleys of each pair with relay friction (empty otherwise).
    pub relays: Vec<RelayState>,
    /// Newton iterations of the last step.
    pub iterations: u32,
    scratch: Scratch,
}

#[derive(Debug, Clone)]
struct Scratch {
    kin: Kin,
    tau: Vec<f64>,
    mbase: Vec<f64>,
    kq: Vec<f64>,
    rhs: Vec<f64>,
    q1: Vec<f64>,
    v1: Vec<f64>,
    a1: Vec<f64>,
    zero: Vec<f64>,
    g: Vec<f64>,
    /// Per pair: b11 b12 b21 b22 w0 w1 r0 r1.
    local: Vec<[f64; 8]>,
    prep: Vec<[PreparedStep; 2]>,
    /// Saturation state of each servo (-1, 0, +1), carried from step to step.
    sat: Vec<i8>,
    /// Unclamped servo torque at the last evaluation, N*m.
    raw: Vec<f64>,
    ff: Vec<f64>,
    ref_rate: Vec<f64>,
    /// Joint references the motor references and feed-forward were computed for.
    last_qref: Vec<f64>,
    th1: Vec<f64>,
    x1: Vec<f64>,
    torque: Vec<f64>,
    /// Per pair with relay friction: its local block.
    relay: Vec<Option<RelayScratch>>,
    /// Pivots of the joint LU (arms with relay friction).
    perm: Vec<usize>,
    /// The Newton matrix of the last step (factors in `kq`, `perm` and the relay
    /// scratch) may start the next step's chord iterations.
    kept: bool,
    /// Steps started since the Newton matrix was last assembled.
    age: u32,
    /// Last measured contraction of a chord iteration (update over the update before
    /// it) and the matrix age it was measured at: the error estimate of a step's first
    /// chord iteration, which has no update before it in the step.
    chord_rate: f64,
    chord_rate_age: u32,
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

/// Energy of the driven arm, J.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SystemEnergy {
    /// Links (and armatures).
    pub links_kinetic_j: f64,
    /// Gravity.
    pub potential_j: f64,
    /// Motor rotors.
    pub motors_kinetic_j: f64,
    /// Rope springs (every rope in parallel counted).
    pub ropes_j: f64,
    /// Constant-force tensioners, `-2 n T x`.
    pub tensioners_j: f64,
    /// Relay pulleys (rotation relative to their mounts; every parallel rope's own).
    pub relays_kinetic_j: f64,
}

impl SystemEnergy {
    /// Sum of every term, J.
    pub fn total_j(&self) -> f64 {
        self.links_kinetic_j
            + self.potential_j
            + self.motors_kinetic_j
            + self.ropes_j
            + self.tensioners_j
            + self.relays_kinetic_j
    }
}

fn bad(field: &str, reason: String) -> ArmError {
    ArmError::BadTransmission {
        field: field.to_string(),
        reason,
    }
}

impl DrivenArm {
    /// Compiles the arm with its pairs and commands for steps of `dt_s`.
    pub fn new(
        spec: ArmSpec,
        pairs: Vec<PairSpec>,
        commands: Vec<Command>,
        initial_q_rad: Vec<f64>,
        dt_s: f64,
    ) -> Result<Self, ArmError> {
        spec.validate()?;
        let n = spec.ndofs();
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 0.05) {
            return Err(ArmError::BadTimeStep { dt_s });
        }
        crate::error::check_joint_vector(&spec.name, n, "initial_q_rad", &initial_q_rad)?;
        if commands.len() != n {
            return Err(bad(
                "command",
                format!(
                    "{} commands for {n} joints: give one per joint",
                    commands.len()
                ),
            ));
        }
        let mut seen = vec![false; n];
        let mut compiled = Vec::with_capacity(pairs.len());
        for (i, p) in pairs.iter().enumerate() {
            let jn = spec.joints.get(p.joint).map_or("?", |j| j.name.as_str());
            let field = |f: &str| format!("transmission[{i}] (joint {jn}).{f}");
            if p.joint >= n {
                return Err(bad(
                    &field("joint"),
                    format!("joint index {} out of range", p.joint),
                ));
            }
            if seen[p.joint] {
                return Err(bad(
                    &field("joint"),
                    "a second transmission on the same joint: give one pair per joint".into(),
                ));
            }
            seen[p.joint] = true;
            for (what, v) in [
                ("joint_radius_m", p.joint_radius_m),
                ("motor_radius_m", p.motor_radius_m),
                ("length_m", p.length_m),
            ] {
                if !(v.is_finite() && v > 0.0) {
                    return Err(bad(&field(what), format!("{v} must be finite and > 0")));
                }
            }
            for (what, v) in [
                ("preload_n", p.preload_n),
                ("prestretch_n", p.prestretch_n),
                ("motor.inertia_kg_m2", p.motor.inertia_kg_m2),
                ("motor.damping_n_m_s", p.motor.damping_n_m_s),
            ] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(bad(&field(what), format!("{v} must be finite and >= 0")));
                }
            }
            if p.ropes_in_parallel == 0 {
                return Err(bad(
                    &field("ropes_in_parallel"),
                    "must be at least 1".into(),
                ));
            }
            if p.tensioner == TensionerKind::ConstantForce && p.preload_n <= 0.0 {
                return Err(bad(
                    &field("preload_n"),
                    "a constant-force tensioner needs a preload > 0".into(),
                ));
            }
            if let MotorMode::Servo {
                kp_n_m_per_rad,
                kd_n_m_s_per_rad,
                torque_limit_n_m,
                ..
            } = p.motor.mode
            {
                if p.motor.inertia_kg_m2 <= 0.0 {
                    return Err(bad(
                        &field("motor.inertia_kg_m2"),
                        "a servo motor needs an inertia > 0 (or use mode = \"kinematic\")".into(),
                    ));
                }
                for (what, v) in [
                    ("motor.kp_n_m_per_rad", kp_n_m_per_rad),
                    ("motor.kd_n_m_s_per_rad", kd_n_m_s_per_rad),
                ] {
                    if !(v.is_finite() && v >= 0.0) {
                        return Err(bad(&field(what), format!("{v} must be finite and >= 0")));
                    }
                }
                if torque_limit_n_m.is_nan() || torque_limit_n_m <= 0.0 {
                    return Err(bad(
                        &field("motor.torque_limit_n_m"),
                        format!("{torque_limit_n_m} must be > 0"),
                    ));
                }
            }
            for r in &p.route {
                if r.joint >= p.joint {
                    return Err(bad(
                        &field("route"),
                        format!(
                            "relay at joint index {} is not proximal to the driven joint {}",
                            r.joint, p.joint
                        ),
                    ));
                }
                if !(r.radius_m.is_finite() && r.radius_m > 0.0)
                    || (r.sign.abs() - 1.0).abs() > 1e-12
                {
                    return Err(bad(
                        &field("route"),
                        format!(
                            "relay radius {} m / sign {}: need radius > 0 and sign +1 or -1",
                            r.radius_m, r.sign
                        ),
                    ));
                }
            }
            let stepper = RopeStepper::new(p.law.clone(), dt_s)
                .map_err(|e| bad(&field("rope"), e.to_string()))?;
            let row = p.routing_row(n);
            let nz = (0..n).filter(|&k| row[k] != 0.0).collect();
            let relays = match p.relay_friction {
                None => None,
                Some(rf) => {
                    rf.validate().map_err(|e| {
                        bad(
                            &field("relay_friction"),
                            format!(
                                "{e}; typical: coefficient 0.001-0.05, inertia 1e-5-1e-2 kg*m^2"
                            ),
                        )
                    })?;
                    Some(CompiledRelays::new(&spec, p, rf))
                }
            };
            compiled.push(CompiledPair {
                spec: p.clone(),
                stepper,
                row,
                nz,
                inv_length: 1.0 / p.length_m,
                n: f64::from(p.ropes_in_parallel),
                relays,
            });
        }
        let routing = RoutingMatrix::new(&pairs, n);
        // Feed-forward map: R^T phi = g on the driven joints.
        let driven: Vec<usize> = compiled.iter().map(|p| p.spec.joint).collect();
        let np = driven.len();
        let mut rt = DMatrix::zeros(np, np);
        for (a, &j) in driven.iter().enumerate() {
            for b in 0..np {
                rt[(a, b)] = compiled[b].row[j];
            }
        }
        let ff_map = if np == 0 {
            vec![]
        } else {
            let inv = rt.try_inverse().ok_or_else(|| {
                bad(
                    "route",
                    "the routing matrix restricted to the driven joints is singular".into(),
                )
            })?;
            let mut v = Vec::with_capacity(np * np);
            for a in 0..np {
                for b in 0..np {
                    v.push(inv[(a, b)]);
                }
            }
            v
        };
        let any_friction = compiled.iter().any(|p| p.relays.is_some());
        Ok(Self {
            any_friction,
            newton_tolerance: if any_friction {
                RELAY_NEWTON_TOLERANCE
            } else {
                1e-12
            },
            dynamics: FastDynamics::new(&spec),
            damping: spec
                .joints
                .iter()
                .map(|j| j.damping_n_m_s_per_rad)
                .collect(),
            spec,
            pairs: compiled,
            routing,
            commands,
            initial_q_rad,
            compensate_routing: true,
            dt_s,
            ff_map,
            driven,
        })
    }

    /// Step, s.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Turns gravity off (or sets another vector), m/s^2.
    pub fn set_gravity(&mut self, g: Vector3<f64>) {
        self.dynamics.set_gravity(g);
        self.spec.gravity_m_s2 = g;
    }

    /// Sets the viscous damping of every joint, N*m*s/rad.
    pub fn set_joint_damping(&mut self, d: f64) {
        self.damping.fill(d);
    }

    fn make_scratch(&self) -> Scratch {
        let n = self.spec.ndofs();
        let np = self.pairs.len();
        let prep0 = self.pairs.first().map(|p| {
            let s = p.stepper.rest_state(0.0, 0.0);
            p.stepper.prepare(&s)
        });
        Scratch {
            kin: self.dynamics.make_kin(),
            tau: vec![0.0; n],
            mbase: vec![0.0; n * n],
            kq: vec![0.0; n * n],
            rhs: vec![0.0; n],
            q1: vec![0.0; n],
            v1: vec![0.0; n],
            a1: vec![0.0; n],
            zero: vec![0.0; n],
            g: vec![0.0; n],
            local: vec![[0.0; 8]; np],
            sat: vec![0; np],
            raw: vec![0.0; np],
            ff: vec![0.0; np],
            ref_rate: vec![0.0; np],
            last_qref: vec![f64::NAN; n],
            th1: vec![0.0; np],
            x1: vec![0.0; np],
            torque: vec![0.0; np],
            prep: prep0.map_or_else(Vec::new, |p| vec![[p; 2]; np]),
            relay: self
                .pairs
                .iter()
                .map(|p| {
                    let prep = p.stepper.prepare(&p.stepper.rest_state(0.0, 0.0));
                    p.relays.as_ref().map(|c| RelayScratch::new(c, prep))
                })
                .collect(),
            perm: vec![0; n],
            kept: false,
            age: 0,
            chord_rate: f64::INFINITY,
            chord_rate_age: 0,
        }
    }

    /// Static pair forces, tensions and stretches that hold the arm at `q_rad` under
    /// gravity (`R^T phi = g(q)` on the driven joints, split by the preload).
    pub fn static_pairs(&self, q_rad: &[f64]) -> Vec<StaticPair> {
        let mut kin = self.dynamics.make_kin();
        let n = self.spec.ndofs();
        let mut g = vec![0.0; n];
        self.gravity_into(q_rad, &mut kin, &mut g);
        (0..self.pairs.len())
            .map(|p| self.static_pair(p, &g))
            .collect()
    }

    fn gravity_into(&self, q: &[f64], kin: &mut Kin, g: &mut [f64]) {
        let zero = vec![0.0; q.len()];
        self.dynamics.kinematics(q, kin);
        self.dynamics.rnea(kin, &zero, &zero, g);
    }

    /// Pair force of pair `p` from the gravity torques `g`.
    fn phi_static(&self, p: usize, g: &[f64]) -> f64 {
        let np = self.driven.len();
        (0..np)
            .map(|b| self.ff_map[p * np + b] * g[self.driven[b]])
            .sum()
    }

    fn static_pair(&self, p: usize, g: &[f64]) -> StaticPair {
        let pair = &self.pairs[p];
        let phi = self.phi_static(p, g);
        let t = pair.spec.preload_n;
        let half = phi / (2.0 * pair.n);
        let (mut fp, mut fm) = (t + half, t - half);
        let mut holds = true;
        if fm < 0.0 {
            fm = 0.0;
            fp = phi / pair.n;
        } else if fp < 0.0 {
            fp = 0.0;
            fm = -phi / pair.n;
        }
        if pair.spec.tensioner == TensionerKind::ConstantForce && half.abs() > t {
            holds = false;
            fp = fp.min(2.0 * t);
            fm = fm.min(2.0 * t);
        }
        let l = pair.spec.length_m;
        let sp = pair.stepper.rest_state(fp, pair.spec.prestretch_n).strain * l;
        let sm = pair.stepper.rest_state(fm, pair.spec.prestretch_n).strain * l;
        StaticPair {
            phi_n: pair.n * (fp - fm),
            f_pos_n: fp,
            f_neg_n: fm,
            u_m: 0.5 * (sp - sm),
            x_m: 0.5 * (sp + sm),
            holds,
        }
    }

    /// The arm at rest at its initial angles, held by the ropes against gravity, motors
    /// at the angles that hold it.
    pub fn initial_state(&self) -> DrivenState {
        let n = self.spec.ndofs();
        let np = self.pairs.len();
        let mut st = DrivenState {
            time_s: 0.0,
            q_rad: self.initial_q_rad.clone(),
            qd_rad_s: vec![0.0; n],
            qdd_rad_s2: vec![0.0; n],
            q_ref_rad: self.initial_q_rad.clone(),
            motor_rad: vec![0.0; np],
            motor_rate_rad_s: vec![0.0; np],
            motor_accel_rad_s2: vec![0.0; np],
            motor_ref_rad: vec![0.0; np],
            motor_torque_n_m: vec![0.0; np],
            carriage_m: vec![0.0; np],
            ropes: vec![[RopeState::default(); 2]; np],
            relays: vec![RelayState::default(); np],
            iterations: 0,
            scratch: self.make_scratch(),
        };
        let statics = self.static_pairs(&self.initial_q_rad);
        for (p, s) in statics.iter().enumerate() {
            let pair = &self.pairs[p];
            let rq: f64 = pair.row.iter().zip(&st.q_rad).map(|(a, b)| a * b).sum();
            let th = (rq + s.u_m) / pair.spec.motor_radius_m;
            st.motor_rad[p] = th;
            st.motor_ref_rad[p] = th;
            st.carriage_m[p] = s.x_m;
            let mut rp = pair.stepper.rest_state(s.f_pos_n, pair.spec.prestretch_n);
            let mut rm = pair.stepper.rest_state(s.f_neg_n, pair.spec.prestretch_n);
            rp.strain = (s.x_m + s.u_m) * pair.inv_length;
            rm.strain = (s.x_m - s.u_m) * pair.inv_length;
            st.ropes[p] = [rp, rm];
            st.motor_torque_n_m[p] = pair.spec.motor_radius_m * s.phi_n;
            if let Some(c) = &pair.relays {
                st.relays[p] = RelayState::at_rest(
                    c,
                    &pair.stepper,
                    pair.spec.motor_radius_m,
                    pair.spec.prestretch_n,
                    [s.f_pos_n, s.f_neg_n],
                    &st.q_rad,
                    th,
                    s.x_m,
                );
                st.ropes[p] = st.relays[p].spans[0];
            }
        }
        st
    }

    /// Energy of the state, J (see [`SystemEnergy`]).
    pub fn energy(&self, st: &DrivenState) -> SystemEnergy {
        let mut kin = self.dynamics.make_kin();
        self.dynamics.kinematics(&st.q_rad, &mut kin);
        let links_kinetic_j = self.dynamics.kinetic_energy(&mut kin, &st.qd_rad_s);
        let potential_j = self.dynamics.potential_energy(&kin);
        let mut motors = 0.0;
        let mut ropes = 0.0;
        let mut tens = 0.0;
        let mut relays = 0.0;
        for (p, pair) in self.pairs.iter().enumerate() {
            let w = st.motor_rate_rad_s[p];
            motors += 0.5 * pair.spec.motor.inertia_kg_m2 * w * w;
            if let Some(c) = &pair.relays {
                let rs = &st.relays[p];
                for (span, len) in rs.spans.iter().zip(&c.span_length_m) {
                    for r in span {
                        ropes += pair.n * pair.stepper.stored_energy_j(r, *len);
                    }
                }
                relays += pair.n * rs.kinetic_j(c);
            } else {
                for r in &st.ropes[p] {
                    ropes += pair.n * pair.stepper.stored_energy_j(r, pair.spec.length_m);
                }
            }
            if pair.spec.tensioner == TensionerKind::ConstantForce {
                tens -= 2.0 * pair.n * pair.spec.preload_n * st.carriage_m[p];
            }
        }
        SystemEnergy {
            links_kinetic_j,
            potential_j,
            motors_kinetic_j: motors,
            ropes_j: ropes,
            tensioners_j: tens,
            relays_kinetic_j: relays,
        }
    }

    /// World position of the tip at `q_rad`, m.
    pub fn tip_m(&self, q_rad: &[f64]) -> Vector3<f64> {
        crate::dynamics::tip_position_m(&self.spec, q_rad).unwrap_or_else(|_| Vector3::zeros())
    }

    /// Tensions `[+, -]` (N, per rope) every pair would have at the end of a step from
    /// `st` that ends at joint angles `q_rad`, motor angles `motor_rad` and tensioner
    /// stretches `carriage_m` (nothing is committed). For pairs without relay friction
    /// only: a pair with friction has one tension per span, and its relay angles are
    /// unknowns of the step ([`Self::span_tensions_n`] gives them at a state).
    pub fn tensions_at(
        &self,
        st: &DrivenState,
        q_rad: &[f64],
        motor_rad: &[f64],
        carriage_m: &[f64],
    ) -> Vec<[f64; 2]> {
        self.pairs
            .iter()
            .enumerate()
            .map(|(p, pair)| {
                let rq: f64 = pair.row.iter().zip(q_rad).map(|(a, b)| a * b).sum();
                let u = pair.spec.motor_radius_m * motor_rad[p] - rq;
                let x = carriage_m[p];
                let f = |side: usize, s: f64| {
                    let prep = pair.stepper.prepare(&st.ropes[p][side]);
                    pair.stepper.tension(&prep, s * pair.inv_length).0
                };
                [f(0, x + u), f(1, x - u)]
            })
            .collect()
    }

    /// Joint torques the ropes exert at the state, `R^T phi`, N*m (with relay
    /// friction, each span loads the joints its pulleys turn with).
    pub fn rope_joint_torques(&self, st: &DrivenState) -> Vec<f64> {
        let phi: Vec<f64> = self
            .pairs
            .iter()
            .enumerate()
            .map(|(p, pair)| {
                if pair.relays.is_some() {
                    0.0
                } else {
                    pair.n * (st.ropes[p][0].tension_n - st.ropes[p][1].tension_n)
                }
            })
            .collect();
        let mut tau = self.routing.transpose_apply(&phi);
        for (p, pair) in self.pairs.iter().enumerate() {
            if let Some(c) = &pair.relays {
                let nc = c.cols.len();
                for (i, span) in st.relays[p].spans.iter().enumerate() {
                    let df = span[0].tension_n - span[1].tension_n;
                    for (a, &col) in c.cols.iter().enumerate() {
                        tau[col] += pair.n * df * c.geometry_m[i * nc + a];
                    }
                }
            }
        }
        tau
    }

    /// Tensions `[+, -]` of every span of pair `p` at the state (motor side first), N
    /// per rope; one entry for a pair without relay friction.
    pub fn span_tensions_n(&self, st: &DrivenState, p: usize) -> Vec<[f64; 2]> {
        match self.pairs[p].relays {
            Some(_) => st.relays[p]
                .spans
                .iter()
                .map(|s| [s[0].tension_n, s[1].tension_n])
                .collect(),
            None => vec![[st.ropes[p][0].tension_n, st.ropes[p][1].tension_n]],
        }
    }

    /// The servo of pair `p` at the end-of-step motor angle `th1_rad` (trapezoidal
    /// rule from `st`): its unsaturated and applied torques, and the motor equation's
    /// residual `J a1 + b w1 - torque` and diagonal `4J/h^2 + 2b/h + d torque/d theta`
    /// (without the ropes). `sat` is the saturation held through the Newton solve.
    /// `None` for a kinematic motor.
    fn servo_row(
        &self,
        p: usize,
        st: &DrivenState,
        th1_rad: f64,
        ref_rate_rad_s: f64,
        ff_n_m: f64,
        sat: i8,
    ) -> Option<ServoRow> {
        let motor = &self.pairs[p].spec.motor;
        let MotorMode::Servo {
            kp_n_m_per_rad,
            kd_n_m_s_per_rad,
            torque_limit_n_m,
            gravity_feedforward,
        } = motor.mode
        else {
            return None;
        };
        let h = self.dt_s;
        let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
        let dth = th1_rad - st.motor_rad[p];
        let w1 = two_h * dth - st.motor_rate_rad_s[p];
        let a1 = four_h2 * dth - 2.0 * two_h * st.motor_rate_rad_s[p] - st.motor_accel_rad_s2[p];
        let raw_n_m = kp_n_m_per_rad * (st.motor_ref_rad[p] - th1_rad)
            + kd_n_m_s_per_rad * (ref_rate_rad_s - w1)
            + if gravity_feedforward { ff_n_m } else { 0.0 };
        // Saturation with an active set held through the Newton solve and corrected
        // at convergence (no chattering between pieces).
        let (torque_n_m, dservo) = if sat == 0 {
            (raw_n_m, kp_n_m_per_rad + two_h * kd_n_m_s_per_rad)
        } else {
            (f64::from(sat) * torque_limit_n_m, 0.0)
        };
        let (jm, bm) = (motor.inertia_kg_m2, motor.damping_n_m_s);
        Some(ServoRow {
            raw_n_m,
            torque_n_m,
            residual_n_m: jm * a1 + bm * w1 - torque_n_m,
            diag: four_h2 * jm + two_h * bm + dservo,
        })
    }

    /// Advances one step of `dt_s`.
    pub fn step(&self, st: &mut DrivenState) -> Result<(), ArmError> {
        let n = self.spec.ndofs();
        let h = self.dt_s;
        let t1 = st.time_s + h;
        let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
        let mut sc = std::mem::replace(&mut st.scratch, self.make_scratch_light());

        // References at the end of the step.
        for j in 0..n {
            st.q_ref_rad[j] = self.commands[j].angle_rad(self.initial_q_rad[j], t1);
        }
        // The references only change while a command moves: reuse them otherwise.
        let same_ref = sc.last_qref == st.q_ref_rad;
        if !same_ref && !self.pairs.is_empty() {
            self.dynamics.kinematics(&st.q_ref_rad, &mut sc.kin);
            self.dynamics
                .rnea(&mut sc.kin, &sc.zero, &sc.zero, &mut sc.g);
            sc.last_qref.copy_from_slice(&st.q_ref_rad);
        }
        let mut ff = std::mem::take(&mut sc.ff);
        let mut ref_rate = std::mem::take(&mut sc.ref_rate);
        for (p, pair) in self.pairs.iter().enumerate() {
            sc.prep[p] = [
                pair.stepper.prepare(&st.ropes[p][0]),
                pair.stepper.prepare(&st.ropes[p][1]),
            ];
            if let (Some(c), Some(rs)) = (&pair.relays, sc.relay[p].as_mut()) {
                relay::begin_step(c, &pair.stepper, rs, h, &st.relays[p]);
            }
            if same_ref {
                ref_rate[p] = 0.0;
                continue;
            }
            let sp = self.static_pair(p, &sc.g);
            let rq: f64 = if self.compensate_routing {
                pair.nz.iter().map(|&k| pair.row[k] * st.q_ref_rad[k]).sum()
            } else {
                pair.nz
                    .iter()
                    .map(|&k| {
                        let q = if k == pair.spec.joint {
                            st.q_ref_rad[k]
                        } else {
                            self.initial_q_rad[k]
                        };
                        pair.row[k] * q
                    })
                    .sum()
            };
            let th = (rq + sp.u_m) / pair.spec.motor_radius_m;
            let smooth = !matches!(self.commands[pair.spec.joint], Command::Step { .. });
            ref_rate[p] = if smooth {
                (th - st.motor_ref_rad[p]) / h
            } else {
                0.0
            };
            st.motor_ref_rad[p] = th;
            ff[p] = pair.spec.motor_radius_m * sp.phi_n;
        }

        // Predictor.
        for j in 0..n {
            sc.q1[j] = st.q_rad[j] + h * st.qd_rad_s[j] + 0.5 * h * h * st.qdd_rad_s2[j];
        }
        let mut th1 = std::mem::take(&mut sc.th1);
        for (p, pair) in self.pairs.iter().enumerate() {
            th1[p] = match pair.spec.motor.mode {
                MotorMode::Kinematic => st.motor_ref_rad[p],
                MotorMode::Servo { .. } => {
                    st.motor_rad[p]
                        + h * st.motor_rate_rad_s[p]
                        + 0.5 * h * h * st.motor_accel_rad_s2[p]
                }
            };
        }
        let mut x1 = std::mem::take(&mut sc.x1);
        x1.copy_from_slice(&st.carriage_m);
        let mut torque = std::mem::take(&mut sc.torque);

        let mut converged = false;
        let mut iterations = 0;
        let mut flips = 0;
        // Relay friction (stick-slip, spans going slack) may need the damped iterations
        // of `relay::apply_relay_update`.
        let max_iterations = if self.any_friction { 120 } else { 60 };
        let tol = self.newton_tolerance;
        // Chord iterations (Newton matrix kept from the last assembly) need every pair
        // to go through `relay::assemble`.
        let chord_capable = self.any_friction && self.pairs.iter().all(|p| p.relays.is_some());
        let mut chord_allowed = chord_capable;
        // The step starts from the last step's Newton matrix when it was kept.
        let mut refresh = !(chord_allowed && sc.kept && sc.age < MAX_KEPT_STEPS);
        let mut mbase_done = false;
        let mut last_update = f64::INFINITY;
        for _ in 0..max_iterations {
            iterations += 1;
            for j in 0..n {
                let dq = sc.q1[j] - st.q_rad[j];
                sc.v1[j] = two_h * dq - st.qd_rad_s[j];
                sc.a1[j] = four_h2 * dq - 2.0 * two_h * st.qd_rad_s[j] - st.qdd_rad_s2[j];
            }
            self.dynamics.kinematics(&sc.q1, &mut sc.kin);
            if refresh && !mbase_done {
                // Newton matrix base, M at the pose of the step's first assembly (the
                // predicted pose unless the last step's matrix served first).
                mbase_done = true;
                self.dynamics.mass_matrix(&mut sc.kin, &mut sc.mbase);
                for v in sc.mbase.iter_mut() {
                    *v *= four_h2;
                }
                for j in 0..n {
                    sc.mbase[j * n + j] += two_h * self.damping[j];
                }
            }
            self.dynamics.rnea(&mut sc.kin, &sc.v1, &sc.a1, &mut sc.tau);
            for j in 0..n {
                sc.rhs[j] = -(sc.tau[j] + self.damping[j] * sc.v1[j]);
            }
            if refresh {
                sc.age = 0;
                sc.kq.copy_from_slice(&sc.mbase);
            }
            let mut retry = false;
            let mut singular = false;
            for (p, pair) in self.pairs.iter().enumerate() {
                let s = &pair.spec;
                if let Some(c) = &pair.relays {
                    match self.friction_pair_block(
                        p,
                        c,
                        st,
                        &mut sc,
                        &th1,
                        &mut x1,
                        &ref_rate,
                        &ff,
                        &mut torque,
                        refresh,
                    ) {
                        Assembly::Done => {}
                        Assembly::Retry => retry = true,
                        Assembly::Singular => singular = true,
                    }
                    continue;
                }
                let rm = s.motor_radius_m;
                let rq: f64 = pair.nz.iter().map(|&k| pair.row[k] * sc.q1[k]).sum();
                let u = rm * th1[p] - rq;
                let x = x1[p];
                let il = pair.inv_length;
                let (fp, kp, _) = pair.stepper.tension_piece(&sc.prep[p][0], (x + u) * il);
                let (fm, km, _) = pair.stepper.tension_piece(&sc.prep[p][1], (x - u) * il);
                let (kp, km) = (kp * il, km * il);
                let cf = s.tensioner == TensionerKind::ConstantForce;
                if cf && kp + km == 0.0 {
                    // Both ropes slack: the carriage takes up the slack first.
                    let lp = sc.prep[p][0].slack_strain() * s.length_m - u;
                    let lm = sc.prep[p][1].slack_strain() * s.length_m + u;
                    x1[p] = lp.min(lm) + 1e-12 * s.length_m;
                    retry = true;
                    continue;
                }
                let nn = pair.n;
                let phi = nn * (fp - fm);
                let ku = nn * (kp + km);
                let kx = nn * (kp - km);
                let (su, sx) = (kp - km, kp + km);
                // rhs = -r_q: r_q contains -R^T phi.
                for &k in &pair.nz {
                    sc.rhs[k] += pair.row[k] * phi;
                }
                let (servo, b11, r0) =
                    match self.servo_row(p, st, th1[p], ref_rate[p], ff[p], sc.sat[p]) {
                        None => (0.0, 1.0, 0.0),
                        Some(row) => {
                            sc.raw[p] = row.raw_n_m;
                            torque[p] = row.torque_n_m;
                            (1.0, row.diag + rm * rm * ku, row.residual_n_m + rm * phi)
                        }
                    };
                let cfm = if cf { 1.0 } else { 0.0 };
                let b12 = servo * cfm * rm * kx;
                let b21 = servo * cfm * su * rm;
                let b22 = if cf { sx } else { 1.0 };
                let r1 = if cf { fp + fm - 2.0 * s.preload_n } else { 0.0 };
                let w = [servo * rm * ku, cfm * su];
                let z = [servo * ku * rm, cfm * kx];
                let det = b11 * b22 - b12 * b21;
                // B^-1 = [b22 -b12; -b21 b11] / det
                let binv = |v: [f64; 2]| {
                    [
                        (b22 * v[0] - b12 * v[1]) / det,
                        (-b21 * v[0] + b11 * v[1]) / det,
                    ]
                };
                let bw = binv(w);
                let br = binv([r0, r1]);
                let beta = z[0] * bw[0] + z[1] * bw[1];
                let gamma = z[0] * br[0] + z[1] * br[1];
                let keff = ku - beta;
                for &a in &pair.nz {
                    let ra = pair.row[a];
                    sc.rhs[a] -= ra * gamma;
                    for &b in &pair.nz {
                        sc.kq[a * n + b] += keff * ra * pair.row[b];
                    }
                }
                sc.local[p] = [b11, b12, b21, b22, w[0], w[1], r0, r1];
            }
            if retry {
                refresh = true;
                continue;
            }
            let factored = if !refresh {
                true
            } else if self.any_friction {
                !singular && relay::lu_in_place(&mut sc.kq, n, &mut sc.perm)
            } else {
                cholesky_in_place(&mut sc.kq, n)
            };
            if !factored {
                (sc.ff, sc.ref_rate, sc.th1, sc.x1, sc.torque) = (ff, ref_rate, th1, x1, torque);
                sc.kept = false;
                st.scratch = sc;
                return Err(ArmError::BlowUp {
                    time_s: t1,
                    detail: if self.any_friction {
                        "the Newton matrix of the step (with relay friction) is singular".into()
                    } else {
                        "the Newton matrix of the step is not positive definite".into()
                    },
                });
            }
            if self.any_friction {
                relay::lu_solve(&sc.kq, n, &sc.perm, &mut sc.rhs);
            } else {
                cholesky_solve(&sc.kq, n, &mut sc.rhs);
            }
            let mut small = true;
            // A safeguard changed a relay update: no error estimate from the update.
            let mut guarded = false;
            // Largest joint update relative to the tolerance (chord control).
            let mut update = 0.0f64;
            for j in 0..n {
                let d = sc.rhs[j];
                sc.q1[j] += d;
                if d.abs() > tol * (1.0 + sc.q1[j].abs()) {
                    small = false;
                }
                update = update.max(d.abs() / (tol * (1.0 + sc.q1[j].abs())));
            }
            let joint_update = update;
            // The relays of a pair were solved alone after this update.
            let mut relaxed = false;
            for (p, pair) in self.pairs.iter().enumerate() {
                if let (Some(c), Some(rs)) = (&pair.relays, sc.relay[p].as_mut()) {
                    if !self.friction_pair_update(p, c, rs, &sc.rhs, &mut th1, &mut x1, tol) {
                        small = false;
                    }
                    let local_update = relay::largest_update(c, rs, tol);
                    update = update.max(local_update);
                    let done = relay::apply_relay_update(c, rs, &st.relays[p], h, iterations, tol);
                    small &= done.small;
                    guarded |= done.guarded;
                    let relax = !done.guarded
                        && iterations <= RELAX_ITERATIONS
                        && local_update > RELAX_RATIO * joint_update.max(1.0);
                    if done.guarded || relax {
                        let inp = Local {
                            h,
                            n: pair.n,
                            motor_radius_m: pair.spec.motor_radius_m,
                            motor: MotorRow::Fixed,
                            constant_force_n: None,
                            theta_rad: th1[p],
                            q: &sc.q1,
                            state: &st.relays[p],
                        };
                        if relax {
                            relaxed = true;
                            relay::relax_relays(c, &pair.stepper, rs, &inp, x1[p], tol);
                        } else {
                            relay::solve_crossed_relays(c, &pair.stepper, rs, &inp, x1[p], tol);
                        }
                    }
                    continue;
                }
                let [b11, b12, b21, b22, w0, w1, r0, r1] = sc.local[p];
                let rdq: f64 = pair.nz.iter().map(|&k| pair.row[k] * sc.rhs[k]).sum();
                let v = [-r0 + w0 * rdq, -r1 + w1 * rdq];
                let det = b11 * b22 - b12 * b21;
                let d0 = (b22 * v[0] - b12 * v[1]) / det;
                let d1 = (-b21 * v[0] + b11 * v[1]) / det;
                if matches!(pair.spec.motor.mode, MotorMode::Servo { .. }) {
                    th1[p] += d0;
                    if d0.abs() > 1e-12 * (1.0 + th1[p].abs()) {
                        small = false;
                    }
                }
                if pair.spec.tensioner == TensionerKind::ConstantForce {
                    x1[p] += d1;
                    if d1.abs() > 1e-15 * (1.0 + pair.spec.length_m) {
                        small = false;
                    }
                }
            }
            if !refresh {
                // A chord update converges linearly: the error left after it is about
                // the next update, rate * update, with the contraction rate of this
                // step (update / last update). The step ends when that error is well
                // below the tolerance (the update itself may be above it; Hairer and
                // Wanner's stopping rule for simplified Newton). The first chord update
                // of a step takes the rate measured last (on a younger matrix: scaled
                // up by the age ratio).
                let measured = last_update.is_finite();
                let rate = if measured {
                    sc.chord_rate = update / last_update;
                    sc.chord_rate_age = sc.age;
                    sc.chord_rate
                } else {
                    sc.chord_rate * f64::from(sc.age.max(1)) / f64::from(sc.chord_rate_age.max(1))
                };
                // Above the tolerance only on a rate measured in this step (a rate
                // kept from an earlier step may have been measured on round-off).
                small = (small || (measured && update <= CHORD_ACCEPT_UPDATE))
                    && rate < 0.5
                    && update * rate <= CHORD_ERROR;
            }
            // A relay moved by a safeguard, or solved alone, has not met the coupled
            // equations yet.
            small &= !guarded && !relaxed;
            if relaxed {
                // The relays now meet their own equations at the joints' update: what is
                // left to measure is the joints'.
                update = joint_update;
            }
            if small && flips < 4 {
                for (p, pair) in self.pairs.iter().enumerate() {
                    if let MotorMode::Servo {
                        torque_limit_n_m, ..
                    } = pair.spec.motor.mode
                    {
                        let raw = sc.raw[p];
                        let want = if raw > torque_limit_n_m {
                            1
                        } else if raw < -torque_limit_n_m {
                            -1
                        } else {
                            0
                        };
                        if want != sc.sat[p] {
                            sc.sat[p] = want;
                            small = false;
                        }
                    }
                }
                if !small {
                    flips += 1;
                    // The servo rows changed: a new Newton matrix.
                    update = f64::INFINITY;
                }
            }
            if small {
                converged = true;
                break;
            }
            // The next iteration keeps the Newton matrix (chord) while the updates
            // shrink fast; a fresh one otherwise.
            let was_refresh = refresh;
            // After relays were solved alone, a fresh Newton matrix for the rest of the
            // step: their slopes changed. Going on with the kept matrix took 11% fewer
            // instructions but left the joints 1.7e-8 rad from a 1e-13 solve instead
            // of 1.1e-9 (tolerance 1e-9, examples/relay_tolerance.rs).
            let contracted = !relaxed && update < CHORD_CONTRACTION * last_update;
            if !was_refresh && !contracted {
                // A chord update that did not shrink: full Newton for the rest of the step.
                chord_allowed = false;
            }
            refresh = !(chord_allowed && update < CHORD_BELOW && (was_refresh || contracted));
            last_update = update;
        }
        if !converged {
            (sc.ff, sc.ref_rate, sc.th1, sc.x1, sc.torque) = (ff, ref_rate, th1, x1, torque);
            sc.kept = false;
            st.scratch = sc;
            return Err(ArmError::BlowUp {
                time_s: t1,
                detail: format!(
                    "the implicit step did not converge in {iterations} Newton iterations"
                ),
            });
        }
        // Commit.
        for (p, pair) in self.pairs.iter().enumerate() {
            let rq: f64 = pair.nz.iter().map(|&k| pair.row[k] * sc.q1[k]).sum();
            let u = pair.spec.motor_radius_m * th1[p] - rq;
            let x = x1[p];
            if let (Some(c), Some(rs)) = (&pair.relays, sc.relay[p].as_mut()) {
                relay::commit(
                    c,
                    &pair.stepper,
                    rs,
                    h,
                    pair.spec.motor_radius_m,
                    th1[p],
                    x,
                    &sc.q1,
                    &mut st.relays[p],
                );
                st.ropes[p] = st.relays[p].spans[0];
            } else {
                for (side, sign) in [(0usize, 1.0), (1usize, -1.0)] {
                    let e = (x + sign * u) * pair.inv_length;
                    let (f, _, _) = pair.stepper.tension_piece(&sc.prep[p][side], e);
                    pair.stepper.commit_with_tension(
                        &sc.prep[p][side],
                        &mut st.ropes[p][side],
                        e,
                        f,
                    );
                }
            }
            let dth = th1[p] - st.motor_rad[p];
            let w1 = two_h * dth - st.motor_rate_rad_s[p];
            let a1 =
                four_h2 * dth - 2.0 * two_h * st.motor_rate_rad_s[p] - st.motor_accel_rad_s2[p];
            st.motor_rad[p] = th1[p];
            st.motor_rate_rad_s[p] = w1;
            st.motor_accel_rad_s2[p] = a1;
            st.carriage_m[p] = x;
            st.motor_torque_n_m[p] = torque[p];
        }
        for j in 0..n {
            let dq = sc.q1[j] - st.q_rad[j];
            let v1 = two_h * dq - st.qd_rad_s[j];
            let a1 = four_h2 * dq - 2.0 * two_h * st.qd_rad_s[j] - st.qdd_rad_s2[j];
            st.q_rad[j] = sc.q1[j];
            st.qd_rad_s[j] = v1;
            st.qdd_rad_s2[j] = a1;
        }
        st.time_s = t1;
        st.iterations = iterations;
        sc.kept = chord_capable;
        sc.age += 1;
        (sc.ff, sc.ref_rate, sc.th1, sc.x1, sc.torque) = (ff, ref_rate, th1, x1, torque);
        st.scratch = sc;
        let finite = st.q_rad.iter().chain(&st.qd_rad_s).all(|v| v.is_finite())
            && st.motor_rad.iter().all(|v| v.is_finite())
            && st.ropes.iter().flatten().all(|r| r.tension_n.is_finite())
            && st
                .relays
                .iter()
                .all(|r| r.spans.iter().flatten().all(|s| s.tension_n.is_finite()));
        if !finite || st.qd_rad_s.iter().any(|v| v.abs() > 1e4) {
            st.scratch.kept = false;
            return Err(ArmError::BlowUp {
                time_s: t1,
                detail: format!(
                    "joint angles {:?} rad, rates {:?} rad/s",
                    st.q_rad, st.qd_rad_s
                ),
            });
        }
        Ok(())
    }

    /// One Newton iteration's contribution of pair `p` with relay friction (servo
    /// torque, then [`relay::assemble`]). Kept out of [`Self::step`] so that the step of
    /// an arm without friction compiles as before.
    #[inline(never)]
    fn friction_pair_block(
        &self,
        p: usize,
        c: &CompiledRelays,
        st: &DrivenState,
        sc: &mut Scratch,
        th1: &[f64],
        x1: &mut [f64],
        ref_rate: &[f64],
        ff: &[f64],
        torque: &mut [f64],
        refresh: bool,
    ) -> Assembly {
        let n = self.spec.ndofs();
        let h = self.dt_s;
        let pair = &self.pairs[p];
        let s = &pair.spec;
        let motor = match self.servo_row(p, st, th1[p], ref_rate[p], ff[p], sc.sat[p]) {
            None => MotorRow::Fixed,
            Some(row) => {
                sc.raw[p] = row.raw_n_m;
                torque[p] = row.torque_n_m;
                MotorRow::Servo {
                    residual_n_m: row.residual_n_m,
                    diag: row.diag,
                }
            }
        };
        let inp = Local {
            h,
            n: pair.n,
            motor_radius_m: s.motor_radius_m,
            motor,
            constant_force_n: (s.tensioner == TensionerKind::ConstantForce).then_some(s.preload_n),
            theta_rad: th1[p],
            q: &sc.q1,
            state: &st.relays[p],
        };
        match sc.relay[p].as_mut() {
            Some(rs) if !refresh => {
                relay::assemble_residual(c, &pair.stepper, rs, &inp, &mut x1[p], &mut sc.rhs)
            }
            Some(rs) => relay::assemble(
                c,
                &pair.stepper,
                rs,
                &inp,
                &mut x1[p],
                &mut sc.kq,
                &mut sc.rhs,
                n,
            ),
            None => Assembly::Singular,
        }
    }

    /// Applies the local update of pair `p` with relay friction; false while a change
    /// is above the tolerance.
    #[inline(never)]
    fn friction_pair_update(
        &self,
        p: usize,
        c: &CompiledRelays,
        rs: &mut RelayScratch,
        dq: &[f64],
        th1: &mut [f64],
        x1: &mut [f64],
        tol: f64,
    ) -> bool {
        let pair = &self.pairs[p];
        let mut small = true;
        relay::local_update(c, rs, dq);
        if matches!(pair.spec.motor.mode, MotorMode::Servo { .. }) {
            let d = rs.dz[c.iz_theta()];
            th1[p] += d;
            if d.abs() > tol * (1.0 + th1[p].abs()) {
                small = false;
            }
        }
        if pair.spec.tensioner == TensionerKind::ConstantForce {
            let d = rs.dz[c.iz_x()];
            x1[p] += d;
            if d.abs() > 1e-15 * (1.0 + pair.spec.length_m) {
                small = false;
            }
        }
        small
    }

    fn make_scratch_light(&self) -> Scratch {
        Scratch {
            kin: Kin::empty(),
            tau: vec![],
            mbase: vec![],
            kq: vec![],
            rhs: vec![],
            q1: vec![],
            v1: vec![],
            a1: vec![],
            zero: vec![],
            g: vec![],
            local: vec![],
            sat: vec![],
            raw: vec![],
            ff: vec![],
            ref_rate: vec![],
            last_qref: vec![],
            th1: vec![],
            x1: vec![],
            torque: vec![],
            prep: vec![],
            relay: vec![],
            perm: vec![],
            kept: false,
            age: 0,
            chord_rate: f64::INFINITY,
            chord_rate_age: 0,
        }
    }
}

/// Chord iterations (the Newton matrix of the step kept) only once every update is
/// below this many tolerances...
const CHORD_BELOW: f64 = 1e4;

/// ...and while each chord update is below this fraction of the previous update.
const CHORD_CONTRACTION: f64 = 0.25;

/// A chord update ends the step only when the error it leaves (estimated from the
/// contraction) is below this fraction of the tolerance...
const CHORD_ERROR: f64 = 1e-2;

/// ...and the update itself below this many tolerances.
const CHORD_ACCEPT_UPDATE: f64 = 1e3;

/// Relays are solved alone ([`relay::relax_relays`]) after a Newton update of the first
/// this many iterations of a step...
const RELAX_ITERATIONS: u32 = 4;

/// ...whose local update (relays, motor) is this many times the joints' (in
/// tolerances, at least one).
const RELAX_RATIO: f64 = 10.0;

/// Steps a kept Newton matrix may start: then a fresh one (a matrix kept over many
/// steps lets errors far below the tolerance accumulate: 2e-11 rad over 0.6 s in the
/// zero-friction comparison of tests/arm/relay_friction.rs without this limit, 4e-15 with).
const MAX_KEPT_STEPS: u32 = 3;

/// One servo's contribution to the implicit step ([`DrivenArm::servo_row`]).
#[derive(Debug, Clone, Copy)]
struct ServoRow {
    /// Torque before saturation, N*m.
    raw_n_m: f64,
    /// Torque applied, N*m.
    torque_n_m: f64,
    /// `J a1 + b w1 - torque`, N*m.
    residual_n_m: f64,
    /// Its derivative with respect to the end motor angle, N*m/rad.
    diag: f64,
}
