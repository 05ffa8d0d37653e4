//! Scenario files: a Bode scenario and an arm scenario (its URDF paths relative to the
//! repository's `robots/`) parsed and validated from arbitrary text.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = longreach_scenario::BodeScenario::from_str(text, "fuzz.toml");
        let robots = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../robots"));
        let _ = longreach_arm::scenario::parse(text, "fuzz.toml", robots);
    }
});
