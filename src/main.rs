//! `longreach`: simulate long-reach arms driven by cable-pulley transmissions with
//! synthetic fiber ropes, and compare the model with measurements.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod arm_ident_cmd;
mod batch_cmd;
mod bode;
mod ident_cmd;
mod modes_cmd;
mod output;
mod rerun_args;
mod ropes;
mod run_cmd;

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
    /// Fit a model's free parameters to a measurement dataset (with uncertainties).
    Fit(ident_cmd::FitArgs),
    /// Compare a model with a measurement dataset: error, where it fails, residual checks.
    Compare(ident_cmd::CompareArgs),
    /// Find the physical effect a model lacks: fit every registered effect and rank them.
    Diagnose(ident_cmd::DiagnoseArgs),
    /// Write a synthetic measurement dataset from a model with hidden effects.
    Synth(ident_cmd::SynthArgs),
    /// Run a batch of scenarios (axes over a base scenario) into one results table.
    Batch(batch_cmd::BatchArgs),
    /// Join the tables of shard runs into the table of the whole batch.
    Merge(batch_cmd::MergeArgs),
    /// Run a driven arm scenario (URDF + rope transmissions + servos): time series and metrics.
    Run(run_cmd::RunArgs),
    /// Modes of an arm scenario linearised at a pose: frequencies, damping, what rings.
    Modes(modes_cmd::ModesArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Bode(args) => bode::run(&args),
        Command::Ropes(args) => ropes::run(&args),
        Command::Fit(args) => ident_cmd::run_fit(&args),
        Command::Compare(args) => ident_cmd::run_compare(&args),
        Command::Diagnose(args) => ident_cmd::run_diagnose(&args),
        Command::Synth(args) => ident_cmd::run_synth(&args),
        Command::Batch(args) => batch_cmd::run(&args),
        Command::Merge(args) => batch_cmd::merge_run(&args),
        Command::Run(args) => run_cmd::run(&args),
        Command::Modes(args) => modes_cmd::run(&args),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
