//! Relay (idler) pulleys with load-dependent bearing friction and inertia.
//!
//! A relay pulley of radius `r` carries a rope wrapped half-way round it (180 deg), so
//! its hub load is the sum of the tensions of the spans on either side, `T_a + T_b`.
//! Its bearing (radius `r_b`, Coulomb coefficient `mu_b`) resists rotation with the
//! torque `mu_b r_b (T_a + T_b)`; written per unit pulley radius this is the
//! dimensionless `coefficient = mu_b r_b / r`:
//!
//! ```text
//!   J psi'' = r (T_a - T_b) - coefficient * r * (T_a + T_b) * tanh(psi' / slip_rate)
//! ```
//!
//! `tanh` regularises Coulomb's sign function over `slip_rate_rad_s` (a pulley turning
//! slower than that is "sticking"), which keeps the implicit step smooth. In steady
//! sliding the tension ratio across the pulley is `(1 + c) / (1 - c) ~ exp(2 c)`, the
//! capstan-like loss a measured transmission shows; with `coefficient = 0` and
//! `inertia_kg_m2 = 0` the pulley is ideal. The rope on either side of a relay pulley
//! is a separate span with its own rope state: that is what lets the tensions differ.

use longreach_rope::Table;
use serde::{Deserialize, Serialize};

use crate::error::{non_negative, positive, DriveError};

/// Friction and inertia of every relay pulley of a transmission (SI).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RelayFriction {
    /// Bearing friction torque per unit pulley radius per newton of hub load
    /// (`mu_b r_b / r`) [-].
    pub coefficient: f64,
    /// Rotational inertia of one relay pulley about its axle [kg*m^2].
    pub inertia_kg_m2: f64,
    /// Rotation rate over which Coulomb friction is regularised (tanh) [rad/s].
    pub slip_rate_rad_s: f64,
    /// Shape-free form: the coefficient as a function of the hub load (N), replacing
    /// `coefficient` (friction that grows or falls with the load, unlike Coulomb's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub coefficient_table: Option<Table>,
}

impl RelayFriction {
    /// Default regularisation rate [rad/s]: well below the rates of a 0.1-10 Hz sweep
    /// of a few degrees on a 25 mm pulley.
    pub const DEFAULT_SLIP_RATE_RAD_S: f64 = 1e-3;

    /// Checks every field; names the one that is wrong.
    pub fn validate(&self) -> Result<(), DriveError> {
        let c = non_negative("relay_friction.coefficient", self.coefficient)?;
        if c >= 1.0 {
            return Err(DriveError::BadParameter {
                field: "relay_friction.coefficient".into(),
                value: c,
                reason: "must be < 1 (the pulley would lock; typical bearings 0.001-0.05)".into(),
            });
        }
        if let Some(t) = &self.coefficient_table {
            if t.y().iter().any(|v| !(*v >= 0.0 && *v < 1.0)) {
                return Err(DriveError::BadParameter {
                    field: "relay_friction.coefficient_table".into(),
                    value: t.y().iter().copied().fold(f64::NAN, f64::max),
                    reason: "every coefficient must lie in [0, 1)".into(),
                });
            }
        }
        let j = non_negative("relay_friction.inertia_kg_m2", self.inertia_kg_m2)?;
        let rubs = c > 0.0
            || self
                .coefficient_table
                .is_some_and(|t| t.y().iter().any(|v| *v > 0.0));
        if rubs && j == 0.0 {
            return Err(DriveError::BadParameter {
                field: "relay_friction.inertia_kg_m2".into(),
                value: j,
                reason: "must be > 0 when the coefficient is > 0: a pulley's friction \
                         depends on its rate, which a massless pulley does not have (a 25 mm \
                         aluminium pulley: ~2e-5 kg*m^2)"
                    .into(),
            });
        }
        positive("relay_friction.slip_rate_rad_s", self.slip_rate_rad_s)?;
        Ok(())
    }

    /// Friction torque opposing the rotation, for a pulley of `radius_m` carrying the
    /// hub load `tension_sum_n` and turning at `rate_rad_s` [N*m], with its partial
    /// derivatives with respect to the hub load and to the rate.
    #[inline]
    pub fn torque_n_m(&self, radius_m: f64, tension_sum_n: f64, rate_rad_s: f64) -> RelayTorque {
        let s = tanh(rate_rad_s / self.slip_rate_rad_s);
        let (c, dc) = match &self.coefficient_table {
            None => (self.coefficient, 0.0),
            Some(t) => t.eval_slope(tension_sum_n),
        };
        let scale = c * radius_m;
        RelayTorque {
            torque_n_m: scale * tension_sum_n * s,
            d_tension_sum_m: if dc == 0.0 {
                scale * s
            } else {
                (c + tension_sum_n * dc) * radius_m * s
            },
            d_rate_n_m_s: scale * tension_sum_n * (1.0 - s * s) / self.slip_rate_rad_s,
        }
    }

    /// Steady sliding tension ratio `T_a / T_b = (1 + c) / (1 - c)` across one pulley.
    pub fn sliding_tension_ratio(&self) -> f64 {
        (1.0 + self.coefficient) / (1.0 - self.coefficient)
    }
}

/// `tanh(x)` within a few ulps, cheaper where the relays slip: from one `exp` where
/// `|x| >= 0.5` (`(1 - t) / (1 + t)` with `t = exp(-2|x|) <= 1/e`, no cancellation),
/// the library's `tanh` below (through `expm1`), and exactly `+-1` from 22 on, where
/// `tanh` rounds to it. The relay step calls it for every relay at every evaluation:
/// the library's `tanh` and its `expm1` took 14% of the CPU of a 5-run relay sweep's
/// diagnosis (perf), `exp` and the `tanh` left below 0.5 take 5%, and the diagnosis
/// ~7% less wall time (2026-12-07).
#[inline]
fn tanh(x: f64) -> f64 {
    let a = x.abs();
    if a >= 22.0 {
        x.signum()
    } else if a >= 0.5 {
        let t = (-2.0 * a).exp();
        ((1.0 - t) / (1.0 + t)).copysign(x)
    } else {
        x.tanh()
    }
}

/// The friction torque of [`RelayFriction::torque_n_m`] and its derivatives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelayTorque {
    /// Torque opposing the rotation [N*m].
    pub torque_n_m: f64,
    /// d torque / d hub load [m].
    pub d_tension_sum_m: f64,
    /// d torque / d rate [N*m*s].
    pub d_rate_n_m_s: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn relay() -> RelayFriction {
        RelayFriction {
            coefficient: 0.02,
            inertia_kg_m2: 1e-5,
            slip_rate_rad_s: RelayFriction::DEFAULT_SLIP_RATE_RAD_S,
            coefficient_table: None,
        }
    }

    #[test]
    fn torque_saturates_at_coulomb_and_derivatives_match_finite_differences() {
        let r = relay();
        let fast = r.torque_n_m(0.025, 300.0, 10.0);
        assert!((fast.torque_n_m - 0.02 * 0.025 * 300.0).abs() < 1e-12);
        let slow = r.torque_n_m(0.025, 300.0, 4e-4);
        let h = 1e-9;
        let up = r.torque_n_m(0.025, 300.0, 4e-4 + h).torque_n_m;
        let dn = r.torque_n_m(0.025, 300.0, 4e-4 - h).torque_n_m;
        let fd = (up - dn) / (2.0 * h);
        assert!((fd - slow.d_rate_n_m_s).abs() < 1e-5 * slow.d_rate_n_m_s.abs());
        let fd_t = (r.torque_n_m(0.025, 301.0, 4e-4).torque_n_m
            - r.torque_n_m(0.025, 299.0, 4e-4).torque_n_m)
            / 2.0;
        assert!((fd_t - slow.d_tension_sum_m).abs() < 1e-12);
        assert!((r.sliding_tension_ratio() - 1.02 / 0.98).abs() < 1e-15);
    }

    /// The relay's `tanh` against the library's over the whole range it is used on:
    /// within 4 ulps of it, odd, and `+-1` exactly where the library's is.
    #[test]
    fn tanh_is_the_librarys_within_a_few_ulps() {
        let mut worst = 0.0f64;
        for i in 0..=400_000 {
            let x = -30.0 + 60.0 * f64::from(i) / 400_000.0;
            let (ours, lib) = (tanh(x), x.tanh());
            worst =
                worst.max((ours - lib).abs() / (f64::EPSILON * lib.abs().max(f64::MIN_POSITIVE)));
            assert_eq!(tanh(-x).to_bits(), (-ours).to_bits(), "{x}");
            if lib.abs().to_bits() == 1f64.to_bits() {
                assert_eq!(ours.to_bits(), lib.to_bits(), "{x}");
            }
        }
        assert!(worst <= 4.0, "{worst} ulps");
        assert_eq!(tanh(0.0).to_bits(), 0f64.to_bits());
    }

    #[test]
    fn bad_values_name_the_field() {
        let mut r = relay();
        r.coefficient = 1.2;
        let e = r.validate().unwrap_err().to_string();
        assert!(e.contains("relay_friction.coefficient"), "{e}");
        r.coefficient = 0.01;
        r.slip_rate_rad_s = 0.0;
        let e = r.validate().unwrap_err().to_string();
        assert!(e.contains("slip_rate_rad_s"), "{e}");
    }
}
