//! Stepped-sine runs of the rig and their simulated frequency response, beside the
//! analytic one (eqs. 12-13).

use serde::Serialize;

use crate::error::DriveError;
use crate::freq::{single_bin, unwrap_deg};
use crate::rig::{RigModel, RigState};
use crate::signal::{InputSignal, SineStep, SteppedSine};
use crate::tf::{gain_phase, rig_transfer};

/// One test frequency: analytic and simulated response, and the rope tension floor.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrequencyPoint {
    /// Test frequency [Hz].
    pub frequency_hz: f64,
    /// Gain of eq. 12/13 [dB].
    pub analytic_gain_db: f64,
    /// Phase of eq. 12/13 [deg].
    pub analytic_phase_deg: f64,
    /// Gain from the simulated run (single-bin DFT over the analysed cycles) [dB].
    pub simulated_gain_db: f64,
    /// Phase from the simulated run [deg].
    pub simulated_phase_deg: f64,
    /// Smallest rope tension in the analysed window [N] (0 = a rope went slack).
    pub min_tension_n: f64,
}

/// A recorded time series of a rig run (one sample per step, plus t = 0).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RigTrace {
    /// Time [s].
    pub time_s: Vec<f64>,
    /// Input angle [rad].
    pub input_rad: Vec<f64>,
    /// Output angle [rad].
    pub output_rad: Vec<f64>,
    /// Rope 1 tension [N].
    pub tension_1_n: Vec<f64>,
    /// Rope 2 tension [N].
    pub tension_2_n: Vec<f64>,
}

impl RigTrace {
    fn push(&mut self, s: &RigState) {
        self.time_s.push(s.time_s());
        self.input_rad.push(s.input_rad());
        self.output_rad.push(s.output_rad());
        self.tension_1_n.push(s.tension_n(0));
        self.tension_2_n.push(s.tension_n(1));
    }
}

/// Runs the rig through `input` from rest and returns its trace. Time `t_n = n dt`.
pub fn run(model: &RigModel, input: &InputSignal) -> Result<RigTrace, DriveError> {
    let dt = model.dt_s();
    let n = (input.duration_s() / dt).round() as usize;
    let mut st = model.rest_state();
    let mut trace = RigTrace::default();
    for v in [
        &mut trace.time_s,
        &mut trace.input_rad,
        &mut trace.output_rad,
        &mut trace.tension_1_n,
        &mut trace.tension_2_n,
    ] {
        v.reserve(n + 1);
    }
    trace.push(&st);
    for i in 1..=n {
        model.step(&mut st, input.angle_rad(i as f64 * dt))?;
        trace.push(&st);
    }
    Ok(trace)
}

/// Sample range `[start, end)` of a step's analysed window on a grid `t_n = n dt`:
/// the whole cycles that end at the step's end, rounded to whole samples.
pub fn analysis_window(step: &SineStep, dt_s: f64) -> (usize, usize) {
    let end = (step.end_s / dt_s).round() as usize;
    let len = (f64::from(step.cycles) / step.frequency_hz / dt_s).round() as usize;
    (end + 1 - len.min(end + 1), end + 1)
}

/// Simulated frequency response of a stepped-sine trace, beside the analytic one.
pub fn frequency_response(
    model: &RigModel,
    sine: &SteppedSine,
    trace: &RigTrace,
) -> Vec<FrequencyPoint> {
    let dt = model.dt_s();
    let mut points: Vec<FrequencyPoint> = sine
        .steps()
        .iter()
        .map(|step| {
            let (a, b) = analysis_window(step, dt);
            let b = b.min(trace.time_s.len());
            let t = &trace.time_s[a..b];
            let x = single_bin(&trace.input_rad[a..b], t, step.frequency_hz);
            let y = single_bin(&trace.output_rad[a..b], t, step.frequency_hz);
            let (sim_gain, sim_phase) = gain_phase(y / x);
            let (an_gain, an_phase) = gain_phase(rig_transfer(model.spec(), step.frequency_hz));
            let min_tension_n = trace.tension_1_n[a..b]
                .iter()
                .chain(&trace.tension_2_n[a..b])
                .copied()
                .fold(f64::INFINITY, f64::min);
            FrequencyPoint {
                frequency_hz: step.frequency_hz,
                analytic_gain_db: an_gain,
                analytic_phase_deg: an_phase,
                simulated_gain_db: sim_gain,
                simulated_phase_deg: sim_phase,
                min_tension_n,
            }
        })
        .collect();
    // Continuous phase across the sweep, its first point in (-180, 180].
    let unwrapped = |get: fn(&FrequencyPoint) -> f64| {
        let v = unwrap_deg(&points.iter().map(get).collect::<Vec<_>>());
        let shift = v.first().map_or(0.0, |p| 360.0 * (p / 360.0).round());
        v.into_iter().map(move |p| p - shift).collect::<Vec<_>>()
    };
    let an = unwrapped(|p| p.analytic_phase_deg);
    let sim = unwrapped(|p| p.simulated_phase_deg);
    for (p, (a, s)) in points.iter_mut().zip(an.into_iter().zip(sim)) {
        p.analytic_phase_deg = a;
        p.simulated_phase_deg = s;
    }
    points
}
