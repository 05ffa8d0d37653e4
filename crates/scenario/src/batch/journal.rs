//! The journal: an append-only JSON-lines file of completed rows (`journal.jsonl`), one
//! header line then one line per row, synced to disk at least every 100 ms. An
//! interrupted batch resumes from it; a torn last line (a kill mid-write) is dropped.
//! Shard journals merge into the rows of the whole batch.

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use super::row::{Cell, Row, Status};
use super::shard::Shard;

/// Journal file name inside an output folder.
pub const JOURNAL_FILE: &str = "journal.jsonl";

/// First line of a journal: which batch, which shard, which columns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Format version (1).
    pub longreach_batch_journal: u32,
    /// Batch name.
    pub batch: String,
    /// Digest of the batch and base texts.
    pub fingerprint: String,
    /// Scenarios in the whole batch.
    pub total: usize,
    /// The shard this journal covers, `None` for the whole batch.
    pub shard: Option<Shard>,
    /// Axis column names.
    pub axes: Vec<String>,
}

impl Header {
    /// Indices this journal must hold when complete.
    pub fn expected(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.total).filter(|&i| self.shard.is_none_or(|s| s.contains(i)))
    }
}

/// Journal problems, each with what to do.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// Reading or writing failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
    /// A journal exists and `--resume` was not given.
    #[error("{path} already holds a batch journal; pass --resume to continue that run, or remove the folder (or choose another --out) to start over")]
    Exists {
        /// The journal.
        path: PathBuf,
    },
    /// The journal belongs to another batch, shard or version of the batch file.
    #[error("{path} was written by a different batch ({what}); remove the folder or choose another --out to run this batch")]
    Mismatch {
        /// The journal.
        path: PathBuf,
        /// What differs.
        what: String,
    },
    /// The first line is not a journal header.
    #[error("{path}: line 1 is not a longreach batch journal header; remove the file or choose another --out")]
    BadHeader {
        /// The journal.
        path: PathBuf,
    },
    /// A row of the journal cannot be a row of this batch (edited or damaged file).
    #[error("{path}:{line}: {what}; the journal was edited or damaged: remove the folder (or choose another --out) and run the batch again")]
    BadRow {
        /// The journal.
        path: PathBuf,
        /// 1-based line of the row.
        line: usize,
        /// What is wrong with it.
        what: String,
    },
    /// Shard journals do not join into the whole batch.
    #[error("cannot merge: {0}")]
    Merge(String),
}

fn io_err(path: &Path) -> impl FnOnce(io::Error) -> JournalError + '_ {
    move |source| JournalError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// An open journal, appending rows.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: File,
    last_sync: Instant,
}

/// Reads a journal: its header and its complete rows (first occurrence of each index),
/// and the byte length of the valid prefix.
pub fn read(path: &Path) -> Result<(Header, Vec<Row>, u64), JournalError> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    let mut offset = 0usize;
    let mut header: Option<Header> = None;
    let mut rows: BTreeMap<usize, Row> = BTreeMap::new();
    let mut line_no = 0usize;
    while let Some(len) = bytes[offset..].iter().position(|&b| b == b'\n') {
        let line = &bytes[offset..offset + len];
        line_no += 1;
        if let Some(h) = &header {
            match serde_json::from_slice::<Row>(line) {
                Ok(row) => {
                    if let Err(what) = check_row(h, &row) {
                        return Err(JournalError::BadRow {
                            path: path.into(),
                            line: line_no,
                            what,
                        });
                    }
                    rows.entry(row.index).or_insert(row);
                }
                // A damaged line ends the valid prefix; the rest is redone.
                Err(_) => break,
            }
        } else {
            let h: Header = serde_json::from_slice(line)
                .map_err(|_| JournalError::BadHeader { path: path.into() })?;
            if h.total == 0 || h.total > crate::limits::MAX_SCENARIOS {
                return Err(JournalError::BadRow {
                    path: path.into(),
                    line: 1,
                    what: format!(
                        "field `total` = {} is not a batch size (1 to {})",
                        h.total,
                        crate::limits::MAX_SCENARIOS
                    ),
                });
            }
            header = Some(h);
        }
        offset += len + 1;
    }
    let header = header.ok_or(JournalError::BadHeader { path: path.into() })?;
    Ok((header, rows.into_values().collect(), offset as u64))
}

/// Whether `row` can be a row of `header`'s batch: its index inside the batch and the
/// journal's shard, one value per axis column, and every metric of an `ok` row a finite
/// number. `resume` and `merge` read journals through this one check.
fn check_row(header: &Header, row: &Row) -> Result<(), String> {
    if row.index >= header.total {
        return Err(format!(
            "row {} is past the batch's {} scenarios",
            row.index, header.total
        ));
    }
    if let Some(s) = header.shard {
        if !s.contains(row.index) {
            return Err(format!(
                "row {} is not in this journal's shard {s}",
                row.index
            ));
        }
    }
    if row.axes.len() != header.axes.len() {
        return Err(format!(
            "row {} has {} axis values for {} axis columns",
            row.index,
            row.axes.len(),
            header.axes.len()
        ));
    }
    if row.status == Status::Ok {
        for (name, cell) in &row.metrics {
            if let Some(Cell::Float(v)) = cell {
                if !v.is_finite() {
                    return Err(format!(
                        "row {}: metric `{name}` = {v} is not a finite number",
                        row.index
                    ));
                }
            }
        }
    }
    Ok(())
}

impl Journal {
    /// Opens the journal in `dir` for `header`'s batch: creates it, or with `resume`
    /// continues an existing one (same batch and shard), returning the rows it holds.
    pub fn open(
        dir: &Path,
        header: &Header,
        resume: bool,
    ) -> Result<(Self, Vec<Row>), JournalError> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let path = dir.join(JOURNAL_FILE);
        let mut rows = Vec::new();
        let file = if path.exists() {
            if !resume {
                return Err(JournalError::Exists { path });
            }
            let (old, kept, valid_len) = read(&path)?;
            let what = if old.fingerprint != header.fingerprint || old.total != header.total {
                Some("the batch file or its base scenario changed".to_string())
            } else if old.shard != header.shard {
                Some(format!(
                    "shard {} there, {} now",
                    old.shard.map_or("none".into(), |s| s.to_string()),
                    header.shard.map_or("none".into(), |s| s.to_string())
                ))
            } else if old.axes != header.axes {
                Some("the axis columns differ".into())
            } else {
                None
            };
            if let Some(what) = what {
                return Err(JournalError::Mismatch { path, what });
            }
            rows = kept;
            let file = OpenOptions::new()
                .write(true)
                .open(&path)
                .map_err(io_err(&path))?;
            file.set_len(valid_len).map_err(io_err(&path))?;
            drop(file);
            OpenOptions::new()
                .append(true)
                .open(&path)
                .map_err(io_err(&path))?
        } else {
            let mut file = File::create(&path).map_err(io_err(&path))?;
            let mut line = serde_json::to_vec(header).map_err(|e| JournalError::Io {
                path: path.clone(),
                source: e.into(),
            })?;
            line.push(b'\n');
            file.write_all(&line).map_err(io_err(&path))?;
            file.sync_all().map_err(io_err(&path))?;
            file
        };
        Ok((
            Self {
                path,
                file,
                last_sync: Instant::now(),
            },
            rows,
        ))
    }

    /// Appends one row as one line (a single write), syncing at most every 100 ms.
    pub fn append(&mut self, row: &Row) -> Result<(), JournalError> {
        let mut line = serde_json::to_vec(row).map_err(|e| JournalError::Io {
            path: self.path.clone(),
            source: e.into(),
        })?;
        line.push(b'\n');
        self.file.write_all(&line).map_err(io_err(&self.path))?;
        if self.last_sync.elapsed() >= Duration::from_millis(100) {
            self.sync()?;
        }
        Ok(())
    }

    /// Forces the rows written so far to disk.
    pub fn sync(&mut self) -> Result<(), JournalError> {
        self.file.sync_data().map_err(io_err(&self.path))?;
        self.last_sync = Instant::now();
        Ok(())
    }
}

/// Joins shard journals (folders holding `journal.jsonl`) into the rows of the whole
/// batch, sorted by index: every journal must come from the same batch, the shards must
/// be disjoint and together hold every scenario of the expansion.
pub fn merge(dirs: &[PathBuf]) -> Result<(Header, Vec<Row>), JournalError> {
    if dirs.is_empty() {
        return Err(JournalError::Merge("no shard folders given".into()));
    }
    let mut first: Option<(Header, PathBuf)> = None;
    let mut owner: BTreeMap<usize, (Row, PathBuf)> = BTreeMap::new();
    let mut shards_seen: BTreeMap<usize, PathBuf> = BTreeMap::new();
    for dir in dirs {
        let path = dir.join(JOURNAL_FILE);
        if !path.exists() {
            return Err(JournalError::Merge(format!(
                "{} has no {JOURNAL_FILE}: give the output folders of the shard runs",
                dir.display()
            )));
        }
        let (header, rows, _) = read(&path)?;
        match &first {
            None => first = Some((header.clone(), dir.clone())),
            Some((h, d)) => {
                if h.fingerprint != header.fingerprint
                    || h.total != header.total
                    || h.axes != header.axes
                {
                    return Err(JournalError::Merge(format!(
                        "{} and {} come from different batch files (or versions of one)",
                        d.display(),
                        dir.display()
                    )));
                }
                let n = |s: Option<Shard>| s.map_or(1, |s| s.n);
                if n(h.shard) != n(header.shard) {
                    return Err(JournalError::Merge(format!(
                        "{} was split into {} shards but {} into {}; merge shards of one split",
                        d.display(),
                        n(h.shard),
                        dir.display(),
                        n(header.shard)
                    )));
                }
            }
        }
        let k = header.shard.map_or(1, |s| s.k);
        if let Some(other) = shards_seen.insert(k, dir.clone()) {
            return Err(JournalError::Merge(format!(
                "{} and {} are both shard {k}; give each shard once",
                other.display(),
                dir.display()
            )));
        }
        for row in rows {
            if !header.shard.is_none_or(|s| s.contains(row.index)) || row.index >= header.total {
                return Err(JournalError::Merge(format!(
                    "{} holds row {} outside its shard",
                    dir.display(),
                    row.index
                )));
            }
            if let Some((_, other)) = owner.get(&row.index) {
                return Err(JournalError::Merge(format!(
                    "row {} is in both {} and {}",
                    row.index,
                    other.display(),
                    dir.display()
                )));
            }
            owner.insert(row.index, (row, dir.clone()));
        }
    }
    let Some((mut header, _)) = first else {
        return Err(JournalError::Merge("no shard folders given".into()));
    };
    let n = header.shard.map_or(1, |s| s.n);
    if let Some(k) = (1..=n).find(|k| !shards_seen.contains_key(k)) {
        return Err(JournalError::Merge(format!(
            "shard {k}/{n} is missing; run it (--shard {k}/{n}) and give its folder too"
        )));
    }
    let missing: Vec<usize> = (0..header.total)
        .filter(|i| !owner.contains_key(i))
        .collect();
    if let Some(&i) = missing.first() {
        let k = i % n + 1;
        return Err(JournalError::Merge(format!(
            "{} of {} scenarios have no row (first: index {i}, shard {k}/{n}); finish that shard with --resume, then merge again",
            missing.len(),
            header.total
        )));
    }
    header.shard = None;
    Ok((header, owner.into_values().map(|(r, _)| r).collect()))
}
