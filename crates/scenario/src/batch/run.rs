//! Running scenarios in parallel: rayon workers expand and run scenarios, one writer
//! thread receives the rows in completion order (journal, progress).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;

use rayon::prelude::*;

use super::expand::Batch;
use super::kind::RowError;
use super::row::{Cell, Row, Status};

/// Options of a run.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// When set, each scenario's expanded TOML (`<index>.toml`) and full output
    /// (`<index>.json`) are written into this folder.
    pub outputs_dir: Option<PathBuf>,
}

/// Expands and runs scenario `index` into its row. Never panics on a bad scenario:
/// failures become `invalid` or `failed` rows.
pub fn run_one(batch: &Batch, index: usize, options: &RunOptions) -> Row {
    let scenario = batch.scenario(index);
    let label = format!("{} scenario {index}", batch.file);
    let keep = options.outputs_dir.is_some();
    let result = batch
        .kind
        .run(&scenario.text, &label, &batch.base_dir, keep)
        .and_then(|(metrics, output)| {
            // A NaN or infinite metric is a numerical blow-up, never a result.
            match metrics.iter().find_map(|(name, cell)| match cell {
                Some(Cell::Float(v)) if !v.is_finite() => {
                    Some(format!("numerical blow-up: metric `{name}` is {v}"))
                }
                _ => None,
            }) {
                Some(e) => Err(RowError::Failed(e)),
                None => Ok((metrics, output)),
            }
        });
    let (metrics, status, error, output) = match result {
        Ok((metrics, output)) => (metrics, Status::Ok, String::new(), output),
        Err(RowError::Invalid(e)) => (Vec::new(), Status::Invalid, e, None),
        Err(RowError::Failed(e)) => (Vec::new(), Status::Failed, e, None),
    };
    let mut row = Row {
        index,
        axes: scenario.axes,
        metrics,
        status,
        error: error.replace('\n', " "),
    };
    if let Some(dir) = &options.outputs_dir {
        let mut write = |name: String, bytes: &[u8]| {
            let path = dir.join(&name);
            if let Err(e) = crate::atomic::write_file(&path, bytes) {
                if row.status == Status::Ok {
                    row.status = Status::Failed;
                    row.error = e.to_string().replace('\n', " ");
                }
            }
        };
        let kept = batch.kind.portable_text(&scenario.text, &batch.base_dir);
        write(format!("{index}.toml"), kept.as_bytes());
        if let Some(output) = output {
            let json = serde_json::to_vec_pretty(&output).unwrap_or_default();
            write(format!("{index}.json"), &json);
        }
    }
    row
}

/// Runs the scenarios `todo` on the current rayon pool (call it inside
/// `ThreadPool::install` to choose the thread count) and hands each row to `sink` on
/// one writer thread, in completion order. The first error of `sink` stops the run
/// (scenarios already started finish, no new ones start) and is returned.
pub fn run_scenarios<E: Send>(
    batch: &Batch,
    todo: &[usize],
    options: &RunOptions,
    mut sink: impl FnMut(Row) -> Result<(), E> + Send,
) -> Result<(), E> {
    if let Some(dir) = &options.outputs_dir {
        let _ = std::fs::create_dir_all(dir);
    }
    let stop = AtomicBool::new(false);
    let (tx, rx) = mpsc::sync_channel::<Row>(1024);
    std::thread::scope(|scope| {
        let writer = scope.spawn(|| {
            for row in rx {
                if let Err(e) = sink(row) {
                    stop.store(true, Ordering::Relaxed);
                    return Err(e);
                }
            }
            Ok(())
        });
        todo.par_iter().for_each_with(tx, |tx, &index| {
            if stop.load(Ordering::Relaxed) {
                return;
            }
            // A closed channel means the writer stopped; the flag ends the run.
            let _ = tx.send(run_one(batch, index, options));
        });
        match writer.join() {
            Ok(result) => result,
            Err(panic) => std::panic::resume_unwind(panic),
        }
    })
}
