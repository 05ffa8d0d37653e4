//! A further retarded-elasticity (Kelvin) element.

use longreach_rope::{KelvinElement, RopeLaw, MAX_KELVIN};

use super::{check, Args, DataKind, Effect, EffectParam, Site, Target};
use crate::DriveError;

/// Another spring || dashpot element in series (a second retardation time).
#[derive(Debug)]
pub struct ExtraRetardation;

const PARAMS: &[EffectParam] = &[
    EffectParam {
        name: "k_n",
        unit: "N",
        default: 1e6,
        lower: 1e4,
        upper: 1e8,
        log_scale: true,
        fitted: true,
    },
    EffectParam {
        name: "c_n_s",
        unit: "N*s",
        default: 1e5,
        lower: 1e2,
        upper: 1e9,
        log_scale: true,
        fitted: true,
    },
];

impl Effect for ExtraRetardation {
    fn name(&self) -> &'static str {
        "extra_retardation"
    }
    fn doc(&self) -> &'static str {
        "Real fibres show a spectrum of retardation times, not the single one (c3/k3) of \
         the four-element model. A second Kelvin element k || c in series adds a second \
         time constant c/k: relaxation curves then have an extra fast (or slow) decay the \
         four-element closed form (eq. 6) cannot bend to, and on the rig the ropes soften \
         and dissipate around the frequency k/(2 pi c)."
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
        law.kelvin.len() >= 2
    }
    fn on_law(&self, args: Args<'_>, law: &mut RopeLaw) -> Result<(), DriveError> {
        let values = args.values;
        check(self, values)?;
        if law.kelvin.len() >= MAX_KELVIN {
            return Err(DriveError::BadParameter {
                field: "extra_retardation".into(),
                value: law.kelvin.len() as f64,
                reason: format!("the law already holds {MAX_KELVIN} Kelvin elements"),
            });
        }
        law.kelvin.push(KelvinElement {
            k_n: values[0],
            c_n_s: values[1],
        });
        Ok(law.validate()?)
    }
}
