//! Error metrics, frequency-response estimation and residual checks: pure functions on
//! slices of samples.
//!
//! Conventions: a signal is a slice of samples taken every `dt_s` seconds, the first at
//! t = 0. An error (residual) is `model - measured`. All functions refuse empty,
//! mismatched or non-finite input with a [`MetricsError`] instead of returning NaN.

use num_complex::Complex64;
use rustfft::FftPlanner;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Why a metric could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetricsError {
    /// Too few samples.
    #[error("{what}: {len} samples, at least {min} needed; pass a longer signal")]
    TooShort {
        /// The quantity being computed.
        what: &'static str,
        /// Samples given.
        len: usize,
        /// Samples needed.
        min: usize,
    },
    /// Two slices that must have equal length do not.
    #[error("{what}: lengths differ ({a} vs {b}); pass slices of equal length")]
    LengthMismatch {
        /// The quantity being computed.
        what: &'static str,
        /// Length of the first slice.
        a: usize,
        /// Length of the second slice.
        b: usize,
    },
    /// A sample is NaN or infinite.
    #[error("{what}: sample {index} of `{signal}` is {value} (not finite); the model or data blew up -- check it before computing metrics")]
    NonFinite {
        /// The quantity being computed.
        what: &'static str,
        /// Which input.
        signal: &'static str,
        /// Index of the first bad sample.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A normalising quantity is zero (constant signal, zero total error, zero amplitude).
    #[error("{what}: {quantity} is zero, the ratio is undefined; {hint}")]
    Zero {
        /// The quantity being computed.
        what: &'static str,
        /// What is zero.
        quantity: &'static str,
        /// What to do.
        hint: &'static str,
    },
    /// A scalar argument is out of range.
    #[error("{what}: {name} = {value} {requirement}")]
    InvalidArgument {
        /// The quantity being computed.
        what: &'static str,
        /// Argument name.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What it must satisfy.
        requirement: &'static str,
    },
    /// An index group for [`share_of_squared_error`] is out of range or overlaps another.
    #[error("share_of_squared_error: group \"{label}\" ({start}..{end}) {problem} (signal length {len}); pass disjoint, non-empty ranges inside the signal")]
    BadGroup {
        /// Group label.
        label: String,
        /// Start index.
        start: usize,
        /// End index (exclusive).
        end: usize,
        /// Length of the error signal.
        len: usize,
        /// What is wrong.
        problem: &'static str,
    },
}

type Result<T> = std::result::Result<T, MetricsError>;

fn check_finite(what: &'static str, signal: &'static str, x: &[f64]) -> Result<()> {
    match x.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(MetricsError::NonFinite {
            what,
            signal,
            index,
            value: x[index],
        }),
        None => Ok(()),
    }
}

fn check_len(what: &'static str, x: &[f64], min: usize) -> Result<()> {
    if x.len() < min {
        Err(MetricsError::TooShort {
            what,
            len: x.len(),
            min,
        })
    } else {
        Ok(())
    }
}

fn check_pair(what: &'static str, a: &[f64], b: &[f64], min: usize) -> Result<()> {
    if a.len() != b.len() {
        return Err(MetricsError::LengthMismatch {
            what,
            a: a.len(),
            b: b.len(),
        });
    }
    check_len(what, a, min)?;
    check_finite(what, "first input", a)?;
    check_finite(what, "second input", b)
}

fn check_dt(what: &'static str, dt_s: f64) -> Result<()> {
    if dt_s.is_finite() && dt_s > 0.0 {
        Ok(())
    } else {
        Err(MetricsError::InvalidArgument {
            what,
            name: "dt_s",
            value: dt_s,
            requirement: "must be a finite sampling interval > 0",
        })
    }
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// Root mean square `sqrt(sum x_i^2 / N)`; this is eq. 7 of the paper when `x` is
/// `f_model - f_measure`.
pub fn rms(x: &[f64]) -> Result<f64> {
    check_len("rms", x, 1)?;
    check_finite("rms", "signal", x)?;
    Ok((x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt())
}

/// Normalised RMS error:
///
/// `NRMSE = RMS(model - measured) / RMS(measured - mean(measured))`
///
/// i.e. the RMS error over the standard deviation (population) of the measurement.
/// 0 is a perfect fit; 1 is as good as predicting the mean. Errors on empty,
/// mismatched or non-finite input and on a constant measurement.
pub fn nrmse(measured: &[f64], model: &[f64]) -> Result<f64> {
    const WHAT: &str = "nrmse";
    check_pair(WHAT, measured, model, 1)?;
    let m = mean(measured);
    let var = measured.iter().map(|v| (v - m).powi(2)).sum::<f64>();
    if var == 0.0 {
        return Err(MetricsError::Zero {
            what: WHAT,
            quantity: "the variance of the measurement",
            hint: "NRMSE needs a measurement that varies; use rms() for a constant one",
        });
    }
    let sse = measured
        .iter()
        .zip(model)
        .map(|(a, b)| (b - a).powi(2))
        .sum::<f64>();
    Ok((sse / var).sqrt())
}

/// Single-bin discrete Fourier transform at the exact frequency `frequency_hz` (not the
/// nearest FFT bin):
///
/// `X = i * (2/N) * sum_n x_n exp(-i 2 pi f n dt)`
///
/// normalised so that for `x(t) = a sin(2 pi f t + p)` sampled over a whole number of
/// cycles (t = 0 at the first sample of the slice), `X = a exp(i p)`: `|X|` is the
/// amplitude and `arg X` the phase of the sine. A constant offset contributes nothing
/// over whole cycles. The caller is responsible for passing a whole number of cycles;
/// otherwise the result has leakage of order (fraction of a cycle) / (cycles).
pub fn single_bin_dft(signal: &[f64], dt_s: f64, frequency_hz: f64) -> Result<Complex64> {
    const WHAT: &str = "single_bin_dft";
    check_len(WHAT, signal, 1)?;
    check_dt(WHAT, dt_s)?;
    check_finite(WHAT, "signal", signal)?;
    if !(frequency_hz.is_finite() && frequency_hz >= 0.0) {
        return Err(MetricsError::InvalidArgument {
            what: WHAT,
            name: "frequency_hz",
            value: frequency_hz,
            requirement: "must be finite and >= 0",
        });
    }
    // One piece of code for the single-bin DFT: the drive crate's (cosine phase);
    // multiplying by i turns it into the sine phase documented above.
    let time_s: Vec<f64> = (0..signal.len()).map(|n| n as f64 * dt_s).collect();
    Ok(Complex64::i() * longreach_drive::freq::single_bin(signal, &time_s, frequency_hz))
}

/// Frequency response of `output` over `input` at `frequency_hz` from single-bin DFTs
/// ([`single_bin_dft`]) of both: `H = Y / X`, returned as
/// `(gain_db, phase_deg) = (20 log10 |H|, arg H)` with the phase wrapped into
/// (-180, 180] deg. Over a sweep, pass the phases through
/// [`longreach_drive::freq::unwrap_deg`] to follow a lag past -180 deg. The slices
/// should span a whole number of cycles.
pub fn frequency_response(
    input: &[f64],
    output: &[f64],
    dt_s: f64,
    frequency_hz: f64,
) -> Result<(f64, f64)> {
    const WHAT: &str = "frequency_response";
    check_pair(WHAT, input, output, 1)?;
    let x = single_bin_dft(input, dt_s, frequency_hz)?;
    let y = single_bin_dft(output, dt_s, frequency_hz)?;
    if x.norm() == 0.0 {
        return Err(MetricsError::Zero {
            what: WHAT,
            quantity: "the input amplitude at this frequency",
            hint:
                "the input does not move at this frequency; check the input channel and frequency",
        });
    }
    if y.norm() == 0.0 {
        return Err(MetricsError::Zero {
            what: WHAT,
            quantity: "the output amplitude at this frequency",
            hint: "the gain is minus infinity dB; check the output channel",
        });
    }
    let h = y / x;
    Ok((
        20.0 * h.norm().log10(),
        wrap_phase_deg(h.arg().to_degrees()),
    ))
}

/// Wraps a phase into (-180, 180] deg.
pub fn wrap_phase_deg(phase_deg: f64) -> f64 {
    let mut p = phase_deg % 360.0;
    if p <= -180.0 {
        p += 360.0;
    } else if p > 180.0 {
        p -= 360.0;
    }
    p
}

/// Share of the total squared error falling into one group of samples.
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorShare {
    /// The group's label.
    pub label: String,
    /// `sum err_i^2` over the group.
    pub sum_sq: f64,
    /// `sum_sq` over the sum of all groups' `sum_sq` (the shares sum to 1).
    pub share: f64,
}

/// Error localisation: splits the squared error into groups of samples
/// `(label, start, end)` (end exclusive, disjoint, inside `err`) and returns each
/// group's share `sum_{group} e^2 / sum_{all groups} e^2`. The shares sum to 1.
/// Samples outside every group are ignored.
pub fn share_of_squared_error<S: AsRef<str>>(
    err: &[f64],
    groups: &[(S, usize, usize)],
) -> Result<Vec<ErrorShare>> {
    const WHAT: &str = "share_of_squared_error";
    check_len(WHAT, err, 1)?;
    check_finite(WHAT, "err", err)?;
    let bad = |g: &(S, usize, usize), problem| MetricsError::BadGroup {
        label: g.0.as_ref().to_string(),
        start: g.1,
        end: g.2,
        len: err.len(),
        problem,
    };
    let mut sorted: Vec<&(S, usize, usize)> = groups.iter().collect();
    sorted.sort_by_key(|g| (g.1, g.2));
    for (k, g) in sorted.iter().enumerate() {
        if g.1 >= g.2 {
            return Err(bad(g, "is empty"));
        }
        if g.2 > err.len() {
            return Err(bad(g, "runs past the end"));
        }
        if k > 0 && sorted[k - 1].2 > g.1 {
            return Err(bad(g, "overlaps another group"));
        }
    }
    let sums: Vec<f64> = groups
        .iter()
        .map(|g| err[g.1..g.2].iter().map(|e| e * e).sum())
        .collect();
    let total: f64 = sums.iter().sum();
    if groups.is_empty() || total == 0.0 {
        return Err(MetricsError::Zero {
            what: WHAT,
            quantity: "the total squared error over the groups",
            hint: "there is no error to localise",
        });
    }
    Ok(groups
        .iter()
        .zip(sums)
        .map(|(g, s)| ErrorShare {
            label: g.0.as_ref().to_string(),
            sum_sq: s,
            share: s / total,
        })
        .collect())
}

/// A window of an error signal (see [`worst_windows`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorWindow {
    /// First sample.
    pub start_index: usize,
    /// One past the last sample.
    pub end_index: usize,
    /// Time of the first sample (s) (`start_index * dt_s`).
    pub start_s: f64,
    /// Time one sample past the window (s) (`end_index * dt_s`).
    pub end_s: f64,
    /// RMS of the error within the window.
    pub rms: f64,
    /// Share of the whole signal's squared error inside this window.
    pub share: f64,
}

/// The `top_n` windows with the largest RMS error. The signal is cut into consecutive,
/// non-overlapping windows of `round(window_s / dt_s)` samples (at least 1; the last
/// one may be shorter); they are returned by decreasing RMS (ties: earlier first).
pub fn worst_windows(
    err: &[f64],
    dt_s: f64,
    window_s: f64,
    top_n: usize,
) -> Result<Vec<ErrorWindow>> {
    const WHAT: &str = "worst_windows";
    check_len(WHAT, err, 1)?;
    check_dt(WHAT, dt_s)?;
    check_finite(WHAT, "err", err)?;
    if !(window_s.is_finite() && window_s > 0.0) {
        return Err(MetricsError::InvalidArgument {
            what: WHAT,
            name: "window_s",
            value: window_s,
            requirement: "must be a finite duration > 0",
        });
    }
    let w = ((window_s / dt_s).round() as usize).max(1);
    let total: f64 = err.iter().map(|e| e * e).sum();
    let mut windows: Vec<ErrorWindow> = err
        .chunks(w)
        .enumerate()
        .map(|(k, c)| {
            let sum_sq: f64 = c.iter().map(|e| e * e).sum();
            let start = k * w;
            ErrorWindow {
                start_index: start,
                end_index: start + c.len(),
                start_s: start as f64 * dt_s,
                end_s: (start + c.len()) as f64 * dt_s,
                rms: (sum_sq / c.len() as f64).sqrt(),
                share: if total > 0.0 { sum_sq / total } else { 0.0 },
            }
        })
        .collect();
    windows.sort_by(|a, b| {
        b.rms
            .total_cmp(&a.rms)
            .then(a.start_index.cmp(&b.start_index))
    });
    windows.truncate(top_n);
    Ok(windows)
}

fn centered(x: &[f64]) -> Vec<f64> {
    let m = mean(x);
    x.iter().map(|v| v - m).collect()
}

/// Normalised autocorrelation at lags 1..=max_lag:
///
/// `r_k = sum_{t=0}^{N-1-k} (x_t - m)(x_{t+k} - m) / sum_{t=0}^{N-1} (x_t - m)^2`
///
/// (the standard biased estimator; element `k-1` holds lag `k`). For white noise the
/// `r_k` are about N(0, 1/N).
pub fn autocorrelation(x: &[f64], max_lag: usize) -> Result<Vec<f64>> {
    const WHAT: &str = "autocorrelation";
    check_len(WHAT, x, max_lag + 2)?;
    check_finite(WHAT, "signal", x)?;
    let c = centered(x);
    let c0: f64 = c.iter().map(|v| v * v).sum();
    if c0 == 0.0 {
        return Err(MetricsError::Zero {
            what: WHAT,
            quantity: "the variance of the signal",
            hint: "a constant signal has no autocorrelation",
        });
    }
    Ok((1..=max_lag)
        .map(|k| {
            c[..c.len() - k]
                .iter()
                .zip(&c[k..])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / c0
        })
        .collect())
}

/// Result of the Ljung-Box whiteness test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LjungBox {
    /// `Q = N (N + 2) sum_{k=1}^{m} r_k^2 / (N - k)`.
    pub q: f64,
    /// Lags used, m.
    pub lags: usize,
    /// Degrees of freedom, `m - fitted_params`.
    pub dof: usize,
    /// `P(chi^2_dof > Q)`: small values (e.g. < 0.05) reject whiteness.
    pub p_value: f64,
}

impl LjungBox {
    /// True if whiteness is not rejected at significance `alpha` (`p_value >= alpha`).
    pub fn is_white(&self, alpha: f64) -> bool {
        self.p_value >= alpha
    }
}

/// Ljung-Box test of the residual for whiteness over lags 1..=max_lag, with
/// `fitted_params` subtracted from the degrees of freedom (use 0 for a residual not
/// produced by fitting ARMA terms). The p-value is the chi-square survival function
/// (statrs).
pub fn ljung_box(residual: &[f64], max_lag: usize, fitted_params: usize) -> Result<LjungBox> {
    const WHAT: &str = "ljung_box";
    if max_lag <= fitted_params {
        return Err(MetricsError::InvalidArgument {
            what: WHAT,
            name: "max_lag",
            value: max_lag as f64,
            requirement: "must exceed fitted_params (degrees of freedom must be >= 1)",
        });
    }
    let r = autocorrelation(residual, max_lag)?;
    let n = residual.len() as f64;
    let q = n
        * (n + 2.0)
        * r.iter()
            .enumerate()
            .map(|(i, rk)| rk * rk / (n - (i + 1) as f64))
            .sum::<f64>();
    let dof = max_lag - fitted_params;
    let chi2 = ChiSquared::new(dof as f64).map_err(|_| MetricsError::InvalidArgument {
        what: WHAT,
        name: "dof",
        value: dof as f64,
        requirement: "must be >= 1",
    })?;
    Ok(LjungBox {
        q,
        lags: max_lag,
        dof,
        p_value: chi2.sf(q),
    })
}

/// Normalised cross-correlation of `x` with `y` for lags -max_lag..=max_lag:
///
/// `rho(l) = sum_t (x_t - mx)(y_{t+l} - my) / sqrt(sum (x - mx)^2 * sum (y - my)^2)`
///
/// Element `k` holds lag `l = k - max_lag` (positive lag: `y` after `x`). For
/// independent white signals |rho| stays below [`white_noise_bound_95`] at 95%.
pub fn cross_correlation(x: &[f64], y: &[f64], max_lag: usize) -> Result<Vec<f64>> {
    const WHAT: &str = "cross_correlation";
    check_pair(WHAT, x, y, max_lag + 2)?;
    let cx = centered(x);
    let cy = centered(y);
    let norm =
        (cx.iter().map(|v| v * v).sum::<f64>() * cy.iter().map(|v| v * v).sum::<f64>()).sqrt();
    if norm == 0.0 {
        return Err(MetricsError::Zero {
            what: WHAT,
            quantity: "the variance of an input",
            hint: "a constant signal has no correlation",
        });
    }
    let n = x.len();
    let m = max_lag as isize;
    Ok((-m..=m)
        .map(|l| {
            let (a, b) = if l >= 0 {
                (&cx[..n - l as usize], &cy[l as usize..])
            } else {
                (&cx[(-l) as usize..], &cy[..n - (-l) as usize])
            };
            a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>() / norm
        })
        .collect())
}

/// Approximate 95% bound `1.96 / sqrt(n)` on the normalised auto- or
/// cross-correlation of white noise of `n` samples.
pub fn white_noise_bound_95(n: usize) -> f64 {
    1.96 / (n as f64).sqrt()
}

/// Pearson correlation coefficient `sum (x-mx)(y-my) / sqrt(sum (x-mx)^2 sum (y-my)^2)`.
/// Use it for residual vs `sign(velocity)` (see [`signum_series`]) or per-run error vs
/// mean tension.
pub fn pearson(x: &[f64], y: &[f64]) -> Result<f64> {
    const WHAT: &str = "pearson";
    check_pair(WHAT, x, y, 2)?;
    let cx = centered(x);
    let cy = centered(y);
    let sxx: f64 = cx.iter().map(|v| v * v).sum();
    let syy: f64 = cy.iter().map(|v| v * v).sum();
    if sxx == 0.0 || syy == 0.0 {
        return Err(MetricsError::Zero {
            what: WHAT,
            quantity: "the variance of an input",
            hint: "correlation with a constant is undefined",
        });
    }
    Ok(cx.iter().zip(&cy).map(|(a, b)| a * b).sum::<f64>() / (sxx * syy).sqrt())
}

/// `sign(x)` sample by sample: +1, -1, or 0 for exactly 0 (e.g. of a velocity, to
/// correlate a residual with the direction of motion, a friction signature).
pub fn signum_series(x: &[f64]) -> Vec<f64> {
    x.iter()
        .map(|&v| {
            if v > 0.0 {
                1.0
            } else if v < 0.0 {
                -1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// Harmonic content of a signal relative to a reference at the fundamental `f`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Harmonics {
    /// Amplitude of the reference at `f`.
    pub fundamental: f64,
    /// Amplitude of the signal at `2 f` over `fundamental`.
    pub second_ratio: f64,
    /// Amplitude of the signal at `3 f` over `fundamental`.
    pub third_ratio: f64,
}

/// Harmonic content at 2f and 3f of `signal` relative to the amplitude of `reference`
/// at `f`, all from [`single_bin_dft`]. Pass a residual and the measured output to see
/// how much of the error is distortion, or the same signal twice for its own THD-like
/// ratios. Both slices should span a whole number of cycles of `f`; `3 f` must lie
/// below the Nyquist frequency.
pub fn harmonic_ratios(
    signal: &[f64],
    reference: &[f64],
    dt_s: f64,
    frequency_hz: f64,
) -> Result<Harmonics> {
    const WHAT: &str = "harmonic_ratios";
    check_pair(WHAT, signal, reference, 1)?;
    check_dt(WHAT, dt_s)?;
    if !(frequency_hz > 0.0 && 3.0 * frequency_hz < 0.5 / dt_s) {
        return Err(MetricsError::InvalidArgument {
            what: WHAT,
            name: "frequency_hz",
            value: frequency_hz,
            requirement: "must be > 0 with 3 f below the Nyquist frequency 1/(2 dt_s)",
        });
    }
    let fundamental = single_bin_dft(reference, dt_s, frequency_hz)?.norm();
    if fundamental == 0.0 {
        return Err(MetricsError::Zero {
            what: WHAT,
            quantity: "the reference amplitude at f",
            hint: "pass a reference that oscillates at f",
        });
    }
    Ok(Harmonics {
        fundamental,
        second_ratio: single_bin_dft(signal, dt_s, 2.0 * frequency_hz)?.norm() / fundamental,
        third_ratio: single_bin_dft(signal, dt_s, 3.0 * frequency_hz)?.norm() / fundamental,
    })
}

/// One-sided power spectral density by a Hann-windowed periodogram of the whole signal:
/// the mean is removed, the signal multiplied by the periodic Hann window
/// `w_n = 0.5 (1 - cos(2 pi n / N))`, and
///
/// `PSD_k = c_k |sum_n w_n x_n exp(-2 pi i k n / N)|^2 / (fs sum_n w_n^2)`, `f_k = k fs / N`
///
/// for k = 0..=N/2, with `c_k = 2` except at DC and (even N) Nyquist where `c_k = 1`;
/// `fs = 1/dt_s`. Units: signal units^2 / Hz. `sum_k PSD_k * fs / N` approximates the
/// variance of a broadband signal. Returns `(freq_hz, psd)`.
pub fn power_spectrum(signal: &[f64], dt_s: f64) -> Result<(Vec<f64>, Vec<f64>)> {
    const WHAT: &str = "power_spectrum";
    check_len(WHAT, signal, 2)?;
    check_dt(WHAT, dt_s)?;
    check_finite(WHAT, "signal", signal)?;
    let n = signal.len();
    let fs = 1.0 / dt_s;
    let m = mean(signal);
    let window: Vec<f64> = (0..n)
        .map(|i| 0.5 * (1.0 - (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos()))
        .collect();
    let s2: f64 = window.iter().map(|w| w * w).sum();
    let mut buf: Vec<Complex64> = signal
        .iter()
        .zip(&window)
        .map(|(x, w)| Complex64::new((x - m) * w, 0.0))
        .collect();
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    let half = n / 2;
    let freq: Vec<f64> = (0..=half).map(|k| k as f64 * fs / n as f64).collect();
    let psd: Vec<f64> = (0..=half)
        .map(|k| {
            let c = if k == 0 || (n.is_multiple_of(2) && k == half) {
                1.0
            } else {
                2.0
            };
            c * buf[k].norm_sqr() / (fs * s2)
        })
        .collect();
    Ok((freq, psd))
}

/// Noise standard deviation of a smooth signal from its second differences:
/// `d_i = x_i - (x_{i-1} + x_{i+1})/2` is `N(0, 1.5 sigma^2)` for white Gaussian noise
/// on a signal whose curvature over two samples is small, so
/// `sigma = median |d_i| / (0.6745 sqrt 1.5)` (the median absolute deviation: robust
/// to the few samples where the signal itself bends sharply, such as the step of a
/// relaxation test at t = 0 or a decay faster than the sampling; a mean of squares
/// would count those as noise and raise the floor).
pub fn noise_sigma_second_difference(x: &[f64]) -> f64 {
    if x.len() < 3 {
        return 0.0;
    }
    let mut d: Vec<f64> = x
        .windows(3)
        .map(|w| (w[1] - 0.5 * (w[0] + w[2])).abs())
        .collect();
    let mid = d.len() / 2;
    let (_, median, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    // 0.67449 = Phi^-1(3/4): the median of |N(0, 1)|
    *median / (0.674_489_750_196_081_7 * 1.5f64.sqrt())
}
