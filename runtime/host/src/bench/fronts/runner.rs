//! Runs a deformation plugin, loaded from its shared library, through a
//! small scene the way the pipeline does: create with a params table,
//! `init` on a volume (CPU backend), `bind` the points whose displacement
//! the front compares, interactions at their frames, one `step` per frame,
//! then `map`. Dynamic models can run on until they come to rest.

use super::super::{BenchError, err};
use crate::plugin_loader;
use std::cell::RefCell;
use std::collections::HashSet;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;
use voxflex_abi::host_side::{DeformationProxy, HostServices};
use voxflex_core::deformation::{
    DeformationModel, DisplacementTarget, ExecutionBackend, FrameInfo, ModelNotes, RestPoints,
};
use voxflex_core::glam::DVec3;
use voxflex_core::volume::Volume;

/// Where plugins are looked for, and the host services they get.
pub(super) struct Plugins {
    dirs: Vec<PathBuf>,
    services: Arc<HostServices>,
    /// Plugins already run once (the first run of each is a discarded
    /// warm-up: library loading, thread start-up, first allocations).
    warm: RefCell<HashSet<String>>,
}

impl Plugins {
    /// The CLI's plugin search path with `extra` searched first; no GPU.
    pub fn new(extra: &[PathBuf]) -> Self {
        Self {
            dirs: plugin_loader::search_path(extra),
            services: HostServices::new(None, rayon::current_num_threads()),
            warm: RefCell::new(HashSet::new()),
        }
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
    /// Wall time from `create` to the last `map`, ms.
    pub time_ms: f64,
    /// Frames stepped (scripted and settling).
    pub frames: u64,
    /// Came to rest within the settling cap (true without settling).
    pub settled: bool,
    /// The model's notes at the end.
    pub notes: ModelNotes,
}

fn map(
    model: &mut DeformationProxy,
    binding: voxflex_core::deformation::BindingId,
    n: usize,
) -> Result<Vec<DVec3>, BenchError> {
    let (mut x, mut y, mut z) = (vec![0f32; n], vec![0f32; n], vec![0f32; n]);
    model
        .map(
            binding,
            DisplacementTarget::Cpu {
                x: &mut x,
                y: &mut y,
                z: &mut z,
            },
        )
        .map_err(err)?;
    Ok((0..n)
        .map(|i| DVec3::new(x[i] as f64, y[i] as f64, z[i] as f64))
        .collect())
}

/// Runs `scene` through its plugin (twice, the first discarded, when the
/// plugin has not run yet).
pub(super) fn run(plugins: &Plugins, scene: &Scene) -> Result<Outcome, BenchError> {
    if plugins.warm.borrow_mut().insert(scene.plugin.to_string()) {
        run_once(plugins, scene)?;
    }
    run_once(plugins, scene)
}

fn run_once(plugins: &Plugins, scene: &Scene) -> Result<Outcome, BenchError> {
    let plugin = plugin_loader::load_by_name(scene.plugin, &plugins.dirs).map_err(err)?;
    let vtable = plugin
        .deformation
        .ok_or_else(|| err(format!("{} is not a deformation plugin", scene.plugin)))?;
    let what = |e: voxflex_core::error::ModelError| {
        err(format!(
            "{} ({}): {e}",
            scene.plugin,
            scene.params.replace('\n', "; ")
        ))
    };
    let t = Instant::now();
    // SAFETY: a checked library that is never unloaded.
    let mut model = unsafe {
        DeformationProxy::create(
            &plugin.name,
            vtable,
            &scene.params,
            plugins.services.clone(),
        )
    }
    .map_err(what)?;
    model
        .init(scene.volume.view(), ExecutionBackend::Cpu)
        .map_err(what)?;
    let binding = model.bind(RestPoints::Points(scene.points)).map_err(what)?;
    let n = scene.points.len();
    let total = scene.frames + scene.settle.map_or(0, |s| s.max_frames);
    let info = |frame| FrameInfo {
        frame,
        frames: total,
        dt_s: scene.dt_s,
    };
    for frame in 0..scene.frames {
        for (_, i) in scene.interactions.iter().filter(|(f, _)| *f == frame) {
            model.interact(i).map_err(what)?;
        }
        model.step(info(frame)).map_err(what)?;
    }
    let mut u = map(&mut model, binding, n)?;
    let (mut frame, mut settled) = (scene.frames, true);
    if let Some(s) = scene.settle {
        settled = false;
        while frame < total {
            let mut changed = false;
            for _ in 0..s.check_every.max(1) {
                changed |= model.step(info(frame)).map_err(what)?.changed;
                frame += 1;
            }
            let next = map(&mut model, binding, n)?;
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
    let notes = model.notes().map_err(what)?;
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
