//! `longreach bode SCENARIO.toml`: the rig's frequency response, analytic (eqs. 12-13)
//! beside simulated (stepped sine, single-bin DFT over whole cycles after settling).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Args;
use comfy_table::{presets::UTF8_BORDERS_ONLY, Table};
use rayon::prelude::*;
use serde::Serialize;

use longreach_plot::{bode_figure, write_png, BodeCurve, Style};
use longreach_scenario::{BodeRun, BodeScenario};

use crate::output::{write_atomic, write_atomic_with};
use crate::rerun_args::{self, RerunArgs};

/// Arguments of `longreach bode`.
#[derive(Debug, Args)]
pub struct BodeArgs {
    /// Bode scenario file (see scenarios/README.md).
    pub scenario: PathBuf,
    /// Write every point as CSV.
    #[arg(long, value_name = "FILE")]
    pub csv: Option<PathBuf>,
    /// Write a Bode plot (PNG): gain and phase, one colour per mean tension.
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
    /// Write the results as JSON.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Print only the summary (resonances), not every frequency.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub rerun: RerunArgs,
}

#[derive(Serialize)]
struct Pair {
    analytic: Option<f64>,
    simulated: Option<f64>,
}

#[derive(Serialize)]
struct JsonRun<'a> {
    mean_tension_n: f64,
    resonance_hz: Pair,
    peak_gain_db: Pair,
    slack: bool,
    points: &'a [longreach_drive::FrequencyPoint],
}

#[derive(Serialize)]
struct JsonOut<'a> {
    title: &'a str,
    rope: &'a str,
    law: String,
    dt_s: f64,
    runs: Vec<JsonRun<'a>>,
    warnings: &'a [String],
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "none in range".into(), |v| format!("{v:.digits$}"))
}

/// Runs the scenario and writes what was asked.
pub fn run(args: &BodeArgs) -> Result<ExitCode> {
    let scenario = BodeScenario::from_file(&args.scenario)?;
    for w in &scenario.warnings {
        eprintln!("warning: {w}");
    }
    let rec = args.rerun.recorder(
        &args.scenario.display().to_string(),
        &rerun_args::default_rrd(None, &args.scenario, ""),
    )?;
    let runs = simulate(&scenario, &rec)
        .with_context(|| format!("simulating {}", args.scenario.display()));
    // The recording is closed in the background while the tables and files below are
    // written (dropping `closing` on an early return waits for it too).
    let closing = rec.finish_in_background();
    let runs = runs?;
    let rig = &scenario.rigs[0];
    let law = if rig.law.c2_n_s.is_some() {
        if rig.law.kp_n.is_some() {
            "flory"
        } else {
            "four_element"
        }
    } else {
        "elastic"
    };
    println!(
        "{}\nrope {} ({law}), L = {} m, r1 = {} m, r2 = {} m, I = {} kg*m^2, C = {} N*m*s, amplitude {:.2} deg, dt = {} s",
        if scenario.title.is_empty() { args.scenario.display().to_string() } else { scenario.title.clone() },
        rig.rope_name,
        rig.rope_length_m,
        rig.input_radius_m,
        rig.output_radius_m,
        rig.output_inertia_kg_m2,
        rig.output_damping_n_m_s,
        scenario.sine.amplitude_rad.to_degrees(),
        scenario.dt_s
    );
    let mut summary = Table::new();
    summary.load_preset(UTF8_BORDERS_ONLY).set_header([
        "mean tension [N]",
        "resonance analytic [Hz]",
        "resonance simulated [Hz]",
        "peak analytic [dB]",
        "peak simulated [dB]",
        "rope slack",
    ]);
    for r in &runs {
        summary.add_row([
            format!("{:.0}", r.mean_tension_n),
            fmt_opt(r.analytic.map(|x| x.frequency_hz), 3),
            fmt_opt(r.simulated.map(|x| x.frequency_hz), 3),
            fmt_opt(r.analytic.map(|x| x.peak_gain_db), 2),
            fmt_opt(r.simulated.map(|x| x.peak_gain_db), 2),
            if r.slack { "yes" } else { "no" }.to_string(),
        ]);
    }
    if !args.quiet {
        for r in &runs {
            let mut t = Table::new();
            t.load_preset(UTF8_BORDERS_ONLY).set_header([
                "frequency [Hz]",
                "analytic gain [dB]",
                "analytic phase [deg]",
                "simulated gain [dB]",
                "simulated phase [deg]",
                "min tension [N]",
            ]);
            for p in &r.points {
                t.add_row([
                    format!("{:.2}", p.frequency_hz),
                    format!("{:.3}", p.analytic_gain_db),
                    format!("{:.2}", p.analytic_phase_deg),
                    format!("{:.3}", p.simulated_gain_db),
                    format!("{:.2}", p.simulated_phase_deg),
                    format!("{:.1}", p.min_tension_n),
                ]);
            }
            println!("\nmean tension {:.0} N\n{t}", r.mean_tension_n);
        }
    }
    println!("\n{summary}");
    println!("Simulated resonance: the largest test-frequency gain refined by a parabola; a slack rope clips the torque at 2*r2*T.");

    if let Some(path) = &args.csv {
        let mut w = csv::Writer::from_writer(Vec::new());
        w.write_record([
            "mean_tension_n",
            "frequency_hz",
            "analytic_gain_db",
            "analytic_phase_deg",
            "simulated_gain_db",
            "simulated_phase_deg",
            "min_tension_n",
        ])?;
        for r in &runs {
            for p in &r.points {
                w.write_record(
                    [
                        r.mean_tension_n,
                        p.frequency_hz,
                        p.analytic_gain_db,
                        p.analytic_phase_deg,
                        p.simulated_gain_db,
                        p.simulated_phase_deg,
                        p.min_tension_n,
                    ]
                    .map(|v| v.to_string()),
                )?;
            }
        }
        write_atomic(path, &w.into_inner()?)?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &args.json {
        let out = JsonOut {
            title: &scenario.title,
            rope: &rig.rope_name,
            law: law.to_string(),
            dt_s: scenario.dt_s,
            warnings: &scenario.warnings,
            runs: runs
                .iter()
                .map(|r| JsonRun {
                    mean_tension_n: r.mean_tension_n,
                    resonance_hz: Pair {
                        analytic: r.analytic.map(|x| x.frequency_hz),
                        simulated: r.simulated.map(|x| x.frequency_hz),
                    },
                    peak_gain_db: Pair {
                        analytic: r.analytic.map(|x| x.peak_gain_db),
                        simulated: r.simulated.map(|x| x.peak_gain_db),
                    },
                    slack: r.slack,
                    points: &r.points,
                })
                .collect(),
        };
        write_atomic(path, serde_json::to_string_pretty(&out)?.as_bytes())?;
        println!("wrote {}", path.display());
    }
    if let Some(path) = &args.png {
        let mut curves = Vec::new();
        for (i, r) in runs.iter().enumerate() {
            let f: Vec<f64> = r.points.iter().map(|p| p.frequency_hz).collect();
            // The analytic curve drawn densely, the simulated points as markers.
            let (f_lo, f_hi) = (f[0].min(f[f.len() - 1]), f[0].max(f[f.len() - 1]));
            let dense: Vec<f64> = (0..=300)
                .map(|k| f_lo * (f_hi / f_lo).powf(k as f64 / 300.0))
                .collect();
            let spec = &scenario.rigs[i];
            let (g, ph): (Vec<f64>, Vec<f64>) = dense
                .iter()
                .map(|&fr| longreach_drive::tf::gain_phase(longreach_drive::rig_transfer(spec, fr)))
                .unzip();
            curves.push(BodeCurve {
                label: format!("{:.0} N analytic", r.mean_tension_n),
                frequency_hz: dense,
                gain_db: g,
                phase_deg: longreach_drive::freq::unwrap_deg(&ph),
                style: Style::Line,
                color: i,
            });
            curves.push(BodeCurve {
                label: format!(
                    "{:.0} N simulated{}",
                    r.mean_tension_n,
                    if r.slack { " (slack)" } else { "" }
                ),
                frequency_hz: f,
                gain_db: r.points.iter().map(|p| p.simulated_gain_db).collect(),
                phase_deg: r.points.iter().map(|p| p.simulated_phase_deg).collect(),
                style: Style::Markers,
                color: i,
            });
        }
        let title = format!(
            "{}: rope {}, analytic (eq. 12/13) vs simulated",
            if scenario.title.is_empty() {
                "Bode"
            } else {
                &scenario.title
            },
            rig.rope_name
        );
        write_atomic_with(path, |tmp| {
            Ok(write_png(&bode_figure(&title, &curves), tmp)?)
        })?;
        println!("wrote {}", path.display());
    }
    rerun_args::finished(closing);
    Ok(ExitCode::SUCCESS)
}

/// Simulates every mean tension of `scenario` in parallel and, when `rec` records,
/// logs the runs (each trace kept only at the logging rate).
pub fn simulate(
    scenario: &BodeScenario,
    rec: &longreach_viz::Recorder,
) -> Result<Vec<BodeRun>, longreach_drive::DriveError> {
    if !rec.is_enabled() {
        return (0..scenario.rigs.len())
            .into_par_iter()
            .map(|i| scenario.run_one(i))
            .collect();
    }
    // Each run is logged (on the logger's thread) as soon as it is done, while the
    // others are still running.
    let tensions_n: Vec<f64> = scenario.rigs.iter().map(|r| r.mean_tension_n).collect();
    let logger = longreach_viz::rig::BodeLogger::new(rec, &scenario.rigs[0], &tensions_n);
    let runs = (0..scenario.rigs.len())
        .into_par_iter()
        .map(|i| {
            let (run, trace) = scenario.run_one_traced(i)?;
            logger.log_run(i, &trace, &run.points);
            Ok(run)
        })
        .collect();
    logger.finish();
    runs
}
