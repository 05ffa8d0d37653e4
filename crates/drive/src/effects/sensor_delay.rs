//! A delay between the rig's output pulley and what its encoder reports.

use std::sync::Arc;

use super::{check, Args, DataKind, Effect, EffectParam, SensorModel, Site, Target};
use crate::DriveError;

/// The output encoder's reading lags the pulley by a constant time (the encoder's
/// filter, the acquisition's sampling and transport): it reports `phi(t - tau)`.
#[derive(Debug)]
pub struct SensorDelay;

const PARAMS: &[EffectParam] = &[EffectParam {
    name: "delay_s",
    unit: "s",
    default: 2e-3,
    lower: 1e-5,
    upper: 0.2,
    log_scale: true,
    fitted: true,
}];

impl Effect for SensorDelay {
    fn name(&self) -> &'static str {
        "sensor_delay"
    }
    fn doc(&self) -> &'static str {
        "The output encoder reports the pulley's angle a constant time tau late (its \
         filter, the acquisition's sampling, a bus): the measured output is phi(t - tau). \
         The plant itself is unchanged, so the gain of every test frequency is right and \
         the phase lags by 360 f tau degrees, a phase error that grows in proportion to \
         the frequency at every mean tension and amplitude; no dissipation fits that, \
         since a damper's phase error peaks at the resonance."
    }
    fn params(&self) -> &'static [EffectParam] {
        PARAMS
    }
    fn site(&self) -> Site {
        Site::Sensor
    }
    fn applies_to(&self, kind: DataKind) -> bool {
        kind == DataKind::SineSweep
    }
    fn present_in(&self, _target: &Target<'_>) -> bool {
        false
    }
    fn sensor(&self, args: Args<'_>) -> Result<Option<Arc<dyn SensorModel>>, DriveError> {
        let values = args.values;
        check(self, values)?;
        Ok(Some(Arc::new(Delay {
            channel: "output_angle_rad",
            delay_s: values[0],
        })))
    }
}

/// A pure delay of one channel: the reported value at `t` is the true one at `t - delay`
/// (linear interpolation between samples; before the first sample, the first value).
#[derive(Debug, Clone, PartialEq)]
pub struct Delay {
    /// The channel it acts on.
    pub channel: &'static str,
    /// Delay, s.
    pub delay_s: f64,
}

impl SensorModel for Delay {
    fn acts_on(&self, channel: &str) -> bool {
        channel == self.channel
    }

    fn apply(&self, time_s: &[f64], values: &mut [f64]) {
        let n = values.len().min(time_s.len());
        if n < 2 || self.delay_s <= 0.0 {
            return;
        }
        let truth = values[..n].to_vec();
        // Samples are (nearly) evenly spaced: find the interval by the mean step, then
        // correct it against the actual times.
        let t0 = time_s[0];
        let dt = (time_s[n - 1] - t0) / (n - 1) as f64;
        for (i, v) in values[..n].iter_mut().enumerate() {
            let t = time_s[i] - self.delay_s;
            if t <= t0 {
                *v = truth[0];
                continue;
            }
            let mut k = (((t - t0) / dt).floor() as usize).min(n - 2);
            while k > 0 && time_s[k] > t {
                k -= 1;
            }
            while k + 2 < n && time_s[k + 1] <= t {
                k += 1;
            }
            let span = time_s[k + 1] - time_s[k];
            let a = if span > 0.0 {
                ((t - time_s[k]) / span).clamp(0.0, 1.0)
            } else {
                0.0
            };
            *v = truth[k] + a * (truth[k + 1] - truth[k]);
        }
    }

    fn response(&self, frequency_hz: f64) -> Option<num_complex::Complex64> {
        Some(num_complex::Complex64::from_polar(
            1.0,
            -std::f64::consts::TAU * frequency_hz * self.delay_s,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_delayed_sine_lags_by_the_delay() {
        let d = Delay {
            channel: "output_angle_rad",
            delay_s: 0.0123,
        };
        let t: Vec<f64> = (0..2000).map(|i| i as f64 * 1e-3).collect();
        let w = std::f64::consts::TAU * 2.0;
        let mut v: Vec<f64> = t.iter().map(|t| (w * t).sin()).collect();
        d.apply(&t, &mut v);
        let worst = t[20..]
            .iter()
            .zip(&v[20..])
            .map(|(t, v)| (v - (w * (t - 0.0123)).sin()).abs())
            .fold(0.0f64, f64::max);
        // Linear interpolation of a 2 Hz sine sampled at 1 kHz: error below w^2 dt^2 / 8.
        assert!(worst < w * w * 1e-6 / 8.0 * 1.01, "{worst}");
        assert!(d.acts_on("output_angle_rad") && !d.acts_on("tension_in_1_n"));
        assert!(SensorDelay.sensor(Args::values(&[0.5])).is_err());
    }
}
