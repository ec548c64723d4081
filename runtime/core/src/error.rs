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
    /// The volume holds NaN or ±∞ voxels that the non-finite policy refuses
    /// (see [`crate::non_finite`]).
    #[error("{path}: {message}")]
    NonFinite {
        /// File at fault.
        path: PathBuf,
        /// The counts and what to do.
        message: String,
    },
    /// A mesh file parsed, but its mesh cannot be used (the error names the
    /// file).
    #[error(transparent)]
    Mesh(#[from] MeshError),
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

/// A TOML parse error of a plugin's table `table` (e.g.
/// `[actuator.params]`) as one line naming the offending line of `text`
/// and what is wrong: how every plugin reports a table it cannot parse.
pub fn toml_table_error(table: &str, text: &str, e: &toml::de::Error) -> ModelError {
    let msg = e.message().trim().replace('\n', " ");
    match e.span() {
        Some(span) => {
            let start = span.start.min(text.len());
            let line_no = text[..start].matches('\n').count() + 1;
            let line = text.lines().nth(line_no - 1).unwrap_or("").trim();
            ModelError(format!("{table} line {line_no} `{line}`: {msg}"))
        }
        None => ModelError(format!("{table}: {msg}")),
    }
}

impl From<GpuError> for ModelError {
    fn from(e: GpuError) -> Self {
        Self(e.to_string())
    }
}

/// A tetrahedral mesh that cannot be used, or a proxy that cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// A node coordinate is NaN or infinite.
    #[error(
        "{source_name}: node {node} has a non-finite coordinate {value:?} (mm); fix or remove it"
    )]
    NonFinite {
        /// The mesh's origin (file name or generator).
        source_name: String,
        /// Node index.
        node: usize,
        /// The node's coordinates, mm.
        value: [f64; 3],
    },
    /// A tetrahedron names a node that does not exist.
    #[error("{source_name}: tetrahedron {tet} names node {node}, but the mesh has {nodes} nodes")]
    BadIndex {
        /// The mesh's origin.
        source_name: String,
        /// Tetrahedron index.
        tet: usize,
        /// The missing node.
        node: u32,
        /// Nodes in the mesh.
        nodes: usize,
    },
    /// A tetrahedron has (almost) no volume.
    #[error(
        "{source_name}: tetrahedron {tet} is degenerate (volume {volume:e} mm³ against edge {edge:e} mm); \
         remove it or remesh"
    )]
    Degenerate {
        /// The mesh's origin.
        source_name: String,
        /// Tetrahedron index.
        tet: usize,
        /// Its volume, mm³.
        volume: f64,
        /// Its longest edge, mm.
        edge: f64,
    },
    /// Arrays of different lengths, or a mesh with nothing in it.
    #[error("{source_name}: {message}")]
    Shape {
        /// The mesh's origin.
        source_name: String,
        /// What is wrong and what to do.
        message: String,
    },
}
