//! URDF loading (`longreach_arm::parse_urdf`) on arbitrary text: an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = longreach_arm::parse_urdf(text, "fuzz.urdf");
    }
});
