//! Legacy VTK (`.vtk`) reader, ASCII `DATASET UNSTRUCTURED_GRID` only, plus the cell
//! assembly and region-array naming shared with the `.vtu` reader.
//!
//! # Why our own parser rather than the `vtkio` crate
//!
//! `vtkio` (0.6.3, the latest stable release; 0.7 is only a release candidate) reads both
//! these legacy files and ASCII `.vtu` correctly, but its legacy parse errors carry neither
//! a line nor the problem — a garbage coordinate, a truncated cell list and a NaN all give
//! `Parse error: Alt` (0.7.0-rc2: `Parse error: Digit`) — and by default it pulls in a
//! second, old quick-xml (0.22), nom 3 and C compression libraries (lzma-sys, lz4). Naming
//! the file, line and problem for every malformed input is a requirement here, so the VTK
//! readers share the line-tracking tokenizer of the other readers; `.vtu` uses quick-xml
//! 0.38, already a dependency.
//!
//! Supported: `POINTS`, `CELLS` (classic `n p0 p1 ...` lists and the VTK 5.1
//! `OFFSETS`/`CONNECTIVITY` layout), `CELL_TYPES`, `POINT_DATA`/`CELL_DATA` with `SCALARS`,
//! `VECTORS`, `NORMALS`, `TENSORS`, `TEXTURE_COORDINATES`, `COLOR_SCALARS`, `LOOKUP_TABLE`,
//! `FIELD`, `GLOBAL_IDS`, `PEDIGREE_IDS` and `METADATA` blocks. Cells of type 10 become
//! tetrahedra; vertices, lines, triangles, polygons and quads are skipped; other cells are an
//! error. A one-component cell array named like a region (see [`REGION_ARRAY_NAMES`]) gives
//! the region ids.

use std::path::Path;

use super::lines::{Cursor, capped, parse_error, quoted};
use super::{build_mesh, region_id, repeated_vertex};
use crate::{Point3, ReadError, TetMesh};

/// Names (compared case-insensitively) of cell arrays used as region ids, most preferred
/// first.
pub const REGION_ARRAY_NAMES: [&str; 12] = [
    "region",
    "regions",
    "region_id",
    "regionid",
    "material",
    "materials",
    "material_id",
    "materialid",
    "gmsh:physical",
    "gmsh:geometrical",
    "cellentityids",
    "medit:ref",
];

/// Preference of a cell array named `name` as the region array (lower is better), or `None`
/// if the name does not look like one.
pub(crate) fn region_priority(name: &str) -> Option<usize> {
    REGION_ARRAY_NAMES
        .iter()
        .position(|n| n.eq_ignore_ascii_case(name))
}

/// A region array found in the cell data.
#[derive(Debug)]
pub(crate) struct RegionArray {
    pub priority: usize,
    pub values: Vec<u32>,
}

impl RegionArray {
    /// Keeps the better of `self` and `other`.
    pub fn keep_better(slot: &mut Option<Self>, other: Self) {
        if slot.as_ref().is_none_or(|r| other.priority < r.priority) {
            *slot = Some(other);
        }
    }
}

/// Converts a region value token to a region id.
pub(crate) fn parse_region(
    path: &Path,
    line: usize,
    text: &str,
    array: &str,
) -> Result<u32, ReadError> {
    text.parse::<f64>().ok().and_then(region_id).ok_or_else(|| {
        parse_error(
            path,
            line,
            format!(
                "region value {} in cell array `{array}` is not a non-negative integer",
                quoted(text)
            ),
        )
    })
}

/// Cells as read: point ids of cell `c` are `conn[start[c]..start[c + 1]]`; `lines[c]` is
/// the line to blame for problems with cell `c`.
#[derive(Debug, Default)]
pub(crate) struct CellList {
    pub start: Vec<usize>,
    pub conn: Vec<u64>,
    pub lines: Vec<usize>,
}

impl CellList {
    pub fn len(&self) -> usize {
        self.lines.len()
    }
}

enum Kind {
    Tet,
    Skip,
    Reject(&'static str),
}

fn classify(cell_type: u32) -> Kind {
    match cell_type {
        10 => Kind::Tet,
        // empty cell, vertices, lines, triangles, polygons, quads of any order
        0..=9 | 21 | 22 | 23 | 28 | 30 | 34 | 35 | 36 | 68 | 69 | 70 | 75 | 76 | 77 => Kind::Skip,
        24 => Kind::Reject("a quadratic tetrahedron"),
        71 | 78 => Kind::Reject("a higher-order tetrahedron"),
        11 | 12 | 25 | 29 | 33 | 72 | 79 => Kind::Reject("a hexahedron"),
        13 | 26 | 31 | 32 | 73 | 80 => Kind::Reject("a wedge"),
        14 | 27 | 37 | 74 | 81 => Kind::Reject("a pyramid"),
        15 | 16 => Kind::Reject("a prism"),
        41 | 42 => Kind::Reject("a polyhedron"),
        _ => Kind::Reject("not supported"),
    }
}

/// Turns cells with their `(type, line)` into tetrahedra and regions.
pub(crate) fn assemble_tets(
    path: &Path,
    points: usize,
    cells: &CellList,
    types: &[(u32, usize)],
    region: Option<&RegionArray>,
) -> Result<(Vec<[u32; 4]>, Vec<u32>), ReadError> {
    let mut tets = Vec::with_capacity(capped(cells.len()));
    let mut regions = Vec::with_capacity(capped(cells.len()));
    for (c, (&(cell_type, type_line), &line)) in types.iter().zip(&cells.lines).enumerate() {
        match classify(cell_type) {
            Kind::Tet => {}
            Kind::Skip => continue,
            Kind::Reject(d) => {
                return Err(parse_error(
                    path,
                    type_line,
                    format!(
                        "cell {c} has VTK cell type {cell_type} ({d}); only tetrahedra (type 10) \
                         are supported, plus lower-dimensional cells, which are skipped"
                    ),
                ));
            }
        }
        let ids = match (cells.start.get(c), cells.start.get(c + 1)) {
            (Some(&a), Some(&b)) => cells.conn.get(a..b).unwrap_or(&[]),
            _ => &[],
        };
        let &[a, b, c3, d] = ids else {
            return Err(parse_error(
                path,
                line,
                format!(
                    "cell {c} is a tetrahedron (type 10) but has {} points, expected 4",
                    ids.len()
                ),
            ));
        };
        let mut tet = [0u32; 4];
        for (v, id) in tet.iter_mut().zip([a, b, c3, d]) {
            *v = usize::try_from(id)
                .ok()
                .filter(|&i| i < points)
                .and_then(|i| u32::try_from(i).ok())
                .ok_or_else(|| {
                    parse_error(
                        path,
                        line,
                        format!("cell {c} refers to point {id}, but there are {points} points (ids 0..{points})"),
                    )
                })?;
        }
        if let Some(v) = repeated_vertex(&tet) {
            return Err(parse_error(
                path,
                line,
                format!("cell {c} lists point {v} twice"),
            ));
        }
        tets.push(tet);
        regions.push(region.and_then(|r| r.values.get(c).copied()).unwrap_or(0));
    }
    if tets.is_empty() {
        return Err(ReadError::Format {
            path: path.to_path_buf(),
            message: "no tetrahedra (VTK cell type 10) in the file".into(),
        });
    }
    Ok((tets, regions))
}

/// Reads a legacy VTK unstructured grid from `text`; `path` is only used in error messages.
/// Vertices no tetrahedron uses are dropped (see [`super::read_mesh_noting`]).
pub fn read_vtk_str(text: &str, path: &Path) -> Result<TetMesh, ReadError> {
    super::without_unused_vertices(parse(text, path)?, path, &mut Vec::new())
}

/// The mesh as the file has it, unused vertices included.
pub(super) fn parse(text: &str, path: &Path) -> Result<TetMesh, ReadError> {
    let mut cur = Cursor::new(text, path);
    let Some((no, first)) = cur.raw_line() else {
        return Err(cur.error(
            1,
            "the file is empty: expected `# vtk DataFile Version ...`",
        ));
    };
    if !first
        .trim()
        .to_ascii_lowercase()
        .starts_with("# vtk datafile")
    {
        return Err(cur.error(
            no,
            format!(
                "not a legacy VTK file: expected `# vtk DataFile Version ...`, found {}",
                quoted(first)
            ),
        ));
    }
    cur.raw_line()
        .ok_or_else(|| cur.eof_error("the title line"))?;
    let encoding = cur.line("`ASCII` or `BINARY`")?;
    if encoding.text.eq_ignore_ascii_case("BINARY") {
        return Err(
            encoding.error("binary legacy VTK files are not supported; save the file as ASCII")
        );
    }
    if !encoding.text.eq_ignore_ascii_case("ASCII") {
        return Err(encoding.error(format!(
            "expected `ASCII` or `BINARY`, found {}",
            quoted(encoding.text)
        )));
    }
    let t = cur.token("`DATASET UNSTRUCTURED_GRID`")?;
    if !t.text.eq_ignore_ascii_case("DATASET") {
        return Err(cur.error(
            t.line,
            format!(
                "expected `DATASET UNSTRUCTURED_GRID`, found {}",
                quoted(t.text)
            ),
        ));
    }
    let t = cur.token("the dataset type")?;
    if !t.text.eq_ignore_ascii_case("UNSTRUCTURED_GRID") {
        return Err(cur.error(
            t.line,
            format!(
                "only DATASET UNSTRUCTURED_GRID is supported, found DATASET {}",
                quoted(t.text)
            ),
        ));
    }
    let mut legacy = Legacy::default();
    while let Some(t) = cur.next_token() {
        legacy.section(&mut cur, t.text, t.line)?;
    }
    legacy.finish(&cur)
}

/// Which attribute data the following arrays belong to: `(point or cell, count, line)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Point(usize),
    Cell(usize),
}

#[derive(Debug, Default)]
struct Legacy {
    points: Option<Vec<Point3>>,
    cells: Option<(CellList, usize)>,
    types: Option<(Vec<(u32, usize)>, usize)>,
    mode: Option<Mode>,
    cell_data: Option<(usize, usize)>,
    region: Option<RegionArray>,
}

/// `a * b`, or an error at `line` if it overflows.
fn product(cur: &Cursor<'_>, line: usize, a: usize, b: usize) -> Result<usize, ReadError> {
    a.checked_mul(b)
        .ok_or_else(|| cur.error(line, "array size overflows"))
}

/// Skips `count` values.
fn skip_values(cur: &mut Cursor<'_>, count: usize, what: &str) -> Result<(), ReadError> {
    for _ in 0..count {
        cur.token(what)?;
    }
    Ok(())
}

impl Legacy {
    fn section(
        &mut self,
        cur: &mut Cursor<'_>,
        keyword: &str,
        line: usize,
    ) -> Result<(), ReadError> {
        let upper = keyword.to_ascii_uppercase();
        match upper.as_str() {
            "POINTS" => {
                if self.points.is_some() {
                    return Err(cur.error(line, "second POINTS section"));
                }
                let (n, _) = cur.parse::<usize>("number of points")?;
                cur.token("the data type of the points")?;
                let mut points = Vec::with_capacity(capped(n));
                for _ in 0..n {
                    let x = cur.finite("point coordinate")?;
                    let y = cur.finite("point coordinate")?;
                    let z = cur.finite("point coordinate")?;
                    points.push(Point3::new(x, y, z));
                }
                self.points = Some(points);
            }
            "CELLS" => {
                if self.cells.is_some() {
                    return Err(cur.error(line, "second CELLS section"));
                }
                self.cells = Some((read_cells(cur, line)?, line));
            }
            "CELL_TYPES" => {
                if self.types.is_some() {
                    return Err(cur.error(line, "second CELL_TYPES section"));
                }
                let (n, _) = cur.parse::<usize>("number of cell types")?;
                let mut types = Vec::with_capacity(capped(n));
                for _ in 0..n {
                    types.push(cur.parse::<u32>("cell type")?);
                }
                self.types = Some((types, line));
            }
            "CELL_DATA" | "POINT_DATA" => {
                let (n, _) = cur.parse::<usize>("number of data values")?;
                if upper == "CELL_DATA" {
                    self.mode = Some(Mode::Cell(n));
                    self.cell_data = Some((n, line));
                } else {
                    self.mode = Some(Mode::Point(n));
                }
            }
            "METADATA" => skip_metadata(cur),
            "FIELD" => self.field(cur)?,
            "SCALARS"
            | "VECTORS"
            | "NORMALS"
            | "TENSORS"
            | "TENSORS6"
            | "TEXTURE_COORDINATES"
            | "COLOR_SCALARS"
            | "LOOKUP_TABLE"
            | "GLOBAL_IDS"
            | "PEDIGREE_IDS" => {
                let n = match self.mode {
                    Some(Mode::Point(n) | Mode::Cell(n)) => n,
                    None => {
                        return Err(
                            cur.error(line, format!("{upper} before POINT_DATA or CELL_DATA"))
                        );
                    }
                };
                self.attribute(cur, &upper, line, n)?;
            }
            _ => {
                return Err(cur.error(
                    line,
                    format!(
                        "unexpected {}: expected a section keyword such as POINTS, CELLS, \
                         CELL_TYPES, CELL_DATA or POINT_DATA (does a count match its data?)",
                        quoted(keyword)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// One `POINT_DATA`/`CELL_DATA` attribute other than `FIELD`, with `n` tuples.
    fn attribute(
        &mut self,
        cur: &mut Cursor<'_>,
        keyword: &str,
        line: usize,
        n: usize,
    ) -> Result<(), ReadError> {
        let name = cur.token("the array name")?.text;
        match keyword {
            "SCALARS" => {
                cur.token("the data type")?;
                let components = cur
                    .rest_of_line()
                    .parse_opt::<usize>("number of components")?
                    .unwrap_or(1);
                if cur
                    .peek_token()
                    .is_some_and(|t| t.text.eq_ignore_ascii_case("LOOKUP_TABLE"))
                {
                    cur.token("LOOKUP_TABLE")?;
                    cur.token("the lookup table name")?;
                }
                if components == 1
                    && matches!(self.mode, Some(Mode::Cell(..)))
                    && let Some(priority) = region_priority(name)
                {
                    let values = read_regions(cur, n, name)?;
                    RegionArray::keep_better(&mut self.region, RegionArray { priority, values });
                    return Ok(());
                }
                skip_values(cur, product(cur, line, n, components)?, "a data value")
            }
            "VECTORS" | "NORMALS" => {
                cur.token("the data type")?;
                skip_values(cur, product(cur, line, n, 3)?, "a vector component")
            }
            "TENSORS" | "TENSORS6" => {
                cur.token("the data type")?;
                let k = if keyword == "TENSORS" { 9 } else { 6 };
                skip_values(cur, product(cur, line, n, k)?, "a tensor component")
            }
            "TEXTURE_COORDINATES" => {
                let (dim, _) = cur.parse::<usize>("texture dimension")?;
                cur.token("the data type")?;
                skip_values(cur, product(cur, line, n, dim)?, "a texture coordinate")
            }
            "COLOR_SCALARS" => {
                let (k, _) = cur.parse::<usize>("number of colour components")?;
                skip_values(cur, product(cur, line, n, k)?, "a colour component")
            }
            "LOOKUP_TABLE" => {
                let (size, _) = cur.parse::<usize>("lookup table size")?;
                skip_values(cur, product(cur, line, size, 4)?, "a lookup table entry")
            }
            // GLOBAL_IDS, PEDIGREE_IDS
            _ => {
                cur.token("the data type")?;
                skip_values(cur, n, "an id")
            }
        }
    }

    /// `FIELD name arrays`, each `name components tuples type values...`.
    fn field(&mut self, cur: &mut Cursor<'_>) -> Result<(), ReadError> {
        cur.token("the field name")?;
        let (arrays, _) = cur.parse::<usize>("number of field arrays")?;
        for _ in 0..arrays {
            let t = cur.token("a field array name")?;
            let (components, _) = cur.parse::<usize>("number of components")?;
            let (tuples, _) = cur.parse::<usize>("number of tuples")?;
            cur.token("the data type")?;
            let cell_count = match self.mode {
                Some(Mode::Cell(n)) => Some(n),
                _ => None,
            };
            match region_priority(t.text) {
                Some(priority) if components == 1 && cell_count == Some(tuples) => {
                    let values = read_regions(cur, tuples, t.text)?;
                    RegionArray::keep_better(&mut self.region, RegionArray { priority, values });
                }
                _ => skip_values(
                    cur,
                    product(cur, t.line, components, tuples)?,
                    "a field value",
                )?,
            }
            if cur
                .peek_token()
                .is_some_and(|t| t.text.eq_ignore_ascii_case("METADATA"))
            {
                cur.token("METADATA")?;
                skip_metadata(cur);
            }
        }
        Ok(())
    }

    fn finish(self, cur: &Cursor<'_>) -> Result<TetMesh, ReadError> {
        let eof = cur.eof_line();
        let points = self
            .points
            .ok_or_else(|| cur.error(eof, "end of file without a POINTS section"))?;
        let (cells, cells_line) = self
            .cells
            .ok_or_else(|| cur.error(eof, "end of file without a CELLS section"))?;
        let (types, types_line) = self
            .types
            .ok_or_else(|| cur.error(eof, "end of file without a CELL_TYPES section"))?;
        if types.len() != cells.len() {
            return Err(cur.error(
                types_line,
                format!(
                    "CELL_TYPES lists {} cells but CELLS (line {cells_line}) has {}",
                    types.len(),
                    cells.len()
                ),
            ));
        }
        if let Some((n, line)) = self.cell_data
            && n != cells.len()
        {
            return Err(cur.error(
                line,
                format!(
                    "CELL_DATA has {n} values but there are {} cells",
                    cells.len()
                ),
            ));
        }
        let (tets, regions) = assemble_tets(
            cur.path(),
            points.len(),
            &cells,
            &types,
            self.region.as_ref(),
        )?;
        build_mesh(cur.path(), points, tets, regions)
    }
}

/// Reads `n` region ids of array `name`.
fn read_regions(cur: &mut Cursor<'_>, n: usize, name: &str) -> Result<Vec<u32>, ReadError> {
    let mut values = Vec::with_capacity(capped(n));
    for _ in 0..n {
        let t = cur.token("a region value")?;
        values.push(parse_region(cur.path(), t.line, t.text, name)?);
    }
    Ok(values)
}

/// Skips a `METADATA` block: the rest of its line and every line up to a blank one.
fn skip_metadata(cur: &mut Cursor<'_>) {
    cur.rest_of_line();
    while let Some((_, line)) = cur.raw_line() {
        if line.trim().is_empty() {
            break;
        }
    }
}

/// Reads a `CELLS` section after its keyword on `line`: either `cells size` followed by
/// `n p0 ... p(n-1)` per cell, or (VTK 5.1) `offsets connectivity-size` followed by
/// `OFFSETS type` and `CONNECTIVITY type` arrays.
fn read_cells(cur: &mut Cursor<'_>, line: usize) -> Result<CellList, ReadError> {
    let (a, _) = cur.parse::<usize>("number of cells")?;
    let (size, _) = cur.parse::<usize>("size of the cell list")?;
    let mut cells = CellList::default();
    if cur
        .peek_token()
        .is_some_and(|t| t.text.eq_ignore_ascii_case("OFFSETS"))
    {
        cur.token("OFFSETS")?;
        cur.token("the data type of the offsets")?;
        let mut offsets_line = line;
        cells.start.reserve(capped(a));
        for i in 0..a {
            let (o, l) = cur.parse::<usize>("cell offset")?;
            let previous = cells.start.last().copied().unwrap_or(0);
            if (i == 0 && o != 0) || o < previous || o > size {
                return Err(cur.error(
                    l,
                    format!("invalid offset {o}: offsets must start at 0, not decrease and end at {size}"),
                ));
            }
            cells.start.push(o);
            offsets_line = l;
        }
        if a > 0 && cells.start.last() != Some(&size) {
            return Err(cur.error(
                offsets_line,
                format!("the last offset must equal the connectivity size {size}"),
            ));
        }
        let t = cur.token("`CONNECTIVITY`")?;
        if !t.text.eq_ignore_ascii_case("CONNECTIVITY") {
            return Err(cur.error(
                t.line,
                format!("expected `CONNECTIVITY`, found {}", quoted(t.text)),
            ));
        }
        cur.token("the data type of the connectivity")?;
        let mut value_lines = Vec::with_capacity(capped(size));
        cells.conn.reserve(capped(size));
        for _ in 0..size {
            let (id, l) = cur.parse::<u64>("point id")?;
            cells.conn.push(id);
            value_lines.push(l);
        }
        let cell_count = a.saturating_sub(1);
        cells.lines = (0..cell_count)
            .map(|c| {
                cells
                    .start
                    .get(c)
                    .and_then(|&s| value_lines.get(s))
                    .copied()
                    .unwrap_or(t.line)
            })
            .collect();
    } else {
        cells.start.reserve(capped(a) + 1);
        cells.lines.reserve(capped(a));
        cells.conn.reserve(capped(size));
        let mut used = 0usize;
        for _ in 0..a {
            let (k, l) = cur.parse::<usize>("number of points of a cell")?;
            used = used.saturating_add(k).saturating_add(1);
            if used > size {
                return Err(cur.error(
                    l,
                    format!("the cells hold more than the {size} values declared on line {line}"),
                ));
            }
            cells.start.push(cells.conn.len());
            cells.lines.push(l);
            for _ in 0..k {
                cells.conn.push(cur.parse::<u64>("point id")?.0);
            }
        }
        cells.start.push(cells.conn.len());
        if used != size {
            return Err(cur.error(
                line,
                format!("CELLS declares {size} values but its {a} cells hold {used}"),
            ));
        }
    }
    Ok(cells)
}
