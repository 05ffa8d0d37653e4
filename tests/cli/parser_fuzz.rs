//! A deterministic, stable-Rust stand-in for the `cargo fuzz` targets of `fuzz/`
//! (docs/fuzzing.md): the same five parsers (URDF, scenario, batch, dataset, model file)
//! on mutations of the repository's own inputs (byte flips, deletions, duplications,
//! splices, numbers replaced by extreme ones), each caught with `catch_unwind`. A panic
//! is a failure that names the target and writes the input to
//! `target/parser-fuzz-crash-<target>-<n>`.
//!
//! Ignored by default (it runs for a while):
//! `LONGREACH_FUZZ_SECONDS=600 cargo test --test cli parser_fuzz -- --ignored --nocapture`
//! runs each target that long (default 20 s each).

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// SplitMix64: small, seeded, reproducible.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const NUMBERS: [&str; 14] = [
    "0",
    "-1",
    "1e308",
    "-1e308",
    "1e-320",
    "nan",
    "inf",
    "-inf",
    "1e12",
    "4294967296",
    "18446744073709551616",
    "-0.0",
    "\"x\"",
    "[]",
];

fn mutate(rng: &mut Rng, seeds: &[String], text: &str) -> String {
    let mut b: Vec<u8> = text.as_bytes().to_vec();
    for _ in 0..1 + rng.below(4) {
        let n = b.len().max(1);
        match rng.below(7) {
            0 if !b.is_empty() => {
                let i = rng.below(n);
                b[i] = rng.next() as u8;
            }
            1 if !b.is_empty() => {
                let i = rng.below(n);
                let len = rng.below(32).min(b.len() - i);
                b.drain(i..i + len);
            }
            2 if !b.is_empty() => {
                let i = rng.below(n);
                let len = rng.below(64).min(b.len() - i);
                let chunk = b[i..i + len].to_vec();
                let at = rng.below(b.len() + 1);
                b.splice(at..at, chunk);
            }
            3 => {
                // a number replaced by an extreme one
                let s = String::from_utf8_lossy(&b).into_owned();
                let digits: Vec<usize> = s
                    .char_indices()
                    .filter(|(_, c)| c.is_ascii_digit())
                    .map(|(i, _)| i)
                    .collect();
                if let Some(&i) = digits.get(rng.below(digits.len())) {
                    let end = s[i..]
                        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == '-'))
                        .map_or(s.len(), |e| i + e);
                    let mut t = s[..i].to_string();
                    t.push_str(NUMBERS[rng.below(NUMBERS.len())]);
                    t.push_str(&s[end..]);
                    b = t.into_bytes();
                }
            }
            4 => {
                // a line from another seed
                let other = &seeds[rng.below(seeds.len())];
                let lines: Vec<&str> = other.lines().collect();
                if let Some(line) = lines.get(rng.below(lines.len())) {
                    let at = rng.below(b.len() + 1);
                    let mut ins = line.as_bytes().to_vec();
                    ins.push(b'\n');
                    b.splice(at..at, ins);
                }
            }
            5 if !b.is_empty() => {
                let at = rng.below(n);
                b.truncate(at);
            }
            _ => {
                let at = rng.below(b.len() + 1);
                let c = [b'[', b']', b'=', b'"', b'<', b'>', b'/', b',', b'\n', b'.'];
                b.insert(at, c[rng.below(c.len())]);
            }
        }
    }
    String::from_utf8_lossy(&b).into_owned()
}

fn files(dir: &Path, ext: &[&str], out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            files(&p, ext, out);
        } else if ext.iter().any(|x| p.extension().is_some_and(|e| e == *x)) {
            out.push(p);
        }
    }
}

fn seeds_of(dirs: &[&str], ext: &[&str]) -> Vec<String> {
    let mut found = Vec::new();
    for d in dirs {
        files(&repo().join(d), ext, &mut found);
    }
    found.sort();
    found
        .iter()
        .filter_map(|p| std::fs::read_to_string(p).ok())
        .filter(|t| t.len() < 200_000)
        .collect()
}

/// Runs `call` on mutations of `seeds` for `budget`; returns (inputs, crashes).
fn drive(
    name: &str,
    seeds: &[String],
    budget: Duration,
    call: &dyn Fn(&str),
) -> (u64, Vec<PathBuf>) {
    assert!(!seeds.is_empty(), "{name}: no seeds");
    let mut rng = Rng(0x5EED ^ name.len() as u64);
    let start = Instant::now();
    let mut runs = 0u64;
    let mut crashes = Vec::new();
    while start.elapsed() < budget {
        let seed = &seeds[rng.below(seeds.len())];
        let input = mutate(&mut rng, seeds, seed);
        runs += 1;
        if catch_unwind(AssertUnwindSafe(|| call(&input))).is_err() {
            let p = repo().join(format!("target/parser-fuzz-crash-{name}-{}", crashes.len()));
            let _ = std::fs::write(&p, &input);
            crashes.push(p);
        }
    }
    (runs, crashes)
}

#[test]
#[ignore = "long: LONGREACH_FUZZ_SECONDS=600 cargo test --test cli parser_fuzz -- --ignored"]
fn parser_fuzz() {
    let secs: u64 = std::env::var("LONGREACH_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let budget = Duration::from_secs(secs);
    let only = std::env::var("LONGREACH_FUZZ_TARGET").ok();
    // Panics are caught and counted; keep their messages off the output.
    std::panic::set_hook(Box::new(|_| {}));
    let scen = repo().join("scenarios");
    let examples = repo().join("data/examples");
    let datasets: Vec<longreach_ident::Dataset> =
        ["example_sweep_control", "example_relax_control"]
            .iter()
            .map(|n| longreach_ident::Dataset::load(examples.join(n)).unwrap())
            .collect();
    let kinds = longreach_scenario::batch::builtin_kinds();
    let shm = if Path::new("/dev/shm").is_dir() {
        "/dev/shm"
    } else {
        "/tmp"
    };
    let dataset_seeds: Vec<String> = std::fs::read_dir(repo().join("fuzz/seeds/dataset"))
        .unwrap()
        .flatten()
        .filter_map(|e| std::fs::read_to_string(e.path()).ok())
        .collect();
    let model_seeds: Vec<String> = std::fs::read_dir(repo().join("fuzz/seeds/model"))
        .unwrap()
        .flatten()
        .filter_map(|e| std::fs::read_to_string(e.path()).ok())
        .collect();
    let targets: Vec<(&str, Vec<String>, Box<dyn Fn(&str)>)> = vec![
        (
            "urdf",
            seeds_of(&["robots"], &["urdf"]),
            Box::new(|t: &str| {
                let _ = longreach_arm::parse_urdf(t, "fuzz.urdf");
            }),
        ),
        (
            "scenario",
            seeds_of(&["scenarios"], &["toml"]),
            Box::new(move |t: &str| {
                let _ = longreach_scenario::BodeScenario::from_str(t, "fuzz.toml");
                let _ = longreach_arm::scenario::parse(t, "fuzz.toml", &scen);
            }),
        ),
        (
            "batch",
            seeds_of(&["scenarios"], &["toml"]),
            Box::new(move |t: &str| {
                let dir = repo().join("scenarios");
                if let Ok(b) =
                    longreach_scenario::batch::Batch::from_str(t, "fuzz.toml", "fuzz", &dir, &kinds)
                {
                    if !b.is_empty() {
                        let _ = b.scenario(0);
                        let _ = b.scenario(b.len() - 1);
                    }
                }
            }),
        ),
        (
            "dataset",
            dataset_seeds,
            Box::new(move |t: &str| {
                let (toml, csv) = t.split_once("\n----\n").unwrap_or((t, ""));
                let dir = tempfile::tempdir_in(shm).unwrap();
                std::fs::write(dir.path().join("dataset.toml"), toml).unwrap();
                for name in [
                    "run.csv",
                    "run_01.csv",
                    "relax.csv",
                    "cyclic.csv",
                    "frf.csv",
                    "frf_01.csv",
                ] {
                    std::fs::write(dir.path().join(name), csv).unwrap();
                }
                let _ = longreach_ident::Dataset::load(dir.path());
            }),
        ),
        (
            "model",
            model_seeds,
            Box::new(move |t: &str| {
                for ds in &datasets {
                    if let Ok(m) = longreach_ident::model::Model::from_toml(t, "fuzz.toml", ds) {
                        let _ = m.law_for_run(0);
                    }
                }
            }),
        ),
    ];
    let mut all_crashes = Vec::new();
    for (name, seeds, call) in &targets {
        if only.as_deref().is_some_and(|o| o != *name) {
            continue;
        }
        let (runs, crashes) = drive(name, seeds, budget, call.as_ref());
        eprintln!(
            "parser_fuzz {name}: {runs} inputs in {secs} s from {} seeds, {} crashes",
            seeds.len(),
            crashes.len()
        );
        all_crashes.extend(crashes);
    }
    let _ = std::panic::take_hook();
    assert!(all_crashes.is_empty(), "crashing inputs: {all_crashes:?}");
}
