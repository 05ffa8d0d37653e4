//! Sensor models: encoder quantisation statistics and seeded Gaussian noise.

use longreach_ident::{Encoder, GaussianNoise, ENCODER_RESOLUTION_RAD};

#[test]
fn encoder_resolution_is_0_18_deg() {
    assert!((ENCODER_RESOLUTION_RAD.to_degrees() - 0.18).abs() < 1e-12);
    assert!((Encoder::rig().resolution_rad() - std::f64::consts::PI / 1000.0).abs() < 1e-18);
    assert!(Encoder::new(0.0).is_err() && Encoder::new(f64::NAN).is_err());
}

#[test]
fn quantisation_error_is_bounded_and_uniform() {
    let enc = Encoder::rig();
    let q = enc.resolution_rad();
    // a slow ramp over many counts with an irrational step
    let angles: Vec<f64> = (0..100_000)
        .map(|i| -1.0 + i as f64 * 2.0e-5 * std::f64::consts::SQRT_2)
        .collect();
    let read = enc.quantise_all(&angles);
    let mut sum_sq = 0.0;
    for (a, r) in angles.iter().zip(&read) {
        let e = r - a;
        assert!(e.abs() <= 0.5 * q * (1.0 + 1e-9), "{a}: {e}");
        // readings are whole counts
        let counts = r / q;
        assert!((counts - counts.round()).abs() < 1e-9);
        sum_sq += e * e;
    }
    let rms = (sum_sq / angles.len() as f64).sqrt();
    let expected = q / 12f64.sqrt();
    assert!((rms / expected - 1.0).abs() < 0.01, "{rms} vs {expected}");
    // round to nearest: just below / above half a count
    assert!(enc.quantise(0.49 * q).abs() < 1e-18);
    assert!((enc.quantise(0.51 * q) - q).abs() < 1e-18);
    assert!((enc.quantise(-2.6 * q) + 3.0 * q).abs() < 1e-15);
}

#[test]
fn gaussian_noise_statistics_and_determinism() {
    let sigma = 0.8;
    let n = 100_000;
    let mut g = GaussianNoise::new(sigma, 2024).unwrap();
    let x: Vec<f64> = (0..n).map(|_| g.sample()).collect();
    let mean = x.iter().sum::<f64>() / n as f64;
    let std = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    assert!((std / sigma - 1.0).abs() < 0.05, "{std}");
    assert!(mean.abs() < 4.0 * sigma / (n as f64).sqrt(), "{mean}");
    // about 68.3% within one sigma
    let inside = x.iter().filter(|v| v.abs() < sigma).count() as f64 / n as f64;
    assert!((inside - 0.6827).abs() < 0.01, "{inside}");
    // same seed, same stream; another seed, another stream
    let mut again = GaussianNoise::new(sigma, 2024).unwrap();
    let y: Vec<f64> = (0..n).map(|_| again.sample()).collect();
    assert!(x.iter().zip(&y).all(|(a, b)| a.to_bits() == b.to_bits()));
    let mut other = GaussianNoise::new(sigma, 2025).unwrap();
    assert!(x
        .iter()
        .take(10)
        .any(|a| a.to_bits() != other.sample().to_bits()));
    // add_to / noisy use the same stream
    let mut a = GaussianNoise::new(sigma, 5).unwrap();
    let mut b = GaussianNoise::new(sigma, 5).unwrap();
    let mut signal = vec![49.0; 100];
    a.add_to(&mut signal);
    let noisy = b.noisy(&[49.0; 100]);
    assert!(signal
        .iter()
        .zip(&noisy)
        .all(|(p, q)| p.to_bits() == q.to_bits()));
    assert!(GaussianNoise::new(-1.0, 0).is_err() && GaussianNoise::new(f64::INFINITY, 0).is_err());
}
