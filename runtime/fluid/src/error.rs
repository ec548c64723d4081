//! Why a fluid-weight computation was refused.

/// A fluid-weight computation that cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
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
    /// The cavity surface cannot hold fluid (e.g. it is flat along gravity).
    #[error("fluid weight: {0}")]
    Surface(String),
}
