//! The motor of a pair in the implicit step: a kinematic motor is held at its
//! reference; a servo motor's equation `J a1 + b w1 + F(w1) = sat(kp (th_ref - th) + kd
//! (thd_ref - thd) + ff) - r_m phi` is one unknown of the pair's local block (`F`: the
//! motor-side friction, [`super::spec::MotorFriction`], when the motor has one).

use super::spec::{MotorMode, MotorSpec};

/// One servo's contribution to the implicit step ([`servo_row`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ServoRow {
    /// Torque before saturation, N*m.
    pub raw_n_m: f64,
    /// Torque applied, N*m.
    pub torque_n_m: f64,
    /// `J a1 + b w1 - torque`, N*m.
    pub residual_n_m: f64,
    /// Its derivative with respect to the end motor angle, N*m/rad.
    pub diag: f64,
}

/// Where a motor starts a step: angle, rate and acceleration, and its reference.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MotorStart {
    pub angle_rad: f64,
    pub rate_rad_s: f64,
    pub accel_rad_s2: f64,
    pub ref_rad: f64,
}

/// The servo of a motor at the end-of-step angle `th1_rad` (trapezoidal rule from
/// `start` over `h`): its unsaturated and applied torques, and the motor equation's
/// residual `J a1 + b w1 - torque` and diagonal `4J/h^2 + 2b/h + d torque/d theta`
/// (without the ropes). `sat` is the saturation held through the Newton solve. `None`
/// for a kinematic motor.
#[inline]
pub(crate) fn servo_row(
    motor: &MotorSpec,
    h: f64,
    start: MotorStart,
    th1_rad: f64,
    ref_rate_rad_s: f64,
    ff_n_m: f64,
    sat: i8,
) -> Option<ServoRow> {
    let MotorMode::Servo {
        kp_n_m_per_rad,
        kd_n_m_s_per_rad,
        torque_limit_n_m,
        gravity_feedforward,
    } = motor.mode
    else {
        return None;
    };
    let (two_h, four_h2) = (2.0 / h, 4.0 / (h * h));
    let dth = th1_rad - start.angle_rad;
    let w1 = two_h * dth - start.rate_rad_s;
    let a1 = four_h2 * dth - 2.0 * two_h * start.rate_rad_s - start.accel_rad_s2;
    let raw_n_m = kp_n_m_per_rad * (start.ref_rad - th1_rad)
        + kd_n_m_s_per_rad * (ref_rate_rad_s - w1)
        + if gravity_feedforward { ff_n_m } else { 0.0 };
    // Saturation with an active set held through the Newton solve and corrected
    // at convergence (no chattering between pieces).
    let (torque_n_m, dservo) = if sat == 0 {
        (raw_n_m, kp_n_m_per_rad + two_h * kd_n_m_s_per_rad)
    } else {
        (f64::from(sat) * torque_limit_n_m, 0.0)
    };
    let (jm, bm) = (motor.inertia_kg_m2, motor.damping_n_m_s);
    let mut row = ServoRow {
        raw_n_m,
        torque_n_m,
        residual_n_m: jm * a1 + bm * w1 - torque_n_m,
        diag: four_h2 * jm + two_h * bm + dservo,
    };
    if let Some(f) = &motor.friction {
        // Motor-side friction (the `motor_friction` effect): the servo must overcome it.
        let (tau, slope) = f.resisting(w1);
        row.residual_n_m += tau;
        row.diag += two_h * slope;
    }
    Some(row)
}

/// The saturation a servo's unclamped torque `raw_n_m` asks for: -1, 0 or +1.
pub(crate) fn wanted_saturation(motor: &MotorSpec, raw_n_m: f64) -> Option<i8> {
    let MotorMode::Servo {
        torque_limit_n_m, ..
    } = motor.mode
    else {
        return None;
    };
    Some(if raw_n_m > torque_limit_n_m {
        1
    } else if raw_n_m < -torque_limit_n_m {
        -1
    } else {
        0
    })
}
