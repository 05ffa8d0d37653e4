//! Joint reference histories: hold, step, trapezoidal move, sine, or any
//! [`InputSignal`] (stepped sine, recorded CSV series).

use longreach_drive::InputSignal;

/// Reference angle of one joint as a function of time (absolute, rad).
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// Stay at the initial angle.
    Hold,
    /// Jump from the initial angle to `to_rad` at `at_s`.
    Step {
        /// Target, rad.
        to_rad: f64,
        /// Time of the jump, s.
        at_s: f64,
    },
    /// Trapezoidal velocity profile from the initial angle to `to_rad`, starting at
    /// `start_s`, with speed limit `max_velocity_rad_s` and acceleration limit
    /// `max_accel_rad_s2` (triangular when the move is too short to cruise).
    Trapezoid {
        /// Target, rad.
        to_rad: f64,
        /// Start, s.
        start_s: f64,
        /// Cruise speed, rad/s.
        max_velocity_rad_s: f64,
        /// Acceleration and deceleration, rad/s^2.
        max_accel_rad_s2: f64,
    },
    /// `initial + amplitude sin(2 pi f (t - start))` from `start_s` on.
    Sine {
        /// Amplitude, rad.
        amplitude_rad: f64,
        /// Frequency, Hz.
        frequency_hz: f64,
        /// Start, s.
        start_s: f64,
    },
    /// `initial + signal(t)` (stepped sine, step, recorded series).
    Signal(InputSignal),
}

impl Command {
    /// Reference angle at `t` for a joint starting at `initial_rad`.
    pub fn angle_rad(&self, initial_rad: f64, t: f64) -> f64 {
        match self {
            Command::Hold => initial_rad,
            Command::Step { to_rad, at_s } => {
                if t >= *at_s {
                    *to_rad
                } else {
                    initial_rad
                }
            }
            Command::Trapezoid {
                to_rad,
                start_s,
                max_velocity_rad_s,
                max_accel_rad_s2,
            } => {
                let d = to_rad - initial_rad;
                let s = trapezoid(d.abs(), *max_velocity_rad_s, *max_accel_rad_s2, t - start_s);
                initial_rad + d.signum() * s
            }
            Command::Sine {
                amplitude_rad,
                frequency_hz,
                start_s,
            } => {
                if t < *start_s {
                    initial_rad
                } else {
                    initial_rad
                        + amplitude_rad
                            * (std::f64::consts::TAU * frequency_hz * (t - start_s)).sin()
                }
            }
            Command::Signal(s) => initial_rad + s.angle_rad(t),
        }
    }

    /// Final target when the command ends at rest (step, trapezoid, hold), else `None`.
    pub fn target_rad(&self, initial_rad: f64) -> Option<f64> {
        match self {
            Command::Hold => Some(initial_rad),
            Command::Step { to_rad, .. } | Command::Trapezoid { to_rad, .. } => Some(*to_rad),
            _ => None,
        }
    }

    /// Time the reference starts moving, s (0 for hold).
    pub fn start_s(&self) -> f64 {
        match self {
            Command::Hold | Command::Signal(_) => 0.0,
            Command::Step { at_s, .. } => *at_s,
            Command::Trapezoid { start_s, .. } | Command::Sine { start_s, .. } => *start_s,
        }
    }

    /// Time the reference reaches its target, s (`None` when it never rests).
    pub fn end_s(&self, initial_rad: f64) -> Option<f64> {
        match self {
            Command::Hold => Some(0.0),
            Command::Step { at_s, .. } => Some(*at_s),
            Command::Trapezoid {
                to_rad,
                start_s,
                max_velocity_rad_s,
                max_accel_rad_s2,
            } => Some(
                start_s
                    + trapezoid_duration(
                        (to_rad - initial_rad).abs(),
                        *max_velocity_rad_s,
                        *max_accel_rad_s2,
                    ),
            ),
            _ => None,
        }
    }
}

/// Duration of a trapezoidal move of length `d`, s.
pub fn trapezoid_duration(d: f64, v: f64, a: f64) -> f64 {
    if d <= 0.0 {
        return 0.0;
    }
    if d >= v * v / a {
        d / v + v / a
    } else {
        2.0 * (d / a).sqrt()
    }
}

/// Distance covered after `t` seconds of a trapezoidal move of length `d`.
fn trapezoid(d: f64, v: f64, a: f64, t: f64) -> f64 {
    if t <= 0.0 || d <= 0.0 {
        return 0.0;
    }
    let (t_acc, v_peak) = if d >= v * v / a {
        (v / a, v)
    } else {
        let tp = (d / a).sqrt();
        (tp, a * tp)
    };
    let d_acc = 0.5 * a * t_acc * t_acc;
    let t_cruise = (d - 2.0 * d_acc) / v_peak;
    let total = 2.0 * t_acc + t_cruise;
    if t >= total {
        d
    } else if t < t_acc {
        0.5 * a * t * t
    } else if t < t_acc + t_cruise {
        d_acc + v_peak * (t - t_acc)
    } else {
        let r = total - t;
        d - 0.5 * a * r * r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoid_reaches_target_with_continuous_profile() {
        let c = Command::Trapezoid {
            to_rad: 1.0,
            start_s: 0.5,
            max_velocity_rad_s: 0.5,
            max_accel_rad_s2: 1.0,
        };
        // d = 1, v = 0.5, a = 1: accel 0.5 s (0.125 rad), cruise 1.5 s, total 2.5 s.
        assert!((c.end_s(0.0).unwrap() - 3.0).abs() < 1e-12);
        assert!((c.angle_rad(0.0, 1.0) - 0.125).abs() < 1e-12);
        assert!((c.angle_rad(0.0, 2.0) - (0.125 + 0.5)).abs() < 1e-12);
        assert!((c.angle_rad(0.0, 3.0) - 1.0).abs() < 1e-12);
        assert!((c.angle_rad(0.0, 2.75) - (1.0 - 0.5 * 0.0625)).abs() < 1e-12);
        // Triangular: d = 0.1 < v^2/a.
        assert!((trapezoid_duration(0.1, 0.5, 1.0) - 2.0 * 0.1f64.sqrt()).abs() < 1e-12);
    }
}
