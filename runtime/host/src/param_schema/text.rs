//! [`ParamSchema::to_text`]: the schema as a table for a terminal
//! (`voxflex plugins --params NAME`).

use super::{ParamKind, ParamSchema, ParamSpec};
use std::fmt::Write;

impl ParamSchema {
    /// One line per key (nested table keys indented under theirs): name,
    /// type, unit, range, default or "required", and the doc line.
    pub fn to_text(&self) -> String {
        let mut rows = vec![];
        collect(&self.params, 0, &mut rows);
        let widths: Vec<usize> = (0..5)
            .map(|c| rows.iter().map(|r| r[c].chars().count()).max().unwrap_or(0))
            .collect();
        let mut out = String::new();
        let header = ["key", "type", "unit", "range", "default"];
        for row in std::iter::once(header.map(str::to_owned).to_vec())
            .chain(rows.into_iter().map(|r| r.to_vec()))
        {
            for (c, cell) in row.iter().take(5).enumerate() {
                let _ = write!(out, "{cell:<w$}  ", w = widths[c].max(header[c].len()));
            }
            let _ = writeln!(out, "{}", row.get(5).map(String::as_str).unwrap_or("doc"));
        }
        out
    }
}

fn collect(specs: &[ParamSpec], depth: usize, rows: &mut Vec<[String; 6]>) {
    for s in specs {
        rows.push(row(s, depth));
        for fields in nested(&s.kind) {
            collect(fields, depth + 1, rows);
        }
    }
}

/// The key tables nested in a kind (a table, an array of tables, the
/// table alternatives of an `AnyOf`).
fn nested(kind: &ParamKind) -> Vec<&Vec<ParamSpec>> {
    match kind {
        ParamKind::Table(f) => vec![f],
        ParamKind::Array { items, .. } => nested(items),
        ParamKind::AnyOf(k) => k.iter().flat_map(nested).collect(),
        _ => vec![],
    }
}

fn row(s: &ParamSpec, depth: usize) -> [String; 6] {
    let range = match (s.minimum, s.maximum) {
        (None, None) => String::new(),
        (Some(a), None) => format!(">= {a}"),
        (None, Some(b)) => format!("<= {b}"),
        (Some(a), Some(b)) => format!("{a} ..= {b}"),
    };
    let default = match (&s.default, s.required) {
        (Some(d), _) => d.clone(),
        (None, true) => "required".into(),
        (None, false) => "-".into(),
    };
    [
        format!("{}{}", "  ".repeat(depth), s.name),
        s.kind.to_string(),
        s.unit.clone().unwrap_or_default(),
        range,
        default,
        s.doc.clone(),
    ]
}
