//! The tetrahedral mesh: vertices (metres), positively oriented tetrahedra, per-tet material
//! regions, and the topology derived from them (see [`Topology`]).

mod geometry;
mod grid;
mod pieces;
pub mod quality;
mod topology;
mod topology_update;
mod validate;

pub use geometry::{
    bounding_box, dihedral_angles, tet_signed_volume, tet_volume_gradients, triangle_normal,
};
pub use grid::PointGrid;
pub use pieces::{Piece, anchored, has_free_piece, pieces};
pub use quality::QualityStats;
pub use quality::tet_mu;
pub use topology::{Csr, NONE, TET_EDGES, TET_FACES, Topology, non_manifold_edges};
pub(crate) use topology::{edge_key, face_key, sorted_pair, sorted_triple};
pub(crate) use topology_update::PARALLEL_MIN_TETS;
pub use validate::ValidationReport;

use crate::{MeshError, Point3};

/// Index of a vertex (particle).
pub type VertexId = u32;
/// Index of a tetrahedron.
pub type TetId = u32;

/// A tetrahedral mesh with derived topology.
///
/// Invariants kept by construction: every vertex id of a tetrahedron is in range and the four
/// ids of a tetrahedron are distinct; there is one region id per tetrahedron. Geometric
/// properties (orientation, degeneracy, conformity) are *checked* by [`TetMesh::validate`],
/// not assumed, because they depend on the data and on the current deformation.
#[derive(Debug, Clone)]
pub struct TetMesh {
    positions: Vec<Point3>,
    tets: Vec<[VertexId; 4]>,
    regions: Vec<u32>,
    topology: Topology,
}

/// Tet `t`'s vertex ids are in range and distinct.
fn check_tet(t: usize, tet: &[VertexId; 4], vertex_count: usize) -> Result<(), MeshError> {
    for (i, &v) in tet.iter().enumerate() {
        if v as usize >= vertex_count {
            return Err(MeshError::VertexOutOfRange {
                tet: t,
                vertex: v,
                vertex_count,
            });
        }
        if tet[..i].contains(&v) {
            return Err(MeshError::RepeatedVertex { tet: t, vertex: v });
        }
    }
    Ok(())
}

impl TetMesh {
    /// Builds a mesh from vertex positions (metres), tetrahedra and one region id per
    /// tetrahedron. The vertex order of each tetrahedron is kept as given; call
    /// [`TetMesh::orient_positively`] to fix files written with the opposite convention.
    pub fn new(
        positions: Vec<Point3>,
        tets: Vec<[VertexId; 4]>,
        regions: Vec<u32>,
    ) -> Result<Self, MeshError> {
        if tets.is_empty() {
            return Err(MeshError::Empty);
        }
        if positions.len() > u32::MAX as usize - 1 {
            return Err(MeshError::TooManyVertices(positions.len()));
        }
        if regions.len() != tets.len() {
            return Err(MeshError::RegionCount {
                regions: regions.len(),
                tets: tets.len(),
            });
        }
        for (t, tet) in tets.iter().enumerate() {
            check_tet(t, tet, positions.len())?;
        }
        let topology = Topology::build(positions.len(), &tets);
        Ok(Self {
            positions,
            tets,
            regions,
            topology,
        })
    }

    /// [`TetMesh::new`] for a local change of `previous`: the tets `changed` (ascending ids of
    /// `previous` whose vertices changed) and the tets appended after those of `previous`;
    /// tet ids do not move and vertices are only appended. Only those tets are checked, and
    /// the topology is carried over from `previous` ([`Topology::updated`]) instead of built
    /// again: what a cut needs at haptic rates.
    pub fn with_changes(
        previous: &TetMesh,
        positions: Vec<Point3>,
        tets: Vec<[VertexId; 4]>,
        regions: Vec<u32>,
        changed: &[u32],
    ) -> Result<Self, MeshError> {
        let old_count = previous.tets.len();
        let local = positions.len() >= previous.positions.len()
            && tets.len() >= old_count
            && regions.len() == tets.len()
            && changed.windows(2).all(|w| w[0] < w[1])
            && changed.last().is_none_or(|&t| (t as usize) < old_count);
        if !local || positions.len() > u32::MAX as usize - 1 {
            return Self::new(positions, tets, regions);
        }
        for t in changed
            .iter()
            .copied()
            .chain(old_count as u32..tets.len() as u32)
        {
            check_tet(t as usize, &tets[t as usize], positions.len())?;
        }
        let topology = previous
            .topology
            .updated(&previous.tets, &tets, changed, positions.len())
            .unwrap_or_else(|| Topology::build(positions.len(), &tets));
        Ok(Self {
            positions,
            tets,
            regions,
            topology,
        })
    }

    /// Builds a mesh where every tetrahedron has region 0.
    pub fn with_single_region(
        positions: Vec<Point3>,
        tets: Vec<[VertexId; 4]>,
    ) -> Result<Self, MeshError> {
        let regions = vec![0; tets.len()];
        Self::new(positions, tets, regions)
    }

    /// Swaps two vertices of every negatively oriented tetrahedron (signed volume < 0) so that
    /// all are positively oriented. Degenerate tetrahedra are left alone. Returns how many
    /// were flipped.
    pub fn orient_positively(&mut self) -> usize {
        let mut flipped = 0;
        for tet in &mut self.tets {
            let [a, b, c, d] = tet.map(|v| self.positions[v as usize]);
            if tet_signed_volume(&a, &b, &c, &d) < 0.0 {
                tet.swap(2, 3);
                flipped += 1;
            }
        }
        if flipped > 0 {
            self.topology = Topology::build(self.positions.len(), &self.tets);
        }
        flipped
    }

    /// Vertex positions in metres.
    pub fn positions(&self) -> &[Point3] {
        &self.positions
    }

    /// Mutable vertex positions (topology is unaffected by moving vertices).
    pub fn positions_mut(&mut self) -> &mut [Point3] {
        &mut self.positions
    }

    /// Tetrahedra as four vertex ids each.
    pub fn tets(&self) -> &[[VertexId; 4]] {
        &self.tets
    }

    /// Material region id of each tetrahedron.
    pub fn regions(&self) -> &[u32] {
        &self.regions
    }

    /// Derived topology: edges, faces, surface and adjacency.
    pub fn topology(&self) -> &Topology {
        &self.topology
    }

    /// The number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// The number of tetrahedra.
    pub fn tet_count(&self) -> usize {
        self.tets.len()
    }

    /// The four corner positions of tetrahedron `t`.
    pub fn tet_corners(&self, t: usize) -> [Point3; 4] {
        self.tets[t].map(|v| self.positions[v as usize])
    }

    /// Signed volume of tetrahedron `t` in m^3 (positive when positively oriented).
    pub fn tet_volume(&self, t: usize) -> f64 {
        let [a, b, c, d] = self.tet_corners(t);
        tet_signed_volume(&a, &b, &c, &d)
    }

    /// Sum of signed tetrahedron volumes in m^3.
    pub fn volume(&self) -> f64 {
        (0..self.tets.len()).map(|t| self.tet_volume(t)).sum()
    }

    /// Axis-aligned bounding box `(min, max)` of the vertices.
    pub fn bounding_box(&self) -> (Point3, Point3) {
        geometry::bounding_box(&self.positions)
    }

    /// Distinct region ids, ascending.
    pub fn region_ids(&self) -> Vec<u32> {
        let mut ids = self.regions.clone();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    /// Checks geometry and conformity; see [`ValidationReport`].
    pub fn validate(&self) -> ValidationReport {
        validate::validate(self)
    }

    /// Dihedral-angle statistics over all tetrahedra.
    pub fn quality(&self) -> QualityStats {
        quality::quality(self)
    }

    /// Pairs of distinct vertices at the same position (within `tolerance_m`), such as the two
    /// copies of a vertex split by a cut, found by sorting (not by comparing every pair).
    /// Every pair within a group of coincident vertices is listed, smaller id first.
    pub fn coincident_vertices(&self, tolerance_m: f64) -> Vec<[VertexId; 2]> {
        let pos = &self.positions;
        let mut order: Vec<u32> = (0..pos.len() as u32).collect();
        order.sort_by(|&a, &b| {
            let (p, q) = (&pos[a as usize], &pos[b as usize]);
            p.x.total_cmp(&q.x)
                .then(p.y.total_cmp(&q.y))
                .then(p.z.total_cmp(&q.z))
                .then(a.cmp(&b))
        });
        let mut pairs = Vec::new();
        for (i, &a) in order.iter().enumerate() {
            for &b in &order[i + 1..] {
                if pos[b as usize].x - pos[a as usize].x > tolerance_m {
                    break;
                }
                if (pos[a as usize] - pos[b as usize]).norm() <= tolerance_m {
                    pairs.push([a.min(b), a.max(b)]);
                }
            }
        }
        pairs.sort_unstable();
        pairs
    }
}
