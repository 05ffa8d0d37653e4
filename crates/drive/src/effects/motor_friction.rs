//! Coulomb and viscous friction on the motor side of a rope pair (gearbox, motor
//! bearings, seals): the servo must overcome it.

use super::{check, Args, DataKind, Effect, EffectParam, Site, Target};
use crate::transmission::{MotorFriction, PairSpec};
use crate::DriveError;

/// Friction on every motor pulley's axis, `tau = -(F_c tanh(w / w_s) + b w)`
/// ([`MotorFriction`]), in the motor equation of the servo.
#[derive(Debug)]
pub struct MotorFrictionEffect;

const PARAMS: &[EffectParam] = &[
    EffectParam {
        name: "coulomb_n_m",
        unit: "N*m",
        // A geared drive of the arm's size (servo torques of 10^2-10^3 N*m).
        default: 5.0,
        lower: 0.0,
        upper: 1e4,
        log_scale: true,
        fitted: true,
    },
    EffectParam {
        name: "viscous_n_m_s",
        unit: "N*m*s",
        default: 1.0,
        lower: 0.0,
        upper: 1e4,
        log_scale: true,
        fitted: true,
    },
    EffectParam {
        name: "slip_rate_rad_s",
        unit: "rad/s",
        default: MotorFriction::DEFAULT_SLIP_RATE_RAD_S,
        lower: 1e-5,
        upper: 1.0,
        log_scale: true,
        fitted: false,
    },
];

impl Effect for MotorFrictionEffect {
    fn name(&self) -> &'static str {
        "motor_friction"
    }
    fn doc(&self) -> &'static str {
        "The motor side of a transmission (gearbox, motor bearings, seals) resists \
         rotation with a dry torque F_c, regularised over a slip rate, plus a viscous \
         torque b w: tau = -(F_c tanh(w / w_s) + b w) on the motor axis. A servo motor \
         must overcome it: while it turns at a steady rate w the servo lags its \
         reference by (F_c tanh(w / w_s) + b w) / kp more than without, so the joint \
         follows a ramp late by that angle times r_m / r_j, and the motor torque carries \
         the friction's sign change at every reversal. A kinematic motor (the rig's \
         input, an ideal stiff drive) follows its reference whatever the friction costs: \
         there the effect changes nothing, so only arm data with servo motors reveal it \
         (the arm_moves kind)."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn site(&self) -> Site {
        Site::Motor
    }
    fn applies_to(&self, kind: DataKind) -> bool {
        // The rig's input is kinematic (sweeps), specimens have no motor: only an arm's
        // servos (`arm_moves`) can reveal it.
        kind == DataKind::ArmMoves
    }
    fn present_in(&self, target: &Target<'_>) -> bool {
        target.pair.is_some_and(|p| p.motor.friction.is_some())
    }
    fn on_pair(&self, args: Args<'_>, pair: &mut PairSpec) -> Result<(), DriveError> {
        let values = args.values;
        check(self, values)?;
        let friction = MotorFriction {
            coulomb_n_m: values[0],
            viscous_n_m_s: values[1],
            slip_rate_rad_s: values[2],
        };
        friction.validate()?;
        pair.motor.friction = Some(friction);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_friction_opposes_the_rate_saturates_and_has_its_derivative() {
        let f = MotorFriction {
            coulomb_n_m: 2.0,
            viscous_n_m_s: 0.5,
            slip_rate_rad_s: 1e-2,
        };
        // Beyond 22 slip rates the dry torque is exactly F_c.
        assert!((f.resisting(3.0).0 - 3.5).abs() < 1e-15);
        assert!((f.resisting(-3.0).0 + 3.5).abs() < 1e-15);
        assert!(f.resisting(0.0).0.abs() < 1e-300);
        let (w, h) = (4e-3, 1e-8);
        let fd = (f.resisting(w + h).0 - f.resisting(w - h).0) / (2.0 * h);
        let an = f.resisting(w).1;
        assert!((fd - an).abs() < 1e-6 * an, "{fd} vs {an}");
    }

    #[test]
    fn on_pair_sets_the_motor_friction_and_checks_the_values() {
        let law = longreach_rope::RopeLaw::elastic(7.3e4);
        let mut pair = crate::RigSpec::paper("dyneema2", law, 0.05, 147.0).pair_spec();
        assert!(pair.motor.friction.is_none());
        MotorFrictionEffect
            .on_pair(Args::values(&[3.0, 0.2, 1e-3]), &mut pair)
            .unwrap();
        assert_eq!(
            pair.motor.friction,
            Some(MotorFriction {
                coulomb_n_m: 3.0,
                viscous_n_m_s: 0.2,
                slip_rate_rad_s: 1e-3
            })
        );
        assert!(MotorFrictionEffect
            .on_pair(Args::values(&[-1.0, 0.2, 1e-3]), &mut pair)
            .is_err());
        assert!(!MotorFrictionEffect.applies_to(DataKind::SineSweep));
        assert!(MotorFrictionEffect.applies_to(DataKind::ArmMoves));
    }
}
