//! A comparison with measurements in Rerun: measured and model outputs overlaid per
//! run with the residual, per-frequency gain and phase of both, and the candidate
//! ranking of a diagnosis.
//!
//! Entity paths (see docs/rerun.md), `<run>` being the run's name:
//!
//! ```text
//! /compare/<run>/{measured,model,residual}      compared channel on sim_time (rad or N)
//! /compare/<run>/with_effect                    model + the winning effect (diagnose)
//! /frequency/<run>/gain_db/{measured,model}     per test frequency, timeline frequency_mhz
//! /frequency/<run>/phase_deg/{measured,model}   (series named "<run> measured", "<run> model")
//! /diagnose/ranking                             the candidate table (markdown)
//! /diagnose/nrmse                               NRMSE bar chart: baseline, then candidates best first
//! ```
//!
//! Default layout: a tab per run (measured, model and residual on `sim_time`), a tab
//! with the gain and phase of every run (on `frequency_mhz`), and for `diagnose` the
//! ranking beside them.

use longreach_ident::analysis::{Comparison, Diagnosis, Prepared};
use rerun::blueprint::{
    BarChartView, Blueprint, BlueprintActivation, Horizontal, Tabs, TextDocumentView,
    TimeSeriesView, Vertical,
};
use rerun::{BarChart, TextDocument};

use crate::{Columns, Recorder, SIM_TIME};

/// Timeline of per-frequency values: the test frequency in millihertz.
pub const FREQUENCY_TIMELINE: &str = "frequency_mhz";

/// Logs a comparison (and, for `diagnose`, the diagnosis and the outputs of the model
/// with the winning effect). `sims[i]` is the model's compared channel on run `i`'s
/// sample times.
pub fn log_comparison(
    rec: &Recorder,
    prep: &Prepared<'_>,
    cmp: &Comparison,
    sims: &[Vec<f64>],
    diagnosis: Option<&Diagnosis>,
    with_effect: Option<&[Vec<f64>]>,
) {
    if !rec.is_enabled() {
        return;
    }
    let mut run_views = Vec::new();
    let mut freq_runs = Vec::new();
    for (i, run) in prep.runs.iter().enumerate() {
        let name = sanitize(&run.name);
        let Some(sim) = sims.get(i) else { continue };
        let mut cols = Columns::on_duration(SIM_TIME);
        let m = cols.series(format!("/compare/{name}/measured"));
        let s = cols.series(format!("/compare/{name}/model"));
        let r = cols.series(format!("/compare/{name}/residual"));
        let w = with_effect.map(|_| cols.series(format!("/compare/{name}/with_effect")));
        for (k, t) in run.time_s.iter().enumerate() {
            let (Some(meas), Some(model)) = (run.measured.get(k), sim.get(k)) else {
                break;
            };
            cols.frame_at_s(*t);
            cols.push(m, *meas);
            cols.push(s, *model);
            cols.push(r, meas - model);
            if let (Some(w), Some(after)) = (w, with_effect) {
                cols.push(
                    w,
                    after
                        .get(i)
                        .and_then(|a| a.get(k))
                        .copied()
                        .unwrap_or(f64::NAN),
                );
            }
        }
        cols.flush(rec.sink());
        let mut freq = Columns::on_sequence(FREQUENCY_TIMELINE);
        // Named after the run: the frequency tab overlays every run.
        let mut named = |what: &str, source: &str| {
            freq.series_group(
                format!("/frequency/{name}/{what}/{source}"),
                vec![format!("{} {source}", run.name)],
            )
        };
        let gm = named("gain_db", "measured");
        let gs = named("gain_db", "model");
        let pm = named("phase_deg", "measured");
        let ps = named("phase_deg", "model");
        for f in cmp.frequency.iter().filter(|f| f.run == run.name) {
            freq.frame_at((f.frequency_hz * 1e3).round() as i64);
            freq.push(gm, f.gain_measured_db);
            freq.push(gs, f.gain_model_db);
            freq.push(pm, f.phase_measured_deg);
            freq.push(ps, f.phase_model_deg);
        }
        if freq.frames() > 0 {
            freq_runs.push(name.clone());
        }
        freq.flush(rec.sink());
        run_views.push(
            TimeSeriesView::new(format!("{} measured vs model ({SIM_TIME})", run.name))
                .with_origin(format!("/compare/{name}"))
                .into(),
        );
    }
    // Rerun plots every series against the time panel's one timeline
    // (rerun-io/rerun#8050): the per-frequency values of every run get a tab of their
    // own, named after the timeline it needs.
    if !freq_runs.is_empty() {
        let every_run = |what: &str| -> Vec<String> {
            freq_runs
                .iter()
                .map(|name| format!("+ /frequency/{name}/{what}/**"))
                .collect()
        };
        run_views.push(
            gain_and_phase("/frequency", every_run)
                .with_name(format!("frequency response ({FREQUENCY_TIMELINE})"))
                .into(),
        );
    }
    let stream = rec.stream();
    let mut top = vec![Tabs::new(run_views).into()];
    if let Some(d) = diagnosis {
        top.push(log_diagnosis(rec, d).into());
    }
    let bp = Blueprint::new(Horizontal::new(top));
    rec.report("blueprint", bp.send(stream, BlueprintActivation::default()));
}

/// Logs the ranking of a diagnosis (`/diagnose/ranking`, `/diagnose/nrmse`); the views
/// that show it.
pub(crate) fn log_diagnosis(rec: &Recorder, d: &Diagnosis) -> Vertical {
    let stream = rec.stream();
    let mut md = format!(
        "# Diagnosis of {}\n\nbaseline NRMSE {:.4} (noise floor {:.4})\n\n| rank | effect | NRMSE | score (dBIC) | explains | decisive |\n|---|---|---|---|---|---|\n",
        d.dataset, d.baseline.nrmse, d.baseline.noise_floor_nrmse
    );
    for (k, c) in d.candidates.iter().enumerate() {
        md.push_str(&format!(
            "| {} | {} | {:.4} | {:.1} | {:.0}% | {} |\n",
            k + 1,
            c.effect,
            c.nrmse,
            c.score,
            100.0 * c.explained.clamp(0.0, 1.0),
            c.decisive
        ));
    }
    md.push_str(&format!(
        "\n**missing effect:** {}\n\n{}\n",
        d.missing_effect.as_deref().unwrap_or("none found"),
        d.explanation
    ));
    rec.report(
        "/diagnose/ranking",
        stream.log_static("/diagnose/ranking", &TextDocument::from_markdown(md)),
    );
    let bars: Vec<f64> = std::iter::once(d.baseline.nrmse)
        .chain(d.candidates.iter().map(|c| c.nrmse))
        .collect();
    rec.report(
        "/diagnose/nrmse",
        stream.log_static("/diagnose/nrmse", &BarChart::new(bars)),
    );
    Vertical::new([
        TextDocumentView::new("Candidates")
            .with_origin("/diagnose/ranking")
            .into(),
        BarChartView::new("NRMSE: baseline, then candidates")
            .with_origin("/diagnose/nrmse")
            .into(),
    ])
}

/// Gain and phase plots side by side (on [`FREQUENCY_TIMELINE`]): views of `origin`
/// showing `contents("gain_db")` and `contents("phase_deg")`.
pub(crate) fn gain_and_phase(origin: &str, contents: impl Fn(&str) -> Vec<String>) -> Horizontal {
    Horizontal::new([
        TimeSeriesView::new("gain (dB) vs frequency (mHz)")
            .with_origin(origin)
            .with_contents(contents("gain_db"))
            .into(),
        TimeSeriesView::new("phase (deg) vs frequency (mHz)")
            .with_origin(origin)
            .with_contents(contents("phase_deg"))
            .into(),
    ])
}

/// A run name as one entity-path part (letters, digits, `_`, `-`, `.`).
pub fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect()
}
