//! The pieces of a mesh: tetrahedra connected through shared vertices (a cut splits the
//! vertices of its surface, so the two sides share none).

use super::TetMesh;

/// One connected piece of a mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct Piece {
    /// Its tetrahedra, ascending.
    pub tets: Vec<u32>,
    /// Its volume at rest, m^3.
    pub volume_m3: f64,
    /// True when one of its vertices is held (the tissue, not a piece cut free).
    pub held: bool,
}

/// The root of `i` in the union-find forest `p`, halving the path.
fn find(p: &mut [u32], mut i: u32) -> u32 {
    while p[i as usize] != i {
        p[i as usize] = p[p[i as usize] as usize];
        i = p[i as usize];
    }
    i
}

/// The union-find forest of `mesh`'s vertices joined through its tetrahedra.
fn forest(mesh: &TetMesh) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
    for tet in mesh.tets() {
        for &v in &tet[1..] {
            let (a, b) = (find(&mut parent, tet[0]), find(&mut parent, v));
            parent[a.max(b) as usize] = a.min(b);
        }
    }
    parent
}

/// The union-find forest of `mesh` and, per root, whether its piece holds a vertex `held`.
fn held_roots(mesh: &TetMesh, held: &[bool]) -> (Vec<u32>, Vec<bool>) {
    let mut parent = forest(mesh);
    let mut root_held = vec![false; mesh.vertex_count()];
    for (v, &h) in held.iter().enumerate().take(mesh.vertex_count()) {
        if h {
            let r = find(&mut parent, v as u32);
            root_held[r as usize] = true;
        }
    }
    (parent, root_held)
}

/// True when some piece of `mesh` holds no vertex `held` (cheaper than [`pieces`]: no
/// volumes, no lists).
pub fn has_free_piece(mesh: &TetMesh, held: &[bool]) -> bool {
    let (mut parent, root_held) = held_roots(mesh, held);
    mesh.tets()
        .iter()
        .any(|tet| !root_held[find(&mut parent, tet[0]) as usize])
}

/// Per vertex of `mesh`, whether its piece holds a vertex `held` (a vertex of no
/// tetrahedron is a piece of its own).
pub fn anchored(mesh: &TetMesh, held: &[bool]) -> Vec<bool> {
    let (mut parent, root_held) = held_roots(mesh, held);
    (0..mesh.vertex_count() as u32)
        .map(|v| root_held[find(&mut parent, v) as usize])
        .collect()
}

/// The pieces of `mesh`, largest volume first; `held[v]` tells whether vertex `v` is held.
pub fn pieces(mesh: &TetMesh, held: &[bool]) -> Vec<Piece> {
    let mut parent = forest(mesh);
    let mut index_of_root = vec![u32::MAX; mesh.vertex_count()];
    let mut out: Vec<Piece> = Vec::new();
    for (t, tet) in mesh.tets().iter().enumerate() {
        let root = find(&mut parent, tet[0]) as usize;
        if index_of_root[root] == u32::MAX {
            index_of_root[root] = out.len() as u32;
            out.push(Piece {
                tets: Vec::new(),
                volume_m3: 0.0,
                held: false,
            });
        }
        let piece = &mut out[index_of_root[root] as usize];
        piece.tets.push(t as u32);
        piece.volume_m3 += mesh.tet_volume(t);
        piece.held |= tet
            .iter()
            .any(|&v| held.get(v as usize).copied().unwrap_or(false));
    }
    out.sort_by(|a, b| b.volume_m3.total_cmp(&a.volume_m3));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Point3;

    #[test]
    fn tets_sharing_a_vertex_are_one_piece_and_others_are_not() {
        let p = |x: f64| {
            [
                Point3::new(x, 0.0, 0.0),
                Point3::new(x + 1.0, 0.0, 0.0),
                Point3::new(x, 1.0, 0.0),
                Point3::new(x, 0.0, 1.0),
            ]
        };
        // tets 0 and 1 share vertex 3; tet 2 stands alone and is twice the size
        let mut x: Vec<Point3> = p(0.0).to_vec();
        x.extend(&p(3.0)[..3]);
        x.extend(p(10.0).map(|q| Point3::from(q.coords * 2.0)));
        let tets = vec![[0, 1, 2, 3], [4, 5, 6, 3], [7, 8, 9, 10]];
        let mesh = TetMesh::new(x, tets, vec![0; 3]).expect("mesh");
        let mut held = vec![false; 11];
        held[5] = true;
        let pieces = pieces(&mesh, &held);
        assert_eq!(pieces.len(), 2);
        assert_eq!(pieces[0].tets, vec![2]);
        assert!((pieces[0].volume_m3 - 8.0 / 6.0).abs() < 1e-12);
        assert!(!pieces[0].held);
        assert_eq!(pieces[1].tets, vec![0, 1]);
        assert!(pieces[1].held);
        assert!(has_free_piece(&mesh, &held));
        held[9] = true;
        assert!(!has_free_piece(&mesh, &held));
    }
}
