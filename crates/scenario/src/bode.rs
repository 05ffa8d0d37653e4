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
        let rigs = sw
            .mean_tensions_n
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                raw.rig
                    .to_spec(text, file, t, &format!("sweep.mean_tensions_n.{i}"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            title: raw.title,
            rigs,
            sine,
            dt_s,
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
/// (log frequency, dB) through it and its two neighbours. `None` at the ends.
pub fn peak_of_points(points: &[FrequencyPoint]) -> Option<Resonance> {
    let i = (0..points.len()).max_by(|&a, &b| {
        points[a]
            .simulated_gain_db
            .total_cmp(&points[b].simulated_gain_db)
    })?;
    if i == 0 || i + 1 == points.len() {
        return None;
    }
    let x: Vec<f64> = (i - 1..=i + 1)
        .map(|k| points[k].frequency_hz.ln())
        .collect();
    let y: Vec<f64> = (i - 1..=i + 1)
        .map(|k| points[k].simulated_gain_db)
        .collect();
    // Vertex of the parabola through three points.
    let d1 = (y[1] - y[0]) / (x[1] - x[0]);
    let d2 = (y[2] - y[1]) / (x[2] - x[1]);
    let a = (d2 - d1) / (x[2] - x[0]);
    if a >= 0.0 {
        return Some(Resonance {
            frequency_hz: points[i].frequency_hz,
            peak_gain_db: y[1],
        });
    }
    // Newton form y = y0 + d1 (x - x0) + a (x - x0)(x - x1); its vertex:
    let xv = (0.5 * (x[0] + x[1]) - d1 / (2.0 * a)).clamp(x[0], x[2]);
    let yv = y[0] + d1 * (xv - x[0]) + a * (xv - x[0]) * (xv - x[1]);
    Some(Resonance {
        frequency_hz: xv.exp(),
        peak_gain_db: yv,
    })
}
