//! Mesh files: readers for Gmsh (`.msh` versions 1, 2.2 and 4.1, ASCII), TetGen
//! (`.node` + `.ele`), legacy VTK (`.vtk`, ASCII unstructured grid) and VTK XML (`.vtu`,
//! ASCII), and a `.vtu` writer for results.
//!
//! Every reader produces a [`TetMesh`] with positions in the file's own units (no scaling),
//! one region id per tetrahedron (from the file's physical/elementary tag, region attribute
//! or cell data where present, else 0), and every tetrahedron positively oriented
//! ([`TetMesh::orient_positively`]). Lower-dimensional elements (points, lines, triangles,
//! quads) are skipped silently; other volume elements, higher-order tetrahedra and files
//! without any tetrahedron are errors. Node order of the file is kept: vertex `i` of the mesh
//! is the `i`-th node in the file that a tetrahedron uses.
//!
//! Like other tools, the readers are lenient where nothing is lost: nodes that no tetrahedron
//! uses (a geometry's construction points, the nodes of skipped surface elements) are
//! dropped, and a TetGen `.node` line may carry values its header does not declare
//! (attributes, boundary markers), which are ignored. Neither is an error; [`read_mesh_noting`]
//! and [`read_mesh_from_str_noting`] say what was left out ([`ReadNote`]).
//!
//! Malformed input never panics: it gives a [`ReadError`] naming the file and, for these
//! text formats, the 1-based line and the problem. NaN or infinite coordinates are errors.
//!
//! All text readers share one tokenizer that tracks line numbers (`lines.rs`).

mod gmsh;
mod lines;
mod tetgen;
mod vtk;
mod vtu;
mod vtu_writer;

use std::path::{Path, PathBuf};

pub use gmsh::read_gmsh_str;
pub use tetgen::{read_tetgen, read_tetgen_str};
pub use vtk::{REGION_ARRAY_NAMES, read_vtk_str};
pub use vtu::read_vtu_str;
pub use vtu_writer::{PointData, WriteError, vtu_string, write_vtu};

use crate::{Point3, ReadError, TetMesh};

/// A mesh file format held in one text (TetGen needs two texts: see [`read_tetgen_str`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshFormat {
    /// Gmsh `.msh`, ASCII, version 1, 2.x or 4.1.
    Gmsh,
    /// Legacy VTK `.vtk`, ASCII, `DATASET UNSTRUCTURED_GRID`.
    VtkLegacy,
    /// VTK XML unstructured grid `.vtu` with ASCII data arrays.
    Vtu,
}

/// True when `path` has the extension of a mesh format [`read_mesh`] reads.
pub fn is_mesh_file(path: &Path) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| {
        ["msh", "node", "ele", "vtk", "vtu"]
            .iter()
            .any(|m| e.eq_ignore_ascii_case(m))
    })
}

/// Reads a tetrahedral mesh, choosing the reader by the file extension: `.msh` (Gmsh),
/// `.node` or `.ele` (TetGen; the sibling file with the other extension is read too),
/// `.vtk` (legacy VTK) or `.vtu` (VTK XML).
pub fn read_mesh(path: &Path) -> Result<TetMesh, ReadError> {
    read_mesh_noting(path).map(|read| read.mesh)
}

/// Something a reader left out of a mesh without failing: worth telling the user, not an
/// error.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReadNote {
    /// Vertices that no tetrahedron uses were dropped; the others keep their order.
    UnusedVertices {
        /// The file.
        path: PathBuf,
        /// How many were dropped.
        count: usize,
        /// The first dropped, by its place (from 0) among the file's nodes.
        first: usize,
    },
    /// Lines of a TetGen `.node` file had values past the coordinates and the attributes and
    /// boundary marker its header declares; they were ignored.
    ExtraNodeValues {
        /// The `.node` file.
        path: PathBuf,
        /// How many lines had them.
        lines: usize,
        /// The first such line (from 1).
        first_line: usize,
    },
}

impl std::fmt::Display for ReadNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReadNote::UnusedVertices { path, count, first } => write!(
                f,
                "{}: dropped {count} vertices no tetrahedron uses (the first: node {first} of \
                 the file, counting from 0)",
                path.display()
            ),
            ReadNote::ExtraNodeValues {
                path,
                lines,
                first_line,
            } => write!(
                f,
                "{}:{first_line}: ignored values the header does not declare on {lines} \
                 line(s)",
                path.display()
            ),
        }
    }
}

/// A mesh read from a file, and what the reader left out of it.
#[derive(Debug, Clone)]
pub struct MeshRead {
    /// The mesh.
    pub mesh: TetMesh,
    /// What was left out (empty when the file was read as it is).
    pub notes: Vec<ReadNote>,
}

/// [`read_mesh`], with what the reader left out.
///
/// ```
/// use std::path::Path;
///
/// use cutlab_sim::io::{MeshFormat, ReadNote, read_mesh_from_str_noting};
///
/// // a tetrahedron and a fifth node nothing uses (legacy VTK)
/// let vtk = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\n\
///            POINTS 5 double\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n9 9 9\n\
///            CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n";
/// let read = read_mesh_from_str_noting(vtk, MeshFormat::VtkLegacy, Path::new("t.vtk"))?;
/// assert_eq!(read.mesh.vertex_count(), 4);
/// assert!(matches!(read.notes[..], [ReadNote::UnusedVertices { count: 1, first: 4, .. }]));
/// # Ok::<(), cutlab_sim::ReadError>(())
/// ```
pub fn read_mesh_noting(path: &Path) -> Result<MeshRead, ReadError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let format = match ext.as_str() {
        "msh" => MeshFormat::Gmsh,
        "vtk" => MeshFormat::VtkLegacy,
        "vtu" => MeshFormat::Vtu,
        "node" | "ele" => {
            let mut notes = Vec::new();
            let mesh = tetgen::read_tetgen_noting(path, &mut notes)?;
            return Ok(MeshRead { mesh, notes });
        }
        _ => {
            let found = if ext.is_empty() {
                "no extension".to_owned()
            } else {
                format!("`.{ext}`")
            };
            return Err(ReadError::Format {
                path: path.to_path_buf(),
                message: format!(
                    "unknown mesh file type ({found}): expected .msh (Gmsh), .node/.ele \
                     (TetGen), .vtk (legacy VTK) or .vtu (VTK XML)"
                ),
            });
        }
    };
    let text = read_text(path)?;
    read_mesh_from_str_noting(&text, format, path)
}

/// Reads a tetrahedral mesh from `text` in `format`; `path` is only used in error messages.
///
/// ```
/// use std::path::Path;
///
/// use cutlab_sim::io::{MeshFormat, read_mesh_from_str};
///
/// // one tetrahedron in Gmsh 2.2 (element type 4), physical group 7
/// let msh = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n\
///            $Nodes\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$EndNodes\n\
///            $Elements\n1\n1 4 2 7 7 1 2 3 4\n$EndElements\n";
/// let mesh = read_mesh_from_str(msh, MeshFormat::Gmsh, Path::new("tet.msh"))?;
/// assert_eq!((mesh.vertex_count(), mesh.tet_count()), (4, 1));
/// assert_eq!(mesh.regions(), &[7]);
/// assert!((mesh.volume() - 1.0 / 6.0).abs() < 1e-15);
/// # Ok::<(), cutlab_sim::ReadError>(())
/// ```
pub fn read_mesh_from_str(
    text: &str,
    format: MeshFormat,
    path: &Path,
) -> Result<TetMesh, ReadError> {
    read_mesh_from_str_noting(text, format, path).map(|read| read.mesh)
}

/// [`read_mesh_from_str`], with what the reader left out (see [`read_mesh_noting`]).
pub fn read_mesh_from_str_noting(
    text: &str,
    format: MeshFormat,
    path: &Path,
) -> Result<MeshRead, ReadError> {
    let mesh = match format {
        MeshFormat::Gmsh => gmsh::parse(text, path),
        MeshFormat::VtkLegacy => vtk::parse(text, path),
        MeshFormat::Vtu => vtu::parse(text, path),
    }?;
    let mut notes = Vec::new();
    let mesh = without_unused_vertices(mesh, path, &mut notes)?;
    Ok(MeshRead { mesh, notes })
}

/// Reads a whole file as text. Invalid UTF-8 is replaced rather than rejected so that the
/// readers can still recognise headers (e.g. of binary files) and report a precise error.
pub(crate) fn read_text(path: &Path) -> Result<String, ReadError> {
    let bytes = std::fs::read(path).map_err(|source| ReadError::Io {
        path: path.to_path_buf(),
        error: source,
    })?;
    Ok(match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    })
}

/// Builds the mesh from parsed data and orients every tetrahedron positively.
pub(crate) fn build_mesh(
    path: &Path,
    positions: Vec<Point3>,
    tets: Vec<[u32; 4]>,
    regions: Vec<u32>,
) -> Result<TetMesh, ReadError> {
    let mut mesh = TetMesh::new(positions, tets, regions).map_err(|source| ReadError::Mesh {
        path: path.to_path_buf(),
        source,
    })?;
    mesh.orient_positively();
    Ok(mesh)
}

/// `mesh` without the vertices no tetrahedron uses (the others keep their order and
/// positions, the tetrahedra their regions and orientation); a note on `notes` when some were
/// dropped.
pub(crate) fn without_unused_vertices(
    mesh: TetMesh,
    path: &Path,
    notes: &mut Vec<ReadNote>,
) -> Result<TetMesh, ReadError> {
    let n = mesh.vertex_count();
    let mut used = vec![false; n];
    for tet in mesh.tets() {
        for &v in tet {
            used[v as usize] = true;
        }
    }
    let Some(first) = used.iter().position(|&u| !u) else {
        return Ok(mesh);
    };
    // new id of each kept vertex, in the file's order
    let mut new_id = vec![u32::MAX; n];
    let mut positions = Vec::with_capacity(n);
    for (v, &p) in mesh.positions().iter().enumerate() {
        if used[v] {
            new_id[v] = positions.len() as u32;
            positions.push(p);
        }
    }
    let count = n - positions.len();
    let tets = mesh
        .tets()
        .iter()
        .map(|tet| tet.map(|v| new_id[v as usize]))
        .collect();
    let mesh = TetMesh::new(positions, tets, mesh.regions().to_vec()).map_err(|source| {
        ReadError::Mesh {
            path: path.to_path_buf(),
            source,
        }
    })?;
    notes.push(ReadNote::UnusedVertices {
        path: path.to_path_buf(),
        count,
        first,
    });
    Ok(mesh)
}

/// A vertex that occurs twice in `tet`, if any.
pub(crate) fn repeated_vertex<T: PartialEq + Copy>(tet: &[T; 4]) -> Option<T> {
    (1..4).find_map(|i| tet[..i].contains(&tet[i]).then_some(tet[i]))
}

/// Converts a region tag or attribute to a region id: a non-negative integer that fits in
/// 32 bits.
pub(crate) fn region_id(value: f64) -> Option<u32> {
    (value.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(&value)).then_some(value as u32)
}
