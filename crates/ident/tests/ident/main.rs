//! Integration tests of this package, linked as one binary (one link and one
//! executable instead of one per file: CI's build time and disk). Each former
//! test file is a module; filter with its name, e.g. `-- cyclic::`.

mod arm;
mod arm_confusion;
mod arm_links;
mod cyclic;
mod dataset_errors;
mod diagnose_loop;
mod examples;
mod fitting;
mod intervals;
mod metrics;
mod new_effects;
mod relay_friction;
mod sensors;
mod shapes;
mod signatures;
mod tensions;
