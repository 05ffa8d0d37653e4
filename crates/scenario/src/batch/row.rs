//! Result rows and the results table: one row per scenario (index, axis values,
//! metrics, status, error), rendered as CSV with round-trip float formatting.

use serde::{Deserialize, Serialize};

/// One value of the table: an axis value or a metric.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Cell {
    /// A flag (`slack`).
    #[serde(rename = "b")]
    Bool(bool),
    /// An integer.
    #[serde(rename = "i")]
    Int(i64),
    /// A float, written with the shortest representation that reads back bitwise
    /// (as a string in the journal, parsed by the standard library: exact both ways).
    #[serde(rename = "f", with = "exact_f64")]
    Float(f64),
    /// Text (rope names; arrays and tables as inline TOML).
    #[serde(rename = "s")]
    Text(String),
}

impl Cell {
    /// The cell of a TOML value (arrays and tables become inline TOML text).
    pub fn from_toml(value: &toml::Value) -> Self {
        match value {
            toml::Value::Boolean(b) => Self::Bool(*b),
            toml::Value::Integer(i) => Self::Int(*i),
            toml::Value::Float(f) => Self::Float(*f),
            toml::Value::String(s) => Self::Text(s.clone()),
            other => Self::Text(other.to_string()),
        }
    }

    /// The CSV text: `{:?}` of f64 is the shortest string that parses back to the same
    /// bits, and always reads as a float (`49.0`, `1e-20`).
    pub fn text(&self) -> String {
        match self {
            Self::Bool(b) => b.to_string(),
            Self::Int(i) => i.to_string(),
            Self::Float(f) => format!("{f:?}"),
            Self::Text(s) => s.clone(),
        }
    }

    /// The value as a float, for integers and floats.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Self::Int(i) => Some(*i as f64),
            Self::Float(f) => Some(*f),
            _ => None,
        }
    }
}

/// f64 as its shortest round-trip text (`{:?}`), read back with `str::parse` (exact;
/// JSON number parsing is not guaranteed to be).
mod exact_f64 {
    use serde::{de::Error, Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(&format_args!("{v:?}"))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        let text = String::deserialize(d)?;
        text.parse()
            .map_err(|_| D::Error::custom(format!("`{text}` is not a float")))
    }
}

/// Outcome of a scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Ran; every metric is finite.
    Ok,
    /// The model rejected the expanded scenario (e.g. a negative length); not run.
    Invalid,
    /// The run failed (numerical blow-up, a non-finite metric).
    Failed,
}

impl Status {
    /// `ok`, `invalid` or `failed`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Invalid => "invalid",
            Self::Failed => "failed",
        }
    }
}

/// One scenario's row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Scenario index in the batch's expansion (0-based).
    pub index: usize,
    /// Axis values, in the batch's column order.
    pub axes: Vec<Cell>,
    /// Named metrics in the kind's order; `None` where a metric does not exist
    /// (e.g. no resonance inside the tested band).
    pub metrics: Vec<(String, Option<Cell>)>,
    /// Outcome.
    pub status: Status,
    /// Error message (one line), empty when ok.
    pub error: String,
}

/// Type of a column, from its values (for Parquet).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellKind {
    /// Every value is a flag.
    Bool,
    /// Every value is an integer.
    Int,
    /// Every value is a number (or the column is empty).
    Float,
    /// Anything else: the CSV text.
    Text,
}

/// One column of the results table.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// Header.
    pub name: String,
    /// One cell per row; `None` is an empty CSV field and a Parquet null.
    pub cells: Vec<Option<Cell>>,
}

impl Column {
    /// The narrowest type holding every non-empty cell (an empty column is a float
    /// column, except `status` and `error`, which are always text).
    pub fn kind(&self) -> CellKind {
        let mut kind: Option<CellKind> = None;
        for cell in self.cells.iter().flatten() {
            let k = match cell {
                Cell::Bool(_) => CellKind::Bool,
                Cell::Int(_) => CellKind::Int,
                Cell::Float(_) => CellKind::Float,
                Cell::Text(_) => CellKind::Text,
            };
            kind = Some(match (kind, k) {
                (None, k) => k,
                (Some(a), b) if a == b => a,
                (Some(CellKind::Int), CellKind::Float) | (Some(CellKind::Float), CellKind::Int) => {
                    CellKind::Float
                }
                _ => CellKind::Text,
            });
        }
        kind.unwrap_or(if self.name == "error" || self.name == "status" {
            CellKind::Text
        } else {
            CellKind::Float
        })
    }
}

/// The results table: `index`, the axis columns, the metric columns (in order of first
/// appearance by index), `status`, `error`; rows sorted by index.
#[derive(Debug, Clone, PartialEq)]
pub struct Table {
    /// Columns, left to right.
    pub columns: Vec<Column>,
}

impl Table {
    /// Builds the table from rows in any order (sorted by index here).
    pub fn build(axis_names: &[String], rows: &[Row]) -> Self {
        let mut sorted: Vec<&Row> = rows.iter().collect();
        sorted.sort_by_key(|r| r.index);
        let mut metric_names: Vec<&str> = Vec::new();
        for row in &sorted {
            for (name, _) in &row.metrics {
                if !metric_names.contains(&name.as_str()) {
                    metric_names.push(name);
                }
            }
        }
        let mut columns = vec![Column {
            name: "index".into(),
            cells: sorted
                .iter()
                .map(|r| Some(Cell::Int(r.index as i64)))
                .collect(),
        }];
        for (i, name) in axis_names.iter().enumerate() {
            columns.push(Column {
                name: name.clone(),
                cells: sorted.iter().map(|r| r.axes.get(i).cloned()).collect(),
            });
        }
        for name in metric_names {
            columns.push(Column {
                name: name.to_string(),
                cells: sorted
                    .iter()
                    .map(|r| {
                        r.metrics
                            .iter()
                            .find(|(n, _)| n == name)
                            .and_then(|(_, c)| c.clone())
                    })
                    .collect(),
            });
        }
        columns.push(Column {
            name: "status".into(),
            cells: sorted
                .iter()
                .map(|r| Some(Cell::Text(r.status.as_str().into())))
                .collect(),
        });
        columns.push(Column {
            name: "error".into(),
            cells: sorted
                .iter()
                .map(|r| (!r.error.is_empty()).then(|| Cell::Text(r.error.clone())))
                .collect(),
        });
        Self { columns }
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, |c| c.cells.len())
    }

    /// True when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The table as CSV (header line, then one line per row; RFC 4180 quoting).
    pub fn to_csv(&self) -> Vec<u8> {
        let mut w = csv::Writer::from_writer(Vec::new());
        let header: Vec<&str> = self.columns.iter().map(|c| c.name.as_str()).collect();
        // Writing into a Vec cannot fail.
        let _ = w.write_record(&header);
        for r in 0..self.len() {
            let record: Vec<String> = self
                .columns
                .iter()
                .map(|c| c.cells[r].as_ref().map_or_else(String::new, Cell::text))
                .collect();
            let _ = w.write_record(&record);
        }
        w.into_inner().unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(index: usize, metric: Option<f64>, extra: bool) -> Row {
        let mut metrics = vec![("gain_db".to_string(), metric.map(Cell::Float))];
        if extra {
            metrics.push(("slack".into(), Some(Cell::Bool(true))));
        }
        Row {
            index,
            axes: vec![Cell::Text(format!("rope{index}"))],
            metrics,
            status: Status::Ok,
            error: String::new(),
        }
    }

    #[test]
    fn table_sorts_rows_and_unions_metrics_in_index_order() {
        let rows = vec![
            row(2, Some(0.1), true),
            row(0, None, false),
            row(1, Some(1e-20), false),
        ];
        let t = Table::build(&["rig.rope".to_string()], &rows);
        let csv = String::from_utf8(t.to_csv()).unwrap();
        assert_eq!(
            csv,
            "index,rig.rope,gain_db,slack,status,error\n\
             0,rope0,,,ok,\n\
             1,rope1,1e-20,,ok,\n\
             2,rope2,0.1,true,ok,\n"
        );
        // Round trip of the float text.
        let back: f64 = "1e-20".parse().unwrap();
        assert_eq!(back.to_bits(), 1e-20_f64.to_bits());
        assert_eq!(t.columns[2].kind(), CellKind::Float);
        assert_eq!(t.columns[3].kind(), CellKind::Bool);
        assert_eq!(t.columns[1].kind(), CellKind::Text);
    }

    #[test]
    fn journal_encoding_round_trips_bitwise() {
        let r = Row {
            index: 3,
            axes: vec![
                Cell::Float(0.1 + 0.2),
                Cell::Int(-4),
                Cell::Text("a,\"b\"".into()),
            ],
            metrics: vec![
                ("x".into(), Some(Cell::Float(f64::MIN_POSITIVE))),
                ("y".into(), None),
            ],
            status: Status::Failed,
            error: "boom".into(),
        };
        let line = serde_json::to_string(&r).unwrap();
        let back: Row = serde_json::from_str(&line).unwrap();
        assert_eq!(back, r);
        // Many bit patterns (a 64-bit LCG), including ones JSON number parsing gets wrong.
        let mut x: u64 = 12345;
        for _ in 0..20_000 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let v = f64::from_bits(x);
            if !v.is_finite() {
                continue;
            }
            let cell = Cell::Float(v);
            let back: Cell = serde_json::from_str(&serde_json::to_string(&cell).unwrap()).unwrap();
            let Cell::Float(w) = back else {
                panic!("{back:?}")
            };
            assert_eq!(w.to_bits(), v.to_bits());
            let text = cell.text();
            assert_eq!(text.parse::<f64>().unwrap().to_bits(), v.to_bits());
        }
    }
}
