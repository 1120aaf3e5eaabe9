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
    pub(crate) fn refill<I: Iterator<Item = (u32, u32)>>(
        &mut self,
        rows: usize,
        pairs: impl Fn() -> I,
    ) {
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
        debug_assert!(
            offsets.first() == Some(&0) && offsets.last().copied() == Some(items.len() as u32)
        );
        Self { offsets, items }
    }

    /// Entries of row `i`.
    pub fn row(&self, i: usize) -> &[u32] {
        &self.items[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Number of entries in all rows.
    pub fn item_count(&self) -> usize {
        self.items.len()
    }
}

/// Edges, surface and adjacency of a [`super::TetMesh`].
///
/// Only what a cut can carry over in runs is stored: the sorted edges, the boundary (sorted by
/// its faces' vertex triples) and the tets around each vertex. The rest is derived on demand
/// from those, locally: the tets around an edge or a face are the tets its vertices' rows have
/// in common ([`Self::tets_of_edge`], [`Self::tets_of_face`]), and an edge's id is its place
/// in the sorted edges ([`Self::edge_id`]). So a cut, which changes a few tets, changes a few
/// entries and copies the rest whole, instead of renumbering the edge and face ids every tet
/// would hold.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Topology {
    /// Unique edges `[a, b]` with `a < b`, sorted.
    pub edges: Vec<[VertexId; 2]>,
    /// Boundary triangles (faces with exactly one tetrahedron), oriented outward, in the order
    /// of their sorted vertex triples.
    pub boundary: Vec<[VertexId; 3]>,
    /// Faces (sorted vertex triples, sorted) used by more than two tetrahedra: a non-manifold,
    /// non-conforming mesh.
    pub overshared_faces: Vec<[VertexId; 3]>,
    /// Tetrahedra around each vertex, ascending.
    pub vertex_tets: Csr,
}

/// The entries two ascending rows have in common, ascending.
fn common<'a>(a: &'a [u32], b: &'a [u32]) -> impl Iterator<Item = u32> + 'a {
    let mut j = 0;
    a.iter().copied().filter(move |&t| {
        while b.get(j).is_some_and(|&o| o < t) {
            j += 1;
        }
        b.get(j) == Some(&t)
    })
}

/// `[a, b]` ascending: the key of an edge whatever its direction.
#[inline]
pub(crate) fn sorted_pair(a: VertexId, b: VertexId) -> [VertexId; 2] {
    if a < b { [a, b] } else { [b, a] }
}

/// `k` sorted ascending: the key of a face whatever its orientation.
#[inline]
pub(crate) fn sorted_triple(mut k: [VertexId; 3]) -> [VertexId; 3] {
    k.sort_unstable();
    k
}

/// The edge `[a, b]` with `a < b` of the local vertices `i`, `j` of `tet`.
pub(crate) fn edge_key(tet: &[VertexId; 4], [i, j]: [usize; 2]) -> [VertexId; 2] {
    sorted_pair(tet[i], tet[j])
}

/// The face opposite local vertex `l` of `tet` as a sorted vertex triple.
pub(crate) fn face_key(tet: &[VertexId; 4], l: usize) -> [VertexId; 3] {
    sorted_triple(TET_FACES[l].map(|i| tet[i]))
}

/// The keys of `tet`'s six edges, in the local order of [`TET_EDGES`].
pub(super) fn tet_edge_keys(tet: &[VertexId; 4]) -> [[VertexId; 2]; 6] {
    TET_EDGES.map(|l| edge_key(tet, l))
}

/// The keys of `tet`'s four faces, in the local order of [`TET_FACES`].
pub(super) fn tet_face_keys(tet: &[VertexId; 4]) -> [[VertexId; 3]; 4] {
    std::array::from_fn(|l| face_key(tet, l))
}

/// The sorted, deduplicated keys `keys_of` gives for the tets `ids` of `tets` (ids out of range
/// skipped).
pub(super) fn keys_of_tets<K: Ord, const L: usize>(
    tets: &[[VertexId; 4]],
    ids: &[u32],
    keys_of: impl Fn(&[VertexId; 4]) -> [K; L],
) -> Vec<K> {
    let mut keys: Vec<K> = ids
        .iter()
        .filter_map(|&t| tets.get(t as usize))
        .flat_map(keys_of)
        .collect();
    keys.sort_unstable();
    keys.dedup();
    keys
}

/// Sorts `keys` (ascending, as `sort_unstable` would) by a counting sort on their first
/// vertex, then a small sort within each bucket: linear in the mesh size, since a vertex has
/// only a handful of edges and faces. The result is the same total order as a full sort.
fn sort_by_first_vertex<K: Ord + Copy>(
    keys: &mut Vec<K>,
    vertex_count: usize,
    first: impl Fn(&K) -> u32,
) {
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

/// The face opposite local vertex `l` of `tet`, oriented outward (see [`TET_FACES`]).
pub(crate) fn oriented_face(tet: &[VertexId; 4], l: usize) -> [VertexId; 3] {
    TET_FACES[l].map(|i| tet[i])
}

impl Topology {
    /// Derives the topology of `tets` over `vertex_count` vertices.
    pub fn build(vertex_count: usize, tets: &[[VertexId; 4]]) -> Self {
        let mut edges: Vec<[VertexId; 2]> = tets.iter().flat_map(tet_edge_keys).collect();
        sort_by_first_vertex(&mut edges, vertex_count, |k| k[0]);
        edges.dedup();

        let mut faces: Vec<([u32; 3], u32, u8)> = Vec::with_capacity(tets.len() * 4);
        for (t, tet) in tets.iter().enumerate() {
            faces.extend(
                tet_face_keys(tet)
                    .into_iter()
                    .zip(0..)
                    .map(|(key, l)| (key, t as u32, l)),
            );
        }
        sort_by_first_vertex(&mut faces, vertex_count, |k| k.0[0]);
        let (mut boundary, mut overshared_faces) = (Vec::new(), Vec::new());
        for group in faces.chunk_by(|a, b| a.0 == b.0) {
            match *group {
                [(_, t, l)] => boundary.push(oriented_face(&tets[t as usize], l as usize)),
                [_, _] => {}
                _ => overshared_faces.push(group[0].0),
            }
        }

        let mut vertex_tets = Csr::default();
        vertex_tets.refill(vertex_count, || {
            tets.iter()
                .enumerate()
                .flat_map(|(t, tet)| tet.map(|v| (v, t as u32)))
        });
        Self {
            edges,
            boundary,
            overshared_faces,
            vertex_tets,
        }
    }

    /// The tets around vertex `v`, ascending (none for a vertex out of range).
    pub fn tets_of_vertex(&self, v: VertexId) -> &[u32] {
        if (v as usize) < self.vertex_tets.rows() {
            self.vertex_tets.row(v as usize)
        } else {
            &[]
        }
    }

    /// The tets around the edge `[a, b]`, ascending: those of both vertices.
    pub fn tets_of_edge(&self, [a, b]: [VertexId; 2]) -> impl Iterator<Item = u32> + '_ {
        common(self.tets_of_vertex(a), self.tets_of_vertex(b))
    }

    /// The tets around the face `[a, b, c]`, ascending: those of all three vertices.
    pub fn tets_of_face(&self, [a, b, c]: [VertexId; 3]) -> impl Iterator<Item = u32> + '_ {
        let third = self.tets_of_vertex(c);
        common(self.tets_of_vertex(a), self.tets_of_vertex(b))
            .filter(move |t| third.binary_search(t).is_ok())
    }

    /// The id (place in [`Self::edges`]) of the edge between `a` and `b`, if there is one.
    pub fn edge_id(&self, a: VertexId, b: VertexId) -> Option<u32> {
        self.edges
            .binary_search(&sorted_pair(a, b))
            .ok()
            .map(|e| e as u32)
    }

    /// The edge ids of `tet`'s six edges, in the local order of [`TET_EDGES`] ([`NONE`] for an
    /// edge this topology does not have: `tet` is not one of its tets).
    pub fn tet_edge_ids(&self, tet: &[VertexId; 4]) -> [u32; 6] {
        tet_edge_keys(tet).map(|[a, b]| self.edge_id(a, b).unwrap_or(NONE))
    }

    /// The edges of the tets `ids` of `tets` (ids out of range skipped) that this topology
    /// lacks, sorted.
    pub(crate) fn lacking_edges(&self, tets: &[[VertexId; 4]], ids: &[u32]) -> Vec<[VertexId; 2]> {
        let mut edges = keys_of_tets(tets, ids, tet_edge_keys);
        edges.retain(|e| self.edges.binary_search(e).is_err());
        edges
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
pub fn non_manifold_edges(
    tris: &[[VertexId; 3]],
    judge: impl Fn(u32, u32) -> bool,
) -> Vec<[VertexId; 2]> {
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
