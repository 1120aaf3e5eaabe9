//! Errors of the simulation crate.

/// A structural problem with mesh data handed to [`crate::TetMesh`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    /// No tetrahedra were given.
    #[error("mesh has no tetrahedra")]
    Empty,
    /// A tetrahedron names a vertex past the end of the vertex list.
    #[error(
        "tetrahedron {tet} refers to vertex {vertex}, but the mesh has {vertex_count} vertices"
    )]
    VertexOutOfRange {
        /// The tetrahedron's index.
        tet: usize,
        /// The vertex it names.
        vertex: u32,
        /// How many vertices the mesh has.
        vertex_count: usize,
    },
    /// A tetrahedron names the same vertex twice.
    #[error("tetrahedron {tet} repeats vertex {vertex}")]
    RepeatedVertex {
        /// The tetrahedron's index.
        tet: usize,
        /// The vertex it repeats.
        vertex: u32,
    },
    /// The region ids are not one per tetrahedron.
    #[error("{regions} region ids given for {tets} tetrahedra")]
    RegionCount {
        /// How many region ids were given.
        regions: usize,
        /// How many tetrahedra there are.
        tets: usize,
    },
    /// More vertices (the count given) than a `u32` id can name.
    #[error("too many vertices ({0}) for 32-bit vertex ids")]
    TooManyVertices(usize),
}

/// A mesh or segmentation file that could not be read. Every variant names the file; parse
/// errors also name the 1-based line (text formats) and the problem.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be opened or read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// What the operating system said.
        error: std::io::Error,
    },
    /// A line of a text format could not be parsed.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: std::path::PathBuf,
        /// The line, counted from 1.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// The file is not of the format expected (a bad header, a missing section, a binary
    /// part that does not decode), where no single line is to blame.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// The file was read, but its tetrahedra do not make a valid mesh.
    #[error("{path}: {source}")]
    Mesh {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong with the mesh.
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
    NoVoxels {
        /// The labels asked for.
        labels: Vec<u32>,
    },
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
