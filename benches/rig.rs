//! Rig benchmarks (issue: rope laws and rig): one rig step with four-element ropes, the
//! same with elastic ropes (the MuJoCo anchor's rope), with ropes that stiffen with
//! tension (catalog law and table), with a creep that grows with tension, with relay
//! friction, and the whole 49-392 N Dyneema2 bode scenario. Run: `cargo bench --bench rig`.

use std::hint::black_box;
use std::path::Path;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};

use longreach_drive::{RelayFriction, RigModel, RigSpec};
use longreach_rope::{Catalog, LawKind, NonlinearCreep, RopeLaw, Table};
use longreach_scenario::BodeScenario;

fn rig(rope: &str, law: LawKind, damping: f64) -> RigModel {
    let params = Catalog::builtin().get(rope).unwrap().clone();
    let law = RopeLaw::from_params(&params, law).unwrap();
    RigModel::new(RigSpec::paper(rope, law, damping, 147.0), 1e-3).unwrap()
}

/// The four-element Dyneema2 rig with its head spring made non-linear by `set`.
fn stiffening(set: impl Fn(&mut RopeLaw)) -> RigModel {
    let params = Catalog::builtin().get("dyneema2").unwrap().clone();
    let mut law = RopeLaw::from_params(&params, LawKind::FourElement).unwrap();
    set(&mut law);
    RigModel::new(RigSpec::paper("dyneema2", law, 0.05, 147.0), 1e-3).unwrap()
}

fn bench_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("rig_step");
    const STEPS: u64 = 10_000;
    group.throughput(Throughput::Elements(STEPS));
    for (name, model) in [
        (
            "four_element_dyneema2",
            rig("dyneema2", LawKind::FourElement, 0.05),
        ),
        // The MuJoCo anchor's rig: stainless (elastic), C = 0.01, 4.5 deg at 3.17 Hz.
        (
            "elastic_stainless1",
            rig("stainless1", LawKind::Elastic, 0.01),
        ),
        // Non-linear ropes: the head spring stiffens with tension (catalog law
        // `k1 (1 + b f)`, b of example_sweep_stiffening's fit; and a saturating table),
        // each rope step solved for the head strain in closed form.
        (
            "stiffening_dyneema2",
            stiffening(|law| law.stiffening_per_n = 7.7e-4),
        ),
        // A creep dashpot that flows faster under tension (`nonlinear_creep`,
        // f/c2 (1 + (f/f_c)^n)): each rope step solved by the general safeguarded
        // Newton, one power per iteration.
        (
            "nonlinear_creep_dyneema2",
            stiffening(|law| {
                law.creep = Some(NonlinearCreep {
                    tension_n: 300.0,
                    exponent: 3.0,
                })
            }),
        ),
        (
            "stiffness_table_dyneema2",
            stiffening(|law| {
                law.stiffness_table = Some(
                    Table::new(
                        &[0.0, 67.0, 151.0, 202.0, 317.0, 600.0],
                        &[1.0, 1.03, 1.17, 1.26, 1.35, 1.36],
                    )
                    .unwrap(),
                )
            }),
        ),
        // Relay pulleys with friction and inertia (`relay_friction` 0.02, 1e-4 kg*m^2, a
        // sweep's relay-friction candidate): each rope split into four spans, the three
        // relays' angles solved with the output's (Newton, chord iterations, the relay
        // safeguards).
        ("relay_friction_dyneema2", {
            let params = Catalog::builtin().get("dyneema2").unwrap().clone();
            let law = RopeLaw::from_params(&params, LawKind::FourElement).unwrap();
            let mut spec = RigSpec::paper("dyneema2", law, 0.05, 147.0);
            spec.relay_friction = Some(RelayFriction {
                coefficient: 0.02,
                inertia_kg_m2: 1e-4,
                slip_rate_rad_s: RelayFriction::DEFAULT_SLIP_RATE_RAD_S,
                coefficient_table: None,
            });
            RigModel::new(spec, 1e-3).unwrap()
        }),
    ] {
        let amp = 4.5f64.to_radians();
        let w = std::f64::consts::TAU * 3.17;
        group.bench_function(name, |b| {
            let mut st = model.rest_state();
            let mut i = 0u64;
            b.iter(|| {
                for _ in 0..STEPS {
                    i += 1;
                    let theta = amp * (w * i as f64 * 1e-3).sin();
                    model.step(&mut st, black_box(theta)).unwrap();
                }
                black_box(st.output_rad())
            })
        });
    }
    group.finish();
}

fn bench_scenario(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/bode_dyneema2.toml");
    let scenario = BodeScenario::from_file(&path).unwrap();
    let mut group = c.benchmark_group("bode_scenario");
    group.sample_size(10);
    group.bench_function("dyneema2_49_to_392_n_one_thread", |b| {
        b.iter(|| black_box(scenario.run_all().unwrap()))
    });
    group.finish();
}

criterion_group!(benches, bench_step, bench_scenario);
criterion_main!(benches);
