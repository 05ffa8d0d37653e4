//! `longreach compare` and `longreach synth` on arm datasets (`arm_moves`): the tables,
//! the JSON and the report of [`longreach_ident::analysis::compare_arm`], and the
//! `--arm` form of `synth`.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{anyhow, bail, Context, Result};
use comfy_table::Table;

use longreach_ident::analysis::{self, ArmComparison, Figures};
use longreach_ident::model::Model;
use longreach_ident::plant::{ArmPoses, Channels};
use longreach_ident::synth::{self, ArmMove, ArmMovesOptions};
use longreach_ident::{ArmMovesDataset, Dataset, DatasetKind};
use longreach_plot::{write_png, Figure, Panel, Series, Style};

use crate::output::{write_atomic, write_atomic_with};
use crate::rerun_args::{self, RerunArgs};

fn opt(x: Option<f64>, digits: usize) -> String {
    x.map_or("-".into(), |v| format!("{v:.digits$}"))
}

/// Prints the comparison of an arm dataset: the channels, where it fails, the figures.
pub fn print_arm_comparison(c: &ArmComparison) {
    let mut t = Table::new();
    t.set_header(vec![
        "run", "channel", "NRMSE", "floor", "x floor", "move", "settling",
    ]);
    for e in &c.channels {
        t.add_row(vec![
            e.run.clone(),
            e.channel.clone(),
            format!("{:.4}", e.nrmse),
            format!("{:.4}", e.noise_floor_nrmse),
            format!("{:.2}", e.ratio),
            opt(e.ratio_move, 2),
            opt(e.ratio_settling, 2),
        ]);
    }
    println!("{t}");
    println!(
        "worst channel at {:.2}x its noise floor ({} channels; within 1.5x: {})",
        c.worst_ratio,
        c.channels.len(),
        c.channels.iter().filter(|e| e.ratio <= 1.5).count()
    );
    let mut w = Table::new();
    w.set_header(vec![
        "where it fails: run",
        "channel",
        "phase",
        "window [s]",
        "x floor",
        "share",
    ]);
    for p in c.worst_windows.iter().take(5) {
        w.add_row(vec![
            p.run.clone(),
            p.channel.clone(),
            p.phase.to_string(),
            format!("{:.2}-{:.2}", p.start_s, p.end_s),
            format!("{:.1}", p.ratio),
            format!("{:.1}%", 100.0 * p.share),
        ]);
    }
    println!("{w}");
    println!("{}", figures_table(c));
    let told =
        analysis::describe_findings("What the sensors show against the model: ", &c.findings);
    if !told.is_empty() {
        println!("{told}");
    }
}

fn figure_cells(f: &Figures) -> [String; 6] {
    [
        opt(f.settling_time_s, 2),
        opt(f.overshoot_pct, 1),
        opt(f.vibration_hz, 2),
        opt(f.damping_ratio, 3),
        opt(f.peak_tension_n, 0),
        opt(f.min_tension_n, 0),
    ]
}

fn figures_table(c: &ArmComparison) -> Table {
    let mut t = Table::new();
    t.set_header(vec![
        "move: run",
        "joint",
        "",
        "settling 2% [s]",
        "overshoot [%]",
        "vibration [Hz]",
        "damping ratio",
        "peak tension [N]",
        "min tension [N]",
    ]);
    for m in &c.figures {
        for (label, f) in [("measured", &m.measured), ("model", &m.model)] {
            let mut row = vec![m.run.clone(), m.joint.clone(), label.to_string()];
            row.extend(figure_cells(f));
            t.add_row(row);
        }
    }
    t
}

/// The simulation step of an arm dataset, chosen from the data with `model`
/// ([`analysis::choose_arm_step`]), printed with every halving tried.
pub fn choose_step(ds: &Dataset, model: &Model) -> Result<analysis::SimulationStep> {
    let prep = analysis::Prepared::new(ds).map_err(|e| anyhow!("{e}"))?;
    let s = analysis::choose_arm_step(&prep, model).map_err(|e| anyhow!("{e}"))?;
    println!("{}", step_words(&s));
    Ok(s)
}

/// One line on the chosen step: its size and why.
pub fn step_words(s: &analysis::SimulationStep) -> String {
    let tried = s
        .trials
        .iter()
        .map(|t| {
            format!(
                "{:.4} ms: NRMSE {:.5}, halving moves the channels {:.2} sigma",
                1e3 * t.step_s,
                t.nrmse,
                t.change_sigma
            )
        })
        .collect::<Vec<_>>()
        .join("; ");
    format!(
        "simulation step {:.4} ms ({}; {tried}){}",
        1e3 * s.step_s,
        if s.converged {
            format!(
                "the coarsest whose halving moves the channels by <= {} sigma of their noise",
                analysis::STEP_TOLERANCE_SIGMA
            )
        } else {
            format!(
                "the finest tried: halving it still moves the channels by more than {} sigma",
                analysis::STEP_TOLERANCE_SIGMA
            )
        },
        if s.converged {
            ""
        } else {
            "; the model's own step error may show in the comparison"
        }
    )
}

/// Runs `compare` on an arm dataset (`path`); with `--rerun`, draws the measured and
/// the model arm of every run and every channel, measured against model.
pub fn run_compare_arm(
    ds: &Dataset,
    path: &Path,
    model: &Model,
    json: Option<&Path>,
    report: Option<&Path>,
    rerun: &RerunArgs,
) -> Result<ExitCode> {
    let rec = rerun.recorder(
        &format!("compare {}", path.display()),
        &rerun_args::default_rrd(None, path, "_compare"),
    )?;
    let step = match choose_step(ds, model) {
        Ok(s) => s,
        Err(e) => {
            rec.discard();
            return Err(e);
        }
    };
    // With Rerun on, the simulations keep the model arm's coordinates (the same
    // channels: the states are only read).
    let simulated = if rec.is_enabled() {
        analysis::simulate_arm_poses(ds, model, step.refinement).map(|v| v.into_iter().unzip())
    } else {
        analysis::simulate_arm(ds, model, step.refinement).map(|s| (s, Vec::new()))
    };
    let (sims, poses): (Vec<Channels>, Vec<ArmPoses>) = match simulated {
        Ok(v) => v,
        Err(e) => {
            // Nothing to draw: no recording is left behind.
            rec.discard();
            bail!("{e}");
        }
    };
    let c = match analysis::compare_arm(ds, &sims) {
        Ok(c) => ArmComparison {
            step: Some(step),
            ..c
        },
        Err(e) => {
            rec.discard();
            bail!("{e}");
        }
    };
    if let Some(am) = analysis::arm_dataset(ds) {
        longreach_viz::arm_compare::log_arm_comparison(&rec, am, &sims, &poses, None, None);
    }
    rerun_args::finish(rec);
    print_arm_comparison(&c);
    if let Some(p) = json {
        write_atomic(p, serde_json::to_string_pretty(&c)?.as_bytes())?;
    }
    if let Some(dir) = report {
        write_arm_report(dir, ds, &c, &sims)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `diagnose --rerun` on an arm dataset: the measured and model arms and channels of
/// the fitted baseline `base`, the channels of the model with the winning effect
/// `winner`, and the ranking. A simulation that fails here is reported and skipped
/// (drawing never stops a command).
pub fn log_arm_diagnosis(
    rec: &longreach_viz::Recorder,
    ds: &Dataset,
    d: &analysis::Diagnosis,
    base: &Model,
    winner: Option<&Model>,
    refinement: usize,
) {
    let Some(am) = analysis::arm_dataset(ds) else {
        return;
    };
    if !rec.is_enabled() {
        return;
    }
    let (sims, poses): (Vec<Channels>, Vec<ArmPoses>) =
        match analysis::simulate_arm_poses(ds, base, refinement) {
            Ok(v) => v.into_iter().unzip(),
            Err(e) => {
                eprintln!(
                    "rerun: simulating the baseline to draw it failed ({e}); diagnose goes on"
                );
                (Vec::new(), Vec::new())
            }
        };
    let after = winner.and_then(|m| match analysis::simulate_arm(ds, m, refinement) {
        Ok(s) => Some(s),
        Err(e) => {
            eprintln!(
                "rerun: simulating the winning model to draw it failed ({e}); diagnose goes on"
            );
            None
        }
    });
    longreach_viz::arm_compare::log_arm_comparison(
        rec,
        am,
        &sims,
        &poses,
        Some(d),
        after.as_deref(),
    );
}

/// `report.md` (the tables) and one PNG per run: measured against model, one panel per
/// driven joint (its joint angle when measured, else its motor angle).
fn write_arm_report(dir: &Path, ds: &Dataset, c: &ArmComparison, sims: &[Channels]) -> Result<()> {
    let DatasetKind::ArmMoves(am) = &ds.kind else {
        bail!("not an arm dataset");
    };
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut md = format!(
        "# {} — model vs measurement (arm)\n\nWorst channel at **{:.2}x** its noise floor.\n\n",
        c.dataset, c.worst_ratio
    );
    if let Some(s) = &c.step {
        md.push_str(&format!("{}.\n\n", step_words(s)));
    }
    md.push_str("| run | channel | NRMSE | floor | x floor | move | settling |\n|---|---|---|---|---|---|---|\n");
    for e in &c.channels {
        md.push_str(&format!(
            "| {} | {} | {:.4} | {:.4} | {:.2} | {} | {} |\n",
            e.run,
            e.channel,
            e.nrmse,
            e.noise_floor_nrmse,
            e.ratio,
            opt(e.ratio_move, 2),
            opt(e.ratio_settling, 2)
        ));
    }
    md.push_str("\n## Where it fails\n\n| run | channel | phase | window [s] | x floor | share |\n|---|---|---|---|---|---|\n");
    for p in c.worst_windows.iter().take(5) {
        md.push_str(&format!(
            "| {} | {} | {} | {:.2}-{:.2} | {:.1} | {:.1}% |\n",
            p.run,
            p.channel,
            p.phase,
            p.start_s,
            p.end_s,
            p.ratio,
            100.0 * p.share
        ));
    }
    md.push_str("\n## Vibration figures\n\n| run | joint | | settling 2% [s] | overshoot [%] | vibration [Hz] | damping ratio | peak tension [N] | min tension [N] |\n|---|---|---|---|---|---|---|---|---|\n");
    for m in &c.figures {
        for (label, f) in [("measured", &m.measured), ("model", &m.model)] {
            md.push_str(&format!(
                "| {} | {} | {label} | {} |\n",
                m.run,
                m.joint,
                figure_cells(f).join(" | ")
            ));
        }
    }
    md.push_str("\n## What the sensors show\n\n");
    findings_table(&mut md, &c.findings);
    md.push_str("\n## Pictures\n\n");
    md.push_str(&joint_pictures(
        dir,
        am,
        &format!("{}: measured vs model", c.dataset),
        "arm",
        &[("model".into(), sims)],
    )?);
    write_atomic(&dir.join("report.md"), md.as_bytes())?;
    Ok(())
}

/// The arm's part of `diagnose --report`: the arm's findings against the baseline and
/// against the named model (else the lead's), the values per joint of a split effect,
/// and one picture per run (`arm_diagnosis_<run>.png`) of every driven joint measured,
/// with the baseline and the named model; returns the markdown.
pub fn arm_diagnosis_report(
    dir: &Path,
    ds: &Dataset,
    d: &analysis::Diagnosis,
    base: &Model,
    winner: Option<&Model>,
    refinement: usize,
) -> Result<String> {
    let DatasetKind::ArmMoves(am) = &ds.kind else {
        bail!("not an arm dataset");
    };
    crate::output::output_dir(dir, "--report")?;
    let mut md = String::from("\n## The arm\n\n");
    let table = |md: &mut String, title: &str, f: &[analysis::ArmFinding]| {
        md.push_str(&format!("### {title}\n\n"));
        findings_table(md, f);
    };
    table(
        &mut md,
        "What the sensors show against the baseline",
        &d.arm_findings,
    );
    let after_of = if d.missing_effects.is_empty() {
        d.lead.as_ref().map(|l| l.effects.join(" + "))
    } else {
        Some(d.missing_effects.join(" + "))
    };
    if let Some(of) = &after_of {
        table(
            &mut md,
            &format!("Against the model with {of}"),
            &d.arm_findings_after,
        );
    }
    for s in &d.joint_splits {
        md.push_str(&format!(
            "### {} per {} ({}; NRMSE {:.4} against {:.4} with one value, BIC improvement {:.1})\n\n| {}s | parameter | value | 95% interval |\n|---|---|---|---|\n",
            s.effect,
            s.per,
            if s.kept { "kept" } else { "not kept" },
            s.nrmse,
            s.nrmse_shared,
            s.score,
            s.per
        ));
        for j in &s.joints {
            for ((name, v), [lo, hi]) in j.values.iter().zip(&j.interval_95) {
                md.push_str(&format!(
                    "| {} | {name} | {v:.6} | [{lo:.6}, {hi:.6}] |\n",
                    j.joint
                ));
            }
        }
        md.push('\n');
    }
    let sims = analysis::simulate_arm(ds, base, refinement).map_err(|e| anyhow!("{e}"))?;
    let after = match winner {
        Some(m) => Some(analysis::simulate_arm(ds, m, refinement).map_err(|e| anyhow!("{e}"))?),
        None => None,
    };
    let mut models = vec![("baseline".to_string(), sims.as_slice())];
    if let Some(a) = &after {
        models.push((
            format!("with {}", d.missing_effects.join(" + ")),
            a.as_slice(),
        ));
    }
    md.push_str(&joint_pictures(
        dir,
        am,
        &format!("{}: measured, baseline, named model", ds.title),
        "arm_diagnosis",
        &models,
    )?);
    Ok(md)
}

/// The arm's findings as a markdown table ("nothing" when there are none).
fn findings_table(md: &mut String, f: &[analysis::ArmFinding]) {
    if f.is_empty() {
        md.push_str("Nothing beyond the tolerances (docs/models.md, \"The arm's evidence\").\n\n");
        return;
    }
    md.push_str(
        "| joint | what | measured | model | runs | finding |\n|---|---|---|---|---|---|\n",
    );
    for x in f {
        md.push_str(&format!(
            "| {} | {} | {:.4} | {:.4} | {} of {} | {} |\n",
            x.joint,
            x.kind,
            x.measured,
            x.model,
            x.runs.len(),
            x.of_runs,
            x.sentence
        ));
    }
    md.push('\n');
}

/// One picture per run, `{prefix}_{run}.png`, a panel per driven joint: its angle
/// measured (the joint encoder, else the motor's) and as each of `models` (label, the
/// channels of every run) simulated it; returns the markdown that shows them.
fn joint_pictures(
    dir: &Path,
    am: &ArmMovesDataset,
    title: &str,
    prefix: &str,
    models: &[(String, &[Channels])],
) -> Result<String> {
    let mut md = String::new();
    for (r, run) in am.runs.iter().enumerate() {
        let mut panels = Vec::new();
        for (k, joint) in am.joints.iter().enumerate() {
            let Some(ch) = run.angle_channel(k).map(|i| &run.channels[i]) else {
                continue;
            };
            let mut series = vec![Series {
                label: format!("{} measured", ch.name),
                x: run.time_s.clone(),
                y: ch.values.clone(),
                style: Style::Line,
                color: 0,
            }];
            for (i, (label, sims)) in models.iter().enumerate() {
                if let Some(y) = sims.get(r).and_then(|s| s.get(&ch.name)) {
                    series.push(Series {
                        label: label.clone(),
                        x: run.time_s.clone(),
                        y: y.to_vec(),
                        style: if i == 0 {
                            Style::DashedLine
                        } else {
                            Style::Line
                        },
                        color: i + 1,
                    });
                }
            }
            panels.push(Panel {
                y_label: format!("{joint} [rad]"),
                series,
                y_range: None,
                log_y: false,
            });
        }
        let fig = Figure {
            title: format!("{title} ({})", run.name),
            x_label: "time [s]".into(),
            log_x: false,
            height_px: longreach_plot::min_height_px(panels.len()).max(600),
            panels,
            width_px: 1000,
        };
        let name = format!("{prefix}_{}.png", run.name);
        write_atomic_with(&dir.join(&name), |p| Ok(write_png(&fig, p)?))?;
        md.push_str(&format!("![{name}]({name})\n"));
    }
    Ok(md)
}

/// `--move JOINT:RAD[:PAYLOAD_KG]`.
pub fn parse_move(s: &str, start_s: f64) -> Result<ArmMove> {
    let parts: Vec<&str> = s.split(':').collect();
    let num = |t: &str, what: &str| -> Result<f64> {
        t.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| anyhow!("--move {s}: {what} `{t}` is not a number; write JOINT:RAD[:PAYLOAD_KG], e.g. j1:0.1 or j3:-0.15:8"))
    };
    match parts.as_slice() {
        [j, m] | [j, m, _] if !j.trim().is_empty() => Ok(ArmMove {
            joint: j.trim().to_string(),
            move_rad: num(m, "the move")?,
            start_s,
            payload_kg: match parts.get(2) {
                Some(p) => Some(num(p, "the payload")?),
                None => None,
            },
        }),
        _ => bail!("--move {s}: write JOINT:RAD[:PAYLOAD_KG], e.g. j1:0.1 or j3:-0.15:8"),
    }
}

/// What `synth --arm` needs besides the model's effects.
pub struct ArmSynth<'a> {
    /// The scenario.
    pub scenario: &'a Path,
    /// The `--move`s.
    pub moves: &'a [String],
    /// Start of every move, s.
    pub start_s: f64,
    /// Run length, s.
    pub duration_s: f64,
    /// Sample rate, Hz.
    pub sample_hz: f64,
    /// Seed.
    pub seed: u64,
}

/// The plan of a synthetic arm dataset (the dataset a model is read against).
pub fn arm_plan(a: &ArmSynth<'_>) -> Result<(Dataset, ArmMovesOptions)> {
    let mut opt = ArmMovesOptions::new(a.scenario, a.seed);
    opt.duration_s = a.duration_s;
    opt.sample_hz = a.sample_hz;
    opt.moves = a
        .moves
        .iter()
        .map(|m| parse_move(m, a.start_s))
        .collect::<Result<_>>()?;
    if opt.moves.is_empty() {
        bail!("synth --arm needs at least one --move JOINT:RAD (one run per move), e.g. --move j1:0.1 --move j5:0.2");
    }
    let plan = synth::arm_plan(&opt).map_err(|e| anyhow!("{e}"))?;
    Ok((plan, opt))
}

/// Simulates the model on the plan and writes the dataset.
pub fn write_arm_synth(
    model: &Model,
    plan: &Dataset,
    opt: &ArmMovesOptions,
    out: &Path,
    title: &str,
) -> Result<()> {
    let d = synth::arm_moves(model, plan, opt).map_err(|e| anyhow!("{e}"))?;
    d.write(out, title)?;
    Ok(())
}
