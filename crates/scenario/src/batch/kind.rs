//! The scenario kinds a batch can run. A kind parses an expanded scenario (TOML text)
//! and runs it into a flat list of named metrics: the [`ScenarioKind`] trait. This
//! crate provides the rig kind ([`BodeKind`]); crates above it (the arm) implement the
//! trait for theirs, and the caller passes every kind to [`crate::batch::Batch`].

use std::path::Path;
use std::sync::Arc;

use toml::Table;

use crate::bode::BodeScenario;
use crate::error::ScenarioError;

use super::row::Cell;

/// Why a scenario produced no metrics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RowError {
    /// The model rejected the scenario (a status `invalid` row).
    Invalid(String),
    /// The run failed (a status `failed` row).
    Failed(String),
}

/// What a run produced: named metrics (`None`: the metric does not exist for this
/// scenario), and the full output as JSON when asked for.
pub type Outcome = (Vec<(String, Option<Cell>)>, Option<serde_json::Value>);

/// A scenario kind the batch runner can drive.
pub trait ScenarioKind: std::fmt::Debug + Send + Sync {
    /// The name written as `kind = "..."` in a scenario.
    fn name(&self) -> &'static str;

    /// True when a scenario without a `kind` key is of this kind (e.g. it has `[rig]`).
    fn detect(&self, tree: &Table) -> bool;

    /// Parses and validates a scenario; `dir` resolves the base scenario's relative paths.
    fn check(&self, text: &str, file: &str, dir: &Path) -> Result<(), ScenarioError>;

    /// Parses, validates and runs a scenario; with `keep_output`, also returns the full
    /// result as JSON. Metrics must not depend on wall time or thread count.
    fn run(
        &self,
        text: &str,
        file: &str,
        dir: &Path,
        keep_output: bool,
    ) -> Result<Outcome, RowError>;

    /// The scenario `text` as kept by `--keep-outputs` (`scenarios/<index>.toml`): it
    /// must run from that folder, so a kind whose scenarios name files relative to
    /// `dir` makes them absolute. Default: unchanged.
    fn portable_text(&self, text: &str, _dir: &Path) -> String {
        text.to_string()
    }
}

/// The kinds this crate provides: the rig's bode scenarios.
pub fn builtin_kinds() -> Vec<Arc<dyn ScenarioKind>> {
    vec![Arc::new(BodeKind)]
}

/// The paper's rig swept by a stepped sine (`longreach bode`, `kind = "bode"`).
///
/// Metrics per mean tension run (prefixed `t<tension>_` when the scenario has several):
/// analytic and simulated resonance [Hz] and peak gain [dB] (empty when the peak lies
/// outside the tested band), slack flag, least rope tension [N].
#[derive(Debug, Clone, Copy, Default)]
pub struct BodeKind;

impl ScenarioKind for BodeKind {
    fn name(&self) -> &'static str {
        "bode"
    }

    fn detect(&self, tree: &Table) -> bool {
        tree.contains_key("rig") && tree.contains_key("sweep")
    }

    fn check(&self, text: &str, file: &str, _dir: &Path) -> Result<(), ScenarioError> {
        BodeScenario::from_str(text, file).map(|_| ())
    }

    fn run(
        &self,
        text: &str,
        file: &str,
        _dir: &Path,
        keep_output: bool,
    ) -> Result<Outcome, RowError> {
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
