//! [`ParamKind`]: the values a key takes, read from its JSON Schema node.

use super::{ParamSpec, Reader, SchemaError};
use serde_json::Value;
use std::fmt;

/// What values a parameter takes.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamKind {
    /// `true` / `false`.
    Bool,
    /// A whole number.
    Integer,
    /// A number (TOML integers are accepted where a number is asked for).
    Number,
    /// Any text (a path, a name).
    String,
    /// One of these strings.
    Choice(Vec<String>),
    /// An array of `len` (`None`: any length) items of one kind.
    Array {
        /// The items' kind.
        items: Box<ParamKind>,
        /// Exact length, when fixed.
        len: Option<usize>,
    },
    /// A table with these keys.
    Table(Vec<ParamSpec>),
    /// Any of these (e.g. a number or three numbers; tagged tables).
    AnyOf(Vec<ParamKind>),
}

impl Reader<'_> {
    /// The kind of `node`, and whether it may be left out (it admits
    /// `null`: an `Option`).
    pub(super) fn kind(
        &self,
        node: &Value,
        depth: usize,
    ) -> Result<(ParamKind, bool), SchemaError> {
        if depth > super::MAX_DEPTH {
            return Err(SchemaError("nested too deep (a reference cycle?)".into()));
        }
        let node = self.resolve(node)?;
        if let Some(alts) = node
            .get("anyOf")
            .or_else(|| node.get("oneOf"))
            .and_then(Value::as_array)
        {
            return self.alternatives(alts, depth);
        }
        if let Some(c) = node.get("const").and_then(Value::as_str) {
            return Ok((ParamKind::Choice(vec![c.to_owned()]), false));
        }
        if let Some(e) = node.get("enum").and_then(Value::as_array) {
            let names = e
                .iter()
                .filter_map(Value::as_str)
                .map(str::to_owned)
                .collect();
            return Ok((ParamKind::Choice(names), false));
        }
        let types: Vec<&str> = match node.get("type") {
            Some(Value::String(t)) => vec![t.as_str()],
            Some(Value::Array(a)) => a.iter().filter_map(Value::as_str).collect(),
            _ => vec![],
        };
        let optional = types.contains(&"null");
        let kind = match types.iter().find(|t| **t != "null").copied() {
            Some("boolean") => ParamKind::Bool,
            Some("integer") => ParamKind::Integer,
            Some("number") => ParamKind::Number,
            Some("string") => ParamKind::String,
            Some("array") => self.array(node, depth)?,
            Some("object") => ParamKind::Table(self.object_fields(node, depth)?),
            other => {
                return Err(SchemaError(format!(
                    "a node of type {other:?} (expected boolean, integer, number, string, array or object)"
                )));
            }
        };
        Ok((kind, optional))
    }

    fn array(&self, node: &Value, depth: usize) -> Result<ParamKind, SchemaError> {
        let items = node
            .get("items")
            .ok_or_else(|| SchemaError("an array without `items`".into()))?;
        let (items, _) = self.kind(items, depth + 1)?;
        let min = node.get("minItems").and_then(Value::as_u64);
        let max = node.get("maxItems").and_then(Value::as_u64);
        let len = match (min, max) {
            (Some(a), Some(b)) if a == b => Some(a as usize),
            _ => None,
        };
        Ok(ParamKind::Array {
            items: Box::new(items),
            len,
        })
    }

    /// `anyOf` / `oneOf`: string constants merge into one choice, `null`
    /// makes the key optional, anything else stays an alternative.
    fn alternatives(&self, alts: &[Value], depth: usize) -> Result<(ParamKind, bool), SchemaError> {
        let (mut choices, mut kinds, mut optional) = (vec![], vec![], false);
        for a in alts {
            if a.get("type").and_then(Value::as_str) == Some("null") {
                optional = true;
                continue;
            }
            match self.kind(a, depth + 1)? {
                (ParamKind::Choice(c), o) => {
                    choices.extend(c);
                    optional |= o;
                }
                (k, o) => {
                    kinds.push(k);
                    optional |= o;
                }
            }
        }
        if !choices.is_empty() {
            kinds.insert(0, ParamKind::Choice(choices));
        }
        let kind = if kinds.len() == 1 {
            kinds.pop().expect("one kind")
        } else {
            ParamKind::AnyOf(kinds)
        };
        Ok((kind, optional))
    }
}

impl fmt::Display for ParamKind {
    /// A short type name: `number`, `"x" | "y"`, `[number; 3]`, `table`,
    /// `[table]`, `number | [number; 3]`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Bool => f.write_str("bool"),
            Self::Integer => f.write_str("integer"),
            Self::Number => f.write_str("number"),
            Self::String => f.write_str("string"),
            Self::Choice(c) => {
                let quoted: Vec<String> = c.iter().map(|s| format!("{s:?}")).collect();
                f.write_str(&quoted.join(" | "))
            }
            Self::Array {
                items,
                len: Some(n),
            } => write!(f, "[{items}; {n}]"),
            Self::Array { items, len: None } => write!(f, "[{items}]"),
            Self::Table(_) => f.write_str("table"),
            Self::AnyOf(k) => {
                let names: Vec<String> = k.iter().map(ToString::to_string).collect();
                f.write_str(&names.join(" | "))
            }
        }
    }
}
