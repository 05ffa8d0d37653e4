//! Shared test data: a second-order rope-drive transfer function.

use longreach_plot::{BodeCurve, Style};

/// Gain [dB] and phase [deg] of `H(s) = wn^2 / (s^2 + 2 zeta wn s + wn^2)` at `f_hz`.
pub fn second_order(f_hz: f64, fn_hz: f64, zeta: f64) -> (f64, f64) {
    let r = f_hz / fn_hz;
    // H(j w) = 1 / ((1 - r^2) + j 2 zeta r)
    let (re, im) = (1.0 - r * r, 2.0 * zeta * r);
    let gain_db = -10.0 * (re * re + im * im).log10();
    let phase_deg = -im.atan2(re).to_degrees();
    (gain_db, phase_deg)
}

/// Log-spaced frequencies from `f0` to `f1` Hz.
pub fn log_space(f0: f64, f1: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| f0 * (f1 / f0).powf(i as f64 / (n - 1) as f64))
        .collect()
}

/// Analytic (line) and "simulated" (markers, slightly perturbed, fewer points)
/// curves for a rope at `tension_n`, natural frequency growing with sqrt(tension).
pub fn rope_curves(tension_n: f64, color: usize) -> [BodeCurve; 2] {
    let fn_hz = 2.0 * (tension_n / 49.0).sqrt();
    let zeta = 0.08;
    let dense = log_space(0.1, 100.0, 300);
    let sparse = log_space(0.12, 80.0, 28);
    let eval = |f: &[f64], wobble: f64| -> (Vec<f64>, Vec<f64>) {
        f.iter()
            .enumerate()
            .map(|(i, &f)| {
                let (g, p) = second_order(f, fn_hz, zeta);
                let w = wobble * ((i as f64) * 1.7).sin();
                (g + w, p + 3.0 * w)
            })
            .unzip()
    };
    let (g, p) = eval(&dense, 0.0);
    let (gs, ps) = eval(&sparse, 0.4);
    [
        BodeCurve {
            label: format!("{tension_n} N analytic"),
            frequency_hz: dense,
            gain_db: g,
            phase_deg: p,
            style: Style::Line,
            color,
        },
        BodeCurve {
            label: format!("{tension_n} N simulated"),
            frequency_hz: sparse,
            gain_db: gs,
            phase_deg: ps,
            style: Style::Markers,
            color,
        },
    ]
}
