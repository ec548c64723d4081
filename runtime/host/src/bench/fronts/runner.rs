//! Runs a deformation plugin, loaded from its shared library, through a
//! small scene the way the pipeline does — through a [`Session`] on the
//! CPU: `swap_model` with a params table (create, `init` on the volume),
//! the points whose displacement the front compares tracked
//! ([`Session::track_points`]), interactions at their frames, one
//! [`Session::step_model`] per frame (the model alone: nobody looks at a
//! resampled volume), then the tracked displacements. Dynamic models can
//! run on until they come to rest.

use super::super::{BenchError, err};
use crate::backend::BackendChoice;
use crate::pipeline::RunError;
use crate::session::{Interaction, Session, SessionDefaults};
use std::cell::RefCell;
use std::collections::HashSet;
use std::path::PathBuf;
use std::time::Instant;
use voxflex_core::deformation::ModelNotes;
use voxflex_core::glam::DVec3;
use voxflex_core::volume::Volume;

/// Where plugins are looked for.
pub(super) struct Plugins {
    /// Searched first, before `VOXFLEX_PLUGIN_PATH` and the executable's
    /// directory (the session's `plugin_dirs`).
    dirs: Vec<PathBuf>,
    /// Plugins already run once (the first run of each is a discarded
    /// warm-up: library loading, thread start-up, first allocations).
    warm: RefCell<HashSet<String>>,
}

impl Plugins {
    /// The CLI's plugin search path with `extra` searched first; no GPU.
    pub fn new(extra: &[PathBuf]) -> Self {
        Self {
            dirs: extra.to_vec(),
            warm: RefCell::new(HashSet::new()),
        }
    }
}

impl Plugins {
    /// The directories searched for a plugin library, in order.
    pub fn search_path(&self) -> Vec<PathBuf> {
        crate::plugin_loader::search_path(&self.dirs)
    }
}

/// Running on after the scripted frames until the bound points stop moving.
#[derive(Clone, Copy, Debug)]
pub(super) struct Settle {
    /// At most this many more frames.
    pub max_frames: u64,
    /// At rest when no bound point moved more than this over
    /// `check_every` frames, mm.
    pub tolerance_mm: f64,
    /// Frames between checks (each check maps the bound points).
    pub check_every: u64,
}

/// One run of a model.
pub(super) struct Scene<'a> {
    /// Plugin name (`corotational-fem`, `mass-spring`, `chainmail`).
    pub plugin: &'a str,
    /// The `[model.params]` table, TOML.
    pub params: String,
    /// The volume the model is built on.
    pub volume: &'a Volume,
    /// Bound points, world mm.
    pub points: &'a [[f32; 3]],
    /// Interactions (TOML tables without `frame`) and the frame each
    /// applies at.
    pub interactions: Vec<(u64, String)>,
    /// Scripted frames.
    pub frames: u64,
    /// Frame time step, s.
    pub dt_s: f64,
    /// Run on to rest (dynamic models), or not.
    pub settle: Option<Settle>,
}

/// What a run gave.
pub(super) struct Outcome {
    /// Displacement of each bound point, mm.
    pub u: Vec<DVec3>,
    /// Wall time from `swap_model` (the model's creation) to the last map
    /// of the bound points, ms.
    pub time_ms: f64,
    /// Frames stepped (scripted and settling).
    pub frames: u64,
    /// Came to rest within the settling cap (true without settling).
    pub settled: bool,
    /// The model's notes at the end.
    pub notes: ModelNotes,
}

/// Runs `scene` through its plugin (twice, the first discarded, when the
/// plugin has not run yet).
pub(super) fn run(plugins: &Plugins, scene: &Scene) -> Result<Outcome, BenchError> {
    if plugins.warm.borrow_mut().insert(scene.plugin.to_string()) {
        run_once(plugins, scene)?;
    }
    run_once(plugins, scene)
}

/// Steps the model alone one frame; true when it moved.
fn step(session: &mut Session) -> Result<bool, RunError> {
    let before = session.versions().model;
    session.step_model()?;
    Ok(session.versions().model != before)
}

fn run_once(plugins: &Plugins, scene: &Scene) -> Result<Outcome, BenchError> {
    let what = |e: RunError| {
        err(format!(
            "{} ({}): {e}",
            scene.plugin,
            scene.params.replace('\n', "; ")
        ))
    };
    let total = scene.frames + scene.settle.map_or(0, |s| s.max_frames);
    let mut session = Session::from_volume(
        scene.volume.clone(),
        SessionDefaults {
            backend: BackendChoice::Cpu,
            plugin_dirs: plugins.dirs.clone(),
            frames: total,
            dt_s: scene.dt_s,
            ..SessionDefaults::default()
        },
    )
    .map_err(what)?;
    let t = Instant::now();
    session
        .swap_model(scene.plugin, &scene.params)
        .map_err(what)?;
    let probes = session.track_points(scene.points).map_err(what)?;
    for frame in 0..scene.frames {
        for (_, i) in scene.interactions.iter().filter(|(f, _)| *f == frame) {
            session
                .interact(&Interaction::Toml(i.clone()))
                .map_err(what)?;
        }
        step(&mut session).map_err(what)?;
    }
    let mut u = session.tracked_displacements(probes).map_err(what)?;
    let (mut frame, mut settled) = (scene.frames, true);
    if let Some(s) = scene.settle {
        settled = false;
        while frame < total {
            let mut changed = false;
            for _ in 0..s.check_every.max(1) {
                changed |= step(&mut session).map_err(what)?;
                frame += 1;
            }
            let next = session.tracked_displacements(probes).map_err(what)?;
            let moved = u
                .iter()
                .zip(&next)
                .map(|(a, b)| (*a - *b).length())
                .fold(0.0, f64::max);
            u = next;
            if !changed || moved <= s.tolerance_mm {
                settled = true;
                break;
            }
        }
    }
    let time_ms = t.elapsed().as_secs_f64() * 1e3;
    let notes = session.model_notes().map_err(what)?;
    if u.iter().any(|d| !d.is_finite()) {
        return Err(err(format!(
            "{} ({}): a bound point's displacement is not finite",
            scene.plugin,
            scene.params.replace('\n', "; ")
        )));
    }
    Ok(Outcome {
        u,
        time_ms,
        frames: frame,
        settled,
        notes,
    })
}

/// A volume of `dims` voxels of `spacing` mm from the origin, every voxel
/// `value` (i16): the solid block a proxy or a ChainMail lattice is built
/// on (node / element at each voxel centre).
pub(super) fn block(dims: [usize; 3], spacing: f64, value: i16) -> Volume {
    let grid = voxflex_core::grid::Grid::new(dims, DVec3::splat(spacing), DVec3::ZERO);
    Volume::new(
        grid,
        voxflex_core::volume::VoxelData::I16(vec![value; dims.iter().product()]),
    )
    .expect("a block volume")
}

/// The voxel centres of `volume` (x fastest) whose world position passes
/// `keep`, as bound points.
pub(super) fn lattice_points(volume: &Volume, keep: impl Fn(DVec3) -> bool) -> Vec<[f32; 3]> {
    let g = &volume.grid;
    (0..g.len())
        .map(|l| {
            let [i, j, k] = g.unlinear(l);
            g.index_to_world(DVec3::new(i as f64, j as f64, k as f64))
        })
        .filter(|p| keep(*p))
        .map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect()
}

/// A note as a CSV cell (empty when the model does not report it).
pub(super) fn note(notes: &ModelNotes, key: &str) -> String {
    notes.get(key).map(|v| format!("{v}")).unwrap_or_default()
}
