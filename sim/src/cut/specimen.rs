//! Specimens: the pieces a cut frees from the tissue.
//!
//! When a cut leaves a piece that holds no held vertex apart from the held tissue, and the
//! piece is larger than a fragment ([`super::CutOptions::fragment_volume_m3`]), the piece is
//! taken out of the wound as a surgeon's forceps would: its particles are moved by the lift
//! given to the cut and aside by the piece's width and as much again (so that the wound stays
//! in view from above), and held there. Nothing joins it to the tissue (the cut split every vertex
//! between them), so the tissue feels nothing of it; it stays in the mesh, with its mass, so
//! the vertex and tetrahedron ids of the recording and the replay are kept, and the cut's
//! event lists it (its tetrahedra, vertices, volume and surface) for whoever reads its shape.
//!
//! A grasper's jaws do not anchor the tissue: a piece held only by them is freed as well
//! (the disc of FLS pattern cutting, held in the grasper as the scissors finish the circle),
//! and stays in the jaws where it is ([`Specimen::in_jaws`]). Only a piece joined to the held
//! tissue before the cut is freed by it: one freed earlier (in the jaws, or let go of since)
//! is not freed again, whether a cut passes elsewhere or through it.

use serde::{Deserialize, Serialize};

use crate::mesh::{TET_FACES, TetMesh, has_free_piece, pieces, sorted_triple};
use crate::{Point3, Vector3};

/// A piece a cut freed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Specimen {
    /// Its tetrahedra, ascending.
    pub tets: Vec<u32>,
    /// Its vertices, ascending.
    pub vertices: Vec<u32>,
    /// Its volume at rest, m^3.
    pub volume_m3: f64,
    /// Its surface at rest (the outer surface and the cut's), m^2.
    pub surface_m2: f64,
    /// How far it was lifted out of the wound, m.
    pub lift_m: [f64; 3],
    /// A grasper's jaws held it when it was freed: it stays in them, where it was, instead
    /// of being lifted aside (`lift_m` is zero); whoever holds the grasp takes it into the
    /// jaws whole (`Grasp::take_hold_of`), and a later cut does not free it again.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub in_jaws: bool,
}

/// The pieces of `mesh` no vertex of which is `held`, of at least `min_volume_m3`, while
/// another piece is held (a free-floating body frees nothing); each to be lifted by `lift_m`
/// and moved aside (see [`aside`]).
pub(super) fn freed(
    mesh: &TetMesh,
    held: &[bool],
    min_volume_m3: f64,
    lift_m: Vector3,
) -> Vec<Specimen> {
    if !has_free_piece(mesh, held) {
        return Vec::new();
    }
    let all = pieces(mesh, held);
    let Some(body) = all.iter().find(|p| p.held) else {
        return Vec::new();
    };
    let body_centre = centroid(mesh, &vertices_of(mesh, &body.tets));
    all.iter()
        .filter(|p| !p.held && p.volume_m3 >= min_volume_m3)
        .map(|p| {
            let vertices = vertices_of(mesh, &p.tets);
            Specimen {
                surface_m2: surface_m2(mesh, &p.tets),
                lift_m: aside(mesh, &vertices, body_centre, lift_m).into(),
                tets: p.tets.clone(),
                vertices,
                volume_m3: p.volume_m3,
                in_jaws: false,
            }
        })
        .collect()
}

/// The vertices of `tets`, ascending.
fn vertices_of(mesh: &TetMesh, tets: &[u32]) -> Vec<u32> {
    let mut vertices: Vec<u32> = tets.iter().flat_map(|&t| mesh.tets()[t as usize]).collect();
    vertices.sort_unstable();
    vertices.dedup();
    vertices
}

/// The mean rest position of `vertices`.
fn centroid(mesh: &TetMesh, vertices: &[u32]) -> Point3 {
    let sum: Vector3 = vertices
        .iter()
        .map(|&v| mesh.positions()[v as usize].coords)
        .sum();
    Point3::from(sum / vertices.len().max(1) as f64)
}

/// Where a specimen of `vertices` goes: `lift_m` out of the wound, and as far again plus its
/// own width aside (across the lift, away from the tissue's centre `body_centre`, or along
/// any direction across the lift when it lies over that centre), so that the wound stays in
/// view from above. Nothing when `lift_m` is zero.
fn aside(mesh: &TetMesh, vertices: &[u32], body_centre: Point3, lift_m: Vector3) -> Vector3 {
    let lift = lift_m.norm();
    if !(lift > 0.0) {
        return Vector3::zeros();
    }
    let up = lift_m / lift;
    let across = |d: Vector3| d - up * up.dot(&d);
    let centre = centroid(mesh, vertices);
    let width = vertices
        .iter()
        .map(|&v| across(mesh.positions()[v as usize] - centre).norm())
        .fold(0.0, f64::max);
    let away = across(centre - body_centre);
    let side = if away.norm() > 1e-3 * (width + lift) {
        away.normalize()
    } else {
        let any = if up.x.abs() < 0.9 {
            Vector3::x()
        } else {
            Vector3::y()
        };
        across(any).normalize()
    };
    lift_m + side * (width + lift)
}

/// The area at rest of the faces of `tets` that no other of them shares, m^2.
fn surface_m2(mesh: &TetMesh, tets: &[u32]) -> f64 {
    let mut faces: Vec<[u32; 3]> = tets
        .iter()
        .flat_map(|&t| {
            let tet = mesh.tets()[t as usize];
            TET_FACES.map(|f| sorted_triple(f.map(|k| tet[k])))
        })
        .collect();
    faces.sort_unstable();
    let x = mesh.positions();
    let area = |f: &[u32; 3]| {
        let [a, b, c]: [Point3; 3] = f.map(|v| x[v as usize]);
        0.5 * (b - a).cross(&(c - a)).norm()
    };
    let mut total = 0.0;
    let mut i = 0;
    while i < faces.len() {
        let mut j = i + 1;
        while j < faces.len() && faces[j] == faces[i] {
            j += 1;
        }
        if j - i == 1 {
            total += area(&faces[i]);
        }
        i = j;
    }
    total
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_free_piece_beside_a_held_one_is_freed_with_its_volume_and_surface() {
        // two unit-corner tets apart: the first held at vertex 0, the second free
        let corner = |o: f64| {
            [
                Point3::new(o, 0.0, 0.0),
                Point3::new(o + 1.0, 0.0, 0.0),
                Point3::new(o, 1.0, 0.0),
                Point3::new(o, 0.0, 1.0),
            ]
        };
        let x: Vec<Point3> = corner(0.0).into_iter().chain(corner(5.0)).collect();
        let mesh = TetMesh::new(x, vec![[0, 1, 2, 3], [4, 5, 6, 7]], vec![0, 0]).expect("mesh");
        let mut held = vec![false; 8];
        held[0] = true;
        let lift = Vector3::new(0.0, 0.0, 0.03);
        let freed = freed(&mesh, &held, 0.1, lift);
        assert_eq!(freed.len(), 1);
        let s = &freed[0];
        assert_eq!(
            (s.tets.clone(), s.vertices.clone()),
            (vec![1], vec![4, 5, 6, 7])
        );
        assert!((s.volume_m3 - 1.0 / 6.0).abs() < 1e-15);
        // three right triangles of 1/2 and the slanted one of sqrt(3)/2
        assert!((s.surface_m2 - (1.5 + 3f64.sqrt() / 2.0)).abs() < 1e-12);
        // out along the lift and aside, away from the held tetrahedron: its centre is at
        // (0.25, 0.25), the free one's at (5.25, 0.25), which reaches sqrt(0.75^2 + 0.25^2)
        // from its centre across the lift
        let width = (0.75f64.powi(2) + 0.25f64.powi(2)).sqrt();
        let expected = [width + 0.03, 0.0, 0.03];
        assert!(
            s.lift_m
                .iter()
                .zip(expected)
                .all(|(a, b)| (a - b).abs() < 1e-12),
            "{:?}",
            s.lift_m
        );
        // smaller than asked: none; nothing held: none (a free-floating body frees nothing)
        assert!(super::freed(&mesh, &held, 0.2, lift).is_empty());
        assert!(super::freed(&mesh, &[false; 8], 0.1, lift).is_empty());
    }
}
