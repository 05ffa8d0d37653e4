//! Records the trajectories of every shipped scenario bit for bit, and compares two
//! recordings: the check that a change of code left the numbers unchanged.
//!
//! ```text
//! cargo run --release -p longreach-arm --example trajectories -- dump DIR
//! cargo run --release -p longreach-arm --example trajectories -- compare DIR_A DIR_B
//! ```
//!
//! `dump` runs every `scenarios/arm_*.toml` and `scenarios/flex_*.toml` for its duration
//! (joint angles and rates, with the modal coordinates of flexible links, motor angles,
//! tensioner stretches and every span tension of every step), every run
//! of every `scenarios/bode_*.toml` (output angle and both tensions of every step), and
//! two rigs with relay friction (a short sweep each, every span tension), and writes one
//! file of little-endian `f64`s per trajectory. `compare` prints, per trajectory,
//! whether the two recordings are bitwise equal and else the largest difference of each
//! quantity; it exits 1 when one differs by more than 1e-12 (rad, or relative for
//! tensions and stretches).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use longreach_drive::{InputSignal, RelayFriction, RigModel, RigSpec, SteppedSine, Tensioner};
use longreach_rope::{Catalog, LawKind, RopeLaw};
use longreach_scenario::BodeScenario;

/// One trajectory: named channels, each one value per recorded step.
#[derive(Default)]
struct Traj {
    channels: BTreeMap<String, Vec<f64>>,
}

impl Traj {
    fn push(&mut self, name: String, v: f64) {
        self.channels.entry(name).or_default().push(v);
    }

    fn write(&self, path: &Path) {
        let mut bytes = Vec::new();
        let names: Vec<&String> = self.channels.keys().collect();
        let header = names
            .iter()
            .map(|s| s.as_str())
            .collect::<Vec<_>>()
            .join(",");
        bytes.extend((header.len() as u64).to_le_bytes());
        bytes.extend(header.as_bytes());
        for name in names {
            let v = &self.channels[name];
            bytes.extend((v.len() as u64).to_le_bytes());
            for x in v {
                bytes.extend(x.to_le_bytes());
            }
        }
        std::fs::write(path, bytes).expect("write");
    }

    fn read(path: &Path) -> Self {
        let b = std::fs::read(path).expect("read");
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().unwrap()) as usize;
        let hl = u64_at(0);
        let header = std::str::from_utf8(&b[8..8 + hl]).unwrap().to_string();
        let mut pos = 8 + hl;
        let mut channels = BTreeMap::new();
        for name in header.split(',').filter(|s| !s.is_empty()) {
            let n = u64_at(pos);
            pos += 8;
            let v = (0..n)
                .map(|k| f64::from_le_bytes(b[pos + 8 * k..pos + 8 * k + 8].try_into().unwrap()))
                .collect();
            pos += 8 * n;
            channels.insert(name.to_string(), v);
        }
        Self { channels }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scenario_files(prefix: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join("scenarios"))
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with(prefix) && n.ends_with(".toml"))
        })
        .collect();
    v.sort();
    v
}

fn dump_arm(path: &Path) -> Traj {
    let sc = longreach_arm::scenario::load(path).unwrap_or_else(|e| panic!("{e}"));
    let arm = &sc.arm;
    let steps = (sc.sim.duration_s / arm.dt_s()).round() as usize;
    let mut st = arm.initial_state();
    let mut t = Traj::default();
    for step in 0..=steps {
        if step > 0 {
            arm.step(&mut st)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        }
        for (j, q) in st.q_rad.iter().enumerate() {
            t.push(format!("q{j}_rad"), *q);
            t.push(format!("qd{j}_rad_s"), st.qd_rad_s[j]);
        }
        for p in 0..st.motor_rad.len() {
            t.push(format!("motor{p}_rad"), st.motor_rad[p]);
            t.push(format!("carriage{p}_m"), st.carriage_m[p]);
            for (i, s) in arm.span_tensions_n(&st, p).iter().enumerate() {
                t.push(format!("tension{p}_span{i}_pos_n"), s[0]);
                t.push(format!("tension{p}_span{i}_neg_n"), s[1]);
            }
        }
    }
    t
}

fn rig_traj(model: &RigModel, input: &InputSignal) -> Traj {
    let dt = model.dt_s();
    let n = (input.duration_s() / dt).round() as usize;
    let mut st = model.rest_state();
    let mut t = Traj::default();
    for k in 0..=n {
        if k > 0 {
            model
                .step(&mut st, input.angle_rad(k as f64 * dt))
                .unwrap_or_else(|e| panic!("{e}"));
        }
        t.push("output_rad".into(), st.output_rad());
        t.push("carriage_m".into(), st.carriage_m());
        for i in 0..2 {
            for (j, f) in st.span_tensions_n(i).iter().enumerate() {
                t.push(format!("rope{i}_span{j}_n"), *f);
            }
        }
    }
    t
}

fn dump(out: &Path) {
    std::fs::create_dir_all(out).unwrap();
    for path in scenario_files("arm_")
        .into_iter()
        .chain(scenario_files("arm5_"))
        .chain(scenario_files("flex_"))
    {
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        dump_arm(&path).write(&out.join(format!("{name}.bin")));
        println!("{name}");
    }
    for path in scenario_files("bode_") {
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        let sc = BodeScenario::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        for i in 0..sc.rigs.len() {
            let (_, trace) = sc.run_one_traced(i).unwrap();
            let mut t = Traj::default();
            for k in 0..trace.time_s.len() {
                t.push("output_rad".into(), trace.output_rad[k]);
                t.push("tension_1_n".into(), trace.tension_1_n[k]);
                t.push("tension_2_n".into(), trace.tension_2_n[k]);
            }
            t.write(&out.join(format!("{name}_run{i}.bin")));
        }
        println!("{name}");
    }
    // Rigs with relay friction (not a shipped scenario; the ident loop's candidate).
    let sine = SteppedSine {
        amplitude_rad: 0.02,
        frequencies_hz: vec![1.0, 2.5, 4.0],
        settle_s: 2.0,
        min_cycles: 2,
        min_hold_s: 1.0,
    };
    let input = InputSignal::stepped_sine(sine).unwrap();
    for (name, rope, kind, tensioner) in [
        (
            "rig_relay_dyneema2_cf",
            "dyneema2",
            LawKind::FourElement,
            Tensioner::ConstantForce,
        ),
        (
            "rig_relay_stainless1_fixed",
            "stainless1",
            LawKind::Elastic,
            Tensioner::Fixed,
        ),
    ] {
        let params = Catalog::builtin().get(rope).unwrap().clone();
        let law = RopeLaw::from_params(&params, kind).unwrap();
        let mut spec = RigSpec::paper(rope, law, 0.05, 147.0);
        spec.tensioner = tensioner;
        spec.relay_friction = Some(RelayFriction {
            coefficient: 0.003,
            inertia_kg_m2: 2e-5,
            slip_rate_rad_s: RelayFriction::DEFAULT_SLIP_RATE_RAD_S,
            coefficient_table: None,
        });
        let model = RigModel::new(spec, 1e-3).unwrap();
        rig_traj(&model, &input).write(&out.join(format!("{name}.bin")));
        println!("{name}");
    }
}

fn compare(a: &Path, b: &Path) -> bool {
    let mut names: Vec<PathBuf> = std::fs::read_dir(a)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    names.sort();
    let mut ok = true;
    for pa in names {
        let name = pa.file_name().unwrap().to_owned();
        let pb = b.join(&name);
        if !pb.exists() {
            println!("{}: missing in {}", name.to_string_lossy(), b.display());
            ok = false;
            continue;
        }
        let (ta, tb) = (Traj::read(&pa), Traj::read(&pb));
        let mut bitwise = ta.channels.len() == tb.channels.len();
        let mut worst: Vec<(String, f64)> = Vec::new();
        for (ch, va) in &ta.channels {
            let Some(vb) = tb.channels.get(ch) else {
                println!("{}: channel {ch} missing", name.to_string_lossy());
                ok = false;
                bitwise = false;
                continue;
            };
            if va.len() != vb.len() {
                println!(
                    "{}: {ch} has {} against {} samples",
                    name.to_string_lossy(),
                    va.len(),
                    vb.len()
                );
                ok = false;
                bitwise = false;
                continue;
            }
            let same = va.iter().zip(vb).all(|(x, y)| x.to_bits() == y.to_bits());
            bitwise &= same;
            if !same {
                let scale = if ch.ends_with("_rad") || ch.ends_with("_rad_s") {
                    1.0
                } else {
                    va.iter().fold(1.0f64, |m, v| m.max(v.abs()))
                };
                let d = va
                    .iter()
                    .zip(vb)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0f64, f64::max)
                    / scale;
                worst.push((ch.clone(), d));
            }
        }
        if bitwise {
            println!("{}: bitwise equal", name.to_string_lossy());
        } else {
            worst.sort_by(|x, y| y.1.total_cmp(&x.1));
            let top: Vec<String> = worst
                .iter()
                .take(3)
                .map(|(c, d)| format!("{c} {d:.2e}"))
                .collect();
            let bad = worst.first().is_some_and(|w| {
                let limit = if w.0.contains("qd") { 1e-9 } else { 1e-12 };
                w.1 > limit
            });
            ok &= !bad;
            println!(
                "{}: differs ({}){}",
                name.to_string_lossy(),
                top.join(", "),
                if bad { "  <-- above the limit" } else { "" }
            );
        }
    }
    ok
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("dump") if args.len() == 2 => dump(Path::new(&args[1])),
        Some("compare") if args.len() == 3 => {
            if !compare(Path::new(&args[1]), Path::new(&args[2])) {
                std::process::exit(1);
            }
        }
        _ => {
            eprintln!("usage: trajectories dump DIR | compare DIR_A DIR_B");
            std::process::exit(2);
        }
    }
}
