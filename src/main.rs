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

/// Exit codes (README "Exit codes"): 0 ok, 1 some batch rows failed, 2 bad input or
/// usage, 3 a run failed numerically; a closed stdout ends quietly with 141, as the
/// SIGPIPE a C tool would die of.
pub mod exit {
    /// Some rows of a batch failed or were invalid (the table is written).
    pub const ROWS_FAILED: u8 = 1;
    /// Bad input or usage: the message names the file, line or field and the fix.
    pub const BAD_INPUT: u8 = 2;
    /// A run failed numerically (blow-up, a result that is not a finite number).
    pub const NUMERICAL: u8 = 3;
    /// stdout was closed by its reader (`longreach ... | head -1`).
    pub const BROKEN_PIPE: u8 = 141;
}

/// A run that failed numerically (exit 3): non-finite states or metrics.
#[derive(Debug)]
pub struct Numerical(pub String);

impl std::fmt::Display for Numerical {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Numerical {}

/// The exit code of an error: numerical failures of the physics are 3, a closed
/// stdout 141, everything else (input, usage, files) 2.
fn exit_code(e: &anyhow::Error) -> u8 {
    use longreach_drive::DriveError;
    use longreach_ident::IdentError;
    for cause in e.chain() {
        if let Some(io) = cause.downcast_ref::<std::io::Error>() {
            if io.kind() == std::io::ErrorKind::BrokenPipe {
                return exit::BROKEN_PIPE;
            }
        }
        let numerical = cause.is::<Numerical>()
            || matches!(
                cause.downcast_ref::<DriveError>(),
                Some(DriveError::BlowUp { .. })
            )
            || matches!(
                cause.downcast_ref::<longreach_arm::ArmError>(),
                Some(longreach_arm::ArmError::BlowUp { .. })
            )
            || matches!(
                cause.downcast_ref::<IdentError>(),
                Some(
                    IdentError::Simulation { .. }
                        | IdentError::NoStartSimulated { .. }
                        | IdentError::NoStartFitted { .. }
                )
            );
        if numerical {
            return exit::NUMERICAL;
        }
    }
    exit::BAD_INPUT
}

/// A closed stdout makes `println!` panic with "failed printing to stdout: Broken
/// pipe": end quietly instead (no message, exit 141), as a tool killed by SIGPIPE would.
/// Every other panic keeps the default report.
fn quiet_on_broken_pipe() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.contains("Broken pipe") || msg.contains("os error 32") {
            std::process::exit(i32::from(exit::BROKEN_PIPE));
        }
        default(info);
    }));
}

fn main() -> ExitCode {
    quiet_on_broken_pipe();
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
            let code = exit_code(&e);
            if code != exit::BROKEN_PIPE {
                eprintln!("error: {e:#}");
            }
            ExitCode::from(code)
        }
    }
}
