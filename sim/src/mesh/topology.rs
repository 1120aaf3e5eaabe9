//! Topology derived from the tetrahedra: unique edges and faces, the boundary surface and
//! adjacency. Built by sorting (never by iterating a hash map), so it is deterministic.

use super::VertexId;

/// Marker for "no element" in adjacency arrays.
pub const NONE: u32 = u32::MAX;

/// Local vertex pairs of the six edges of a tetrahedron.
pub const TET_EDGES: [[usize; 2]; 6] = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];

/// Local vertices of the face opposite each vertex, ordered so that the right-hand normal
/// points out of a positively oriented tetrahedron.
pub const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// Compressed sparse rows: `items[offsets[i]..offsets[i + 1]]` are the entries of row `i`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Csr {
    offsets: Vec<u32>,
    items: Vec<u32>,
}

impl Csr {
    /// Builds rows from `(row, item)` pairs; entries of a row keep the order of `pairs`
    /// after a stable sort by row.
    pub fn from_pairs(rows: usize, pairs: &[(u32, u32)]) -> Self {
        let mut csr = Self::default();
        csr.refill(rows, || pairs.iter().copied());
        csr
    }

    /// Rebuilds these rows from the `(row, item)` pairs `pairs()` yields (called twice: to
    /// count the rows, then to fill them), the entries of a row in the order they come, in the
    /// allocations this one holds (no list of pairs needed).
    pub(crate) fn refill<I: Iterator<Item = (u32, u32)>>(&mut self, rows: usize, pairs: impl Fn() -> I) {
        let Self { offsets, items } = self;
        offsets.clear();
        offsets.resize(rows + 1, 0);
        // (internal iteration: a chain of adapters folds faster than it steps)
        pairs().for_each(|(r, _)| offsets[r as usize + 1] += 1);
        for i in 0..rows {
            offsets[i + 1] += offsets[i];
        }
        items.clear();
        items.resize(offsets[rows] as usize, 0);
        // (offsets[r] serves as row r's cursor, ending at row r + 1's start; shifted back after)
        pairs().for_each(|(r, it)| {
            let slot = &mut offsets[r as usize];
            items[*slot as usize] = it;
            *slot += 1;
        });
        offsets.copy_within(0..rows, 1);
        offsets[0] = 0;
    }

    /// From its parts (`offsets` ascending from 0 to `items.len()`).
    pub(crate) fn from_parts(offsets: Vec<u32>, items: Vec<u32>) -> Self {
        debug_assert!(offsets.first() == Some(&0) && offsets.last().copied() == Some(items.len() as u32));
        Self { offsets, items }
    }

    /// Entries of row `i`.
    pub fn row(&self, i: usize) -> &[u32] {
        &self.items[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// The row ends `offsets[a..=b]` and the entries of rows `a..b`.
    pub(crate) fn rows_of(&self, range: std::ops::Range<usize>) -> (&[u32], &[u32]) {
        let ends = &self.offsets[range.start..=range.end];
        (ends, &self.items[ends[0] as usize..ends[ends.len() - 1] as usize])
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }
}

/// Edges, faces, surface and adjacency of a [`super::TetMesh`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Topology {
    /// Unique edges `[a, b]` with `a < b`, sorted.
    pub edges: Vec<[VertexId; 2]>,
    /// Edge ids of each tetrahedron, in the local order of [`TET_EDGES`].
    pub tet_edges: Vec<[u32; 6]>,
    /// Unique faces as sorted vertex triples, sorted.
    pub faces: Vec<[VertexId; 3]>,
    /// The (up to) two tetrahedra of each face; [`NONE`] where absent. Faces shared by more
    /// than two tetrahedra are listed in `overshared_faces`.
    pub face_tets: Vec<[u32; 2]>,
    /// Face ids of each tetrahedron: the face opposite local vertex i (see [`TET_FACES`]).
    pub tet_faces: Vec<[u32; 4]>,
    /// Boundary triangles (faces with exactly one tetrahedron), oriented outward.
    pub boundary: Vec<[VertexId; 3]>,
    /// Face id of each boundary triangle.
    pub boundary_face_ids: Vec<u32>,
    /// Faces used by more than two tetrahedra (a non-manifold, non-conforming mesh).
    pub overshared_faces: Vec<u32>,
    /// Tetrahedra around each vertex, ascending.
    pub vertex_tets: Csr,
    /// Tetrahedra around each edge, ascending.
    pub edge_tets: Csr,
}

/// Sorts `keys` (ascending, as `sort_unstable` would) by a counting sort on their first
/// vertex, then a small sort within each bucket: linear in the mesh size, since a vertex has
/// only a handful of edges and faces. The result is the same total order as a full sort.
fn sort_by_first_vertex<K: Ord + Copy>(keys: &mut Vec<K>, vertex_count: usize, first: impl Fn(&K) -> u32) {
    let mut offsets = vec![0usize; vertex_count + 1];
    for k in keys.iter() {
        offsets[first(k) as usize + 1] += 1;
    }
    for i in 0..vertex_count {
        offsets[i + 1] += offsets[i];
    }
    let mut fill = offsets.clone();
    let mut sorted: Vec<K> = Vec::with_capacity(keys.len());
    sorted.extend_from_slice(keys);
    for k in keys.iter() {
        let slot = &mut fill[first(k) as usize];
        sorted[*slot] = *k;
        *slot += 1;
    }
    for v in 0..vertex_count {
        sorted[offsets[v]..offsets[v + 1]].sort_unstable();
    }
    *keys = sorted;
}

impl Topology {
    /// Derives the topology of `tets` over `vertex_count` vertices.
    pub fn build(vertex_count: usize, tets: &[[VertexId; 4]]) -> Self {
        // Edges.
        let mut edge_keys: Vec<([u32; 2], u32, u8)> = Vec::with_capacity(tets.len() * 6);
        for (t, tet) in tets.iter().enumerate() {
            for (l, &[i, j]) in TET_EDGES.iter().enumerate() {
                let (a, b) = (tet[i], tet[j]);
                edge_keys.push(([a.min(b), a.max(b)], t as u32, l as u8));
            }
        }
        sort_by_first_vertex(&mut edge_keys, vertex_count, |k| k.0[0]);
        let mut edges = Vec::with_capacity(tets.len() * 2);
        let mut tet_edges = vec![[0u32; 6]; tets.len()];
        let mut edge_tet_pairs = Vec::with_capacity(edge_keys.len());
        for &(key, t, l) in &edge_keys {
            if edges.last() != Some(&key) {
                edges.push(key);
            }
            let e = (edges.len() - 1) as u32;
            tet_edges[t as usize][l as usize] = e;
            edge_tet_pairs.push((e, t));
        }
        let edge_tets = Csr::from_pairs(edges.len(), &edge_tet_pairs);

        // Faces.
        let mut face_keys: Vec<([u32; 3], u32, u8)> = Vec::with_capacity(tets.len() * 4);
        for (t, tet) in tets.iter().enumerate() {
            for (l, f) in TET_FACES.iter().enumerate() {
                let mut key = [tet[f[0]], tet[f[1]], tet[f[2]]];
                key.sort_unstable();
                face_keys.push((key, t as u32, l as u8));
            }
        }
        sort_by_first_vertex(&mut face_keys, vertex_count, |k| k.0[0]);
        let mut faces = Vec::with_capacity(tets.len() * 2 + 16);
        let mut face_tets: Vec<[u32; 2]> = Vec::with_capacity(faces.capacity());
        let mut face_use: Vec<u32> = Vec::with_capacity(faces.capacity());
        let mut first_local: Vec<(u32, u8)> = Vec::with_capacity(faces.capacity());
        let mut tet_faces = vec![[0u32; 4]; tets.len()];
        for &(key, t, l) in &face_keys {
            if faces.last() != Some(&key) {
                faces.push(key);
                face_tets.push([NONE, NONE]);
                face_use.push(0);
                first_local.push((t, l));
            }
            let f = faces.len() - 1;
            tet_faces[t as usize][l as usize] = f as u32;
            let slot = face_use[f] as usize;
            if slot < 2 {
                face_tets[f][slot] = t;
            }
            face_use[f] += 1;
        }
        let mut boundary = Vec::new();
        let mut boundary_face_ids = Vec::new();
        let mut overshared_faces = Vec::new();
        for (f, &uses) in face_use.iter().enumerate() {
            if uses == 1 {
                let (t, l) = first_local[f];
                let tet = &tets[t as usize];
                let lf = TET_FACES[l as usize];
                boundary.push([tet[lf[0]], tet[lf[1]], tet[lf[2]]]);
                boundary_face_ids.push(f as u32);
            } else if uses > 2 {
                overshared_faces.push(f as u32);
            }
        }

        // Vertex -> tets.
        let mut vt_pairs = Vec::with_capacity(tets.len() * 4);
        for (t, tet) in tets.iter().enumerate() {
            for &v in tet {
                vt_pairs.push((v, t as u32));
            }
        }
        let vertex_tets = Csr::from_pairs(vertex_count, &vt_pairs);

        Self {
            edges,
            tet_edges,
            faces,
            face_tets,
            tet_faces,
            boundary,
            boundary_face_ids,
            overshared_faces,
            vertex_tets,
            edge_tets,
        }
    }

    /// Vertices that lie on the boundary surface, ascending.
    pub fn boundary_vertices(&self) -> Vec<VertexId> {
        let mut v: Vec<u32> = self.boundary.iter().flatten().copied().collect();
        v.sort_unstable();
        v.dedup();
        v
    }

    /// Checks that the boundary is a closed 2-manifold: every boundary edge is used by exactly
    /// two boundary triangles, in opposite directions. Returns the offending edges.
    pub fn boundary_non_manifold_edges(&self) -> Vec<[VertexId; 2]> {
        non_manifold_edges(&self.boundary, |_, _| true)
    }
}

/// Edges of the oriented triangles `tris` (those `judge(a, b)` accepts) that are not used by
/// exactly two of them in opposite directions, sorted.
pub fn non_manifold_edges(tris: &[[VertexId; 3]], judge: impl Fn(u32, u32) -> bool) -> Vec<[VertexId; 2]> {
    let mut half: Vec<([u32; 2], i8)> = Vec::with_capacity(tris.len() * 3);
    for tri in tris {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            if judge(a, b) {
                half.push(if a < b { ([a, b], 1) } else { ([b, a], -1) });
            }
        }
    }
    half.sort_unstable();
    let mut bad = Vec::new();
    let mut i = 0;
    while i < half.len() {
        let mut j = i;
        let mut sum = 0i32;
        while j < half.len() && half[j].0 == half[i].0 {
            sum += half[j].1 as i32;
            j += 1;
        }
        if j - i != 2 || sum != 0 {
            bad.push(half[i].0);
        }
        i = j;
    }
    bad
}
