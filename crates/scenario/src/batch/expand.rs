//! Batch files: parsing, the structural checks made before anything runs, and the
//! expansion of scenario `i` (mixed-radix over the dimensions, first dimension slowest;
//! random axes drawn from ChaCha8 seeded by `seed` on stream `i`).

use std::path::Path;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, Uniform};
use serde::Deserialize;
use toml::{Table, Value};

use crate::error::ScenarioError;
use crate::locate::line_of;
use crate::spec::{field_error, from_toml};

use std::path::PathBuf;
use std::sync::Arc;

use super::kind::ScenarioKind;
use super::path;
use super::row::Cell;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BatchSpec {
    #[serde(default)]
    name: Option<String>,
    base: Value,
    #[serde(default)]
    set: Table,
    #[serde(default)]
    axis: Vec<AxisSpec>,
    #[serde(default)]
    case: Vec<Table>,
    #[serde(default)]
    random: Vec<RandomSpec>,
    #[serde(default)]
    seed: Option<u64>,
    #[serde(default)]
    samples: Option<usize>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct AxisSpec {
    path: String,
    values: Vec<Value>,
    #[serde(default)]
    zip: Option<String>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct NormalSpec {
    mean: f64,
    std_dev: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RandomSpec {
    path: String,
    #[serde(default)]
    uniform: Option<[f64; 2]>,
    #[serde(default)]
    normal: Option<NormalSpec>,
    #[serde(default)]
    choice: Option<Vec<Value>>,
}

/// How a random axis draws.
#[derive(Debug, Clone)]
enum Draw {
    Uniform(Uniform<f64>),
    Normal(Normal<f64>),
    Choice(Vec<Value>),
}

#[derive(Debug, Clone)]
struct RandomAxis {
    column: usize,
    draw: Draw,
}

/// A dimension of the product: its points, each setting some columns.
#[derive(Debug, Clone)]
struct Dim {
    points: Vec<Vec<(usize, Value)>>,
}

/// A column of axis values: a scenario path, or the `sample` counter.
#[derive(Debug, Clone)]
struct AxisColumn {
    name: String,
    is_path: bool,
}

/// A parsed, checked batch: expands scenario `i` on demand.
#[derive(Debug, Clone)]
pub struct Batch {
    /// Batch name (`name` key, or the file stem): the default output folder.
    pub name: String,
    /// The batch file, for messages.
    pub file: String,
    /// Kind of every scenario (the base's `kind`, or detected from its tables).
    pub kind: Arc<dyn ScenarioKind>,
    /// Folder the base scenario's relative paths resolve against (the base file's folder,
    /// or the batch file's for an inline base).
    pub base_dir: PathBuf,
    /// Digest of the batch text and the base text: a journal belongs to one batch.
    pub fingerprint: String,
    base: Table,
    columns: Vec<AxisColumn>,
    dims: Vec<Dim>,
    random: Vec<RandomAxis>,
    seed: u64,
    total: usize,
}

/// One expanded scenario.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Index in the expansion.
    pub index: usize,
    /// Axis values, in column order.
    pub axes: Vec<Cell>,
    /// The scenario as TOML text.
    pub text: String,
}

fn err(text: &str, file: &str, field: &str, message: String, fix: String) -> ScenarioError {
    ScenarioError {
        file: file.to_string(),
        line: line_of(text, field),
        field: field.to_string(),
        message,
        fix,
    }
}

/// Line of a quoted dotted key (`"rig.rope" = ...`) inside the table at `table_path`.
fn line_of_key(text: &str, table_path: &str, key: &str) -> Option<usize> {
    let start = line_of(text, table_path).unwrap_or(1);
    let quoted = [format!("\"{key}\""), format!("'{key}'")];
    text.lines()
        .enumerate()
        .skip(start - 1)
        .find(|(_, l)| {
            quoted
                .iter()
                .any(|q| l.trim_start().starts_with(q.as_str()))
        })
        .map(|(i, _)| i + 1)
        .or(Some(start))
}

/// 64-bit FNV-1a, as 16 hex digits.
/// Fingerprint of a batch for `--resume`: the batch text, the base text and the
/// contents of every file the base names (a string value that is an existing file
/// relative to the base's folder: URDF, CSV commands...), so that editing a
/// referenced file makes an old journal stale.
fn fingerprint(text: &str, base_text: &str, base: &Table, base_dir: &Path) -> String {
    fn files(v: &Value, dir: &Path, out: &mut Vec<PathBuf>) {
        match v {
            Value::String(s) => {
                let p = dir.join(s);
                if !s.is_empty() && p.is_file() {
                    out.push(p);
                }
            }
            Value::Array(a) => a.iter().for_each(|x| files(x, dir, out)),
            Value::Table(t) => t.values().for_each(|x| files(x, dir, out)),
            _ => {}
        }
    }
    let mut paths = Vec::new();
    base.values().for_each(|v| files(v, base_dir, &mut paths));
    let contents: Vec<String> = paths
        .iter()
        .map(|p| String::from_utf8_lossy(&std::fs::read(p).unwrap_or_default()).into_owned())
        .collect();
    let mut parts = vec![text, base_text];
    parts.extend(contents.iter().map(String::as_str));
    fnv1a(&parts)
}

fn fnv1a(parts: &[&str]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for part in parts {
        for b in part.bytes().chain([0u8]) {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    format!("{h:016x}")
}

impl Batch {
    /// Reads and checks a batch file; a `base = "file"` is read relative to it. `kinds`
    /// are the scenario kinds the base may be of (e.g. [`super::builtin_kinds`]).
    pub fn from_file(file: &Path, kinds: &[Arc<dyn ScenarioKind>]) -> Result<Self, ScenarioError> {
        let name = file.display().to_string();
        let text = std::fs::read_to_string(file).map_err(|e| ScenarioError {
            file: name.clone(),
            line: None,
            field: String::new(),
            message: format!("cannot read the batch file: {e}"),
            fix: "check the path".into(),
        })?;
        let dir = file.parent().unwrap_or(Path::new("."));
        let stem = file
            .file_stem()
            .map_or_else(|| "batch".into(), |s| s.to_string_lossy().into_owned());
        Self::from_str(&text, &name, &stem, dir, kinds)
    }

    /// Parses and checks batch text; `file` names it in errors, `stem` is the default
    /// name and `dir` the folder a `base = "file"` is relative to.
    pub fn from_str(
        text: &str,
        file: &str,
        stem: &str,
        dir: &Path,
        kinds: &[Arc<dyn ScenarioKind>],
    ) -> Result<Self, ScenarioError> {
        let spec: BatchSpec = from_toml(text, file)?;
        // The base: a file next to the batch file, or an inline table.
        let (base_text, base_file, base_dir) = match &spec.base {
            Value::String(rel) => {
                let p = dir.join(rel);
                let t = std::fs::read_to_string(&p).map_err(|e| {
                    err(
                        text,
                        file,
                        "base",
                        format!("cannot read the base scenario {}: {e}", p.display()),
                        "give the base scenario's path relative to the batch file, or an inline [base] table".into(),
                    )
                })?;
                let base_dir = p
                    .parent()
                    .map_or_else(|| dir.to_path_buf(), Path::to_path_buf);
                (t, p.display().to_string(), base_dir)
            }
            Value::Table(t) => (
                toml::to_string(t).map_err(|e| {
                    err(
                        text,
                        file,
                        "base",
                        e.to_string(),
                        "simplify the [base] table".into(),
                    )
                })?,
                format!("{file} [base]"),
                dir.to_path_buf(),
            ),
            other => {
                return Err(err(
                    text,
                    file,
                    "base",
                    format!(
                        "expected a file name or a table, found {}",
                        other.type_str()
                    ),
                    "write base = \"scenario.toml\" or an inline [base] table".into(),
                ))
            }
        };
        let mut base: Table = from_toml(&base_text, &base_file)?;
        let kind_name = match base.get("kind") {
            None => None,
            Some(Value::String(s)) => Some(s.as_str()),
            Some(_) => {
                return Err(field_error(
                    &base_text,
                    &base_file,
                    "kind",
                    "`kind` must be a string".into(),
                    "write kind = \"bode\"",
                ))
            }
        };
        let names: Vec<&str> = kinds.iter().map(|k| k.name()).collect();
        let kind = match kind_name {
            Some(name) => kinds.iter().find(|k| k.name() == name),
            None => kinds.iter().find(|k| k.detect(&base)),
        }
        .cloned()
        .ok_or_else(|| {
            field_error(
                &base_text,
                &base_file,
                "kind",
                match kind_name {
                    Some(name) => format!("batches cannot run scenarios of kind `{name}`"),
                    None => "cannot tell the scenario's kind from its tables".into(),
                },
                &format!(
                    "use a base scenario of kind {} (`kind = \"...\"`)",
                    names.join(", ")
                ),
            )
        })?;
        kind.check(&base_text, &base_file, &base_dir)?;

        // Paths set so far by one source each: (path, which source).
        let mut claimed: Vec<(String, String)> = Vec::new();
        let claim = |claimed: &mut Vec<(String, String)>,
                     p: &str,
                     source: String,
                     field: &str,
                     line: Option<usize>|
         -> Result<(), ScenarioError> {
            if let Some((other, by)) = claimed.iter().find(|(q, _)| path::overlaps(p, q)) {
                return Err(ScenarioError {
                    file: file.to_string(),
                    line,
                    field: field.to_string(),
                    message: format!("`{p}` overlaps `{other}`, already set by {by}"),
                    fix: "set each scenario field from one axis, zip group, case list or random axis only".into(),
                });
            }
            claimed.push((p.to_string(), source));
            Ok(())
        };
        let check_path = |base: &Table, p: &str, line: Option<usize>, at: &str| {
            path::get(base, p).cloned().ok_or_else(|| {
                let (prefix, keys) = path::known_keys(base, p);
                let within = if prefix.is_empty() {
                    "at the top level".to_string()
                } else {
                    format!("in `{prefix}`")
                };
                ScenarioError {
                    file: file.to_string(),
                    line,
                    field: at.to_string(),
                    message: format!("`{p}` is not a field of the base scenario {base_file}"),
                    fix: format!(
                        "use a path that exists in the base ({within}: {}); to vary an optional field, write it in the base scenario first",
                        keys.join(", ")
                    ),
                }
            })
        };
        let conform = |old: &Value, new: Value, line: Option<usize>, at: &str, p: &str| {
            path::conform(old, new).map_err(|m| ScenarioError {
                file: file.to_string(),
                line,
                field: at.to_string(),
                message: format!("type mismatch for `{p}`: {m}"),
                fix: format!("give `{p}` values of the same TOML type as in the base scenario (numbers without quotes, names in quotes, lists in [ ])"),
            })
        };

        // [set]: fixed overrides.
        for (key, value) in &spec.set {
            let line = line_of_key(text, "set", key);
            let at = format!("set.\"{key}\"");
            claim(&mut claimed, key, "[set]".into(), &at, line)?;
            let old = check_path(&base, key, line, &at)?;
            let new = conform(&old, value.clone(), line, &at, key)?;
            path::set(&mut base, key, new);
        }
        // Axes may refine what [set] set (it applies first): only axes must not overlap.
        claimed.clear();
        if !spec.set.is_empty() {
            let after = toml::to_string(&base).map_err(|e| {
                err(
                    text,
                    file,
                    "set",
                    e.to_string(),
                    "simplify the [set] values".into(),
                )
            })?;
            kind.check(&after, &format!("{file}: the base after [set]"), &base_dir)
                .map_err(|e| ScenarioError {
                    line: line_of(text, "set"),
                    file: file.to_string(),
                    ..e
                })?;
        }

        let mut columns: Vec<AxisColumn> = Vec::new();
        let mut dims: Vec<Dim> = Vec::new();
        // [[axis]]: one dimension each, or one per zip group.
        let mut zip_dims: Vec<(String, usize, usize)> = Vec::new(); // (group, dim, first axis)
        for (a, axis) in spec.axis.iter().enumerate() {
            let at = format!("axis.{a}");
            let line = line_of(text, &format!("{at}.path"));
            claim(
                &mut claimed,
                &axis.path,
                format!("axis {a} (line {})", line.unwrap_or(0)),
                &format!("{at}.path"),
                line,
            )?;
            let old = check_path(&base, &axis.path, line, &format!("{at}.path"))?;
            if axis.values.is_empty() {
                return Err(err(
                    text,
                    file,
                    &format!("{at}.values"),
                    format!("axis `{}` has no values", axis.path),
                    "list at least one value, or remove the axis".into(),
                ));
            }
            let values = axis
                .values
                .iter()
                .enumerate()
                .map(|(j, v)| {
                    let f = format!("{at}.values.{j}");
                    conform(&old, v.clone(), line_of(text, &f), &f, &axis.path)
                })
                .collect::<Result<Vec<_>, _>>()?;
            let column = columns.len();
            columns.push(AxisColumn {
                name: axis.path.clone(),
                is_path: true,
            });
            let group = axis
                .zip
                .as_ref()
                .and_then(|g| zip_dims.iter().find(|(n, _, _)| n == g));
            match group {
                Some(&(ref g, d, first)) => {
                    let dim = &mut dims[d];
                    if dim.points.len() != values.len() {
                        return Err(err(
                            text,
                            file,
                            &format!("{at}.values"),
                            format!(
                                "zipped axes of group `{g}` differ in length: `{}` has {} values, `{}` has {}",
                                spec.axis[first].path,
                                dim.points.len(),
                                axis.path,
                                values.len()
                            ),
                            format!("give every axis with zip = \"{g}\" the same number of values, or use separate axes for a cartesian product"),
                        ));
                    }
                    for (p, v) in dim.points.iter_mut().zip(values) {
                        p.push((column, v));
                    }
                }
                None => {
                    if let Some(g) = &axis.zip {
                        zip_dims.push((g.clone(), dims.len(), a));
                    }
                    dims.push(Dim {
                        points: values.into_iter().map(|v| vec![(column, v)]).collect(),
                    });
                }
            }
        }
        // [[case]]: one dimension whose points set several paths each.
        if !spec.case.is_empty() {
            let mut points = Vec::with_capacity(spec.case.len());
            let mut case_columns: Vec<(String, usize)> = Vec::new();
            for (c, case) in spec.case.iter().enumerate() {
                let mut point = Vec::new();
                if case.is_empty() {
                    return Err(err(
                        text,
                        file,
                        &format!("case.{c}"),
                        format!("case {c} sets nothing"),
                        "write \"dotted.path\" = value lines under [[case]], or remove it".into(),
                    ));
                }
                for (key, value) in case {
                    let line = line_of_key(text, &format!("case.{c}"), key);
                    let at = format!("case.{c}.\"{key}\"");
                    let column = match case_columns.iter().find(|(k, _)| k == key) {
                        Some(&(_, col)) => col,
                        None => {
                            claim(&mut claimed, key, format!("[[case]] {c}"), &at, line)?;
                            columns.push(AxisColumn {
                                name: key.clone(),
                                is_path: true,
                            });
                            case_columns.push((key.clone(), columns.len() - 1));
                            columns.len() - 1
                        }
                    };
                    let old = check_path(&base, key, line, &at)?;
                    point.push((column, conform(&old, value.clone(), line, &at, key)?));
                }
                points.push(point);
            }
            dims.push(Dim { points });
        }
        // [[random]]: drawn per scenario.
        let mut random = Vec::new();
        for (r, rs) in spec.random.iter().enumerate() {
            let at = format!("random.{r}");
            let line = line_of(text, &format!("{at}.path"));
            claim(
                &mut claimed,
                &rs.path,
                format!("random axis {r} (line {})", line.unwrap_or(0)),
                &format!("{at}.path"),
                line,
            )?;
            let old = check_path(&base, &rs.path, line, &format!("{at}.path"))?;
            let bad = |what: &str, message: String, fix: &str| {
                err(text, file, &format!("{at}.{what}"), message, fix.into())
            };
            let draw = match (&rs.uniform, &rs.normal, &rs.choice) {
                (Some([lo, hi]), None, None) => {
                    if !matches!(old, Value::Float(_)) {
                        return Err(bad("uniform", format!("`{}` holds {} but uniform draws floats", rs.path, old.type_str()), "use choice = [...] for non-float fields"));
                    }
                    Draw::Uniform(Uniform::new(*lo, *hi).map_err(|e| {
                        bad("uniform", format!("uniform = [{lo}, {hi}]: {e}"), "give finite bounds with low < high")
                    })?)
                }
                (None, Some(n), None) => {
                    if !matches!(old, Value::Float(_)) {
                        return Err(bad("normal", format!("`{}` holds {} but normal draws floats", rs.path, old.type_str()), "use choice = [...] for non-float fields"));
                    }
                    Draw::Normal(Normal::new(n.mean, n.std_dev).map_err(|e| {
                        bad("normal", format!("normal mean {} std_dev {}: {e}", n.mean, n.std_dev), "give a finite mean and a finite std_dev >= 0")
                    })?)
                }
                (None, None, Some(values)) => {
                    if values.is_empty() {
                        return Err(bad("choice", "choice has no values".into(), "list at least one value"));
                    }
                    Draw::Choice(
                        values
                            .iter()
                            .enumerate()
                            .map(|(j, v)| {
                                let f = format!("{at}.choice.{j}");
                                conform(&old, v.clone(), line_of(text, &f), &f, &rs.path)
                            })
                            .collect::<Result<_, _>>()?,
                    )
                }
                _ => {
                    return Err(err(
                        text,
                        file,
                        &at,
                        format!("random axis `{}` needs exactly one of uniform, normal, choice", rs.path),
                        "write uniform = [low, high], normal = { mean = m, std_dev = s } or choice = [a, b, ...]".into(),
                    ))
                }
            };
            columns.push(AxisColumn {
                name: rs.path.clone(),
                is_path: true,
            });
            random.push(RandomAxis {
                column: columns.len() - 1,
                draw,
            });
        }
        if !random.is_empty() && spec.seed.is_none() {
            return Err(err(
                text,
                file,
                "random",
                "random axes need a seed".into(),
                "add `seed = 1` (any integer) at the top of the batch file".into(),
            ));
        }
        if let Some(n) = spec.samples {
            if n == 0 {
                return Err(err(
                    text,
                    file,
                    "samples",
                    "samples = 0 gives no scenarios".into(),
                    "give samples >= 1, or remove the key".into(),
                ));
            }
            if n > crate::limits::MAX_SCENARIOS {
                return Err(err(
                    text,
                    file,
                    "samples",
                    format!(
                        "samples = {n} is past the limit of {} scenarios per batch",
                        crate::limits::MAX_SCENARIOS
                    ),
                    "draw fewer samples, or split the study into several batch files".into(),
                ));
            }
            columns.push(AxisColumn {
                name: "sample".into(),
                is_path: false,
            });
            let column = columns.len() - 1;
            dims.push(Dim {
                points: (0..n)
                    .map(|s| vec![(column, Value::Integer(s as i64))])
                    .collect(),
            });
        }
        let total = dims
            .iter()
            .try_fold(1usize, |acc, d| acc.checked_mul(d.points.len()))
            .ok_or_else(|| ScenarioError {
                file: file.to_string(),
                line: None,
                field: "axis".into(),
                message: "the product of the axes overflows".into(),
                fix: "use fewer or shorter axes, or zip some of them".into(),
            })?;
        if total > crate::limits::MAX_SCENARIOS {
            return Err(ScenarioError {
                file: file.to_string(),
                line: None,
                field: "axis".into(),
                message: format!(
                    "the axes expand into {total} scenarios, past the limit of {} per batch",
                    crate::limits::MAX_SCENARIOS
                ),
                fix: "use fewer or shorter axes, zip some of them, or split the study into several batch files".into(),
            });
        }
        let name = spec.name.clone().unwrap_or_else(|| stem.to_string());
        if name.is_empty() || name.contains(['/', '\\']) || name.starts_with('.') {
            return Err(err(
                text,
                file,
                "name",
                format!("`{name}` cannot name an output folder"),
                "use letters, digits, `_` and `-`".into(),
            ));
        }
        let fingerprint = fingerprint(text, &base_text, &base, &base_dir);
        Ok(Self {
            name,
            file: file.to_string(),
            kind,
            base_dir,
            fingerprint,
            base,
            columns,
            dims,
            random,
            seed: spec.seed.unwrap_or(0),
            total,
        })
    }

    /// Number of scenarios in the expansion.
    pub fn len(&self) -> usize {
        self.total
    }

    /// True when the expansion is empty (never, for a checked batch).
    pub fn is_empty(&self) -> bool {
        self.total == 0
    }

    /// Axis column names (scenario paths, and `sample`), in table order.
    pub fn axis_names(&self) -> Vec<String> {
        self.columns.iter().map(|c| c.name.clone()).collect()
    }

    /// Expands scenario `index` (< [`Self::len`]).
    pub fn scenario(&self, index: usize) -> Scenario {
        let mut tree = self.base.clone();
        let mut cells: Vec<Option<Cell>> = vec![None; self.columns.len()];
        let mut rem = index;
        for dim in self.dims.iter().rev() {
            let k = rem % dim.points.len();
            rem /= dim.points.len();
            for (column, value) in &dim.points[k] {
                let col = &self.columns[*column];
                if col.is_path {
                    path::set(&mut tree, &col.name, value.clone());
                }
                cells[*column] = Some(Cell::from_toml(value));
            }
        }
        if !self.random.is_empty() {
            let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
            rng.set_stream(index as u64);
            for axis in &self.random {
                let value = match &axis.draw {
                    Draw::Uniform(u) => Value::Float(u.sample(&mut rng)),
                    Draw::Normal(n) => Value::Float(n.sample(&mut rng)),
                    Draw::Choice(values) => values[rng.random_range(0..values.len())].clone(),
                };
                path::set(&mut tree, &self.columns[axis.column].name, value);
            }
        }
        // Columns not set by this scenario (a case without that path) show the value used.
        let axes = cells
            .into_iter()
            .zip(&self.columns)
            .map(|(cell, col)| {
                cell.or_else(|| path::get(&tree, &col.name).map(Cell::from_toml))
                    .unwrap_or(Cell::Text(String::new()))
            })
            .collect();
        let text = toml::to_string(&tree).unwrap_or_default();
        Scenario { index, axes, text }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn batch(body: &str) -> Result<Batch, ScenarioError> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios");
        let text = format!("base = \"bode_dyneema2.toml\"\n{body}");
        Batch::from_str(&text, "t.toml", "t", &dir, &super::super::builtin_kinds())
    }

    fn texts(b: &Batch, i: usize) -> Vec<String> {
        b.scenario(i).axes.iter().map(Cell::text).collect()
    }

    #[test]
    fn product_is_row_major_and_zip_groups_advance_together() {
        let b = batch(
            "[[axis]]\npath = \"rig.rope\"\nvalues = [\"dyneema2\", \"zylon2\"]\n\
             [[axis]]\npath = \"rig.output_inertia_kg_m2\"\nvalues = [1, 2, 3]\nzip = \"p\"\n\
             [[axis]]\npath = \"sweep.mean_tensions_n.1\"\nvalues = [10.0, 20.0, 30.0]\nzip = \"p\"\n",
        )
        .unwrap();
        assert_eq!(b.len(), 6);
        assert_eq!(texts(&b, 0), ["dyneema2", "1.0", "10.0"]);
        assert_eq!(texts(&b, 2), ["dyneema2", "3.0", "30.0"]);
        assert_eq!(texts(&b, 4), ["zylon2", "2.0", "20.0"]);
        // The expanded text is a valid scenario with the overrides in place.
        let s = crate::BodeScenario::from_str(&b.scenario(4).text, "expanded").unwrap();
        assert!((s.rigs[1].mean_tension_n - 20.0).abs() < 1e-15);
        assert!((s.rigs[0].mean_tension_n - 49.0).abs() < 1e-15);
        assert!((s.rigs[0].output_inertia_kg_m2 - 2.0).abs() < 1e-15);
        assert_eq!(s.rigs[0].rope_name, "zylon2");
    }

    #[test]
    fn the_fingerprint_follows_the_files_the_base_names() {
        let dir = tempfile::tempdir().unwrap();
        let scen = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/bode_dyneema2.toml"),
        )
        .unwrap();
        // A base naming a side file (as an arm scenario names its URDF).
        std::fs::write(dir.path().join("side.txt"), "one").unwrap();
        std::fs::write(
            dir.path().join("base.toml"),
            scen.replacen("title = \"Paper rig, dyneema2\"", "title = \"side.txt\"", 1),
        )
        .unwrap();
        let text = "base = \"base.toml\"\n";
        let kinds = super::super::builtin_kinds();
        let fp = || {
            Batch::from_str(text, "t.toml", "t", dir.path(), &kinds)
                .unwrap()
                .fingerprint
        };
        let first = fp();
        assert_eq!(first, fp(), "deterministic");
        std::fs::write(dir.path().join("side.txt"), "two").unwrap();
        assert_ne!(
            first,
            fp(),
            "editing a referenced file changes the fingerprint"
        );
    }

    #[test]
    fn random_axes_depend_only_on_seed_and_index() {
        let body = "seed = 3\nsamples = 4\n[[random]]\npath = \"rig.prestretch_n\"\nuniform = [400.0, 600.0]\n";
        let (a, b) = (batch(body).unwrap(), batch(body).unwrap());
        let v = |b: &Batch, i: usize| b.scenario(i).axes[0].as_f64().unwrap();
        for i in 0..4 {
            assert_eq!(v(&a, i).to_bits(), v(&b, i).to_bits());
            assert!((400.0..600.0).contains(&v(&a, i)));
        }
        assert_ne!(v(&a, 0).to_bits(), v(&a, 1).to_bits());
        let c = batch(&body.replace("seed = 3", "seed = 4")).unwrap();
        assert_ne!(v(&a, 0).to_bits(), v(&c, 0).to_bits());
    }

    #[test]
    fn structural_errors_name_line_and_fix() {
        let e = batch("[[axis]]\npath = \"rig.nope\"\nvalues = [1.0]\n").unwrap_err();
        assert_eq!(e.line, Some(3));
        assert!(e.fix.contains("rope_length_m"), "{e}");
        let e = batch("[set]\n\"rig.rope_length_m\" = \"long\"\n").unwrap_err();
        assert_eq!(e.line, Some(3));
        assert!(e.message.contains("type mismatch"), "{e}");
        // [set] may be refined by an axis, but two axes may not overlap.
        assert!(batch("[set]\n\"sweep.mean_tensions_n\" = [1.0]\n[[axis]]\npath = \"sweep.mean_tensions_n.0\"\nvalues = [2.0]\n").is_ok());
        let e = batch("[[axis]]\npath = \"sweep.mean_tensions_n\"\nvalues = [[1.0]]\n[[axis]]\npath = \"sweep.mean_tensions_n.0\"\nvalues = [2.0]\n").unwrap_err();
        assert_eq!(e.line, Some(6));
        // A well-typed value the model rejects is not a structural error.
        let b = batch("[[axis]]\npath = \"rig.rope_length_m\"\nvalues = [-1.0]\n").unwrap();
        assert!(crate::BodeScenario::from_str(&b.scenario(0).text, "x").is_err());
    }
}
