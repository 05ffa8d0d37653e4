//! Coulomb and viscous friction in a joint's bearing: the rig's output shaft, an arm's
//! joint (URDF `<dynamics friction>`).

use std::sync::Arc;

use super::{
    check, Applied, Args, Argument, DataKind, Effect, EffectParam, JointForce, JointTorque, Shape,
    Site, Target,
};
use crate::DriveError;
use longreach_rope::Table;

/// Friction in the bearing of a joint: a Coulomb torque regularised over a slip rate,
/// plus a viscous torque ([`BearingFriction`]).
#[derive(Debug)]
pub struct JointFriction;

const PARAMS: &[EffectParam] = &[
    EffectParam {
        name: "coulomb_n_m",
        unit: "N*m",
        default: 0.01,
        lower: 1e-6,
        upper: 1e3,
        log_scale: true,
        fitted: true,
    },
    EffectParam {
        name: "viscous_n_m_s",
        unit: "N*m*s",
        default: 1e-3,
        lower: 0.0,
        upper: 1e3,
        log_scale: true,
        fitted: true,
    },
    EffectParam {
        name: "slip_rate_rad_s",
        unit: "rad/s",
        default: BearingFriction::DEFAULT_SLIP_RATE_RAD_S,
        lower: 1e-5,
        upper: 1.0,
        log_scale: true,
        fitted: false,
    },
];

impl Effect for JointFriction {
    fn name(&self) -> &'static str {
        "joint_friction"
    }
    fn doc(&self) -> &'static str {
        "The bearing of a joint (the rig's output shaft, an arm's joint: URDF \
         <dynamics friction>) resists rotation with a dry torque F_c of constant size, \
         regularised over a slip rate, plus a viscous torque b w: \
         tau = -(F_c tanh(w / w_s) + b w). Unlike the relay pulleys' friction it does \
         not grow with the rope tension, so on the rig it lowers the resonance peak by \
         the same torque at every mean tension, much more at small amplitudes than at \
         large ones; a free oscillation loses 4 F_c / k per cycle, linearly; a move \
         stops short of its target by up to F_c / k, a position error a viscous damper \
         cannot leave."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn site(&self) -> Site {
        Site::Joint
    }
    fn applies_to(&self, kind: DataKind) -> bool {
        matches!(kind, DataKind::SineSweep | DataKind::ArmMoves)
    }
    fn present_in(&self, target: &Target<'_>) -> bool {
        target.holds_joint_effect(self)
    }
    fn shape(&self) -> Option<Shape> {
        Some(Shape {
            argument: Argument::JointRateRadS,
            value: "coulomb_n_m",
            unit: "N*m",
            value_at_zero: None,
            non_decreasing: false,
            max_value: 1e3,
            log_knots: true,
            replaces: &["coulomb_n_m"],
        })
    }
    fn curve(&self, values: &[f64], _rate_rad_s: f64) -> f64 {
        values[0]
    }
    fn joint_force(&self, args: Args<'_>) -> Result<Option<Arc<dyn JointForce>>, DriveError> {
        let values = args.values;
        check(self, values)?;
        Ok(Some(Arc::new(BearingFriction {
            coulomb_n_m: values[0],
            viscous_n_m_s: values[1],
            slip_rate_rad_s: values[2],
            // Shape-free: the dry torque as a function of the speed (|rate|).
            coulomb_table: args.table.copied(),
        })))
    }
}

impl JointFriction {
    /// The effect with a dry torque `coulomb_n_m` alone (the URDF's `<dynamics
    /// friction>`; its `damping` is the joint's own viscous damping).
    pub fn dry(coulomb_n_m: f64) -> Result<Applied, DriveError> {
        Applied::new(
            &JointFriction,
            vec![coulomb_n_m, 0.0, BearingFriction::DEFAULT_SLIP_RATE_RAD_S],
        )
    }
}

/// The torque law of [`JointFriction`]:
/// `tau = -(coulomb tanh(w / slip_rate) + viscous w)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BearingFriction {
    /// Dry (Coulomb) torque, N*m.
    pub coulomb_n_m: f64,
    /// Viscous torque per rate, N*m*s/rad.
    pub viscous_n_m_s: f64,
    /// Rate over which the dry torque is regularised (tanh), rad/s.
    pub slip_rate_rad_s: f64,
    /// Shape-free form: the dry torque as a function of the speed `|w|` (N*m), in place
    /// of `coulomb_n_m` (a Stribeck curve, a drag that grows with speed).
    pub coulomb_table: Option<Table>,
}

impl BearingFriction {
    /// Default regularisation rate [rad/s]: far below the rates of a rig sweep or an
    /// arm move, wide enough for the implicit step's Newton iteration.
    pub const DEFAULT_SLIP_RATE_RAD_S: f64 = 1e-2;

    /// The work the torque does on the joint over a step of the trapezoidal rule from
    /// rate `w0` to `w1` through the angle `dq`, J (negative: dissipated): the rule's
    /// discrete work, `(tau(w0) + tau(w1)) / 2 * dq`.
    pub fn step_work_j(&self, w0: f64, w1: f64, dq: f64) -> f64 {
        0.5 * (self.torque(0.0, w0, &[]).torque_n_m + self.torque(0.0, w1, &[]).torque_n_m) * dq
    }
}

impl JointForce for BearingFriction {
    #[inline]
    fn torque(&self, _angle_rad: f64, rate_rad_s: f64, _state: &[f64]) -> JointTorque {
        let x = rate_rad_s / self.slip_rate_rad_s;
        let s = if x.abs() >= 22.0 {
            x.signum()
        } else {
            x.tanh()
        };
        // F(|w|) and dF/d|w|.
        let (f, df) = match &self.coulomb_table {
            None => (self.coulomb_n_m, 0.0),
            Some(t) => t.eval_slope(rate_rad_s.abs()),
        };
        JointTorque {
            torque_n_m: -(f * s + self.viscous_n_m_s * rate_rad_s),
            d_angle_n_m: 0.0,
            d_rate_n_m_s: -(f * (1.0 - s * s) / self.slip_rate_rad_s
                + df * rate_rad_s.signum() * s
                + self.viscous_n_m_s),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torque_opposes_motion_saturates_and_has_its_derivative() {
        let f = BearingFriction {
            coulomb_n_m: 0.2,
            viscous_n_m_s: 0.01,
            slip_rate_rad_s: 1e-2,
            coulomb_table: None,
        };
        let fast = f.torque(0.0, 3.0, &[]);
        assert!((fast.torque_n_m + 0.2 + 0.03).abs() < 1e-15);
        assert!((f.torque(0.0, -3.0, &[]).torque_n_m - 0.23).abs() < 1e-15);
        let w = 4e-3;
        let h = 1e-8;
        let fd = (f.torque(0.0, w + h, &[]).torque_n_m - f.torque(0.0, w - h, &[]).torque_n_m)
            / (2.0 * h);
        let an = f.torque(0.0, w, &[]).d_rate_n_m_s;
        assert!((fd - an).abs() < 1e-6 * an.abs(), "{fd} vs {an}");
        assert!(f.torque(0.0, 0.0, &[]).torque_n_m.abs() < 1e-300);
        let e = JointFriction
            .joint_force(Args::values(&[0.2, 0.01, 1e-2]))
            .unwrap();
        assert!(e.is_some());
        assert!(JointFriction
            .joint_force(Args::values(&[-1.0, 0.01, 1e-2]))
            .is_err());
    }
}
