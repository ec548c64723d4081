//! A plugin's parameter schema as the host uses it: the JSON Schema a
//! plugin declares through the ABI ([`voxflex_abi::params_schema`]),
//! reduced to the subset `schemars` writes for `serde` types — objects,
//! arrays, numbers, strings, booleans, string choices, optional values and
//! tagged alternatives — and read into [`ParamSpec`]s: name, type, unit,
//! range, default and a one-line doc per key.
//!
//! [`ParamSchema::check`] checks a scene's parameter table against it
//! (`voxflex validate` reports every problem at once, with the key's path,
//! unit and range; the plugin's own `create` still has the last word), and
//! [`ParamSchema::to_text`] prints it (`voxflex plugins --params NAME`).

mod check;
mod kind;
mod text;

pub use kind::ParamKind;

use serde_json::{Map, Value};

/// A schema that is not the subset the host reads.
#[derive(Debug, thiserror::Error)]
#[error("parameter schema: {0}")]
pub struct SchemaError(pub String);

/// One key of a parameter table.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamSpec {
    /// The key, as the TOML table spells it.
    pub name: String,
    /// What values it takes.
    pub kind: ParamKind,
    /// The table must have it.
    pub required: bool,
    /// Its default, as TOML text (absent: no default, or none means "off").
    pub default: Option<String>,
    /// Unit of its numbers (`"mm"`, `"Pa"`, …), when it has one.
    pub unit: Option<String>,
    /// Smallest and largest allowed number (inclusive), when bounded.
    pub minimum: Option<f64>,
    /// See [`Self::minimum`].
    pub maximum: Option<f64>,
    /// First line of its documentation.
    pub doc: String,
}

/// A plugin's parameter table: its keys, the required ones first, each
/// group by name (JSON objects keep no order).
#[derive(Clone, Debug, PartialEq)]
pub struct ParamSchema {
    /// The keys.
    pub params: Vec<ParamSpec>,
}

impl ParamSchema {
    /// Reads the JSON Schema text a plugin declared.
    pub fn from_json(text: &str) -> Result<Self, SchemaError> {
        let root: Value =
            serde_json::from_str(text).map_err(|e| SchemaError(format!("not JSON: {e}")))?;
        let defs = root
            .get("$defs")
            .and_then(Value::as_object)
            .cloned()
            .unwrap_or_default();
        let reader = Reader { defs: &defs };
        let params = reader.object_fields(&root, 0)?;
        Ok(Self { params })
    }

    /// The key called `name`.
    pub fn get(&self, name: &str) -> Option<&ParamSpec> {
        self.params.iter().find(|p| p.name == name)
    }
}

/// Nesting deeper than this is refused (a `$ref` cycle).
const MAX_DEPTH: usize = 16;

/// Resolves `$ref`s against the schema's `$defs` while reading.
struct Reader<'a> {
    defs: &'a Map<String, Value>,
}

impl Reader<'_> {
    /// `node` with its `$ref` followed (the referring node's own keys, such
    /// as `description` and `default`, stay with the caller).
    fn resolve<'v>(&'v self, node: &'v Value) -> Result<&'v Value, SchemaError> {
        match node.get("$ref").and_then(Value::as_str) {
            None => Ok(node),
            Some(r) => {
                let name = r
                    .strip_prefix("#/$defs/")
                    .ok_or_else(|| SchemaError(format!("reference {r} is not into #/$defs")))?;
                self.defs
                    .get(name)
                    .ok_or_else(|| SchemaError(format!("reference {r} names no definition")))
            }
        }
    }

    /// The fields of an object schema.
    fn object_fields(&self, node: &Value, depth: usize) -> Result<Vec<ParamSpec>, SchemaError> {
        if depth > MAX_DEPTH {
            return Err(SchemaError("nested too deep (a reference cycle?)".into()));
        }
        let node = self.resolve(node)?;
        let required: Vec<&str> = node
            .get("required")
            .and_then(Value::as_array)
            .map(|a| a.iter().filter_map(Value::as_str).collect())
            .unwrap_or_default();
        let Some(props) = node.get("properties").and_then(Value::as_object) else {
            return Ok(vec![]);
        };
        let mut specs = props
            .iter()
            .map(|(name, p)| {
                let (kind, optional) = self.kind(p, depth + 1)?;
                let target = self.resolve(p)?;
                let number = |k: &str| p.get(k).or_else(|| target.get(k)).and_then(Value::as_f64);
                Ok(ParamSpec {
                    name: name.clone(),
                    kind,
                    required: required.contains(&name.as_str()) && !optional,
                    default: p.get("default").filter(|d| !d.is_null()).map(toml_text),
                    unit: p.get("unit").and_then(Value::as_str).map(str::to_owned),
                    minimum: number("minimum"),
                    maximum: number("maximum"),
                    doc: first_line(p.get("description").or_else(|| target.get("description"))),
                })
            })
            .collect::<Result<Vec<_>, SchemaError>>()?;
        specs.sort_by(|a, b| (!a.required, &a.name).cmp(&(!b.required, &b.name)));
        Ok(specs)
    }
}

/// The first sentence of a description's first paragraph, with rustdoc
/// links (`[`x`]`) shown as code (empty without a description).
fn first_line(d: Option<&Value>) -> String {
    let paragraph = d
        .and_then(Value::as_str)
        .and_then(|s| s.split("\n\n").next())
        .map(|s| s.split_whitespace().collect::<Vec<_>>().join(" "))
        .unwrap_or_default()
        .replace("[`", "`")
        .replace("`]", "`");
    match paragraph.find(". ") {
        Some(end) => paragraph[..=end].to_owned(),
        None => paragraph,
    }
}

/// A JSON default as the TOML a scene would write.
fn toml_text(v: &Value) -> String {
    match v {
        Value::String(s) => format!("{s:?}"),
        Value::Array(a) => format!(
            "[{}]",
            a.iter().map(toml_text).collect::<Vec<_>>().join(", ")
        ),
        Value::Object(o) => format!(
            "{{ {} }}",
            o.iter()
                .filter(|(_, x)| !x.is_null())
                .map(|(k, x)| format!("{k} = {}", toml_text(x)))
                .collect::<Vec<_>>()
                .join(", ")
        ),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests;
