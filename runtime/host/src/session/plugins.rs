//! The plugin libraries a scene names, loaded (and checked) before any
//! stage is built.

use crate::pipeline::RunError;
use crate::plugin_loader::{self, LoadedPlugin};
use crate::scene::Scene;
use std::path::Path;

/// The deformation and renderer plugins of a scene, loaded.
#[derive(Clone, Debug, Default)]
pub struct ScenePlugins {
    /// `[model] plugin`, when the scene has a model.
    pub model: Option<LoadedPlugin>,
    /// `[render] plugin`, when the scene renders.
    pub renderer: Option<LoadedPlugin>,
    /// Each `[[actuator]] plugin`, in scene order.
    pub actuators: Vec<LoadedPlugin>,
}

impl ScenePlugins {
    /// Loads the plugins `scene` names from its search path; only those.
    pub fn load(scene: &Scene) -> Result<Self, RunError> {
        let dirs = plugin_loader::search_path(&scene.plugin_dirs());
        let model = match &scene.model {
            Some(m) => Some(plugin_loader::load_by_name(&m.plugin, &dirs)?),
            None => None,
        };
        let renderer = match &scene.render {
            Some(r) => Some(plugin_loader::load_by_name(&r.plugin, &dirs)?),
            None => None,
        };
        let actuators = scene
            .actuators
            .iter()
            .map(|a| plugin_loader::load_by_name(&a.plugin, &dirs))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            model,
            renderer,
            actuators,
        })
    }

    /// The library files, model first (for fingerprints).
    pub fn files(&self) -> Vec<&Path> {
        self.model
            .iter()
            .chain(self.renderer.iter())
            .chain(self.actuators.iter())
            .map(|p| p.path.as_path())
            .collect()
    }
}
