//! File → Save scene: the session's state as a scene `voxflex run`
//! replays — the scene the viewer opened with its model, parameters,
//! interactions, frame count and ROI maps replaced by the session's — and
//! the atomic write (a temporary file in the same directory, then a
//! rename).

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};
use voxflex_core::camera::{Camera, Projection};
use voxflex_runtime::scene::Scene;
use voxflex_runtime::session::{AppliedInteraction, RoiInfo, Seed, Session};

/// What the session holds that the saved scene replays.
#[derive(Clone, Debug, Default)]
pub struct SessionState {
    /// The model's plugin and parameters (TOML text); `None`: no model.
    pub model: Option<(String, String)>,
    /// Frames the model stepped (its own clock).
    pub frames: u64,
    /// The interactions the model received, with their frames.
    pub interactions: Vec<AppliedInteraction>,
    /// The ROI maps.
    pub rois: Vec<RoiInfo>,
    /// The backend computing: `cpu` or `gpu`.
    pub backend: &'static str,
    /// The 3D view: renderer, its parameters and camera (`None`: keep the
    /// opened scene's `[render]`).
    pub render: Option<SavedRender>,
}

/// The 3D view as the saved scene's `[render]` table gives it.
#[derive(Clone, Debug, PartialEq)]
pub struct SavedRender {
    /// Renderer plugin.
    pub plugin: String,
    /// Its parameters (`[render.params]`) as TOML text.
    pub params_toml: String,
    /// The 3D view's camera at full quality (its size is the image's).
    pub camera: Camera,
}

impl SessionState {
    /// Reads the state off `session`.
    pub fn of(session: &Session) -> Self {
        Self {
            model: session.model_params(),
            frames: session.model_frames().unwrap_or(0),
            interactions: session.interactions_so_far(),
            rois: session.rois(),
            backend: if session.adapter_name() == "cpu" {
                "cpu"
            } else {
                "gpu"
            },
            render: None,
        }
    }
}

fn table_of(text: &str, what: &str) -> anyhow::Result<toml::Table> {
    text.parse::<toml::Table>()
        .with_context(|| format!("{what} is not a TOML table: {text}"))
}

/// The scene text: `base` (the scene opened, or the built-in one for a
/// volume file, whose `[volume]` is then `volume_file`) with `[scene]
/// frames` and `backend`, `[model]`, `[[interaction]]` and `[[roi]]` from
/// `state`, and `[render]` from `state.render` when set (renderer,
/// parameters, image size and camera, one image). A relative volume path
/// is made absolute (the saved file may lie elsewhere); everything else
/// (`[resample]`, `[output]`) is kept as the base scene has it.
pub fn scene_text(
    base: &Scene,
    volume_file: Option<&Path>,
    state: &SessionState,
) -> anyhow::Result<String> {
    let mut doc = table_of(&base.text, "the opened scene")?;
    let settings = entry_table(&mut doc, "scene");
    settings.insert("frames".into(), (state.frames.max(1) as i64).into());
    settings.insert("backend".into(), state.backend.into());
    settings.remove("plugin_dirs");
    let volume = entry_table(&mut doc, "volume");
    if let Some(file) = volume_file {
        volume.clear();
        volume.insert("source".into(), absolute(file, None).into());
    } else if let Some(toml::Value::String(src)) = volume.get("source").cloned()
        && !src.starts_with("phantom:")
    {
        let dir = base.path.parent();
        volume.insert("source".into(), absolute(Path::new(&src), dir).into());
    }
    doc.remove("model");
    doc.remove("interaction");
    doc.remove("roi");
    if let Some((plugin, params)) = &state.model {
        let mut model = toml::Table::new();
        model.insert("plugin".into(), plugin.clone().into());
        model.insert(
            "params".into(),
            table_of(params, "the model's parameters")?.into(),
        );
        doc.insert("model".into(), model.into());
        let mut list = vec![];
        for a in &state.interactions {
            let mut t = table_of(&a.toml, "an interaction")?;
            t.insert("frame".into(), (a.frame as i64).into());
            list.push(toml::Value::Table(t));
        }
        if !list.is_empty() {
            doc.insert("interaction".into(), list.into());
        }
    }
    if let Some(r) = &state.render {
        let render = entry_table(&mut doc, "render");
        render_table(render, r)?;
    }
    let rois: Vec<toml::Value> = state.rois.iter().filter_map(roi_table).collect();
    if !rois.is_empty() {
        doc.insert("roi".into(), rois.into());
    }
    let header = "# Saved by voxflex-viewer: `voxflex run` on this file replays the session.\n";
    Ok(format!("{header}{}", toml::to_string(&doc)?))
}

/// Sets `[render]`'s renderer, parameters, size and camera from `r` (one
/// image: no turntable; `file` as the base scene has it).
fn render_table(render: &mut toml::Table, r: &SavedRender) -> anyhow::Result<()> {
    let c = &r.camera;
    render.insert("plugin".into(), r.plugin.clone().into());
    render.insert("width".into(), i64::from(c.width).into());
    render.insert("height".into(), i64::from(c.height).into());
    render.remove("turntable");
    render.insert("camera".into(), camera_table(c).into());
    render.insert(
        "params".into(),
        table_of(&r.params_toml, "the renderer's parameters")?.into(),
    );
    Ok(())
}

/// `[render.camera]` for `c`: angles, distance, projection and target.
pub fn camera_table(c: &Camera) -> toml::Table {
    let mut t = toml::Table::new();
    t.insert("azimuth_deg".into(), c.azimuth_deg.into());
    t.insert("elevation_deg".into(), c.elevation_deg.into());
    t.insert("distance_mm".into(), c.distance_mm.into());
    match c.projection {
        Projection::Orthographic { height_mm } => {
            t.insert("projection".into(), "orthographic".into());
            t.insert("height_mm".into(), height_mm.into());
        }
        Projection::Perspective { fov_y_deg } => {
            t.insert("projection".into(), "perspective".into());
            t.insert("fov_deg".into(), fov_y_deg.into());
        }
    }
    let target: Vec<toml::Value> = c.target.to_array().iter().map(|&v| v.into()).collect();
    t.insert("target_mm".into(), target.into());
    t
}

/// `doc[key]` as a table (made when absent or not a table).
fn entry_table<'a>(doc: &'a mut toml::Table, key: &str) -> &'a mut toml::Table {
    let slot = doc
        .entry(key)
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    if !slot.is_table() {
        *slot = toml::Value::Table(toml::Table::new());
    }
    slot.as_table_mut().expect("a table")
}

/// `path` made absolute against `dir` (or the working directory).
fn absolute(path: &Path, dir: Option<&Path>) -> String {
    let joined: PathBuf = match dir {
        _ if path.is_absolute() => path.to_path_buf(),
        Some(d) => d.join(path),
        None => std::env::current_dir()
            .map(|d| d.join(path))
            .unwrap_or_else(|_| path.to_path_buf()),
    };
    std::fs::canonicalize(&joined)
        .unwrap_or(joined)
        .display()
        .to_string()
}

/// A map's `[[roi]]` table (world or voxel seeds; a slice-click seed is
/// left out: the session keeps it as a world point when the viewer seeds):
/// `lambda = "auto"` when the map's λ was chosen by the rule (so the scene
/// chooses again on its own volume), and the growth bounds when set.
fn roi_table(r: &RoiInfo) -> Option<toml::Value> {
    let mut t = toml::Table::new();
    let seed: Vec<toml::Value> = match r.seed {
        Seed::World(p) => p.to_array().iter().map(|&x| x.into()).collect(),
        _ => return None,
    };
    t.insert("name".into(), format!("map-{}", r.id.0).into());
    t.insert("seed".into(), seed.into());
    let lambda: toml::Value = if r.lambda_auto {
        "auto".into()
    } else {
        f64::from(r.params.lambda).into()
    };
    t.insert("lambda".into(), lambda);
    if let Some([lo, hi]) = r.limits.intensity {
        let window = vec![toml::Value::from(f64::from(lo)), f64::from(hi).into()];
        t.insert("intensity".into(), window.into());
    }
    if let Some(d) = r.limits.max_distance_mm {
        t.insert("max_distance_mm".into(), d.into());
    }
    t.insert("o_min".into(), f64::from(r.params.o_min).into());
    t.insert("o_max".into(), f64::from(r.params.o_max).into());
    t.insert("seed_radius".into(), i64::from(r.params.seed_radius).into());
    t.insert(
        "connectivity".into(),
        i64::from(r.params.connectivity).into(),
    );
    Some(t.into())
}

/// Writes `text` to `path` atomically: a temporary file next to it, synced,
/// then renamed over it (a reader never sees half a scene).
pub fn write_atomic(path: &Path, text: &str) -> anyhow::Result<()> {
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .with_context(|| format!("{} names no file", path.display()))?;
    let tmp = dir.join(format!(".{}.tmp", name.to_string_lossy()));
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(text.as_bytes())?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().with_context(|| format!("writing {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::open::BUILT_IN_SCENE;

    #[test]
    fn the_saved_scene_parses_with_the_sessions_model_interactions_and_frames() {
        let base = Scene::parse(BUILT_IN_SCENE, Path::new("configs/chainmail-head.toml")).unwrap();
        let state = SessionState {
            model: Some((
                "affine".into(),
                "field = \"twist\"\nangle_deg = 10.0\n".into(),
            )),
            frames: 3,
            interactions: vec![AppliedInteraction {
                frame: 1,
                toml: "kind = \"release\"\n".into(),
            }],
            rois: vec![],
            backend: "cpu",
            render: None,
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.toml");
        write_atomic(&path, &scene_text(&base, None, &state).unwrap()).unwrap();
        let saved = Scene::load(&path).unwrap();
        assert_eq!(saved.settings.frames, 3);
        let m = saved.model.as_ref().unwrap();
        assert_eq!(m.plugin, "affine");
        assert!(saved.model_params_toml().contains("twist"));
        assert_eq!(saved.interactions.len(), 1);
        assert_eq!(saved.interactions[0].frame, 1);
        assert!(saved.interactions[0].toml.contains("release"));
        assert_eq!(saved.volume.source, "phantom:head");
        // Only the scene is left in the directory (the temporary file was renamed).
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    /// A map's automatic λ, bounds and constants survive the saved scene:
    /// it reads back as the same `[[roi]]` request.
    #[test]
    fn the_saved_scene_keeps_an_roi_maps_auto_lambda_and_bounds() {
        use voxflex_core::glam::DVec3;
        use voxflex_opacity::{GrowthLimits, GrowthParams, Seed};
        use voxflex_runtime::scene::LambdaSetting;
        use voxflex_runtime::session::{RoiId, RoiInfo};
        let base = Scene::parse(BUILT_IN_SCENE, Path::new("configs/chainmail-head.toml")).unwrap();
        let info = |id, lambda_auto, limits| RoiInfo {
            id: RoiId(id),
            seed: Seed::World(DVec3::new(40.0, -2.5, 15.0)),
            params: GrowthParams {
                lambda: 5.656_854,
                seed_radius: 3,
                connectivity: 26,
                ..GrowthParams::default()
            },
            steps: 12,
            converged: true,
            voxels_above_half: 100,
            lambda_auto,
            limits,
        };
        let bounded = GrowthLimits {
            intensity: Some([-20.5, 80.0]),
            max_distance_mm: Some(35.0),
        };
        let state = SessionState {
            rois: vec![
                info(0, true, bounded),
                info(1, false, GrowthLimits::default()),
            ],
            backend: "cpu",
            ..SessionState::default()
        };
        let text = scene_text(&base, None, &state).unwrap();
        let saved = Scene::parse(&text, Path::new("s.toml")).unwrap();
        let [auto, fixed] = &saved.rois[..] else {
            panic!("two maps: {text}")
        };
        assert!(
            matches!(&auto.lambda, LambdaSetting::Word(w) if w == "auto"),
            "{text}"
        );
        assert_eq!(auto.intensity, Some([-20.5, 80.0]));
        assert_eq!(auto.max_distance_mm, Some(35.0));
        assert!(
            matches!(fixed.lambda, LambdaSetting::Value(l) if l == 5.656_854),
            "{text}"
        );
        assert_eq!((fixed.intensity, fixed.max_distance_mm), (None, None));
        assert_eq!((fixed.seed_radius, fixed.connectivity), (3, 26));
    }

    /// The saved `[render]` gives back the viewer's camera (through the
    /// scene's own `camera_for`) and the renderer parameters.
    #[test]
    fn the_saved_scene_renders_the_viewers_camera_and_parameters() {
        use voxflex_core::glam::DVec3;
        let base = Scene::parse(BUILT_IN_SCENE, Path::new("configs/chainmail-head.toml")).unwrap();
        for projection in [
            Projection::Orthographic { height_mm: 123.5 },
            Projection::Perspective { fov_y_deg: 40.0 },
        ] {
            let camera = Camera {
                target: DVec3::new(3.0, -4.5, 6.25),
                azimuth_deg: 33.0,
                elevation_deg: -12.5,
                distance_mm: 700.0,
                projection,
                width: 384,
                height: 256,
            };
            let state = SessionState {
                render: Some(SavedRender {
                    plugin: "raycast".into(),
                    params_toml: "mode = \"mip\"\ntransfer_function = { points = [[0, 0, 0, 0, 0], [100, 1, 1, 1, 1]] }\n".into(),
                    camera,
                }),
                backend: "cpu",
                ..SessionState::default()
            };
            let text = scene_text(&base, None, &state).unwrap();
            let saved = Scene::parse(&text, Path::new("s.toml")).unwrap();
            let r = saved.render.as_ref().unwrap();
            assert_eq!((r.width, r.height, r.turntable), (384, 256, 0));
            // The camera does not depend on the grid it is rendered on.
            let grid = voxflex_core::grid::Grid::new([5, 6, 7], DVec3::ONE, DVec3::splat(-90.0));
            assert_eq!(
                voxflex_runtime::visualise::camera_for(r, &grid, 0.0),
                camera
            );
            let params = saved.render_params_toml();
            assert!(
                params.contains("mip") && params.contains("points"),
                "{params}"
            );
        }
    }
}
