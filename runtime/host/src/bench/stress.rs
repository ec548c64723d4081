//! `voxflex bench --stress`: a numerical stress run of every deformation
//! model through the real path (each plugin loaded from its shared library,
//! driven across the C ABI through a CPU [`Session`] like a scene's), on
//! randomized scenes.
//!
//! Per model, `--stress-scenes` scenes (default 200) of `--stress-frames`
//! frames (default 13), from a seeded RNG (`--seed`): a small u8 volume
//! (2–14 voxels a side, one axis 1 or 2 voxels in a quarter of the scenes:
//! degenerate slabs; spacing 0.3–5 mm) holding a soft and a hard material;
//! materials with Young's modulus log-uniform in 1 Pa … 1e12 Pa, Poisson
//! ratio in 0 … 0.499, density 10 … 1e5 kg/m³ (ChainMail: constraint 0 … 8,
//! elastic 0 … 1, rigid); the frame time step log-uniform in 1e-6 … 1 s;
//! a grab of up to 2× the body's size over 1–4 frames, a fixed slab in
//! most scenes, then repeated cuts, carves, releases and loads at random
//! frames; solver, integrator, proxy step and affine field drawn too.
//!
//! Outcomes counted per model:
//! - **frames run** (a frame: interactions, the session's model stage, then
//!   its map stage when due — every lattice point mapped and the removed
//!   tetrahedra asked; no resample);
//! - **warnings** (`tracing` warnings raised by the models);
//! - **refused**: a scene or interaction the model refused with a clear
//!   error (a creation, `init`, `bind` or `interact` error) — an OK outcome;
//! - **errors**: a `step`/`map`/`removed_tetrahedra` that stopped its scene
//!   with the model's error (the session's [`ModelCall`] names which) — an
//!   OK outcome (the scene stops there);
//! - **panics**: any call that panicked inside the plugin (caught at the
//!   C-ABI boundary) — must be 0;
//! - **silent non-finite**: a frame whose step *succeeded* but whose mapped
//!   displacements hold NaN or ∞ — must be 0;
//! - **worst growth**: the models expose no energy across the ABI, so the
//!   displacement norm stands in: `max |u|` over the lattice points (mm).
//!   Once the scene's last grab has stopped moving and the frame applies no
//!   interaction, growth is `max|u|(t) / max(max|u|(t−1), 1e-3 · body
//!   size)`; the worst over the model's frames is reported (1 = no growth;
//!   a dynamic model ringing after a grab shows somewhat above 1; a blow-up
//!   shows as orders of magnitude), with its scene number;
//! - **blow-ups**: a finite frame whose `max |u|` exceeds 100× (body size +
//!   grab length) — a silent blow-up, reported by scene number.

use super::{BenchError, BenchOptions, err};
use crate::backend::BackendChoice;
use crate::plugin_loader;
use crate::session::{Interaction, ModelCall, Session, SessionDefaults};
use std::fmt::Write as _;
use std::path::PathBuf;
use voxflex_core::glam::DVec3;
use voxflex_core::grid::Grid;
use voxflex_core::volume::{Volume, VoxelData};

/// The models stressed, in report order.
pub const MODELS: [&str; 4] = ["chainmail", "mass-spring", "corotational-fem", "affine"];

/// SplitMix64: small, seedable, good enough to draw scenes.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    /// Log-uniform in [lo, hi].
    fn log(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.unit()).exp()
    }
    fn int(&mut self, lo: usize, hi_inclusive: usize) -> usize {
        lo + (self.next() % (hi_inclusive - lo + 1) as u64) as usize
    }
    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
    fn point_in(&mut self, min: DVec3, max: DVec3) -> DVec3 {
        DVec3::new(
            self.range(min.x, max.x),
            self.range(min.y, max.y),
            self.range(min.z, max.z),
        )
    }
    fn direction(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

fn arr(v: DVec3) -> String {
    format!("[{:e}, {:e}, {:e}]", v.x, v.y, v.z)
}

/// One randomized scene.
struct StressScene {
    volume: Volume,
    params: String,
    dt_s: f64,
    /// `(frame, interaction TOML)`, in frame order.
    interactions: Vec<(u64, String)>,
    /// Frame from which no grab moves any more.
    quiet_from: u64,
    /// Body size (largest extent of the material, mm).
    size: f64,
    /// Length of the grab, mm.
    grab: f64,
}

fn scene(model: &str, rng: &mut Rng, frames: u64) -> StressScene {
    // The volume: a hard block inside a soft one, inside air.
    let mut dims = [rng.int(2, 14), rng.int(2, 14), rng.int(2, 14)];
    if rng.chance(0.25) {
        dims[rng.int(0, 2)] = rng.int(1, 2);
    }
    let spacing = DVec3::new(rng.log(0.3, 5.0), rng.log(0.3, 5.0), rng.log(0.3, 5.0));
    let grid = Grid::centred(dims, spacing);
    let lo = dims.map(|d| if d > 3 && rng.chance(0.5) { 1 } else { 0 });
    let hi = dims.map(|d| if d > 3 && rng.chance(0.5) { d - 1 } else { d });
    let hard = dims.map(|d| d / 2);
    let mut data = vec![0u8; grid.len()];
    for (l, v) in data.iter_mut().enumerate() {
        let [i, j, k] = grid.unlinear(l);
        let c = [i, j, k];
        if (0..3).all(|a| c[a] >= lo[a] && c[a] < hi[a]) {
            *v = if (0..3).all(|a| c[a] >= hard[a]) && rng.chance(0.9) {
                200
            } else {
                100
            };
        }
    }
    let idx = |c: [usize; 3]| DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
    let bmin = grid.index_to_world(idx(lo));
    let bmax = grid.index_to_world(idx(hi.map(|h| h - 1)));
    let size = (bmax - bmin).max_element().max(spacing.min_element());
    let volume = Volume::new(grid, VoxelData::U8(data)).expect("sized from the grid");

    let e = [rng.log(1.0, 1e12), rng.log(1.0, 1e12)];
    let nu = [rng.range(0.0, 0.499), rng.range(0.0, 0.499)];
    let rho = [rng.log(10.0, 1e5), rng.log(10.0, 1e5)];
    let step = rng.int(1, 3);
    let mesh_materials = format!(
        "materials = [\n  {{ name = \"soft\", range = [50, 150], youngs_modulus = {:e}, poisson_ratio = {:?}, density = {:e} }},\n  \
         {{ name = \"hard\", range = [150, 256], youngs_modulus = {:e}, poisson_ratio = {:?}, density = {:e} }},\n]\n\
         proxy = {{ kind = \"uniform\", step = {step} }}\n",
        e[0], nu[0], rho[0], e[1], nu[1], rho[1]
    );
    let params = match model {
        "chainmail" => {
            let c = [rng.range(0.0, 8.0), rng.range(0.0, 8.0)];
            let el = [rng.unit(), rng.unit()];
            format!(
                "materials = [\n  {{ name = \"soft\", range = [50, 150], constraint = {:?}, elastic = {:?} }},\n  \
                 {{ name = \"hard\", range = [150, 256], constraint = {:?}, elastic = {:?}{} }},\n]\n\
                 algorithm = \"{}\"\nschedule = \"{}\"\n",
                c[0],
                el[0],
                c[1],
                el[1],
                if rng.chance(0.3) {
                    ", rigid = true"
                } else {
                    ""
                },
                if rng.chance(0.2) {
                    "sequential"
                } else {
                    "parallel"
                },
                if rng.chance(0.5) {
                    "blocks"
                } else {
                    "frontier"
                },
            )
        }
        "mass-spring" => format!(
            "{mesh_materials}integrator = \"{}\"\nvolume_stiffness = {:?}\n",
            if rng.chance(0.5) {
                "explicit"
            } else {
                "implicit"
            },
            if rng.chance(0.5) { 0.0 } else { 1.0 }
        ),
        "corotational-fem" => format!(
            "{mesh_materials}solver = \"{}\"\nsubsteps = {}\n",
            if rng.chance(0.3) { "static" } else { "dynamic" },
            rng.int(1, 3)
        ),
        _ => {
            let field = ["twist", "bend", "affine"][rng.int(0, 2)];
            let mut p = format!(
                "field = \"{field}\"\naxis = \"{}\"\nramp_frames = {}\n",
                ["x", "y", "z"][rng.int(0, 2)],
                rng.int(1, 6)
            );
            if field == "affine" {
                let m: Vec<String> = (0..3)
                    .map(|r| {
                        let row: Vec<String> = (0..4)
                            .map(|c| {
                                let d = if r == c { 1.0 } else { 0.0 };
                                format!("{:e}", d + rng.range(-2.0, 2.0))
                            })
                            .collect();
                        format!("[{}]", row.join(", "))
                    })
                    .collect();
                let _ = writeln!(p, "matrix = [{}]", m.join(", "));
            } else {
                let _ = writeln!(p, "angle_deg = {:?}", rng.range(-720.0, 720.0));
                if field == "bend" {
                    let towards = if p.contains("axis = \"x\"") { "y" } else { "x" };
                    let _ = writeln!(p, "towards = \"{towards}\"");
                }
            }
            if rng.chance(0.3) {
                let _ = writeln!(
                    p,
                    "region = {{ centre = {}, radius = {:e} }}",
                    arr(rng.point_in(bmin, bmax)),
                    rng.range(0.1, 1.0) * size
                );
            }
            p
        }
    };

    // Interactions.
    let mut interactions = vec![];
    if rng.chance(0.7) {
        // Hold a slab at the body's low end along a random axis.
        let a = rng.int(0, 2);
        let (mut min, mut max) = (bmin - DVec3::splat(0.01), bmax + DVec3::splat(0.01));
        max[a] = bmin[a] + 0.01 + rng.range(0.0, 0.3) * (bmax[a] - bmin[a]);
        min[a] -= spacing[a];
        interactions.push((
            0,
            format!("kind = \"fix\"\nmin = {}\nmax = {}", arr(min), arr(max)),
        ));
    }
    let grab_len = rng.range(0.0, 2.0) * size;
    let grab_frames = rng.int(1, 4) as u64;
    let grab_at = rng.int(0, 1) as u64;
    interactions.push((
        grab_at,
        format!(
            "kind = \"grab\"\npoint = {}\nby = {}\nframes = {grab_frames}",
            arr(rng.point_in(bmin, bmax)),
            arr(rng.direction() * grab_len)
        ),
    ));
    let quiet_from = grab_at + grab_frames;
    for _ in 0..rng.int(0, 4) {
        let f = rng.int(1, frames.saturating_sub(1).max(1) as usize) as u64;
        let text = match rng.int(0, 3) {
            0 => {
                // A square through a random body point, in a random plane.
                let c = rng.point_in(bmin, bmax);
                let n = rng.direction();
                let u = n.any_orthonormal_vector();
                let v = n.cross(u);
                let r = size * rng.range(0.3, 2.0);
                let corners: Vec<String> = [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
                    .iter()
                    .map(|(a, b)| arr(c + (u * *a + v * *b) * r))
                    .collect();
                format!("kind = \"cut\"\npolygon = [{}]", corners.join(", "))
            }
            1 => format!(
                "kind = \"carve\"\ncentre = {}\nradius = {:e}",
                arr(rng.point_in(bmin, bmax)),
                rng.range(0.05, 0.7) * size
            ),
            2 => "kind = \"release\"".to_string(),
            _ => format!(
                "kind = \"load\"\nmin = {}\nmax = {}\ntraction = {}\nframes = {}",
                arr(bmin - DVec3::splat(0.01)),
                arr(bmax + DVec3::splat(0.01)),
                // Up to half the softer material's modulus: strains stay
                // moderate, so a huge displacement is the model's doing.
                arr(rng.direction() * rng.log(1e-6, 0.5) * e[0].min(e[1])),
                rng.int(1, 3)
            ),
        };
        interactions.push((f, text));
    }
    interactions.sort_by_key(|(f, _)| *f);
    let quiet_from = interactions
        .iter()
        .map(|(f, _)| f + 1)
        .max()
        .unwrap_or(0)
        .max(quiet_from);
    StressScene {
        volume,
        params,
        dt_s: rng.log(1e-6, 1.0),
        interactions,
        quiet_from,
        size,
        grab: grab_len,
    }
}

impl StressScene {
    /// The scene on one line, to reproduce a finding.
    fn describe(&self) -> String {
        let inter: Vec<String> = self
            .interactions
            .iter()
            .map(|(f, t)| format!("@{f} {}", t.replace('\n', " ")))
            .collect();
        format!(
            "dims {:?}, spacing {:?} mm, dt {:e} s, params: {} interactions: {}",
            self.volume.grid.dims,
            self.volume.grid.spacing.to_array(),
            self.dt_s,
            self.params.replace('\n', " "),
            inter.join("; ")
        )
    }
}

/// What the stress run counted for one model.
#[derive(Clone, Debug, Default)]
pub struct ModelTally {
    /// Scenes drawn.
    pub scenes: u64,
    /// Frames run (stepped and mapped).
    pub frames: u64,
    /// Warnings raised.
    pub warnings: u64,
    /// Creations, inits, binds and interactions refused with a clear error.
    pub refused: u64,
    /// Scenes stopped by a step or map error.
    pub errors: u64,
    /// Calls that panicked inside the plugin.
    pub panics: u64,
    /// Frames that succeeded with non-finite displacements.
    pub silent_non_finite: u64,
    /// Finite frames with `max |u|` beyond 100× (body size + grab).
    pub blow_ups: u64,
    /// Worst displacement growth between quiet frames, and its scene.
    pub worst_growth: (f64, u64),
    /// First message of each kind of failure, with its scene.
    pub examples: Vec<String>,
}

impl ModelTally {
    fn fail(
        &mut self,
        sc: &StressScene,
        scene: u64,
        what: &str,
        e: &dyn std::fmt::Display,
    ) -> bool {
        let m = e.to_string();
        let panic = m.contains("panicked");
        if panic {
            self.panics += 1;
            self.examples
                .push(format!("scene {scene} {what}: {m}; {}", sc.describe()));
        } else if self.examples.len() < 3 {
            self.examples.push(format!("scene {scene} {what}: {m}"));
        }
        panic
    }
}

fn run_scene(
    model: &str,
    dirs: &[PathBuf],
    sc: &StressScene,
    id: u64,
    frames: u64,
    t: &mut ModelTally,
) {
    let defaults = SessionDefaults {
        backend: BackendChoice::Cpu,
        plugin_dirs: dirs.to_vec(),
        frames,
        dt_s: sc.dt_s,
        ..SessionDefaults::default()
    };
    let mut s = match Session::from_volume(sc.volume.clone(), defaults) {
        Ok(s) => s,
        Err(e) => {
            t.refused += 1;
            t.fail(sc, id, "session", &e);
            return;
        }
    };
    // Create, init and the bind of the source lattice.
    if let Err(e) = s.swap_model(model, &sc.params) {
        t.refused += 1;
        t.fail(
            sc,
            id,
            e.model_call().map_or("swap_model", ModelCall::name),
            &e,
        );
        return;
    }
    let mut prev_max = 0.0f64;
    let floor = 1e-3 * sc.size;
    let blow_up = 100.0 * (sc.size + sc.grab);
    for frame in 0..frames {
        let mut interacted = false;
        for (_, text) in sc.interactions.iter().filter(|(f, _)| *f == frame) {
            interacted = true;
            if let Err(e) = s.interact(&Interaction::Toml(text.clone())) {
                t.refused += 1;
                t.fail(sc, id, "interact", &e);
            }
        }
        // The model stage, then the map stage when due: every lattice
        // point mapped and the removed tetrahedra asked, as the pipeline
        // does (no resample: the stress is the models').
        let field = s.step_model().and_then(|_| s.displacement_field());
        let [x, y, z] = match field {
            Ok(f) => f,
            Err(e) => {
                t.errors += 1;
                let call = e.model_call().map_or("session", ModelCall::name);
                t.fail(sc, id, &format!("frame {frame} {call}"), &e);
                return;
            }
        };
        t.frames += 1;
        let mut max = 0.0f64;
        let mut finite = true;
        for ((&ux, &uy), &uz) in x.iter().zip(&y).zip(&z) {
            let u = DVec3::new(ux as f64, uy as f64, uz as f64);
            if !u.is_finite() {
                finite = false;
                break;
            }
            max = max.max(u.length());
        }
        if !finite {
            t.silent_non_finite += 1;
            t.examples.push(format!(
                "scene {id} frame {frame}: non-finite displacement; {}",
                sc.describe()
            ));
            return;
        }
        if max > blow_up {
            t.blow_ups += 1;
            if t.examples.len() < 8 {
                t.examples.push(format!(
                    "scene {id} frame {frame}: max |u| {max:.3e} mm for a {:.3e} mm body; {}",
                    sc.size,
                    sc.describe()
                ));
            }
            // One report per scene.
            return;
        }
        if frame > sc.quiet_from && !interacted {
            let g = max / prev_max.max(floor);
            if g > t.worst_growth.0 {
                t.worst_growth = (g, id);
            }
        }
        prev_max = max;
    }
}

/// Runs the stress suite; returns the report and the tallies per model.
pub fn stress(
    args: &BenchOptions,
    models: &[&str],
) -> Result<(String, Vec<(String, ModelTally)>), BenchError> {
    let scenes = args.stress_scenes;
    let frames = args.stress_frames.max(1);
    let dirs = plugin_loader::search_path(&args.plugin_dirs);
    let mut out = String::new();
    let _ = writeln!(
        out,
        "voxflex bench --stress: seed {}, {scenes} scenes × {frames} frames per model, CPU",
        args.seed
    );
    let _ = writeln!(
        out,
        "{:<17} {:>6} {:>7} {:>8} {:>7} {:>6} {:>6} {:>9} {:>8} {:>13}",
        "model",
        "scenes",
        "frames",
        "warnings",
        "refused",
        "errors",
        "panics",
        "non-finite",
        "blow-ups",
        "worst growth"
    );
    let mut tallies = vec![];
    for &model in models {
        // Scenes are drawn per model from its place in MODELS, so a filtered
        // run draws the same scenes.
        let mi = MODELS
            .iter()
            .position(|m| *m == model)
            .unwrap_or(MODELS.len());
        // Found (and checked) once; each scene's session loads it by name.
        plugin_loader::load_by_name(model, &dirs).map_err(err)?;
        let mut t = ModelTally::default();
        let capture = crate::warnings::capture();
        for s in 0..scenes {
            let mut rng =
                Rng(args.seed ^ ((mi as u64) << 48) ^ s.wrapping_mul(0x2545_F491_4F6C_DD1D));
            let sc = scene(model, &mut rng, frames);
            t.scenes += 1;
            run_scene(model, &args.plugin_dirs, &sc, s, frames, &mut t);
        }
        // The capture keeps the first warnings and ends with a count of the
        // rest ("… and N more warnings not kept").
        let warnings = capture.finish();
        let more = warnings
            .last()
            .and_then(|w| w.strip_prefix("… and "))
            .and_then(|w| w.split(' ').next())
            .and_then(|n| n.parse::<u64>().ok());
        t.warnings = match more {
            Some(n) => warnings.len() as u64 - 1 + n,
            None => warnings.len() as u64,
        };
        let _ = writeln!(
            out,
            "{model:<17} {:>6} {:>7} {:>8} {:>7} {:>6} {:>6} {:>9} {:>8} {:>8.3} (#{})",
            t.scenes,
            t.frames,
            t.warnings,
            t.refused,
            t.errors,
            t.panics,
            t.silent_non_finite,
            t.blow_ups,
            t.worst_growth.0,
            t.worst_growth.1
        );
        tallies.push((model.to_string(), t));
    }
    for (model, t) in &tallies {
        for e in &t.examples {
            let _ = writeln!(out, "  {model}: {e}");
        }
    }
    Ok((out, tallies))
}

/// `voxflex bench --stress`: the report, and the JSON file when asked.
pub fn run(args: &BenchOptions) -> Result<String, BenchError> {
    let models: Vec<&str> = if args.stress_model.is_empty() {
        MODELS.to_vec()
    } else {
        for m in &args.stress_model {
            if !MODELS.contains(&m.as_str()) {
                return Err(err(format!(
                    "--stress-model {m}: unknown; use one of {}",
                    MODELS.join(", ")
                )));
            }
        }
        MODELS
            .into_iter()
            .filter(|m| args.stress_model.iter().any(|a| a == m))
            .collect()
    };
    let (out, tallies) = stress(args, &models)?;
    if let Some(p) = &args.json {
        let mut json = serde_json::Map::new();
        for (model, t) in &tallies {
            json.insert(
                model.clone(),
                serde_json::json!({
                    "scenes": t.scenes,
                    "frames": t.frames,
                    "warnings": t.warnings,
                    "refused": t.refused,
                    "errors": t.errors,
                    "panics": t.panics,
                    "silent_non_finite": t.silent_non_finite,
                    "blow_ups": t.blow_ups,
                    "worst_growth": t.worst_growth.0,
                    "worst_growth_scene": t.worst_growth.1,
                }),
            );
        }
        let text = serde_json::to_string_pretty(&json).map_err(err)?;
        voxflex_io::write_atomically(p, |w| w.write_all(text.as_bytes())).map_err(err)?;
    }
    let failed: u64 = tallies
        .iter()
        .map(|(_, t)| t.panics + t.silent_non_finite)
        .sum();
    if failed > 0 {
        // The table first, then the one-line error the CLI prints.
        print!("{out}");
        return Err(err(format!(
            "{failed} call(s) panicked or frame(s) went non-finite without an error (see the \
             table above)"
        )));
    }
    Ok(out)
}
