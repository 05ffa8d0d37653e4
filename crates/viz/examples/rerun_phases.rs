//! Where the time of a recorded arm run goes: the run without logging, then with an
//! `.rrd` at 60 Hz split into open, static scene (+ blueprint), run, join (the logger's
//! drawing thread sends its last frames), close (waits for Rerun's file writer: the last
//! chunks and the file's footer); and the CPU time of the whole process (every
//! thread: the writer works beside the run) for both. Prints the minimum and the
//! median over the repetitions (the minimum is the robust figure on a busy machine).
//!
//! Run: `cargo run --release -p longreach-viz --example rerun_phases -- [SCENARIO] [SECONDS] [REPS]`

use std::time::Instant;

use longreach_viz::{arm::ArmLogger, Recorder, Target, DEFAULT_HZ};

/// CPU time of this process (all threads) so far, ms: utime + stime of /proc/self/stat
/// (clock ticks of 10 ms; 0 where /proc is missing).
fn cpu_ms() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name's closing parenthesis start at field 3; utime and
    // stime are fields 14 and 15.
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<f64> = after
        .split_whitespace()
        .map(|v| v.parse().unwrap_or(0.0))
        .collect();
    f.get(11)
        .zip(f.get(12))
        .map_or(0.0, |(u, s)| (u + s) * 10.0)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .unwrap_or_else(|| "scenarios/arm_dyneema2_distal_step.toml".into());
    let duration_s: f64 = args.next().map_or(10.0, |s| s.parse().expect("seconds"));
    let reps: usize = args.next().map_or(15, |s| s.parse().expect("repetitions"));
    let sc = longreach_arm::scenario::load(std::path::Path::new(&path)).expect("scenario");
    let dir = tempfile::tempdir().expect("temporary folder");
    let run = |observe: &mut dyn FnMut(&longreach_arm::DrivenState)| {
        longreach_arm::run::run_observed(
            &sc.arm,
            duration_s,
            sc.sim.output_every,
            sc.sim.residual_window_s,
            &mut |_, _| {},
            observe,
        )
        .expect("run")
    };
    let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
    let names = [
        "off", "open", "static", "run", "join", "close", "total", "cpu off", "cpu rec",
    ];
    let mut rows: Vec<[f64; 9]> = Vec::new();
    for _ in 0..reps {
        let c0 = cpu_ms();
        let t = Instant::now();
        run(&mut |_| {});
        let off = ms(t, Instant::now());
        let c1 = cpu_ms();
        let t0 = Instant::now();
        let target = Target::Save(Some(dir.path().join("arm.rrd")));
        let rec = Recorder::start("phases", &target, dir.path(), DEFAULT_HZ).expect("recording");
        let t1 = Instant::now();
        let mut viewer = ArmLogger::new(&rec, &sc.arm);
        let t2 = Instant::now();
        run(&mut |st| viewer.observe(st));
        let t3 = Instant::now();
        viewer.finish();
        let tj = Instant::now();
        rec.finish();
        let t4 = Instant::now();
        let c2 = cpu_ms();
        rows.push([
            off,
            ms(t0, t1),
            ms(t1, t2),
            ms(t2, t3),
            ms(t3, tj),
            ms(tj, t4),
            ms(t0, t4),
            c1 - c0,
            c2 - c1,
        ]);
    }
    for (stat, pick) in [("min", 0usize), ("median", reps / 2)] {
        let line: Vec<String> = names
            .iter()
            .enumerate()
            .map(|(c, name)| {
                let mut v: Vec<f64> = rows.iter().map(|r| r[c]).collect();
                v.sort_by(f64::total_cmp);
                format!("{name} {:.1}", v[pick])
            })
            .collect();
        println!("{stat:6} ms: {}", line.join(" | "));
    }
    // Each repetition runs without and with the recording back to back, so their
    // ratio cancels the machine's slow drifts (other jobs on a shared host).
    let mut ratios: Vec<f64> = rows.iter().map(|r| r[6] / r[0]).collect();
    ratios.sort_by(f64::total_cmp);
    let pct = |i: usize| 100.0 * (ratios[i] - 1.0);
    println!(
        "recorded run vs off, paired per repetition: median {:+.1}% (quartiles {:+.1}% .. {:+.1}%)",
        pct(reps / 2),
        pct(reps / 4),
        pct(3 * reps / 4)
    );
}
