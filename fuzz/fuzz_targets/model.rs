//! Model files (`Model::from_toml`) against the example datasets of every kind.
#![no_main]
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

fn datasets() -> &'static Vec<longreach_ident::Dataset> {
    static DS: OnceLock<Vec<longreach_ident::Dataset>> = OnceLock::new();
    DS.get_or_init(|| {
        let root = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../data/examples"));
        ["example_sweep_control", "example_relax_control"]
            .iter()
            .map(|n| longreach_ident::Dataset::load(root.join(n)).expect("example dataset"))
            .collect()
    })
}

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        for ds in datasets() {
            if let Ok(m) = longreach_ident::model::Model::from_toml(text, "fuzz.toml", ds) {
                let _ = m.law_for_run(0);
            }
        }
    }
});
