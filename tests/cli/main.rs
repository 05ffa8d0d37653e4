//! Integration tests of this package, linked as one binary (one link and one
//! executable instead of one per file: CI's build time and disk). Each former
//! test file is a module; filter with its name, e.g. `-- arm_cli::`.

mod arm_cli;
mod arm_scenarios;
mod bad_inputs;
mod batch;
mod batch_arm;
mod bode_cli;
mod ident_cli;
mod parser_fuzz;
mod rerun_cli;
mod rig_frequency_response;
