//! The plugin implementation of every mesh-based model.

use crate::mesh_model::{MeshModel, MeshModelParams, MeshSolver};
use voxflex_abi::DeclaresParams;
use voxflex_abi::ffi::{CAPABILITY_CPU, CAPABILITY_GPU};
use voxflex_abi::plugin::{DeformationPlugin, HostContext};
use voxflex_core::error::ModelError;

/// The table of a mesh model is the shared keys ([`MeshModelParams`]) and
/// the solver's own (`S::Params`): its schema is the two merged —
/// properties, required keys and definitions.
impl<S: MeshSolver> DeclaresParams for MeshModel<S> {
    fn params_schema() -> Result<String, String> {
        let mut shared = schemars::schema_for!(MeshModelParams);
        let solver = schemars::schema_for!(S::Params);
        let (Some(into), Some(from)) = (shared.as_object_mut(), solver.as_object()) else {
            return Err("a mesh model's schema is not an object".into());
        };
        for key in ["properties", "$defs"] {
            if let Some(serde_json::Value::Object(extra)) = from.get(key) {
                let map = into
                    .entry(key)
                    .or_insert_with(|| serde_json::Value::Object(Default::default()));
                if let serde_json::Value::Object(map) = map {
                    map.extend(extra.clone());
                }
            }
        }
        if let Some(serde_json::Value::Array(extra)) = from.get("required") {
            let list = into
                .entry("required")
                .or_insert_with(|| serde_json::Value::Array(vec![]));
            if let serde_json::Value::Array(list) = list {
                list.extend(extra.iter().cloned());
            }
        }
        into.insert("title".into(), S::NAME.into());
        voxflex_abi::params_schema::json(&shared)
    }
}

/// Every mesh-based model is a plugin by its solver alone: a crate that
/// implements [`MeshSolver`] for `S` exports `MeshModel<S>` with
/// [`voxflex_abi::export_deformation_plugin!`].
impl<S: MeshSolver> DeformationPlugin for MeshModel<S> {
    const NAME: &'static str = S::NAME;
    const DESCRIPTION: &'static str = S::DESCRIPTION;
    const CAPABILITIES: u32 = CAPABILITY_CPU | if S::GPU { CAPABILITY_GPU } else { 0 };

    fn create(params_toml: &str, host: HostContext) -> Result<Self, ModelError> {
        Ok(Self::from_toml(params_toml)?.with_gpu(host.gpu()))
    }
}
