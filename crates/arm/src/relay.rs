//! Relay-pulley friction in the arm transmissions: every rope of a pair is split into
//! spans at its relay pulleys, each span with its own rope state, and every relay
//! pulley (one per rope side) turns relative to the link it is mounted on, with its
//! inertia and the load-dependent bearing friction of [`RelayFriction`]
//! (crates/drive/src/relay.rs).
//!
//! # Kinematics
//!
//! A pair with `m` relays (base first, at joints `k_0 .. k_{m-1}`, radii `r_l`, crossing
//! signs `s_l`) has `m + 1` spans per rope side: span 0 from the motor pulley to relay 0,
//! span `l + 1` from relay `l` to the next pulley, span `m` ending at the joint pulley.
//! Each relay pulley sits on the proximal link of its joint (concentric with the
//! joint axis), so a rotation `q_k` of the joint changes the wrap on the distal side
//! of the pulley. The elongation of span `i` of rope side `sigma = +-1` is
//!
//! ```text
//! e_i = o_i + [i = 0] (x + sigma r_m theta) - sigma G_i . q + [i >= 1] (-r_{i-1} psi_{i-1}) + [i < m] r_i psi_i
//! ```
//!
//! with `G_{l+1}[k_l] = s_l r_l`, `G_m[j] += r_j` (rows of `G` sum to the routing row
//! `R[p]`), `psi_l` the relay angle relative to its mount (positive when the rope moves
//! towards the joint) and `o_i` constant offsets fixed at the initial state (every span
//! of a rope at the same tension). The rope energy `V = n sum_i W(e_i)` gives the joint
//! torques `n sum sigma f_i G_i`, the motor load `n r_m (f+_0 - f-_0)` and, per relay
//! pulley, the law of `longreach_drive::relay`:
//!
//! ```text
//! J psi_l'' + tau_f(psi_l', f_l + f_{l+1}) + r_l (f_l - f_{l+1}) = 0
//! tau_f = coefficient r_l (f_l + f_{l+1}) tanh(psi_l' / slip_rate)
//! ```
//!
//! With `coefficient = 0` and `inertia = 0` every span of a rope carries the same
//! tension and the pair is the ideal pair of [`crate::transmission`]. The `n` ropes in
//! parallel each run over their own relay pulleys (inertia counted `n` times).
//!
//! # Integration
//!
//! The relay angles join the motor angle and the tensioner stretch as the local
//! unknowns `z = [theta, x, psi+_0.., psi-_0..]` of the pair in the implicit step
//! (trapezoidal rule, exact-hold ropes per span). The local block is a chain per rope
//! bordered by the motor and tensioner rows; it is eliminated along that structure
//! ([`LocalFactor`]). Friction makes it non-symmetric, so the `n x n` joint matrix of
//! an arm with friction is solved by LU (threshold pivoting) instead of Cholesky.

use longreach_drive::{RelayFriction, RelayTorque};
use longreach_rope::{PreparedStep, RopeState, RopeStepper};

use crate::spec::ArmSpec;
use crate::transmission::{proximal_joints, PairSpec};

/// Relay friction of one pair compiled for the step.
#[derive(Debug, Clone)]
pub struct CompiledRelays {
    /// The friction law of every relay pulley of the pair.
    pub friction: RelayFriction,
    /// Joint of each relay, base first.
    pub joints: Vec<usize>,
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
    /// Compiles the relays of `pair` on `spec`. Span lengths come from the URDF
    /// geometry (`PairSpec::span_lengths_m` along the chain, cut at the relay joints)
    /// scaled to `length_m`; when the route does not follow the chain (or a span would
    /// have zero length) the rope is split into equal spans.
    pub fn new(spec: &ArmSpec, pair: &PairSpec, friction: RelayFriction) -> Self {
        let mut route = pair.route.clone();
        route.sort_by_key(|r| r.joint);
        let m = route.len();
        let span_length_m = span_lengths(
            spec,
            pair,
            &route.iter().map(|r| r.joint).collect::<Vec<_>>(),
        );
        let mut cols: Vec<usize> = route
            .iter()
            .map(|r| r.joint)
            .chain(std::iter::once(pair.joint))
            .collect();
        cols.sort_unstable();
        cols.dedup();
        let nc = cols.len();
        let col = |j: usize| cols.iter().position(|&c| c == j).unwrap_or(0);
        let mut geometry_m = vec![0.0; (m + 1) * nc];
        for (l, r) in route.iter().enumerate() {
            geometry_m[(l + 1) * nc + col(r.joint)] += r.sign * r.radius_m;
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
    pub(crate) fn iz_theta(&self) -> usize {
        self.relays()
    }

    /// Index of the tensioner stretch among the local unknowns.
    pub(crate) fn iz_x(&self) -> usize {
        self.relays() + 1
    }

    /// Index of relay `l` of rope `side` among the local unknowns.
    pub(crate) fn iz_psi(&self, side: usize, l: usize) -> usize {
        iz_psi(self.relays(), side, l)
    }

    /// The non-zero entries `(index in cols, G_i[col])` of span `i`'s row of `G`.
    fn span_geometry(&self, i: usize) -> &[(usize, f64)] {
        &self.sparse[self.sparse_start[i]..self.sparse_start[i + 1]]
    }

    /// `G_i . q` of span `i`, m (the zero entries of `G` left out: same sum).
    fn gq(&self, i: usize, q: &[f64]) -> f64 {
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
    fn span_local_derivative(
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
fn iz_psi(m: usize, side: usize, l: usize) -> usize {
    if side == 0 {
        m - 1 - l
    } else {
        m + 2 + l
    }
}

/// Span lengths of the pair cut at `relay_joints` (sorted), scaled to `length_m`.
fn span_lengths(spec: &ArmSpec, pair: &PairSpec, relay_joints: &[usize]) -> Vec<f64> {
    let m = relay_joints.len();
    let equal = vec![pair.length_m / (m + 1) as f64; m + 1];
    let chain: Vec<usize> = proximal_joints(spec, pair.joint)
        .into_iter()
        .chain(std::iter::once(pair.joint))
        .collect();
    if pair.span_lengths_m.len() != chain.len() {
        return equal;
    }
    // Distance of each chain joint from the motor pulley along the rope.
    let mut pos = Vec::with_capacity(chain.len());
    let mut acc = 0.0;
    for s in &pair.span_lengths_m {
        acc += s;
        pos.push(acc);
    }
    let at = |j: usize| chain.iter().position(|&c| c == j).map(|i| pos[i]);
    let mut cuts = Vec::with_capacity(m + 2);
    cuts.push(0.0);
    for &j in relay_joints {
        match at(j) {
            Some(p) => cuts.push(p),
            None => return equal,
        }
    }
    cuts.push(acc);
    let spans: Vec<f64> = cuts.windows(2).map(|w| w[1] - w[0]).collect();
    if acc <= 0.0 || spans.iter().any(|s| !(s.is_finite() && *s > 1e-9 * acc)) {
        return equal;
    }
    let scale = pair.length_m / acc;
    spans.iter().map(|s| s * scale).collect()
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

/// The motor row of the local block.
#[derive(Debug, Clone, Copy)]
pub(crate) enum MotorRow {
    /// The motor angle is given.
    Fixed,
    /// Servo: residual without the rope load (N*m) and its derivative (N*m/rad).
    Servo { residual_n_m: f64, diag: f64 },
}

/// Per-pair scratch of the step.
#[derive(Debug, Clone)]
pub(crate) struct RelayScratch {
    /// Relay angles at the end of the step, `[psi+_0.., psi-_0..]`.
    pub psi1: Vec<f64>,
    /// Prepared rope steps, index `side * spans + i`.
    pub prep: Vec<PreparedStep>,
    f: Vec<f64>,
    k: Vec<f64>,
    /// The factor of the local block `K_zz` kept from the last assembly.
    factor: LocalFactor,
    kqz: Vec<f64>,
    /// `[r_z | K_zq]` (unknowns x (1 + cols), row-major), then after the solve
    /// `[K_zz^-1 r_z | K_zz^-1 K_zq]`.
    rhs: Vec<f64>,
    /// Local derivatives of every span's elongation (index `side * spans + i`).
    de: Vec<([(usize, f64); 4], usize)>,
    tmp: Vec<f64>,
    /// Relay rows pinned at the last assembly (`psi` held: no inertia, no friction,
    /// both spans slack).
    pinned: Vec<bool>,
    /// `K_zz^-1 r_z` of a chord iteration.
    y: Vec<f64>,
    /// Newton update of the local unknowns.
    pub dz: Vec<f64>,
    /// Last Newton update (undamped) of each relay angle, rad.
    prev_step: Vec<f64>,
    /// Step factor of each relay angle (halved when its updates oscillate).
    damping: Vec<f64>,
    /// Relays whose last update jumped across the stick band.
    crossed: Vec<bool>,
    /// Tridiagonal system of one rope side's relays (sub, diagonal, super, right side).
    tri: Vec<[f64; 4]>,
}

impl RelayScratch {
    pub(crate) fn new(c: &CompiledRelays, prep0: PreparedStep) -> Self {
        let (l, nc, s) = (c.unknowns(), c.cols.len(), 2 * c.spans());
        Self {
            psi1: vec![0.0; 2 * c.relays()],
            prep: vec![prep0; s],
            f: vec![0.0; s],
            k: vec![0.0; s],
            factor: LocalFactor::new(c.relays()),
            kqz: vec![0.0; nc * l],
            rhs: vec![0.0; l * (nc + 1)],
            de: vec![([(0, 0.0); 4], 0); s],
            tmp: vec![0.0; nc + 1],
            pinned: vec![false; l],
            y: vec![0.0; l],
            dz: vec![0.0; l],
            prev_step: vec![0.0; 2 * c.relays()],
            damping: vec![1.0; 2 * c.relays()],
            crossed: vec![false; 2 * c.relays()],
            tri: vec![[0.0; 4]; c.relays()],
        }
    }
}

/// The factor of a pair's local block `K_zz`, kept for the chord iterations. The block
/// is a chain per rope (each relay row couples to its neighbours along the rope) whose
/// first relay also couples to the two border unknowns, motor angle and tensioner
/// stretch; each chain is eliminated from its far end towards the motor (the Thomas
/// algorithm), the first relays into the border, and the `2 x 2` border solved. No
/// pivoting: a relay row's diagonal is its inertia and friction slope plus the sum of
/// the magnitudes of its neighbour entries (both spans' stiffness times `r^2`; with
/// the friction's hub-load term when the radii are equal), so the chain is diagonally
/// dominant and elimination keeps it so. A zero or non-finite pivot reports the block
/// singular.
#[derive(Debug, Clone)]
struct LocalFactor {
    /// Diagonal of relay row `side * m + l`, then its pivot after elimination.
    dia: Vec<f64>,
    /// Entry of relay row `l` at relay `l - 1` of the same rope (towards the motor).
    sub: Vec<f64>,
    /// Entry of relay row `l` at relay `l + 1` of the same rope (towards the joint).
    sup: Vec<f64>,
    /// Elimination multiplier of relay row `l` into row `l - 1`.
    mult: Vec<f64>,
    /// `1 / pivot` of every relay row.
    inv: Vec<f64>,
    /// Entries of the first relay row of each rope at `[theta, x]`.
    edge: [[f64; 2]; 2],
    /// Entries of the border rows `[theta, x]` at the first relay of each rope.
    couple: [[f64; 2]; 2],
    /// Elimination multipliers of the first relay rows into the border rows.
    gmul: [[f64; 2]; 2],
    /// The border block `[theta, x] x [theta, x]`, then its Schur complement.
    border: [[f64; 2]; 2],
    /// Inverse of the border's Schur complement.
    binv: [[f64; 2]; 2],
}

impl LocalFactor {
    fn new(m: usize) -> Self {
        Self {
            dia: vec![1.0; 2 * m],
            sub: vec![0.0; 2 * m],
            sup: vec![0.0; 2 * m],
            mult: vec![0.0; 2 * m],
            inv: vec![1.0; 2 * m],
            edge: [[0.0; 2]; 2],
            couple: [[0.0; 2]; 2],
            gmul: [[0.0; 2]; 2],
            border: [[1.0, 0.0], [0.0, 1.0]],
            binv: [[1.0, 0.0], [0.0, 1.0]],
        }
    }

    /// Factors the block set up in `dia`, `sub`, `sup`, `edge`, `couple` and `border`
    /// (`m` relays per rope); false when a pivot is zero or not finite.
    fn factor(&mut self, m: usize) -> bool {
        let regular = |p: f64| p != 0.0 && p.is_finite();
        for side in 0..2 {
            let base = side * m;
            for l in (1..m).rev() {
                let piv = self.dia[base + l];
                if !regular(piv) {
                    return false;
                }
                self.inv[base + l] = 1.0 / piv;
                let f = self.sup[base + l - 1] / piv;
                self.mult[base + l] = f;
                self.dia[base + l - 1] -= f * self.sub[base + l];
            }
            if m > 0 {
                let piv = self.dia[base];
                if !regular(piv) {
                    return false;
                }
                self.inv[base] = 1.0 / piv;
                for beta in 0..2 {
                    let g = self.couple[beta][side] / piv;
                    self.gmul[beta][side] = g;
                    self.border[beta][0] -= g * self.edge[side][0];
                    self.border[beta][1] -= g * self.edge[side][1];
                }
            }
        }
        let [[a, b], [c, d]] = self.border;
        let det = a * d - b * c;
        if !regular(det) {
            return false;
        }
        self.binv = [[d / det, -b / det], [-c / det, a / det]];
        true
    }

    /// Solves `K_zz X = B` in place for the `w` columns of `b` (unknowns x `w`,
    /// row-major, rows in the order of [`CompiledRelays::iz_theta`]).
    fn solve(&self, m: usize, b: &mut [f64], w: usize) {
        let (it, ix) = (m, m + 1);
        for side in 0..2 {
            let base = side * m;
            for l in (1..m).rev() {
                let f = self.mult[base + l];
                let (dst, src) = two_rows(b, w, iz_psi(m, side, l - 1), iz_psi(m, side, l));
                for (x, y) in dst.iter_mut().zip(src) {
                    *x -= f * y;
                }
            }
            if m > 0 {
                let first = iz_psi(m, side, 0);
                for (border, row) in [it, ix].into_iter().enumerate() {
                    let f = self.gmul[border][side];
                    let (dst, src) = two_rows(b, w, row, first);
                    for (x, y) in dst.iter_mut().zip(src) {
                        *x -= f * y;
                    }
                }
            }
        }
        let [[p, q], [r, s]] = self.binv;
        {
            let (bt, bx) = b[it * w..(ix + 1) * w].split_at_mut(w);
            for (u, v) in bt.iter_mut().zip(bx.iter_mut()) {
                (*u, *v) = (p * *u + q * *v, r * *u + s * *v);
            }
        }
        if m == 0 {
            return;
        }
        for side in 0..2 {
            let base = side * m;
            let [et, ex] = self.edge[side];
            let inv = self.inv[base];
            let first = iz_psi(m, side, 0);
            // The border rows follow each other (`it`, `ix`), next to both first relays.
            let (row, border) = two_rows(b, w, first, it);
            let (bt, bx) = (&border[..w], &border[w..2 * w]);
            for ((v, t), x) in row.iter_mut().zip(bt).zip(bx) {
                *v = (*v - et * t - ex * x) * inv;
            }
            for l in 1..m {
                let (sub, inv) = (self.sub[base + l], self.inv[base + l]);
                let (row, prev) = two_rows(b, w, iz_psi(m, side, l), iz_psi(m, side, l - 1));
                for (x, y) in row.iter_mut().zip(prev) {
                    *x = (*x - sub * y) * inv;
                }
            }
        }
    }

    /// [`Self::solve`] for one right side (the chord iterations), same arithmetic.
    fn solve_one(&self, m: usize, b: &mut [f64]) {
        let (it, ix) = (m, m + 1);
        for side in 0..2 {
            let base = side * m;
            for l in (1..m).rev() {
                b[iz_psi(m, side, l - 1)] -= self.mult[base + l] * b[iz_psi(m, side, l)];
            }
            if m > 0 {
                let first = b[iz_psi(m, side, 0)];
                b[it] -= self.gmul[0][side] * first;
                b[ix] -= self.gmul[1][side] * first;
            }
        }
        let [[p, q], [r, s]] = self.binv;
        let (u, v) = (b[it], b[ix]);
        (b[it], b[ix]) = (p * u + q * v, r * u + s * v);
        if m == 0 {
            return;
        }
        for side in 0..2 {
            let base = side * m;
            let [et, ex] = self.edge[side];
            let first = iz_psi(m, side, 0);
            b[first] = (b[first] - et * b[it] - ex * b[ix]) * self.inv[base];
            for l in 1..m {
                let prev = b[iz_psi(m, side, l - 1)];
                let row = iz_psi(m, side, l);
                b[row] = (b[row] - self.sub[base + l] * prev) * self.inv[base + l];
            }
        }
    }
}

/// Row `dst` (mutable) and the rows from `src` on (`w` entries each, row-major `b`),
/// `dst != src`.
fn two_rows(b: &mut [f64], w: usize, dst: usize, src: usize) -> (&mut [f64], &[f64]) {
    if dst < src {
        let (lo, hi) = b.split_at_mut(src * w);
        (&mut lo[dst * w..(dst + 1) * w], hi)
    } else {
        let (lo, hi) = b.split_at_mut(dst * w);
        (&mut hi[..w], &lo[src * w..])
    }
}

/// What [`assemble`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Assembly {
    /// Contributions added.
    Done,
    /// Both motor-side spans were slack under a constant-force tensioner: `x` was moved
    /// to take up the slack; redo the iteration.
    Retry,
    /// The local block is singular.
    Singular,
}

/// Inputs of one pair's local block at one Newton iteration.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Local<'a> {
    pub h: f64,
    pub n: f64,
    pub motor_radius_m: f64,
    pub motor: MotorRow,
    /// `Some(preload)` for a constant-force tensioner.
    pub constant_force_n: Option<f64>,
    pub theta_rad: f64,
    pub q: &'a [f64],
    pub state: &'a RelayState,
}

/// Elongation of span `i` of side `side` at the trial state, m (`gq = G_i . q`, the
/// same for both sides of span `i`).
fn elongation(
    c: &CompiledRelays,
    inp: &Local<'_>,
    gq: f64,
    x_m: f64,
    psi: &[f64],
    side: usize,
    i: usize,
) -> f64 {
    let m = c.relays();
    let sg = if side == 0 { 1.0 } else { -1.0 };
    let mut e = inp.state.offset_m[i][side] - sg * gq;
    if i == 0 {
        e += x_m + sg * inp.motor_radius_m * inp.theta_rad;
    }
    if i >= 1 {
        e -= c.radius_m[i - 1] * psi[side * m + i - 1];
    }
    if i < m {
        e += c.radius_m[i] * psi[side * m + i];
    }
    e
}

/// Tension (N, per rope), stiffness (N/m) and strain of span `i` of side `side` at the
/// trial state (`gq = G_i . q`, the same for both sides) from the prepared steps.
fn span_tension(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    inp: &Local<'_>,
    gq: f64,
    x_m: f64,
    psi: &[f64],
    prep: &[PreparedStep],
    side: usize,
    i: usize,
) -> (f64, f64, f64) {
    let e = elongation(c, inp, gq, x_m, psi, side, i);
    let strain = e * c.inv_span_length[i];
    let (f, k, _) = stepper.tension_piece(&prep[side * c.spans() + i], strain);
    (f, k * c.inv_span_length[i], strain)
}

/// Tensions and stiffnesses of every span of both ropes at the trial state into
/// `sc.f`, `sc.k` (`G_i . q` once per span).
fn evaluate_spans(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    sc: &mut RelayScratch,
    inp: &Local<'_>,
    x_m: f64,
) {
    let ns = c.spans();
    for i in 0..ns {
        let gq = c.gq(i, inp.q);
        for side in 0..2 {
            let (f, k, _) = span_tension(c, stepper, inp, gq, x_m, &sc.psi1, &sc.prep, side, i);
            sc.f[side * ns + i] = f;
            sc.k[side * ns + i] = k;
        }
    }
}

/// [`evaluate_spans`]; false when both motor-side spans are slack under a
/// constant-force tensioner (`x_m` then moved to take up the slack: redo the
/// iteration).
fn span_tensions(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    sc: &mut RelayScratch,
    inp: &Local<'_>,
    x_m: &mut f64,
) -> bool {
    let ns = c.spans();
    evaluate_spans(c, stepper, sc, inp, *x_m);
    if inp.constant_force_n.is_some() && sc.k[0] + sc.k[ns] == 0.0 {
        // Both motor-side spans slack: the carriage takes up the slack first.
        let need = |side: usize| {
            let e = elongation(c, inp, c.gq(0, inp.q), *x_m, &sc.psi1, side, 0) - *x_m;
            sc.prep[side * ns].slack_strain() * c.span_length_m[0] - e
        };
        *x_m = need(0).min(need(1)) + 1e-12 * c.span_length_m.iter().sum::<f64>();
        return false;
    }
    true
}

/// Residual of the equation of relay `rl` of rope `side` (`J a1 + tau_f + r (f_l -
/// f_{l+1})`) and its friction torque, at the tensions in `fs`.
fn relay_residual(
    c: &CompiledRelays,
    inp: &Local<'_>,
    psi1: &[f64],
    fs: &[f64],
    side: usize,
    rl: usize,
) -> (f64, RelayTorque) {
    let (m, ns) = (c.relays(), c.spans());
    let h = inp.h;
    let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
    let r = c.radius_m[rl];
    let (fa, fb) = (fs[side * ns + rl], fs[side * ns + rl + 1]);
    let psi0 = inp.state.angle_rad[rl][side];
    let w0 = inp.state.rate_rad_s[rl][side];
    let a0 = inp.state.accel_rad_s2[rl][side];
    let dpsi = psi1[side * m + rl] - psi0;
    let w1 = two_h * dpsi - w0;
    let a1 = four_h2 * dpsi - 2.0 * two_h * w0 - a0;
    let t = c.friction.torque_n_m(r, fa + fb, w1);
    (
        c.friction.inertia_kg_m2 * a1 + t.torque_n_m + r * (fa - fb),
        t,
    )
}

/// Derivatives of the equation of relay `rl` (friction torque `t`, stiffnesses `ka`,
/// `kb` of its spans `rl` and `rl + 1`, step `h`) with respect to the relay angles of
/// its rope: the rope chain's row, which [`assemble`], [`relax_relays`] and
/// [`solve_crossed_relays`] all use.
#[derive(Debug, Clone, Copy)]
struct RelaySlopes {
    /// `(r + ts, -r + ts)`: the equation is `... + wa f_l + wb f_{l+1}`.
    wa: f64,
    wb: f64,
    /// At the relay itself (inertia, friction slope, both spans).
    diag: f64,
    /// At relay `rl - 1` (0 for the first relay).
    sub: f64,
    /// At relay `rl + 1` (0 for the last relay).
    sup: f64,
}

fn relay_slopes(
    c: &CompiledRelays,
    h: f64,
    t: &RelayTorque,
    ka: f64,
    kb: f64,
    rl: usize,
) -> RelaySlopes {
    let m = c.relays();
    let r = c.radius_m[rl];
    let ts = t.d_tension_sum_m;
    let (wa, wb) = (r + ts, -r + ts);
    RelaySlopes {
        wa,
        wb,
        diag: 4.0 / (h * h) * c.friction.inertia_kg_m2 + 2.0 / h * t.d_rate_n_m_s + wa * ka * r
            - wb * kb * r,
        sub: if rl > 0 {
            -wa * ka * c.radius_m[rl - 1]
        } else {
            0.0
        },
        sup: if rl + 1 < m {
            wb * kb * c.radius_m[rl + 1]
        } else {
            0.0
        },
    }
}

/// The chord iteration of [`assemble`]: the local block's factor, `K_zz^-1 K_zq` and
/// `K_qz` are kept from the last call of [`assemble`] (the joint matrix likewise by the
/// caller); only the residuals are evaluated at the trial state: `r_z` is solved with
/// the kept factor and the pair's part of `-r_q` and of its Schur complement added to
/// `rhs`.
#[inline(never)]
pub(crate) fn assemble_residual(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    sc: &mut RelayScratch,
    inp: &Local<'_>,
    x_m: &mut f64,
    rhs: &mut [f64],
) -> Assembly {
    let m = c.relays();
    let ns = c.spans();
    let l = c.unknowns();
    let w = c.cols.len() + 1;
    let (n, rm) = (inp.n, inp.motor_radius_m);
    if !span_tensions(c, stepper, sc, inp, x_m) {
        return Assembly::Retry;
    }
    let fs = &sc.f;
    let y = &mut sc.y;
    y.fill(0.0);
    if let MotorRow::Servo { residual_n_m, .. } = inp.motor {
        y[c.iz_theta()] = residual_n_m + n * rm * (fs[0] - fs[ns]);
    }
    if let Some(t) = inp.constant_force_n {
        y[c.iz_x()] = fs[0] + fs[ns] - 2.0 * t;
    }
    for side in 0..2 {
        for rl in 0..m {
            let row = c.iz_psi(side, rl);
            y[row] = if sc.pinned[row] {
                0.0
            } else {
                relay_residual(c, inp, &sc.psi1, fs, side, rl).0
            };
        }
    }
    for side in 0..2 {
        let sg = if side == 0 { 1.0 } else { -1.0 };
        for i in 0..ns {
            let f = fs[side * ns + i];
            for &(a, ga) in c.span_geometry(i) {
                rhs[c.cols[a]] += n * sg * f * ga;
            }
        }
    }
    sc.factor.solve_one(m, y);
    for (z, &v) in y.iter().enumerate() {
        sc.rhs[z * w] = v;
    }
    for (a, &ca) in c.cols.iter().enumerate() {
        let s: f64 = sc.kqz[a * l..(a + 1) * l]
            .iter()
            .zip(y.iter())
            .map(|(u, v)| u * v)
            .sum();
        rhs[ca] += s;
    }
    Assembly::Done
}

/// Adds the pair's contributions (Schur complement of its local unknowns) to the joint
/// matrix `kq` (`nq x nq`, row-major) and right-hand side `rhs` (`-r_q`); `x_m` is
/// moved when the carriage must take up slack.
#[inline(never)]
pub(crate) fn assemble(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    sc: &mut RelayScratch,
    inp: &Local<'_>,
    x_m: &mut f64,
    kq: &mut [f64],
    rhs: &mut [f64],
    nq: usize,
) -> Assembly {
    let m = c.relays();
    let ns = c.spans();
    let l = c.unknowns();
    let nc = c.cols.len();
    let (h, n, rm) = (inp.h, inp.n, inp.motor_radius_m);
    if !span_tensions(c, stepper, sc, inp, x_m) {
        return Assembly::Retry;
    }
    let w = nc + 1;
    let motor_free = matches!(inp.motor, MotorRow::Servo { .. });
    let x_free = inp.constant_force_n.is_some();
    sc.rhs.fill(0.0);
    sc.kqz.fill(0.0);
    for side in 0..2 {
        for i in 0..ns {
            sc.de[side * ns + i] = c.span_local_derivative(side, i, rm, motor_free, x_free);
        }
    }
    let (fs, ks) = (&sc.f, &sc.k);
    let brhs = &mut sc.rhs;
    let fa = &mut sc.factor;
    // Adds `-wt k_s sg G_s` (the derivative of `wt f_s` with respect to the joints) to
    // the `K_zq` part of row `row` (the zero entries of `G` left out).
    let add_kzq = |brhs: &mut [f64], row: usize, wt: f64, side: usize, i: usize| {
        let k = ks[side * ns + i];
        let sg = if side == 0 { 1.0 } else { -1.0 };
        let br = &mut brhs[row * w + 1..(row + 1) * w];
        for &(cc, g) in c.span_geometry(i) {
            br[cc] -= wt * k * sg * g;
        }
    };
    let (it, ix) = (c.iz_theta(), c.iz_x());
    let (kp, km) = (ks[0], ks[ns]);
    let r0 = c.radius_m.first().copied().unwrap_or(0.0);
    // Border rows (motor, tensioner): their 2 x 2 block and their entries at the
    // relays next to the motor (`psi+_0`, `psi-_0`); a held unknown has an identity row.
    fa.border = [[1.0, 0.0], [0.0, 1.0]];
    fa.couple = [[0.0; 2]; 2];
    if let MotorRow::Servo { residual_n_m, diag } = inp.motor {
        brhs[it * w] = residual_n_m + n * rm * (fs[0] - fs[ns]);
        fa.border[0][0] = diag + n * rm * rm * (kp + km);
        if x_free {
            fa.border[0][1] = n * rm * (kp - km);
        }
        fa.couple[0] = [n * rm * kp * r0, -n * rm * km * r0];
        add_kzq(brhs, it, n * rm, 0, 0);
        add_kzq(brhs, it, -n * rm, 1, 0);
    }
    if let Some(t) = inp.constant_force_n {
        brhs[ix * w] = fs[0] + fs[ns] - 2.0 * t;
        fa.border[1][1] = kp + km;
        if motor_free {
            fa.border[1][0] = rm * (kp - km);
        }
        fa.couple[1] = [kp * r0, km * r0];
        add_kzq(brhs, ix, 1.0, 0, 0);
        add_kzq(brhs, ix, 1.0, 1, 0);
    }
    // Relay rows: a chain per rope (relay `l` shares span `l + 1` with relay `l + 1`).
    for side in 0..2 {
        let sg = if side == 0 { 1.0 } else { -1.0 };
        for rl in 0..m {
            let row = c.iz_psi(side, rl);
            let k = side * m + rl;
            let (res, t) = relay_residual(c, inp, &sc.psi1, fs, side, rl);
            let ka = ks[side * ns + rl];
            let RelaySlopes {
                wa,
                wb,
                diag,
                sub,
                sup,
            } = relay_slopes(c, h, &t, ka, ks[side * ns + rl + 1], rl);
            sc.pinned[row] = diag == 0.0;
            if sc.pinned[row] {
                // No inertia, no friction and both spans slack: the pulley stays put.
                fa.dia[k] = 1.0;
                fa.sub[k] = 0.0;
                fa.sup[k] = 0.0;
                if rl == 0 {
                    fa.edge[side] = [0.0; 2];
                }
                continue;
            }
            brhs[row * w] = res;
            fa.dia[k] = diag;
            fa.sub[k] = sub;
            fa.sup[k] = sup;
            if rl == 0 {
                fa.edge[side] = [
                    if motor_free { wa * ka * sg * rm } else { 0.0 },
                    if x_free { wa * ka } else { 0.0 },
                ];
            }
            add_kzq(brhs, row, wa, side, rl);
            add_kzq(brhs, row, wb, side, rl + 1);
        }
    }
    // Joint rows: rhs = -r_q gets the rope torques, kq the span stiffnesses (the zero
    // entries of `G` left out).
    let (des, kqz) = (&sc.de, &mut sc.kqz);
    for side in 0..2 {
        let sg = if side == 0 { 1.0 } else { -1.0 };
        for i in 0..ns {
            let (f, k) = (fs[side * ns + i], ks[side * ns + i]);
            let geo = c.span_geometry(i);
            let (d, len) = &des[side * ns + i];
            for &(a, ga) in geo {
                let ca = c.cols[a];
                rhs[ca] += n * sg * f * ga;
                if k == 0.0 {
                    continue;
                }
                for &(b, gb) in geo {
                    kq[ca * nq + c.cols[b]] += n * k * ga * gb;
                }
                let kr = &mut kqz[a * l..(a + 1) * l];
                for &(z, v) in &d[..*len] {
                    kr[z] -= n * k * sg * ga * v;
                }
            }
        }
    }
    if !fa.factor(m) {
        return Assembly::Singular;
    }
    fa.solve(m, brhs, w);
    // K_qz [y | Y], every column summed over the unknowns in order.
    let acc = &mut sc.tmp[..w];
    for (a, &ca) in c.cols.iter().enumerate() {
        acc.fill(0.0);
        for (&u, yrow) in kqz[a * l..(a + 1) * l].iter().zip(brhs.chunks_exact(w)) {
            // Most unknowns do not touch a given joint's spans: skip their zero rows.
            if u == 0.0 {
                continue;
            }
            for (s, y) in acc.iter_mut().zip(yrow) {
                *s += u * y;
            }
        }
        rhs[ca] += acc[0];
        for (b, &cb) in c.cols.iter().enumerate() {
            kq[ca * nq + cb] -= acc[1 + b];
        }
    }
    Assembly::Done
}

/// The local update `dz = -K_zz^-1 (r_z + K_zq dq)` after the joint update `dq`.
#[inline(never)]
pub(crate) fn local_update(c: &CompiledRelays, sc: &mut RelayScratch, dq: &[f64]) {
    let w = c.cols.len() + 1;
    for (dz, row) in sc.dz.iter_mut().zip(sc.rhs.chunks_exact(w)) {
        let mut s = row[0];
        for (&y, &col) in row[1..].iter().zip(&c.cols) {
            s += y * dq[col];
        }
        *dz = -s;
    }
}

/// The largest local update `dz` (motor angle and relay angles, before the relay
/// safeguards) in tolerances, `|dz| / (tol (1 + |z|))`.
pub(crate) fn largest_update(c: &CompiledRelays, sc: &RelayScratch, tol: f64) -> f64 {
    let m = c.relays();
    let mut worst = 0.0f64;
    for side in 0..2 {
        for rl in 0..m {
            let d = sc.dz[c.iz_psi(side, rl)];
            worst = worst.max(d.abs() / (tol * (1.0 + sc.psi1[side * m + rl].abs())));
        }
    }
    worst.max(sc.dz[c.iz_theta()].abs() / tol)
}

/// Newton iterations of a step after which oscillating relay updates are damped.
pub(crate) const DAMP_AFTER_ITERATIONS: u32 = 16;

/// Applies the local update `dz` to the relay angles; returns whether every change is
/// within the tolerance and whether a safeguard changed the update. Two safeguards
/// keep Newton from cycling on the non-smooth parts of the relay equation: a relay
/// whose rate would jump across the stick band (from one sliding direction to the
/// other, beyond the slip rate: Newton on the regularised Coulomb law overshoots from
/// the sliding plateaus) is marked for [`solve_crossed_relays`], which solves its own
/// equation inside the band; and a relay whose updates flip sign without shrinking (a
/// span going slack and taut between iterates: a kink of the rope law on each side of
/// the pulley) after [`DAMP_AFTER_ITERATIONS`] Newton iterations takes half steps from
/// then on (bisection of the kink). A step never ends on a guarded iteration.
#[inline(never)]
pub(crate) fn apply_relay_update(
    c: &CompiledRelays,
    sc: &mut RelayScratch,
    state: &RelayState,
    h: f64,
    iteration: u32,
    tol: f64,
) -> RelayUpdate {
    let m = c.relays();
    let mut small = true;
    let mut guarded = false;
    for side in 0..2 {
        for rl in 0..m {
            let k = side * m + rl;
            let (psi0, w0) = (state.angle_rad[rl][side], state.rate_rad_s[rl][side]);
            let old = sc.psi1[k];
            let raw = sc.dz[c.iz_psi(side, rl)];
            if iteration > DAMP_AFTER_ITERATIONS
                && raw * sc.prev_step[k] < 0.0
                && raw.abs() > 0.9 * sc.prev_step[k].abs()
            {
                sc.damping[k] *= 0.5;
            }
            sc.prev_step[k] = raw;
            let mut new = old + raw * sc.damping[k];
            if jumps_stick_band(c, h, psi0, w0, old, new) {
                // Across the stick band: solved alone next ([`solve_crossed_relays`]).
                new = psi0 + 0.5 * h * w0;
                sc.crossed[k] = true;
                guarded = true;
            }
            guarded |= sc.damping[k] < 1.0;
            if (new - old).abs() > tol * (1.0 + new.abs()) {
                small = false;
            }
            sc.psi1[k] = new;
        }
    }
    RelayUpdate { small, guarded }
}

/// Solves the equation of every relay that [`apply_relay_update`] found jumping across
/// the stick band alone, every other unknown held at its trial value, for its angle.
/// `g(psi) = J a1 + tau_f + r (f_l - f_{l+1})` increases with `psi` (inertia,
/// friction slope and the stiffness of both spans add up; the hub-load term is
/// `coefficient` times smaller), so a Newton iteration kept inside a bracket (bisection
/// when it would leave it) finds its root; the global Newton iteration then goes on
/// from a point that meets the relay's own equation, inside the steep band, instead of
/// jumping from one sliding plateau to the other.
#[inline(never)]
pub(crate) fn solve_crossed_relays(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    sc: &mut RelayScratch,
    inp: &Local<'_>,
    x_m: f64,
    tol: f64,
) {
    let (m, ns) = (c.relays(), c.spans());
    let h = inp.h;
    for side in 0..2 {
        for rl in 0..m {
            let k = side * m + rl;
            if !std::mem::take(&mut sc.crossed[k]) {
                continue;
            }
            let (ia, ib) = (side * ns + rl, side * ns + rl + 1);
            let (gqa, gqb) = (c.gq(rl, inp.q), c.gq(rl + 1, inp.q));
            // g and dg/dpsi at the trial angle.
            let eval = |sc: &mut RelayScratch| {
                let (fa, ka, _) =
                    span_tension(c, stepper, inp, gqa, x_m, &sc.psi1, &sc.prep, side, rl);
                let (fb, kb, _) =
                    span_tension(c, stepper, inp, gqb, x_m, &sc.psi1, &sc.prep, side, rl + 1);
                sc.f[ia] = fa;
                sc.f[ib] = fb;
                let (g, t) = relay_residual(c, inp, &sc.psi1, &sc.f, side, rl);
                (g, relay_slopes(c, h, &t, ka, kb, rl).diag)
            };
            let mut lo = f64::NEG_INFINITY;
            let mut hi = f64::INFINITY;
            for _ in 0..60 {
                let psi = sc.psi1[k];
                let (g, dg) = eval(sc);
                if g == 0.0 {
                    break;
                }
                if g > 0.0 {
                    hi = psi;
                } else {
                    lo = psi;
                }
                let mut next = psi - g / dg;
                if !(next > lo && next < hi && next.is_finite()) {
                    next = if lo.is_finite() && hi.is_finite() {
                        0.5 * (lo + hi)
                    } else {
                        // No bracket yet: a Newton step (dg > 0) points towards the
                        // root; take it, at least a slip-rate's worth.
                        psi - (g / dg).signum()
                            * (g / dg).abs().max(0.5 * h * c.friction.slip_rate_rad_s)
                    };
                }
                sc.psi1[k] = next;
                if (next - psi).abs() <= 1e-3 * tol * (1.0 + next.abs()) {
                    break;
                }
            }
        }
    }
}

/// Whether moving a relay's end-of-step angle from `old` to `new` (rad; start of the
/// step at `psi0`, rate `w0`) takes its end rate from one sliding direction to the
/// other, beyond the slip rate: Newton on the regularised Coulomb law overshoots from
/// one plateau across the steep stick band. Such a relay is put in the band's middle,
/// end rate zero (`psi0 + h w0 / 2`).
fn jumps_stick_band(c: &CompiledRelays, h: f64, psi0: f64, w0: f64, old: f64, new: f64) -> bool {
    let w_old = 2.0 / h * (old - psi0) - w0;
    let w_new = 2.0 / h * (new - psi0) - w0;
    c.friction.coefficient > 0.0 && w_old * w_new < 0.0 && w_new.abs() > c.friction.slip_rate_rad_s
}

/// Newton iterations of [`relax_relays`] at most.
const RELAX_MAX_ITERATIONS: u32 = 6;

/// Newton on the relay equations of one pair alone, the joints, the motor and the
/// tensioner held at their trial values. Along one rope the relays form a chain (relay
/// `l` shares span `l + 1` with relay `l + 1`), so each iteration is a tridiagonal solve
/// with fresh derivatives, until every update is below a tenth of the tolerance. A relay
/// whose rate would jump across the stick band is put in its middle instead (as in
/// [`apply_relay_update`]); the next iteration has the band's slope.
///
/// The global Newton iteration that follows starts from relays that meet their own
/// equations at the joints' trial angles: on the relay-friction scenario a step takes
/// 1.45 iterations instead of 1.77 at the same tolerance (docs/arm.md, "Speed").
#[inline(never)]
pub(crate) fn relax_relays(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    sc: &mut RelayScratch,
    inp: &Local<'_>,
    x_m: f64,
    tol: f64,
) {
    let (m, ns) = (c.relays(), c.spans());
    let h = inp.h;
    for _ in 0..RELAX_MAX_ITERATIONS {
        let mut worst = 0.0f64;
        // The two ropes' relays do not share a span: both are solved from one
        // evaluation.
        evaluate_spans(c, stepper, sc, inp, x_m);
        for side in 0..2 {
            for rl in 0..m {
                let (g, t) = relay_residual(c, inp, &sc.psi1, &sc.f, side, rl);
                let (ka, kb) = (sc.k[side * ns + rl], sc.k[side * ns + rl + 1]);
                let d = relay_slopes(c, h, &t, ka, kb, rl);
                sc.tri[rl] = [d.sub, d.diag, d.sup, -g];
            }
            // Thomas algorithm (the chain is diagonally dominant: inertia and friction
            // slope add to the diagonal).
            for rl in 1..m {
                let prev = sc.tri[rl - 1][1];
                // A pinned relay (no inertia, no friction, both spans slack) stays put.
                let w = if prev == 0.0 {
                    0.0
                } else {
                    sc.tri[rl][0] / prev
                };
                sc.tri[rl][1] -= w * sc.tri[rl - 1][2];
                sc.tri[rl][3] -= w * sc.tri[rl - 1][3];
            }
            let mut next = 0.0;
            for rl in (0..m).rev() {
                let [_, d, sup, rhs] = sc.tri[rl];
                let dz = if d == 0.0 {
                    0.0
                } else {
                    (rhs - sup * next) / d
                };
                next = if dz.is_finite() { dz } else { 0.0 };
                let k = side * m + rl;
                let (psi0, w0) = (
                    inp.state.angle_rad[rl][side],
                    inp.state.rate_rad_s[rl][side],
                );
                let old = sc.psi1[k];
                let mut new = if dz.is_finite() { old + dz } else { old };
                if jumps_stick_band(c, h, psi0, w0, old, new) {
                    new = psi0 + 0.5 * h * w0;
                }
                sc.psi1[k] = new;
                worst = worst.max((new - old).abs() / (tol * (1.0 + new.abs())));
            }
        }
        if worst <= 0.1 {
            break;
        }
    }
}

/// What [`apply_relay_update`] did.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RelayUpdate {
    /// Every change within the tolerance.
    pub small: bool,
    /// A safeguard (rest across the stick band, damping) changed the Newton update.
    pub guarded: bool,
}

/// Ends the step: commits every span at the converged state and advances the relay
/// pulleys (trapezoidal rule).
#[inline(never)]
pub(crate) fn commit(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    sc: &mut RelayScratch,
    h: f64,
    motor_radius_m: f64,
    theta_rad: f64,
    x_m: f64,
    q: &[f64],
    state: &mut RelayState,
) {
    let ns = c.spans();
    let m = c.relays();
    {
        let inp = Local {
            h,
            n: 1.0,
            motor_radius_m,
            motor: MotorRow::Fixed,
            constant_force_n: None,
            theta_rad,
            q,
            state: &*state,
        };
        for i in 0..ns {
            let gq = c.gq(i, q);
            for side in 0..2 {
                let (f, _, strain) =
                    span_tension(c, stepper, &inp, gq, x_m, &sc.psi1, &sc.prep, side, i);
                sc.f[side * ns + i] = f;
                sc.k[side * ns + i] = strain;
            }
        }
    }
    for side in 0..2 {
        for i in 0..ns {
            let k = side * ns + i;
            stepper.commit_with_tension(&sc.prep[k], &mut state.spans[i][side], sc.k[k], sc.f[k]);
        }
    }
    let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
    for rl in 0..m {
        for side in 0..2 {
            let psi1 = sc.psi1[side * m + rl];
            let dpsi = psi1 - state.angle_rad[rl][side];
            let w0 = state.rate_rad_s[rl][side];
            let a1 = four_h2 * dpsi - 2.0 * two_h * w0 - state.accel_rad_s2[rl][side];
            state.rate_rad_s[rl][side] = two_h * dpsi - w0;
            state.accel_rad_s2[rl][side] = a1;
            state.angle_rad[rl][side] = psi1;
        }
    }
}

/// Prepares the step of every span and predicts the relay angles.
#[inline(never)]
pub(crate) fn begin_step(
    c: &CompiledRelays,
    stepper: &RopeStepper,
    sc: &mut RelayScratch,
    h: f64,
    state: &RelayState,
) {
    let ns = c.spans();
    let m = c.relays();
    for (i, span) in state.spans.iter().enumerate() {
        sc.prep[i] = stepper.prepare(&span[0]);
        sc.prep[ns + i] = stepper.prepare(&span[1]);
    }
    sc.prev_step.fill(0.0);
    sc.damping.fill(1.0);
    for rl in 0..m {
        for side in 0..2 {
            sc.psi1[side * m + rl] = state.angle_rad[rl][side]
                + h * state.rate_rad_s[rl][side]
                + 0.5 * h * h * state.accel_rad_s2[rl][side];
        }
    }
}

/// A pivot candidate replaces the diagonal in [`lu_in_place`] only when the diagonal is
/// below this fraction of it (threshold partial pivoting, as sparse LU codes do, e.g.
/// UMFPACK's default 0.1: the factor entries grow at most tenfold per step, and an arm's
/// Newton matrix, mass matrix plus rope stiffness, keeps its order).
const PIVOT_THRESHOLD: f64 = 0.1;

/// LU factorisation with threshold partial pivoting of the row-major `n x n` matrix `a`
/// in place (unit lower factor below the diagonal, the reciprocals of the pivots on it:
/// the solves multiply); false when singular or not finite.
#[inline(never)]
pub(crate) fn lu_in_place(a: &mut [f64], n: usize, perm: &mut [usize]) -> bool {
    for k in 0..n {
        let mut piv = k;
        let mut best = a[k * n + k].abs();
        for i in k + 1..n {
            let v = a[i * n + k].abs();
            if v > best {
                best = v;
                piv = i;
            }
        }
        if best <= 0.0 || !best.is_finite() {
            return false;
        }
        if a[k * n + k].abs() >= PIVOT_THRESHOLD * best {
            piv = k;
        }
        perm[k] = piv;
        if piv != k {
            // Columns `k..` only (LAPACK `gbtrf` style): the multipliers already stored
            // stay with the elimination step that made them, as `lu_solve` replays them.
            for j in k..n {
                a.swap(k * n + j, piv * n + j);
            }
        }
        let inv = 1.0 / a[k * n + k];
        a[k * n + k] = inv;
        for i in k + 1..n {
            let f = a[i * n + k] * inv;
            a[i * n + k] = f;
            if f != 0.0 {
                let (top, bottom) = a.split_at_mut(i * n);
                let pivot_row = &top[k * n + k + 1..(k + 1) * n];
                for (x, u) in bottom[k + 1..n].iter_mut().zip(pivot_row) {
                    *x -= f * u;
                }
            }
        }
    }
    true
}

/// Solves `A x = b` in place with the factor of [`lu_in_place`].
#[inline(never)]
pub(crate) fn lu_solve(a: &[f64], n: usize, perm: &[usize], b: &mut [f64]) {
    for k in 0..n {
        if perm[k] != k {
            b.swap(k, perm[k]);
        }
        let bk = b[k];
        if bk != 0.0 {
            for i in k + 1..n {
                b[i] -= a[i * n + k] * bk;
            }
        }
    }
    for i in (0..n).rev() {
        let s: f64 = a[i * n + i + 1..(i + 1) * n]
            .iter()
            .zip(&b[i + 1..n])
            .map(|(u, x)| u * x)
            .sum();
        b[i] = (b[i] - s) * a[i * n + i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lu_solves_a_non_symmetric_system_that_needs_pivoting() {
        // [0 2 1; 1 1 0; 3 0 1] x = b for x = [1, -2, 3].
        let a0 = [0.0, 2.0, 1.0, 1.0, 1.0, 0.0, 3.0, 0.0, 1.0];
        let x = [1.0, -2.0, 3.0];
        let mut b: Vec<f64> = (0..3)
            .map(|i| (0..3).map(|j| a0[i * 3 + j] * x[j]).sum())
            .collect();
        let mut a = a0;
        let mut perm = [0; 3];
        assert!(lu_in_place(&mut a, 3, &mut perm));
        lu_solve(&a, 3, &perm, &mut b);
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-14, "{b:?}");
        }
        let mut singular = [1.0, 2.0, 2.0, 4.0];
        assert!(!lu_in_place(&mut singular, 2, &mut [0; 2]));
    }

    /// `A x = b` solved by [`lu_in_place`] and by nalgebra's dense LU: the pivot rows
    /// and the largest difference of the solutions.
    fn against_nalgebra(a0: &[f64], n: usize) -> (Vec<usize>, f64) {
        let b0: Vec<f64> = (0..n).map(|k| ((k * 7 % 11) as f64) - 5.0).collect();
        let mut a = a0.to_vec();
        let mut perm = vec![0; n];
        assert!(lu_in_place(&mut a, n, &mut perm));
        let mut b = b0.clone();
        lu_solve(&a, n, &perm, &mut b);
        let x = nalgebra::DMatrix::from_row_slice(n, n, a0)
            .lu()
            .solve(&nalgebra::DVector::from_vec(b0))
            .expect("regular");
        let worst = (0..n).map(|i| (b[i] - x[i]).abs()).fold(0.0, f64::max);
        (perm, worst)
    }

    /// Test matrix: diagonal `d(i)`, every other entry `1 / (1 + |i - j|)`, negative
    /// below the diagonal.
    fn test_matrix(n: usize, d: &dyn Fn(usize) -> f64) -> Vec<f64> {
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let v = 1.0 / (1.0 + i.abs_diff(j) as f64);
                a[i * n + j] = if i == j {
                    d(i)
                } else if i > j {
                    -v
                } else {
                    v
                };
            }
        }
        a
    }

    #[test]
    fn local_factor_solves_the_chains_and_border_as_a_dense_lu_does() {
        // Three relays per rope, both border unknowns free: fill the factor's entries,
        // build the same dense block in the order of `iz_psi`, and compare the solves
        // of two right sides.
        let m = 3;
        let l = 2 * m + 2;
        let mut fa = LocalFactor::new(m);
        let mut dense = vec![0.0; l * l];
        for side in 0..2 {
            for rl in 0..m {
                let k = side * m + rl;
                let row = iz_psi(m, side, rl);
                fa.dia[k] = 5.0 + k as f64;
                dense[row * l + row] = fa.dia[k];
                if rl > 0 {
                    fa.sub[k] = -1.0 - 0.1 * k as f64;
                    dense[row * l + iz_psi(m, side, rl - 1)] = fa.sub[k];
                }
                if rl + 1 < m {
                    fa.sup[k] = 1.5 - 0.2 * k as f64;
                    dense[row * l + iz_psi(m, side, rl + 1)] = fa.sup[k];
                }
            }
            let first = iz_psi(m, side, 0);
            fa.edge[side] = [0.7 - side as f64, 0.3];
            fa.couple[0][side] = -0.4 + side as f64;
            fa.couple[1][side] = 0.9;
            for border in 0..2 {
                dense[first * l + m + border] = fa.edge[side][border];
                dense[(m + border) * l + first] = fa.couple[border][side];
            }
        }
        fa.border = [[6.0, 0.5], [-0.8, 4.0]];
        for (i, row) in fa.border.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                dense[(m + i) * l + m + j] = *v;
            }
        }
        assert!(fa.factor(m));
        let w = 2;
        let b0: Vec<f64> = (0..l * w).map(|k| ((k * 5 % 7) as f64) - 3.0).collect();
        let mut b = b0.clone();
        fa.solve(m, &mut b, w);
        let x = nalgebra::DMatrix::from_row_slice(l, l, &dense)
            .lu()
            .solve(&nalgebra::DMatrix::from_row_slice(l, w, &b0))
            .expect("regular");
        for i in 0..l {
            for c in 0..w {
                assert!((b[i * w + c] - x[(i, c)]).abs() < 1e-13, "row {i}: {b:?}");
            }
        }
        // One right side: the chord iterations' solve gives the first column bitwise.
        let mut one: Vec<f64> = (0..l).map(|i| b0[i * w]).collect();
        fa.solve_one(m, &mut one);
        for i in 0..l {
            assert_eq!(one[i].to_bits(), b[i * w].to_bits(), "row {i}");
        }
        // A zero pivot is reported, not divided by.
        let mut zero = LocalFactor::new(m);
        zero.dia[m + 1] = 0.0;
        assert!(!zero.factor(m));
    }

    #[test]
    fn lu_keeps_the_diagonal_above_the_pivot_threshold_and_solves_exactly() {
        // Diagonal 0.4 against entries up to 0.5 below it: above a tenth of the largest
        // candidate, so no row is interchanged.
        let (perm, err) = against_nalgebra(&test_matrix(7, &|_| 0.4), 7);
        assert_eq!(perm, (0..7).collect::<Vec<_>>());
        assert!(err < 1e-12, "{err}");
        // Zero diagonal (a skew-symmetric matrix of even order, regular): every column
        // needs an interchange, and the solve must replay them in order.
        let (perm, err) = against_nalgebra(&test_matrix(6, &|_| 0.0), 6);
        let interchanges = perm.iter().enumerate().filter(|(k, &p)| p != *k).count();
        assert!(interchanges >= 2, "{perm:?}");
        assert!(err < 1e-12, "{err}");
    }
}
