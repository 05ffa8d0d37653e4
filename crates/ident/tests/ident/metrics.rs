//! Metrics against closed forms and independent computations.

use std::f64::consts::PI;

use longreach_ident::metrics::*;
use longreach_ident::GaussianNoise;

fn sine(n: usize, dt: f64, f: f64, a: f64, p: f64, offset: f64) -> Vec<f64> {
    (0..n)
        .map(|i| offset + a * (2.0 * PI * f * i as f64 * dt + p).sin())
        .collect()
}

#[test]
fn rms_and_nrmse_by_hand() {
    assert!((rms(&[3.0, -4.0]).unwrap() - (12.5f64).sqrt()).abs() < 1e-15);
    // err = [0,0,0,1]: RMS 0.5; measured std = sqrt(5/4)
    let v = nrmse(&[1.0, 2.0, 3.0, 4.0], &[1.0, 2.0, 3.0, 5.0]).unwrap();
    assert!((v - 0.5 / 1.25f64.sqrt()).abs() < 1e-15);
    // predicting the mean gives exactly 1
    assert!((nrmse(&[1.0, 2.0, 3.0, 4.0], &[2.5; 4]).unwrap() - 1.0).abs() < 1e-15);
    assert!(matches!(
        nrmse(&[], &[]),
        Err(MetricsError::TooShort { .. })
    ));
    assert!(matches!(
        nrmse(&[2.0, 2.0], &[1.0, 2.0]),
        Err(MetricsError::Zero { .. })
    ));
    assert!(matches!(
        nrmse(&[1.0, 2.0], &[1.0]),
        Err(MetricsError::LengthMismatch { .. })
    ));
    let e = nrmse(&[1.0, 2.0], &[1.0, f64::NAN]).unwrap_err();
    assert!(e.to_string().contains("sample 1"), "{e}");
}

#[test]
fn single_bin_dft_gives_amplitude_and_phase() {
    // 1.25 Hz at 1 kHz: 5 cycles = 4000 samples; offset and a 2nd harmonic must not leak
    let dt = 1e-3;
    let x: Vec<f64> = sine(4000, dt, 1.25, 0.7, 0.4, 3.0)
        .iter()
        .zip(sine(4000, dt, 2.5, 0.2, 1.0, 0.0))
        .map(|(a, b)| a + b)
        .collect();
    let c = single_bin_dft(&x, dt, 1.25).unwrap();
    assert!((c.norm() - 0.7).abs() < 1e-12, "{c}");
    assert!((c.arg() - 0.4).abs() < 1e-12, "{c}");
    let c2 = single_bin_dft(&x, dt, 2.5).unwrap();
    assert!((c2.norm() - 0.2).abs() < 1e-12 && (c2.arg() - 1.0).abs() < 1e-12);
    // a frequency between FFT bins, non-integer samples per cycle: 0.7 Hz, 12 cycles at
    // 200 Hz = 3428.57 samples -> 3429; leakage is of order 0.43 / 3429
    let x = sine(3429, 0.005, 0.7, 1.3, -2.0, 0.0);
    let c = single_bin_dft(&x, 0.005, 0.7).unwrap();
    assert!((c.norm() - 1.3).abs() < 1.3 * 2e-4, "{c}");
    assert!((c.arg() + 2.0).abs() < 2e-4, "{c}");
    assert!(single_bin_dft(&x, 0.0, 0.7).is_err());
    assert!(single_bin_dft(&[], 0.1, 0.7).is_err());
}

#[test]
fn frequency_response_of_known_gain_and_lag() {
    let dt = 0.005;
    let f = 2.0; // 4 cycles = 400 samples
    let input = sine(400, dt, f, 0.08, 0.3, 0.01);
    for lag_deg in [-10.0f64, -90.0, -170.0, -190.0] {
        let output = sine(400, dt, f, 0.08 * 3.0, 0.3 + lag_deg.to_radians(), -0.02);
        let (g, p) = frequency_response(&input, &output, dt, f).unwrap();
        assert!((g - 20.0 * 3f64.log10()).abs() < 1e-10);
        assert!((p - wrap_phase_deg(lag_deg)).abs() < 1e-9, "{lag_deg}: {p}");
    }
    assert!(matches!(
        frequency_response(&[0.0; 400], &input, dt, f),
        Err(MetricsError::Zero { .. })
    ));
}

#[test]
fn phase_wrapping_and_unwrapping() {
    assert!((wrap_phase_deg(190.0) + 170.0).abs() < 1e-12);
    assert!((wrap_phase_deg(-180.0) - 180.0).abs() < 1e-12);
    assert!((wrap_phase_deg(-540.5) - 179.5).abs() < 1e-12);
    // unwrapping is the drive crate's (one copy for the workspace)
    let u = longreach_drive::freq::unwrap_deg(&[-10.0, -170.0, 175.0, 160.0, 100.0]);
    let expected = [-10.0, -170.0, -185.0, -200.0, -260.0];
    for (a, b) in u.iter().zip(expected) {
        assert!((a - b).abs() < 1e-12, "{u:?}");
    }
}

#[test]
fn error_shares_sum_to_one() {
    let err = [1.0, -1.0, 2.0, 2.0, 0.0, 5.0];
    let shares =
        share_of_squared_error(&err, &[("low", 0, 2), ("high", 2, 4), ("rest", 4, 6)]).unwrap();
    let total = 2.0 + 8.0 + 25.0;
    let expected = [2.0 / total, 8.0 / total, 25.0 / total];
    for (s, e) in shares.iter().zip(expected) {
        assert!((s.share - e).abs() < 1e-15);
    }
    assert!((shares.iter().map(|s| s.share).sum::<f64>() - 1.0).abs() < 1e-15);
    assert_eq!(shares[1].label, "high");
    let e = share_of_squared_error(&err, &[("a", 0, 3), ("b", 2, 4)]).unwrap_err();
    assert!(e.to_string().contains("overlaps"), "{e}");
    assert!(share_of_squared_error(&err, &[("a", 0, 7)]).is_err());
    assert!(share_of_squared_error(&[0.0; 3], &[("a", 0, 3)]).is_err());
}

#[test]
fn worst_windows_find_the_burst() {
    let dt = 0.01;
    let mut err = vec![0.1; 1000];
    for e in &mut err[300..350] {
        *e = 2.0; // 3.0..3.5 s
    }
    for e in &mut err[700..710] {
        *e = -1.0;
    }
    let w = worst_windows(&err, dt, 0.5, 2).unwrap();
    assert_eq!(w.len(), 2);
    assert_eq!((w[0].start_index, w[0].end_index), (300, 350));
    assert!((w[0].start_s - 3.0).abs() < 1e-12 && (w[0].rms - 2.0).abs() < 1e-12);
    assert_eq!(w[1].start_index, 700);
    let total: f64 = err.iter().map(|e| e * e).sum();
    assert!((w[0].share - 200.0 / total).abs() < 1e-12);
}

#[test]
fn autocorrelation_and_ljung_box() {
    let n = 5000;
    let mut noise = GaussianNoise::new(1.0, 7).unwrap();
    let white: Vec<f64> = (0..n).map(|_| noise.sample()).collect();
    // AR(1) with phi = 0.6: r_k = 0.6^k
    let mut ar = vec![0.0; n];
    for i in 1..n {
        ar[i] = 0.6 * ar[i - 1] + white[i];
    }
    let r = autocorrelation(&ar, 3).unwrap();
    for (k, rk) in r.iter().enumerate() {
        assert!(
            (rk - 0.6f64.powi(k as i32 + 1)).abs() < 0.05,
            "lag {}: {rk}",
            k + 1
        );
    }
    let rw = autocorrelation(&white, 20).unwrap();
    let bound = white_noise_bound_95(n);
    assert!(rw.iter().filter(|r| r.abs() > bound).count() <= 3, "{rw:?}");

    let lb = ljung_box(&white, 20, 0).unwrap();
    assert!(lb.is_white(0.01), "{lb:?}");
    let lb = ljung_box(&ar, 20, 0).unwrap();
    assert!(!lb.is_white(0.01) && lb.p_value < 1e-12, "{lb:?}");
    // with 2 degrees of freedom the chi-square survival function is exp(-Q/2)
    let lb = ljung_box(&white, 2, 0).unwrap();
    let n = n as f64;
    let q = n * (n + 2.0) * (rw[0].powi(2) / (n - 1.0) + rw[1].powi(2) / (n - 2.0));
    assert!((lb.q - q).abs() < 1e-9 * q);
    assert!((lb.p_value - (-q / 2.0).exp()).abs() < 1e-12);
    assert!(ljung_box(&white, 3, 3).is_err());
}

#[test]
fn cross_correlation_finds_the_delay() {
    let mut noise = GaussianNoise::new(1.0, 11).unwrap();
    let x: Vec<f64> = (0..2000).map(|_| noise.sample()).collect();
    let y: Vec<f64> = (0..2000)
        .map(|i| if i >= 3 { 2.0 * x[i - 3] } else { 0.0 })
        .collect();
    let c = cross_correlation(&x, &y, 5).unwrap();
    assert_eq!(c.len(), 11);
    let (best, value) = c
        .iter()
        .enumerate()
        .fold((0, f64::MIN), |a, (i, &v)| if v > a.1 { (i, v) } else { a });
    assert_eq!(best as isize - 5, 3);
    assert!(value > 0.99);
}

#[test]
fn pearson_and_sign() {
    let x = [1.0, 2.0, 3.0, 4.0, 5.0];
    let y: Vec<f64> = x.iter().map(|v| 2.0 * v + 1.0).collect();
    assert!((pearson(&x, &y).unwrap() - 1.0).abs() < 1e-15);
    let z: Vec<f64> = x.iter().map(|v| -v).collect();
    assert!((pearson(&x, &z).unwrap() + 1.0).abs() < 1e-15);
    // [1,2,3] vs [1,3,2]: r = 0.5
    assert!((pearson(&[1.0, 2.0, 3.0], &[1.0, 3.0, 2.0]).unwrap() - 0.5).abs() < 1e-15);
    assert_eq!(signum_series(&[-0.5, 0.0, 3.0]), vec![-1.0, 0.0, 1.0]);
    // a Coulomb-like residual correlates fully with sign(velocity)
    let v: Vec<f64> = (0..1000).map(|i| (i as f64 * 0.01).cos()).collect();
    let res: Vec<f64> = v.iter().map(|v| 0.3 * v.signum()).collect();
    assert!((pearson(&res, &signum_series(&v)).unwrap() - 1.0).abs() < 1e-12);
}

#[test]
fn harmonic_ratios_by_construction() {
    let dt = 0.005;
    let f = 1.0; // 3 cycles = 600 samples
    let reference = sine(600, dt, f, 2.0, 0.1, 0.0);
    let signal: Vec<f64> = sine(600, dt, 2.0 * f, 0.2, 0.5, 0.3)
        .iter()
        .zip(sine(600, dt, 3.0 * f, 0.05, 1.0, 0.0))
        .zip(&reference)
        .map(|((a, b), c)| a + b + c)
        .collect();
    let h = harmonic_ratios(&signal, &reference, dt, f).unwrap();
    assert!((h.fundamental - 2.0).abs() < 1e-12);
    assert!((h.second_ratio - 0.1).abs() < 1e-12);
    assert!((h.third_ratio - 0.025).abs() < 1e-12);
    assert!(harmonic_ratios(&signal, &reference, dt, 40.0).is_err());
}

#[test]
fn power_spectrum_parseval_and_peak() {
    let dt = 0.01;
    let n = 20000;
    let sigma = 2.0;
    let mut noise = GaussianNoise::new(sigma, 3).unwrap();
    let x: Vec<f64> = (0..n).map(|_| 5.0 + noise.sample()).collect();
    let (f, p) = power_spectrum(&x, dt).unwrap();
    assert_eq!(f.len(), n / 2 + 1);
    assert!((f[1] - 1.0 / (n as f64 * dt)).abs() < 1e-12 && (f[n / 2] - 50.0).abs() < 1e-9);
    let df = f[1];
    let power: f64 = p.iter().sum::<f64>() * df;
    assert!(
        (power - sigma * sigma).abs() < 0.05 * sigma * sigma,
        "{power}"
    );
    // white noise: flat one-sided level 2 sigma^2 dt
    let mean_level = p[1..n / 2].iter().sum::<f64>() / (n / 2 - 1) as f64;
    assert!((mean_level - 2.0 * sigma * sigma * dt).abs() < 0.05 * 2.0 * sigma * sigma * dt);
    // a sine of amplitude a on bin 400 (2 Hz): power a^2/2 within +-2 bins of the peak
    let s = sine(n, dt, 400.0 * df, 1.5, 0.2, 0.0);
    let (_, p) = power_spectrum(&s, dt).unwrap();
    let peak = p
        .iter()
        .enumerate()
        .fold((0, 0.0), |a, (i, &v)| if v > a.1 { (i, v) } else { a })
        .0;
    assert_eq!(peak, 400);
    let around: f64 = p[398..=402].iter().sum::<f64>() * df;
    assert!((around - 1.125).abs() < 1e-9, "{around}");
}
