//! Error types of voxflex-core. Every message names the file, key or value at
//! fault and says what to do.

use std::path::PathBuf;

/// A volume whose values do not fit its grid.
#[derive(Debug, thiserror::Error)]
pub enum VolumeError {
    /// `data` length differs from `dims` product.
    #[error("volume has {actual} values but dims {dims:?} need {expected}")]
    SizeMismatch {
        /// Grid dimensions.
        dims: [usize; 3],
        /// Values the grid needs.
        expected: usize,
        /// Values supplied.
        actual: usize,
    },
}

/// Reading or writing a volume file failed.
#[derive(Debug, thiserror::Error)]
pub enum IoError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// File at fault.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
    /// A header field is missing, malformed or inconsistent with the data.
    #[error("{path}: header field `{field}`: {message}")]
    Header {
        /// File at fault.
        path: PathBuf,
        /// The field at fault (format's own name).
        field: String,
        /// What is wrong and what to do.
        message: String,
    },
    /// The file's format is not one voxflex reads.
    #[error("{path}: {message}")]
    Unsupported {
        /// File at fault.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
    /// The header is fine but the data is damaged (a truncated or corrupt
    /// gzip/zlib stream, a malformed ASCII value).
    #[error("{path}: damaged data: {message}")]
    Corrupt {
        /// File at fault (the data file when it is separate from the header).
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
    /// The caller asked for something the volume or file cannot give (a
    /// slice index out of range, a volume too large for the format).
    #[error("{path}: {message}")]
    InvalidRequest {
        /// File the request was about.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
}

/// A GPU service call failed.
#[derive(Debug, Clone, thiserror::Error)]
#[error("GPU: {0}")]
pub struct GpuError(pub String);

/// A deformation model (plugin or built-in) reported an error.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{0}")]
pub struct ModelError(pub String);

impl ModelError {
    /// An error with the given message.
    pub fn new(msg: impl Into<String>) -> Self {
        Self(msg.into())
    }
}

impl From<GpuError> for ModelError {
    fn from(e: GpuError) -> Self {
        Self(e.to_string())
    }
}
