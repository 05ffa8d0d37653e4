//! Relay pulleys with friction and inertia in a rope pair: every rope of the pair is
//! split into spans at its relay pulleys, each span with its own rope state, and every
//! relay pulley (one per rope side) turns relative to what it is mounted on (the
//! proximal link of a joint, or the base), with its inertia and the load-dependent
//! bearing friction of [`RelayFriction`] ([`friction`]).
//!
//! # Kinematics
//!
//! A pair with `m` relays (in order along the rope from the motor; mounted relays at
//! joints `k_l`, radii `r_l`, crossing signs `s_l`) has `m + 1` spans per rope side: span
//! 0 from the motor pulley to relay 0, span `l + 1` from relay `l` to the next pulley,
//! span `m` ending at the joint pulley. A relay pulley mounted at a joint sits on the
//! proximal link of that joint (concentric with the joint axis), so a rotation `q_k` of
//! the joint changes the wrap on the distal side of the pulley; a relay fixed to the
//! base (the idlers of the paper's rig) adds no joint term. The elongation of span `i`
//! of rope side `sigma = +-1` is
//!
//! ```text
//! e_i = o_i + [i = 0] (x + sigma r_m theta) - sigma G_i . q + [i >= 1] (-r_{i-1} psi_{i-1}) + [i < m] r_i psi_i
//! ```
//!
//! with `G_{l+1}[k_l] = s_l r_l` for a mounted relay, `G_m[j] += r_j` (rows of `G` sum to
//! the routing row `R[p]`), `psi_l` the relay angle relative to its mount (positive when
//! the rope moves towards the joint) and `o_i` constant offsets fixed at the initial
//! state (every span of a rope at the same tension). The rope energy `V = n sum_i W(e_i)`
//! gives the joint torques `n sum sigma f_i G_i`, the motor load `n r_m (f+_0 - f-_0)`
//! and, per relay pulley, the law of [`RelayFriction`]:
//!
//! ```text
//! J psi_l'' + tau_f(psi_l', f_l + f_{l+1}) + r_l (f_l - f_{l+1}) = 0
//! tau_f = coefficient r_l (f_l + f_{l+1}) tanh(psi_l' / slip_rate)
//! ```
//!
//! With `coefficient = 0` and `inertia = 0` every span of a rope carries the same
//! tension and the pair is the ideal pair of [`super`]. The `n` ropes in parallel each
//! run over their own relay pulleys (inertia counted `n` times).
//!
//! # Integration
//!
//! The relay angles join the motor angle and the tensioner stretch as the local
//! unknowns `z = [theta, x, psi+_0.., psi-_0..]` of the pair in the implicit step
//! (trapezoidal rule, exact-hold ropes per span). The local block is a chain per rope
//! bordered by the motor and tensioner rows; it is eliminated along that structure
//! ([`factor`]). Friction makes it non-symmetric, so the joint matrix of a plant with
//! friction is solved by LU (threshold pivoting) instead of Cholesky.
//!
//! The module is split by job: the compiled chain and its state (here), the friction
//! law ([`friction`]), the factorisation of the local block and of the joint matrix
//! ([`factor`]), the assembly of residuals and derivatives, the step's start and commit
//! ([`assembly`]), and the Newton safeguards for the non-smooth parts ([`safeguards`]).

pub mod assembly;
pub mod factor;
pub mod friction;
pub mod safeguards;

pub use friction::{RelayFriction, RelayTorque};

/// The time rule of the relay pulleys' rotation, backward Euler (the other unknowns of
/// the step take the trapezoidal rule): first order, L-stable. A sticking pulley is a
/// very stiff damper (the regularised friction's slope); the trapezoidal rule's
/// amplification tends to -1 on it, backward Euler's to 0: the relay modes, far above
/// the band of interest, are damped by the step instead of ringing, and the Newton
/// iteration starts closer. The rig's relay modes lie two decades above its 2-4 Hz; the
/// arm's lie above the band its sensors resolve (100-300 Hz for the shipped 0.005
/// kg*m^2 pulleys, kHz for light ones).
///
/// The arm's relays took the trapezoidal rule until 2026-11-27: on longreach5 with 8 kg
/// moving j2 and light relay pulleys (c = 0.01, 2e-5 kg*m^2) its Newton iteration
/// diverged at t = 1.64 s (1 ms) and 1.98 s (0.25 ms), where backward Euler runs
/// through. On the shipped relay-friction arm scenario the two rules differed by at
/// most 4e-4 rad at 0.125 ms, ten times less than either differs from itself between
/// 1 ms and 0.125 ms (docs/arm.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RelayRule;

impl RelayRule {
    /// End rate and acceleration of a step of `h` that moves a relay by `dpsi` from
    /// rate `w0` (backward Euler needs no start acceleration).
    #[inline]
    pub fn end_rates(h: f64, dpsi: f64, w0: f64) -> (f64, f64) {
        let w1 = dpsi / h;
        (w1, (w1 - w0) / h)
    }

    /// `(d w1 / d psi1, d a1 / d psi1)` of [`Self::end_rates`].
    #[inline]
    pub fn slopes(h: f64) -> (f64, f64) {
        (1.0 / h, 1.0 / (h * h))
    }

    /// The predicted end angle of a step from `(psi0, w0, a0)`: the end rate
    /// extrapolated from the last two, `w1 ~ w0 + h a0`.
    #[inline]
    pub fn predict(h: f64, psi0: f64, w0: f64, a0: f64) -> f64 {
        psi0 + h * (w0 + h * a0)
    }

    /// The end angle at which the end rate is zero.
    #[inline]
    pub fn at_rest(psi0: f64) -> f64 {
        psi0
    }
}

use longreach_rope::{RopeState, RopeStepper};

use super::spec::PairSpec;

/// Relay friction of one pair compiled for the step.
#[derive(Debug, Clone)]
pub struct CompiledRelays {
    /// The friction law of every relay pulley of the pair.
    pub friction: RelayFriction,
    /// Joint each relay turns about (`None`: fixed to the base), in order along the rope.
    pub joints: Vec<Option<usize>>,
    /// Radius of each relay, m.
    pub radius_m: Vec<f64>,
    /// Length of each span (motor side first, `relays + 1`), m; sums to the rope length.
    pub span_length_m: Vec<f64>,
    /// `1 / span_length_m`.
    pub inv_span_length: Vec<f64>,
    /// Joints the span elongations depend on (sorted).
    pub cols: Vec<usize>,
    /// `G` (spans x cols), m: span `i` of rope `+` shortens by `G_i . q`.
    pub geometry_m: Vec<f64>,
    /// The non-zero entries `(index in cols, G_i[col])` of every row of `G`, span `i`
    /// at `sparse_start[i]..sparse_start[i + 1]` (at most two per span).
    sparse: Vec<(usize, f64)>,
    sparse_start: Vec<usize>,
}

impl CompiledRelays {
    /// Compiles the relays of `pair` (validated): its route in order along the rope
    /// (relays fixed to the base first, then by joint), the spans of
    /// [`PairSpec::span_lengths_m`] (equal spans when it does not hold one length per
    /// span), the span geometry `G` of the mounted relays.
    pub fn new(pair: &PairSpec, friction: RelayFriction) -> Self {
        let mut route = pair.route.clone();
        route.sort_by_key(|r| r.joint);
        let m = route.len();
        let span_length_m = if pair.span_lengths_m.len() == m + 1 {
            pair.span_lengths_m.clone()
        } else {
            vec![pair.length_m / (m + 1) as f64; m + 1]
        };
        let mut cols: Vec<usize> = route
            .iter()
            .filter_map(|r| r.joint)
            .chain(std::iter::once(pair.joint))
            .collect();
        cols.sort_unstable();
        cols.dedup();
        let nc = cols.len();
        let col = |j: usize| cols.iter().position(|&c| c == j).unwrap_or(0);
        let mut geometry_m = vec![0.0; (m + 1) * nc];
        for (l, r) in route.iter().enumerate() {
            if let Some(k) = r.joint {
                geometry_m[(l + 1) * nc + col(k)] += r.sign * r.radius_m;
            }
        }
        geometry_m[m * nc + col(pair.joint)] += pair.joint_radius_m;
        let mut sparse = Vec::new();
        let mut sparse_start = vec![0];
        for row in geometry_m.chunks_exact(nc) {
            sparse.extend(
                row.iter()
                    .enumerate()
                    .filter(|(_, g)| **g != 0.0)
                    .map(|(a, g)| (a, *g)),
            );
            sparse_start.push(sparse.len());
        }
        Self {
            friction,
            joints: route.iter().map(|r| r.joint).collect(),
            radius_m: route.iter().map(|r| r.radius_m).collect(),
            inv_span_length: span_length_m.iter().map(|l| 1.0 / l).collect(),
            span_length_m,
            cols,
            geometry_m,
            sparse,
            sparse_start,
        }
    }

    /// Relay pulleys per rope side.
    pub fn relays(&self) -> usize {
        self.radius_m.len()
    }

    /// Spans per rope side.
    pub fn spans(&self) -> usize {
        self.span_length_m.len()
    }

    /// Local unknowns of the pair in the step: motor, tensioner, relays of both sides.
    pub fn unknowns(&self) -> usize {
        2 + 2 * self.relays()
    }

    /// Index of the motor angle among the local unknowns, in the order
    /// `[psi+_{m-1} .. psi+_0, theta, x, psi-_0 .. psi-_{m-1}]` (each rope's relays
    /// from the joint end towards the border rows, as [`LocalFactor`] eliminates them).
    pub fn iz_theta(&self) -> usize {
        self.relays()
    }

    /// Index of the tensioner stretch among the local unknowns.
    pub fn iz_x(&self) -> usize {
        self.relays() + 1
    }

    /// Index of relay `l` of rope `side` among the local unknowns.
    pub fn iz_psi(&self, side: usize, l: usize) -> usize {
        iz_psi(self.relays(), side, l)
    }

    /// The non-zero entries `(index in cols, G_i[col])` of span `i`'s row of `G`.
    pub(crate) fn span_geometry(&self, i: usize) -> &[(usize, f64)] {
        &self.sparse[self.sparse_start[i]..self.sparse_start[i + 1]]
    }

    /// `G_i . q` of span `i`, m (the zero entries of `G` left out: same sum).
    pub(crate) fn gq(&self, i: usize, q: &[f64]) -> f64 {
        self.span_geometry(i)
            .iter()
            .map(|&(a, g)| g * q[self.cols[a]])
            .sum()
    }

    /// Derivative of the elongation of span `i` of rope `side` with respect to the
    /// free local unknowns (motor radius `rm`; the motor angle and the tensioner
    /// stretch only when free): at most four entries `(unknown, value)`. A held unknown
    /// keeps an identity row with a zero right side, so its update is zero and its
    /// column can be left out; left in, its entries (span stiffnesses, about 3e4 N/m,
    /// against the identity's 1) would make every LU interchange rows.
    pub(crate) fn span_local_derivative(
        &self,
        side: usize,
        i: usize,
        rm: f64,
        motor_free: bool,
        x_free: bool,
    ) -> ([(usize, f64); 4], usize) {
        let m = self.relays();
        let sg = if side == 0 { 1.0 } else { -1.0 };
        let mut out = [(0usize, 0.0f64); 4];
        let mut len = 0;
        if i == 0 {
            if motor_free {
                out[len] = (self.iz_theta(), sg * rm);
                len += 1;
            }
            if x_free {
                out[len] = (self.iz_x(), 1.0);
                len += 1;
            }
        }
        if i >= 1 {
            out[len] = (self.iz_psi(side, i - 1), -self.radius_m[i - 1]);
            len += 1;
        }
        if i < m {
            out[len] = (self.iz_psi(side, i), self.radius_m[i]);
            len += 1;
        }
        (out, len)
    }
}

/// Index of relay `l` of rope `side` among the local unknowns of a pair with `m` relays
/// per rope (see [`CompiledRelays::iz_theta`]).
pub(crate) fn iz_psi(m: usize, side: usize, l: usize) -> usize {
    if side == 0 {
        m - 1 - l
    } else {
        m + 2 + l
    }
}

/// State of the spans and relay pulleys of one pair with relay friction (empty for a
/// pair without).
#[derive(Debug, Clone, Default)]
pub struct RelayState {
    /// Rope state `[+, -]` of every span, motor side first (one rope of the `n`).
    pub spans: Vec<[RopeState; 2]>,
    /// Angle of every relay pulley of the `[+, -]` rope relative to its mount, rad
    /// (positive when the rope moves towards the joint).
    pub angle_rad: Vec<[f64; 2]>,
    /// Relay rates, rad/s.
    pub rate_rad_s: Vec<[f64; 2]>,
    /// Relay accelerations, rad/s^2.
    pub accel_rad_s2: Vec<[f64; 2]>,
    /// Constant elongation offsets `o_i` of every span, m.
    pub offset_m: Vec<[f64; 2]>,
}

impl RelayState {
    /// The state of a pair at rest at joint angles `q`, motor angle `theta_rad` and
    /// tensioner stretch `x_m`, every span of rope `+` (`-`) at `tension_n[0]` (`[1]`).
    pub fn at_rest(
        c: &CompiledRelays,
        stepper: &RopeStepper,
        motor_radius_m: f64,
        prestretch_n: f64,
        tension_n: [f64; 2],
        q: &[f64],
        theta_rad: f64,
        x_m: f64,
    ) -> Self {
        let m = c.relays();
        let rest = [
            stepper.rest_state(tension_n[0], prestretch_n),
            stepper.rest_state(tension_n[1], prestretch_n),
        ];
        let mut offset_m = vec![[0.0; 2]; m + 1];
        for (i, o) in offset_m.iter_mut().enumerate() {
            for (side, sg) in [(0, 1.0), (1, -1.0)] {
                let e = rest[side].strain * c.span_length_m[i];
                let mut terms = -sg * c.gq(i, q);
                if i == 0 {
                    terms += x_m + sg * motor_radius_m * theta_rad;
                }
                o[side] = e - terms;
            }
        }
        Self {
            spans: vec![rest; m + 1],
            angle_rad: vec![[0.0; 2]; m],
            rate_rad_s: vec![[0.0; 2]; m],
            accel_rad_s2: vec![[0.0; 2]; m],
            offset_m,
        }
    }

    /// Kinetic energy of the relay pulleys of one rope set, J (multiply by `n`).
    pub fn kinetic_j(&self, c: &CompiledRelays) -> f64 {
        self.rate_rad_s
            .iter()
            .flatten()
            .map(|w| 0.5 * c.friction.inertia_kg_m2 * w * w)
            .sum()
    }
}
