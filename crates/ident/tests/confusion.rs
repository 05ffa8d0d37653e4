//! Confusion-matrix study: for every registered effect, datasets made by `synth` with
//! that effect hidden (different ropes, parameter values, seeds, mean tensions, with and
//! without tension channels) are diagnosed; the hidden effect must rank first in at
//! least 90% of them and control datasets must give null in at least 95%.
//!
//! Heavy (sweeps with a non-linear rope take ~1 min each on 2 cores):
//! `cargo test -p longreach-ident --release --test confusion -- --ignored --nocapture`
//! (`CONFUSION_KINDS=relaxation` or `=sine_sweep` to run one kind).
//! The small version (relaxation, control + extra_retardation) runs by default in
//! `tests/loop.rs`.

use longreach_drive::effects::{self, DataKind, Effect, REGISTRY};
use longreach_ident::analysis::{diagnose, Prepared};
use longreach_ident::model::Model;
use longreach_ident::synth::{self, RelaxationOptions, SweepOptions};
use longreach_ident::{Dataset, DatasetKind, RelaxationDataset, RelaxationSpecimen};

fn base_model(rope: &str, kind: DataKind) -> Model {
    let ds = Dataset {
        dir: Default::default(),
        title: String::new(),
        kind: DatasetKind::Relaxation(RelaxationDataset {
            specimen: RelaxationSpecimen {
                rope: rope.into(),
                length_m: 0.1,
                strain: 0.015,
            },
            runs: Vec::new(),
        }),
    };
    let mut m = Model::baseline(&ds).unwrap();
    if kind == DataKind::SineSweep {
        m.base = vec![longreach_ident::model::ParamDef::fitted(
            "k1_scale", "1", 1.0, 0.2, 5.0,
        )];
    }
    m
}

/// Hidden parameter values per effect, two settings each (strong enough to matter).
fn settings(e: &dyn Effect) -> Vec<Vec<f64>> {
    match e.name() {
        "nonlinear_stiffness" => vec![vec![2e-3], vec![5e-3]],
        "internal_damping" => vec![vec![400.0], vec![1500.0]],
        "extra_retardation" => vec![vec![1.5e5, 3e6], vec![5e5, 2e5]],
        "nonlinear_creep" => vec![vec![400.0, 2.0], vec![800.0, 3.0]],
        "plastic_ratchet" => vec![vec![1e5], vec![3e5]],
        _ => e.params().iter().map(|p| vec![p.default]).collect(),
    }
}

fn run_case(
    kind: DataKind,
    rope: &str,
    hidden: Option<(&'static dyn Effect, &[f64])>,
    seed: u64,
    tensions: bool,
) -> Option<String> {
    let base = base_model(rope, kind);
    let mut truth = base.clone();
    if let Some((e, v)) = hidden {
        truth = truth.with_effect(e);
        for (p, x) in truth.effects[0].params.iter_mut().zip(v) {
            p.value = *x;
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ds");
    match kind {
        DataKind::SineSweep => {
            let mut opt = SweepOptions::paper(rope, seed);
            opt.tension_channels = tensions;
            if seed.is_multiple_of(2) {
                opt.runs = [98.0, 196.0, 343.0]
                    .iter()
                    .map(|&t| (t, 3f64.to_radians()))
                    .collect();
            }
            synth::sweep(&truth, &opt)
                .unwrap()
                .write(&path, "case")
                .unwrap();
        }
        _ => {
            let opt = RelaxationOptions::paper(rope, seed);
            synth::relaxation(&truth, &opt)
                .unwrap()
                .write(&path, "case")
                .unwrap();
        }
    }
    let ds = Dataset::load(&path).unwrap();
    let prep = Prepared::new(&ds).unwrap();
    let (d, _, _) = diagnose(&prep, &base).unwrap();
    println!(
        "{kind:?} {rope} hidden={:?} seed={seed} -> missing={:?} ranking={:?}",
        hidden.map(|h| (h.0.name(), h.1.to_vec())),
        d.missing_effect,
        d.candidates
            .iter()
            .map(|c| (c.effect.as_str(), (c.score * 10.0).round() / 10.0))
            .collect::<Vec<_>>()
    );
    d.missing_effect
}

#[test]
#[ignore]
fn confusion_matrix_full() {
    let ropes = ["dyneema2", "vectran2"];
    let mut rows = Vec::new();
    let mut control = (0, 0);
    // CONFUSION_KINDS=relaxation or =sine_sweep restricts the study to one kind.
    let only = std::env::var("CONFUSION_KINDS").unwrap_or_default();
    for kind in [DataKind::Relaxation, DataKind::SineSweep] {
        let name = if kind == DataKind::Relaxation {
            "relaxation"
        } else {
            "sine_sweep"
        };
        if !only.is_empty() && !only.contains(name) {
            continue;
        }
        for (i, rope) in ropes.iter().enumerate() {
            for seed in 0..2u64 {
                let s = 100 + i as u64 * 10 + seed;
                control.1 += 1;
                if run_case(kind, rope, None, s, seed == 0).is_none() {
                    control.0 += 1;
                }
            }
        }
        for e in REGISTRY.iter().copied().filter(|e| e.applies_to(kind)) {
            let (mut hit, mut n) = (0, 0);
            for (i, rope) in ropes.iter().enumerate() {
                for (j, v) in settings(e).iter().enumerate() {
                    let s = 1000 + i as u64 * 10 + j as u64;
                    n += 1;
                    if run_case(kind, rope, Some((e, v)), s, j == 0).as_deref() == Some(e.name()) {
                        hit += 1;
                    }
                }
            }
            rows.push((kind, e.name(), hit, n));
        }
    }
    println!("| kind | hidden effect | named first | datasets |\n|---|---|---|---|");
    for (k, e, h, n) in &rows {
        println!("| {k:?} | {e} | {h} | {n} |");
    }
    println!("| all | control (null) | {} | {} |", control.0, control.1);
    let _ = effects::names();
    for (_, e, h, n) in &rows {
        assert!(*h as f64 >= 0.9 * *n as f64, "{e}: {h}/{n}");
    }
    assert!(control.0 as f64 >= 0.95 * control.1 as f64);
}
