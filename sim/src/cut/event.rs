//! Topology events: everything a cut changed, so a recording can replay it and a viewer can
//! update its mesh incrementally.

use serde::{Deserialize, Serialize};

/// A vertex created on a cut edge at `a + t (b - a)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CreatedVertex {
    /// The new vertex's id.
    pub id: u32,
    /// The cut edge `[a, b]`.
    pub edge: [u32; 2],
    /// Where along the edge it lies, from 0 at `a` to 1 at `b`.
    pub t: f64,
}

/// A vertex moved onto the clipping plane (current and reference positions, metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MovedVertex {
    /// The vertex's id.
    pub id: u32,
    /// Its position before the move.
    pub from: [f64; 3],
    /// Its position on the plane.
    pub to: [f64; 3],
}

/// A vertex split in two: `copy` takes over the tetrahedra on one side.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SplitVertex {
    /// The vertex that was split (it keeps the tetrahedra on the other side).
    pub original: u32,
    /// The new vertex.
    pub copy: u32,
}

/// Everything one cut changed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CutEvent {
    /// Tetrahedra replaced by their children (ids before the cut).
    pub tets_removed: Vec<u32>,
    /// New tetrahedra `(id, vertices)` after the cut (the first child of a tetrahedron reuses
    /// its id; the others are appended).
    pub tets_added: Vec<(u32, [u32; 4])>,
    /// Tetrahedra whose vertices changed because a vertex was split.
    pub tets_relinked: Vec<(u32, [u32; 4])>,
    /// Vertices created on cut edges.
    pub vertices_created: Vec<CreatedVertex>,
    /// Vertices moved onto the clipping plane.
    pub vertices_moved: Vec<MovedVertex>,
    /// Vertices split in two, the sides of the cut taking one each.
    pub vertices_split: Vec<SplitVertex>,
    /// Springs (edges) removed.
    pub springs_removed: Vec<[u32; 2]>,
    /// Springs (edges) added.
    pub springs_added: Vec<[u32; 2]>,
    /// Triangles of the new cut surface (one per side).
    pub cut_faces: usize,
    /// Smallest child volume relative to its parent's (1 when nothing was split).
    pub min_child_volume_fraction: f64,
    /// Edges split beyond the blade's reach because no vertex could move (fallback).
    pub forced_splits: usize,
    /// Small free pieces the cut would have carved out and left attached instead (see
    /// [`super::CutOptions::fragment_volume_m3`]).
    #[serde(default)]
    pub fragments_reattached: usize,
    /// Pieces the cut freed from the tissue, lifted out of the wound.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub specimens: Vec<super::Specimen>,
}

impl Default for CutEvent {
    /// Nothing changed (and so no child is smaller than its parent: fraction 1).
    fn default() -> Self {
        Self {
            tets_removed: Vec::new(),
            tets_added: Vec::new(),
            tets_relinked: Vec::new(),
            vertices_created: Vec::new(),
            vertices_moved: Vec::new(),
            vertices_split: Vec::new(),
            springs_removed: Vec::new(),
            springs_added: Vec::new(),
            cut_faces: 0,
            min_child_volume_fraction: 1.0,
            forced_splits: 0,
            fragments_reattached: 0,
            specimens: Vec::new(),
        }
    }
}

impl CutEvent {
    /// True when the cut changed nothing.
    pub fn is_empty(&self) -> bool {
        self.tets_removed.is_empty()
            && self.vertices_moved.is_empty()
            && self.vertices_split.is_empty()
            && self.specimens.is_empty()
    }

    /// The particles this cut made of the set `of` (ascending ids: the particles in a
    /// grasper's jaws), in the order made: those it created on an edge between two of the
    /// set, then the copies it split off any of the set or of those just made. A grasper's
    /// jaws hold both sides of a cut through their bite, so what the cut made of their
    /// tissue is in them too.
    pub fn made_from(&self, of: &[u32]) -> Vec<(u32, MadeFrom)> {
        let mut set: std::collections::BTreeSet<u32> = of.iter().copied().collect();
        let mut made = Vec::new();
        for c in &self.vertices_created {
            let [a, b] = c.edge;
            if set.contains(&a) && set.contains(&b) {
                set.insert(c.id);
                made.push((c.id, MadeFrom::Between { a, b, t: c.t }));
            }
        }
        for s in &self.vertices_split {
            if set.contains(&s.original) {
                set.insert(s.copy);
                made.push((s.copy, MadeFrom::CopyOf(s.original)));
            }
        }
        made
    }
}

/// What a cut made a particle of ([`CutEvent::made_from`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MadeFrom {
    /// Created on the edge `a`-`b`, at `t` from 0 at `a` to 1 at `b`.
    Between {
        /// The edge's first end.
        a: u32,
        /// The edge's second end.
        b: u32,
        /// Where along the edge.
        t: f64,
    },
    /// Split off this particle: a copy standing where it stood.
    CopyOf(u32),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_a_cut_made_of_a_set_is_its_edges_created_and_the_copies_of_those_and_it() {
        let created = |id, edge, t| CreatedVertex { id, edge, t };
        let split = |original, copy| SplitVertex { original, copy };
        let event = CutEvent {
            vertices_created: vec![
                created(10, [1, 2], 0.25),
                created(11, [2, 7], 0.5),
                created(12, [7, 8], 0.5),
            ],
            vertices_split: vec![split(1, 20), split(10, 21), split(7, 22), split(21, 23)],
            ..CutEvent::default()
        };
        assert_eq!(
            event.made_from(&[1, 2]),
            vec![
                (
                    10,
                    MadeFrom::Between {
                        a: 1,
                        b: 2,
                        t: 0.25
                    }
                ),
                (20, MadeFrom::CopyOf(1)),
                (21, MadeFrom::CopyOf(10)),
                (23, MadeFrom::CopyOf(21)),
            ],
            "one end outside the set makes nothing of an edge, nor does a split of another"
        );
        assert!(event.made_from(&[]).is_empty());
    }
}
