//! The model's parameter form: a plugin's [`ParamSchema`] read into one
//! editable field per top-level key (a widget by the key's kind), filled
//! from the scene's table or the schema's defaults, and assembled back into
//! the TOML table `swap_model` takes. Problems — from
//! [`ParamSchema::check`] while the user edits, or from the session on
//! Apply — are filed under the key they name.

use voxflex_runtime::param_schema::{ParamKind, ParamSchema, ParamSpec};

/// The value a field edits, by the widget that edits it.
#[derive(Clone, Debug, PartialEq)]
pub enum FieldValue {
    /// A checkbox.
    Bool(bool),
    /// A whole-number drag value.
    Integer(i64),
    /// A number drag value.
    Number(f64),
    /// A combo box over the choices (the one chosen).
    Choice(String),
    /// A one-line text edit.
    Text(String),
    /// `N` number drag values (a fixed-length array; `integer`: whole numbers).
    Numbers {
        /// The values.
        values: Vec<f64>,
        /// The items are integers.
        integer: bool,
    },
    /// Inline TOML text of the value (tables, arrays of tables, anything
    /// with alternatives).
    Toml(String),
}

/// One key of the form.
#[derive(Clone, Debug)]
pub struct Field {
    /// The key as the schema declares it.
    pub spec: ParamSpec,
    /// Its value.
    pub value: FieldValue,
    /// Whether the key goes into the table (always for required keys; an
    /// optional key without a default starts off).
    pub on: bool,
    /// Problems naming this key.
    pub issues: Vec<String>,
}

/// The form of one plugin.
#[derive(Clone, Debug)]
pub struct ParamForm {
    /// The plugin.
    pub plugin: String,
    /// One field per top-level key, in the schema's order.
    pub fields: Vec<Field>,
    /// Problems that name no key of the form (a bad TOML text, a session
    /// error naming no key).
    pub general: Vec<String>,
    schema: ParamSchema,
}

impl ParamForm {
    /// The form for `plugin`'s `schema`, filled from `current` (the scene's
    /// table) where it has the key, else the schema's default.
    pub fn new(plugin: &str, schema: &ParamSchema, current: &toml::Table) -> Self {
        let fields = schema
            .params
            .iter()
            .map(|spec| field(spec, current.get(&spec.name)))
            .collect();
        let mut form = Self {
            plugin: plugin.to_owned(),
            fields,
            general: vec![],
            schema: schema.clone(),
        };
        form.check();
        form
    }

    /// The table the form holds (the keys that are on), or the problems
    /// that keep it from being TOML (each filed under its key).
    pub fn table(&self) -> Result<toml::Table, Vec<(String, String)>> {
        let mut table = toml::Table::new();
        let mut bad = vec![];
        for f in self.fields.iter().filter(|f| f.on) {
            match to_toml(&f.value) {
                Ok(v) => {
                    table.insert(f.spec.name.clone(), v);
                }
                Err(e) => bad.push((f.spec.name.clone(), e)),
            }
        }
        if bad.is_empty() { Ok(table) } else { Err(bad) }
    }

    /// The table as TOML text (what `swap_model` takes).
    pub fn toml_text(&self) -> Result<String, Vec<(String, String)>> {
        self.table().map(|t| t.to_string())
    }

    /// Re-checks the form against the schema, filing each problem under
    /// the key it names; returns whether it has none.
    pub fn check(&mut self) -> bool {
        let issues: Vec<String> = match self.table() {
            Ok(t) => self.schema.check(&t),
            Err(bad) => bad
                .into_iter()
                .map(|(k, e)| format!("`{k}`: {e}"))
                .collect(),
        };
        self.file_issues(&issues);
        issues.is_empty()
    }

    /// Files `issues` (e.g. the session's error on Apply) under the keys
    /// they name; the rest go to [`Self::general`].
    pub fn file_issues(&mut self, issues: &[String]) {
        for f in &mut self.fields {
            f.issues.clear();
        }
        self.general.clear();
        for issue in issues {
            match self.key_named(issue) {
                Some(i) => self.fields[i].issues.push(issue.clone()),
                None => self.general.push(issue.clone()),
            }
        }
    }

    /// The field whose key `issue` names first (as `` `key`` ``,
    /// `` `key.sub`` ``, `` `key[0]`` ``, or `key` as a word).
    fn key_named(&self, issue: &str) -> Option<usize> {
        let named = |name: &str| {
            issue.split('`').skip(1).step_by(2).any(|quoted| {
                quoted == name
                    || quoted.starts_with(&format!("{name}."))
                    || quoted.starts_with(&format!("{name}["))
            })
        };
        self.fields
            .iter()
            .position(|f| named(&f.spec.name))
            .or_else(|| {
                let words: Vec<&str> = issue
                    .split(|c: char| !(c.is_alphanumeric() || c == '_'))
                    .collect();
                self.fields
                    .iter()
                    .position(|f| words.contains(&f.spec.name.as_str()))
            })
    }
}

/// A key's field: from the scene's value, else its default, else an empty
/// value of its kind (off unless required).
fn field(spec: &ParamSpec, current: Option<&toml::Value>) -> Field {
    let default = spec.default.as_deref().and_then(parse_value);
    let given = current.cloned().or(default);
    let on = spec.required || given.is_some();
    let value = match given {
        Some(v) => from_toml(&spec.kind, &v),
        None => empty(&spec.kind),
    };
    Field {
        spec: spec.clone(),
        value,
        on,
        issues: vec![],
    }
}

/// TOML value text (`1.5`, `[1, 2]`, `{ a = 1 }`) read as a value.
pub fn parse_value(text: &str) -> Option<toml::Value> {
    let doc: toml::Table = format!("v = {text}").parse().ok()?;
    doc.get("v").cloned()
}

fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

/// The widget value for `v` of `kind` (inline TOML where the widgets do
/// not fit the value).
fn from_toml(kind: &ParamKind, v: &toml::Value) -> FieldValue {
    let fallback = || FieldValue::Toml(v.to_string());
    match (kind, v) {
        (ParamKind::Bool, toml::Value::Boolean(b)) => FieldValue::Bool(*b),
        (ParamKind::Integer, toml::Value::Integer(i)) => FieldValue::Integer(*i),
        (ParamKind::Number, _) => number(v).map_or_else(fallback, FieldValue::Number),
        (ParamKind::Choice(_), toml::Value::String(s)) => FieldValue::Choice(s.clone()),
        (ParamKind::String, toml::Value::String(s)) => FieldValue::Text(s.clone()),
        (
            ParamKind::Array {
                items,
                len: Some(n),
            },
            toml::Value::Array(a),
        ) if a.len() == *n && scalar_number(items).is_some() => {
            let values: Option<Vec<f64>> = a.iter().map(number).collect();
            let integer = scalar_number(items) == Some(true);
            values.map_or_else(fallback, |values| FieldValue::Numbers { values, integer })
        }
        _ => fallback(),
    }
}

/// `Some(true)` for integer items, `Some(false)` for number items.
fn scalar_number(kind: &ParamKind) -> Option<bool> {
    match kind {
        ParamKind::Integer => Some(true),
        ParamKind::Number => Some(false),
        _ => None,
    }
}

/// The value a field of `kind` starts at without a value or default.
fn empty(kind: &ParamKind) -> FieldValue {
    match kind {
        ParamKind::Bool => FieldValue::Bool(false),
        ParamKind::Integer => FieldValue::Integer(0),
        ParamKind::Number => FieldValue::Number(0.0),
        ParamKind::String => FieldValue::Text(String::new()),
        ParamKind::Choice(c) => FieldValue::Choice(c.first().cloned().unwrap_or_default()),
        ParamKind::Array {
            items,
            len: Some(n),
        } if scalar_number(items).is_some() => FieldValue::Numbers {
            values: vec![0.0; *n],
            integer: scalar_number(items) == Some(true),
        },
        ParamKind::Array { .. } => FieldValue::Toml("[]".into()),
        ParamKind::Table(_) => FieldValue::Toml("{}".into()),
        ParamKind::AnyOf(k) => k.first().map_or(FieldValue::Toml(String::new()), empty),
    }
}

/// The TOML value a field holds, or why its text is not TOML.
fn to_toml(v: &FieldValue) -> Result<toml::Value, String> {
    Ok(match v {
        FieldValue::Bool(b) => toml::Value::Boolean(*b),
        FieldValue::Integer(i) => toml::Value::Integer(*i),
        FieldValue::Number(x) => toml::Value::Float(*x),
        FieldValue::Choice(s) | FieldValue::Text(s) => toml::Value::String(s.clone()),
        FieldValue::Numbers { values, integer } => toml::Value::Array(
            values
                .iter()
                .map(|&x| {
                    if *integer {
                        toml::Value::Integer(x.round() as i64)
                    } else {
                        toml::Value::Float(x)
                    }
                })
                .collect(),
        ),
        FieldValue::Toml(text) => parse_value(text).ok_or_else(|| {
            format!(
                "`{text}` is not a TOML value (e.g. `[{{ range = [0.0, 1.0], constraint = 0.5 }}]`)"
            )
        })?,
    })
}

#[cfg(test)]
#[path = "param_form_tests.rs"]
mod tests;
