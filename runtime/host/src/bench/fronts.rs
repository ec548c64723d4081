//! `voxflex bench --fronts`: the run-time/error front of every model.
//!
//! Each front runs one reference problem at several resolutions and
//! tolerances through the real path (plugins loaded from their shared
//! libraries, CPU backend) and records, per configuration, the wall time
//! (ms) and the error against a reference (units per front). Written into
//! `--out` (default `docs/fronts/`): `<front>.csv` (one row per
//! configuration), `<front>.svg` (run time on x, error on y, log scales,
//! one series per model/configuration, the default configuration ringed),
//! and `front.md` (every front's table, its Pareto front and its knee).
//!
//! Fronts ([`cut`], [`fem`], [`grab`], [`resample`], [`roi`],
//! [`two_material`], [`render`]):
//! - `fem_cantilever`: corotational FEM tip deflection vs Timoshenko beam
//!   theory and vs the finest solve, proxy step × CG tolerance;
//! - `fem_elastica`: static Newton under large rotation vs the Euler
//!   elastica, PL²/EI = 3, 10, 30, proxy step;
//! - `grab`: corotational FEM, mass-spring and ChainMail on the same grab
//!   of a soft beam vs a fine FEM solve (displacement at the bound points);
//! - `cut`: ChainMail, mass-spring and corotational FEM on the same
//!   complete cut of a soft beam, one piece then grabbed, vs the analytic
//!   answer (the grabbed piece translates rigidly, the other stays still);
//! - `resample`: tetrahedral vs trilinear interpolation vs an f64
//!   reference under affine, twist and bend, several sizes;
//! - `roi`: ROI map 1 − Dice against the labelled abdomen, per λ;
//! - `two_material`: the grab with a stiff inclusion whose faces lie on no
//!   coarse proxy cell face, FEM P1/P2, mass-spring and ChainMail vs a
//!   converged fine P2 solve (material resolution);
//! - `render`: the `raycast` plugin's image error against a converged
//!   reference, per ray step and filter option (sampling, gradient, jitter).
//!
//! Per mesh model, a combined front ([`combined`]) over every front it
//! appears in: per configuration, its error and time ratios to each
//! front's best, geometric mean across fronts, and that front's knee.
//!
//! The knee ([`knee`]): among the Pareto-optimal points, the one farthest
//! from the chord between the fastest and the most accurate, in log–log
//! coordinates, per problem where a front holds several ([`Point::group`]:
//! a load, a field, a seed). `front.md` says for each whether the default
//! configuration is the knee, Pareto-optimal, or dominated.

mod beam;
mod combined;
mod cut;
mod fem;
mod grab;
mod plot;
mod render;
mod resample;
mod roi;
mod runner;
mod two_material;

use super::{BenchError, BenchOptions, err};
use std::fmt::Write as _;
use std::path::Path;

/// One measured configuration of a front.
#[derive(Clone, Debug)]
pub(crate) struct Point {
    /// The series (model / configuration family) it belongs to.
    pub series: String,
    /// What varies along the series (e.g. `step 4`).
    pub config: String,
    /// Wall time, ms.
    pub time_ms: f64,
    /// Error against the front's reference (the front's units).
    pub error: f64,
    /// The model's default configuration.
    pub is_default: bool,
    /// The problem it solves, when a front holds several (a load, a field,
    /// a seed): Pareto front and knee are taken per group.
    pub group: String,
    /// Further CSV columns (same keys for every point of a front).
    pub extra: Vec<(&'static str, String)>,
    /// Its place in its model's combined front ([`combined`]); `None` for
    /// the rows that do not enter one.
    pub tuning: Option<Tuning>,
}

/// A row's place in its model's combined front ([`combined`]): set on the
/// rows that run a mesh plugin with its defaults but for the knobs the
/// combined front compares (element and proxy step) — the default CG
/// tolerance, the default dynamic solver or integrator where a front
/// measures several (the FEM fronts that measure the static solve alone
/// tag it: static and dynamic reach the same rest).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Tuning {
    /// The plugin (`corotational-fem`, `mass-spring`).
    pub model: &'static str,
    /// The configuration, the same label in every front (`P1 step 4`).
    pub config: String,
}

impl Tuning {
    /// The tag of `model` at element `element` (a [`fem::ELEMENTS`] name;
    /// `P1` for the springs, which lie on the proxy's edges) and proxy
    /// step `step` (voxels).
    pub(crate) fn new(model: &'static str, element: &str, step: usize) -> Self {
        Self {
            model,
            config: format!("{element} step {step}"),
        }
    }
}

impl Point {
    /// The value of extra column `key` ("" when the point has none).
    fn extra_value(&self, key: &str) -> &str {
        self.extra
            .iter()
            .find(|(e, _)| *e == key)
            .map_or("", |(_, v)| v.as_str())
    }
}

/// One front: its points and how they were measured.
#[derive(Clone, Debug)]
pub(crate) struct Front {
    /// File stem (`<key>.csv`, `<key>.svg`).
    pub key: &'static str,
    /// Plot and section title.
    pub title: String,
    /// Error axis label, with units.
    pub error_label: String,
    /// Problem, reference and timing, one paragraph for `front.md`.
    pub description: String,
    /// The measured configurations.
    pub points: Vec<Point>,
}

/// The fronts by name, in run order.
pub(crate) const NAMES: [&str; 8] = [
    "fem_cantilever",
    "fem_elastica",
    "grab",
    "two_material",
    "cut",
    "resample",
    "roi",
    "render",
];

/// Runs the fronts and writes their files; returns a human-readable report.
pub(super) fn run(args: &BenchOptions) -> Result<String, BenchError> {
    for o in &args.only {
        if !NAMES.contains(&o.as_str()) {
            return Err(err(format!(
                "--only {o}: no such front; use one of {}",
                NAMES.join(", ")
            )));
        }
    }
    let wanted = |n: &str| args.only.is_empty() || args.only.iter().any(|o| o == n);
    let out = &args.out;
    std::fs::create_dir_all(out)
        .map_err(|e| err(format!("cannot create --out {}: {e}", out.display())))?;
    let plugins = runner::Plugins::new(&args.plugin_dirs);
    let mut fronts = vec![];
    let mut report = String::new();
    for name in NAMES.iter().filter(|n| wanted(n)) {
        tracing::info!("front {name}…");
        let t = std::time::Instant::now();
        let mut f = match *name {
            "fem_cantilever" => vec![fem::cantilever(&plugins, args.quick)?],
            "fem_elastica" => vec![fem::elastica(&plugins, args.quick)?],
            "grab" => vec![grab::front(&plugins, args.quick)?],
            "two_material" => vec![two_material::front(&plugins, args.quick)?],
            "cut" => vec![cut::front(&plugins, args.quick)?],
            "resample" => vec![resample::front(args.quick)?],
            "render" => vec![render::front(&plugins, args.quick)?],
            _ => vec![roi::front(args.quick)?],
        };
        for front in &f {
            check(front)?;
            write_front(out, front)?;
            let _ = writeln!(
                report,
                "{}: {} configurations in {:.1} s → {}/{}.{{csv,svg}}",
                front.key,
                front.points.len(),
                t.elapsed().as_secs_f64(),
                out.display(),
                front.key
            );
            for line in knee_summary(front).lines() {
                let _ = writeln!(report, "  {line}");
            }
        }
        fronts.append(&mut f);
    }
    let mut md = markdown(&fronts, args.quick);
    for c in combined::all(&fronts)? {
        write_csv_svg(out, &c.front, combined::TIME_LABEL)?;
        md.push_str(&c.markdown());
        for line in c.summary().lines() {
            let _ = writeln!(report, "{line}");
        }
    }
    write(&out.join("front.md"), &md)?;
    let _ = writeln!(report, "summary → {}/front.md", out.display());
    Ok(report)
}

/// Every error and time is finite and non-negative: a front never hides a
/// failed run.
fn check(front: &Front) -> Result<(), BenchError> {
    for p in &front.points {
        if !(p.error.is_finite() && p.error >= 0.0 && p.time_ms.is_finite()) {
            return Err(err(format!(
                "front {}: {} {} gave error {} after {} ms",
                front.key, p.series, p.config, p.error, p.time_ms
            )));
        }
    }
    Ok(())
}

fn write(path: &Path, text: &str) -> Result<(), BenchError> {
    voxflex_io::write_atomically(path, |w| w.write_all(text.as_bytes()))
        .map_err(|e| err(format!("writing {}: {e}", path.display())))
}

fn write_front(out: &Path, front: &Front) -> Result<(), BenchError> {
    write_csv_svg(out, front, "run time, ms")
}

/// `<key>.csv` and `<key>.svg` (time axis labelled `time_label`).
fn write_csv_svg(out: &Path, front: &Front, time_label: &str) -> Result<(), BenchError> {
    write(&out.join(format!("{}.csv", front.key)), &csv(front))?;
    let svg =
        plot::svg(front, time_label).map_err(|e| err(format!("plotting {}: {e}", front.key)))?;
    write(&out.join(format!("{}.svg", front.key)), &svg)
}

/// The extra column names of a front, in order of first appearance.
fn extra_keys(front: &Front) -> Vec<&'static str> {
    let mut keys: Vec<&'static str> = vec![];
    for p in &front.points {
        for (k, _) in &p.extra {
            if !keys.contains(k) {
                keys.push(k);
            }
        }
    }
    keys
}

fn csv(front: &Front) -> String {
    let keys = extra_keys(front);
    let mut s = String::from("series,config,time_ms,error,default");
    for k in &keys {
        let _ = write!(s, ",{k}");
    }
    s.push('\n');
    for p in &front.points {
        let _ = write!(
            s,
            "{},{},{:.4},{:.6e},{}",
            p.series, p.config, p.time_ms, p.error, p.is_default
        );
        for k in &keys {
            let _ = write!(s, ",{}", p.extra_value(k));
        }
        s.push('\n');
    }
    s
}

/// Indices of the Pareto-optimal points (no other point is both faster
/// and more accurate), fastest first.
pub(crate) fn pareto(points: &[Point]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len()).collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .time_ms
            .total_cmp(&points[b].time_ms)
            .then(points[a].error.total_cmp(&points[b].error))
    });
    let mut best = f64::INFINITY;
    let mut front = vec![];
    for i in idx {
        if points[i].error < best {
            best = points[i].error;
            front.push(i);
        }
    }
    front
}

/// Errors below this are drawn and ranked as this (an exact answer has no
/// logarithm).
pub(crate) const ERROR_FLOOR: f64 = 1e-12;

/// The Pareto points of `points` (fastest first), each with its distance
/// below the chord from the fastest to the most accurate one, in
/// log10(time), log10(error) normalised to the front's span (positive:
/// towards fast and accurate); 0 for each with fewer than three.
pub(crate) fn below_chord(points: &[Point]) -> Vec<(usize, f64)> {
    let front = pareto(points);
    if front.len() < 3 {
        return front.into_iter().map(|i| (i, 0.0)).collect();
    }
    let xy = |i: usize| {
        (
            points[i].time_ms.max(1e-6).log10(),
            points[i].error.max(ERROR_FLOOR).log10(),
        )
    };
    let (a, b) = (xy(front[0]), xy(*front.last().unwrap()));
    let (sx, sy) = ((b.0 - a.0).abs().max(1e-9), (b.1 - a.1).abs().max(1e-9));
    let n = |p: (f64, f64)| ((p.0 - a.0) / sx, (p.1 - a.1) / sy);
    let (bx, by) = n(b);
    let len = (bx * bx + by * by).sqrt().max(1e-12);
    front
        .into_iter()
        .map(|k| {
            let (x, y) = n(xy(k));
            (k, (by * x - bx * y) / len)
        })
        .collect()
}

/// How far (in the normalised log–log units of [`below_chord`]) a Pareto
/// point must lie below the chord to make a bend: the combined FEM front
/// measured 0.098 below the chord on a loaded machine and 0.012 *above*
/// it on a quiet one (docs/BENCHMARKS.md), so shallower bends are timing
/// noise, not a knee.
pub(crate) const KNEE_MARGIN: f64 = 0.05;

/// The knee of the Pareto front: the Pareto point farthest below the chord
/// from the fastest to the most accurate one ([`below_chord`]), when it
/// lies at least [`KNEE_MARGIN`] below it; `None` for a front without a
/// bend (fewer than three Pareto points, or all within the margin of the
/// chord: each step trades time for error at about the same rate, and
/// [`no_knee`] says which).
pub(crate) fn knee(points: &[Point]) -> Option<usize> {
    below_chord(points)
        .into_iter()
        .filter(|&(_, d)| d >= KNEE_MARGIN)
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// Why `points` have no [`knee`], in words for `front.md`: no points, too
/// few Pareto points, or a straight front (with its log–log slope: error ∝
/// time^−s).
pub(crate) fn no_knee(points: &[Point]) -> String {
    let front = pareto(points);
    if front.is_empty() {
        return "no points".into();
    }
    if front.len() < 3 {
        return format!(
            "no knee ({} Pareto point{}, a bend needs three)",
            front.len(),
            if front.len() == 1 { "" } else { "s" }
        );
    }
    let (a, b) = (&points[front[0]], &points[*front.last().unwrap()]);
    let slope = (a.error.max(ERROR_FLOOR) / b.error.max(ERROR_FLOOR)).log10()
        / (b.time_ms.max(1e-6) / a.time_ms.max(1e-6))
            .log10()
            .max(1e-9);
    format!(
        "no knee: no Pareto point lies {KNEE_MARGIN} of the span below the chord (a straight \
         front, error ∝ time^−{slope:.2} from {} {} to {} {})",
        a.series, a.config, b.series, b.config
    )
}

/// The groups of a front, in order of first appearance, each with the
/// indices of its points.
fn groups(front: &Front) -> Vec<(&str, Vec<usize>)> {
    let mut out: Vec<(&str, Vec<usize>)> = vec![];
    for (i, p) in front.points.iter().enumerate() {
        match out.iter_mut().find(|(g, _)| *g == p.group) {
            Some((_, v)) => v.push(i),
            None => out.push((&p.group, vec![i])),
        }
    }
    out
}

/// Whether each point is Pareto-optimal within its group.
fn on_front(front: &Front) -> Vec<bool> {
    let mut on = vec![false; front.points.len()];
    for (_, idx) in groups(front) {
        let pts: Vec<Point> = idx.iter().map(|&i| front.points[i].clone()).collect();
        for k in pareto(&pts) {
            on[idx[k]] = true;
        }
    }
    on
}

/// Per group, one line: the knee, and where the default configuration(s)
/// lie (the knee, on the Pareto front, or off it).
fn knee_summary(front: &Front) -> String {
    let mut lines = vec![];
    for (g, idx) in groups(front) {
        let pts: Vec<Point> = idx.iter().map(|&i| front.points[i].clone()).collect();
        let on = pareto(&pts);
        let k = knee(&pts);
        let mut s = if g.is_empty() {
            String::new()
        } else {
            format!("{g}: ")
        };
        match k {
            Some(k) => {
                let _ = write!(
                    s,
                    "knee {} {} ({:.3} ms, error {:.3e})",
                    pts[k].series, pts[k].config, pts[k].time_ms, pts[k].error
                );
            }
            None => s.push_str(&no_knee(&pts)),
        }
        for (i, p) in pts.iter().enumerate().filter(|(_, p)| p.is_default) {
            let _ = write!(
                s,
                "; default {} {} ({:.3} ms, error {:.3e}) is {}",
                p.series,
                p.config,
                p.time_ms,
                p.error,
                if Some(i) == k {
                    "the knee"
                } else if on.contains(&i) {
                    "on the Pareto front"
                } else {
                    "off the Pareto front"
                }
            );
        }
        lines.push(s);
    }
    lines.join("\n")
}

/// `front.md`: per front, its description, the knee line and the table.
fn markdown(fronts: &[Front], quick: bool) -> String {
    let mut s = String::from("# Run-time/error fronts\n\n");
    let _ = writeln!(
        s,
        "Written by `voxflex bench --fronts{}` ({} threads, CPU path, plugins loaded from their \
         shared libraries). Time: wall time of the configuration's whole run (ms). The default \
         configuration is ringed in each plot and marked **default** below; the knee is the \
         Pareto-optimal point farthest below the chord from the fastest to the most accurate \
         point (log–log), taken per problem where a front holds several (loads, fields, \
         seeds).\n",
        if quick { " --quick" } else { "" },
        rayon::current_num_threads()
    );
    for f in fronts {
        let _ = writeln!(s, "## {} (`{}`)\n", f.title, f.key);
        let _ = writeln!(s, "{}\n", f.description);
        let _ = writeln!(s, "![{}]({}.svg)\n", f.title, f.key);
        for line in knee_summary(f).lines() {
            let _ = writeln!(s, "- {line}");
        }
        s.push('\n');
        let keys = extra_keys(f);
        let on = on_front(f);
        let _ = write!(
            s,
            "| series | config | time ms | {} | Pareto |",
            f.error_label.replace('|', "\\|")
        );
        for k in &keys {
            let _ = write!(s, " {k} |");
        }
        s.push_str("\n|---|---|---|---|---|");
        for _ in &keys {
            s.push_str("---|");
        }
        s.push('\n');
        for (i, p) in f.points.iter().enumerate() {
            let d = if p.is_default { " **default**" } else { "" };
            let _ = write!(
                s,
                "| {}{d} | {} | {:.2} | {:.3e} | {} |",
                p.series,
                p.config,
                p.time_ms,
                p.error,
                if on[i] { "yes" } else { "" }
            );
            for k in &keys {
                let _ = write!(s, " {} |", p.extra_value(k));
            }
            s.push('\n');
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(t: f64, e: f64) -> Point {
        Point {
            series: "s".into(),
            config: format!("{t}"),
            time_ms: t,
            error: e,
            is_default: false,
            group: String::new(),
            extra: vec![],
            tuning: None,
        }
    }

    #[test]
    fn pareto_drops_dominated_points_and_the_knee_is_the_bend() {
        // An L-shaped front: error falls fast, then time grows for little.
        let pts = vec![
            p(1.0, 1.0),
            p(2.0, 0.01),
            p(3.0, 0.5), // dominated by (2, 0.01)
            p(100.0, 0.005),
            p(1000.0, 0.004),
        ];
        assert_eq!(pareto(&pts), vec![0, 1, 3, 4]);
        assert_eq!(knee(&pts), Some(1));
        // A straight front (equal log steps) has no bend: every point is
        // Pareto-optimal, none lies below the chord, and there is no knee.
        let pts = vec![p(1.0, 1.0), p(10.0, 0.1), p(100.0, 0.01)];
        assert_eq!(pareto(&pts).len(), 3);
        assert_eq!(knee(&pts), None);
        assert!(no_knee(&pts).contains("time^−1.00"), "{}", no_knee(&pts));
        // Nor does a bend within the timing noise make one: the middle
        // point 0.03 of the span below the chord (the span is 2 decades
        // each way, the chord's normal at 45°); at 0.08 it is the knee.
        let below = |d: f64| 10f64.powf(-1.0 - d * 2.0 * 2f64.sqrt());
        let pts = vec![p(1.0, 1.0), p(10.0, below(0.03)), p(100.0, 0.01)];
        assert!((below_chord(&pts)[1].1 - 0.03).abs() < 1e-12);
        assert_eq!(knee(&pts), None);
        let deep = vec![p(1.0, 1.0), p(10.0, below(0.08)), p(100.0, 0.01)];
        assert_eq!(knee(&deep), Some(1));
        // Too few points to bend.
        assert_eq!(knee(&pts[..2]), None);
        assert!(no_knee(&pts[..1]).contains("1 Pareto point,"));
        assert_eq!(no_knee(&[]), "no points");
    }
}
