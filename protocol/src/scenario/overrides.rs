//! Command-line overrides: `KEY=VALUE`, a dotted key and a TOML value.
//!
//! `guidance.kappa=0`, `uavs.altitudes_m=[80,90]`, `guidance.use_map=false`,
//! `comms.range_m=inf`, `region={half_extent_m=100}`. A bare word that is not a TOML value
//! (`fast`, `1.2.3`) is taken as a string, so it fails the type check naming its key rather
//! than the override syntax; anything with TOML punctuation that does not parse (`[80, 90`)
//! is a [`ScenarioError::BadOverride`] carrying the TOML parser's reason.

use toml::{Table, Value};

use super::ScenarioError;
use super::validate::{dotted, unknown_key};

/// One parsed override.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Override {
    /// The override as the user wrote it.
    text: String,
    /// The key's segments, `["guidance", "kappa"]`.
    path: Vec<String>,
    /// The value to put there.
    value: Value,
}

impl Override {
    /// Parses `KEY=VALUE`.
    pub(super) fn parse(text: &str) -> Result<Self, ScenarioError> {
        let bad = |reason: String| ScenarioError::BadOverride {
            text: text.to_owned(),
            reason,
        };
        let Some((key, value)) = text.split_once('=') else {
            return Err(bad(
                "there is no `=` between the key and the value".to_owned()
            ));
        };
        let key = key.trim();
        if key.is_empty() {
            return Err(bad("the key before `=` is empty".to_owned()));
        }
        let mut path = Vec::new();
        for segment in key.split('.') {
            let plain = !segment.is_empty()
                && segment
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
            if !plain {
                return Err(bad(format!(
                    "`{key}` is not a dotted key: each part between dots must be letters, \
                     digits, `_` or `-`"
                )));
            }
            path.push(segment.to_owned());
        }
        let value = value.trim();
        if value.is_empty() {
            return Err(bad(
                "the value after `=` is empty (write \"\" for an empty string)".to_owned(),
            ));
        }
        let value = match value.parse::<Value>() {
            Ok(parsed) => parsed,
            Err(_) if is_bare_word(value) => Value::String(value.to_owned()),
            Err(error) => {
                return Err(bad(format!(
                    "`{value}` is not a TOML value: {}",
                    error.message()
                )));
            }
        };
        Ok(Self {
            text: text.to_owned(),
            path,
            value,
        })
    }

    /// Puts the value at its key in `table`, after checking the key against `schema`.
    ///
    /// A table value merges into a table already there (`region={half_extent_m=100}` keeps the
    /// file's other `[region]` keys); any other value replaces what was there.
    pub(super) fn apply(self, table: &mut Table, schema: &Table) -> Result<(), ScenarioError> {
        self.check_path(schema)?;
        let Some((last, parents)) = self.path.split_last() else {
            return Ok(());
        };
        let mut level = table;
        for name in parents {
            let slot = level
                .entry(name.clone())
                .or_insert_with(|| Value::Table(Table::new()));
            if !slot.is_table() {
                // The override wins over whatever the file held at this key.
                *slot = Value::Table(Table::new());
            }
            let Value::Table(inner) = slot else {
                return Ok(());
            };
            level = inner;
        }
        match level.get_mut(last) {
            Some(existing) => merge(existing, self.value),
            None => {
                level.insert(last.clone(), self.value);
            }
        }
        Ok(())
    }

    /// Every segment but the last must name a table of the schema, the last a key in it.
    fn check_path(&self, schema: &Table) -> Result<(), ScenarioError> {
        let mut level = schema;
        let mut prefix = String::new();
        for (depth, name) in self.path.iter().enumerate() {
            let key = dotted(&prefix, name);
            let Some(found) = level.get(name) else {
                return Err(unknown_key(key, level));
            };
            let is_last = depth + 1 == self.path.len();
            match found {
                Value::Table(inner) => level = inner,
                _ if is_last => {}
                _ => {
                    return Err(ScenarioError::BadOverride {
                        text: self.text.clone(),
                        reason: format!(
                            "`{key}` is a single value, not a table of keys; write {key}=VALUE"
                        ),
                    });
                }
            }
            prefix = key;
        }
        Ok(())
    }
}

/// Writes `value` over `into`, key by key where both are tables.
fn merge(into: &mut Value, value: Value) {
    match (into, value) {
        (Value::Table(into), Value::Table(from)) => {
            for (name, value) in from {
                match into.get_mut(&name) {
                    Some(existing) => merge(existing, value),
                    None => {
                        into.insert(name, value);
                    }
                }
            }
        }
        (into, value) => *into = value,
    }
}

/// A word with no TOML punctuation or space: meant as a string, not as a broken value.
fn is_bare_word(text: &str) -> bool {
    !text
        .chars()
        .any(|c| c.is_whitespace() || "[]{}\"',=#".contains(c))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reason(text: &str) -> String {
        match Override::parse(text) {
            Err(ScenarioError::BadOverride { reason, .. }) => reason,
            other => format!("not a bad override: {other:?}"),
        }
    }

    #[test]
    fn parses_each_kind_of_value() {
        let cases = [
            ("guidance.kappa=0", Value::Integer(0)),
            ("guidance.kappa = 0.5", Value::Float(0.5)),
            ("guidance.use_map=false", Value::Boolean(false)),
            ("comms.range_m=inf", Value::Float(f64::INFINITY)),
            (
                "uavs.altitudes_m=[80,90]",
                Value::Array(vec![Value::Integer(80), Value::Integer(90)]),
            ),
            ("x.y=fast", Value::String("fast".to_owned())),
            ("x.y=\"a b\"", Value::String("a b".to_owned())),
        ];
        for (text, value) in cases {
            assert_eq!(Override::parse(text).unwrap().value, value, "{text}");
        }
        // `a=b` holds TOML punctuation, so it is refused rather than guessed to be a string.
        assert!(Override::parse("x.y=a=b").is_err());
        let path = Override::parse(" guidance.kappa =0").unwrap().path;
        assert_eq!(path, ["guidance", "kappa"]);
    }

    #[test]
    fn refuses_malformed_overrides_with_a_reason() {
        assert!(reason("guidance.kappa").contains("no `=`"));
        assert!(reason("=1").contains("key before `=` is empty"));
        assert!(reason("guidance..kappa=1").contains("not a dotted key"));
        assert!(reason("guidance.kap pa=1").contains("not a dotted key"));
        assert!(reason("guidance.kappa=").contains("empty"));
        assert!(reason("uavs.altitudes_m=[80, 90").contains("not a TOML value"));
    }

    #[test]
    fn checks_the_path_against_the_schema() {
        let schema = super::super::schema().unwrap();
        let mut table = Table::new();
        let unknown = Override::parse("guidance.kapa=1")
            .unwrap()
            .apply(&mut table, &schema);
        assert!(
            matches!(unknown, Err(ScenarioError::UnknownKey { ref key, ref expected })
                if key == "guidance.kapa" && expected.contains(&"kappa".to_owned())),
            "{unknown:?}"
        );
        let through_value = Override::parse("seed.x=1")
            .unwrap()
            .apply(&mut table, &schema);
        assert!(
            matches!(through_value, Err(ScenarioError::BadOverride { ref reason, .. })
                if reason.contains("`seed` is a single value")),
            "{through_value:?}"
        );
    }

    #[test]
    fn tables_merge_and_values_replace() {
        let schema = super::super::schema().unwrap();
        let mut table: Table = "[region]\nhalf_extent_m = 100.0\nbuilding_fraction = 0.1\n"
            .parse()
            .unwrap();
        Override::parse("region={half_extent_m=120}")
            .unwrap()
            .apply(&mut table, &schema)
            .unwrap();
        Override::parse("camera.rows=100")
            .unwrap()
            .apply(&mut table, &schema)
            .unwrap();
        let region = table["region"].as_table().unwrap();
        assert_eq!(region["half_extent_m"], Value::Integer(120));
        assert_eq!(region["building_fraction"], Value::Float(0.1));
        assert_eq!(table["camera"]["rows"], Value::Integer(100));
    }
}
