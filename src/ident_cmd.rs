//! `longreach fit | compare | diagnose | synth`: the measurement loop (issue 3).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, ValueEnum};
use comfy_table::Table;

use longreach_drive::effects;
use longreach_ident::analysis::{self, Comparison, Prepared};
use longreach_ident::fitting::Clipped;
use longreach_ident::model::{Model, ParamDef};
use longreach_ident::{synth, Dataset};
use longreach_plot::{write_png, BodeCurve, Figure, Panel, Series, Style};

use crate::output::{write_atomic, write_atomic_with};
use crate::rerun_args::{self, RerunArgs};

/// Arguments shared by fit, compare and diagnose.
#[derive(Debug, Args)]
pub struct DataArgs {
    /// Dataset folder (holding dataset.toml, format longreach-measurement/1).
    pub dataset: PathBuf,
    /// Model file (TOML, docs/models.md); default: the paper's model of the dataset.
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Write the result as JSON to this file.
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// `longreach fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    #[command(flatten)]
    data: DataArgs,
    /// Write the model with its fitted values (and their 95% intervals, as comments)
    /// as a model file: the next `compare --model`, `fit --model` or `diagnose --model`
    /// starts from it.
    #[arg(long)]
    write_model: Option<PathBuf>,
    /// On an arm dataset: write the dataset's arm scenario with the fitted model folded
    /// in (ropes' k1, effects as [[effect]] with their joints and tables), for `run`,
    /// `batch` and `modes` (docs/models.md, "Writing an arm scenario").
    #[arg(long)]
    write_scenario: Option<PathBuf>,
}

/// `longreach compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    #[command(flatten)]
    data: DataArgs,
    /// Write pictures and report.md into this folder.
    #[arg(long)]
    report: Option<PathBuf>,
    #[command(flatten)]
    rerun: RerunArgs,
}

/// `longreach diagnose`.
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    #[command(flatten)]
    data: DataArgs,
    /// Write pictures and report.md into this folder.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Write the baseline plus the winning effect, fitted, as a model file.
    #[arg(long)]
    write_model: Option<PathBuf>,
    /// On an arm dataset: write the dataset's arm scenario with the fitted model folded
    /// in (ropes' k1, effects as [[effect]] with their joints and tables), for `run`,
    /// `batch` and `modes` (docs/models.md, "Writing an arm scenario").
    #[arg(long)]
    write_scenario: Option<PathBuf>,
    /// Leave this registered effect out of the candidates (repeatable): an effect known
    /// to be absent (e.g. `relay_friction` on ideal idlers, which also saves its fits),
    /// or the catalog without it, to see what the diagnosis says of data whose effect
    /// it does not hold.
    #[arg(long, value_name = "EFFECT")]
    without: Vec<String>,
    /// The exhaustive pair step: when the best single effect leaves the data above 1.5x
    /// the noise floor, pair it with every other candidate (not only the best few, one
    /// screened partner and on sweeps the best-ranked other) and fit every pair from
    /// each of its starts (not only the closest to the data and, except on arms, its own
    /// search). Slower; for a diagnosis that ends with a lead a second effect may
    /// explain (docs/models.md, "Decision rule").
    #[arg(long)]
    all_pairs: bool,
    #[command(flatten)]
    rerun: RerunArgs,
}

/// Kind of synthetic dataset.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum SynthKind {
    /// Stepped-sine sweep of the paper's rig.
    SineSweep,
    /// Tension relaxation at constant strain.
    Relaxation,
    /// Moves of a long-reach arm (give `--arm SCENARIO` and `--move`s).
    ArmMoves,
}

/// `longreach synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Dataset kind (`arm-moves` when `--arm` is given).
    #[arg(long, value_enum)]
    kind: Option<SynthKind>,
    /// Arm scenario (`longreach run` format) of an arm dataset; the dataset carries a
    /// copy (URDF path relative to it, commands dropped).
    #[arg(long)]
    arm: Option<PathBuf>,
    /// One run per move of an arm dataset: `JOINT:RAD[:PAYLOAD_KG]`, a trapezoidal move
    /// of one joint (0.2 rad/s, 0.5 rad/s^2) from the scenario's initial pose, every
    /// other joint held. Repeatable.
    #[arg(long = "move")]
    moves: Vec<String>,
    /// Start of every arm move [s].
    #[arg(long, default_value_t = 0.5)]
    move_start_s: f64,
    /// Length of every arm run [s].
    #[arg(long, default_value_t = 8.0)]
    duration_s: f64,
    /// Sample rate of arm runs [Hz].
    #[arg(long, default_value_t = 50.0)]
    sample_hz: f64,
    /// Output dataset folder (written atomically).
    #[arg(long)]
    out: PathBuf,
    /// Rope (catalog name) when no model is given.
    #[arg(long, default_value = "dyneema2")]
    rope: String,
    /// Model file whose values generate the data (its rope overrides --rope).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Hidden effect `name=v1,v2,..` (parameters in the effect's order; `name` alone
    /// uses the defaults). Repeatable. An unknown name lists the registered effects;
    /// docs/models.md ("Effects") describes them and their parameters. On an arm,
    /// `name@j2+j5=...` hides it at those joints only (values per joint: repeat it on
    /// other joints).
    #[arg(long = "effect")]
    effects: Vec<String>,
    /// Mean tensions of the sweep runs [N].
    #[arg(long, value_delimiter = ',', default_value = "49,147,294,392")]
    tensions_n: Vec<f64>,
    /// Input amplitude of the sweep runs [deg].
    #[arg(long, default_value_t = 4.5)]
    amplitude_deg: f64,
    /// Leave out the tension channels of sweeps.
    #[arg(long)]
    no_tension: bool,
    /// Test frequencies of the sweep runs [Hz], in the order played.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0.1,0.2,0.4,0.7,1,1.4,1.8,2.1,2.4,2.7,3,3.3,3.6,4,4.5,5,6"
    )]
    frequencies_hz: Vec<f64>,
    /// Settle time of every sweep frequency before its analysed hold [s] (the hold is
    /// at least 2 s and 2 cycles).
    #[arg(long, default_value_t = 3.0)]
    settle_s: f64,
    /// Simulation sub-steps per 5 ms sample of a sweep's truth (5: 1 ms; finer makes
    /// data whose own step error is smaller, as a rig's has none).
    #[arg(long, default_value_t = 5)]
    substeps: usize,
    /// Strain of a relaxation test; several (`0.01,0.02`) write one run per strain,
    /// which tells laws of tension apart that one strain cannot.
    #[arg(long, value_delimiter = ',', default_value = "0.015")]
    strain: Vec<f64>,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Title written into dataset.toml.
    #[arg(long)]
    title: Option<String>,
}

/// An ident error ([`longreach_ident::IdentError`], [`longreach_ident::model::ModelError`])
/// as the CLI reports it: its message alone. The message already quotes its cause, which
/// `{:#}` would print a second time if the cause were kept as a source.
/// A numerical failure of the loop (a simulation that blew up, no start that fits)
/// becomes [`crate::Numerical`] (exit 3); every other error is bad input (exit 2).
fn message<E: std::fmt::Display + 'static>(e: E) -> anyhow::Error {
    use longreach_ident::IdentError;
    let numerical = matches!(
        (&e as &dyn std::any::Any).downcast_ref::<IdentError>(),
        Some(
            IdentError::Simulation { .. }
                | IdentError::NoStartSimulated { .. }
                | IdentError::NoStartFitted { .. }
        )
    );
    if numerical {
        anyhow::Error::new(crate::Numerical(e.to_string()))
    } else {
        anyhow!("{e}")
    }
}

/// Refuses a result that is not a number the model stands behind (exit 3): every
/// `(name, value)` must be finite.
fn check_finite(what: &str, values: &[(String, f64)]) -> Result<()> {
    if let Some((name, v)) = values.iter().find(|(_, v)| !v.is_finite()) {
        return Err(anyhow::Error::new(crate::Numerical(format!(
            "{what}: {name} = {v} is not a finite number, so no result is reported\n  fix: a parameter the data cannot determine should be fixed in the model file (fit = false, docs/models.md); check that the runs excite what is fitted"
        ))));
    }
    Ok(())
}

fn load(data: &DataArgs) -> Result<(Dataset, Model)> {
    if let Some(p) = &data.json {
        crate::output::check_output_file(p, "--json")?;
    }
    let ds = Dataset::load(&data.dataset)?;
    let model = match &data.model {
        None => Model::baseline(&ds).map_err(message)?,
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read model file {}", p.display()))?;
            Model::from_toml(&text, &p.display().to_string(), &ds).map_err(message)?
        }
    };
    Ok((ds, model))
}

fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    write_atomic(path, text.as_bytes())
}

fn fmt(x: f64) -> String {
    if x == 0.0 || (1e-3..1e5).contains(&x.abs()) {
        format!("{x:.5}")
    } else {
        format!("{x:.5e}")
    }
}

/// A 95% interval `[lower, upper]` with enough digits to show its width.
fn fmt_interval(lo: f64, hi: f64) -> String {
    if !(lo.is_finite() && hi.is_finite()) {
        return format!("[{}, {}]", fmt(lo), fmt(hi));
    }
    let mag = lo.abs().max(hi.abs());
    let width = hi - lo;
    // significant digits: two beyond the first that differs across the interval
    let sig = if width > 0.0 && mag > 0.0 {
        ((mag / width).log10().ceil() as i32 + 2).clamp(3, 12)
    } else {
        6
    };
    if mag == 0.0 || (1e-3..1e5).contains(&mag) {
        let d = (sig - 1 - mag.max(1e-300).log10().floor() as i32).max(0) as usize;
        format!("[{lo:.d$}, {hi:.d$}]")
    } else {
        let d = (sig - 1) as usize;
        format!("[{lo:.d$e}, {hi:.d$e}]")
    }
}

/// A table knot's parameter name split at its argument's value
/// (`stiffness_factor_rise@tension_n=151.09452775173452`: the name up to `=`, 151.09...).
fn knot(name: &str) -> Option<(&str, f64)> {
    let (head, arg) = name.rsplit_once('=')?;
    let v: f64 = arg.parse().ok()?;
    (head.contains('@') && v.is_finite()).then_some((head, v))
}

/// A parameter's name as the tables print it: a table knot's argument to 4
/// significant digits (`stiffness_factor_rise@tension_n=151.1`). Model files and
/// `--json` keep the knots exact.
fn display_name(name: &str) -> String {
    let Some((head, v)) = knot(name) else {
        return name.to_string();
    };
    let digits = if v == 0.0 {
        0
    } else {
        (3 - v.abs().log10().floor() as i32).max(0) as usize
    };
    format!("{head}={v:.digits$}")
}

/// The order the tables print parameters in: by name, a table's knots by the value of
/// their argument (a total order: the name up to `=`, then the value).
fn by_name_then_knot<'a, T>(
    items: impl IntoIterator<Item = (&'a String, T)>,
) -> Vec<(&'a String, T)> {
    let mut v: Vec<(&'a String, T)> = items.into_iter().collect();
    let key = |n: &'a str| knot(n).unwrap_or((n, f64::NEG_INFINITY));
    v.sort_by(|a, b| {
        let (ka, kb) = (key(a.0), key(b.0));
        ka.0.cmp(kb.0).then(ka.1.total_cmp(&kb.1))
    });
    v
}

/// Table rows `(name, value, interval, std error, note)` of a fit's parameters.
fn fit_rows(r: &longreach_ident::FitResult) -> Vec<[String; 5]> {
    (0..r.names.len())
        .map(|i| {
            let (lo, hi) = r.interval_95[i];
            [
                display_name(&r.names[i]),
                fmt(r.values[i]),
                fmt_interval(lo, hi),
                fmt(r.std_errors[i]),
                r.interval_note(i),
            ]
        })
        .collect()
}

/// The prepared dataset; an arm's at the simulation step chosen from the data with
/// `model` (printed); a sweep's at its coarsest step, which [`refined_for`] refines
/// where the model needs it.
fn prepare<'a>(
    ds: &'a longreach_ident::Dataset,
    model: &Model,
) -> Result<(Prepared<'a>, Option<analysis::SimulationStep>)> {
    let (prep, step) = analysis::prepared_at_step(ds, model).map_err(message)?;
    if let Some(s) = &step {
        println!("{}", crate::arm_ident_cmd::step_words(s));
    }
    Ok((prep, step))
}

/// A sweep prepared again at the step `model` needs where its step error shows
/// against what it leaves over the floor (`ratio_to_floor`, its NRMSE over the floor at
/// `prep`'s step; `analysis::needed_sweep_step`), printed; `None` where it needs none.
fn refined_for<'a>(
    prep: &Prepared<'a>,
    model: &Model,
    ratio_to_floor: f64,
) -> Result<Option<Prepared<'a>>> {
    let need = analysis::needed_sweep_step(prep, model, ratio_to_floor, prep.refinement())
        .map_err(message)?;
    let Some(need) = need else {
        return Ok(None);
    };
    println!(
        "{}; at {:.4} ms the model ({:.2}x the floor) moved by {:.2} sigma when the step was halved, a step error of about {:.0}% of its squared error over the floor",
        crate::arm_ident_cmd::step_words(&need.step),
        1e3 * need.from_step_s,
        ratio_to_floor,
        need.change_sigma,
        100.0 * need.share.min(1.0)
    );
    Ok(Some(
        prep.at_refinement(need.step.refinement).map_err(message)?,
    ))
}

/// Runs `fit`.
pub fn run_fit(a: &FitArgs) -> Result<ExitCode> {
    if let Some(p) = &a.write_model {
        crate::output::check_output_file(p, "--write-model")?;
    }
    let (ds, model) = load(&a.data)?;
    check_write_scenario(a.write_scenario.as_deref(), &ds)?;
    let (mut prep, _) = prepare(&ds, &model)?;
    let mut f = analysis::fit_model(&prep, &model).map_err(message)?;
    if let Some(fine) = refined_for(&prep, &f.model, f.nrmse / f.noise_floor)? {
        // fitted on at the finer step from the values reached (the NRMSE before the fit
        // stays the first step's)
        let before = f.nrmse_before;
        f = analysis::fit_model_from(&fine, &f.model, analysis::Start::Own).map_err(message)?;
        f.nrmse_before = before;
        prep = fine;
    }
    let mut numbers = vec![
        ("NRMSE before".to_string(), f.nrmse_before),
        ("NRMSE".to_string(), f.nrmse),
        ("noise floor".to_string(), f.noise_floor),
    ];
    if let Some(r) = &f.fit {
        let specs = model.fit_specs(prep.runs.len());
        for (i, s) in specs.iter().enumerate() {
            let (lo, hi) = r.interval_95[i];
            numbers.push((format!("{} value", s.name), r.values[i]));
            numbers.push((format!("{} std error", s.name), r.std_errors[i]));
            numbers.push((format!("{} 95% interval", s.name), hi - lo));
        }
    }
    check_finite("fit", &numbers)?;
    let mut table = Table::new();
    table.set_header(vec![
        "parameter",
        "value",
        "95% interval",
        "std error",
        "unit",
        "note",
    ]);
    let mut params = BTreeMap::new();
    if let Some(r) = &f.fit {
        let specs = model.fit_specs(prep.runs.len());
        for (i, ([n, v, iv, se, note], s)) in fit_rows(r).into_iter().zip(&specs).enumerate() {
            table.add_row(vec![n.clone(), v, iv, se, s.unit.clone(), note]);
            params.insert(
                n,
                serde_json::json!({
                    "value": r.values[i],
                    "std_error": r.std_errors[i],
                    "interval_95": r.interval_95[i],
                    "interval_clipped": r.interval_clipped[i].as_str(),
                    "unit": s.unit,
                }),
            );
        }
    }
    println!("{table}");
    if let Some(r) = &f.fit {
        println!("95% intervals: {}", r.interval_method);
    }
    let unit = if prep.kind == effects::DataKind::SineSweep {
        "rad"
    } else {
        "N"
    };
    let rms_before =
        f.nrmse_before / f.nrmse.max(f64::MIN_POSITIVE) * (f.ssr / prep.n_samples() as f64).sqrt();
    let rms_after = (f.ssr / prep.n_samples() as f64).sqrt();
    println!(
        "NRMSE before {:.5}, after {:.5} (noise floor {:.5}); RMS error (eq. 7) before {} {unit}, after {} {unit}{}",
        f.nrmse_before,
        f.nrmse,
        f.noise_floor,
        fmt(rms_before),
        fmt(rms_after),
        if prep.has_channels() {
            " (every channel stacked, each over its noise, on the output angle's scale)"
        } else {
            ""
        }
    );
    if let Some(p) = &a.data.json {
        write_json(
            p,
            &serde_json::json!({
                "dataset": ds.title,
                "params": params,
                "nrmse_before": f.nrmse_before,
                "nrmse": f.nrmse,
                "noise_floor_nrmse": f.noise_floor,
                "rms_before": rms_before,
                "rms": rms_after,
                "rms_unit": unit,
                "simulation_step_s": prep.step_s(),
                "converged": f.fit.as_ref().map(|r| r.converged),
                "interval_method": f.fit.as_ref().map(|r| r.interval_method.clone()),
            }),
        )?;
    }
    if let Some(p) = &a.write_model {
        let comment = format!(
            "written by `longreach fit` for dataset {}\nNRMSE before {:.5}, after {:.5} (noise floor {:.5})",
            ds.title, f.nrmse_before, f.nrmse, f.noise_floor
        );
        let text = f.model.to_toml_with_fit(&comment, f.fit.as_ref());
        write_atomic(p, text.as_bytes())?;
    }
    if let Some(p) = &a.write_scenario {
        let comment = format!(
            "written by `longreach fit` for dataset {}: NRMSE {:.5} (noise floor {:.5})",
            ds.title, f.nrmse, f.noise_floor
        );
        write_scenario(p, &ds, &f.model, &comment)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `--write-scenario`: the output file is writable and the dataset an arm's.
fn check_write_scenario(p: Option<&Path>, ds: &Dataset) -> Result<()> {
    let Some(p) = p else { return Ok(()) };
    crate::output::check_output_file(p, "--write-scenario")?;
    if !matches!(ds.kind, longreach_ident::DatasetKind::ArmMoves(_)) {
        bail!(
            "--write-scenario writes an arm scenario and needs an arm dataset (arm_moves); {} is a {} dataset\n  fix: use --write-model for the rig's and the specimens' data",
            ds.title,
            ds.kind.name()
        );
    }
    Ok(())
}

/// Writes the dataset's arm scenario with `model` folded in to `p` (atomically).
fn write_scenario(p: &Path, ds: &Dataset, model: &Model, comment: &str) -> Result<()> {
    let text = longreach_ident::arm_scenario::arm_scenario_text(ds, model, p, comment)
        .map_err(|e| anyhow!("--write-scenario {}: {e}", p.display()))?;
    write_atomic(p, text.as_bytes())?;
    println!("wrote the arm scenario {}", p.display());
    Ok(())
}

fn print_comparison(c: &Comparison) {
    let mut t = Table::new();
    t.set_header(vec![
        "run",
        "mean tension [N]",
        "NRMSE",
        "noise floor",
        "share of error",
    ]);
    for r in &c.runs {
        t.add_row(vec![
            r.run.clone(),
            r.mean_tension_n.map_or("-".into(), |x| format!("{x:.0}")),
            format!("{:.4}", r.nrmse),
            format!("{:.4}", r.noise_floor_nrmse),
            format!("{:.1}%", 100.0 * r.share),
        ]);
    }
    println!("{t}");
    if c.runs.iter().any(|r| r.channels.len() > 1) {
        let mut ch = Table::new();
        ch.set_header(vec![
            "run",
            "channel",
            "NRMSE",
            "noise floor",
            "RMS error",
            "noise sigma",
            "x floor",
        ]);
        for r in &c.runs {
            for e in &r.channels {
                ch.add_row(vec![
                    r.run.clone(),
                    e.channel.clone(),
                    format!("{:.4}", e.nrmse),
                    format!("{:.4}", e.noise_floor_nrmse),
                    format!("{} {}", fmt(e.rms_error), e.unit),
                    format!("{} {}", fmt(e.noise_sigma), e.unit),
                    format!("{:.2}", e.ratio),
                ]);
            }
        }
        println!("{ch}");
    }
    println!(
        "overall NRMSE {:.4} (noise floor {:.4}, {:.2}x)",
        c.nrmse,
        c.noise_floor_nrmse,
        c.nrmse / c.noise_floor_nrmse.max(f64::MIN_POSITIVE)
    );
    let mut w = Table::new();
    w.set_header(vec![
        "where it fails: run",
        "frequency [Hz]",
        "window [s]",
        "share",
    ]);
    for p in c.where_.iter().take(5) {
        w.add_row(vec![
            p.run.clone(),
            p.frequency_hz.map_or("-".into(), |f| format!("{f:.2}")),
            format!("{:.1}-{:.1}", p.start_s, p.end_s),
            format!("{:.1}%", 100.0 * p.share),
        ]);
    }
    println!("{w}");
    let r = &c.residual;
    println!(
        "residual: Ljung-Box p = {:.3}, corr(input) = {:.3}, corr(sign velocity) = {:.3}, corr(mean tension) = {}, harmonics 2f {:.2}% 3f {:.2}%, corr(time) = {:.3}",
        r.ljung_box_p,
        r.corr_input,
        r.corr_velocity_sign,
        r.corr_mean_tension.map_or("-".into(), |x| format!("{x:.3}")),
        100.0 * r.harmonic_2f,
        100.0 * r.harmonic_3f,
        r.corr_time
    );
}

/// Runs `compare`: simulates the model at its values (no fitting).
pub fn run_compare(a: &CompareArgs) -> Result<ExitCode> {
    let (ds, model) = load(&a.data)?;
    if matches!(ds.kind, longreach_ident::DatasetKind::ArmMoves(_)) {
        return crate::arm_ident_cmd::run_compare_arm(
            &ds,
            &a.data.dataset,
            &model,
            a.data.json.as_deref(),
            a.report.as_deref(),
            &a.rerun,
        );
    }
    let rec = a.rerun.recorder(
        &format!("compare {}", a.data.dataset.display()),
        &rerun_args::default_rrd(None, &a.data.dataset, "_compare"),
    )?;
    let (mut prep, _) = prepare(&ds, &model)?;
    let mut sims = prep.simulate(&model).map_err(message)?;
    let mut c = analysis::compare(&prep, &model, &sims).map_err(message)?;
    if let Some(fine) = refined_for(&prep, &model, c.nrmse / c.noise_floor_nrmse)? {
        prep = fine;
        sims = prep.simulate(&model).map_err(message)?;
        c = analysis::compare(&prep, &model, &sims).map_err(message)?;
    }
    let mut numbers = vec![
        ("NRMSE".to_string(), c.nrmse),
        ("noise floor".to_string(), c.noise_floor_nrmse),
    ];
    numbers.extend(
        c.runs
            .iter()
            .map(|r| (format!("run {} NRMSE", r.run), r.nrmse)),
    );
    check_finite("compare", &numbers)?;
    longreach_viz::ident::log_comparison(&rec, &prep, &c, &sims, None, None);
    rerun_args::finish(rec);
    print_comparison(&c);
    if let Some(p) = &a.data.json {
        write_json(p, &c)?;
    }
    if let Some(dir) = &a.report {
        write_report(dir, &prep, &c, &sims, None, None)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The verdict in a few words: the named effect(s), or "none found".
fn missing_words(d: &analysis::Diagnosis) -> String {
    if d.missing_effects.is_empty() {
        "none found".into()
    } else {
        d.missing_effects.join(" and ")
    }
}

/// Runs `diagnose`.
pub fn run_diagnose(a: &DiagnoseArgs) -> Result<ExitCode> {
    let without: Vec<&str> = a.without.iter().map(String::as_str).collect();
    // (before any work: the library checks the list again, at no cost)
    if let Err(e) = analysis::check_registered(&without) {
        bail!("--without {e}");
    }
    if let Some(p) = &a.write_model {
        crate::output::check_output_file(p, "--write-model")?;
    }
    let (ds, model) = load(&a.data)?;
    check_write_scenario(a.write_scenario.as_deref(), &ds)?;
    let rec = a.rerun.recorder(
        &format!("diagnose {}", a.data.dataset.display()),
        &rerun_args::default_rrd(None, &a.data.dataset, "_diagnose"),
    )?;
    // (a sweep at its coarsest step, which the diagnosis refines where the models it
    // judges need it: `analysis::diagnose_with`)
    let prep = match prepare(&ds, &model) {
        Ok((p, _)) => p,
        Err(e) => {
            rec.discard();
            return Err(e);
        }
    };
    let options = analysis::DiagnoseOptions {
        without: &without,
        all_pairs: a.all_pairs,
    };
    let (d, base, winner) = match analysis::diagnose_with(&prep, &model, &options) {
        Ok(r) => r,
        Err(e) => {
            rec.discard();
            return Err(message(e));
        }
    };
    if matches!(ds.kind, longreach_ident::DatasetKind::ArmMoves(_)) {
        // The arm plant's compared channel is every channel stacked: draw the arms
        // and the channels themselves instead.
        crate::arm_ident_cmd::log_arm_diagnosis(
            &rec,
            &ds,
            &d,
            &base.model,
            winner.as_ref().map(|w| &w.model),
            prep.arm_refinement,
        );
    } else {
        let after = winner.as_ref().map(|w| w.sims.as_slice());
        longreach_viz::ident::log_comparison(
            &rec,
            &prep,
            &d.comparison,
            &base.sims,
            Some(&d),
            after,
        );
    }
    rerun_args::finish(rec);
    println!(
        "baseline NRMSE {:.4} (noise floor {:.4})",
        d.baseline.nrmse, d.baseline.noise_floor_nrmse
    );
    if let Some(r) = &base.fit {
        let mut t = Table::new();
        t.set_header(vec![
            "baseline parameter",
            "value",
            "95% interval",
            "std error",
            "note",
        ]);
        for row in fit_rows(r) {
            t.add_row(row.to_vec());
        }
        println!("{t}");
        println!("95% intervals: {}", r.interval_method);
    }
    let mut t = Table::new();
    t.set_header(vec![
        "rank",
        "effect",
        "NRMSE",
        "score (dBIC)",
        "explains",
        "decisive",
    ]);
    for (i, c) in d.candidates.iter().enumerate() {
        t.add_row(vec![
            (i + 1).to_string(),
            c.effect.clone(),
            format!("{:.4}", c.nrmse),
            format!("{:.1}", c.score),
            format!("{:.0}%", 100.0 * c.explained.clamp(0.0, 1.0)),
            if c.screened && !d.candidates.iter().all(|c| c.screened) {
                "false (screened)".to_string()
            } else {
                c.decisive.to_string()
            },
        ]);
    }
    println!("{t}");
    if d.candidates.iter().all(|c| c.screened) {
        if !d.candidates.is_empty() {
            println!("candidates screened at their starting values, not fitted: no intervals");
        }
    } else {
        let mut t = Table::new();
        t.set_header(vec![
            "candidate",
            "parameter",
            "value",
            "95% interval",
            "note",
        ]);
        for c in &d.candidates {
            for (name, v) in by_name_then_knot(&c.params) {
                let (interval, note) = match c.interval_95.get(name) {
                    Some(&[lo, hi]) => (
                        fmt_interval(lo, hi),
                        c.interval_clipped
                            .get(name)
                            .map_or(String::new(), |b| Clipped::note_for(b)),
                    ),
                    None if c.error.is_some() => ("-".into(), "fit failed".into()),
                    None if c.screened => ("-".into(), "screened, not fitted".into()),
                    None => ("-".into(), "known".into()),
                };
                t.add_row(vec![
                    c.effect.clone(),
                    display_name(name),
                    fmt(*v),
                    interval,
                    note,
                ]);
            }
        }
        println!("{t}");
    }
    if !d.pairs.is_empty() {
        let mut t = Table::new();
        t.set_header(vec![
            "pair",
            "NRMSE",
            "score (dBIC)",
            "explains",
            "decisive",
        ]);
        for c in &d.pairs {
            t.add_row(vec![
                c.effect.replace('+', " + "),
                format!("{:.4}", c.nrmse),
                format!("{:.1}", c.score),
                format!("{:.0}%", 100.0 * c.explained.clamp(0.0, 1.0)),
                c.decisive.to_string(),
            ]);
        }
        println!("{t}");
    }
    println!("missing effect: {}", missing_words(&d));
    if let Some(l) = &d.lead {
        println!(
            "lead (not named): {} at {:.2}x the noise floor",
            l.effects.join(" + "),
            l.ratio_to_floor
        );
    }
    println!("{}", d.explanation);
    if let Some(p) = &a.data.json {
        write_json(p, &d)?;
    }
    if let Some(p) = &a.write_model {
        let fitted = winner.as_ref().unwrap_or(&base);
        let comment = format!(
            "written by `longreach diagnose` for dataset {}\nbaseline NRMSE {:.5}; with {}: {}",
            ds.title,
            d.baseline.nrmse,
            if d.missing_effects.is_empty() {
                "no effect".to_string()
            } else {
                d.missing_effects.join(" and ")
            },
            d.nrmse_after.map_or("-".into(), |x| format!("{x:.5}"))
        );
        let text = fitted.model.to_toml_with_fit(&comment, fitted.fit.as_ref());
        write_atomic(p, text.as_bytes())?;
    }
    if let Some(p) = &a.write_scenario {
        let fitted = winner.as_ref().unwrap_or(&base);
        let comment = format!(
            "written by `longreach diagnose` for dataset {}: with {}, NRMSE {} (baseline {:.5})",
            ds.title,
            if d.missing_effects.is_empty() {
                "no effect".to_string()
            } else {
                d.missing_effects.join(" and ")
            },
            d.nrmse_after.map_or("-".into(), |x| format!("{x:.5}")),
            d.baseline.nrmse
        );
        write_scenario(p, &ds, &fitted.model, &comment)?;
    }
    if let Some(dir) = &a.report {
        let m = winner.as_ref().map_or(&base, |w| w);
        let after = match &winner {
            Some(w) => Some(analysis::compare(&prep, &w.model, &w.sims).map_err(message)?),
            None => None,
        };
        // An arm's part: what its sensors show, the values per joint and every joint
        // measured against the baseline and the named model (the compared channel is
        // every channel stacked, which says little in a picture).
        let arm_md = match &ds.kind {
            longreach_ident::DatasetKind::ArmMoves(_) => {
                Some(crate::arm_ident_cmd::arm_diagnosis_report(
                    dir,
                    &ds,
                    &d,
                    &base.model,
                    winner.as_ref().map(|w| &w.model),
                    prep.arm_refinement,
                )?)
            }
            _ => None,
        };
        write_report(
            dir,
            &prep,
            &d.comparison,
            &base.sims,
            Some((&d, &m.sims, after.as_ref())),
            arm_md.as_deref(),
        )?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Where `--effect name@j2+j5=...` acts (joints, or flexible links for an effect on a
/// link's bending: `link_flexibility@link2=...`), if given.
fn effect_at(s: &str) -> Option<Vec<String>> {
    let head = s.split_once('=').map_or(s, |(h, _)| h);
    head.split_once('@').map(|(_, j)| {
        j.split('+')
            .map(|x| x.trim().to_string())
            .filter(|x| !x.is_empty())
            .collect()
    })
}

fn parse_effect(s: &str) -> Result<(&'static dyn effects::Effect, Vec<f64>)> {
    let (name, vals) = s.split_once('=').unwrap_or((s, ""));
    let name = name.split_once('@').map_or(name, |(n, _)| n);
    let e = effects::find(name.trim()).ok_or_else(|| {
        anyhow!(
            "unknown effect `{name}`; registered effects: {}",
            effects::names().join(", ")
        )
    })?;
    let v: Vec<f64> = if vals.trim().is_empty() {
        e.params().iter().map(|p| p.default).collect()
    } else {
        vals.split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("--effect {s}: parameters must be numbers"))?
    };
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        bail!("--effect {s}: parameter {x} is not a finite number\n  fix: give finite values, e.g. --effect {}", e.name());
    }
    if v.len() != e.params().len() {
        bail!(
            "--effect {s}: {} takes {} parameter(s): {}",
            e.name(),
            e.params().len(),
            e.params()
                .iter()
                .map(|p| format!("{} [{}]", p.name, p.unit))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok((e, v))
}

/// Runs `synth`.
pub fn run_synth(a: &SynthArgs) -> Result<ExitCode> {
    let kind = match (a.kind, &a.arm) {
        (Some(SynthKind::ArmMoves) | None, Some(_)) => SynthKind::ArmMoves,
        (Some(k @ (SynthKind::SineSweep | SynthKind::Relaxation)), Some(_)) => {
            bail!("--arm makes an arm dataset: drop --kind {k:?} or --arm")
        }
        (Some(SynthKind::ArmMoves), None) => {
            bail!("--kind arm-moves needs --arm SCENARIO (an arm scenario of `longreach run`)")
        }
        (Some(k), None) => k,
        (None, None) => bail!("give --kind sine-sweep | relaxation, or --arm SCENARIO"),
    };
    // Refuse an --out that is not ours before the (long) simulation, not after it.
    longreach_ident::dataset::check_target(&a.out)?;
    // An arm dataset's plan is the dataset its model is read against; otherwise a
    // placeholder dataset only supplies the rope name for a model file's defaults.
    let arm_plan = match &a.arm {
        Some(scenario) => Some(crate::arm_ident_cmd::arm_plan(
            &crate::arm_ident_cmd::ArmSynth {
                scenario,
                moves: &a.moves,
                start_s: a.move_start_s,
                duration_s: a.duration_s,
                sample_hz: a.sample_hz,
                seed: a.seed,
            },
        )?),
        None => None,
    };
    let rope = a.rope.clone();
    let base_ds = match &arm_plan {
        Some((plan, _)) => plan.clone(),
        None => placeholder_dataset(&rope),
    };
    let mut model = match &a.model {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("cannot read model file {}", p.display()))?;
            Model::from_toml(&text, &p.display().to_string(), &base_ds).map_err(message)?
        }
        None => Model::baseline(&base_ds).map_err(message)?,
    };
    for s in &a.effects {
        let (e, v) = parse_effect(s)?;
        let at = effect_at(s);
        if let Some(j) = &at {
            if let Some((msg, fix)) = longreach_ident::model::at_problem(e, j, &base_ds) {
                bail!("--effect {s}: {msg}\n  fix: {fix}");
            }
        }
        if let Some((_, at)) = longreach_ident::model::at_overlap(&model.effects, e, at.as_deref())
        {
            bail!(
                "--effect {s}: {} is hidden twice on {at}\n  fix: hide an effect once, or once per joint (link) with disjoint @joints (@links)",
                e.name()
            );
        }
        let mut m = model.with_effect(e);
        if let Some(u) = m.effects.last_mut() {
            u.at = at;
            for (p, x) in u.params.iter_mut().zip(&v) {
                *p = ParamDef {
                    value: *x,
                    fit: false,
                    ..p.clone()
                };
            }
        }
        m.law_for_run(0).map_err(|e| anyhow!("--effect {s}: {e}"))?;
        model = m;
    }
    let title = a.title.clone().unwrap_or_else(|| {
        a.out
            .file_name()
            .map_or("synthetic".into(), |n| n.to_string_lossy().into_owned())
    });
    match kind {
        SynthKind::ArmMoves => {
            let (plan, opt) = arm_plan
                .as_ref()
                .ok_or_else(|| anyhow!("--kind arm-moves needs --arm SCENARIO"))?;
            crate::arm_ident_cmd::write_arm_synth(&model, plan, opt, &a.out, &title)?;
        }
        SynthKind::SineSweep => {
            let mut opt = synth::SweepOptions::paper(&model.rope, a.seed);
            opt.runs = a
                .tensions_n
                .iter()
                .map(|&t| (t, a.amplitude_deg.to_radians()))
                .collect();
            opt.tension_channels = !a.no_tension;
            if a.frequencies_hz.is_empty()
                || a.frequencies_hz
                    .iter()
                    .any(|f| !(f.is_finite() && *f > 0.0))
            {
                bail!(
                    "--frequencies-hz {:?}: give one or more positive frequencies in Hz, e.g. 0.5,1,2.4",
                    a.frequencies_hz
                );
            }
            if !(a.settle_s.is_finite() && a.settle_s >= 0.0) {
                bail!("--settle-s {}: give a settle time >= 0 s", a.settle_s);
            }
            if !(1..=1000).contains(&a.substeps) {
                bail!(
                    "--substeps {}: give 1 to 1000 sub-steps per sample",
                    a.substeps
                );
            }
            opt.frequencies_hz = a.frequencies_hz.clone();
            opt.settle_s = a.settle_s;
            opt.substeps = a.substeps;
            let d = synth::sweep(&model, &opt).map_err(message)?;
            d.write(&a.out, &title)?;
        }
        SynthKind::Relaxation => {
            let mut opt = synth::RelaxationOptions::paper(&model.rope, a.seed);
            if let Some((first, more)) = a.strain.split_first() {
                opt.strain = *first;
                opt.more_strains = more.to_vec();
            }
            let d = synth::relaxation(&model, &opt).map_err(message)?;
            d.write(&a.out, &title)?;
        }
    }
    println!("wrote {}", a.out.display());
    Ok(ExitCode::SUCCESS)
}

fn placeholder_dataset(rope: &str) -> Dataset {
    Dataset {
        dir: PathBuf::new(),
        title: String::new(),
        kind: longreach_ident::DatasetKind::Relaxation(longreach_ident::RelaxationDataset {
            specimen: longreach_ident::RelaxationSpecimen {
                rope: rope.to_string(),
                length_m: 0.1,
                strain: 0.015,
            },
            runs: Vec::new(),
        }),
    }
}

fn write_report(
    dir: &Path,
    prep: &Prepared<'_>,
    c: &Comparison,
    sims: &[Vec<f64>],
    diag: Option<(
        &analysis::Diagnosis,
        &Vec<Vec<f64>>,
        Option<&analysis::Comparison>,
    )>,
    arm_md: Option<&str>,
) -> Result<()> {
    crate::output::output_dir(dir, "--report")?;
    let mut md = format!("# {} — model vs measurement\n\n", c.dataset);
    if let Some(step_s) = diag.and_then(|d| d.0.simulation_step_s) {
        if prep.kind == effects::DataKind::ArmMoves {
            md.push_str(&format!(
                "The arm simulated at steps of {:.4} ms (chosen from the data: the coarsest \
                 step whose halving moves the channels by at most {} sigma of their noise).\n\n",
                1e3 * step_s,
                analysis::STEP_TOLERANCE_SIGMA
            ));
        } else {
            md.push_str(&format!(
                "The rig simulated at steps of {:.4} ms (2.5 ms unless a model the diagnosis \
                 judged showed its step error: at least {:.0}% of what it left over the floor; \
                 then the coarsest step whose halving moves the channels by at most {} sigma \
                 of their noise).\n\n",
                1e3 * step_s,
                100.0 * analysis::STEP_ERROR_SHARE,
                analysis::STEP_TOLERANCE_SIGMA
            ));
        }
    }
    md.push_str(&format!(
        "Overall NRMSE **{:.4}** (noise floor {:.4}).\n\n| run | NRMSE | floor | share |\n|---|---|---|---|\n",
        c.nrmse, c.noise_floor_nrmse
    ));
    for r in &c.runs {
        md.push_str(&format!(
            "| {} | {:.4} | {:.4} | {:.1}% |\n",
            r.run,
            r.nrmse,
            r.noise_floor_nrmse,
            100.0 * r.share
        ));
    }
    if c.runs.iter().any(|r| r.channels.len() > 1) {
        md.push_str(
            "\nEvery channel (each enters the NRMSE above over its own noise):\n\n| run | channel | NRMSE | floor | RMS error | noise sigma | x floor |\n|---|---|---|---|---|---|---|\n",
        );
        for r in &c.runs {
            for e in &r.channels {
                md.push_str(&format!(
                    "| {} | {} | {:.4} | {:.4} | {} {} | {} {} | {:.2} |\n",
                    r.run,
                    e.channel,
                    e.nrmse,
                    e.noise_floor_nrmse,
                    fmt(e.rms_error),
                    e.unit,
                    fmt(e.noise_sigma),
                    e.unit,
                    e.ratio
                ));
            }
        }
    }
    write_where_and_checks(c, &mut md);
    if let Some((d, _, _)) = diag {
        md.push_str(&format!(
            "\n## Diagnosis\n\nMissing effect: **{}**\n\n{}\n\n",
            missing_words(d),
            d.explanation
        ));
        if let Some(l) = &d.lead {
            md.push_str(&format!(
                "Lead, not named: **{}** ({:.2}x the noise floor, explains {:.0}% of the excess error).\n\n",
                l.effects.join(" + "),
                l.ratio_to_floor,
                100.0 * l.explained.clamp(0.0, 1.0)
            ));
        }
        let floor = d.baseline.noise_floor_nrmse.max(f64::MIN_POSITIVE);
        md.push_str(
            "Candidates (each fitted with the baseline; score: BIC improvement over the baseline; explains: share of the baseline's squared error above the noise floor it removes):\n\n| effect | NRMSE | x floor | score | explains | decisive |\n|---|---|---|---|---|---|\n",
        );
        for k in d.candidates.iter().chain(&d.pairs) {
            md.push_str(&format!(
                "| {} | {:.4} | {:.2} | {:.1} | {:.0}% | {} |\n",
                k.effect.replace('+', " + "),
                k.nrmse,
                k.nrmse / floor,
                k.score,
                100.0 * k.explained.clamp(0.0, 1.0),
                if k.decisive {
                    "**yes**"
                } else if k.screened {
                    "screened, not fitted"
                } else {
                    ""
                }
            ));
        }
        if !d.signatures.is_empty() {
            md.push_str(
                "\n### Residual signatures (what the baseline still misses)\n\n| signature | simplest term | size | removes of the excess | details |\n|---|---|---|---|---|\n",
            );
            for g in &d.signatures {
                let details: Vec<String> = g
                    .equivalent
                    .iter()
                    .map(|e| format!("{} = {} {}", e.what, fmt(e.value), e.unit))
                    .chain((!g.note.is_empty()).then(|| g.note.clone()))
                    .collect();
                md.push_str(&format!(
                    "| {} | {} | {} {} | {:.0}% | {} |\n",
                    g.evidence,
                    g.term,
                    fmt(g.size),
                    if g.unit == "1" { "" } else { g.unit },
                    100.0 * g.share_removed,
                    details.join("; ")
                ));
            }
        }
        md.push_str(
            "\n### Fitted values and 95% intervals\n\n| model | parameter | value | 95% interval |\n|---|---|---|---|\n",
        );
        let b = &d.baseline;
        let models = std::iter::once(("baseline", &b.params, &b.interval_95, &b.interval_clipped))
            .chain(d.candidates.iter().map(|c| {
                (
                    c.effect.as_str(),
                    &c.params,
                    &c.interval_95,
                    &c.interval_clipped,
                )
            }));
        for (model, params, intervals, clipped) in models {
            for (name, [lo, hi]) in by_name_then_knot(intervals) {
                let flag = clipped
                    .get(name)
                    .map_or(String::new(), |c| format!(" ({})", Clipped::note_for(c)));
                md.push_str(&format!(
                    "| {model} | {} | {} | {}{flag} |\n",
                    display_name(name),
                    params.get(name).map_or("-".into(), |v| fmt(*v)),
                    fmt_interval(*lo, *hi)
                ));
            }
        }
    }
    if let Some(a) = arm_md {
        md.push_str(a);
    }
    md.push_str("\n## Pictures\n\n");
    // Bode per run (sweeps)
    for run in &prep.runs {
        let pts: Vec<_> = c.frequency.iter().filter(|f| f.run == run.name).collect();
        if pts.is_empty() {
            continue;
        }
        let f: Vec<f64> = pts.iter().map(|p| p.frequency_hz).collect();
        let mut curves = vec![
            BodeCurve {
                label: "measured".into(),
                frequency_hz: f.clone(),
                gain_db: pts.iter().map(|p| p.gain_measured_db).collect(),
                phase_deg: longreach_drive::freq::unwrap_deg(
                    &pts.iter().map(|p| p.phase_measured_deg).collect::<Vec<_>>(),
                ),
                style: Style::LineMarkers,
                color: 0,
            },
            BodeCurve {
                label: "model".into(),
                frequency_hz: f,
                gain_db: pts.iter().map(|p| p.gain_model_db).collect(),
                phase_deg: longreach_drive::freq::unwrap_deg(
                    &pts.iter().map(|p| p.phase_model_deg).collect::<Vec<_>>(),
                ),
                style: Style::DashedLine,
                color: 1,
            },
        ];
        if let Some((d, _, Some(ac))) = diag {
            let q: Vec<_> = ac.frequency.iter().filter(|f| f.run == run.name).collect();
            if !d.missing_effects.is_empty() && q.len() == pts.len() {
                curves.push(BodeCurve {
                    label: format!("model + {}", d.missing_effects.join(" + ")),
                    frequency_hz: q.iter().map(|p| p.frequency_hz).collect(),
                    gain_db: q.iter().map(|p| p.gain_model_db).collect(),
                    phase_deg: longreach_drive::freq::unwrap_deg(
                        &q.iter().map(|p| p.phase_model_deg).collect::<Vec<_>>(),
                    ),
                    style: Style::Line,
                    color: 2,
                });
            }
        }
        let title = format!("{} {}: measured vs model", c.dataset, run.name);
        let name = format!("bode_{}.png", run.name);
        let fig = longreach_plot::bode_figure(&title, &curves);
        write_atomic_with(&dir.join(&name), |p| Ok(write_png(&fig, p)?))?;
        md.push_str(&format!("![{name}]({name})\n"));
    }
    // worst window overlay
    if let Some(w) = c.worst_windows.first() {
        if let Some(ri) = prep.runs.iter().position(|r| r.name == w.run) {
            let run = &prep.runs[ri];
            let idx: Vec<usize> = (0..run.time_s.len())
                .filter(|&i| run.time_s[i] >= w.start_s && run.time_s[i] <= w.end_s)
                .collect();
            let t: Vec<f64> = idx.iter().map(|&i| run.time_s[i]).collect();
            let mut series = vec![
                Series {
                    label: "measured".into(),
                    x: t.clone(),
                    y: idx.iter().map(|&i| run.measured[i]).collect(),
                    style: Style::Line,
                    color: 0,
                },
                Series {
                    label: "model".into(),
                    x: t.clone(),
                    y: idx.iter().map(|&i| sims[ri][i]).collect(),
                    style: Style::DashedLine,
                    color: 1,
                },
            ];
            if let Some((d, after, _)) = diag {
                if !d.missing_effects.is_empty() {
                    series.push(Series {
                        label: format!("model + {}", d.missing_effects.join(" + ")),
                        x: t.clone(),
                        y: idx.iter().map(|&i| after[ri][i]).collect(),
                        style: Style::Line,
                        color: 2,
                    });
                }
            }
            let fig = Figure {
                title: format!(
                    "worst window: {} {:.1}-{:.1} s ({:.0}% of the error)",
                    w.run,
                    w.start_s,
                    w.end_s,
                    100.0 * w.share
                ),
                x_label: "time [s]".into(),
                log_x: false,
                panels: vec![Panel {
                    y_label: if prep.kind == effects::DataKind::SineSweep {
                        "output angle [rad]".into()
                    } else {
                        "tension [N]".into()
                    },
                    series,
                    y_range: None,
                    log_y: false,
                }],
                width_px: 1000,
                height_px: 500,
            };
            write_atomic_with(&dir.join("worst_window.png"), |p| Ok(write_png(&fig, p)?))?;
            md.push_str("![worst window](worst_window.png)\n");
        }
    }
    // residual spectrum of the run with the largest share
    if let Some(ri) = c
        .runs
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.share.total_cmp(&b.1.share))
        .map(|x| x.0)
    {
        let run = &prep.runs[ri];
        let res: Vec<f64> = (0..run.measured.len())
            .map(|i| sims[ri][i] - run.measured[i])
            .collect();
        if let Ok((f, psd)) = longreach_ident::metrics::power_spectrum(&res, run.dt_s) {
            let keep: Vec<usize> = (1..f.len()).filter(|&k| psd[k] > 0.0).collect();
            let fig = Figure {
                title: format!("residual spectrum, {}", run.name),
                x_label: "frequency [Hz]".into(),
                log_x: true,
                panels: vec![Panel {
                    y_label: "PSD [unit^2/Hz]".into(),
                    series: vec![Series {
                        label: "residual".into(),
                        x: keep.iter().map(|&k| f[k]).collect(),
                        y: keep.iter().map(|&k| psd[k]).collect(),
                        style: Style::Line,
                        color: 3,
                    }],
                    y_range: None,
                    log_y: true,
                }],
                width_px: 1000,
                height_px: 500,
            };
            write_atomic_with(&dir.join("residual_spectrum.png"), |p| {
                Ok(write_png(&fig, p)?)
            })?;
            md.push_str("![residual spectrum](residual_spectrum.png)\n");
        }
    }
    if let Some((d, _, _)) = diag {
        for r in &d.refinements {
            write_law_figure(dir, r, &mut md)?;
        }
    }
    write_atomic(&dir.join("report.md"), md.as_bytes())
}

/// `report.md`'s sections on where the model fails (the largest shares of the squared
/// error) and the residual checks.
fn write_where_and_checks(c: &analysis::Comparison, md: &mut String) {
    if !c.where_.is_empty() {
        md.push_str("\n## Where it fails\n\n| run | test frequency | window | share of the squared error |\n|---|---|---|---|\n");
        for w in c.where_.iter().take(8) {
            md.push_str(&format!(
                "| {} | {} | {:.1}-{:.1} s | {:.1}% |\n",
                w.run,
                w.frequency_hz.map_or("-".into(), |f| format!("{f:.2} Hz")),
                w.start_s,
                w.end_s,
                100.0 * w.share
            ));
        }
    }
    let r = &c.residual;
    md.push_str(&format!(
        "\n## Residual checks\n\n| check | value | reading |\n|---|---|---|\n\
         | whiteness (Ljung-Box, 20 lags) | Q = {:.1}, p = {:.2e} | {} |\n\
         | correlation with the input | {:.2} | {} |\n\
         | correlation with the velocity's sign | {:.2} | {} |\n\
         | correlation of the runs' error with their mean tension | {} | {} |\n\
         | harmonics at 2f / 3f (of the output) | {:.1}% / {:.1}% | {} |\n\
         | correlation with time (drift) | {:.2} | {} |\n",
        r.ljung_box_q,
        r.ljung_box_p,
        if r.ljung_box_p < 0.05 {
            "not white"
        } else {
            "white"
        },
        r.corr_input,
        if r.corr_input.abs() > 0.3 {
            "the model misses a part of the response"
        } else {
            "-"
        },
        r.corr_velocity_sign,
        if r.corr_velocity_sign.abs() > 0.2 {
            "dry friction?"
        } else {
            "-"
        },
        r.corr_mean_tension
            .map_or("-".into(), |x| format!("{x:.2}")),
        if r.corr_mean_tension.is_some_and(|x| x.abs() > 0.7) {
            "a law that depends on tension?"
        } else {
            "-"
        },
        100.0 * r.harmonic_2f,
        100.0 * r.harmonic_3f,
        if r.harmonic_2f.max(r.harmonic_3f) > 0.02 {
            "a non-linearity"
        } else {
            "-"
        },
        r.corr_time,
        if r.corr_time.abs() > 0.3 {
            "drift"
        } else {
            "-"
        },
    ));
}

/// The law an effect's refinement fitted (its table, with the 95% band at the knots)
/// against the catalog's formula with its fitted values, as `law_EFFECT.png`, and a
/// table of the knots in the report.
fn write_law_figure(dir: &Path, r: &analysis::ShapeRefinement, md: &mut String) -> Result<()> {
    let x: Vec<f64> = r.curve.iter().map(|p| p[0]).collect();
    let band = |k: usize, label: &str| Series {
        label: label.into(),
        x: r.knots.clone(),
        y: r.band_95.iter().map(|b| b[k]).collect(),
        style: Style::DashedLine,
        color: 2,
    };
    let fig = Figure {
        title: format!(
            "{}: {} vs {}; NRMSE {:.4} catalog, {:.4} table{}",
            r.effect,
            r.value,
            r.argument,
            r.nrmse_parametric,
            r.nrmse,
            if r.kept { ", kept" } else { ", not kept" }
        ),
        x_label: r.argument.clone(),
        log_x: false,
        panels: vec![Panel {
            y_label: format!("{} [{}]", r.value, r.unit),
            series: vec![
                Series {
                    label: "catalog law, fitted".into(),
                    x: x.clone(),
                    y: r.curve.iter().map(|p| p[1]).collect(),
                    style: Style::DashedLine,
                    color: 1,
                },
                Series {
                    label: format!("table, {} knots", r.knots.len()),
                    x: r.knots.clone(),
                    y: r.values.clone(),
                    style: Style::LineMarkers,
                    color: 0,
                },
                band(0, "95% band"),
                band(1, ""),
            ],
            y_range: None,
            log_y: false,
        }],
        width_px: 1000,
        height_px: 500,
    };
    // (`joint_friction@j2+j5`: a table per joint, named without `@` and `+`)
    let name = format!(
        "law_{}.png",
        r.effect.replace('@', "_at_").replace('+', "_")
    );
    write_atomic_with(&dir.join(&name), |p| Ok(write_png(&fig, p)?))?;
    md.push_str(&format!(
        "\n### The law of {} refined\n\n![{name}]({name})\n\n| {} | {} (table) | 95% band | catalog law |\n|---|---|---|---|\n",
        r.effect, r.argument, r.value
    ));
    for (i, k) in r.knots.iter().enumerate() {
        md.push_str(&format!(
            "| {} | {} | {} | {} |\n",
            fmt(*k),
            fmt(r.values[i]),
            fmt_interval(r.band_95[i][0], r.band_95[i][1]),
            fmt(r.catalog[i])
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn knot_names_print_to_four_digits_and_in_the_order_of_their_argument() {
        let rise = |t: &str| format!("stiffness_factor_rise@tension_n={t}");
        assert_eq!(
            display_name(&rise("151.09452775173452")),
            rise("151.1"),
            "four significant digits"
        );
        assert_eq!(display_name(&rise("67.21311525054008")), rise("67.21"));
        assert_eq!(display_name(&rise("1500.4")), rise("1500"));
        assert_eq!(
            display_name("stiffness_factor@tension_n=0"),
            "stiffness_factor@tension_n=0"
        );
        // not knots: unchanged
        for n in ["k1_scale", "coulomb_n_m@j1+j2", "delay_s[2]", "a=b"] {
            assert_eq!(display_name(n), n);
        }
        let names: Vec<String> = [
            rise("597.7379012266548"),
            "k1_scale".into(),
            rise("67.21311525054008"),
            rise("151.09452775173452"),
            "stiffening_per_n".into(),
        ]
        .into_iter()
        .collect();
        let map: BTreeMap<String, f64> = names.iter().map(|n| (n.clone(), 0.0)).collect();
        let order: Vec<String> = by_name_then_knot(&map)
            .into_iter()
            .map(|(n, _)| display_name(n))
            .collect();
        // (by name, the string order put 597.7 before 67.21)
        assert_eq!(
            order,
            [
                "k1_scale".to_string(),
                "stiffening_per_n".into(),
                rise("67.21"),
                rise("151.1"),
                rise("597.7"),
            ]
        );
    }
}
