//! Input-angle histories that drive a transmission: stepped sine (phase-continuous,
//! settle time, whole cycles), step, or a recorded series.

use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

use crate::error::{non_negative, positive, DriveError};

/// A stepped sine: each frequency is held for `settle_s` (transient) plus a whole
/// number of cycles to analyse (at least `min_cycles`, and at least `min_hold_s`
/// seconds); the phase is continuous across frequency steps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SteppedSine {
    /// Amplitude of the input angle [rad].
    pub amplitude_rad: f64,
    /// Test frequencies in the order played [Hz].
    pub frequencies_hz: Vec<f64>,
    /// Transient time at the start of every step, not analysed [s].
    pub settle_s: f64,
    /// Least number of whole cycles analysed per step.
    pub min_cycles: u32,
    /// Least analysed time per step [s] (rounded up to whole cycles).
    pub min_hold_s: f64,
}

/// One frequency step of a [`SteppedSine`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SineStep {
    /// Frequency [Hz].
    pub frequency_hz: f64,
    /// Start of the step [s].
    pub start_s: f64,
    /// Start of the analysed window (after the settle time) [s].
    pub analysis_start_s: f64,
    /// End of the step and of the analysed window [s].
    pub end_s: f64,
    /// Whole cycles in the analysed window.
    pub cycles: u32,
    /// Phase of the sine at `start_s` [rad].
    pub start_phase_rad: f64,
}

impl SteppedSine {
    /// Checks amplitude, frequencies and times; names the field that is wrong.
    pub fn validate(&self) -> Result<(), DriveError> {
        positive("amplitude_rad", self.amplitude_rad)?;
        non_negative("settle_s", self.settle_s)?;
        non_negative("min_hold_s", self.min_hold_s)?;
        if self.frequencies_hz.is_empty() {
            return Err(DriveError::BadParameter {
                field: "frequencies_hz".into(),
                value: 0.0,
                reason: "list at least one test frequency".into(),
            });
        }
        for &f in &self.frequencies_hz {
            positive("frequencies_hz", f)?;
        }
        if self.min_cycles == 0 {
            return Err(DriveError::BadParameter {
                field: "min_cycles".into(),
                value: 0.0,
                reason: "analyse at least one whole cycle per frequency (2 is usual)".into(),
            });
        }
        Ok(())
    }

    /// The schedule of frequency steps.
    pub fn steps(&self) -> Vec<SineStep> {
        let mut out = Vec::with_capacity(self.frequencies_hz.len());
        let (mut t, mut phase) = (0.0, 0.0);
        for &f in &self.frequencies_hz {
            let cycles = (self.min_hold_s * f).ceil().max(f64::from(self.min_cycles)) as u32;
            let hold = f64::from(cycles) / f;
            let step = SineStep {
                frequency_hz: f,
                start_s: t,
                analysis_start_s: t + self.settle_s,
                end_s: t + self.settle_s + hold,
                cycles,
                start_phase_rad: phase,
            };
            phase = (phase + TAU * f * (step.end_s - step.start_s)) % TAU;
            t = step.end_s;
            out.push(step);
        }
        out
    }
}

/// How many of the strictly increasing `time_s` are `<= t` (`partition_point`), found
/// in one guess on a uniformly sampled series (a recorded command; a simulation asks
/// for every joint at every step, and the binary search took 5% of an arm diagnosis)
/// and by bisection otherwise. The guess is kept only when it brackets `t`, so the
/// answer is the bisection's on any series.
fn samples_up_to(time_s: &[f64], t: f64) -> usize {
    let n = time_s.len();
    if n >= 2 && time_s[0] <= t && t < time_s[n - 1] {
        let span = time_s[n - 1] - time_s[0];
        let guess = ((t - time_s[0]) / span * (n - 1) as f64) as usize;
        if guess + 1 < n && time_s[guess] <= t && t < time_s[guess + 1] {
            return guess + 1;
        }
    }
    time_s.partition_point(|&x| x <= t)
}

/// An input-angle history.
#[derive(Debug, Clone, PartialEq)]
pub enum InputSignal {
    /// Stepped sine with its precomputed schedule.
    SteppedSine {
        /// The definition.
        sine: SteppedSine,
        /// Its steps.
        steps: Vec<SineStep>,
    },
    /// `0` before `start_s`, `amplitude_rad` from then on, for `duration_s`.
    Step {
        /// Step height [rad].
        amplitude_rad: f64,
        /// Time of the step [s].
        start_s: f64,
        /// Length of the run [s].
        duration_s: f64,
    },
    /// A recorded series, linearly interpolated (held constant past its ends).
    Series {
        /// Strictly increasing times [s].
        time_s: Vec<f64>,
        /// Angles [rad].
        angle_rad: Vec<f64>,
    },
}

impl InputSignal {
    /// A stepped sine (validated).
    pub fn stepped_sine(sine: SteppedSine) -> Result<Self, DriveError> {
        sine.validate()?;
        let steps = sine.steps();
        Ok(Self::SteppedSine { sine, steps })
    }

    /// A recorded series (validated: equal lengths, finite, strictly increasing time).
    pub fn series(time_s: Vec<f64>, angle_rad: Vec<f64>) -> Result<Self, DriveError> {
        if time_s.len() != angle_rad.len() || time_s.len() < 2 {
            return Err(DriveError::BadSeries(format!(
                "{} times and {} angles: give at least two samples of each, as many of one as of the other",
                time_s.len(),
                angle_rad.len()
            )));
        }
        for (i, (t, a)) in time_s.iter().zip(&angle_rad).enumerate() {
            if !t.is_finite() || !a.is_finite() {
                return Err(DriveError::BadSeries(format!(
                    "sample {i}: time {t}, angle {a}: every value must be finite"
                )));
            }
            if i > 0 && *t <= time_s[i - 1] {
                return Err(DriveError::BadSeries(format!(
                    "sample {i}: time {t} s does not increase (previous {} s)",
                    time_s[i - 1]
                )));
            }
        }
        Ok(Self::Series { time_s, angle_rad })
    }

    /// Length of the history [s].
    pub fn duration_s(&self) -> f64 {
        match self {
            Self::SteppedSine { steps, .. } => steps.last().map_or(0.0, |s| s.end_s),
            Self::Step { duration_s, .. } => *duration_s,
            Self::Series { time_s, .. } => time_s.last().copied().unwrap_or(0.0),
        }
    }

    /// Input angle at time `t` [rad].
    pub fn angle_rad(&self, t: f64) -> f64 {
        match self {
            Self::SteppedSine { sine, steps } => {
                // Steps are contiguous: find the one holding t (the last one past the end).
                let idx = steps.partition_point(|s| s.end_s <= t).min(steps.len() - 1);
                let s = &steps[idx];
                sine.amplitude_rad
                    * (s.start_phase_rad + TAU * s.frequency_hz * (t - s.start_s)).sin()
            }
            Self::Step {
                amplitude_rad,
                start_s,
                ..
            } => {
                if t >= *start_s {
                    *amplitude_rad
                } else {
                    0.0
                }
            }
            Self::Series { time_s, angle_rad } => {
                let i = samples_up_to(time_s, t);
                if i == 0 {
                    angle_rad[0]
                } else if i >= time_s.len() {
                    angle_rad[angle_rad.len() - 1]
                } else {
                    let (t0, t1) = (time_s[i - 1], time_s[i]);
                    let w = (t - t0) / (t1 - t0);
                    angle_rad[i - 1] + w * (angle_rad[i] - angle_rad[i - 1])
                }
            }
        }
    }
}
