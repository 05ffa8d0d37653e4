//! A model compared with a dataset: the error per run and per test frequency, where it
//! concentrates, the residual checks and the resonances.

use longreach_drive::effects::DataKind;
use num_complex::Complex64;
use serde::Serialize;

use super::prepare::Prepared;
use crate::dataset::DatasetKind;
use crate::error::IdentError;
use crate::metrics;
use crate::model::Model;
use crate::sim;

/// The error of one measured channel of one run (over the analysed samples).
#[derive(Debug, Clone, Serialize)]
pub struct RunChannelError {
    /// Column name (`output_angle_rad`, `tension_in_1_n`, ...).
    pub channel: String,
    /// Unit of the channel (`rad`, `N`).
    pub unit: &'static str,
    /// RMS error, in the channel's unit.
    pub rms_error: f64,
    /// Noise standard deviation (the floor), in the channel's unit.
    pub noise_sigma: f64,
    /// NRMSE of the channel.
    pub nrmse: f64,
    /// The floor on the NRMSE scale.
    pub noise_floor_nrmse: f64,
    /// `rms_error / noise_sigma`: 1 at the floor.
    pub ratio: f64,
}

/// NRMSE of one run.
#[derive(Debug, Clone, Serialize)]
pub struct RunError {
    /// Run name.
    pub run: String,
    /// Mean tension [N] (sweeps).
    pub mean_tension_n: Option<f64>,
    /// Input amplitude [rad] (sweeps).
    pub amplitude_rad: Option<f64>,
    /// NRMSE of the compared channels, stacked (each over its noise; the primary
    /// channel's alone when the run measured no other).
    pub nrmse: f64,
    /// Noise floor of this run on the NRMSE scale.
    pub noise_floor_nrmse: f64,
    /// Share of the dataset's squared error.
    pub share: f64,
    /// Every compared channel on its own, the primary first.
    pub channels: Vec<RunChannelError>,
}

/// Measured vs model frequency response at one test frequency of one run.
#[derive(Debug, Clone, Serialize)]
pub struct FrequencyError {
    /// Run name.
    pub run: String,
    /// Test frequency [Hz].
    pub frequency_hz: f64,
    /// Measured gain [dB].
    pub gain_measured_db: f64,
    /// Model gain [dB].
    pub gain_model_db: f64,
    /// Model minus measured [dB].
    pub gain_error_db: f64,
    /// Measured phase [deg].
    pub phase_measured_deg: f64,
    /// Model phase [deg].
    pub phase_model_deg: f64,
    /// Model minus measured, wrapped to (-180, 180] [deg].
    pub phase_error_deg: f64,
    /// Share of the dataset's squared error in this step's analysis window.
    pub share: f64,
}

/// A place where the error concentrates.
#[derive(Debug, Clone, Serialize)]
pub struct Where {
    /// Run name.
    pub run: String,
    /// Test frequency [Hz] (sweeps), null otherwise.
    pub frequency_hz: Option<f64>,
    /// Start of the window [s].
    pub start_s: f64,
    /// End of the window [s].
    pub end_s: f64,
    /// Share of the dataset's squared error.
    pub share: f64,
}

/// Residual checks.
#[derive(Debug, Clone, Serialize)]
pub struct ResidualChecks {
    /// Ljung-Box Q of the residual (decimated to at most 4000 samples, 20 lags).
    pub ljung_box_q: f64,
    /// Its p-value (small: the residual is not white).
    pub ljung_box_p: f64,
    /// Correlation of the residual with the input angle (sweeps) or time (others).
    pub corr_input: f64,
    /// Correlation of the residual with the sign of the measured velocity.
    pub corr_velocity_sign: f64,
    /// Correlation of each run's RMS error with its mean tension (sweeps, >= 3 runs).
    pub corr_mean_tension: Option<f64>,
    /// Largest residual amplitude at 2f over the measured output at f (sweeps).
    pub harmonic_2f: f64,
    /// Same at 3f.
    pub harmonic_3f: f64,
    /// Correlation of the residual with time (drift).
    pub corr_time: f64,
}

/// Resonance of one run, measured and model.
#[derive(Debug, Clone, Serialize)]
pub struct RunResonance {
    /// Run name.
    pub run: String,
    /// Mean tension [N].
    pub mean_tension_n: f64,
    /// Input amplitude [rad].
    pub amplitude_rad: f64,
    /// Measured resonance [Hz] (peak of the gain, interpolated).
    pub measured_hz: Option<f64>,
    /// Model resonance [Hz].
    pub model_hz: Option<f64>,
    /// Measured peak gain [dB].
    pub measured_peak_db: Option<f64>,
    /// Model peak gain [dB].
    pub model_peak_db: Option<f64>,
}

/// Everything `compare` reports.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// Dataset title.
    pub dataset: String,
    /// Dataset kind.
    pub kind: String,
    /// Model parameters.
    pub params: std::collections::BTreeMap<String, f64>,
    /// Effects in the model.
    pub effects: Vec<String>,
    /// Overall NRMSE.
    pub nrmse: f64,
    /// Noise floor on the NRMSE scale.
    pub noise_floor_nrmse: f64,
    /// Per run.
    pub runs: Vec<RunError>,
    /// Per test frequency (sweeps).
    pub frequency: Vec<FrequencyError>,
    /// Where the squared error concentrates (largest share first).
    #[serde(rename = "where")]
    pub where_: Vec<Where>,
    /// Worst 2-second windows (largest share first).
    pub worst_windows: Vec<Where>,
    /// Residual checks.
    pub residual: ResidualChecks,
    /// Resonances (sweeps).
    pub resonance: Vec<RunResonance>,
    /// The simulation step of an arm or a sweep as prepared, s (the longest of any
    /// run; [`Prepared::step_s`]); `None` for the specimens' tests.
    pub simulation_step_s: Option<f64>,
}

/// Compares a (fitted) model with the dataset; `sims` are its simulations.
pub fn compare(
    prep: &Prepared<'_>,
    model: &Model,
    sims: &[Vec<f64>],
) -> Result<Comparison, IdentError> {
    let sums = prep.sums(sims);
    let channel_sums = prep.channel_sums(sims);
    let total_sse: f64 = sums.iter().map(|s| s.0).sum::<f64>().max(f64::MIN_POSITIVE);
    let (nrmse, floor) = prep.overall(sims);
    let runs: Vec<RunError> = prep
        .runs
        .iter()
        .zip(&sums)
        .zip(&channel_sums)
        .map(|((r, s), ch)| RunError {
            run: r.name.clone(),
            mean_tension_n: r.mean_tension_n,
            amplitude_rad: r.amplitude_rad,
            nrmse: (s.0 / s.1).sqrt(),
            noise_floor_nrmse: r.noise_sigma * (s.2 as f64 / s.1).sqrt(),
            share: s.0 / total_sse,
            channels: ch
                .iter()
                .map(|c| {
                    let rms_error = (c.sse / c.n.max(1) as f64).sqrt();
                    RunChannelError {
                        channel: c.name.to_string(),
                        unit: unit_of(c.name),
                        rms_error,
                        noise_sigma: c.noise_sigma,
                        nrmse: c.nrmse(),
                        noise_floor_nrmse: c.floor_nrmse(),
                        ratio: rms_error / c.noise_sigma,
                    }
                })
                .collect(),
        })
        .collect();
    let mut frequency = Vec::new();
    let mut places = Vec::new();
    let mut resonance = Vec::new();
    let mut h2: f64 = 0.0;
    let mut h3: f64 = 0.0;
    let inputs: Vec<&[f64]> = match &prep.ds.kind {
        DatasetKind::SineSweep(sw) => sw.runs.iter().map(sim::drive_input).collect(),
        _ => Vec::new(),
    };
    for (ri, (run, y)) in prep.runs.iter().zip(sims).enumerate() {
        if run.segments.is_empty() {
            // time windows of 10% of the run
            let n = run.measured.len();
            let w = (n / 10).max(1);
            let mut a = 0;
            while a < n {
                let b = (a + w).min(n);
                let sse: f64 = (a..b).map(|i| prep.squared_error(ri, y, i)).sum();
                places.push(Where {
                    run: run.name.clone(),
                    frequency_hz: None,
                    start_s: run.time_s[a],
                    end_s: run.time_s[b - 1],
                    share: sse / total_sse,
                });
                a = b;
            }
            continue;
        }
        let input = inputs[ri];
        let mut meas_pts = Vec::new();
        let mut model_pts = Vec::new();
        for &(f, a, b) in &run.segments {
            let x = dft(&input[a..b], run.dt_s, f);
            let ym = dft(&run.measured[a..b], run.dt_s, f);
            let yy = dft(&y[a..b], run.dt_s, f);
            let (hm, hy) = (ym / x, yy / x);
            let sse: f64 = (a..b).map(|i| prep.squared_error(ri, y, i)).sum();
            let gm = 20.0 * hm.norm().log10();
            let gy = 20.0 * hy.norm().log10();
            let pm = hm.arg().to_degrees();
            let py = hy.arg().to_degrees();
            frequency.push(FrequencyError {
                run: run.name.clone(),
                frequency_hz: f,
                gain_measured_db: gm,
                gain_model_db: gy,
                gain_error_db: gy - gm,
                phase_measured_deg: pm,
                phase_model_deg: py,
                phase_error_deg: metrics::wrap_phase_deg(py - pm),
                share: sse / total_sse,
            });
            places.push(Where {
                run: run.name.clone(),
                frequency_hz: Some(f),
                start_s: run.time_s[a],
                end_s: run.time_s[b - 1],
                share: sse / total_sse,
            });
            meas_pts.push((f, gm));
            model_pts.push((f, gy));
            if 3.0 * f < 0.5 / run.dt_s {
                let res: Vec<f64> = (a..b).map(|i| y[i] - run.measured[i]).collect();
                if let Ok(h) = metrics::harmonic_ratios(&res, &run.measured[a..b], run.dt_s, f) {
                    h2 = h2.max(h.second_ratio);
                    h3 = h3.max(h.third_ratio);
                }
            }
        }
        let (mf, mp) = peak(&meas_pts).unzip();
        let (yf, yp) = peak(&model_pts).unzip();
        resonance.push(RunResonance {
            run: run.name.clone(),
            mean_tension_n: run.mean_tension_n.unwrap_or(f64::NAN),
            amplitude_rad: run.amplitude_rad.unwrap_or(f64::NAN),
            measured_hz: mf,
            model_hz: yf,
            measured_peak_db: mp,
            model_peak_db: yp,
        });
    }
    places.sort_by(|a, b| b.share.total_cmp(&a.share));
    // worst windows of 2 s across runs
    let mut windows = Vec::new();
    for (ri, (run, y)) in prep.runs.iter().zip(sims).enumerate() {
        // the stacked error of each sample (its square: every channel's, weighted)
        let err: Vec<f64> = (0..run.measured.len())
            .map(|i| {
                if run.channels.is_empty() {
                    y[i] - run.measured[i]
                } else {
                    prep.squared_error(ri, y, i).sqrt()
                }
            })
            .collect();
        let all: f64 = err.iter().map(|v| v * v).sum();
        let scale = all / total_sse.max(f64::MIN_POSITIVE);
        let ws = metrics::worst_windows(
            &err,
            run.dt_s,
            2.0_f64
                .min(run.time_s.last().copied().unwrap_or(1.0) / 5.0)
                .max(run.dt_s),
            3,
        )?;
        for w in ws {
            windows.push(Where {
                run: run.name.clone(),
                frequency_hz: None,
                start_s: run.time_s[w.start_index],
                end_s: run.time_s[w.end_index - 1],
                share: w.share * scale,
            });
        }
    }
    windows.sort_by(|a, b| b.share.total_cmp(&a.share));
    windows.truncate(5);
    // residual checks over the analysed samples of the primary channel (the time series
    // of the output angle: whiteness, correlations, harmonics)
    let res = prep.primary_residuals_of(sims);
    let mut inp = Vec::new();
    let mut vel = Vec::new();
    let mut time = Vec::new();
    for (ri, run) in prep.runs.iter().enumerate() {
        for &i in &run.idx {
            let x = if inputs.is_empty() {
                run.time_s[i]
            } else {
                inputs[ri][i]
            };
            inp.push(x);
            let (a, b) = (i.saturating_sub(1), (i + 1).min(run.measured.len() - 1));
            vel.push(run.measured[b] - run.measured[a]);
            time.push(run.time_s[i]);
        }
    }
    let step = (res.len() / 4000).max(1);
    let dec: Vec<f64> = res.iter().step_by(step).copied().collect();
    let lb = metrics::ljung_box(&dec, 20.min(dec.len().saturating_sub(3)).max(1), 0).ok();
    let corr = |x: &[f64]| metrics::pearson(&res, x).unwrap_or(0.0);
    let corr_mean_tension = if prep.runs.len() >= 3 && prep.kind == DataKind::SineSweep {
        let t: Vec<f64> = prep
            .runs
            .iter()
            .map(|r| r.mean_tension_n.unwrap_or(0.0))
            .collect();
        let rmse: Vec<f64> = sums.iter().map(|s| (s.0 / s.2 as f64).sqrt()).collect();
        metrics::pearson(&t, &rmse).ok()
    } else {
        None
    };
    let residual = ResidualChecks {
        ljung_box_q: lb.map_or(f64::NAN, |l| l.q),
        ljung_box_p: lb.map_or(f64::NAN, |l| l.p_value),
        corr_input: corr(&inp),
        corr_velocity_sign: corr(&metrics::signum_series(&vel)),
        corr_mean_tension,
        harmonic_2f: h2,
        harmonic_3f: h3,
        corr_time: corr(&time),
    };
    Ok(Comparison {
        dataset: prep.ds.title.clone(),
        kind: prep.ds.kind.name().to_string(),
        params: model.named_values().into_iter().collect(),
        effects: model
            .effects
            .iter()
            .map(|u| u.effect.name().to_string())
            .collect(),
        nrmse,
        noise_floor_nrmse: floor,
        runs,
        frequency,
        where_: places.into_iter().take(10).collect(),
        worst_windows: windows,
        residual,
        resonance,
        simulation_step_s: prep.step_s(),
    })
}

/// Unit of a channel, from its column name.
pub(super) fn unit_of(name: &str) -> &'static str {
    if name.ends_with("_rad") {
        "rad"
    } else if name.ends_with("_n") {
        "N"
    } else {
        "1"
    }
}

/// Sine-phase single-bin DFT (see [`metrics::single_bin_dft`]) without allocation checks.
pub(super) fn dft(x: &[f64], dt_s: f64, f: f64) -> Complex64 {
    metrics::single_bin_dft(x, dt_s, f).unwrap_or_default()
}

/// Peak of a gain curve `(f, dB)`, its points in any order (see
/// [`longreach_scenario::bode::peak_of_curve`]).
fn peak(pts: &[(f64, f64)]) -> Option<(f64, f64)> {
    longreach_scenario::bode::peak_of_curve(pts)
}
