//! Integration tests of this package, linked as one binary (one link and one
//! executable instead of one per file: CI's build time and disk). Each former
//! test file is a module; filter with its name, e.g. `-- relay::`.

mod joint_friction;
mod relay;
mod rig;
