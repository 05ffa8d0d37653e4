//! Assembly: the residuals and derivatives of a pair with relay friction at a trial
//! state (span tensions, relay equations, the Schur complement of its local unknowns
//! onto the joints), the local update after a joint update, and the step's start and
//! commit.

use longreach_rope::{PreparedStep, RopeStepper};

use super::factor::LocalFactor;
use super::friction::RelayTorque;
use super::{CompiledRelays, RelayRule, RelayState};

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
    pub(crate) psi1: Vec<f64>,
    /// Prepared rope steps, index `side * spans + i`.
    pub(crate) prep: Vec<PreparedStep>,
    pub(crate) f: Vec<f64>,
    pub(crate) k: Vec<f64>,
    /// The factor of the local block `K_zz` kept from the last assembly.
    pub(crate) factor: LocalFactor,
    pub(crate) kqz: Vec<f64>,
    /// `[r_z | K_zq]` (unknowns x (1 + cols), row-major), then after the solve
    /// `[K_zz^-1 r_z | K_zz^-1 K_zq]`.
    pub(crate) rhs: Vec<f64>,
    /// Local derivatives of every span's elongation (index `side * spans + i`).
    pub(crate) de: Vec<([(usize, f64); 4], usize)>,
    pub(crate) tmp: Vec<f64>,
    /// Relay rows pinned at the last assembly (`psi` held: no inertia, no friction,
    /// both spans slack).
    pub(crate) pinned: Vec<bool>,
    /// `K_zz^-1 r_z` of a chord iteration.
    pub(crate) y: Vec<f64>,
    /// Newton update of the local unknowns.
    pub(crate) dz: Vec<f64>,
    /// Last Newton update (undamped) of each relay angle, rad.
    pub(crate) prev_step: Vec<f64>,
    /// Step factor of each relay angle (halved when its updates oscillate).
    pub(crate) damping: Vec<f64>,
    /// Relays whose last update jumped across the stick band.
    pub(crate) crossed: Vec<bool>,
    /// Sum of the squared residuals of the pair's local equations at the last
    /// assembly (the merit of the globalised iterations, [`crate::transmission::step`]).
    pub(crate) merit: f64,
    /// Relay angles before the last full Newton update, and that update (the
    /// globalised iterations' line search).
    pub(crate) psi_back: Vec<f64>,
    pub(crate) dpsi: Vec<f64>,
    /// Tridiagonal system of one rope side's relays (sub, diagonal, super, right side).
    pub(crate) tri: Vec<[f64; 4]>,
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
            merit: 0.0,
            psi_back: vec![0.0; 2 * c.relays()],
            dpsi: vec![0.0; 2 * c.relays()],
        }
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
pub(crate) fn span_tension(
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
pub(crate) fn evaluate_spans(
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
pub(crate) fn relay_residual(
    c: &CompiledRelays,
    inp: &Local<'_>,
    psi1: &[f64],
    fs: &[f64],
    side: usize,
    rl: usize,
) -> (f64, RelayTorque) {
    let (m, ns) = (c.relays(), c.spans());
    let h = inp.h;
    let r = c.radius_m[rl];
    let (fa, fb) = (fs[side * ns + rl], fs[side * ns + rl + 1]);
    let psi0 = inp.state.angle_rad[rl][side];
    let w0 = inp.state.rate_rad_s[rl][side];
    let dpsi = psi1[side * m + rl] - psi0;
    let (w1, a1) = RelayRule::end_rates(h, dpsi, w0);
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
pub(crate) struct RelaySlopes {
    /// `(r + ts, -r + ts)`: the equation is `... + wa f_l + wb f_{l+1}`.
    pub(crate) wa: f64,
    pub(crate) wb: f64,
    /// At the relay itself (inertia, friction slope, both spans).
    pub(crate) diag: f64,
    /// At relay `rl - 1` (0 for the first relay).
    pub(crate) sub: f64,
    /// At relay `rl + 1` (0 for the last relay).
    pub(crate) sup: f64,
}

pub(crate) fn relay_slopes(
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
    let (dwdp, dadp) = RelayRule::slopes(h);
    RelaySlopes {
        wa,
        wb,
        diag: dadp * c.friction.inertia_kg_m2 + dwdp * t.d_rate_n_m_s + wa * ka * r - wb * kb * r,
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
    sc.merit = y.iter().map(|v| v * v).sum();
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
    sc.merit = (0..l).map(|z| brhs[z * w] * brhs[z * w]).sum();
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
    // A massless relay (no inertia, hence no friction: `RelayFriction::validate`) is
    // algebraic: its angle only balances its spans, and the trapezoidal rate of an
    // algebraic unknown would ring at the step frequency; it keeps the step's mean rate.
    let massless = c.friction.inertia_kg_m2 == 0.0;
    for rl in 0..m {
        for side in 0..2 {
            let psi1 = sc.psi1[side * m + rl];
            let dpsi = psi1 - state.angle_rad[rl][side];
            if massless {
                state.rate_rad_s[rl][side] = dpsi / h;
                state.accel_rad_s2[rl][side] = 0.0;
            } else {
                let (w1, a1) = RelayRule::end_rates(h, dpsi, state.rate_rad_s[rl][side]);
                state.rate_rad_s[rl][side] = w1;
                state.accel_rad_s2[rl][side] = a1;
            }
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
            sc.psi1[side * m + rl] = RelayRule::predict(
                h,
                state.angle_rad[rl][side],
                state.rate_rad_s[rl][side],
                state.accel_rad_s2[rl][side],
            );
        }
    }
}
