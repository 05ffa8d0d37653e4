//! Per-joint and per-link values of an arm effect: an effect at the joints or motors of
//! an arm (`joint_friction`, `motor_friction`) fitted with the same values at every
//! driven joint, split into one use per joint that the data move, each with its own
//! values; an effect on a link's bending (`link_flexibility`) fitted with the same
//! values on every flexible link, split into one use per flexible link.
//!
//! Real arms do not carry the same bearing at every joint: a shoulder's is larger than a
//! wrist's; nor the same tube in every link. A shared value fitted to moves of several
//! joints (to the modes of several links) is a compromise that leaves each of them off,
//! and the residual of such a compromise looks like a missing effect. The split is
//! tried when the winner's catalog law leaves the data above [`super::REFINE_MARGIN`]
//! ([`super::diagnose`]):
//!
//! * **Which links**: every flexible link of the scenario (`[[flex]]`) gets its own use
//!   (`links = ["linkK"]`), each from the shared fit's values. Fewer than two flexible
//!   links: nothing to split.
//! * **Which joints**: every driven joint whose command changes in at least one run gets
//!   its own use of the effect (`joints = ["jK"]`); the joints no run moves share one
//!   (they still turn a little under the others' moves, through the ropes' give, and
//!   the encoders see it). Each starts from the shared fit's values, a value that fit
//!   left on a bound from the effect's default. Fewer than two moved joints: nothing to
//!   split.
//! * **Fit**: every free parameter of the model with the per-joint values together, by
//!   least squares from the shared fit ([`fit_model_from`], [`Start::Own`]).
//! * **Kept** when its Bayesian information criterion beats the shared fit's by
//!   [`MIN_SCORE`] (every per-joint or per-link value counted as a parameter).

use longreach_drive::effects::{bends_links, Site};
use serde::Serialize;

use super::diagnose::MIN_SCORE;
use super::fit::{fit_model_from, Fitted, Start};
use super::prepare::Prepared;
use super::shape::bic;
use crate::dataset::DatasetKind;
use crate::error::IdentError;
use crate::model::EffectUse;

/// The values of one joint (or link) after a split.
#[derive(Debug, Clone, Serialize)]
pub struct JointValues {
    /// The joint (the dataset's column name), or the joints no run moves joined by `+`;
    /// for a split per link, the flexible link (its URDF name).
    pub joint: String,
    /// `(parameter, value)` in the effect's order.
    pub values: Vec<(String, f64)>,
    /// The 95% interval of each value (`[lower, upper]`; the value itself twice when it
    /// is held).
    pub interval_95: Vec<[f64; 2]>,
}

/// The outcome of splitting an effect's values per joint (or per flexible link).
#[derive(Debug, Clone, Serialize)]
pub struct JointSplit {
    /// The effect split.
    pub effect: String,
    /// What each use covers: `"joint"`, or `"link"` for an effect on a link's bending.
    pub per: &'static str,
    /// Its shared values, `(parameter, value)`.
    pub shared: Vec<(String, f64)>,
    /// The values of every moved joint, then those the joints no run moves share.
    pub joints: Vec<JointValues>,
    /// The joints no run moves (one use, with values of its own).
    pub held: Vec<String>,
    /// NRMSE with the shared values.
    pub nrmse_shared: f64,
    /// NRMSE with the values per joint.
    pub nrmse: f64,
    /// BIC improvement over the shared values (positive: the split is better).
    pub score: f64,
    /// Whether the split replaces the shared values (score above [`MIN_SCORE`]).
    pub kept: bool,
}

/// Whether effect `u` can take values per joint (an effect at joints or at motors) or
/// per flexible link (an effect on a link's bending), not yet restricted.
pub fn splittable(u: &EffectUse) -> bool {
    u.at.is_none()
        && (matches!(u.effect.site(), Site::Joint | Site::Motor) || bends_links(u.effect))
}

/// The driven joints of an arm dataset whose command changes in at least one run, and
/// those no run moves, in the dataset's joint order. Empty for other datasets.
pub fn moved_joints(prep: &Prepared<'_>) -> (Vec<String>, Vec<String>) {
    let DatasetKind::ArmMoves(am) = &prep.ds.kind else {
        return (Vec::new(), Vec::new());
    };
    let moves = |k: usize| {
        am.runs.iter().any(|r| {
            r.command_rad.get(k).is_some_and(|c| {
                let first = c.first().copied().unwrap_or(0.0);
                c.iter().any(|&x| x.to_bits() != first.to_bits())
            })
        })
    };
    let (moved, held): (Vec<_>, Vec<_>) =
        am.joints.iter().enumerate().partition(|(k, _)| moves(*k));
    let names = |v: Vec<(usize, &String)>| v.into_iter().map(|(_, j)| j.clone()).collect();
    (names(moved), names(held))
}

/// Splits effect number `e` of the fitted model `fitted` into values per moved joint,
/// or per flexible link (module docs). `None` when the dataset is not an arm's, the
/// effect is not [`splittable`] or fewer than two joints move (fewer than two links
/// bend). The returned [`Fitted`] is the split model when kept, else `fitted`.
pub fn split_per_joint(
    prep: &Prepared<'_>,
    fitted: &Fitted,
    e: usize,
) -> Result<Option<(JointSplit, Fitted)>, IdentError> {
    let Some(u) = fitted.model.effects.get(e) else {
        return Ok(None);
    };
    if !splittable(u) {
        return Ok(None);
    }
    let per_link = bends_links(u.effect);
    let (moved, held) = if per_link {
        match &prep.ds.kind {
            DatasetKind::ArmMoves(am) => (am.flex_links.clone(), Vec::new()),
            _ => (Vec::new(), Vec::new()),
        }
    } else {
        moved_joints(prep)
    };
    if moved.len() < 2 {
        return Ok(None);
    }
    let mut model = fitted.model.clone();
    let shared = model.effects.remove(e);
    // Each use starts from the shared values, but a value the shared fit left on a
    // bound (a viscous coefficient driven to 0 on its log scale by a compromise between
    // joints) from the effect's default: on its bound it could not move.
    // ([`crate::model::Model::with_bound_values_reset`], the fits' own restart rule)
    let start = fitted
        .model
        .with_bound_values_reset(prep.runs.len())
        .map_or_else(|| shared.clone(), |m| m.effects[e].clone());
    let mut uses: Vec<EffectUse> = moved
        .iter()
        .map(|j| EffectUse {
            at: Some(vec![j.clone()]),
            ..start.clone()
        })
        .collect();
    if !held.is_empty() {
        uses.push(EffectUse {
            at: Some(held.clone()),
            ..start.clone()
        });
    }
    let n_uses = uses.len();
    // (in the shared use's place: the effects after it keep their order)
    model.effects.splice(e..e, uses);
    let f = fit_model_from(prep, &model, Start::Own)?;
    let n_runs = prep.runs.len();
    let n = prep.n_samples() as f64;
    let score = bic(fitted.ssr, fitted.model.fit_specs(n_runs).len(), n)
        - bic(f.ssr, f.model.fit_specs(n_runs).len(), n);
    let kept = score > MIN_SCORE;
    let intervals = f
        .fit
        .as_ref()
        .map(|r| r.intervals_by_name())
        .unwrap_or_default();
    let joints = f.model.effects[e..e + n_uses]
        .iter()
        .map(|u| JointValues {
            joint: u.at.as_deref().unwrap_or_default().join("+"),
            values: u.params.iter().map(|p| (p.name.clone(), p.value)).collect(),
            interval_95: u
                .params
                .iter()
                .map(|p| {
                    intervals
                        .get(&u.param_name(p))
                        .copied()
                        .unwrap_or([p.value, p.value])
                })
                .collect(),
        })
        .collect();
    debug_assert_eq!(
        f.model.effects.len(),
        fitted.model.effects.len() + n_uses - 1
    );
    let split = JointSplit {
        effect: shared.effect.name().to_string(),
        per: crate::model::at_unit(shared.effect),
        shared: shared
            .params
            .iter()
            .map(|p| (p.name.clone(), p.value))
            .collect(),
        joints,
        held,
        nrmse_shared: fitted.nrmse,
        nrmse: f.nrmse,
        score,
        kept,
    };
    Ok(Some((split, if kept { f } else { fitted.clone() })))
}
