//! Probe: `cargo run --release -p longreach-ident --example diag_probe -- DIR`
use longreach_ident::analysis::{diagnose, Prepared};
use longreach_ident::model::Model;
use longreach_ident::Dataset;
fn main() {
    let dir = std::env::args().nth(1).unwrap();
    let ds = Dataset::load(&dir).unwrap();
    let t = std::time::Instant::now();
    let prep = Prepared::new(&ds).unwrap();
    let m = Model::baseline(&ds).unwrap();
    let (d, base, _w) = diagnose(&prep, &m).unwrap();
    println!("time {:?}", t.elapsed());
    println!(
        "baseline nrmse {:.5} floor {:.5} params {:?} se {:?}",
        d.baseline.nrmse, d.baseline.noise_floor_nrmse, d.baseline.params, d.baseline.std_errors
    );
    if let Some(f) = &base.fit {
        println!("iters {} evals {}", f.iterations, f.evaluations);
    }
    for c in &d.candidates {
        println!(
            "{:22} nrmse {:.5} score {:10.1} expl {:.3} dec {} {:?} {:?}",
            c.effect, c.nrmse, c.score, c.explained, c.decisive, c.params, c.error
        );
    }
    println!("missing {:?}\n{}", d.missing_effect, d.explanation);
    for r in &d.comparison.runs {
        println!("{:?}", r);
    }
    for r in &d.comparison.resonance {
        println!("{:?}", r);
    }
    println!("{:?}", d.comparison.residual);
}
