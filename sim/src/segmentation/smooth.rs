//! Optional smoothing of the staircase surface of a voxel mesh.
//!
//! Taubin's lambda|mu scheme: each iteration moves every boundary vertex by
//! `lambda (avg - p)` and then by `mu (avg - p)`, `avg` the mean of its neighbours along
//! boundary edges, with `lambda = 0.5`, `mu = -0.53`; the negative step undoes the shrinkage
//! of plain Laplacian smoothing. Only boundary vertices move, one at a time, and a move is
//! undone when any tetrahedron around the vertex would drop below [`MIN_VOLUME_RATIO`] of
//! its volume before smoothing, so every tetrahedron stays positively oriented and no sliver
//! is created.

use crate::TetMesh;
use crate::mesh::{Csr, tet_signed_volume};

const LAMBDA: f64 = 0.5;
const MU: f64 = -0.53;
/// Smallest allowed tetrahedron volume after a move, relative to its volume before smoothing.
pub const MIN_VOLUME_RATIO: f64 = 0.1;

/// Smooths the boundary of `mesh` in place; returns the number of rejected vertex moves.
pub(super) fn smooth_boundary(mesh: &mut TetMesh, iterations: usize) -> usize {
    if iterations == 0 {
        return 0;
    }
    let topo = mesh.topology();
    let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(topo.boundary.len() * 6);
    for tri in &topo.boundary {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            pairs.push((a, b));
            pairs.push((b, a));
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    let neighbours = Csr::from_pairs(mesh.vertex_count(), &pairs);
    let boundary = topo.boundary_vertices();
    let vertex_tets = topo.vertex_tets.clone();
    let tets = mesh.tets().to_vec();
    let rest: Vec<f64> = (0..tets.len()).map(|t| mesh.tet_volume(t)).collect();
    let mut rejected = 0;
    let mut steps = Vec::with_capacity(boundary.len());
    for _ in 0..iterations {
        for factor in [LAMBDA, MU] {
            let pos = mesh.positions();
            steps.clear();
            for &v in &boundary {
                let nb = neighbours.row(v as usize);
                let sum = nb
                    .iter()
                    .fold(crate::Vector3::zeros(), |s, &u| s + pos[u as usize].coords);
                let avg = sum / nb.len().max(1) as f64;
                steps.push(factor * (avg - pos[v as usize].coords));
            }
            for (&v, step) in boundary.iter().zip(&steps) {
                let v = v as usize;
                let old = mesh.positions()[v];
                mesh.positions_mut()[v] = old + step;
                let pos = mesh.positions();
                let ok = vertex_tets.row(v).iter().all(|&t| {
                    let [a, b, c, d] = tets[t as usize].map(|i| pos[i as usize]);
                    tet_signed_volume(&a, &b, &c, &d) >= MIN_VOLUME_RATIO * rest[t as usize]
                });
                if !ok {
                    mesh.positions_mut()[v] = old;
                    rejected += 1;
                }
            }
        }
    }
    rejected
}
