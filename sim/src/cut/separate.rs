//! Particle remodelling by vertex splitting: once the cut surface consists of mesh faces, a
//! vertex on it is split into one copy per connected piece of its star (the tetrahedra around
//! it, connected through faces that were not cut). A vertex inside the cut surface gets two
//! copies, one per side; a vertex on the cut front keeps a connected star and is not split, so
//! the incision ends cleanly there.

use std::collections::BTreeSet;

use crate::mesh::{NONE, TET_FACES, TetMesh};

use super::pattern::sorted3;

/// For each split, the original vertex and the tetrahedra that move to a new copy.
pub fn star_components(mesh: &TetMesh, cut_faces: &BTreeSet<[u32; 3]>, vertices: &BTreeSet<u32>) -> Vec<(u32, Vec<u32>)> {
    let topo = mesh.topology();
    let mut out = Vec::new();
    for &v in vertices {
        let star = topo.vertex_tets.row(v as usize);
        if star.len() < 2 {
            continue;
        }
        // union-find over the star
        let mut parent: Vec<usize> = (0..star.len()).collect();
        fn find(p: &mut [usize], mut i: usize) -> usize {
            while p[i] != i {
                p[i] = p[p[i]];
                i = p[i];
            }
            i
        }
        for (si, &t) in star.iter().enumerate() {
            let tet = mesh.tets()[t as usize];
            for (l, f) in TET_FACES.iter().enumerate() {
                if !f.iter().any(|&k| tet[k] == v) {
                    continue;
                }
                let fid = topo.tet_faces[t as usize][l] as usize;
                let [t0, t1] = topo.face_tets[fid];
                let other = if t0 == t { t1 } else { t0 };
                if other == NONE || cut_faces.contains(&sorted3(topo.faces[fid])) {
                    continue;
                }
                if let Ok(oi) = star.binary_search(&other) {
                    let (a, b) = (find(&mut parent, si), find(&mut parent, oi));
                    if a != b {
                        parent[a.max(b)] = a.min(b);
                    }
                }
            }
        }
        let roots: Vec<usize> = (0..star.len()).map(|i| find(&mut parent, i)).collect();
        let mut distinct: Vec<usize> = roots.clone();
        distinct.sort_unstable();
        distinct.dedup();
        // the component holding the smallest tet id keeps the vertex (root 0 after the
        // min-linking above, since star is ascending)
        for &r in distinct.iter().skip(1) {
            let tets = star.iter().zip(&roots).filter(|(_, rr)| **rr == r).map(|(t, _)| *t).collect();
            out.push((v, tets));
        }
    }
    out
}
