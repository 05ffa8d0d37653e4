//! Timing probe: simulate every run of a sweep dataset once. `cargo run --release -p longreach-ident --example sim_speed -- DIR SUBSTEPS`
use longreach_ident::{sim, Dataset, DatasetKind};
use longreach_rope::{Catalog, LawKind, RopeLaw};
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let ds = Dataset::load(&args[1]).unwrap();
    let sub: usize = args[2].parse().unwrap();
    let DatasetKind::SineSweep(sw) = &ds.kind else {
        panic!()
    };
    let p = Catalog::builtin().get(&sw.rig.rope).unwrap().clone();
    let law = RopeLaw::from_params(&p, LawKind::FourElement).unwrap();
    let t = std::time::Instant::now();
    let load = t.elapsed();
    let t = std::time::Instant::now();
    for run in &sw.runs {
        let s = sim::simulate_sweep_run(&sw.rig, run, law.clone(), sub).unwrap();
        let idx: Vec<usize> = run
            .segments()
            .unwrap()
            .iter()
            .flat_map(|g| g.analysis_start_index..g.analysis_end_index)
            .collect();
        let m: Vec<f64> = idx.iter().map(|&i| run.output_angle_rad[i]).collect();
        let y: Vec<f64> = idx.iter().map(|&i| s.output_rad[i]).collect();
        println!(
            "{} {} nrmse {:.5}",
            run.name,
            run.mean_tension_n,
            longreach_ident::metrics::nrmse(&m, &y).unwrap()
        );
    }
    println!("{load:?} sim {:?}", t.elapsed());
}
