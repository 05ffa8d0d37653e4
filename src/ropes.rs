//! `longreach ropes`: the rope catalog.

use std::process::ExitCode;

use anyhow::Result;
use clap::Args;
use comfy_table::{presets::UTF8_BORDERS_ONLY, Table};

use longreach_rope::{Catalog, LawKind};

/// Arguments of `longreach ropes`.
#[derive(Debug, Args)]
pub struct RopesArgs {}

fn opt(v: Option<f64>) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{v:.3e}"))
}

/// Prints every catalog rope with its constants.
pub fn run(_args: &RopesArgs) -> Result<ExitCode> {
    let catalog = Catalog::builtin();
    let mut table = Table::new();
    table.load_preset(UTF8_BORDERS_ONLY).set_header([
        "rope",
        "law",
        "strength [N]",
        "k1 [N]",
        "c2 [N*s]",
        "k3 [N]",
        "c3 [N*s]",
        "kp [N]",
        "fiber",
    ]);
    for r in catalog.ropes() {
        table.add_row([
            r.name.clone(),
            LawKind::default_for(r).as_str().to_string(),
            format!("{:.0}", r.tensile_strength_n),
            format!("{:.3e}", r.k1_n),
            opt(r.c2_n_s),
            opt(r.k3_n),
            opt(r.c3_n_s),
            opt(r.kp_n),
            r.fiber.clone(),
        ]);
    }
    println!(
        "Rope catalog (robots/ropes.toml; per-strain constants, paper Tables I, IV, VI)\n{table}"
    );
    Ok(ExitCode::SUCCESS)
}
