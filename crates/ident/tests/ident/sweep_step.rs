//! A sweep's simulation step chosen from the data for the model simulated
//! (`choose_sweep_step`, docs/models.md "The sweep's step").

use longreach_ident::analysis::Prepared;
use longreach_ident::model::Model;
use longreach_ident::Dataset;

fn example(name: &str) -> String {
    format!("{}/../../data/examples/{name}", env!("CARGO_MANIFEST_DIR"))
}

/// A sweep's simulation step chosen from the data ([`choose_sweep_step`]) on the
/// independent MuJoCo example with the baseline (the relay rig, the rope at its
/// catalog stiffness): at the loop's 2.5 ms the baseline moves by more than a noise
/// standard deviation when the step is halved; every halving moves it about 4x less
/// (the rig's step is second order); the step kept is the coarsest whose halving stays
/// within the tolerance, and the NRMSE it gives has stopped moving.
#[test]
fn a_sweep_step_is_chosen_from_the_data() {
    use longreach_ident::analysis::{choose_sweep_step, STEP_TOLERANCE_SIGMA};
    let ds = Dataset::load(example("example_mujoco_stiffening")).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let model = Model::baseline(&ds).unwrap();
    let s = choose_sweep_step(&prep, &model).unwrap();
    eprintln!("{s:?}");
    assert!(s.trials[0].change_sigma > 1.0, "{s:?}");
    for w in s.trials.windows(2) {
        let ratio = w[0].change_sigma / w[1].change_sigma;
        assert!((3.0..5.0).contains(&ratio), "{ratio}: {s:?}");
        assert_eq!(w[1].refinement, 2 * w[0].refinement);
        assert!(w[0].change_sigma > STEP_TOLERANCE_SIGMA, "{s:?}");
    }
    let last = s.trials.last().unwrap();
    assert!(
        s.converged && last.change_sigma <= STEP_TOLERANCE_SIGMA,
        "{s:?}"
    );
    assert_eq!(last.refinement, s.refinement);
    assert!(
        (s.step_s - 2.5e-3 / s.refinement as f64).abs() < 1e-12,
        "{s:?}"
    );
    // the NRMSE at the kept step, again from a dataset prepared at it
    let fine = prep.at_refinement(s.refinement).unwrap();
    let sims = fine.simulate(&model).unwrap();
    assert_eq!(fine.overall(&sims).0.to_bits(), last.nrmse.to_bits());
    let moved = (s.trials[s.trials.len() - 2].nrmse / last.nrmse - 1.0).abs();
    assert!(moved < 1e-3, "{moved}: {s:?}");
    // an arm-only question is not asked of a sweep, and the other way round
    assert!(longreach_ident::analysis::choose_arm_step(&prep, &model).is_err());
}

/// A sweep whose model is the truth held at its values (a model file's fixed values):
/// relay friction on the paper's rig (coefficient 0.01, pulley inertia 1e-3 kg*m^2,
/// pulleys of an arm's size), made at 0.125 ms. At the loop's 2.5 ms the relay
/// pulleys' own step error (backward Euler) leaves the truth at 1.50x the floor, and
/// the diagnosis refines the step before it judges any candidate (to 0.3125 ms):
/// nothing is named, the model ends at the floor (1.00x), and the explanation says why
/// the step was refined.
#[test]
fn a_sweep_diagnosis_refines_the_step_its_baseline_needs() {
    use longreach_drive::effects;
    use longreach_ident::analysis::{compare, diagnose, FLOOR_MARGIN};
    use longreach_ident::model::{BaseParam, ParamDef};
    use longreach_ident::synth::{self, SweepOptions};
    let mut opt = SweepOptions::paper("dyneema2", 5);
    opt.runs = vec![(147.0, 4.5f64.to_radians()), (294.0, 3f64.to_radians())];
    opt.frequencies_hz = vec![0.5, 1.5, 2.4, 3.0, 4.5];
    opt.settle_s = 2.0;
    opt.min_hold_s = 2.0;
    opt.substeps = 40;
    let dir = tempfile::tempdir().unwrap();
    let ds0 = Dataset::load(example("example_sweep_control")).unwrap();
    let mut truth = Model::baseline(&ds0)
        .unwrap()
        .with_effect(effects::find("relay_friction").unwrap());
    truth.base = vec![ParamDef::base(BaseParam::K1Scale, 1.0, 0.2, 5.0)];
    truth.effects[0].params[0].value = 0.01;
    truth.effects[0].params[1].value = 1e-3;
    synth::sweep(&truth, &opt)
        .unwrap()
        .write(dir.path().join("ds"), "relay")
        .unwrap();
    let ds = Dataset::load(dir.path().join("ds")).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let mut model = truth.clone();
    model.base[0].fit = false;
    for p in &mut model.effects[0].params {
        p.fit = false;
    }
    let at_coarse = compare(&prep, &model, &prep.simulate(&model).unwrap()).unwrap();
    assert!(
        at_coarse.nrmse > 1.3 * at_coarse.noise_floor_nrmse,
        "{} {}",
        at_coarse.nrmse,
        at_coarse.noise_floor_nrmse
    );
    let (d, base, winner) = diagnose(&prep, &model).unwrap();
    assert!(
        winner.is_none() && d.missing_effects.is_empty(),
        "{}",
        d.explanation
    );
    assert!(
        d.simulation_step_s.unwrap() < 2.5e-3,
        "{:?}",
        d.simulation_step_s
    );
    assert!(d
        .explanation
        .contains("chosen from the data with the baseline"));
    assert!(
        base.nrmse <= FLOOR_MARGIN * base.noise_floor,
        "{} {}",
        base.nrmse,
        base.noise_floor
    );
}
