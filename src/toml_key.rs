//! Which key of a TOML table a typed deserialisation refused. Deserialising a struct from a
//! `toml::Value` (as the plant configuration, its faults and the scenarios' `[tcu]` table do, key
//! by key after checking the tables) gives "invalid type: string "x", expected f64" with no key:
//! the key is found by removing each key in turn — the refused one is the key whose removal makes
//! the error go away (or turn into its own "missing field"); removing any other key leaves the
//! same error, since serde reports a wrong type while it visits the keys, before missing ones.

use serde::Deserialize;
use toml_edit::{ImDocument, Item, TableLike, Value};

/// The 1-based line where a key path is written in TOML text: `table.key`, with `[i]` after a
/// segment for an element of an array or of an array of tables (`faults[2].value`,
/// `pedal_pct[1]`). `None` when the text does not parse or does not hold the whole path.
pub fn line_of(text: &str, path: &str) -> Option<usize> {
    let doc = ImDocument::parse(text).ok()?;
    span_of(doc.as_item(), path).map(|s| line_at(text, s.start))
}

/// The span of a key path below `root`.
fn span_of(root: &Item, path: &str) -> Span {
    let mut node = Node::Item(root);
    let mut span = None;
    for seg in path.split('.') {
        let (name, indexes) = seg.split_at(seg.find('[').unwrap_or(seg.len()));
        (node, span) = child(node, name)?;
        for ix in indexes.split(['[', ']']).filter(|s| !s.is_empty()) {
            (node, span) = element(node, ix.parse().ok()?)?;
        }
    }
    span
}

/// [`line_of`], and for a key named relative to a table of the text (a scenario's `[driver]`
/// read by the profile parser says `pedal_pct[3]`) the line under the one top-level table that
/// holds it (none when several do).
pub(crate) fn line_in_text(text: &str, key: &str) -> Option<usize> {
    let doc = ImDocument::parse(text).ok()?;
    let root = doc.as_item();
    let span = span_of(root, key).or_else(|| {
        let found: Vec<_> = root
            .as_table_like()?
            .iter()
            .filter_map(|(_, item)| item.as_table_like().and(span_of(item, key)))
            .collect();
        match <[_; 1]>::try_from(found) {
            Ok([s]) => Some(s),
            Err(_) => None,
        }
    });
    span.map(|s| line_at(text, s.start))
}

/// ` line N` after a file name, or nothing.
pub(crate) fn at_line(line: Option<usize>) -> String {
    line.map_or(String::new(), |l| format!(" line {l}"))
}

/// A place in a parsed document.
#[derive(Clone, Copy)]
enum Node<'a> {
    Item(&'a Item),
    Value(&'a Value),
    Table(&'a toml_edit::Table),
}

type Span = Option<std::ops::Range<usize>>;

/// The key `name` of a table (its span: the key's).
fn child<'a>(n: Node<'a>, name: &str) -> Option<(Node<'a>, Span)> {
    let t: &dyn TableLike = match n {
        Node::Item(i) => i.as_table_like()?,
        Node::Value(v) => v.as_inline_table()?,
        Node::Table(t) => t,
    };
    let (k, v) = t.get_key_value(name)?;
    Some((Node::Item(v), k.span().or(v.span())))
}

/// Element `i` of an array or an array of tables.
fn element(n: Node<'_>, i: usize) -> Option<(Node<'_>, Span)> {
    match n {
        Node::Item(Item::ArrayOfTables(a)) => {
            let t = a.get(i)?;
            Some((Node::Table(t), t.span()))
        }
        Node::Item(Item::Value(Value::Array(a))) | Node::Value(Value::Array(a)) => {
            let v = a.get(i)?;
            Some((Node::Value(v), v.span()))
        }
        _ => None,
    }
}

/// The 1-based line of a byte offset.
fn line_at(text: &str, offset: usize) -> usize {
    1 + text[..offset.min(text.len())]
        .bytes()
        .filter(|b| *b == b'\n')
        .count()
}

/// The key of `table` that `T` refuses, if one alone explains the error.
pub(crate) fn refused_key<T: for<'de> Deserialize<'de>>(table: &toml::Table) -> Option<String> {
    table
        .keys()
        .find(|k| {
            let mut t = table.clone();
            t.remove(k.as_str());
            match toml::Value::Table(t).try_into::<T>() {
                Ok(_) => true,
                Err(e) => e.message().contains(&format!("missing field `{k}`")),
            }
        })
        .cloned()
}

/// `name.key` for the key `T` refuses in `table`, else `name`.
pub(crate) fn refused_path<T: for<'de> Deserialize<'de>>(
    name: &str,
    table: &toml::Table,
) -> String {
    refused_key::<T>(table).map_or(name.to_string(), |k| format!("{name}.{k}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize)]
    #[allow(dead_code)]
    struct S {
        name: String,
        speed: f64,
        every: Option<u32>,
    }

    fn table(text: &str) -> toml::Table {
        toml::from_str(text).unwrap()
    }

    #[test]
    fn keys_are_found_at_their_lines() {
        let text = "a = 1\n[rig]\nspeed = 3.0\npedal_pct = [\n  10,\n  20,\n]\n\
                    point = { x = 1, y = 2 }\n[[faults]]\nsignal = \"s\"\n[[faults]]\n\
                    signal = \"t\"\nvalue = 7\n";
        assert_eq!(line_of(text, "a"), Some(1));
        assert_eq!(line_of(text, "rig.speed"), Some(3));
        assert_eq!(line_of(text, "rig.pedal_pct"), Some(4));
        assert_eq!(line_of(text, "rig.pedal_pct[1]"), Some(6));
        assert_eq!(line_of(text, "rig.point.y"), Some(8));
        assert_eq!(line_of(text, "faults[1]"), Some(11));
        assert_eq!(line_of(text, "faults[1].value"), Some(13));
        assert_eq!(line_of(text, "faults[0].value"), None);
        assert_eq!(line_of(text, "rig.missing"), None);
        assert_eq!(line_of("not toml [", "a"), None);
    }

    #[test]
    fn the_key_with_the_wrong_type_is_named() {
        let t = table("name = \"a\"\nspeed = \"fast\"\nevery = 3");
        assert_eq!(refused_key::<S>(&t).as_deref(), Some("speed"));
        let t = table("name = \"a\"\nspeed = 1.0\nevery = 1e300");
        assert_eq!(refused_key::<S>(&t).as_deref(), Some("every"));
        assert_eq!(refused_path::<S>("rig", &t), "rig.every");
        // A required key of the wrong type.
        let t = table("name = 7\nspeed = 1.0");
        assert_eq!(refused_key::<S>(&t).as_deref(), Some("name"));
    }
}
