//! Particle remodelling by vertex splitting: once the cut surface consists of mesh faces, a
//! vertex on it is split into one copy per connected piece of its star (the tetrahedra around
//! it, connected through faces that were not cut). A vertex inside the cut surface gets two
//! copies, one per side; a vertex on the cut front keeps a connected star and is not split, so
//! the incision ends cleanly there.
//!
//! Everything here is local to the stars of the vertices on the cut: no full-mesh pass.

use std::collections::{BTreeMap, BTreeSet};

use crate::mesh::TET_FACES;
use crate::mesh::{non_manifold_edges, sorted_triple};

/// Stars of the vertices of the cut: for each, the ids of the tetrahedra around it, ascending.
pub type Stars = BTreeMap<u32, Vec<u32>>;

/// For each split, the original vertex and the tetrahedra (of its star) that move to a new
/// copy. The piece holding the smallest tetrahedron id keeps the vertex.
pub fn star_components(
    tets: &[[u32; 4]],
    stars: &Stars,
    cut_faces: &BTreeSet<[u32; 3]>,
) -> Vec<(u32, Vec<u32>)> {
    let mut out = Vec::new();
    let mut faces: Vec<([u32; 3], usize)> = Vec::new();
    for (&v, star) in stars {
        if star.len() < 2 {
            continue;
        }
        // faces through v, keyed by their sorted vertices, with the star index of their tet
        faces.clear();
        for (si, &t) in star.iter().enumerate() {
            let tet = tets[t as usize];
            for f in TET_FACES {
                if f.iter().any(|&k| tet[k] == v) {
                    faces.push((sorted_triple(f.map(|k| tet[k])), si));
                }
            }
        }
        faces.sort_unstable();
        let mut parent: Vec<usize> = (0..star.len()).collect();
        fn find(p: &mut [usize], mut i: usize) -> usize {
            while p[i] != i {
                p[i] = p[p[i]];
                i = p[i];
            }
            i
        }
        for w in faces.windows(2) {
            if w[0].0 == w[1].0 && !cut_faces.contains(&w[0].0) {
                let (a, b) = (find(&mut parent, w[0].1), find(&mut parent, w[1].1));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
        let roots: Vec<usize> = (0..star.len()).map(|i| find(&mut parent, i)).collect();
        let mut distinct = roots.clone();
        distinct.sort_unstable();
        distinct.dedup();
        for &r in distinct.iter().skip(1) {
            let moved = star
                .iter()
                .zip(&roots)
                .filter(|(_, rr)| **rr == r)
                .map(|(t, _)| *t)
                .collect();
            out.push((v, moved));
        }
    }
    out
}

/// Surface edges around the cut that are not closed 2-manifold edges (used by other than
/// exactly two boundary triangles in opposite directions), among the tetrahedra `local` (the
/// union of the stars, after splitting). `on_cut(v)` tells whether a vertex (or a copy) lies on
/// the cut; only edges with such an end are judged, since all faces around them are local.
pub fn pinched_edges(
    tets: &[[u32; 4]],
    local: &BTreeSet<u32>,
    on_cut: &dyn Fn(u32) -> bool,
) -> Vec<[u32; 2]> {
    let mut faces: Vec<([u32; 3], [u32; 3])> = Vec::new();
    for &t in local {
        let tet = tets[t as usize];
        for f in TET_FACES {
            let oriented = f.map(|k| tet[k]);
            if oriented.iter().any(|&v| on_cut(v)) {
                faces.push((sorted_triple(oriented), oriented));
            }
        }
    }
    faces.sort_unstable();
    let mut boundary: Vec<[u32; 3]> = Vec::new();
    let mut i = 0;
    while i < faces.len() {
        let mut j = i;
        while j < faces.len() && faces[j].0 == faces[i].0 {
            j += 1;
        }
        if j - i == 1 {
            boundary.push(faces[i].1);
        }
        i = j;
    }
    non_manifold_edges(&boundary, |a, b| on_cut(a) || on_cut(b))
}
