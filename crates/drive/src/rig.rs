//! The paper's 1-DoF cable-pulley rig (Figs. 7-8, eqs. 9-11) as a time-stepped plant.
//!
//! An input pulley (radius `r1`, angle `theta`, driven kinematically) turns an output
//! pulley (radius `r2`, inertia `I`, viscous loss `C`, angle `phi`) through two
//! antagonistic ropes of length `L`:
//!
//! ```text
//!   I phi'' + C phi' = r2 (f1 - f2)                       (eq. 9, f = (f1 - f2)/2)
//!   e1 = (x + r1 theta - r2 phi) / L,  e2 = (x - r1 theta + r2 phi) / L   (eqs. 10-11)
//! ```
//!
//! Rope 1 is the rope a positive input angle stretches. `x` is the common stretch set
//! by the tensioner: a constant-force tensioner (the input pulley rides a carriage
//! pulled with `2 T`) moves `x` so that `f1 + f2 = 2 T` at all times while each rope's
//! own tension is free; a fixed tensioner keeps `x` at its initial value.
//!
//! # Relay pulleys
//!
//! Without [`RigSpec::relay_friction`] the relay pulleys are ideal (recorded, no
//! effect), as in the paper's model, and each rope is one span. With it, each rope is
//! split at its `n = relay_pulleys` relay pulleys into `n + 1` spans of length
//! `L / (n + 1)`, each with its own rope state (visco-elastic and plastic), and every
//! relay pulley of every rope has its own angle `psi` and rate. Its rim position along
//! the rope, `q = q_rest + r_relay psi` (positive towards the input pulley), ends the
//! span on its input side and starts the one on its output side:
//!
//! ```text
//!   span stretches of rope i:  x + s_i r1 theta - q_1,  q_1 - q_2,  ...,  q_n - s_i r2 phi
//!   J psi'' = r_relay (T_in - T_out) - coefficient r_relay (T_in + T_out) tanh(psi' / slip)
//! ```
//!
//! with `s_1 = +1`, `s_2 = -1` ([`crate::RelayFriction`]). The carriage holds the sum
//! of the two spans at the input pulley, the output pulley is driven by the two spans
//! at the output pulley. [`RigState::span_tensions_n`] reports every span.
//!
//! # Integration
//!
//! The output pulley is integrated with the trapezoidal rule (Newmark average
//! acceleration: unconditionally stable, second order, no numerical damping); each
//! rope (or span) with its exact-hold step ([`longreach_rope::RopeStepper`]). The
//! end-of-step angle and carriage position solve the implicit equations by Newton's
//! method on the piecewise-smooth rope tensions, with a bracketed fallback.
//!
//! With relay friction the relay pulleys are integrated with the backward Euler rule:
//! a sticking pulley is a very stiff damper (the regularised friction's slope), on which
//! the trapezoidal rule rings at the step frequency (its amplification tends to -1) and
//! flips the friction's sign every step; backward Euler is L-stable and damps it. The
//! relay pulleys' own modes (hundreds of Hz) are far above the rig's 2-4 Hz, so their
//! first-order numerical damping does not show in the response. Newton's method runs on
//! all unknowns (output angle, carriage, relay positions) with a backtracking line
//! search; each rope's relay chain is tridiagonal and is eliminated by the Thomas
//! algorithm, leaving a 2 x 2 system in the output angle and the carriage.

use longreach_rope::{Piece, PreparedStep, RopeLaw, RopeState, RopeStepper};

use crate::error::{non_negative, positive, DriveError};
use crate::transmission::{RelayFriction, Tensioner};

/// Most relay pulleys per rope the plant takes when they have friction.
pub const MAX_RELAY_PULLEYS: u32 = 8;
/// Spans per rope at most (`MAX_RELAY_PULLEYS + 1`).
const MAX_SPANS: usize = MAX_RELAY_PULLEYS as usize + 1;

/// Everything that defines a rig (SI units; the fields of `[rig]` in files).
#[derive(Debug, Clone, PartialEq)]
pub struct RigSpec {
    /// Rope name (catalog or inline), for reports.
    pub rope_name: String,
    /// Constitutive law of each rope (per unit strain).
    pub law: RopeLaw,
    /// L: each rope, input pulley to output pulley [m].
    pub rope_length_m: f64,
    /// r1 [m].
    pub input_radius_m: f64,
    /// r2 [m].
    pub output_radius_m: f64,
    /// I about the output axis [kg*m^2].
    pub output_inertia_kg_m2: f64,
    /// C, viscous resistance of the output shaft [N*m*s].
    pub output_damping_n_m_s: f64,
    /// Idler pulleys each rope runs over (no effect unless `relay_friction` is set).
    pub relay_pulleys: u32,
    /// Their radius [m].
    pub relay_radius_m: f64,
    /// Bearing friction and inertia of every relay pulley; `None`: ideal relay
    /// pulleys and one span per rope (the paper's model).
    pub relay_friction: Option<RelayFriction>,
    /// Pre-tension mechanism.
    pub tensioner: Tensioner,
    /// Mean rope tension held by the tensioner [N].
    pub mean_tension_n: f64,
    /// Pre-stretch tension applied before the test (sets Flory's ratchet) [N].
    pub prestretch_n: f64,
}

impl RigSpec {
    /// The paper's rig (Sec. IV-A) with `law`: L = 15.2 m, r1 = r2 = 25 mm,
    /// I = 2.84e4 kg*mm^2, three relay pulleys, constant-force tensioner, pre-stretch
    /// 490 N, and the given output damping and mean tension.
    pub fn paper(rope_name: &str, law: RopeLaw, damping_n_m_s: f64, mean_tension_n: f64) -> Self {
        Self {
            rope_name: rope_name.to_string(),
            law,
            rope_length_m: 15.2,
            input_radius_m: 0.025,
            output_radius_m: 0.025,
            output_inertia_kg_m2: 0.0284,
            output_damping_n_m_s: damping_n_m_s,
            relay_pulleys: 3,
            relay_radius_m: 0.025,
            relay_friction: None,
            tensioner: Tensioner::ConstantForce,
            mean_tension_n,
            prestretch_n: 490.0,
        }
    }

    /// Checks every field; names the one that is wrong.
    pub fn validate(&self) -> Result<(), DriveError> {
        positive("rope_length_m", self.rope_length_m)?;
        positive("input_radius_m", self.input_radius_m)?;
        positive("output_radius_m", self.output_radius_m)?;
        positive("output_inertia_kg_m2", self.output_inertia_kg_m2)?;
        non_negative("output_damping_n_m_s", self.output_damping_n_m_s)?;
        positive("relay_radius_m", self.relay_radius_m)?;
        positive("mean_tension_n", self.mean_tension_n)?;
        non_negative("prestretch_n", self.prestretch_n)?;
        if let Some(relay) = &self.relay_friction {
            relay.validate()?;
            if self.relay_pulleys > MAX_RELAY_PULLEYS {
                return Err(DriveError::BadParameter {
                    field: "relay_pulleys".into(),
                    value: f64::from(self.relay_pulleys),
                    reason: format!(
                        "at most {MAX_RELAY_PULLEYS} relay pulleys per rope with relay_friction"
                    ),
                });
            }
        }
        self.law.validate()?;
        Ok(())
    }
}

/// A rig compiled for one time step.
#[derive(Debug, Clone)]
pub struct RigModel {
    spec: RigSpec,
    stepper: RopeStepper,
    dt_s: f64,
    /// Carriage stretch at rest [m].
    rest_stretch_m: f64,
    rest_rope: RopeState,
    /// 1 / L [1/m].
    inv_length_per_m: f64,
    /// 2 / dt and 4 / dt^2, and the trapezoidal rule's dynamic stiffness 4 I/dt^2 + 2 C/dt.
    two_over_h: f64,
    four_over_h2: f64,
    k_dyn: f64,
    /// Relay pulleys with friction (`None`: ideal, one span per rope).
    relay: Option<RelayModel>,
}

/// The relay pulleys of a rig with [`RigSpec::relay_friction`], compiled.
#[derive(Debug, Clone)]
struct RelayModel {
    friction: RelayFriction,
    /// Relay pulleys per rope (>= 1).
    n: usize,
    /// L / (n + 1) [m] and its inverse.
    span_length_m: f64,
    inv_span_length_per_m: f64,
    /// J / r^2: the pulley's inertia as a mass on its rim [kg].
    mass_kg: f64,
    /// Rim position of each relay pulley at rest [m] (`q`, towards the input).
    rest_q_m: Vec<f64>,
}

/// The relay pulleys and spans of one rig state (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct RelayState {
    /// `spans[i][j]`: span `j` of rope `i`, from the input pulley (0) to the output
    /// pulley (`relay_pulleys`).
    pub spans: [Vec<RopeState>; 2],
    /// `angle_rad[i][j]`: angle of relay pulley `j` of rope `i` (0 at rest; positive
    /// when the rope on it moves towards the input pulley) [rad].
    pub angle_rad: [Vec<f64>; 2],
    /// Their rates [rad/s].
    pub rate_rad_s: [Vec<f64>; 2],
}

/// Mutable state of a rig.
#[derive(Debug, Clone, PartialEq)]
pub struct RigState {
    /// Time [s].
    pub time_s: f64,
    /// theta, input pulley angle [rad].
    pub input_rad: f64,
    /// phi, output pulley angle [rad].
    pub output_rad: f64,
    /// phi' [rad/s].
    pub output_rate_rad_s: f64,
    /// phi'' [rad/s^2].
    pub output_accel_rad_s2: f64,
    /// Common stretch of both ropes set by the tensioner [m].
    pub carriage_m: f64,
    /// Rope 1 (stretched by positive input) and rope 2; with relay friction, the span
    /// of each rope next to the output pulley (a copy of the last of `relay.spans`).
    pub ropes: [RopeState; 2],
    /// Spans and relay pulleys (`None` on a rig with ideal relay pulleys).
    pub relay: Option<RelayState>,
}

impl RigState {
    /// Tension of rope `i` (0 or 1) next to the output pulley [N] (the whole rope's
    /// tension when the relay pulleys are ideal).
    pub fn tension_n(&self, i: usize) -> f64 {
        self.ropes[i].tension_n
    }

    /// Tension of rope `i` (0 or 1) next to the input pulley [N].
    pub fn tension_in_n(&self, i: usize) -> f64 {
        match &self.relay {
            Some(r) => r.spans[i][0].tension_n,
            None => self.ropes[i].tension_n,
        }
    }

    /// Tensions of every span of rope `i` (0 or 1), from the input pulley to the output
    /// pulley [N]: `relay_pulleys + 1` values with relay friction, one otherwise.
    pub fn span_tensions_n(&self, i: usize) -> Vec<f64> {
        match &self.relay {
            Some(r) => r.spans[i].iter().map(|s| s.tension_n).collect(),
            None => vec![self.ropes[i].tension_n],
        }
    }

    /// Smaller of the two rope tensions [N].
    pub fn min_tension_n(&self) -> f64 {
        self.ropes[0].tension_n.min(self.ropes[1].tension_n)
    }
}

/// Rope tensions and slopes at one trial end state.
struct Eval {
    f: [f64; 2],
    /// d(tension)/d(stretch) [N/m].
    k: [f64; 2],
    e: [f64; 2],
    affine: bool,
    pieces: [Piece; 2],
}

/// Sign of the differential stretch for rope `i`.
const SIGN: [f64; 2] = [1.0, -1.0];

impl RigModel {
    /// Compiles `spec` for steps of `dt_s`.
    pub fn new(spec: RigSpec, dt_s: f64) -> Result<Self, DriveError> {
        spec.validate()?;
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 0.05) {
            return Err(DriveError::BadParameter {
                field: "dt_s".into(),
                value: dt_s,
                reason: "must be in (0, 0.05] s; 1e-3 s resolves the rig's 2-4 Hz resonance well"
                    .into(),
            });
        }
        let stepper = RopeStepper::new(spec.law.clone(), dt_s)?;
        let rest_rope = stepper.rest_state(spec.mean_tension_n, spec.prestretch_n);
        let relay = match spec.relay_friction {
            Some(friction) if spec.relay_pulleys > 0 => {
                let n = spec.relay_pulleys as usize;
                let span_length_m = spec.rope_length_m / (n + 1) as f64;
                let rest_stretch = rest_rope.strain * span_length_m;
                Some(RelayModel {
                    friction,
                    n,
                    span_length_m,
                    inv_span_length_per_m: 1.0 / span_length_m,
                    mass_kg: friction.inertia_kg_m2 / (spec.relay_radius_m * spec.relay_radius_m),
                    rest_q_m: (1..=n).map(|j| rest_stretch * (n + 1 - j) as f64).collect(),
                })
            }
            _ => None,
        };
        Ok(Self {
            relay,
            inv_length_per_m: 1.0 / spec.rope_length_m,
            two_over_h: 2.0 / dt_s,
            four_over_h2: 4.0 / (dt_s * dt_s),
            k_dyn: 4.0 * spec.output_inertia_kg_m2 / (dt_s * dt_s)
                + 2.0 * spec.output_damping_n_m_s / dt_s,
            rest_stretch_m: rest_rope.strain * spec.rope_length_m,
            rest_rope,
            stepper,
            dt_s,
            spec,
        })
    }

    /// The rig's definition.
    pub fn spec(&self) -> &RigSpec {
        &self.spec
    }

    /// Step [s].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// The rope stepper (law compiled for `dt_s`).
    pub fn stepper(&self) -> &RopeStepper {
        &self.stepper
    }

    /// Both angles zero, at rest under the mean tension (the format's initial state).
    pub fn rest_state(&self) -> RigState {
        RigState {
            time_s: 0.0,
            input_rad: 0.0,
            output_rad: 0.0,
            output_rate_rad_s: 0.0,
            output_accel_rad_s2: 0.0,
            carriage_m: self.rest_stretch_m,
            ropes: [self.rest_rope; 2],
            relay: self.relay.as_ref().map(|r| RelayState {
                spans: [vec![self.rest_rope; r.n + 1], vec![self.rest_rope; r.n + 1]],
                angle_rad: [vec![0.0; r.n], vec![0.0; r.n]],
                rate_rad_s: [vec![0.0; r.n], vec![0.0; r.n]],
            }),
        }
    }

    /// Mechanical energy of `st` [J]: kinetic energy of the output and relay pulleys,
    /// elastic energy of every rope span ([`RopeStepper::stored_energy_j`]), and, with
    /// a constant-force tensioner, the tensioner's potential `-2 T x`. With the input
    /// held still it can only fall (rope dashpots, damping and friction dissipate; the
    /// trapezoidal rule conserves it, backward Euler on the relay pulleys dissipates,
    /// checked in `tests/drive/relay.rs` to 1e-12 J per step).
    pub fn energy_j(&self, st: &RigState) -> f64 {
        let s = &self.spec;
        let mut e = 0.5 * s.output_inertia_kg_m2 * st.output_rate_rad_s.powi(2);
        match (&self.relay, &st.relay) {
            (Some(m), Some(r)) => {
                for i in 0..2 {
                    for span in &r.spans[i] {
                        e += self.stepper.stored_energy_j(span, m.span_length_m);
                    }
                    for w in &r.rate_rad_s[i] {
                        e += 0.5 * m.friction.inertia_kg_m2 * w * w;
                    }
                }
            }
            _ => {
                for rope in &st.ropes {
                    e += self.stepper.stored_energy_j(rope, s.rope_length_m);
                }
            }
        }
        if s.tensioner == Tensioner::ConstantForce {
            e -= 2.0 * s.mean_tension_n * st.carriage_m;
        }
        e
    }

    /// Strain of rope `i` for carriage stretch `x`, input `theta`, output `phi`.
    fn strain(&self, i: usize, x: f64, theta: f64, phi: f64) -> f64 {
        let s = &self.spec;
        (x + SIGN[i] * (s.input_radius_m * theta - s.output_radius_m * phi)) * self.inv_length_per_m
    }

    /// Advances one step with the input angle `input_rad` at the end of the step.
    pub fn step(&self, st: &mut RigState, input_rad: f64) -> Result<(), DriveError> {
        if let Some(relay) = &self.relay {
            return self.step_relay(relay, st, input_rad);
        }
        let s = &self.spec;
        let h = self.dt_s;
        let (r2, l, inv_l) = (s.output_radius_m, s.rope_length_m, self.inv_length_per_m);
        let prep = [
            self.stepper.prepare(&st.ropes[0]),
            self.stepper.prepare(&st.ropes[1]),
        ];
        let (phi0, w0, a0) = (st.output_rad, st.output_rate_rad_s, st.output_accel_rad_s2);
        let k_dyn = self.k_dyn;
        let inertial = |phi: f64| self.inertial_torque_n_m((phi0, w0, a0), phi);
        let two_t = 2.0 * s.mean_tension_n;
        let constant_force = s.tensioner == Tensioner::ConstantForce;
        let eval = |phi: f64, x: f64| {
            let e = [
                self.strain(0, x, input_rad, phi),
                self.strain(1, x, input_rad, phi),
            ];
            let (f1, k1, p1) = self.stepper.tension_piece(&prep[0], e[0]);
            let (f2, k2, p2) = self.stepper.tension_piece(&prep[1], e[1]);
            Eval {
                f: [f1, f2],
                k: [k1 * inv_l, k2 * inv_l],
                e,
                affine: p1 != Piece::Nonlinear && p2 != Piece::Nonlinear,
                pieces: [p1, p2],
            }
        };

        // Predictor, then Newton. On piecewise-affine laws one Newton step is exact when
        // no rope changes piece; the evaluation at the new point confirms it.
        let mut phi = phi0 + h * w0 + 0.5 * h * h * a0;
        let mut x = st.carriage_m;
        let mut ev = eval(phi, x);
        let mut converged = false;
        for _ in 0..40 {
            let [f1, f2] = ev.f;
            let [k1, k2] = ev.k;
            let res_m = inertial(phi) - r2 * (f1 - f2);
            let d11 = k_dyn + r2 * r2 * (k1 + k2);
            let (dphi, dx) = if constant_force {
                if k1 + k2 == 0.0 {
                    // Both ropes slack: the carriage takes up the slack first.
                    x = self.first_taut_stretch(&prep, input_rad, phi) + 1e-12 * l;
                    ev = eval(phi, x);
                    continue;
                }
                let res_t = f1 + f2 - two_t;
                let d12 = -r2 * (k1 - k2);
                let d22 = k1 + k2;
                let det = d11 * d22 - d12 * d12;
                (
                    -(d22 * res_m - d12 * res_t) / det,
                    -(d11 * res_t - d12 * res_m) / det,
                )
            } else {
                (-res_m / d11, 0.0)
            };
            phi += dphi;
            x += dx;
            let next = eval(phi, x);
            let same_piece = next.affine && ev.affine && next.pieces == ev.pieces;
            ev = next;
            // Tolerances the nested rope solve of non-linear laws can meet: 1e-12 rad,
            // and a carriage strain of 1e-14 (tension error ~1e-9 N).
            if same_piece || (dphi.abs() <= 1e-12 * (1.0 + phi.abs()) && dx.abs() <= 1e-14 * l) {
                converged = true;
                break;
            }
        }
        if converged {
            for i in 0..2 {
                self.stepper
                    .commit_with_tension(&prep[i], &mut st.ropes[i], ev.e[i], ev.f[i]);
            }
        } else {
            (phi, x) = self.solve_bracketed(&prep, input_rad, &inertial, k_dyn)?;
            for i in 0..2 {
                let e = self.strain(i, x, input_rad, phi);
                self.stepper.commit(&prep[i], &mut st.ropes[i], e);
            }
        }
        let ropes_finite = st.ropes.iter().all(|r| r.tension_n.is_finite());
        self.end_step(
            st,
            input_rad,
            (phi0, w0, a0),
            phi,
            x,
            ropes_finite,
            "tensions",
        )
    }

    /// Output rate and acceleration `(w1, a1)` at the end of a step that ends at angle
    /// `phi` from the start `(phi0, w0, a0)` (trapezoidal rule:
    /// `w1 = 2(phi - phi0)/h - w0`, `a1 = 4(phi - phi0)/h^2 - 4 w0/h - a0`).
    fn end_rates(&self, (phi0, w0, a0): (f64, f64, f64), phi: f64) -> (f64, f64) {
        let (two_h, four_h2) = (self.two_over_h, self.four_over_h2);
        let w1 = two_h * (phi - phi0) - w0;
        let a1 = four_h2 * (phi - phi0) - two_h * 2.0 * w0 - a0;
        (w1, a1)
    }

    /// Inertia and damping torque of the output pulley at the end of a step ending at
    /// `phi` from the start `start`, N*m.
    fn inertial_torque_n_m(&self, start: (f64, f64, f64), phi: f64) -> f64 {
        let (w1, a1) = self.end_rates(start, phi);
        self.spec.output_inertia_kg_m2 * a1 + self.spec.output_damping_n_m_s * w1
    }

    /// Ends a step at output angle `phi` and carriage `x`: trapezoidal rate and
    /// acceleration from the step's start `(phi0, w0, a0)`, time and input advanced;
    /// a non-finite state (`states_finite` covers the ropes and relays) or a runaway
    /// rate is a blow-up naming the time and the output-end tensions (`tensions`).
    fn end_step(
        &self,
        st: &mut RigState,
        input_rad: f64,
        start: (f64, f64, f64),
        phi: f64,
        x: f64,
        states_finite: bool,
        tensions: &str,
    ) -> Result<(), DriveError> {
        let (w1, a1) = self.end_rates(start, phi);
        st.time_s += self.dt_s;
        st.input_rad = input_rad;
        st.output_rad = phi;
        st.output_rate_rad_s = w1;
        st.output_accel_rad_s2 = a1;
        st.carriage_m = x;
        let finite =
            phi.is_finite() && w1.is_finite() && a1.is_finite() && x.is_finite() && states_finite;
        if !finite || w1.abs() > 1e6 {
            return Err(DriveError::BlowUp {
                time_s: st.time_s,
                what: format!(
                    "output angle {phi} rad, rate {w1} rad/s, {tensions} {} / {} N",
                    st.ropes[0].tension_n, st.ropes[1].tension_n
                ),
            });
        }
        Ok(())
    }

    /// Carriage stretch at which the first rope becomes taut for the given angles.
    fn first_taut_stretch(&self, prep: &[PreparedStep; 2], theta: f64, phi: f64) -> f64 {
        (0..2)
            .map(|i| {
                let u = self.strain(i, 0.0, theta, phi) * self.spec.rope_length_m;
                prep[i].slack_strain() * self.spec.rope_length_m - u
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Carriage stretch holding `f1 + f2 = 2T` at output angle `phi` (bisection on a
    /// monotone function, Newton-accelerated).
    fn carriage_for(&self, prep: &[PreparedStep; 2], theta: f64, phi: f64) -> f64 {
        let target = 2.0 * self.spec.mean_tension_n;
        let sum = |x: f64| -> (f64, f64) {
            let (f1, k1) = self
                .stepper
                .tension(&prep[0], self.strain(0, x, theta, phi));
            let (f2, k2) = self
                .stepper
                .tension(&prep[1], self.strain(1, x, theta, phi));
            (f1 + f2 - target, (k1 + k2) / self.spec.rope_length_m)
        };
        let mut lo = self.first_taut_stretch(prep, theta, phi);
        let mut step = 1e-6 * self.spec.rope_length_m;
        let mut hi = lo + step;
        while sum(hi).0 < 0.0 {
            lo = hi;
            step *= 2.0;
            hi += step;
        }
        let mut x = hi;
        for _ in 0..200 {
            let (g, dg) = sum(x);
            if g > 0.0 {
                hi = x;
            } else {
                lo = x;
            }
            let mut next = if dg > 0.0 { x - g / dg } else { f64::NAN };
            if !(next > lo && next < hi) {
                next = 0.5 * (lo + hi);
            }
            if (next - x).abs() <= 1e-16 * (1.0 + x.abs()) || hi - lo <= 1e-17 {
                return next;
            }
            x = next;
        }
        x
    }

    /// Fallback solve: the carriage is eliminated for each trial angle, and the
    /// monotone residual in the angle is bracketed.
    fn solve_bracketed(
        &self,
        prep: &[PreparedStep; 2],
        theta: f64,
        inertial: &dyn Fn(f64) -> f64,
        k_dyn: f64,
    ) -> Result<(f64, f64), DriveError> {
        let r2 = self.spec.output_radius_m;
        let constant_force = self.spec.tensioner == Tensioner::ConstantForce;
        let resid = |phi: f64| -> (f64, f64) {
            let x = if constant_force {
                self.carriage_for(prep, theta, phi)
            } else {
                self.rest_stretch_m
            };
            let f1 = self
                .stepper
                .tension(&prep[0], self.strain(0, x, theta, phi))
                .0;
            let f2 = self
                .stepper
                .tension(&prep[1], self.strain(1, x, theta, phi))
                .0;
            (inertial(phi) - r2 * (f1 - f2), x)
        };
        // The residual grows at least as fast as k_dyn * phi: bracket with that slope.
        let (r_mid, _) = resid(0.0);
        let span = 2.0 * r_mid.abs() / k_dyn + 1e-9;
        let (mut lo, mut hi) = (-span, span);
        let mut guard = 0;
        while resid(lo).0 > 0.0 || resid(hi).0 < 0.0 {
            lo *= 2.0;
            hi *= 2.0;
            guard += 1;
            if guard > 200 {
                return Err(DriveError::BlowUp {
                    time_s: f64::NAN,
                    what: "no output angle balances the rope torques".into(),
                });
            }
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if resid(mid).0 > 0.0 {
                hi = mid;
            } else {
                lo = mid;
            }
            if hi - lo <= 1e-15 * (1.0 + mid.abs()) {
                break;
            }
        }
        let phi = 0.5 * (lo + hi);
        Ok((phi, resid(phi).1))
    }
}

/// Span tensions and slopes of both ropes at one trial end state (relay friction).
#[derive(Clone, Copy)]
struct SpanEval {
    /// Tension of span `j` of rope `i` [N].
    f: [[f64; MAX_SPANS]; 2],
    /// d(tension)/d(stretch) [N/m].
    k: [[f64; MAX_SPANS]; 2],
    /// Strain.
    e: [[f64; MAX_SPANS]; 2],
    pieces: [[Piece; MAX_SPANS]; 2],
    /// Residuals: output torque / r2 [N], carriage [N], relay pulleys [N].
    res_out: f64,
    res_x: f64,
    res_q: [[f64; MAX_SPANS]; 2],
    /// Friction slope d(force)/d(hub load) [-] and d(force)/dq [N/m] of each pulley.
    dfdt: [[f64; MAX_SPANS]; 2],
    dfdq: [[f64; MAX_SPANS]; 2],
}

impl SpanEval {
    /// Sum of squared residuals [N^2].
    fn merit(&self, n: usize) -> f64 {
        let mut m = self.res_out * self.res_out + self.res_x * self.res_x;
        for r in &self.res_q {
            m += r[..n].iter().map(|v| v * v).sum::<f64>();
        }
        m
    }
}

/// Solves the tridiagonal system `sub[r] y[r-1] + diag[r] y[r] + sup[r] y[r+1] = rhs[r]`
/// for three right-hand sides at once (Thomas algorithm; the relay chain's matrix is
/// diagonally dominant, so no pivoting is needed).
fn thomas3(
    n: usize,
    sub: &[f64; MAX_SPANS],
    diag: &[f64; MAX_SPANS],
    sup: &[f64; MAX_SPANS],
    rhs: &mut [[f64; MAX_SPANS]; 3],
    floor: f64,
) {
    let mut c = [0.0; MAX_SPANS];
    let d0 = diag[0].max(floor);
    c[0] = sup[0] / d0;
    for v in rhs.iter_mut() {
        v[0] /= d0;
    }
    for r in 1..n {
        let d = (diag[r] - sub[r] * c[r - 1]).max(floor);
        c[r] = sup[r] / d;
        for v in rhs.iter_mut() {
            v[r] = (v[r] - sub[r] * v[r - 1]) / d;
        }
    }
    for r in (0..n.saturating_sub(1)).rev() {
        for v in rhs.iter_mut() {
            v[r] -= c[r] * v[r + 1];
        }
    }
}

impl RigModel {
    /// One step of a rig whose relay pulleys have friction and inertia (module docs).
    fn step_relay(
        &self,
        m: &RelayModel,
        st: &mut RigState,
        input_rad: f64,
    ) -> Result<(), DriveError> {
        let s = &self.spec;
        let h = self.dt_s;
        let n = m.n;
        let Some(rs) = st.relay.as_mut().filter(|r| {
            r.spans.iter().all(|s| s.len() == n + 1)
                && r.angle_rad
                    .iter()
                    .chain(&r.rate_rad_s)
                    .all(|a| a.len() == n)
        }) else {
            return Err(DriveError::BadParameter {
                field: "state".into(),
                value: f64::NAN,
                reason: format!(
                    "this rig has relay friction on {n} pulley(s) per rope: start from its \
                     own rest_state()"
                ),
            });
        };
        let (r1, r2, rr) = (s.input_radius_m, s.output_radius_m, s.relay_radius_m);
        let (ls, inv_ls, mass) = (m.span_length_m, m.inv_span_length_per_m, m.mass_kg);
        let fr = m.friction;
        let mut prep = [[self.stepper.prepare(&rs.spans[0][0]); MAX_SPANS]; 2];
        for i in 0..2 {
            for j in 0..=n {
                prep[i][j] = self.stepper.prepare(&rs.spans[i][j]);
            }
        }
        // Relay rim positions and rates at the start of the step [m, m/s].
        let mut q0 = [[0.0; MAX_SPANS]; 2];
        let mut v0 = [[0.0; MAX_SPANS]; 2];
        for i in 0..2 {
            for j in 0..n {
                q0[i][j] = m.rest_q_m[j] + rr * rs.angle_rad[i][j];
                v0[i][j] = rr * rs.rate_rad_s[i][j];
            }
        }
        let (phi0, w0, a0) = (st.output_rad, st.output_rate_rad_s, st.output_accel_rad_s2);
        let k_dyn = self.k_dyn;
        let inertial = |phi: f64| self.inertial_torque_n_m((phi0, w0, a0), phi);
        let two_t = 2.0 * s.mean_tension_n;
        let constant_force = s.tensioner == Tensioner::ConstantForce;
        let x_fixed = st.carriage_m;
        let inv_h = 1.0 / h;
        let eval = |phi: f64, x: f64, q: &[[f64; MAX_SPANS]; 2]| -> SpanEval {
            let mut ev = SpanEval {
                f: [[0.0; MAX_SPANS]; 2],
                k: [[0.0; MAX_SPANS]; 2],
                e: [[0.0; MAX_SPANS]; 2],
                pieces: [[Piece::Slack; MAX_SPANS]; 2],
                res_out: 0.0,
                res_x: 0.0,
                res_q: [[0.0; MAX_SPANS]; 2],
                dfdt: [[0.0; MAX_SPANS]; 2],
                dfdq: [[0.0; MAX_SPANS]; 2],
            };
            for i in 0..2 {
                let a = x + SIGN[i] * r1 * input_rad;
                let b = SIGN[i] * r2 * phi;
                for j in 0..=n {
                    let left = if j == 0 { a } else { q[i][j - 1] };
                    let right = if j == n { b } else { q[i][j] };
                    let e = (left - right) * inv_ls;
                    let (f, k, p) = self.stepper.tension_piece(&prep[i][j], e);
                    ev.f[i][j] = f;
                    ev.k[i][j] = k * inv_ls;
                    ev.e[i][j] = e;
                    ev.pieces[i][j] = p;
                }
                for j in 0..n {
                    let (t_in, t_out) = (ev.f[i][j], ev.f[i][j + 1]);
                    let v = (q[i][j] - q0[i][j]) * inv_h;
                    let tq = fr.torque_n_m(rr, t_in + t_out, v / rr);
                    ev.res_q[i][j] =
                        mass * (v - v0[i][j]) * inv_h + tq.torque_n_m / rr - t_in + t_out;
                    ev.dfdt[i][j] = tq.d_tension_sum_m / rr;
                    ev.dfdq[i][j] = tq.d_rate_n_m_s / (rr * rr) * inv_h;
                }
            }
            ev.res_out = (inertial(phi) - r2 * (ev.f[0][n] - ev.f[1][n])) / r2;
            ev.res_x = if constant_force {
                ev.f[0][0] + ev.f[1][0] - two_t
            } else {
                0.0
            };
            ev
        };

        // Predictor: the output as in the ideal rig, the relay pulleys at their rates.
        let mut phi = phi0 + h * w0 + 0.5 * h * h * a0;
        let mut x = st.carriage_m;
        let mut q = q0;
        for i in 0..2 {
            for j in 0..n {
                q[i][j] += h * v0[i][j];
            }
        }
        let mut ev = eval(phi, x, &q);
        let affine_law = fr.coefficient == 0.0;
        let floor = 1e-12 * self.stepper.law().k1_n * inv_ls;
        // Residual forces this small end the iteration (a tension error ~1e-11 of the
        // mean, the ideal rig's step tolerances in force).
        let res_tol2 = (1e-11 * two_t).powi(2);
        let mut converged = false;
        for _ in 0..80 {
            if constant_force && ev.k[0][0] + ev.k[1][0] == 0.0 {
                // Both input spans slack: the carriage takes up the slack first.
                x = (0..2)
                    .map(|i| prep[i][0].slack_strain() * ls + q[i][0] - SIGN[i] * r1 * input_rad)
                    .fold(f64::INFINITY, f64::min)
                    + 1e-12 * s.rope_length_m;
                ev = eval(phi, x, &q);
                continue;
            }
            // Newton direction: eliminate each rope's relay chain (tridiagonal), then
            // solve for the output angle and the carriage.
            let mut y = [[[0.0; MAX_SPANS]; 3]; 2];
            for i in 0..2 {
                let (mut sub, mut diag, mut sup) =
                    ([0.0; MAX_SPANS], [0.0; MAX_SPANS], [0.0; MAX_SPANS]);
                for j in 0..n {
                    let (kl, kr, g) = (ev.k[i][j], ev.k[i][j + 1], ev.dfdt[i][j]);
                    diag[j] =
                        mass * inv_h * inv_h + ev.dfdq[i][j] + kl * (1.0 - g) + kr * (1.0 + g);
                    sub[j] = -kl * (1.0 - g);
                    sup[j] = -kr * (1.0 + g);
                    y[i][0][j] = -ev.res_q[i][j];
                }
                // d(residual of the first pulley)/dx and d(last pulley)/dphi.
                y[i][1][0] = ev.k[i][0] * (1.0 - ev.dfdt[i][0]);
                y[i][2][n - 1] += SIGN[i] * r2 * ev.k[i][n] * (1.0 + ev.dfdt[i][n - 1]);
                thomas3(n, &sub, &diag, &sup, &mut y[i], floor);
            }
            // Rows of the output (scaled by 1/r2) and the carriage.
            let jpp = (k_dyn + r2 * r2 * (ev.k[0][n] + ev.k[1][n])) / r2;
            let g = [-SIGN[0] * ev.k[0][n], -SIGN[1] * ev.k[1][n]];
            let (mut a11, mut a12, mut b1) = (jpp, 0.0, -ev.res_out);
            for i in 0..2 {
                a11 += g[i] * y[i][2][n - 1];
                a12 += g[i] * y[i][1][n - 1];
                b1 -= g[i] * y[i][0][n - 1];
            }
            let (dphi, dx) = if constant_force {
                let hx = [-ev.k[0][0], -ev.k[1][0]];
                let (mut a21, mut a22, mut b2) = (0.0, ev.k[0][0] + ev.k[1][0], -ev.res_x);
                for i in 0..2 {
                    a21 += hx[i] * y[i][2][0];
                    a22 += hx[i] * y[i][1][0];
                    b2 -= hx[i] * y[i][0][0];
                }
                let det = a11 * a22 - a12 * a21;
                ((b1 * a22 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det)
            } else {
                (b1 / a11, 0.0)
            };
            let mut dq = [[0.0; MAX_SPANS]; 2];
            let mut dq_max = 0.0_f64;
            for i in 0..2 {
                for j in 0..n {
                    dq[i][j] = y[i][0][j] + y[i][1][j] * dx + y[i][2][j] * dphi;
                    dq_max = dq_max.max(dq[i][j].abs());
                }
            }
            let small = dphi.abs() <= 1e-12 * (1.0 + phi.abs())
                && dx.abs() <= 1e-14 * s.rope_length_m
                && dq_max <= 1e-14 * s.rope_length_m;
            // Backtracking line search on the squared residuals.
            let merit0 = ev.merit(n);
            let mut alpha = 1.0;
            let mut halvings = 0;
            let mut trial;
            loop {
                let mut qt = q;
                for i in 0..2 {
                    for j in 0..n {
                        qt[i][j] += alpha * dq[i][j];
                    }
                }
                let (pt, xt) = (phi + alpha * dphi, x + alpha * dx);
                trial = (pt, xt, qt, eval(pt, xt, &qt));
                if trial.3.merit(n) <= (1.0 - 1e-4 * alpha) * merit0 || alpha < 1e-6 || small {
                    break;
                }
                alpha *= 0.5;
                halvings += 1;
            }
            let same_piece = affine_law
                && halvings == 0
                && trial.3.pieces == ev.pieces
                && ev.pieces.iter().flatten().all(|p| *p != Piece::Nonlinear);
            (phi, x, q, ev) = trial;
            if !constant_force {
                x = x_fixed;
            }
            if small || same_piece || ev.merit(n) <= res_tol2 {
                converged = true;
                break;
            }
        }
        if !converged {
            return Err(DriveError::BlowUp {
                time_s: st.time_s + h,
                what: format!(
                    "the relay-pulley solve did not converge (output angle {phi} rad, residual \
                     {:.3e} N); reduce dt_s or raise relay_friction.slip_rate_rad_s",
                    ev.merit(n).sqrt()
                ),
            });
        }
        for i in 0..2 {
            for j in 0..=n {
                self.stepper.commit_with_tension(
                    &prep[i][j],
                    &mut rs.spans[i][j],
                    ev.e[i][j],
                    ev.f[i][j],
                );
            }
            for j in 0..n {
                rs.rate_rad_s[i][j] = (q[i][j] - q0[i][j]) * inv_h / rr;
                rs.angle_rad[i][j] = (q[i][j] - m.rest_q_m[j]) / rr;
            }
            st.ropes[i] = rs.spans[i][n];
        }
        let states_finite = rs.spans.iter().flatten().all(|r| r.tension_n.is_finite())
            && rs.rate_rad_s.iter().flatten().all(|w| w.is_finite());
        self.end_step(
            st,
            input_rad,
            (phi0, w0, a0),
            phi,
            x,
            states_finite,
            "output-side tensions",
        )
    }
}
