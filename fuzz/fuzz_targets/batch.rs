//! Batch files: parsed and expanded (its `base = "..."` relative to the repository's
//! `scenarios/`), then the first and last scenarios built.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios"));
        let kinds = longreach_scenario::batch::builtin_kinds();
        if let Ok(b) = longreach_scenario::batch::Batch::from_str(text, "fuzz.toml", "fuzz", dir, &kinds) {
            if !b.is_empty() {
                let _ = b.scenario(0);
                let _ = b.scenario(b.len() - 1);
            }
        }
    }
});
