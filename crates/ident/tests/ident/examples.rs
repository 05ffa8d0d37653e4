//! The example datasets of data/examples load, and the rig software's FRF files agree
//! with our DFT on the runs' time series.

use longreach_drive::freq::unwrap_deg;
use longreach_ident::metrics::{frequency_response, wrap_phase_deg};
use longreach_ident::{
    Dataset, DatasetKind, RelaxationDataset, SweepDataset, Tensioner, WindowAlignment,
};

const TEST_FREQUENCIES_HZ: [f64; 17] = [
    0.1, 0.2, 0.4, 0.7, 1.0, 1.4, 1.8, 2.1, 2.4, 2.7, 3.0, 3.3, 3.6, 4.0, 4.5, 5.0, 6.0,
];

fn example(name: &str) -> String {
    format!("{}/../../data/examples/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn sweep(name: &str) -> SweepDataset {
    match Dataset::load(example(name)).unwrap().kind {
        DatasetKind::SineSweep(s) => s,
        other => panic!("{name}: expected a sine sweep, got {}", other.name()),
    }
}

fn check_sweep(name: &str, tensions_n: &[f64], amplitudes_deg: &[f64]) {
    let s = sweep(name);
    assert_eq!(s.runs.len(), tensions_n.len(), "{name}: run count");
    let rig = &s.rig;
    assert_eq!(rig.rope, "dyneema2");
    assert!((rig.rope_length_m - 15.2).abs() < 1e-12);
    assert!((rig.input_radius_m - 0.025).abs() < 1e-12);
    assert!((rig.output_radius_m - 0.025).abs() < 1e-12);
    assert!((rig.output_inertia_kg_m2 - 0.0284).abs() < 1e-12);
    assert!((rig.output_damping_n_m_s - 0.05).abs() < 1e-12);
    assert_eq!(rig.relay_pulleys, 3);
    assert!((rig.relay_radius_m - 0.025).abs() < 1e-12);
    assert_eq!(rig.tensioner, Tensioner::ConstantForce);
    for (k, run) in s.runs.iter().enumerate() {
        assert_eq!(run.name, format!("run_{:02}", k + 1));
        assert_eq!(run.len(), 22972, "{name} {}: samples", run.name);
        for ch in [
            &run.frequency_hz,
            &run.command_rad,
            &run.input_angle_rad,
            &run.output_angle_rad,
        ] {
            assert_eq!(ch.len(), 22972);
        }
        for ch in [
            &run.tension_in_1_n,
            &run.tension_in_2_n,
            &run.tension_out_1_n,
            &run.tension_out_2_n,
        ] {
            assert_eq!(
                ch.as_ref().map(Vec::len),
                Some(22972),
                "{name} {}: tension channel",
                run.name
            );
        }
        assert!((run.settle_s - 3.0).abs() < 1e-12);
        assert!((run.mean_tension_n - tensions_n[k]).abs() < 1e-9);
        assert!((run.amplitude_rad - amplitudes_deg[k].to_radians()).abs() < 1e-6);
        assert!((run.dt_s() - 0.005).abs() < 1e-12);
        assert!((run.time_s[22971] - 114.855).abs() < 1e-9);
        assert_eq!(run.test_frequencies_hz(), TEST_FREQUENCIES_HZ.to_vec());
        // the constant-force tensioner: tension_in_1 + tension_in_2 = 2 * mean tension
        let t1 = run.tension_in_1_n.as_ref().unwrap();
        let t2 = run.tension_in_2_n.as_ref().unwrap();
        let mean_sum = t1.iter().zip(t2).map(|(a, b)| a + b).sum::<f64>() / t1.len() as f64;
        assert!(
            (mean_sum - 2.0 * run.mean_tension_n).abs() < 0.5,
            "{name} {}: {mean_sum}",
            run.name
        );
        let frf = run.frf.as_ref().expect("every example run has an frf_file");
        assert_eq!(frf.frequency_hz, TEST_FREQUENCIES_HZ.to_vec());
        assert_eq!(frf.gain_db.len(), 17);
        assert_eq!(frf.phase_deg.len(), 17);
    }
}

#[test]
fn sweep_control_loads() {
    check_sweep(
        "example_sweep_control",
        &[49.0, 147.0, 294.0, 392.0, 147.0],
        &[4.5, 4.5, 4.5, 4.5, 1.5],
    );
}

#[test]
fn sweep_stiffening_loads() {
    check_sweep(
        "example_sweep_stiffening",
        &[49.0, 147.0, 294.0, 392.0],
        &[4.5; 4],
    );
}

#[test]
fn sweep_cells_read_into_the_right_fields() {
    // values copied from run_01.csv, line 3 (t = 0.005 s) and the frf_01.csv rows
    let s = sweep("example_sweep_control");
    let run = &s.runs[0];
    assert_eq!(run.file, "run_01.csv");
    assert!((run.time_s[1] - 0.005).abs() < 1e-15);
    assert!((run.frequency_hz[1] - 0.1).abs() < 1e-15);
    assert!((run.command_rad[1] - 0.0002467).abs() < 1e-15);
    assert!((run.tension_in_1_n.as_ref().unwrap()[1] - 49.52).abs() < 1e-12);
    assert!((run.tension_in_2_n.as_ref().unwrap()[1] - 48.97).abs() < 1e-12);
    assert!((run.tension_out_1_n.as_ref().unwrap()[1] - 49.02).abs() < 1e-12);
    assert!((run.tension_out_2_n.as_ref().unwrap()[1] - 48.98).abs() < 1e-12);
    let frf = run.frf.as_ref().unwrap();
    assert_eq!(frf.file, "frf_01.csv");
    assert!((frf.gain_db[8] - 14.3611).abs() < 1e-12);
    assert!((frf.phase_deg[8] + 133.0666).abs() < 1e-12);
}

#[test]
fn relaxation_loads() {
    let d = Dataset::load(example("example_relax_control/dataset.toml")).unwrap();
    assert_eq!(d.title, "example_relax_control");
    let DatasetKind::Relaxation(RelaxationDataset { specimen, runs }) = d.kind else {
        panic!("expected relaxation");
    };
    assert_eq!(specimen.rope, "dyneema2");
    assert!((specimen.length_m - 0.1).abs() < 1e-12);
    assert!((specimen.strain - 0.015).abs() < 1e-12);
    assert_eq!(runs.len(), 1);
    assert_eq!(runs[0].time_s.len(), 5500);
    assert_eq!(runs[0].tension_n.len(), 5500);
    assert!((runs[0].time_s[5499] - 549.9).abs() < 1e-9);
    assert!((runs[0].tension_n[0] - 1092.798).abs() < 1e-9);
}

#[test]
fn segments_of_a_sweep_run() {
    let s = sweep("example_sweep_control");
    let run = &s.runs[0];
    let segs = run.segments().unwrap();
    assert_eq!(segs.len(), 17);
    let dt = run.dt_s();
    let mut expected_start = 0;
    for (seg, f) in segs.iter().zip(TEST_FREQUENCIES_HZ) {
        assert!((seg.frequency_hz - f).abs() < 1e-12);
        assert_eq!(seg.start_index, expected_start, "steps tile the run");
        expected_start = seg.end_index;
        // analysed part: after the 3 s settle, >= 2 whole cycles (to the nearest sample)
        assert_eq!(seg.analysis_start_index, seg.start_index + 600);
        assert!(seg.analysis_end_index <= seg.end_index);
        assert!(seg.cycles >= 2);
        let cycles = (seg.analysis_end_index - seg.analysis_start_index) as f64 * dt * f;
        assert!(
            (cycles - seg.cycles as f64).abs() <= 0.5 * dt * f + 1e-9,
            "{f} Hz: {cycles}"
        );
        // every sample of the step has the step's frequency
        assert!(run.frequency_hz[seg.start_index..seg.end_index]
            .iter()
            .all(|&x| (x - f).abs() < 1e-12));
    }
    assert_eq!(expected_start, run.len());
    // 0.7 Hz: 2 cycles = 571.43 samples -> 571; 6 Hz: 2 s after settle = 12 cycles = 400 samples
    assert_eq!(
        segs[3].analysis_end_index - segs[3].analysis_start_index,
        571
    );
    assert_eq!(segs[3].cycles, 2);
    assert_eq!(segs[16].cycles, 12);
    assert_eq!(
        segs[16].analysis_end_index - segs[16].analysis_start_index,
        400
    );
    // end-of-step alignment: same lengths, ending at the step end
    let end = run.segments_aligned(WindowAlignment::EndOfStep).unwrap();
    for (a, b) in segs.iter().zip(&end) {
        assert_eq!(b.analysis_end_index, b.end_index);
        assert_eq!(
            a.analysis_end_index - a.analysis_start_index,
            b.analysis_end_index - b.analysis_start_index
        );
    }
}

/// Our single-bin DFT on the analysis windows reproduces the rig software's FRF files.
#[test]
fn frf_files_match_our_frequency_response() {
    let mut worst_gain_db = 0.0f64;
    let mut worst_phase_deg = 0.0f64;
    for name in ["example_sweep_control", "example_sweep_stiffening"] {
        for run in sweep(name).runs {
            let frf = run.frf.as_ref().unwrap();
            let dt = run.dt_s();
            let mut phases = Vec::new();
            for (k, seg) in run.segments().unwrap().iter().enumerate() {
                let w = seg.analysis_start_index..seg.analysis_end_index;
                let (g, p) = frequency_response(
                    &run.input_angle_rad[w.clone()],
                    &run.output_angle_rad[w],
                    dt,
                    seg.frequency_hz,
                )
                .unwrap();
                let dg = (g - frf.gain_db[k]).abs();
                let dp = wrap_phase_deg(p - frf.phase_deg[k]).abs();
                assert!(
                    dg < 0.05,
                    "{name} {} {} Hz: gain {g} vs {}",
                    run.name,
                    seg.frequency_hz,
                    frf.gain_db[k]
                );
                assert!(
                    dp < 0.5,
                    "{name} {} {} Hz: phase {p} vs {}",
                    run.name,
                    seg.frequency_hz,
                    frf.phase_deg[k]
                );
                worst_gain_db = worst_gain_db.max(dg);
                worst_phase_deg = worst_phase_deg.max(dp);
                phases.push(p);
            }
            // the lag of this second-order system goes from ~0 towards -180 deg
            let unwrapped = unwrap_deg(&phases);
            assert!(unwrapped[0] < 0.0 && unwrapped[0] > -2.0);
            assert!(unwrapped[16] < -170.0 && unwrapped[16] > -180.0);
            assert!(
                unwrapped.windows(2).all(|w| w[1] < w[0]),
                "{name} {}: {unwrapped:?}",
                run.name
            );
        }
    }
    println!("FRF agreement: max |gain diff| = {worst_gain_db:.5} dB, max |phase diff| = {worst_phase_deg:.5} deg");
}
