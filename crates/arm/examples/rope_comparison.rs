//! Prints the rope comparison table of docs/arm.md:
//! `cargo run --release -p longreach-arm --example rope_comparison -- scenarios`.

fn main() {
    let dir = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "scenarios".into());
    match longreach_arm::run::rope_comparison_table(std::path::Path::new(&dir)) {
        Ok(t) => print!("{t}"),
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    }
}
