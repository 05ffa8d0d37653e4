//! The rig's frequency response (issue: rope laws, rig and frequency response):
//! analytic resonances against an independent dense evaluation of eq. 12, simulated
//! against analytic, and the slack case against the example measurement.

use std::path::Path;

use longreach_drive::{rig_resonance, RigSpec};
use longreach_rope::{Catalog, LawKind, RopeLaw};
use longreach_scenario::BodeScenario;

const ROPES: [&str; 5] = ["stainless1", "zylon2", "dyneema2", "vectran2", "kevlar2"];

fn scenario(rope: &str) -> BodeScenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("scenarios/bode_{rope}.toml"));
    BodeScenario::from_file(&path).unwrap()
}

/// |G(i w)| of eq. 12 written out independently in real arithmetic (per-strain
/// constants divided by L; eq. 13 when the rope has only k1).
fn gain_eq12(p: &longreach_rope::RopeParams, f_hz: f64) -> f64 {
    let (l, r1, r2, i, c) = (15.2, 0.025, 0.025, 0.0284, 0.05);
    let w = 2.0 * std::f64::consts::PI * f_hz;
    // J(iw) = 1/k1 + 1/(i w c2) + 1/(k3 + i w c3), times L.
    let (mut jr, mut ji) = (1.0 / p.k1_n, 0.0);
    if let (Some(c2), Some(k3), Some(c3)) = (p.c2_n_s, p.k3_n, p.c3_n_s) {
        ji -= 1.0 / (w * c2);
        let d = k3 * k3 + w * w * c3 * c3;
        jr += k3 / d;
        ji -= w * c3 / d;
    }
    let (jr, ji) = (jr * l, ji * l);
    // (I s^2 + C s) / (2 r2) at s = i w: (-I w^2 + i C w) / (2 r2)
    let (ar, ai) = (-i * w * w / (2.0 * r2), c * w / (2.0 * r2));
    let (dr, di) = (ar * jr - ai * ji + r2, ar * ji + ai * jr);
    r1 / (dr * dr + di * di).sqrt()
}

#[test]
fn analytic_resonances_match_dense_eq12_and_are_ordered() {
    let mut found = Vec::new();
    for rope in ROPES {
        // Independent: the best of 200 000 log-spaced frequencies in 0.5-10 Hz.
        let n = 200_000;
        let (mut best_f, mut best_g) = (0.0, 0.0);
        let params = Catalog::builtin().get(rope).unwrap().clone();
        for k in 0..=n {
            let f = 0.5 * 20f64.powf(k as f64 / n as f64);
            let g = gain_eq12(&params, f);
            if g > best_g {
                (best_f, best_g) = (f, g);
            }
        }
        let p = Catalog::builtin().get(rope).unwrap().clone();
        let law = RopeLaw::from_params(&p, LawKind::default_for(&p)).unwrap();
        let r = rig_resonance(&RigSpec::paper(rope, law, 0.05, 147.0), 0.1, 6.0).unwrap();
        assert!(
            ((r.frequency_hz - best_f) / best_f).abs() < 0.01,
            "{rope}: {} Hz vs dense {best_f} Hz",
            r.frequency_hz
        );
        assert!((r.peak_gain_db - 20.0 * best_g.log10()).abs() < 0.01);
        found.push(r.frequency_hz);
    }
    // stainless1 > zylon2 > dyneema2 > vectran2 > kevlar2, about 3.2, 2.3, 2.3, 1.9, 1.5 Hz.
    for w in found.windows(2) {
        assert!(w[0] > w[1], "{found:?}");
    }
    for (f, expect) in found.iter().zip([3.2, 2.3, 2.3, 1.9, 1.5]) {
        assert!((f - expect).abs() < 0.06, "{found:?}");
    }
}

#[test]
fn simulated_matches_analytic_wherever_no_rope_goes_slack() {
    let mut checked = 0;
    for rope in ROPES {
        for run in scenario(rope).run_all().unwrap() {
            if run.slack {
                continue;
            }
            for p in &run.points {
                let dg = (p.simulated_gain_db - p.analytic_gain_db).abs();
                let dp = (p.simulated_phase_deg - p.analytic_phase_deg).abs();
                assert!(
                    dg < 0.1 && dp < 1.0,
                    "{rope} {} N {} Hz: {dg} dB, {dp} deg",
                    run.mean_tension_n,
                    p.frequency_hz
                );
            }
            checked += 1;
        }
    }
    // Only the low-tension runs of the stiffer ropes may go slack.
    assert!(checked >= 35, "only {checked} runs without slack");
}

/// Dyneema2, C = 0.05, 49 N: one rope goes slack near resonance and the peak gain falls
/// below that of 147 N, as in runs 1 and 2 of example_sweep_control.
#[test]
fn slack_lowers_the_peak_gain_as_measured() {
    let s = scenario("dyneema2");
    let idx = |t: f64| {
        s.rigs
            .iter()
            .position(|r| (r.mean_tension_n - t).abs() < 1e-9)
            .unwrap()
    };
    let low = s.run_one(idx(49.0)).unwrap();
    let mid = s.run_one(idx(147.0)).unwrap();
    assert!(low.slack && !mid.slack);
    let peak = |r: &longreach_scenario::BodeRun| {
        r.points
            .iter()
            .map(|p| p.simulated_gain_db)
            .fold(f64::MIN, f64::max)
    };
    assert!(
        peak(&low) < peak(&mid) - 1.0,
        "{} vs {}",
        peak(&low),
        peak(&mid)
    );
    // The measured FRFs show the same: run 1 (49 N) peaks lower than run 2 (147 N).
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/examples/example_sweep_control");
    let measured_peak = |file: &str| -> f64 {
        let mut r = csv::Reader::from_path(dir.join(file)).unwrap();
        r.records()
            .map(|rec| rec.unwrap()[1].parse::<f64>().unwrap())
            .fold(f64::MIN, f64::max)
    };
    let (m1, m2) = (measured_peak("frf_01.csv"), measured_peak("frf_02.csv"));
    assert!(m1 < m2 - 1.0, "{m1} vs {m2}");
    // And the model's slack peak lands within 1.5 dB of the measured one.
    assert!((peak(&low) - m1).abs() < 1.5, "{} vs {m1}", peak(&low));
}
