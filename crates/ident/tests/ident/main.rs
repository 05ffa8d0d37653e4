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
mod sweep_step;
mod tensions;

/// The two stages of `m`'s fit on `prep` against its whole fit: the screen lies between
/// the start and the whole fit, and the second stage after it is `fit_model`'s fit to
/// the bit (it retraces the screen's path through the same simulations).
fn check_staged_fit(
    prep: &longreach_ident::analysis::Prepared<'_>,
    m: &longreach_ident::model::Model,
) {
    use longreach_ident::analysis::{fit_model, Staged};
    let whole = fit_model(prep, m).unwrap();
    let mut staged = Staged::new(prep, m);
    let screen = staged.screen().unwrap();
    assert!(screen.fit.is_none(), "a screen has no intervals");
    let start_ssr = prep.ssr(&prep.simulate(m).unwrap());
    assert!(
        whole.ssr <= screen.ssr && screen.ssr < start_ssr,
        "whole {:e} <= screen {:e} < start {start_ssr:e}",
        whole.ssr,
        screen.ssr
    );
    let again = staged.fit().unwrap();
    assert_eq!(again.ssr.to_bits(), whole.ssr.to_bits());
    assert_eq!(again.model.named_values(), whole.model.named_values());
    assert_eq!(again.sims, whole.sims);
}
