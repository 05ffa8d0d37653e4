//! Simulating a model on the measured input of every run of a dataset.
//!
//! Sweeps: the rig plant of [`longreach_drive::RigModel`] driven by the recorded input
//! angle (the command when the input encoder shows exactly the quantised command, since
//! the command is then the true input to within the encoder's resolution), stepped at
//! the data's sample period divided by `substeps`, the input interpolated between
//! samples by a cubic whose rate is continuous (Catmull-Rom; a linear interpolation
//! steps the rate at every sample, and a rope whose tension follows its strain rate
//! then rings at the step's parity: docs/models.md, "The sweep input between
//! samples"). Relaxation: eq. 6 in closed form for the paper's four-element law,
//! the exact-hold rope stepper otherwise. Cyclic: the rope stepper on the measured
//! strain.

use longreach_drive::effects::Applied;
use longreach_drive::{DriveError, RigModel, RigSpec as DriveRig, Tensioner as DriveTensioner};
use longreach_rope::{relaxation_tension_n, RopeLaw, RopeStepper};

use crate::dataset::{RigSpec, SweepRun};
use crate::sensors::ENCODER_RESOLUTION_RAD;

/// Default sub-steps per sample for sweeps (dt = 5 ms / 2 = 2.5 ms at 200 Hz; see
/// `docs/models.md` for the accuracy check against the analytic response).
pub const SWEEP_SUBSTEPS: usize = 2;

/// Sub-steps per sample for relaxation and cyclic tests.
pub const ROPE_SUBSTEPS: usize = 10;

/// A simulated sweep run, one value per sample of the run.
#[derive(Debug, Clone, PartialEq)]
pub struct SimSweep {
    /// Output angle [rad].
    pub output_rad: Vec<f64>,
    /// Rope 1 tension next to the output pulley [N].
    pub tension_1_n: Vec<f64>,
    /// Rope 2 tension next to the output pulley [N].
    pub tension_2_n: Vec<f64>,
    /// Rope 1 tension next to the input pulley [N] (differs from `tension_1_n` only
    /// with relay friction).
    pub tension_in_1_n: Vec<f64>,
    /// Rope 2 tension next to the input pulley [N].
    pub tension_in_2_n: Vec<f64>,
}

/// The input angle that drives the model for `run`: the command when the measured
/// input equals the quantised command at every sample, else the measured input.
pub fn drive_input(run: &SweepRun) -> &[f64] {
    let q = ENCODER_RESOLUTION_RAD;
    let exact = run
        .command_rad
        .iter()
        .zip(&run.input_angle_rad)
        .all(|(c, i)| ((c / q).round() * q - i).abs() <= 1e-6);
    if exact {
        &run.command_rad
    } else {
        &run.input_angle_rad
    }
}

/// The drive crate's rig for a dataset's `[rig]`, a rope law and a mean tension.
pub fn drive_rig(rig: &RigSpec, law: RopeLaw, mean_tension_n: f64) -> DriveRig {
    DriveRig {
        rope_name: rig.rope.clone(),
        law,
        rope_length_m: rig.rope_length_m,
        input_radius_m: rig.input_radius_m,
        output_radius_m: rig.output_radius_m,
        output_inertia_kg_m2: rig.output_inertia_kg_m2,
        output_damping_n_m_s: rig.output_damping_n_m_s,
        relay_pulleys: rig.relay_pulleys,
        relay_radius_m: rig.relay_radius_m,
        relay_friction: None,
        tensioner: DriveTensioner::ConstantForce,
        mean_tension_n,
        prestretch_n: 490.0,
    }
}

/// Simulates `spec` with the plant effects `effects` (relay pulleys, output shaft) on
/// the input series `input_rad` sampled every `dt_s`.
pub fn simulate_sweep(
    spec: DriveRig,
    effects: &[Applied],
    input_rad: &[f64],
    dt_s: f64,
    substeps: usize,
) -> Result<SimSweep, DriveError> {
    let substeps = substeps.max(1);
    let model = RigModel::with_effects(spec, effects, dt_s / substeps as f64)?;
    let mut st = model.rest_state();
    let n = input_rad.len();
    let mut out = SimSweep {
        output_rad: Vec::with_capacity(n),
        tension_1_n: Vec::with_capacity(n),
        tension_2_n: Vec::with_capacity(n),
        tension_in_1_n: Vec::with_capacity(n),
        tension_in_2_n: Vec::with_capacity(n),
    };
    let push = |out: &mut SimSweep, st: &longreach_drive::RigState| {
        out.output_rad.push(st.output_rad());
        out.tension_1_n.push(st.tension_n(0));
        out.tension_2_n.push(st.tension_n(1));
        out.tension_in_1_n.push(st.tension_in_n(0));
        out.tension_in_2_n.push(st.tension_in_n(1));
    };
    if n == 0 {
        return Ok(out);
    }
    push(&mut out, &st);
    for i in 0..n - 1 {
        let (u0, u1) = (input_rad[i], input_rad[i + 1]);
        // Catmull-Rom slopes (per sample); one-sided at the ends.
        let m0 = if i > 0 {
            0.5 * (u1 - input_rad[i - 1])
        } else {
            u1 - u0
        };
        let m1 = if i + 2 < n {
            0.5 * (input_rad[i + 2] - u0)
        } else {
            u1 - u0
        };
        for k in 1..=substeps {
            let a = k as f64 / substeps as f64;
            model.step(&mut st, hermite(u0, u1, m0, m1, a))?;
        }
        push(&mut out, &st);
    }
    Ok(out)
}

/// The cubic Hermite interpolant at `a` in [0, 1] of the interval from `u0` (slope
/// `m0` per interval) to `u1` (slope `m1`).
#[inline]
fn hermite(u0: f64, u1: f64, m0: f64, m1: f64, a: f64) -> f64 {
    let a2 = a * a;
    let a3 = a2 * a;
    (2.0 * a3 - 3.0 * a2 + 1.0) * u0
        + (a3 - 2.0 * a2 + a) * m0
        + (-2.0 * a3 + 3.0 * a2) * u1
        + (a3 - a2) * m1
}

/// Simulates a sweep run of a dataset with `law`.
pub fn simulate_sweep_run(
    rig: &RigSpec,
    run: &SweepRun,
    law: RopeLaw,
    substeps: usize,
) -> Result<SimSweep, DriveError> {
    let spec = drive_rig(rig, law, run.mean_tension_n);
    simulate_sweep(spec, &[], drive_input(run), run.dt_s(), substeps)
}

/// True when `law` is exactly the paper's four-element model (eq. 6 applies).
fn is_plain_four_element(law: &RopeLaw) -> bool {
    law.c1_n_s == 0.0
        && law.c2_n_s.is_some()
        && law.kelvin.len() == 1
        && law.kp_n.is_none()
        && law.is_linear()
}

/// Tension [N] of a specimen held at `strain` from t = 0 (eq. 5 initial state) at the
/// sample times `time_s` (increasing, first >= 0).
pub fn simulate_relaxation(
    law: &RopeLaw,
    strain: f64,
    time_s: &[f64],
) -> Result<Vec<f64>, DriveError> {
    if let (true, Some(c2)) = (is_plain_four_element(law), law.c2_n_s) {
        let k = law.kelvin[0];
        return Ok(time_s
            .iter()
            .map(|&t| relaxation_tension_n(law.k1_n, c2, k.k_n, k.c_n_s, strain, t))
            .collect());
    }
    let mut out = Vec::with_capacity(time_s.len());
    let mut prev_t = 0.0;
    let mut state: Option<(RopeStepper, longreach_rope::RopeState)> = None;
    let mut dt_cur = f64::NAN;
    for &t in time_s {
        let gap = t - prev_t;
        if gap > 0.0 {
            let h = gap / ROPE_SUBSTEPS as f64;
            let (stepper, st) = match state.take() {
                Some((s, st)) if ((h - dt_cur) / h).abs() < 1e-9 => (s, st),
                Some((_, st)) => (RopeStepper::new(law.clone(), h)?, st),
                None => {
                    let s = RopeStepper::new(law.clone(), h)?;
                    let st = s.instant_strain_state(strain);
                    (s, st)
                }
            };
            dt_cur = h;
            let mut st = st;
            for _ in 0..ROPE_SUBSTEPS {
                let p = stepper.prepare(&st);
                stepper.commit(&p, &mut st, strain);
            }
            state = Some((stepper, st));
        } else if state.is_none() {
            let s = RopeStepper::new(law.clone(), 0.01)?;
            let st = s.instant_strain_state(strain);
            state = Some((s, st));
        }
        prev_t = t;
        let f = state.as_ref().map_or(f64::NAN, |(_, st)| st.tension_n);
        if !f.is_finite() {
            return Err(DriveError::BlowUp {
                time_s: t,
                what: format!("relaxation tension {f} N"),
            });
        }
        out.push(f);
    }
    Ok(out)
}

/// Tension [N] of a specimen following the strain history `strain` sampled at `time_s`,
/// starting unloaded.
pub fn simulate_cyclic(
    law: &RopeLaw,
    time_s: &[f64],
    strain: &[f64],
) -> Result<Vec<f64>, DriveError> {
    let mut out = Vec::with_capacity(time_s.len());
    if time_s.is_empty() {
        return Ok(out);
    }
    let dt = (time_s[time_s.len() - 1] - time_s[0]) / (time_s.len().max(2) - 1) as f64;
    let h = (dt / ROPE_SUBSTEPS as f64).clamp(1e-9, 1.0);
    let stepper = RopeStepper::new(law.clone(), h)?;
    let mut st = stepper.instant_strain_state(strain[0]);
    out.push(st.tension_n);
    for w in strain.windows(2) {
        for k in 1..=ROPE_SUBSTEPS {
            let e = w[0] + (w[1] - w[0]) * k as f64 / ROPE_SUBSTEPS as f64;
            let p = stepper.prepare(&st);
            stepper.commit(&p, &mut st, e);
        }
        if !st.tension_n.is_finite() {
            return Err(DriveError::BlowUp {
                time_s: f64::NAN,
                what: "cyclic tension".into(),
            });
        }
        out.push(st.tension_n);
    }
    Ok(out)
}
