//! The scenario kinds a batch can run: each parses an expanded scenario (TOML text) and
//! runs it into a flat list of named metrics. A new kind is one variant and one arm in
//! [`Kind::from_name`], [`Kind::check`] and [`Kind::run`].

use crate::bode::BodeScenario;
use crate::error::ScenarioError;

use super::row::Cell;

/// A scenario kind, from the base scenario's `kind` key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// The paper's rig swept by a stepped sine (`longreach bode`); the default kind.
    Bode,
}

/// Why a scenario produced no metrics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RowError {
    /// The model rejected the scenario (a status `invalid` row).
    Invalid(String),
    /// The run failed (a status `failed` row).
    Failed(String),
}

/// What a run produced: metrics, and the full output when asked for.
pub type Outcome = (Vec<(String, Option<Cell>)>, Option<serde_json::Value>);

impl Kind {
    /// The kind named by a scenario's `kind` key (`None`: the key is absent).
    pub fn from_name(name: Option<&str>) -> Option<Self> {
        match name {
            None | Some("bode") => Some(Self::Bode),
            Some(_) => None,
        }
    }

    /// The kind's name, as written in `kind = "..."`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Bode => "bode",
        }
    }

    /// The names `kind` may take, for error messages.
    pub const NAMES: &'static str = "bode";

    /// Parses and validates a scenario of this kind.
    pub fn check(self, text: &str, file: &str) -> Result<(), ScenarioError> {
        match self {
            Self::Bode => BodeScenario::from_str(text, file).map(|_| ()),
        }
    }

    /// Parses, validates and runs a scenario; `keep_output` also returns the full result
    /// as JSON. A metric that is NaN or infinite fails the row (numerical blow-up).
    pub fn run(self, text: &str, file: &str, keep_output: bool) -> Result<Outcome, RowError> {
        let (metrics, output) = match self {
            Self::Bode => run_bode(text, file, keep_output)?,
        };
        for (name, cell) in &metrics {
            if let Some(Cell::Float(v)) = cell {
                if !v.is_finite() {
                    return Err(RowError::Failed(format!(
                        "numerical blow-up: metric `{name}` is {v}"
                    )));
                }
            }
        }
        Ok((metrics, output))
    }
}

/// A bode scenario's metrics, per mean tension run (prefixed `t<tension>_` when the
/// scenario has several): analytic and simulated resonance [Hz] and peak gain [dB]
/// (empty when the peak lies outside the tested band), slack flag, least tension [N].
fn run_bode(text: &str, file: &str, keep_output: bool) -> Result<Outcome, RowError> {
    let scenario =
        BodeScenario::from_str(text, file).map_err(|e| RowError::Invalid(one_line(&e)))?;
    let runs = scenario
        .run_all()
        .map_err(|e| RowError::Failed(e.to_string()))?;
    let several = runs.len() > 1;
    let mut metrics = Vec::with_capacity(6 * runs.len());
    for run in &runs {
        let prefix = if several {
            format!("t{}_", run.mean_tension_n).replace('.', "p")
        } else {
            String::new()
        };
        let mut push = |name: &str, cell: Option<Cell>| {
            metrics.push((format!("{prefix}{name}"), cell));
        };
        let f = |r: Option<longreach_drive::Resonance>| r.map(|r| Cell::Float(r.frequency_hz));
        let g = |r: Option<longreach_drive::Resonance>| r.map(|r| Cell::Float(r.peak_gain_db));
        push("analytic_resonance_hz", f(run.analytic));
        push("simulated_resonance_hz", f(run.simulated));
        push("analytic_peak_gain_db", g(run.analytic));
        push("simulated_peak_gain_db", g(run.simulated));
        push("slack", Some(Cell::Bool(run.slack)));
        let min_tension_n = run
            .points
            .iter()
            .map(|p| p.min_tension_n)
            .fold(f64::INFINITY, f64::min);
        push(
            "min_tension_n",
            (!run.points.is_empty()).then_some(Cell::Float(min_tension_n)),
        );
    }
    let output = if keep_output {
        Some(serde_json::to_value(&runs).map_err(|e| RowError::Failed(e.to_string()))?)
    } else {
        None
    };
    Ok((metrics, output))
}

/// A scenario error on one line (rows hold one-line errors).
pub fn one_line(e: &ScenarioError) -> String {
    let mut s = String::new();
    if !e.field.is_empty() {
        s.push_str(&format!("field `{}`: ", e.field));
    }
    s.push_str(&e.message);
    if !e.fix.is_empty() {
        s.push_str(&format!(" (fix: {})", e.fix));
    }
    s.replace('\n', " ")
}
