//! `longreach batch FILE`: expand a batch file into scenarios, run them on rayon with a
//! journal (resumable) and write one results table (CSV and Parquet);
//! `longreach merge OUT [SHARD_DIR...]`: join shard runs into the table of the whole batch.
//! The format and the cluster recipes are in docs/batch.md.

use std::fs::File;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use parquet::basic::{Compression, LogicalType, Repetition, Type as Physical};
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, Int64Type};
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::types::Type;

use longreach_scenario::batch::{
    builtin_kinds, merge, one_line, run_scenarios, Batch, Cell, CellKind, Header, Journal, Outcome,
    Row, RowError, RunOptions, ScenarioKind, ScenarioTree, Shard, Status, Table,
};
use longreach_scenario::ScenarioError;

use crate::output::{write_atomic, write_atomic_with};

/// Arguments of `longreach batch`.
#[derive(Debug, Args)]
pub struct BatchArgs {
    /// Batch file (TOML; see docs/batch.md).
    pub file: PathBuf,
    /// Worker threads (default: all cores).
    #[arg(short = 'j', long, value_name = "N")]
    pub jobs: Option<usize>,
    /// Output folder (default: out/<batch name>); a shard writes into
    /// <out>/shard-K-of-N.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Continue an interrupted run from its journal (rows done are kept, not redone).
    #[arg(long)]
    pub resume: bool,
    /// Run only shard K of N (1 <= K <= N): the scenarios with index % N == K-1.
    /// Without it, the Slurm array variables or JOB_COMPLETION_INDEX choose the shard.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<String>,
    /// Number of shards for a Kubernetes Indexed Job (or set LONGREACH_SHARD_COUNT).
    #[arg(long, value_name = "N")]
    pub shard_count: Option<usize>,
    /// Also write each scenario's TOML and full output into <out>/scenarios/.
    #[arg(long)]
    pub keep_outputs: bool,
    /// List the expanded scenarios (index and axis values, as CSV) without running.
    #[arg(long)]
    pub dry_run: bool,
    /// Record these scenarios (indices, comma-separated) to Rerun, each into
    /// <out>/rerun/<index>.rrd, as `run` or `bode` would.
    #[arg(long, value_name = "I,J,...", value_delimiter = ',')]
    pub rerun_select: Vec<usize>,
    /// Frames of simulated time logged per simulated second (with --rerun-select).
    #[arg(long, value_name = "HZ", default_value_t = longreach_viz::DEFAULT_HZ)]
    pub rerun_hz: f64,
}

/// Arguments of `longreach merge`.
#[derive(Debug, Args)]
pub struct MergeArgs {
    /// Folder for the merged results.csv and results.parquet.
    pub out: PathBuf,
    /// Output folders of the shard runs (default: every OUT/shard-*-of-* folder).
    pub shards: Vec<PathBuf>,
}

/// The scenario kinds a batch may run: register a new kind here (one line).
fn kinds() -> Vec<Arc<dyn ScenarioKind>> {
    let mut kinds = builtin_kinds();
    kinds.push(Arc::new(ArmKind));
    kinds
}

/// The long-reach arm (`longreach run` scenarios: `[arm]`, `[sim]`, transmissions).
///
/// Metrics: `tip_error_m`; per joint `<joint>_settling_time_s`, `_overshoot_pct`,
/// `_residual_vibration_rad`, `_final_error_rad`; per rope pair (by driven joint)
/// `<joint>_peak_tension_n`, `_min_tension_n`, `_slack_events`, `_safety_factor`,
/// `_static_safety_factor`.
#[derive(Debug)]
struct ArmKind;

impl ScenarioKind for ArmKind {
    fn name(&self) -> &'static str {
        "arm"
    }

    fn detect(&self, tree: &ScenarioTree) -> bool {
        tree.contains_key("arm")
    }

    fn check(&self, text: &str, file: &str, dir: &Path) -> Result<(), ScenarioError> {
        longreach_arm::scenario::parse(text, file, dir).map(|_| ())
    }

    fn portable_text(&self, text: &str, dir: &Path) -> String {
        longreach_arm::scenario::with_absolute_paths(text, dir)
    }

    fn run(
        &self,
        text: &str,
        file: &str,
        dir: &Path,
        keep_output: bool,
    ) -> std::result::Result<Outcome, RowError> {
        let sc = longreach_arm::scenario::parse(text, file, dir)
            .map_err(|e| RowError::Invalid(one_line(&e)))?;
        let (_, m) = longreach_arm::run::run(
            &sc.arm,
            sc.sim.duration_s,
            sc.sim.output_every,
            sc.sim.residual_window_s,
            &mut |_, _| {},
        )
        .map_err(|e| RowError::Failed(e.to_string()))?;
        let f = |v: f64| Some(Cell::Float(v));
        let o = |v: Option<f64>| v.map(Cell::Float);
        let mut metrics = vec![("tip_error_m".to_string(), f(m.tip_error_m))];
        for j in &m.joints {
            let n = &j.joint;
            metrics.push((format!("{n}_settling_time_s"), o(j.settling_time_s)));
            metrics.push((format!("{n}_overshoot_pct"), o(j.overshoot_pct)));
            metrics.push((
                format!("{n}_residual_vibration_rad"),
                f(j.residual_vibration_rad),
            ));
            metrics.push((format!("{n}_final_error_rad"), f(j.final_error_rad)));
        }
        for p in &m.pairs {
            let n = &p.joint;
            metrics.push((format!("{n}_peak_tension_n"), f(p.peak_tension_n)));
            metrics.push((format!("{n}_min_tension_n"), f(p.min_tension_n)));
            metrics.push((
                format!("{n}_slack_events"),
                Some(Cell::Int(i64::from(p.slack_events))),
            ));
            metrics.push((format!("{n}_safety_factor"), f(p.safety_factor)));
            metrics.push((
                format!("{n}_static_safety_factor"),
                f(p.static_safety_factor),
            ));
        }
        let output = if keep_output {
            Some(serde_json::to_value(&m).map_err(|e| RowError::Failed(e.to_string()))?)
        } else {
            None
        };
        Ok((metrics, output))
    }
}

/// Runs `longreach batch`.
pub fn run(args: &BatchArgs) -> Result<ExitCode> {
    let max_jobs = longreach_scenario::limits::max_jobs();
    if let Some(j) = args.jobs.filter(|&j| j == 0 || j > max_jobs) {
        bail!(
            "-j {j}: this machine runs at most {max_jobs} worker threads ({} per core)\n  fix: give -j between 1 and {max_jobs}, or leave it out for one per core",
            longreach_scenario::limits::JOBS_PER_CORE
        );
    }
    let batch = Batch::from_file(&args.file, &kinds())?;
    let shard = match &args.shard {
        Some(s) => Some(Shard::parse(s).map_err(|e| anyhow!(e))?),
        None => {
            Shard::from_env(|k| std::env::var(k).ok(), args.shard_count).map_err(|e| anyhow!(e))?
        }
    };
    let mine: Vec<usize> = (0..batch.len())
        .filter(|&i| shard.is_none_or(|s| s.contains(i)))
        .collect();
    if let Some(&bad) = args.rerun_select.iter().find(|&&i| i >= batch.len()) {
        bail!(
            "--rerun-select {bad}: the batch has scenarios 0..{} (list them with --dry-run)",
            batch.len().saturating_sub(1)
        );
    }
    if args.dry_run {
        return dry_run(&batch, shard, &mine);
    }
    let mut dir = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("out").join(&batch.name));
    if let Some(s) = shard {
        dir = dir.join(format!("shard-{}-of-{}", s.k, s.n));
    }
    let header = Header {
        longreach_batch_journal: 1,
        batch: batch.name.clone(),
        fingerprint: batch.fingerprint.clone(),
        total: batch.len(),
        shard,
        axes: batch.axis_names(),
    };
    crate::output::output_dir(&dir, "--out")?;
    let (mut journal, mut rows) = Journal::open(&dir, &header, args.resume)?;
    let done: std::collections::BTreeSet<usize> = rows.iter().map(|r| r.index).collect();
    let todo: Vec<usize> = mine.into_iter().filter(|i| !done.contains(i)).collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.jobs.unwrap_or(0))
        .build()
        .context("cannot start the worker threads")?;
    eprintln!(
        "batch {}: {} scenarios{}; {} done before, {} to run on {} threads -> {}",
        batch.name,
        batch.len(),
        shard.map_or_else(String::new, |s| format!(" (shard {s})")),
        done.len(),
        todo.len(),
        pool.current_num_threads(),
        dir.display()
    );
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::new(todo.len() as u64)
    } else {
        ProgressBar::hidden()
    };
    if let Ok(style) = ProgressStyle::with_template(
        "{bar:40} {pos}/{len} done, {msg}, {elapsed} elapsed, ETA {eta}",
    ) {
        bar.set_style(style);
    }
    let mut failed = rows.iter().filter(|r| r.status != Status::Ok).count();
    bar.set_message(format!("{failed} failed"));
    let options = RunOptions {
        outputs_dir: args.keep_outputs.then(|| dir.join("scenarios")),
    };
    let result = pool.install(|| {
        run_scenarios(&batch, &todo, &options, |row: Row| {
            journal.append(&row)?;
            if row.status != Status::Ok {
                failed += 1;
                bar.set_message(format!("{failed} failed"));
            }
            bar.inc(1);
            rows.push(row);
            Ok::<(), longreach_scenario::batch::JournalError>(())
        })
    });
    bar.finish_and_clear();
    journal.sync()?;
    result?;
    let code = write_tables(&dir, &header.axes, &rows)?;
    let selected: Vec<usize> = args
        .rerun_select
        .iter()
        .copied()
        .filter(|&i| shard.is_none_or(|s| s.contains(i)))
        .collect();
    if !selected.is_empty() {
        record_selected(&batch, &selected, &dir.join("rerun"), args.rerun_hz)?;
    }
    Ok(code)
}

/// Runs the `selected` scenarios again with a Rerun recorder into `dir/<index>.rrd`
/// (the same inputs give the same results, so the recording shows the row's run).
fn record_selected(batch: &Batch, selected: &[usize], dir: &Path, hz: f64) -> Result<()> {
    crate::output::output_dir(dir, "--out")?;
    for &i in selected {
        let s = batch.scenario(i);
        let label = format!("{} scenario {i}", batch.file);
        let target = longreach_viz::Target::Save(Some(dir.join(format!("{i}.rrd"))));
        let rec = longreach_viz::Recorder::start(&label, &target, dir, hz)?;
        let result: Result<()> = match batch.kind.name() {
            "arm" => {
                let sc = longreach_arm::scenario::parse(&s.text, &label, &batch.base_dir)
                    .map_err(|e| anyhow!("{e}"))?;
                let mut viewer = longreach_viz::arm::ArmLogger::new(&rec, &sc.arm);
                let r = longreach_arm::run::run_observed(
                    &sc.arm,
                    sc.sim.duration_s,
                    sc.sim.output_every,
                    sc.sim.residual_window_s,
                    &mut |_, _| {},
                    &mut |st| viewer.observe(st),
                );
                viewer.finish();
                r.map(|_| ()).map_err(|e| anyhow!("{label}: {e}"))
            }
            "bode" => {
                let sc = longreach_scenario::BodeScenario::from_str(&s.text, &label)
                    .map_err(|e| anyhow!("{e}"))?;
                crate::bode::simulate(&sc, &rec)
                    .map(|_| ())
                    .map_err(|e| anyhow!("{label}: {e}"))
            }
            other => Err(anyhow!(
                "--rerun-select: scenarios of kind `{other}` cannot be recorded yet"
            )),
        };
        crate::rerun_args::finish(rec);
        if let Err(e) = result {
            eprintln!("{e:#}");
        }
    }
    Ok(())
}

fn dry_run(batch: &Batch, shard: Option<Shard>, mine: &[usize]) -> Result<ExitCode> {
    eprintln!(
        "batch {}: {} scenarios of kind {}{}",
        batch.name,
        batch.len(),
        batch.kind.name(),
        shard.map_or_else(String::new, |s| format!(", {} in shard {s}", mine.len()))
    );
    let mut w = csv::Writer::from_writer(std::io::stdout().lock());
    let mut header = vec!["index".to_string()];
    header.extend(batch.axis_names());
    w.write_record(&header)?;
    for &i in mine {
        let s = batch.scenario(i);
        let mut record = vec![i.to_string()];
        record.extend(s.axes.iter().map(Cell::text));
        w.write_record(&record)?;
    }
    w.flush()?;
    Ok(ExitCode::SUCCESS)
}

/// Writes results.csv and results.parquet (sorted by index) atomically; prints a summary
/// and returns exit code 1 when a row is not ok.
fn write_tables(dir: &Path, axes: &[String], rows: &[Row]) -> Result<ExitCode> {
    let table = Table::build(axes, rows);
    let csv_path = dir.join("results.csv");
    write_atomic(&csv_path, &table.to_csv())?;
    let pq_path = dir.join("results.parquet");
    write_atomic_with(&pq_path, |tmp| write_parquet(&table, tmp))?;
    let bad: Vec<&Row> = {
        let mut bad: Vec<&Row> = rows.iter().filter(|r| r.status != Status::Ok).collect();
        bad.sort_by_key(|r| r.index);
        bad
    };
    println!(
        "{} rows: {} ok, {} invalid, {} failed -> {} and {}",
        rows.len(),
        rows.len() - bad.len(),
        bad.iter().filter(|r| r.status == Status::Invalid).count(),
        bad.iter().filter(|r| r.status == Status::Failed).count(),
        csv_path.display(),
        pq_path.display()
    );
    for r in bad.iter().take(5) {
        eprintln!("scenario {} {}: {}", r.index, r.status.as_str(), r.error);
    }
    if bad.len() > 5 {
        eprintln!(
            "... and {} more (see the status and error columns)",
            bad.len() - 5
        );
    }
    Ok(if bad.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// Runs `longreach merge`.
pub fn merge_run(args: &MergeArgs) -> Result<ExitCode> {
    let shards = if args.shards.is_empty() {
        let mut found: Vec<PathBuf> = std::fs::read_dir(&args.out)
            .with_context(|| format!("cannot list {}", args.out.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.is_dir()
                    && p.file_name()
                        .is_some_and(|n| n.to_string_lossy().starts_with("shard-"))
            })
            .collect();
        found.sort();
        if found.is_empty() {
            bail!(
                "{} holds no shard-K-of-N folders; give the shard folders after OUT",
                args.out.display()
            );
        }
        found
    } else {
        args.shards.clone()
    };
    let (header, rows) = merge(&shards)?;
    crate::output::output_dir(&args.out, "--out")?;
    eprintln!(
        "merged {} shard folders of batch {}: {} rows",
        shards.len(),
        header.batch,
        rows.len()
    );
    write_tables(&args.out, &header.axes, &rows)
}

/// The table as one Parquet row group (Snappy): columns typed from their values
/// (BOOLEAN, INT64, DOUBLE, or UTF-8 strings); columns with empty cells are OPTIONAL.
fn write_parquet(table: &Table, path: &Path) -> Result<()> {
    let kinds: Vec<CellKind> = table.columns.iter().map(|c| c.kind()).collect();
    let fields = table
        .columns
        .iter()
        .zip(&kinds)
        .map(|(c, kind)| {
            let (physical, logical) = match kind {
                CellKind::Bool => (Physical::BOOLEAN, None),
                CellKind::Int => (Physical::INT64, None),
                CellKind::Float => (Physical::DOUBLE, None),
                CellKind::Text => (Physical::BYTE_ARRAY, Some(LogicalType::String)),
            };
            let repetition = if c.cells.iter().all(Option::is_some) {
                Repetition::REQUIRED
            } else {
                Repetition::OPTIONAL
            };
            Type::primitive_type_builder(&c.name, physical)
                .with_repetition(repetition)
                .with_logical_type(logical)
                .build()
                .map(Arc::new)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let schema = Arc::new(
        Type::group_type_builder("longreach_batch")
            .with_fields(fields)
            .build()?,
    );
    let props = Arc::new(
        WriterProperties::builder()
            .set_compression(Compression::SNAPPY)
            .build(),
    );
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut writer = SerializedFileWriter::new(file, schema, props)?;
    let mut group = writer.next_row_group()?;
    for (c, kind) in table.columns.iter().zip(&kinds) {
        let mut col = group
            .next_column()?
            .ok_or_else(|| anyhow!("parquet writer has fewer columns than the table"))?;
        let def: Vec<i16> = c.cells.iter().map(|x| i16::from(x.is_some())).collect();
        let levels = c.cells.iter().any(Option::is_none).then_some(&def[..]);
        let present = c.cells.iter().flatten();
        match kind {
            CellKind::Bool => {
                let v: Vec<bool> = present.map(|x| matches!(x, Cell::Bool(true))).collect();
                col.typed::<BoolType>().write_batch(&v, levels, None)?;
            }
            CellKind::Int => {
                let v: Vec<i64> = present
                    .map(|x| if let Cell::Int(i) = x { *i } else { 0 })
                    .collect();
                col.typed::<Int64Type>().write_batch(&v, levels, None)?;
            }
            CellKind::Float => {
                let v: Vec<f64> = present.map(|x| x.as_f64().unwrap_or(f64::NAN)).collect();
                col.typed::<DoubleType>().write_batch(&v, levels, None)?;
            }
            CellKind::Text => {
                let v: Vec<ByteArray> = present
                    .map(|x| ByteArray::from(x.text().as_str()))
                    .collect();
                col.typed::<ByteArrayType>().write_batch(&v, levels, None)?;
            }
        }
        col.close()?;
    }
    group.close()?;
    writer.close()?;
    Ok(())
}
