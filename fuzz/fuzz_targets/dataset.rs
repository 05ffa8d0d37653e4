//! Measurement datasets: the input is `dataset.toml`, a line `----`, then the text of
//! a CSV written under every run-file name the examples use; `Dataset::load` on it.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let (toml, csv) = text.split_once("\n----\n").unwrap_or((&text, ""));
    let base = if std::path::Path::new("/dev/shm").is_dir() { "/dev/shm" } else { "/tmp" };
    let Ok(dir) = tempfile::tempdir_in(base) else { return };
    let _ = std::fs::write(dir.path().join("dataset.toml"), toml);
    for name in ["run.csv", "run_01.csv", "relax.csv", "cyclic.csv", "frf.csv", "frf_01.csv"] {
        let _ = std::fs::write(dir.path().join(name), csv);
    }
    let _ = longreach_ident::Dataset::load(dir.path());
});
