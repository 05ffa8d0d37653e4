//! What an arm's sensors show against a model, in the arm's own terms: the evidence
//! `diagnose` gives on an arm dataset (issue 18: "residual vibration at 3.1 Hz measured
//! against 4.2 Hz in the model on every move of j1"; "the motor settles, the joint keeps
//! a 2 mrad offset").
//!
//! From the comparison's figures of every move ([`super::compare_arm`]), per joint over
//! its moves, a finding when the measurement and the model differ by more than the
//! figure's tolerance:
//!
//! - residual vibration frequency: by more than 5% and a quarter cycle over the window
//!   it is measured in (the time after the command stops);
//! - its damping ratio: by more than a factor 1.25 and 0.003;
//! - 2% settling time: by more than 10% and two samples (one that never settles within
//!   the run counts as settling at its end, at the latest);
//! - overshoot: by more than 1 point of the move and a fifth of the measured one;
//! - peak and minimum rope tension: by more than 3%.
//!
//! From the encoder channels of every run, per driven joint, a finding when the mean of
//! measured minus model over a window is beyond [`OFFSET_COUNTS`] encoder counts (the
//! quantisation noise averages out over the window; a model with nothing missing leaves
//! a fraction of a count):
//!
//! - at rest before the first move (the statics: a payload, the ropes' stiffness);
//! - after the moves, over the last fifth of the run (what holds the joint: friction, the
//!   ropes' give), the joint's offset said against its motor's.
//!
//! Each finding carries its size in tolerances (`weight`); the explanation gives the
//! largest few.

use serde::Serialize;

use super::{ArmComparison, Figures};
use crate::dataset::{ArmMovesDataset, ArmQuantity, ARM_ENCODER_RESOLUTION_RAD};
use crate::plant::Channels;

/// An offset of a joint or motor angle from the model counts when it is beyond this many
/// encoder counts.
pub const OFFSET_COUNTS: f64 = 1.5;

/// How many findings the explanation gives.
pub const FINDINGS_TOLD: usize = 4;

/// One thing the arm's sensors show against the model.
#[derive(Debug, Clone, Serialize)]
pub struct ArmFinding {
    /// The joint.
    pub joint: String,
    /// What differs: `vibration_hz`, `damping_ratio`, `settling_time_s`,
    /// `overshoot_pct`, `peak_tension_n`, `min_tension_n`, `rest_offset_rad` (before the
    /// moves), `settled_offset_rad` (after them).
    pub kind: &'static str,
    /// The runs it shows in.
    pub runs: Vec<String>,
    /// Of how many runs that could show it (moves of the joint; runs for offsets).
    pub of_runs: usize,
    /// Measured value (mean over `runs`; an offset: measured minus model).
    pub measured: f64,
    /// The model's value (mean over `runs`; an offset: the motor's offset).
    pub model: f64,
    /// The difference in tolerances (ordering).
    pub weight: f64,
    /// The finding in words.
    pub sentence: String,
}

/// A figure's measured and model values, and whether they differ beyond tolerance
/// (with the difference in tolerances).
type Judged = Option<(f64, f64, f64)>;

/// How a move's figures can be told apart: the sample interval, the time from the
/// move's start to the end of the run (a figure that never settles settles there at
/// the latest), and the time after the command stops (the window the residual
/// vibration is measured over: its frequency is known to a quarter cycle over it).
#[derive(Debug, Clone, Copy)]
struct Resolution {
    dt_s: f64,
    horizon_s: f64,
    settle_window_s: f64,
}

fn judge(kind: &str, m: &Figures, s: &Figures, res: Resolution) -> Judged {
    let pair = |a: Option<f64>, b: Option<f64>| a.zip(b);
    match kind {
        "vibration_hz" => pair(m.vibration_hz, s.vibration_hz)
            .filter(|(a, _)| *a > 0.0)
            .map(|(a, b)| {
                let tol = (0.05 * a).max(0.25 / res.settle_window_s.max(res.dt_s));
                (a, b, (b - a).abs() / tol)
            }),
        "damping_ratio" => pair(m.damping_ratio, s.damping_ratio)
            .filter(|(a, b)| *a > 0.0 && *b > 0.0)
            .map(|(a, b)| {
                let w = ((b / a).ln().abs() / 1.25f64.ln()).min((b - a).abs() / 0.003);
                (a, b, w)
            }),
        "settling_time_s" => {
            // (one that never settles within the run settles at its end at the latest:
            // judged against that, a settling close to the end is not told apart)
            let at = |x: Option<f64>| x.unwrap_or(res.horizon_s);
            let (a, b) = (at(m.settling_time_s), at(s.settling_time_s));
            (m.settling_time_s.is_some() || s.settling_time_s.is_some()).then(|| {
                let w = (b - a).abs() / (0.1 * a).max(2.0 * res.dt_s);
                let shown = |x: Option<f64>, v: f64| if x.is_some() { v } else { f64::INFINITY };
                (shown(m.settling_time_s, a), shown(s.settling_time_s, b), w)
            })
        }
        "overshoot_pct" => pair(m.overshoot_pct, s.overshoot_pct)
            .map(|(a, b)| (a, b, (b - a).abs() / (0.2 * a.abs()).max(1.0))),
        "peak_tension_n" => pair(m.peak_tension_n, s.peak_tension_n)
            .filter(|(a, _)| *a > 0.0)
            .map(|(a, b)| (a, b, (b / a - 1.0).abs() / 0.03)),
        "min_tension_n" => pair(m.min_tension_n, s.min_tension_n)
            .filter(|(a, _)| *a > 0.0)
            .map(|(a, b)| (a, b, (b / a - 1.0).abs() / 0.03)),
        _ => None,
    }
}

const FIGURES: [&str; 6] = [
    "vibration_hz",
    "damping_ratio",
    "settling_time_s",
    "overshoot_pct",
    "peak_tension_n",
    "min_tension_n",
];

/// "on every move of j5 (2)", "in 1 of the 2 runs (move_01)": where a finding shows,
/// `what` the unit counted ("move of j5", "run").
fn runs_words(runs: &[String], of: usize, what: &str) -> String {
    let (prep, plural) = match what.split_once(' ') {
        Some((a, b)) => ("on", format!("{a}s {b}")),
        None => ("in", format!("{what}s")),
    };
    if runs.len() == of && of > 1 {
        format!("{prep} every {what} ({of})")
    } else if of > 1 {
        format!(
            "{prep} {} of the {of} {plural} ({})",
            runs.len(),
            runs.join(", ")
        )
    } else {
        format!("{prep} the {what} ({})", runs.join(", "))
    }
}

fn figure_sentence(kind: &str, m: f64, s: f64, where_: &str) -> String {
    let num = |x: f64, d: usize| {
        if x.is_finite() {
            format!("{x:.d$}")
        } else {
            "never".into()
        }
    };
    match kind {
        "vibration_hz" => format!(
            "residual vibration at {} Hz measured against {} Hz in the model {where_}",
            num(m, 2),
            num(s, 2)
        ),
        "damping_ratio" => format!(
            "the residual vibration dies out with a damping ratio of {} measured against {} in the model {where_}",
            num(m, 3),
            num(s, 3)
        ),
        "settling_time_s" => {
            let t = |x: f64| {
                if x.is_finite() {
                    format!("after {x:.2} s")
                } else {
                    "never (within the run)".into()
                }
            };
            format!(
                "2% settling {} measured against {} in the model {where_}",
                t(m),
                t(s)
            )
        }
        "overshoot_pct" => format!(
            "{}% overshoot measured against {}% in the model {where_}",
            num(m, 1),
            num(s, 1)
        ),
        "peak_tension_n" => format!(
            "peak rope tension {} N measured against {} N in the model {where_}",
            num(m, 0),
            num(s, 0)
        ),
        _ => format!(
            "lowest rope tension {} N measured against {} N in the model {where_}",
            num(m, 0),
            num(s, 0)
        ),
    }
}

/// The [`Resolution`] of the moves of run `run`, over the span its commands move in
/// (the comparison's, [`super::move_span`], which its figures are measured from); `None`:
/// no such run, or its commands never change.
fn resolution(am: &ArmMovesDataset, run: &str) -> Option<Resolution> {
    let r = am.runs.iter().find(|r| r.name == run)?;
    let (a, b) = super::move_span(r)?;
    let t = |i: usize| r.time_s.get(i).copied().unwrap_or(0.0);
    let end = *r.time_s.last()?;
    Some(Resolution {
        dt_s: r.dt_s(),
        horizon_s: end - t(a),
        settle_window_s: end - t(b),
    })
}

/// Mean of measured minus model of channel `name` of run `r` over samples `a..b`.
fn offset(
    am: &ArmMovesDataset,
    sims: &[Channels],
    r: usize,
    q: ArmQuantity,
    joint: &str,
    (a, b): (usize, usize),
) -> Option<f64> {
    let name = q.column(joint);
    let run = &am.runs[r];
    let meas = &run.channels.iter().find(|c| c.name == name)?.values;
    let model = sims.get(r)?.get(&name)?;
    let (a, b) = (a.min(meas.len()), b.min(meas.len()).min(model.len()));
    (b > a).then(|| (a..b).map(|i| meas[i] - model[i]).sum::<f64>() / (b - a) as f64)
}

/// The findings of `cmp` (the comparison of a model with the arm dataset `am`, whose
/// runs the model simulated as `sims`), largest first (module docs).
pub fn arm_findings(
    am: &ArmMovesDataset,
    cmp: &ArmComparison,
    sims: &[Channels],
) -> Vec<ArmFinding> {
    let mut out = Vec::new();
    // Figures, per joint over its moves.
    for joint in &am.joints {
        // (each move with its run's resolution, found once for every figure)
        let moves: Vec<_> = cmp
            .figures
            .iter()
            .filter(|f| &f.joint == joint)
            .filter_map(|f| Some((f, resolution(am, &f.run)?)))
            .collect();
        for kind in FIGURES {
            let judged: Vec<(String, f64, f64, f64)> = moves
                .iter()
                .filter_map(|(f, res)| {
                    judge(kind, &f.measured, &f.model, *res)
                        .map(|(a, b, w)| (f.run.clone(), a, b, w))
                })
                .collect();
            let of = judged.len();
            let off: Vec<_> = judged.iter().filter(|j| j.3 > 1.0).collect();
            if off.is_empty() {
                continue;
            }
            // (the same sign on every move it shows in, else the mixed moves are listed)
            let mean = |f: &dyn Fn(&(String, f64, f64, f64)) -> f64| {
                off.iter().map(|j| f(j)).sum::<f64>() / off.len() as f64
            };
            let (m, s) = (mean(&|j| j.1), mean(&|j| j.2));
            let runs: Vec<String> = off.iter().map(|j| j.0.clone()).collect();
            let where_ = runs_words(&runs, of, &format!("move of {joint}"));
            out.push(ArmFinding {
                joint: joint.clone(),
                kind,
                of_runs: of,
                measured: m,
                model: s,
                weight: mean(&|j| j.3.min(100.0)) * off.len() as f64 / of.max(1) as f64,
                sentence: figure_sentence(kind, m, s, &where_),
                runs,
            });
        }
    }
    // Offsets of the encoders, per joint over the runs.
    let count = ARM_ENCODER_RESOLUTION_RAD;
    let limit = OFFSET_COUNTS * count;
    for joint in &am.joints {
        let mut rest: Vec<(String, f64, f64)> = Vec::new();
        let mut settled: Vec<(String, f64, f64)> = Vec::new();
        let (mut n_rest, mut n_settled) = (0, 0);
        for (r, run) in am.runs.iter().enumerate() {
            let n = run.time_s.len();
            // (the first sample where a command has moved)
            let first_move = super::move_span(run).map(|(a, _)| a + 1);
            let q_of = |w: (usize, usize)| {
                let j = offset(am, sims, r, ArmQuantity::Joint, joint, w);
                let m = offset(am, sims, r, ArmQuantity::Motor, joint, w);
                (j, m)
            };
            if let Some(fm) = first_move.filter(|&i| i >= 10) {
                if let (j, Some(m)) = q_of((0, fm)) {
                    n_rest += 1;
                    let shown = j.unwrap_or(m);
                    if shown.abs() > limit {
                        rest.push((run.name.clone(), shown, m));
                    }
                }
            }
            if n >= 10 {
                if let (Some(j), Some(m)) = q_of((n - n / 5, n)) {
                    n_settled += 1;
                    if j.abs() > limit {
                        settled.push((run.name.clone(), j, m));
                    }
                }
            }
        }
        let mrad = |x: f64| format!("{:.2} mrad", 1e3 * x);
        if !rest.is_empty() {
            let j = rest.iter().map(|x| x.1).sum::<f64>() / rest.len() as f64;
            let m = rest.iter().map(|x| x.2).sum::<f64>() / rest.len() as f64;
            let runs: Vec<String> = rest.iter().map(|x| x.0.clone()).collect();
            out.push(ArmFinding {
                joint: joint.clone(),
                kind: "rest_offset_rad",
                of_runs: n_rest,
                measured: j,
                model: m,
                weight: (j.abs() / limit).min(100.0) * rest.len() as f64 / n_rest.max(1) as f64,
                sentence: format!(
                    "at rest before the moves {joint} sits {} {} the model (its motor {}) {}: the statics differ (a load the model lacks, the ropes' stiffness)",
                    mrad(j.abs()),
                    if j < 0.0 { "below" } else { "above" },
                    mrad(m),
                    runs_words(&runs, n_rest, "run")
                ),
                runs,
            });
        }
        if !settled.is_empty() {
            let j = settled.iter().map(|x| x.1).sum::<f64>() / settled.len() as f64;
            let m = settled.iter().map(|x| x.2).sum::<f64>() / settled.len() as f64;
            let runs: Vec<String> = settled.iter().map(|x| x.0.clone()).collect();
            // (a hint only where the two tell: the motor where the model's is, or
            // motor and joint off together)
            let hint = if m.abs() < limit.max(j.abs() / 3.0) {
                ": something between motor and joint holds the joint (friction at the joint, the ropes' give)"
            } else if (j - m).abs() < limit.max(j.abs() / 3.0) {
                ": joint and motor are off together, the servo holds another position or load than the model's (its gains, gravity, a payload)"
            } else {
                ""
            };
            out.push(ArmFinding {
                joint: joint.clone(),
                kind: "settled_offset_rad",
                of_runs: n_settled,
                measured: j,
                model: m,
                weight: (j.abs() / limit).min(100.0) * settled.len() as f64
                    / n_settled.max(1) as f64,
                sentence: format!(
                    "after the moves {joint} settles {} from where the model's does, its motor {} {}{hint}",
                    mrad(j),
                    mrad(m),
                    runs_words(&runs, n_settled, "run")
                ),
                runs,
            });
        }
    }
    out.sort_by(|a, b| b.weight.total_cmp(&a.weight));
    out
}

/// The largest [`FINDINGS_TOLD`] findings as one sentence, `lead` first (`""` when none).
pub fn describe_findings(lead: &str, findings: &[ArmFinding]) -> String {
    if findings.is_empty() {
        return String::new();
    }
    let told: Vec<&str> = findings
        .iter()
        .take(FINDINGS_TOLD)
        .map(|f| f.sentence.as_str())
        .collect();
    let more = findings.len().saturating_sub(FINDINGS_TOLD);
    format!(
        "{lead}{}{}. ",
        told.join("; "),
        if more > 0 {
            format!(" (and {more} more in the JSON's arm_findings)")
        } else {
            String::new()
        }
    )
}
