//! Tension-dependent rope stiffness.

use longreach_rope::RopeLaw;

use super::{check, DataKind, Effect, EffectParam, Site, Target};
use crate::DriveError;

/// Rope stiffness that rises with tension: the head spring's tangent stiffness is
/// `k1 * (1 + b * f)`.
#[derive(Debug)]
pub struct NonlinearStiffness;

const PARAMS: &[EffectParam] = &[EffectParam {
    name: "stiffening_per_n",
    unit: "1/N",
    default: 2e-3,
    lower: 1e-6,
    upper: 0.05,
    log_scale: true,
    fitted: true,
}];

impl Effect for NonlinearStiffness {
    fn name(&self) -> &'static str {
        "nonlinear_stiffness"
    }
    fn doc(&self) -> &'static str {
        "A braided rope stiffens as its tension rises: the strands straighten and pack \
         tighter, so the instantaneous spring k1 of the four-element model becomes a \
         tangent stiffness k1 (1 + b f) (b in 1/N). On the rig the resonance then moves \
         up with the mean tension (f_res ~ sqrt(k)), which one global k1 cannot follow; \
         in relaxation the initial tension is higher than k1 e0 and relaxes faster."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn applies_to(&self, _kind: DataKind) -> bool {
        true
    }
    fn site(&self) -> Site {
        Site::RopeLaw
    }
    fn present_in(&self, target: &Target<'_>) -> bool {
        let law = target.law;
        law.stiffening_per_n > 0.0
    }
    fn on_law(&self, values: &[f64], law: &mut RopeLaw) -> Result<(), DriveError> {
        check(self, values)?;
        law.stiffening_per_n = values[0];
        Ok(law.validate()?)
    }
}
