//! The combined front of a mesh model over every front it appears in: the
//! rule issue 12 sets its default proxy step by, one a reader can re-run.
//!
//! A front's rows enter their model's combined front through their
//! [`Tuning`] tag (the plugin at its defaults but for element and proxy
//! step). Within a front, a configuration's time and error are their
//! arithmetic means over the front's groups (loads, cut planes: variants
//! of one problem, in the front's units — the expected error over them, so
//! a variant one configuration happens to solve exactly counts as one
//! answer of several, not as decades); a configuration missing from one of
//! the groups is missing from the front. Its ratios are those means over
//! the front's best among the model's configurations there (the least
//! time, the least error). Across fronts, whose units differ, the ratios
//! combine by geometric mean. A configuration missing from a front is left
//! out, and the output names the fronts that lack it. The combined points
//! form a [`Front`] whose time is the combined time ratio and whose error
//! is the combined error ratio, so its Pareto front and knee are
//! `front.md`'s own ([`pareto`], [`knee`], [`below_chord`]).

use super::{ERROR_FLOOR, Front, Point, below_chord, knee, no_knee, pareto};
use crate::bench::BenchError;
use std::fmt::Write as _;

/// The time axis of a combined front.
pub(super) const TIME_LABEL: &str = "time / front's fastest (geometric mean over fronts)";

/// The error axis of a combined front.
const ERROR_LABEL: &str = "error / front's best (geometric mean over fronts)";

/// The models with a combined front: plugin, file key.
const MODELS: [(&str, &str); 2] = [
    ("corotational-fem", "combined_fem"),
    ("mass-spring", "combined_mass_spring"),
];

/// One model's combined front.
#[derive(Clone, Debug)]
pub(crate) struct Combined {
    /// The fronts combined (keys), in run order.
    pub fronts: Vec<&'static str>,
    /// The combined points: `time_ms` is the combined time ratio, `error`
    /// the combined error ratio (both dimensionless, ≥ 1 in every front).
    pub front: Front,
    /// The configurations left out, each with the fronts that lack it.
    pub left_out: Vec<(String, Vec<&'static str>)>,
}

/// One configuration of a model in one front: its time and error ratios
/// and whether the front rings it as the default.
#[derive(Clone, Debug)]
struct Ratio {
    config: String,
    time: f64,
    error: f64,
    is_default: bool,
}

/// The combined fronts of every model in [`MODELS`] that appears in
/// `fronts`.
pub(super) fn all(fronts: &[Front]) -> Result<Vec<Combined>, BenchError> {
    let mut out = vec![];
    for (model, key) in MODELS {
        if let Some(c) = combine(model, key, fronts)? {
            out.push(c);
        }
    }
    Ok(out)
}

/// `model`'s configurations in `front` with their ratios (in order of
/// first appearance), or `None` when no row of `front` is the model's.
fn ratios(front: &Front, model: &str) -> Result<Option<Vec<Ratio>>, BenchError> {
    let rows: Vec<(&Point, &str)> = front
        .points
        .iter()
        .filter_map(|p| {
            p.tuning
                .as_ref()
                .filter(|t| t.model == model)
                .map(|t| (p, t.config.as_str()))
        })
        .collect();
    if rows.is_empty() {
        return Ok(None);
    }
    let mut groups: Vec<&str> = vec![];
    let mut configs: Vec<&str> = vec![];
    for (p, c) in &rows {
        if !groups.contains(&p.group.as_str()) {
            groups.push(&p.group);
        }
        if !configs.contains(c) {
            configs.push(c);
        }
    }
    let mut out = vec![];
    for config in configs {
        let of: Vec<&Point> = rows
            .iter()
            .filter(|(_, c)| *c == config)
            .map(|(p, _)| *p)
            .collect();
        for g in &groups {
            if of.iter().filter(|p| p.group == *g).count() > 1 {
                return Err(BenchError(format!(
                    "front {}: two rows of {model} tag {config} in group '{g}'; tag one \
                     (the plugin's default solver and tolerance)",
                    front.key
                )));
            }
        }
        if of.len() < groups.len() {
            continue;
        }
        let n = of.len() as f64;
        out.push(Ratio {
            config: config.to_string(),
            time: of.iter().map(|p| p.time_ms).sum::<f64>() / n,
            error: of.iter().map(|p| p.error).sum::<f64>() / n,
            is_default: of.iter().any(|p| p.is_default),
        });
    }
    let best_time = out.iter().map(|r| r.time).fold(f64::INFINITY, f64::min);
    let best_error = out.iter().map(|r| r.error).fold(f64::INFINITY, f64::min);
    for r in &mut out {
        r.time = r.time.max(1e-6) / best_time.max(1e-6);
        r.error = r.error.max(ERROR_FLOOR) / best_error.max(ERROR_FLOOR);
    }
    Ok(Some(out))
}

/// The geometric mean of `v`.
fn geometric_mean(v: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x.ln(), n + 1));
    (sum / n.max(1) as f64).exp()
}

/// `model`'s combined front over `fronts` (file stem `key`), or `None`
/// when no front holds its rows.
pub(crate) fn combine(
    model: &'static str,
    key: &'static str,
    fronts: &[Front],
) -> Result<Option<Combined>, BenchError> {
    let mut per: Vec<(&'static str, Vec<Ratio>)> = vec![];
    for f in fronts {
        if let Some(r) = ratios(f, model)? {
            per.push((f.key, r));
        }
    }
    if per.is_empty() {
        return Ok(None);
    }
    let mut configs: Vec<&str> = vec![];
    for (_, rs) in &per {
        for r in rs {
            if !configs.contains(&r.config.as_str()) {
                configs.push(&r.config);
            }
        }
    }
    let mut points = vec![];
    let mut left_out = vec![];
    for config in configs {
        let found: Vec<(&'static str, Option<&Ratio>)> = per
            .iter()
            .map(|(k, rs)| (*k, rs.iter().find(|r| r.config == config)))
            .collect();
        let missing: Vec<&'static str> = found
            .iter()
            .filter(|(_, r)| r.is_none())
            .map(|(k, _)| *k)
            .collect();
        if !missing.is_empty() {
            left_out.push((config.to_string(), missing));
            continue;
        }
        let rs: Vec<(&'static str, &Ratio)> = found
            .into_iter()
            .filter_map(|(k, r)| Some((k, r?)))
            .collect();
        let by_front = rs
            .iter()
            .map(|(k, r)| format!("{k} ×{:.3} ×{:.3}", r.time, r.error))
            .collect::<Vec<_>>()
            .join("; ");
        points.push(Point {
            series: model.to_string(),
            config: config.to_string(),
            time_ms: geometric_mean(rs.iter().map(|(_, r)| r.time)),
            error: geometric_mean(rs.iter().map(|(_, r)| r.error)),
            is_default: rs.iter().any(|(_, r)| r.is_default),
            group: String::new(),
            extra: vec![
                ("below_chord", String::new()),
                ("time_error_by_front", by_front),
            ],
            tuning: None,
        });
    }
    for (i, d) in below_chord(&points) {
        points[i].extra[0].1 = format!("{d:.4}");
    }
    let fronts: Vec<&'static str> = per.iter().map(|(k, _)| *k).collect();
    let description = format!(
        "The configurations of `{model}` at its defaults but for element and proxy step (the \
         rows each front tags: default CG tolerance, default dynamic solver or integrator where \
         a front measures several), combined over the fronts run that hold them: {}. Per front, \
         a configuration's time and error are their means over the front's groups (loads, cut \
         planes), divided by the least time and the least error among `{model}`'s \
         configurations there; across fronts the ratios combine by geometric mean. A \
         configuration missing from a front (or from one of its groups) is left out. Pareto \
         front and knee as in every front above. `time_error_by_front`: each front's time and \
         error ratio.",
        fronts.join(", ")
    );
    Ok(Some(Combined {
        fronts,
        front: Front {
            key,
            title: format!("{model}: combined over its fronts"),
            error_label: ERROR_LABEL.into(),
            description,
            points,
        },
        left_out,
    }))
}

impl Combined {
    /// The knee and where the default lies, one line; then the
    /// configurations left out, one line.
    pub(super) fn summary(&self) -> String {
        let pts = &self.front.points;
        let on = pareto(pts);
        let k = knee(pts);
        let at = |p: &Point| {
            format!(
                "{} (time ×{:.3}, error ×{:.3})",
                p.config, p.time_ms, p.error
            )
        };
        let mut s = format!(
            "{} combined over {}: ",
            self.front.key,
            self.fronts.join(", ")
        );
        match k {
            Some(k) => {
                let _ = write!(s, "knee {}", at(&pts[k]));
            }
            None if pts.is_empty() => s.push_str("no configuration in every front"),
            None => s.push_str(&no_knee(pts)),
        }
        for (i, p) in pts.iter().enumerate().filter(|(_, p)| p.is_default) {
            let place = if Some(i) == k {
                "the knee"
            } else if on.contains(&i) {
                "on the Pareto front"
            } else {
                "off the Pareto front"
            };
            let _ = write!(s, "; default {} is {place}", at(p));
        }
        if !self.left_out.is_empty() {
            let _ = write!(s, "\nleft out (not in every front): ");
            let parts: Vec<String> = self
                .left_out
                .iter()
                .map(|(c, m)| format!("{c} (not in {})", m.join(", ")))
                .collect();
            s.push_str(&parts.join("; "));
        }
        s
    }

    /// The `front.md` section: description, plot, summary and table.
    pub(super) fn markdown(&self) -> String {
        let f = &self.front;
        let mut s = format!("## {} (`{}`)\n\n{}\n\n", f.title, f.key, f.description);
        let _ = writeln!(s, "![{}]({}.svg)\n", f.title, f.key);
        for line in self.summary().lines() {
            let _ = writeln!(s, "- {line}");
        }
        s.push_str(
            "\n| config | time ratio | error ratio | Pareto | below chord | time, error ratio by \
             front |\n|---|---|---|---|---|---|\n",
        );
        let on = pareto(&f.points);
        for (i, p) in f.points.iter().enumerate() {
            let d = if p.is_default { " **default**" } else { "" };
            let _ = writeln!(
                s,
                "| {}{d} | {:.3} | {:.3} | {} | {} | {} |",
                p.config,
                p.time_ms,
                p.error,
                if on.contains(&i) { "yes" } else { "" },
                p.extra[0].1,
                p.extra[1].1
            );
        }
        s.push('\n');
        s
    }
}

#[cfg(test)]
mod tests {
    use super::super::Tuning;
    use super::*;

    fn row(model: &'static str, step: usize, group: &str, t: f64, e: f64) -> Point {
        Point {
            series: model.into(),
            config: format!("step {step}"),
            time_ms: t,
            error: e,
            is_default: step == 4,
            group: group.into(),
            extra: vec![],
            tuning: Some(Tuning::new(model, "P1", step)),
        }
    }

    fn front(key: &'static str, points: Vec<Point>) -> Front {
        Front {
            key,
            title: key.into(),
            error_label: "e".into(),
            description: String::new(),
            points,
        }
    }

    /// Two fronts whose ratios are known: `a` (one problem) measures steps
    /// 8, 4, 2, 1 and an untagged row; `b` (two groups) measures 8, 4, 2,
    /// its step 2 exact in one group.
    fn fronts() -> Vec<Front> {
        let mut other = row("m", 4, "", 0.5, 1e-6);
        other.tuning = None;
        let a = front(
            "a",
            vec![
                row("m", 8, "", 1.0, 1.0),
                row("m", 4, "", 2.0, 0.1),
                row("m", 2, "", 100.0, 0.05),
                row("m", 1, "", 1000.0, 0.04),
                other,
            ],
        );
        let b = front(
            "b",
            vec![
                row("m", 8, "g1", 10.0, 1000.0),
                row("m", 8, "g2", 30.0, 3000.0),
                row("m", 4, "g1", 30.0, 100.0),
                row("m", 4, "g2", 50.0, 300.0),
                row("m", 2, "g1", 1000.0, 0.0),
                row("m", 2, "g2", 3000.0, 200.0),
            ],
        );
        vec![a, b]
    }

    #[test]
    fn ratios_combine_by_geometric_mean_and_a_config_missing_from_a_front_is_left_out() {
        let c = combine("m", "combined_m", &fronts()).unwrap().unwrap();
        assert_eq!(c.fronts, vec!["a", "b"]);
        // Step 1 is only in `a`: left out, and said so.
        assert_eq!(c.left_out, vec![("P1 step 1".to_string(), vec!["b"])]);
        assert!(c.summary().contains("P1 step 1 (not in b)"));
        let got: Vec<(&str, f64, f64)> = c
            .front
            .points
            .iter()
            .map(|p| (p.config.as_str(), p.time_ms, p.error))
            .collect();
        // a: times ×1, 2, 100; errors over a's best (0.04, step 1's):
        // ×25, 2.5, 1.25. b, means over its groups: times 20, 40, 2000
        // (×1, 2, 100), errors 2000, 200, 100 (×20, 2, 1: step 2's exact
        // group counts as one answer of two).
        let want = [
            ("P1 step 8", 1.0, (25.0f64 * 20.0).sqrt()),
            ("P1 step 4", 2.0, (2.5f64 * 2.0).sqrt()),
            ("P1 step 2", 100.0, 1.25f64.sqrt()),
        ];
        assert_eq!(got.len(), want.len());
        for ((c, t, e), (wc, wt, we)) in got.iter().zip(want) {
            assert_eq!(*c, wc);
            assert!((t - wt).abs() < 1e-9 * wt, "{c}: time {t} against {wt}");
            assert!((e - we).abs() < 1e-9 * we, "{c}: error {e} against {we}");
        }
        // The knee is the bend, found by the fronts' own rule, and the
        // default (step 4 in both fronts) is it.
        let k = knee(&c.front.points).unwrap();
        assert_eq!(c.front.points[k].config, "P1 step 4");
        assert!(c.front.points[k].is_default);
        assert!(
            c.summary()
                .contains("default P1 step 4 (time ×2.000, error ×2.236) is the knee")
        );
        // The untagged row and another model's are not combined.
        assert!(combine("other", "x", &fronts()).unwrap().is_none());
    }

    #[test]
    fn two_rows_tagging_one_configuration_in_one_group_are_an_error() {
        let mut f = fronts();
        let dup = f[0].points[1].clone();
        f[0].points.push(dup);
        let e = combine("m", "combined_m", &f).unwrap_err();
        assert!(e.0.contains("two rows of m tag P1 step 4"), "{}", e.0);
    }

    #[test]
    fn a_config_missing_from_one_group_is_missing_from_its_front() {
        let mut f = fronts();
        f[1].points
            .retain(|p| !(p.group == "g2" && p.config == "step 8"));
        let c = combine("m", "combined_m", &f).unwrap().unwrap();
        assert!(
            c.left_out
                .iter()
                .any(|(c, m)| c == "P1 step 8" && m == &vec!["b"])
        );
        assert_eq!(c.front.points.len(), 2);
    }
}
