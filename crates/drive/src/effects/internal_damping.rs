//! Internal (structural) damping of the rope.

use longreach_rope::RopeLaw;

use super::{check, Args, DataKind, Effect, EffectParam, Site, Target};
use crate::DriveError;

/// A dashpot `c1` parallel to the head spring `k1`.
#[derive(Debug)]
pub struct InternalDamping;

const PARAMS: &[EffectParam] = &[EffectParam {
    name: "c1_n_s",
    unit: "N*s",
    default: 300.0,
    lower: 1.0,
    upper: 1e5,
    log_scale: true,
    fitted: true,
}];

impl Effect for InternalDamping {
    fn name(&self) -> &'static str {
        "internal_damping"
    }
    fn doc(&self) -> &'static str {
        "Friction between fibres and strands dissipates energy at every stretch, beyond \
         what the four-element model's dashpots c2 (creep) and c3 (retardation) hold. \
         Modelled as a dashpot c1 parallel to the instantaneous spring k1 (a Kelvin head, \
         N*s per unit strain). On the rig it lowers and widens the resonance peak and adds \
         phase lag growing with frequency; in relaxation it delays the instantaneous \
         response by c1/k1 seconds."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn applies_to(&self, kind: DataKind) -> bool {
        kind != DataKind::Relaxation
    }
    fn site(&self) -> Site {
        Site::RopeLaw
    }
    fn present_in(&self, target: &Target<'_>) -> bool {
        let law = target.law;
        law.c1_n_s > 0.0
    }
    fn on_law(&self, args: Args<'_>, law: &mut RopeLaw) -> Result<(), DriveError> {
        let values = args.values;
        check(self, values)?;
        law.c1_n_s = values[0];
        Ok(law.validate()?)
    }
}
