//! Minimal subdivision of one tetrahedron by a plane.
//!
//! Given the side of each vertex (+1, -1, or 0 on the plane) and one new vertex on every edge
//! that crosses the plane, a tetrahedron splits into:
//!
//! - 1 | 3 (three crossing edges, triangular section): a small tetrahedron at the lone vertex
//!   and a prism, 1 + 3 = **4** tetrahedra;
//! - 2 | 2 (four crossing edges, quadrilateral section): two prisms, 3 + 3 = **6** tetrahedra;
//! - with one vertex on the plane and two crossing edges: a tetrahedron and a pyramid, 3;
//! - with two vertices on the plane and one crossing edge: 2.
//!
//! Every quadrilateral (a face of the tetrahedron with two crossing edges, or the section of a
//! 2 | 2 cut) needs a diagonal; faces shared with a neighbour must use the same one so the mesh
//! stays conforming, and a prism whose three quadrilateral diagonals turn the same way round
//! (a cycle) cannot be split into three tetrahedra. [`TetSplit::children`] takes the diagonals
//! as an input and refuses cyclic prisms; the caller chooses them (by the paper's mu or by the
//! fixed smallest-vertex rule, which never makes a cycle).

use crate::mesh::{TET_EDGES, sorted_pair, sorted_triple};

/// Identifies a quadrilateral whose diagonal must be chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum QuadKey {
    /// A face of the tetrahedron (sorted original vertex ids): shared with the neighbour.
    Face([u32; 3]),
    /// The section of a 2 | 2 cut: both sides use the same diagonal, so the two cut faces
    /// match vertex for vertex.
    Section,
}

/// A quadrilateral with its vertices in cyclic order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Quad {
    /// Which quadrilateral it is (a face, or a section).
    pub key: QuadKey,
    /// Its four vertices in cyclic order.
    pub ring: [u32; 4],
}

impl Quad {
    /// The two possible diagonals, as sorted vertex pairs.
    pub fn diagonals(&self) -> [[u32; 2]; 2] {
        [
            sorted_pair(self.ring[0], self.ring[2]),
            sorted_pair(self.ring[1], self.ring[3]),
        ]
    }

    /// The diagonal through the smallest vertex id (the fixed rule).
    pub fn min_vertex_diagonal(&self) -> [u32; 2] {
        let m = self.ring.iter().copied().min().unwrap_or(0);
        let [d0, d1] = self.diagonals();
        if d0.contains(&m) { d0 } else { d1 }
    }
}

/// A tetrahedron to be split: its vertices, their sides and the new vertex on each crossing
/// edge (in the order of [`TET_EDGES`], [`crate::mesh::NONE`] where the edge does not cross).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TetSplit {
    /// The tetrahedron's vertices.
    pub verts: [u32; 4],
    /// The side of the plane of each vertex: +1, -1, or 0 on it.
    pub signs: [i8; 4],
    /// The new vertex on each edge, in the order of [`TET_EDGES`] ([`crate::mesh::NONE`]
    /// where the edge does not cross).
    pub split: [u32; 6],
}

/// The children of a split and the triangles of its section (the cut faces).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Children {
    /// The tetrahedra the split makes.
    pub tets: Vec<[u32; 4]>,
    /// The triangles of the section, the faces on the plane.
    pub section: Vec<[u32; 3]>,
}

impl TetSplit {
    fn x(&self, i: usize, j: usize) -> u32 {
        let e = TET_EDGES
            .iter()
            .position(|&[a, b]| (a, b) == (i.min(j), i.max(j)))
            .unwrap_or(0);
        self.split[e]
    }

    fn face(&self, locals: [usize; 3]) -> QuadKey {
        QuadKey::Face(sorted_triple(locals.map(|l| self.verts[l])))
    }

    /// Local vertex indices grouped by side: (positive, negative, on the plane).
    fn sides(&self) -> (Vec<usize>, Vec<usize>, Vec<usize>) {
        let mut s = (Vec::new(), Vec::new(), Vec::new());
        for l in 0..4 {
            match self.signs[l] {
                1 => s.0.push(l),
                -1 => s.1.push(l),
                _ => s.2.push(l),
            }
        }
        s
    }

    /// The quadrilaterals whose diagonals the split needs.
    pub fn quads(&self) -> Vec<Quad> {
        let (mut p, mut n, z) = self.sides();
        if p.len() > n.len() {
            std::mem::swap(&mut p, &mut n);
        }
        let v = |l: usize| self.verts[l];
        match (p.len(), n.len(), z.len()) {
            (1, 3, 0) => {
                let a = p[0];
                let q = [n[0], n[1], n[2]];
                (0..3)
                    .map(|i| {
                        let (qi, qj) = (q[i], q[(i + 1) % 3]);
                        Quad {
                            key: self.face([a, qi, qj]),
                            ring: [self.x(a, qi), self.x(a, qj), v(qj), v(qi)],
                        }
                    })
                    .collect()
            }
            (2, 2, 0) => {
                let (a, b, c, d) = (p[0], p[1], n[0], n[1]);
                let (xac, xad, xbc, xbd) = (self.x(a, c), self.x(a, d), self.x(b, c), self.x(b, d));
                vec![
                    Quad {
                        key: self.face([a, b, c]),
                        ring: [v(a), xac, xbc, v(b)],
                    },
                    Quad {
                        key: self.face([a, b, d]),
                        ring: [xad, v(a), v(b), xbd],
                    },
                    Quad {
                        key: self.face([a, c, d]),
                        ring: [v(c), xac, xad, v(d)],
                    },
                    Quad {
                        key: self.face([b, c, d]),
                        ring: [xbc, v(c), v(d), xbd],
                    },
                    Quad {
                        key: QuadKey::Section,
                        ring: [xac, xad, xbd, xbc],
                    },
                    Quad {
                        key: QuadKey::Section,
                        ring: [xac, xbc, xbd, xad],
                    },
                ]
            }
            (1, 2, 1) => {
                let (a, b, c) = (p[0], n[0], n[1]);
                vec![Quad {
                    key: self.face([a, b, c]),
                    ring: [self.x(a, b), v(b), v(c), self.x(a, c)],
                }]
            }
            _ => Vec::new(),
        }
    }

    /// Splits the tetrahedron with the diagonals `diagonal(quad)` (one of
    /// [`Quad::diagonals`]). None when a prism's diagonals form a cycle. Children are in no
    /// particular orientation; the caller orients them.
    pub fn children(&self, diagonal: &dyn Fn(&Quad) -> [u32; 2]) -> Option<Children> {
        let (mut p, mut n, z) = self.sides();
        if p.len() > n.len() {
            std::mem::swap(&mut p, &mut n);
        }
        let v = |l: usize| self.verts[l];
        let quads = self.quads();
        let diag = |k: usize| diagonal(&quads[k]);
        let mut out = Children::default();
        match (p.len(), n.len(), z.len()) {
            (1, 3, 0) => {
                let a = p[0];
                let xs = [self.x(a, n[0]), self.x(a, n[1]), self.x(a, n[2])];
                out.tets.push([v(a), xs[0], xs[1], xs[2]]);
                out.tets.extend(prism(
                    xs,
                    [v(n[0]), v(n[1]), v(n[2])],
                    [diag(0), diag(1), diag(2)],
                )?);
                out.section.push(xs);
            }
            (2, 2, 0) => {
                let (a, b, c, d) = (p[0], p[1], n[0], n[1]);
                let (xac, xad, xbc, xbd) = (self.x(a, c), self.x(a, d), self.x(b, c), self.x(b, d));
                // positive prism (a, xac, xad) - (b, xbc, xbd): quads [a b c], section, [a b d]
                out.tets.extend(prism(
                    [v(a), xac, xad],
                    [v(b), xbc, xbd],
                    [diag(0), diag(4), diag(1)],
                )?);
                // negative prism (c, xac, xbc) - (d, xad, xbd): quads [a c d], section, [b c d]
                out.tets.extend(prism(
                    [v(c), xac, xbc],
                    [v(d), xad, xbd],
                    [diag(2), diag(5), diag(3)],
                )?);
                let [s, t] = diag(4);
                for o in quads[4].ring.into_iter().filter(|&w| w != s && w != t) {
                    out.section.push(sorted_triple([s, t, o]));
                }
            }
            (1, 2, 1) => {
                let (a, b, c, d) = (p[0], n[0], n[1], z[0]);
                let (xab, xac) = (self.x(a, b), self.x(a, c));
                out.tets.push([v(a), xab, xac, v(d)]);
                let [s, t] = diag(0);
                if sorted_pair(xab, v(c)) == [s, t] {
                    out.tets.push([v(d), xab, v(b), v(c)]);
                    out.tets.push([v(d), xab, v(c), xac]);
                } else {
                    out.tets.push([v(d), xab, v(b), xac]);
                    out.tets.push([v(d), v(b), v(c), xac]);
                }
                out.section.push([v(d), xab, xac]);
            }
            (1, 1, 2) => {
                let (a, b) = (p[0], n[0]);
                let xab = self.x(a, b);
                out.tets.push([v(a), xab, v(z[0]), v(z[1])]);
                out.tets.push([v(b), xab, v(z[0]), v(z[1])]);
                out.section.push([xab, v(z[0]), v(z[1])]);
            }
            _ => return None,
        }
        for s in &mut out.section {
            *s = sorted_triple(*s);
        }
        Some(out)
    }
}

/// Splits the prism with triangles `p`, `q` (lateral edges `p_i - q_i`) into three
/// tetrahedra, given the diagonal of each quadrilateral `(p_i, p_i+1, q_i+1, q_i)`. None when
/// the diagonals form a cycle (or one is not a diagonal of its quadrilateral).
pub fn prism(p: [u32; 3], q: [u32; 3], diag: [[u32; 2]; 3]) -> Option<[[u32; 4]; 3]> {
    // rising[i]: quad i uses p_i - q_i+1 (else p_i+1 - q_i)
    let mut rising = [false; 3];
    for i in 0..3 {
        let j = (i + 1) % 3;
        if diag[i] == sorted_pair(p[i], q[j]) {
            rising[i] = true;
        } else if diag[i] != sorted_pair(p[j], q[i]) {
            return None;
        }
    }
    if rising.iter().all(|&r| r) || rising.iter().all(|&r| !r) {
        return None;
    }
    for i in 0..3 {
        let (j, k) = ((i + 1) % 3, (i + 2) % 3); // k = i - 1
        // p_i carries two diagonals: quad i rising and quad k falling
        if rising[i] && !rising[k] {
            let mut t = [[p[i], q[i], q[j], q[k]], [0; 4], [0; 4]];
            // pyramid apex p_i over quad j = (p_j, p_k, q_k, q_j)
            if rising[j] {
                t[1] = [p[i], p[j], p[k], q[k]];
                t[2] = [p[i], p[j], q[k], q[j]];
            } else {
                t[1] = [p[i], p[j], p[k], q[j]];
                t[2] = [p[i], p[k], q[k], q[j]];
            }
            return Some(t);
        }
        // q_i carries two diagonals: quad i falling and quad k rising
        if !rising[i] && rising[k] {
            let mut t = [[q[i], p[i], p[j], p[k]], [0; 4], [0; 4]];
            if rising[j] {
                t[1] = [q[i], p[j], p[k], q[k]];
                t[2] = [q[i], p[j], q[k], q[j]];
            } else {
                t[1] = [q[i], p[j], p[k], q[j]];
                t[2] = [q[i], p[k], q[k], q[j]];
            }
            return Some(t);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prism_refuses_cycles_and_splits_the_rest_into_three() {
        let (p, q) = ([0, 1, 2], [3, 4, 5]);
        let up = |i: usize| sorted_pair(p[i], q[(i + 1) % 3]);
        let down = |i: usize| sorted_pair(p[(i + 1) % 3], q[i]);
        assert!(prism(p, q, [up(0), up(1), up(2)]).is_none());
        assert!(prism(p, q, [down(0), down(1), down(2)]).is_none());
        let mut count = 0;
        for mask in 1..7u32 {
            let d = [0, 1, 2].map(|i| if mask >> i & 1 == 1 { up(i) } else { down(i) });
            let t = prism(p, q, d).expect("non-cyclic");
            count += 1;
            // each tet has 4 distinct vertices and the diagonals appear as edges
            for tet in t {
                let mut s = tet;
                s.sort_unstable();
                assert!(s.windows(2).all(|w| w[0] != w[1]), "{tet:?}");
            }
            for dd in d {
                assert!(
                    t.iter()
                        .any(|tet| tet.contains(&dd[0]) && tet.contains(&dd[1])),
                    "{d:?} {t:?}"
                );
            }
        }
        assert_eq!(count, 6);
    }
}
