//! Times the shape-free refinement of a model's effect on a dataset:
//! `cargo run --release -p longreach-ident --example refine_probe -- DATASET MODEL.toml`;
//! a third argument `sim` stops after the simulation (timed: the fastest of 10, or of
//! `PROBE_SIMS`).
use std::time::Instant;

use longreach_ident::analysis::{fit_model, refine_shape, Prepared};
use longreach_ident::model::Model;
use longreach_ident::Dataset;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let ds = Dataset::load(&args[1])?;
    let text = std::fs::read_to_string(&args[2])?;
    let model = Model::from_toml(&text, &args[2], &ds)?;
    let prep = Prepared::new(&ds)?;
    // (the fastest of 10, or of PROBE_SIMS: the machine's other load only slows a run
    // down; PROBE_SIMS=1 under callgrind)
    let repeats: usize = std::env::var("PROBE_SIMS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10);
    let mut best = f64::INFINITY;
    let mut sims = Vec::new();
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        sims = prep.simulate(&model)?;
        best = best.min(t.elapsed().as_secs_f64());
    }
    println!(
        "one simulation: {:.1} ms (fastest of {}), nrmse {:.6}",
        best * 1e3,
        repeats.max(1),
        prep.overall(&sims).0
    );
    if args.get(3).is_some_and(|a| a == "sim") {
        return Ok(());
    }
    let t = Instant::now();
    let f = fit_model(&prep, &model)?;
    println!(
        "parametric fit: {:.1} s, nrmse {:.4} (floor {:.4}), evaluations {:?}",
        t.elapsed().as_secs_f64(),
        f.nrmse,
        f.noise_floor,
        f.fit.as_ref().map(|r| r.evaluations)
    );
    let t = Instant::now();
    let e = f.model.effects.len() - 1;
    if let Some((r, g)) = refine_shape(&prep, &f, e)? {
        println!("refinement: {:.1} s", t.elapsed().as_secs_f64());
        println!("{}", serde_json::to_string_pretty(&r)?);
        println!("{}", g.model.to_toml("refined"));
    }
    Ok(())
}
