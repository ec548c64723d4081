//! Building a session's actuation stage from a scene's `[[actuator]]` and
//! `[[effector]]` tables.

use super::Session;
use super::plugins::ScenePlugins;
use crate::actuation::geometry::rest_geometry;
use crate::actuation::stage::{ActuationStage, NewActuator};
use crate::pipeline::RunError;
use crate::scene::Scene;
use voxflex_abi::actuator::ActuatorProxy;
use voxflex_core::actuator::ActuatorModel;
use voxflex_core::glam::DVec3;

impl Session {
    /// Loads each actuator's geometry, creates and initialises its plugin,
    /// and binds every actuator and effector point on the model. A scene
    /// without actuators builds nothing.
    pub(super) fn build_actuation(
        &mut self,
        scene: &Scene,
        plugins: &ScenePlugins,
    ) -> Result<(), RunError> {
        if scene.actuators.is_empty() {
            return Ok(());
        }
        let context = self.context.clone();
        let mut actuators = Vec::new();
        for (n, (a, plugin)) in scene.actuators.iter().zip(&plugins.actuators).enumerate() {
            let name = a.display_name(n);
            let here = |m: String| RunError::Other(format!("{context}: [[actuator]] {name}: {m}"));
            let vtable = plugin.actuator.ok_or_else(|| {
                here(format!(
                    "plugin `{}` is a {} plugin, not an actuator",
                    plugin.name,
                    plugin.kind_name()
                ))
            })?;
            let params = a.params_toml();
            plugin
                .check_params(&params)
                .map_err(|e| here(e.to_string()))?;
            let geometry = rest_geometry(a, &scene.base_dir(), &self.source).map_err(here)?;
            // SAFETY: the vtable comes from a checked, never-unloaded library.
            let model = unsafe {
                ActuatorProxy::create(&plugin.name, vtable, &params, self.services.clone())
            }
            .map_err(|e| here(e.to_string()))?;
            let model: Box<dyn ActuatorModel> = Box::new(model);
            actuators.push(NewActuator {
                name,
                plugin: plugin.name.clone(),
                model,
                geometry,
                gravity: DVec3::from_array(a.gravity_m_s2),
            });
        }
        let effectors = scene
            .effectors
            .iter()
            .enumerate()
            .map(|(n, e)| {
                let targets = e.targets().map_err(|(k, m)| {
                    RunError::Other(format!("{context}: [[effector]] `{k}`: {m}"))
                })?;
                Ok((e.display_name(n), e.rest(), targets))
            })
            .collect::<Result<Vec<_>, RunError>>()?;
        let mut stage = ActuationStage::new(actuators, effectors, scene.actuation)?;
        let model = self.model.as_mut().ok_or_else(|| {
            RunError::Other(format!(
                "{context}: [[actuator]] needs a [model] to act on (corotational-fem)"
            ))
        })?;
        stage.bind(model.model.as_mut())?;
        self.actuation = Some(stage);
        Ok(())
    }
}
