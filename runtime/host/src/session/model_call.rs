//! [`ModelCall`]: which call into a session's deformation model failed,
//! carried by [`RunError::ModelCall`] so a caller can tell a refused
//! creation from a failed step without reading the message.

use crate::pipeline::RunError;
use voxflex_core::error::ModelError;

/// A call a session makes into its deformation model, in the order a
/// model sees them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ModelCall {
    /// Creating the instance from its parameters (`swap_model`).
    Create,
    /// `init` on the source volume (`swap_model`, `set_backend`).
    Init,
    /// `bind` of the source lattice or of tracked points.
    Bind,
    /// `interact` (`Session::interact`).
    Interact,
    /// `step` (the model stage).
    Step,
    /// `map` (the map stage, tracked points).
    Map,
    /// `removed_tetrahedra` (the map stage's topology request).
    RemovedTetrahedra,
    /// `notes` (`model_notes`, `metrics`).
    Notes,
}

impl ModelCall {
    /// The call's name as in the plugin interface (`create`, `init`, `bind`,
    /// `interact`, `step`, `map`, `removed_tetrahedra`, `notes`).
    pub fn name(self) -> &'static str {
        match self {
            ModelCall::Create => "create",
            ModelCall::Init => "init",
            ModelCall::Bind => "bind",
            ModelCall::Interact => "interact",
            ModelCall::Step => "step",
            ModelCall::Map => "map",
            ModelCall::RemovedTetrahedra => "removed_tetrahedra",
            ModelCall::Notes => "notes",
        }
    }

    /// Wraps a model's error with this call: `map_err(ModelCall::Step.failed())`.
    pub(crate) fn failed(self) -> impl FnOnce(ModelError) -> RunError {
        move |error| RunError::ModelCall { call: self, error }
    }
}

impl std::fmt::Display for ModelCall {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl RunError {
    /// The model call that failed, when this error is a model's
    /// ([`RunError::ModelCall`]); `None` for every other error.
    pub fn model_call(&self) -> Option<ModelCall> {
        match self {
            RunError::ModelCall { call, .. } => Some(*call),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_model_error_carries_its_call() {
        let e = ModelCall::Step.failed()(ModelError::new("plugin `x`: bad"));
        assert_eq!(e.model_call(), Some(ModelCall::Step));
        assert_eq!(e.to_string(), "plugin `x`: bad", "the model's own words");
        assert_eq!(RunError::Other("o".into()).model_call(), None);
    }
}
