//! Load-dependent friction and inertia at the relay pulleys.

use super::{check, Args, Argument, DataKind, Effect, EffectParam, Shape, Site, Target};
use crate::transmission::PairSpec;
use crate::{DriveError, RelayFriction};

/// Bearing friction proportional to the hub load, and inertia, at every relay pulley
/// ([`RelayFriction`]); each rope is then split into spans with their own state.
#[derive(Debug)]
pub struct RelayFrictionEffect;

const PARAMS: &[EffectParam] = &[
    EffectParam {
        name: "coefficient",
        unit: "1",
        default: 0.01,
        lower: 1e-4,
        upper: 0.2,
        log_scale: true,
        fitted: true,
    },
    EffectParam {
        name: "inertia_kg_m2",
        unit: "kg*m^2",
        // A 25 mm aluminium pulley 10 mm thick: 1/2 m r^2 ~ 1.7e-5 kg*m^2.
        default: 2e-5,
        lower: 1e-7,
        // The arm's relay pulleys (radius ~0.2 m) reach ~1e-2 kg*m^2.
        upper: 0.1,
        log_scale: true,
        fitted: true,
    },
];

impl Effect for RelayFrictionEffect {
    fn name(&self) -> &'static str {
        "relay_friction"
    }
    fn doc(&self) -> &'static str {
        "Each rope runs half-way round its relay (idler) pulleys, whose bearings carry \
         the sum of the two span tensions and resist rotation with a Coulomb torque \
         coefficient * r * (T_in + T_out) (coefficient = mu_b r_b / r, dimensionless); \
         each pulley also has an inertia J. The rope is then a chain of spans with their \
         own tensions: while the rope slides over a pulley the tensions on its two sides \
         differ by the ratio (1 + c)/(1 - c), while it sticks the pulley holds the rope. \
         On the rig this is dry friction, not viscous damping: the resonance peak is \
         lowered much more at small input amplitudes than at large ones, a free \
         oscillation decays linearly rather than exponentially, and the tensions next to \
         the input and output pulleys differ by the velocity sign."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn applies_to(&self, kind: DataKind) -> bool {
        // The rig's sweeps and an arm's moves (every relay pulley of every pair); a
        // specimen has no pulley.
        matches!(kind, DataKind::SineSweep | DataKind::ArmMoves)
    }
    fn site(&self) -> Site {
        Site::RelayPulley
    }
    fn present_in(&self, target: &Target<'_>) -> bool {
        target
            .pair
            .is_some_and(|p| p.relay_friction.is_some_and(|f| f.coefficient > 0.0))
    }
    fn shape(&self) -> Option<Shape> {
        Some(Shape {
            argument: Argument::HubLoadN,
            value: "coefficient",
            unit: "1",
            value_at_zero: None,
            non_decreasing: false,
            max_value: 0.5,
            log_knots: false,
            replaces: &["coefficient"],
        })
    }
    fn curve(&self, values: &[f64], _hub_load_n: f64) -> f64 {
        values[0]
    }
    fn on_pair(&self, args: Args<'_>, pair: &mut PairSpec) -> Result<(), DriveError> {
        let values = args.values;
        check(self, values)?;
        let friction = RelayFriction {
            coefficient: values[0],
            inertia_kg_m2: values[1],
            slip_rate_rad_s: pair
                .relay_friction
                .map_or(RelayFriction::DEFAULT_SLIP_RATE_RAD_S, |f| {
                    f.slip_rate_rad_s
                }),
            // Shape-free: the coefficient as a function of the hub load.
            coefficient_table: args.table.copied(),
        };
        friction.validate()?;
        pair.relay_friction = Some(friction);
        Ok(())
    }
}
