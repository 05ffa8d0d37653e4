//! `longreach run SCENARIO.toml`: a driven arm (URDF + rope transmissions + servos)
//! in time, with its time series and per-joint / per-rope metrics.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use comfy_table::{presets::UTF8_BORDERS_ONLY, Table};
use indicatif::{ProgressBar, ProgressStyle};

use crate::output::{write_atomic, write_atomic_with};
use crate::rerun_args::{self, RerunArgs};

/// Arguments of `longreach run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Arm scenario file (see docs/arm.md for the schema).
    pub scenario: PathBuf,
    /// Directory for `timeseries.csv` and `metrics.json` (created if missing).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write the metrics as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    pub rerun: RerunArgs,
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".into(), |x| format!("{x:.digits$}"))
}

/// Runs the scenario and prints the metrics tables.
pub fn run(args: &RunArgs) -> Result<ExitCode> {
    let sc = longreach_arm::scenario::load(&args.scenario).map_err(|e| anyhow::anyhow!("{e}"))?;
    for w in &sc.warnings {
        eprintln!("warning: {w}");
    }
    let arm = &sc.arm;
    let steps = (sc.sim.duration_s / arm.dt_s()).round() as u64;
    // A progress bar when the run is expected to take more than a second (~5 us/step
    // per link pair is a safe over-estimate).
    let expected_s = steps as f64 * 5e-6 * arm.spec().ndofs().max(1) as f64;
    let bar = if expected_s > 1.0 {
        let b = ProgressBar::new(steps);
        b.set_style(
            ProgressStyle::with_template("{bar:40} {pos}/{len} steps ({eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b
    } else {
        ProgressBar::hidden()
    };
    if let (Some(dir), Some(_)) = (&args.out, &args.rerun.rerun) {
        crate::output::output_dir(dir, "--out")?;
    }
    let rec = args.rerun.recorder(
        &args.scenario.display().to_string(),
        &rerun_args::default_rrd(args.out.as_deref(), &args.scenario, ""),
    )?;
    let mut viewer = longreach_viz::arm::ArmLogger::new(&rec, arm);
    let t0 = Instant::now();
    let result = longreach_arm::run::run_observed(
        arm,
        sc.sim.duration_s,
        sc.sim.output_every,
        sc.sim.residual_window_s,
        &mut |i, _| bar.set_position(i as u64),
        &mut |st| viewer.observe(st),
    );
    bar.finish_and_clear();
    let wall = t0.elapsed().as_secs_f64();
    // The recording of a failed run is kept: it shows how it failed. It is closed in
    // the background while the tables and files below are written (dropping `closing`
    // on an early return waits for it too).
    viewer.finish();
    let closing = rec.finish_in_background();
    let (trace, metrics) = result
        .map_err(|e| crate::Numerical(format!("running {}: {e}", args.scenario.display())))?;

    let mut jt = Table::new();
    jt.load_preset(UTF8_BORDERS_ONLY).set_header(vec![
        "joint",
        "move (deg)",
        "settling 2% (s)",
        "overshoot (%)",
        "residual vib. (mrad)",
        "final error (mrad)",
    ]);
    for j in &metrics.joints {
        jt.add_row(vec![
            j.joint.clone(),
            format!("{:.2}", j.move_rad.to_degrees()),
            opt(j.settling_time_s, 3),
            opt(j.overshoot_pct, 2),
            format!("{:.4}", 1e3 * j.residual_vibration_rad),
            format!("{:.4}", 1e3 * j.final_error_rad),
        ]);
    }
    let mut pt = Table::new();
    pt.load_preset(UTF8_BORDERS_ONLY).set_header(vec![
        "pair (joint)",
        "rope",
        "ropes",
        "peak tension (N)",
        "min tension (N)",
        "slack events",
        "safety factor",
        "static SF",
    ]);
    for p in &metrics.pairs {
        pt.add_row(vec![
            p.joint.clone(),
            p.rope.clone(),
            p.ropes_in_parallel.to_string(),
            format!("{:.1}", p.peak_tension_n),
            format!("{:.1}", p.min_tension_n),
            p.slack_events.to_string(),
            format!("{:.2}", p.safety_factor),
            format!("{:.2}", p.static_safety_factor),
        ]);
    }
    println!(
        "{}: {} steps of {} s in {wall:.2} s wall ({:.0}x real time, {:.2} Newton iterations/step)",
        args.scenario.display(),
        metrics.steps,
        arm.dt_s(),
        sc.sim.duration_s / wall.max(1e-9),
        metrics.mean_iterations
    );
    println!("{jt}");
    println!("{pt}");
    println!(
        "tip position error at the end: {:.3} mm",
        1e3 * metrics.tip_error_m
    );
    if let Some(d) = metrics.tip_deflection_m {
        println!(
            "of which the links' bending (tip vs straight links at the same joint angles): {:.3} mm",
            1e3 * d
        );
    }
    for p in &metrics.pairs {
        if p.safety_factor < 3.0 {
            println!(
                "note: pair {} ({}) peaks at {:.0} N per rope: safety factor {:.2} < 3",
                p.joint, p.rope, p.peak_tension_n, p.safety_factor
            );
        }
    }

    #[derive(serde::Serialize)]
    struct Out<'a> {
        #[serde(flatten)]
        metrics: &'a longreach_arm::run::RunMetrics,
        warnings: &'a [String],
    }
    let json = serde_json::to_string_pretty(&Out {
        metrics: &metrics,
        warnings: &sc.warnings,
    })?;
    if let Some(dir) = &args.out {
        crate::output::output_dir(dir, "--out")?;
        let csv_path = dir.join("timeseries.csv");
        write_atomic_with(&csv_path, |tmp| {
            let mut w = csv::Writer::from_path(tmp)?;
            w.write_record(&trace.columns)?;
            for r in &trace.rows {
                w.write_record(r.iter().map(|v| format!("{v:.9e}")))?;
            }
            w.flush()?;
            Ok(())
        })?;
        write_atomic(&dir.join("metrics.json"), json.as_bytes())?;
        println!("wrote {} and metrics.json", csv_path.display());
    }
    if let Some(path) = &args.json {
        write_atomic(path, json.as_bytes())?;
    }
    rerun_args::finished(closing);
    Ok(ExitCode::SUCCESS)
}
