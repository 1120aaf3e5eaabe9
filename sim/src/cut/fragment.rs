//! Fragments: the small free pieces a step's cut would carve out of the tissue.
//!
//! A blade that turns, or crosses its own wound, cuts along planes that meet the stroke's
//! earlier cut at small angles; between the two surfaces a few tetrahedra can end up with no
//! uncut face to the rest of the tissue. Such a piece is a numerical sliver, not a specimen:
//! it is smaller than [`super::CutOptions::fragment_volume_m3`] and holds no held vertex. The
//! rule: the step that would free it leaves uncut the faces it would have cut around that
//! piece on one side of its plane, so the piece stays with the tissue across them (the cut
//! passes beside it, its earlier wound still separating it from the other side; uncutting
//! the faces of both sides would bridge the wound). The event counts the pieces so
//! reattached.
//!
//! Pieces are found by a flood over tetrahedra sharing a vertex, from the tetrahedra the
//! step's cut touched, which stops as soon as a piece is larger than a fragment or holds a
//! held vertex: its cost is in proportion to the cut, not to the mesh.

use std::collections::BTreeMap;

/// What the flood needs to know of the cut mesh being built.
pub(super) struct PieceQuery<'a> {
    /// The tetrahedra after the step's splits and relinks.
    pub tets: &'a [[u32; 4]],
    /// The tetrahedra around a vertex (after the splits and relinks).
    pub tets_at: &'a dyn Fn(u32) -> Vec<u32>,
    /// A tetrahedron's volume at rest, m^3.
    pub volume: &'a dyn Fn(u32) -> f64,
    /// True when a vertex is held.
    pub held: &'a dyn Fn(u32) -> bool,
    /// Pieces at least this large (m^3) are not fragments.
    pub max_volume_m3: f64,
}

impl PieceQuery<'_> {
    /// The tetrahedra of each piece that holds one of `seeds`, no held vertex, and less than
    /// [`Self::max_volume_m3`] of volume: the fragments.
    pub fn fragments(&self, seeds: &[u32]) -> Vec<Vec<u32>> {
        // the piece each visited tetrahedron was reached from; a piece is large once marked
        let mut piece_of: BTreeMap<u32, usize> = BTreeMap::new();
        let mut large: Vec<bool> = Vec::new();
        let mut out = Vec::new();
        for &seed in seeds {
            if piece_of.contains_key(&seed) {
                continue;
            }
            let id = large.len();
            let (members, is_large) = self.flood(seed, id, &mut piece_of, &large);
            large.push(is_large);
            if !is_large {
                out.push(members);
            }
        }
        out
    }

    /// Floods the piece of `seed` as piece `id`; stops when it proves large (a held vertex,
    /// too much volume, or a tetrahedron of an earlier piece, which was large since pieces do
    /// not meet).
    fn flood(
        &self,
        seed: u32,
        id: usize,
        piece_of: &mut BTreeMap<u32, usize>,
        large: &[bool],
    ) -> (Vec<u32>, bool) {
        let mut members = vec![seed];
        piece_of.insert(seed, id);
        let mut volume = 0.0;
        let mut next = 0;
        while next < members.len() {
            let t = members[next];
            next += 1;
            volume += (self.volume)(t);
            let tet = self.tets[t as usize];
            if volume >= self.max_volume_m3 || tet.iter().any(|&v| (self.held)(v)) {
                return (members, true);
            }
            for v in tet {
                for u in (self.tets_at)(v) {
                    match piece_of.get(&u) {
                        Some(&p) if p != id => {
                            debug_assert!(large[p], "pieces that meet are one piece");
                            return (members, true);
                        }
                        Some(_) => {}
                        None => {
                            piece_of.insert(u, id);
                            members.push(u);
                        }
                    }
                }
            }
        }
        (members, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two tetrahedra sharing vertex 3 (one piece), and one alone (vertices 6..10).
    fn three() -> Vec<[u32; 4]> {
        vec![[0, 1, 2, 3], [3, 4, 5, 6], [7, 8, 9, 10]]
    }

    fn query<'a>(
        tets: &'a [[u32; 4]],
        tets_at: &'a dyn Fn(u32) -> Vec<u32>,
        held: &'a dyn Fn(u32) -> bool,
        max_volume_m3: f64,
    ) -> PieceQuery<'a> {
        PieceQuery {
            tets,
            tets_at,
            volume: &|_| 1.0,
            held,
            max_volume_m3,
        }
    }

    #[test]
    fn a_small_piece_without_held_vertices_is_a_fragment_and_others_are_not() {
        let tets = three();
        let tets_at = |v: u32| -> Vec<u32> {
            (0..tets.len() as u32)
                .filter(|&t| tets[t as usize].contains(&v))
                .collect()
        };
        // nothing held, fragments below 2.5 tets: the pair and the single one
        let q = query(&tets, &tets_at, &|_| false, 2.5);
        assert_eq!(q.fragments(&[0, 1, 2]), vec![vec![0, 1], vec![2]]);
        // below 1.5 tets: only the single one
        let q = query(&tets, &tets_at, &|_| false, 1.5);
        assert_eq!(q.fragments(&[1, 0, 2]), vec![vec![2]]);
        // vertex 5 held: the pair is tissue
        let q = query(&tets, &tets_at, &|v| v == 5, 2.5);
        assert_eq!(q.fragments(&[0, 2]), vec![vec![2]]);
        // only the pieces of the seeds are looked at
        assert!(q.fragments(&[0]).is_empty());
    }
}
