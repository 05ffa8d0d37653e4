//! The measurement loop on the example datasets and on synthetic data with a known
//! answer: fit, compare, diagnose, synth, model files.
//!
//! Heavier studies are `#[ignore]`d; run them with
//! `cargo test -p longreach-ident --release --test ident -- --ignored --nocapture diagnose_loop::`.

use std::path::PathBuf;

use longreach_drive::effects::{self, DataKind};
use longreach_ident::analysis::{
    compare, diagnose, diagnose_without, fit_model, fit_model_from, fit_model_from_starts,
    Candidate, Prepared, SignatureKind, Start,
};
use longreach_ident::model::{BaseParam, Model, ModelError, ParamDef};
use longreach_ident::synth::{self, CyclicOptions, RelaxationOptions};
use longreach_ident::{Dataset, IdentError};
use longreach_rope::Catalog;

fn example(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../data/examples")
        .join(name)
}

#[test]
fn registry_has_the_issue_effects_with_valid_params() {
    for name in [
        "nonlinear_stiffness",
        "internal_damping",
        "extra_retardation",
        "nonlinear_creep",
        "plastic_ratchet",
    ] {
        let e = effects::find(name).unwrap_or_else(|| panic!("{name} not registered"));
        assert!(e.doc().len() > 100, "{name} needs a paragraph of physics");
        for p in e.params() {
            assert!(
                p.lower < p.default && p.default < p.upper,
                "{name}.{}",
                p.name
            );
        }
    }
    // apply sets the law's fields, and bounds are enforced
    let p = Catalog::builtin().get("dyneema2").unwrap().clone();
    let mut law =
        longreach_rope::RopeLaw::from_params(&p, longreach_rope::LawKind::FourElement).unwrap();
    effects::find("nonlinear_stiffness")
        .unwrap()
        .on_law(effects::Args::values(&[2e-3]), &mut law)
        .unwrap();
    assert!((law.stiffening_per_n - 2e-3).abs() < 1e-18);
    effects::find("extra_retardation")
        .unwrap()
        .on_law(effects::Args::values(&[2e5, 2e6]), &mut law)
        .unwrap();
    assert_eq!(law.kelvin.len(), 2);
    assert!((law.kelvin[1].c_n_s / law.kelvin[1].k_n - 10.0).abs() < 1e-12);
    let err = effects::find("internal_damping")
        .unwrap()
        .on_law(effects::Args::values(&[-1.0]), &mut law);
    assert!(err
        .unwrap_err()
        .to_string()
        .contains("internal_damping.c1_n_s"));
    assert!(!effects::find("plastic_ratchet")
        .unwrap()
        .applies_to(DataKind::SineSweep));
}

#[test]
fn sweep_control_baseline_is_at_the_noise_floor() {
    let ds = Dataset::load(example("example_sweep_control")).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let base = Model::baseline(&ds).unwrap();
    // compare at the catalog constants (no fit)
    let sims = prep.simulate(&base).unwrap();
    let c = compare(&prep, &base, &sims).unwrap();
    assert!(
        c.nrmse <= 1.1 * c.noise_floor_nrmse,
        "{} vs floor {}",
        c.nrmse,
        c.noise_floor_nrmse
    );
    // the output angle's floor is the encoder's q/sqrt(12) over the output's spread; the
    // stacked floor (the example's four tensions too, ~0.8 N each over their own
    // spread) is a little higher: 0.0223 against 0.0103 for the output angle alone
    assert!(c.noise_floor_nrmse > 0.015 && c.noise_floor_nrmse < 0.03);
    for r in &c.runs {
        let angle = &r.channels[0];
        assert_eq!(angle.channel, "output_angle_rad");
        assert!(angle.noise_floor_nrmse > 0.005 && angle.noise_floor_nrmse < 0.03);
        assert_eq!(r.channels.len(), 5);
    }
    assert_eq!(c.runs.len(), 5);
    let share: f64 = c.runs.iter().map(|r| r.share).sum();
    assert!((share - 1.0).abs() < 1e-9);
    // fitted global stiffness scale: the catalog's k1
    let f = fit_model(&prep, &base).unwrap();
    let (k, se) = f.fit.as_ref().unwrap().get("k1_scale").unwrap();
    assert!((k - 1.0).abs() < 2e-3 && se < 1e-3, "k1_scale {k} +- {se}");
}

#[test]
fn relaxation_control_fit_matches_the_catalog() {
    let ds = Dataset::load(example("example_relax_control")).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let f = fit_model(&prep, &Model::baseline(&ds).unwrap()).unwrap();
    let cat = Catalog::builtin().get("dyneema2").unwrap().clone();
    let r = f.fit.as_ref().unwrap();
    let rel = |name: &str, truth: f64| (r.get(name).unwrap().0 / truth - 1.0).abs();
    assert!(rel("k1", cat.k1_n) < 0.05);
    assert!(rel("c2", cat.c2_n_s.unwrap()) < 0.05);
    assert!(rel("k3", cat.k3_n.unwrap()) < 0.05);
    // c3 comes out 6.1% low (2.6 standard errors): the data's noise limits it; see the
    // report in docs/models.md.
    assert!(rel("c3", cat.c3_n_s.unwrap()) < 0.08);
    assert!(
        f.nrmse <= 1.05 * f.noise_floor,
        "{} vs {}",
        f.nrmse,
        f.noise_floor
    );
    // eq. 7 RMS near the 2 N noise of the example
    let rms = r.rms();
    assert!(rms > 1.8 && rms < 2.2, "rms {rms}");
}

fn short_relaxation(model: &Model, seed: u64) -> Dataset {
    let mut opt = RelaxationOptions::paper("dyneema2", seed);
    opt.duration_s = 200.0;
    let d = synth::relaxation(model, &opt).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ds");
    d.write(&path, "synthetic").unwrap();
    Dataset::load(&path).unwrap()
}

fn relax_base() -> Model {
    let ds = Dataset::load(example("example_relax_control")).unwrap();
    Model::baseline(&ds).unwrap()
}

/// `model` with a second retardation time (`extra_retardation`) of stiffness `k_n` [N]
/// and damping `c_n_s` [N*s] added.
pub(crate) fn with_retardation(model: &Model, k_n: f64, c_n_s: f64) -> Model {
    let mut m = model.with_effect(effects::find("extra_retardation").unwrap());
    let e = m.effects.len() - 1;
    m.effects[e].params[0].value = k_n;
    m.effects[e].params[1].value = c_n_s;
    m
}

/// The loop's errors are typed values (a base parameter the law cannot take, an effect
/// refusing its values, a synthetic test's options) whose messages are the ones the CLI
/// prints. A base parameter sets what its typed role says (read once from the model
/// file), never what its label spells.
#[test]
fn errors_are_typed_and_keep_their_messages() {
    let mut m = relax_base();
    m.law = longreach_rope::RopeLaw::elastic(m.law.k1_n);
    m.base = vec![ParamDef {
        name: "a label, not a key".into(),
        ..ParamDef::base(BaseParam::K3, 1e5, 1e4, 1e6)
    }];
    let e = m.law_for_run(0).unwrap_err();
    assert!(
        matches!(&e, ModelError::NeedsKelvinElement { param } if param == "k3"),
        "{e:?}"
    );
    assert_eq!(e.to_string(), "`k3` needs a four-element or Flory law");
    // the analysis hands the model's error on as it is
    let ds = Dataset::load(example("example_relax_control")).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let e = prep.simulate(&m).unwrap_err();
    assert!(
        matches!(e, IdentError::Model(ModelError::NeedsKelvinElement { .. })),
        "{e:?}"
    );
    assert_eq!(e.to_string(), "`k3` needs a four-element or Flory law");
    // an effect to leave out that the registry does not hold: refused by name, with
    // the registered ones, before any fit
    let e = diagnose_without(&prep, &relax_base(), &["backlash"]).unwrap_err();
    assert!(
        matches!(&e, IdentError::UnknownEffect { name, known } if name == "backlash" && known.contains("plastic_ratchet")),
        "{e:?}"
    );
    assert!(e.to_string().contains("fix: give one of"), "{e}");

    let mut m = relax_base().with_effect(effects::find("internal_damping").unwrap());
    m.effects[0].params[0].value = -1.0;
    let e = m.law_for_run(0).unwrap_err();
    assert!(
        matches!(
            &e,
            ModelError::Effect {
                effect: "internal_damping",
                ..
            }
        ),
        "{e:?}"
    );
    let msg = e.to_string();
    assert!(
        msg.starts_with("effect internal_damping: ") && msg.contains("internal_damping.c1_n_s"),
        "{msg}"
    );

    let opt = CyclicOptions {
        strain_rate_per_s: 0.0,
        ..CyclicOptions::paper("dyneema2", 1)
    };
    let e = synth::cyclic(&relax_base(), &opt).unwrap_err();
    assert!(matches!(e, IdentError::CyclicRates { .. }), "{e:?}");
    assert_eq!(
        e.to_string(),
        "cyclic test: strain rate 0 1/s and dt 0.05 s must be > 0"
    );
}

#[test]
fn small_confusion_matrix_relaxation() {
    // control -> null; a hidden second retardation time -> extra_retardation.
    let base = relax_base();
    let control = short_relaxation(&base, 11);
    let prep = Prepared::new(&control).unwrap();
    let (d, _, _) = diagnose(&prep, &base).unwrap();
    assert_eq!(d.missing_effect, None, "{}", d.explanation);

    let hidden = with_retardation(&base, 1.5e5, 3e6);
    let ds = short_relaxation(&hidden, 12);
    let prep = Prepared::new(&ds).unwrap();
    let (d, base_fit, winner) = diagnose(&prep, &base).unwrap();
    assert_eq!(
        d.missing_effect.as_deref(),
        Some("extra_retardation"),
        "{}",
        d.explanation
    );
    assert_eq!(d.candidates[0].effect, "extra_retardation");
    let after = winner.unwrap().nrmse;
    // error falls: 3x lower or within 1.5x of the noise floor
    assert!(after * 3.0 <= base_fit.nrmse || after <= 1.5 * base_fit.noise_floor);
}

#[test]
fn model_file_round_trip_and_located_errors() {
    let ds = Dataset::load(example("example_relax_control")).unwrap();
    let m = relax_base().with_effect(effects::find("nonlinear_creep").unwrap());
    let text = m.to_toml("test");
    let back = Model::from_toml(&text, "m.toml", &ds).unwrap();
    let sorted = |m: &Model| {
        let mut v = m.named_values();
        v.sort_by(|a, b| a.0.cmp(&b.0));
        v
    };
    assert_eq!(sorted(&back), sorted(&m));
    let bad = "rope = \"dyneema2\"\n\n[[effect]]\nname = \"nonlinear_creep\"\n[effect.params]\nexponent = 9.0\n";
    let e = Model::from_toml(bad, "bad.toml", &ds)
        .unwrap_err()
        .to_string();
    assert!(e.contains("bad.toml:6") && e.contains("exponent"), "{e}");
    let bad = "rope = \"dyneema2\"\n[[effect]]\nname = \"magic\"\n";
    let e = Model::from_toml(bad, "bad.toml", &ds)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bad.toml:3") && e.contains("nonlinear_stiffness"),
        "{e}"
    );
}

/// Issue 3's acceptance on the example sweeps (about 1-2 min each on 2 cores).
#[test]
#[ignore]
fn examples_diagnose() {
    let ds = Dataset::load(example("example_sweep_control")).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let (d, _, _) = diagnose(&prep, &Model::baseline(&ds).unwrap()).unwrap();
    assert_eq!(d.missing_effect, None);
    assert!(d.baseline.nrmse <= 1.5 * d.baseline.noise_floor_nrmse);

    let ds = Dataset::load(example("example_sweep_stiffening")).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let (d, base, w) = diagnose(&prep, &Model::baseline(&ds).unwrap()).unwrap();
    assert_eq!(d.missing_effect.as_deref(), Some("nonlinear_stiffness"));
    assert!(w.unwrap().nrmse * 3.0 <= base.nrmse);
}

/// `diagnose` on the shipped example `name` (made by MuJoCo): `effect` is named and the
/// model with it comes within 1.5x the noise floor. Its candidate, and the baseline's
/// NRMSE over the floor.
fn mujoco_names(name: &str, effect: &str) -> (Candidate, f64) {
    let ds = Dataset::load(example(name)).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let (d, base, winner) = diagnose(&prep, &Model::baseline(&ds).unwrap()).unwrap();
    assert_eq!(
        d.missing_effect.as_deref(),
        Some(effect),
        "{}",
        d.explanation
    );
    let w = winner.unwrap();
    assert!(
        w.nrmse <= 1.5 * w.noise_floor,
        "NRMSE {} against the floor {}: {}",
        w.nrmse,
        w.noise_floor,
        d.explanation
    );
    let named = d
        .candidates
        .into_iter()
        .find(|c| c.effect == effect)
        .unwrap();
    (named, base.nrmse / base.noise_floor)
}

/// Data longreach did not make: sweeps of the rig by MuJoCo 4.0
/// (`tools/mujoco_rig_sweep.py`; its output pulley integrated by MuJoCo, elastic
/// stainless1 ropes on a constant-force tensioner, 49 and 392 N). The control fits to
/// the noise floor and nothing is named. With MuJoCo's own dry friction on the output
/// shaft (`frictionloss` 0.02 N*m, a soft constraint, not longreach's tanh law) the
/// effect named is `joint_friction`, the model with it within 1.5x the floor, and the
/// 95% interval of its Coulomb torque holds MuJoCo's 0.02 N*m (or, its law refined into
/// a table over the sliding rate, the table's median knot lies within 20% of it, and
/// no knot's interval excludes it without being flagged as not determined).
#[test]
fn a_mujoco_sweep_names_its_dry_friction_and_its_control_nothing() {
    let ds = Dataset::load(example("example_mujoco_control")).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let (d, base, winner) = diagnose(&prep, &Model::baseline(&ds).unwrap()).unwrap();
    assert_eq!(d.missing_effect, None, "{}", d.explanation);
    assert!(winner.is_none());
    assert!(
        base.nrmse <= 1.05 * base.noise_floor,
        "the rig model misses MuJoCo's control: {} against the floor {}",
        base.nrmse,
        base.noise_floor
    );

    let (named, base_ratio) = mujoco_names("example_mujoco_friction", "joint_friction");
    assert!(base_ratio > 10.0, "the baseline at {base_ratio}x the floor");
    match named.interval_95.get("coulomb_n_m") {
        Some(&[lo, hi]) => assert!(
            lo <= 0.02 && 0.02 <= hi,
            "Coulomb {} [{lo}, {hi}] N*m against MuJoCo's 0.02",
            named.params["coulomb_n_m"]
        ),
        // Refined into a table of the Coulomb torque over the sliding rate (MuJoCo's
        // frictionloss is a soft constraint, not the catalog's tanh law): its knots
        // over the rates the output reaches hold MuJoCo's 0.02 N*m.
        None => {
            let mut knots: Vec<f64> = named
                .params
                .iter()
                .filter(|(k, _)| k.starts_with("coulomb_n_m@"))
                .map(|(_, &v)| v)
                .collect();
            assert!(knots.len() >= 2, "{:?}", named.params);
            knots.sort_by(f64::total_cmp);
            let median = knots[knots.len() / 2];
            assert!(
                (0.016..=0.024).contains(&median),
                "the table's median knot {median} N*m against MuJoCo's 0.02: {knots:?}"
            );
            // No knot's interval claims what it does not know: each either holds
            // MuJoCo's 0.02 N*m or is flagged as not determined (the viscous
            // coefficient fitted beside the table is one direction of the data with
            // it). Before the shift was taken in the logarithm, every knot after rate 0
            // read [bound, value], "clipped at the lower bound", none holding 0.02.
            let moving: Vec<(&String, &[f64; 2])> = named
                .interval_95
                .iter()
                .filter(|(k, _)| k.starts_with("coulomb_n_m@") && !k.ends_with("=0"))
                .collect();
            assert_eq!(moving.len(), knots.len() - 1, "{:?}", named.interval_95);
            for (k, &[lo, hi]) in &moving {
                let undetermined =
                    named.interval_clipped.get(*k).map(String::as_str) == Some("both");
                assert!(
                    undetermined || (lo <= 0.02 && 0.02 <= hi),
                    "{k}: [{lo}, {hi}] N*m excludes MuJoCo's 0.02 without being flagged"
                );
            }
        }
    }
}

/// Two more catalog effects in data longreach did not make, each of another law than
/// the catalog's. MuJoCo's rig with ropes of law T = k1 e (1 + e / 0.005): their tangent
/// stiffness grows as the square root of the tension, `k1 sqrt(1 + 4 T / (k1 0.005))`,
/// not linearly as the catalog's `k1 (1 + b T)`; at the two mean tensions the catalog
/// law can still take MuJoCo's values, and `nonlinear_stiffness` is named at the floor
/// with them (the search of starting values weighs the grid's own minima beside their
/// refinements on the analytic response: every refinement led to `k1_scale` 0.71 and
/// the fit from there stopped at 26x the floor). And MuJoCo's rig whose output encoder
/// reports the angle 10 ms late (interpolated between MuJoCo's 0.2 ms steps):
/// `sensor_delay` is named at the floor with 10 ms within 3% (MuJoCo's semi-explicit
/// step leads by about half a step, 0.1 ms).
#[test]
fn a_mujoco_sweep_names_a_stiffening_of_another_law_and_a_late_encoder() {
    let (named, _) = mujoco_names("example_mujoco_stiffening", "nonlinear_stiffness");
    // MuJoCo's tangent stiffness over k1 at a tension, and the fitted law's
    let truth = |t: f64| (1.0 + 4.0 * t / (1.37e5 * 0.005)).sqrt();
    let (k, b) = (named.params["k1_scale"], named.params["stiffening_per_n"]);
    let fitted = |t: f64| k * (1.0 + b * t);
    for t in [49.0, 392.0] {
        assert!(
            (fitted(t) / truth(t) - 1.0).abs() <= 0.03,
            "tangent stiffness at {t} N: {} k1 fitted, {} k1 in MuJoCo",
            fitted(t),
            truth(t)
        );
    }

    let (named, _) = mujoco_names("example_mujoco_delay", "sensor_delay");
    let delay_s = named.params["delay_s"];
    assert!(
        (delay_s / 0.010 - 1.0).abs() <= 0.03,
        "delay {delay_s} s against MuJoCo's 0.010"
    );
}

/// The diagnosis of MuJoCo's example `name`, whose output is two inertias (the pulley
/// and a load behind a torsional shaft, the encoder on the pulley): it misses the data
/// by more than `times` the floor, names nothing, and its residual's signature is a
/// second mode, returned with the candidates.
fn a_second_mode_and_no_name(
    name: &str,
    times: f64,
) -> (longreach_ident::analysis::Signature, Vec<Candidate>) {
    let ds = Dataset::load(example(name)).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let (d, base, winner) = diagnose(&prep, &Model::baseline(&ds).unwrap()).unwrap();
    assert!(base.nrmse > times * base.noise_floor, "{}", base.nrmse);
    assert_eq!(d.missing_effect, None, "{}", d.explanation);
    assert!(d.missing_effects.is_empty() && winner.is_none());
    assert!(d
        .explanation
        .contains("what a second mode at the output leaves"));
    let mode = d
        .signatures
        .iter()
        .find(|s| s.kind == SignatureKind::SecondMode)
        .unwrap_or_else(|| panic!("no second mode: {}", d.explanation))
        .clone();
    (mode, d.candidates)
}

/// An effect outside the catalog in data longreach did not make: MuJoCo's rig whose
/// output is the pulley and a load of 0.02 kg*m^2 behind a 40 N*m/rad shaft (modes at
/// 2.96 and 14 Hz, the second above the sweep). Nothing is named: no effect of the
/// catalog explains even a tenth of the excess. What to add instead: the residual's
/// signature is a second mode, the load's own with the pulley held at
/// sqrt(40 / 0.02) / 2 pi = 7.12 Hz.
#[test]
fn a_mujoco_sweep_with_a_second_mode_names_nothing() {
    let (mode, candidates) = a_second_mode_and_no_name("example_mujoco_shaft", 5.0);
    for c in &candidates {
        assert!(
            c.explained < 0.1 && !c.decisive,
            "{} explains {:.3}",
            c.effect,
            c.explained
        );
    }
    assert!((mode.size / 7.12 - 1.0).abs() < 0.1, "{mode:?}");
}

/// The same with the load's mode inside the sweep: 0.01 of the 0.0284 kg*m^2 behind a
/// shaft of 8 N*m/rad and 0.005 N*m*s (the load's mode with the pulley held at
/// sqrt(8 / 0.01) / 2 pi = 4.50 Hz, damping ratio 0.0088). Nothing is named, and the
/// signature recovers the load: its frequency and its share of the inertia.
#[test]
fn a_mujoco_sweep_with_a_mode_inside_the_band_names_nothing_and_finds_the_load() {
    let (mode, _) = a_second_mode_and_no_name("example_mujoco_mode", 10.0);
    // Measured: 4.649 Hz, J2 / I 0.325, k2 7.87 N*m/rad, 62% of the excess.
    let truth_hz = (8.0f64 / 0.01).sqrt() / std::f64::consts::TAU;
    assert!((mode.size / truth_hz - 1.0).abs() < 0.05, "{mode:?}");
    let share = mode.equivalent.as_ref().unwrap().value;
    assert!((share - 0.01 / 0.0284).abs() < 0.05, "{mode:?}");
    assert!(mode.share_removed > 0.5, "{mode:?}");
}

/// Two effects hidden at once are both found, in either order: the first diagnosis
/// names one (or both, through its pair step) and `diagnose --model` on the model
/// holding it names the other; the model then fits to the floor and a third pass names
/// nothing (one effect never becomes two). (A Flory ratchet and a second retardation
/// time: in a single relaxation test a shape-free creep law can imitate any monotone
/// decay, so a creep law and a retardation time cannot both be told apart there.)
#[test]
fn two_hidden_effects_are_both_found_and_no_third() {
    let base = relax_base();
    let mut truth = base.with_effect(effects::find("plastic_ratchet").unwrap());
    truth.effects[0].params[0].value = 1e5;
    let truth = with_retardation(&truth, 1.5e5, 3e6);
    let ds = short_relaxation(&truth, 21);
    let prep = Prepared::new(&ds).unwrap();
    let mut model = base;
    let mut found: Vec<String> = Vec::new();
    for pass in 0..3 {
        let (d, base_fit, winner) = diagnose(&prep, &model).unwrap();
        println!(
            "pass {pass}: baseline {:.5} (floor {:.5}) named {:?}: {}",
            base_fit.nrmse, base_fit.noise_floor, d.missing_effects, d.explanation
        );
        match winner {
            Some(w) => {
                found.extend(d.missing_effects.iter().cloned());
                assert!(pass < 2, "a third effect named: {:?}", d.missing_effects);
                model = w.model;
            }
            None => {
                assert!(
                    base_fit.nrmse <= 1.5 * base_fit.noise_floor,
                    "nothing named but the model misses the data: {}",
                    d.explanation
                );
                break;
            }
        }
    }
    found.sort();
    assert_eq!(found, ["extra_retardation", "plastic_ratchet"], "{found:?}");
}

/// An effect outside the catalog is never named as the catalog effect that imitates
/// part of it: a relaxation test with a hidden second retardation time and a periodic
/// disturbance of the load cell (a 40 s, 8 N ripple: nothing in the registry makes
/// one). `extra_retardation` explains most of the error and leads every other
/// candidate, but the ripple leaves the data far above the floor: the verdict is
/// "none found", with `extra_retardation` as the lead and the residual's signatures.
#[test]
fn a_catalog_effect_far_from_the_floor_is_a_lead_not_a_name() {
    let base = relax_base();
    let truth = with_retardation(&base, 3e4, 6e5);
    let mut ds = short_relaxation(&truth, 22);
    let longreach_ident::DatasetKind::Relaxation(rx) = &mut ds.kind else {
        panic!("not a relaxation dataset")
    };
    for run in &mut rx.runs {
        for (t, f) in run.time_s.iter().zip(run.tension_n.iter_mut()) {
            *f += 8.0 * (std::f64::consts::TAU * t / 40.0).sin();
        }
    }
    let prep = Prepared::new(&ds).unwrap();
    let (d, base_fit, winner) = diagnose(&prep, &base).unwrap();
    println!(
        "baseline {:.5} (floor {:.5}) named {:?} lead {:?}: {}",
        base_fit.nrmse,
        base_fit.noise_floor,
        d.missing_effects,
        d.lead.as_ref().map(|l| (&l.effects, l.ratio_to_floor)),
        d.explanation
    );
    assert!(winner.is_none(), "named {:?}", d.missing_effects);
    assert_eq!(d.missing_effect, None);
    let lead = d.lead.as_ref().expect("a lead");
    assert_eq!(lead.effects, ["extra_retardation"]);
    assert!(lead.ratio_to_floor > longreach_ident::analysis::NAME_MARGIN);
    assert!(lead.explained > 0.5, "{}", lead.explained);
    assert!(d.explanation.contains("Not named"), "{}", d.explanation);
    assert!(
        !d.signatures.is_empty(),
        "the residual's signatures are reported"
    );
}

/// A fit from several starts ([`fit_model_from_starts`], the exhaustive pair step's) is
/// as good as the best of the fits from each start alone, whatever their order, and
/// reaches the truth when one start leads there: a relaxation with a hidden second
/// retardation time (k = 1.5e5 N, c = 3e6 N*s: 20 s), fitted from a start with the
/// element a thousand times faster (0.02 s, far below the 0.1 s sampling), from which
/// the least squares alone stays 400x farther from the data, and from one near the
/// truth.
#[test]
fn a_fit_from_several_starts_keeps_the_best_basin() {
    let base = relax_base();
    let truth = with_retardation(&base, 1.5e5, 3e6);
    let prep_ds = short_relaxation(&truth, 31);
    let prep = Prepared::new(&prep_ds).unwrap();
    let at = |k: f64, c: f64| with_retardation(&base, k, c);
    let (far, near) = (at(1e7, 2e5), at(2e5, 2e6));
    let alone: Vec<f64> = [&far, &near]
        .iter()
        .map(|m| fit_model_from(&prep, m, Start::Own).unwrap().ssr)
        .collect();
    // (the premise: from the far start alone the least squares stays in another basin;
    // 2.97e6 against 7.57e3 when written)
    assert!(alone[0] > 10.0 * alone[1], "{alone:?}");
    let best_alone = alone[1];
    for starts in [[far.clone(), near.clone()], [near.clone(), far.clone()]] {
        let f = fit_model_from_starts(&prep, &starts[0], &starts).unwrap();
        assert!(
            f.ssr <= best_alone * (1.0 + 1e-6),
            "from both starts {} against {alone:?} alone",
            f.ssr
        );
        let k = f.model.effects[0].params[0].value;
        let c = f.model.effects[0].params[1].value;
        assert!(
            (k / 1.5e5 - 1.0).abs() < 0.1 && (c / 3e6 - 1.0).abs() < 0.1,
            "k {k} c {c}"
        );
        assert!(
            f.nrmse <= 1.05 * f.noise_floor,
            "{} {}",
            f.nrmse,
            f.noise_floor
        );
    }
}
