//! Bode scenarios: the rig swept by a stepped sine at several mean tensions, simulated
//! and compared with eqs. 12-13 (`longreach bode`).

use serde::{Deserialize, Serialize};

use longreach_drive::sweep::{self, FrequencyPoint, RigTrace};
use longreach_drive::{
    rig_resonance, DriveError, InputSignal, Resonance, RigModel, RigSpec, SteppedSine,
};

use crate::error::ScenarioError;
use crate::rig::RigSection;
use crate::spec::{field_error, from_toml};

fn default_settle_s() -> f64 {
    8.0
}
fn default_min_cycles() -> u32 {
    2
}
fn default_min_hold_s() -> f64 {
    2.0
}
fn default_dt_s() -> f64 {
    1e-3
}

/// `[sweep]`: the stepped sine and the mean tensions to test.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSection {
    /// Mean rope tensions, one run each [N].
    pub mean_tensions_n: Vec<f64>,
    /// Input amplitude [rad] (give this or `amplitude_deg`).
    #[serde(default)]
    pub amplitude_rad: Option<f64>,
    /// Input amplitude [deg] (give this or `amplitude_rad`).
    #[serde(default)]
    pub amplitude_deg: Option<f64>,
    /// Test frequencies [Hz].
    pub frequencies_hz: Vec<f64>,
    /// Transient time per frequency, not analysed [s].
    #[serde(default = "default_settle_s")]
    pub settle_s: f64,
    /// Least whole cycles analysed per frequency.
    #[serde(default = "default_min_cycles")]
    pub min_cycles: u32,
    /// Least analysed time per frequency [s].
    #[serde(default = "default_min_hold_s")]
    pub min_hold_s: f64,
}

/// `[simulation]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSection {
    /// Time step [s].
    #[serde(default = "default_dt_s")]
    pub dt_s: f64,
}

impl Default for SimulationSection {
    fn default() -> Self {
        Self {
            dt_s: default_dt_s(),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct BodeFile {
    #[serde(default)]
    title: String,
    #[serde(default)]
    kind: Option<String>,
    rig: RigSection,
    sweep: SweepSection,
    #[serde(default)]
    simulation: SimulationSection,
}

/// A validated bode scenario: one rig per mean tension, one stepped sine.
#[derive(Debug, Clone)]
pub struct BodeScenario {
    /// Title for reports.
    pub title: String,
    /// One rig per mean tension, in file order.
    pub rigs: Vec<RigSpec>,
    /// The input.
    pub sine: SteppedSine,
    /// Time step [s].
    pub dt_s: f64,
    /// What the user should know about this scenario's numbers (a time step coarser
    /// than the rig's fastest mode or the test frequencies need): printed once by the
    /// CLI and recorded in its JSON.
    pub warnings: Vec<String>,
}

/// Relative frequency error of the trapezoidal rule (the rig's integrator) on an
/// undamped mode of `omega` rad/s at step `dt_s`: it rings at `(2/dt) atan(omega dt/2)`.
pub fn trapezoid_frequency_error(omega: f64, dt_s: f64) -> f64 {
    let x = omega * dt_s;
    if x <= 0.0 {
        return 0.0;
    }
    1.0 - (2.0 / x) * (x / 2.0).atan()
}

/// Relative frequency error of the fastest mode above which a warning is printed.
pub const MODE_ERROR_WARN: f64 = 1e-3;
/// ... and above which a Bode result is refused (`omega dt` > 1.9): the mode's image,
/// `(2/dt) atan(omega dt/2)`, has moved past a quarter of the sampling rate towards the
/// Nyquist rate, where the test frequencies are (a stiff rope at dt = 0.05 s read
/// +15 dB where the answer is 0 dB).
pub const MODE_ERROR_REFUSE: f64 = 0.2;
/// Least steps per period of the highest test frequency before a warning.
pub const STEPS_PER_PERIOD_WARN: f64 = 20.0;

/// The rig's fastest mode [rad/s]: the output pulley on the two ropes' head springs
/// (the stiffest element of every law, stiffened at twice the mean tension for a
/// stiffening rope), `omega^2 = 2 r2^2 k / (L I)`.
pub fn rig_fastest_mode(spec: &RigSpec) -> f64 {
    let law = &spec.law;
    let stiffening = 1.0 + law.stiffening_per_n.max(0.0) * 2.0 * spec.mean_tension_n.max(0.0);
    let k = law.k1_n * stiffening / spec.rope_length_m;
    (2.0 * spec.output_radius_m.powi(2) * k / spec.output_inertia_kg_m2).sqrt()
}

/// Checks `dt_s` against the test frequencies (every one below the Nyquist rate) and
/// the rig's fastest mode (refused when the trapezoidal rule moves it by more than
/// [`MODE_ERROR_REFUSE`]); returns the warnings for a step that resolves them less well
/// than it should, each with the step that would.
fn check_time_step(
    text: &str,
    file: &str,
    rigs: &[RigSpec],
    sine: &SteppedSine,
    dt_s: f64,
) -> Result<Vec<String>, ScenarioError> {
    let mut warnings = Vec::new();
    let nyquist_hz = 0.5 / dt_s;
    for (i, &f) in sine.frequencies_hz.iter().enumerate() {
        if f >= nyquist_hz {
            return Err(field_error(
                text,
                file,
                &format!("sweep.frequencies_hz.{i}"),
                format!(
                    "{f} Hz is at or above the Nyquist rate {nyquist_hz} Hz of dt_s = {dt_s} s"
                ),
                &format!(
                    "test below {nyquist_hz} Hz, or give simulation.dt_s <= {:.3e} s",
                    1.0 / (STEPS_PER_PERIOD_WARN * f)
                ),
            ));
        }
    }
    let f_max = sine.frequencies_hz.iter().copied().fold(0.0, f64::max);
    if f_max * dt_s * STEPS_PER_PERIOD_WARN > 1.0 {
        warnings.push(format!(
            "{file}: simulation.dt_s = {dt_s} s gives {:.1} steps per period at {f_max} Hz (fewer than {STEPS_PER_PERIOD_WARN}); dt_s <= {:.3e} s resolves it",
            1.0 / (f_max * dt_s),
            1.0 / (STEPS_PER_PERIOD_WARN * f_max)
        ));
    }
    let (omega, tension) = rigs
        .iter()
        .map(|r| (rig_fastest_mode(r), r.mean_tension_n))
        .fold((0.0, 0.0), |a, b| if b.0 > a.0 { b } else { a });
    if !omega.is_finite() {
        return Ok(warnings);
    }
    let error = trapezoid_frequency_error(omega, dt_s);
    // The step that keeps the mode within MODE_ERROR_WARN: error ~ (omega dt)^2 / 12.
    let good_dt = (12.0 * MODE_ERROR_WARN).sqrt() / omega;
    let mode_hz = omega / std::f64::consts::TAU;
    if error > MODE_ERROR_REFUSE {
        return Err(field_error(
            text,
            file,
            "simulation.dt_s",
            format!(
                "dt_s = {dt_s} s is too coarse for the rig's fastest mode ({mode_hz:.1} Hz at {tension} N): the integrator moves it by {:.0}% and the simulated gain would be wrong",
                100.0 * error
            ),
            &format!("give dt_s <= {good_dt:.3e} s"),
        ));
    }
    if error > MODE_ERROR_WARN {
        warnings.push(format!(
            "{file}: simulation.dt_s = {dt_s} s resolves the rig's fastest mode ({mode_hz:.1} Hz at {tension} N) to {:.2}% in frequency; dt_s <= {good_dt:.3e} s resolves it to {:.1}%",
            100.0 * error,
            100.0 * MODE_ERROR_WARN
        ));
    }
    Ok(warnings)
}

/// One mean tension's analytic and simulated response.
#[derive(Debug, Clone, Serialize)]
pub struct BodeRun {
    /// Mean tension [N].
    pub mean_tension_n: f64,
    /// Analytic resonance (eq. 12/13).
    pub analytic: Option<Resonance>,
    /// Simulated resonance: the test frequency with the largest simulated gain,
    /// refined by a parabola through it and its neighbours (log frequency, dB).
    pub simulated: Option<Resonance>,
    /// True when a rope went slack somewhere in the analysed windows.
    pub slack: bool,
    /// Every test frequency.
    pub points: Vec<FrequencyPoint>,
}

impl BodeScenario {
    /// Parses and validates a bode scenario; `file` names it in errors.
    pub fn from_str(text: &str, file: &str) -> Result<Self, ScenarioError> {
        let raw: BodeFile = from_toml(text, file)?;
        if let Some(kind) = &raw.kind {
            if kind != "bode" {
                return Err(field_error(
                    text,
                    file,
                    "kind",
                    format!("`{kind}` is not a bode scenario"),
                    "use kind = \"bode\" (or omit it) for `longreach bode`",
                ));
            }
        }
        let sw = &raw.sweep;
        let amplitude_rad = match (sw.amplitude_rad, sw.amplitude_deg) {
            (Some(r), None) => r,
            (None, Some(d)) => d.to_radians(),
            _ => {
                return Err(field_error(
                    text,
                    file,
                    "sweep",
                    "give exactly one of amplitude_rad and amplitude_deg".into(),
                    "e.g. amplitude_deg = 4.5",
                ))
            }
        };
        if sw.mean_tensions_n.is_empty() {
            return Err(field_error(
                text,
                file,
                "sweep.mean_tensions_n",
                "the list is empty".into(),
                "list at least one mean tension in N, e.g. [49.0, 98.0]",
            ));
        }
        let sine = SteppedSine {
            amplitude_rad,
            frequencies_hz: sw.frequencies_hz.clone(),
            settle_s: sw.settle_s,
            min_cycles: sw.min_cycles,
            min_hold_s: sw.min_hold_s,
        };
        sine.validate().map_err(|e| match e {
            DriveError::BadParameter { field, value, reason } => {
                let field = if field == "amplitude_rad" && sw.amplitude_deg.is_some() {
                    "amplitude_deg".to_string()
                } else {
                    field
                };
                field_error(
                    text,
                    file,
                    &format!("sweep.{field}"),
                    format!("{value} {reason}"),
                    "give positive frequencies [Hz], a positive amplitude and non-negative times [s]",
                )
            }
            other => field_error(text, file, "sweep", other.to_string(), ""),
        })?;
        let dt_s = raw.simulation.dt_s;
        if !(dt_s.is_finite() && dt_s > 0.0 && dt_s <= 0.05) {
            return Err(field_error(
                text,
                file,
                "simulation.dt_s",
                format!("{dt_s} must be in (0, 0.05] s"),
                "1e-3 s resolves the rig's 2-4 Hz resonance to better than 0.01 dB",
            ));
        }
        let duration_s: f64 = sine.steps().last().map_or(0.0, |last| last.end_s);
        if let Err(steps) = crate::limits::check_steps(duration_s, dt_s) {
            return Err(field_error(
                text,
                file,
                "sweep.settle_s",
                format!(
                    "the sweep lasts {duration_s:.3e} s: {steps:.3e} steps of {dt_s} s, past the limit of {:.0e} steps per run",
                    crate::limits::MAX_STEPS_PER_RUN
                ),
                "shorten settle_s or min_hold_s, drop the lowest frequencies, or split the sweep into several scenarios",
            ));
        }
        let rigs = sw
            .mean_tensions_n
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                raw.rig
                    .to_spec(text, file, t, &format!("sweep.mean_tensions_n.{i}"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let warnings = check_time_step(text, file, &rigs, &sine, dt_s)?;
        Ok(Self {
            title: raw.title,
            rigs,
            sine,
            dt_s,
            warnings,
        })
    }

    /// Reads and validates a bode scenario file.
    pub fn from_file(path: &std::path::Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
            file: path.display().to_string(),
            line: None,
            field: String::new(),
            message: format!("cannot read the file: {e}"),
            fix: "check the path".into(),
        })?;
        Self::from_str(&text, &path.display().to_string())
    }

    /// Simulates one mean tension (index into `rigs`).
    pub fn run_one(&self, index: usize) -> Result<BodeRun, DriveError> {
        self.run_one_traced(index).map(|(run, _)| run)
    }

    /// [`Self::run_one`], also returning the run's time series (one sample per step).
    pub fn run_one_traced(&self, index: usize) -> Result<(BodeRun, RigTrace), DriveError> {
        let spec = &self.rigs[index];
        let model = RigModel::new(spec.clone(), self.dt_s)?;
        let input = InputSignal::stepped_sine(self.sine.clone())?;
        let trace = sweep::run(&model, &input)?;
        let points = sweep::frequency_response(&model, &self.sine, &trace);
        let f_lo = self
            .sine
            .frequencies_hz
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        let f_hi = self.sine.frequencies_hz.iter().copied().fold(0.0, f64::max);
        let run = BodeRun {
            mean_tension_n: spec.mean_tension_n,
            analytic: rig_resonance(spec, f_lo, f_hi),
            simulated: peak_of_points(&points),
            slack: points.iter().any(|p| p.min_tension_n <= 0.0),
            points,
        };
        Ok((run, trace))
    }

    /// Simulates every mean tension, in order.
    pub fn run_all(&self) -> Result<Vec<BodeRun>, DriveError> {
        (0..self.rigs.len()).map(|i| self.run_one(i)).collect()
    }
}

/// Peak of a sampled gain curve: the largest point refined by a parabola in
/// (log frequency, dB) through it and its two neighbours in frequency. `None` at the
/// ends of the band.
pub fn peak_of_points(points: &[FrequencyPoint]) -> Option<Resonance> {
    let curve: Vec<(f64, f64)> = points
        .iter()
        .map(|p| (p.frequency_hz, p.simulated_gain_db))
        .collect();
    peak_of_curve(&curve).map(|(frequency_hz, peak_gain_db)| Resonance {
        frequency_hz,
        peak_gain_db,
    })
}

/// Peak `(f, dB)` of a gain curve given as `(frequency, gain in dB)` points in any
/// order (a sweep plays its frequencies in the order given): the largest finite point
/// refined by a parabola in `(ln f, dB)` through it and its neighbours in frequency.
/// `None` at an end of the band; a repeated frequency keeps the sampled peak.
pub fn peak_of_curve(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|p| p.0 > 0.0 && p.0.is_finite() && p.1.is_finite())
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (k, _) = pts
        .iter()
        .enumerate()
        .max_by(|a, b| a.1 .1.total_cmp(&b.1 .1))?;
    if k == 0 || k + 1 >= pts.len() {
        return None;
    }
    let (x0, x1, x2) = (pts[k - 1].0.ln(), pts[k].0.ln(), pts[k + 1].0.ln());
    let (y0, y1, y2) = (pts[k - 1].1, pts[k].1, pts[k + 1].1);
    if x1 <= x0 || x2 <= x1 {
        return Some(pts[k]);
    }
    // Vertex of the parabola through three points.
    let d1 = (y1 - y0) / (x1 - x0);
    let d2 = (y2 - y1) / (x2 - x1);
    let a = (d2 - d1) / (x2 - x0);
    if a >= 0.0 || !a.is_finite() {
        return Some(pts[k]);
    }
    // Newton form y = y0 + d1 (x - x0) + a (x - x0)(x - x1); its vertex:
    let xv = (0.5 * (x0 + x1) - d1 / (2.0 * a)).clamp(x0, x2);
    let yv = y0 + d1 * (xv - x0) + a * (xv - x0) * (xv - x1);
    Some((xv.exp(), yv))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(f: f64, g: f64) -> FrequencyPoint {
        FrequencyPoint {
            frequency_hz: f,
            analytic_gain_db: 0.0,
            analytic_phase_deg: 0.0,
            simulated_gain_db: g,
            simulated_phase_deg: 0.0,
            min_tension_n: 1.0,
        }
    }

    #[test]
    fn peak_does_not_depend_on_the_order_of_frequencies() {
        let up = [point(1.0, 0.0), point(2.0, 10.0), point(3.0, 2.0)];
        let down = [point(3.0, 2.0), point(2.0, 10.0), point(1.0, 0.0)];
        let a = peak_of_points(&up).unwrap();
        let b = peak_of_points(&down).unwrap();
        assert_eq!(a.frequency_hz.to_bits(), b.frequency_hz.to_bits());
        let twice = [point(2.0, 1.0), point(2.0, 10.0), point(2.0, 2.0)];
        assert!(peak_of_points(&twice).is_some());
    }
}
