//! A benchmark's result: figures as rows of a Markdown table and the same
//! as JSON, with the command, the machine's load and its cores, written
//! into the output folder as `<bench>.md` and `<bench>.json`.

use anyhow::Context;
use serde_json::{Map, Value, json};
use std::path::{Path, PathBuf};

/// The 1-, 5- and 15-minute load averages (`/proc/loadavg`), if readable.
pub fn load_average() -> Option<[f64; 3]> {
    let text = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = text.split_whitespace().map(|x| x.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

/// One benchmark's figures.
#[derive(Debug)]
pub struct Report {
    /// Benchmark name (`drag`, `interactive`, `open`): the file stem.
    pub bench: String,
    /// What was measured, one sentence.
    pub title: String,
    /// Rows of the Markdown table: figure, value, and the requirement
    /// with whether it is met (empty when there is none).
    pub rows: Vec<[String; 3]>,
    /// Every figure, machine-readable.
    pub json: Map<String, Value>,
    /// Load average when the benchmark started.
    pub load_before: Option<[f64; 3]>,
}

impl Report {
    /// An empty report of `bench`, the load average taken now.
    pub fn new(bench: &str, title: &str) -> Self {
        Self {
            bench: bench.into(),
            title: title.into(),
            rows: vec![],
            json: Map::new(),
            load_before: load_average(),
        }
    }

    /// Adds a table row.
    pub fn row(&mut self, figure: &str, value: String, requirement: &str) {
        self.rows.push([figure.into(), value, requirement.into()]);
    }

    /// Adds a JSON field.
    pub fn field(&mut self, key: &str, value: Value) {
        self.json.insert(key.into(), value);
    }

    /// Writes `<bench>.json` and `<bench>.md` into `dir` (created) and
    /// returns their paths.
    pub fn write(mut self, dir: &Path) -> anyhow::Result<(PathBuf, PathBuf)> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let load_after = load_average();
        let command: Vec<String> = std::env::args().collect();
        let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
        self.json.insert("bench".into(), json!(self.bench));
        self.json.insert("command".into(), json!(command.join(" ")));
        self.json.insert("cores".into(), json!(cores));
        self.json
            .insert("load_before".into(), json!(self.load_before));
        self.json.insert("load_after".into(), json!(load_after));
        let json_path = dir.join(format!("{}.json", self.bench));
        let text = serde_json::to_string_pretty(&Value::Object(self.json.clone()))?;
        std::fs::write(&json_path, text + "\n")
            .with_context(|| format!("writing {}", json_path.display()))?;
        let md_path = dir.join(format!("{}.md", self.bench));
        let load = |l: Option<[f64; 3]>| {
            l.map_or("unknown".into(), |[a, b, c]| {
                format!("{a:.2} {b:.2} {c:.2}")
            })
        };
        let mut md = format!(
            "# Viewer benchmark `{}`\n\n{}\n\n`{}` — {cores} cores, load average (1, 5, 15 min) {} before, {} after.\n\n| figure | measured | requirement |\n|---|---|---|\n",
            self.bench,
            self.title,
            command.join(" "),
            load(self.load_before),
            load(load_after),
        );
        for [f, v, r] in &self.rows {
            md.push_str(&format!("| {f} | {v} | {r} |\n"));
        }
        std::fs::write(&md_path, md).with_context(|| format!("writing {}", md_path.display()))?;
        Ok((json_path, md_path))
    }
}

/// `met` or `NOT met` for a requirement `ok`.
pub fn verdict(ok: bool) -> &'static str {
    if ok { "met" } else { "NOT met" }
}
