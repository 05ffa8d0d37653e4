//! Rope constitutive laws (Figs. 1-2, eqs. 1-5 of the paper) and their time stepping.
//!
//! A rope is a chain of elements in series, all carrying the same tension `f`:
//!
//! ```text
//!   head (k1 spring, optionally || c1 dashpot)  -- c2 dashpot (creep)  -- Kelvin (k3 || c3) ...  -- ratchet || kp
//! ```
//!
//! Total strain `e = e1 + e2 + sum(e3_j) + ep`. The elastic law is the head spring alone;
//! the four-element (Burgers) law adds the c2 dashpot and one Kelvin element; Flory's
//! law adds the ratchet || kp element: the plastic strain `ep` holds its largest value
//! and grows only while the tension exceeds the previous peak, with
//! `f_peak = kp * ep` (eq. 2).
//!
//! A rope never pushes: when the imposed strain is shorter than the rope's natural
//! length (`e < e2 + sum(e3) + ep`) the rope is slack, `f = 0`, the head spring is
//! unloaded, the creep dashpot and the ratchet hold, and each Kelvin element relaxes
//! towards zero through its own dashpot.
//!
//! # Time stepping
//!
//! Each step imposes the total strain at the end of the step and returns the tension.
//! The tension is taken piecewise linear in time over a step (first-order hold); under
//! that hold every linear element is integrated *exactly*: a Kelvin element
//! `k e + c de/dt = f` by its exponential with the exact hold weights, the creep
//! dashpot by the trapezoid (exact for a linear tension); a damped head whose spring
//! stiffens (`f = f_s(e1) + c1 de1/dt`) by the same exponential with its spring
//! linearised about the step's start strain, `f_s(e1_0) + k (e1 - e1_0)` (second order,
//! [`RopeStepper::prepare`]). The step is therefore
//! unconditionally stable for any rope and any `dt`, second-order accurate, and the
//! unknown end tension solves one scalar monotone equation: closed form for linear
//! laws (a piecewise-linear function of the end strain: slack / elastic / plastic),
//! safeguarded Newton when an effect makes an element non-linear. When the head spring
//! (without c1) is the only non-linear element, the Newton runs on the head strain
//! through the spring law's closed-form inverse (one exponential per iteration, no
//! logarithm; [`RopeStepper::tension_piece`]).

use serde::{Deserialize, Serialize};

use crate::catalog::RopeParams;
use crate::error::RopeError;
use crate::table::Table;

/// Largest number of Kelvin (retarded-elasticity) elements a law may hold.
pub const MAX_KELVIN: usize = 3;

/// Which of the paper's laws to build from a catalog rope.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LawKind {
    /// `f = k1 * e` (eq. 13; stainless steel).
    Elastic,
    /// Burgers model of Fig. 1 (eq. 3, 10, 12).
    FourElement,
    /// Four-element in series with ratchet || kp (Fig. 2, eqs. 1-2).
    Flory,
}

impl LawKind {
    /// The law the paper uses for a rope: four-element when the rope has the
    /// visco-elastic constants, elastic otherwise.
    pub fn default_for(params: &RopeParams) -> Self {
        if params.has_four_element() {
            Self::FourElement
        } else {
            Self::Elastic
        }
    }

    /// Lower-case name as used in files.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Elastic => "elastic",
            Self::FourElement => "four_element",
            Self::Flory => "flory",
        }
    }
}

/// A retarded-elasticity element: spring `k` parallel to dashpot `c` (per unit strain).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct KelvinElement {
    /// Spring [N].
    pub k_n: f64,
    /// Dashpot [N*s].
    pub c_n_s: f64,
}

/// Stress-dependent creep: the c2 dashpot's strain rate is
/// `f / c2 * (1 + (f / tension_n)^exponent)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NonlinearCreep {
    /// Tension at which the creep rate doubles [N].
    pub tension_n: f64,
    /// Exponent of the stress dependence (dimensionless, >= 1).
    pub exponent: f64,
}

/// A rope constitutive law, per unit strain (multiply strains by the rope length).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RopeLaw {
    /// Head spring k1 [N]: its tangent stiffness is `k1 * (1 + stiffening_per_n * f)`.
    pub k1_n: f64,
    /// Dashpot parallel to the head spring (internal damping) [N*s]; 0 = none.
    pub c1_n_s: f64,
    /// Creep dashpot c2 [N*s]; `None` = no creep.
    pub c2_n_s: Option<f64>,
    /// Kelvin elements in series (k3 || c3 of Fig. 1, and any added retardation).
    pub kelvin: Vec<KelvinElement>,
    /// Spring parallel to Flory's ratchet [N]; `None` = no plasticity.
    pub kp_n: Option<f64>,
    /// Relative stiffening of the head spring per newton of tension [1/N]; 0 = linear.
    pub stiffening_per_n: f64,
    /// Stress-dependent creep of the c2 dashpot; `None` = linear dashpot.
    pub creep: Option<NonlinearCreep>,
    /// Shape-free head spring: its tangent stiffness is `k1 * g(f)` with `g` this table
    /// of the tension (replaces `stiffening_per_n`); `None` = none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stiffness_table: Option<Table>,
    /// Shape-free creep: the c2 dashpot's rate is `f / c2 * h(f)` with `h` this table of
    /// the tension (replaces `creep`); `None` = none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub creep_table: Option<Table>,
}

impl RopeLaw {
    /// `f = k1 * e`.
    pub fn elastic(k1_n: f64) -> Self {
        Self {
            k1_n,
            c1_n_s: 0.0,
            c2_n_s: None,
            kelvin: Vec::new(),
            kp_n: None,
            stiffening_per_n: 0.0,
            creep: None,
            stiffness_table: None,
            creep_table: None,
        }
    }

    /// The four-element (Burgers) model of Fig. 1.
    pub fn four_element(k1_n: f64, c2_n_s: f64, k3_n: f64, c3_n_s: f64) -> Self {
        Self {
            c2_n_s: Some(c2_n_s),
            kelvin: vec![KelvinElement {
                k_n: k3_n,
                c_n_s: c3_n_s,
            }],
            ..Self::elastic(k1_n)
        }
    }

    /// Flory's model of Fig. 2: four-element in series with ratchet || kp.
    pub fn flory(k1_n: f64, c2_n_s: f64, k3_n: f64, c3_n_s: f64, kp_n: f64) -> Self {
        Self {
            kp_n: Some(kp_n),
            ..Self::four_element(k1_n, c2_n_s, k3_n, c3_n_s)
        }
    }

    /// Builds a law of the given kind from catalog constants.
    pub fn from_params(params: &RopeParams, kind: LawKind) -> Result<Self, RopeError> {
        let missing = |key: &str, hint: &str| RopeError::MissingConstant {
            rope: params.name.clone(),
            law: kind.as_str().to_string(),
            missing: key.to_string(),
            hint: hint.to_string(),
        };
        let law = match kind {
            LawKind::Elastic => Self::elastic(params.k1_n),
            LawKind::FourElement | LawKind::Flory => {
                let hint = "elastic ropes such as stainless1 use law = \"elastic\"";
                let k3 = params.k3_n.ok_or_else(|| missing("k3", hint))?;
                let c2 = params.c2_n_s.ok_or_else(|| missing("c2", hint))?;
                let c3 = params.c3_n_s.ok_or_else(|| missing("c3", hint))?;
                if kind == LawKind::Flory {
                    let kp = params
                        .kp_n
                        .ok_or_else(|| missing("kp", "give kp (Table IV) or use four_element"))?;
                    Self::flory(params.k1_n, c2, k3, c3, kp)
                } else {
                    Self::four_element(params.k1_n, c2, k3, c3)
                }
            }
        };
        law.validate()?;
        Ok(law)
    }

    /// Checks every constant; says which one is wrong.
    pub fn validate(&self) -> Result<(), RopeError> {
        let bad = |field: &str, value: f64, reason: &str| {
            Err(RopeError::BadParameter {
                field: field.to_string(),
                value,
                reason: reason.to_string(),
            })
        };
        let pos = "must be finite and > 0";
        if !(self.k1_n.is_finite() && self.k1_n > 0.0) {
            return bad("k1", self.k1_n, pos);
        }
        if !(self.c1_n_s.is_finite() && self.c1_n_s >= 0.0) {
            return bad(
                "c1",
                self.c1_n_s,
                "must be finite and >= 0 (0 = no internal damping)",
            );
        }
        if let Some(c2) = self.c2_n_s {
            if !(c2.is_finite() && c2 > 0.0) {
                return bad("c2", c2, pos);
            }
        }
        if self.kelvin.len() > MAX_KELVIN {
            return bad(
                "kelvin",
                self.kelvin.len() as f64,
                "at most 3 Kelvin elements are supported",
            );
        }
        for el in &self.kelvin {
            if !(el.k_n.is_finite() && el.k_n > 0.0) {
                return bad("kelvin k", el.k_n, pos);
            }
            if !(el.c_n_s.is_finite() && el.c_n_s > 0.0) {
                return bad("kelvin c", el.c_n_s, pos);
            }
        }
        if let Some(kp) = self.kp_n {
            if !(kp.is_finite() && kp > 0.0) {
                return bad("kp", kp, pos);
            }
        }
        if !(self.stiffening_per_n.is_finite() && self.stiffening_per_n >= 0.0) {
            return bad(
                "stiffening_per_n",
                self.stiffening_per_n,
                "must be finite and >= 0 (0 = linear spring)",
            );
        }
        if let Some(t) = &self.stiffness_table {
            if !t.positive() {
                return bad(
                    "stiffness_table",
                    t.y().iter().copied().fold(f64::INFINITY, f64::min),
                    "every stiffness factor must be > 0",
                );
            }
            if self.stiffening_per_n > 0.0 {
                return bad(
                    "stiffness_table",
                    self.stiffening_per_n,
                    "give stiffening_per_n or a stiffness table, not both",
                );
            }
        }
        if let Some(t) = &self.creep_table {
            if self.c2_n_s.is_none() {
                return bad(
                    "creep_table",
                    t.y()[0],
                    "non-linear creep needs the c2 dashpot (a four-element or Flory law)",
                );
            }
            if !t.positive() {
                return bad(
                    "creep_table",
                    t.y().iter().copied().fold(f64::INFINITY, f64::min),
                    "every creep factor must be > 0",
                );
            }
            if self.creep.is_some() {
                return bad(
                    "creep_table",
                    t.y()[0],
                    "give the creep law or a creep table, not both",
                );
            }
        }
        if let Some(c) = self.creep {
            if self.c2_n_s.is_none() {
                return bad(
                    "creep",
                    c.tension_n,
                    "non-linear creep needs the c2 dashpot (a four-element or Flory law)",
                );
            }
            if !(c.tension_n.is_finite() && c.tension_n > 0.0) {
                return bad("creep tension_n", c.tension_n, pos);
            }
            if !(c.exponent.is_finite() && c.exponent >= 1.0) {
                return bad("creep exponent", c.exponent, "must be finite and >= 1");
            }
        }
        Ok(())
    }

    /// True when every element is linear (the end tension has a closed form).
    pub fn is_linear(&self) -> bool {
        !self.stiffens() && !self.creeps_nonlinearly()
    }

    /// True when the head spring's stiffness depends on the tension.
    pub fn stiffens(&self) -> bool {
        self.stiffening_per_n != 0.0 || self.stiffness_table.is_some()
    }

    /// True when the creep dashpot's rate is not linear in the tension.
    pub fn creeps_nonlinearly(&self) -> bool {
        self.creep.is_some() || self.creep_table.is_some()
    }

    /// Strain of the head spring carrying tension `f` (inverse of the spring law).
    #[inline]
    pub fn head_strain(&self, tension_n: f64) -> f64 {
        let f = tension_n.max(0.0);
        if let Some(t) = &self.stiffness_table {
            return t.integral_inv(f) / self.k1_n;
        }
        let b = self.stiffening_per_n;
        if b == 0.0 {
            f / self.k1_n
        } else {
            (b * f).ln_1p() / (self.k1_n * b)
        }
    }

    /// Tension of the head spring at strain `e1` (the spring alone, no dashpot).
    pub fn head_tension(&self, e1: f64) -> f64 {
        let e = e1.max(0.0);
        if let Some(t) = &self.stiffness_table {
            return t.inverse_integral_inv(self.k1_n * e);
        }
        let b = self.stiffening_per_n;
        if b == 0.0 {
            self.k1_n * e
        } else {
            (self.k1_n * b * e).exp_m1() / b
        }
    }

    /// Tension of the head spring at strain `e1` and its tangent stiffness there, from
    /// one exponential: the spring law's inverse in closed form (`(exp(k1 b e) - 1)/b`
    /// and `k1 exp(k1 b e)`; per segment for a table, [`Table::inverse_integral_inv_value`]).
    #[inline]
    pub fn head_tension_stiffness(&self, e1: f64) -> (f64, f64) {
        let e = e1.max(0.0);
        if let Some(t) = &self.stiffness_table {
            let (f, g) = t.inverse_integral_inv_value(self.k1_n * e);
            return (f, self.k1_n * g);
        }
        let b = self.stiffening_per_n;
        if b == 0.0 {
            (self.k1_n * e, self.k1_n)
        } else {
            let x = (self.k1_n * b * e).exp_m1();
            (x / b, self.k1_n * (1.0 + x))
        }
    }

    /// Largest slope of the head spring's tangent stiffness against its tension,
    /// `k1 max |g'(f)|` [1 per unit strain]: times the tangent stiffness it bounds
    /// `d^2 f / d e1^2` (the error bound of [`RopeStepper`]'s closed-form solve).
    fn head_curvature(&self) -> f64 {
        match &self.stiffness_table {
            Some(t) => self.k1_n * t.max_abs_slope(),
            None => self.k1_n * self.stiffening_per_n,
        }
    }

    /// Tangent stiffness of the head spring at tension `f` [N per unit strain].
    #[inline]
    pub fn head_stiffness(&self, tension_n: f64) -> f64 {
        if let Some(t) = &self.stiffness_table {
            return self.k1_n * t.eval(tension_n);
        }
        self.k1_n * (1.0 + self.stiffening_per_n * tension_n.max(0.0))
    }

    /// Elastic energy per unit length of the head spring at strain `e1` [N].
    fn head_energy(&self, e1: f64) -> f64 {
        let e1 = e1.max(0.0);
        if let Some(t) = &self.stiffness_table {
            return t.integral_x_over(self.head_tension(e1)) / self.k1_n;
        }
        let b = self.stiffening_per_n;
        if b == 0.0 {
            0.5 * self.k1_n * e1 * e1
        } else {
            let k = self.k1_n;
            (k * b * e1).exp_m1() / (k * b * b) - e1 / b
        }
    }

    /// Quasi-static strain of the rope held at tension `f` long enough for every Kelvin
    /// element to settle (creep excluded: it never settles).
    pub fn settled_strain(&self, tension_n: f64) -> f64 {
        self.head_strain(tension_n) + self.kelvin.iter().map(|k| tension_n / k.k_n).sum::<f64>()
    }

    /// Creep strain rate of the c2 dashpot at tension `f` [1/s].
    pub fn creep_rate(&self, tension_n: f64) -> f64 {
        match self.c2_n_s {
            None => 0.0,
            Some(c2) => {
                let f = tension_n.max(0.0);
                if let Some(t) = &self.creep_table {
                    return f / c2 * t.eval(f);
                }
                let nl = self
                    .creep
                    .map_or(0.0, |c| (f / c.tension_n).powf(c.exponent));
                f / c2 * (1.0 + nl)
            }
        }
    }

    /// Derivative of [`Self::creep_rate`] with respect to tension.
    fn creep_rate_slope(&self, tension_n: f64) -> f64 {
        self.creep_rate_and_slope(tension_n).1
    }

    /// [`Self::creep_rate`] and [`Self::creep_rate_slope`] at once, bit for bit the
    /// same values: the power law's one `powf` (the dearest part of a step of a rope
    /// that creeps non-linearly, which its Newton solve evaluates several times) is
    /// shared.
    fn creep_rate_and_slope(&self, tension_n: f64) -> (f64, f64) {
        match self.c2_n_s {
            None => (0.0, 0.0),
            Some(c2) => {
                let f = tension_n.max(0.0);
                if let Some(t) = &self.creep_table {
                    let (h, dh) = t.eval_slope(f);
                    return (f / c2 * h, (h + f * dh) / c2);
                }
                let (nl, dnl) = self.creep.map_or((0.0, 0.0), |c| {
                    let p = (f / c.tension_n).powf(c.exponent);
                    (p, (c.exponent + 1.0) * p)
                });
                (f / c2 * (1.0 + nl), (1.0 + dnl) / c2)
            }
        }
    }
}

/// Mutable state of one rope (strains are per unit length).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RopeState {
    /// Tension at the end of the last step [N] (never negative).
    pub tension_n: f64,
    /// Total strain imposed at the end of the last step.
    pub strain: f64,
    /// Head-spring strain (only a state when the head has internal damping).
    pub e1: f64,
    /// Creep (c2 dashpot) strain.
    pub e2: f64,
    /// Kelvin element strains.
    pub e3: [f64; MAX_KELVIN],
    /// Plastic strain held by the ratchet.
    pub ep: f64,
    /// Largest tension seen [N].
    pub peak_tension_n: f64,
}

impl RopeState {
    /// Natural (unstretched) strain of the rope: below it the rope is slack.
    pub fn natural_strain(&self) -> f64 {
        self.e2 + self.e3.iter().sum::<f64>() + self.ep
    }

    /// True when the rope carried no tension at the end of the last step.
    pub fn is_slack(&self) -> bool {
        self.tension_n <= 0.0
    }
}

/// Hold weights of one Kelvin element over a step: `e1 = a*e0 + b0*f0 + b1*f1`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Hold {
    a: f64,
    b0: f64,
    b1: f64,
}

impl Hold {
    /// Exact solution of `k e + c de/dt = f(t)` over `h` with `f` linear in time.
    fn kelvin(k: f64, c: f64, h: f64) -> Self {
        let x = h * k / c;
        let a = (-x).exp();
        // phi = (1 - a) / x and one_minus_phi = 1 - phi, by series where they cancel.
        let (phi, one_minus_phi) = if x < 1e-3 {
            let omp = x / 2.0 - x * x / 6.0 + x * x * x / 24.0 - x.powi(4) / 120.0;
            (1.0 - omp, omp)
        } else {
            let phi = -(-x).exp_m1() / x;
            (phi, 1.0 - phi)
        };
        Self {
            a,
            b0: (phi - a) / k,
            b1: one_minus_phi / k,
        }
    }
}

/// A law compiled for one time step: the hold weights are computed once.
#[derive(Debug, Clone, PartialEq)]
pub struct RopeStepper {
    law: RopeLaw,
    dt_s: f64,
    kelvin: [Hold; MAX_KELVIN],
    n_kelvin: usize,
    /// Weights of the head when it has internal damping (a Kelvin element k1 || c1).
    head_hold: Option<Hold>,
    linear: bool,
    /// The head spring (without c1) is the only non-linear element: the step is solved
    /// for the head strain with the spring law's closed-form inverse
    /// ([`Self::solve_head`]).
    head_only: bool,
    /// [`RopeLaw::head_curvature`].
    head_curvature: f64,
    /// Linear laws: the step's constant compliance [1/N], its inverse, and the inverse
    /// with the ratchet's kp spring added (plastic flow).
    compliance: f64,
    inv_compliance: f64,
    inv_plastic_compliance: f64,
    /// dt / (2 c2), 0 without creep.
    half_h_over_c2: f64,
}

/// Which piece of a rope law holds at the end of a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Piece {
    /// No tension.
    Slack,
    /// Taut, ratchet locked: tension affine in strain (linear laws).
    Elastic,
    /// Taut, ratchet sliding: tension affine in strain with kp in the chain.
    Plastic,
    /// A non-linear element is active: no affine piece.
    Nonlinear,
}

/// What one step needs from the state at its start: the end tension is a monotone
/// function of the end strain, `rest + compliance*f + nonlinear(f) + ep(f) = e`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreparedStep {
    /// Strain of every element at zero end tension, plastic strain excluded.
    rest: f64,
    /// Linear compliance of the step [1/N].
    compliance: f64,
    /// Tension above which the ratchet slides (`kp * ep`), infinite without one.
    yield_n: f64,
    /// Plastic strain at the start.
    ep0: f64,
    /// Tension at the start.
    f0: f64,
    /// Creep rate at the start tension [1/s] (laws that creep non-linearly; else 0).
    creep_rate0: f64,
}

impl PreparedStep {
    /// Strain at or below which the rope is slack at the end of the step.
    pub fn slack_strain(&self) -> f64 {
        self.rest + self.ep0
    }
}

impl RopeStepper {
    /// Compiles `law` for steps of `dt_s` seconds.
    pub fn new(law: RopeLaw, dt_s: f64) -> Result<Self, RopeError> {
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 1.0) {
            return Err(RopeError::BadTimeStep { dt_s });
        }
        law.validate()?;
        let mut kelvin = [Hold::default(); MAX_KELVIN];
        for (slot, el) in kelvin.iter_mut().zip(&law.kelvin) {
            *slot = Hold::kelvin(el.k_n, el.c_n_s, dt_s);
        }
        let head_hold = (law.c1_n_s > 0.0).then(|| Hold::kelvin(law.k1_n, law.c1_n_s, dt_s));
        let half_h_over_c2 = law.c2_n_s.map_or(0.0, |c2| 0.5 * dt_s / c2);
        let compliance = half_h_over_c2
            + kelvin[..law.kelvin.len()].iter().map(|k| k.b1).sum::<f64>()
            + head_hold.map_or(1.0 / law.k1_n, |h| h.b1);
        let inv_kp = law.kp_n.map_or(0.0, |kp| 1.0 / kp);
        Ok(Self {
            n_kelvin: law.kelvin.len(),
            linear: law.is_linear(),
            head_only: law.stiffens() && law.c1_n_s == 0.0 && !law.creeps_nonlinearly(),
            head_curvature: law.head_curvature(),
            compliance,
            inv_compliance: 1.0 / compliance,
            inv_plastic_compliance: 1.0 / (compliance + inv_kp),
            half_h_over_c2,
            law,
            dt_s,
            kelvin,
            head_hold,
        })
    }

    /// The law this stepper integrates.
    pub fn law(&self) -> &RopeLaw {
        &self.law
    }

    /// Step [s].
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// State of a rope that has rested at `tension_n` long enough for its Kelvin
    /// elements to settle, after a pre-stretch to `prestretch_n` (which sets the
    /// ratchet: `ep = max(prestretch, tension) / kp`, eq. 2). Creep strain starts at 0.
    pub fn rest_state(&self, tension_n: f64, prestretch_n: f64) -> RopeState {
        let f = tension_n.max(0.0);
        let mut s = RopeState {
            tension_n: f,
            e1: self.law.head_strain(f),
            peak_tension_n: f.max(prestretch_n),
            ..RopeState::default()
        };
        for (e3, el) in s.e3.iter_mut().zip(&self.law.kelvin) {
            *e3 = f / el.k_n;
        }
        if let Some(kp) = self.law.kp_n {
            s.ep = f.max(prestretch_n.max(0.0)) / kp;
        }
        s.strain = s.e1 + s.natural_strain();
        s
    }

    /// The state of eq. 5: strain `e0` applied instantly to a fresh rope
    /// (`e1 = e0`, every other strain zero).
    pub fn instant_strain_state(&self, strain: f64) -> RopeState {
        let e1 = strain.max(0.0);
        let f = self.law.head_tension(e1);
        RopeState {
            tension_n: f,
            strain,
            e1,
            peak_tension_n: f,
            ..RopeState::default()
        }
    }

    /// Prepares the step that starts from `s`.
    pub fn prepare(&self, s: &RopeState) -> PreparedStep {
        let h = self.dt_s;
        let f0 = s.tension_n;
        let yield_n = self.law.kp_n.map_or(f64::INFINITY, |kp| kp * s.ep);
        if self.linear {
            let mut rest = s.e2 + self.half_h_over_c2 * f0;
            for (hold, e3) in self.kelvin[..self.n_kelvin].iter().zip(&s.e3) {
                rest += hold.a * e3 + hold.b0 * f0;
            }
            if let Some(hold) = self.head_hold {
                rest += hold.a * s.e1 + hold.b0 * f0;
            }
            return PreparedStep {
                rest,
                compliance: self.compliance,
                yield_n,
                ep0: s.ep,
                f0,
                creep_rate0: 0.0,
            };
        }
        let creep_rate0 = self.law.creep_rate(f0);
        let mut rest = s.e2 + 0.5 * h * creep_rate0;
        let mut compliance = 0.0;
        if self.law.c2_n_s.is_some() && !self.law.creeps_nonlinearly() {
            compliance += 0.5 * h * self.law.creep_rate_slope(0.0);
        }
        for (hold, e3) in self.kelvin[..self.n_kelvin].iter().zip(&s.e3) {
            rest += hold.a * e3 + hold.b0 * f0;
            compliance += hold.b1;
        }
        match self.head_hold {
            Some(hold) if !self.law.stiffens() => {
                // Kelvin head k1 || c1.
                rest += hold.a * s.e1 + hold.b0 * f0;
                compliance += hold.b1;
            }
            Some(_) => {
                // Kelvin head whose spring stiffens: the spring linearised about the
                // head's own strain, f_s(e1) ~ f_s0 + k (e1 - e1_0) with its tangent k,
                // so that the dashpot carries f - f_s(e1) (second order in the step).
                // (Linearised as k e1, the dashpot carried f - k e1: at a steady tension
                // the head crept towards f / k instead of the spring's own strain, a
                // law of its own at any step.)
                let (fs0, k) = self.law.head_tension_stiffness(s.e1);
                let scaled = Hold::kelvin(k, self.law.c1_n_s, h);
                rest += s.e1 + scaled.b0 * (f0 - fs0) - scaled.b1 * fs0;
                compliance += scaled.b1;
            }
            None if !self.law.stiffens() => compliance += 1.0 / self.law.k1_n,
            None => {}
        }
        PreparedStep {
            rest,
            compliance,
            yield_n,
            ep0: s.ep,
            f0,
            creep_rate0,
        }
    }

    /// Strain-minus-target residual of the step at end tension `f`, and its slope.
    fn residual(&self, p: &PreparedStep, f: f64, strain: f64) -> (f64, f64) {
        let mut g = p.rest + p.compliance * f - strain;
        let mut dg = p.compliance;
        if self.head_hold.is_none() && self.law.stiffens() {
            g += self.law.head_strain(f);
            dg += 1.0 / self.law.head_stiffness(f);
        }
        if self.law.creeps_nonlinearly() {
            let (r, dr) = self.law.creep_rate_and_slope(f);
            g += 0.5 * self.dt_s * r;
            dg += 0.5 * self.dt_s * dr;
        }
        match self.law.kp_n {
            Some(kp) if f > p.yield_n => {
                g += f / kp;
                dg += 1.0 / kp;
            }
            _ => g += p.ep0,
        }
        (g, dg)
    }

    /// End tension [N] and its slope d(tension)/d(strain) [N] for the end strain `strain`.
    pub fn tension(&self, p: &PreparedStep, strain: f64) -> (f64, f64) {
        let (f, k, _) = self.tension_piece(p, strain);
        (f, k)
    }

    /// Like [`Self::tension`], plus which piece of the law holds: [`Piece::Slack`],
    /// [`Piece::Elastic`], [`Piece::Plastic`] (linear laws, on which the tension is affine
    /// in the strain) or [`Piece::Nonlinear`].
    #[inline]
    pub fn tension_piece(&self, p: &PreparedStep, strain: f64) -> (f64, f64, Piece) {
        if strain <= p.slack_strain() {
            return (0.0, 0.0, Piece::Slack);
        }
        if self.linear {
            let f = (strain - p.slack_strain()) * self.inv_compliance;
            if f <= p.yield_n {
                return (f, self.inv_compliance, Piece::Elastic);
            }
            // The ratchet slides: the kp spring joins the chain (eq. 2).
            return (
                (strain - p.rest) * self.inv_plastic_compliance,
                self.inv_plastic_compliance,
                Piece::Plastic,
            );
        }
        let (f, k) = if self.head_only {
            self.solve_head(p, strain)
        } else {
            self.solve_nonlinear(p, strain)
        };
        (f, k, Piece::Nonlinear)
    }

    /// The step of a law whose only non-linear element is the head spring (no c1, linear
    /// creep): `rest + compliance f + head_strain(f) + ep = strain`, solved for the head
    /// strain on the ratchet's locked piece (`ep = ep0`), then, when the tension exceeds
    /// the ratchet's yield, on its sliding piece (`ep = f / kp`: kp joins the chain).
    #[inline]
    fn solve_head(&self, p: &PreparedStep, strain: f64) -> (f64, f64) {
        let (f, k) = self.solve_head_piece(p.compliance, strain - p.slack_strain(), p.f0);
        match self.law.kp_n {
            Some(kp) if f > p.yield_n => {
                self.solve_head_piece(p.compliance + 1.0 / kp, strain - p.rest, p.f0)
            }
            _ => (f, k),
        }
    }

    /// The head strain `z` in `[0, u]` with `z + c T(z) = u` (`u > 0`, `c >= 0`, `T` the
    /// head spring's tension, in closed form: [`RopeLaw::head_tension_stiffness`]), by
    /// Newton from the `z` that leaves the tension `guess` (the step's start) in the
    /// linear compliance, bisection as the safeguard. For a spring that never softens
    /// `z + c T(z)` is convex and increasing, so Newton never leaves `[0, u]`; each
    /// iteration costs one exponential and no logarithm. It stops once the tension's
    /// error after the update, bounded by the second-order term `kt k1 max|g'| dz^2`
    /// (the Taylor remainder of `T`, and the distance of `z + dz` from the root), is
    /// below `1e-14 (1 + f)`. Returns the tension and d(tension)/d(strain); NaN for a
    /// strain that is not a number (as [`Self::solve_nonlinear`]: the step reports it).
    #[inline]
    fn solve_head_piece(&self, c: f64, u: f64, guess: f64) -> (f64, f64) {
        if u.is_nan() {
            return (f64::NAN, 0.0);
        }
        let (mut lo, mut hi) = (0.0_f64, u);
        let mut z = (u - c * guess.max(0.0)).clamp(0.0, u);
        for _ in 0..200 {
            let (f, kt) = self.law.head_tension_stiffness(z);
            let phi = z + c * f - u;
            if phi > 0.0 {
                hi = z;
            } else {
                lo = z;
            }
            let dz = -phi / (1.0 + c * kt);
            if kt * self.head_curvature * dz * dz <= 1e-14 * (1.0 + f) {
                let f1 = (f + kt * dz).max(0.0);
                let kt1 = self.law.head_stiffness(f1);
                return (f1, kt1 / (1.0 + c * kt1));
            }
            let mut next = z + dz;
            if !(next > lo && next < hi) {
                next = 0.5 * (lo + hi);
            }
            z = next;
            if hi - lo <= 4.0 * f64::EPSILON * hi {
                break;
            }
        }
        let (f, kt) = self.law.head_tension_stiffness(z);
        (f, kt / (1.0 + c * kt))
    }

    /// Safeguarded Newton on the monotone step residual, from the step's start tension.
    /// The root is bracketed as the iterates find it (the residual is negative at zero
    /// tension on a taut rope); a step that leaves the bracket is a bisection, or a
    /// doubling while no iterate has overshot. It stops when the step is below
    /// `1e-13 (1 + f)`, or when two Newton steps in a row show that the error left after
    /// the last is below a hundredth of that: Newton's error after a step `d` is about
    /// `K d^2`, and `K` is read off the previous step (`d / d_prev^2`; only where the
    /// residual is smooth: both steps on one side of the ratchet's yield, no table). A step of a rope
    /// that creeps non-linearly, whose creep term barely bends the residual, then
    /// costs two or three evaluations of its power law (12 before). The slope returned is
    /// the last iterate's, within that step of the root. A residual that is not finite,
    /// or a tension beyond 1e15 N, gives NaN.
    fn solve_nonlinear(&self, p: &PreparedStep, strain: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (0.0_f64, f64::INFINITY);
        let mut f = p.f0.max(0.0);
        // (the contraction is read only where the residual is smooth: not across the
        // ratchet's yield, not on a table's piecewise-linear law)
        let smooth = self.law.stiffness_table.is_none() && self.law.creep_table.is_none();
        let mut prev_step: Option<(f64, bool)> = None;
        for _ in 0..200 {
            let (g, dg) = self.residual(p, f, strain);
            if !(g.is_finite() && f <= 1e15) {
                return (f64::NAN, 0.0);
            }
            if g > 0.0 {
                hi = f;
            } else {
                lo = f;
            }
            // (converged before the bracket is consulted: near the root, the residual's
            // rounding can put it on either side, and a Newton step below half an ulp
            // leaves the iterate on the bracket's end, which bisected it 10 times a
            // solve on average)
            let step = g / dg;
            let tol = 1e-13 * (1.0 + f.abs());
            let quadratic = smooth
                && prev_step.is_some_and(|(d, yielded)| {
                    yielded == (f > p.yield_n)
                        && yielded == (f - step > p.yield_n)
                        && step.abs().powi(3) <= 1e-2 * tol * d * d
                });
            if step.abs() <= tol || quadratic {
                return ((f - step).max(0.0), 1.0 / dg);
            }
            let newton = f - step;
            let bisect = !(newton > lo && newton < hi);
            let next = match (bisect, hi.is_finite()) {
                (false, _) => newton,
                (true, true) => 0.5 * (lo + hi),
                (true, false) => 2.0 * f.max(1.0),
            };
            prev_step = (!bisect).then_some((step.abs(), f > p.yield_n));
            f = next;
        }
        let (_, dg) = self.residual(p, f, strain);
        (f, 1.0 / dg)
    }

    /// Ends the step at `strain`: updates every element and returns the tension [N].
    pub fn commit(&self, p: &PreparedStep, s: &mut RopeState, strain: f64) -> f64 {
        let (f1, _) = self.tension(p, strain);
        self.commit_with_tension(p, s, strain, f1)
    }

    /// Ends the step at `strain` whose tension `f1` the caller already has from
    /// [`Self::tension`] with the same prepared step.
    pub fn commit_with_tension(
        &self,
        p: &PreparedStep,
        s: &mut RopeState,
        strain: f64,
        f1: f64,
    ) -> f64 {
        let f0 = p.f0;
        let h = self.dt_s;
        s.e2 += if !self.law.creeps_nonlinearly() {
            self.half_h_over_c2 * (f0 + f1)
        } else {
            0.5 * h * (p.creep_rate0 + self.law.creep_rate(f1))
        };
        for (e3, hold) in s.e3.iter_mut().zip(&self.kelvin[..self.n_kelvin]) {
            *e3 = hold.a * *e3 + hold.b0 * f0 + hold.b1 * f1;
        }
        if let Some(kp) = self.law.kp_n {
            if f1 > p.yield_n {
                s.ep = f1 / kp;
            }
        }
        s.e1 = if f1 > 0.0 {
            strain - s.natural_strain()
        } else {
            match self.head_hold {
                // A damped head relaxes like a Kelvin element while slack.
                Some(hold) => hold.a * s.e1 + hold.b0 * f0,
                None => 0.0,
            }
        };
        s.tension_n = f1;
        s.strain = strain;
        s.peak_tension_n = s.peak_tension_n.max(f1);
        f1
    }

    /// Steps the rope through an imposed strain history, one sample per step,
    /// returning the tension after each step.
    pub fn run_strain_history(
        &self,
        state: &mut RopeState,
        strains: &[f64],
    ) -> Result<Vec<f64>, RopeError> {
        let mut out = Vec::with_capacity(strains.len());
        for &e in strains {
            let p = self.prepare(state);
            let f = self.commit(&p, state, e);
            if !f.is_finite() {
                return Err(RopeError::NonFinite {
                    what: "tension",
                    value: f,
                    strain: e,
                });
            }
            out.push(f);
        }
        Ok(out)
    }

    /// Elastic energy stored in the springs of a rope of `length_m` [J] (head spring and
    /// Kelvin springs; the ratchet's locked strain stores none that can be returned).
    pub fn stored_energy_j(&self, s: &RopeState, length_m: f64) -> f64 {
        let head = self.law.head_energy(s.e1);
        let kelvin: f64 = self
            .law
            .kelvin
            .iter()
            .zip(&s.e3)
            .map(|(el, e)| 0.5 * el.k_n * e * e)
            .sum();
        length_m * (head + kelvin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A strain that is not a number gives a tension that is not a number, on the
    /// head-spring solve as on the general one, for the step to report: no panic (a
    /// relay whose angle went NaN once panicked in the head solve's clamp).
    #[test]
    fn a_strain_that_is_not_a_number_gives_nan_not_a_panic() {
        let head = RopeLaw {
            stiffening_per_n: 2e-3,
            ..RopeLaw::flory(7.29e4, 1.65e7, 8.9e5, 1.47e6, 3e4)
        };
        let damped = RopeLaw {
            c1_n_s: 300.0,
            ..head.clone()
        };
        for (law, head_only) in [(head, true), (damped, false)] {
            let st = RopeStepper::new(law, 1e-3).unwrap();
            assert_eq!(st.head_only, head_only);
            let s = st.rest_state(150.0, 0.0);
            let p = st.prepare(&s);
            let (f, _) = st.tension(&p, f64::NAN);
            assert!(f.is_nan(), "head_only {head_only}: {f}");
            // and the same stepper still answers a real strain
            let (f, k) = st.tension(&p, s.strain);
            assert!((f / 150.0 - 1.0).abs() < 0.02 && k > 0.0, "{f} {k}");
        }
    }

    /// A damped head whose spring stiffens, `f = f_s(e1) + c1 de1/dt`, driven by a
    /// sinusoidal strain (head alone: `e1` is the strain): the stepper's tension against
    /// that closed form (7.2e-3 N at 1 ms for a swing of 395 N), and its error falling
    /// as the step squared. The head once had its spring linearised as `k e1` with the
    /// tangent `k`: the dashpot then carried `f - k e1`, and the tension sat up to
    /// 1407 N off this law at any step (1409 N at 10 us): another law.
    #[test]
    fn a_damped_stiffening_head_follows_its_law_to_second_order() {
        let law = RopeLaw {
            stiffening_per_n: 2e-3,
            c1_n_s: 400.0,
            ..RopeLaw::elastic(7.29e4)
        };
        let (e0, a, w) = (4e-3, 1.5e-3, 2.0 * std::f64::consts::PI * 3.0);
        let strain = |t: f64| e0 + a * (w * t).sin();
        let exact = |t: f64| law.head_tension(strain(t)) + law.c1_n_s * a * w * (w * t).cos();
        // the largest error over 1 s against the closed form, after the start's transient
        let error = |dt_s: f64| {
            let st = RopeStepper::new(law.clone(), dt_s).unwrap();
            let mut s = st.rest_state(law.head_tension(e0), 0.0);
            // (the state at t = 0 is the closed form's: strain e0, rate a w)
            s.tension_n = exact(0.0);
            let n = (1.0 / dt_s).round() as usize;
            (1..=n)
                .map(|i| {
                    let t = i as f64 * dt_s;
                    let p = st.prepare(&s);
                    let f = st.commit(&p, &mut s, strain(t));
                    (f - exact(t)).abs()
                })
                .skip(n / 10)
                .fold(0.0, f64::max)
        };
        let amplitude = law.head_tension(e0 + a) - law.head_tension(e0 - a);
        let (coarse, fine) = (error(1e-3), error(0.5e-3));
        assert!(coarse < 2e-3 * amplitude, "{coarse} N of {amplitude} N");
        let order = (coarse / fine).log2();
        assert!(
            (1.7..2.5).contains(&order),
            "order {order}: {coarse} {fine}"
        );
    }

    /// The closed-form head solve ([`RopeStepper::solve_head`]) against the general
    /// safeguarded Newton on the step residual, step by step along strain histories
    /// that go slack, load past the ratchet's yield and swing fast: tensions equal within
    /// the solvers' tolerance (1e-12), slopes within 1e-6 (the general Newton returns its
    /// last iterate's slope, one converged step from the root; a Jacobian entry of the
    /// implicit step, whose error there only changes how its iterations converge).
    #[test]
    fn closed_form_head_solve_matches_the_general_newton() {
        let table = |x: &[f64], y: &[f64]| Some(Table::new(x, y).unwrap());
        let base = RopeLaw::four_element(7.29e4 * 1.5, 1.65e7, 8.9e5, 1.47e6);
        let laws = [
            RopeLaw {
                stiffening_per_n: 7.7e-4,
                ..base.clone()
            },
            RopeLaw {
                stiffening_per_n: 0.05,
                ..RopeLaw::elastic(7.29e4)
            },
            RopeLaw {
                stiffness_table: table(
                    &[0.0, 30.0, 67.0, 110.0, 151.0, 202.0, 260.0, 317.0],
                    &[1.0, 1.01, 1.03, 1.1, 1.17, 1.26, 1.3, 1.35],
                ),
                ..base.clone()
            },
            // a table that softens (falling values) and stiffens steeply
            RopeLaw {
                stiffness_table: table(&[0.0, 20.0, 100.0, 300.0], &[1.0, 0.4, 3.0, 5.0]),
                ..base.clone()
            },
            RopeLaw {
                stiffening_per_n: 2e-3,
                ..RopeLaw::flory(7.29e4, 1.65e7, 8.9e5, 1.47e6, 3e4)
            },
            RopeLaw {
                stiffness_table: table(&[0.0, 100.0, 400.0], &[1.0, 2.0, 2.2]),
                ..RopeLaw::flory(7.29e4, 1.65e7, 8.9e5, 1.47e6, 3e4)
            },
        ];
        let mut slack = 0;
        for (n, law) in laws.iter().enumerate() {
            for dt in [1.25e-3, 0.1] {
                let st = RopeStepper::new(law.clone(), dt).unwrap();
                assert!(st.head_only && !st.linear, "law {n}");
                let mut s = st.rest_state(150.0, if law.kp_n.is_some() { 200.0 } else { 0.0 });
                let e0 = s.strain;
                for i in 0..4000 {
                    let t = i as f64 * dt;
                    // 0.1 to 12 Hz, swinging from slack to well past the rest strain
                    let w = 2.0 * std::f64::consts::PI * (0.1 + 3.0 * (i % 1000) as f64 / 250.0);
                    let strain = e0 * (1.0 + 1.3 * (w * t).sin()) + 2e-3 * (i / 1000) as f64;
                    let p = st.prepare(&s);
                    if strain > p.slack_strain() {
                        let (f, k) = st.solve_head(&p, strain);
                        let (fr, kr) = st.solve_nonlinear(&p, strain);
                        assert!(
                            (f - fr).abs() <= 1e-12 * (1.0 + fr),
                            "law {n}, dt {dt}, step {i}: {f} vs {fr}"
                        );
                        assert!(
                            (k - kr).abs() <= 1e-6 * kr,
                            "law {n}, step {i}: {k} vs {kr}"
                        );
                    }
                    st.commit(&p, &mut s, strain);
                    assert!(s.tension_n.is_finite());
                    slack += usize::from(s.is_slack());
                }
            }
        }
        assert!(slack > 1000, "{slack} slack steps");
    }
}
