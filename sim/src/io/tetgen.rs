//! TetGen `.node` + `.ele` reader.
//!
//! `.node`: a header `points dimension(3) attributes boundary-markers(0|1)`, then one line
//! per point `index x y z [attributes...] [marker]`; values past those the header declares
//! (attributes or markers a tool wrote without declaring them) are ignored, with a note. `.ele`: a header
//! `tetrahedra nodes-per-tet(4) attributes`, then `index n1 n2 n3 n4 [attributes...]`.
//! Indices start at 0 or 1, as declared by the first point's index, and are consecutive.
//! `#` starts a comment. The first tetrahedron attribute (TetGen's region attribute, `-A`)
//! is the region id; without attributes every region is 0.

use std::path::{Path, PathBuf};

use super::lines::{Cursor, capped, quoted};
use super::{ReadNote, build_mesh, read_text, region_id, repeated_vertex};
use crate::{Point3, ReadError, TetMesh};

/// Reads a TetGen mesh given either of its files (`x.node` or `x.ele`); the sibling with the
/// other extension is read too.
/// Vertices no tetrahedron uses are dropped (see [`super::read_mesh_noting`]).
pub fn read_tetgen(path: &Path) -> Result<TetMesh, ReadError> {
    read_tetgen_noting(path, &mut Vec::new())
}

/// [`read_tetgen`], adding what it left out to `notes`.
pub(super) fn read_tetgen_noting(
    path: &Path,
    notes: &mut Vec<ReadNote>,
) -> Result<TetMesh, ReadError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let (node_path, ele_path): (PathBuf, PathBuf) = match ext.as_deref() {
        Some("node") => (path.to_path_buf(), path.with_extension("ele")),
        Some("ele") => (path.with_extension("node"), path.to_path_buf()),
        _ => {
            return Err(ReadError::Format {
                path: path.to_path_buf(),
                message: "a TetGen mesh path must end in .node or .ele".into(),
            });
        }
    };
    let node_text = read_text(&node_path)?;
    let ele_text = read_text(&ele_path)?;
    read_tetgen_str_noting(&node_text, &node_path, &ele_text, &ele_path, notes)
}

/// Reads a TetGen mesh from the texts of its `.node` and `.ele` files; the paths are only
/// used in error messages. Vertices no tetrahedron uses are dropped (see
/// [`super::read_mesh_noting`]).
pub fn read_tetgen_str(
    node_text: &str,
    node_path: &Path,
    ele_text: &str,
    ele_path: &Path,
) -> Result<TetMesh, ReadError> {
    read_tetgen_str_noting(node_text, node_path, ele_text, ele_path, &mut Vec::new())
}

/// [`read_tetgen_str`], adding what it left out to `notes`.
pub(super) fn read_tetgen_str_noting(
    node_text: &str,
    node_path: &Path,
    ele_text: &str,
    ele_path: &Path,
    notes: &mut Vec<ReadNote>,
) -> Result<TetMesh, ReadError> {
    let (positions, base, extra) =
        read_nodes(&mut Cursor::new(node_text, node_path).with_comments('#'))?;
    if let Some((lines, first_line)) = extra {
        notes.push(ReadNote::ExtraNodeValues {
            path: node_path.to_path_buf(),
            lines,
            first_line,
        });
    }
    let (tets, regions) = read_tets(
        &mut Cursor::new(ele_text, ele_path).with_comments('#'),
        positions.len(),
        base,
    )?;
    let mesh = build_mesh(ele_path, positions, tets, regions)?;
    super::without_unused_vertices(mesh, ele_path, notes)
}

/// The lines of a `.node` file with values past those its header declares: how many, and the
/// first (1-based).
type ExtraValues = Option<(usize, usize)>;

/// Reads the `.node` file: positions, the index base (0 or 1) and the lines with undeclared
/// values, which are ignored (numbers only: other text is an error).
fn read_nodes(cur: &mut Cursor<'_>) -> Result<(Vec<Point3>, i64, ExtraValues), ReadError> {
    let mut header =
        cur.line("the header `points dimension attributes boundary-markers`: the file is empty")?;
    let n: usize = header.parse("number of points")?;
    let dim: usize = header.parse_opt("dimension")?.unwrap_or(3);
    let attributes: usize = header.parse_opt("number of attributes")?.unwrap_or(0);
    let markers: usize = header.parse_opt("number of boundary markers")?.unwrap_or(0);
    header.finish("the number of boundary markers")?;
    if dim != 3 {
        return Err(header.error(format!("dimension {dim}: only 3-D meshes are supported")));
    }
    if markers > 1 {
        return Err(header.error(format!(
            "number of boundary markers {markers}: expected 0 or 1"
        )));
    }
    if n == 0 {
        return Err(header.error("no points (points listed in a .poly file are not supported)"));
    }
    let mut positions = Vec::with_capacity(capped(n));
    let mut base = 0i64;
    let mut extra: ExtraValues = None;
    for i in 0..n {
        let mut line = cur.line(&format!(
            "point {} of {n} (declared on line {})",
            i + 1,
            header.no
        ))?;
        let index: i64 = line.parse("point index")?;
        if i == 0 {
            if index != 0 && index != 1 {
                return Err(
                    line.error(format!("the first point index is {index}: expected 0 or 1"))
                );
            }
            base = index;
        } else if i64::try_from(i).ok().and_then(|i| i.checked_add(base)) != Some(index) {
            return Err(line.error(format!(
                "point index {index}: expected {} (points must be numbered consecutively)",
                i as i128 + i128::from(base)
            )));
        }
        let x = line.finite("x coordinate")?;
        let y = line.finite("y coordinate")?;
        let z = line.finite("z coordinate")?;
        for _ in 0..attributes {
            line.parse::<f64>("point attribute")?;
        }
        for _ in 0..markers {
            line.parse::<i64>("boundary marker")?;
        }
        let what = format!(
            "trailing value (a number: an attribute or a boundary marker the header on line {} \
             does not declare)",
            header.no
        );
        let mut undeclared = false;
        while line.parse_opt::<f64>(&what)?.is_some() {
            undeclared = true;
        }
        if undeclared {
            extra.get_or_insert((0, line.no)).0 += 1;
        }
        positions.push(Point3::new(x, y, z));
    }
    if let Some(line) = cur.next_line() {
        return Err(line.error(format!(
            "more points than the {n} declared on line {}: found {}",
            header.no,
            quoted(line.text)
        )));
    }
    Ok((positions, base, extra))
}

/// Reads the `.ele` file given the number of points and their index base.
fn read_tets(
    cur: &mut Cursor<'_>,
    points: usize,
    base: i64,
) -> Result<(Vec<[u32; 4]>, Vec<u32>), ReadError> {
    let mut header =
        cur.line("the header `tetrahedra nodes-per-tetrahedron attributes`: the file is empty")?;
    let n: usize = header.parse("number of tetrahedra")?;
    let per_tet: usize = header.parse_opt("nodes per tetrahedron")?.unwrap_or(4);
    let attributes: usize = header.parse_opt("number of attributes")?.unwrap_or(0);
    header.finish("the number of attributes")?;
    match per_tet {
        4 => {}
        10 => {
            return Err(header.error(
                "second-order (10-node) tetrahedra are not supported; only linear tetrahedra (4 nodes)",
            ));
        }
        _ => return Err(header.error(format!("{per_tet} nodes per tetrahedron: expected 4"))),
    }
    if n == 0 {
        return Err(header.error("no tetrahedra"));
    }
    let last = i128::from(base) + points as i128 - 1;
    let mut tets = Vec::with_capacity(capped(n));
    let mut regions = Vec::with_capacity(capped(n));
    for i in 0..n {
        let mut line = cur.line(&format!(
            "tetrahedron {} of {n} (declared on line {})",
            i + 1,
            header.no
        ))?;
        let index: i64 = line.parse("tetrahedron index")?;
        let mut tet = [0u32; 4];
        for v in &mut tet {
            let node: i64 = line.parse("node index")?;
            *v = node
                .checked_sub(base)
                .and_then(|k| usize::try_from(k).ok())
                .filter(|&k| k < points)
                .and_then(|k| u32::try_from(k).ok())
                .ok_or_else(|| {
                    line.error(format!(
                        "tetrahedron {index} refers to node {node}, but the .node file has \
                         nodes {base}..={last}"
                    ))
                })?;
        }
        if let Some(v) = repeated_vertex(&tet) {
            return Err(line.error(format!(
                "tetrahedron {index} lists node {} twice",
                i128::from(v) + i128::from(base)
            )));
        }
        let mut region = 0;
        for a in 0..attributes {
            let value: f64 = line.parse("tetrahedron attribute")?;
            if a == 0 {
                region = region_id(value).ok_or_else(|| {
                    line.error(format!(
                        "region attribute {value} is not a non-negative integer region id"
                    ))
                })?;
            }
        }
        line.finish(&format!(
            "the 4 nodes and {attributes} attribute(s) declared on line {}",
            header.no
        ))?;
        tets.push(tet);
        regions.push(region);
    }
    if let Some(line) = cur.next_line() {
        return Err(line.error(format!(
            "more tetrahedra than the {n} declared on line {}: found {}",
            header.no,
            quoted(line.text)
        )));
    }
    Ok((tets, regions))
}
