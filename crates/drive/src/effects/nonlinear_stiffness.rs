//! Tension-dependent rope stiffness.

use longreach_rope::RopeLaw;

use super::{check, Args, Argument, DataKind, Effect, EffectParam, Shape, Site, Target};
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
        target.law.stiffens()
    }
    fn shape(&self) -> Option<Shape> {
        Some(Shape {
            argument: Argument::TensionN,
            value: "stiffness_factor",
            unit: "1",
            value_at_zero: Some(1.0),
            non_decreasing: true,
            max_value: 100.0,
            log_knots: false,
            replaces: &["stiffening_per_n"],
        })
    }
    fn curve(&self, values: &[f64], tension_n: f64) -> f64 {
        1.0 + values[0] * tension_n.max(0.0)
    }
    fn on_law(&self, args: Args<'_>, law: &mut RopeLaw) -> Result<(), DriveError> {
        let values = args.values;
        check(self, values)?;
        match args.table {
            // Shape-free: the head spring's tangent stiffness is k1 g(f), g the table.
            Some(t) => {
                law.stiffening_per_n = 0.0;
                law.stiffness_table = Some(*t);
            }
            None => law.stiffening_per_n = values[0],
        }
        Ok(law.validate()?)
    }
}
