//! The implicit step of a plant driven by rope pairs: joints (whatever their dynamics,
//! through [`JointSide`]), rope pairs with their motors, tensioners and relay pulleys,
//! and passive torques of effects at the joints ([`JointLoad`]), integrated together.
//!
//! # Scheme
//!
//! The trapezoidal rule (Newmark average acceleration: unconditionally stable, second
//! order, no numerical damping) on the joints, motors and relay pulleys, the exact-hold
//! step on every rope (span), and Newton's method on the end-of-step state. The Newton
//! matrix is `4 M(q0)/h^2 + 2 D/h + R^T K R` with the pairs' tangent stiffness `K`, each
//! pair's local unknowns (motor, tensioner, relays) eliminated by its own Schur
//! complement ([`super::ideal`], [`super::relay`]), so the joint solve is one `n x n`
//! Cholesky (LU when relay friction makes it non-symmetric). The residual is evaluated
//! exactly at the trial state, so the converged step is the trapezoidal rule of the full
//! non-linear equations; freezing `M` in the matrix only costs an extra iteration.
//!
//! # Stages
//!
//! [`Drivetrain::step`] runs, in order: [`begin`](Drivetrain::begin) (prepare every
//! rope's step, predict the relays), [`predict`](Drivetrain::predict) (joints, motors,
//! tensioners), then Newton iterations of [`assemble`](Drivetrain::assemble) (joint
//! residual and matrix, every pair's block, the joint loads), the joint solve,
//! [`update_locals`](Drivetrain::update_locals) (motor, tensioner and relay updates with
//! their safeguards), the convergence test with the servos' active set, and finally
//! [`commit`](Drivetrain::commit).
//!
//! With relay friction, chord iterations (the Newton matrix kept, within a step and for
//! up to [`MAX_KEPT_STEPS`] steps) and relays solved alone keep the step cheap: see
//! docs/arm.md, "Speed".

use longreach_rope::PreparedStep;

use super::free::FreeFactor;
use super::ideal;
use super::load::JointLoad;
use super::pair::CompiledPair;
use super::relay::assembly::{self as relay, Assembly, Local, MotorRow, RelayScratch};
use super::relay::factor::{lu_in_place, lu_solve};
use super::relay::safeguards;
use super::relay::RelayState;
use super::servo::{servo_row, wanted_saturation, MotorStart};
use super::spec::Tensioner;
use super::state::{PlantState, Solver};
use crate::error::DriveError;

/// Default Newton tolerance of a plant without relay friction, rad.
pub const NEWTON_TOLERANCE: f64 = 1e-12;

/// Default Newton tolerance of a plant with relay friction, rad (2 nm of rope on a
/// 0.2 m pulley). On `arm_dyneema2_base_step_relay_friction.toml` (10 s) the joint
/// angles of a 1e-8, 1e-9 and 1e-10 solve stay within 2.2e-9, 1.1e-9 and 5.4e-11 rad of
/// a 1e-13 solve, for 1.45, 1.50 and 1.75 Newton iterations per step (2.55 at 1e-13;
/// `cargo run --release -p longreach-arm --example relay_tolerance`). Before the relays
/// were solved alone ([`safeguards::relax_relays`]), 1e-9 gave 3.2e-9 rad for 1.91
/// iterations and 1e-8 gave 2.3e-7 rad.
pub const RELAY_NEWTON_TOLERANCE: f64 = 1e-8;

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

/// Relays are solved alone ([`safeguards::relax_relays`]) after a Newton update of the
/// first this many iterations of a step...
const RELAX_ITERATIONS: u32 = 4;

/// ...whose local update (relays, motor) is this many times the joints' (in
/// tolerances, at least one).
const RELAX_RATIO: f64 = 10.0;

/// Newton iterations after which a step that has not converged is globalised: full
/// Newton without the relay safeguards, each update cut back (halved) until the sum of
/// the squared residuals falls (Armijo). The safeguards settle the stick-slip of the
/// shipped arm within a few iterations; a step whose spans keep going slack and taut
/// between iterates (a rope pair at low preload near resonance, relays of tiny inertia)
/// can cycle under them, which the line search ends.
const GLOBALISE_AFTER: u32 = 24;

/// Smallest step fraction of the line search: below it the update is taken as it is.
const MIN_STEP_FRACTION: f64 = 1.0 / 1024.0;

/// Steps a kept Newton matrix may start: then a fresh one (a matrix kept over many
/// steps lets errors far below the tolerance accumulate: 2e-11 rad over 0.6 s in the
/// zero-friction comparison of the arm's relay-friction tests without this limit, 4e-15
/// with).
pub const MAX_KEPT_STEPS: u32 = 3;

/// Steps a Newton matrix base with free coordinates ([`Drivetrain::with_free_coords`]:
/// the joint side's `4 M / h^2 + 2 D / h` with the bending modes' `K`, the factor of
/// their block and its Schur complement on the joints) serves before it is made
/// again at the step's predicted pose; the pairs' part is fresh at every iteration.
/// The iterations still converge on the exact residual, to the same tolerance (a
/// base a few steps old is one more approximation of the Jacobian, like freezing `M`
/// over the iterations). On `flex_dyneema2_base_step.toml` (10 s) a base of 1, 4 and
/// 8 steps took 2.10, 2.11 and 2.13 Newton iterations per step, and the joint angles
/// stayed within 2.3e-12, 2.5e-12 and 2.0e-11 rad of the step before the elimination;
/// 8 steps: CPU time per step 4.4-4.7 us against 5.0-5.2 us for 4 on the shared VM
/// (docs/arm.md, Speed).
pub const FREE_BASE_STEPS: u32 = 8;

/// The joints of a plant: their rigid dynamics without the ropes (the arm's links, the
/// rig's output pulley), and any coordinates of theirs no pair touches after them (the
/// bending modes of flexible links: [`Drivetrain::with_free_coords`]). The step calls [`Self::begin_iteration`] first in every Newton
/// iteration, then [`Self::matrix`] when it needs a fresh Newton matrix, then
/// [`Self::residual`].
pub trait JointSide {
    /// The joint side's own buffers (kept in the state, reused from step to step).
    type Scratch: Clone + std::fmt::Debug;

    /// Number of joints.
    fn ndofs(&self) -> usize;

    /// Kinematics at the trial joint angles `q1` (rad).
    fn begin_iteration(&self, sc: &mut Self::Scratch, q1: &[f64]);

    /// The base of the Newton matrix at the angles of the last
    /// [`Self::begin_iteration`]: `4 M / h^2 + 2 D / h` (`four_h2 = 4/h^2`, `two_h =
    /// 2/h`), row-major `n x n` into `out`.
    fn matrix(&self, sc: &mut Self::Scratch, four_h2: f64, two_h: f64, out: &mut [f64]);

    /// Minus the residual of the joint equations without the ropes and loads,
    /// `-(M a1 + C v1 + g + D v1)` (N*m), at the angles of the last
    /// [`Self::begin_iteration`] and the end rates `v1`, accelerations `a1`, into `out`.
    fn residual(&self, sc: &mut Self::Scratch, v1: &[f64], a1: &[f64], out: &mut [f64]);
}

/// The pairs and joint loads of a plant compiled for one time step, and the settings
/// of its implicit step (immutable; share it between runs).
#[derive(Debug, Clone)]
pub struct Drivetrain {
    /// The rope pairs.
    pub pairs: Vec<CompiledPair>,
    /// Passive torques of effects at the joints.
    pub loads: Vec<JointLoad>,
    dt_s: f64,
    ndofs: usize,
    /// Some pair has relay friction: the joint matrix is solved by LU.
    any_friction: bool,
    /// Every pair has relay friction: chord iterations.
    chord_capable: bool,
    newton_tolerance: f64,
    /// Coordinates at the end of the joint side's that no pair and no load touches
    /// ([`Self::with_free_coords`]).
    free: usize,
}

/// Motor feed-forward and reference rates of one step, per pair (the plant's
/// references stage computes them with the motor references).
#[derive(Debug, Clone, Copy)]
pub struct MotorInputs<'a> {
    /// Reference rate of each motor, rad/s.
    pub ref_rate_rad_s: &'a [f64],
    /// Feed-forward torque of each servo, N*m.
    pub feedforward_n_m: &'a [f64],
}

/// Energy of the drivetrain's own parts at a state, J.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DrivetrainEnergy {
    /// Motor rotors.
    pub motors_kinetic_j: f64,
    /// Rope springs (every rope in parallel counted).
    pub ropes_j: f64,
    /// Constant-force tensioners, `-2 n T x`.
    pub tensioners_j: f64,
    /// Relay pulleys (rotation relative to their mounts; every parallel rope's own).
    pub relays_kinetic_j: f64,
    /// Energy stored in effect states at the joints.
    pub loads_j: f64,
}

impl Drivetrain {
    /// The drivetrain of a plant of `ndofs` joints: its pairs (compiled for `dt_s`), the
    /// joint loads, and the Newton tolerance (`None`: [`NEWTON_TOLERANCE`], or
    /// [`RELAY_NEWTON_TOLERANCE`] with relay friction).
    pub fn new(
        pairs: Vec<CompiledPair>,
        loads: Vec<JointLoad>,
        ndofs: usize,
        dt_s: f64,
        newton_tolerance: Option<f64>,
    ) -> Result<Self, DriveError> {
        for l in &loads {
            if l.joint >= ndofs {
                return Err(DriveError::BadTransmission {
                    field: format!("effect {}", l.effect),
                    reason: format!("joint index {} out of range ({ndofs} joints)", l.joint),
                });
            }
        }
        let any_friction = pairs.iter().any(|p| p.relays.is_some());
        let chord_capable = any_friction && pairs.iter().all(|p| p.relays.is_some());
        let tol = newton_tolerance.unwrap_or(if any_friction {
            RELAY_NEWTON_TOLERANCE
        } else {
            NEWTON_TOLERANCE
        });
        if !(tol.is_finite() && tol > 0.0) {
            return Err(DriveError::BadParameter {
                field: "newton_tolerance".into(),
                value: tol,
                reason: "must be finite and > 0 (1e-12 rad, or 1e-8 with relay friction)".into(),
            });
        }
        Ok(Self {
            pairs,
            loads,
            dt_s,
            ndofs,
            any_friction,
            chord_capable,
            newton_tolerance: tol,
            free: 0,
        })
    }

    /// The same drivetrain on a joint side whose last `free` coordinates no pair and no
    /// joint load touches (the bending modes of flexible links): the step factors their
    /// block of the Newton matrix once per matrix base and solves the joints' Schur
    /// complement in each iteration (`free` module; the same update to round-off, at
    /// the cost of an `(n - free)`-square solve). The joint side's [`JointSide::matrix`]
    /// must then be positive definite on them; a base serves [`FREE_BASE_STEPS`] steps.
    /// Refused when a pair or a load touches one.
    pub fn with_free_coords(mut self, free: usize) -> Result<Self, DriveError> {
        let n = self.ndofs;
        let nj = n
            .checked_sub(free)
            .ok_or_else(|| DriveError::BadParameter {
                field: "free coordinates".into(),
                value: free as f64,
                reason: format!("more than the {n} coordinates"),
            })?;
        let touched = self
            .pairs
            .iter()
            .flat_map(|p| p.nz.iter().copied())
            .chain(self.loads.iter().map(|l| l.joint))
            .find(|&k| k >= nj);
        if let Some(k) = touched {
            return Err(DriveError::BadTransmission {
                field: "free coordinates".into(),
                reason: format!(
                    "coordinate {k} is driven by a pair or a load: only the last \
                     coordinates no rope or effect acts on can be free"
                ),
            });
        }
        self.free = free;
        Ok(self)
    }

    /// Coordinates no pair and no load touches (see [`Self::with_free_coords`]).
    pub fn free_coords(&self) -> usize {
        self.free
    }

    /// Step, s.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Relative tolerance on the Newton updates of the step (angles, rad): the step
    /// ends when every update is below `tol (1 + |angle|)` (or, for chord iterations,
    /// when the error left is estimated below a hundredth of it).
    pub fn newton_tolerance(&self) -> f64 {
        self.newton_tolerance
    }

    /// True when some pair has relay friction.
    pub fn any_friction(&self) -> bool {
        self.any_friction
    }

    /// A state with every joint at `q_rad`, at rest, each pair at rest in `statics`
    /// (the pair forces that hold the joints), and the joint side's scratch `joint`.
    pub fn rest_state<S>(
        &self,
        q_rad: &[f64],
        statics: &[super::pair::StaticPair],
        joint: S,
    ) -> PlantState<S> {
        let n = self.ndofs;
        let np = self.pairs.len();
        let mut st = PlantState {
            time_s: 0.0,
            q_rad: q_rad.to_vec(),
            qd_rad_s: vec![0.0; n],
            qdd_rad_s2: vec![0.0; n],
            q_ref_rad: q_rad.to_vec(),
            motor_rad: vec![0.0; np],
            motor_rate_rad_s: vec![0.0; np],
            motor_accel_rad_s2: vec![0.0; np],
            motor_ref_rad: vec![0.0; np],
            motor_torque_n_m: vec![0.0; np],
            servo_saturation: vec![0; np],
            carriage_m: vec![0.0; np],
            ropes: vec![[longreach_rope::RopeState::default(); 2]; np],
            relays: vec![RelayState::default(); np],
            effect_state: self
                .loads
                .iter()
                .flat_map(|l| l.force.initial_state())
                .collect(),
            iterations: 0,
            solver: self.make_solver(),
            joint_scratch: joint,
        };
        for (p, s) in statics.iter().enumerate() {
            let rest = self.pairs[p].at_rest(s, q_rad);
            st.motor_rad[p] = rest.motor_rad;
            st.motor_ref_rad[p] = rest.motor_rad;
            st.carriage_m[p] = rest.carriage_m;
            st.ropes[p] = rest.ropes;
            st.relays[p] = rest.relays;
            st.motor_torque_n_m[p] = rest.motor_torque_n_m;
        }
        st
    }

    fn make_solver(&self) -> Solver {
        let n = self.ndofs;
        let np = self.pairs.len();
        let prep0 = self.pairs.first().map(|p| {
            let s = p.stepper.rest_state(0.0, 0.0);
            p.stepper.prepare(&s)
        });
        Solver {
            mbase: vec![0.0; n * n],
            kq: vec![0.0; n * n],
            rhs: vec![0.0; n],
            q1: vec![0.0; n],
            v1: vec![0.0; n],
            a1: vec![0.0; n],
            local: vec![[0.0; 8]; np],
            raw: vec![0.0; np],
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
            q1_back: vec![0.0; n],
            th1_back: vec![0.0; np],
            x1_back: vec![0.0; np],
            dq: vec![0.0; n],
            dth: vec![0.0; np],
            dx: vec![0.0; np],
            free: (self.free > 0).then(|| FreeFactor::new(n - self.free, self.free)),
            kept: false,
            age: 0,
            chord_rate: f64::INFINITY,
            chord_rate_age: 0,
        }
    }

    /// Energy of the motors, ropes, tensioners, relays and joint-load states at `st`.
    pub fn energy<S>(&self, st: &PlantState<S>) -> DrivetrainEnergy {
        let mut e = DrivetrainEnergy::default();
        for (p, pair) in self.pairs.iter().enumerate() {
            let w = st.motor_rate_rad_s[p];
            e.motors_kinetic_j += 0.5 * pair.spec.motor.inertia_kg_m2 * w * w;
            e.ropes_j += pair.rope_energy_j(&st.ropes[p], &st.relays[p]);
            e.relays_kinetic_j += pair.relay_energy_j(&st.relays[p]);
            e.tensioners_j += pair.tensioner_energy_j(st.carriage_m[p]);
        }
        let mut off = 0;
        for l in &self.loads {
            let k = l.force.state_len();
            e.loads_j += l
                .force
                .energy_j(st.q_rad[l.joint], &st.effect_state[off..off + k]);
            off += k;
        }
        e
    }

    /// Advances `st` by one step of `dt_s`. The plant has set, for the end of the
    /// step, the motor references (`st.motor_ref_rad`, and `motors` with their rates
    /// and feed-forward) and its joint references.
    pub fn step<J: JointSide>(
        &self,
        joints: &J,
        st: &mut PlantState<J::Scratch>,
        motors: MotorInputs<'_>,
    ) -> Result<(), DriveError> {
        // Two instances: a plant without free coordinates runs none of their code.
        if self.free > 0 {
            self.step_with::<J, true>(joints, st, motors)
        } else {
            self.step_with::<J, false>(joints, st, motors)
        }
    }

    /// [`Self::step`], `FREE`: with free coordinates ([`Self::with_free_coords`]).
    #[inline(never)]
    fn step_with<J: JointSide, const FREE: bool>(
        &self,
        joints: &J,
        st: &mut PlantState<J::Scratch>,
        motors: MotorInputs<'_>,
    ) -> Result<(), DriveError> {
        let n = self.ndofs;
        let h = self.dt_s;
        let t1 = st.time_s + h;
        let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
        self.check_state(st)?;
        self.begin(st);
        self.predict(st);
        let tol = self.newton_tolerance;
        let mut converged = false;
        let mut iterations = 0;
        let mut flips = 0;
        // Relay friction (stick-slip, spans going slack) may need the damped iterations
        // of `safeguards::apply_relay_update`.
        let max_iterations = if self.any_friction { 120 } else { 60 };
        // Chord iterations (Newton matrix kept from the last assembly) need every pair
        // to go through `relay::assemble`.
        let mut chord_allowed = self.chord_capable;
        // The step starts from the last step's Newton matrix when it was kept.
        let mut refresh = !(chord_allowed && st.solver.kept && st.solver.age < MAX_KEPT_STEPS);
        // With free coordinates, the base and its factor may serve a few steps.
        let mut mbase_done = FREE
            && st
                .solver
                .free
                .as_ref()
                .is_some_and(|f| f.ok && f.age < FREE_BASE_STEPS);
        let mut last_update = f64::INFINITY;
        // The globalised iterations' line search: the merit before the last full update
        // and the fraction of it taken.
        let mut globalised = false;
        let mut line: Option<(f64, f64)> = None;
        for _ in 0..max_iterations {
            iterations += 1;
            if iterations > GLOBALISE_AFTER && !globalised {
                globalised = true;
                chord_allowed = false;
                refresh = true;
            }
            let assembled = self.assemble::<J, FREE>(
                joints,
                st,
                motors,
                Refresh {
                    refresh,
                    mbase_done: &mut mbase_done,
                },
            );
            if globalised && matches!(assembled, Assembled::Done) {
                let merit = self.merit(st);
                if let Some((merit0, fraction)) = line {
                    if merit > (1.0 - 1e-4 * fraction) * merit0 && fraction > MIN_STEP_FRACTION {
                        // Not enough descent: back to the point before the update, half
                        // as far along it.
                        line = Some((merit0, 0.5 * fraction));
                        self.retract(st, 0.5 * fraction);
                        continue;
                    }
                }
                line = Some((merit, 1.0));
            }
            let (retry, singular) = match assembled {
                Assembled::Done => (false, false),
                Assembled::Retry => (true, false),
                Assembled::Singular => (false, true),
            };
            if retry {
                refresh = true;
                continue;
            }
            let sv = &mut st.solver;
            // With free coordinates, the joints' Schur complement (`free` module).
            let nj = if FREE { n - self.free } else { n };
            let factored = if !refresh {
                true
            } else if FREE && sv.free.as_ref().is_some_and(|f| !f.ok) {
                false
            } else if self.any_friction {
                !singular && lu_in_place(&mut sv.kq, nj, &mut sv.perm)
            } else {
                cholesky_in_place(&mut sv.kq, nj)
            };
            if !factored {
                sv.kept = false;
                // (a matrix of NaNs is not singular: the iteration diverged before it)
                let diverged = sv.q1.iter().chain(&sv.rhs).any(|x| !x.is_finite());
                return Err(DriveError::BlowUp {
                    time_s: t1,
                    what: if diverged {
                        "the Newton iteration of the step diverged (its iterate is not a number)"
                            .into()
                    } else if self.any_friction {
                        "the Newton matrix of the step (with relay friction) is singular".into()
                    } else {
                        "the Newton matrix of the step is not positive definite".into()
                    },
                });
            }
            if FREE {
                if let Some(ff) = sv.free.as_mut() {
                    ff.reduce(&mut sv.rhs);
                }
            }
            if self.any_friction {
                lu_solve(&sv.kq, nj, &sv.perm, &mut sv.rhs);
            } else {
                cholesky_solve(&sv.kq, nj, &mut sv.rhs);
            }
            if FREE {
                if let Some(ff) = &sv.free {
                    ff.expand(&mut sv.rhs);
                }
            }
            let mut small = true;
            // Largest joint update relative to the tolerance (chord control).
            let mut update = 0.0f64;
            if globalised {
                sv.q1_back.copy_from_slice(&sv.q1);
                sv.dq.copy_from_slice(&sv.rhs);
            }
            for j in 0..n {
                let d = sv.rhs[j];
                sv.q1[j] += d;
                if d.abs() > tol * (1.0 + sv.q1[j].abs()) {
                    small = false;
                }
                update = update.max(d.abs() / (tol * (1.0 + sv.q1[j].abs())));
            }
            let joint_update = update;
            let locals = if globalised {
                self.update_locals_plain(st)
            } else {
                self.update_locals(st, iterations, joint_update)
            };
            small &= locals.small;
            update = update.max(locals.update);
            let sv = &mut st.solver;
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
                    sv.chord_rate = update / last_update;
                    sv.chord_rate_age = sv.age;
                    sv.chord_rate
                } else {
                    sv.chord_rate * f64::from(sv.age.max(1)) / f64::from(sv.chord_rate_age.max(1))
                };
                // Above the tolerance only on a rate measured in this step (a rate
                // kept from an earlier step may have been measured on round-off).
                small = (small || (measured && update <= CHORD_ACCEPT_UPDATE))
                    && rate < 0.5
                    && update * rate <= CHORD_ERROR;
            }
            // A relay moved by a safeguard, or solved alone, has not met the coupled
            // equations yet.
            small &= !locals.guarded && !locals.relaxed;
            if locals.relaxed {
                // The relays now meet their own equations at the joints' update: what is
                // left to measure is the joints'.
                update = joint_update;
            }
            if small && flips < 4 {
                // The servos' active set: a servo whose unclamped torque crossed its
                // limit (or came back) changes its row.
                for (p, pair) in self.pairs.iter().enumerate() {
                    if let Some(want) = wanted_saturation(&pair.spec.motor, sv.raw[p]) {
                        if want != st.servo_saturation[p] {
                            st.servo_saturation[p] = want;
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
            let contracted = !locals.relaxed && update < CHORD_CONTRACTION * last_update;
            if !was_refresh && !contracted {
                // A chord update that did not shrink: full Newton for the rest of the step.
                chord_allowed = false;
            }
            refresh = !(chord_allowed && update < CHORD_BELOW && (was_refresh || contracted));
            last_update = update;
        }
        if !converged {
            st.solver.kept = false;
            return Err(DriveError::BlowUp {
                time_s: t1,
                what: format!(
                    "the implicit step did not converge in {iterations} Newton iterations"
                ),
            });
        }
        self.commit::<_, FREE>(st, two_h, four_h2);
        st.iterations = iterations;
        let finite = st.q_rad.iter().chain(&st.qd_rad_s).all(|v| v.is_finite())
            && st.motor_rad.iter().all(|v| v.is_finite())
            && st.ropes.iter().flatten().all(|r| r.tension_n.is_finite())
            && st
                .relays
                .iter()
                .all(|r| r.spans.iter().flatten().all(|s| s.tension_n.is_finite()));
        if !finite || st.qd_rad_s.iter().any(|v| v.abs() > 1e4) {
            st.solver.kept = false;
            return Err(DriveError::BlowUp {
                time_s: t1,
                what: format!(
                    "joint angles {:?} rad, rates {:?} rad/s",
                    st.q_rad, st.qd_rad_s
                ),
            });
        }
        Ok(())
    }

    /// Refuses a state made for another plant (other joints, pairs, relays or effect
    /// states), which would otherwise be misread.
    pub fn check_state<S>(&self, st: &PlantState<S>) -> Result<(), DriveError> {
        let np = self.pairs.len();
        let shapes = st.q_rad.len() == self.ndofs
            && st.qd_rad_s.len() == self.ndofs
            && st.qdd_rad_s2.len() == self.ndofs
            && st.motor_rad.len() == np
            && st.ropes.len() == np
            && st.relays.len() == np
            && st.solver.relay.len() == np
            && st.effect_state.len()
                == self
                    .loads
                    .iter()
                    .map(|l| l.force.state_len())
                    .sum::<usize>()
            && self
                .pairs
                .iter()
                .zip(&st.relays)
                .all(|(p, r)| match &p.relays {
                    None => r.spans.is_empty(),
                    Some(c) => {
                        r.spans.len() == c.spans()
                            && r.angle_rad.len() == c.relays()
                            && r.rate_rad_s.len() == c.relays()
                            && r.accel_rad_s2.len() == c.relays()
                    }
                });
        if shapes {
            Ok(())
        } else {
            Err(DriveError::BadParameter {
                field: "state".into(),
                value: f64::NAN,
                reason: format!(
                    "this state was made for another plant (this one has {} joint(s), {np} \
                     pair(s), {} with relay friction): start from this plant's own \
                     rest_state() (rig) or initial_state() (arm)",
                    self.ndofs,
                    self.pairs.iter().filter(|p| p.relays.is_some()).count()
                ),
            })
        }
    }

    /// Stage 1: every rope's (span's) step prepared from the state, the relays
    /// predicted.
    #[inline(always)]
    fn begin<S>(&self, st: &mut PlantState<S>) {
        let h = self.dt_s;
        let sv = &mut st.solver;
        for (p, pair) in self.pairs.iter().enumerate() {
            sv.prep[p] = [
                pair.stepper.prepare(&st.ropes[p][0]),
                pair.stepper.prepare(&st.ropes[p][1]),
            ];
            if let (Some(c), Some(rs)) = (&pair.relays, sv.relay[p].as_mut()) {
                relay::begin_step(c, &pair.stepper, rs, h, &st.relays[p]);
            }
        }
    }

    /// Stage 2: the predictor. Joints and servos by the trapezoidal rule's
    /// constant-acceleration extrapolation, kinematic motors at their references,
    /// tensioners where they were.
    #[inline(always)]
    fn predict<S>(&self, st: &mut PlantState<S>) {
        let h = self.dt_s;
        let sv = &mut st.solver;
        for j in 0..self.ndofs {
            sv.q1[j] = st.q_rad[j] + h * st.qd_rad_s[j] + 0.5 * h * h * st.qdd_rad_s2[j];
        }
        for (p, pair) in self.pairs.iter().enumerate() {
            sv.th1[p] = if pair.spec.motor.is_servo() {
                st.motor_rad[p]
                    + h * st.motor_rate_rad_s[p]
                    + 0.5 * h * h * st.motor_accel_rad_s2[p]
            } else {
                st.motor_ref_rad[p]
            };
        }
        sv.x1.copy_from_slice(&st.carriage_m);
    }

    /// Stage 3 (every Newton iteration): the joint residual (and, on `refresh`, the
    /// matrix), every pair's block (Schur complement of its local unknowns) and the
    /// joint loads, into the solver's right side and matrix.
    #[inline(always)]
    fn assemble<J: JointSide, const FREE: bool>(
        &self,
        joints: &J,
        st: &mut PlantState<J::Scratch>,
        motors: MotorInputs<'_>,
        fresh: Refresh<'_>,
    ) -> Assembled {
        let n = self.ndofs;
        let h = self.dt_s;
        let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
        let refresh = fresh.refresh;
        let PlantState {
            q_rad,
            qd_rad_s,
            qdd_rad_s2,
            solver: sv,
            joint_scratch,
            ..
        } = st;
        for j in 0..n {
            let dq = sv.q1[j] - q_rad[j];
            sv.v1[j] = two_h * dq - qd_rad_s[j];
            sv.a1[j] = four_h2 * dq - 2.0 * two_h * qd_rad_s[j] - qdd_rad_s2[j];
        }
        joints.begin_iteration(joint_scratch, &sv.q1);
        if refresh && !*fresh.mbase_done {
            // Newton matrix base, M at the pose of the step's first assembly (the
            // predicted pose unless the last step's matrix served first).
            *fresh.mbase_done = true;
            joints.matrix(joint_scratch, four_h2, two_h, &mut sv.mbase);
            if FREE {
                if let Some(ff) = sv.free.as_mut() {
                    // The free coordinates' block is factored once per base.
                    ff.ok = ff.factor(&sv.mbase);
                }
            }
        }
        joints.residual(joint_scratch, &sv.v1, &sv.a1, &mut sv.rhs);
        // The joints' part of the Newton matrix: all of it, or the Schur complement of
        // the free coordinates (row-major `nj x nj`).
        let nj = if FREE { n - self.free } else { n };
        if refresh {
            sv.age = 0;
            match &sv.free {
                Some(ff) if FREE => sv.kq[..nj * nj].copy_from_slice(&ff.schur),
                _ => sv.kq.copy_from_slice(&sv.mbase),
            }
        }
        let mut off = 0;
        for l in &self.loads {
            let k = l.force.state_len();
            let j = l.joint;
            let t = l
                .force
                .torque(sv.q1[j], sv.v1[j], &st.effect_state[off..off + k]);
            off += k;
            sv.rhs[j] += t.torque_n_m;
            if refresh {
                sv.kq[j * nj + j] -= t.d_angle_n_m + two_h * t.d_rate_n_m_s;
            }
        }
        let mut retry = false;
        let mut singular = false;
        for (p, pair) in self.pairs.iter().enumerate() {
            let start = MotorStart {
                angle_rad: st.motor_rad[p],
                rate_rad_s: st.motor_rate_rad_s[p],
                accel_rad_s2: st.motor_accel_rad_s2[p],
                ref_rad: st.motor_ref_rad[p],
            };
            let servo = servo_row(
                &pair.spec.motor,
                h,
                start,
                sv.th1[p],
                motors.ref_rate_rad_s[p],
                motors.feedforward_n_m[p],
                st.servo_saturation[p],
            );
            if let Some(row) = servo {
                sv.raw[p] = row.raw_n_m;
                sv.torque[p] = row.torque_n_m;
            }
            if let Some(c) = &pair.relays {
                let motor = match servo {
                    None => MotorRow::Fixed,
                    Some(row) => MotorRow::Servo {
                        residual_n_m: row.residual_n_m,
                        diag: row.diag,
                    },
                };
                let s = &pair.spec;
                let inp = Local {
                    h,
                    n: pair.n,
                    motor_radius_m: s.motor_radius_m,
                    motor,
                    constant_force_n: (s.tensioner == Tensioner::ConstantForce)
                        .then_some(s.preload_n),
                    theta_rad: sv.th1[p],
                    q: &sv.q1,
                    state: &st.relays[p],
                };
                let done = match sv.relay[p].as_mut() {
                    Some(rs) if !refresh => relay::assemble_residual(
                        c,
                        &pair.stepper,
                        rs,
                        &inp,
                        &mut sv.x1[p],
                        &mut sv.rhs,
                    ),
                    Some(rs) => relay::assemble(
                        c,
                        &pair.stepper,
                        rs,
                        &inp,
                        &mut sv.x1[p],
                        &mut sv.kq,
                        &mut sv.rhs,
                        nj,
                    ),
                    None => Assembly::Singular,
                };
                match done {
                    Assembly::Done => {}
                    Assembly::Retry => retry = true,
                    Assembly::Singular => singular = true,
                }
                continue;
            }
            if !ideal::block(
                pair,
                &sv.prep[p],
                &sv.q1,
                sv.th1[p],
                &mut sv.x1[p],
                servo,
                &mut sv.rhs,
                &mut sv.kq,
                nj,
                &mut sv.local[p],
                !self.any_friction,
            ) {
                retry = true;
            }
        }
        if retry {
            Assembled::Retry
        } else if singular {
            Assembled::Singular
        } else {
            Assembled::Done
        }
    }

    /// Stage 4 (after the joint solve): every pair's local update (motor, tensioner,
    /// relays) from the joint update in the solver's right side, with the relay
    /// safeguards.
    #[inline(always)]
    fn update_locals<S>(
        &self,
        st: &mut PlantState<S>,
        iterations: u32,
        joint_update: f64,
    ) -> Locals {
        let h = self.dt_s;
        let tol = self.newton_tolerance;
        let sv = &mut st.solver;
        let mut out = Locals {
            small: true,
            update: 0.0,
            guarded: false,
            relaxed: false,
        };
        for (p, pair) in self.pairs.iter().enumerate() {
            if let (Some(c), Some(rs)) = (&pair.relays, sv.relay[p].as_mut()) {
                relay::local_update(c, rs, &sv.rhs);
                if pair.spec.motor.is_servo() {
                    let d = rs.dz[c.iz_theta()];
                    sv.th1[p] += d;
                    if d.abs() > tol * (1.0 + sv.th1[p].abs()) {
                        out.small = false;
                    }
                }
                if pair.spec.tensioner == Tensioner::ConstantForce {
                    let d = rs.dz[c.iz_x()];
                    sv.x1[p] += d;
                    if d.abs() > pair.carriage_tolerance_m(tol) {
                        out.small = false;
                    }
                }
                let local_update = relay::largest_update(c, rs, tol);
                out.update = out.update.max(local_update);
                let done = safeguards::apply_relay_update(c, rs, &st.relays[p], h, iterations, tol);
                out.small &= done.small;
                out.guarded |= done.guarded;
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
                        theta_rad: sv.th1[p],
                        q: &sv.q1,
                        state: &st.relays[p],
                    };
                    if relax {
                        out.relaxed = true;
                        safeguards::relax_relays(c, &pair.stepper, rs, &inp, sv.x1[p], tol);
                    } else {
                        safeguards::solve_crossed_relays(c, &pair.stepper, rs, &inp, sv.x1[p], tol);
                    }
                }
                continue;
            }
            let (d0, d1) = ideal::local_update(pair, &sv.local[p], &sv.rhs);
            if pair.spec.motor.is_servo() {
                sv.th1[p] += d0;
                if d0.abs() > 1e-12 * (1.0 + sv.th1[p].abs()) {
                    out.small = false;
                }
            }
            if pair.spec.tensioner == Tensioner::ConstantForce {
                sv.x1[p] += d1;
                if d1.abs() > 1e-15 * (1.0 + pair.spec.length_m) {
                    out.small = false;
                }
            }
        }
        out
    }

    /// The sum of the squared residuals at the last assembly (joints, every pair's local
    /// equations): the merit of the globalised iterations. Mixed units (N*m, N), as
    /// the equations are written; the line search only compares it with itself.
    fn merit<S>(&self, st: &PlantState<S>) -> f64 {
        let sv = &st.solver;
        let mut m: f64 = sv.rhs.iter().map(|r| r * r).sum();
        for (p, pair) in self.pairs.iter().enumerate() {
            match (&pair.relays, &sv.relay[p]) {
                (Some(_), Some(rs)) => m += rs.merit,
                _ => {
                    let [.., r0, r1] = sv.local[p];
                    m += r0 * r0 + r1 * r1;
                }
            }
        }
        m
    }

    /// Puts the trial state back at the point before the last full update and moves it
    /// `fraction` of the way along that update.
    fn retract<S>(&self, st: &mut PlantState<S>, fraction: f64) {
        let sv = &mut st.solver;
        for j in 0..self.ndofs {
            sv.q1[j] = sv.q1_back[j] + fraction * sv.dq[j];
        }
        for p in 0..self.pairs.len() {
            sv.th1[p] = sv.th1_back[p] + fraction * sv.dth[p];
            sv.x1[p] = sv.x1_back[p] + fraction * sv.dx[p];
            if let Some(rs) = sv.relay[p].as_mut() {
                for (k, psi) in rs.psi1.iter_mut().enumerate() {
                    *psi = rs.psi_back[k] + fraction * rs.dpsi[k];
                }
            }
        }
    }

    /// Stage 4 of a globalised iteration: every pair's full local update, without the
    /// relay safeguards, the point before it and the update kept for the line search.
    fn update_locals_plain<S>(&self, st: &mut PlantState<S>) -> Locals {
        let tol = self.newton_tolerance;
        let sv = &mut st.solver;
        sv.th1_back.copy_from_slice(&sv.th1);
        sv.x1_back.copy_from_slice(&sv.x1);
        let mut out = Locals {
            small: true,
            update: 0.0,
            guarded: false,
            relaxed: false,
        };
        for (p, pair) in self.pairs.iter().enumerate() {
            let (d0, d1) = match (&pair.relays, sv.relay[p].as_mut()) {
                (Some(c), Some(rs)) => {
                    relay::local_update(c, rs, &sv.rhs);
                    out.update = out.update.max(relay::largest_update(c, rs, tol));
                    let m = c.relays();
                    rs.psi_back.copy_from_slice(&rs.psi1);
                    for side in 0..2 {
                        for rl in 0..m {
                            let k = side * m + rl;
                            let d = rs.dz[c.iz_psi(side, rl)];
                            rs.dpsi[k] = d;
                            rs.psi1[k] += d;
                            if d.abs() > tol * (1.0 + rs.psi1[k].abs()) {
                                out.small = false;
                            }
                        }
                    }
                    (rs.dz[c.iz_theta()], rs.dz[c.iz_x()])
                }
                _ => ideal::local_update(pair, &sv.local[p], &sv.rhs),
            };
            let (d0, d1) = (
                if pair.spec.motor.is_servo() { d0 } else { 0.0 },
                if pair.spec.tensioner == Tensioner::ConstantForce {
                    d1
                } else {
                    0.0
                },
            );
            sv.dth[p] = d0;
            sv.dx[p] = d1;
            sv.th1[p] += d0;
            sv.x1[p] += d1;
            if d0.abs() > tol * (1.0 + sv.th1[p].abs()) || d1.abs() > pair.carriage_tolerance_m(tol)
            {
                out.small = false;
            }
        }
        out
    }

    /// Last stage: every rope (span) committed at the converged state, the relays,
    /// motors and joints advanced by the trapezoidal rule, the joint loads' states
    /// advanced, the time moved on.
    #[inline(always)]
    fn commit<S, const FREE: bool>(&self, st: &mut PlantState<S>, two_h: f64, four_h2: f64) {
        let h = self.dt_s;
        let n = self.ndofs;
        let sv = &mut st.solver;
        for (p, pair) in self.pairs.iter().enumerate() {
            let rq: f64 = pair.nz.iter().map(|&k| pair.row[k] * sv.q1[k]).sum();
            let u = pair.spec.motor_radius_m * sv.th1[p] - rq;
            let x = sv.x1[p];
            if let (Some(c), Some(rs)) = (&pair.relays, sv.relay[p].as_mut()) {
                relay::commit(
                    c,
                    &pair.stepper,
                    rs,
                    h,
                    pair.spec.motor_radius_m,
                    sv.th1[p],
                    x,
                    &sv.q1,
                    &mut st.relays[p],
                );
                st.ropes[p] = st.relays[p].spans[0];
            } else {
                commit_ideal(pair, &sv.prep[p], &mut st.ropes[p], x, u);
            }
            let dth = sv.th1[p] - st.motor_rad[p];
            let w1 = two_h * dth - st.motor_rate_rad_s[p];
            let a1 =
                four_h2 * dth - 2.0 * two_h * st.motor_rate_rad_s[p] - st.motor_accel_rad_s2[p];
            st.motor_rad[p] = sv.th1[p];
            st.motor_rate_rad_s[p] = w1;
            st.motor_accel_rad_s2[p] = a1;
            st.carriage_m[p] = x;
            st.motor_torque_n_m[p] = sv.torque[p];
        }
        let mut off = 0;
        for l in &self.loads {
            let k = l.force.state_len();
            let j = l.joint;
            let v1 = two_h * (sv.q1[j] - st.q_rad[j]) - st.qd_rad_s[j];
            l.force.advance(
                (st.q_rad[j], st.qd_rad_s[j]),
                (sv.q1[j], v1),
                h,
                &mut st.effect_state[off..off + k],
            );
            off += k;
        }
        for j in 0..n {
            let dq = sv.q1[j] - st.q_rad[j];
            let v1 = two_h * dq - st.qd_rad_s[j];
            let a1 = four_h2 * dq - 2.0 * two_h * st.qd_rad_s[j] - st.qdd_rad_s2[j];
            st.q_rad[j] = sv.q1[j];
            st.qd_rad_s[j] = v1;
            st.qdd_rad_s2[j] = a1;
        }
        st.time_s += h;
        sv.kept = self.chord_capable;
        sv.age += 1;
        if let Some(ff) = sv.free.as_mut().filter(|_| FREE) {
            ff.age += 1;
        }
    }
}

/// Commits both ropes of an ideal pair at tensioner stretch `x` and differential
/// stretch `u` (m).
#[inline(always)]
pub(crate) fn commit_ideal(
    pair: &CompiledPair,
    prep: &[PreparedStep; 2],
    ropes: &mut [longreach_rope::RopeState; 2],
    x: f64,
    u: f64,
) {
    for (side, sign) in [(0usize, 1.0), (1usize, -1.0)] {
        let e = (x + sign * u) * pair.inv_length;
        let (f, _, _) = pair.stepper.tension_piece(&prep[side], e);
        pair.stepper
            .commit_with_tension(&prep[side], &mut ropes[side], e, f);
    }
}

/// Whether an iteration assembles a fresh Newton matrix (and whether the step's matrix
/// base is already made).
struct Refresh<'a> {
    refresh: bool,
    mbase_done: &'a mut bool,
}

/// What [`Drivetrain::assemble`] found.
enum Assembled {
    Done,
    /// A carriage took up slack: redo the iteration.
    Retry,
    /// A pair's local block is singular.
    Singular,
}

/// What [`Drivetrain::update_locals`] found.
struct Locals {
    /// Every local change within the tolerance.
    small: bool,
    /// Largest local update (relays, motor) in tolerances.
    update: f64,
    /// A safeguard changed a relay update: no error estimate from the update.
    guarded: bool,
    /// The relays of a pair were solved alone after this update.
    relaxed: bool,
}

/// In-place Cholesky factorisation of the SPD row-major `n x n` matrix `a` (lower
/// triangle); false when not positive definite.
#[inline(always)]
pub(crate) fn cholesky_in_place(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d <= 0.0 || !d.is_finite() {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / d;
        }
    }
    true
}

/// Solves `L L^T x = b` in place with the factor of [`cholesky_in_place`].
#[inline(always)]
pub(crate) fn cholesky_solve(l: &[f64], n: usize, b: &mut [f64]) {
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= l[k * n + i] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
}
