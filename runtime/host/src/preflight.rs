//! What `voxflex validate` checks: every error `run` gives about a scene
//! file, given first, without computing a frame.
//!
//! [`Scene::load`](crate::scene::Scene::load) already refuses bad keys and
//! values. On top of it this loads the plugins the scene names and creates
//! an instance of each with its parameter table — the ABI's `create`,
//! which parses and validates the parameters, **without** `init` (no
//! volume, no GPU) — so a typo in `[model.params]` or `[render.params]`,
//! ν = 0.6 or E < 0 is refused with the plugin's own message; it hands
//! every `[[interaction]]` to that uninitialised model, whose `interact` is
//! then a dry run (parse and validate, apply nothing: the
//! `DeformationModel::interact` contract), so a typo, an unknown kind or a
//! cut polygon without area is refused as `run` refuses it, located in its
//! own table — and a plugin with interactions of its own checks them with
//! its own parser; it loads the source (the same
//! [`load_source`] `run` uses: unknown phantom, unreadable or damaged
//! file, refused non-finite voxels); and it checks each `[[roi]]`'s growth
//! parameters and, when no model moves the volume, its seed (inside the
//! volume, inside its intensity window). Each `[[actuator]]`'s plugin is
//! created with its table and initialised on its geometry (the cavity
//! file or label surface, the cable's points).
//!
//! Each error reads as `run`'s, with the scene location in front where
//! `run` has none. Not checked (they need a frame or the volume in the
//! model): an interaction a model refuses by kind once running (ChainMail
//! has no `load`), a grab or fix that finds no element, parameters a model
//! checks against the volume in `init` (a ChainMail `crop` beyond it, a
//! mesh-file proxy), and, with a model, ROI seeds (the deformed grid they
//! are looked up in is only known after the run).

use crate::actuation::geometry::rest_geometry;
use crate::pipeline::{RunError, load_source};
use crate::plugin_loader;
use crate::scene::{Scene, SceneError, locate_in_array};
use crate::visualise::roi_request;
use voxflex_abi::actuator::ActuatorProxy;
use voxflex_abi::host_side::{DeformationProxy, HostServices};
use voxflex_abi::renderer::RendererProxy;
use voxflex_core::actuator::{ActuatorGeometry, ActuatorModel};
use voxflex_core::deformation::DeformationModel;
use voxflex_core::volume::Volume;
use voxflex_opacity::{LambdaChoice, OpacityError};

/// Checks `scene` as described in the module docs; returns the loaded
/// source volume. Every error names the scene file, and where `run`'s
/// message does not, the table it is about.
pub fn check(scene: &Scene) -> Result<Volume, RunError> {
    let dirs = plugin_loader::search_path(&scene.plugin_dirs());
    let services = HostServices::new(None, 1);
    if scene.model.is_some() {
        let table = model_table(scene);
        check_model(scene, &dirs, &services)
            .map_err(|e| at_table(scene, &[&table, "[model]"], e))?;
    }
    if scene.render.is_some() {
        check_renderer(scene, &dirs, &services)
            .map_err(|e| at_table(scene, &["[render.params]", "[render]"], e))?;
    }
    let source = load_source(scene).map_err(|e| at_table(scene, &["[volume]"], e))?;
    for n in 0..scene.actuators.len() {
        check_actuator(scene, n, &dirs, &services, &source).map_err(|e| {
            RunError::Scene(SceneError::Invalid {
                location: locate_in_array(&scene.text, &scene.path, "actuator", n, ""),
                message: format!("[[actuator]]: {e}"),
            })
        })?;
    }
    for (n, roi) in scene.rois.iter().enumerate() {
        let req = roi_request(roi);
        check_roi(&req, scene.model.is_none().then_some(&source)).map_err(|e| {
            RunError::Scene(SceneError::Invalid {
                location: locate_in_array(&scene.text, &scene.path, "roi", n, ""),
                message: format!("[[roi]]: {e}"),
            })
        })?;
    }
    Ok(source)
}

/// Actuator `n`: its plugin found and an actuator, its parameters accepted
/// (schema, then the plugin's `create`), its geometry loaded (the cavity
/// file or label) and accepted by the plugin's `init` (a closed, outward
/// cavity; a cable of distinct points).
fn check_actuator(
    scene: &Scene,
    n: usize,
    dirs: &[std::path::PathBuf],
    services: &std::sync::Arc<HostServices>,
    source: &Volume,
) -> Result<(), RunError> {
    let a = &scene.actuators[n];
    let p = plugin_loader::load_by_name(&a.plugin, dirs)?;
    let vtable = p.actuator.ok_or_else(|| {
        RunError::Other(format!(
            "plugin `{}` is a {} plugin, not an actuator",
            p.name,
            p.kind_name()
        ))
    })?;
    let params = a.params_toml();
    p.check_params(&params)?;
    let geometry = rest_geometry(a, &scene.base_dir(), source).map_err(RunError::Other)?;
    // SAFETY: the vtable comes from a checked, never-unloaded library.
    let mut actuator =
        unsafe { ActuatorProxy::create(&p.name, vtable, &params, services.clone()) }?;
    actuator.init(ActuatorGeometry {
        points: &geometry.points,
        triangles: &geometry.triangles,
        gravity_m_s2: voxflex_core::glam::DVec3::from_array(a.gravity_m_s2),
    })?;
    Ok(())
}

/// The model plugin: found, a deformation plugin, able to run on the
/// scene's backend, and accepting its parameters.
fn check_model(
    scene: &Scene,
    dirs: &[std::path::PathBuf],
    services: &std::sync::Arc<HostServices>,
) -> Result<(), RunError> {
    let Some(m) = &scene.model else {
        return Ok(());
    };
    let path = scene.path.display();
    let p = plugin_loader::load_by_name(&m.plugin, dirs)?;
    let vtable = p.deformation.ok_or_else(|| {
        RunError::Other(format!(
            "{path}: plugin `{}` is a {} plugin; [model] needs a deformation plugin",
            p.name,
            p.kind_name()
        ))
    })?;
    if scene.settings.backend == crate::backend::BackendChoice::Gpu
        && p.capabilities & voxflex_abi::ffi::CAPABILITY_GPU == 0
    {
        return Err(RunError::Other(format!(
            "{path}: backend = \"gpu\", but plugin `{}` has no GPU path; use backend = \"cpu\" or \"auto\"",
            p.name
        )));
    }
    p.check_params(&scene.model_params_toml())?;
    // SAFETY: the vtable comes from a checked, never-unloaded library.
    let mut model = unsafe {
        DeformationProxy::create(
            &p.name,
            vtable,
            &scene.model_params_toml(),
            services.clone(),
        )
    }?;
    // Before init, `interact` is a dry run: the model parses and validates
    // each interaction with its own parser and applies nothing.
    for i in &scene.interactions {
        model.interact(&i.toml).map_err(|e| {
            RunError::Scene(SceneError::Invalid {
                location: locate_in_array(&scene.text, &scene.path, "interaction", i.index, "kind"),
                message: e.0,
            })
        })?;
    }
    Ok(())
}

/// The renderer plugin: found, a renderer, and accepting its parameters.
fn check_renderer(
    scene: &Scene,
    dirs: &[std::path::PathBuf],
    services: &std::sync::Arc<HostServices>,
) -> Result<(), RunError> {
    let Some(r) = &scene.render else {
        return Ok(());
    };
    let p = plugin_loader::load_by_name(&r.plugin, dirs)?;
    let vtable = p.renderer.ok_or_else(|| {
        RunError::Other(format!(
            "{}: [render] plugin `{}` is a {} plugin, not a renderer",
            scene.path.display(),
            p.name,
            p.kind_name()
        ))
    })?;
    p.check_params(&scene.render_params_toml())?;
    // SAFETY: checked, never-unloaded library.
    unsafe {
        RendererProxy::create(
            &p.name,
            vtable,
            &scene.render_params_toml(),
            services.clone(),
        )
    }?;
    Ok(())
}

/// The growth parameters of one `[[roi]]`, and its seed and window on
/// `volume` when the map is grown on it.
fn check_roi(
    req: &voxflex_opacity::RoiRequest,
    volume: Option<&Volume>,
) -> Result<(), OpacityError> {
    req.params.validate()?;
    if let LambdaChoice::Fixed(lambda) = req.lambda {
        voxflex_opacity::GrowthParams {
            lambda,
            ..req.params
        }
        .validate()?;
    }
    req.limits.validate()?;
    let Some(v) = volume else {
        return Ok(());
    };
    let voxel = req.seed.resolve(&v.grid)?;
    let value = v
        .view()
        .data
        .get_f32(v.grid.linear(voxel[0], voxel[1], voxel[2]));
    if let Some([lo, hi]) = req.limits.intensity
        && !(lo <= value && value <= hi)
    {
        return Err(OpacityError::SeedOutsideWindow {
            voxel,
            value,
            lo,
            hi,
        });
    }
    Ok(())
}

/// The header of the model's parameter table: `[model.params.<plugin>]`
/// when the scene has one, else `[model.params]`.
fn model_table(scene: &Scene) -> String {
    match &scene.model {
        Some(m) if scene.text.contains(&format!("[model.params.{}]", m.plugin)) => {
            format!("[model.params.{}]", m.plugin)
        }
        _ => "[model.params]".into(),
    }
}

/// `file:line:column` of the first line that starts with the first of
/// `headers` the scene has, else the file.
fn locate_table(scene: &Scene, headers: &[&str]) -> String {
    let path = scene.path.display();
    headers
        .iter()
        .find_map(|h| {
            scene
                .text
                .lines()
                .enumerate()
                .find(|(_, l)| l.trim_start().starts_with(h))
        })
        .map(|(n, l)| format!("{path}:{}:{}", n + 1, l.len() - l.trim_start().len() + 1))
        .unwrap_or_else(|| path.to_string())
}

/// `e` as `run` words it, with the location of the first of `headers`
/// the scene has in front unless it already names the scene file.
fn at_table(scene: &Scene, headers: &[&str], e: RunError) -> RunError {
    let message = e.to_string();
    if message.starts_with(&scene.path.display().to_string()) {
        return e;
    }
    RunError::Scene(SceneError::Invalid {
        location: locate_table(scene, headers),
        message,
    })
}
