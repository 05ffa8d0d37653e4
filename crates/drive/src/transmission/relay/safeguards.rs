//! Newton safeguards for the non-smooth parts of the relay equations: a relay whose
//! rate would jump across the stick band of the regularised Coulomb law, a relay whose
//! updates flip sign without shrinking (a span going slack and taut), and the relays
//! of a pair solved alone when a Newton update leaves them far behind the joints.

use longreach_rope::RopeStepper;

use super::assembly::{
    evaluate_spans, relay_residual, relay_slopes, span_tension, Local, RelayScratch,
};
use super::{CompiledRelays, RelayRule, RelayState};

/// What [`apply_relay_update`] did.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RelayUpdate {
    /// Every change within the tolerance.
    pub small: bool,
    /// A safeguard (rest across the stick band, damping) changed the Newton update.
    pub guarded: bool,
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
                new = RelayRule::at_rest(psi0);
                sc.crossed[k] = true;
                guarded = true;
            }
            // A damped update is a safeguard's only while the undamped one is above the
            // tolerance: below it the damping changes nothing that counts, and the step
            // may end (else a relay damped once kept every later iteration guarded and
            // the step crept to its iteration limit).
            guarded |= sc.damping[k] < 1.0 && raw.abs() > tol * (1.0 + new.abs());
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
                // (a residual that is not a number is left to the global iteration,
                // which reports it; a NaN step would make the angle NaN)
                if g == 0.0 || !(g.is_finite() && dg.is_finite()) {
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
/// end rate zero ([`super::RelayRule::at_rest`]).
fn jumps_stick_band(c: &CompiledRelays, h: f64, psi0: f64, w0: f64, old: f64, new: f64) -> bool {
    let (w_old, _) = RelayRule::end_rates(h, old - psi0, w0);
    let (w_new, _) = RelayRule::end_rates(h, new - psi0, w0);
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
                    new = RelayRule::at_rest(psi0);
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
