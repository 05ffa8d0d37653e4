//! Stress-dependent creep.

use longreach_rope::{NonlinearCreep, RopeLaw};

use super::{check, Args, Argument, DataKind, Effect, EffectParam, Shape, Site, Target};
use crate::DriveError;

/// The creep dashpot c2 flows faster under high tension.
#[derive(Debug)]
pub struct NonlinearCreepEffect;

const PARAMS: &[EffectParam] = &[
    EffectParam {
        name: "tension_n",
        unit: "N",
        default: 500.0,
        lower: 10.0,
        upper: 1e5,
        log_scale: true,
        fitted: true,
    },
    EffectParam {
        name: "exponent",
        unit: "1",
        default: 2.0,
        lower: 1.0,
        upper: 6.0,
        log_scale: false,
        fitted: true,
    },
];

impl Effect for NonlinearCreepEffect {
    fn name(&self) -> &'static str {
        "nonlinear_creep"
    }
    fn doc(&self) -> &'static str {
        "Creep of polyethylene fibres (Dyneema) is thermally activated and grows faster \
         than linearly with stress. The creep dashpot's rate becomes \
         f/c2 (1 + (f/f_c)^n): at tensions well below f_c it is the paper's linear c2, \
         above it the rope creeps (and relaxes) much faster. A relaxation test then drops \
         quickly at first and slows down as the tension falls, which a linear c2 cannot \
         follow. Invisible on the rig, whose test lasts too short for c2 to act."
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
        law.creeps_nonlinearly() || law.c2_n_s.is_none()
    }
    fn shape(&self) -> Option<Shape> {
        Some(Shape {
            argument: Argument::TensionN,
            value: "creep_factor",
            unit: "1",
            value_at_zero: Some(1.0),
            non_decreasing: true,
            max_value: 1e6,
            log_knots: false,
            replaces: &["tension_n", "exponent"],
        })
    }
    fn curve(&self, values: &[f64], tension_n: f64) -> f64 {
        1.0 + (tension_n.max(0.0) / values[0]).powf(values[1])
    }
    fn on_law(&self, args: Args<'_>, law: &mut RopeLaw) -> Result<(), DriveError> {
        let values = args.values;
        check(self, values)?;
        match args.table {
            // Shape-free: the creep rate is f / c2 h(f), h the table.
            Some(t) => {
                law.creep = None;
                law.creep_table = Some(*t);
            }
            None => {
                law.creep = Some(NonlinearCreep {
                    tension_n: values[0],
                    exponent: values[1],
                })
            }
        }
        Ok(law.validate()?)
    }
}
