//! Confusion-matrix study: for every registered effect, datasets made by `synth` with
//! that effect hidden (different ropes, parameter values, seeds, mean tensions, with and
//! without tension channels) are diagnosed; the hidden effect must rank first in at
//! least 90% of them and control datasets must give null in at least 95%.
//!
//! Heavy (sweeps with a non-linear rope take ~1 min each on 2 cores):
//! `cargo test -p longreach-ident --release --test confusion -- --ignored --nocapture`
//! (`CONFUSION_KINDS=relaxation` or `=sine_sweep` to run one kind).
//! One row or one dataset: `CONFUSION_EFFECTS=relay_friction` (comma-separated effect
//! names; `control` selects the control datasets) runs only those rows,
//! `CONFUSION_ROPES=dyneema2` only that rope, `CONFUSION_SETTINGS=1` only that
//! parameter setting (index into `settings`, 0 or 1) of each effect. With a filter the
//! criterion is asserted on the rows that ran.
//! The small version (relaxation, control + extra_retardation) runs by default in
//! `crates/ident/tests/ident/diagnose_loop.rs`.
//!
//! Tension channels: every sweep dataset is written with `synth`'s four tension
//! channels and diagnosed twice, with them (they enter the fits and the scores, each
//! over its noise) and with them left out (the output angle alone, as before they
//! entered); each counts as a dataset of its row. `CONFUSION_TENSIONS=with` or
//! `=without` runs one of the two.

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
        m.base = vec![longreach_ident::model::ParamDef::base(
            longreach_ident::model::BaseParam::K1Scale,
            1.0,
            0.2,
            5.0,
        )];
    }
    m
}

/// Hidden parameter values per effect, two settings each (strong enough to matter).
///
/// `extra_retardation` in relaxation: retardation times c/k of 20 s and 8 s, at least
/// 4.6x from the ropes' own c3/k3 (1.74 s dyneema2, 0.36 s vectran2). Two Kelvin
/// elements with equal times are one Kelvin element (`1/k = 1/k3 + 1/k`), which the
/// baseline's refitted k3, c3 absorb exactly: the former 0.4 s setting was invisible on
/// vectran2. On the rig: corners k/(2 pi c) of 0.4 and 1.6 Hz, inside the 0.1-6 Hz
/// band, where the element's loss peak and its step in stiffness show. The former
/// 20 s setting (corner 0.008 Hz) only adds a little damping at the resonance, which
/// a dashpot c1 = 8 N*s parallel to k1 reproduces to 0.2% of the noise floor's squared
/// error: no sweep can tell the two apart.
fn settings(e: &dyn Effect, kind: DataKind) -> Vec<Vec<f64>> {
    match e.name() {
        "nonlinear_stiffness" => vec![vec![2e-3], vec![5e-3]],
        "internal_damping" => vec![vec![400.0], vec![1500.0]],
        "extra_retardation" if kind == DataKind::Relaxation => {
            vec![vec![1.5e5, 3e6], vec![5e5, 4e6]]
        }
        "extra_retardation" => vec![vec![5e5, 2e5], vec![3e5, 3e4]],
        "nonlinear_creep" => vec![vec![400.0, 2.0], vec![800.0, 3.0]],
        "plastic_ratchet" => vec![vec![1e5], vec![3e5]],
        // Bearing coefficient and pulley inertia: a good bearing and a poor one.
        "relay_friction" => vec![vec![0.003, 2e-5], vec![0.01, 5e-5]],
        _ => e.params().iter().map(|p| vec![p.default]).collect(),
    }
}

fn run_case(
    kind: DataKind,
    rope: &str,
    hidden: Option<(&'static dyn Effect, &[f64])>,
    seed: u64,
    variant: usize,
    tensions: bool,
) -> Verdict {
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
            opt.tension_channels = true;
            if variant.is_multiple_of(2) {
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
    let mut prep = Prepared::new(&ds).unwrap();
    if !tensions {
        for r in &mut prep.runs {
            r.channels.clear();
        }
    }
    let t0 = std::time::Instant::now();
    let (d, base_fit, _) = diagnose(&prep, &base).unwrap();
    println!(
        "{kind:?} {rope} hidden={:?} seed={seed} tensions={} -> missing={:?} ranking={:?} ({:.1} s)",
        hidden.map(|h| (h.0.name(), h.1.to_vec())),
        prep.has_channels(),
        d.missing_effect,
        d.candidates
            .iter()
            .map(|c| (c.effect.as_str(), (c.score * 10.0).round() / 10.0))
            .collect::<Vec<_>>(),
        t0.elapsed().as_secs_f64()
    );
    if std::env::var_os("CONFUSION_VERBOSE").is_some() {
        println!(
            "  baseline nrmse {:.5} (floor {:.5}) {:?}",
            base_fit.nrmse, base_fit.noise_floor, d.baseline.params
        );
        for c in &d.candidates {
            println!(
                "  {} nrmse {:.5} score {:.1} explained {:.3} {:?}",
                c.effect, c.nrmse, c.score, c.explained, c.params
            );
            if let Some(e) = &c.error {
                println!("    error: {e}");
            }
        }
    }
    Verdict {
        missing: d.missing_effect,
        first: d.candidates.first().map(|c| c.effect.clone()),
    }
}

/// What `diagnose` said about one dataset.
struct Verdict {
    /// The effect named missing (decisive), if any.
    missing: Option<String>,
    /// The first-ranked candidate.
    first: Option<String>,
}

/// The tension variants a dataset of `kind` is diagnosed in: sweeps with and without
/// their tension channels (`CONFUSION_TENSIONS=with|without` for one), relaxation as
/// it is.
fn variants(kind: DataKind) -> &'static [bool] {
    if kind != DataKind::SineSweep {
        return &[true];
    }
    match std::env::var("CONFUSION_TENSIONS").as_deref() {
        Ok("with") => &[true],
        Ok("without") => &[false],
        _ => &[true, false],
    }
}

#[test]
#[ignore]
fn confusion_matrix_full() {
    let ropes = ["dyneema2", "vectran2"];
    let mut rows = Vec::new();
    let mut control = (0, 0);
    let t0 = std::time::Instant::now();
    // CONFUSION_KINDS=relaxation or =sine_sweep restricts the study to one kind.
    let only = std::env::var("CONFUSION_KINDS").unwrap_or_default();
    // CONFUSION_EFFECTS, CONFUSION_ROPES, CONFUSION_SETTINGS: see the header.
    let list = |var: &str| -> Vec<String> {
        std::env::var(var)
            .unwrap_or_default()
            .split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect()
    };
    let (only_effects, only_ropes, only_settings) = (
        list("CONFUSION_EFFECTS"),
        list("CONFUSION_ROPES"),
        list("CONFUSION_SETTINGS"),
    );
    let wanted = |l: &[String], x: &str| l.is_empty() || l.iter().any(|s| s == x);
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
            if !wanted(&only_effects, "control") || !wanted(&only_ropes, rope) {
                continue;
            }
            for seed in 0..2u64 {
                let s = 100 + i as u64 * 10 + seed;
                for &t in variants(kind) {
                    control.1 += 1;
                    if run_case(kind, rope, None, s, seed as usize, t)
                        .missing
                        .is_none()
                    {
                        control.0 += 1;
                    }
                }
            }
        }
        for e in REGISTRY
            .iter()
            .copied()
            .filter(|e| e.applies_to(kind) && wanted(&only_effects, e.name()))
        {
            // (decisive, ranked first, datasets)
            let (mut decisive, mut first, mut n) = (0, 0, 0);
            for (i, rope) in ropes.iter().enumerate() {
                if !wanted(&only_ropes, rope) {
                    continue;
                }
                for (j, v) in settings(e, kind).iter().enumerate() {
                    if !wanted(&only_settings, &j.to_string()) {
                        continue;
                    }
                    let s = 1000 + i as u64 * 10 + j as u64;
                    for &t in variants(kind) {
                        n += 1;
                        let v = run_case(kind, rope, Some((e, v)), s, j, t);
                        decisive += usize::from(v.missing.as_deref() == Some(e.name()));
                        first += usize::from(v.first.as_deref() == Some(e.name()));
                    }
                }
            }
            rows.push((kind, e.name(), decisive, first, n));
        }
    }
    println!(
        "| kind | hidden effect | decisive | ranked first | datasets |\n|---|---|---|---|---|"
    );
    for (k, e, d, f, n) in &rows {
        println!("| {k:?} | {e} | {d} | {f} | {n} |");
    }
    println!(
        "| all | control (null) | {} | - | {} |",
        control.0, control.1
    );
    println!("wall time {:.0} s", t0.elapsed().as_secs_f64());
    let _ = effects::names();
    // Issue 3: the hidden effect ranks first in >= 90% of the datasets; controls give
    // null in >= 95%. (`decisive` is reported; where two effects fit equally well the
    // rule refuses to decide, see docs/models.md.)
    for (_, e, _, f, n) in &rows {
        assert!(*f as f64 >= 0.9 * *n as f64, "{e}: ranked first {f}/{n}");
    }
    assert!(control.0 as f64 >= 0.95 * control.1 as f64);
    assert!(
        !rows.is_empty() || control.1 > 0,
        "the filters selected no dataset"
    );
}
