//! The linearised arm at a pose: natural frequencies, damping ratios and mode shapes
//! of the whole plant (links, flexible links' bending, ropes, motors, servos), from the
//! step itself.
//!
//! # Method
//!
//! The arm is held at its static equilibrium at the pose ([`DrivenArm::initial_state`],
//! every command a hold). One step maps the state `x` (coordinates, rates and
//! accelerations of the joints and modes, motor angles, rates and accelerations,
//! tensioner stretches, every rope's tension and internal strains, effect states) to
//! the next; its Jacobian `A` is taken by central differences of the step around the
//! equilibrium, and its eigenvalues `lambda` are mapped back to the continuous poles
//! by the inverse of the trapezoidal rule's map, `s = (2/h) (lambda - 1) / (lambda + 1)`:
//! exact for the parts integrated by the trapezoidal rule (links, motors, tensioners),
//! the ropes' exact-hold step within `O((s h)^2)`. The accelerations are states of the
//! step whose image is fixed by the others, so they add eigenvalues `lambda = 0`
//! (`s = -2/h`), dropped with every other real pole. Each oscillatory pole gives a mode:
//! `f = |s| / 2 pi` (natural), the damped `Im s / 2 pi`, `zeta = -Re s / |s|`, and its
//! shape: the eigenvector (inverse iteration on `A - lambda`), scaled to 1 J of potential
//! energy in the springs it loads, split between the ropes (`1/2 n k |de|^2` per rope,
//! `k` the step's tangent stiffness), the links' bending (`1/2 K |eta|^2`) and the
//! servos (`1/2 k_p |dtheta|^2`).

use nalgebra::{Complex, DMatrix, DVector};

use crate::error::ArmError;
use crate::system::{DrivenArm, DrivenState};
use crate::transmission::MotorMode;

/// One part of the plant a mode loads, and its share of the mode's potential energy.
#[derive(Debug, Clone, PartialEq)]
pub struct Share {
    /// What: `rope j2` (a pair's ropes), `link link3` (its bending), `servo j2`.
    pub part: String,
    /// Share of the potential energy, 0..1.
    pub share: f64,
}

/// One mode of the linearised arm.
#[derive(Debug, Clone, PartialEq)]
pub struct Mode {
    /// Natural frequency `|s| / 2 pi`, Hz.
    pub natural_hz: f64,
    /// Damped frequency `Im s / 2 pi`, Hz.
    pub damped_hz: f64,
    /// Damping ratio `-Re s / |s|`.
    pub damping_ratio: f64,
    /// Potential-energy shares, largest first.
    pub shares: Vec<Share>,
    /// Joint angles at 1 J of potential energy (signed, phase of the largest part), rad.
    pub joints_rad: Vec<f64>,
    /// Every generalised coordinate at 1 J, in the same phase: the joints (rad, as
    /// `joints_rad`), then the flexible links' modal coordinates (m; the layout of
    /// [`crate::flex::FlexLink::offset`]), so that `equilibrium_q + a * coords` is the
    /// arm bent along the mode.
    pub coords: Vec<f64>,
    /// Deflection of each flexible link's end at 1 J (in-plane, out-of-plane), m.
    pub link_end_m: Vec<(String, [f64; 2])>,
    /// Motor angles at 1 J, rad.
    pub motors_rad: Vec<f64>,
    /// Change of each pair's `+` rope tension at 1 J, N.
    pub tensions_n: Vec<f64>,
}

/// The modes of an arm at a pose.
#[derive(Debug, Clone, PartialEq)]
pub struct Modes {
    /// Joint angles of the pose, rad.
    pub pose_rad: Vec<f64>,
    /// The generalised coordinates of the equilibrium the modes are about: the joints,
    /// then the flexible links' modal coordinates (bent under gravity).
    pub equilibrium_q: Vec<f64>,
    /// Step the arm was linearised with, s.
    pub dt_s: f64,
    /// Oscillatory modes, by natural frequency.
    pub modes: Vec<Mode>,
    /// Real poles (creep, first-order settling; the accelerations' `s = -2/h` left out).
    pub real_poles: usize,
}

/// Where each group of the state sits in the packed vector.
struct Layout {
    nq: usize,
    np: usize,
    n_effect: usize,
}

const ROPE_FIELDS: usize = 4 + longreach_rope::MAX_KELVIN;

impl Layout {
    fn len(&self) -> usize {
        3 * self.nq + 3 * self.np + self.np + 2 * self.np * ROPE_FIELDS + self.n_effect
    }
}

fn pack(st: &DrivenState, l: &Layout) -> Vec<f64> {
    let mut x = Vec::with_capacity(l.len());
    x.extend(&st.q_rad);
    x.extend(&st.qd_rad_s);
    x.extend(&st.qdd_rad_s2);
    x.extend(&st.motor_rad);
    x.extend(&st.motor_rate_rad_s);
    x.extend(&st.motor_accel_rad_s2);
    x.extend(&st.carriage_m);
    for pr in &st.ropes {
        for r in pr {
            x.extend([r.tension_n, r.strain, r.e1, r.e2]);
            x.extend(&r.e3);
        }
    }
    x.extend(&st.effect_state);
    x
}

fn unpack(x: &[f64], st: &mut DrivenState, l: &Layout) {
    let mut k = 0;
    let mut take = |dst: &mut [f64]| {
        dst.copy_from_slice(&x[k..k + dst.len()]);
        k += dst.len();
    };
    take(&mut st.q_rad);
    take(&mut st.qd_rad_s);
    take(&mut st.qdd_rad_s2);
    take(&mut st.motor_rad);
    take(&mut st.motor_rate_rad_s);
    take(&mut st.motor_accel_rad_s2);
    take(&mut st.carriage_m);
    for pr in st.ropes.iter_mut() {
        for r in pr.iter_mut() {
            let mut f = [r.tension_n, r.strain, r.e1, r.e2];
            take(&mut f);
            [r.tension_n, r.strain, r.e1, r.e2] = f;
            take(&mut r.e3);
        }
    }
    take(&mut st.effect_state);
    debug_assert_eq!(k, l.len());
}

/// Scale of a perturbation of each packed entry.
fn scales(l: &Layout) -> Vec<f64> {
    let mut s = Vec::with_capacity(l.len());
    s.extend(std::iter::repeat_n(1e-7, l.nq));
    s.extend(std::iter::repeat_n(1e-5, l.nq));
    s.extend(std::iter::repeat_n(1e-3, l.nq));
    s.extend(std::iter::repeat_n(1e-7, l.np));
    s.extend(std::iter::repeat_n(1e-5, l.np));
    s.extend(std::iter::repeat_n(1e-3, l.np));
    s.extend(std::iter::repeat_n(1e-9, l.np));
    for _ in 0..2 * l.np {
        s.push(1e-4);
        s.extend(std::iter::repeat_n(1e-9, ROPE_FIELDS - 1));
    }
    s.extend(std::iter::repeat_n(1e-7, l.n_effect));
    s
}

/// The modes of `arm` at its initial pose (every command held). Arms with relay
/// friction are refused (their stick-slip has no linearisation).
pub fn modes(arm: &DrivenArm) -> Result<Modes, ArmError> {
    if arm.pairs().iter().any(|p| p.relays.is_some()) {
        return Err(ArmError::BadTransmission {
            field: "relay_friction".into(),
            reason: "modes linearises the arm; relay friction (stick-slip) has no linearisation: \
                     remove it for the modes"
                .into(),
        });
    }
    let n = arm.njoints();
    let arm = arm.clone().with_commands(vec![crate::Command::Hold; n])?;
    let st0 = arm.initial_state();
    let l = Layout {
        nq: st0.q_rad.len(),
        np: st0.motor_rad.len(),
        n_effect: st0.effect_state.len(),
    };
    let x0 = pack(&st0, &l);
    let dim = x0.len();
    let sc = scales(&l);
    let step_from = |x: &[f64]| -> Result<Vec<f64>, ArmError> {
        let mut st = st0.clone();
        unpack(x, &mut st, &l);
        arm.step(&mut st)?;
        Ok(pack(&st, &l))
    };
    let mut a = DMatrix::<f64>::zeros(dim, dim);
    for c in 0..dim {
        let e = sc[c] * (1.0 + x0[c].abs() * 1e-3);
        let mut xp = x0.clone();
        xp[c] += e;
        let yp = step_from(&xp)?;
        let mut xm = x0.clone();
        xm[c] -= e;
        let ym = step_from(&xm)?;
        for r in 0..dim {
            a[(r, c)] = (yp[r] - ym[r]) / (2.0 * e);
        }
    }
    // Entries that never move (held motors, fixed tensioners, absent elements) make
    // zero rows and columns: drop them.
    let live: Vec<usize> = (0..dim)
        .filter(|&i| (0..dim).any(|j| a[(i, j)] != 0.0 || a[(j, i)] != 0.0))
        .collect();
    let m = live.len();
    // Balanced by the perturbation scales (the same eigenvalues; entries of order one).
    let ar = DMatrix::from_fn(m, m, |i, j| {
        a[(live[i], live[j])] * sc[live[j]] / sc[live[i]]
    });
    let h = arm.dt_s();
    let eig = nalgebra::Schur::try_new(ar.clone(), 1e-11, 1000 * m.max(1))
        .ok_or_else(|| ArmError::BadTransmission {
            field: "modes".into(),
            reason: "the eigenvalues of the linearised step did not converge".into(),
        })?
        .complex_eigenvalues();
    let one = Complex::new(1.0, 0.0);
    let mut out = Vec::new();
    let mut real_poles = 0;
    let ac: DMatrix<Complex<f64>> = ar.map(|v| Complex::new(v, 0.0));
    for lam in eig.iter() {
        if lam.norm() < 1e-9 {
            continue; // the accelerations' image
        }
        let s = (lam - one) / (lam + one) * (2.0 / h);
        if s.im.abs() <= 1e-6 * s.norm().max(1.0) || -s.re >= 0.999 * s.norm() {
            real_poles += 1;
            continue;
        }
        if s.im < 0.0 {
            continue;
        }
        // Eigenvector by inverse iteration.
        let shift = lam * Complex::new(1.0 + 1e-10, 1e-10);
        let mut b = ac.clone();
        for i in 0..m {
            b[(i, i)] -= shift;
        }
        let lu = b.lu();
        let mut v = DVector::from_fn(m, |i, _| Complex::new(1.0 + (i as f64 * 0.37).sin(), 0.1));
        for _ in 0..3 {
            if let Some(w) = lu.solve(&v) {
                let nrm = w.norm();
                v = w / Complex::new(nrm, 0.0);
            }
        }
        let mut full = vec![Complex::new(0.0, 0.0); dim];
        for (i, &k) in live.iter().enumerate() {
            full[k] = v[i] * sc[k];
        }
        out.push(shape(&arm, &st0, &full, s, &l));
    }
    out.sort_by(|a, b| a.natural_hz.total_cmp(&b.natural_hz));
    Ok(Modes {
        pose_rad: arm.initial_q_rad().to_vec(),
        equilibrium_q: st0.q_rad.clone(),
        dt_s: h,
        modes: out,
        real_poles,
    })
}

/// The mode of pole `s` with the eigenvector `v` (packed layout).
fn shape(
    arm: &DrivenArm,
    st0: &DrivenState,
    v: &[Complex<f64>],
    s: Complex<f64>,
    l: &Layout,
) -> Mode {
    let nq = l.nq;
    let np = l.np;
    let n = arm.njoints();
    let dq = &v[..nq];
    let dth = &v[3 * nq..3 * nq + np];
    let dx = &v[3 * nq + 3 * np..3 * nq + 4 * np];
    let spec = arm.spec();
    let mut parts: Vec<(String, f64)> = Vec::new();
    // Ropes: tangent stiffness of each side from the step's own tension law.
    let q0 = &st0.q_rad;
    let t0 = arm.tensions_at(st0, q0, &st0.motor_rad, &st0.carriage_m);
    let mut dtension = vec![Complex::new(0.0, 0.0); np];
    for (p, pair) in arm.pairs().iter().enumerate() {
        let d = 1e-7;
        let mut xc = st0.carriage_m.clone();
        xc[p] += d;
        let t1 = arm.tensions_at(st0, q0, &st0.motor_rad, &xc);
        let (kp, km) = ((t1[p][0] - t0[p][0]) / d, (t1[p][1] - t0[p][1]) / d);
        let rq: Complex<f64> = pair.nz.iter().map(|&k| dq[k] * pair.row[k]).sum();
        let du = dth[p] * pair.spec.motor_radius_m - rq;
        let (ep, em) = (dx[p] + du, dx[p] - du);
        let nr = pair.spec.ropes_in_parallel as f64;
        let e = 0.5 * nr * (kp * ep.norm_sqr() + km * em.norm_sqr());
        dtension[p] = ep * kp;
        parts.push((format!("rope {}", spec.joints[pair.spec.joint].name), e));
        if let MotorMode::Servo { kp_n_m_per_rad, .. } = pair.spec.motor.mode {
            parts.push((
                format!("servo {}", spec.joints[pair.spec.joint].name),
                0.5 * kp_n_m_per_rad * dth[p].norm_sqr(),
            ));
        }
    }
    let mut ends = Vec::new();
    if let Some(f) = arm.flex() {
        for fl in &f.flex {
            let mut e = 0.0;
            let (mut w1, mut w2) = (Complex::new(0.0, 0.0), Complex::new(0.0, 0.0));
            for m in 0..fl.nm {
                let (a, b) = (dq[fl.offset + m], dq[fl.offset + fl.nm + m]);
                e += 0.5 * fl.stiffness[m] * (a.norm_sqr() + b.norm_sqr());
                let phi_l = crate::flex::mode_shape(m, 1.0).0;
                w1 += a * phi_l;
                w2 += b * phi_l;
            }
            let name = spec.links[fl.link].name.clone();
            parts.push((format!("link {name}"), e));
            ends.push((name, [w1, w2]));
        }
    }
    let total: f64 = parts
        .iter()
        .map(|p| p.1)
        .sum::<f64>()
        .max(f64::MIN_POSITIVE);
    // Scale to 1 J, phase of the largest joint or link-end motion.
    let scale = 1.0 / total.sqrt();
    let pivot = dq
        .iter()
        .copied()
        .max_by(|a, b| a.norm().total_cmp(&b.norm()))
        .unwrap_or(Complex::new(1.0, 0.0));
    let rot = if pivot.norm() > 0.0 {
        pivot.conj() / pivot.norm()
    } else {
        Complex::new(1.0, 0.0)
    };
    let re = |c: Complex<f64>| (c * rot).re * scale;
    let mut shares: Vec<Share> = parts
        .into_iter()
        .map(|(part, e)| Share {
            part,
            share: e / total,
        })
        .collect();
    shares.sort_by(|a, b| b.share.total_cmp(&a.share));
    Mode {
        natural_hz: s.norm() / (2.0 * std::f64::consts::PI),
        damped_hz: s.im / (2.0 * std::f64::consts::PI),
        damping_ratio: -s.re / s.norm(),
        shares,
        joints_rad: dq[..n].iter().map(|&c| re(c)).collect(),
        coords: dq.iter().map(|&c| re(c)).collect(),
        link_end_m: ends
            .into_iter()
            .map(|(nm, [a, b])| (nm, [re(a), re(b)]))
            .collect(),
        motors_rad: dth.iter().map(|&c| re(c)).collect(),
        tensions_n: dtension.iter().map(|&c| re(c)).collect(),
    }
}
