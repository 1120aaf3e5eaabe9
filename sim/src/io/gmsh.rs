//! Gmsh `.msh` reader, ASCII only: format version 1 (`$NOD`/`$ELM`), 2.x (`$Nodes`,
//! `$Elements`, e.g. 2.2) and 4.1 (entity blocks, `$Entities`).
//!
//! Nodes are identified by tags that need not be contiguous or sorted; vertex `i` of the
//! mesh is the `i`-th node in the file. Linear tetrahedra (element type 4) become
//! tetrahedra; points, lines, triangles and quadrangles are skipped; any other element type
//! is an error. The region of a tetrahedron is its physical group tag when it has a non-zero
//! one, else its elementary (geometrical entity) tag. Sections the reader does not need
//! (`$PhysicalNames`, `$NodeData`, custom ones...) are skipped up to their `$End...` line.

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::path::Path;

use super::build_mesh;
use super::lines::{Cursor, Line, capped, quoted};
use crate::{Point3, ReadError, TetMesh};

/// Reads a Gmsh mesh from `text`; `path` is only used in error messages.
/// Vertices no tetrahedron uses are dropped (see [`super::read_mesh_noting`]).
pub fn read_gmsh_str(text: &str, path: &Path) -> Result<TetMesh, ReadError> {
    super::without_unused_vertices(parse(text, path)?, path, &mut Vec::new())
}

/// The mesh as the file has it, unused vertices included.
pub(super) fn parse(text: &str, path: &Path) -> Result<TetMesh, ReadError> {
    let mut cur = Cursor::new(text, path);
    let first = cur.line("`$MeshFormat` (Gmsh 2 or 4) or `$NOD` (Gmsh 1): the file is empty")?;
    let version = match first.text {
        "$MeshFormat" => read_mesh_format(&mut cur)?,
        "$NOD" => {
            // Version 1 has no header: the first section is the node section.
            let mut reader = Reader::new(Version::V1);
            reader.nodes = Some(read_nodes_v12(&mut cur, &first, "$ENDNOD")?);
            return reader.read_sections(&mut cur);
        }
        other => {
            return Err(first.error(format!(
                "not a Gmsh mesh: expected `$MeshFormat` or `$NOD`, found {}",
                quoted(other)
            )));
        }
    };
    Reader::new(version).read_sections(&mut cur)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Version {
    V1,
    V2,
    V41,
}

/// Reads the contents of `$MeshFormat` up to `$EndMeshFormat`.
fn read_mesh_format(cur: &mut Cursor<'_>) -> Result<Version, ReadError> {
    let mut line = data_line(cur, || {
        "the format line `version file-type data-size`".into()
    })?;
    let version_text = line.token("the format version")?;
    let version: f64 = version_text
        .parse()
        .map_err(|_| line.error(format!("invalid format version {}", quoted(version_text))))?;
    let file_type: u32 = line.parse("file type (0 for ASCII)")?;
    if file_type == 1 {
        return Err(line.error(
            "binary Gmsh files are not supported; save the mesh as ASCII \
             (Gmsh: File > Export with `Save all` off and `Binary` off, or Mesh.Binary = 0)",
        ));
    }
    if file_type != 0 {
        return Err(line.error(format!("invalid file type {file_type}: expected 0 (ASCII)")));
    }
    let version = if (2.0..3.0).contains(&version) {
        Version::V2
    } else if (version - 4.1).abs() < 1e-9 {
        Version::V41
    } else {
        return Err(line.error(format!(
            "unsupported Gmsh format version {version_text}: supported are 1, 2.x and 4.1 \
             (ASCII); re-save the mesh as version 4.1 or 2.2"
        )));
    };
    line.token("the data size")?;
    line.finish("the data size")?;
    expect_end(cur, "$EndMeshFormat", "the format line")?;
    Ok(version)
}

/// Nodes read so far: positions in file order and a map from node tag to vertex index.
#[derive(Debug)]
struct Nodes {
    positions: Vec<Point3>,
    index: HashMap<u64, u32>,
}

impl Nodes {
    fn with_capacity(n: usize) -> Self {
        Self {
            positions: Vec::with_capacity(capped(n)),
            index: HashMap::with_capacity(capped(n)),
        }
    }

    /// Adds node `tag` at `p`; `line` is the line to blame for a duplicate tag.
    fn add(&mut self, tag: u64, p: Point3, line: &Line<'_>) -> Result<(), ReadError> {
        let next = u32::try_from(self.positions.len())
            .map_err(|_| line.error("too many nodes for 32-bit vertex ids"))?;
        match self.index.entry(tag) {
            Entry::Occupied(_) => {
                return Err(line.error(format!("node tag {tag} is defined twice")));
            }
            Entry::Vacant(e) => e.insert(next),
        };
        self.positions.push(p);
        Ok(())
    }

    /// The vertex index of node `tag`, referred to by element `element` on `line`.
    fn lookup(&self, tag: u64, element: u64, line: &Line<'_>) -> Result<u32, ReadError> {
        self.index.get(&tag).copied().ok_or_else(|| {
            line.error(format!(
                "element {element} refers to unknown node tag {tag}"
            ))
        })
    }
}

/// What to do with an element of a Gmsh element type.
enum Kind {
    Tet,
    /// Lower-dimensional: skipped.
    Skip,
    /// Not supported: the description for the error message.
    Reject(&'static str),
}

fn classify(element_type: u32) -> Kind {
    match element_type {
        4 => Kind::Tet,
        // points, lines, triangles and quadrangles of any order
        1 | 2 | 3 | 8 | 9 | 10 | 15 | 16 | 20..=28 => Kind::Skip,
        11 => Kind::Reject("a second-order (10-node) tetrahedron"),
        29..=31 => Kind::Reject("a higher-order tetrahedron"),
        5 | 12 | 17 | 92 | 93 => Kind::Reject("a hexahedron"),
        6 | 13 | 18 => Kind::Reject("a prism"),
        7 | 14 | 19 => Kind::Reject("a pyramid"),
        _ => Kind::Reject("not supported"),
    }
}

fn reject_message(what: &str, element_type: u32, description: &str) -> String {
    format!(
        "{what} has Gmsh element type {element_type} ({description}); only linear tetrahedra \
         (type 4) are supported, plus lower-dimensional elements, which are skipped"
    )
}

/// The next line of a section's data; the end of the file or a `$` line (the section ended
/// early) is an error saying what was `expected`.
fn data_line<'a>(
    cur: &mut Cursor<'a>,
    expected: impl Fn() -> String,
) -> Result<Line<'a>, ReadError> {
    let Some(line) = cur.next_line() else {
        return Err(cur.eof_error(&expected()));
    };
    if line.text.starts_with('$') {
        return Err(line.error(format!(
            "section ends early: expected {}, found {}",
            expected(),
            quoted(line.text)
        )));
    }
    Ok(line)
}

/// Checks that the next line is `end` (case-insensitive), which should follow `after`.
fn expect_end(cur: &mut Cursor<'_>, end: &str, after: &str) -> Result<(), ReadError> {
    let line = cur.line(&format!("`{end}`"))?;
    if line.text.eq_ignore_ascii_case(end) {
        Ok(())
    } else {
        Err(line.error(format!(
            "expected `{end}` after {after}, found {} (does the count in the section header \
             match the data?)",
            quoted(line.text)
        )))
    }
}

/// Converts a physical/elementary tag to a region id.
fn region_of(
    physical: Option<i64>,
    elementary: Option<i64>,
    line: &Line<'_>,
) -> Result<u32, ReadError> {
    let tag = match (physical, elementary) {
        (Some(p), _) if p != 0 => p,
        (_, Some(e)) => e,
        _ => 0,
    };
    u32::try_from(tag).map_err(|_| {
        line.error(format!(
            "region tag {tag} is not a non-negative 32-bit integer"
        ))
    })
}

/// Reads the nodes of a version 1 `$NOD` or version 2 `$Nodes` section (whose header line
/// is `header`) up to `end`: a count, then `tag x y z` lines.
fn read_nodes_v12(cur: &mut Cursor<'_>, header: &Line<'_>, end: &str) -> Result<Nodes, ReadError> {
    let mut line = data_line(cur, || {
        format!("the number of nodes after `{}`", header.text)
    })?;
    let n: usize = line.parse("number of nodes")?;
    line.finish("the number of nodes")?;
    let mut nodes = Nodes::with_capacity(n);
    for i in 0..n {
        let mut line = data_line(cur, || format!("node {} of {n}", i + 1))?;
        let tag: u64 = line.parse("node tag")?;
        let p = read_xyz(&mut line)?;
        line.finish("the z coordinate")?;
        nodes.add(tag, p, &line)?;
    }
    expect_end(cur, end, &format!("{n} nodes"))?;
    Ok(nodes)
}

fn read_xyz(line: &mut Line<'_>) -> Result<Point3, ReadError> {
    let x = line.finite("x coordinate")?;
    let y = line.finite("y coordinate")?;
    let z = line.finite("z coordinate")?;
    Ok(Point3::new(x, y, z))
}

/// Reads the four node tags of tetrahedron `element` and resolves them.
fn read_tet(nodes: &Nodes, element: u64, line: &mut Line<'_>) -> Result<[u32; 4], ReadError> {
    let mut tags = [0u64; 4];
    for t in &mut tags {
        *t = line.parse("node tag of a tetrahedron")?;
    }
    line.finish("the 4 node tags of a tetrahedron")?;
    if let Some(t) = super::repeated_vertex(&tags) {
        return Err(line.error(format!("tetrahedron {element} lists node tag {t} twice")));
    }
    let mut tet = [0u32; 4];
    for (v, &t) in tet.iter_mut().zip(&tags) {
        *v = nodes.lookup(t, element, line)?;
    }
    Ok(tet)
}

/// The state of a reader after the format header.
#[derive(Debug)]
struct Reader {
    version: Version,
    nodes: Option<Nodes>,
    tets: Vec<[u32; 4]>,
    regions: Vec<u32>,
    /// Version 4.1: first physical tag of each volume entity (if it has one).
    volume_physical: HashMap<i64, Option<i64>>,
    elements_seen: bool,
}

impl Reader {
    fn new(version: Version) -> Self {
        Self {
            version,
            nodes: None,
            tets: Vec::new(),
            regions: Vec::new(),
            volume_physical: HashMap::new(),
            elements_seen: false,
        }
    }

    /// Reads the remaining sections and builds the mesh.
    fn read_sections(mut self, cur: &mut Cursor<'_>) -> Result<TetMesh, ReadError> {
        let (nodes_name, elements_name) = match self.version {
            Version::V1 => ("$NOD", "$ELM"),
            Version::V2 | Version::V41 => ("$Nodes", "$Elements"),
        };
        while let Some(line) = cur.next_line() {
            let name = line.text;
            if !name.starts_with('$') {
                return Err(line.error(format!(
                    "expected a section header such as `{nodes_name}`, found {}",
                    quoted(name)
                )));
            }
            if name == nodes_name {
                if self.nodes.is_some() {
                    return Err(line.error(format!("second `{name}` section")));
                }
                self.nodes = Some(match self.version {
                    Version::V1 => read_nodes_v12(cur, &line, "$ENDNOD")?,
                    Version::V2 => read_nodes_v12(cur, &line, "$EndNodes")?,
                    Version::V41 => read_nodes_v41(cur)?,
                });
            } else if name == elements_name {
                if self.elements_seen {
                    return Err(line.error(format!("second `{name}` section")));
                }
                self.elements_seen = true;
                let Some(nodes) = self.nodes.take() else {
                    return Err(line.error(format!(
                        "`{name}` section before the `{nodes_name}` section"
                    )));
                };
                let result = match self.version {
                    Version::V1 | Version::V2 => self.read_elements_v12(cur, &nodes, &line),
                    Version::V41 => self.read_elements_v41(cur, &nodes),
                };
                self.nodes = Some(nodes);
                result?;
            } else if self.version == Version::V41 && name == "$Entities" {
                self.read_entities(cur)?;
            } else if name == "$MeshFormat" {
                return Err(line.error("second `$MeshFormat` section"));
            } else {
                skip_section(cur, &line)?;
            }
        }
        let Some(nodes) = self.nodes else {
            return Err(cur.error(
                cur.eof_line(),
                format!("end of file without a `{nodes_name}` section"),
            ));
        };
        if !self.elements_seen {
            return Err(cur.error(
                cur.eof_line(),
                format!("end of file without an `{elements_name}` section"),
            ));
        }
        if self.tets.is_empty() {
            return Err(ReadError::Format {
                path: cur.path().to_path_buf(),
                message: "no tetrahedra (Gmsh element type 4) in the file".into(),
            });
        }
        build_mesh(cur.path(), nodes.positions, self.tets, self.regions)
    }

    /// Version 1 `$ELM` (`tag type physical elementary node-count nodes...`) or version 2
    /// `$Elements` (`tag type tag-count tags... nodes...`).
    fn read_elements_v12(
        &mut self,
        cur: &mut Cursor<'_>,
        nodes: &Nodes,
        header: &Line<'_>,
    ) -> Result<(), ReadError> {
        let v1 = self.version == Version::V1;
        let mut line = data_line(cur, || {
            format!("the number of elements after `{}`", header.text)
        })?;
        let n: usize = line.parse("number of elements")?;
        line.finish("the number of elements")?;
        self.tets.reserve(capped(n));
        self.regions.reserve(capped(n));
        for i in 0..n {
            let mut line = data_line(cur, || format!("element {} of {n}", i + 1))?;
            let tag: u64 = line.parse("element tag")?;
            let element_type: u32 = line.parse("element type")?;
            let (physical, elementary) = if v1 {
                let p: i64 = line.parse("physical region tag")?;
                let e: i64 = line.parse("elementary region tag")?;
                let count: usize = line.parse("number of nodes")?;
                if count != 4 && matches!(classify(element_type), Kind::Tet) {
                    return Err(
                        line.error(format!("tetrahedron {tag} has {count} nodes, expected 4"))
                    );
                }
                (Some(p), Some(e))
            } else {
                let count: usize = line.parse("number of tags")?;
                let mut tags = [None, None];
                for k in 0..count {
                    let t: i64 = line.parse("element tag (physical, elementary or partition)")?;
                    if let Some(slot) = tags.get_mut(k) {
                        *slot = Some(t);
                    }
                }
                (tags[0], tags[1])
            };
            match classify(element_type) {
                Kind::Skip => continue,
                Kind::Reject(d) => {
                    return Err(line.error(reject_message(
                        &format!("element {tag}"),
                        element_type,
                        d,
                    )));
                }
                Kind::Tet => {}
            }
            let tet = read_tet(nodes, tag, &mut line)?;
            self.regions.push(region_of(physical, elementary, &line)?);
            self.tets.push(tet);
        }
        let end = if v1 { "$ENDELM" } else { "$EndElements" };
        expect_end(cur, end, &format!("{n} elements"))
    }

    /// Version 4.1 `$Entities`: records the first physical tag of each volume.
    fn read_entities(&mut self, cur: &mut Cursor<'_>) -> Result<(), ReadError> {
        let mut line = data_line(cur, || {
            "the entity counts `points curves surfaces volumes`".into()
        })?;
        let mut counts = [0usize; 4];
        for (c, what) in counts
            .iter_mut()
            .zip(["points", "curves", "surfaces", "volumes"])
        {
            *c = line.parse(&format!("number of {what}"))?;
        }
        line.finish("the number of volumes")?;
        let [points, curves, surfaces, volumes] = counts;
        let lower = points.saturating_add(curves).saturating_add(surfaces);
        for i in 0..lower {
            data_line(cur, || {
                format!("point, curve or surface entity {} of {lower}", i + 1)
            })?;
        }
        for i in 0..volumes {
            let mut line = data_line(cur, || format!("volume entity {} of {volumes}", i + 1))?;
            let tag: i64 = line.parse("volume tag")?;
            for _ in 0..6 {
                line.token("bounding box coordinate")?;
            }
            let physical_count: usize = line.parse("number of physical tags")?;
            let physical = if physical_count > 0 {
                Some(line.parse::<i64>("physical tag")?)
            } else {
                None
            };
            self.volume_physical.insert(tag, physical);
        }
        expect_end(
            cur,
            "$EndEntities",
            &format!("{} entities", lower.saturating_add(volumes)),
        )
    }

    /// Version 4.1 `$Elements`: blocks of `dim entity-tag type count` followed by `count`
    /// lines `tag nodes...`.
    fn read_elements_v41(&mut self, cur: &mut Cursor<'_>, nodes: &Nodes) -> Result<(), ReadError> {
        let mut header = data_line(cur, || {
            "the element section header `blocks elements min-tag max-tag`".into()
        })?;
        let blocks: usize = header.parse("number of element blocks")?;
        let total: usize = header.parse("number of elements")?;
        header.parse::<u64>("minimum element tag")?;
        header.parse::<u64>("maximum element tag")?;
        header.finish("the maximum element tag")?;
        self.tets.reserve(capped(total));
        self.regions.reserve(capped(total));
        let mut seen = 0usize;
        for b in 0..blocks {
            let mut block = data_line(cur, || {
                format!("element block header {} of {blocks}", b + 1)
            })?;
            let _dim: u32 = block.parse("entity dimension")?;
            let entity: i64 = block.parse("entity tag")?;
            let element_type: u32 = block.parse("element type")?;
            let count: usize = block.parse("number of elements in the block")?;
            block.finish("the number of elements in the block")?;
            seen = seen.saturating_add(count);
            let region = match classify(element_type) {
                Kind::Skip => {
                    for i in 0..count {
                        data_line(cur, || {
                            format!("element {} of {count} in block {}", i + 1, b + 1)
                        })?;
                    }
                    continue;
                }
                Kind::Reject(d) => {
                    let what = format!("element block {} (entity {entity})", b + 1);
                    return Err(block.error(reject_message(&what, element_type, d)));
                }
                Kind::Tet => {
                    let physical = self.volume_physical.get(&entity).copied().flatten();
                    region_of(physical, Some(entity), &block)?
                }
            };
            for i in 0..count {
                let mut line = data_line(cur, || {
                    format!("element {} of {count} in block {}", i + 1, b + 1)
                })?;
                let tag: u64 = line.parse("element tag")?;
                let tet = read_tet(nodes, tag, &mut line)?;
                self.tets.push(tet);
                self.regions.push(region);
            }
        }
        if seen != total {
            return Err(header.error(format!(
                "the header declares {total} elements but the blocks hold {seen}"
            )));
        }
        expect_end(cur, "$EndElements", &format!("{blocks} element blocks"))
    }
}

/// Version 4.1 `$Nodes`: blocks of `dim entity-tag parametric count`, then `count` tag
/// lines, then `count` coordinate lines.
fn read_nodes_v41(cur: &mut Cursor<'_>) -> Result<Nodes, ReadError> {
    let mut header = data_line(cur, || {
        "the node section header `blocks nodes min-tag max-tag`".into()
    })?;
    let blocks: usize = header.parse("number of node blocks")?;
    let total: usize = header.parse("number of nodes")?;
    header.parse::<u64>("minimum node tag")?;
    header.parse::<u64>("maximum node tag")?;
    header.finish("the maximum node tag")?;
    let mut nodes = Nodes::with_capacity(total);
    let mut tags: Vec<(u64, Line<'_>)> = Vec::new();
    for b in 0..blocks {
        let mut block = data_line(cur, || format!("node block header {} of {blocks}", b + 1))?;
        let dim: usize = block.parse("entity dimension")?;
        block.parse::<i64>("entity tag")?;
        let parametric: u32 = block.parse("parametric flag")?;
        let count: usize = block.parse("number of nodes in the block")?;
        block.finish("the number of nodes in the block")?;
        if dim > 3 {
            return Err(block.error(format!("invalid entity dimension {dim}")));
        }
        let parameters = match parametric {
            0 => 0,
            1 => dim,
            _ => {
                return Err(block.error(format!(
                    "invalid parametric flag {parametric}: expected 0 or 1"
                )));
            }
        };
        tags.clear();
        tags.reserve(capped(count));
        for i in 0..count {
            let mut line = data_line(cur, || {
                format!("node tag {} of {count} in block {}", i + 1, b + 1)
            })?;
            let tag: u64 = line.parse("node tag")?;
            line.finish("the node tag")?;
            tags.push((tag, line));
        }
        for (i, (tag, tag_line)) in tags.iter().enumerate() {
            let mut line = data_line(cur, || {
                format!(
                    "coordinates of node {} of {count} in block {}",
                    i + 1,
                    b + 1
                )
            })?;
            let p = read_xyz(&mut line)?;
            for _ in 0..parameters {
                line.finite("parametric coordinate")?;
            }
            line.finish(if parameters > 0 {
                "the parametric coordinates"
            } else {
                "the z coordinate"
            })?;
            nodes.add(*tag, p, tag_line)?;
        }
    }
    if nodes.positions.len() != total {
        return Err(header.error(format!(
            "the header declares {total} nodes but the blocks hold {}",
            nodes.positions.len()
        )));
    }
    expect_end(cur, "$EndNodes", &format!("{blocks} node blocks"))?;
    Ok(nodes)
}

/// Skips a section the reader does not use, from its header `start` to its `$End...` line.
fn skip_section(cur: &mut Cursor<'_>, start: &Line<'_>) -> Result<(), ReadError> {
    let name = start.text.strip_prefix('$').unwrap_or(start.text);
    let end = format!("$End{name}");
    while let Some(line) = cur.next_line() {
        if line.text.eq_ignore_ascii_case(&end) {
            return Ok(());
        }
    }
    Err(cur.error(
        cur.eof_line(),
        format!(
            "unexpected end of file: section `{}` (line {}) has no `{end}`",
            start.text, start.no
        ),
    ))
}
