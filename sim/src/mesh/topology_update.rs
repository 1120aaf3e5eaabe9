//! The topology of a mesh after a local change, derived from the topology before it: what a
//! cut needs instead of [`Topology::build`] over the whole mesh. The result is the one `build`
//! gives (tested field by field), at the cost of copying runs of sorted lists: the rows of the
//! vertices the changed tets touch are merged again, the edges and the boundary faces those
//! tets had or have are looked up in the new rows, and everything between is copied whole.

use super::VertexId;
use super::topology::{
    Csr, Topology, keys_of_tets, oriented_face, sorted_triple, tet_edge_keys, tet_face_keys,
};

/// From this many tets on, the passes of a cut over the whole mesh run on two threads
/// ([`Topology::updated`] merges the edges and the boundary side by side).
pub(crate) const PARALLEL_MIN_TETS: usize = 20_000;

/// `old` (ascending by `key`) without its entries whose key is in `removed` (ascending), with
/// `added` (ascending by `key`) merged in, an added entry before an old one of the same key.
/// The runs of `old` between the changes are copied whole.
fn merge_runs<T: Copy, K: Ord>(
    old: &[T],
    removed: &[K],
    added: &[T],
    key: impl Fn(&T) -> K,
) -> Vec<T> {
    let mut out = Vec::with_capacity(old.len() + added.len());
    let (mut i, mut r, mut a) = (0, 0, 0);
    let place = |i: usize, k: &K| i + old[i..].partition_point(|x| key(x) < *k);
    loop {
        let stop_removed = removed.get(r).map_or(old.len(), |k| place(i, k));
        let stop_added = added.get(a).map_or(old.len(), |t| place(i, &key(t)));
        let stop = stop_removed.min(stop_added);
        out.extend_from_slice(&old[i..stop]);
        i = stop;
        if a < added.len() && stop_added == stop {
            out.push(added[a]);
            a += 1;
        } else if r < removed.len() {
            if old.get(i).is_some_and(|x| key(x) == removed[r]) {
                i += 1;
            }
            r += 1;
        } else {
            return out;
        }
    }
}

/// Appends to `out` the merge of two ascending runs of tet ids.
fn merge_ascending(
    out: &mut Vec<u32>,
    kept: impl Iterator<Item = u32>,
    new: impl Iterator<Item = u32>,
) {
    let mut kept = kept.peekable();
    for t in new {
        while let Some(o) = kept.next_if(|&o| o < t) {
            out.push(o);
        }
        out.push(t);
    }
    out.extend(kept);
}

impl Topology {
    /// The topology of `tets` over `vertex_count` vertices, given this topology of
    /// `old_tets` and the tets that differ: `changed` (ascending ids below `old_tets.len()`
    /// whose vertices changed) and every tet from `old_tets.len()` on (appended). Tet ids
    /// never move and vertex ids only grow. Returns `None` where the old topology cannot be
    /// carried over (faces shared by more than two tets), for [`Topology::build`] to do.
    pub fn updated(
        &self,
        old_tets: &[[VertexId; 4]],
        tets: &[[VertexId; 4]],
        changed: &[u32],
        vertex_count: usize,
    ) -> Option<Self> {
        let old_count = old_tets.len();
        if !self.overshared_faces.is_empty()
            || tets.len() < old_count
            || self.vertex_tets.item_count() != 4 * old_count
            || self.vertex_tets.rows() > vertex_count
        {
            return None;
        }
        let mut is_changed = vec![false; old_count];
        for &t in changed {
            *is_changed.get_mut(t as usize)? = true;
        }
        let dirty: Vec<u32> = changed
            .iter()
            .copied()
            .chain(old_count as u32..tets.len() as u32)
            .collect();
        let vertex_tets =
            self.vertex_rows_updated(old_tets, tets, &dirty, &is_changed, vertex_count)?;
        let mut new = Self {
            vertex_tets,
            ..Self::default()
        };

        // the edges the changed tets had and no tet has now, and those the dirty tets have and
        // no tet had
        let edges = || {
            let mut removed = keys_of_tets(old_tets, changed, tet_edge_keys);
            removed.retain(|&e| new.tets_of_edge(e).next().is_none());
            let added = self.lacking_edges(tets, &dirty);
            merge_runs(&self.edges, &removed, &added, |e| *e)
        };
        // the faces the changed tets had or the dirty tets have: boundary where one tet has it
        let boundary = || {
            let mut faces = keys_of_tets(old_tets, changed, tet_face_keys);
            faces.extend(keys_of_tets(tets, &dirty, tet_face_keys));
            faces.sort_unstable();
            faces.dedup();
            let mut added = Vec::new();
            for &f in &faces {
                let mut around = new.tets_of_face(f);
                match (around.next(), around.next(), around.next()) {
                    (Some(t), None, _) => {
                        let tet = &tets[t as usize];
                        let l = (0..4).find(|&l| !f.contains(&tet[l]))?;
                        added.push(oriented_face(tet, l));
                    }
                    (_, _, Some(_)) => return None,
                    _ => {}
                }
            }
            Some(merge_runs(&self.boundary, &faces, &added, |&tri| {
                sorted_triple(tri)
            }))
        };
        // independent: side by side on a large mesh (the same result either way)
        let (edges, boundary) =
            crate::parallel::join(tets.len() >= PARALLEL_MIN_TETS, edges, boundary);
        new.edges = edges;
        new.boundary = boundary?;
        Some(new)
    }

    /// The tets around each vertex after the change: the rows of the vertices the dirty tets
    /// touch (before or after) merged again, the others copied.
    fn vertex_rows_updated(
        &self,
        old_tets: &[[VertexId; 4]],
        tets: &[[VertexId; 4]],
        dirty: &[u32],
        is_changed: &[bool],
        vertex_count: usize,
    ) -> Option<Csr> {
        let mut touched = vec![false; vertex_count];
        let mut vertex_pairs: Vec<(u32, u32)> = Vec::with_capacity(dirty.len() * 4);
        for &t in dirty {
            for &v in &tets[t as usize] {
                *touched.get_mut(v as usize)? = true;
                vertex_pairs.push((v, t));
            }
            if let Some(old) = old_tets.get(t as usize) {
                for &v in old {
                    *touched.get_mut(v as usize)? = true;
                }
            }
        }
        vertex_pairs.sort_unstable();
        let mut offsets = Vec::with_capacity(vertex_count + 1);
        let mut items = Vec::with_capacity(tets.len() * 4);
        offsets.push(0u32);
        let mut j = 0;
        for (v, &touched) in touched.iter().enumerate() {
            let old_row = self.tets_of_vertex(v as u32);
            if !touched {
                items.extend_from_slice(old_row);
            } else {
                let count = vertex_pairs[j..]
                    .iter()
                    .take_while(|p| p.0 as usize == v)
                    .count();
                let run = vertex_pairs[j..j + count].iter().map(|p| p.1);
                j += count;
                merge_ascending(
                    &mut items,
                    old_row.iter().copied().filter(|&t| !is_changed[t as usize]),
                    run,
                );
            }
            offsets.push(items.len() as u32);
        }
        Some(Csr::from_parts(offsets, items))
    }
}
