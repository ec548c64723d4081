//! Opening what the command line names: a scene, a volume file, or (with
//! nothing) the built-in head phantom scene.

use anyhow::Context;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use voxflex_core::camera::Camera;
use voxflex_io::ObliquePlacement;
use voxflex_runtime::backend::BackendChoice;
use voxflex_runtime::gpu_context::WgpuService;
use voxflex_runtime::param_schema::ParamSchema;
use voxflex_runtime::scene::Scene;
use voxflex_runtime::session::{
    Interaction, RenderParams, Session, SessionDefaults, SessionSource,
};
use voxflex_runtime::visualise::camera_for;

/// The scene opened without an argument: the head phantom (4 mm voxels)
/// with ChainMail, and the parameters of every deformation plugin for it.
pub const BUILT_IN_SCENE: &str = include_str!("../../../configs/chainmail-head.toml");

/// What to open and how.
#[derive(Clone, Debug, Default)]
pub struct OpenRequest {
    /// A scene (`.toml`) or a volume file; `None`: the built-in phantom.
    pub input: Option<PathBuf>,
    /// Backend the session computes on.
    pub backend: BackendChoice,
    /// Directories searched for plugins before the usual search path.
    pub plugin_dirs: Vec<PathBuf>,
    /// The UI's wgpu device as a GPU service, for the session to compute
    /// on (see [`crate::gpu_image`]); `None`: it opens its own.
    pub gpu: Option<Arc<WgpuService>>,
    /// What an oblique volume file becomes (a scene's own `[volume]
    /// oblique` applies to scenes).
    pub oblique: ObliquePlacement,
}

/// A session and the scene that gives the plugins their parameters.
pub struct OpenedSession {
    /// The session.
    pub session: Session,
    /// The scene opened (the built-in one for a volume file or nothing).
    pub scene: Scene,
    /// A title for the window.
    pub title: String,
    /// True when `scene` is what was opened (its `[render]` table then
    /// sets the 3D view), false for a volume file.
    pub scene_opened: bool,
}

fn is_scene(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("toml"))
}

fn built_in_scene() -> anyhow::Result<Scene> {
    Scene::parse(BUILT_IN_SCENE, Path::new("configs/chainmail-head.toml"))
        .context("the built-in head phantom scene")
}

/// The scene's frame-0 `fix` interactions, handed to the model: they are
/// part of the model's set-up (the skull held still), not of the scripted
/// motion a `voxflex run` replays, which the viewer's user drives instead.
/// Returns how many were applied.
fn apply_scene_constraints(session: &mut Session, scene: &Scene) -> anyhow::Result<usize> {
    let mut applied = 0;
    for i in scene.interactions.iter().filter(|i| i.frame == 0) {
        let kind = i
            .toml
            .parse::<toml::Table>()
            .ok()
            .and_then(|t| t.get("kind").and_then(|k| k.as_str()).map(str::to_owned));
        if kind.as_deref() == Some("fix") {
            session
                .interact(&Interaction::Toml(i.toml.clone()))
                .with_context(|| {
                    format!("applying the scene's [[interaction]] {} (fix)", i.index)
                })?;
            applied += 1;
        }
    }
    Ok(applied)
}

/// Opens `req`: a scene with its model, a volume file with no model yet
/// (the built-in scene's parameters serve its plugin choices), or the
/// built-in head phantom scene.
pub fn open(req: &OpenRequest) -> anyhow::Result<OpenedSession> {
    match &req.input {
        Some(path) if !is_scene(path) => {
            let defaults = SessionDefaults {
                backend: req.backend,
                plugin_dirs: req.plugin_dirs.clone(),
                background: None,
                gpu: req.gpu.clone(),
                read: voxflex_io::ReadOptions {
                    oblique: req.oblique,
                    ..Default::default()
                },
                ..SessionDefaults::default()
            };
            let session = Session::from_volume(SessionSource::File(path.clone()), defaults)
                .with_context(|| format!("opening volume {}", path.display()))?;
            Ok(OpenedSession {
                session,
                scene: built_in_scene()?,
                title: path.display().to_string(),
                scene_opened: false,
            })
        }
        input => {
            let (mut scene, title) = match input {
                Some(path) => (
                    Scene::load(path).with_context(|| format!("opening {}", path.display()))?,
                    path.display().to_string(),
                ),
                None => (built_in_scene()?, "built-in head phantom".into()),
            };
            scene.settings.backend = req.backend;
            scene
                .settings
                .plugin_dirs
                .splice(0..0, req.plugin_dirs.iter().cloned());
            let mut session = Session::open_on(&scene, req.gpu.clone())
                .with_context(|| format!("opening {title}"))?;
            apply_scene_constraints(&mut session, &scene)
                .with_context(|| format!("opening {title}"))?;
            Ok(OpenedSession {
                session,
                scene,
                title,
                scene_opened: true,
            })
        }
    }
}

/// The renderer and its parameters for the 3D view: the scene's
/// `[render]` table when a scene was opened and has one, else the
/// `raycast` plugin's defaults.
pub fn render_params(opened: &OpenedSession) -> RenderParams {
    match &opened.scene.render {
        Some(r) if opened.scene_opened => RenderParams {
            plugin: r.plugin.clone(),
            params_toml: opened.scene.render_params_toml(),
        },
        _ => RenderParams::default(),
    }
}

/// The 3D view's first camera: the scene's `[render]` camera when a scene
/// was opened and has one, else the session's default view of the volume.
pub fn first_camera(opened: &mut OpenedSession) -> anyhow::Result<Camera> {
    let grid = opened.session.volume()?.grid;
    Ok(match &opened.scene.render {
        Some(r) if opened.scene_opened => camera_for(r, &grid, 0.0),
        _ => opened.session.default_camera(512, 512)?,
    })
}

/// The deformation plugins the session's search path holds, each with the
/// parameters `scene` gives it (empty when it gives none).
pub fn deformation_models(session: &Session, scene: &Scene) -> Vec<(String, String)> {
    session
        .plugins()
        .plugins
        .into_iter()
        .filter(|p| p.loads && p.plugin.deformation.is_some())
        .map(|p| {
            let params = scene
                .model_params_toml_for(&p.plugin.name)
                .unwrap_or_default();
            (p.plugin.name, params)
        })
        .collect()
}

/// Each deformation plugin's parameter schema on the session's search path.
pub fn deformation_schemas(session: &Session) -> Vec<(String, ParamSchema)> {
    session
        .plugins()
        .plugins
        .into_iter()
        .filter(|p| p.loads && p.plugin.deformation.is_some())
        .map(|p| (p.plugin.name, p.plugin.params))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A volume file opened directly takes the viewer's `--oblique`: an
    /// oblique header stays on its own voxels by default and is resampled
    /// onto the grid that holds it with `linear`.
    #[test]
    fn an_oblique_file_opens_as_the_oblique_option_says() {
        let tmp = tempfile::tempdir().unwrap();
        voxflex_integration_tests::write_oblique_nrrd(tmp.path());
        for (oblique, dims) in [
            (ObliquePlacement::ClosestAxes, [6, 5, 4]),
            (ObliquePlacement::Linear, [8, 7, 4]),
        ] {
            let req = OpenRequest {
                input: Some(tmp.path().join("oblique.nrrd")),
                backend: BackendChoice::Cpu,
                plugin_dirs: vec![],
                gpu: None,
                oblique,
            };
            let opened = open(&req).unwrap();
            assert_eq!(opened.session.source().grid.dims, dims, "{oblique}");
        }
    }

    /// The built-in head scene holds its skull still (a frame-0 `fix` on
    /// bone) and pulls the scalp (a scripted grab): the viewer applies
    /// the first, leaves the second to the user.
    #[test]
    fn a_scene_opens_with_its_frame_zero_fixes_and_without_its_script() {
        let req = OpenRequest {
            input: None,
            backend: BackendChoice::Cpu,
            plugin_dirs: vec![voxflex_integration_tests::plugin_dir(&["chainmail"])],
            gpu: None,
            oblique: Default::default(),
        };
        let opened = open(&req).unwrap();
        let applied = opened.session.interactions_so_far();
        let kinds: Vec<&str> = applied.iter().map(|a| a.toml.as_str()).collect();
        assert_eq!(applied.len(), 1, "{kinds:?}");
        assert!(
            kinds[0].contains("fix") && kinds[0].contains("bone"),
            "{kinds:?}"
        );
        assert_eq!(applied[0].frame, 0);
    }
}
