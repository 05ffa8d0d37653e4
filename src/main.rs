//! `longreach`: simulate long-reach arms driven by cable-pulley transmissions with
//! synthetic fiber ropes, and compare the model with measurements.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod batch_cmd;
mod bode;
mod output;
mod ropes;

/// Long-reach robot arms driven through synthetic-fiber and steel ropes: simulate,
/// sweep, compare with measurements.
#[derive(Debug, Parser)]
#[command(name = "longreach", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Frequency response of the cable-pulley rig: analytic (eqs. 12-13) and simulated.
    Bode(bode::BodeArgs),
    /// List the rope catalog (the paper's constants).
    Ropes(ropes::RopesArgs),
    /// Run a batch of scenarios (axes over a base scenario) into one results table.
    Batch(batch_cmd::BatchArgs),
    /// Join the tables of shard runs into the table of the whole batch.
    Merge(batch_cmd::MergeArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bode(args) => bode::run(&args),
        Command::Ropes(args) => ropes::run(&args),
        Command::Batch(args) => batch_cmd::run(&args),
        Command::Merge(args) => batch_cmd::merge_run(&args),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
