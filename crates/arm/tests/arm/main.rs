//! Integration tests of this package, linked as one binary (one link and one
//! executable instead of one per file: CI's build time and disk). Each former
//! test file is a module; filter with its name, e.g. `-- driven::`.

#[allow(dead_code)]
mod common;
mod driven;
mod dynamics;
mod effects;
mod flex;
mod joint_friction;
mod multibody;
mod payload;
mod rapier_cross_check;
mod relay_friction;
mod rig_equivalence;
mod scenario_parse;
mod urdf_loading;
