//! Diagnosis: the baseline and every applicable registered effect fitted and ranked by
//! BIC, the decision rule (the constants below) and the verdict in words.

use longreach_drive::effects::{DataKind, REGISTRY};
use rayon::prelude::*;
use serde::Serialize;

use super::{
    compare, describe, fit_model, refine_shape, screen_model, signatures, Comparison, Fitted,
    Prepared, RunResonance, ShapeRefinement, Signature, Where,
};
use crate::error::IdentError;
use crate::model::Model;

/// One candidate effect of a diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// Effect name.
    pub effect: String,
    /// NRMSE of baseline + effect, fitted (or screened, see `screened`).
    pub nrmse: f64,
    /// Score: BIC improvement over the baseline, `n ln(SSR_b / SSR_c) - dk ln n`.
    pub score: f64,
    /// Share of the baseline's excess squared error (above the noise floor) explained.
    pub explained: f64,
    /// Fitted parameters (baseline's and the effect's).
    pub params: std::collections::BTreeMap<String, f64>,
    /// 95% intervals of the fitted ones, `[lower, upper]` (empty when screened).
    pub interval_95: std::collections::BTreeMap<String, [f64; 2]>,
    /// Those clipped at a bound: `"lower"`, `"upper"` or `"both"`.
    pub interval_clipped: std::collections::BTreeMap<String, String>,
    /// True for the winner when the evidence is decisive.
    pub decisive: bool,
    /// True when the candidate was only screened ([`screen_model`]: its starting values,
    /// one simulation) because the baseline already fits to the noise floor.
    pub screened: bool,
    /// Why the fit failed, if it did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// The baseline part of a diagnosis.
#[derive(Debug, Clone, Serialize)]
pub struct BaselineSummary {
    /// NRMSE after fitting.
    pub nrmse: f64,
    /// Noise floor on the NRMSE scale.
    pub noise_floor_nrmse: f64,
    /// Fitted parameters.
    pub params: std::collections::BTreeMap<String, f64>,
    /// Their standard errors.
    pub std_errors: std::collections::BTreeMap<String, f64>,
    /// Their 95% intervals, `[lower, upper]`.
    pub interval_95: std::collections::BTreeMap<String, [f64; 2]>,
    /// Those clipped at a bound: `"lower"`, `"upper"` or `"both"`.
    pub interval_clipped: std::collections::BTreeMap<String, String>,
}

/// The result of `diagnose`.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// Dataset title.
    pub dataset: String,
    /// Baseline.
    pub baseline: BaselineSummary,
    /// Where the baseline fails.
    #[serde(rename = "where")]
    pub where_: Vec<Where>,
    /// Candidates, best first.
    pub candidates: Vec<Candidate>,
    /// The missing effect when decisive.
    pub missing_effect: Option<String>,
    /// The verdict in words.
    pub explanation: String,
    /// The baseline's comparison (residual checks, resonances).
    pub comparison: Comparison,
    /// NRMSE of the model with the winning effect (null when none).
    pub nrmse_after: Option<f64>,
    /// When no effect is decisive and the baseline misses the data: the residual's
    /// signatures, each with the simplest term that would produce it, its size and the
    /// share of the excess error it removes (empty otherwise).
    pub signatures: Vec<Signature>,
    /// Effect laws refined in their shape-free form ([`refine_shape`]): the model's own
    /// effects when it misses the data, then the best candidate's when its catalog
    /// formula leaves the data well above the floor.
    pub refinements: Vec<ShapeRefinement>,
}

/// Fraction of the baseline's excess squared error a decisive winner must explain.
pub const MIN_EXPLAINED: f64 = 0.5;
/// Baseline NRMSE above this multiple of the noise floor is a failure worth diagnosing
/// (the squared error 10% above the floor: beyond the floor estimate's own scatter,
/// ~2% for a few thousand samples, and the sweep simulation's time-step error, ~2% of
/// the floor's squared error at 2.5 ms; see `docs/models.md`).
pub const FLOOR_MARGIN: f64 = 1.05;
/// Least score (BIC improvement over the baseline) of a decisive winner: "very strong"
/// evidence on the scale of Kass and Raftery (1995), `2 ln B > 10`.
pub const MIN_SCORE: f64 = 10.0;
/// Least score lead of a decisive winner over the second candidate beyond one
/// parameter's BIC penalty `ln n` (n: analysed samples): two effects that fit equally
/// well differ by their parameter counts alone, `ln n` per parameter; the data must
/// favour the winner "very strongly" over the next explanation, not only over the
/// baseline.
pub const MIN_SCORE_GAP: f64 = 10.0;

/// A fitted model left above this multiple of the noise floor (NRMSE) has its effects'
/// laws refined in their shape-free form ([`refine_shape`]).
pub const REFINE_MARGIN: f64 = 1.5;

/// What a candidate's fit is judged against.
struct Judge {
    base_ssr: f64,
    excess: f64,
    n: f64,
    k_base: usize,
    n_runs: usize,
    screened: bool,
}

impl Judge {
    /// The candidate of effect `name` fitted as `f`: its score against the baseline and
    /// the share of the excess error it explains.
    fn candidate(&self, name: String, f: &Fitted) -> Candidate {
        let dk = f
            .model
            .fit_specs(self.n_runs)
            .len()
            .saturating_sub(self.k_base) as f64;
        let ssr_c = f.ssr.min(self.base_ssr);
        let score = self.n * (self.base_ssr / ssr_c.max(f64::MIN_POSITIVE)).ln() - dk * self.n.ln();
        let explained = if self.excess > 0.0 {
            (self.base_ssr - ssr_c) / self.excess
        } else {
            0.0
        };
        Candidate {
            effect: name,
            nrmse: f.nrmse,
            score,
            explained: explained.min(1.5),
            params: f.model.named_values().into_iter().collect(),
            interval_95: f
                .fit
                .as_ref()
                .map(|r| r.intervals_by_name())
                .unwrap_or_default(),
            interval_clipped: f
                .fit
                .as_ref()
                .map(|r| r.clipped_by_name())
                .unwrap_or_default(),
            decisive: false,
            screened: self.screened,
            error: None,
        }
    }
}

/// [`refine_shape`], a failure noted for the explanation instead of ending the
/// diagnosis.
fn refine_or_note(
    prep: &Prepared<'_>,
    f: &Fitted,
    e: usize,
    notes: &mut Vec<String>,
) -> Option<(ShapeRefinement, Fitted)> {
    match refine_shape(prep, f, e) {
        Ok(r) => r,
        Err(err) => {
            notes.push(format!(
                "Refining the law of {} in its shape-free form failed: {err}. ",
                f.model.effects[e].effect.name()
            ));
            None
        }
    }
}

/// Fits the baseline and every applicable registered effect; ranks and decides.
/// Returns the diagnosis and the winning model (if any).
pub fn diagnose(
    prep: &Prepared<'_>,
    model: &Model,
) -> Result<(Diagnosis, Fitted, Option<Fitted>), IdentError> {
    let mut base = fit_model(prep, model)?;
    let mut refinements = Vec::new();
    let mut notes = Vec::new();
    // A model that already holds effects and still misses the data: its effects' laws
    // are refined first, so that a further effect is named only against the best the
    // existing ones can do (a wrong-shaped law is not patched by a false second effect).
    if base.nrmse > REFINE_MARGIN * base.noise_floor {
        for e in 0..base.model.effects.len() {
            if let Some((r, refined)) = refine_or_note(prep, &base, e, &mut notes) {
                base = refined;
                refinements.push(r);
            }
        }
    }
    let cmp = compare(prep, &base.model, &base.sims)?;
    let n = prep.n_samples() as f64;
    let k_base = base.model.fit_specs(prep.runs.len()).len();
    let ssr_floor = prep.floor_ssr();
    let effects: Vec<_> = REGISTRY
        .iter()
        .copied()
        .filter(|e| e.applies_to(prep.kind) && !base.model.has_effect(*e))
        .filter(|e| match prep.plant.excludes(*e) {
            Some(why) => {
                notes.push(format!("Not a candidate: {why}. "));
                false
            }
            None => true,
        })
        .collect();
    // At the noise floor no candidate can be decisive: screen them (starting values,
    // one simulation each) instead of fitting them in the time domain.
    let at_floor = base.nrmse <= FLOOR_MARGIN * base.noise_floor;
    let fits: Vec<(String, Result<Fitted, IdentError>)> = effects
        .par_iter()
        .map(|e| {
            let m = base.model.with_effect(*e);
            let f = if at_floor {
                screen_model(prep, &m)
            } else {
                fit_model(prep, &m)
            };
            (e.name().to_string(), f)
        })
        .collect();
    let excess = (base.ssr - ssr_floor).max(0.0);
    let judge = Judge {
        base_ssr: base.ssr,
        excess,
        n,
        k_base,
        n_runs: prep.runs.len(),
        screened: at_floor,
    };
    let mut cands: Vec<(Candidate, Option<Fitted>)> = fits
        .into_iter()
        .map(|(name, r)| match r {
            Ok(f) => (judge.candidate(name, &f), Some(f)),
            Err(err) => (
                Candidate {
                    effect: name,
                    nrmse: f64::NAN,
                    score: f64::NEG_INFINITY,
                    explained: 0.0,
                    params: Default::default(),
                    interval_95: Default::default(),
                    interval_clipped: Default::default(),
                    decisive: false,
                    screened: at_floor,
                    error: Some(err.to_string()),
                },
                None,
            ),
        })
        .collect();
    let rank = |cands: &mut Vec<(Candidate, Option<Fitted>)>| {
        cands.sort_by(|a, b| {
            b.0.score
                .total_cmp(&a.0.score)
                .then(a.0.effect.cmp(&b.0.effect))
        })
    };
    rank(&mut cands);
    // The best candidate's law in its shape-free form when its catalog formula leaves
    // the data well above the floor: the effect may be right and its formula wrong.
    if !at_floor {
        if let Some((c, Some(f))) = cands.first() {
            if f.nrmse > REFINE_MARGIN * f.noise_floor && c.explained > 0.0 {
                let e = f.model.effects.len().saturating_sub(1);
                if let Some((r, refined)) = refine_or_note(prep, f, e, &mut notes) {
                    if r.kept {
                        cands[0] = (judge.candidate(c.effect.clone(), &refined), Some(refined));
                        rank(&mut cands);
                    }
                    refinements.push(r);
                }
            }
        }
    }
    let decisive = !at_floor
        && cands.first().is_some_and(|(best, fit)| {
            let gap = cands
                .get(1)
                .map_or(f64::INFINITY, |(second, _)| best.score - second.score);
            // The winner reaches the floor, or leaves at most half the excess the
            // second leaves: a lead in score between two candidates that both stop far
            // above the floor may be a fit that stopped early, not evidence.
            let best_ssr = fit.as_ref().map_or(f64::INFINITY, |f| f.ssr);
            let reaches_floor = best_ssr <= FLOOR_MARGIN * FLOOR_MARGIN * ssr_floor;
            let second_left = cands
                .get(1)
                .and_then(|(_, f)| f.as_ref())
                .map_or(base.ssr, |f| f.ssr.min(base.ssr));
            let separated = second_left - ssr_floor >= 2.0 * (best_ssr - ssr_floor).max(0.0);
            best.explained >= MIN_EXPLAINED
                && best.score > MIN_SCORE
                && gap >= MIN_SCORE_GAP + n.ln()
                && (reaches_floor || separated)
        });
    let mut winner = None;
    if decisive {
        cands[0].0.decisive = true;
        winner = cands[0].1.take();
    }
    let missing = decisive.then(|| cands[0].0.effect.clone());
    let sigs = if missing.is_none() && !at_floor {
        signatures(prep, &base.model, &base.sims, &cmp)
    } else {
        Vec::new()
    };
    let explanation = explain(
        prep,
        &base,
        &cmp,
        &cands.iter().map(|c| c.0.clone()).collect::<Vec<_>>(),
        missing.as_deref(),
        at_floor,
        &sigs,
        &refinements,
        &notes,
    );
    let diag = Diagnosis {
        dataset: prep.ds.title.clone(),
        baseline: BaselineSummary {
            nrmse: base.nrmse,
            noise_floor_nrmse: base.noise_floor,
            params: base.model.named_values().into_iter().collect(),
            std_errors: base
                .fit
                .as_ref()
                .map(|f| {
                    f.names
                        .iter()
                        .cloned()
                        .zip(f.std_errors.iter().copied())
                        .collect()
                })
                .unwrap_or_default(),
            interval_95: base
                .fit
                .as_ref()
                .map(|f| f.intervals_by_name())
                .unwrap_or_default(),
            interval_clipped: base
                .fit
                .as_ref()
                .map(|f| f.clipped_by_name())
                .unwrap_or_default(),
        },
        where_: cmp.where_.clone(),
        candidates: cands.iter().map(|c| c.0.clone()).collect(),
        missing_effect: missing,
        nrmse_after: winner.as_ref().map(|w: &Fitted| w.nrmse),
        explanation,
        comparison: cmp,
        signatures: sigs,
        refinements,
    };
    Ok((diag, base, winner))
}

fn explain(
    prep: &Prepared<'_>,
    base: &Fitted,
    cmp: &Comparison,
    cands: &[Candidate],
    missing: Option<&str>,
    at_floor: bool,
    sigs: &[Signature],
    refinements: &[ShapeRefinement],
    notes: &[String],
) -> String {
    let mut s = String::new();
    for n in notes {
        s.push_str(n);
    }
    for r in refinements {
        s.push_str(&describe_refinement(r));
    }
    let ratio = base.nrmse / base.noise_floor.max(f64::MIN_POSITIVE);
    if at_floor {
        s.push_str(&format!(
            "The baseline fits to the noise floor (NRMSE {:.4}, {:.2}x the floor {:.4} of the sensors): no missing effect is needed; none found (the candidates were screened at their starting values, not fitted).",
            base.nrmse, ratio, base.noise_floor
        ));
        return s;
    }
    s.push_str(&format!(
        "The baseline misses the data: NRMSE {:.4} is {:.1}x the noise floor {:.4}. ",
        base.nrmse, ratio, base.noise_floor
    ));
    if let Some(w) = cmp.where_.first() {
        match w.frequency_hz {
            Some(f) => s.push_str(&format!(
                "The largest share of the error ({:.0}%) is in run {} at {:.2} Hz. ",
                100.0 * w.share,
                w.run,
                f
            )),
            None => s.push_str(&format!(
                "The largest share of the error ({:.0}%) is in run {} between {:.1} and {:.1} s. ",
                100.0 * w.share,
                w.run,
                w.start_s,
                w.end_s
            )),
        }
    }
    // Evidence from the data, by kind.
    if prep.kind == DataKind::SineSweep {
        let mut res: Vec<&RunResonance> = cmp
            .resonance
            .iter()
            .filter(|r| r.measured_hz.is_some() && r.model_hz.is_some())
            .collect();
        res.sort_by(|a, b| a.mean_tension_n.total_cmp(&b.mean_tension_n));
        if let (Some(lo), Some(hi)) = (res.first(), res.last()) {
            if hi.mean_tension_n > lo.mean_tension_n {
                let (ml, mh) = (lo.measured_hz.unwrap_or(0.0), hi.measured_hz.unwrap_or(0.0));
                let (yl, yh) = (lo.model_hz.unwrap_or(0.0), hi.model_hz.unwrap_or(0.0));
                s.push_str(&format!(
                    "The measured resonance moves from {ml:.2} to {mh:.2} Hz between {:.0} and {:.0} N while the model goes from {yl:.2} to {yh:.2} Hz",
                    lo.mean_tension_n, hi.mean_tension_n
                ));
                let moved = (mh / ml).ln() - (yh / yl).ln();
                if moved > 0.03 {
                    s.push_str(": the rope's stiffness depends on its tension. ");
                } else {
                    s.push_str(". ");
                }
                let dpk: f64 = res
                    .iter()
                    .map(|r| r.model_peak_db.unwrap_or(0.0) - r.measured_peak_db.unwrap_or(0.0))
                    .sum::<f64>()
                    / res.len() as f64;
                if dpk.abs() > 1.0 {
                    s.push_str(&format!(
                        "The model's resonance peak is {:.1} dB {} than measured on average{}. ",
                        dpk.abs(),
                        if dpk > 0.0 { "higher" } else { "lower" },
                        if dpk > 0.0 {
                            ": the rope dissipates more than the model"
                        } else {
                            ""
                        }
                    ));
                }
            }
        }
    } else {
        let r = &cmp.residual;
        s.push_str(&format!(
            "The residual correlates with time at {:.2} (drift) and is {}white (Ljung-Box p = {:.2e}). ",
            r.corr_time,
            if r.ljung_box_p < 0.05 { "not " } else { "" },
            r.ljung_box_p
        ));
    }
    match (missing, cands.first()) {
        (Some(m), Some(best)) => {
            let after = best.nrmse;
            s.push_str(&format!(
                "Adding {m} explains {:.0}% of the excess error and brings the NRMSE from {:.4} to {:.4} ({:.1}x lower); ",
                100.0 * best.explained.min(1.0),
                base.nrmse,
                after,
                base.nrmse / after.max(f64::MIN_POSITIVE)
            ));
            if let Some(second) = cands.get(1) {
                s.push_str(&format!(
                    "the next best, {}, explains {:.0}%.",
                    second.effect,
                    100.0 * second.explained.clamp(0.0, 1.0)
                ));
            }
        }
        (_, best) => {
            if let Some(b) = best {
                s.push_str(&format!(
                    "No registered effect explains the failure decisively (best: {}, explaining {:.0}% of the excess error). ",
                    b.effect,
                    100.0 * b.explained.clamp(0.0, 1.0)
                ));
                if let Some(second) = cands.get(1) {
                    if b.explained >= MIN_EXPLAINED && second.explained >= MIN_EXPLAINED {
                        s.push_str(&format!(
                            "{} and {} both explain it (scores {:.1} and {:.1}): these data cannot tell them apart (a test of another kind or frequency range can; see docs/models.md). ",
                            b.effect, second.effect, b.score, second.score
                        ));
                    }
                }
            } else {
                s.push_str("No registered effect applies to this kind of data. ");
            }
            s.push_str(&describe(sigs));
        }
    }
    s
}

/// One sentence on a shape-free refinement.
fn describe_refinement(r: &ShapeRefinement) -> String {
    let k = r.knots.len().saturating_sub(1);
    let points: Vec<String> = r
        .knots
        .iter()
        .zip(&r.values)
        .zip(&r.catalog)
        .skip(1)
        .map(|((x, y), c)| format!("{y:.3} at {x:.0} (catalog law {c:.3})"))
        .collect();
    if r.kept {
        format!(
            "The catalog law of {} left NRMSE {:.4}; refined as a table of {} over {} ({k} knots chosen by BIC, score {:.1}) it gives {:.4}: {} {}. ",
            r.effect,
            r.nrmse_parametric,
            r.value,
            r.argument,
            r.score,
            r.nrmse,
            r.value,
            points.join(", ")
        )
    } else {
        format!(
            "The law of {} refined as a table of {} over {} does not fit better than its catalog law (NRMSE {:.4} against {:.4}, BIC score {:.1}): its formula is not what misses the data. ",
            r.effect, r.value, r.argument, r.nrmse, r.nrmse_parametric, r.score
        )
    }
}
