//! `.vtu` (VTK XML unstructured grid, ASCII) writer for meshes and per-vertex results, so
//! ParaView can open them. Floats are written in Rust's shortest round-trip form, so reading
//! the file back gives bit-identical positions.

use std::fmt::Display;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::{TetMesh, Vector3};

/// A per-vertex field to write with [`write_vtu`]: one value per mesh vertex.
#[derive(Debug, Clone, Copy)]
pub enum PointData<'a> {
    /// One number per vertex (e.g. a stress measure).
    Scalar(&'a [f64]),
    /// One 3-vector per vertex (e.g. velocity, displacement, force).
    Vector(&'a [Vector3]),
}

impl PointData<'_> {
    fn len(&self) -> usize {
        match self {
            PointData::Scalar(v) => v.len(),
            PointData::Vector(v) => v.len(),
        }
    }

    /// The first vertex with a non-finite value, if any.
    fn first_non_finite(&self) -> Option<usize> {
        match self {
            PointData::Scalar(v) => v.iter().position(|x| !x.is_finite()),
            PointData::Vector(v) => v.iter().position(|x| !x.iter().all(|c| c.is_finite())),
        }
    }
}

/// Why a `.vtu` file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// The file could not be created or written.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the operating system said.
        error: std::io::Error,
    },
    /// A point-data array is not one value per vertex.
    #[error("point data `{name}` has {len} values for {vertices} vertices")]
    Length {
        /// The array's name.
        name: String,
        /// How many values it has.
        len: usize,
        /// How many vertices the mesh has.
        vertices: usize,
    },
    /// A point-data array has a NaN or infinite value.
    #[error("point data `{name}` has a NaN or infinite value at vertex {vertex}")]
    NonFinite {
        /// The array's name.
        name: String,
        /// The first vertex with such a value.
        vertex: usize,
    },
    /// A vertex position has a NaN or infinite coordinate.
    #[error("vertex {vertex} has a NaN or infinite position")]
    NonFinitePosition {
        /// The first such vertex.
        vertex: usize,
    },
    /// A point-data name is empty or repeated.
    #[error("point data name {name:?} is empty or used twice")]
    Name {
        /// The name.
        name: String,
    },
}

/// Writes `mesh` as an ASCII `.vtu` file at `path`: points, tetrahedra (VTK type 10), the
/// cell array `region`, and the named per-vertex `point_data` (e.g.
/// `&[("velocity", PointData::Vector(&v))]`). NaN or infinite values are refused because
/// VTK's ASCII parser cannot read them.
///
/// ```
/// use cutlab_sim::Point3;
/// use cutlab_sim::generate::{GridCells, boxed};
/// use cutlab_sim::io::{PointData, read_mesh, write_vtu};
///
/// let mesh = boxed(Point3::origin(), [0.01; 3], GridCells { nx: 1, ny: 1, nz: 1 })?.mesh;
/// let height: Vec<f64> = mesh.positions().iter().map(|p| p.z).collect();
/// let path = std::env::temp_dir().join(format!("cube-{}.vtu", std::process::id()));
/// write_vtu(&path, &mesh, &[("height", PointData::Scalar(&height))])?;
/// // read back, the positions bit for bit
/// assert_eq!(read_mesh(&path)?.positions(), mesh.positions());
/// std::fs::remove_file(&path)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn write_vtu(
    path: &Path,
    mesh: &TetMesh,
    point_data: &[(&str, PointData<'_>)],
) -> Result<(), WriteError> {
    check(mesh, point_data)?;
    let io_error = |source| WriteError::Io {
        path: path.to_path_buf(),
        error: source,
    };
    let file = std::fs::File::create(path).map_err(io_error)?;
    let mut out = std::io::BufWriter::new(file);
    write_body(&mut out, mesh, point_data).map_err(io_error)?;
    out.flush().map_err(io_error)
}

/// The `.vtu` text [`write_vtu`] would write.
pub fn vtu_string(
    mesh: &TetMesh,
    point_data: &[(&str, PointData<'_>)],
) -> Result<String, WriteError> {
    check(mesh, point_data)?;
    let mut out = Vec::new();
    write_body(&mut out, mesh, point_data).map_err(|source| WriteError::Io {
        path: PathBuf::from("<memory>"),
        error: source,
    })?;
    Ok(String::from_utf8_lossy(&out).into_owned())
}

fn check(mesh: &TetMesh, point_data: &[(&str, PointData<'_>)]) -> Result<(), WriteError> {
    if let Some(vertex) = mesh
        .positions()
        .iter()
        .position(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(WriteError::NonFinitePosition { vertex });
    }
    for (i, (name, data)) in point_data.iter().enumerate() {
        if name.is_empty() || point_data[..i].iter().any(|(n, _)| n == name) {
            return Err(WriteError::Name {
                name: (*name).to_owned(),
            });
        }
        if data.len() != mesh.vertex_count() {
            return Err(WriteError::Length {
                name: (*name).to_owned(),
                len: data.len(),
                vertices: mesh.vertex_count(),
            });
        }
        if let Some(vertex) = data.first_non_finite() {
            return Err(WriteError::NonFinite {
                name: (*name).to_owned(),
                vertex,
            });
        }
    }
    Ok(())
}

/// Values per line for one-component arrays.
const PER_LINE: usize = 10;

/// Writes `values` in rows of `PER_LINE`, indented, each line ending in a newline.
fn write_rows<T: Display>(
    out: &mut impl Write,
    values: impl Iterator<Item = T>,
) -> std::io::Result<()> {
    for (i, v) in values.enumerate() {
        if i % PER_LINE == 0 {
            if i > 0 {
                writeln!(out)?;
            }
            write!(out, "          {v}")?;
        } else {
            write!(out, " {v}")?;
        }
    }
    writeln!(out)
}

/// The shortest text that parses back to exactly `x`.
struct Float(f64);

impl Display for Float {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}", self.0)
    }
}

fn write_body(
    out: &mut impl Write,
    mesh: &TetMesh,
    point_data: &[(&str, PointData<'_>)],
) -> std::io::Result<()> {
    writeln!(out, r#"<?xml version="1.0"?>"#)?;
    writeln!(
        out,
        r#"<VTKFile type="UnstructuredGrid" version="0.1" byte_order="LittleEndian">"#
    )?;
    writeln!(out, "  <UnstructuredGrid>")?;
    writeln!(
        out,
        r#"    <Piece NumberOfPoints="{}" NumberOfCells="{}">"#,
        mesh.vertex_count(),
        mesh.tet_count()
    )?;
    if !point_data.is_empty() {
        writeln!(out, "      <PointData>")?;
        for (name, data) in point_data {
            let name = quick_xml::escape::escape(*name);
            match data {
                PointData::Scalar(v) => {
                    writeln!(
                        out,
                        r#"        <DataArray type="Float64" Name="{name}" format="ascii">"#
                    )?;
                    write_rows(out, v.iter().map(|&x| Float(x)))?;
                }
                PointData::Vector(v) => {
                    writeln!(
                        out,
                        r#"        <DataArray type="Float64" Name="{name}" NumberOfComponents="3" format="ascii">"#
                    )?;
                    for x in *v {
                        writeln!(
                            out,
                            "          {} {} {}",
                            Float(x.x),
                            Float(x.y),
                            Float(x.z)
                        )?;
                    }
                }
            }
            writeln!(out, "        </DataArray>")?;
        }
        writeln!(out, "      </PointData>")?;
    }
    writeln!(out, r#"      <CellData Scalars="region">"#)?;
    writeln!(
        out,
        r#"        <DataArray type="UInt32" Name="region" format="ascii">"#
    )?;
    write_rows(out, mesh.regions().iter())?;
    writeln!(out, "        </DataArray>")?;
    writeln!(out, "      </CellData>")?;
    writeln!(out, "      <Points>")?;
    writeln!(
        out,
        r#"        <DataArray type="Float64" NumberOfComponents="3" format="ascii">"#
    )?;
    for p in mesh.positions() {
        writeln!(
            out,
            "          {} {} {}",
            Float(p.x),
            Float(p.y),
            Float(p.z)
        )?;
    }
    writeln!(out, "        </DataArray>")?;
    writeln!(out, "      </Points>")?;
    writeln!(out, "      <Cells>")?;
    writeln!(
        out,
        r#"        <DataArray type="Int64" Name="connectivity" format="ascii">"#
    )?;
    for [a, b, c, d] in mesh.tets() {
        writeln!(out, "          {a} {b} {c} {d}")?;
    }
    writeln!(out, "        </DataArray>")?;
    writeln!(
        out,
        r#"        <DataArray type="Int64" Name="offsets" format="ascii">"#
    )?;
    write_rows(out, (1..=mesh.tet_count()).map(|i| 4 * i))?;
    writeln!(out, "        </DataArray>")?;
    writeln!(
        out,
        r#"        <DataArray type="UInt8" Name="types" format="ascii">"#
    )?;
    write_rows(out, std::iter::repeat_n(10, mesh.tet_count()))?;
    writeln!(out, "        </DataArray>")?;
    writeln!(out, "      </Cells>")?;
    writeln!(out, "    </Piece>")?;
    writeln!(out, "  </UnstructuredGrid>")?;
    writeln!(out, "</VTKFile>")
}
