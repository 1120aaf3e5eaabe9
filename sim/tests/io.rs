//! Mesh readers and the `.vtu` writer: real files, generated files, malformed input (every
//! error must name the file and the right line), and a write/read round trip.

use std::path::{Path, PathBuf};

use cutlab_sim::io::{
    MeshFormat, PointData, ReadNote, WriteError, read_mesh, read_mesh_from_str,
    read_mesh_from_str_noting, read_mesh_noting, read_tetgen_str, vtu_string, write_vtu,
};
use cutlab_sim::{Point3, ReadError, TetMesh, Vector3};

// ---------------------------------------------------------------------------------------
// helpers

fn data(rel: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../data")).join(rel)
}

fn read_data(rel: &str) -> TetMesh {
    let path = data(rel);
    read_mesh(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// A unique scratch directory under the system temp dir.
fn scratch_dir(tag: &str) -> PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("cutlab-io-test-{}-{tag}-{n}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

/// Asserts `result` is a parse error in `file` at `line` whose message contains `needle`
/// (case-insensitive), and that the displayed error starts with `file:line:`.
#[track_caller]
fn assert_parse_error(result: Result<TetMesh, ReadError>, file: &str, line: usize, needle: &str) {
    let err = match result {
        Ok(m) => panic!("expected an error, read {} tets", m.tet_count()),
        Err(e) => e,
    };
    let shown = err.to_string();
    match &err {
        ReadError::Parse {
            path,
            line: l,
            message,
        } => {
            assert_eq!(path, Path::new(file), "{shown}");
            assert_eq!(*l, line, "wrong line in: {shown}");
            assert!(
                message.to_lowercase().contains(&needle.to_lowercase()),
                "message lacks {needle:?}: {shown}"
            );
        }
        other => panic!("expected a parse error, got {other:?}"),
    }
    assert!(shown.starts_with(&format!("{file}:{line}: ")), "{shown}");
}

/// Asserts `result` is a file-level format error in `file` containing `needle`.
#[track_caller]
fn assert_format_error(result: Result<TetMesh, ReadError>, file: &str, needle: &str) {
    match result {
        Err(ReadError::Format { path, message }) => {
            assert_eq!(path, Path::new(file));
            assert!(
                message.to_lowercase().contains(&needle.to_lowercase()),
                "{message}"
            );
        }
        Err(other) => panic!("expected a format error, got {other}"),
        Ok(m) => panic!("expected an error, read {} tets", m.tet_count()),
    }
}

/// Replaces line `no` (1-based) of `text`.
fn with_line(text: &str, no: usize, new: &str) -> String {
    let mut lines: Vec<&str> = text.lines().collect();
    lines[no - 1] = new;
    lines.join("\n") + "\n"
}

/// The first `n` lines of `text`.
fn first_lines(text: &str, n: usize) -> String {
    text.lines().take(n).map(|l| format!("{l}\n")).collect()
}

fn gmsh(text: &str) -> Result<TetMesh, ReadError> {
    read_mesh_from_str(text, MeshFormat::Gmsh, Path::new("small.msh"))
}

fn vtk(text: &str) -> Result<TetMesh, ReadError> {
    read_mesh_from_str(text, MeshFormat::VtkLegacy, Path::new("small.vtk"))
}

fn vtu(text: &str) -> Result<TetMesh, ReadError> {
    read_mesh_from_str(text, MeshFormat::Vtu, Path::new("small.vtu"))
}

fn tetgen(node: &str, ele: &str) -> Result<TetMesh, ReadError> {
    read_tetgen_str(node, Path::new("small.node"), ele, Path::new("small.ele"))
}

/// The unit cube split into six tetrahedra around the diagonal 0-7 (Kuhn); half of them are
/// negatively oriented as listed. Vertex `i` is at `(i & 1, i >> 1 & 1, i >> 2 & 1)`.
fn cube() -> (Vec<[f64; 3]>, Vec<[usize; 4]>) {
    let points = (0..8)
        .map(|i| [(i & 1) as f64, (i >> 1 & 1) as f64, (i >> 2 & 1) as f64])
        .collect();
    let tets = vec![
        [0, 1, 3, 7],
        [0, 1, 5, 7],
        [0, 2, 3, 7],
        [0, 2, 6, 7],
        [0, 4, 5, 7],
        [0, 4, 6, 7],
    ];
    (points, tets)
}

/// Checks a mesh read from a [`cube`] file with the given regions.
#[track_caller]
fn assert_cube(mesh: &TetMesh, regions: &[u32]) {
    let (points, tets) = cube();
    assert_eq!(mesh.vertex_count(), 8);
    assert_eq!(mesh.tet_count(), 6);
    for (p, q) in mesh.positions().iter().zip(&points) {
        assert_eq!([p.x, p.y, p.z], *q);
    }
    for (t, (read, written)) in mesh.tets().iter().zip(&tets).enumerate() {
        let mut a = read.map(|v| v as usize);
        let mut b = *written;
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b, "tet {t} has other vertices");
        assert!(mesh.tet_volume(t) > 0.0, "tet {t} not positively oriented");
    }
    assert!((mesh.volume() - 1.0).abs() < 1e-12);
    assert_eq!(mesh.regions(), regions);
    assert!(mesh.validate().is_ok(), "{}", mesh.validate());
}

const CUBE_REGIONS: [u32; 6] = [1, 1, 1, 2, 2, 2];

// ---------------------------------------------------------------------------------------
// real files

#[test]
fn liver_gmsh_v1() {
    let mesh = read_data("sofa/liver.msh");
    assert_eq!(mesh.vertex_count(), 181);
    assert_eq!(mesh.tet_count(), 596);
    // Every element of the file has physical region 1.
    assert_eq!(mesh.region_ids(), vec![1]);
    assert!(mesh.validate().is_ok(), "{}", mesh.validate());
    assert!(mesh.volume() > 0.0);
}

#[track_caller]
fn check_bar(rel: &str, nodes: usize, tets: usize) {
    let mesh = read_data(rel);
    assert_eq!(mesh.vertex_count(), nodes);
    assert_eq!(mesh.tet_count(), tets);
    let (lo, hi) = mesh.bounding_box();
    assert_eq!([lo.x, lo.y, lo.z], [0.0, 0.0, 0.0]);
    assert_eq!([hi.x, hi.y, hi.z], [10.0, 0.5, 1.0]);
    assert!(
        (mesh.volume() - 5.0).abs() < 1e-9,
        "volume {}",
        mesh.volume()
    );
    // No $Entities section and entity tag 0: region 0 throughout.
    assert_eq!(mesh.region_ids(), vec![0]);
    assert!(mesh.validate().is_ok(), "{}", mesh.validate());
}

#[test]
fn bar_186_gmsh_v41() {
    check_bar("ipc/bar-186.msh", 86, 186);
}

#[test]
fn bar_651_gmsh_v41() {
    check_bar("ipc/bar-651.msh", 292, 651);
}

#[test]
fn bar_2523_gmsh_v41() {
    check_bar("ipc/bar-2523.msh", 886, 2523);
}

#[test]
fn armadillo_tetgen_from_either_file() {
    let a = read_data("pbd/armadillo_4k.node");
    let b = read_data("pbd/armadillo_4k.ele");
    assert_eq!(a.vertex_count(), 1180);
    assert_eq!(a.tet_count(), 3717);
    assert_eq!(a.region_ids(), vec![0]);
    assert!(a.validate().is_ok(), "{}", a.validate());
    assert_eq!(a.positions(), b.positions());
    assert_eq!(a.tets(), b.tets());
    // Index base 0: the first point of the file is vertex 0.
    let first: [f64; 3] = ["-1.0329299999999999", "1.35422", "-1.1708700000000001"]
        .map(|s| s.parse().expect("float"));
    let p = a.positions()[0];
    assert_eq!([p.x, p.y, p.z], first);
}

#[test]
fn unknown_extension_is_a_clear_error() {
    let r = read_mesh(Path::new("mesh.obj"));
    assert_format_error(r, "mesh.obj", "unknown mesh file type (`.obj`)");
    let r = read_mesh(Path::new("mesh"));
    assert_format_error(r, "mesh", "no extension");
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    let r = read_mesh(Path::new("/nonexistent/cutlab/x.msh"));
    let e = r.expect_err("error");
    assert!(matches!(e, ReadError::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/cutlab/x.msh"));
}

// ---------------------------------------------------------------------------------------
// Gmsh

/// The cube as Gmsh 2.2 with a point, a line and a triangle element to skip. Node tags are
/// `10 * (i + 1)`; regions are the physical tags.
fn cube_msh22() -> String {
    let (points, tets) = cube();
    let mut s = String::from("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n");
    s += "$PhysicalNames\n2\n3 1 \"soft\"\n3 2 \"hard\"\n$EndPhysicalNames\n";
    s += &format!("$Nodes\n{}\n", points.len());
    for (i, p) in points.iter().enumerate() {
        s += &format!("{} {} {} {}\n", 10 * (i + 1), p[0], p[1], p[2]);
    }
    s += &format!("$EndNodes\n$Elements\n{}\n", tets.len() + 3);
    s += "1 15 2 0 1 10\n2 1 2 0 1 10 20\n3 2 2 0 1 10 20 30\n";
    for (t, tet) in tets.iter().enumerate() {
        let tags = tet.map(|v| (10 * (v + 1)).to_string()).join(" ");
        s += &format!("{} 4 2 {} 5 {tags}\n", t + 4, CUBE_REGIONS[t]);
    }
    s += "$EndElements\n";
    s
}

#[test]
fn generated_gmsh22() {
    let mesh = gmsh(&cube_msh22()).unwrap_or_else(|e| panic!("{e}"));
    assert_cube(&mesh, &CUBE_REGIONS);
}

#[test]
fn gmsh22_elementary_tag_when_no_physical() {
    let text = cube_msh22()
        .replace(" 4 2 1 5 ", " 4 2 0 5 ")
        .replace(" 4 2 2 5 ", " 4 2 0 6 ");
    let mesh = gmsh(&text).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(mesh.regions(), [5, 5, 5, 6, 6, 6]);
    let text = cube_msh22()
        .replace(" 4 2 1 5 ", " 4 0 ")
        .replace(" 4 2 2 5 ", " 4 0 ");
    let mesh = gmsh(&text).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(mesh.regions(), [0; 6]);
}

#[test]
fn generated_gmsh_v1() {
    let (points, tets) = cube();
    let mut s = format!("$NOD\n{}\n", points.len());
    for (i, p) in points.iter().enumerate() {
        s += &format!("{} {} {} {}\n", i + 1, p[0], p[1], p[2]);
    }
    s += &format!("$ENDNOD\n$ELM\n{}\n", tets.len());
    for (t, tet) in tets.iter().enumerate() {
        let tags = tet.map(|v| (v + 1).to_string()).join(" ");
        s += &format!("{} 4 {} 1 4 {tags}\n", t + 1, CUBE_REGIONS[t]);
    }
    s += "$ENDELM\n";
    assert_cube(&gmsh(&s).unwrap_or_else(|e| panic!("{e}")), &CUBE_REGIONS);
    // A tetrahedron claiming 5 nodes: the first element, on line 14.
    let bad = s.replace("1 4 1 1 4 1 2 4 8", "1 4 1 1 5 1 2 4 8 3");
    assert_parse_error(gmsh(&bad), "small.msh", 14, "has 5 nodes, expected 4");
}

/// Gmsh 4.1 with non-contiguous node tags in two blocks, a triangle block to skip and a
/// volume entity with physical tag 3.
const MSH41: &str = "\
$MeshFormat
4.1 0 8
$EndMeshFormat
$Entities
0 0 0 1
7 0 0 0 1 1 1 1 3 0
$EndEntities
$Nodes
2 5 10 50
3 7 0 3
10
30
20
0 0 0
1 0 0
0 1 0
3 7 0 2
50
40
0 0 1
1 1 1
$EndNodes
$Elements
2 3 1 3
2 7 2 1
1 10 30 20
3 7 4 2
2 10 30 20 50
3 30 20 50 40
$EndElements
";

#[test]
fn gmsh41_noncontiguous_tags_and_entity_regions() {
    let mesh = gmsh(MSH41).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(mesh.vertex_count(), 5);
    assert_eq!(mesh.tet_count(), 2);
    assert_eq!(mesh.regions(), [3, 3]);
    // Tags 10, 30, 20, 50, 40 are vertices 0..5 in file order.
    assert_eq!(mesh.positions()[1], Point3::new(1.0, 0.0, 0.0));
    assert_eq!(mesh.positions()[4], Point3::new(1.0, 1.0, 1.0));
    let mut t = mesh.tets()[1];
    t.sort_unstable();
    assert_eq!(t, [1, 2, 3, 4]);
    assert!(mesh.validate().is_ok(), "{}", mesh.validate());
    // Without $Entities the entity tag is the region.
    let mut lines: Vec<&str> = MSH41.lines().collect();
    lines.drain(3..7);
    let mesh = gmsh(&(lines.join("\n") + "\n")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(mesh.regions(), [7, 7]);
}

#[test]
fn gmsh_empty_file() {
    assert_parse_error(gmsh(""), "small.msh", 1, "empty");
    assert_parse_error(gmsh("\n\n"), "small.msh", 3, "empty");
}

#[test]
fn gmsh_not_gmsh() {
    assert_parse_error(gmsh("solid cube\n"), "small.msh", 1, "not a gmsh mesh");
}

#[test]
fn gmsh22_truncated() {
    let text = cube_msh22();
    // 3 + 5 header lines, `$Nodes`, count, 8 nodes (lines 11-18), `$EndNodes` (19),
    // `$Elements` (20), count (21), 3 skipped elements (22-24), tets on lines 25-30.
    let cut = first_lines(&text, 27);
    assert_parse_error(
        gmsh(&cut),
        "small.msh",
        28,
        "unexpected end of file: expected element 7 of 9",
    );
    let cut = first_lines(&text, 14);
    assert_parse_error(gmsh(&cut), "small.msh", 15, "expected node 5 of 8");
    let cut = first_lines(&text, 30);
    assert_parse_error(gmsh(&cut), "small.msh", 31, "`$EndElements`");
    // Cut in the middle of a line.
    let cut = first_lines(&text, 29) + "9 4 2 2 5 10 50";
    assert_parse_error(gmsh(&cut), "small.msh", 30, "line ends early");
}

#[test]
fn gmsh22_wrong_counts() {
    let text = cube_msh22();
    // Node count too large: the section ends early at `$EndNodes` (line 19).
    assert_parse_error(
        gmsh(&with_line(&text, 10, "9")),
        "small.msh",
        19,
        "section ends early: expected node 9 of 9",
    );
    // Node count too small: line 18 holds a node where `$EndNodes` belongs.
    assert_parse_error(
        gmsh(&with_line(&text, 10, "7")),
        "small.msh",
        18,
        "expected `$EndNodes` after 7 nodes",
    );
    // Element count too large / too small.
    assert_parse_error(
        gmsh(&with_line(&text, 21, "10")),
        "small.msh",
        31,
        "expected element 10 of 10",
    );
    assert_parse_error(
        gmsh(&with_line(&text, 21, "8")),
        "small.msh",
        30,
        "expected `$EndElements` after 8 elements",
    );
}

#[test]
fn gmsh22_unknown_node_tag() {
    let text = with_line(&cube_msh22(), 26, "5 4 2 1 5 10 20 60 99");
    assert_parse_error(
        gmsh(&text),
        "small.msh",
        26,
        "element 5 refers to unknown node tag 99",
    );
}

#[test]
fn gmsh22_nan_and_inf_coordinates() {
    let text = with_line(&cube_msh22(), 13, "30 0 nan 0");
    assert_parse_error(
        gmsh(&text),
        "small.msh",
        13,
        "y coordinate is not finite: `nan`",
    );
    let text = with_line(&cube_msh22(), 18, "80 1 1 -inf");
    assert_parse_error(
        gmsh(&text),
        "small.msh",
        18,
        "z coordinate is not finite: `-inf`",
    );
}

#[test]
fn gmsh22_garbage_numbers() {
    let text = with_line(&cube_msh22(), 12, "20 1,0 0 0");
    assert_parse_error(gmsh(&text), "small.msh", 12, "invalid x coordinate `1,0`");
    let text = with_line(&cube_msh22(), 25, "4 4x 2 1 5 10 20 40 80");
    assert_parse_error(gmsh(&text), "small.msh", 25, "invalid element type `4x`");
    let text = with_line(&cube_msh22(), 12, "20 1 0 0 0");
    assert_parse_error(gmsh(&text), "small.msh", 12, "unexpected extra value `0`");
    let text = with_line(&cube_msh22(), 12, "-20 1 0 0");
    assert_parse_error(gmsh(&text), "small.msh", 12, "invalid node tag `-20`");
}

#[test]
fn gmsh22_wrong_element_types() {
    let hex = "5 5 2 1 5 10 20 30 40 50 60 70 80";
    assert_parse_error(
        gmsh(&with_line(&cube_msh22(), 26, hex)),
        "small.msh",
        26,
        "type 5 (a hexahedron)",
    );
    let tet10 = "5 11 2 1 5 10 20 30 40 50 60 70 80 10 20";
    assert_parse_error(
        gmsh(&with_line(&cube_msh22(), 26, tet10)),
        "small.msh",
        26,
        "second-order",
    );
    assert_parse_error(
        gmsh(&with_line(&cube_msh22(), 26, "5 999 0 1 2")),
        "small.msh",
        26,
        "type 999",
    );
}

#[test]
fn gmsh22_no_tetrahedra() {
    let text = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n\
                $EndNodes\n$Elements\n1\n1 2 0 1 2 3\n$EndElements\n";
    assert_format_error(gmsh(text), "small.msh", "no tetrahedra");
}

#[test]
fn gmsh22_missing_sections() {
    let text = first_lines(&cube_msh22(), 19);
    assert_parse_error(
        gmsh(&text),
        "small.msh",
        20,
        "without an `$Elements` section",
    );
    let text = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Elements\n0\n$EndElements\n";
    assert_parse_error(gmsh(text), "small.msh", 4, "before the `$Nodes` section");
    let text = "$MeshFormat\n2.2 0 8\n";
    assert_parse_error(gmsh(text), "small.msh", 3, "`$EndMeshFormat`");
    let text = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Comments\nhello\n";
    assert_parse_error(
        gmsh(text),
        "small.msh",
        6,
        "section `$Comments` (line 4) has no `$EndComments`",
    );
}

#[test]
fn gmsh22_duplicate_and_repeated_tags() {
    let text = with_line(&cube_msh22(), 12, "10 1 0 0");
    assert_parse_error(gmsh(&text), "small.msh", 12, "node tag 10 is defined twice");
    let text = with_line(&cube_msh22(), 25, "4 4 2 1 5 10 20 20 80");
    assert_parse_error(gmsh(&text), "small.msh", 25, "lists node tag 20 twice");
}

#[test]
fn gmsh_binary_and_unsupported_versions() {
    let text = cube_msh22().replace("2.2 0 8", "2.2 1 8");
    assert_parse_error(
        gmsh(&text),
        "small.msh",
        2,
        "binary Gmsh files are not supported",
    );
    let text = MSH41.replace("4.1 0 8", "4 0 8");
    assert_parse_error(
        gmsh(&text),
        "small.msh",
        2,
        "unsupported Gmsh format version 4",
    );
    let text = MSH41.replace("4.1 0 8", "3.0 0 8");
    assert_parse_error(
        gmsh(&text),
        "small.msh",
        2,
        "unsupported Gmsh format version 3.0",
    );
}

#[test]
fn gmsh41_truncated() {
    assert_parse_error(
        gmsh(&first_lines(MSH41, 28)),
        "small.msh",
        29,
        "expected element 2 of 2 in block 2",
    );
    assert_parse_error(
        gmsh(&first_lines(MSH41, 13)),
        "small.msh",
        14,
        "coordinates of node 1 of 3 in block 1",
    );
}

#[test]
fn gmsh41_wrong_counts() {
    assert_parse_error(
        gmsh(&with_line(MSH41, 9, "2 6 10 50")),
        "small.msh",
        9,
        "declares 6 nodes but the blocks hold 5",
    );
    // The block claims 3 nodes but has 2: its third "tag" line is a coordinate line.
    assert_parse_error(
        gmsh(&with_line(MSH41, 17, "3 7 0 3")),
        "small.msh",
        20,
        "unexpected extra value `0`",
    );
    assert_parse_error(
        gmsh(&with_line(MSH41, 24, "2 4 1 3")),
        "small.msh",
        24,
        "declares 4 elements but the blocks hold 3",
    );
    assert_parse_error(
        gmsh(&with_line(MSH41, 27, "3 7 4 3")),
        "small.msh",
        30,
        "section ends early",
    );
}

#[test]
fn gmsh41_unknown_node_tag() {
    assert_parse_error(
        gmsh(&with_line(MSH41, 29, "3 30 20 50 41")),
        "small.msh",
        29,
        "unknown node tag 41",
    );
}

#[test]
fn gmsh41_nan() {
    assert_parse_error(
        gmsh(&with_line(MSH41, 21, "1 NaN 1")),
        "small.msh",
        21,
        "y coordinate is not finite",
    );
}

#[test]
fn gmsh41_wrong_element_type() {
    assert_parse_error(
        gmsh(&with_line(MSH41, 27, "3 7 11 2")),
        "small.msh",
        27,
        "second-order",
    );
    assert_parse_error(
        gmsh(&with_line(MSH41, 27, "3 7 6 2")),
        "small.msh",
        27,
        "a prism",
    );
}

// ---------------------------------------------------------------------------------------
// TetGen

const NODE: &str = "\
# five points, index base 1
5 3 0 1
1 0 0 0 0
2 1 0 0 0
3 0 1 0 1
4 0 0 1 1
5 1 1 1 0   # top
";

const ELE: &str = "\
2 4 1
1 1 2 3 4 2
2 2 4 3 5 5
# generated by hand
";

#[test]
fn generated_tetgen_base_one_with_regions() {
    let mesh = tetgen(NODE, ELE).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(mesh.vertex_count(), 5);
    assert_eq!(mesh.tet_count(), 2);
    assert_eq!(mesh.regions(), [2, 5]);
    assert_eq!(mesh.positions()[4], Point3::new(1.0, 1.0, 1.0));
    let mut t = mesh.tets()[1];
    t.sort_unstable();
    assert_eq!(t, [1, 2, 3, 4]);
    assert!(mesh.validate().is_ok(), "{}", mesh.validate());
}

#[test]
fn generated_tetgen_cube_base_zero_files() {
    let (points, tets) = cube();
    let mut node = format!("{} 3 0 0\n", points.len());
    for (i, p) in points.iter().enumerate() {
        node += &format!("{i} {} {} {}\n", p[0], p[1], p[2]);
    }
    let mut ele = format!("{} 4 1\n", tets.len());
    for (t, tet) in tets.iter().enumerate() {
        ele += &format!(
            "{t} {} {} {} {} {}\n",
            tet[0], tet[1], tet[2], tet[3], CUBE_REGIONS[t]
        );
    }
    let dir = scratch_dir("tetgen");
    std::fs::write(dir.join("cube.1.node"), node).expect("write");
    std::fs::write(dir.join("cube.1.ele"), ele).expect("write");
    assert_cube(
        &read_mesh(&dir.join("cube.1.node")).unwrap_or_else(|e| panic!("{e}")),
        &CUBE_REGIONS,
    );
    assert_cube(
        &read_mesh(&dir.join("cube.1.ele")).unwrap_or_else(|e| panic!("{e}")),
        &CUBE_REGIONS,
    );
    // Without the sibling: an I/O error naming the missing file.
    std::fs::remove_file(dir.join("cube.1.ele")).expect("remove");
    let e = read_mesh(&dir.join("cube.1.node")).expect_err("error");
    assert!(matches!(e, ReadError::Io { .. }));
    assert!(e.to_string().contains("cube.1.ele"), "{e}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn tetgen_empty() {
    assert_parse_error(tetgen("", ELE), "small.node", 1, "the file is empty");
    assert_parse_error(
        tetgen("# only a comment\n", ELE),
        "small.node",
        2,
        "the file is empty",
    );
    assert_parse_error(tetgen(NODE, ""), "small.ele", 1, "the file is empty");
}

#[test]
fn tetgen_truncated() {
    assert_parse_error(
        tetgen(&first_lines(NODE, 6), ELE),
        "small.node",
        7,
        "expected point 5 of 5",
    );
    assert_parse_error(
        tetgen(NODE, &first_lines(ELE, 2)),
        "small.ele",
        3,
        "expected tetrahedron 2 of 2",
    );
    assert_parse_error(
        tetgen(NODE, "2 4 1\n1 1 2 3 4 2\n2 2 4 3"),
        "small.ele",
        3,
        "line ends early",
    );
}

#[test]
fn tetgen_wrong_counts() {
    assert_parse_error(
        tetgen(&with_line(NODE, 2, "4 3 0 1"), ELE),
        "small.node",
        7,
        "more points than the 4 declared on line 2",
    );
    // Six declared: the end of the file comes where point 6 should be.
    assert_parse_error(
        tetgen(&with_line(NODE, 2, "6 3 0 1"), ELE),
        "small.node",
        8,
        "expected point 6 of 6",
    );
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 1, "1 4 1")),
        "small.ele",
        3,
        "more tetrahedra than the 1 declared",
    );
    // Attribute count wrong: the region value becomes an extra value.
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 1, "2 4 0")),
        "small.ele",
        2,
        "unexpected extra value `2`",
    );
}

#[test]
fn tetgen_out_of_range_ids() {
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 3, "2 2 4 3 6 5")),
        "small.ele",
        3,
        "refers to node 6",
    );
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 3, "2 0 4 3 5 5")),
        "small.ele",
        3,
        "refers to node 0, but the .node file has nodes 1..=5",
    );
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 3, "2 2 4 3 -1 5")),
        "small.ele",
        3,
        "refers to node -1",
    );
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 3, "2 2 4 4 5 5")),
        "small.ele",
        3,
        "lists node 4 twice",
    );
}

#[test]
fn tetgen_nan() {
    assert_parse_error(
        tetgen(&with_line(NODE, 5, "3 0 nan 0 1"), ELE),
        "small.node",
        5,
        "y coordinate is not finite",
    );
    assert_parse_error(
        tetgen(&with_line(NODE, 5, "3 0 1 inf 1"), ELE),
        "small.node",
        5,
        "z coordinate is not finite",
    );
}

#[test]
fn tetgen_wrong_element_type() {
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 1, "2 10 1")),
        "small.ele",
        1,
        "second-order",
    );
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 1, "2 3 1")),
        "small.ele",
        1,
        "3 nodes per tetrahedron",
    );
    assert_parse_error(
        tetgen(&with_line(NODE, 2, "5 2 0 1"), ELE),
        "small.node",
        2,
        "dimension 2",
    );
}

#[test]
fn tetgen_numbering_and_garbage() {
    assert_parse_error(
        tetgen(&with_line(NODE, 4, "7 1 0 0 0"), ELE),
        "small.node",
        4,
        "expected 2 (points must be numbered consecutively)",
    );
    assert_parse_error(
        tetgen(&with_line(NODE, 3, "2 0 0 0 0"), ELE),
        "small.node",
        3,
        "first point index is 2",
    );
    assert_parse_error(
        tetgen(&with_line(NODE, 4, "2 1 0 O 0"), ELE),
        "small.node",
        4,
        "invalid z coordinate `O`",
    );
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 2, "1 1 2 3 4 2.5")),
        "small.ele",
        2,
        "region attribute 2.5",
    );
    assert_parse_error(
        tetgen(NODE, &with_line(ELE, 1, "0 4 1")),
        "small.ele",
        1,
        "no tetrahedra",
    );
}

// ---------------------------------------------------------------------------------------
// legacy VTK

/// The cube as legacy VTK: a triangle cell to skip, points wrapped three per line, and a
/// `material` cell array.
fn cube_vtk() -> String {
    let (points, tets) = cube();
    let mut s =
        String::from("# vtk DataFile Version 3.0\ncube\nASCII\nDATASET UNSTRUCTURED_GRID\n");
    s += &format!("POINTS {} double\n", points.len());
    for pair in points.chunks(2) {
        let row: Vec<String> = pair.iter().flatten().map(|c| c.to_string()).collect();
        s += &(row.join(" ") + "\n");
    }
    s += &format!("CELLS {} {}\n3 0 1 2\n", tets.len() + 1, 4 + 5 * tets.len());
    for tet in &tets {
        s += &format!("4 {} {} {} {}\n", tet[0], tet[1], tet[2], tet[3]);
    }
    s += &format!("CELL_TYPES {}\n5\n", tets.len() + 1);
    s += &"10\n".repeat(tets.len());
    s += &format!(
        "CELL_DATA {}\nSCALARS material int 1\nLOOKUP_TABLE default\n0\n",
        tets.len() + 1
    );
    s += &CUBE_REGIONS.map(|r| r.to_string()).join(" ");
    s += "\nPOINT_DATA 8\nVECTORS velocity double\n";
    s += &"0 0 0\n".repeat(8);
    s
}

// Line map of cube_vtk(): 1-4 header, 5 POINTS, 6-9 points, 10 CELLS, 11 triangle,
// 12-17 tets, 18 CELL_TYPES, 19 `5`, 20-25 `10`, 26 CELL_DATA, 27 SCALARS, 28 LOOKUP_TABLE,
// 29 `0`, 30 regions, 31 POINT_DATA, 32 VECTORS, 33-40 vectors.

#[test]
fn generated_legacy_vtk() {
    assert_cube(
        &vtk(&cube_vtk()).unwrap_or_else(|e| panic!("{e}")),
        &CUBE_REGIONS,
    );
}

#[test]
fn legacy_vtk_field_region_and_no_region() {
    let text = cube_vtk().replace(
        "SCALARS material int 1\nLOOKUP_TABLE default\n",
        "FIELD FieldData 2\nweight 1 7 float\n1 1 1 1 1 1 1\ngmsh:physical 1 7 int\n",
    );
    assert_cube(&vtk(&text).unwrap_or_else(|e| panic!("{e}")), &CUBE_REGIONS);
    let text = cube_vtk().replace("SCALARS material int 1", "SCALARS pressure float 1");
    assert_cube(&vtk(&text).unwrap_or_else(|e| panic!("{e}")), &[0; 6]);
}

#[test]
fn legacy_vtk_51_offsets_connectivity() {
    let (points, tets) = cube();
    let mut s =
        String::from("# vtk DataFile Version 5.1\ncube\nASCII\nDATASET UNSTRUCTURED_GRID\n");
    s += &format!("POINTS {} double\n", points.len());
    for p in &points {
        s += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    s += "METADATA\nINFORMATION 0\n\n";
    s += &format!(
        "CELLS {} {}\nOFFSETS vtktypeint64\n",
        tets.len() + 1,
        4 * tets.len()
    );
    s += &(0..=tets.len())
        .map(|i| (4 * i).to_string())
        .collect::<Vec<_>>()
        .join(" ");
    s += "\nCONNECTIVITY vtktypeint64\n";
    for tet in &tets {
        s += &format!("{} {} {} {}\n", tet[0], tet[1], tet[2], tet[3]);
    }
    s += &format!("CELL_TYPES {}\n", tets.len());
    s += &"10\n".repeat(tets.len());
    assert_cube(&vtk(&s).unwrap_or_else(|e| panic!("{e}")), &[0; 6]);
}

#[test]
fn legacy_vtk_empty_and_not_vtk() {
    assert_parse_error(vtk(""), "small.vtk", 1, "the file is empty");
    assert_parse_error(vtk("ply\n"), "small.vtk", 1, "not a legacy VTK file");
}

#[test]
fn legacy_vtk_truncated() {
    let text = cube_vtk();
    assert_parse_error(
        vtk(&first_lines(&text, 8)),
        "small.vtk",
        9,
        "expected point coordinate",
    );
    assert_parse_error(
        vtk(&first_lines(&text, 17)),
        "small.vtk",
        18,
        "without a CELL_TYPES section",
    );
    assert_parse_error(
        vtk(&first_lines(&text, 4)),
        "small.vtk",
        5,
        "without a POINTS section",
    );
    assert_parse_error(
        vtk(&first_lines(&text, 2)),
        "small.vtk",
        3,
        "expected `ASCII` or `BINARY`",
    );
    assert_parse_error(
        vtk(&first_lines(&text, 29)),
        "small.vtk",
        30,
        "expected a region value",
    );
}

#[test]
fn legacy_vtk_wrong_counts() {
    let text = cube_vtk();
    assert_parse_error(
        vtk(&with_line(&text, 10, "CELLS 7 35")),
        "small.vtk",
        10,
        "CELLS declares 35 values but its 7 cells hold 34",
    );
    assert_parse_error(
        vtk(&with_line(&text, 10, "CELLS 7 30")),
        "small.vtk",
        17,
        "more than the 30 values declared on line 10",
    );
    assert_parse_error(
        vtk(&with_line(&text, 18, "CELL_TYPES 6")),
        "small.vtk",
        25,
        "unexpected `10`",
    );
    // Too many points declared: the CELLS keyword is read as a coordinate.
    assert_parse_error(
        vtk(&with_line(&text, 5, "POINTS 9 double")),
        "small.vtk",
        10,
        "invalid point coordinate `CELLS`",
    );
    // Too few region values declared: the last one is left over as a keyword.
    assert_parse_error(
        vtk(&with_line(&text, 26, "CELL_DATA 6")),
        "small.vtk",
        30,
        "unexpected `2`",
    );
}

#[test]
fn legacy_vtk_out_of_range_point() {
    let text = with_line(&cube_vtk(), 14, "4 0 2 3 8");
    assert_parse_error(
        vtk(&text),
        "small.vtk",
        14,
        "cell 3 refers to point 8, but there are 8 points",
    );
    let text = with_line(&cube_vtk(), 14, "4 0 2 3 -7");
    assert_parse_error(vtk(&text), "small.vtk", 14, "invalid point id `-7`");
    let text = with_line(&cube_vtk(), 14, "3 0 2 3");
    let text = text.replace("CELLS 7 34", "CELLS 7 33");
    assert_parse_error(
        vtk(&text),
        "small.vtk",
        14,
        "cell 3 is a tetrahedron (type 10) but has 3 points",
    );
}

#[test]
fn legacy_vtk_nan() {
    let text = with_line(&cube_vtk(), 7, "0 1 0 NaN 1 0");
    assert_parse_error(
        vtk(&text),
        "small.vtk",
        7,
        "point coordinate is not finite: `NaN`",
    );
    let text = with_line(&cube_vtk(), 9, "0 1 1 1 inf 1");
    assert_parse_error(vtk(&text), "small.vtk", 9, "not finite: `inf`");
}

#[test]
fn legacy_vtk_wrong_cell_type() {
    assert_parse_error(
        vtk(&with_line(&cube_vtk(), 21, "12")),
        "small.vtk",
        21,
        "cell 2 has VTK cell type 12 (a hexahedron)",
    );
    assert_parse_error(
        vtk(&with_line(&cube_vtk(), 21, "24")),
        "small.vtk",
        21,
        "a quadratic tetrahedron",
    );
    assert_parse_error(
        vtk(&with_line(&cube_vtk(), 4, "DATASET POLYDATA")),
        "small.vtk",
        4,
        "only DATASET UNSTRUCTURED_GRID",
    );
    assert_parse_error(
        vtk(&with_line(&cube_vtk(), 3, "BINARY")),
        "small.vtk",
        3,
        "binary legacy VTK files are not supported",
    );
}

#[test]
fn legacy_vtk_garbage_and_bad_regions() {
    assert_parse_error(
        vtk(&with_line(&cube_vtk(), 8, "0 1 0 1 1 O")),
        "small.vtk",
        8,
        "invalid point coordinate `O`",
    );
    assert_parse_error(
        vtk(&with_line(&cube_vtk(), 30, "1 1 1 2 -2 2")),
        "small.vtk",
        30,
        "region value `-2`",
    );
    assert_parse_error(
        vtk(&with_line(&cube_vtk(), 19, "five")),
        "small.vtk",
        19,
        "invalid cell type `five`",
    );
}

#[test]
fn legacy_vtk_no_tetrahedra() {
    let text = "# vtk DataFile Version 3.0\nt\nASCII\nDATASET UNSTRUCTURED_GRID\nPOINTS 3 float\n\
                0 0 0 1 0 0 0 1 0\nCELLS 1 4\n3 0 1 2\nCELL_TYPES 1\n5\n";
    assert_format_error(vtk(text), "small.vtk", "no tetrahedra");
}

// ---------------------------------------------------------------------------------------
// .vtu

fn cube_mesh() -> TetMesh {
    let (points, tets) = cube();
    let positions = points
        .iter()
        .map(|p| Point3::new(p[0], p[1], p[2]))
        .collect();
    let tets = tets.iter().map(|t| t.map(|v| v as u32)).collect();
    let mut mesh = TetMesh::new(positions, tets, CUBE_REGIONS.to_vec()).expect("cube");
    mesh.orient_positively();
    mesh
}

/// A hand-written `.vtu` in the style of ParaView: an `<InformationKey>` inside the points
/// array, a leading-0 offsets array, a triangle and a `MaterialID` cell array.
const VTU: &str = r#"<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">
  <UnstructuredGrid>
    <Piece NumberOfPoints="5" NumberOfCells="3">
      <PointData>
        <DataArray type="Float32" Name="temperature" format="ascii">1 2 3 4 5</DataArray>
      </PointData>
      <CellData>
        <DataArray type="Int32" Name="MaterialID" format="ascii">0 4 9</DataArray>
      </CellData>
      <Points>
        <DataArray type="Float64" NumberOfComponents="3" format="ascii">
          <InformationKey name="L2_NORM_RANGE" location="vtkDataArray" length="2">
            <Value index="0">0</Value>
          </InformationKey>
          0 0 0
          1 0 0
          0 1 0
          0 0 1
          1 1 1
        </DataArray>
      </Points>
      <Cells>
        <DataArray type="Int64" Name="connectivity" format="ascii">
          0 1 2
          0 2 1 3
          1 2 3 4
        </DataArray>
        <DataArray type="Int64" Name="offsets" format="ascii">0 3 7 11</DataArray>
        <DataArray type="UInt8" Name="types" format="ascii">
          5
          10
          10
        </DataArray>
      </Cells>
    </Piece>
  </UnstructuredGrid>
</VTKFile>
"#;

#[test]
fn handwritten_vtu() {
    let mesh = vtu(VTU).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(mesh.vertex_count(), 5);
    assert_eq!(mesh.tet_count(), 2);
    assert_eq!(mesh.regions(), [4, 9]);
    assert!(mesh.validate().is_ok(), "{}", mesh.validate());
}

#[test]
fn vtu_writer_output_reads_back() {
    let mesh = cube_mesh();
    let v: Vec<Vector3> = (0..8)
        .map(|i| Vector3::new(i as f64, 0.5, -1e-300))
        .collect();
    let s: Vec<f64> = (0..8).map(|i| 0.1 * i as f64).collect();
    let text = vtu_string(
        &mesh,
        &[
            ("velocity", PointData::Vector(&v)),
            ("p<&>", PointData::Scalar(&s)),
        ],
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(text.contains(r#"Name="velocity" NumberOfComponents="3""#));
    assert!(text.contains(r#"Name="p&lt;&amp;&gt;""#));
    assert!(text.contains(r#"Name="region""#));
    assert_cube(&vtu(&text).unwrap_or_else(|e| panic!("{e}")), &CUBE_REGIONS);
}

#[test]
fn vtu_writer_refuses_bad_point_data() {
    let mesh = cube_mesh();
    let short = [0.0; 7];
    let e = vtu_string(&mesh, &[("p", PointData::Scalar(&short))]).err();
    assert!(
        matches!(
            e,
            Some(WriteError::Length {
                len: 7,
                vertices: 8,
                ..
            })
        ),
        "{e:?}"
    );
    let mut nan = [0.0; 8];
    nan[3] = f64::NAN;
    let e = vtu_string(&mesh, &[("p", PointData::Scalar(&nan))]).err();
    assert!(
        matches!(e, Some(WriteError::NonFinite { vertex: 3, .. })),
        "{e:?}"
    );
    let ok = [0.0; 8];
    let e = vtu_string(
        &mesh,
        &[("p", PointData::Scalar(&ok)), ("p", PointData::Scalar(&ok))],
    )
    .err();
    assert!(matches!(e, Some(WriteError::Name { .. })), "{e:?}");
    let e = write_vtu(Path::new("/nonexistent/cutlab/out.vtu"), &mesh, &[]).expect_err("error");
    assert!(e.to_string().contains("/nonexistent/cutlab/out.vtu"), "{e}");
}

#[test]
fn vtu_empty_and_not_vtk() {
    assert_parse_error(vtu(""), "small.vtu", 1, "no <VTKFile> element");
    assert_parse_error(
        vtu("<?xml version=\"1.0\"?>\n<html/>\n"),
        "small.vtu",
        2,
        "root element is <html>",
    );
    let text = VTU.replace(
        r#"type="UnstructuredGrid" version"#,
        r#"type="PolyData" version"#,
    );
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        2,
        "only VTKFile type=\"UnstructuredGrid\"",
    );
}

#[test]
fn vtu_truncated() {
    assert_parse_error(
        vtu(&first_lines(VTU, 18)),
        "small.vtu",
        19,
        "inside <DataArray> (opened on line 12)",
    );
    assert_parse_error(
        vtu(&first_lines(VTU, 23)),
        "small.vtu",
        24,
        "inside <Cells> (opened on line 23)",
    );
    // A Piece without cells.
    let mut lines: Vec<&str> = VTU.lines().collect();
    lines.drain(22..35);
    let text = lines.join("\n") + "\n";
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        23,
        "the <Piece> on line 4 has no `connectivity` array",
    );
}

#[test]
fn vtu_wrong_counts() {
    let text = VTU.replace(r#"NumberOfPoints="5""#, r#"NumberOfPoints="6""#);
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        12,
        "the Points array has 15 values, expected 3 x NumberOfPoints = 3 x 6",
    );
    let text = VTU.replace(r#"NumberOfCells="3""#, r#"NumberOfCells="4""#);
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        9,
        "cell array `MaterialID` has 3 values, expected NumberOfCells = 4",
    );
    let text = VTU.replace("0 3 7 11", "3 7 12");
    assert_parse_error(vtu(&text), "small.vtu", 29, "invalid offset 12");
    let text = VTU.replace(r#"NumberOfPoints="5""#, r#"NumberOfPoints="many""#);
    assert_parse_error(vtu(&text), "small.vtu", 4, "invalid NumberOfPoints `many`");
}

#[test]
fn vtu_out_of_range_point() {
    let text = VTU.replace("1 2 3 4\n", "1 2 3 5\n");
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        27,
        "cell 2 refers to point 5, but there are 5 points",
    );
}

#[test]
fn vtu_nan() {
    let text = VTU.replace("0 0 1\n", "0 nan 1\n");
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        19,
        "point coordinate is not finite: `nan`",
    );
}

#[test]
fn vtu_wrong_cell_type() {
    let mut lines: Vec<&str> = VTU.lines().collect();
    lines[32] = "          12";
    let text = lines.join("\n") + "\n";
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        33,
        "cell 2 has VTK cell type 12 (a hexahedron)",
    );
}

#[test]
fn vtu_binary_and_appended_unsupported() {
    let text = VTU.replace(
        r#"Name="offsets" format="ascii""#,
        r#"Name="offsets" format="binary""#,
    );
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        29,
        "binary and appended .vtu data are not supported",
    );
    let text = VTU.replace(
        "  </UnstructuredGrid>\n",
        "  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">_</AppendedData>\n",
    );
    assert_parse_error(vtu(&text), "small.vtu", 38, "appended data");
}

#[test]
fn vtu_malformed_xml() {
    let text = VTU.replace("</Points>", "</Pointz>");
    assert_parse_error(vtu(&text), "small.vtu", 22, "malformed XML");
}

// ---------------------------------------------------------------------------------------
// round trip

#[test]
fn bar_651_round_trip_through_vtu() {
    let mesh = read_data("ipc/bar-651.msh");
    let displacement: Vec<Vector3> = mesh
        .positions()
        .iter()
        .map(|p| Vector3::new(0.0, 0.0, -1e-3 * p.x * p.x / 3.0))
        .collect();
    let speed: Vec<f64> = mesh.positions().iter().map(|p| p.x.sqrt() / 7.0).collect();
    let dir = scratch_dir("roundtrip");
    let path = dir.join("bar-651.vtu");
    write_vtu(
        &path,
        &mesh,
        &[
            ("displacement", PointData::Vector(&displacement)),
            ("speed", PointData::Scalar(&speed)),
        ],
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let back = read_mesh(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back.vertex_count(), mesh.vertex_count());
    for (a, b) in mesh.positions().iter().zip(back.positions()) {
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
    }
    assert_eq!(back.tets(), mesh.tets());
    assert_eq!(back.regions(), mesh.regions());
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn round_trip_keeps_awkward_floats_and_regions() {
    let mut mesh = cube_mesh();
    for (i, p) in mesh.positions_mut().iter_mut().enumerate() {
        *p = Point3::new(p.x + 0.1 * i as f64, p.y * (1.0 + 1e-15), p.z * 1e-7 - 0.0);
    }
    let text = vtu_string(&mesh, &[]).unwrap_or_else(|e| panic!("{e}"));
    let back = vtu(&text).unwrap_or_else(|e| panic!("{e}"));
    for (a, b) in mesh.positions().iter().zip(back.positions()) {
        assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
    }
    assert_eq!(back.tets(), mesh.tets());
    assert_eq!(back.regions(), CUBE_REGIONS);
}

// ---------------------------------------------------------------------------------------
// robustness: no input may make a reader panic

/// Every reader on `text` (TetGen with `text` as either file), ignoring the result.
fn read_all_ways(text: &str) {
    let _ = gmsh(text);
    let _ = vtk(text);
    let _ = vtu(text);
    let _ = tetgen(text, ELE);
    let _ = tetgen(NODE, text);
}

fn samples() -> Vec<String> {
    vec![
        cube_msh22(),
        MSH41.to_owned(),
        NODE.to_owned(),
        ELE.to_owned(),
        cube_vtk(),
        VTU.to_owned(),
    ]
}

#[test]
fn truncation_anywhere_never_panics() {
    for sample in samples() {
        for (cut, _) in sample.char_indices() {
            read_all_ways(&sample[..cut]);
        }
    }
}

#[test]
fn random_corruption_never_panics() {
    // A fixed linear congruential generator: deterministic, no extra dependency.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = move |n: usize| {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((state >> 33) as usize) % n.max(1)
    };
    const REPLACEMENTS: [&str; 14] = [
        "",
        " ",
        "\n",
        "0",
        "-1",
        "99",
        "1e309",
        "nan",
        "18446744073709551615",
        "$End",
        "<",
        "\"",
        "x",
        "4",
    ];
    for sample in samples() {
        for _ in 0..1500 {
            let mut text = sample.clone();
            for _ in 0..1 + next(3) {
                let bytes = text.as_bytes();
                let mut at = next(bytes.len());
                while !text.is_char_boundary(at) {
                    at -= 1;
                }
                let len = next(6).min(text.len() - at);
                let mut end = at + len;
                while !text.is_char_boundary(end) {
                    end -= 1;
                }
                text.replace_range(at..end, REPLACEMENTS[next(REPLACEMENTS.len())]);
            }
            read_all_ways(&text);
        }
    }
}

#[test]
fn huge_counts_do_not_allocate_or_panic() {
    let text = cube_msh22().replace("$Nodes\n8\n", "$Nodes\n18446744073709551615\n");
    assert_parse_error(gmsh(&text), "small.msh", 19, "section ends early");
    let text = with_line(MSH41, 9, "18446744073709551615 18446744073709551615 10 50");
    assert_parse_error(gmsh(&text), "small.msh", 22, "section ends early");
    let text = with_line(&cube_vtk(), 5, "POINTS 18446744073709551615 double");
    assert_parse_error(
        vtk(&text),
        "small.vtk",
        10,
        "invalid point coordinate `CELLS`",
    );
    let text = VTU.replace(
        r#"NumberOfCells="3""#,
        r#"NumberOfCells="18446744073709551615""#,
    );
    assert_parse_error(
        vtu(&text),
        "small.vtu",
        9,
        "has 3 values, expected NumberOfCells = 18446744073709551615",
    );
    let text = with_line(NODE, 2, "18446744073709551615 3 0 1");
    assert_parse_error(
        tetgen(&text, ELE),
        "small.node",
        8,
        "expected point 6 of 18446744073709551615",
    );
}

// ---------------------------------------------------------------------------------------
// lenient reading: unused vertices dropped, undeclared TetGen values ignored, with notes

/// The [`cube`] with unused vertices inserted before vertices 0, 3 and after the last (at
/// file places 0, 4 and 10), as a [`TetMesh`] to write.
fn cube_with_unused_vertices() -> TetMesh {
    let (points, tets) = cube();
    let unused = Point3::new(5.0, 5.0, 5.0);
    let mut positions = vec![unused];
    let mut place = Vec::new();
    for (i, p) in points.iter().enumerate() {
        if i == 3 {
            positions.push(unused);
        }
        place.push(positions.len() as u32);
        positions.push(Point3::new(p[0], p[1], p[2]));
    }
    positions.push(unused);
    let tets = tets.iter().map(|t| t.map(|v| place[v])).collect();
    TetMesh::new(positions, tets, CUBE_REGIONS.to_vec()).expect("mesh")
}

#[test]
fn vtu_with_unused_vertices_loads_without_them_and_says_so() {
    let text = vtu_string(&cube_with_unused_vertices(), &[]).expect("vtu");
    let read = read_mesh_from_str_noting(&text, MeshFormat::Vtu, Path::new("small.vtu"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_cube(&read.mesh, &CUBE_REGIONS);
    assert_eq!(
        read.notes,
        [ReadNote::UnusedVertices {
            path: PathBuf::from("small.vtu"),
            count: 3,
            first: 0,
        }]
    );
    assert!(read.notes[0].to_string().contains("dropped 3 vertices"));
    // the plain reader drops them too
    assert_cube(&vtu(&text).unwrap_or_else(|e| panic!("{e}")), &CUBE_REGIONS);
}

#[test]
fn gmsh_with_unused_nodes_loads_without_them_and_says_so() {
    // two nodes of no tetrahedron (tags 5 and 90), one of them also a point element's
    let msh = cube_msh22()
        .replacen("$Nodes\n8\n", "$Nodes\n10\n5 9 9 9\n", 1)
        .replacen("$EndNodes", "90 -1 -1 -1\n$EndNodes", 1)
        .replacen("1 15 2 0 1 10\n", "1 15 2 0 1 5\n", 1);
    let read = read_mesh_from_str_noting(&msh, MeshFormat::Gmsh, Path::new("small.msh"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_cube(&read.mesh, &CUBE_REGIONS);
    assert!(
        matches!(
            read.notes[..],
            [ReadNote::UnusedVertices {
                count: 2,
                first: 0,
                ..
            }]
        ),
        "{:?}",
        read.notes
    );
    // a file that uses every node gives no note
    let read = read_mesh_from_str_noting(&cube_msh22(), MeshFormat::Gmsh, Path::new("c.msh"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(read.notes.is_empty(), "{:?}", read.notes);
}

#[test]
fn a_scene_whose_mesh_file_has_unused_vertices_loads_with_a_note() {
    use cutlab_sim::scene::{BuildOptions, Scene};
    let dir = scratch_dir("unused");
    write_vtu(&dir.join("cube.vtu"), &cube_with_unused_vertices(), &[]).expect("write");
    let scene_path = dir.join("cube.toml");
    std::fs::write(
        &scene_path,
        r#"
name = "cube"

[mesh]
kind = "file"
path = "cube.vtu"

[[materials]]
region = 1
density_kg_per_m3 = 900.0
stiffness = { uniform = { newtons_per_metre = 100.0 } }
damping_newton_seconds_per_metre = 0.05
pretension = 0.04

[[materials]]
region = 2
density_kg_per_m3 = 900.0
stiffness = { uniform = { newtons_per_metre = 100.0 } }
damping_newton_seconds_per_metre = 0.05
pretension = 0.04

[[held]]
kind = "box"
min_mm = [-1.0, -1.0, -1.0]
max_mm = [2000.0, 2000.0, 1.0]
"#,
    )
    .expect("write scene");
    // (before, the unused vertices had no mass: the model refused them)
    let scene = Scene::load(scene_path.to_str().expect("utf-8"), BuildOptions::default())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.model.vertex_count(), 8);
    assert!(
        matches!(
            scene.read_notes[..],
            [ReadNote::UnusedVertices { count: 3, .. }]
        ),
        "{:?}",
        scene.read_notes
    );
    let mut sim = scene.simulation();
    sim.step().expect("step");
    // read_mesh_noting on the file says the same
    let read = read_mesh_noting(&dir.join("cube.vtu")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(read.notes, scene.read_notes);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn tetgen_node_values_past_the_declared_ones_are_ignored_with_a_note() {
    // no attribute nor marker declared, yet lines 3 to 6 carry an attribute and a marker
    let node = "\
5 3 0 0
1 0 0 0
2 1 0 0 0.5 1
3 0 1 0 0.5 1
4 0 0 1 0.5 0
5 1 1 1 0.5 0
";
    let read_node = |node: &str| {
        let mut notes = Vec::new();
        let dir = scratch_dir("tetgen-extra");
        std::fs::write(dir.join("m.node"), node).expect("write");
        std::fs::write(dir.join("m.ele"), ELE).expect("write");
        let read = read_mesh_noting(&dir.join("m.ele"));
        std::fs::remove_dir_all(&dir).ok();
        if let Ok(read) = &read {
            notes.clone_from(&read.notes);
        }
        (read.map(|r| r.mesh), notes)
    };
    let (mesh, notes) = read_node(node);
    let mesh = mesh.unwrap_or_else(|e| panic!("{e}"));
    let expected = tetgen(NODE, ELE).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(mesh.positions(), expected.positions());
    assert_eq!(mesh.tets(), expected.tets());
    // one note: four lines from line 3 on carried values the header does not declare
    let extra_from_line_3 = |notes: &[ReadNote]| {
        matches!(
            notes,
            [ReadNote::ExtraNodeValues {
                lines: 4,
                first_line: 3,
                ..
            }]
        )
    };
    assert!(extra_from_line_3(&notes), "{notes:?}");
    assert!(notes[0].to_string().contains("m.node:3:"), "{}", notes[0]);
    // one attribute declared, a marker beyond it: the marker is ignored
    let (mesh, notes) = read_node(&node.replacen("5 3 0 0", "5 3 1 0", 1).replacen(
        "1 0 0 0\n",
        "1 0 0 0 0.5\n",
        1,
    ));
    assert_eq!(
        mesh.unwrap_or_else(|e| panic!("{e}")).positions(),
        expected.positions()
    );
    assert!(extra_from_line_3(&notes), "{notes:?}");
    // what is not a number is still an error
    assert_parse_error(
        tetgen(&with_line(NODE, 4, "2 1 0 0 0 x"), ELE),
        "small.node",
        4,
        "invalid trailing value",
    );
    // the plain reader reads the same mesh
    assert_eq!(
        tetgen(node, ELE)
            .unwrap_or_else(|e| panic!("{e}"))
            .positions(),
        expected.positions()
    );
}
