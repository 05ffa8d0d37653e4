//! `longreach modes SCENARIO.toml [--pose ...]`: the arm linearised at a pose (links,
//! their bending, ropes, motors, servos): natural frequencies, damping ratios and what
//! each mode moves and loads.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Args;
use comfy_table::{presets::UTF8_BORDERS_ONLY, Table};
use serde_json::json;

use crate::output::write_atomic;
use crate::rerun_args::{self, RerunArgs};

/// Arguments of `longreach modes`.
#[derive(Debug, Args)]
pub struct ModesArgs {
    /// Arm scenario file (see docs/arm.md for the schema).
    pub scenario: PathBuf,
    /// Joint angles of the pose, rad, comma-separated (default: the scenario's
    /// `initial_q_rad`).
    #[arg(
        long,
        value_name = "Q1,Q2,...",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub pose: Option<Vec<f64>>,
    /// Write the modes as JSON to this file.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Modes to print and to draw with `--rerun` (lowest first; the JSON holds them
    /// all).
    #[arg(long, default_value_t = 12)]
    pub top: usize,
    /// Draw the `--top` modes in Rerun: the arm oscillating along each mode shape (a
    /// tab per mode, with its frequency and damping). `--rerun-hz` is not used.
    #[command(flatten)]
    pub rerun: RerunArgs,
}

/// Linearises the scenario's arm and prints its modes.
pub fn run(args: &ModesArgs) -> Result<ExitCode> {
    let sc = longreach_arm::scenario::load(&args.scenario).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut arm = sc.arm;
    if let Some(q) = &args.pose {
        arm = arm
            .with_initial_q_rad(q.clone())
            .map_err(|e| anyhow::anyhow!("--pose: {e}"))?;
    }
    // A bad target or an unwritable file fails before the linearisation.
    let rec = args.rerun.recorder(
        &format!("modes {}", args.scenario.display()),
        &rerun_args::default_rrd(None, &args.scenario, "_modes"),
    )?;
    let m = match longreach_arm::modes::modes(&arm) {
        Ok(m) => m,
        Err(e) => {
            // Nothing to draw: no recording is left behind.
            rec.discard();
            return Err(e).with_context(|| format!("linearising {}", args.scenario.display()));
        }
    };
    longreach_viz::modes::log_modes(&rec, &arm, &m, args.top);
    let closing = rec.finish_in_background();
    let spec = arm.spec();
    let mut t = Table::new();
    t.load_preset(UTF8_BORDERS_ONLY).set_header(vec![
        "mode",
        "f_n [Hz]",
        "f_d [Hz]",
        "zeta",
        "energy in (largest shares)",
        "largest joint motion",
    ]);
    for (i, md) in m.modes.iter().take(args.top).enumerate() {
        let parts = md
            .shares
            .iter()
            .take(3)
            .filter(|s| s.share >= 0.01)
            .map(|s| format!("{} {:.0}%", s.part, 100.0 * s.share))
            .collect::<Vec<_>>()
            .join(", ");
        let (j, q) = md
            .joints_rad
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            .map_or((0, 0.0), |(j, q)| (j, *q));
        t.add_row(vec![
            format!("{}", i + 1),
            format!("{:.3}", md.natural_hz),
            format!("{:.3}", md.damped_hz),
            format!("{:.4}", md.damping_ratio),
            parts,
            if q.abs() > 1e-9 {
                format!("{} {:+.2e} rad/sqrt(J)", spec.joints[j].name, q)
            } else {
                "none (bending across the joints' plane)".into()
            },
        ]);
    }
    println!(
        "{}: {} modes at pose {:?} rad (dt {} s; {} real poles: creep, settling)",
        args.scenario.display(),
        m.modes.len(),
        m.pose_rad,
        m.dt_s,
        m.real_poles
    );
    println!("{t}");
    if let Some(path) = &args.json {
        let modes: Vec<_> = m
            .modes
            .iter()
            .map(|md| {
                json!({
                    "natural_hz": md.natural_hz,
                    "damped_hz": md.damped_hz,
                    "damping_ratio": md.damping_ratio,
                    "shares": md.shares.iter().map(|s| json!({"part": s.part, "share": s.share})).collect::<Vec<_>>(),
                    "joints_rad": spec.joints.iter().zip(&md.joints_rad).map(|(j, q)| json!({"joint": j.name, "angle": q})).collect::<Vec<_>>(),
                    "link_ends_m": md.link_end_m.iter().map(|(l, d)| json!({"link": l, "in_plane": d[0], "out_of_plane": d[1]})).collect::<Vec<_>>(),
                    "motors_rad": md.motors_rad,
                    "tensions_n": md.tensions_n,
                })
            })
            .collect();
        let doc = json!({
            "scenario": args.scenario.display().to_string(),
            "pose_rad": m.pose_rad,
            "dt_s": m.dt_s,
            "real_poles": m.real_poles,
            "scale": "amplitudes at 1 J of potential energy in the ropes, links and servos",
            "modes": modes,
        });
        write_atomic(path, serde_json::to_string_pretty(&doc)?.as_bytes())?;
    }
    rerun_args::finished(closing);
    Ok(ExitCode::SUCCESS)
}
