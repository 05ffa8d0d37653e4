//! Every `scenarios/arm_*.toml` runs, and the long-reach design holds its ropes.
//! The rope comparison table of docs/arm.md is regenerated here and must match.

use std::path::{Path, PathBuf};

use longreach_arm::run::{run, RunMetrics};

use longreach_arm::scenario::load;

fn scenarios_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios")
}

fn run_file(name: &str) -> RunMetrics {
    let sc = load(&scenarios_dir().join(name)).unwrap_or_else(|e| panic!("{e}"));
    let (_, m) = run(
        &sc.arm,
        sc.sim.duration_s,
        sc.sim.output_every,
        sc.sim.residual_window_s,
        &mut |_, _| {},
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"));
    m
}

#[test]
fn every_arm_scenario_runs_and_the_design_holds_its_ropes() {
    let mut files: Vec<String> = std::fs::read_dir(scenarios_dir())
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("arm_") && n.ends_with(".toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 20, "{files:?}");
    for f in &files {
        let m = run_file(f);
        for p in &m.pairs {
            // The design requirement (robots/longreach5/README.md): every rope below a
            // third of its tensile strength in the worst static pose.
            assert!(
                p.static_safety_factor >= 3.0,
                "{f}: pair {} static safety factor {}",
                p.joint,
                p.static_safety_factor
            );
            assert!(p.peak_tension_n.is_finite() && p.min_tension_n >= 0.0);
        }
    }
}

#[test]
fn rope_comparison_table_in_docs_is_current() {
    let table = longreach_arm::run::rope_comparison_table(&scenarios_dir()).unwrap();
    println!("{table}");
    let doc = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/arm.md"))
        .unwrap_or_default();
    let begin = "<!-- rope-comparison:begin -->\n";
    let end = "<!-- rope-comparison:end -->";
    let found = doc.find(begin).and_then(|a| {
        doc[a + begin.len()..]
            .find(end)
            .map(|b| &doc[a + begin.len()..a + begin.len() + b])
    });
    assert_eq!(
        found,
        Some(table.as_str()),
        "docs/arm.md's rope comparison is stale: replace the block between the markers with the table printed above"
    );
}
