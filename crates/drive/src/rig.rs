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
//! own tension is free; a fixed tensioner keeps `x` at its initial value. Relay pulleys
//! are ideal (recorded, no effect), as in the paper's model.
//!
//! # Integration
//!
//! The output pulley is integrated with the trapezoidal rule (Newmark average
//! acceleration: unconditionally stable, second order, no numerical damping); each
//! rope with its exact-hold step ([`longreach_rope::RopeStepper`]). The end-of-step
//! angle and carriage position solve the implicit equations by Newton's method on
//! the piecewise-smooth rope tensions, with a bracketed fallback.

use longreach_rope::{Piece, PreparedStep, RopeLaw, RopeState, RopeStepper};
use serde::{Deserialize, Serialize};

use crate::error::{non_negative, positive, DriveError};

/// How the ropes are pre-tensioned.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Tensioner {
    /// A carriage pulled with a constant force holds `f1 + f2 = 2 * mean_tension_n`.
    ConstantForce,
    /// Rope ends fixed after pre-tensioning to `mean_tension_n` at rest.
    Fixed,
}

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
    /// Idler pulleys each rope runs over (ideal: no effect).
    pub relay_pulleys: u32,
    /// Their radius [m].
    pub relay_radius_m: f64,
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
}

/// Mutable state of a rig.
#[derive(Debug, Clone, Copy, PartialEq)]
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
    /// Rope 1 (stretched by positive input) and rope 2.
    pub ropes: [RopeState; 2],
}

impl RigState {
    /// Tension of rope `i` (0 or 1) [N].
    pub fn tension_n(&self, i: usize) -> f64 {
        self.ropes[i].tension_n
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
        Ok(Self {
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
        }
    }

    /// Strain of rope `i` for carriage stretch `x`, input `theta`, output `phi`.
    fn strain(&self, i: usize, x: f64, theta: f64, phi: f64) -> f64 {
        let s = &self.spec;
        (x + SIGN[i] * (s.input_radius_m * theta - s.output_radius_m * phi)) * self.inv_length_per_m
    }

    /// Advances one step with the input angle `input_rad` at the end of the step.
    pub fn step(&self, st: &mut RigState, input_rad: f64) -> Result<(), DriveError> {
        let s = &self.spec;
        let h = self.dt_s;
        let (i_out, c_out, r2, l, inv_l) = (
            s.output_inertia_kg_m2,
            s.output_damping_n_m_s,
            s.output_radius_m,
            s.rope_length_m,
            self.inv_length_per_m,
        );
        let prep = [
            self.stepper.prepare(&st.ropes[0]),
            self.stepper.prepare(&st.ropes[1]),
        ];
        let (phi0, w0, a0) = (st.output_rad, st.output_rate_rad_s, st.output_accel_rad_s2);
        // Trapezoidal rule: w1 = 2(phi1-phi0)/h - w0, a1 = 4(phi1-phi0)/h^2 - 4 w0/h - a0.
        let (k_dyn, two_h, four_h2) = (self.k_dyn, self.two_over_h, self.four_over_h2);
        let inertial = |phi: f64| {
            let a1 = four_h2 * (phi - phi0) - two_h * 2.0 * w0 - a0;
            let w1 = two_h * (phi - phi0) - w0;
            i_out * a1 + c_out * w1
        };
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
        let w1 = two_h * (phi - phi0) - w0;
        let a1 = four_h2 * (phi - phi0) - two_h * 2.0 * w0 - a0;
        st.time_s += h;
        st.input_rad = input_rad;
        st.output_rad = phi;
        st.output_rate_rad_s = w1;
        st.output_accel_rad_s2 = a1;
        st.carriage_m = x;
        let finite = phi.is_finite()
            && w1.is_finite()
            && a1.is_finite()
            && x.is_finite()
            && st.ropes.iter().all(|r| r.tension_n.is_finite());
        if !finite || w1.abs() > 1e6 {
            return Err(DriveError::BlowUp {
                time_s: st.time_s,
                what: format!(
                    "output angle {phi} rad, rate {w1} rad/s, tensions {} / {} N",
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
