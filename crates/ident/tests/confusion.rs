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
//! `CONFUSION_KEEP=DIR` keeps a copy of each dataset of the extended study in
//! `DIR/<rope>_<seed>` (for `longreach diagnose` on one of them).
//!
//! Tension channels: every sweep dataset is written with `synth`'s four tension
//! channels and diagnosed twice, with them (they enter the fits and the scores, each
//! over its noise) and with them left out (the output angle alone, as before they
//! entered); each counts as a dataset of its row. `CONFUSION_TENSIONS=with` or
//! `=without` runs one of the two.

use longreach_drive::effects::{self, DataKind, Effect, REGISTRY};
use longreach_ident::analysis::{diagnose_with, DiagnoseOptions, Diagnosis, Fitted, Prepared};
use longreach_ident::model::Model;
use longreach_ident::synth::{self, RelaxationOptions, SweepOptions};
use longreach_ident::{Dataset, DatasetKind, RelaxationDataset, RelaxationSpecimen};

/// The diagnosis the studies run: `diagnose_without(without)`, with the exhaustive pair
/// step when `CONFUSION_ALL_PAIRS=1` (`diagnose --all-pairs`).
fn diagnose_as_set(
    prep: &Prepared<'_>,
    base: &Model,
    without: &[&str],
) -> (Diagnosis, Fitted, Option<Fitted>) {
    let all_pairs = std::env::var("CONFUSION_ALL_PAIRS").is_ok_and(|v| v == "1");
    diagnose_with(prep, base, &DiagnoseOptions { without, all_pairs }).unwrap()
}

/// The comma-separated names of the environment variable `var` (a study's filter;
/// empty: no filter).
fn list(var: &str) -> Vec<String> {
    std::env::var(var)
        .unwrap_or_default()
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// The data kinds a study runs, with their names: both, or the one
/// `CONFUSION_KINDS=relaxation|sine_sweep` selects.
fn kinds() -> Vec<(DataKind, &'static str)> {
    let only = std::env::var("CONFUSION_KINDS").unwrap_or_default();
    [
        (DataKind::Relaxation, "relaxation"),
        (DataKind::SineSweep, "sine_sweep"),
    ]
    .into_iter()
    .filter(|(_, name)| only.is_empty() || only.contains(name))
    .collect()
}

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
    without: &[&str],
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
    let (d, base_fit, _) = diagnose_as_set(&prep, &base, without);
    println!(
        "{kind:?} {rope} hidden={:?} seed={seed} tensions={} without={without:?} -> missing={:?} ranking={:?} ({:.1} s)",
        hidden.map(|h| (h.0.name(), h.1.to_vec())),
        prep.has_channels(),
        d.missing_effects,
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
        first: d.candidates.first().map(|c| c.effect.clone()),
        named: d.missing_effects.clone(),
        lead: d
            .lead
            .as_ref()
            .map(|l| (l.effects.join("+"), l.ratio_to_floor)),
        base_ratio: base_fit.nrmse / base_fit.noise_floor,
    }
}

/// What `diagnose` said about one dataset.
struct Verdict {
    /// The first-ranked candidate.
    first: Option<String>,
    /// Every effect named missing (a pair names two).
    named: Vec<String>,
    /// The lead when nothing was named: its effects and its NRMSE over the floor.
    lead: Option<(String, f64)>,
    /// The baseline's NRMSE over the noise floor.
    base_ratio: f64,
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

/// The strains of the extended study's relaxation shapes beyond the paper's 1.5%:
/// none (one relaxation), and a second run at 0.8% (`EXTENDED_STRAINS=one|two` for
/// one of the two).
fn strain_sets(kind: DataKind) -> &'static [&'static [f64]] {
    if kind != DataKind::Relaxation {
        return &[&[]];
    }
    match std::env::var("EXTENDED_STRAINS").as_deref() {
        Ok("one") => &[&[]],
        Ok("two") => &[&[0.008]],
        _ => &[&[], &[0.008]],
    }
}

#[test]
#[ignore]
fn confusion_matrix_full() {
    let ropes = ["dyneema2", "vectran2"];
    let mut rows = Vec::new();
    let mut control = (0, 0);
    let t0 = std::time::Instant::now();
    // CONFUSION_EFFECTS, CONFUSION_ROPES, CONFUSION_SETTINGS: see the header.
    let (only_effects, only_ropes, only_settings) = (
        list("CONFUSION_EFFECTS"),
        list("CONFUSION_ROPES"),
        list("CONFUSION_SETTINGS"),
    );
    let wanted = |l: &[String], x: &str| l.is_empty() || l.iter().any(|s| s == x);
    for (kind, _) in kinds() {
        for (i, rope) in ropes.iter().enumerate() {
            if !wanted(&only_effects, "control") || !wanted(&only_ropes, rope) {
                continue;
            }
            for seed in 0..2u64 {
                let s = 100 + i as u64 * 10 + seed;
                for &t in variants(kind) {
                    control.1 += 1;
                    if run_case(kind, rope, None, s, seed as usize, t, &[])
                        .named
                        .is_empty()
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
                        let v = run_case(kind, rope, Some((e, v)), s, j, t, &[]);
                        decisive +=
                            usize::from(v.named.first().map(String::as_str) == Some(e.name()));
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

/// Held-out study: the catalog without the effect in the data. For every registered
/// effect of the rig's and the specimen's data, a dataset is made with it hidden (its
/// stronger setting, both ropes, sweeps with their tension channels) and diagnosed with
/// that effect left out of the candidates (`diagnose_without`): the data hold an
/// effect outside the catalog the diagnosis has, as data from another simulator or a
/// real rig may. Every name it gives is then a false name; the right answer is none
/// found, with a lead and its signatures. Prints a row per dataset (the baseline's and
/// the lead's NRMSE over the floor) and asserts that at most 5% of the datasets get a
/// name. `CONFUSION_KINDS`, `CONFUSION_EFFECTS`, `CONFUSION_ROPES` filter as for the
/// full study:
/// `cargo test -p longreach-ident --release --test confusion confusion_held_out -- --ignored --nocapture`.
#[test]
#[ignore]
fn confusion_held_out() {
    let ropes = ["dyneema2", "vectran2"];
    let (only_effects, only_ropes) = (list("CONFUSION_EFFECTS"), list("CONFUSION_ROPES"));
    let wanted = |l: &[String], x: &str| l.is_empty() || l.iter().any(|s| s == x);
    let t0 = std::time::Instant::now();
    let mut rows = Vec::new();
    for (kind, name) in kinds() {
        for e in REGISTRY
            .iter()
            .copied()
            .filter(|e| e.applies_to(kind) && wanted(&only_effects, e.name()))
        {
            let set = settings(e, kind);
            let Some(v) = set.last() else { continue };
            for (i, rope) in ropes.iter().enumerate() {
                if !wanted(&only_ropes, rope) {
                    continue;
                }
                let s = 3000 + i as u64 * 10;
                let v = run_case(kind, rope, Some((e, v)), s, 1, true, &[e.name()]);
                rows.push((name, e.name(), *rope, v));
            }
        }
    }
    println!("| kind | held-out effect | rope | baseline / floor | named | lead (not named) |\n|---|---|---|---|---|---|");
    for (k, e, r, v) in &rows {
        println!(
            "| {k} | {e} | {r} | {:.2}x | {} | {} |",
            v.base_ratio,
            if v.named.is_empty() {
                "none found".to_string()
            } else {
                v.named.join(" + ")
            },
            v.lead
                .as_ref()
                .map_or("-".to_string(), |(l, x)| format!("{l} at {x:.2}x")),
        );
    }
    let named = rows.iter().filter(|r| !r.3.named.is_empty()).count();
    println!(
        "false names: {named} of {} datasets; wall time {:.0} s",
        rows.len(),
        t0.elapsed().as_secs_f64()
    );
    assert!(!rows.is_empty(), "the filters selected no dataset");
    assert!(
        named as f64 <= 0.05 * rows.len() as f64,
        "{named} of {} datasets named an effect the catalog was given without the one in the data",
        rows.len()
    );
}

/// What the extended study records of one diagnosis.
struct Outcome {
    /// The first two candidates by score.
    top2: Vec<String>,
    /// The effects of the best pair (the pair step), empty when none was fitted.
    best_pair: Vec<String>,
    /// The effects named missing.
    named: Vec<String>,
    /// NRMSE of the model with the named effects over the noise floor (None: nothing named).
    after_ratio: Option<f64>,
}

/// Diagnoses a dataset made by `synth` from `truth` (the baseline of `rope` plus hidden
/// effects, parametric or shape-free).
fn diagnose_truth(
    kind: DataKind,
    rope: &str,
    truth: &Model,
    seed: u64,
    variant: usize,
    tensions: bool,
    more_strains: &[f64],
    label: &str,
) -> Outcome {
    let base = base_model(rope, kind);
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
            synth::sweep(truth, &opt)
                .unwrap()
                .write(&path, "case")
                .unwrap();
        }
        _ => {
            let mut opt = RelaxationOptions::paper(rope, seed);
            opt.more_strains = more_strains.to_vec();
            synth::relaxation(truth, &opt)
                .unwrap()
                .write(&path, "case")
                .unwrap();
        }
    }
    if let Ok(keep) = std::env::var("CONFUSION_KEEP") {
        let to = std::path::Path::new(&keep).join(format!("{rope}_{seed}"));
        std::fs::create_dir_all(&to).unwrap();
        for f in std::fs::read_dir(&path).unwrap() {
            let f = f.unwrap();
            std::fs::copy(f.path(), to.join(f.file_name())).unwrap();
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
    let (d, base_fit, winner) = diagnose_as_set(&prep, &base, &[]);
    let floor = base_fit.noise_floor;
    let out = Outcome {
        top2: d
            .candidates
            .iter()
            .take(2)
            .map(|c| c.effect.clone())
            .collect(),
        best_pair: d
            .pairs
            .first()
            .map(|p| p.effect.split('+').map(String::from).collect())
            .unwrap_or_default(),
        named: d.missing_effects.clone(),
        after_ratio: winner.as_ref().map(|w| w.nrmse / floor),
    };
    println!(
        "{label}: {kind:?} {rope} seed={seed} tensions={} baseline {:.2}x -> named {:?} after {} top2 {:?} lead {:?} pairs {:?} refined {:?} ({:.1} s)",
        prep.has_channels(),
        base_fit.nrmse / floor,
        out.named,
        out.after_ratio.map_or("-".into(), |r| format!("{r:.2}x")),
        out.top2,
        d.lead.as_ref().map(|l| (l.effects.join("+"), (l.ratio_to_floor * 100.0).round() / 100.0)),
        d.pairs
            .iter()
            .map(|p| (p.effect.as_str(), (p.nrmse / floor * 100.0).round() / 100.0))
            .collect::<Vec<_>>(),
        d.refinements
            .iter()
            .map(|r| (r.effect.as_str(), r.knots.len() - 1, r.kept))
            .collect::<Vec<_>>(),
        t0.elapsed().as_secs_f64()
    );
    if std::env::var_os("CONFUSION_VERBOSE").is_some() {
        println!("  {}", d.explanation);
        for r in &d.refinements {
            println!(
                "  refined {}: {:?}",
                r.effect,
                r.tried
                    .iter()
                    .map(|k| (
                        k.knots,
                        (k.nrmse / floor * 1000.0).round() / 1000.0,
                        k.bic.round()
                    ))
                    .collect::<Vec<_>>()
            );
        }
        for c in d.candidates.iter().chain(&d.pairs) {
            println!(
                "  {} nrmse {:.5} ({:.2}x) score {:.1} explained {:.3}",
                c.effect,
                c.nrmse,
                c.nrmse / floor,
                c.score,
                c.explained
            );
        }
    }
    out
}

/// A hidden law of another shape than the catalog's: the effect (at `values`) with its
/// function replaced by `law` sampled at 12 knots over `[0, top]`.
fn shaped(
    rope: &str,
    kind: DataKind,
    effect: &str,
    values: &[f64],
    top: f64,
    law: &dyn Fn(f64) -> f64,
) -> Model {
    let e = effects::find(effect).unwrap();
    let mut m = base_model(rope, kind).with_effect(e);
    let k = m.effects.len() - 1;
    for (p, v) in m.effects[k].params.iter_mut().zip(values) {
        p.value = *v;
    }
    let shape = e.shape().unwrap();
    let knots: Vec<f64> = (0..12).map(|i| top * i as f64 / 11.0).collect();
    let y: Vec<f64> = knots.iter().map(|&x| law(x)).collect();
    let sh = longreach_ident::model::ShapeUse::new(e, shape, &knots, &y, false).unwrap();
    m.with_shape(k, sh)
}

/// The shapes of the extended study: three monotone laws of each functional effect,
/// none of the catalog's form (`1 + b f` for stiffness, `1 + (f/f_c)^n` for creep, a
/// constant coefficient for the frictions). `(effect, kind, shape name, truth)`.
fn shape_cases(rope: &str) -> Vec<(&'static str, DataKind, &'static str, Model)> {
    let sw = DataKind::SineSweep;
    let rx = DataKind::Relaxation;
    let logistic = |x: f64, mid: f64, w: f64| 1.0 / (1.0 + (-(x - mid) / w).exp());
    vec![
        // stiffness factor against the head spring's tension (sweeps: 0-800 N)
        (
            "nonlinear_stiffness",
            sw,
            "saturating",
            shaped(rope, sw, "nonlinear_stiffness", &[2e-3], 900.0, &|f| {
                1.0 + 0.9 * (1.0 - (-f / 120.0).exp())
            }),
        ),
        (
            "nonlinear_stiffness",
            sw,
            "convex",
            shaped(rope, sw, "nonlinear_stiffness", &[2e-3], 900.0, &|f| {
                1.0 + (f / 450.0).powi(2)
            }),
        ),
        (
            "nonlinear_stiffness",
            sw,
            "sigmoid",
            shaped(rope, sw, "nonlinear_stiffness", &[2e-3], 900.0, &|f| {
                let s0 = logistic(0.0, 250.0, 60.0);
                1.0 + 0.8 * (logistic(f, 250.0, 60.0) - s0) / (1.0 - s0)
            }),
        ),
        // relay bearing coefficient against the hub load (sweeps: ~100-1000 N)
        (
            "relay_friction",
            sw,
            "falling",
            shaped(rope, sw, "relay_friction", &[0.01, 2e-5], 1200.0, &|h| {
                0.004 + 0.012 / (1.0 + h / 200.0)
            }),
        ),
        (
            "relay_friction",
            sw,
            "rising",
            shaped(rope, sw, "relay_friction", &[0.01, 2e-5], 1200.0, &|h| {
                0.002 + 0.010 * (1.0 - (-h / 400.0).exp())
            }),
        ),
        (
            "relay_friction",
            sw,
            "knee",
            shaped(rope, sw, "relay_friction", &[0.01, 2e-5], 1200.0, &|h| {
                0.003 + 0.008 * logistic(h, 500.0, 80.0)
            }),
        ),
        // dry torque of the output shaft's bearing against the speed (sweeps: 0-4 rad/s)
        (
            "joint_friction",
            sw,
            "stribeck",
            shaped(rope, sw, "joint_friction", &[0.02, 1e-4, 0.01], 5.0, &|w| {
                0.012 + 0.02 * (-(w / 0.3).powi(2)).exp()
            }),
        ),
        (
            "joint_friction",
            sw,
            "rising",
            shaped(rope, sw, "joint_friction", &[0.02, 1e-4, 0.01], 5.0, &|w| {
                0.01 + 0.02 * (1.0 - (-w / 1.0).exp())
            }),
        ),
        (
            "joint_friction",
            sw,
            "falling_linear",
            shaped(rope, sw, "joint_friction", &[0.02, 1e-4, 0.01], 5.0, &|w| {
                (0.03 - 0.005 * w).max(0.005)
            }),
        ),
        // creep factor against tension (relaxation: ~0-1200 N)
        (
            "nonlinear_creep",
            rx,
            "exponential",
            shaped(rope, rx, "nonlinear_creep", &[500.0, 2.0], 1500.0, &|f| {
                (f / 400.0).exp()
            }),
        ),
        (
            "nonlinear_creep",
            rx,
            "saturating",
            shaped(rope, rx, "nonlinear_creep", &[500.0, 2.0], 1500.0, &|f| {
                1.0 + 4.0 * (1.0 - (-f / 500.0).exp())
            }),
        ),
        (
            "nonlinear_creep",
            rx,
            "knee",
            shaped(rope, rx, "nonlinear_creep", &[500.0, 2.0], 1500.0, &|f| {
                1.0 + 6.0 * logistic(f, 700.0, 80.0) - 6.0 * logistic(0.0, 700.0, 80.0)
            }),
        ),
        // stiffness factor in relaxation
        (
            "nonlinear_stiffness",
            rx,
            "saturating",
            shaped(rope, rx, "nonlinear_stiffness", &[2e-3], 1500.0, &|f| {
                1.0 + 0.8 * (1.0 - (-f / 300.0).exp())
            }),
        ),
        (
            "nonlinear_stiffness",
            rx,
            "convex",
            shaped(rope, rx, "nonlinear_stiffness", &[2e-3], 1500.0, &|f| {
                1.0 + (f / 900.0).powi(2)
            }),
        ),
        (
            "nonlinear_stiffness",
            rx,
            "sigmoid",
            shaped(rope, rx, "nonlinear_stiffness", &[2e-3], 1500.0, &|f| {
                let s0 = logistic(0.0, 600.0, 100.0);
                1.0 + 0.7 * (logistic(f, 600.0, 100.0) - s0) / (1.0 - s0)
            }),
        ),
    ]
}

/// The pairs of the extended study: two effects hidden at once (catalog laws).
fn pair_cases(rope: &str) -> Vec<(DataKind, [(&'static str, Vec<f64>); 2])> {
    let _ = rope;
    vec![
        (
            DataKind::SineSweep,
            [
                ("nonlinear_stiffness", vec![2e-3]),
                ("internal_damping", vec![400.0]),
            ],
        ),
        (
            DataKind::SineSweep,
            [
                ("relay_friction", vec![0.01, 5e-5]),
                ("nonlinear_stiffness", vec![2e-3]),
            ],
        ),
        (
            DataKind::SineSweep,
            [
                ("joint_friction", vec![0.02, 1e-4, 0.01]),
                ("sensor_delay", vec![0.012]),
            ],
        ),
        (
            DataKind::Relaxation,
            [
                ("nonlinear_creep", vec![400.0, 2.0]),
                ("extra_retardation", vec![1.5e5, 3e6]),
            ],
        ),
        (
            DataKind::Relaxation,
            [
                ("plastic_ratchet", vec![1e5]),
                ("nonlinear_stiffness", vec![2e-3]),
            ],
        ),
    ]
}

/// The extended confusion study (issue 17): (a) three monotone laws of each functional
/// effect unlike the catalog's own, (b) pairs of effects, (c) sweeps with and without
/// their tension channels, with the controls. Criterion: the hidden effect first in >=
/// 90% of each row (both effects of a pair in the top two), "none found" on >= 95% of
/// the controls, the NRMSE with the named effects within 1.5x the floor on >= 90% of
/// the datasets with something hidden.
///
/// `cargo test -p longreach-ident --release --test confusion confusion_extended -- --ignored --nocapture`;
/// filters: `EXTENDED_PARTS=shapes,pairs,controls`, `CONFUSION_EFFECTS` (an effect's
/// rows; for pairs either effect), `CONFUSION_KINDS`, `CONFUSION_ROPES`,
/// `CONFUSION_TENSIONS=with|without`, `EXTENDED_SHAPES=saturating,...` (shape names).
#[test]
#[ignore]
fn confusion_extended() {
    let parts = list("EXTENDED_PARTS");
    let only_effects = list("CONFUSION_EFFECTS");
    let only_ropes = list("CONFUSION_ROPES");
    let only_shapes = list("EXTENDED_SHAPES");
    let only_kinds = std::env::var("CONFUSION_KINDS").unwrap_or_default();
    let wanted = |l: &[String], x: &str| l.is_empty() || l.iter().any(|s| s == x);
    let kind_ok = |k: DataKind| {
        only_kinds.is_empty()
            || only_kinds.contains(if k == DataKind::SineSweep {
                "sine_sweep"
            } else {
                "relaxation"
            })
    };
    // The ropes the filter keeps, each with its index in the full run (a rope filtered
    // out is skipped, not removed: every dataset keeps the full run's seed).
    let ropes = || {
        ["dyneema2", "vectran2"]
            .into_iter()
            .enumerate()
            .filter(|(_, r)| wanted(&only_ropes, r))
    };
    let t0 = std::time::Instant::now();
    // row -> (first, datasets)
    let mut rows: std::collections::BTreeMap<String, (usize, usize)> = Default::default();
    let mut after = (0usize, 0usize);
    let mut controls = (0usize, 0usize);
    if wanted(&parts, "shapes") {
        for (i, rope) in ropes() {
            for (c, (effect, kind, shape, truth)) in shape_cases(rope).into_iter().enumerate() {
                if !wanted(&only_effects, effect) || !wanted(&only_shapes, shape) || !kind_ok(kind)
                {
                    continue;
                }
                for (&t, more) in variants(kind)
                    .iter()
                    .flat_map(|t| strain_sets(kind).iter().map(move |s| (t, s)))
                {
                    let seed = 3000 + 100 * i as u64 + c as u64;
                    let o = diagnose_truth(
                        kind,
                        rope,
                        &truth,
                        seed,
                        i,
                        t,
                        more,
                        &format!("shape {effect}/{shape}"),
                    );
                    let strains = if more.is_empty() {
                        String::new()
                    } else {
                        format!(", {} strains", more.len() + 1)
                    };
                    let row = rows
                        .entry(format!("{kind:?} {effect} (3 shapes{strains})"))
                        .or_default();
                    row.0 += usize::from(o.top2.first().map(String::as_str) == Some(effect));
                    row.1 += 1;
                    after.0 += usize::from(o.after_ratio.is_some_and(|r| r <= 1.5));
                    after.1 += 1;
                }
            }
        }
    }
    if wanted(&parts, "pairs") {
        for (i, rope) in ropes() {
            for (kind, pair) in pair_cases(rope) {
                if !kind_ok(kind)
                    || !(wanted(&only_effects, pair[0].0) || wanted(&only_effects, pair[1].0))
                {
                    continue;
                }
                let mut truth = base_model(rope, kind);
                for (name, v) in &pair {
                    truth = truth.with_effect(effects::find(name).unwrap());
                    let k = truth.effects.len() - 1;
                    for (p, x) in truth.effects[k].params.iter_mut().zip(v) {
                        p.value = *x;
                    }
                }
                for &t in variants(kind) {
                    let label = format!("pair {}+{}", pair[0].0, pair[1].0);
                    let o =
                        diagnose_truth(kind, rope, &truth, 4000 + 10 * i as u64, i, t, &[], &label);
                    // both among the first two singles, or the best pair
                    let both = pair.iter().all(|(n, _)| o.top2.iter().any(|x| x == n))
                        || pair.iter().all(|(n, _)| o.best_pair.iter().any(|x| x == n));
                    let row = rows
                        .entry(format!("{kind:?} pair {}+{}", pair[0].0, pair[1].0))
                        .or_default();
                    row.0 += usize::from(both);
                    row.1 += 1;
                    after.0 += usize::from(o.after_ratio.is_some_and(|r| r <= 1.5));
                    after.1 += 1;
                }
            }
        }
    }
    if wanted(&parts, "controls") && wanted(&only_effects, "control") {
        for (i, rope) in ropes() {
            for kind in [DataKind::SineSweep, DataKind::Relaxation] {
                if !kind_ok(kind) {
                    continue;
                }
                for &t in variants(kind) {
                    let truth = base_model(rope, kind);
                    let o = diagnose_truth(
                        kind,
                        rope,
                        &truth,
                        5000 + 10 * i as u64,
                        i,
                        t,
                        &[],
                        "control",
                    );
                    controls.0 += usize::from(o.named.is_empty());
                    controls.1 += 1;
                }
            }
        }
    }
    println!("| row | hidden first (pairs: both in the top two) | datasets |\n|---|---|---|");
    for (r, (f, n)) in &rows {
        println!("| {r} | {f} | {n} |");
    }
    println!("| controls | none found {} | {} |", controls.0, controls.1);
    println!(
        "NRMSE after within 1.5x the floor: {} of {}; wall time {:.0} s",
        after.0,
        after.1,
        t0.elapsed().as_secs_f64()
    );
    for (r, (f, n)) in &rows {
        assert!(*f as f64 >= 0.9 * *n as f64, "{r}: first {f}/{n}");
    }
    assert!(
        controls.0 as f64 >= 0.95 * controls.1 as f64,
        "controls {controls:?}"
    );
    assert!(after.0 as f64 >= 0.9 * after.1 as f64, "after {after:?}");
    assert!(
        !rows.is_empty() || controls.1 > 0,
        "the filters selected no dataset"
    );
}
