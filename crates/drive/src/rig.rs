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
//! # One plant core
//!
//! The rig is the transmission core's plant with one joint ([`crate::transmission`]):
//! the output pulley is the joint side (`I`, `C`), the input pulley is the kinematic
//! motor of one rope pair (motor radius `r1`, joint pulley `r2`, routing row `[r2]`),
//! the tensioner and the relay pulleys are the pair's. The arm (crates/arm) is the same
//! core with its links as the joint side.
//!
//! # Relay pulleys
//!
//! Without [`RigSpec::relay_friction`] the relay pulleys are ideal (recorded, no
//! effect), as in the paper's model, and each rope is one span. With it, each rope is
//! split at its `n = relay_pulleys` relay pulleys, fixed to the base, into `n + 1` spans
//! of length `L / (n + 1)`, each with its own rope state (visco-elastic and plastic),
//! and every relay pulley of every rope has its own angle `psi` (positive when the rope
//! on it moves towards the output pulley) and rate:
//!
//! ```text
//!   span elongations of rope i:  x + s_i r1 theta + r psi_1,  r psi_2 - r psi_1,  ...,  -s_i r2 phi - r psi_n   (+ constants)
//!   J psi'' + coefficient r (T_a + T_b) tanh(psi' / slip) + r (T_a - T_b) = 0
//! ```
//!
//! with `s_1 = +1`, `s_2 = -1` ([`crate::RelayFriction`], [`crate::transmission::relay`]).
//! The carriage holds the sum of the two spans at the input pulley, the output pulley
//! is driven by the two spans at the output pulley. [`RigState::span_tensions_n`]
//! reports every span.
//!
//! # Integration
//!
//! The trapezoidal rule (Newmark average acceleration: unconditionally stable, second
//! order, no numerical damping) on the output pulley and the relay pulleys, the
//! exact-hold step on each rope (or span) ([`longreach_rope::RopeStepper`]), Newton on
//! the end-of-step state ([`crate::transmission::step`]).
//!
//! The ideal rig (no relay friction, no effect at the output shaft) takes a fast path
//! through the same pair block: on piecewise-affine ropes one Newton step is exact
//! unless a rope changes piece, so the step ends as soon as an update leaves every rope
//! on the piece it was linearised on (usually after one update), with a bracketed
//! fallback when the pieces cycle.

use longreach_rope::{Piece, PreparedStep, RopeLaw, RopeParams, RopeState};

use crate::effects::Applied;
use crate::error::{non_negative, positive, DriveError};
use crate::transmission::ideal;
use crate::transmission::pair::StaticPair;
use crate::transmission::{
    CompiledPair, Drivetrain, JointLoad, JointSide, MotorInputs, MotorSpec, PairSpec, PlantState,
    Relay, RelayFriction, RelayState, Tensioner,
};

/// Most relay pulleys per rope the plant takes when they have friction.
pub const MAX_RELAY_PULLEYS: u32 = 8;

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
    /// The output pulley (the joint side).
    shaft: OutputShaft,
    /// The rope pair (and the effects at the output shaft).
    drive: Drivetrain,
    /// Ideal relays and no effect at the shaft: the fast path.
    fast: bool,
}

/// The output pulley as the joint side of the core's step: inertia `I`, viscous loss
/// `C`.
#[derive(Debug, Clone, Copy)]
struct OutputShaft {
    inertia_kg_m2: f64,
    damping_n_m_s: f64,
}

impl JointSide for OutputShaft {
    type Scratch = ();

    fn ndofs(&self) -> usize {
        1
    }

    fn begin_iteration(&self, _sc: &mut (), _q1: &[f64]) {}

    fn matrix(&self, _sc: &mut (), four_h2: f64, two_h: f64, out: &mut [f64]) {
        out[0] = four_h2 * self.inertia_kg_m2 + two_h * self.damping_n_m_s;
    }

    fn residual(&self, _sc: &mut (), v1: &[f64], a1: &[f64], out: &mut [f64]) {
        out[0] = -(self.inertia_kg_m2 * a1[0] + self.damping_n_m_s * v1[0]);
    }
}

/// Mutable state of a rig: the core's plant state with one joint (the output pulley)
/// and one pair (the input pulley is its motor).
#[derive(Debug, Clone)]
pub struct RigState {
    plant: PlantState<()>,
}

impl RigState {
    /// Time [s].
    pub fn time_s(&self) -> f64 {
        self.plant.time_s
    }

    /// theta, input pulley angle [rad].
    pub fn input_rad(&self) -> f64 {
        self.plant.motor_rad[0]
    }

    /// phi, output pulley angle [rad].
    pub fn output_rad(&self) -> f64 {
        self.plant.q_rad[0]
    }

    /// phi' [rad/s].
    pub fn output_rate_rad_s(&self) -> f64 {
        self.plant.qd_rad_s[0]
    }

    /// phi'' [rad/s^2].
    pub fn output_accel_rad_s2(&self) -> f64 {
        self.plant.qdd_rad_s2[0]
    }

    /// Common stretch of both ropes set by the tensioner [m].
    pub fn carriage_m(&self) -> f64 {
        self.plant.carriage_m[0]
    }

    /// Rope states `[1, 2]` next to the output pulley (the whole ropes when the relay
    /// pulleys are ideal).
    pub fn ropes(&self) -> [RopeState; 2] {
        match self.plant.relays[0].spans.last() {
            Some(last) => *last,
            None => self.plant.ropes[0],
        }
    }

    /// Spans and relay pulleys (empty on a rig with ideal relay pulleys): `spans[j]` is
    /// span `j` of both ropes `[1, 2]`, from the input pulley (0) to the output pulley.
    pub fn relays(&self) -> &RelayState {
        &self.plant.relays[0]
    }

    /// The core's plant state.
    pub fn plant(&self) -> &PlantState<()> {
        &self.plant
    }

    /// Tension of rope `i` (0 or 1) next to the output pulley [N] (the whole rope's
    /// tension when the relay pulleys are ideal).
    pub fn tension_n(&self, i: usize) -> f64 {
        self.ropes()[i].tension_n
    }

    /// Tension of rope `i` (0 or 1) next to the input pulley [N].
    pub fn tension_in_n(&self, i: usize) -> f64 {
        self.plant.ropes[0][i].tension_n
    }

    /// Tensions of every span of rope `i` (0 or 1), from the input pulley to the output
    /// pulley [N]: `relay_pulleys + 1` values with relay friction, one otherwise.
    pub fn span_tensions_n(&self, i: usize) -> Vec<f64> {
        let r = &self.plant.relays[0];
        if r.spans.is_empty() {
            vec![self.plant.ropes[0][i].tension_n]
        } else {
            r.spans.iter().map(|s| s[i].tension_n).collect()
        }
    }

    /// Smaller of the two rope tensions next to the output pulley [N].
    pub fn min_tension_n(&self) -> f64 {
        let [a, b] = self.ropes();
        a.tension_n.min(b.tension_n)
    }
}

impl RigModel {
    /// Compiles `spec` for steps of `dt_s`.
    pub fn new(spec: RigSpec, dt_s: f64) -> Result<Self, DriveError> {
        Self::with_effects(spec, &[], dt_s)
    }

    /// Compiles `spec` with registered effects at their sites ([`crate::effects`]): a
    /// rope-law or pair effect changes the rig's rope pair (and the returned
    /// [`Self::spec`] shows the law and relay friction it made), a joint effect acts at
    /// the output shaft.
    pub fn with_effects(
        mut spec: RigSpec,
        effects: &[Applied],
        dt_s: f64,
    ) -> Result<Self, DriveError> {
        let mut pair_spec = spec.pair_spec();
        let mut loads = Vec::new();
        for a in effects {
            a.apply_to_pair(&mut pair_spec)?;
            if let Some(force) = a.joint_force()? {
                loads.push(JointLoad {
                    joint: 0,
                    effect: a.effect.name(),
                    force,
                });
            }
        }
        spec.law = pair_spec.law.clone();
        spec.relay_friction = pair_spec.relay_friction;
        spec.validate()?;
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 0.05) {
            return Err(DriveError::BadParameter {
                field: "dt_s".into(),
                value: dt_s,
                reason: "must be in (0, 0.05] s; 1e-3 s resolves the rig's 2-4 Hz resonance well"
                    .into(),
            });
        }
        let pair = CompiledPair::new(pair_spec, 1, dt_s, "rig")?;
        let fast = pair.relays.is_none() && loads.is_empty();
        let drive = Drivetrain::new(vec![pair], loads, 1, dt_s, None)?;
        Ok(Self {
            shaft: OutputShaft {
                inertia_kg_m2: spec.output_inertia_kg_m2,
                damping_n_m_s: spec.output_damping_n_m_s,
            },
            drive,
            fast,
            spec,
        })
    }

    /// The rig's definition.
    pub fn spec(&self) -> &RigSpec {
        &self.spec
    }

    /// Step [s].
    pub fn dt_s(&self) -> f64 {
        self.drive.dt_s()
    }

    /// The rope pair, compiled (its rope stepper, relays).
    pub fn pair(&self) -> &CompiledPair {
        &self.drive.pairs[0]
    }

    /// Both angles zero, at rest under the mean tension (the format's initial state).
    pub fn rest_state(&self) -> RigState {
        let pair = &self.drive.pairs[0];
        let statics: Vec<StaticPair> = vec![pair.static_split(0.0)];
        RigState {
            plant: self.drive.rest_state(&[0.0], &statics, ()),
        }
    }

    /// Mechanical energy of `st` [J]: kinetic energy of the output and relay pulleys,
    /// elastic energy of every rope span, and, with a constant-force tensioner, the
    /// tensioner's potential `-2 T x`. With the input held still it can only fall (rope
    /// dashpots, damping and friction dissipate; the trapezoidal rule conserves the
    /// rest).
    pub fn energy_j(&self, st: &RigState) -> f64 {
        let w = st.output_rate_rad_s();
        let d = self.drive.energy(&st.plant);
        0.5 * self.spec.output_inertia_kg_m2 * w * w
            + d.ropes_j
            + d.relays_kinetic_j
            + d.tensioners_j
            + d.loads_j
    }

    /// Advances one step with the input angle `input_rad` at the end of the step.
    pub fn step(&self, st: &mut RigState, input_rad: f64) -> Result<(), DriveError> {
        if self.fast {
            return self.step_fast(st, input_rad);
        }
        let ps = &mut st.plant;
        let (ff, rate) = ([0.0], [0.0]);
        ps.motor_ref_rad[0] = input_rad;
        self.drive.step(
            &self.shaft,
            ps,
            MotorInputs {
                ref_rate_rad_s: &rate,
                feedforward_n_m: &ff,
            },
        )?;
        ps.q_ref_rad[0] = ps.q_rad[0];
        Ok(())
    }

    /// The step of an ideal rig with nothing at the output shaft: Newton on the output
    /// angle and the carriage, the ropes evaluated by the pair's own code
    /// ([`ideal::evaluate`]); exact on piecewise-affine ropes once no rope changes
    /// piece. (The `2 x 2` solve in `(phi, x)` is the pair block's Schur complement
    /// solved directly: the same Newton step, in the arithmetic the rig always had.)
    #[inline]
    fn step_fast(&self, st: &mut RigState, input_rad: f64) -> Result<(), DriveError> {
        let pair = &self.drive.pairs[0];
        let h = self.drive.dt_s();
        let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
        let (i_out, c_out) = (self.shaft.inertia_kg_m2, self.shaft.damping_n_m_s);
        // The trapezoidal rule's dynamic stiffness 4 I / h^2 + 2 C / h.
        let k_dyn = 4.0 * i_out / (h * h) + 2.0 * c_out / h;
        let r2 = pair.spec.joint_radius_m;
        let l = pair.spec.length_m;
        let two_t = 2.0 * pair.spec.preload_n;
        let constant_force = pair.spec.tensioner == Tensioner::ConstantForce;
        // Every rig has one joint and one pair: a state of another rig differs in its
        // relays or effect states only.
        let ps = &mut st.plant;
        let fits =
            ps.relays.first().is_some_and(|r| r.spans.is_empty()) && ps.effect_state.is_empty();
        // (The joint and motor references of the fast path stay at rest: nothing reads
        // them; the input angle is the motor's.)
        let PlantState {
            time_s,
            q_rad,
            qd_rad_s,
            qdd_rad_s2,
            motor_rad,
            carriage_m,
            ropes,
            ..
        } = ps;
        let (true, [q], [qd], [qdd], [motor], [carriage], [ropes]) = (
            fits,
            q_rad.as_mut_slice(),
            qd_rad_s.as_mut_slice(),
            qdd_rad_s2.as_mut_slice(),
            motor_rad.as_mut_slice(),
            carriage_m.as_mut_slice(),
            ropes.as_mut_slice(),
        ) else {
            return Err(self.drive.check_state(&st.plant).err().unwrap_or_else(|| {
                DriveError::BadParameter {
                    field: "state".into(),
                    value: f64::NAN,
                    reason: "not a state of this rig: start from its own rest_state()".into(),
                }
            }));
        };
        let prep = [
            pair.stepper.prepare(&ropes[0]),
            pair.stepper.prepare(&ropes[1]),
        ];
        let (phi0, w0, a0) = (*q, *qd, *qdd);
        let inertial = |phi: f64| {
            let w1 = two_h * (phi - phi0) - w0;
            let a1 = four_h2 * (phi - phi0) - two_h * 2.0 * w0 - a0;
            i_out * a1 + c_out * w1
        };
        let eval = |phi: f64, x: &mut f64| ideal::evaluate(pair, &prep, r2 * phi, input_rad, x);
        // Predictor, then Newton. On piecewise-affine laws one Newton step is exact when
        // no rope changes piece; the evaluation at the new point confirms it.
        let mut phi = phi0 + h * w0 + 0.5 * h * h * a0;
        let mut x = *carriage;
        let mut ev = eval(phi, &mut x);
        let mut converged = None;
        // (the last update as a multiple of the tolerance, when it started where both
        // ropes were on their smooth non-linear piece)
        let mut prev_scaled: Option<f64> = None;
        let smooth = |p: &[Piece; 2]| p.iter().all(|q| *q == Piece::Nonlinear);
        for _ in 0..40 {
            let Some(e0) = ev else {
                // Both ropes slack: the carriage took up the slack first.
                ev = eval(phi, &mut x);
                continue;
            };
            let [f1, f2] = e0.f;
            let [k1, k2] = e0.k;
            let res_m = inertial(phi) - r2 * (f1 - f2);
            let d11 = k_dyn + r2 * r2 * (k1 + k2);
            let (dphi, dx) = if constant_force {
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
            // Tolerances the nested rope solve of non-linear laws can meet: 1e-12 rad,
            // and a carriage strain of 1e-14 (tension error ~1e-9 N).
            let (tol_phi, tol_x) = (1e-12 * (1.0 + phi.abs()), 1e-14 * l);
            // Newton's error after an update `d` is about `K d^2`, `K` read off the
            // update before (`d / d_prev^2`), while both ropes stay on their smooth
            // non-linear piece. When that error is below a hundredth of the tolerance,
            // the point just reached is the solution, and its tensions are those of the
            // point before plus the stiffness times the update (their error, of the
            // update's square, is far below the tolerance's): neither the next update
            // nor the evaluation here is made. Two rope evaluations a step where there
            // were four, on a stiffening rope's sweep.
            // (read only there: a piecewise-affine rope's step pays nothing for it)
            prev_scaled = if smooth(&e0.pieces) {
                let scaled = (dphi.abs() / tol_phi).max(dx.abs() / tol_x);
                if prev_scaled.is_some_and(|d0| scaled * scaled * scaled <= 1e-2 * d0 * d0) {
                    let f = [f1 + k1 * (dx - r2 * dphi), f2 + k2 * (dx + r2 * dphi)];
                    if f[0] > 0.0 && f[1] > 0.0 {
                        converged = Some(ideal::IdealEval {
                            f,
                            e: [
                                self.strain(0, x, input_rad, phi),
                                self.strain(1, x, input_rad, phi),
                            ],
                            ..e0
                        });
                        break;
                    }
                }
                Some(scaled)
            } else {
                None
            };
            let next = eval(phi, &mut x);
            ev = next;
            let Some(e1) = next else { continue };
            let affine = |p: &[Piece; 2]| p.iter().all(|q| *q != Piece::Nonlinear);
            let same_piece = affine(&e0.pieces) && affine(&e1.pieces) && e1.pieces == e0.pieces;
            if same_piece || (dphi.abs() <= tol_phi && dx.abs() <= tol_x) {
                converged = Some(e1);
                break;
            }
        }
        match converged {
            Some(e) => {
                for i in 0..2 {
                    pair.stepper
                        .commit_with_tension(&prep[i], &mut ropes[i], e.e[i], e.f[i]);
                }
            }
            None => {
                (phi, x) = self.solve_bracketed(&prep, input_rad, (phi0, w0, a0))?;
                for (i, rope) in ropes.iter_mut().enumerate() {
                    let e = self.strain(i, x, input_rad, phi);
                    pair.stepper.commit(&prep[i], rope, e);
                }
            }
        }
        let w1 = two_h * (phi - phi0) - w0;
        let a1 = four_h2 * (phi - phi0) - two_h * 2.0 * w0 - a0;
        let finite = phi.is_finite()
            && w1.is_finite()
            && a1.is_finite()
            && x.is_finite()
            && ropes.iter().all(|r| r.tension_n.is_finite());
        *time_s += h;
        *q = phi;
        *qd = w1;
        *qdd = a1;
        *motor = input_rad;
        *carriage = x;
        if !finite || w1.abs() > 1e6 {
            return Err(self.blow_up(st, "tensions"));
        }
        Ok(())
    }

    #[cold]
    fn blow_up(&self, st: &RigState, tensions: &str) -> DriveError {
        DriveError::BlowUp {
            time_s: st.time_s(),
            what: format!(
                "output angle {} rad, rate {} rad/s, {tensions} {} / {} N",
                st.output_rad(),
                st.output_rate_rad_s(),
                st.tension_n(0),
                st.tension_n(1)
            ),
        }
    }

    /// Strain of rope `i` for carriage stretch `x`, input `theta`, output `phi`.
    fn strain(&self, i: usize, x: f64, theta: f64, phi: f64) -> f64 {
        let pair = &self.drive.pairs[0];
        let sign = if i == 0 { 1.0 } else { -1.0 };
        let u = pair.spec.motor_radius_m * theta - pair.spec.joint_radius_m * phi;
        (x + sign * u) * pair.inv_length
    }

    /// Carriage stretch at which the first rope becomes taut for the given angles.
    fn first_taut_stretch(&self, prep: &[PreparedStep; 2], theta: f64, phi: f64) -> f64 {
        let l = self.spec.rope_length_m;
        (0..2)
            .map(|i| prep[i].slack_strain() * l - self.strain(i, 0.0, theta, phi) * l)
            .fold(f64::INFINITY, f64::min)
    }

    /// Carriage stretch holding `f1 + f2 = 2T` at output angle `phi` (bisection on a
    /// monotone function, Newton-accelerated).
    fn carriage_for(&self, prep: &[PreparedStep; 2], theta: f64, phi: f64) -> f64 {
        let stepper = &self.drive.pairs[0].stepper;
        let target = 2.0 * self.spec.mean_tension_n;
        let sum = |x: f64| -> (f64, f64) {
            let (f1, k1) = stepper.tension(&prep[0], self.strain(0, x, theta, phi));
            let (f2, k2) = stepper.tension(&prep[1], self.strain(1, x, theta, phi));
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
        (phi0, w0, a0): (f64, f64, f64),
    ) -> Result<(f64, f64), DriveError> {
        let stepper = &self.drive.pairs[0].stepper;
        let h = self.drive.dt_s();
        let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
        let (i_out, c_out) = (self.shaft.inertia_kg_m2, self.shaft.damping_n_m_s);
        let k_dyn = four_h2 * i_out + two_h * c_out;
        let r2 = self.spec.output_radius_m;
        let constant_force = self.spec.tensioner == Tensioner::ConstantForce;
        let x_rest = self.drive.pairs[0].static_split(0.0).x_m;
        let resid = |phi: f64| -> (f64, f64) {
            let x = if constant_force {
                self.carriage_for(prep, theta, phi)
            } else {
                x_rest
            };
            let f1 = stepper.tension(&prep[0], self.strain(0, x, theta, phi)).0;
            let f2 = stepper.tension(&prep[1], self.strain(1, x, theta, phi)).0;
            let w1 = two_h * (phi - phi0) - w0;
            let a1 = four_h2 * (phi - phi0) - two_h * 2.0 * w0 - a0;
            (i_out * a1 + c_out * w1 - r2 * (f1 - f2), x)
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

impl RigSpec {
    /// The rig's rope pair for the transmission core: the input pulley as a kinematic
    /// motor of radius `r1`, the output pulley as the joint pulley `r2` of joint 0, the
    /// relay pulleys fixed to the base (equal spans; ideal, hence without effect,
    /// unless the pair has relay friction).
    pub fn pair_spec(&self) -> PairSpec {
        let relays = self.relay_pulleys as usize;
        PairSpec {
            joint: 0,
            rope_name: self.rope_name.clone(),
            rope: RopeParams {
                name: self.rope_name.clone(),
                fiber: String::new(),
                tensile_strength_n: f64::INFINITY,
                mass_per_length_kg_m: 0.0,
                k1_n: self.law.k1_n,
                k3_n: None,
                c2_n_s: None,
                c3_n_s: None,
                kp_n: None,
                k1_table4_n: None,
                relaxation_fit_rms_n: None,
            },
            law: self.law.clone(),
            ropes_in_parallel: 1,
            joint_radius_m: self.output_radius_m,
            motor_radius_m: self.input_radius_m,
            route: vec![
                Relay {
                    joint: None,
                    radius_m: self.relay_radius_m,
                    sign: 1.0,
                };
                relays
            ],
            length_m: self.rope_length_m,
            span_lengths_m: Vec::new(),
            preload_n: self.mean_tension_n,
            prestretch_n: self.prestretch_n,
            tensioner: self.tensioner,
            motor: MotorSpec::kinematic(),
            effects: Vec::new(),
            relay_friction: self.relay_friction,
        }
    }
}
