//! Analytic transfer functions of the rig: eq. 12 (four-element ropes) and eq. 13
//! (elastic ropes), generalised to every linear element a [`RopeLaw`] can hold.

use num_complex::Complex64;
use std::f64::consts::TAU;

use longreach_rope::RopeLaw;

use crate::rig::RigSpec;

/// Compliance of a rope of unit length, per unit strain, at Laplace variable `s`
/// [1/N]: `1/(k1 + c1 s) + 1/(c2 s) + sum_j 1/(k_j + c_j s)` (Fig. 1 in series).
///
/// Non-linear elements enter by their tangent at `tension_n` (the small-signal law
/// around the mean tension); Flory's ratchet is locked below its peak (eq. 2) and adds
/// nothing.
pub fn rope_compliance(law: &RopeLaw, s: Complex64, tension_n: f64) -> Complex64 {
    let k1 = law.head_stiffness(tension_n);
    let mut j = (Complex64::new(k1, 0.0) + s * law.c1_n_s).inv();
    if let Some(c2) = law.c2_n_s {
        let slope = match law.creep {
            None => 1.0 / c2,
            Some(c) => {
                (1.0 + (c.exponent + 1.0) * (tension_n.max(0.0) / c.tension_n).powf(c.exponent))
                    / c2
            }
        };
        j += (s / slope).inv();
    }
    for el in &law.kelvin {
        j += (Complex64::new(el.k_n, 0.0) + s * el.c_n_s).inv();
    }
    j
}

/// `phi / theta` of the rig at `frequency_hz` (eq. 12; eq. 13 for an elastic rope):
/// `G(s) = r1 / ((I s^2 + C s) / (2 r2) * L * J(s) + r2)`.
pub fn rig_transfer(spec: &RigSpec, frequency_hz: f64) -> Complex64 {
    let s = Complex64::new(0.0, TAU * frequency_hz);
    let j = rope_compliance(&spec.law, s, spec.mean_tension_n) * spec.rope_length_m;
    let load = (s * s * spec.output_inertia_kg_m2 + s * spec.output_damping_n_m_s)
        / (2.0 * spec.output_radius_m);
    Complex64::new(spec.input_radius_m, 0.0) / (load * j + spec.output_radius_m)
}

/// Gain [dB] and phase [deg, in (-360, 0] for a lag] of a complex ratio.
pub fn gain_phase(g: Complex64) -> (f64, f64) {
    let phase = g.arg().to_degrees();
    (
        20.0 * g.norm().log10(),
        if phase > 0.0 { phase - 360.0 } else { phase },
    )
}

/// A resonance: the frequency of the gain's maximum and the gain there.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Resonance {
    /// Frequency of the peak [Hz].
    pub frequency_hz: f64,
    /// Peak gain [dB].
    pub peak_gain_db: f64,
}

/// The maximum of a unimodal `f` on `[a, b]` by golden-section search: at most
/// `max_iter` reductions of the bracket, stopping once it is narrower than `rel_tol`
/// times its upper end; the bracket's midpoint.
pub fn golden_section_max(
    f: impl Fn(f64) -> f64,
    mut a: f64,
    mut b: f64,
    max_iter: usize,
    rel_tol: f64,
) -> f64 {
    let r = (5f64.sqrt() - 1.0) / 2.0;
    for _ in 0..max_iter {
        let (c, d) = (b - r * (b - a), a + r * (b - a));
        if f(c) > f(d) {
            b = d;
        } else {
            a = c;
        }
        if b - a < rel_tol * b {
            break;
        }
    }
    0.5 * (a + b)
}

/// Resonance of the analytic rig response: the global maximum of `|G|` between
/// `lo_hz` and `hi_hz`, found on a log grid and refined by golden-section search.
/// `None` when the maximum sits at an end of the range (no resonance inside).
pub fn rig_resonance(spec: &RigSpec, lo_hz: f64, hi_hz: f64) -> Option<Resonance> {
    let gain = |f: f64| rig_transfer(spec, f).norm();
    let n = 2000;
    let freq = |i: usize| lo_hz * (hi_hz / lo_hz).powf(i as f64 / n as f64);
    let best = (0..=n)
        .map(|i| (i, gain(freq(i))))
        .fold((0, f64::MIN), |a, b| if b.1 > a.1 { b } else { a })
        .0;
    if best == 0 || best == n {
        return None;
    }
    let f = golden_section_max(gain, freq(best - 1), freq(best + 1), 100, 1e-12);
    Some(Resonance {
        frequency_hz: f,
        peak_gain_db: 20.0 * gain(f).log10(),
    })
}
