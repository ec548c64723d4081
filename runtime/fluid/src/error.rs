//! Why a fluid-weight computation was refused.

/// A fluid-weight computation that cannot run.
#[derive(Debug, Clone, thiserror::Error)]
pub enum FluidError {
    /// A parameter is out of its range.
    #[error("fluid weight: `{key}` = {value}: {message}")]
    Param {
        /// The parameter's name (as in a scene's actuator table).
        key: &'static str,
        /// Its value, as given.
        value: String,
        /// What is wrong and what to do.
        message: String,
    },
    /// The cavity surface cannot be weighed as given.
    #[error("fluid weight: {0}")]
    Surface(String),
    /// A GPU call failed.
    #[error("fluid weight on the GPU: {0}")]
    Gpu(#[from] voxflex_core::error::GpuError),
}
