//! Prints `chain_urdf(n, length_m, mass_kg)` to stdout.
//!
//! `cargo run -p longreach-arm --example print_chain -- 5 2.0 10.0`

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let parse = |i: usize, default: f64| -> f64 {
        args.get(i)
            .and_then(|s| s.parse::<f64>().ok())
            .unwrap_or(default)
    };
    let n = parse(0, 5.0).max(1.0) as usize;
    print!(
        "{}",
        longreach_arm::chain_urdf(n, parse(1, 2.0), parse(2, 10.0))
    );
}
