//! Which key of a TOML table a typed deserialisation refused. Deserialising a struct from a
//! `toml::Value` (as the plant configuration, its faults and the scenarios' `[tcu]` table do, key
//! by key after checking the tables) gives "invalid type: string "x", expected f64" with no key:
//! the key is found by removing each key in turn — the refused one is the key whose removal makes
//! the error go away (or turn into its own "missing field"); removing any other key leaves the
//! same error, since serde reports a wrong type while it visits the keys, before missing ones.

use serde::Deserialize;

/// The key of `table` that `T` refuses, if one alone explains the error.
pub fn refused_key<T: for<'de> Deserialize<'de>>(table: &toml::Table) -> Option<String> {
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
pub fn refused_path<T: for<'de> Deserialize<'de>>(name: &str, table: &toml::Table) -> String {
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
