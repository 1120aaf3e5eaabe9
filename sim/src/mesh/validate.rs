//! Mesh validation: geometry and conformity problems, each reported with element ids.

use std::fmt;

use super::{TetId, TetMesh, VertexId, triangle_normal};
use crate::{Point3, Vector3};

/// Tetrahedra whose normalised volume `6 sqrt(2) V / l_rms^3` (1 for a regular tetrahedron)
/// is below this magnitude count as degenerate.
pub const DEGENERATE_QUALITY: f64 = 1e-8;

/// What [`TetMesh::validate`] found. Empty lists mean no problem of that kind.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct ValidationReport {
    /// Tetrahedra with negative signed volume.
    pub inverted_tets: Vec<TetId>,
    /// Tetrahedra with (near-)zero volume relative to their size.
    pub degenerate_tets: Vec<TetId>,
    /// Faces (sorted vertex triples) shared by more than two tetrahedra.
    pub overshared_faces: Vec<[VertexId; 3]>,
    /// Boundary triangles that lie inside the interior, on top of another boundary face that
    /// does not match them vertex for vertex (a T-junction / hanging node).
    pub hanging_faces: Vec<[VertexId; 3]>,
    /// Vertices used by no tetrahedron.
    pub dangling_vertices: Vec<VertexId>,
    /// Vertices with a NaN or infinite coordinate.
    pub non_finite_vertices: Vec<VertexId>,
}

impl ValidationReport {
    /// True when no problem was found.
    pub fn is_ok(&self) -> bool {
        self.inverted_tets.is_empty()
            && self.degenerate_tets.is_empty()
            && self.overshared_faces.is_empty()
            && self.hanging_faces.is_empty()
            && self.dangling_vertices.is_empty()
            && self.non_finite_vertices.is_empty()
    }
}

fn list<T: fmt::Debug>(f: &mut fmt::Formatter<'_>, what: &str, items: &[T]) -> fmt::Result {
    if items.is_empty() {
        return Ok(());
    }
    const SHOWN: usize = 10;
    write!(f, "{} {what}: ", items.len())?;
    for (i, it) in items.iter().take(SHOWN).enumerate() {
        if i > 0 {
            write!(f, ", ")?;
        }
        write!(f, "{it:?}")?;
    }
    if items.len() > SHOWN {
        write!(f, ", ...")?;
    }
    writeln!(f)
}

impl fmt::Display for ValidationReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_ok() {
            return writeln!(f, "mesh is valid");
        }
        list(f, "inverted tetrahedra", &self.inverted_tets)?;
        list(f, "degenerate tetrahedra", &self.degenerate_tets)?;
        list(
            f,
            "faces shared by more than two tetrahedra",
            &self.overshared_faces,
        )?;
        list(f, "hanging faces", &self.hanging_faces)?;
        list(f, "dangling vertices", &self.dangling_vertices)?;
        list(
            f,
            "vertices with non-finite coordinates",
            &self.non_finite_vertices,
        )
    }
}

pub(super) fn validate(mesh: &TetMesh) -> ValidationReport {
    let mut r = ValidationReport::default();
    let pos = mesh.positions();
    for (v, p) in pos.iter().enumerate() {
        if !p.iter().all(|c| c.is_finite()) {
            r.non_finite_vertices.push(v as VertexId);
        }
    }
    let topo = mesh.topology();
    for v in 0..mesh.vertex_count() {
        if topo.vertex_tets.row(v).is_empty() {
            r.dangling_vertices.push(v as VertexId);
        }
    }
    for (t, tet) in mesh.tets().iter().enumerate() {
        if tet
            .iter()
            .any(|&v| !pos[v as usize].iter().all(|c| c.is_finite()))
        {
            continue; // already reported through its vertices
        }
        let vol = mesh.tet_volume(t);
        let p = mesh.tet_corners(t);
        let l2: f64 = super::TET_EDGES
            .iter()
            .map(|&[i, j]| (p[i] - p[j]).norm_squared())
            .sum::<f64>()
            / 6.0;
        let q = 6.0 * std::f64::consts::SQRT_2 * vol / l2.powf(1.5);
        // NaN quality (e.g. all corners coincide) counts as degenerate.
        if q.is_nan() || q.abs() < DEGENERATE_QUALITY {
            r.degenerate_tets.push(t as TetId);
        } else if vol < 0.0 {
            r.inverted_tets.push(t as TetId);
        }
    }
    r.overshared_faces = topo.overshared_faces.clone();
    r.hanging_faces = hanging_faces(mesh);
    r
}

/// Finds boundary triangles that lie on top of another boundary triangle with the opposite
/// normal, inside the body, without matching it vertex for vertex, where the surface does not
/// close up (an edge of the triangle is not shared by exactly two boundary triangles). That is
/// a T-junction: a hanging node on an edge or face. The two sides of a cut lie on top of each
/// other too, but each side is a closed surface, so they are not reported.
fn hanging_faces(mesh: &TetMesh) -> Vec<[VertexId; 3]> {
    let topo = mesh.topology();
    let open_edges: std::collections::BTreeSet<[u32; 2]> =
        topo.boundary_non_manifold_edges().into_iter().collect();
    if open_edges.is_empty() {
        return Vec::new();
    }
    let is_open = |t: &[u32; 3]| {
        (0..3).any(|k| {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            open_edges.contains(&[a.min(b), a.max(b)])
        })
    };
    let pos = mesh.positions();
    let tris = &topo.boundary;
    if tris.is_empty() {
        return Vec::new();
    }
    let finite = |t: &[u32; 3]| {
        t.iter()
            .all(|&v| pos[v as usize].iter().all(|c| c.is_finite()))
    };
    // Grid over boundary triangles with cells of the mean boundary edge length.
    let mut mean_len = 0.0;
    let mut n = 0usize;
    for t in tris.iter().filter(|t| finite(t)) {
        mean_len += (pos[t[0] as usize] - pos[t[1] as usize]).norm();
        n += 1;
    }
    if n == 0 {
        return Vec::new();
    }
    mean_len /= n as f64;
    if mean_len.is_nan() || mean_len <= 0.0 {
        return Vec::new();
    }
    let cell = |p: &Point3| -> [i64; 3] { [0, 1, 2].map(|k| (p[k] / mean_len).floor() as i64) };
    let mut entries: Vec<([i64; 3], u32)> = Vec::new();
    for (i, t) in tris.iter().enumerate() {
        if !finite(t) {
            continue;
        }
        let ps = t.map(|v| pos[v as usize]);
        let lo = cell(&ps[0].inf(&ps[1]).inf(&ps[2]));
        let hi = cell(&ps[0].sup(&ps[1]).sup(&ps[2]));
        if (0..3).map(|k| hi[k] - lo[k] + 1).product::<i64>() > 4096 {
            continue; // an enormous triangle relative to the mesh; skip rather than blow up
        }
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    entries.push(([x, y, z], i as u32));
                }
            }
        }
    }
    entries.sort_unstable();
    let tol = 1e-9 * mean_len;
    let mut hanging = vec![false; tris.len()];
    let mut i = 0;
    while i < entries.len() {
        let mut j = i;
        while j < entries.len() && entries[j].0 == entries[i].0 {
            j += 1;
        }
        for a in i..j {
            for b in i..j {
                let (ta, tb) = (entries[a].1 as usize, entries[b].1 as usize);
                if ta != tb
                    && !hanging[ta]
                    && (is_open(&tris[ta]) || is_open(&tris[tb]))
                    && covers(pos, &tris[tb], &tris[ta], tol)
                {
                    hanging[ta] = true;
                    hanging[tb] = true;
                }
            }
        }
        i = j;
    }
    tris.iter()
        .zip(&hanging)
        .filter(|(_, h)| **h)
        .map(|(t, _)| *t)
        .collect()
}

/// True when triangle `small` lies in the plane of `big` with opposite normal, its centroid
/// inside `big`, and its vertices do not all coincide with vertices of `big`.
fn covers(pos: &[Point3], big: &[u32; 3], small: &[u32; 3], tol: f64) -> bool {
    let pb = big.map(|v| pos[v as usize]);
    let ps = small.map(|v| pos[v as usize]);
    let nb = triangle_normal(&pb[0], &pb[1], &pb[2]);
    let ns = triangle_normal(&ps[0], &ps[1], &ps[2]);
    let (lb, ls) = (nb.norm(), ns.norm());
    if lb == 0.0 || ls == 0.0 || nb.dot(&ns) > -0.999_999 * lb * ls {
        return false;
    }
    let n = nb / lb;
    if ps.iter().any(|p| (p - pb[0]).dot(&n).abs() > tol) {
        return false;
    }
    let c = Point3::from((ps[0].coords + ps[1].coords + ps[2].coords) / 3.0);
    if !inside_triangle(&pb, &n, &c, tol) {
        return false;
    }
    let coincident = ps.iter().all(|p| pb.iter().any(|q| (p - q).norm() <= tol));
    !coincident
}

fn inside_triangle(t: &[Point3; 3], n: &Vector3, p: &Point3, tol: f64) -> bool {
    (0..3).all(|k| {
        let (a, b) = (t[k], t[(k + 1) % 3]);
        (b - a).cross(&(p - a)).dot(n) >= -tol * (b - a).norm()
    })
}
