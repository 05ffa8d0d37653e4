//! Sensor models for synthetic measurement data: encoder quantisation and Gaussian
//! tension noise. Everything is deterministic from a seed (ChaCha8 generator from
//! `rand_chacha`, the same stream on every platform).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::Normal;

/// Resolution of the rig's encoders (Omron E6B2-CWZ1X, paper Sec. IV-A): 0.18 deg
/// = pi/1000 rad per count.
pub const ENCODER_RESOLUTION_RAD: f64 = std::f64::consts::PI / 1000.0;

/// Why a sensor model could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SensorError {
    /// A parameter is out of range.
    #[error("{name} = {value}: {requirement}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must satisfy.
        requirement: &'static str,
    },
}

/// An incremental encoder: reports the angle rounded to the nearest whole count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Encoder {
    resolution_rad: f64,
}

impl Encoder {
    /// An encoder with `resolution_rad` radians per count (> 0, finite).
    pub fn new(resolution_rad: f64) -> Result<Self, SensorError> {
        if resolution_rad.is_finite() && resolution_rad > 0.0 {
            Ok(Encoder { resolution_rad })
        } else {
            Err(SensorError::InvalidParameter {
                name: "resolution_rad",
                value: resolution_rad,
                requirement: "must be a finite angle > 0",
            })
        }
    }

    /// The rig's encoder, [`ENCODER_RESOLUTION_RAD`].
    pub fn rig() -> Self {
        Encoder {
            resolution_rad: ENCODER_RESOLUTION_RAD,
        }
    }

    /// Radians per count.
    pub fn resolution_rad(&self) -> f64 {
        self.resolution_rad
    }

    /// The reading for true angle `angle_rad`: `q * round(angle / q)` (ties away from
    /// zero). The error is at most half a count; for an angle that moves over many
    /// counts it is close to uniform with RMS `q / sqrt(12)`.
    pub fn quantise(&self, angle_rad: f64) -> f64 {
        (angle_rad / self.resolution_rad).round() * self.resolution_rad
    }

    /// [`Encoder::quantise`] applied to every sample.
    pub fn quantise_all(&self, angle_rad: &[f64]) -> Vec<f64> {
        angle_rad.iter().map(|&a| self.quantise(a)).collect()
    }
}

/// Additive zero-mean Gaussian noise of standard deviation `sigma`, from a seeded
/// ChaCha8 generator: the same seed gives the same samples.
#[derive(Debug, Clone)]
pub struct GaussianNoise {
    normal: Normal<f64>,
    rng: ChaCha8Rng,
}

impl GaussianNoise {
    /// Noise with standard deviation `sigma` (>= 0, finite; in the unit of the signal,
    /// e.g. N for tension) from generator seed `seed`.
    pub fn new(sigma: f64, seed: u64) -> Result<Self, SensorError> {
        let bad = SensorError::InvalidParameter {
            name: "sigma",
            value: sigma,
            requirement: "must be a finite standard deviation >= 0",
        };
        if !(sigma.is_finite() && sigma >= 0.0) {
            return Err(bad);
        }
        let normal = Normal::new(0.0, sigma).map_err(|_| bad)?;
        Ok(GaussianNoise {
            normal,
            rng: ChaCha8Rng::seed_from_u64(seed),
        })
    }

    /// The next noise sample.
    pub fn sample(&mut self) -> f64 {
        self.rng.sample(self.normal)
    }

    /// Adds noise to every sample of `signal`, in order.
    pub fn add_to(&mut self, signal: &mut [f64]) {
        for v in signal {
            *v += self.sample();
        }
    }

    /// A copy of `signal` with noise added.
    pub fn noisy(&mut self, signal: &[f64]) -> Vec<f64> {
        let mut out = signal.to_vec();
        self.add_to(&mut out);
        out
    }
}
