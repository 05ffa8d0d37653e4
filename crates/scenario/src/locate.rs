//! Finds where a key sits in TOML text, so errors found after parsing can name a line.

use toml::de::{DeTable, DeValue};

/// 1-based line of the dotted key `path` (e.g. `rig.rope_length_m`, `sweep.frequencies_hz.3`)
/// in `text`; falls back to the deepest enclosing key that exists.
pub fn line_of(text: &str, path: &str) -> Option<usize> {
    let doc = DeTable::parse(text).ok()?;
    let mut best: Option<std::ops::Range<usize>> = None;
    let mut table: Option<&DeTable<'_>> = Some(doc.get_ref());
    let mut array: Option<&[toml::Spanned<DeValue<'_>>]> = None;
    for part in path.split('.').filter(|p| !p.is_empty()) {
        let value = if let Some(t) = table {
            match t.iter().find(|(k, _)| k.get_ref().as_ref() == part) {
                Some((k, v)) => {
                    best = Some(k.span());
                    v
                }
                None => break,
            }
        } else if let Some(a) = array {
            match part.parse::<usize>().ok().and_then(|i| a.get(i)) {
                Some(v) => {
                    best = Some(v.span());
                    v
                }
                None => break,
            }
        } else {
            break;
        };
        table = None;
        array = None;
        match value.get_ref() {
            DeValue::Table(t) => table = Some(t),
            DeValue::Array(a) => array = Some(a.as_ref()),
            _ => {}
        }
    }
    best.map(|span| line_at(text, span.start))
}

/// 1-based line of a byte offset.
pub fn line_at(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_nested_keys_and_array_items() {
        let text =
            "title = \"x\"\n[rig]\nrope = \"a\"\nrope_length_m = -1\n[sweep]\nf = [1.0,\n 2.0]\n";
        assert_eq!(line_of(text, "title"), Some(1));
        assert_eq!(line_of(text, "rig.rope_length_m"), Some(4));
        assert_eq!(line_of(text, "sweep.f.1"), Some(7));
        assert_eq!(line_of(text, "rig.missing"), Some(2));
        assert_eq!(line_of(text, "nothing"), None);
    }
}
