//! Closed-form tension relaxation of the four-element model (paper eq. 6) and its RMS
//! error against a measurement (eq. 7).

/// Tension [N] of a four-element rope held at constant strain `strain` from `t = 0`,
/// starting from eq. 5 (`e1(0) = strain`, `e2(0) = e3(0) = 0`), at time `time_s`.
///
/// Eq. 6: `f(t) = e0 k1/(2B) [exp(-(A+B)t/D)(C+B) - exp(-(A-B)t/D)(C-B)]` with
/// `A = c2 k1 + c2 k3 + c3 k1`, `B = sqrt(A^2 - 4 c2 c3 k1 k3)`,
/// `C = c2 k1 - c2 k3 + c3 k1`, `D = 2 c2 c3`. `A - B` is evaluated as
/// `4 c2 c3 k1 k3 / (A + B)` to avoid cancellation (the slow creep mode).
pub fn relaxation_tension_n(
    k1_n: f64,
    c2_n_s: f64,
    k3_n: f64,
    c3_n_s: f64,
    strain: f64,
    time_s: f64,
) -> f64 {
    let a = c2_n_s * k1_n + c2_n_s * k3_n + c3_n_s * k1_n;
    let prod = 4.0 * c2_n_s * c3_n_s * k1_n * k3_n;
    let b = (a * a - prod).sqrt();
    let c = c2_n_s * k1_n - c2_n_s * k3_n + c3_n_s * k1_n;
    let d = 2.0 * c2_n_s * c3_n_s;
    let a_minus_b = prod / (a + b);
    let scale = strain * k1_n / (2.0 * b);
    scale * ((-(a + b) / d * time_s).exp() * (c + b) - (-a_minus_b / d * time_s).exp() * (c - b))
}

/// RMS of model minus measurement (eq. 7). Returns `None` for empty or unequal inputs.
pub fn rms_error(model: &[f64], measured: &[f64]) -> Option<f64> {
    if model.is_empty() || model.len() != measured.len() {
        return None;
    }
    let ss: f64 = model
        .iter()
        .zip(measured)
        .map(|(m, y)| (m - y) * (m - y))
        .sum();
    Some((ss / model.len() as f64).sqrt())
}
