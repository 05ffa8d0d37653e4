//! Flory's ratchet active during the test.

use longreach_rope::RopeLaw;

use super::{check, Args, DataKind, Effect, EffectParam, Site, Target};
use crate::DriveError;

/// The ratchet || kp element of Flory's model (Fig. 2, eqs. 1-2).
#[derive(Debug)]
pub struct PlasticRatchet;

const PARAMS: &[EffectParam] = &[EffectParam {
    name: "kp_n",
    unit: "N",
    default: 3e4,
    lower: 1e3,
    upper: 1e7,
    log_scale: true,
    fitted: true,
}];

impl Effect for PlasticRatchet {
    fn name(&self) -> &'static str {
        "plastic_ratchet"
    }
    fn doc(&self) -> &'static str {
        "Flory's ratchet: a braided rope takes a permanent elongation the first time it \
         carries a tension higher than any before, ep = f_peak / kp, and keeps it (eq. 2). \
         It only acts while the tension exceeds the previous peak: in a relaxation or \
         load-strain test on a specimen whose pre-stretch was lower than the test load, \
         the tension falls at once by the share the kp spring takes \
         (f = k e0 with 1/k = 1/k1 + 1/kp). On the rig with a constant-force tensioner and \
         the paper's 490 N pre-stretch it never slides below that peak, so sweeps cannot \
         reveal it."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn applies_to(&self, kind: DataKind) -> bool {
        kind != DataKind::SineSweep
    }
    fn site(&self) -> Site {
        Site::RopeLaw
    }
    fn present_in(&self, target: &Target<'_>) -> bool {
        let law = target.law;
        law.kp_n.is_some()
    }
    fn on_law(&self, args: Args<'_>, law: &mut RopeLaw) -> Result<(), DriveError> {
        let values = args.values;
        check(self, values)?;
        law.kp_n = Some(values[0]);
        Ok(law.validate()?)
    }
}
