//! Frequency analysis of sampled signals: the single-bin DFT over whole cycles.

use num_complex::Complex64;
use std::f64::consts::TAU;

/// Single-bin DFT of `signal` sampled at `time_s` (any times), at `frequency_hz`:
/// `(2/N) sum x_n exp(-i 2 pi f t_n)`. For `x = a sin(2 pi f t + p)` over a whole number
/// of cycles this is `a exp(i (p - pi/2))`; ratios of two such bins give gain and phase.
pub fn single_bin(signal: &[f64], time_s: &[f64], frequency_hz: f64) -> Complex64 {
    let w = TAU * frequency_hz;
    let (mut re, mut im) = (0.0, 0.0);
    for (&x, &t) in signal.iter().zip(time_s) {
        let (s, c) = (w * t).sin_cos();
        re += x * c;
        im -= x * s;
    }
    let n = signal.len().max(1) as f64;
    Complex64::new(2.0 * re / n, 2.0 * im / n)
}

/// Unwraps a phase sequence [deg] so that successive values differ by less than 180.
pub fn unwrap_deg(phase_deg: &[f64]) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::with_capacity(phase_deg.len());
    for &p in phase_deg {
        let v = match out.last() {
            None => p,
            Some(&prev) => p - 360.0 * ((p - prev) / 360.0).round(),
        };
        out.push(v);
    }
    out
}
