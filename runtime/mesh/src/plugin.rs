//! The plugin implementation of every mesh-based model.

use crate::mesh_model::{MeshModel, MeshSolver};
use voxflex_abi::ffi::{CAPABILITY_CPU, CAPABILITY_GPU};
use voxflex_abi::plugin::{DeformationPlugin, HostContext};
use voxflex_core::error::ModelError;

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
