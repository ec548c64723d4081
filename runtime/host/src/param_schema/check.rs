//! [`ParamSchema::check`]: a scene's parameter table against the schema —
//! unknown keys (with the nearest known one), missing keys, wrong types,
//! values out of range or not among the choices — every problem at once,
//! each naming the key's path (`materials[0].youngs_modulus`).

use super::{ParamKind, ParamSchema, ParamSpec};
use toml::Value;

impl ParamSchema {
    /// Every problem of `table` against this schema (empty: it conforms).
    pub fn check(&self, table: &toml::Table) -> Vec<String> {
        let mut issues = vec![];
        check_table(&self.params, table, "", &mut issues);
        issues
    }
}

fn join(path: &str, key: &str) -> String {
    if path.is_empty() {
        key.to_owned()
    } else {
        format!("{path}.{key}")
    }
}

fn check_table(specs: &[ParamSpec], table: &toml::Table, path: &str, issues: &mut Vec<String>) {
    for (key, value) in table {
        match specs.iter().find(|s| s.name == *key) {
            Some(spec) => check_value(&spec.kind, value, &join(path, key), spec, issues),
            None => issues.push(unknown(specs, key, &join(path, key))),
        }
    }
    for spec in specs
        .iter()
        .filter(|s| s.required && !table.contains_key(&s.name))
    {
        issues.push(format!(
            "`{}` is missing: {} ({})",
            join(path, &spec.name),
            spec.kind,
            spec.doc
        ));
    }
}

/// "unknown key", with the nearest known key when one is close.
fn unknown(specs: &[ParamSpec], key: &str, path: &str) -> String {
    let known: Vec<&str> = specs.iter().map(|s| s.name.as_str()).collect();
    let nearest = known
        .iter()
        .map(|k| (strsim::levenshtein(k, key), *k))
        .min()
        .filter(|(d, k)| *d <= 2 || (*d <= 4 && *d * 3 <= k.len()));
    match nearest {
        Some((_, k)) => format!("unknown key `{path}`: did you mean `{k}`?"),
        None => format!("unknown key `{path}` (known: {})", known.join(", ")),
    }
}

/// The value's TOML type name, for messages.
fn type_name(v: &Value) -> &'static str {
    match v {
        Value::String(_) => "a string",
        Value::Integer(_) => "an integer",
        Value::Float(_) => "a number",
        Value::Boolean(_) => "a boolean",
        Value::Datetime(_) => "a date",
        Value::Array(_) => "an array",
        Value::Table(_) => "a table",
    }
}

fn check_value(
    kind: &ParamKind,
    v: &Value,
    path: &str,
    spec: &ParamSpec,
    issues: &mut Vec<String>,
) {
    let wrong = |issues: &mut Vec<String>| {
        issues.push(format!("`{path}` is {}, expected {kind}", type_name(v)));
    };
    match (kind, v) {
        (ParamKind::Bool, Value::Boolean(_)) | (ParamKind::String, Value::String(_)) => {}
        (ParamKind::Integer, Value::Integer(i)) => check_range(*i as f64, path, spec, issues),
        (ParamKind::Number, Value::Integer(i)) => check_range(*i as f64, path, spec, issues),
        (ParamKind::Number, Value::Float(x)) if x.is_finite() => {
            check_range(*x, path, spec, issues)
        }
        (ParamKind::Number, Value::Float(x)) => {
            issues.push(format!("`{path}` = {x} is not a finite number"));
        }
        (ParamKind::Choice(c), Value::String(s)) if c.contains(s) => {}
        (ParamKind::Choice(_), Value::String(s)) => {
            issues.push(format!("`{path}` = {s:?} is not one of {kind}"));
        }
        (ParamKind::Array { items, len }, Value::Array(a)) => {
            if let Some(n) = len.filter(|n| *n != a.len()) {
                issues.push(format!("`{path}` has {} items, expected {n}", a.len()));
            }
            for (i, x) in a.iter().enumerate() {
                check_value(items, x, &format!("{path}[{i}]"), spec, issues);
            }
        }
        (ParamKind::Table(fields), Value::Table(t)) => check_table(fields, t, path, issues),
        (ParamKind::AnyOf(kinds), _) => check_any(kinds, v, path, spec, issues),
        _ => wrong(issues),
    }
}

/// A value any of `kinds` accepts passes; otherwise the problems of the
/// alternative that came closest (fewest problems) are reported.
fn check_any(
    kinds: &[ParamKind],
    v: &Value,
    path: &str,
    spec: &ParamSpec,
    issues: &mut Vec<String>,
) {
    let mut best: Option<Vec<String>> = None;
    for k in kinds {
        let mut mine = vec![];
        check_value(k, v, path, spec, &mut mine);
        if mine.is_empty() {
            return;
        }
        if best.as_ref().is_none_or(|b| mine.len() < b.len()) {
            best = Some(mine);
        }
    }
    issues.extend(best.unwrap_or_default());
}

fn check_range(x: f64, path: &str, spec: &ParamSpec, issues: &mut Vec<String>) {
    let unit = spec
        .unit
        .as_deref()
        .map(|u| format!(" {u}"))
        .unwrap_or_default();
    if let Some(min) = spec.minimum.filter(|m| x < *m) {
        issues.push(format!(
            "`{path}` = {x}{unit} is below its minimum {min}{unit}"
        ));
    }
    if let Some(max) = spec.maximum.filter(|m| x > *m) {
        issues.push(format!(
            "`{path}` = {x}{unit} is above its maximum {max}{unit}"
        ));
    }
}
