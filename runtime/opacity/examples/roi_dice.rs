//! ROI map Dice against the labels of `phantom:abdomen`, for fixed λ and
//! for `lambda = "auto"`, seeds in the liver, the spleen and the right
//! kidney (CPU path). Writes a markdown table, a CSV and an SVG plot.
//!
//! ```sh
//! cargo run --release -p voxflex-opacity --example roi_dice -- [--dims 120,94,80] [--out docs] [--seed-radius 2] [--connectivity 6]
//! ```
//!
//! Output: `<out>/roi_dice_vs_lambda.md`, `<out>/roi_dice_vs_lambda.csv`,
//! `<out>/figures/roi_dice_vs_lambda.svg`; the table is also printed.

use std::fmt::Write as _;
use std::time::Instant;
use voxflex_opacity::auto_lambda::CANDIDATES;
use voxflex_opacity::{
    GrowthLimits, GrowthParams, LambdaChoice, OpacityMap, RoiRequest, Seed, grow_roi,
};
use voxflex_phantom::abdomen::{SEEDS, label, map_dice};
use voxflex_phantom::abdomen_labelled;

/// Label histogram of `map ≥ 0.5`, largest first (diagnostics).
fn covers(map: &OpacityMap, dims: [usize; 3], labels: &[u8]) -> String {
    let mut n = [0usize; 256];
    for (l, &q) in map.values.iter().enumerate() {
        if q >= 32768 {
            let v = map.voxel(l);
            n[labels[v[0] + dims[0] * (v[1] + dims[1] * v[2])] as usize] += 1;
        }
    }
    let mut v: Vec<(usize, usize)> = n.iter().copied().enumerate().filter(|x| x.1 > 0).collect();
    v.sort_by_key(|x| std::cmp::Reverse(x.1));
    v.iter()
        .take(6)
        .map(|&(l, c)| format!("{} {c}", label::NAMES.get(l).unwrap_or(&"?")))
        .collect::<Vec<_>>()
        .join(", ")
}

/// One seed's curve: name, `(λ, Dice)` points, and the automatic λ's point.
type Series = (&'static str, Vec<(f32, f64)>, (f32, f64));

/// A line plot of Dice against λ (log axis), one polyline per seed and a
/// marker at the automatic λ — plain SVG, no dependency.
fn svg(series: &[Series]) -> String {
    let (w, h, ml, mr, mt, mb) = (640.0, 400.0, 60.0, 130.0, 20.0, 50.0);
    let (l0, l1) = (0.0f64, 32f64.log2());
    let x = |l: f32| ml + (l as f64).log2().clamp(l0, l1) / (l1 - l0) * (w - ml - mr);
    let y = |d: f64| mt + (1.0 - d) * (h - mt - mb);
    let colours = ["#1b9e77", "#d95f02", "#7570b3"];
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(s, r#"<rect width="{w}" height="{h}" fill="white"/>"#);
    for t in 0..=5 {
        let d = t as f64 / 5.0;
        let _ = writeln!(
            s,
            r##"<line x1="{ml}" x2="{}" y1="{y}" y2="{y}" stroke="#ddd"/><text x="{}" y="{}" text-anchor="end">{d:.1}</text>"##,
            w - mr,
            ml - 6.0,
            y(d) + 4.0,
            y = y(d)
        );
    }
    for l in [1.0f32, 2.0, 4.0, 8.0, 16.0, 32.0] {
        let _ = writeln!(
            s,
            r##"<line x1="{x}" x2="{x}" y1="{mt}" y2="{}" stroke="#ddd"/><text x="{x}" y="{}" text-anchor="middle">{l}</text>"##,
            h - mb,
            h - mb + 16.0,
            x = x(l)
        );
    }
    let _ = writeln!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">λ (log scale)</text><text x="16" y="{}" transform="rotate(-90 16 {})" text-anchor="middle">Dice vs label</text>"#,
        (ml + w - mr) / 2.0,
        h - 12.0,
        (mt + h - mb) / 2.0,
        (mt + h - mb) / 2.0
    );
    for (n, (name, pts, auto)) in series.iter().enumerate() {
        let c = colours[n % colours.len()];
        let p: Vec<String> = pts
            .iter()
            .map(|&(l, d)| format!("{:.1},{:.1}", x(l), y(d)))
            .collect();
        let _ = writeln!(
            s,
            r#"<polyline fill="none" stroke="{c}" stroke-width="2" points="{}"/>"#,
            p.join(" ")
        );
        let _ = writeln!(
            s,
            r#"<circle cx="{:.1}" cy="{:.1}" r="6" fill="none" stroke="{c}" stroke-width="2"/>"#,
            x(auto.0),
            y(auto.1)
        );
        let ly = mt + 20.0 + 20.0 * n as f64;
        let _ = writeln!(
            s,
            r#"<line x1="{}" x2="{}" y1="{ly}" y2="{ly}" stroke="{c}" stroke-width="2"/><text x="{}" y="{}">{name}</text>"#,
            w - mr + 10.0,
            w - mr + 30.0,
            w - mr + 36.0,
            ly + 4.0
        );
    }
    let ly = mt + 20.0 + 20.0 * series.len() as f64;
    let _ = writeln!(
        s,
        r#"<circle cx="{}" cy="{ly}" r="6" fill="none" stroke="black"/><text x="{}" y="{}">auto λ</text>"#,
        w - mr + 20.0,
        w - mr + 36.0,
        ly + 4.0
    );
    s.push_str("</svg>\n");
    s
}

fn main() {
    let mut dims = [120usize, 94, 80];
    let mut out = std::path::PathBuf::from("docs");
    let mut params = GrowthParams::default();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--dims" => {
                let v: Vec<usize> = args[i + 1]
                    .split(',')
                    .map(|x| x.parse().expect("--dims nx,ny,nz"))
                    .collect();
                dims = [v[0], v[1], v[2]];
                i += 2;
            }
            "--out" => {
                out = args[i + 1].clone().into();
                i += 2;
            }
            "--connectivity" => {
                params.connectivity = args[i + 1].parse().expect("--connectivity 6|26");
                i += 2;
            }
            "--seed-radius" => {
                params.seed_radius = args[i + 1].parse().expect("--seed-radius N");
                i += 2;
            }
            a => panic!(
                "unknown argument {a}; use --dims nx,ny,nz, --out DIR, --seed-radius N, --connectivity 6|26"
            ),
        }
    }
    let t = Instant::now();
    let ph = abdomen_labelled(dims);
    let vol = ph.volume.view();
    eprintln!("phantom {dims:?} in {:.2?}", t.elapsed());
    let mut lambdas: Vec<f32> = CANDIDATES.to_vec();
    lambdas.push(30.0);
    lambdas.sort_by(f32::total_cmp);
    let mut csv = String::from("seed,lambda,voxels,dice,steps\n");
    let mut series = vec![];
    let mut md = String::from("| seed (label voxels) |");
    for l in &lambdas {
        let _ = write!(md, " λ={l:.3} |");
    }
    md += " auto: λ, Dice |\n|---|";
    for _ in &lambdas {
        md += "---|";
    }
    md += "---|\n";
    for (name, lab, p) in SEEDS {
        let seed = Seed::World(p);
        let mut pts = vec![];
        let _ = write!(md, "| {name} ({}) |", ph.count(lab));
        for &lambda in &lambdas {
            let req = RoiRequest {
                seed,
                params,
                lambda: LambdaChoice::Fixed(lambda),
                limits: GrowthLimits::default(),
                steps: None,
            };
            let t = Instant::now();
            let o = grow_roi(vol, &req, None).expect("grow");
            let d = map_dice(&o.grown.map, dims, &ph.labels, lab);
            if std::env::var_os("ROI_DICE_LABELS").is_some() {
                eprintln!("  covers: {}", covers(&o.grown.map, dims, &ph.labels));
            }
            eprintln!(
                "{name} λ={lambda:.3}: d_s {:.1} σ_s {:.1}, {} voxels, Dice {d:.3}, {} steps, {:.2?}",
                o.grown.stats.mean,
                o.grown.stats.sigma,
                o.voxels,
                o.grown.report.steps,
                t.elapsed()
            );
            let _ = writeln!(
                csv,
                "{name},{lambda},{},{d:.4},{}",
                o.voxels, o.grown.report.steps
            );
            let _ = write!(md, " {d:.3} |");
            if lambda != 30.0 {
                pts.push((lambda, d));
            }
        }
        let req = RoiRequest {
            seed,
            params,
            lambda: LambdaChoice::Auto,
            limits: GrowthLimits::default(),
            steps: None,
        };
        let t = Instant::now();
        let o = grow_roi(vol, &req, None).expect("grow auto");
        let d = map_dice(&o.grown.map, dims, &ph.labels, lab);
        let trials = o.auto.as_ref().map(|a| a.trials.len()).unwrap_or(0);
        eprintln!(
            "{name} auto: λ={} ({trials} trials), {} voxels, Dice {d:.3}, {:.2?}",
            o.lambda,
            o.voxels,
            t.elapsed()
        );
        let _ = writeln!(
            csv,
            "{name},auto={},{},{d:.4},{}",
            o.lambda, o.voxels, o.grown.report.steps
        );
        let _ = writeln!(md, " {:.3}, **{d:.3}** |", o.lambda);
        series.push((name, pts, (o.lambda, d)));
    }
    let _ = label::LIVER;
    println!("{md}");
    std::fs::create_dir_all(out.join("figures")).expect("create output dir");
    std::fs::write(out.join("roi_dice_vs_lambda.md"), &md).expect("write md");
    std::fs::write(out.join("roi_dice_vs_lambda.csv"), &csv).expect("write csv");
    std::fs::write(out.join("figures/roi_dice_vs_lambda.svg"), svg(&series)).expect("write svg");
    eprintln!(
        "wrote {}/roi_dice_vs_lambda.{{md,csv}} and figures/roi_dice_vs_lambda.svg",
        out.display()
    );
}
