//! Dotted paths into a TOML tree (`rig.rope`, `sweep.mean_tensions_n.0`): lookup,
//! replacement, and the type check that keeps overrides structurally sound.

use toml::{Table, Value};

/// The value at `path` (`.`-separated; integer parts index arrays), if it exists.
pub fn get<'a>(table: &'a Table, path: &str) -> Option<&'a Value> {
    let mut parts = path.split('.');
    let mut value = table.get(parts.next()?)?;
    for part in parts {
        value = match value {
            Value::Table(t) => t.get(part)?,
            Value::Array(a) => a.get(part.parse::<usize>().ok()?)?,
            _ => return None,
        };
    }
    Some(value)
}

/// Replaces the value at `path`; returns false (and changes nothing) when it does not exist.
pub fn set(table: &mut Table, path: &str, new: Value) -> bool {
    let mut parts = path.split('.');
    let Some(first) = parts.next() else {
        return false;
    };
    let Some(mut value) = table.get_mut(first) else {
        return false;
    };
    for part in parts {
        value = match value {
            Value::Table(t) => match t.get_mut(part) {
                Some(v) => v,
                None => return false,
            },
            Value::Array(a) => match part.parse::<usize>().ok().and_then(|i| a.get_mut(i)) {
                Some(v) => v,
                None => return false,
            },
            _ => return false,
        };
    }
    *value = new;
    true
}

/// Keys that exist beside the deepest existing part of `path`, for "did you mean" fixes.
pub fn known_keys(table: &Table, path: &str) -> (String, Vec<String>) {
    let parts: Vec<&str> = path.split('.').collect();
    let mut keys: Vec<String> = table.keys().cloned().collect();
    let mut prefix = String::new();
    for n in 1..parts.len() {
        let head = parts[..n].join(".");
        match get(table, &head) {
            Some(Value::Table(t)) => {
                keys = t.keys().cloned().collect();
                prefix = head;
            }
            Some(Value::Array(a)) => {
                keys = vec![format!("0..{}", a.len())];
                prefix = head;
            }
            _ => break,
        }
    }
    keys.sort();
    (prefix, keys)
}

/// True when one path equals the other or contains it (`rig` and `rig.rope`).
pub fn overlaps(a: &str, b: &str) -> bool {
    a == b || a.starts_with(&format!("{b}.")) || b.starts_with(&format!("{a}."))
}

/// Gives `new` the TOML type of `base`: integers become floats where the base holds a
/// float (also inside arrays); any other difference of type is an error naming both.
pub fn conform(base: &Value, new: Value) -> Result<Value, String> {
    match (base, new) {
        (Value::Float(_), Value::Integer(i)) => Ok(Value::Float(i as f64)),
        (Value::Array(b), Value::Array(items)) => match b.first() {
            Some(first) => items
                .into_iter()
                .enumerate()
                .map(|(i, v)| conform(first, v).map_err(|e| format!("item {i}: {e}")))
                .collect::<Result<Vec<_>, _>>()
                .map(Value::Array),
            None => Ok(Value::Array(items)),
        },
        (Value::Table(b), Value::Table(t)) => t
            .into_iter()
            .map(|(k, v)| match b.get(&k) {
                Some(bv) => conform(bv, v)
                    .map(|v| (k.clone(), v))
                    .map_err(|e| format!("key `{k}`: {e}")),
                None => Ok((k, v)),
            })
            .collect::<Result<Table, _>>()
            .map(Value::Table),
        (b, v) if std::mem::discriminant(b) == std::mem::discriminant(&v) => Ok(v),
        (b, v) => Err(format!(
            "expected {} (the type of the base value), found {} `{v}`",
            b.type_str(),
            v.type_str()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tree() -> Table {
        toml::from_str("[rig]\nrope = \"a\"\nl = 1.5\n[sweep]\nt = [1.0, 2.0]\nn = 3\n").unwrap()
    }

    #[test]
    fn get_and_set_follow_tables_and_array_indices() {
        let mut t = tree();
        assert_eq!(get(&t, "sweep.t.1"), Some(&Value::Float(2.0)));
        assert_eq!(get(&t, "sweep.t.2"), None);
        assert_eq!(get(&t, "rig.nope"), None);
        assert!(set(&mut t, "sweep.t.1", Value::Float(7.0)));
        assert_eq!(
            get(&t, "sweep.t"),
            Some(&Value::Array(vec![1.0.into(), 7.0.into()]))
        );
        assert!(!set(&mut t, "rig.missing", Value::Float(7.0)));
        assert_eq!(get(&t, "rig.missing"), None);
    }

    #[test]
    fn conform_promotes_integers_and_rejects_other_types() {
        let t = tree();
        let l = get(&t, "rig.l").unwrap();
        assert_eq!(conform(l, Value::Integer(2)), Ok(Value::Float(2.0)));
        assert!(conform(l, Value::String("x".into())).is_err());
        let n = get(&t, "sweep.n").unwrap();
        assert!(conform(n, Value::Float(2.5)).is_err());
        let arr = get(&t, "sweep.t").unwrap();
        let got = conform(arr, Value::Array(vec![Value::Integer(5)])).unwrap();
        assert_eq!(got, Value::Array(vec![Value::Float(5.0)]));
        let bad = conform(arr, Value::Array(vec![Value::Boolean(true)])).unwrap_err();
        assert!(bad.starts_with("item 0: expected float"), "{bad}");
    }

    #[test]
    fn overlapping_paths() {
        assert!(overlaps("rig", "rig.rope"));
        assert!(overlaps("rig.rope", "rig.rope"));
        assert!(!overlaps("rig.rope", "rig.rope_length_m"));
        let (prefix, keys) = known_keys(&tree(), "rig.lenght");
        assert_eq!(prefix, "rig");
        assert_eq!(keys, vec!["l".to_string(), "rope".to_string()]);
    }
}
