//! Specimens: the pieces a cut frees from the tissue.
//!
//! When a cut leaves a piece that holds no held vertex apart from the held tissue, and the
//! piece is larger than a fragment ([`super::CutOptions::fragment_volume_m3`]), the piece is
//! taken out of the wound as a surgeon's forceps would: its particles are moved by the lift
//! given to the cut and held there. Nothing joins it to the tissue (the cut split every vertex
//! between them), so the tissue feels nothing of it; it stays in the mesh, with its mass, so
//! the vertex and tetrahedron ids of the recording and the replay are kept, and the cut's
//! event lists it (its tetrahedra, vertices, volume and surface) for whoever reads its shape.

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
}

/// The pieces of `mesh` no vertex of which is `held`, of at least `min_volume_m3`, while
/// another piece is held (a free-floating body frees nothing); each to be lifted by `lift_m`.
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
    if all.len() < 2 || !all.iter().any(|p| p.held) {
        return Vec::new();
    }
    all.into_iter()
        .filter(|p| !p.held && p.volume_m3 >= min_volume_m3)
        .map(|p| {
            let mut vertices: Vec<u32> = p
                .tets
                .iter()
                .flat_map(|&t| mesh.tets()[t as usize])
                .collect();
            vertices.sort_unstable();
            vertices.dedup();
            Specimen {
                surface_m2: surface_m2(mesh, &p.tets),
                tets: p.tets,
                vertices,
                volume_m3: p.volume_m3,
                lift_m: lift_m.into(),
            }
        })
        .collect()
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
        assert_eq!(s.lift_m, [0.0, 0.0, 0.03]);
        // smaller than asked: none; nothing held: none (a free-floating body frees nothing)
        assert!(super::freed(&mesh, &held, 0.2, lift).is_empty());
        assert!(super::freed(&mesh, &[false; 8], 0.1, lift).is_empty());
    }
}
