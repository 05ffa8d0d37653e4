//! Scenario batches: a base scenario plus axes that override its fields by dotted path,
//! expanded into numbered scenarios, run in parallel (rayon) into one results table,
//! with an append-only journal for resuming and disjoint shards for many machines.
//!
//! The batch file format is documented in `docs/batch.md`. In short:
//!
//! ```toml
//! base = "bode_dyneema2.toml"          # or an inline [base] table
//! [set]                                # fixed overrides, no column
//! "simulation.dt_s" = 0.002
//! [[axis]]                             # one dimension of the cartesian product
//! path = "rig.rope"
//! values = ["dyneema2", "zylon2"]
//! [[axis]]                             # axes with the same `zip` advance together
//! path = "rig.output_inertia_kg_m2"
//! values = [0.0284, 0.0568]
//! zip = "payload"
//! [[case]]                             # explicit list: one more dimension
//! "rig.output_damping_n_m_s" = 0.05
//! [[random]]                           # drawn per scenario from (seed, index)
//! path = "rig.prestretch_n"
//! uniform = [400.0, 600.0]
//! ```
//!
//! Two kinds of problems are told apart. A batch file that is wrong in itself (unknown
//! path, a value whose TOML type differs from the base value's, an empty axis, zipped
//! axes of different lengths, an invalid base) fails [`Batch::from_file`] before
//! anything runs. A well-typed value that the model rejects (a negative length, an
//! unknown rope name) or a run that blows up numerically becomes a row whose `status`
//! is `invalid` or `failed`, with the error, and never stops the batch.

mod expand;
mod journal;
mod kind;
mod path;
mod row;
mod run;
mod shard;

pub use expand::{Batch, Scenario};
pub use journal::{merge, Header, Journal, JournalError, JOURNAL_FILE};
pub use kind::{builtin_kinds, one_line, BodeKind, Outcome, RowError, ScenarioKind};
pub use row::{Cell, CellKind, Column, Row, Status, Table};
pub use run::{run_one, run_scenarios, RunOptions};
pub use shard::Shard;
/// A scenario as a TOML tree (what [`ScenarioKind::detect`] looks at).
pub use toml::Table as ScenarioTree;
