//! An arm's model written back as an arm scenario (`fit`/`diagnose --write-scenario`):
//! the dataset's arm scenario with the fitted model folded in, for `run`, `batch` and
//! `modes` to simulate the arm as identified.
//!
//! What the model holds, where it goes (the arm plant's rules,
//! [`crate::plant::ArmPlant`], so that the scenario simulates as the model did):
//!
//! - `k1_scale`: every transmission's `k1_scale` (the factor on its rope's k1)
//!   multiplied; other base parameters are refused (an arm's baseline fits `k1_scale`
//!   alone);
//! - effects at joints, motors, relays and rope laws: an `[[effect]]` each, with its
//!   values, its `joints` when the model restricts it, and its table (`[effect.shape]`)
//!   when it holds one. An effect at joints or motors replaces the scenario's own of the
//!   same name at those joints (its `[[effect]]` entries there are dropped or narrowed,
//!   a transmission's `effects` entry dropped), as the plant replaces it; any other
//!   effect the scenario already holds is refused (the two would add);
//! - effects on a link's bending (`link_flexibility`): appended to the `[[flex]]`
//!   effects of every flexible link, or of the links the model restricts it to (a link
//!   that only `link = "*"` covers gets an entry of its own, a copy of that one), after
//!   the scenario's own;
//! - the payload (`payload_mass`): an `[[effect]]`, a payload the servos are not told
//!   of, as in the model;
//! - effects on sensor channels: not part of the arm; listed in the header comment.
//!
//! Per-run values cannot be written (one scenario is one arm). The text is parsed back
//! as an arm scenario before it is returned.

use std::path::Path;

use longreach_drive::effects::Site;

use crate::dataset::{Dataset, DatasetKind};
use crate::model::{BaseParam, EffectUse, Model, Role};

/// The dataset's arm scenario with `model` folded in (module docs), as the text of a
/// scenario file at `out` (its URDF path relative to `out`'s folder), headed by
/// `comment`. Errors say what cannot be written and why.
pub fn arm_scenario_text(
    ds: &Dataset,
    model: &Model,
    out: &Path,
    comment: &str,
) -> Result<String, String> {
    let DatasetKind::ArmMoves(am) = &ds.kind else {
        return Err(format!(
            "--write-scenario needs an arm dataset (arm_moves); {} is a {}",
            ds.title,
            ds.kind.name()
        ));
    };
    let path = &am.scenario_path;
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read the arm scenario {}: {e}", path.display()))?;
    let mut doc: toml::Table = text
        .parse()
        .map_err(|e| format!("the arm scenario {} is not TOML: {e}", path.display()))?;
    let out_dir = out.parent().filter(|p| !p.as_os_str().is_empty());
    crate::dataset::rebase_urdf(
        &mut doc,
        path.parent().unwrap_or(Path::new(".")),
        out_dir.unwrap_or(Path::new(".")),
    )?;
    for b in &model.base {
        match b.role {
            Role::Base(BaseParam::K1Scale) => {
                if b.per_run && b.run_values.is_some() {
                    return Err(per_run("k1_scale"));
                }
                scale_k1(&mut doc, b.value)?;
            }
            Role::Base(p) => {
                return Err(format!(
                    "base parameter `{}` cannot be written into an arm scenario (an arm's ropes take `k1_scale`); remove it from the model",
                    p.name()
                ))
            }
            Role::Effect | Role::Shape => {}
        }
    }
    let mut not_arm = Vec::new();
    for u in &model.effects {
        if u.params.iter().any(|p| p.per_run && p.run_values.is_some()) {
            return Err(per_run(u.effect.name()));
        }
        if u.effect.site() == Site::Sensor {
            not_arm.push(u.label());
            continue;
        }
        if crate::plant::bends_links(u.effect) {
            add_to_flex(&mut doc, u)?;
            continue;
        }
        make_room(&mut doc, u, &am.joints)?;
        let effects = doc
            .entry("effect")
            .or_insert_with(|| toml::Value::Array(Vec::new()))
            .as_array_mut()
            .ok_or("`effect` is not an array of tables in the scenario")?;
        effects.push(toml::Value::Table(effect_table(u, true)));
    }
    let body = toml::to_string(&doc).map_err(|e| format!("cannot encode the scenario: {e}"))?;
    let mut head = String::new();
    for line in comment.lines() {
        head.push_str(&format!("# {line}\n"));
    }
    head.push_str(&format!(
        "# The arm scenario {} with the model folded in (docs/models.md, \"Writing an arm scenario\").\n",
        path.display()
    ));
    if !not_arm.is_empty() {
        head.push_str(&format!(
            "# Not written (they act on the measurement, not the arm): {}.\n",
            not_arm.join(", ")
        ));
    }
    let text = format!("{head}\n{body}");
    let file = out.display().to_string();
    longreach_arm::scenario::parse(&text, &file, out_dir.unwrap_or(Path::new(".")))
        .map_err(|e| format!("the written scenario does not parse back: {e}"))?;
    Ok(text)
}

fn per_run(name: &str) -> String {
    format!(
        "`{name}` has values per run, which one arm scenario cannot hold; fit it with per_run = false first"
    )
}

/// The `[[effect]]` table of `u` (its values in the effect's order, its joints and
/// table); `with_joints` false for a `[[flex]]` effect.
fn effect_table(u: &EffectUse, with_joints: bool) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("name".into(), u.effect.name().into());
    t.insert(
        "params".into(),
        toml::Value::Array(u.params.iter().map(|p| p.value.into()).collect()),
    );
    if let (true, Some(j)) = (with_joints, &u.at) {
        t.insert(
            "joints".into(),
            toml::Value::Array(j.iter().map(|n| n.as_str().into()).collect()),
        );
    }
    if let Some(sh) = &u.shape {
        let mut s = toml::Table::new();
        let list = |v: &[f64]| toml::Value::Array(v.iter().map(|&x| x.into()).collect());
        s.insert(sh.shape.argument.name().into(), list(&sh.knots));
        s.insert(sh.shape.value.into(), list(&sh.values_for(0)));
        t.insert("shape".into(), toml::Value::Table(s));
    }
    t
}

/// Every transmission's `k1_scale` (its own, else `[transmission_defaults]`'s, else 1)
/// times `scale`.
fn scale_k1(doc: &mut toml::Table, scale: f64) -> Result<(), String> {
    if scale.to_bits() == 1f64.to_bits() {
        return Ok(());
    }
    let number = |v: &toml::Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
    let default = match doc
        .get("transmission_defaults")
        .and_then(|d| d.get("k1_scale"))
    {
        Some(v) => number(v).ok_or("[transmission_defaults] k1_scale is not a number")?,
        None => 1.0,
    };
    let ts = doc
        .get_mut("transmission")
        .and_then(|t| t.as_array_mut())
        .ok_or("the arm scenario has no [[transmission]]")?;
    for t in ts.iter_mut().filter_map(|t| t.as_table_mut()) {
        let own = match t.get("k1_scale") {
            Some(v) => number(v).ok_or("a transmission's k1_scale is not a number")?,
            None => default,
        };
        t.insert("k1_scale".into(), (own * scale).into());
    }
    Ok(())
}

/// Appends `u` to the effects of the flexible links it acts on (`[[flex]]` entries not
/// `rigid`), after the entry's own (or its defaults'): every entry when `u` acts on
/// every flexible link; else the entries of its links, and for a link that only
/// `link = "*"` covers, a copy of that entry naming the link (a link's own entry wins
/// over `"*"`, so the copy takes the link out of `"*"` with the same numbers).
fn add_to_flex(doc: &mut toml::Table, u: &EffectUse) -> Result<(), String> {
    let defaults = doc
        .get("flex_defaults")
        .and_then(|d| d.get("effects"))
        .cloned();
    let flex = doc
        .get_mut("flex")
        .and_then(|f| f.as_array_mut())
        .filter(|f| !f.is_empty())
        .ok_or_else(|| {
            format!(
                "`{}` acts on flexible links and the arm scenario has none ([[flex]])",
                u.effect.name()
            )
        })?;
    let link_of = |t: &toml::Value| t.get("link").and_then(|l| l.as_str()).map(str::to_string);
    let rigid = |t: &toml::Value| t.get("rigid").and_then(|r| r.as_bool()) == Some(true);
    // (links named by entries of their own; those "*" covers get a copy)
    let own: Vec<String> = flex
        .iter()
        .filter_map(link_of)
        .filter(|l| l != "*")
        .collect();
    let mut copies = Vec::new();
    if let Some(names) = &u.at {
        for t in flex
            .iter()
            .filter(|t| link_of(t).as_deref() == Some("*") && !rigid(t))
        {
            for n in names.iter().filter(|n| !own.contains(n)) {
                let mut c = t.clone();
                if let Some(c) = c.as_table_mut() {
                    c.insert("link".into(), n.as_str().into());
                }
                copies.push(c);
            }
        }
    }
    flex.extend(copies);
    let acts_on = |t: &toml::Value| match (&u.at, link_of(t)) {
        (None, _) => true,
        (Some(names), Some(l)) => names.contains(&l),
        (Some(_), None) => false,
    };
    for t in flex.iter_mut().filter(|t| !rigid(t) && acts_on(t)) {
        let Some(t) = t.as_table_mut() else {
            continue;
        };
        let mut list = t
            .get("effects")
            .cloned()
            .or_else(|| defaults.clone())
            .unwrap_or_else(|| toml::Value::Array(Vec::new()));
        list.as_array_mut()
            .ok_or("a [[flex]] entry's `effects` is not an array")?
            .push(toml::Value::Table(effect_table(u, false)));
        t.insert("effects".into(), list);
    }
    Ok(())
}

/// Clears the scenario's own entries of `u`'s effect where `u` acts: at joints and
/// motors, as the plant does, they are replaced (an `[[effect]]` dropped or narrowed
/// to the joints `u` leaves, a transmission's `effects` entry dropped); any other
/// effect the scenario already holds there is refused.
fn make_room(doc: &mut toml::Table, u: &EffectUse, driven: &[String]) -> Result<(), String> {
    let name = u.effect.name();
    let covers = |j: &str| u.at.as_ref().is_none_or(|js| js.iter().any(|x| x == j));
    let replaces = matches!(u.effect.site(), Site::Joint | Site::Motor);
    let refuse = |where_: &str| {
        format!(
            "the arm scenario already holds `{name}` ({where_}) and the model's would add to it; remove it from the scenario or the model"
        )
    };
    if let Some(effects) = doc.get_mut("effect").and_then(|e| e.as_array_mut()) {
        let mut kept = Vec::new();
        for e in effects.drain(..) {
            let same = e.get("name").and_then(|n| n.as_str()) == Some(name);
            if !same {
                kept.push(e);
                continue;
            }
            let own: Vec<String> = match e.get("joints").and_then(|j| j.as_array()) {
                Some(a) => a
                    .iter()
                    .filter_map(|x| x.as_str().map(str::to_string))
                    .collect(),
                None => driven.to_vec(),
            };
            let left: Vec<String> = own.iter().filter(|j| !covers(j)).cloned().collect();
            if left.len() == own.len() {
                kept.push(e);
                continue;
            }
            if !replaces {
                return Err(refuse("an [[effect]]"));
            }
            if !left.is_empty() {
                let mut e = e;
                if let Some(t) = e.as_table_mut() {
                    t.insert(
                        "joints".into(),
                        toml::Value::Array(left.into_iter().map(Into::into).collect()),
                    );
                }
                kept.push(e);
            }
        }
        *effects = kept;
    }
    if let Some(ts) = doc.get_mut("transmission").and_then(|t| t.as_array_mut()) {
        for t in ts.iter_mut().filter_map(|t| t.as_table_mut()) {
            let joint = t
                .get("joint")
                .and_then(|j| j.as_str())
                .unwrap_or_default()
                .to_string();
            if !covers(&joint) {
                continue;
            }
            let Some(list) = t.get_mut("effects").and_then(|l| l.as_array_mut()) else {
                continue;
            };
            let before = list.len();
            list.retain(|e| e.get("name").and_then(|n| n.as_str()) != Some(name));
            if list.len() != before && !replaces {
                return Err(refuse(&format!("in the transmission of {joint}")));
            }
        }
    }
    Ok(())
}
