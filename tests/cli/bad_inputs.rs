//! The bad-input corpus (`tests/bad_inputs/<group>/<case>/`): every case is a broken
//! input a user could give (URDF, scenario, batch, journal, dataset, model file, output
//! path) with `case.toml` saying how to run it and what must come out:
//!
//! ```toml
//! args = ["bode", "scenario.toml"]   # relative to the case's copy; {repo} = this repo
//! exit = 2                           # the exit code (README "Exit codes")
//! contains = ["sweep.settle_s", "fix"]   # words the output must hold (case-insensitive)
//! keep = ["photos/cat.txt"]          # files that must be byte-identical afterwards
//! stdout_closed = true               # optional: run with a closed stdout
//! written = { "m.json" = ["warnings"] }  # optional: files written, with words they hold
//! ```
//!
//! Each case runs on a copy in a temporary folder, with a timeout (a hang fails and is
//! killed). Checked for every case: the exit code, the words, no panic and no abort,
//! nothing of the user's lost (`keep`), no temporary (`.partial`, `.old`) left behind.
//! Every failure of the corpus is reported at once.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(60);

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Case {
    args: Vec<String>,
    exit: i32,
    #[serde(default)]
    contains: Vec<String>,
    #[serde(default)]
    keep: Vec<String>,
    #[serde(default)]
    stdout_closed: bool,
    /// Files the command must write, with words each must hold (e.g. a warning
    /// recorded in the JSON).
    #[serde(default)]
    written: std::collections::BTreeMap<String, Vec<String>>,
}

fn corpus() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/bad_inputs")
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// Files under `dir` (relative paths), folders included.
fn listing(dir: &Path, base: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let p = entry.path();
        out.push(p.strip_prefix(base).unwrap().to_path_buf());
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            listing(&p, base, out);
        }
    }
}

fn cases() -> Vec<PathBuf> {
    let mut found = Vec::new();
    for group in std::fs::read_dir(corpus()).unwrap().flatten() {
        if !group.file_type().unwrap().is_dir() {
            continue;
        }
        for case in std::fs::read_dir(group.path()).unwrap().flatten() {
            if case.path().join("case.toml").is_file() {
                found.push(case.path());
            }
        }
    }
    found.sort();
    found
}

/// Runs one case; `Err` says everything that went wrong with it.
fn run_case(dir: &Path) -> Result<(), String> {
    let text = std::fs::read_to_string(dir.join("case.toml")).unwrap();
    let case: Case = toml::from_str(&text).map_err(|e| format!("case.toml: {e}"))?;
    let tmp = tempfile::tempdir().unwrap();
    let work = tmp.path().join("case");
    copy_dir(dir, &work);
    let repo = env!("CARGO_MANIFEST_DIR");
    let args: Vec<String> = case
        .args
        .iter()
        .map(|a| a.replace("{repo}", repo))
        .collect();
    // A closed stdout: a pipe whose reading end is closed before the child starts.
    let stdout_to = if case.stdout_closed {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        Stdio::from(writer)
    } else {
        Stdio::piped()
    };
    let mut child = Command::new(env!("CARGO_BIN_EXE_longreach"))
        .args(&args)
        .current_dir(&work)
        .stdin(Stdio::null())
        .stdout(stdout_to)
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start longreach: {e}"))?;
    let mut stderr = child.stderr.take().unwrap();
    let out_reader = child.stdout.take().map(|mut stdout| {
        std::thread::spawn(move || {
            let mut s = String::new();
            let _ = stdout.read_to_string(&mut s);
            s
        })
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let out = out_reader.map(|r| r.join().unwrap()).unwrap_or_default();
    let err = err_reader.join().unwrap();
    let all = format!("{out}\n{err}");
    let mut problems = Vec::new();
    match status {
        None => problems.push(format!("hang: killed after {} s", TIMEOUT.as_secs())),
        Some(s) => match s.code() {
            Some(c) if c == case.exit => {}
            Some(c) => problems.push(format!("exit {c}, expected {}", case.exit)),
            None => problems.push(format!("killed by a signal (abort?): {s}")),
        },
    }
    if all.contains("panicked") || all.contains("RUST_BACKTRACE") {
        problems.push("panicked".into());
    }
    let lower = all.to_lowercase();
    for word in &case.contains {
        if !lower.contains(&word.to_lowercase()) {
            problems.push(format!("output lacks \"{word}\""));
        }
    }
    for kept in &case.keep {
        let before = std::fs::read(dir.join(kept)).map_err(|e| format!("keep {kept}: {e}"))?;
        match std::fs::read(work.join(kept)) {
            Ok(after) if after == before => {}
            Ok(_) => problems.push(format!("{kept} was changed")),
            Err(_) => problems.push(format!("{kept} was lost")),
        }
    }
    for (file, words) in &case.written {
        match std::fs::read_to_string(work.join(file)) {
            Ok(text) => {
                for w in words.iter().filter(|w| !text.contains(w.as_str())) {
                    problems.push(format!("{file} lacks \"{w}\""));
                }
            }
            Err(_) => problems.push(format!("{file} was not written")),
        }
    }
    let mut files = Vec::new();
    listing(tmp.path(), tmp.path(), &mut files);
    for f in files {
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        if name.contains(".partial") || name.ends_with(".old") || name.contains(".old.") {
            problems.push(format!("left behind: {}", f.display()));
        }
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{}\n    stdout: {}\n    stderr: {}",
            problems.join("; "),
            out.trim()
                .lines()
                .take(5)
                .collect::<Vec<_>>()
                .join("\n            "),
            err.trim()
                .lines()
                .take(8)
                .collect::<Vec<_>>()
                .join("\n            ")
        ))
    }
}

#[test]
fn bad_inputs_corpus() {
    let all = cases();
    assert!(!all.is_empty(), "no cases under {}", corpus().display());
    // Two at a time: the cases are small, and the machine is shared.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(dir) = all.get(i) else { break };
                if let Err(e) = run_case(dir) {
                    let name = dir.strip_prefix(corpus()).unwrap().display().to_string();
                    failures.lock().unwrap().push(format!("{name}: {e}"));
                }
            });
        }
    });
    let mut failures = failures.into_inner().unwrap();
    failures.sort();
    eprintln!(
        "bad-input corpus: {} cases, {} passed",
        all.len(),
        all.len() - failures.len()
    );
    assert!(
        failures.is_empty(),
        "{} of {} cases failed:\n{}",
        failures.len(),
        all.len(),
        failures.join("\n")
    );
}
