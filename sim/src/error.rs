//! Errors of the simulation crate.

/// A structural problem with mesh data handed to [`crate::TetMesh`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    #[error("mesh has no tetrahedra")]
    Empty,
    #[error(
        "tetrahedron {tet} refers to vertex {vertex}, but the mesh has {vertex_count} vertices"
    )]
    VertexOutOfRange {
        tet: usize,
        vertex: u32,
        vertex_count: usize,
    },
    #[error("tetrahedron {tet} repeats vertex {vertex}")]
    RepeatedVertex { tet: usize, vertex: u32 },
    #[error("{regions} region ids given for {tets} tetrahedra")]
    RegionCount { regions: usize, tets: usize },
    #[error("too many vertices ({0}) for 32-bit vertex ids")]
    TooManyVertices(usize),
}

/// A mesh or segmentation file that could not be read. Every variant names the file; parse
/// errors also name the 1-based line (text formats) and the problem.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    #[error("{path}: {error}")]
    Io {
        path: std::path::PathBuf,
        error: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: std::path::PathBuf,
        line: usize,
        message: String,
    },
    #[error("{path}: {message}")]
    Format {
        path: std::path::PathBuf,
        message: String,
    },
    #[error("{path}: {source}")]
    Mesh {
        path: std::path::PathBuf,
        source: MeshError,
    },
}

/// A label volume that could not be turned into a mesh (see [`crate::segmentation`]).
#[derive(Debug, thiserror::Error)]
pub enum SegmentationError {
    /// A segmentation file could not be read; the error names the file.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// None of the requested labels occurs in the volume (after resampling).
    #[error("no voxel carries labels {labels:?}")]
    NoVoxels { labels: Vec<u32> },
    /// Inconsistent data handed to [`crate::segmentation::LabelVolume::new`].
    #[error("invalid label volume: {0}")]
    InvalidVolume(String),
    /// Meaningless [`crate::segmentation::MeshingOptions`] or mask labels.
    #[error("invalid meshing options: {0}")]
    InvalidOptions(String),
    /// The generated mesh was rejected by [`crate::TetMesh::new`].
    #[error("building the mesh: {0}")]
    Mesh(#[from] MeshError),
}
