//! A pair with ideal relays (one tension per rope) in the implicit step.
//!
//! Its local unknowns are the motor angle (a servo's; a kinematic motor is held) and the
//! tensioner stretch (a constant-force tensioner's; a fixed one is held). With the
//! differential stretch `u = r_m theta - R[p] q`, the ropes' tensions `f+-` and
//! stiffnesses `k+-` at `x +- u`, the pair's part of the Newton system is
//!
//! ```text
//! joints:     -R^T phi,                       d/dq = R^T (n (k+ + k-)) R, ...
//! motor:      r_s + r_m phi                   (servo residual without the ropes)
//! tensioner:  f+ + f- - 2 T
//! ```
//!
//! The `2 x 2` border `B` of the local unknowns is eliminated (Schur complement): the
//! joints see the stiffness `k_eff R R^T` and the right side `-R^T gamma`, and after
//! the joint update `dq` the local update is `B^-1 (-r + w R . dq)` ([`local_update`]).

use longreach_rope::{Piece, PreparedStep};

use super::pair::CompiledPair;
use super::servo::ServoRow;
use super::spec::Tensioner;

/// The ropes of an ideal pair at a trial state ([`evaluate`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct IdealEval {
    /// Tensions `[+, -]`, N per rope.
    pub f: [f64; 2],
    /// Stiffnesses `[+, -]`, N/m.
    pub k: [f64; 2],
    /// Strains `[+, -]`.
    pub e: [f64; 2],
    /// Pieces of the rope law.
    pub pieces: [Piece; 2],
}

/// Tensions, stiffnesses and pieces of both ropes at the trial state (routed joint
/// position `rq = R[p] . q1`, motor `th1`, tensioner `x1`); `None` when both ropes are
/// slack under a constant-force tensioner: the carriage was then moved to take up the
/// slack (redo the iteration).
#[inline(always)]
pub(crate) fn evaluate(
    pair: &CompiledPair,
    prep: &[PreparedStep; 2],
    rq: f64,
    th1: f64,
    x1: &mut f64,
) -> Option<IdealEval> {
    let s = &pair.spec;
    let rm = s.motor_radius_m;
    let u = rm * th1 - rq;
    let x = *x1;
    let il = pair.inv_length;
    let (ep, em) = ((x + u) * il, (x - u) * il);
    let (fp, kp, pp) = pair.stepper.tension_piece(&prep[0], ep);
    let (fm, km, pm) = pair.stepper.tension_piece(&prep[1], em);
    let (kp, km) = (kp * il, km * il);
    if s.tensioner == Tensioner::ConstantForce && kp + km == 0.0 {
        // Both ropes slack: the carriage takes up the slack first.
        let lp = prep[0].slack_strain() * s.length_m - u;
        let lm = prep[1].slack_strain() * s.length_m + u;
        *x1 = lp.min(lm) + 1e-12 * s.length_m;
        return None;
    }
    Some(IdealEval {
        f: [fp, fm],
        k: [kp, km],
        e: [ep, em],
        pieces: [pp, pm],
    })
}

/// Adds the pair's contributions at the trial state (joints `q1`, motor `th1`,
/// tensioner `x1`) to the joint matrix `kq` (`n x n`, row-major) and the right side
/// `rhs` (`-r_q`), and keeps its border in `local`; `servo` is the motor's row
/// ([`super::servo::servo_row`]), `None` for a kinematic motor; `lower_only`: the joint
/// matrix is factored by Cholesky, which reads its lower triangle only, so the pair adds
/// only there. False when the carriage had to take up slack ([`evaluate`]): redo the
/// iteration.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn block(
    pair: &CompiledPair,
    prep: &[PreparedStep; 2],
    q1: &[f64],
    th1: f64,
    x1: &mut f64,
    servo: Option<ServoRow>,
    rhs: &mut [f64],
    kq: &mut [f64],
    n: usize,
    local: &mut [f64; 8],
    lower_only: bool,
) -> bool {
    let rq: f64 = pair.nz.iter().map(|&k| pair.row[k] * q1[k]).sum();
    let Some(ev) = evaluate(pair, prep, rq, th1, x1) else {
        return false;
    };
    let s = &pair.spec;
    let rm = s.motor_radius_m;
    let [fp, fm] = ev.f;
    let [kp, km] = ev.k;
    let cf = s.tensioner == Tensioner::ConstantForce;
    let nn = pair.n;
    let phi = nn * (fp - fm);
    let ku = nn * (kp + km);
    let kx = nn * (kp - km);
    let (su, sx) = (kp - km, kp + km);
    // rhs = -r_q: r_q contains -R^T phi.
    for &k in &pair.nz {
        rhs[k] += pair.row[k] * phi;
    }
    let (servo, b11, r0) = match servo {
        None => (0.0, 1.0, 0.0),
        Some(row) => (1.0, row.diag + rm * rm * ku, row.residual_n_m + rm * phi),
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
    // `nz` is ascending: its first `ia + 1` joints are at or left of the diagonal.
    for (ia, &a) in pair.nz.iter().enumerate() {
        let ra = pair.row[a];
        rhs[a] -= ra * gamma;
        let cols = if lower_only {
            &pair.nz[..=ia]
        } else {
            &pair.nz[..]
        };
        for &b in cols {
            kq[a * n + b] += keff * ra * pair.row[b];
        }
    }
    *local = [b11, b12, b21, b22, w[0], w[1], r0, r1];
    true
}

/// The local update `(d theta, d x)` of the pair after the joint update `dq`, from the
/// border kept by [`block`].
#[inline(always)]
pub(crate) fn local_update(pair: &CompiledPair, local: &[f64; 8], dq: &[f64]) -> (f64, f64) {
    let [b11, b12, b21, b22, w0, w1, r0, r1] = *local;
    let rdq: f64 = pair.nz.iter().map(|&k| pair.row[k] * dq[k]).sum();
    let v = [-r0 + w0 * rdq, -r1 + w1 * rdq];
    let det = b11 * b22 - b12 * b21;
    let d0 = (b22 * v[0] - b12 * v[1]) / det;
    let d1 = (-b21 * v[0] + b11 * v[1]) / det;
    (d0, d1)
}
