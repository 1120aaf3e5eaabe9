//! Mesh files: readers for Gmsh (`.msh` versions 1, 2.2 and 4.1, ASCII), TetGen
//! (`.node` + `.ele`), legacy VTK (`.vtk`, ASCII unstructured grid) and VTK XML (`.vtu`,
//! ASCII), and a `.vtu` writer for results.
//!
//! Every reader produces a [`TetMesh`] with positions in the file's own units (no scaling),
//! one region id per tetrahedron (from the file's physical/elementary tag, region attribute
//! or cell data where present, else 0), and every tetrahedron positively oriented
//! ([`TetMesh::orient_positively`]). Lower-dimensional elements (points, lines, triangles,
//! quads) are skipped silently; other volume elements, higher-order tetrahedra and files
//! without any tetrahedron are errors. Node numbering of the file is kept: vertex `i` of the
//! mesh is the `i`-th node in the file.
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

use std::path::Path;

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
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let format = match ext.as_str() {
        "msh" => MeshFormat::Gmsh,
        "vtk" => MeshFormat::VtkLegacy,
        "vtu" => MeshFormat::Vtu,
        "node" | "ele" => return read_tetgen(path),
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
    read_mesh_from_str(&text, format, path)
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
    match format {
        MeshFormat::Gmsh => read_gmsh_str(text, path),
        MeshFormat::VtkLegacy => read_vtk_str(text, path),
        MeshFormat::Vtu => read_vtu_str(text, path),
    }
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

/// A vertex that occurs twice in `tet`, if any.
pub(crate) fn repeated_vertex<T: PartialEq + Copy>(tet: &[T; 4]) -> Option<T> {
    (1..4).find_map(|i| tet[..i].contains(&tet[i]).then_some(tet[i]))
}

/// Converts a region tag or attribute to a region id: a non-negative integer that fits in
/// 32 bits.
pub(crate) fn region_id(value: f64) -> Option<u32> {
    (value.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(&value)).then_some(value as u32)
}
