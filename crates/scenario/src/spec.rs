//! Parsing helpers shared by every scenario kind: TOML text to typed specs with errors
//! that name the file, the line, the field and the fix.

use longreach_rope::{Catalog, LawKind, RopeLaw, RopeParams};
use serde::de::DeserializeOwned;

use crate::error::ScenarioError;
use crate::locate::{line_at, line_of};

/// Deserializes `value` (a TOML tree, possibly with overrides applied) into `T`,
/// turning serde's message into a [`ScenarioError`] located in `text`.
pub fn from_toml<T: DeserializeOwned>(text: &str, file: &str) -> Result<T, ScenarioError> {
    toml::from_str(text).map_err(|e| toml_error(text, file, &e))
}

/// A TOML parse or type error as a scenario error.
pub fn toml_error(text: &str, file: &str, e: &toml::de::Error) -> ScenarioError {
    let message = e.message().trim().to_string();
    let line = e.span().map(|s| line_at(text, s.start));
    // Only a missing or unknown field's message quotes the field; a type error quotes
    // the value, so its field is the key of the line.
    let names_field = message.starts_with("missing field")
        || message.starts_with("unknown field")
        || message.starts_with("duplicate key");
    let field = names_field
        .then(|| quoted(&message))
        .flatten()
        .or_else(|| {
            // A type error points at the value: the key is what precedes `=` on its line.
            let line = line?;
            let src = text.lines().nth(line - 1)?;
            let key = src.split('=').next()?.trim().trim_matches('"');
            if key.is_empty() || key.starts_with('[') {
                return None;
            }
            // Prefixed with the table the line sits in (`[sweep]` -> `sweep.settle_s`).
            let table = text
                .lines()
                .take(line - 1)
                .filter_map(|l| {
                    let l = l.trim();
                    let inner = l.strip_prefix("[[").and_then(|r| r.split("]]").next());
                    let inner =
                        inner.or_else(|| l.strip_prefix('[').and_then(|r| r.split(']').next()));
                    inner.map(|t| t.trim().to_string())
                })
                .last();
            Some(match table {
                Some(t) if !t.is_empty() => format!("{t}.{key}"),
                _ => key.to_string(),
            })
        })
        .unwrap_or_default();
    let fix = if message.starts_with("missing field") {
        format!("add `{field} = <value>` (SI units, as the name says) to this table; see scenarios/README.md for every field")
    } else if message.starts_with("unknown field") {
        "remove the key or correct its spelling to one of the expected fields listed".to_string()
    } else if message.starts_with("invalid type")
        || message.starts_with("invalid value")
        || message.starts_with("invalid length")
    {
        "give a value of the expected type (numbers without quotes, names in quotes, lists in [ ])"
            .to_string()
    } else {
        "correct the TOML syntax at this line".to_string()
    };
    ScenarioError {
        file: file.to_string(),
        line,
        field,
        message,
        fix,
    }
}

fn quoted(message: &str) -> Option<String> {
    let start = message.find('`')? + 1;
    let len = message[start..].find('`')?;
    Some(message[start..start + len].to_string())
}

/// An error about a field found after parsing (a value out of range, an unknown name).
pub fn field_error(
    text: &str,
    file: &str,
    field: &str,
    message: String,
    fix: &str,
) -> ScenarioError {
    ScenarioError {
        file: file.to_string(),
        line: line_of(text, field),
        field: field.to_string(),
        message,
        fix: fix.to_string(),
    }
}

/// A rope given by catalog name (`rope = "dyneema2"`) or inline
/// (`[rig.rope]` with the catalog keys `tensile_strength_n`, `k1`, `k3`, `c2`, `c3`, `kp`).
pub type RopeRef = toml::Value;

fn parse_rope_ref(
    text: &str,
    file: &str,
    field: &str,
    rope: &RopeRef,
) -> Result<RopeParams, ScenarioError> {
    match rope {
        toml::Value::String(name) => Catalog::builtin().get(name).cloned().map_err(|e| {
            field_error(
                text,
                file,
                field,
                e.to_string(),
                "use a catalog name (`longreach ropes` lists them) or an inline table with tensile_strength_n, k1 and optionally k3, c2, c3, kp",
            )
        }),
        toml::Value::Table(_) => {
            let mut p: RopeParams = rope.clone().try_into().map_err(|e: toml::de::Error| {
                field_error(
                    text,
                    file,
                    field,
                    format!("inline rope: {}", e.message().trim()),
                    "an inline rope takes tensile_strength_n and k1 [N], and optionally k3 [N], c2, c3 [N*s], kp [N], mass_per_length_kg_m",
                )
            })?;
            p.name = field.rsplit('.').next().unwrap_or("inline").to_string();
            p.name = format!("inline {}", p.name);
            p.validate(file).map_err(|e| {
                field_error(text, file, field, e.to_string(), "give finite positive per-strain constants (N, N*s)")
            })?;
            Ok(p)
        }
        other => Err(field_error(
            text,
            file,
            field,
            format!("expected a rope name or an inline table, found {}", other.type_str()),
            "write rope = \"dyneema2\" or a [rig.rope] table",
        )),
    }
}

/// Resolves a rope reference and law into a [`RopeLaw`]; `field` is the dotted path
/// of the rope key for errors. Returns the rope's name, parameters and law.
pub fn resolve_rope(
    text: &str,
    file: &str,
    field: &str,
    rope: &RopeRef,
    law: Option<LawKind>,
) -> Result<(String, RopeParams, RopeLaw), ScenarioError> {
    let params = parse_rope_ref(text, file, field, rope)?;
    let kind = law.unwrap_or_else(|| LawKind::default_for(&params));
    let law = RopeLaw::from_params(&params, kind).map_err(|e| {
        field_error(
            text,
            file,
            field,
            e.to_string(),
            "choose a law the rope has constants for: elastic, four_element (k3, c2, c3) or flory (also kp)",
        )
    })?;
    Ok((params.name.clone(), params, law))
}
