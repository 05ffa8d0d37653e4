//! The arm confusion study (issue 18 item 5): for every effect `diagnose` tries on arm
//! moves, synthetic `arm_moves` datasets of the flexible longreach5
//! (`scenarios/flex_dyneema2_base_step.toml`, so that `link_flexibility` is among the
//! candidates of every diagnosis) with that effect hidden, at 2 magnitudes x 2 move
//! sets (two short moves each), are diagnosed; controls (nothing hidden, 2 seeds x the
//! 2 move sets) too. Criterion: the hidden effect ranked first in >= 90% of each row,
//! "none found" on >= 95% of the controls, and the NRMSE after the winner within 1.5x
//! the noise floor.
//!
//! `#[ignore]`d for its time (each diagnosis 13-160 s in release on 2 cores,
//! about 47 min for the whole study in release on 2 cores, 2026-11-27):
//! `cargo test --workspace --test ident arm_confusion -- --ignored --nocapture`.
//! Filters: `CONFUSION_EFFECTS=link_flexibility,control` (comma-separated effect names;
//! `control` the controls), `CONFUSION_SETTINGS=0` (magnitude, 0 or 1),
//! `CONFUSION_MOVES=1` (move set, 0 or 1); `CONFUSION_VERBOSE=1` prints every
//! candidate. Each dataset's line is printed as it finishes; with a filter the criterion
//! is asserted on the rows that ran.

use std::path::{Path, PathBuf};

use longreach_drive::effects::{DataKind, Effect, REGISTRY};
use longreach_ident::analysis::{diagnose, prepared_at_step};
use longreach_ident::model::Model;
use longreach_ident::synth::{arm_moves, arm_plan, ArmMove, ArmMovesOptions};
use longreach_ident::Dataset;

fn scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/flex_dyneema2_base_step.toml")
}

/// Two move sets of two short moves each (one run per move).
fn move_sets() -> [Vec<ArmMove>; 2] {
    let mv = |joint: &str, move_rad: f64, payload_kg: Option<f64>| ArmMove {
        joint: joint.into(),
        move_rad,
        start_s: 0.2,
        payload_kg,
    };
    [
        vec![mv("j2", 0.05, None), mv("j5", 0.1, None)],
        vec![mv("j1", 0.03, Some(2.0)), mv("j4", 0.08, Some(2.0))],
    ]
}

/// Hidden values per effect, a small and a large magnitude (in the effect's order).
fn settings(e: &dyn Effect) -> [Vec<f64>; 2] {
    match e.name() {
        "link_flexibility" => [vec![0.6, 0.01], vec![1.6, 0.03]],
        "joint_friction" => [vec![1.0, 0.1, 0.01], vec![5.0, 0.5, 0.01]],
        "motor_friction" => [vec![5.0, 1.0, 0.01], vec![20.0, 5.0, 0.01]],
        "nonlinear_stiffness" => [vec![5e-4], vec![2e-3]],
        "internal_damping" => [vec![400.0], vec![1500.0]],
        "extra_retardation" => [vec![5e5, 2e5], vec![3e5, 3e4]],
        "nonlinear_creep" => [vec![400.0, 2.0], vec![800.0, 3.0]],
        "plastic_ratchet" => [vec![1e5], vec![3e5]],
        "payload_mass" => [vec![1.5], vec![4.0]],
        // bearing friction 0.5% and 2% of the hub load, relay pulleys of 0.005 kg*m^2
        "relay_friction" => [vec![0.005, 0.005], vec![0.02, 0.005]],
        _ => {
            let d: Vec<f64> = e.params().iter().map(|p| p.default).collect();
            [d.clone(), d]
        }
    }
}

fn filter(var: &str) -> Option<Vec<String>> {
    std::env::var(var)
        .ok()
        .filter(|s| !s.is_empty())
        .map(|s| s.split(',').map(|x| x.trim().to_string()).collect())
}

fn selected(f: &Option<Vec<String>>, name: &str) -> bool {
    f.as_ref().is_none_or(|v| v.iter().any(|x| x == name))
}

/// One dataset diagnosed: (ranked first, decisive name, NRMSE after / floor).
fn run_case(
    hidden: Option<(&'static dyn Effect, &[f64])>,
    moves: &[ArmMove],
    seed: u64,
    label: &str,
) -> (Option<String>, Option<String>, Option<f64>) {
    let dir = tempfile::tempdir().unwrap();
    let mut opt = ArmMovesOptions::new(scenario(), seed);
    opt.duration_s = 1.5;
    opt.moves = moves.to_vec();
    let plan = arm_plan(&opt).unwrap();
    let mut truth = Model::baseline(&plan).unwrap();
    if let Some((e, values)) = hidden {
        truth = truth.with_effect(e);
        for (p, v) in truth.effects[0].params.iter_mut().zip(values) {
            p.value = *v;
        }
    }
    let path = dir.path().join("ds");
    arm_moves(&truth, &plan, &opt)
        .unwrap()
        .write(&path, label)
        .unwrap();
    let ds = Dataset::load(&path).unwrap();
    let (prep, _) = prepared_at_step(&ds, &Model::baseline(&ds).unwrap()).unwrap();
    let t = std::time::Instant::now();
    let (d, base, _) = diagnose(&prep, &Model::baseline(&ds).unwrap()).unwrap();
    let first = d.candidates.first().map(|c| c.effect.clone());
    let after = d.nrmse_after.map(|a| a / base.noise_floor);
    eprintln!(
        "ARM_CONFUSION {label}: {:.1} s; baseline {:.4} floor {:.4}; first {:?} (score {:.1}, next {:?} {:.1}); verdict {:?}; after {}",
        t.elapsed().as_secs_f64(),
        base.nrmse,
        base.noise_floor,
        first,
        d.candidates.first().map_or(f64::NAN, |c| c.score),
        d.candidates.get(1).map(|c| c.effect.as_str()),
        d.candidates.get(1).map_or(f64::NAN, |c| c.score),
        d.missing_effect,
        after.map_or("-".into(), |a| format!("{a:.2}x floor")),
    );
    if std::env::var_os("CONFUSION_VERBOSE").is_some() {
        for c in &d.candidates {
            eprintln!(
                "    {} nrmse {:.4} score {:.1} {:?} {:?}",
                c.effect, c.nrmse, c.score, c.params, c.error
            );
        }
    }
    (first, d.missing_effect, after)
}

#[test]
#[ignore = "the arm confusion study: minutes to an hour on 2 cores (docs/models.md, Arm datasets); run with --ignored --nocapture"]
fn arm_confusion() {
    let effects_f = filter("CONFUSION_EFFECTS");
    let settings_f = filter("CONFUSION_SETTINGS");
    let moves_f = filter("CONFUSION_MOVES");
    let sets = move_sets();
    let mut failures = Vec::new();
    let (mut controls, mut nulls) = (0, 0);
    if selected(&effects_f, "control") {
        for (s, moves) in sets.iter().enumerate() {
            if !selected(&moves_f, &s.to_string()) {
                continue;
            }
            for seed in [100, 101] {
                let label = format!("control moves {s} seed {seed}");
                let (_, verdict, _) = run_case(None, moves, seed, &label);
                controls += 1;
                if verdict.is_none() {
                    nulls += 1;
                } else {
                    failures.push(format!("{label}: {verdict:?} named"));
                }
            }
        }
    }
    for e in REGISTRY
        .iter()
        .copied()
        .filter(|e| e.applies_to(DataKind::ArmMoves) && selected(&effects_f, e.name()))
    {
        let (mut n, mut firsts) = (0, 0);
        for (k, values) in settings(e).iter().enumerate() {
            if !selected(&settings_f, &k.to_string()) {
                continue;
            }
            for (s, moves) in sets.iter().enumerate() {
                if !selected(&moves_f, &s.to_string()) {
                    continue;
                }
                let label = format!("{} {values:?} moves {s}", e.name());
                let (first, _, after) = run_case(Some((e, values)), moves, 1 + k as u64, &label);
                n += 1;
                if first.as_deref() == Some(e.name()) {
                    firsts += 1;
                }
                if after.is_some_and(|a| a > 1.5) {
                    failures.push(format!("{label}: NRMSE after {after:?} x the floor"));
                }
            }
        }
        eprintln!("ARM_CONFUSION row {}: first {firsts}/{n}", e.name());
        if n > 0 && (firsts as f64) < 0.9 * n as f64 {
            failures.push(format!("{}: first in {firsts} of {n}", e.name()));
        }
    }
    if controls > 0 {
        eprintln!("ARM_CONFUSION controls: none found {nulls}/{controls}");
        if (nulls as f64) < 0.95 * controls as f64 {
            failures.push(format!("controls: none found in {nulls} of {controls}"));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
