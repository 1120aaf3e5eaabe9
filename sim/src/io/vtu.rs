//! VTK XML unstructured grid (`.vtu`) reader for ASCII data arrays (`format="ascii"`), on
//! quick-xml. Binary and appended data are reported as unsupported. Several `<Piece>`s are
//! concatenated. Cells and regions follow the same rules as the legacy reader (see
//! [`super::vtk`]); point data is ignored.

use std::path::Path;

use quick_xml::Reader;
use quick_xml::events::{BytesStart, Event};

use super::build_mesh;
use super::lines::{Cursor, Token, capped, parse_error, parse_finite, parse_token, quoted};
use super::vtk::{CellList, RegionArray, assemble_tets, parse_region, region_priority};
use crate::{Point3, ReadError, TetMesh};

/// Reads an ASCII `.vtu` unstructured grid from `text`; `path` is only used in error
/// messages.
/// Vertices no tetrahedron uses are dropped (see [`super::read_mesh_noting`]).
pub fn read_vtu_str(text: &str, path: &Path) -> Result<TetMesh, ReadError> {
    super::without_unused_vertices(parse(text, path)?, path, &mut Vec::new())
}

/// The mesh as the file has it, unused vertices included.
pub(super) fn parse(text: &str, path: &Path) -> Result<TetMesh, ReadError> {
    let mut vtu = Vtu {
        src: text,
        path,
        lines: LineIndex::new(text),
        reader: Reader::from_str(text),
        stack: Vec::new(),
        piece: None,
        positions: Vec::new(),
        tets: Vec::new(),
        regions: Vec::new(),
        root_seen: false,
    };
    vtu.run()?;
    if vtu.tets.is_empty() {
        return Err(ReadError::Format {
            path: path.to_path_buf(),
            message: "no tetrahedra (VTK cell type 10) in the file".into(),
        });
    }
    build_mesh(path, vtu.positions, vtu.tets, vtu.regions)
}

/// Byte offsets of the line breaks of a text, to turn byte positions into line numbers.
#[derive(Debug)]
struct LineIndex(Vec<usize>);

impl LineIndex {
    fn new(text: &str) -> Self {
        Self(
            text.bytes()
                .enumerate()
                .filter(|&(_, b)| b == b'\n')
                .map(|(i, _)| i)
                .collect(),
        )
    }

    /// The 1-based line of byte `pos`.
    fn line_of(&self, pos: u64) -> usize {
        let pos = usize::try_from(pos).unwrap_or(usize::MAX);
        self.0.partition_point(|&nl| nl < pos) + 1
    }
}

/// The arrays of one `<Piece>`.
#[derive(Debug, Default)]
struct Piece {
    line: usize,
    points: usize,
    cells: usize,
    positions: Option<Vec<Point3>>,
    /// Connectivity, the line of each value and the line of the array.
    connectivity: Option<(Vec<u64>, Vec<usize>, usize)>,
    offsets: Option<(Vec<usize>, usize)>,
    types: Option<Vec<(u32, usize)>>,
    region: Option<RegionArray>,
}

/// Attributes of a `<DataArray>`.
#[derive(Debug)]
struct ArrayInfo {
    name: String,
    components: usize,
    line: usize,
}

#[derive(Debug)]
struct Vtu<'a> {
    src: &'a str,
    path: &'a Path,
    lines: LineIndex,
    reader: Reader<&'a [u8]>,
    /// Names of the open elements and the lines they start on.
    stack: Vec<(String, usize)>,
    piece: Option<Piece>,
    positions: Vec<Point3>,
    tets: Vec<[u32; 4]>,
    regions: Vec<u32>,
    root_seen: bool,
}

impl<'a> Vtu<'a> {
    fn error(&self, line: usize, message: impl Into<String>) -> ReadError {
        parse_error(self.path, line, message)
    }

    fn xml_error(&self, e: &quick_xml::Error) -> ReadError {
        self.error(
            self.lines.line_of(self.reader.error_position()),
            format!("malformed XML: {e}"),
        )
    }

    fn run(&mut self) -> Result<(), ReadError> {
        loop {
            let line = self.lines.line_of(self.reader.buffer_position());
            let event = self.reader.read_event().map_err(|e| self.xml_error(&e))?;
            match event {
                Event::Start(e) => {
                    let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
                    if name == "DataArray" {
                        let info = self.check_data_array(&e, line)?;
                        self.data_array(info, true)?;
                    } else {
                        self.start(&name, &e, line)?;
                        self.stack.push((name, line));
                    }
                }
                Event::Empty(e) => {
                    let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
                    if name == "DataArray" {
                        let info = self.check_data_array(&e, line)?;
                        self.data_array(info, false)?;
                    } else {
                        self.start(&name, &e, line)?;
                        self.end(&name, line)?;
                    }
                }
                Event::End(_) => {
                    if let Some((name, _)) = self.stack.pop() {
                        self.end(&name, line)?;
                    }
                }
                Event::Eof => {
                    if let Some((name, start)) = self.stack.last() {
                        return Err(self.error(
                            self.lines.line_of(self.reader.buffer_position()),
                            format!(
                                "unexpected end of file inside <{name}> (opened on line {start})"
                            ),
                        ));
                    }
                    break;
                }
                _ => {}
            }
        }
        if !self.root_seen {
            return Err(self.error(
                self.lines.line_of(self.reader.buffer_position()),
                "no <VTKFile> element: the file is empty or not a VTK XML file",
            ));
        }
        Ok(())
    }

    /// The value of attribute `key` of element `e` on `line`.
    fn attribute(
        &self,
        e: &BytesStart<'_>,
        key: &str,
        line: usize,
    ) -> Result<Option<String>, ReadError> {
        for a in e.attributes() {
            let a = a.map_err(|err| self.error(line, format!("malformed XML attribute: {err}")))?;
            if a.key.local_name().as_ref() == key.as_bytes() {
                let value = a
                    .decode_and_unescape_value(self.reader.decoder())
                    .map_err(|err| {
                        self.error(line, format!("malformed XML attribute `{key}`: {err}"))
                    })?;
                return Ok(Some(value.into_owned()));
            }
        }
        Ok(None)
    }

    fn count_attribute(
        &self,
        e: &BytesStart<'_>,
        key: &str,
        line: usize,
    ) -> Result<usize, ReadError> {
        let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
        let value = self
            .attribute(e, key, line)?
            .ok_or_else(|| self.error(line, format!("<{name}> has no `{key}` attribute")))?;
        value.trim().parse().map_err(|_| {
            self.error(
                line,
                format!("invalid {key} {} on <{name}>", quoted(&value)),
            )
        })
    }

    /// Handles the start of an element other than `<DataArray>`.
    fn start(&mut self, name: &str, e: &BytesStart<'_>, line: usize) -> Result<(), ReadError> {
        if !self.root_seen {
            if name != "VTKFile" {
                return Err(self.error(
                    line,
                    format!("not a VTK XML file: the root element is <{name}>, expected <VTKFile>"),
                ));
            }
            self.root_seen = true;
            let kind = self.attribute(e, "type", line)?.unwrap_or_default();
            if kind != "UnstructuredGrid" {
                return Err(self.error(
                    line,
                    format!("only VTKFile type=\"UnstructuredGrid\" (.vtu) is supported, found type={kind:?}"),
                ));
            }
            return Ok(());
        }
        match name {
            "AppendedData" => Err(self.error(
                line,
                "appended data (<AppendedData>) is not supported; save the file with ASCII data \
                 (ParaView: Data Mode = Ascii)",
            )),
            "Piece" => {
                if self.piece.is_some() {
                    return Err(self.error(line, "<Piece> inside another <Piece>"));
                }
                let points = self.count_attribute(e, "NumberOfPoints", line)?;
                let cells = self.count_attribute(e, "NumberOfCells", line)?;
                self.piece = Some(Piece {
                    line,
                    points,
                    cells,
                    ..Piece::default()
                });
                Ok(())
            }
            _ => Ok(()),
        }
    }

    /// Handles the end of an element other than `<DataArray>`.
    fn end(&mut self, name: &str, line: usize) -> Result<(), ReadError> {
        if name == "Piece"
            && let Some(piece) = self.piece.take()
        {
            self.finish_piece(piece, line)?;
        }
        Ok(())
    }

    /// Reads the attributes of a `<DataArray>` and rejects non-ASCII data.
    fn check_data_array(&self, e: &BytesStart<'_>, line: usize) -> Result<ArrayInfo, ReadError> {
        let name = self.attribute(e, "Name", line)?.unwrap_or_default();
        let format = self
            .attribute(e, "format", line)?
            .unwrap_or_else(|| "ascii".into());
        if !format.eq_ignore_ascii_case("ascii") {
            return Err(self.error(
                line,
                format!(
                    "DataArray {name:?} has format={format:?}: binary and appended .vtu data are \
                     not supported; save the file with ASCII data (ParaView: Data Mode = Ascii)"
                ),
            ));
        }
        let components = match self.attribute(e, "NumberOfComponents", line)? {
            None => 1,
            Some(v) => v.trim().parse().map_err(|_| {
                self.error(line, format!("invalid NumberOfComponents {}", quoted(&v)))
            })?,
        };
        Ok(ArrayInfo {
            name,
            components,
            line,
        })
    }

    /// The text chunks `(first line, text)` of a `<DataArray>` up to its end tag, skipping
    /// nested elements such as `<InformationKey>`.
    fn content(&mut self, line: usize) -> Result<Vec<(usize, &'a str)>, ReadError> {
        let mut chunks = Vec::new();
        let mut depth = 0usize;
        loop {
            let event = self.reader.read_event().map_err(|e| self.xml_error(&e))?;
            match event {
                Event::Text(t) if depth == 0 => {
                    let end = usize::try_from(self.reader.buffer_position()).unwrap_or(usize::MAX);
                    let start = end.saturating_sub(t.len());
                    let text = self
                        .src
                        .get(start..end)
                        .filter(|s| s.as_bytes() == &*t)
                        .ok_or_else(|| self.error(line, "cannot locate the DataArray text"))?;
                    chunks.push((self.lines.line_of(start as u64), text));
                }
                Event::GeneralRef(_) if depth == 0 => {
                    return Err(self.error(line, "entity reference inside a numeric DataArray"));
                }
                Event::CData(_) if depth == 0 => {
                    return Err(self.error(line, "CDATA inside a DataArray is not supported"));
                }
                Event::Start(_) => depth += 1,
                Event::End(_) => {
                    if depth == 0 {
                        return Ok(chunks);
                    }
                    depth -= 1;
                }
                Event::Eof => {
                    return Err(self.error(
                        self.lines.line_of(self.reader.buffer_position()),
                        format!(
                            "unexpected end of file inside <DataArray> (opened on line {line})"
                        ),
                    ));
                }
                _ => {}
            }
        }
    }

    /// Reads (or skips) a `<DataArray>` whose start tag was just read; `has_content` is false
    /// for `<DataArray/>`.
    fn data_array(&mut self, info: ArrayInfo, has_content: bool) -> Result<(), ReadError> {
        let chunks = if has_content {
            self.content(info.line)?
        } else {
            Vec::new()
        };
        let parent = self
            .stack
            .last()
            .map(|(name, _)| name.as_str())
            .unwrap_or_default();
        let path = self.path;
        let Some(piece) = self.piece.as_mut() else {
            return Ok(());
        };
        match parent {
            "Points" => {
                if info.components != 3 {
                    return Err(parse_error(
                        path,
                        info.line,
                        format!(
                            "the Points array has {} components, expected 3",
                            info.components
                        ),
                    ));
                }
                let mut coords = Vec::with_capacity(capped(piece.points.saturating_mul(3)));
                for_each_token(path, &chunks, |t| {
                    coords.push(finite(path, t)?);
                    Ok(())
                })?;
                if Some(coords.len()) != piece.points.checked_mul(3) {
                    return Err(parse_error(
                        path,
                        info.line,
                        format!(
                            "the Points array has {} values, expected 3 x NumberOfPoints = 3 x {}",
                            coords.len(),
                            piece.points
                        ),
                    ));
                }
                let positions = coords
                    .chunks_exact(3)
                    .map(|c| Point3::new(c[0], c[1], c[2]))
                    .collect();
                piece.positions = Some(positions);
            }
            "Cells" => match info.name.as_str() {
                "connectivity" => {
                    let mut ids = Vec::with_capacity(capped(piece.cells.saturating_mul(4)));
                    let mut lines = Vec::with_capacity(capped(piece.cells.saturating_mul(4)));
                    for_each_token(path, &chunks, |t| {
                        ids.push(integer(path, t, "point id")?);
                        lines.push(t.line);
                        Ok(())
                    })?;
                    piece.connectivity = Some((ids, lines, info.line));
                }
                "offsets" => {
                    let mut offsets = Vec::with_capacity(capped(piece.cells));
                    for_each_token(path, &chunks, |t| {
                        offsets.push(integer(path, t, "cell offset")?);
                        Ok(())
                    })?;
                    piece.offsets = Some((offsets, info.line));
                }
                "types" => {
                    let mut types = Vec::with_capacity(capped(piece.cells));
                    for_each_token(path, &chunks, |t| {
                        types.push((integer(path, t, "cell type")?, t.line));
                        Ok(())
                    })?;
                    if types.len() != piece.cells {
                        return Err(parse_error(
                            path,
                            info.line,
                            format!(
                                "the types array has {} values, expected NumberOfCells = {}",
                                types.len(),
                                piece.cells
                            ),
                        ));
                    }
                    piece.types = Some(types);
                }
                _ => {}
            },
            "CellData" if info.components == 1 => {
                if let Some(priority) = region_priority(&info.name) {
                    let mut values = Vec::with_capacity(capped(piece.cells));
                    for_each_token(path, &chunks, |t| {
                        values.push(parse_region(path, t.line, t.text, &info.name)?);
                        Ok(())
                    })?;
                    if values.len() != piece.cells {
                        return Err(parse_error(
                            path,
                            info.line,
                            format!(
                                "cell array `{}` has {} values, expected NumberOfCells = {}",
                                info.name,
                                values.len(),
                                piece.cells
                            ),
                        ));
                    }
                    RegionArray::keep_better(&mut piece.region, RegionArray { priority, values });
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// Checks a complete piece and appends its tetrahedra to the mesh.
    fn finish_piece(&mut self, piece: Piece, end_line: usize) -> Result<(), ReadError> {
        let path = self.path;
        let missing = |what: &str| {
            parse_error(
                path,
                end_line,
                format!("the <Piece> on line {} has no {what}", piece.line),
            )
        };
        let positions = piece.positions.ok_or_else(|| missing("<Points> array"))?;
        let (conn, value_lines, conn_line) = piece
            .connectivity
            .ok_or_else(|| missing("`connectivity` array in <Cells>"))?;
        let (mut offsets, offsets_line) = piece
            .offsets
            .ok_or_else(|| missing("`offsets` array in <Cells>"))?;
        let types = piece
            .types
            .ok_or_else(|| missing("`types` array in <Cells>"))?;
        // Offsets are the ends of the cells; some writers add a leading 0.
        if Some(offsets.len()) == piece.cells.checked_add(1) && offsets.first() == Some(&0) {
            offsets.remove(0);
        }
        if offsets.len() != piece.cells {
            return Err(parse_error(
                path,
                offsets_line,
                format!(
                    "the offsets array has {} values, expected NumberOfCells = {}",
                    offsets.len(),
                    piece.cells
                ),
            ));
        }
        let mut start = Vec::with_capacity(offsets.len() + 1);
        start.push(0);
        for &o in &offsets {
            if start.last().is_some_and(|&s| o < s) || o > conn.len() {
                return Err(parse_error(
                    path,
                    offsets_line,
                    format!(
                        "invalid offset {o}: offsets must not decrease and must not exceed the {} \
                         connectivity values",
                        conn.len()
                    ),
                ));
            }
            start.push(o);
        }
        let lines = start
            .iter()
            .take(piece.cells)
            .map(|&s| value_lines.get(s).copied().unwrap_or(conn_line))
            .collect();
        let cells = CellList { start, conn, lines };
        let (tets, regions) =
            assemble_tets(path, positions.len(), &cells, &types, piece.region.as_ref())?;
        let base = u32::try_from(self.positions.len())
            .map_err(|_| parse_error(path, piece.line, "too many points for 32-bit vertex ids"))?;
        self.positions.extend(positions);
        for tet in tets {
            let shifted = tet.map(|v| v.checked_add(base));
            let [Some(a), Some(b), Some(c), Some(d)] = shifted else {
                return Err(parse_error(
                    path,
                    piece.line,
                    "too many points for 32-bit vertex ids",
                ));
            };
            self.tets.push([a, b, c, d]);
        }
        self.regions.extend(regions);
        Ok(())
    }
}

/// Calls `f` on every token of the text chunks.
fn for_each_token<'a>(
    path: &'a Path,
    chunks: &[(usize, &'a str)],
    mut f: impl FnMut(Token<'a>) -> Result<(), ReadError>,
) -> Result<(), ReadError> {
    for &(line, text) in chunks {
        let mut cur = Cursor::starting_at_line(text, path, line);
        while let Some(t) = cur.next_token() {
            f(t)?;
        }
    }
    Ok(())
}

fn finite(path: &Path, t: Token<'_>) -> Result<f64, ReadError> {
    parse_finite(path, t.line, t.text, "point coordinate")
}

fn integer<T: std::str::FromStr>(path: &Path, t: Token<'_>, what: &str) -> Result<T, ReadError> {
    parse_token(path, t.line, t.text, what)
}
